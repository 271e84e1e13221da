"""Never beaten at equal terms: the minimax design against *every* classic shaper at that shaper's own time and peaks.

`benchmarks/shaping_axis.py` compares with the best shaper of each axis (the longest). This script takes each of
Klipper's six shapers (ZV, MZV, ZVD, EI, 2-hump EI, 3-hump EI) on the held-out axes of that benchmark, at the
shaper's own shortest move time, and designs the minimax command at exactly that time with the shaper's own peak
velocity and acceleration as its limits, both command spaces: the smooth one (`smooth=True`, continuous
acceleration) and the steps (`smooth=False`, acceleration that may jump, as a shaped trapezoid's does), and what a
user gets by default (`smooth="auto"`, the shaper in the same table: the smooth design, plus the one with jumps where
the shaper leaves no more; the better minimax row counts). Every residual is the worst over ±20 % of every mode in %
of one reference per axis (the unshaped time-optimal move at the user's limits).
Target: the steps design and the default leave no more than any shaper (ratio <= 1) on every axis and shaper.

With `--drawn` also on the 12 axes that `benchmarks/shaping_axis.py` draws (1-3 modes, 1-20 Hz; its table's
rows), so every axis of the shaping benchmarks is compared with every shaper that fits its move.

With `--jerk J` [m/s³] the same on the single-mode named axes under a jerk limit: the shapers on the S-curve with
|jerk| <= J, and the minimax designs with each shaper's own peak jerk as a limit too, the design "with steps" then
being the ramps (a jerk constant on each interval that may jump, as a shaped S-curve's does).

With `--damping` the damping ratio is unknown, as Klipper assumes by default: each of Klipper's six shapers is
designed at damping ratio 0.1 (Klipper's default `damping_ratio`) at its own shortest time, and the minimax design
`design_move(..., damping="unknown")` at that time with the shaper's own peaks as its limits (smooth and steps, as
above); all are judged on
the band ±20 % times 25 damping ratios (geometric) of [0.01, 0.1], each against the unshaped time-optimal move
at that damping (`jb.residual_curve` on that dense grid, not the design's 5 samples). Records the ratio
minimax / shaper and the wall time of each `design_move` call (the first on an axis includes its compilation).

With `--certify` the continuous certificate on the named single-mode axes, at ZV's and EI's own time and peaks:
the design with jumps (`smooth=False`) as `design_move` makes it, and again with `certify_rtol=0.05` (refined until
the rigorous lower bound on what any command can leave is within 5 % of its worst, or 1024 steps); each against an
independent LP solved by scipy's HiGHS over piecewise-constant accelerations on 4x the design's steps (the design's
frequencies and cuts, exact limits): the bound must lie below HiGHS's value, and the design within 5 % of it (or,
near a zero optimum, within `CERTIFY_ATOL` = 0.01 % of the unshaped move's residual, absolute). With `--certify
--drawn` also every other axis of the shaping benchmarks (the 6-mode one and the 12 drawn) at ZV's and EI's terms.

Writes `benchmarks/results/shaping_every_shaper.json` (with `--jerk`: `shaping_every_shaper_jerk.json`; with
`--damping`: `shaping_every_shaper_damping.json`; with `--certify`: `shaping_every_shaper_certify.json`). Run:
`python benchmarks/shaping_every_shaper.py [--jerk 20 | --damping | --certify [--drawn]]` (`--certify` takes about
15 minutes on 2 cores, HiGHS on 3072 steps takes minutes; `--certify --drawn` about 52 minutes).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))  # the independent references of the test suite (HiGHS's LP)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from _common import write_results  # noqa: E402
from shaping_axis import A_MAX, CLASSIC, NAMED_AXES, V_MAX, D, U, draw_axes, on_shaper_terms, worst_against  # noqa: E402

import jaxbelt as jb  # noqa: E402
from jaxbelt.shaping.plan import CERTIFY_ATOL  # noqa: E402


def _label(f, z) -> str:
    """An axis' label as the shaping tables write it: frequency [Hz] (damping ratio) of each mode."""
    return ", ".join(f"{x:.2f} ({y:.3f})" for x, y in zip(f, z, strict=True))


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
            cells[key + "_worst"] = worst_against(axis, plan, "minimax", ref) if mm.command is not None else math.nan
            cells[key + "_ok"] = bool(mm.ok)
            cells[key + "_ratio"] = cells[key + "_worst"] / row.worst_percent
        plan = jb.design_move(
            axis, d, row.move_time, v_max=row.peak_v, a_max=row.peak_a, j_max=row.peak_j if j_max is not None else None,
            uncertainty=U, include=("minimax", row.name),
        )  # fmt: skip
        default_cells(cells, plan, lambda p, name: worst_against(axis, p, name, ref), row.worst_percent)
        out.append(cells)
        print(
            f"{label:28s} {row.name:10s} {row.move_time:.3f} s: shaper {row.worst_percent:.3g} %, smooth "
            f"{cells['smooth_worst']:.3g} % (x{cells['smooth_ratio']:.3g}), steps {cells['steps_worst']:.3g} % "
            f"(x{cells['steps_ratio']:.3g}), default {cells['default_worst']:.3g} % (x{cells['default_ratio']:.3g}, "
            f"{cells['default_row']})",
            flush=True,
        )
    return out


