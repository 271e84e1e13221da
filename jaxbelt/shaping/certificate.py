"""The certificate of a solved minimax design, in the words of its row's note: the LP's gap and, for a design with
steps, the continuous lower bound on what any command can leave (`jaxbelt.shaping.certify`), refined until within
`certify_rtol` (`certificate`); and what the smooth row's note says of its place against any command
(`smooth_certificate`).

A lower-level module of the minimax rows: `jaxbelt.shaping.minimax_solve` certifies each design it solves here.
"""

import math

import numpy as np

from . import design as _design
from .certify import continuous_lower_bound

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


def _certify(solver: _design.MinimaxSolver, mm, rtol: float, progress: bool):
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
        finer = _design.MinimaxSolver(*solver.args, opts).design(T)
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


def certificate(solver: _design.MinimaxSolver, mm, certify_rtol, progress: bool):
    """The certificate of a solved minimax design `mm`, in the words of its row's note: the LP's gap and, for the
    steps basis, the continuous bound, refined to `certify_rtol` if given (`_certify`). `(design (possibly
    refined), continuous bound (NaN but for the steps basis), note, converged)`."""
    bound = math.nan
    note = f"certified gap {float(mm.gap):.1e}"
    if float(mm.gap) > _design.CERTIFIED_GAP:  # accepted by the absolute gap (an optimum near zero)
        note = f"certified within {100 * (float(mm.worst) - float(mm.lower_bound)):.1e} % of the optimum"
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
