"""What no input shaper gives: how the best achievable residual, and the shortest move, change with the axis.

The minimax design's optimal value $V(\\theta, T)$ (the least worst-case residual, as a fraction of the
references, over the design's final frequency grid) is differentiable in the axis $\\theta$ (mode
frequencies, damping ratios, gains; through `BeltPlatform.to_axis()` the belt stiffness, the payload inertia
and the pulley radii of Incerti's platform) and in the move time $T$, by the envelope theorem on the LP
(`jaxbelt.shaping.lp`). The shortest move time at a residual target $V^*$ is the root $T^*(\\theta)$ of
$V(\\theta, T) = V^*$; implicit differentiation gives
$\\dfrac{dT^*}{d\\theta} = -\\dfrac{\\partial V/\\partial\\theta}{\\partial V/\\partial T}$.

Both functions take the grid, references and discretisation of a solved design (`plan.minimax` of a
`jaxbelt.design_move` plan, or `jaxbelt.shaping.design.minimax_design`): the derivative is that of the
discretised optimum, which the tests check against central finite differences.
"""

import math
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_real, device_array, is_concrete
from .._guard import all_ok, checked, reraising, traced_checks
from .._params import recheck
from .._threads import blas_limited
from ..models.axis import FREQUENCY_RANGE_HZ, ModalAxis
from .design import MinimaxDesign, default_options, knot_cap, max_distance, minimax_design, minimax_value
from .moves import fastest_time


def _check_axis(owner: str, axis, design) -> None:
    n = design.problem.axis.n_modes
    if not isinstance(axis, ModalAxis) or axis.n_modes != n:
        got = f"a ModalAxis with {axis.n_modes} modes" if isinstance(axis, ModalAxis) else type(axis).__name__
        raise ValueError(f"{owner}: parameter `axis` must be a ModalAxis with {n} modes, like the design's; got {got}")


def _check_design(owner: str, design) -> None:
    if not isinstance(design, MinimaxDesign):
        raise ValueError(
            f"{owner}: parameter `design` must be a solved minimax design (a MinimaxDesign: `plan.minimax` of a "
            f"`jaxbelt.design_move(..., include=('minimax', ...))` plan, or `minimax_design(...)`); got "
            f"{type(design).__name__}"
        )


def _fastest(design: MinimaxDesign) -> float:
    """The shortest rest-to-rest time [s] of the design's distance within its limits (|v|, |a|, and |jerk| where
    the design has a jerk limit): the time-optimal move, a lower bound of every command's move time. NaN where
    the design's data are traced."""
    p = design.problem
    data = (p.distance, p.v_max, p.a_max, p.j_max)
    if not is_concrete(data):
        return math.nan
    D, v, a, j = (float(np.asarray(x)) for x in data)
    return fastest_time(D, v, a, j if design.options.jerk else None)


def _check_move_time(owner: str, name: str, move_time, design: MinimaxDesign, what: str = "move time"):
    """`move_time` [s] finite, > 0 and not below the shortest feasible move of the design's distance and limits:
    concrete, a `ValueError` now; traced, `[(ok, message)]` to attach to the result."""
    check_real(name, move_time, "s", owner)  # a string, a bool or None is refused, not converted
    t_min = _fastest(design)
    shortest = (
        f"the shortest feasible move under the design's limits takes {t_min:.6g} s" if math.isfinite(t_min) else ""
    )
    if is_concrete(move_time):
        T = np.asarray(move_time, dtype=float)
        if T.ndim != 0:
            raise ValueError(f"{owner}: parameter `{name}` must be a scalar {what} [s]; got shape {T.shape}")
        T = float(T)
        if not (math.isfinite(T) and T > 0):
            raise ValueError(
                f"{owner}: parameter `{name}` ({what}) must be finite and > 0 s; got {T}{'; ' + shortest if shortest else ''}"
            )
        if math.isfinite(t_min) and T < t_min * (1 - 1e-9):
            raise ValueError(
                f"{owner}: parameter `{name}` ({what}) = {T:.6g} s is shorter than any move can be: {shortest} "
                f"(distance {float(np.asarray(design.problem.distance)):g}, v_max {float(np.asarray(design.problem.v_max)):g}, "
                f"a_max {float(np.asarray(design.problem.a_max)):g}); give `{name}` >= {t_min:.6g} s or relax the limits"
            )
        return []
    return _traced_time_checks(owner, name, move_time, t_min, what)


def _traced_time_checks(owner: str, name: str, move_time, t_min: float, what: str):
    """`[(ok, message)]`: the traced `move_time` [s] finite, > 0 and, where `t_min` [s] is finite, not below it."""
    T = jnp.asarray(move_time, dtype=float)
    ok = jnp.isfinite(T) & (T > 0)
    if math.isfinite(t_min):
        ok = ok & (T >= t_min * (1 - 1e-9))
    return [
        (
            ok,
            f"{owner}: parameter `{name}` ({what}) must be finite, > 0 and at least the shortest feasible move under the design's limits ({t_min:.6g} s)",
        )
    ]


def _problem(design: MinimaxDesign, axis, move_time):
    p = design.problem
    # on the host where concrete: an eager `jnp.asarray` compiles a small program in each process
    T = device_array(move_time, dtype=float) if is_concrete(move_time) else jnp.asarray(move_time, dtype=float)
    return eqx.tree_at(lambda q: (q.axis, q.move_time), p, (axis, T))


