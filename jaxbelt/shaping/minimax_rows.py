"""The minimax rows: the convex design (`jaxbelt.shaping.design`) at the move time, with its far modes, its certificate
(`jaxbelt.shaping.certify`), the design with jumps `smooth="auto"` adds, and the command space that holds every
candidate (`jaxbelt.shaping.hull`).
"""

import dataclasses
import math

import numpy as np

from .._checks import device_array
from . import design as _design
from .candidates import _members
from .certify import continuous_lower_bound
from .far_modes import LPSetup, _far_note, lp_setup
from .hull import best_blend
from .measure import _measure_grids, _row
from .moves import (
    blend_moves,
    prepare_peaks,
)
from .request import SURELY_FEASIBLE, MoveRequest
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
        return _design.max_distance(self.problem(T), self.opts) >= 1.0

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
        return _design.minimax_design(self.problem(T), self.opts)

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
        for factors in _measure_grids(u):
            prepare_curve(axis, cmd, factors)
        prepare_peaks(cmd)


def _minimax_solver(setup: LPSetup, d, v_max, a_max, j_max, u, ref):
    """The minimax design's `_Minimax` of `setup` (`far_modes.lp_setup`): the LP weighs the modes it keeps (`ref`,
    the references of every mode of the axis, taken for those)."""
    return _Minimax(setup.lp_axis, d, v_max, a_max, j_max, u, np.asarray(ref)[setup.kept], setup.opts)


def _design_at(solver: _Minimax, T: float, t_min: float, clearly: bool):
    """`solver`'s design at move time `T` [s], and NaN; or None and the shortest move time its basis can make
    (bisection) where it cannot make this one. A smooth (B-spline) move needs a little more time than the
    time-optimal one (`t_min`): well above that (`clearly`), the feasibility LP (its program costs a compile) is
    skipped unless the design then fails to converge."""
    mm = solver.design(T) if clearly else None
    if (mm is None or not mm.converged) and not solver.feasible(T):
        return None, solver.shortest_feasible(t_min)
    return (solver.design(T) if mm is None else mm), math.nan


#: the name of the row `design_move` adds, with `smooth="auto"`, for the minimax design whose acceleration may jump
JUMPS = "minimax (jumps)"


def _minimax_row(name, solver, mm, axis, ref, u, limits, far, per, certify_rtol, progress):
    """The table row of a solved minimax design `mm` (its note states the certificate: the LP's gap and, for the
    steps basis, the continuous bound, refined to `certify_rtol` if given), and the (possibly refined) design and
    the continuous bound (NaN but for the steps basis): `(row, mm, bound)`."""
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
        bound = continuous_lower_bound(mm)
        if certify_rtol is not None:
            mm, bound, note = _certify(solver, mm, bound, certify_rtol, progress)
        note += f"; any command leaves >= {100 * bound:.3g} % (continuous bound)"
    T_mm = float(mm.command.duration)
    row = _row(name, axis, mm.command, T_mm, ref, u, limits, note=note, ok=ok, per=per)
    if far.left_out:  # the left-out modes' residual, exact for this command (the program `_row` ran)
        row = dataclasses.replace(row, note=row.note + "; " + _far_note(axis, row.command, ref, u, far, per))
    return row, mm, bound


def _jumps_reason(primary, space, axis, ref, band, rate) -> str:
    """Why `smooth="auto"` adds the design with jumps ("" when it does not): the smooth minimax row is missing, not
    feasible or not converged, or a classic shaped move (whether or not the table shows it) or the unshaped move
    leaves no more than it, as executed (`space`: `_members`; `rate`: the drive's setpoint rate [Hz])."""
    if primary is None or not primary.ok or not math.isfinite(primary.worst_percent):
        return "added: the smooth design is not feasible or not converged at this time"
    names = list(space)
    _, _, worst = best_blend(axis, [primary.command, *space.values()], ref, band, rate, blend=False)
    k = int(np.argmin(worst[1:]))
    if worst[1 + k] > worst[0]:
        return ""
    return (
        f"added: {names[k]} leaves {100 * worst[1 + k]:.3g} % <= the smooth design's {100 * worst[0]:.3g} % (as "
        f"executed at {rate:g} Hz)"
    )


