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

import numpy as np

from . import design as _design
from . import worker
from .certificate import certificate
from .far_modes import lp_setup
from .request import SURELY_FEASIBLE, MoveRequest


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

    - at a given move time: that time, `solve(req, T)` running in the minimax worker (`jaxbelt.shaping.worker`)
      beside the other candidates, and `beside` queuing work on the same worker after it (the minimax rows: their
      shaped moves, blends and the design with jumps need only the design, so they overlap the timed candidates
      too; warm, 3 modes, 2 cores at load 5: 3.9-4.3 s -> 2.3-3.3 s, the same rows). On leaving the block the
      queued work is waited for; on an error the work not started is cancelled and the work started is waited
      for: no LP outlives the call, none runs outside its BLAS limit. The worker runs under the caller's 64-bit
      mode and default device (`worker.submit`), after the LP's preparation `request.validate` queued
      (`req.prepared`, waited for with the rest);
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
        design = worker.submit(solve, req, req.move_time)
        queued = [f for f in (req.prepared, design) if f is not None]

        def beside(fun, *args):
            queued.append(worker.submit(fun, *args))
            return queued[-1]

        try:
            yield req.move_time, design, beside
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