#: below this multiple of the time-optimal move time, `best_residual` checks that the design's spline covers the
#: distance within the limits (an LP, ~30 ms once compiled, ~3 s to compile): the spline's own shortest move is a
#: few % longer (3-7 % measured with 48-96 knots, `design.SURELY_FEASIBLE`), so 25 % leaves room and spares most
#: `shortest_move_time` calls the compile
SPLINE_CHECK_BELOW = 1.25


def _check_spline_reaches(owner: str, axis, move_time, design: MinimaxDesign, options=None) -> None:
    """`ValueError` where `move_time` [s] (concrete, near the time-optimal move) is too short for the design's
    spline command (or one of `options`' knots: `shortest_move_time`'s re-made designs) to cover the distance within
    the limits: the minimax LP is infeasible there, and its value is a large meaningless number."""
    T, t_min = float(move_time), _fastest(design)
    if not (math.isfinite(t_min) and T < SPLINE_CHECK_BELOW * t_min):
        return
    options = design.options if options is None else options
    reach = float(max_distance(_problem(design, axis, move_time), options))
    if not reach >= 1.0:
        raise ValueError(
            f"{owner}: parameter `move_time` = {T:.6g} s is too short for the design's command: a spline of "
            f"{options.n_knots} knot intervals moves at most {100 * reach:.4g} % of the distance in that time "
            f"within the limits (the time-optimal move, which no smooth command reaches, takes {t_min:.6g} s); give a "
            "longer `move_time`"
        )


@reraising("best_residual")
@blas_limited
def best_residual(axis: ModalAxis, move_time, design: MinimaxDesign):
    """The least worst-case residual (fraction of the references) any smooth move of the design's distance and
    limits can leave on `axis` in `move_time` [s], on the frequency grid of `design`. Differentiable in the axis'
    arrays and `move_time` (`jax.grad`, forward mode too); the references are held fixed.

    Raises `ValueError` at the call, before any solve, for a `design` that is not a `MinimaxDesign` and for a
    `move_time` that is not finite and > 0 or is shorter than the shortest feasible move of the design's
    distance within its limits (the time-optimal move, `fastest_time`): no command meets it, and the LP's value
    there means nothing. Traced values (under `jax.jit`, `jax.vmap`, `jax.grad`) are checked at run time, the
    axis first: a frequency that is NaN, <= 0 or outside `FREQUENCY_RANGE_HZ`, a damping ratio outside [0, 1) or
    a zero gain raises a `ValueError` naming the parameter and the mode (and, under `vmap`, the element of the
    batch), then a `move_time` out of range; never a finite "residual" of an invalid axis."""
    o = "best_residual"
    _check_design(o, design)
    _check_axis(o, axis, design)
    traced_time = not is_concrete(move_time)
    if traced_time:
        check_real("move_time", move_time, "s", o)  # a string, a bool or None is refused, not converted
        if jnp.ndim(move_time) != 0:
            raise ValueError(
                f"{o}: parameter `move_time` must be a scalar move time [s]; got shape {jnp.shape(move_time)}"
            )
    else:
        _check_move_time(o, "move_time", move_time, design)  # raises now
        if is_concrete((axis, design.problem)):
            _check_spline_reaches(o, axis, move_time, design)
    lp_axis, lp_time = axis, move_time
    if (traced_time or not is_concrete(axis)) and not _peeked_valid(o, axis, move_time, design):
        # on the LP's inputs: under an eager `vmap`/`grad` an invalid element raises here, before the LP is compiled
        # and solved (12-30 s); under `jit` the LP depends on them, so the check runs whatever the caller keeps.
        # The axis' own checks and the move time's run in one small compiled program (~0.3 s the first time), not
        # one eager program per operation (3-7 s for the first `vmap` in a process)
        lp_axis, lp_time = _guarded_lp_inputs(
            axis,
            jnp.asarray(move_time, dtype=float),
            None if math.isnan(t_min := _fastest(design)) else t_min,  # static: NaN would never equal itself
            traced_time,
            design.problem.axis,
            design.problem.move_time,
        )
    value = minimax_value(_problem(design, lp_axis, lp_time), design.options, tau=jax.lax.stop_gradient(design.worst))
    # a move time far beyond the design's (1e5 s for a 0.8 s design) leaves a residual far below the LP's tolerance,
    # and its solve can end in NaN: an error naming the move time, never a NaN "residual"
    T0 = float(design.command.duration) if is_concrete(design.command.duration) else math.nan
    lost = (
        f"{o}: the minimax LP at this `move_time` returned a non-finite value: a move this much longer than the "
        f"design's ({T0:.6g} s) leaves a residual below what the LP resolves (~0); give a `move_time` closer to the "
        "design's"
    )
    if is_concrete(value) and not traced_time:
        if not np.isfinite(float(value)):
            raise ValueError(lost.replace("at this `move_time`", f"at `move_time` = {float(move_time):.6g} s"))
        return value
    # the axis' own checks came first (a traced frequency of 0, NaN or 1e-300 Hz, a damping ratio of 1.5): the error
    # names the parameter and the mode, not the LP's non-finite value that would follow from it
    return checked(value, checks=[(jnp.isfinite(value), lost)])


