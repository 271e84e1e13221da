"""Solve the minimax design (`jaxbelt.shaping.design`) for `design_move`'s minimax rows: at a move time (with its
feasibility), at the shortest time that reaches a target, and refined until its continuous certificate
(`jaxbelt.shaping.certify`) is within a tolerance; the certificate's words for the row's note.

A lower-level module of the minimax rows (`jaxbelt.shaping.minimax_rows`): it designs and certifies, measures no row.
"""

import math

import numpy as np

from .._checks import device_array
from . import design as _design
from .bands import measure_grids
from .certify import continuous_lower_bound
from .far_modes import LPSetup
from .moves import prepare_peaks
from .request import MoveRequest
from .residual import prepare_curve


class _Minimax:
    """The convex design at a move time, with its feasibility (one problem structure per axis size)."""

    def __init__(self, axis, distance, v_max, a_max, j_max, u, ref, opts):
        self.args = (axis, distance, v_max, a_max, j_max, u, ref)
        self.opts = opts

    def problem(self, T):
        axis, distance, v_max, a_max, j_max, u, ref = self.args
        return _design.make_problem(axis, distance, T, v_max, a_max, j_max, u, ref, self.opts)

    def feasible(self, T) -> bool:
        problem = self.problem(T)
        return _design.max_distance(problem, self.opts) >= 1.0

    def shortest_feasible(self, t_min):
        """The least time at which the spline can move the distance within the limits (bisection)."""
        lo, hi = t_min, t_min * 1.05
        while not self.feasible(hi):
            lo, hi = hi, hi * 1.2
        for _ in range(30):
            if hi - lo <= 1e-4 * hi:
                break
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if self.feasible(mid) else (mid, hi)
        return hi

    def design(self, T):
        problem = self.problem(T)
        return _design.minimax_design(problem, self.opts)

    def prepare(self, T) -> None:
        """While the program store is on: start compiling, in the background, the programs a design at T runs and
        those `_measure` runs on its command, each traced while the ones before compile (on two cores the LP's
        compilation, the longest, overlaps the others' tracing and compiling). Nothing otherwise."""
        problem = self.problem(T)
        coef = _design.prepare_design(problem, self.opts)
        if coef is None:
            return
        axis, u = self.args[0], self.args[5]
        cmd = _design.design_command(device_array(np.zeros(coef.shape, coef.dtype)), problem.move_time, self.opts)
        for factors in measure_grids(u):
            prepare_curve(axis, cmd, factors)
        prepare_peaks(cmd)


def minimax_solver(setup: LPSetup, d, v_max, a_max, j_max, u, ref):
    """The minimax design's `_Minimax` of `setup` (`far_modes.lp_setup`): the LP weighs the modes it keeps (`ref`,
    the references of every mode of the axis, taken for those)."""
    return _Minimax(setup.lp_axis, d, v_max, a_max, j_max, u, np.asarray(ref)[setup.kept], setup.opts)


def design_at(solver: _Minimax, T: float, t_min: float, clearly: bool):
    """`solver`'s design at move time `T` [s], and NaN; or None and the shortest move time its basis can make
    (bisection) where it cannot make this one. A smooth (B-spline) move needs a little more time than the
    time-optimal one (`t_min`): well above that (`clearly`), the feasibility LP (its program costs a compile) is
    skipped unless the design then fails to converge."""
    mm = solver.design(T) if clearly else None
    if (mm is None or not mm.converged) and not solver.feasible(T):
        return None, solver.shortest_feasible(t_min)
    return (solver.design(T) if mm is None else mm), math.nan


#: the most acceleration steps `design_move(..., certify_rtol=...)` refines to
CERTIFY_MAX_STEPS = 1024


#: the absolute floor of `certify_rtol`'s proof (a fraction of the references: 0.01 % of the unshaped move's
#: residual): where the optimum is near zero the bound is 0 and no relative tolerance can be proved, but a design
#: within this of the least any command can leave needs no refining
CERTIFY_ATOL = 1e-4


