"""Never beaten at equal terms: the minimax design against *every* classic shaper at that shaper's own time and peaks.

`benchmarks/shaping_axis.py` compares with the best shaper of each axis (the longest). This script takes each of
Klipper's six shapers (ZV, MZV, ZVD, EI, 2-hump EI, 3-hump EI) on the held-out axes of that benchmark, at the
shaper's own shortest move time, and designs the minimax command at exactly that time with the shaper's own peak
velocity and acceleration as its limits, both command spaces: the smooth default (continuous acceleration) and the
steps (`smooth=False`, acceleration that may jump, as a shaped trapezoid's does). Every residual is the worst over
±20 % of every mode in % of one reference per axis (the unshaped time-optimal move at the user's limits).
Target: the steps design leaves no more than any shaper (ratio <= 1) on every axis and shaper.

With `--jerk J` [m/s³] the same on the single-mode named axes under a jerk limit: the shapers on the S-curve with
|jerk| <= J, and the minimax designs with each shaper's own peak jerk as a limit too, the design "with steps" then
being the ramps (a jerk constant on each interval that may jump, as a shaped S-curve's does).

Writes `benchmarks/results/shaping_every_shaper.json` (with `--jerk`: `shaping_every_shaper_jerk.json`). Run:
`python benchmarks/shaping_every_shaper.py [--jerk 20]`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from _common import write_results  # noqa: E402
from shaping_axis import A_MAX, CLASSIC, NAMED_AXES, V_MAX, U, on_shaper_terms, worst_against  # noqa: E402

import jaxbelt as jb  # noqa: E402


def every_shaper(label, f, z, d, shapers=CLASSIC, j_max=None):
    axis = jb.ModalAxis(f, z)
    own = jb.design_move(axis, d, None, v_max=V_MAX, a_max=A_MAX, j_max=j_max, uncertainty=U, include=shapers)
    ref = own.reference_m
    out = []
    for row in own.table:
        if not row.ok:
            continue
        cells = dict(axis=label, shaper=row.name, time=row.move_time, shaper_worst=row.worst_percent)
        if j_max is not None:
            cells["j_max"] = float(j_max)
        for smooth in (True, False):
            plan = on_shaper_terms(axis, d, row, smooth, jerk=j_max is not None)
            mm = plan.candidate("minimax")
            key = "smooth" if smooth else "steps"
            cells[key + "_worst"] = worst_against(axis, mm.command, ref) if mm.command is not None else float("nan")
            cells[key + "_ok"] = bool(mm.ok)
            cells[key + "_ratio"] = cells[key + "_worst"] / row.worst_percent
        out.append(cells)
        print(
            f"{label:28s} {row.name:10s} {row.move_time:.3f} s: shaper {row.worst_percent:.3g} %, smooth "
            f"{cells['smooth_worst']:.3g} % (x{cells['smooth_ratio']:.3g}), steps {cells['steps_worst']:.3g} % "
            f"(x{cells['steps_ratio']:.3g})",
            flush=True,
        )
    return out


def headline_of(rows):
    """The headline numbers of a run's rows (a smooth design that cannot move the distance within the shaper's
    time and peaks is counted, not compared)."""
    steps = np.array([r["steps_ratio"] for r in rows])
    smooth = np.array([r["smooth_ratio"] for r in rows])
    return [
        dict(what="design with jumps (steps; with a jerk limit, ramps) / shaper, equal time and peaks (max over axes and shapers)", value=float(np.nanmax(steps)),
             unit="x", target="<= 1"),
        dict(what="smooth design / shaper, equal time and peaks (max over the pairs where it is feasible)",
             value=float(np.nanmax(smooth)), unit="x", target=None),
        dict(what="pairs (axis, shaper) where the smooth design leaves more than the shaper",
             value=int(np.sum(smooth > 1)), unit="", target=None),
        dict(what="pairs where the smooth design cannot move the distance within the shaper's time and peaks",
             value=int(np.sum(~np.isfinite(smooth))), unit="", target=None),
        dict(what="pairs (axis, shaper) compared", value=len(rows), unit="", target=None),
    ]  # fmt: skip


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one axis, two shapers (CI size)")
    ap.add_argument("--headline", action="store_true", help="only recompute the headline from the last run's rows")
    ap.add_argument("--jerk", type=float, default=None, help="a jerk limit [m/s^3]: the single-mode axes, S-curves")
    args = ap.parse_args(argv)
    name = "shaping_every_shaper" if args.jerk is None else "shaping_every_shaper_jerk"
    if args.headline:
        import json

        from _common import results_dir

        from jaxbelt._io import write_text

        path = results_dir(False) / f"{name}.json"
        data = json.loads(path.read_text())
        data["headline"] = headline_of(data["rows"])
        write_text(path, json.dumps(data, indent=2, default=float))
        return
    t0 = time.perf_counter()
    rows = []
    axes = NAMED_AXES[:1] if args.quick else NAMED_AXES[:3]  # the 10-mode axis has no buildable shaper
    if args.jerk is not None:
        axes = [a for a in axes if len(a[1]) == 1]
    for label, f, z, d in axes:
        shapers = ("ZV", "EI") if args.quick else CLASSIC
        rows += every_shaper(label, np.asarray(f), np.asarray(z), d, shapers, j_max=args.jerk)
    headline = headline_of(rows)
    write_results(name, rows, headline, quick=args.quick, extra=dict(wall_s=time.perf_counter() - t0, j_max=args.jerk))
    for h in headline:
        print(f"{h['what']}: {h['value']:.4g} {h['unit']} (target {h['target']})")


if __name__ == "__main__":
    main()