def _peeked_valid(owner: str, axis: ModalAxis, move_time, design: MinimaxDesign) -> bool:
    """The traced axis and move time of an eager `jax.vmap` or `jax.grad` checked on the host, before any program is
    compiled (the compiled checks took 3-7 s to refuse the first batch of a process): a `ValueError` naming the
    parameter, the mode and the element of the batch where one is invalid, True where all are valid, False where
    the values are not known before the program runs (under `jit`: the compiled checks decide)."""
    from .. import _compat

    names = ("frequencies", "damping_ratios", "gains")
    peeked = [_compat.peek(getattr(axis, k)) for k in names] + [_compat.peek(move_time)]
    seen = [p for p in peeked if p is not None]
    if len(seen) != len(peeked):
        return False
    sizes = {v.shape[0] for v, batched in seen if batched}
    if len(sizes) != 1 and any(b for _, b in seen):
        return False
    n = sizes.pop() if sizes else None
    f, z, g, T = (
        np.asarray(v, dtype=float) if (b or n is None) else np.broadcast_to(v, (n, *np.shape(v))) for v, b in seen
    )
    lo, hi = FREQUENCY_RANGE_HZ
    t_min = _fastest(design)
    with np.errstate(invalid="ignore"):
        ok = (
            np.all(np.isfinite(f) & (f >= lo) & (f <= hi), axis=-1)
            & np.all(np.isfinite(z) & (z >= 0) & (z < 1), axis=-1)
            & np.all(np.isfinite(g) & (g != 0), axis=-1)
            & np.isfinite(T)
            & (T > 0)
            & (~np.isfinite(t_min) | (T >= t_min * (1 - 1e-9)))
        )
    if np.all(ok):
        return True
    j = int(np.flatnonzero(~np.atleast_1d(ok))[0])
    at = (lambda a: a[j]) if n is not None else (lambda a: a)
    where = f" (element {j} of the batch)" if n is not None else ""
    try:
        ModalAxis(at(f), at(z), at(g))  # the axis' own message: the parameter, the mode, the value
        _check_move_time(owner, "move_time", float(at(T)), design)
    except ValueError as e:
        lead = str(e) if str(e).startswith(f"{owner}:") else f"{owner}: {e}"
        raise ValueError(lead + where) from None
    return False  # a rule above that the constructors do not share: the compiled checks decide


@eqx.filter_jit
def _guarded_lp_inputs(axis, move_time, t_min: float | None, time_checked: bool, mine, mine_time):
    """The LP's `(axis, move_time)` with the checks of `best_residual`'s traced inputs attached, in one program: the
    axis' own checks first (the parameter, the mode), then, where `time_checked`, `move_time` [s] finite, > 0 and
    not below `t_min` [s] (static: one program per design's shortest move); where a check fails, the design's own
    axis and move time `(mine, mine_time)` go to the LP instead (`_valid_or_designs`)."""
    checks = traced_checks(axis)
    if time_checked:
        t = math.nan if t_min is None else t_min
        checks += _traced_time_checks("best_residual", "move_time", move_time, t, "move time")
    safe = _valid_or_designs(axis, move_time, None, checks, mine=mine, mine_time=mine_time)
    return checked(safe, checks=checks)


def _valid_or_designs(axis, move_time, design: MinimaxDesign | None, checks, *, mine=None, mine_time=None):
    """`(axis, move_time)` for the LP: where a traced check fails (an element of a `vmap` batch with a NaN or
    negative frequency, ...), the design's own axis and move time instead, so that the LP of that element converges
    at once rather than iterating on NaN to its limit; the failed check raises on the value all the same. Where
    every check holds the values pass through unchanged (derivatives included)."""
    if not checks:
        return axis, move_time
    ok = all_ok(checks)
    if design is not None:
        mine, mine_time = design.problem.axis, design.problem.move_time

    def pick(x, y):
        return jnp.where(ok, x, jax.lax.stop_gradient(y))

    names = ("frequencies", "damping_ratios", "gains")
    safe = eqx.tree_at(
        lambda a: tuple(getattr(a, k) for k in names),
        axis,
        tuple(pick(getattr(axis, k), getattr(mine, k)) for k in names),
    )
    return safe, pick(jnp.asarray(move_time, dtype=float), mine_time)


#: relative tolerance of `shortest_move_time`'s root on the design's grid (`refine=False`; the LP's own value is
#: solved to 1e-9)
ROOT_RTOL = 1e-8
#: relative tolerance of `shortest_move_time`'s answer re-designed (`refine=True`): a design at the returned time,
#: with the given design's discretisation, leaves a worst residual (fine grid) within this fraction of the target
REDESIGN_RTOL = 5e-3
#: relative tolerance of the root on the design's grid while `refine=True` calibrates its level (`_shortest_time`):
#: each root is checked by a design re-made there (to `REDESIGN_RTOL`), so it need not be finer than a fifth of that
CALIBRATION_RTOL = 1e-3
#: relative tolerance `shortest_move_time(refine=True)` guarantees: where the re-made designs cannot come within
#: `REDESIGN_RTOL`, the closest is returned if within this, else a `ValueError` says the target is not resolved
MEETS_RTOL = 1e-2
#: the absolute tolerance [fraction of the references] to which the minimax LP meets its residual constraints (its
#: relative primal residual, duality gap and dual residual are solved to 1e-9, `minimax_value`)
LP_RESOLUTION = 1e-9
#: the least `target` `shortest_move_time` accepts: a worst residual that the LP resolves to 1 %
#: (`LP_RESOLUTION` / `MEETS_RTOL` = 1e-7: 1e-5 % of the unshaped move's residual). Below it the LP's value is its own
#: rounding, and a root there (26 s, 10 s for a target of 1e-12) would be noise.
TARGET_FLOOR = 1e-7
#: how far `shortest_move_time` looks for the target without a bracket: up to this multiple of the design's time
MAX_EXPANSION = 64.0


def _first_step(T: float, v: float, target: float) -> float:
    """The first move time to try from T [s], whose value is v, towards `target` (no slope known yet): 1 % towards
    it (the secant takes over from the second value on)."""
    return T * (1.01 if v > target else 0.99)