def _certify_options(opts, rtol: float):
    """The discretisation a certificate within `rtol` needs besides the steps: the modulus |r| <= t is imposed by
    P cuts (a P-gon that lets |r| exceed t by 1/cos(pi/P) - 1: 2 % for the default 16), so P grows until that is
    below rtol/4, and the exchange refines the frequency grid until the fine grid is within rtol/4 of the LP's."""
    P = opts.n_angles
    while 1.0 / math.cos(math.pi / P) - 1.0 > rtol / 4:
        P *= 2
    return opts._replace(
        n_angles=P,
        exchange_tol=min(opts.exchange_tol, rtol / 4),
        n_rounds=max(opts.n_rounds, 8),
        n_extra=max(opts.n_extra, 24),
    )


def _certify(solver: _Minimax, mm, rtol: float, progress: bool):
    """Refine the steps design `mm` until (worst - bound) <= max(rtol * worst, `CERTIFY_ATOL`) (the worst on the
    fine grid; the bound: `certify.continuous_lower_bound`, the best of the designs met): first the cuts and the
    frequency grid (`_certify_options`), then the number of steps, doubled up to `CERTIFY_MAX_STEPS`. The
    least-residual design met on the way, the best bound so far, and the row's note."""
    T = float(mm.command.duration)

    def within(d, b):
        return float(d.fine_worst) - b <= max(rtol * float(d.fine_worst), CERTIFY_ATOL)

    opts = _certify_options(mm.options, rtol)
    bound = continuous_lower_bound(mm)
    tried = mm.options.n_knots  # the most steps designed so far
    stopped = ""  # why the refinement stopped short, where a finer design did not converge
    while not within(mm, bound) and opts.n_knots <= CERTIFY_MAX_STEPS:
        if progress:
            print(f"design_move: certifying with {opts.n_knots} steps, {opts.n_angles} cuts ...", flush=True)
        finer = _Minimax(*solver.args, opts).design(T)
        if not finer.converged:
            stopped = f"the design with {opts.n_knots} steps did not converge"
            break
        tried = opts.n_knots
        bound = max(bound, continuous_lower_bound(finer))
        if float(finer.fine_worst) <= float(mm.fine_worst):
            mm = finer
        opts = opts._replace(n_knots=2 * opts.n_knots)
    stopped = stopped or f"{tried} steps, the most within CERTIFY_MAX_STEPS = {CERTIFY_MAX_STEPS}"
    gap = float(mm.fine_worst) - bound
    rel = gap / float(mm.fine_worst)
    how = f"{100 * rel:.2g} % (relative)"
    if rel > rtol and gap <= CERTIFY_ATOL:  # met by the absolute floor (an optimum near zero)
        how = f"{100 * gap:.2g} % of the unshaped move's residual (absolute, at most CERTIFY_ATOL = {100 * CERTIFY_ATOL:g} %)"
    note = (
        f"certified gap {float(mm.gap):.1e}; {mm.options.n_knots} steps, {mm.options.n_angles} cuts: within "
        f"{how} of the least any command can leave"
        + ("" if within(mm, bound) else f" (not within certify_rtol: {stopped})")
    )
    return mm, bound, note


def shortest_minimax(solver: _Minimax, t_min, target, progress):
    """The minimax design at the least move time whose worst residual (fine grid) reaches `target` (%):
    bisection between the least feasible time and a time where the target is met."""
    if not math.isfinite(target):
        return None
    lo = solver.shortest_feasible(t_min)
    d_lo = solver.design(lo)
    if 100 * float(d_lo.fine_worst) <= target:
        return d_lo
    hi = lo * 1.25
    d_hi = solver.design(hi)
    while 100 * float(d_hi.fine_worst) > target:
        lo, hi = hi, hi * 1.25
        if hi > 20 * t_min:
            return d_hi
        d_hi = solver.design(hi)
    for _ in range(12):
        if hi - lo <= 2e-3 * hi:
            break
        mid = 0.5 * (lo + hi)
        d_mid = solver.design(mid)
        if 100 * float(d_mid.fine_worst) <= target:
            hi, d_hi = mid, d_mid
        else:
            lo = mid
    return d_hi