def default_cells(cells, plan, measure, shaper_worst):
    """The default `design_move` (`smooth="auto"`, the shaper in the table at its own time and peaks): the minimax
    row a user takes (the better of "minimax" and, where added, "minimax (jumps)"), measured by `measure` (a
    candidate's worst residual in %, from the plan and the candidate's name), against the shaper's; into `cells` (`default_*`)."""
    rows = [c for c in plan.table if c.name in ("minimax", "minimax (jumps)") and c.ok]
    best = min(rows, key=lambda c: c.worst_percent) if rows else None
    cells["default_row"] = best.name if best is not None else None
    cells["default_rows"] = [c.name for c in plan.table if c.name.startswith("minimax")]
    cells["default_worst"] = measure(plan, best.name) if best is not None else float("nan")
    cells["default_ratio"] = cells["default_worst"] / shaper_worst


#: the damping range of `--damping` (`design_move(..., damping="unknown")`), the shapers' damping ratio, and the
#: dense grid of damping ratios the residuals are judged on
DAMPING_RANGE = (0.01, 0.1)
SHAPER_DAMPING = 0.1
DENSE_DAMPING = np.geomspace(*DAMPING_RANGE, 25)


def _dense_axis(f):
    """Each mode of frequencies `f` once per damping ratio of `DENSE_DAMPING` (unit gains)."""
    n = DENSE_DAMPING.size
    return jb.ModalAxis(np.repeat(f, n), np.tile(DENSE_DAMPING, len(f)), np.ones(n * len(f)))


def unknown_damping(label, f, d, shapers=CLASSIC):
    """`--damping`: the minimax design for an unknown damping ratio against Klipper's shapers designed at 0.1."""
    f = np.asarray(f, dtype=float)
    dense = _dense_axis(f)
    unshaped = jb.fastest_move(d, V_MAX, A_MAX)
    ref = np.max(np.asarray(jb.residual_curve(dense, unshaped, np.linspace(1 - U, 1 + U, 401))), axis=1)
    at_klipper = jb.ModalAxis(f, np.full(f.size, SHAPER_DAMPING))
    own = jb.design_move(at_klipper, d, None, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=shapers)
    out = []
    for row in own.table:
        if not row.ok:
            continue
        shaper = worst_against(dense, own, row.name, ref)
        cells = dict(axis=label, shaper=row.name, time=row.move_time, shaper_worst=shaper)
        for smooth in (True, False):  # the smooth design and the one with steps, as the default mode
            t0 = time.perf_counter()
            plan = jb.design_move(
                at_klipper,
                d,
                row.move_time,
                v_max=row.peak_v,
                a_max=row.peak_a,
                uncertainty=U,
                include=("minimax",),
                smooth=smooth,
                damping="unknown",
            )
            key = "smooth" if smooth else "steps"
            cells[key + "_design_move_s"] = time.perf_counter() - t0
            mm = plan.candidate("minimax")
            cells[key + "_worst"] = worst_against(dense, plan, "minimax", ref) if mm.command is not None else math.nan
            cells[key + "_stated"] = mm.worst_percent  # over the 5 samples, against the plan's own references
            cells[key + "_ok"] = bool(mm.ok)
            cells[key + "_ratio"] = cells[key + "_worst"] / shaper
        t0 = time.perf_counter()
        plan = jb.design_move(
            at_klipper, d, row.move_time, v_max=row.peak_v, a_max=row.peak_a, uncertainty=U,
            include=("minimax", row.name), damping="unknown",
        )  # fmt: skip
        cells["default_design_move_s"] = time.perf_counter() - t0
        default_cells(cells, plan, lambda p, name: worst_against(dense, p, name, ref), shaper)
        out.append(cells)
        print(
            f"{label:28s} {row.name:10s} {row.move_time:.3f} s: shaper (zeta 0.1) {shaper:.3g} %, smooth "
            f"{cells['smooth_worst']:.3g} % (x{cells['smooth_ratio']:.3g}, {cells['smooth_design_move_s']:.2f} s), "
            f"steps {cells['steps_worst']:.3g} % (x{cells['steps_ratio']:.3g}, {cells['steps_design_move_s']:.2f} s), "
            f"default {cells['default_worst']:.3g} % (x{cells['default_ratio']:.3g}, {cells['default_row']})",
            flush=True,
        )
    return out