def _interpolated(seen, lo: float, hi: float) -> float | None:
    """Inverse quadratic interpolation (as in Brent's method) of the root of g(T), from the three `(T, g)` of `seen`
    nearest the root (least |g|, distinct g): the T at which the quadratic T(g) through them reaches g = 0, where it
    lies strictly inside the bracket (lo, hi), where `seen` holds values on both sides of the root; else None (the
    caller steps by a secant or bisects). log V is not linear in T over a call's range (its slope halves or doubles
    within 5 %)."""
    if not (any(q[1] > 0 for q in seen) and any(q[1] <= 0 for q in seen)):
        return None  # no bracket: the quadratic extrapolates poorly (its slope changes within 5 % of T)
    pts: list[tuple[float, float]] = []
    for T_k, g_k in sorted(seen, key=lambda p: abs(p[1])):
        if all(g_k != q[1] and T_k != q[0] for q in pts):
            pts.append((T_k, g_k))
        if len(pts) == 3:
            break
    if len(pts) < 3:
        return None
    (t0, g0), (t1, g1), (t2, g2) = pts
    T = (
        t0 * g1 * g2 / ((g0 - g1) * (g0 - g2))
        + t1 * g0 * g2 / ((g1 - g0) * (g1 - g2))
        + t2 * g0 * g1 / ((g2 - g0) * (g2 - g1))
    )
    if not (math.isfinite(T) and lo < T < hi):
        return None
    # a quadratic step far beyond the nearest point (more than twice the secant's): not trusted
    sec = t0 - g0 * (t1 - t0) / (g1 - g0)
    if abs(T - t0) > 2.0 * abs(sec - t0) + 1e-12 * abs(t0):
        return None
    return T


def _root_time(
    value,
    target,
    lo,
    hi,
    start,
    feasible,
    known,
    *,
    rtol: float,
    owner: str,
    iters: int = 60,
    predict_within=0.0,
    first: float | None = None,
):
    """Host root of `value(T) = target` (`value` decreasing in T, > 0): secant steps on log(value) against T, kept
    inside a bracket [lo, hi] that shrinks as the signs of value - target are learnt; `hi` may be inf (the bracket
    then grows by steps of 1.5 up to `MAX_EXPANSION` times `start`). `feasible(T)` False (a move time too short
    for the design's command) counts as above the target. `known`: the `(T, value)` pairs evaluated so far (the
    bracket and the first secant start from them; each evaluation is appended; a single known pair at `start` is its
    value there, so the search steps away from it at once). Stops at |value - target| <= rtol
    target. Returns `(T, value(T))`; with `predict_within` > 0, once an evaluation is within that relative distance
    of the target (log scale), the next interpolated step unevaluated, as `(T, target)` (the caller checks it
    otherwise: `shortest_move_time(refine=True)` re-makes the design there). `first`: the first move time to
    evaluate, where it lies inside the bracket (default: the secant of the known pairs). Forward solves only: no
    derivative program is compiled."""

    def g(v_):
        return math.log(v_ / target)

    for T_k, v_k in known[::-1]:  # a value found before (an earlier call's, `_Memo`) may already meet the goal
        if lo <= T_k <= hi and abs(v_k - target) <= rtol * target:
            return T_k, v_k
    for T_k, v_k in known:
        if v_k > target:
            lo = max(lo, T_k)
        else:
            hi = min(hi, T_k)
    pts = [(T_k, g(v_k)) for T_k, v_k in known[-2:]]  # (T, log(v / target)) of the last two evaluations
    if not (math.isfinite(hi) and lo > 0) and len(known) > 2:  # extrapolating: from the two nearest the target
        pts = sorted(pts + [(T_k, g(v_k)) for T_k, v_k in known[:-2]], key=lambda p: -abs(p[1]))[-2:]
    seen = [(T_k, g(v_k)) for T_k, v_k in known]  # every (T, log(v / target)) known: `_interpolated`
    T = float(start)
    if first is not None and lo < first < hi and all(first != T_k for T_k, _ in known):
        T = float(first)  # the caller's guess
    elif (step := _interpolated(seen, lo, hi)) is not None:
        T = step
    elif len(pts) == 2 and pts[0][1] != pts[1][1]:
        (t0, g0), (t1, g1) = pts
        step = t1 - g1 * (t1 - t0) / (g1 - g0)
        T = step if lo < step < hi else T
    elif len(pts) == 1 and known[-1][0] == T:  # the start's value is known (the design's own): step from it
        if abs(known[-1][1] - target) <= rtol * target:
            return known[-1]
        step = _first_step(T, known[-1][1], target)
        T = step if lo < step < hi else (0.5 * (lo + hi) if math.isfinite(hi) else T)
    best = None
    v = math.nan
    for _ in range(iters):
        if not feasible(T):
            lo = T  # too short for the design's command: above any target
            T = 0.5 * (lo + hi) if math.isfinite(hi) else 0.5 * (lo + float(start))
            continue
        v = float(value(T))
        if not (math.isfinite(v) and v > 0):
            raise ValueError(
                f"{owner}: the minimax LP at move time {T:.6g} s returned the residual {v!r}; give a target closer "
                "to the design's worst residual"
            )
        known.append((T, v))
        if best is None or abs(g(v)) < abs(g(best[1])):
            best = (T, v)
        if abs(v - target) <= rtol * target:
            return T, v
        if v > target:
            lo = T
        else:
            hi = T
        if math.isfinite(hi) and hi - lo <= 1e-12 * hi:
            break
        pts = [*pts[-1:], (T, g(v))]
        seen.append((T, g(v)))
        step = _interpolated(seen, lo, hi)
        step = math.nan if step is None else step
        if math.isnan(step) and len(pts) == 2 and pts[0][1] != pts[1][1]:
            (t0, g0), (t1, g1) = pts
            step = t1 - g1 * (t1 - t0) / (g1 - g0)
        if len(pts) == 1:  # no slope yet
            step = _first_step(T, v, target)
        if math.isfinite(step) and lo < step < hi:
            if abs(g(v)) <= predict_within and len(pts) == 2:
                return step, target  # close enough to trust the interpolated step without its LP
            T = step
        elif math.isfinite(hi):
            T = 0.5 * (lo + hi)
        elif T * 1.5 <= MAX_EXPANSION * float(start):
            T = T * 1.5
        else:
            raise ValueError(
                f"{owner}: the target {target:g} is not reached within {MAX_EXPANSION:g} times the design's move "
                f"time ({MAX_EXPANSION * float(start):.4g} s: worst residual {v:.4g} there); give a larger `target`"
            )
    if best is None or not math.isfinite(hi):
        raise _not_in_bracket(owner, target, v, T)
    return best


