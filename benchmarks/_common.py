"""Shared timing and result-writing helpers for jaxbelt benchmarks.

Every benchmark writes `benchmarks/results/<scene>.json` with this schema:

    {"scene": str, "machine": {...}, "quick": bool,
     "rows": [{"name": str, "method": str, "error": float | None, "median_s": float,
               "compile_s": float | None, "repeats": int, ...extra}],
     "headline": [{"what": str, "value": float, "unit": str, "target": str | None}]}

`rows` are the work-precision points (error against a tight reference, median run time after
compilation); `headline` holds the few numbers the README table shows. Every file is written
atomically (a temporary file beside it, then renamed): a run that fails leaves the previous results whole.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import jax
import numpy as np

from jaxbelt._io import save_figure as save_figure  # every figure written atomically
from jaxbelt._io import write_text

COMMITTED = Path(__file__).resolve().parent / "results"
#: Scratch folder of `run_all.py --quick` (git-ignored): quick figures never overwrite the committed ones.
QUICK_RESULTS = COMMITTED / "quick"
#: Where JSON and PNG files go: `$JAXBELT_BENCH_OUT` when set (run_all sets it), else `results/`.
RESULTS = Path(os.environ["JAXBELT_BENCH_OUT"]) if os.environ.get("JAXBELT_BENCH_OUT") else COMMITTED


def results_dir(quick: bool = False) -> Path:
    """Where a benchmark writes: `$JAXBELT_BENCH_OUT` if set (run_all sets it), else `results/quick/`
    for a quick run and `results/` for a full one."""
    if os.environ.get("JAXBELT_BENCH_OUT"):
        return RESULTS
    return QUICK_RESULTS if quick else COMMITTED


def block(x):
    return jax.tree_util.tree_map(lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x)


def time_jax(fn, *args, repeats: int = 7, min_time: float = 0.05):
    """Compile time and median run time [s] of a jitted callable.

    The first call (compile + run) is timed apart; then `repeats` timings, each the mean over
    enough inner calls to last at least `min_time`, and their median is returned.
    Returns (median_s, compile_s, output).
    """
    t = time.perf_counter()
    out = block(fn(*args))
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    block(fn(*args))
    once = max(time.perf_counter() - t, 1e-7)
    inner = max(1, int(min_time / once))
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(inner):
            block(fn(*args))
        samples.append((time.perf_counter() - t) / inner)
    return float(np.median(samples)), float(compile_s), out


def time_py(fn, *args, repeats: int = 5, min_time: float = 0.0, warm_up: bool = True):
    """Median wall time [s] of a plain Python callable (e.g. scipy); returns (median_s, output). One call before the
    timed ones unless `warm_up` is False (a quick run's check of a slow reference)."""
    out = fn(*args) if warm_up else None
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        inner = 0
        while True:
            out = fn(*args)
            inner += 1
            if time.perf_counter() - t >= min_time:
                break
        samples.append((time.perf_counter() - t) / inner)
    return float(np.median(samples)), out


def machine_info() -> dict:
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        # the environment the figures were measured in: the thread variables a user may or may not set (jaxbelt
        # sets none), and how busy the machine was as the results were written (1-minute load average)
        "thread_env": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")},
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def write_results(scene: str, rows: list, headline: list, quick: bool, extra: dict | None = None) -> Path:
    out = results_dir(quick)
    out.mkdir(parents=True, exist_ok=True)
    data = {"scene": scene, "machine": machine_info(), "quick": bool(quick), "rows": rows, "headline": headline}
    if extra:
        data.update(extra)
    path = out / f"{scene}.json"
    write_text(path, json.dumps(data, indent=2, default=float))  # atomically: a failed run keeps the last results
    return path


def rel_error(x, ref) -> float:
    """max |x - ref| / max |ref| over all entries (per-column max taken, then the worst column)."""
    x = np.asarray(x, dtype=float)
    ref = np.asarray(ref, dtype=float)
    if ref.ndim >= 2:
        scale = np.max(np.abs(ref), axis=tuple(range(ref.ndim - 1)))
        scale = np.where(scale > 0, scale, 1.0)
        return float(np.max(np.max(np.abs(x - ref), axis=tuple(range(ref.ndim - 1))) / scale))
    scale = np.max(np.abs(ref)) or 1.0
    return float(np.max(np.abs(x - ref)) / scale)
