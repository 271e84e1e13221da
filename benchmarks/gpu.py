"""GPU (or any backend): the start-up batch against the card's copy rate and memory, the four-bar χ sweep, and the
first and warm calls of `design_move` and `tune_pid`; the same tasks on the CPU beside them.

Runs on whatever JAX's default backend is (`python benchmarks/gpu.py` on a GPU machine; on a CPU-only machine it
measures the CPU alone). Each measurement of device memory runs in a fresh process (a device's peak memory cannot
be reset), and so does each first call. Writes `benchmarks/results/gpu.json` and `.png`.

- **Start-up batch** (`jaxbelt.fast.startup_gamma_batch`, Incerti 2014 closed form): B voltage time constants x
  501 times, the full state (5 states) for B = 10^4, 10^5 and one output (the driven pulley speed) for B = 10^6 (GPU only):
  median run time after compilation, bytes written per second against a device-to-device copy of as many bytes
  (`x + 1` on an array of the output's size: each byte read once and written once), peak device memory
  (`memory_stats()["peak_bytes_in_use"]`, where the backend reports it) and XLA's own account
  (`memory_analysis()`: output + temporaries) against the output's size. Each batch is checked against
  `jb.simulate` on three of its elements.
  Targets: peak device memory <= 1.3x the output of a large batch; write rate >= 30 % of the copy rate.
- **Four-bar exact-χ sweep** (`jb.sweep` of `fluctuation_objective`, Tsit5 rtol 1e-6) at 10^3 and 8192 gain sets.
- **`design_move`** (2 modes) and **`tune_pid`** (3 steps): first call in a fresh process (compilation included,
  no cache) and the warm call after it.

`--quick`: small sizes (the suite's check of this script on a CPU), every section of the default backend in this
process (and those of the CPU beside a GPU in one fresh process).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _common import results_dir  # noqa: E402

PRELUDE = r"""
import json, sys, time
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
def median_time(fn, repeats):
    jax.block_until_ready(fn())
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        samples.append(time.perf_counter() - t)
    return float(np.median(samples)), float(np.min(samples)), float(np.max(samples))
def peak_bytes():
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")
def result(out):
    print("RESULT " + json.dumps(out))
"""

BATCH = (
    PRELUDE
    + r"""
from jaxbelt.fast import startup_gamma_batch
n, one_output, repeats = int(sys.argv[1]), sys.argv[2] == "1", int(sys.argv[3])
model = jb.BeltStartup()
ts = jnp.linspace(0.0, 0.5, 501)
components = (3,) if one_output else None  # one state (the driven pulley speed), or all five
g = jnp.linspace(0.01, 0.1, n)
before = peak_bytes()
f = jax.jit(lambda g: startup_gamma_batch(model, g, ts, components=components))
compiled = f.lower(g).compile()
t0 = time.perf_counter(); y = jax.block_until_ready(compiled(g)); first = time.perf_counter() - t0
peak = peak_bytes()
ma = compiled.memory_analysis()
out_bytes = int(y.size * y.dtype.itemsize)
run = median_time(lambda: compiled(g), repeats)
# accuracy: three elements against simulate (the closed form through its public entry point)
check = []
for k in (0, n // 2, n - 1):
    ref = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, float(g[k])), ts=ts)).ys
    ref = ref[:, list(components)] if components else ref
    check.append(float(jnp.max(jnp.abs(y[k] - ref)) / jnp.max(jnp.abs(ref))))
