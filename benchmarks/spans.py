"""Benchmark of the belt-span scene: crossing diagram and linear run-out response sweeps.

1. Crossing diagram of Moon & Wickert's stand over 1e5 running speeds x 5 modes (natural frequencies,
   load lines of two pulleys x 3 harmonics) plus the 5 x 2 x 3 crossing speeds by Newton iteration;
   against a numpy loop over speeds and scipy `brentq` for the crossings.
2. Linear steady response to pulley run-out over 1000 speeds: jaxbelt's modal formula (vmap, jit) at
   several mode counts against a numpy loop (same formula, 64 modes) and a numpy loop of the exact
   travelling-wave solution (the reference, undamped).

Usage: `python benchmarks/spans.py [--quick]`; writes benchmarks/results/spans.json and .png.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, save_figure, time_jax, time_py, write_results  # noqa: E402

import jaxbelt as jb  # noqa: E402

L, VT, RADII, RUNOUTS, PHASE = 0.86, 41.0, (0.063, 0.045), (0.355e-3, 0.21e-3), np.radians(240.0)
N_MODES, HARM = 5, 3


# --- numpy / scipy references ---------------------------------------------------------------------
def np_crossing_loop(speeds):
    n = np.arange(1, N_MODES + 1)
    ks = np.arange(1, HARM + 1)
    r = np.asarray(RADII)
    nat = np.empty((speeds.size, N_MODES))
    load = np.empty((speeds.size, len(RADII), HARM))
    for i, V in enumerate(speeds):
        nat[i] = n * np.pi / L * VT * (1 - (V / VT) ** 2)
        load[i] = V * ks[None, :] / r[:, None]
    cross = np.empty((N_MODES, len(RADII), HARM))
    for a in range(N_MODES):
        for j in range(len(RADII)):
            for k in range(HARM):

                def f(V, n=a + 1, h=k + 1, r=RADII[j]):
                    return n * np.pi / L * VT * (1 - (V / VT) ** 2) - h * V / r

                cross[a, j, k] = brentq(f, 0.0, VT, xtol=1e-14)
    return nat, load, cross


def np_modal_loop(speeds, n_modes=64, zeta=0.0, x=0.25):
    """The modal formula of `linear_runout_response` written in numpy, one speed at a time."""
    n = np.arange(1, n_modes + 1)
    out = np.empty(speeds.size)
    xm = x / L

    def e0(k):
        return (np.exp(1j * k) - 1) / (1j * k)

    def e1(k):
        return np.exp(1j * k) / (1j * k) + (np.exp(1j * k) - 1) / k**2

    def proj(p, q, v):
        k1, k2 = n * np.pi * (1 - v), -n * np.pi * (1 + v)
        return ((p * e0(k1) + q * e1(k1)) - (p * e0(k2) + q * e1(k2))) / 2j

    def phasor(v, Om, s0, s1):
        wn = n * np.pi * (1 - v**2)
        Nn = (n * np.pi) ** 2 * (1 - v**2)
        sig = 1j * wn - zeta * wn
        ds = s1 - s0
        p, q = Om**2 * s0 - 2j * v * Om * ds, Om**2 * ds
        cp = -1j * wn * proj(p, q, v) / (2 * Nn * (1j * Om - sig))
        cm = -1j * wn * proj(np.conj(p), np.conj(q), v) / (2 * Nn * (-1j * Om - sig))
        psi = np.sin(n * np.pi * xm) * np.exp(1j * n * np.pi * v * xm)
        return s0 * (1 - xm) + s1 * xm + 2 * np.sum(cp * psi + np.conj(cm) * np.conj(psi))

    s0 = -1j * RUNOUTS[0] / L
    s1 = -1j * RUNOUTS[1] * np.exp(1j * PHASE) / L
    for i, V in enumerate(speeds):
        v = V / VT
        W0 = phasor(v, V / RADII[0] * L / VT, s0, 0.0)
        W1 = phasor(v, V / RADII[1] * L / VT, 0.0, s1)
        out[i] = 2 * L * (abs(W0) + abs(W1))
    return out


def np_exact_loop(speeds, x=0.25):
    """Exact undamped steady state: W = A exp(-i Om x/(1+v)) + B exp(i Om x/(1-v)), a 2x2 solve per pulley."""
    out = np.empty(speeds.size)
    xm = x / L
    bcs = ((-1j * RUNOUTS[0] / L, 0.0), (0.0, -1j * RUNOUTS[1] * np.exp(1j * PHASE) / L))
    for i, V in enumerate(speeds):
        v = V / VT
        amp = 0.0
        for j in range(2):
            Om = V / RADII[j] * L / VT
            g = np.array([-1j * Om / (1 + v), 1j * Om / (1 - v)])
            A = np.array([[1.0, 1.0], np.exp(g)])
            c = np.linalg.solve(A, np.array(bcs[j], dtype=complex))
            amp += abs(c @ np.exp(g * xm))
        out[i] = 2 * L * amp
    return out


def main(quick: bool):
    rows, headline = [], []
    n_speeds = 10_000 if quick else 100_000
    n_sweep = 200 if quick else 1000
    reps = 3 if quick else 7

    # 1. crossing diagram ----------------------------------------------------------------------------
    speeds = np.linspace(0.0, 0.6 * VT, n_speeds)

    @jax.jit
    def jax_diagram(V):
        rig = jb.RunoutRig(length=L, pulley_radii=RADII, wave_speed=VT)
        nat, load = jb.crossing_diagram(rig, V, N_MODES, HARM)
        return nat, load, jb.crossing_speeds(rig, N_MODES, HARM)

    t_jax, c_jax, (nat, load, cross) = time_jax(jax_diagram, jnp.asarray(speeds), repeats=reps)
    t_np, (nat0, load0, cross0) = time_py(np_crossing_loop, speeds, repeats=max(1, reps // 3))
    err_loci = max(
        float(np.max(np.abs(np.asarray(nat) - nat0) / np.abs(nat0).max())),
        float(np.max(np.abs(np.asarray(load) - load0) / np.abs(load0).max())),
    )
    err_cross = float(np.max(np.abs(np.asarray(cross) - cross0) / cross0))
    rows.append(
        dict(
            name="crossing diagram",
            method="jaxbelt (jit, Newton crossings)",
            error=max(err_loci, err_cross),
            median_s=t_jax,
            compile_s=c_jax,
            repeats=reps,
            n_speeds=n_speeds,
            n_modes=N_MODES,
        )
    )
    rows.append(
        dict(
            name="crossing diagram",
            method="numpy loop + scipy brentq",
            error=0.0,
            median_s=t_np,
            compile_s=None,
            repeats=max(1, reps // 3),
            n_speeds=n_speeds,
            n_modes=N_MODES,
        )
    )
    mw = np.asarray(jb.crossing_speeds(jb.RunoutRig(), 2))
    headline += [
        dict(what=f"crossing diagram {n_speeds} speeds x {N_MODES} modes, jaxbelt", value=t_jax, unit="s", target=None),
        dict(what="crossing diagram speed-up over numpy/scipy loop", value=t_np / t_jax, unit="x", target=None),
        dict(what="Moon & Wickert crossing, mode 1", value=float(mw[0, 0, 0]), unit="m/s", target="9.0 +/- 0.05"),
        dict(what="Moon & Wickert crossing, mode 2", value=float(mw[1, 0, 0]), unit="m/s", target="16.0 +/- 0.1"),
    ]
    print(
        f"crossing diagram: jax {t_jax * 1e3:.2f} ms (compile {c_jax:.2f} s), numpy/scipy loop {t_np * 1e3:.1f} ms, "
        f"max rel. difference {max(err_loci, err_cross):.2e}"
    )

    # 2. linear response sweep -----------------------------------------------------------------------
    # the sweep avoids exact resonance (undamped reference): 1000 speeds on a grid offset from crossings
    sw = np.linspace(0.3, 0.5 * VT, n_sweep) + 1.234e-4
    ref = np_exact_loop(sw)
    t_exact, _ = time_py(np_exact_loop, sw, repeats=max(1, reps // 3))
    wp = []
    for nm in (8, 16, 32, 64, 128, 256):
        rig = jb.RunoutRig(length=L, wave_speed=VT, pulley_radii=RADII, runouts=RUNOUTS, phase=PHASE, position=0.25)
        f = jax.jit(lambda V, nm=nm, rig=rig: jb.linear_runout_response(rig, V, nm))
        t, c, out = time_jax(f, jnp.asarray(sw), repeats=reps)
        err = float(np.max(np.abs(np.asarray(out) - ref) / ref))
        rows.append(
            dict(
                name="linear response sweep",
                method=f"jaxbelt modal, {nm} modes",
                error=err,
                median_s=t,
                compile_s=c,
                repeats=reps,
                n_speeds=n_sweep,
                n_modes=nm,
            )
        )
        wp.append((nm, t, err))
        print(f"linear response {n_sweep} speeds, {nm:3d} modes: jax {t * 1e3:.2f} ms, max rel. error {err:.2e}")
    t_np_modal, out_np = time_py(np_modal_loop, sw, repeats=max(1, reps // 3))
    err_np = float(np.max(np.abs(out_np - ref) / ref))
    rows.append(
        dict(
            name="linear response sweep",
            method="numpy loop, modal 64 modes",
            error=err_np,
            median_s=t_np_modal,
            compile_s=None,
            repeats=max(1, reps // 3),
            n_speeds=n_sweep,
            n_modes=64,
        )
    )
    rows.append(
        dict(
            name="linear response sweep",
            method="numpy loop, exact travelling waves (reference)",
            error=0.0,
            median_s=t_exact,
            compile_s=None,
            repeats=max(1, reps // 3),
            n_speeds=n_sweep,
        )
    )
    t64 = [t for nm, t, _ in wp if nm == 64][0]
    e64 = [e for nm, _, e in wp if nm == 64][0]
    headline += [
        dict(what=f"linear response {n_sweep} speeds, 64 modes, jaxbelt", value=t64, unit="s", target=None),
        dict(
            what="linear response speed-up over numpy loop (same formula, 64 modes)",
            value=t_np_modal / t64,
            unit="x",
            target=None,
        ),
        dict(
            what="linear response, 64 modes: max rel. error vs exact travelling-wave solution",
            value=e64,
            unit="",
            target="< 1e-4",
        ),
    ]
    print(f"numpy modal loop {t_np_modal * 1e3:.1f} ms (err {err_np:.2e}); numpy exact loop {t_exact * 1e3:.1f} ms")

    path = write_results("spans", rows, headline, quick)
    _plot(wp, t_np_modal, err_np, t_exact, t_jax, t_np, n_speeds, n_sweep)
    print(f"wrote {path}")


def _plot(wp, t_np_modal, err_np, t_exact, t_jax, t_np, n_speeds, n_sweep):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.2))
    ax = axs[0]
    ts = [t for _, t, _ in wp]
    es = [max(e, 1e-16) for _, _, e in wp]
    ax.loglog(ts, es, "o-", label="jaxbelt modal (jit + vmap)")
    for nm, t, e in wp:
        ax.annotate(f"{nm}", (t, max(e, 1e-16)), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.loglog([t_np_modal], [err_np], "s", color="C1", label="numpy loop, 64 modes")
    ax.axvline(t_exact, color="C2", ls="--", label="numpy loop, exact waves (reference)")
    ax.set_xlabel("median time [s]")
    ax.set_ylabel("max relative error")
    ax.set_title(f"Linear run-out response, {n_sweep} speeds")
    ax.legend(fontsize=8)
    ax = axs[1]
    ax.bar(["jaxbelt", "numpy loop\n+ brentq"], [t_jax, t_np], color=["C0", "C1"])
    ax.set_yscale("log")
    ax.set_ylabel("median time [s]")
    ax.set_title(f"Crossing diagram, {n_speeds} speeds x {N_MODES} modes")
    fig.tight_layout()
    RESULTS.mkdir(parents=True, exist_ok=True)
    save_figure(fig, RESULTS / "spans.png", dpi=110)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="CI-sized run")
    main(ap.parse_args().quick)