def damping_headline(rows):
    steps = np.array([r["steps_ratio"] for r in rows])
    smooth = np.array([r["smooth_ratio"] for r in rows])
    best = {}
    for r in rows:  # per axis: the best shaper over the range, and the minimax designs at that shaper's terms
        if r["axis"] not in best or r["shaper_worst"] < best[r["axis"]]["shaper_worst"]:
            best[r["axis"]] = r
    walls = np.array([r[k + "_design_move_s"] for r in rows for k in ("smooth", "steps")])
    return [
        dict(what="steps design (damping='unknown') / Klipper shaper at zeta 0.1, equal time and peaks, worst over "
             "band x damping 0.01-0.1 (max over axes and shapers)", value=float(np.nanmax(steps)), unit="x",
             target="<= 1"),
        dict(what="default design_move (smooth='auto', damping='unknown') / Klipper shaper at zeta 0.1, equal time "
             "and peaks (max over axes and shapers)", value=float(np.nanmax([r["default_ratio"] for r in rows])),
             unit="x", target="<= 1"),
        dict(what="smooth design (damping='unknown') / Klipper shaper at zeta 0.1 (max over the pairs where it is "
             "feasible)", value=float(np.nanmax(smooth)), unit="x", target=None),
        dict(what="pairs where the smooth design leaves more than the shaper", value=int(np.sum(smooth > 1)), unit="",
             target=None),
        dict(what="pairs where the smooth design cannot move the distance within the shaper's time and peaks",
             value=int(np.sum(~np.isfinite(smooth))), unit="", target=None),
        *(dict(what=f"{a}: best shaper over the range ({r['shaper']}, {r['shaper_worst']:.3g} %) against the smooth "
               f"minimax at its terms ({r['smooth_worst']:.3g} %): ratio", value=r["smooth_ratio"], unit="x",
               target=None) for a, r in best.items()),
        dict(what="design_move(damping='unknown') wall time, median over the calls", value=float(np.median(walls)),
             unit="s", target=None),
        dict(what="pairs (axis, shaper) compared", value=len(rows), unit="", target=None),
    ]  # fmt: skip


def headline_of(rows):
    """The headline numbers of a run's rows (a smooth design that cannot move the distance within the shaper's
    time and peaks is counted, not compared)."""
    steps = np.array([r["steps_ratio"] for r in rows])
    smooth = np.array([r["smooth_ratio"] for r in rows])
    return [
        dict(what="design with jumps (steps; with a jerk limit, ramps) / shaper, equal time and peaks (max over axes and shapers)", value=float(np.nanmax(steps)),
             unit="x", target="<= 1"),
        dict(what="default design_move (smooth='auto': the smooth design, and the one with jumps where a shaper "
             "leaves no more) / shaper, equal time and peaks (max over axes and shapers)",
             value=float(np.nanmax([r["default_ratio"] for r in rows])), unit="x", target="<= 1"),
        dict(what="smooth design / shaper, equal time and peaks (max over the pairs where it is feasible)",
             value=float(np.nanmax(smooth)), unit="x", target=None),
        dict(what="pairs (axis, shaper) where the smooth design leaves more than the shaper",
             value=int(np.sum(smooth > 1)), unit="", target=None),
        dict(what="pairs where the smooth design cannot move the distance within the shaper's time and peaks",
             value=int(np.sum(~np.isfinite(smooth))), unit="", target=None),
        dict(what="pairs (axis, shaper) compared", value=len(rows), unit="", target=None),
    ]  # fmt: skip


