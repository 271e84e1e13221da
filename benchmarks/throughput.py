"""Throughput of batched sweeps: elements per second for `vmap`/batched sweeps of 10^2 ... 10^5.

Scenes (each element is one trajectory or one evaluation):

- `startup`: gamma sweep of the belt start-up, `simulate(Scene(model, ExponentialVoltage(24, gammas),
  ts=ts))` with a 1-D `gammas` (the batched closed form), 501 output points over 0.5 s;
- `shaping`: `vmap` of `residual_energy` over random feasible exponent triples (n = 2);
- `pid`: `vmap` over (Kp, Ki, Kd) of the exact chi over 0.375-0.5 s of the closed-loop four-bar drive
  (diffrax, rtol = atol = 1e-6);
- `runout`: `linear_runout_response` (64 modes, damping ratio 0.01) over belt speeds;
- `span_freqs`: `MovingString.natural_frequencies` (3 modes) over belt speeds.

For every batch size: median run time after compilation (`_common.time_jax`), the first call
(compile + one run) apart, elements per second, bytes of the outputs, and the process peak RSS
growth during that measurement (the kernel's peak is reset through `/proc/self/clear_refs` before
each size where Linux allows it, so every size gets its own peak; otherwise `ru_maxrss` is monotone and
the growth is relative to the earlier peak) and, where `jax.devices()[0].memory_stats()` answers,
the device's peak bytes. A scene stops at the largest size whose single timed run stays under
~20 s (the next size is skipped when 10x the current run time would pass that). At the smallest size
every scene is checked against a reference (a loop of scalar calls, or a closed form) and the max
relative difference is stored in the row.

Gradient cost over forward cost is measured here for the start-up and belt-span sweeps; for H
(shaping) and chi (four-bar) it is read from `benchmarks/results/shaping.json` and `fourbar.json`.

`python benchmarks/throughput.py [--quick]` writes `benchmarks/results/throughput.json` and `.png`.
`--quick`: the reference check's batch of 3 only (its compiled programs timed again: compilation dominates), one
repeat, the derivative cost of the start-up sweep alone.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import RESULTS, save_figure, time_jax, write_results  # noqa: E402

import jaxbelt as jb  # noqa: E402
from jaxbelt.objectives.fluctuation import closed_loop_metrics  # noqa: E402

TS = jnp.linspace(0.0, 0.5, 501)
V_MAX = 24.0
KP, KI, KD, W0 = 80.0, 32.0, 0.015, 30.0
RUNOUT = dict(
    length=0.86,
    wave_speed=41.0,
    pulley_radii=(0.063, 0.063),
    runouts=(0.355e-3, 0.21e-3),
    phase=float(np.radians(240.0)),
    damping_ratio=0.01,
    position=0.01,
)
SPAN = dict(tension=140.0, density=0.05, length=0.2621)
MAX_RUN_S = 20.0


# --- the batched computations and their scalar references (the test imports these) ----------------
def startup_batch(gammas):
    """The five states at 501 times, shape (B, 501, 5), from the batched closed form."""
    model = jb.BeltStartup()
    return jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V_MAX, gammas), ts=TS)).ys


def startup_scalar(gamma):
    model = jb.BeltStartup()
    return jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V_MAX, gamma), ts=TS), method="expm").ys


def shaping_one(g):
    return jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(g))


def shaping_batch(gs):
    return jax.vmap(shaping_one)(gs)


def pid_one(g):
    drive = jb.FourBarDrive()
    pid = jb.PID(kp=KP, ki=KI, kd=KD, omega_ref=W0)
    return closed_loop_metrics(drive, pid.with_gains(g), 0.375, 0.5, rtol=1e-6, atol=1e-6)["chi"]


def pid_batch(gs):
    return jax.vmap(pid_one)(gs)


def runout_batch(speeds):
    return jb.linear_runout_response(jb.RunoutRig(**RUNOUT), speeds)


def span_freqs_batch(speeds):
    return jb.MovingString(**SPAN).natural_frequencies(speeds, n_modes=3)


def span_freqs_closed_form(speeds):
    """$\\omega_n = (n\\pi/L) V_{cr} (1 - V^2/V_{cr}^2)$ in numpy (belt-vibration report, eq. 39), the reference."""
    vc = np.sqrt(SPAN["tension"] / SPAN["density"])
    v = np.asarray(speeds, dtype=float)
    return (np.pi / SPAN["length"]) * vc * (1 - (v / vc) ** 2)[:, None] * np.arange(1, 4)


def random_inputs(scene: str, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    if scene == "startup":
        return jnp.asarray(rng.uniform(0.005, 0.1, n))
    if scene == "shaping":
        # feasible for n = 2: every exponent > 2, distinct (gaps >= 0.3)
        g1 = rng.uniform(2.2, 4.0, n)
        g2 = g1 + rng.uniform(0.3, 2.0, n)
        g3 = g2 + rng.uniform(0.3, 2.0, n)
        return jnp.asarray(np.stack([g1, g2, g3], axis=1))
    if scene == "pid":
        return jnp.asarray(np.array([KP, KI, KD]) * np.exp(rng.uniform(-0.7, 0.7, size=(n, 3))))
    if scene in ("runout", "span_freqs"):
        return jnp.asarray(rng.uniform(1.0, 20.0, n))
    raise KeyError(scene)


def batch_and_reference(scene: str, x):
    """(batched result, independent reference) for inputs `x`, both numpy."""
    batch = {
        "startup": startup_batch,
        "shaping": shaping_batch,
        "pid": pid_batch,
        "runout": runout_batch,
        "span_freqs": span_freqs_batch,
    }[scene]
    out = np.asarray(jax.jit(batch)(x))
    if scene == "startup":
        f = jax.jit(startup_scalar)
        ref = np.stack([np.asarray(f(g)) for g in x])
    elif scene == "shaping":
        f = jax.jit(shaping_one)
        ref = np.array([float(f(g)) for g in x])
    elif scene == "pid":
        f = jax.jit(pid_one)
        ref = np.array([float(f(g)) for g in x])
    elif scene == "runout":
        f = jax.jit(lambda v: jb.linear_runout_response(jb.RunoutRig(**RUNOUT), v))
        ref = np.array([float(f(v)) for v in x])
    else:
        ref = span_freqs_closed_form(x)
    return out, ref


REFERENCE = {
    "startup": "loop of scalar simulate(method='expm') calls",
    "shaping": "loop of scalar residual_energy calls",
    "pid": "loop of scalar closed_loop_metrics calls",
    "runout": "loop of scalar linear_runout_response calls",
    "span_freqs": "numpy closed form (eq. 39)",
}
FUNCS = {
    "startup": startup_batch,
    "shaping": shaping_batch,
    "pid": pid_batch,
    "runout": runout_batch,
    "span_freqs": span_freqs_batch,
}


def max_rel_diff(x, ref) -> float:
    """max |x - ref| / max |ref|, per last-axis column (states, modes), the worst column."""
    x, ref = np.asarray(x, float), np.asarray(ref, float)
    if ref.ndim >= 2:
        x, ref = x.reshape(-1, ref.shape[-1]), ref.reshape(-1, ref.shape[-1])
        scale = np.max(np.abs(ref), axis=0)
        return float(np.max(np.max(np.abs(x - ref), axis=0) / np.where(scale > 0, scale, 1.0)))
    return float(np.max(np.abs(x - ref)) / max(np.max(np.abs(ref)), 1e-300))


# --- memory -------------------------------------------------------------------------------------
def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")  # resets the peak RSS (VmHWM, and so ru_maxrss) to the current RSS
        return True
    except OSError:
        return False


def _rss_kib() -> int | None:
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmRSS"):
                return int(line.split()[1])
    except OSError:
        pass
    return None


def _maxrss_kib() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)  # KiB on Linux


def _device_peak():
    try:
        stats = jax.devices()[0].memory_stats()
    except Exception:  # noqa: BLE001 - backends without the call
        return None
    if not stats:
        return None
    return stats.get("peak_bytes_in_use")


def _nbytes(tree) -> int:
    return int(sum(getattr(a, "nbytes", 0) for a in jax.tree_util.tree_leaves(tree)))


def reps_for(scene: str, n: int, quick: bool) -> int:
    if scene == "pid" and n >= 1000:
        return 1
    if quick:
        return 1
    return 3 if n > 1000 else 5


# --- measurements --------------------------------------------------------------------------------
def measure_scene(scene: str, sizes, quick: bool, t_budget_end: float) -> list[dict]:
    rows = []
    fn = jax.jit(FUNCS[scene])
    check = max_rel_diff(*batch_and_reference(scene, random_inputs(scene, 3, seed=1)))
    print(f"{scene}: batch of 3 vs {REFERENCE[scene]}: max rel. difference {check:.2e}", flush=True)
    for n in sizes:
        x = random_inputs(scene, n)
        reset = _reset_peak()
        rss0 = _rss_kib() if reset else None
        peak0 = _maxrss_kib()
        fn = jax.jit(FUNCS[scene])  # a fresh compile per size (shapes differ anyway)
        t0 = time.perf_counter()
        # a cheap run repeats until >= 0.05 s per sample; a long one is timed fewer times
        reps = reps_for(scene, n, quick)
        median, first, out = time_jax(fn, x, repeats=reps, min_time=0.05 if n <= 10**4 else 0.0)
        wall = time.perf_counter() - t0
        peak1 = _maxrss_kib()
        growth = peak1 - (rss0 if rss0 is not None else peak0)
        row = {
            "name": scene,
            "method": {
                "startup": "batched closed form",
                "shaping": "vmap quadrature",
                "pid": "vmap diffrax",
                "runout": "vectorised modal formula",
                "span_freqs": "vectorised closed form",
            }[scene],
            "error": check if n == sizes[0] else None,
            "reference": REFERENCE[scene] if n == sizes[0] else None,
            "reference_n": 3 if n == sizes[0] else None,
            "batch": n,
            "median_s": median,
            "compile_s": max(first - median, 0.0),
            "first_call_s": first,
            "repeats": reps,
            "per_element_us": median / n * 1e6,
            "elements_per_s": n / median,
            "output_bytes": _nbytes(out),
            "peak_rss_growth_kib": int(growth),
            "peak_rss_reset_per_size": reset,
            "device_peak_bytes": _device_peak(),
            "measure_wall_s": wall,
        }
        rows.append(row)
        print(
            f"  {scene} n={n:>6d}: {median * 1e3:9.3f} ms ({row['per_element_us']:.3g} us/elem, "
            f"{row['elements_per_s']:.3g}/s), first call {first:.2f} s, out {row['output_bytes'] / 1e6:.2f} MB, "
            f"peak RSS growth {max(growth, 0) / 1024:.0f} MiB",
            flush=True,
        )
        del out
        if n == sizes[-1]:
            break
        if median > MAX_RUN_S or 10 * median > MAX_RUN_S:
            print(f"  {scene}: stopping at n={n} (the next size would take ~{10 * median:.0f} s > {MAX_RUN_S:.0f} s)")
            break
        if (
            not quick
            and time.perf_counter() + 10 * median * (2 + reps_for(scene, 10 * n, quick)) + first > t_budget_end
        ):
            print(f"  {scene}: stopping at n={n}: the script's time budget would be passed")
            break
    return rows


def gradient_costs(quick: bool) -> list[dict]:
    """Derivative over forward time for the start-up and belt-span sweeps (1000 elements; quick: 200)."""
    n = 200 if quick else 1000
    reps = 1 if quick else 5
    out = []
    model = jb.BeltStartup()

    def mean_speed(gs):  # per-element scalar: mean driven-pulley speed over 0.5 s (smooth in gamma)
        return jnp.mean(jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V_MAX, gs), ts=TS)).ys[..., 3], axis=-1)

    def runout(v):
        return jb.linear_runout_response(jb.RunoutRig(**RUNOUT), v)

    def freqs(v):
        return jb.MovingString(**SPAN).natural_frequencies(v, n_modes=3)[..., 0]

    cases = [
        ("startup", "mean omega2 over 0.5 s, d/dgamma", mean_speed, random_inputs("startup", n)),
        ("runout", "peak-to-peak response, d/dspeed", runout, random_inputs("runout", n)),
        ("span_freqs", "first natural frequency, d/dspeed", freqs, random_inputs("span_freqs", n)),
    ]
    if quick:  # one case through the loop (two compilations each)
        cases = cases[:1]
    for scene, what, f, x in cases:
        # elements are independent, so one forward-mode product with a tangent of ones is the batch of
        # element derivatives (reverse mode through the batched start-up closed form asked for 36 GB
        # at n = 1000, so forward mode is what a sweep should use)
        fwd = jax.jit(f)
        jvp = jax.jit(lambda x, f=f: jax.jvp(f, (x,), (jnp.ones_like(x),)))
        t_f, c_f, _ = time_jax(fwd, x, repeats=reps)
        t_g, c_g, (_, g) = time_jax(jvp, x, repeats=reps)
        row = {
            "scene": scene,
            "what": what,
            "batch": n,
            "forward_s": t_f,
            "grad_s": t_g,
            "mode": "forward (jvp)",
            "ratio": t_g / t_f,
            "forward_compile_s": c_f,
            "grad_compile_s": c_g,
            "source": "measured here",
        }
        if quick:  # --quick keeps to forward mode (time)
            row.update(reverse_s=None, reverse_ratio=None, reverse_note="not measured in --quick")
        elif scene != "startup":  # reverse mode: the gradient of the sum is the batch of derivatives
            rev = jax.jit(jax.grad(lambda x, f=f: jnp.sum(f(x))))
            t_r, c_r, g_r = time_jax(rev, x, repeats=reps)
            row.update(
                reverse_s=t_r,
                reverse_ratio=t_r / t_f,
                reverse_compile_s=c_r,
                reverse_vs_forward_mode_rel=max_rel_diff(g_r, g),
            )
        else:
            # not measured: vmap of the scalar expm solve at n = 1000 hung (idle, no CPU) in the second
            # call on this machine; reverse mode through the batched closed form needs ~36 GB
            row.update(
                reverse_s=None, reverse_ratio=None, reverse_note="not measured (see the comment in gradient_costs)"
            )
        # central differences on three elements: the derivative is right, not just fast
        h = 1e-6 * np.maximum(np.abs(np.asarray(x[:3])), 1.0)
        xp, xm = np.asarray(x).copy(), np.asarray(x).copy()
        xp[:3] += h
        xm[:3] -= h
        fd = (np.asarray(fwd(jnp.asarray(xp)))[:3] - np.asarray(fwd(jnp.asarray(xm)))[:3]) / (2 * h)
        row["grad_vs_central_fd_rel"] = max_rel_diff(np.asarray(g)[:3], fd)
        out.append(row)
        print(
            f"gradient {scene}: forward {t_f * 1e3:.3f} ms, jvp {t_g * 1e3:.3f} ms (ratio {row['ratio']:.2f}), "
            f"reverse ratio {row['reverse_ratio']}, vs FD {row['grad_vs_central_fd_rel']:.1e}",
            flush=True,
        )
    for scene, file, keys in (("shaping", "shaping.json", None), ("pid", "fourbar.json", "gradient")):
        path = RESULTS / file
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            out.append({"scene": scene, "source": f"{file} missing", "ratio": None})
            continue
        if keys is None:
            for h in data.get("headline", []):
                if h["what"].startswith("gradient / forward"):
                    out.append(
                        {
                            "scene": scene,
                            "what": f"H: {h['what']}",
                            "ratio": h["value"],
                            "target": h.get("target"),
                            "source": f"benchmarks/results/{file}",
                            "quick_run": data.get("quick"),
                        }
                    )
        else:
            gr = data.get(keys, {})
            for h in data.get("headline", []):
                if h["what"].startswith("gradient / forward"):
                    out.append(
                        {
                            "scene": scene,
                            "what": f"chi: {h['what']}",
                            "ratio": h["value"],
                            "target": h.get("target"),
                            "source": f"benchmarks/results/{file}",
                            "quick_run": data.get("quick"),
                            "forward_s": gr.get("forward_s"),
                            "grad_s": gr.get("grad_s"),
                        }
                    )
    return out


def _fmt_us(us: float) -> str:
    return f"{us:.3g} us" if us >= 0.01 else f"{us * 1e3:.3g} ns"


def main(quick: bool) -> None:
    t_start = time.perf_counter()
    budget = 25.0 if quick else 210.0
    # quick: the reference check's batch of 3 alone (its programs, compiled for the check, are timed again)
    sizes = (3,) if quick else (100, 1000, 10**4, 10**5)
    rows = []
    scenes = ("startup", "shaping", "runout", "span_freqs", "pid")  # the slow one last
    for i, scene in enumerate(scenes):
        # the PID sweep gets what is left; the others a share, so one slow scene cannot eat the rest
        end = t_start + budget if scene == "pid" else t_start + budget * (i + 1) / (len(scenes) + 2)
        rows += measure_scene(scene, sizes, quick, end)
    grads = gradient_costs(quick)

    # one README row per scene (largest batch); the per-size rows and derivative costs are in the JSON
    headline = []
    for scene in scenes:
        sel = [r for r in rows if r["name"] == scene]
        big = sel[-1]
        mib = (big["output_bytes"] + 1024 * max(big["peak_rss_growth_kib"], 0)) / 2**20
        headline.append(
            {
                "what": f"throughput {scene}, batch {big['batch']} "
                f"({_fmt_us(big['per_element_us'])} per element, {mib:.0f} MiB)",
                "value": big["elements_per_s"],
                "unit": "1/s",
                "target": None,
            }
        )
    for g in grads:
        if g.get("ratio") is not None and g["source"] == "measured here":
            headline.append(
                {
                    "what": f"{g['scene']}: derivative / forward time, batch {g['batch']}, forward mode",
                    "value": g["ratio"],
                    "unit": "x",
                    "target": None,
                }
            )
    wall = time.perf_counter() - t_start
    extra = {
        "gradient_over_forward": grads,
        "sizes": list(sizes),
        "max_run_s": MAX_RUN_S,
        "wall_s": wall,
        "notes": (
            "compile_s = first call (compile + one run) minus the median run; peak_rss_growth_kib = "
            "peak RSS during the measurement minus the RSS before it (peak reset per size via "
            "/proc/self/clear_refs when allowed); device_peak_bytes is null where the backend "
            "reports no memory stats (CPU)."
        ),
    }
    path = write_results("throughput", rows, headline, quick, extra)
    print(f"wrote {path} ({wall:.1f} s)")
    plot(rows, scenes)


def plot(rows, scenes):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {
        "startup": "start-up gamma sweep (501 pts, closed form)",
        "shaping": "shaping H(exponents)",
        "pid": "PID gains -> chi (diffrax)",
        "runout": "run-out response (64 modes)",
        "span_freqs": "span natural frequencies (3 modes)",
    }
    fig, ax = plt.subplots(figsize=(7.5, 6), constrained_layout=True)
    for scene in scenes:
        sel = [r for r in rows if r["name"] == scene]
        ax.loglog([r["batch"] for r in sel], [r["elements_per_s"] for r in sel], "o-", label=labels[scene])
    ax.set_xlabel("batch size")
    ax.set_ylabel("elements per second (after compilation)")
    ax.set_title(f"jaxbelt: throughput of batched sweeps ({jax.default_backend()})")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    save_figure(fig, RESULTS / "throughput.png", dpi=120)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    main(ap.parse_args().quick)