def _not_in_bracket(owner: str, target: float, v: float, T: float) -> ValueError:
    """The error of a search that ends with the worst residual `v` at `T` [s], not at `target`."""
    return ValueError(
        f"{owner}: the target {target:g} is not reached within the bracket; the worst residual is {v:.4g} at "
        f"{T:.6g} s; pass a wider `bracket`, or none (it then finds itself)"
    )


def _redesign_options(design: MinimaxDesign, T: float):
    """The discretisation `design_move` picks at move time `T` [s] for a design made by its rule
    (`default_options`: knots per cycle of the highest mode over the move, a starting grid that grows with T),
    else `design`'s own. A design re-made at a longer time with more knots leaves a smaller residual (20 % smaller
    at 1e-6 of the references, 160 instead of 128 knots): `shortest_move_time` calibrates against the design
    `design_move` would make there, its knot cap included (`design.knot_cap`)."""
    o, p = design.options, design.problem
    freqs, u, T0 = np.asarray(p.axis.frequencies), float(np.asarray(p.uncertainty)), float(design.command.duration)
    t_min = _fastest(design)
    for kpc in (6.0, 12.0):  # design_move's rule at a fixed time, and while it searches the shortest time
        mine = default_options(freqs, T0, u, o.jerk, kpc, o.basis, cap=knot_cap(T0, t_min))
        if (mine.n_knots, mine.n_freq) == (o.n_knots, o.n_freq):
            at_T = default_options(freqs, T, u, o.jerk, kpc, o.basis, cap=knot_cap(T, t_min))
            return o._replace(n_knots=at_T.n_knots, n_freq=at_T.n_freq)
    return o


def _redesign(axis, design: MinimaxDesign, T: float) -> MinimaxDesign:
    """A fresh design at move time `T` [s] with the discretisation `design_move` picks there (`_redesign_options`:
    `design`'s own where it keeps its knots; a new knot count runs its slot's compiled LP, `design.knot_slots`) and `design`'s references: its own
    frequency grid, exchanged from the start."""
    return minimax_design(_problem(design, axis, T), _redesign_options(design, T))


def _same_axis(axis, design) -> bool:
    """Whether `axis` is (concretely) the axis `design` was made on: then the LP's value on the design's grid at the
    design's own move time is the design's worst, known without a solve."""
    mine = design.problem.axis
    if not is_concrete((axis, mine)):
        return False
    return all(
        np.array_equal(np.asarray(getattr(axis, k)), np.asarray(getattr(mine, k)))
        for k in ("frequencies", "damping_ratios", "gains")
    )


#: pairs kept per design and axis by `_Memo` (the oldest dropped first)
MEMO_SIZE = 64


class _Memo:
    """What earlier calls of `shortest_move_time` on one design and one axis found, pure functions of the design, the
    axis and the move time: the LP's values on the design's grid `grid` [(T [s], value)] (with the design's options:
    `refine=False`) and `refined` (with the options `design_move` picks at T: `refine=True`), and the designs re-made
    `remade` {T: the re-made design}. A later call with another target starts its bracket, its secant and its level
    from them."""

    def __init__(self):
        self.grid: list[tuple[float, float]] = []
        self.refined: list[tuple[float, float]] = []
        self.remade: dict[float, MinimaxDesign] = {}
        self.on_remade: dict[float, list[tuple[float, float]]] = {}  # the LP's values on a re-made design's grid


def _keep(pairs: list, new) -> None:
    """Add the `(T, value)` pairs `new` to the memo's list `pairs` (the latest `MEMO_SIZE`)."""
    seen = set(pairs)
    pairs += [p for p in new if p not in seen]
    del pairs[:-MEMO_SIZE]


#: `_Memo`s by design (the entry goes with the design) and by the axis' values
_MEMOS: dict[int, dict[bytes, _Memo]] = {}


def _memo(design: MinimaxDesign, axis) -> _Memo:
    key = id(design)
    if key not in _MEMOS:
        _MEMOS[key] = {}
        weakref.finalize(design, _MEMOS.pop, key, None)
    values = b"".join(
        np.asarray(getattr(axis, k), dtype=float).tobytes() for k in ("frequencies", "damping_ratios", "gains")
    )
    return _MEMOS[key].setdefault(values, _Memo())