#: `--certify`: the relative tolerance, and the (axis label, shaper) pairs
CERTIFY_RTOL = 0.05
CERTIFY_PAIRS = (("2 Hz, ζ 0.08, 2.5 cycles", "ZV"), ("40 Hz, ζ 0.003", "ZV"), ("40 Hz, ζ 0.003", "EI"))


#: `--certify --drawn`: the shapers at whose terms every other axis of the shaping benchmarks is certified
CERTIFY_DRAWN_SHAPERS = ("ZV", "EI")


def certify_rows(drawn: bool = False):
    """`--certify`: per pair, the design with jumps as made and certified, against HiGHS on 4x its steps (with
    `drawn`, also every other axis of the shaping benchmarks at ZV's and EI's terms)."""
    from references import highs_steps_lp

    named = {label: (f, z, d) for label, f, z, d in NAMED_AXES[:3]}
    pairs = list(CERTIFY_PAIRS)
    if drawn:
        named.update({_label(f, z): (f, z, D) for f, z in draw_axes(12)})
        pairs += [(label, s) for label in named for s in CERTIFY_DRAWN_SHAPERS if (label, s) not in pairs]
    out = []
    for label, shaper in pairs:
        f, z, d = named[label]
        axis = jb.ModalAxis(f, z)
        row = jb.design_move(axis, d, None, v_max=V_MAX, a_max=A_MAX, uncertainty=U, include=(shaper,)).table[0]
        if not row.ok:  # the shaper cannot be built on this axis (a firmware fit's damping range)
            print(f"{label:28s} {shaper:4s}: not built ({row.note})", flush=True)
            continue
        cells = dict(axis=label, shaper=shaper, time=row.move_time, shaper_worst=row.worst_percent)
        for key, rtol in (("made", None), ("certified", CERTIFY_RTOL)):
            t0 = time.perf_counter()
            plan = jb.design_move(
                axis, d, row.move_time, v_max=row.peak_v, a_max=row.peak_a, uncertainty=U, include=("minimax",),
                smooth=False, certify_rtol=rtol,
            )  # fmt: skip
            wall = time.perf_counter() - t0
            mm = plan.minimax
            t0 = time.perf_counter()
            highs = highs_steps_lp(mm, 4 * mm.options.n_knots)
            cells.update({
                f"{key}_design_move_s": wall, f"{key}_steps": mm.options.n_knots, f"{key}_cuts": mm.options.n_angles,
                f"{key}_lp_worst": float(mm.worst), f"{key}_bound": plan.continuous_bound,
                f"{key}_highs_4x": highs, f"{key}_highs_s": time.perf_counter() - t0,
                f"{key}_over_highs": float(mm.worst) / highs, f"{key}_bound_below_highs": plan.continuous_bound <= highs + 1e-9,
                f"{key}_within_highs": float(mm.worst) <= max(1.05 * highs, highs + CERTIFY_ATOL),
                f"{key}_note": plan.table[0].note,
            })  # fmt: skip
        out.append(cells)
        print(
            f"{label:28s} {shaper:4s}: made {cells['made_steps']} steps, {cells['made_over_highs']:.4f}x HiGHS(4x); "
            f"certified {cells['certified_steps']} steps, {cells['certified_over_highs']:.4f}x HiGHS(4x), bound "
            f"{cells['certified_bound']:.4g} <= HiGHS {cells['certified_highs_4x']:.4g}: {cells['certified_bound_below_highs']} "
            f"({cells['certified_design_move_s']:.0f} s)",
            flush=True,
        )
    return out