def _space_rows(rows, space, axis, ref, u, limits, per, band, rate):
    """`rows` with each minimax row replaced by the least worst residual, as executed at `rate` [Hz], of the blends
    of its design with the designs with jumps of the table and the members of `space` (`jaxbelt.shaping.hull`):
    at most what each of them leaves, by construction. The row's note says which blend it is. A minimax row whose
    design is infeasible or did not converge is kept as it is (not ok, its note says why): a blend of the other
    candidates alone is not that design, and the table shows those candidates' own rows."""
    designs = {r.name: r.command for r in rows if r.name in ("minimax", JUMPS) and r.ok and r.command is not None}
    out = []
    for r in rows:
        if r.name not in designs:  # not a minimax row, or one whose design failed: it keeps its own verdict
            out.append(r)
            continue
        keys = [n for n in designs if n in (r.name, JUMPS)]
        names, cmds = keys + list(space), [designs[n] for n in keys] + list(space.values())
        w, worst, each = best_blend(axis, cmds, ref, band, rate)
        parts = ", ".join(f"{names[i]} {w[i]:.3g}" for i in np.flatnonzero(w))
        note = (
            f"its command space holds every classic shaped move and the unshaped move: the blend {parts} leaves "
            f"{100 * worst:.3g} % as executed at {rate:g} Hz (the design alone {100 * each[0]:.3g} %; the least of "
            f"the others {100 * float(np.min(each[1:])):.3g} %)"
        )
        if w[0] == 1.0:
            out.append(dataclasses.replace(r, note=r.note + "; " + note))
            continue
        cmd = blend_moves(cmds, w)
        out.append(_row(r.name, axis, cmd, float(cmd.end_time), ref, u, limits, note=r.note + "; " + note, per=per))
    return out


def _smooth_certificate(row, bound: float) -> str:
    """What the smooth row's note says of its place against any command: the continuous bound where the design with
    jumps gave one, or, where its worst is below `CERTIFY_ATOL`, that it is within that of the least any command can
    leave (a residual is never below 0); "" otherwise (no bound is computed: `certify_rtol` makes one)."""
    worst = row.worst_percent / 100
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


def _jumps_minimax(axis, d, T, v_max, a_max, j_max, u, ref, limits, per, t_min, clearly, why, certify_rtol, progress):
    """The minimax design at move time `T` whose acceleration may jump (steps; with `j_max`, ramps whose jerk may
    jump), as `smooth=False` designs it: `(row, design or None, continuous bound)`. Its command space holds what a
    classic shaper makes of the time-optimal move (a shaped trapezoid or S-curve), so at equal time and limits it
    leaves no more than the shapers (measured: `benchmarks/shaping_every_shaper.py`)."""
    if progress:
        print(f"design_move: {why}; designing the minimax command with jumps ...", flush=True)
    # keeps every mode the spline's LP keeps (refused there where it keeps none)
    setup = lp_setup(axis, T, u, j_max, True, False, refuse=False)
    far, solver = setup.far, _minimax_solver(setup, d, v_max, a_max, j_max, u, ref)
    mm, t_f = _design_at(solver, T, t_min, clearly)
    if mm is None:
        note = f"{why}; infeasible with {solver.opts.n_knots} equal steps: needs a move time >= {t_f:.4g} s"
        return _row(JUMPS, axis, None, T, ref, u, limits, ok=False, note=note, per=per), None, math.nan
    row, mm, bound = _minimax_row(JUMPS, solver, mm, axis, ref, u, limits, far, per, certify_rtol, progress)
    return dataclasses.replace(row, note=why + "; " + row.note), mm, bound


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


def _certify(solver: _Minimax, mm, bound: float, rtol: float, progress: bool):
    """Refine the steps design until (worst - bound) <= max(rtol * worst, `CERTIFY_ATOL`) (the worst on the fine
    grid): first the cuts
    and the frequency grid (`_certify_options`), then the number of steps, doubled up to `CERTIFY_MAX_STEPS`. The
    least-residual design met on the way, the best bound so far, and the row's note."""
    T = float(mm.command.duration)

    def within(d, b):
        return float(d.fine_worst) - b <= max(rtol * float(d.fine_worst), CERTIFY_ATOL)

    opts = _certify_options(mm.options, rtol)
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