def _secant_last(known: list, goal: float) -> list:
    """`known` (T, value) pairs reordered for `_root_time`, whose secant starts from the last two: the nearest pair
    on each side of `goal` (the largest T whose value is above it, the least T whose value is at or below it), else
    the two values nearest it."""
    above = [p for p in known if p[1] > goal]
    below = [p for p in known if p[1] <= goal]
    if above and below:
        last = [max(above), min(below)]
    else:
        last = sorted(known, key=lambda p: -abs(math.log(p[1] / goal)))[-2:]
    return [p for p in known if p not in last] + last


def _shortest_time(axis, target, design, lo, hi, start, *, user_bracket: bool, refine: bool) -> float:
    """The shortest move time: `refine=False`, the root of the LP's value on `design`'s grid, `V(T) = target` (to
    `ROOT_RTOL`); `refine=True`, a time at which the design re-made there (`_redesign`: its own frequency exchange,
    the discretisation `design_move` picks) leaves a fine-grid worst within `REDESIGN_RTOL` of the target.

    `refine=True`: each step re-makes the design at the root of the LP's value on the final grid of the known
    design whose fine worst is nearest the target (`design` itself, or one re-made before: `_grid_of`, with the
    knots `design_move` picks at each T) at the level c target, c that design's LP value over its fine worst
    (known without a solve): a design re-made nearby exchanges to nearly the same grid, so the step lands within
    `REDESIGN_RTOL` once or twice. The root starts from the re-made designs' log worst extrapolated in T
    (`_extrapolated`) and stops evaluating within `PREDICT_WITHIN` (`_root_time`); 1-3 forward LPs, each ~1/4 of a
    re-made design. Without a known design of this axis (another axis, a `bracket` that leaves out the design's
    time) the first step is the root on `design`'s grid at its own level. At most `MAX_REDESIGNS` re-made designs;
    the designs and the LP values are kept for later calls (`_Memo`)."""
    o = "shortest_move_time"
    feasible_from = [float(design.command.duration)]  # the design exists there: feasible at and above it

    def feasible(T):
        if T >= feasible_from[0]:
            return True
        try:  # with the knots the LPs take at T (with `refine`, those `design_move` picks there)
            _check_spline_reaches(o, axis, T, design, _redesign_options(design, T) if refine else None)
        except ValueError:
            return False
        feasible_from[0] = T
        return True

    memo = _memo(design, axis)
    own = start == float(design.command.duration) and _same_axis(axis, design)
    # refine=False: the LP on the design's grid with its options; refine=True: on the design's grid with the options
    # `design_move` picks at T (`_redesign_options`: the knots follow T), so that the ratio of the grid's value to a
    # re-made design's fine worst does not jump where the knot count does (4 % on a three-mode axis at 0.82 s)
    pairs = memo.refined if refine else memo.grid
    # the values known so far: an earlier call's within the bracket (`_Memo`), and the design's own value at its own
    # time, known without a solve
    known: list[tuple[float, float]] = [(T_, v_) for T_, v_ in pairs if lo <= T_ <= hi]
    mine = own and (not refine or _redesign_options(design, start) == design.options)
    if mine and (start, float(design.worst)) not in known:
        known.append((start, float(design.worst)))

    on_grid = _grid_of(design, axis, design, None if refine else design.options)

    def root(goal, start_, rtol, predict=0.0, first=None, fn=on_grid, known=known, pairs=pairs):
        # the pairs known are values of the same function: re-used for the bracket and the secant at a new level
        known[:] = _secant_last(known, goal) if len(known) > 1 else known
        try:
            T_, v_ = _root_time(
                fn, goal, lo, hi, start_, feasible, known, rtol=rtol, owner=o, predict_within=predict, first=first
            )
        finally:
            _keep(pairs, known)
        if user_bracket and abs(v_ - goal) > 1e-3 * goal:
            raise _not_in_bracket(o, target, v_, T_)
        return T_, v_

    if not refine:
        return root(target, start, ROOT_RTOL)[0]
    # the re-made designs known: an earlier call's (`_Memo`), and the design itself where it is the one `design_move`
    # makes at its own time (same axis, the options its rule picks there)
    made: dict[float, float] = {T_: float(d_.fine_worst) for T_, d_ in memo.remade.items() if lo <= T_ <= hi}
    if mine:
        made.setdefault(start, float(design.fine_worst))
    for T_, f_ in sorted(made.items()):
        if abs(f_ - target) <= REDESIGN_RTOL * target:
            return T_  # an earlier call's re-made design (or the design itself) meets this target already
    # the closest known so far (an earlier call's re-made design may be the closest this call finds)
    best = min(made.items(), key=lambda p: abs(p[1] - target)) if made else (start, math.inf)
    T = start
    for _ in range(MAX_REDESIGNS):
        # the level c: the grid's value over the fine worst at the known design nearest the target (the ratio moves
        # with T by the re-made designs' own frequency exchange: 1-3 % over the range of a call)
        if made:
            # the LP on the final grid of the known design nearest the target (the design itself or a re-made one),
            # with the knots of each T: a design re-made near it exchanges to nearly the same grid, so the level c,
            # that design's LP value over its fine worst (known without a solve), holds to ~0.5 %; on `design`'s own
            # grid it drifted 1-2 % within 1 % of T
            near = min(made, key=lambda T_: abs(math.log(made[T_] / target)))
            src: MinimaxDesign = memo.remade[near] if near in memo.remade else design
            on_src = _grid_of(src, axis, design)
            ks = memo.on_remade.setdefault(near, [(near, float(src.worst))])
            guess = _extrapolated(made, near, target)
            c = float(src.worst) / made[near]
            T = root(c * target, near, CALIBRATION_RTOL, PREDICT_WITHIN, guess, on_src, ks, ks)[0]
        else:  # no design of this axis known: `design`'s grid at its own level
            c = float(design.worst) / float(design.fine_worst)
            T = root(c * target, T, CALIBRATION_RTOL, PREDICT_WITHIN)[0]
        if T in made:
            break  # the level returns to a time already tried: the re-made designs cannot come closer
        d = _remade(axis, design, memo, T)
        if not d.converged:
            raise ValueError(
                f"{o}: the design re-made at move time {T:.6g} s did not converge (gap {float(d.gap):.1e}); pass "
                "`refine=False` for the root on the design's own grid"
            )
        f = float(d.fine_worst)
        made[T] = f
        if abs(f - target) < abs(best[1] - target):
            best = (T, f)
        if abs(f - target) <= REDESIGN_RTOL * target:
            return T  # the re-made design there meets the target
        if f < target and not feasible(T * (1 - 1e-3)):
            return T  # the shortest move the design's spline makes already leaves less than the target
    if abs(best[1] - target) > MEETS_RTOL * target:
        raise ValueError(
            f"{o}: the target {target:g} is not resolved: the designs re-made at the move times tried leave at best "
            f"{best[1]:.4g} on their fine grids ({100 * (best[1] / target - 1):+.2g} % from the target, at "
            f"{best[0]:.6g} s), not within {100 * MEETS_RTOL:g} %; give a larger `target`, or pass `refine=False` for "
            "the root on the design's own grid"
        )
    return best[0]  # its re-made design comes within MEETS_RTOL of the target