def certify_headline(rows):
    """Relative to HiGHS where its value is above `CERTIFY_ATOL`; near a zero optimum (most axes at an ordinary
    move time) the absolute difference, against that floor."""
    big = [r for r in rows if r["certified_highs_4x"] >= CERTIFY_ATOL]
    small = [r for r in rows if r["certified_highs_4x"] < CERTIFY_ATOL]
    out = []
    if big:
        out += [
            dict(what="design with jumps as design_move makes it / HiGHS on 4x its steps (max over the pairs where HiGHS >= 0.01 %)",
                 value=float(max(r["made_over_highs"] for r in big)), unit="x", target=None),
            dict(what=f"design with jumps, certify_rtol={CERTIFY_RTOL} / HiGHS on 4x its steps (max over the pairs where HiGHS >= 0.01 %)",
                 value=float(max(r["certified_over_highs"] for r in big)), unit="x", target="<= 1.05"),
        ]  # fmt: skip
    if small:
        out.append(
            dict(what=f"design with jumps, certify_rtol={CERTIFY_RTOL}, minus HiGHS on 4x its steps (max over the pairs where HiGHS < 0.01 %)",
                 value=float(max(100 * (r["certified_lp_worst"] - r["certified_highs_4x"]) for r in small)), unit="%",
                 target=f"<= {100 * CERTIFY_ATOL:g}")
        )  # fmt: skip
    return out + [
        dict(what="pairs whose certified design is not within max(5 %, 0.01 % absolute) of HiGHS on 4x its steps",
             value=int(sum(not r["certified_within_highs"] for r in rows)), unit="", target="<= 0"),
        dict(what=f"pairs whose own certificate proved certify_rtol={CERTIFY_RTOL} (or the 0.01 % floor) within the step cap",
             value=int(sum("not within" not in r["certified_note"] for r in rows)), unit="", target=None),
        dict(what="pairs whose continuous bound lies above HiGHS's value (a wrong bound)",
             value=int(sum(not (r["made_bound_below_highs"] and r["certified_bound_below_highs"]) for r in rows)),
             unit="", target="<= 0"),
        dict(what="pairs compared", value=len(rows), unit="", target=None),
    ]  # fmt: skip


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one axis, ZV alone (a check of the script)")
    ap.add_argument("--headline", action="store_true", help="only recompute the headline from the last run's rows")
    ap.add_argument("--jerk", type=float, default=None, help="a jerk limit [m/s^3]: the single-mode axes, S-curves")
    ap.add_argument("--damping", action="store_true", help="unknown damping: shapers at 0.1, judged over 0.01-0.1")
    ap.add_argument("--drawn", action="store_true", help="also the 12 drawn axes of shaping_axis.py (about 20 min)")
    ap.add_argument("--certify", action="store_true", help="the continuous certificate against HiGHS on 4x the steps")
    args = ap.parse_args(argv)
    if sum((args.damping, args.jerk is not None, args.certify)) > 1:
        ap.error("--damping, --jerk and --certify are separate modes")
    name = "shaping_every_shaper" if args.jerk is None else "shaping_every_shaper_jerk"
    name = "shaping_every_shaper_damping" if args.damping else name
    name = "shaping_every_shaper_certify" if args.certify else name
    heads = damping_headline if args.damping else (certify_headline if args.certify else headline_of)
    if args.headline:
        import json

        from _common import results_dir

        from jaxbelt._io import write_text

        path = results_dir(False) / f"{name}.json"
        data = json.loads(path.read_text())
        data["headline"] = heads(data["rows"])
        write_text(path, json.dumps(data, indent=2, default=float))
        return
    t0 = time.perf_counter()
    if args.certify:
        rows = certify_rows(args.drawn)
        write_results(name, rows, heads(rows), quick=False, extra=dict(wall_s=time.perf_counter() - t0))
        for h in heads(rows):
            print(f"{h['what']}: {h['value']:.4g} {h['unit']} (target {h['target']})")
        return
    rows = []
    axes = NAMED_AXES[:1] if args.quick else NAMED_AXES[:3]  # the 10-mode axis has no buildable shaper
    if args.drawn:  # and the 12 axes `shaping_axis.py` draws (its table's rows)
        axes = [*axes, *((_label(f, z), f, z, D) for f, z in draw_axes(12))]
    if args.jerk is not None:
        axes = [a for a in axes if len(a[1]) == 1]
    for label, f, z, d in axes:
        shapers = ("ZV",) if args.quick else CLASSIC  # quick: one row checks every step
        if args.damping:
            rows += unknown_damping(label, f, d, shapers)
        else:
            rows += every_shaper(label, np.asarray(f), np.asarray(z), d, shapers, j_max=args.jerk)
    headline = heads(rows)
    extra = dict(wall_s=time.perf_counter() - t0, j_max=args.jerk)
    if args.damping:
        extra.update(damping_range=DAMPING_RANGE, shaper_damping=SHAPER_DAMPING, dense_damping=DENSE_DAMPING.tolist())
    write_results(name, rows, headline, quick=args.quick, extra=extra)
    for h in headline:
        print(f"{h['what']}: {h['value']:.4g} {h['unit']} (target {h['target']})")


if __name__ == "__main__":
    main()
