"""Benchmark of the four-bar drive (Incerti, 2012): closed-loop run with the paper's PID.

1. Work-precision: error of the state at the output times (relative to each component's peak)
   against a tight Dopri8 reference (rtol 1e-12), versus median run time, for diffrax solvers
   over tolerances, the paper's fixed-step RK4 at 1 ms (and finer), and scipy `solve_ivp`
   (LSODA, Radau, DOP853) on an independent numpy vector field in the same run.
2. Cost of the gradient of the smooth χ with respect to (Kp, Ki, Kd) relative to the forward χ.
3. `vmap` sweep over gain sets (exact χ over 0.375-0.5 s) against a scipy loop (timed on a
   subset and scaled, stated as such).

`python benchmarks/fourbar.py [--quick]` writes `benchmarks/results/fourbar.json` and `.png`. `--quick` (a check
of the script): Tsit5 at two tolerances against Tsit5 at rtol 1e-11 (not Dopri8 at 1e-12: the same program as
the timed ones, one compilation fewer), RK4 at 1 ms, LSODA at 1e-6, the forward-mode gradient only (the full run
checks it against the reverse mode), a sweep of 10 gain sets (2 of them by scipy), one repeat of each timing.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # jaxbelt computes in float64 (it leaves the setting to its caller)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import RESULTS, rel_error, save_figure, time_jax, time_py, write_results  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import jaxbelt as jb  # noqa: E402
from jaxbelt.objectives import closed_loop_metrics, fluctuation_objective  # noqa: E402

KP, KI, KD, W0 = 80.0, 32.0, 0.015, 30.0


# --- independent numpy vector field (textbook velocity/acceleration analysis) ---------------
def np_rhs_factory(d):
    p = {
        k: float(getattr(d, k))
        for k in (
            "a",
            "b",
            "c",
            "hx",
            "hy",
            "f1",
            "f2",
            "f3",
            "m1",
            "m2",
            "m3",
            "jg1",
            "jg2",
            "jg3",
            "g",
            "R",
            "L",
            "km",
            "jm",
            "ja",
            "jb",
            "z",
            "T0",
            "lam",
        )
    }
    k_asm = d.assembly
    jeq = p["jb"] + (p["jm"] + p["ja"]) * p["z"] ** 2

    def coeffs(al):
        a, b, c = p["a"], p["b"], p["c"]
        bx, by = a * math.cos(al), a * math.sin(al)
        dx, dy = p["hx"] - bx, p["hy"] - by
        dd = math.hypot(dx, dy)
        x = (dd * dd + b * b - c * c) / (2 * dd)
        yy = math.sqrt(b * b - x * x)
        ux, uy = dx / dd, dy / dd
        cx, cy = bx + x * ux + k_asm * yy * uy, by + x * uy - k_asm * yy * ux
        be, ga = math.atan2(cy - by, cx - bx), math.atan2(cy - p["hy"], cx - p["hx"])
        s = math.sin(ga - be)
        Q = a * math.sin(al - ga) / (b * s)
        R = a * math.sin(al - be) / (c * s)
        Q2 = (a * math.cos(al - ga) + b * Q * Q * math.cos(be - ga) - c * R * R) / (b * s)
        R2 = (-a * math.cos(al - be) - b * Q * Q + c * R * R * math.cos(ga - be)) / (-c * s)
        sa, ca, sb, cb, sg, cg = math.sin(al), math.cos(al), math.sin(be), math.cos(be), math.sin(ga), math.cos(ga)
        f1, f2, f3 = p["f1"], p["f2"], p["f3"]
        # (mass, r'x, r'y, r''x, r''y, J_G, θ', θ'')
        links = (
            (p["m1"], -f1 * sa, f1 * ca, -f1 * ca, -f1 * sa, p["jg1"], 1.0, 0.0),
            (
                p["m2"],
                -a * sa - f2 * Q * sb,
                a * ca + f2 * Q * cb,
                -a * ca - f2 * (Q2 * sb + Q * Q * cb),
                -a * sa + f2 * (Q2 * cb - Q * Q * sb),
                p["jg2"],
                Q,
                Q2,
            ),
            (
                p["m3"],
                -f3 * R * sg,
                f3 * R * cg,
                -f3 * (R2 * sg + R * R * cg),
                f3 * (R2 * cg - R * R * sg),
                p["jg3"],
                R,
                R2,
            ),
        )
        J = sum(m * (vx * vx + vy * vy) + jg * w * w for m, vx, vy, _, _, jg, w, _ in links)
        dJ = sum(2 * m * (vx * ax + vy * ay) + 2 * jg * w * dw for m, vx, vy, ax, ay, jg, w, dw in links)
        dEp = p["g"] * sum(m * vy for m, _, vy, *_ in links)
        return J, dJ, dEp

    def rhs(t, y, kp, ki, kd, w0):
        al, w, i = y
        J, dJ, dEp = coeffs(al)
        z = p["z"]
        acc = (z * (p["km"] * i - p["T0"] - z * p["lam"] * w) - dEp - 0.5 * dJ * w * w) / (jeq + J)
        v = kp * t * (w0 - z * w) + ki * (w0 * t - z * al) - kd * z * acc
        return [w, acc, (v - p["R"] * i - p["km"] * z * w) / p["L"]]

    return rhs


def scipy_solve(rhs, ts, method, rtol, gains=(KP, KI, KD, W0)):
    sol = solve_ivp(
        rhs, (ts[0], ts[-1]), [0.0, 0.0, 0.0], method=method, t_eval=ts, rtol=rtol, atol=rtol * 1e-2, args=gains
    )
    return sol.y.T


def chi_np(ts, w, t0, t1):
    m = (ts >= t0 - 1e-12) & (ts <= t1 + 1e-12)
    x, v = ts[m], w[m]
    return (v.max() - v.min()) / (np.trapezoid(v, x) / (x[-1] - x[0]))


def main(quick: bool) -> None:
    drive = jb.FourBarDrive()
    pid = jb.PID(kp=KP, ki=KI, kd=KD, omega_ref=W0)
    t_end = 0.5
    ts = np.linspace(0.0, t_end, 501)
    scene = jb.Scene(drive, pid, ts=ts)
    tsit5 = eqx.filter_jit(
        lambda sc, r: jb.simulate(sc, solver=diffrax.Tsit5(), rtol=r, atol=r * 1e-2, max_steps=10**6).ys
    )
    if quick:  # quick: the reference from the Tsit5 program timed below, at rtol 1e-11 (one compilation fewer)
        ref = np.asarray(tsit5(scene, jnp.asarray(1e-11)))
    else:
        ref = np.asarray(jb.simulate(scene, solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12, max_steps=10**6).ys)
    rows = []
    repeats = 1 if quick else 5

    # --- 1. work-precision ------------------------------------------------------------------
    solvers = {"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8(), "Kvaerno5": diffrax.Kvaerno5()}
    tols = (1e-5, 1e-8) if quick else (1e-4, 1e-6, 1e-8, 1e-10)
    for name, solver in solvers.items():
        if quick and name != "Tsit5":  # quick: one adaptive solver (its headline rows); the others are the full run's
            continue
        run = (
            tsit5
            if name == "Tsit5"
            else eqx.filter_jit(
                lambda sc, r, s=solver: jb.simulate(sc, solver=s, rtol=r, atol=r * 1e-2, max_steps=10**6).ys
            )
        )
        for tol in tols:
            med, comp, ys = time_jax(run, scene, jnp.asarray(tol), repeats=repeats)
            rows.append(
                {
                    "name": f"diffrax {name}",
                    "method": "ode",
                    "rtol": tol,
                    "error": rel_error(ys, ref),
                    "median_s": med,
                    "compile_s": comp,
                    "repeats": repeats,
                }
            )
            print(rows[-1])
    for dt in (1e-3,) if quick else (1e-3, 5e-4, 2.5e-4, 1.25e-4):  # outputs every 1 ms: dt <= 1 ms

        def run(d, p, dt=dt):  # simulate jits the stepping itself (rk4 needs concrete ts)
            return jb.simulate(jb.Scene(d, p, ts=ts), method="rk4", dt=dt).ys

        med, comp, ys = time_jax(run, drive, pid, repeats=repeats)
        rows.append(
            {
                "name": f"RK4 dt={dt * 1e3:g} ms" + (" (paper)" if dt == 1e-3 else ""),
                "method": "rk4",
                "dt": dt,
                "error": rel_error(ys, ref),
                "median_s": med,
                "compile_s": comp,
                "repeats": repeats,
            }
        )
        print(rows[-1])
    rhs = np_rhs_factory(drive)
    sp_tols = (1e-6,) if quick else (1e-4, 1e-6, 1e-8, 1e-10)
    for method in ("LSODA",) if quick else ("LSODA", "Radau", "DOP853"):
        for tol in sp_tols:
            if method == "Radau" and tol < 1e-9:
                continue  # minutes per solve: out of the time budget
            med, ys = time_py(scipy_solve, rhs, ts, method, tol, repeats=1 if quick else 2)
            rows.append(
                {
                    "name": f"scipy {method}",
                    "method": "scipy",
                    "rtol": tol,
                    "error": rel_error(ys, ref),
                    "median_s": med,
                    "compile_s": None,
                    "repeats": 1 if quick else 2,
                }
            )
            print(rows[-1])

    # --- 2. gradient / forward cost -----------------------------------------------------------
    pid_s = jb.PID(kp=KP, ki=KI, kd=KD, omega_ref=W0, v_limit=60.0, limiter="smooth")
    fwd = eqx.filter_jit(lambda g: fluctuation_objective(drive, pid_s.with_gains(g)))
    # reverse mode through the checkpointed solve, and forward mode (what tune_pid uses: 3 gains)
    grd_rev = eqx.filter_jit(jax.grad(lambda g: fluctuation_objective(drive, pid_s.with_gains(g))))
    grd = eqx.filter_jit(jax.jacfwd(lambda g: fluctuation_objective(drive, pid_s.with_gains(g), adjoint="forward")))
    g0 = jnp.array([KP, KI, KD])
    t_fwd, c_fwd, _ = time_jax(fwd, g0, repeats=repeats)
    t_grd, c_grd, g_fwd = time_jax(grd, g0, repeats=repeats)
    t_rev = c_rev = None
    if not quick:  # quick: the forward mode alone (the headline's target); the full run checks it against reverse
        t_rev, c_rev, g_rev = time_jax(grd_rev, g0, repeats=repeats)
        assert np.allclose(np.asarray(g_rev), np.asarray(g_fwd), rtol=1e-6), (g_rev, g_fwd)
    print("forward", t_fwd, "grad (forward mode)", t_grd, "grad (reverse mode)", t_rev)

    # --- 3. vmap sweep over gains vs a scipy loop ---------------------------------------------
    n_sweep = 10 if quick else 1000
    rng = np.random.default_rng(0)
    gains = np.array([KP, KI, KD]) * np.exp(rng.uniform(-0.7, 0.7, size=(n_sweep, 3)))
    sweep_pid = jb.PID(kp=KP, ki=KI, kd=KD, omega_ref=W0)

    def chi_of(g):
        return closed_loop_metrics(drive, sweep_pid.with_gains(g), 0.375, 0.5, rtol=1e-6, atol=1e-6)["chi"]

    sweep = jax.jit(jax.vmap(chi_of))
    t_sweep, c_sweep, chis = time_jax(sweep, jnp.asarray(gains), repeats=1 if quick else 3, min_time=0.0)
    n_sp = 2 if quick else 20
    ts_sw = np.linspace(0.0, 0.5, 1001)
    t0 = time.perf_counter()
    chis_sp = []
    for g in gains[:n_sp]:
        ys = scipy_solve(rhs, ts_sw, "LSODA", 1e-6, gains=(g[0], g[1], g[2], W0))
        chis_sp.append(chi_np(ts_sw, ys[:, 1], 0.375, 0.5))
    t_sp = (time.perf_counter() - t0) / n_sp * n_sweep
    chi_diff = float(np.max(np.abs(np.asarray(chis)[:n_sp] - np.array(chis_sp))))
    print("sweep", t_sweep, "scipy (scaled)", t_sp, "max chi diff", chi_diff)

    rk4_row = next(r for r in rows if r["method"] == "rk4" and r.get("dt") == 1e-3)
    headline = [
        {
            "what": "closed-loop run 0.5 s, Tsit5 rtol 1e-8: error",
            "unit": "rel",
            "value": next(r["error"] for r in rows if r["name"] == "diffrax Tsit5" and r["rtol"] == 1e-8),
            "target": None,
        },
        {
            "what": "closed-loop run 0.5 s, Tsit5 rtol 1e-8: time",
            "unit": "s",
            "value": next(r["median_s"] for r in rows if r["name"] == "diffrax Tsit5" and r["rtol"] == 1e-8),
            "target": None,
        },
        {"what": "paper's RK4 at 1 ms: error", "unit": "rel", "value": rk4_row["error"], "target": None},
        {"what": "paper's RK4 at 1 ms: time", "unit": "s", "value": rk4_row["median_s"], "target": None},
        {
            "what": "scipy LSODA rtol 1e-6: time",
            "unit": "s",
            "value": next(r["median_s"] for r in rows if r["name"] == "scipy LSODA" and r["rtol"] == 1e-6),
            "target": None,
        },
        {
            "what": "gradient / forward time (smooth chi, 3 gains, forward mode)",
            "unit": "x",
            "value": t_grd / t_fwd,
            "target": "<= 5",
        },
        *(
            []
            if t_rev is None
            else [
                {
                    "what": "gradient / forward time (smooth chi, reverse mode)",
                    "unit": "x",
                    "value": t_rev / t_fwd,
                    "target": None,
                }
            ]
        ),
        {"what": f"vmap sweep of {n_sweep} gain sets (chi)", "unit": "s", "value": t_sweep, "target": None},
        {
            "what": f"scipy LSODA loop, {n_sweep} gain sets (timed on {n_sp}, scaled)",
            "unit": "s",
            "value": t_sp,
            "target": None,
        },
        {"what": "sweep speed-up over scipy loop", "unit": "x", "value": t_sp / t_sweep, "target": None},
    ]
    extra = {
        "gradient": {
            "forward_s": t_fwd,
            "grad_s": t_grd,
            "forward_compile_s": c_fwd,
            "grad_compile_s": c_grd,
            "grad_reverse_s": t_rev,
            "grad_reverse_compile_s": c_rev,
        },
        "sweep": {
            "n": n_sweep,
            "vmap_s": t_sweep,
            "vmap_compile_s": c_sweep,
            "scipy_scaled_s": t_sp,
            "scipy_timed_runs": n_sp,
            "max_chi_difference_vs_scipy": chi_diff,
        },
    }
    path = write_results("fourbar", rows, headline, quick, extra)
    print("wrote", path)
    plot(rows)


def plot(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    groups = {}
    for r in rows:
        key = "RK4 fixed step (paper: 1 ms)" if r["method"] == "rk4" else r["name"]
        groups.setdefault(key, []).append(r)
    for name, sel in groups.items():
        sel = sorted(sel, key=lambda r: r["median_s"])
        ax.loglog(
            [r["median_s"] for r in sel],
            [max(r["error"], 1e-16) for r in sel],
            marker="o",
            ls="--" if sel[0]["method"] == "scipy" else "-",
            label=name,
        )
    ax.set_xlabel("median run time [s]")
    ax.set_ylabel("max error / peak (vs Dopri8 rtol 1e-12)")
    ax.set_title("four-bar drive, closed loop (PID) 0.5 s: work-precision")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    save_figure(fig, RESULTS / "fourbar.png", dpi=120)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    main(ap.parse_args().quick)