#: `shortest_move_time(refine=True)`'s root on the grid stops evaluating once an LP's value is within this (log scale)
#: of its level: the next interpolated step is re-made at unevaluated (the re-made design checks it; the step's own
#: error is second order, ~0.1 % at 2 %)
PREDICT_WITHIN = 0.02
#: the most designs `shortest_move_time(refine=True)` re-makes in one call (1-2 where its prediction lands)
MAX_REDESIGNS = 6


def _extrapolated(made: dict, near: float, target: float) -> float | None:
    """The move time [s] at which the re-made designs' fine worst `made` {T: f} reaches `target`, extrapolated from
    the known design `near` along the secant of log f to the nearest other at least 0.5 % of T away (over such
    spans the re-made designs' log f is near-linear in T, while the grid's value on the design's fixed grid bends:
    its slope halved or doubled within 5 %; closer than 0.5 % the exchange's own steps, ~1 %, swamp the slope).
    None where no such design is known or the slope is not negative."""
    far = [T_ for T_ in made if abs(T_ - near) >= 5e-3 * near]
    if not far:
        return None
    other = min(far, key=lambda T_: abs(T_ - near))
    slope = math.log(made[near] / made[other]) / (near - other)
    if not slope < 0:
        return None
    T = near + math.log(target / made[near]) / slope
    return min(max(T, near / 1.3), near * 1.3)


def _grid_of(src: MinimaxDesign, axis, design: MinimaxDesign, options=None):
    """T [s] -> the minimax LP's value on the final frequency grid of `src` (with `design`'s references), with the
    discretisation `design_move` picks at T (`_redesign_options`), or `options`."""
    tau = jax.lax.stop_gradient(src.worst)

    def value(T_):
        opts = _redesign_options(design, T_) if options is None else options
        return minimax_value(_problem(src, axis, T_), opts, tau=tau)

    return value


def _remade(axis, design: MinimaxDesign, memo: "_Memo", T: float) -> MinimaxDesign:
    """The design re-made at `T` [s] (`_redesign`), kept in `memo` (its 16 latest)."""
    if T not in memo.remade:
        memo.remade[T] = _redesign(axis, design, T)
        for old_T in list(memo.remade)[:-16]:
            del memo.remade[old_T]
            memo.on_remade.pop(old_T, None)
    return memo.remade[T]