def _shortest_minimax(solver: _Minimax, t_min, target, progress):
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


def prepare_minimax(req: MoveRequest):
    """At a given move time: the minimax LP's setup (`far_modes.lp_setup`: the modes it leaves out, refused at once
    when it would weigh none), and, well above the time-optimal move, the design's programs start compiling in the
    background while the reference and the other candidates are computed (a stand-in reference of the right shape).
    None otherwise."""
    if "minimax" not in req.include or req.move_time is None:
        return None
    setup = lp_setup(req.axis, req.move_time, req.uncertainty, req.j_max, True, req.smooth, req.per)
    if req.clearly:
        stand_in = np.ones(req.axis.n_modes)
        _minimax_solver(setup, req.distance, req.v_max, req.a_max, req.j_max, req.uncertainty, stand_in).prepare(
            req.move_time
        )
    return setup


def minimax_rows(req: MoveRequest, ref, classic: list, setup: LPSetup | None):
    """The minimax rows (the design; with `smooth="auto"` the design with jumps where the smooth one does not win),
    each the least worst blend of the command space that holds every candidate (`_space_rows`), the design of the
    better row and the continuous bound: `(rows, design or None, bound)`. `classic`: the classic rows (the target
    with `move_time` None); `setup`: `prepare_minimax`'s."""
    axis, d, u, per, ref = req.axis, req.distance, req.uncertainty, req.per, np.asarray(ref)
    usable = [r for r in classic if r.ok]
    target = min((r.worst_percent for r in usable), default=math.nan)
    T_guess = req.move_time if req.move_time is not None else min((r.move_time for r in usable), default=2 * req.t_min)
    if setup is None:
        setup = lp_setup(axis, T_guess, u, req.j_max, False, req.smooth, per)
    far, solver = setup.far, _minimax_solver(setup, d, req.v_max, req.a_max, req.j_max, u, ref)
    rows, bound = [], math.nan
    if req.move_time is not None:
        mm, t_f = _design_at(solver, req.move_time, req.t_min, req.clearly)
        if mm is None:
            note = f"infeasible for the {'smooth' if req.smooth else 'steps'} design: needs a move time >= {t_f:.4g} s"
            rows.append(_row("minimax", axis, None, req.move_time, ref, u, req.limits, ok=False, note=note, per=per))
    else:
        mm = _shortest_minimax(solver, req.t_min, target, req.progress)
    if mm is not None:
        row, mm, bound = _minimax_row("minimax", solver, mm, axis, ref, u, req.limits, far, per, req.certify_rtol,
                                      req.progress)  # fmt: skip
        rows.append(row)
    primary = rows[0] if rows else None
    T = req.move_time if req.move_time is not None else (float(mm.command.duration) if mm is not None else None)
    if T is None:
        return rows, mm, bound
    # every classic shaped move and the unshaped move at the design's time, whatever `include` shows
    space = _members(req.nominal, d, T, req.v_max, req.a_max, req.j_max)
    why = _jumps_reason(primary, space, axis, ref, req.band, req.rate_hz) if req.move_time is not None else ""
    if req.auto and (why or req.certify_rtol is not None):
        why = why or "added: `certify_rtol` asks for the continuous certificate, which the design with jumps carries"
        clearly = T >= SURELY_FEASIBLE * req.t_min
        jrow, jmm, jbound = _jumps_minimax(axis, d, T, req.v_max, req.a_max, req.j_max, u, ref, req.limits, per,
                                            req.t_min, clearly, why, req.certify_rtol, req.progress)  # fmt: skip
        rows.append(jrow)
        if jmm is not None and jrow.ok:
            bound = jbound
            if primary is None or not primary.ok or jrow.worst_percent < primary.worst_percent:
                mm = jmm  # `plan.minimax`: the design of the better minimax row
    if primary is not None and primary.ok and req.smooth:  # the smooth row's place against any command
        rows[0] = dataclasses.replace(primary, note=primary.note + _smooth_certificate(primary, bound))
    if space and req.smooth_arg is not True:  # the command space that holds every candidate
        rows = _space_rows(rows, space, axis, ref, u, req.limits, per, req.band, req.rate_hz)
    return rows, mm, bound
