"""The minimax rows: the convex design (`jaxbelt.shaping.design`) at the move time, with its far modes, its certificate
(`jaxbelt.shaping.certificate`, `jaxbelt.shaping.certify`), the design with jumps `smooth="auto"` adds, and the
command space that holds every candidate (`jaxbelt.shaping.hull`, `jaxbelt.shaping.measure.blended_rows`).

This stage composes lower modules only, in this order: the design with its LP's setup and its certificate, in one
call (`minimax_solve.solve`), its row (`measure`), the shaped moves of the command space (`shaped`), the comparison
as executed (`hull`), the design with jumps (the same two calls), and the blends (`measure`).
"""

import concurrent.futures
import contextlib
import dataclasses
import math
import os

import jax
import numpy as np

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


#: the thread the minimax LP at a given move time runs in, beside the other candidates (`solving`): the LP is the
#: longest stage of a design and needs nothing they compute; XLA releases the GIL while it runs and compiles, so on
#: two cores the two overlap (a warm 3-mode design 2.5 s -> 1.7 s, a first call 18 s -> 12 s). Created at import,
#: its thread starts at the first submit; a forked child makes its own (a parent's executor never runs the child's
#: work: `design_move` would wait for it forever).
_WORKER: concurrent.futures.ThreadPoolExecutor


def _new_worker() -> None:
    global _WORKER
    _WORKER = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxbelt-minimax")


_new_worker()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_worker)


def _in_callers_context(fun, *args):
    """`fun(*args)` as a thread of its own would run it under the caller's JAX settings: the 64-bit mode and the
    default device, which a `with jax.enable_x64(True):` or `with jax.default_device(d):` block sets for the
    caller's thread only (read here, in the caller's thread; re-entered in the worker's)."""
    x64, device = bool(jax.enable_x64.value), jax.default_device.value

    def run():
        with jax.enable_x64(x64), jax.default_device(device):
            return fun(*args)

    return run


@contextlib.contextmanager
def solving(req: MoveRequest, ref):
    """Inside the block, the minimax rows at `req.move_time` (`minimax_rows`: the LP, its row, the design with jumps
    and the blends) are made in the worker thread (`_WORKER`): yields their future, for `minimax_rows(...,
    solved=)`, or None where the move time is not given or the minimax design is not asked for (then
    `minimax_rows` makes them itself). On leaving the block (also on an error) the work is cancelled if it has not
    started, and waited for if it has: no LP outlives the call, none runs outside its BLAS limit. The worker runs
    under the caller's 64-bit mode and default device (`_in_callers_context`).

    Everything after the LP needs only the LP's design, the request and the references (the classic rows matter only
    where the move time is searched): measured in the worker too, it overlaps the pseudo-polynomial designs of the
    caller's thread instead of following them (warm, 3 modes, on 2 cores shared at a load of 5: 3.9-4.3 s -> 2.3-3.3 s;
    the same rows)."""
    if req.move_time is None or "minimax" not in req.include:
        yield None
        return
    fut = _WORKER.submit(_in_callers_context(_rows_at, req, ref))
    try:
        yield fut
    finally:
        if not fut.cancel():
            concurrent.futures.wait([fut])


def _rows_at(req: MoveRequest, ref):
    """`minimax_rows` at the given move time `req.move_time`: the LP solved here (the worker's work)."""
    return _rows(req, ref, solve(req, ref, req.move_time))


def minimax_rows(req: MoveRequest, ref, classic: list, solved=None):
    """The minimax rows (the design; with `smooth="auto"` the design with jumps where the smooth one does not win),
    each the least worst blend of the command space that holds every candidate (`measure.blended_rows`), the design
    of the better row and the continuous bound: `(rows, design or None, bound)`. `classic`: the classic rows (the
    target with `move_time` None).

    The design with jumps (steps; with `j_max`, ramps whose jerk may jump), as `smooth=False` designs it: its command
    space holds what a classic shaper makes of the time-optimal move (a shaped trapezoid or S-curve), so at equal
    time and limits it leaves no more than the shapers (measured: `benchmarks/shaping_every_shaper.py`).

    `solved`: the future of `solving(req, ref)` (these rows, made in the worker), or None: make them here."""
    if solved is not None:
        return solved.result()
    usable = [r for r in classic if r.ok]
    target = min((r.worst_percent for r in usable), default=math.nan)
    T_guess = min((r.move_time for r in usable), default=2 * req.t_min)  # where the shortest time is searched
    return _rows(req, ref, solve(req, ref, req.move_time, T_guess=T_guess, target=target))


def _rows(req: MoveRequest, ref, solved_now):
    """`minimax_rows` from `solve`'s answer `solved_now` at `req.move_time` (or the shortest time, None)."""
    ref, T, d = np.asarray(ref), req.move_time, req.distance
    setup, _, (mm, bound, note, ok) = solved_now
    if T is None:  # at the shortest time that reaches the best classic shaper (no design where none is usable)
        if mm is None:
            return [], None, math.nan
        T = float(mm.command.duration)
    elif mm is None:
        note = f"infeasible for the {'smooth' if req.smooth else 'steps'} design: {note}"
    rows = [design_row("minimax", mm, T, note, ok, setup.far, req, ref)]
    # every classic shaped move and the unshaped move at the design's time, whatever `include` shows
    space = shaped_members(req.nominal, d, T, req.v_max, req.a_max, req.j_max)
    primary = rows[0]
    why = jumps_reason(primary, space, req.axis, ref, req.band, req.rate_hz) if req.move_time is not None else ""
    if req.auto and (why or req.certify_rtol is not None):
        why = why or "added: `certify_rtol` asks for the continuous certificate, which the design with jumps carries"
        if req.progress:
            print(f"design_move: {why}; designing the minimax command with jumps ...", flush=True)
        j_setup, j_solver, (jmm, jbound, note, ok) = solve(req, ref, T, jumps=True)
        note = note if jmm is not None else f"infeasible with {j_solver.opts.n_knots} equal steps: {note}"
        jrow = design_row(JUMPS, jmm, T, note, ok, j_setup.far, req, ref)
        rows.append(dataclasses.replace(jrow, note=why + "; " + jrow.note))
        if jmm is not None and jrow.ok:
            bound = jbound
            if not primary.ok or jrow.worst_percent < primary.worst_percent:
                mm = jmm  # `plan.minimax`: the design of the better minimax row
    if primary.ok and req.smooth:  # the smooth row's place against any command
        rows[0] = dataclasses.replace(primary, note=primary.note + smooth_certificate(primary.worst_percent, bound))
    if space and req.smooth_arg is not True:  # the command space that holds every candidate
        rows = blended_rows(req, ref, rows, space)
    return rows, mm, bound
