"""Solve the minimax design (`jaxbelt.shaping.design`) for `design_move`'s minimax rows: in one call (`solve`) its
LP's setup, its solver, the design at a move time (with its feasibility) or at the shortest time that reaches a
target, and its certificate (`jaxbelt.shaping.certificate`); where it runs and the move time it places the table at
(`solving`: at a given move time in a worker thread beside the timed candidates, else here, at the shortest time
that reaches the best classic row).

A lower-level module of the minimax rows (`jaxbelt.shaping.minimax_rows`): it designs and certifies, measures no row.
"""

import concurrent.futures
import contextlib
import math
import os

import jax
import numpy as np

from . import design as _design
from .candidates import prepare_timed
from .certificate import certificate
from .far_modes import lp_setup, prepare_lp
from .hull import prepare_blend
from .request import SURELY_FEASIBLE, MoveRequest

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


def _here(fun, *args) -> concurrent.futures.Future:
    """`fun(*args)` run now, in the caller's thread, as a done future (its error raised by `result()`)."""
    done: concurrent.futures.Future = concurrent.futures.Future()
    try:
        done.set_result(fun(*args))
    except Exception as e:  # noqa: BLE001 - handed to the caller by `result()`, as the worker's would be
        done.set_exception(e)
    return done


@contextlib.contextmanager
def solving(req: MoveRequest, classic: list):
    """The move time [s] of the timed candidates and the minimax rows, the minimax design, and where the work that
    follows the design runs, for the block: yields `(T, future of solve's result, beside)` (no future without
    "minimax" in `req.include`); `beside(fun, *args)` returns the future of `fun(*args)`.

    - at a given move time: that time, `solve(req, T)` running in the worker thread (`_WORKER`) beside the other
      candidates, and `beside` queuing work on the same worker after it (the minimax rows: their shaped moves,
      blends and the design with jumps need only the design, so they overlap the timed candidates too; warm, 3 modes,
      2 cores at load 5: 3.9-4.3 s -> 2.3-3.3 s, the same rows). On leaving the block the queued work is waited
      for; on an error the work not started is cancelled and the work started is waited for: no LP outlives the
      call, none runs outside its BLAS limit. The worker runs under the caller's 64-bit mode and default device
      (`_in_callers_context`);
    - with `move_time` None: the design at the shortest time whose worst residual reaches the best usable row of
      `classic` (the measured classic rows; searched from the shortest of their times), solved here, and its time;
      without a design, the shortest usable classic row's time (twice the time-optimal move's without one);
      `beside` runs here."""
    usable = [r for r in classic if r.ok]
    fallback = min((r.move_time for r in usable), default=2 * req.t_min)
    if "minimax" not in req.include:
        yield (fallback if req.move_time is None else req.move_time), None, _here
        return
    if req.move_time is not None:
        queued = [_WORKER.submit(_in_callers_context(_prepared_solve, req, req.move_time))]

        def beside(fun, *args):
            queued.append(_WORKER.submit(_in_callers_context(fun, *args)))
            return queued[-1]

        try:
            yield req.move_time, queued[0], beside
        except BaseException:
            for f in queued:  # the work not started is not needed
                f.cancel()
            raise
        finally:
            concurrent.futures.wait(queued)  # the work started has finished (cancelled futures count as done)
        return
    target = min((r.worst_percent for r in usable), default=math.nan)
    done = _here(lambda: solve(req, None, T_guess=fallback, target=target))  # solved here, in the caller's thread
    mm = done.result()[2][0]
    yield (fallback if mm is None else float(mm.command.duration)), done, _here


def _prepared_solve(req: MoveRequest, T: float):
    """`solve(req, T)` (`T` [s]: the given move time) after starting, in the background, the compilation of the programs the table's rows
    run: the minimax design's (`far_modes.prepare_lp`, where the smooth design is surely feasible), the timed
    candidates' measure (`candidates.prepare_timed`) and the blends' (`hull.prepare_blend`). Traced here, in the
    worker, while the caller traces the pseudo-polynomials' optimiser; each compiles in the compile threads while
    the ones after it are traced, and a call waits for its program's compilation (`jaxbelt._guard.prepare`)."""
    if req.clearly and req.lp is not None:
        prepare_lp(req.lp, req.distance, req.v_max, req.a_max, req.j_max, req.uncertainty, T)
    prepare_timed(req, T)
    if req.smooth_arg is not True:  # the blends of the command space (`minimax_rows`), the worker's last programme
        prepare_blend(req.axis.n_modes, req.band)
    return solve(req, T)


def solve(req: MoveRequest, T: float | None, *, jumps: bool = False, T_guess: float = math.nan,
          target: float = math.nan):  # fmt: skip
    """The minimax design of `req` against its references `req.ref` [m], in one call: its LP's setup (`req.lp`, or
    `far_modes.lp_setup` at `T_guess` [s] where the shortest time is searched; with `jumps`, the design with jumps
    at `T`, keeping every mode the spline's LP keeps), its solver, and the design at move time `T` [s]
    (`MinimaxSolver.at`; the feasibility LP skipped well above the time-optimal move's) or, with `T` None, at the
    shortest time whose worst residual reaches `target` (%, `MinimaxSolver.shortest`), with its certificate
    (`certificate`): `(setup, solver, (design or None, continuous bound, note, converged))`; without a design, the
    note says the shortest move time the basis can make (none with `T` None: the target is not finite)."""
    u, j = req.uncertainty, req.j_max
    if jumps and T is not None:  # (at a move time) refused by the spline's setup where it keeps no mode
        setup, clearly = lp_setup(req.axis, T, u, j, True, False, refuse=False), T >= SURELY_FEASIBLE * req.t_min
    else:
        setup = req.lp if req.lp is not None else lp_setup(req.axis, T_guess, u, j, False, req.smooth, req.per)
        clearly = req.clearly
    solver = _design.MinimaxSolver(
        setup.lp_axis, req.distance, req.v_max, req.a_max, j, u, np.asarray(req.ref)[setup.kept], setup.opts
    )
    if T is None:
        mm, t_f = solver.shortest(req.t_min, target), math.nan
    else:
        mm, t_f = solver.at(T, req.t_min, clearly)
    if mm is None:
        return setup, solver, (None, math.nan, f"needs a move time >= {t_f:.4g} s", False)
    return setup, solver, certificate(solver, mm, req.certify_rtol, req.progress)