def certificate(solver: _Minimax, mm, certify_rtol, progress: bool):
    """The certificate of a solved minimax design `mm`, in the words of its row's note: the LP's gap and, for the
    steps basis, the continuous bound, refined to `certify_rtol` if given (`_certify`). `(design (possibly
    refined), continuous bound (NaN but for the steps basis), note, converged)`."""
    bound = math.nan
    note = f"certified gap {float(mm.gap):.1e}"
    if float(mm.gap) > _design.CERTIFIED_GAP:  # accepted by the absolute gap (an optimum near zero)
        note = f"certified within {100 * float(mm.worst - mm.lower_bound):.1e} % of the optimum"
    ok = mm.converged
    if not ok:
        lp = mm.lp
        note = (
            f"not converged (gap {float(mm.gap):.1e}; the LP's interior-point solver stopped after "
            f"{int(np.asarray(lp.iterations))} iterations, primal residual {float(np.asarray(lp.primal_residual)):.1e}, "
            f"dual {float(np.asarray(lp.dual_residual)):.1e}): try a longer `move_time` or `smooth=False`"
        )
    elif mm.options.basis == "steps":  # the spline's multipliers bound next to nothing: steps only
        if certify_rtol is not None:
            mm, bound, note = _certify(solver, mm, certify_rtol, progress)
        else:
            bound = continuous_lower_bound(mm)
        note += f"; any command leaves >= {100 * bound:.3g} % (continuous bound)"
    return mm, bound, note, ok


def smooth_certificate(worst_percent: float, bound: float) -> str:
    """What the smooth row's note says of its place against any command, for its worst residual `worst_percent` (%):
    the continuous bound where the design with jumps gave one, or, where its worst is below `CERTIFY_ATOL`, that it
    is within that of the least any command can leave (a residual is never below 0); "" otherwise (no bound is
    computed: `certify_rtol` makes one)."""
    worst = worst_percent / 100
    if math.isfinite(bound):
        return (
            f"; any command leaves >= {100 * bound:.3g} % (continuous bound, from the design with jumps): this one "
            f"at most {100 * max(worst - bound, 0.0):.2g} percentage points above the least any command can leave"
        )
    if worst <= CERTIFY_ATOL:
        return (
            f"; within {100 * worst:.2g} percentage points of the least any command can leave (its worst is below CERTIFY_ATOL = "
            f"{100 * CERTIFY_ATOL:g} %)"
        )
    return ""


def prepare_minimax(req: MoveRequest) -> None:
    """At a given move time well above the time-optimal move's (`req.lp` set, `req.clearly`): the design's programs
    start compiling in the background while the reference and the other candidates are computed (a stand-in
    reference of the right shape). Nothing otherwise."""
    if req.lp is None or not req.clearly:
        return
    stand_in = np.ones(req.axis.n_modes)
    minimax_solver(req.lp, req.distance, req.v_max, req.a_max, req.j_max, req.uncertainty, stand_in).prepare(
        req.move_time
    )


def solved(solver: _Minimax, req: MoveRequest, T: float | None, clearly: bool, target: float = math.nan):
    """The design of `solver` (`minimax_solver`) at move time `T` [s] (`design_at`; `clearly`: well above the
    time-optimal move's), or with `T` None at the shortest time whose worst residual reaches `target` (%,
    `shortest_minimax`), and its certificate (`certificate`): `(design or None, continuous bound, note,
    converged)`; without a design, the note says the shortest move time the basis can make (none with `T` None:
    the target is not finite)."""
    if T is None:
        mm, t_f = shortest_minimax(solver, req.t_min, target, req.progress), math.nan
    else:
        mm, t_f = design_at(solver, T, req.t_min, clearly)
    if mm is None:
        return None, math.nan, f"needs a move time >= {t_f:.4g} s", False
    return certificate(solver, mm, req.certify_rtol, req.progress)
