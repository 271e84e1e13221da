"""Benchmark of `jb.explore`: from a slider's new value to the redrawn figure, per scene.

For each scene an explorer is built (its first computation, compilation included, timed apart), one slider is
moved once (the first change, timed apart), then 20 more times across its range; each change is timed from
`Explorer.update(...)` to the end of `figure.canvas.draw()` (a full Agg rendering of the figure). The median of
the 20 is the headline; the XLA compilations during them are counted (none expected: a new value reuses the
compiled programs). A second column times the same changes with the notebook view built (`Explorer.widget`,
inline backend): `update` then renders the figure and sends it as a PNG.

Targets (2 CPU cores): <= 100 ms for the fast scenes (start-up, four-bar chi, H with one L-BFGS step, span
frequencies); <= 1 s warm for the long ones (a 1-mode `design_move`, a 3-harmonic `response_curve`), whose
computation runs in the explorer's background thread (`update` waits for it). The `design_move` scene is measured
twice: moving a damping ratio (the problem's sizes stay: warm), and moving the frequency, which crosses the design's
problem sizes (its frequency grid grows with f u T): those changes compile, and are counted.

Run: `python benchmarks/explore.py [--quick]`; writes `benchmarks/results/explore.json` and `.png`. Nothing here
sets a thread variable (jaxbelt limits BLAS threads around its own calls). The load average of the machine at the
start and end is recorded: the figures are wall times on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.monitoring  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import results_dir, save_figure, write_results  # noqa: E402

import jaxbelt as jb  # noqa: E402

_COMPILE = "/jax/core/compile/backend_compile_duration"

#: (case, scene, start options, slider, first change, 20 values to move through, target [s])
CASES = [
    ("startup", "startup", {}, "k", 100e3, np.geomspace(60e3, 240e3, 20), 0.1),
    ("fourbar chi", "fourbar", {}, "kp", 70.0, np.linspace(40.0, 120.0, 20), 0.1),
    ("H + one L-BFGS step", "shaping", {}, "gamma0", 3.05, np.linspace(3.0, 3.6, 20), 0.1),
    ("span frequencies", "spans", {}, "tension", 150.0, np.linspace(100.0, 200.0, 20), 0.1),
    ("response_curve (3 harmonics)", "nonlinear", {}, "damping1", 0.0125, np.geomspace(0.008, 0.016, 20), 1.0),
    ("design_move (1 mode), damping", "axis", {}, "zeta1", 0.02, np.geomspace(0.005, 0.05, 20), 1.0),
    ("design_move (1 mode), frequency", "axis", {}, "f1", 7.4, np.linspace(6.0, 9.0, 20), None),
]
QUICK = ("startup", "span frequencies")


class _Compiles:
    def __init__(self):
        self.n = 0
        jax.monitoring.register_event_duration_secs_listener(self._listen)

    def _listen(self, name, duration, **kw):
        if name == _COMPILE:
            self.n += 1


def _changes(ex, slider, values, *, draw: bool, compiles: _Compiles | None = None) -> tuple[list[float], int]:
    """Times [s] of the changes to `values`, and how many of them compiled a program."""
    out, compiling = [], 0
    for v in values:
        n0 = compiles.n if compiles is not None else 0
        t = time.perf_counter()
        ex.update(**{slider: float(v)})
        if draw:
            ex.figure.canvas.draw()
        out.append(time.perf_counter() - t)
        compiling += compiles is not None and compiles.n > n0
    return out, compiling


def measure(case, scene, options, slider, first, values, target, compiles: _Compiles) -> dict:
    t = time.perf_counter()
    ex = jb.explore(scene, **options)
    build_s = time.perf_counter() - t
    t = time.perf_counter()
    ex.update(**{slider: first})
    ex.figure.canvas.draw()
    first_s = time.perf_counter() - t
    n0 = compiles.n
    samples, compiling = _changes(ex, slider, values, draw=True, compiles=compiles)
    n_compiles = compiles.n - n0
    _ = ex.widget  # the notebook view: from now on `update` renders the figure and sends its PNG
    ex.update(**{slider: first})
    view, _ = _changes(ex, slider, values, draw=False)
    ex.close()
    row = dict(
        name=case,
        method=f"explore('{scene}'), slider `{slider}`",
        error=None,
        median_s=float(np.median(samples)),
        min_s=float(np.min(samples)),
        max_s=float(np.max(samples)),
        compile_s=build_s,
        first_change_s=first_s,
        view_median_s=float(np.median(view)),
        repeats=len(samples),
        compiles=n_compiles,
        changes_compiling=int(compiling),
        target_s=target,
        long=bool(ex.scene.long),
    )
    print(
        f"{case:34s} median {1e3 * row['median_s']:7.1f} ms ({1e3 * row['min_s']:.0f}-{1e3 * row['max_s']:.0f}), "
        f"with the PNG view {1e3 * row['view_median_s']:7.1f} ms, {n_compiles} compilations in {compiling} changes; "
        f"build {build_s:.1f} s, first change {1e3 * first_s:.0f} ms"
    )
    return row


def _plot(rows, path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.8), layout="constrained")
    ax = fig.subplots()
    y = np.arange(len(rows))
    ax.barh(y - 0.2, [1e3 * r["median_s"] for r in rows], 0.4, label="update + canvas.draw()")
    ax.barh(y + 0.2, [1e3 * r["view_median_s"] for r in rows], 0.4, label="update with the PNG view")
    for k, r in enumerate(rows):
        if r["target_s"]:
            ax.plot([1e3 * r["target_s"]] * 2, [k - 0.45, k + 0.45], color="k", lw=1.5)
    ax.set_yticks(y, [r["name"] for r in rows])
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("slider change to redrawn figure [ms] (median of 20; black: target)")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    save_figure(fig, path, dpi=110)


def main(quick: bool) -> None:
    load_start = os.getloadavg()
    compiles = _Compiles()
    rows = []
    for case in CASES:
        if quick and case[0] not in QUICK:
            continue
        name, scene, options, slider, first, values, target = case
        rows.append(measure(name, scene, options, slider, first, values[:5] if quick else values, target, compiles))
    headline = [
        dict(
            what=f"{r['name']}: slider change to redrawn figure (median of {r['repeats']})",
            value=1e3 * r["median_s"],
            unit="ms",
            target=None if r["target_s"] is None else f"<= {1e3 * r['target_s']:g} ms",
        )
        for r in rows
    ]
    extra = dict(load_average=dict(start=list(load_start), end=list(os.getloadavg())))
    path = write_results("explore", rows, headline, quick, extra)
    _plot(rows, results_dir(quick) / "explore.png")
    print(f"wrote {path}; load average {load_start[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="CI-sized run: two fast scenes, 5 changes each")
    main(ap.parse_args().quick)