@blas_limited
def shortest_move_time(axis: ModalAxis, target, design: MinimaxDesign, *, bracket=None, refine: bool = True):
    """The least move time [s] at which the minimax design on `axis` reaches the worst residual `target` (a
    fraction of the references; e.g. `design.fine_worst`, the worst of the command itself on the fine grid;
    `design_move`'s table states a row's residual as the drive executes it, which differs by the drive's sampling:
    at 1 kHz, 0.5 % at most on the benchmark's 1-3 mode axes up to 27 Hz, 2.4 % on a 6-mode axis up to 60 Hz).

    - `refine=True` (default): the time at which a design *re-made there* with the discretisation `design_move`
      picks at that time (`minimax_design(problem at T, options)`: its knots follow T) leaves a worst residual on
      its fine grid within `REDESIGN_RTOL` = 0.5 % of `target` (where the re-made designs cannot get that close,
      the closest found, within `MEETS_RTOL`). The time to re-make at is the root of the LP's value on `design`'s
      grid (with the knots of that time) at a level c `target`, c the grid's value over the fine worst of the
      known design nearest the target; the root starts from the re-made designs' own log worst extrapolated in
      T. A warm call usually re-makes one design (2 where its level is off by the re-made designs' own exchange,
      ~1 %) after 1-3 forward LPs; the designs re-made and the LP values found are kept for later calls with
      the same design and axis.
    - `refine=False`: the root on `design`'s own frequency grid at the level `target` itself, to a relative
      `ROOT_RTOL` = 1e-8 of the LP's value (`best_residual(axis, T, design) = target`). Exact for that grid; a
      design re-made at that time exchanges its own grid and lands 1-4 % above the target.

    Differentiable with respect to the axis by the implicit function theorem (`jax.grad`, `jax.jvp` called
    eagerly: the root is found on concrete values, so not inside `jax.jit`): the derivative of the root on
    `design`'s grid, at the level found (with `refine`, the calibration held fixed; finite differences of the
    refined answer also see the calibration move within its 0.5 %: compare with `refine=False`). `bracket`: the
    search interval [s] (default: none: the search starts at the design's own move time and finds its bracket,
    from the shortest feasible move up to `MAX_EXPANSION` = 64 times the design's time); a `bracket` must hold
    the root, and only feasible move times (the limits must allow the distance at its lower end). Forward LP
    solves only (secant steps; no derivative program is compiled until you differentiate) and no recompilation:
    the design's discretisation is kept, and the move time is an argument.

    Raises `ValueError` at the call for a `design` that is not a `MinimaxDesign`, a `target` that is not finite
    and > 0 or lies below what the LP resolves (`TARGET_FLOOR` = 1e-7 of the references: the LP meets its
    constraints to about `LP_RESOLUTION` = 1e-9, so a smaller target is rounding), a traced `target`, and a
    `bracket` that is not `(lo, hi)` with 0 < lo < hi or whose lower end is shorter than the shortest feasible
    move (the default bracket starts there instead); under `jax.jit` or `jax.vmap` (the root is found on the host)
    and for an invalid axis under `jax.grad` (its parameter and mode named, before any solve). With `refine=True`,
    where no re-made design comes within `MEETS_RTOL` = 1 % of the target, a `ValueError` says the target is not
    resolved (never a time whose design misses it)."""
    o = "shortest_move_time"
    _check_design(o, design)
    _check_axis(o, axis, design)
    check_real("target", target, "", o)
    if not is_concrete(target):
        raise ValueError(
            f"{o}: parameter `target` must be a concrete number (a worst residual, as a fraction of the references), "
            "not a traced value: the shortest move time is differentiable with respect to the axis only; "
            "differentiate the axis' arrays, or call it outside jax.jit/jax.vmap"
        )
    if not (is_concrete(target) and np.ndim(target) == 0 and math.isfinite(float(target)) and float(target) > 0):
        raise ValueError(
            f"{o}: parameter `target` (a worst residual, as a fraction of the references) must be a finite scalar "
            f"> 0; got {target!r}"
        )
    if float(target) < TARGET_FLOOR:
        raise ValueError(
            f"{o}: parameter `target` = {float(target):g} lies below what the minimax LP resolves: it meets its "
            f"residual constraints to about {LP_RESOLUTION:g} of the references, so a worst residual below "
            f"{TARGET_FLOOR:g} ({100 * TARGET_FLOOR:g} % of the unshaped move's) cannot be told from rounding to "
            f"{100 * MEETS_RTOL:g} %; give `target` >= {TARGET_FLOOR:g}"
        )
    if not isinstance(refine, bool | np.bool_):
        raise ValueError(f"{o}: parameter `refine` must be True or False; got {refine!r}")
    T0 = float(design.command.duration)
    t_min = _fastest(design)
    if bracket is None:
        lo, hi = (t_min if math.isfinite(t_min) else 0.0), math.inf
    else:
        check_real("bracket", bracket, "s", o)
        try:
            lo, hi = (float(x) for x in bracket)
        except (TypeError, ValueError):
            raise ValueError(f"{o}: parameter `bracket` must be two move times (lo, hi) [s]; got {bracket!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise ValueError(f"{o}: parameter `bracket` must be (lo, hi) with 0 < lo < hi [s]; got {bracket!r}")
        _check_move_time(o, "bracket", lo, design, "lower end of the bracket")
    start = T0 if (lo < T0 < hi) else 0.5 * (lo + hi)
    leaves, treedef = jax.tree_util.tree_flatten(axis)
    args = (float(target), treedef, design, float(lo), float(hi), start, bracket is not None, bool(refine))
    return _shortest(tuple(leaves), *args)


def _concrete_axis(axis) -> None:
    """The axis on which the root search runs: concrete values (the search is on the host), checked as at
    construction. Under `jax.grad`/`jax.jvp` called eagerly the search sees the primal values, so an invalid
    traced value (a NaN or negative frequency, a damping ratio of 1.5) is named here, before any LP is solved;
    under `jax.jit` or `jax.vmap` there are no values to search with."""
    o = "shortest_move_time"
    if not is_concrete(axis):
        raise ValueError(
            f"{o}: parameter `axis` is traced by jax.jit or jax.vmap: the shortest move time is a root found on "
            "the host from concrete values, so it cannot be compiled or batched. Call it outside jax.jit (for a "
            "batch of axes, a Python loop); jax.grad and jax.jvp called eagerly work (implicit derivative)"
        )
    try:
        recheck(axis)
    except ValueError as e:
        raise ValueError(f"{o}: {e}") from None


def _shortest(leaves, target, treedef, design, lo, hi, start, user_bracket, refine):
    @jax.custom_jvp
    def f(leaves):
        axis = jax.tree_util.tree_unflatten(treedef, leaves)
        _concrete_axis(axis)
        return jnp.asarray(
            _shortest_time(axis, target, design, lo, hi, start, user_bracket=user_bracket, refine=refine)
        )

    @f.defjvp
    def f_jvp(primals, tangents):
        (lv,), (tv,) = primals, tangents
        T = f(lv)

        def V(lv_, T_):
            return best_residual(jax.tree_util.tree_unflatten(treedef, lv_), T_, design)

        _, dV_theta = jax.jvp(lambda l_: V(l_, T), (lv,), (tv,))
        dV_T = jax.grad(lambda T_: V(lv, T_))(T)
        return T, -dV_theta / dV_T

    return f(leaves)
