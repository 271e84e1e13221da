"""The minimax rows: the convex design (`jaxbelt.shaping.design`) at the move time, with its far modes, its certificate
(`jaxbelt.shaping.certificate`, `jaxbelt.shaping.certify`), the design with jumps `smooth="auto"` adds, and the
command space that holds every candidate (`jaxbelt.shaping.hull`, `jaxbelt.shaping.measure.blended_rows`).

This stage composes lower modules only, in this order: the design (solved by `minimax_solve`, placed at the table's
move time by `minimax_solve.solving`), the shaped moves of the command space (`shaped`), its row (`measure`), the
comparison as executed (`hull`), the design with jumps (`minimax_solve.solve`, its row), and the blends (`measure`).
"""

import dataclasses
import math

from .bands import JUMPS as JUMPS
from .certificate import smooth_certificate
from .hull import jumps_reason
from .measure import blended_rows, design_row
from .minimax_solve import solve
from .request import MoveRequest
from .shaped import shaped_members


def _smooth_certificate(row, bound: float) -> str:
    """`certificate.smooth_certificate` of a row (its `worst_percent`)."""
    return smooth_certificate(row.worst_percent, bound)


def minimax_rows(req: MoveRequest, solved, T: float):
    """The minimax rows at the move time `T` [s] (`minimax_solve.solving`; the design; with `smooth="auto"` the design
    with jumps where the smooth one does not win), each the least worst blend of the command space that holds every
    candidate (`measure.blended_rows`), the design of the better row and the continuous bound: `(rows, design or
    None, bound)`. `solved`: the future of `minimax_solve.solve`'s result for the design (`solving`), None without
    "minimax" in `req.include`; with `move_time` None and no design reaching the target, no row.

    The design with jumps (steps; with `j_max`, ramps whose jerk may jump), as `smooth=False` designs it: its command
    space holds what a classic shaper makes of the time-optimal move (a shaped trapezoid or S-curve), so at equal
    time and limits it leaves no more than the shapers (measured: `benchmarks/shaping_every_shaper.py`)."""
    if solved is None:
        return [], None, math.nan
    setup, _, (mm, bound, note, ok) = solved.result()
    if mm is None:
        if req.move_time is None:  # no design at the shortest time that reaches the best classic shaper
            return [], None, math.nan
        note = f"infeasible for the {'smooth' if req.smooth else 'steps'} design: {note}"
    # every classic shaped move and the unshaped move at the design's time, whatever `include` shows
    space = shaped_members(req.nominal, req.distance, T, req.v_max, req.a_max, req.j_max)
    rows = [design_row("minimax", mm, T, note, ok, setup.far, req)]
    smooth = mm
    primary = rows[0]
    correction = (req.uncertainty, req.limits)
    why = jumps_reason(primary, space, req.axis, req.ref, req.band, req.rate_hz, correction) if req.move_time else ""
    if req.auto and (why or req.certify_rtol is not None):
        why = why or "added: `certify_rtol` asks for the continuous certificate, which the design with jumps carries"
        if req.progress:
            print(f"design_move: {why}; designing the minimax command with jumps ...", flush=True)
        j_setup, j_solver, (jmm, jbound, note, ok) = solve(req, T, jumps=True)
        note = note if jmm is not None else f"infeasible with {j_solver.opts.n_knots} equal steps: {note}"
        jrow = design_row(JUMPS, jmm, T, note, ok, j_setup.far, req)
        rows.append(dataclasses.replace(jrow, note=why + "; " + jrow.note))
        if jmm is not None and jrow.ok:
            bound = jbound
            if not primary.ok or jrow.worst_percent < primary.worst_percent:
                mm = jmm  # `plan.minimax`: the design of the better minimax row
    if primary.ok and req.smooth:  # the smooth command's place against any command: both continuous
        worst = 100.0 * float(smooth.fine_worst) if smooth is not None else primary.worst_percent
        rows[0] = dataclasses.replace(primary, note=primary.note + smooth_certificate(worst, bound))
    if space and req.smooth_arg is not True:  # the command space that holds every candidate
        rows = blended_rows(req, rows, space)
    return rows, mm, bound
