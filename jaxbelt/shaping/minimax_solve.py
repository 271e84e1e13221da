"""Solve the minimax design (`jaxbelt.shaping.design`) for `design_move`'s minimax rows, in one call (`solve`): its
LP's setup, its solver, the design at a move time (with its feasibility) or at the shortest time that reaches a
target, and its certificate (`jaxbelt.shaping.certificate`).

A lower-level module of the minimax rows (`jaxbelt.shaping.minimax_rows`): it designs and certifies, measures no row.
"""

import math

import numpy as np

from . import design as _design
from .certificate import certificate
from .far_modes import lp_setup
from .request import SURELY_FEASIBLE, MoveRequest


def solve(req: MoveRequest, ref, T: float | None, *, jumps: bool = False, T_guess: float = math.nan,
          target: float = math.nan):  # fmt: skip
    """The minimax design of `req` against the references `ref` [m], in one call: its LP's setup (`req.lp`, or
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
        setup.lp_axis, req.distance, req.v_max, req.a_max, j, u, np.asarray(ref)[setup.kept], setup.opts
    )
    if T is None:
        mm, t_f = solver.shortest(req.t_min, target), math.nan
    else:
        mm, t_f = solver.at(T, req.t_min, clearly)
    if mm is None:
        return setup, solver, (None, math.nan, f"needs a move time >= {t_f:.4g} s", False)
    return setup, solver, certificate(solver, mm, req.certify_rtol, req.progress)