del y
x = jnp.zeros((out_bytes // 8,), jnp.float64)
copy = jax.jit(lambda x: x + 1.0).lower(x).compile()
copy_t = median_time(lambda: copy(x), repeats)
result(dict(n=n, one_output=one_output, output_bytes=out_bytes, median_s=run[0], min_s=run[1], max_s=run[2],
            first_run_s=first, write_rate=out_bytes / run[0], copy_rate=out_bytes / copy_t[0],
            peak_bytes=peak, peak_before=before,
            xla_output_bytes=int(getattr(ma, "output_size_in_bytes", 0) or 0),
            xla_temp_bytes=int(getattr(ma, "temp_size_in_bytes", 0) or 0), rel_error=max(check)))
"""
)

SWEEP = (
    PRELUDE
    + r"""
n, repeats = int(sys.argv[1]), int(sys.argv[2])
drive = jb.FourBarDrive()
base = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
rng = np.random.default_rng(0)
gains = jnp.asarray(np.array([80.0, 32.0, 0.015]) * np.exp(rng.uniform(-0.7, 0.7, size=(n, 3))))
chi = lambda g: jb.fluctuation_objective(drive, base.with_gains(g), 0.375, 0.5, smooth=False, rtol=1e-6, atol=1e-6)
t0 = time.perf_counter(); first = jax.block_until_ready(jb.sweep(chi, gains)); first_s = time.perf_counter() - t0
run = median_time(lambda: jb.sweep(chi, gains), repeats)
ref = [float(jb.fluctuation_objective(drive, base.with_gains(gains[k]), 0.375, 0.5, smooth=False, rtol=1e-10,
                                      atol=1e-10)) for k in (0, n - 1)]
err = max(abs(float(first[0]) - ref[0]), abs(float(first[-1]) - ref[1]))
result(dict(n=n, first_s=first_s, median_s=run[0], min_s=run[1], max_s=run[2], chi_abs_error=err))
"""
)

CALLS = (
    PRELUDE
    + r"""
task, repeats = sys.argv[1], int(sys.argv[2])
if task == "design_move":
    axis = jb.ModalAxis(frequencies=[7.3, 18.0], damping_ratios=[0.015, 0.01])
    call = lambda: jb.design_move(axis, distance=0.1, move_time=0.8, v_max=0.3, a_max=1.2, uncertainty=0.2)
else:
    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    call = lambda: jb.tune_pid(drive, pid, t0=0.375, t1=0.5, steps=3, progress=False)
t0 = time.perf_counter(); call(); first = time.perf_counter() - t0
samples = []
for _ in range(repeats):
    t = time.perf_counter(); call(); samples.append(time.perf_counter() - t)
result(dict(task=task, first_s=first, warm_s=float(np.median(samples)), warm_min_s=float(np.min(samples)),
            warm_max_s=float(np.max(samples))))
"""
)


def _run(code: str, *args, platform: str | None = None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
    if platform:
        env["JAX_PLATFORMS"] = platform
    run = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=env)
    if run.returncode != 0:
        return {"error": run.stderr.strip().splitlines()[-1] if run.stderr.strip() else f"exit {run.returncode}"}
    return json.loads(next(ln for ln in run.stdout.splitlines() if ln.startswith("RESULT "))[len("RESULT ") :])


INFO = (
    PRELUDE + "d = jax.devices()[0]; result(dict(backend=jax.default_backend(), device=d.device_kind, "
    "count=jax.device_count(), jax=jax.__version__))"
)

# --quick: the sections one after the other in one process (a check of the script pays one start of Python, JAX and
# jaxbelt instead of three); each section's code runs as it would alone, with its own arguments
SEQUENCE = r"""
import json, sys
for code, args in json.loads(sys.argv[1]):
    sys.argv = ["-c", *args]
    try:
        exec(compile(code, "<gpu benchmark section>", "exec"), {"__name__": "__main__"})
    except Exception as e:
        print("RESULT " + json.dumps({"error": f"{type(e).__name__}: {e}"}), flush=True)
"""


def _backend_info(platform: str | None) -> dict:
    return _run(INFO, platform=platform)


def _run_in_one_process(jobs: list[tuple[str, tuple]], platform: str | None) -> list[dict]:
    """Run each (code, args) of `jobs` in turn in one fresh process; one result per job (an error where a job
    printed none)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
    if platform:
        env["JAX_PLATFORMS"] = platform
    spec = json.dumps([(code, [str(a) for a in args]) for code, args in jobs])
    run = subprocess.run([sys.executable, "-c", SEQUENCE, spec], capture_output=True, text=True, env=env)
    found = [json.loads(ln[len("RESULT ") :]) for ln in run.stdout.splitlines() if ln.startswith("RESULT ")]
    tail = run.stderr.strip().splitlines()[-1] if run.stderr.strip() else f"exit {run.returncode}"
    return found + [{"error": tail}] * (len(jobs) - len(found))


def _run_here(jobs: list[tuple[str, tuple]]) -> list[dict]:
    """Run each (code, args) of `jobs` in turn in this process (a quick run on the default backend: no fresh process);
    one result per job. A job that raises or prints no result fails the run (a quick run checks the script)."""
    import contextlib
    import io

    found, argv = [], sys.argv
    for code, args in jobs:
        buf = io.StringIO()
        try:
            sys.argv = ["-c", *map(str, args)]
            with contextlib.redirect_stdout(buf):
                exec(compile(code, "<gpu benchmark section>", "exec"), {"__name__": "__main__"})
        finally:
            sys.argv = argv
        lines = [ln for ln in buf.getvalue().splitlines() if ln.startswith("RESULT ")]
        if not lines:
            raise RuntimeError(f"gpu: a section printed no result; its output: {buf.getvalue()[-2000:]}")
        found.append(json.loads(lines[-1][len("RESULT ") :]))
    return found


def section(platform: str | None, quick: bool, repeats: int) -> dict:
    if quick:  # one process: the backend, a batch of 1000 (first, so that its memory peak is its own), a sweep of 64
        batches, sweeps = [(1000, False)], [64]
        jobs = [(INFO, ()), (BATCH, (1000, 0, repeats)), (SWEEP, (64, repeats))]
        # the default backend in this process (a quick run's check of the code; its memory peaks are not its own),
        # another backend in a fresh one
        info, batch, sweep = _run_here(jobs) if platform is None else _run_in_one_process(jobs, platform)
        done = {("batch", 1000): batch, ("sweep", 64): sweep}
    else:
        info, done = _backend_info(platform), {}
        if info.get("backend") not in (None, "cpu"):
            batches, sweeps = [(10_000, False), (100_000, False), (1_000_000, True)], [1000, 8192]
        else:  # a CPU's memory: 10^6 trajectories of one output would be 4 GB, of the full state 20 GB
            batches, sweeps = [(10_000, False), (100_000, False)], [1000]
    out = dict(info, batches=[], sweeps=[], calls=[])
    for n, one in batches:
        r = done.get(("batch", n)) or _run(BATCH, n, int(one), repeats, platform=platform)
        out["batches"].append(dict(r, n=n, one_output=one))
        if "error" not in r:
            peak = r["peak_bytes"]
            print(
                f"[{info.get('backend')}] batch {n} x 501 {'one output' if one else 'full state'}: "
                f"{1e3 * r['median_s']:.2f} ms, {r['write_rate'] / 1e9:.1f} GB/s written "
                f"({100 * r['write_rate'] / r['copy_rate']:.0f} % of copy), XLA peak "
                f"{(r['xla_output_bytes'] + r['xla_temp_bytes']) / r['output_bytes']:.2f}x output"
                + (f", device peak {peak / r['output_bytes']:.2f}x" if peak else ""),
                flush=True,
            )
        else:
            print(f"[{info.get('backend')}] batch {n}: {r['error']}", flush=True)
    for n in sweeps:
        r = done.get(("sweep", n)) or _run(SWEEP, n, repeats, platform=platform)
        out["sweeps"].append(dict(r, n=n))
        print(f"[{info.get('backend')}] four-bar chi sweep {n}: {r}", flush=True)
    if not quick:
        for task in ("design_move", "tune_pid"):
            r = _run(CALLS, task, repeats, platform=platform)
            out["calls"].append(dict(r, task=task))
            print(f"[{info.get('backend')}] {task}: {r}", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (a check of the script)")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs of each call (default 5; quick: 1)")
    args = parser.parse_args()
    if args.repeats is None:
        args.repeats = 1 if args.quick else 5
    default = section(None, args.quick, args.repeats)
    sections = {default.get("backend", "?"): default}
    if default.get("backend") not in (None, "cpu"):
        sections["cpu"] = section("cpu", args.quick, args.repeats)
    targets = []
    for name, s in sections.items():
        large = [b for b in s["batches"] if "error" not in b]
        if large:
            b = large[-1]
            peak = b["peak_bytes"] if b.get("peak_bytes") else b["xla_output_bytes"] + b["xla_temp_bytes"]
            targets.append(
                dict(
                    backend=name,
                    what=f"peak memory / output, batch {b['n']}",
                    value=peak / b["output_bytes"],
                    target="<= 1.3",
                    source="device" if b.get("peak_bytes") else "XLA memory_analysis",
                )
            )
            targets.append(
                dict(
                    backend=name,
                    what=f"write rate / copy rate, batch {b['n']}",
                    value=b["write_rate"] / b["copy_rate"],
                    target=">= 0.3",
                )
            )
    result = dict(scene="gpu", quick=args.quick, sections=sections, targets=targets, when=time.strftime("%Y-%m-%d"))
    out_dir = results_dir(args.quick)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "gpu.json").write_text(json.dumps(result, indent=2) + "\n")
    _plot(sections, out_dir / "gpu.png")
    for t in targets:
        print(f"[{t['backend']}] {t['what']}: {t['value']:.2f} (target {t['target']})")


def _plot(sections: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for name, s in sections.items():
        ok = [b for b in s["batches"] if "error" not in b]
        if not ok:
            continue
        n = [b["n"] for b in ok]
        axes[0].loglog(n, [b["write_rate"] / 1e9 for b in ok], "o-", label=f"{name}: start-up batch")
        axes[0].loglog(n, [b["copy_rate"] / 1e9 for b in ok], "k--", alpha=0.5, label=f"{name}: copy of as many bytes")
        axes[1].semilogx(
            n,
            [(b["peak_bytes"] or b["xla_output_bytes"] + b["xla_temp_bytes"]) / b["output_bytes"] for b in ok],
            "o-",
            label=name,
        )
    axes[0].set_xlabel("trajectories B (x 501 times)")
    axes[0].set_ylabel("bytes written [GB/s]")
    axes[0].legend(fontsize=8)
    axes[1].axhline(1.3, color="r", lw=0.8, label="target 1.3x")
    axes[1].set_xlabel("trajectories B")
    axes[1].set_ylabel("peak memory / output")
    axes[1].legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
