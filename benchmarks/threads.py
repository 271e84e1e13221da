"""BLAS threads in a user's environment: warm entry points with `OPENBLAS_NUM_THREADS` unset, cores idle and busy.

jaxlib's CPU linear algebra and numpy call OpenBLAS, whose spinning worker threads took the cores from the work
when the cores were busy (a warm `design_move` 17x slower). jaxbelt now limits BLAS to one thread inside its own
calls (`jaxbelt._threads`). This benchmark measures, each in a fresh process, the warm calls of `design_move`
(2 modes) and `tune_pid` (3 steps) under three settings:

- `user`: nothing set (what a library user has);
- `OPENBLAS_NUM_THREADS=1`: the variable jaxbelt's scripts used to set;
- `limit off`: `JAXBELT_BLAS_THREADS=0`, jaxbelt's own limit switched off (the behaviour before it);

with the cores idle and with every core busy (one spinning Python process per core). Target: with the cores
busy, `user` <= 2x `OPENBLAS_NUM_THREADS=1` for the warm `design_move`.

Run: `python benchmarks/threads.py [--repeats N] [--quick]`; writes `benchmarks/results/threads.json` and `.png`.
Nothing here sets a thread variable for the processes it measures, except the setting being measured.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _common import machine_info, results_dir  # noqa: E402

PROBE = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
repeats = int(sys.argv[1])
wanted = sys.argv[2].split(",")
axis = jb.ModalAxis(frequencies=[7.3, 18.0], damping_ratios=[0.015, 0.01])
drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
tasks = {
    "design_move": lambda: jb.design_move(axis, distance=0.1, move_time=0.8, v_max=0.3, a_max=1.2, uncertainty=0.2),
    "tune_pid": lambda: jb.tune_pid(drive, pid, t0=0.375, t1=0.5, steps=3, progress=False),
}
out = {}
for name, task in ((k, tasks[k]) for k in wanted):
    task()  # compiles
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        task()
        samples.append(time.perf_counter() - t)
    out[name] = samples
print("RESULT " + json.dumps(out))
"""

SETTINGS = {
    "user": {},
    "OPENBLAS_NUM_THREADS=1": {"OPENBLAS_NUM_THREADS": "1"},
    "limit off": {"JAXBELT_BLAS_THREADS": "0"},
}


def _env(extra: dict) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "JAXBELT_BLAS_THREADS")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


def _busy(n: int):
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


TASKS = ("design_move", "tune_pid")


def measure(setting: str, busy: bool, repeats: int, tasks=TASKS) -> dict:
    spinners = _busy(os.cpu_count() or 1) if busy else []
    try:
        time.sleep(0.5 if busy else 0.0)
        run = subprocess.run(
            [sys.executable, "-c", PROBE, str(repeats), ",".join(tasks)],
            capture_output=True,
            text=True,
            env=_env(SETTINGS[setting]),
            timeout=1800,
        )
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    if run.returncode != 0:
        raise RuntimeError(run.stderr[-2000:])
    line = next(ln for ln in run.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="warm calls per task and process (default 5)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="check that the benchmark runs: tune_pid only, cores idle, one repeat, the user's setting alone (one "
        "fresh process; its ratios are NaN); writes into the scratch folder",
    )
    args = parser.parse_args()
    tasks, loads, settings = TASKS, (False, True), tuple(SETTINGS)
    if args.quick:
        args.repeats, tasks, loads, settings = 1, ("tune_pid",), (False,), ("user",)
    rows = []
    for busy in loads:
        for setting in settings:
            samples = measure(setting, busy, args.repeats, tasks)
            for task, s in samples.items():
                row = dict(
                    task=task,
                    setting=setting,
                    cores="busy" if busy else "idle",
                    median_s=float(np.median(s)),
                    min_s=float(np.min(s)),
                    max_s=float(np.max(s)),
                    repeats=len(s),
                )
                rows.append(row)
                print(
                    f"{task:12s} {row['cores']:4s} {setting:24s} {row['median_s']:.3f} s ({row['min_s']:.3f}-{row['max_s']:.3f})"
                )

    def med(task, setting, cores):
        found = [r["median_s"] for r in rows if (r["task"], r["setting"], r["cores"]) == (task, setting, cores)]
        return found[0] if found else float("nan")

    headline = []
    for task in tasks:
        for cores in ("idle", "busy")[: len(loads)]:
            ratio = med(task, "user", cores) / med(task, "OPENBLAS_NUM_THREADS=1", cores)
            before = med(task, "limit off", cores) / med(task, "OPENBLAS_NUM_THREADS=1", cores)
            target = "<= 2" if (task, cores) == ("design_move", "busy") else None
            headline.append(
                dict(
                    what=f"{task} warm, cores {cores}: user / OPENBLAS_NUM_THREADS=1",
                    value=ratio,
                    unit="x",
                    target=target,
                )
            )
            headline.append(
                dict(
                    what=f"{task} warm, cores {cores}: limit off / OPENBLAS_NUM_THREADS=1",
                    value=before,
                    unit="x",
                    target=None,
                )
            )
    out_dir = results_dir(args.quick)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = dict(scene="threads", machine=machine_info(), quick=args.quick, rows=rows, headline=headline)
    (out_dir / "threads.json").write_text(json.dumps(result, indent=2) + "\n")
    _plot(rows, out_dir / "threads.png")
    for h in headline:
        print(f"{h['what']}: {h['value']:.2f}x" + (f" (target {h['target']})" if h["target"] else ""))


def _plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for ax, task in zip(axes, ("design_move", "tune_pid")):
        for k, cores in enumerate(("idle", "busy")):
            for j, setting in enumerate(SETTINGS):
                found = [r for r in rows if (r["task"], r["setting"], r["cores"]) == (task, setting, cores)]
                if not found:  # a quick run measures a part
                    continue
                r = found[0]
                x = k * (len(SETTINGS) + 1) + j
                ax.bar(x, r["median_s"], color=f"C{j}", label=setting if k == 0 else None)
                ax.errorbar(
                    x, r["median_s"], yerr=[[r["median_s"] - r["min_s"]], [r["max_s"] - r["median_s"]]], color="k"
                )
        ax.set_xticks([1, len(SETTINGS) + 2], ["cores idle", "cores busy"])
        ax.set_ylabel("warm call [s]")
        ax.set_title(f"{task} (median, min-max)")
        ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
