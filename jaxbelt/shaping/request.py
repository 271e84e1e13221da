"""Validate: `design_move`'s arguments checked, by name, into one `MoveRequest` (the first stage of the pipeline),
with every quantity the later stages share derived from them once.

Every refusal names the parameter and its valid range; a damping range expands the axis the residuals are judged on
(each mode once per damping sample). The later stages take their data from the request and never re-enter these
checks: the axes are made from the checked arrays (`far_modes.modes_axis`), the minimax LP is set up here (its
programs start compiling, `far_modes.prepare_lp`, queued first on the minimax worker, `jaxbelt.shaping.worker`), and
the references of "% of the unshaped move" are computed here.
"""

import dataclasses
import math
from typing import Any

import numpy as np

from .._checks import check_positive, check_range
from ..models.axis import ModalAxis
from . import worker
from .bands import band_factors
from .design import SURELY_FEASIBLE as SURELY_FEASIBLE
from .design import knot_cap
from .far_modes import LPSetup, lp_setup, modes_axis, prepare_lp
from .hull import INTERPOLATIONS
from .moves import (
    PiecewiseMove,
    _trapezoid_move,
    check_move_limits,
    fastest_move,
    fastest_time,
)
from .residual import closed_curve
from .shapers import SHAPERS

#: damping samples per mode with `design_move(..., damping=(lo, hi))`: the worst residual of a design over the damping
#: range lies within 2 % of the worst over these samples (1.9 % measured on a 25-sample grid of (0.01, 0.1) for a
#: 7.3 Hz minimax design, whose residual the LP equalises over the samples; tests/test_damping_range.py)
N_DAMPING = 5


#: the damping range `damping="unknown"` stands for, and the damping ratio the classic shapers are then designed at
#: (Klipper's default for an axis whose damping is not measured)
UNKNOWN_DAMPING = (0.01, 0.1)


UNKNOWN_SHAPER_DAMPING = 0.1


#: the highest setpoint rate `design_move` models [Hz]: every candidate is sampled at it (a 10 s move: 1e7 samples)
MAX_RATE_HZ = 1e6


def _check_axis(axis) -> None:
    """A `TypeError` naming `axis` unless it is a `ModalAxis`."""
    if not isinstance(axis, ModalAxis):
        raise TypeError(
            f"design_move: `axis` must be a jaxbelt.ModalAxis (or BeltPlatform(...).to_axis()); got "
            f"{type(axis).__name__}"
        )


def _check_inputs(distance, move_time, v_max, a_max, j_max, uncertainty, include):
    """The move's arguments checked by name: `(distance [m], the time-optimal move's time [s])`."""
    o = "design_move"
    check_move_limits(o, distance, v_max, a_max, j_max)
    d = float(np.asarray(distance))
    check_range("uncertainty", uncertainty, lo=0.0, hi=0.9, hi_open=True, owner=o)
    valid = ("minimax", *SHAPERS, "pseudo-polynomial", "unshaped")
    if isinstance(include, str) or not all(isinstance(n, str) for n in include):
        raise TypeError(f"{o}: parameter `include` must be a tuple of candidate names out of {valid}; got {include!r}")
    unknown = [n for n in include if n not in valid]
    if unknown or not include:
        raise ValueError(
            f"{o}: parameter `include` must name at least one candidate out of {valid}; got {tuple(include)!r}"
            + (f" ({', '.join(map(repr, unknown))} unknown)" if unknown else "")
        )
    if move_time is None and not any(n in SHAPERS for n in include):
        raise ValueError(
            f"{o}: with `move_time` None the shortest time is the one at which the minimax design reaches the best "
            f"classic shaper's residual, so parameter `include` must name at least one of {SHAPERS}; got "
            f"{tuple(include)!r} (or give `move_time`)"
        )
    t_min = fastest_time(d, v_max, a_max, j_max)
    if move_time is not None:
        check_positive("move_time", move_time, "s", o)
        if float(move_time) < t_min * (1 - 1e-12):
            raise ValueError(
                f"{o}: parameter `move_time` = {float(move_time):g} s is shorter than the limits allow: the shortest "
                f"rest-to-rest move of {d:g} m with v_max = {float(v_max):g}, a_max = {float(a_max):g}"
                + (f", j_max = {float(j_max):g}" if j_max is not None else "")
                + f" takes {t_min:.6g} s"
            )
    return d, t_min


def _check_execution(rate_hz, interpolation) -> float:
    """`design_move`'s drive: its setpoint rate [Hz] (finite, > 0) and interpolation; a `ValueError` naming them."""
    check_positive("rate_hz", rate_hz, "Hz", "design_move")
    if not float(rate_hz) <= MAX_RATE_HZ:
        raise ValueError(
            f"design_move: parameter `rate_hz` must lie in (0, {MAX_RATE_HZ:g}] Hz (a drive's setpoint rate); got "
            f"{rate_hz!r}"
        )
    if not (isinstance(interpolation, str) and interpolation in INTERPOLATIONS):
        raise ValueError(
            f"design_move: parameter `interpolation` must be one of {INTERPOLATIONS} (position setpoints, linear "
            f"between them); got {interpolation!r}"
        )
    return float(rate_hz)


def _check_resolution(resolution, distance: float) -> float | None:
    """`design_move`'s `resolution` [m]: None, or finite with 0 < resolution <= |distance| (a drive's step or
    encoder count in the axis' length units); a `ValueError` naming it otherwise."""
    if resolution is None:
        return None
    msg = (
        f"design_move: parameter `resolution` (the drive's position step [m]) must be None or a finite number in "
        f"(0, {abs(distance):g}] (at most the distance); got {resolution!r}"
    )
    if isinstance(resolution, bool | np.bool_ | str | bytes) or np.ndim(resolution) != 0:
        raise ValueError(msg)
    try:
        q = float(resolution)
    except (TypeError, ValueError):
        raise ValueError(msg) from None
    if not (math.isfinite(q) and 0.0 < q <= abs(distance)):
        raise ValueError(msg)
    return q


def _check_damping(damping) -> tuple[float, float] | None:
    """`design_move`'s `damping` as `(lo, hi)`, or None; a `ValueError` naming it otherwise."""
    if damping is None:
        return None
    if isinstance(damping, str) and damping == "unknown":
        return UNKNOWN_DAMPING
    msg = (
        "design_move: parameter `damping` must be None, 'unknown' or (lo, hi) with 0 <= lo <= hi < 1 (damping "
        f"ratios); got {damping!r}"
    )
    if isinstance(damping, str | bytes) or not hasattr(damping, "__len__") or len(damping) != 2:
        raise ValueError(msg)
    try:
        lo, hi = (float(x) for x in damping)
    except (TypeError, ValueError):
        raise ValueError(msg) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi < 1.0):
        raise ValueError(msg)
    return lo, hi


def damping_samples(lo: float, hi: float, n: int = N_DAMPING) -> np.ndarray:
    """The damping ratios a range [lo, hi] is judged at: `n` samples including both ends, spaced geometrically when
    lo > 0 (the residual of a lightly damped mode changes with log zeta), evenly from 0; one when lo == hi."""
    if hi == lo:
        return np.array([lo])
    return np.geomspace(lo, hi, n) if lo > 0 else np.linspace(lo, hi, n)


def _check_range(x_min, x_max, d: float) -> tuple[float, float] | None:
    """`design_move`'s position range `(x_min, x_max)` [m, from the start], None where neither is given; a
    `ValueError` naming them unless x_min <= min(0, d) and x_max >= max(0, d) (the range holds the start and the
    end)."""
    if x_min is None and x_max is None:
        return None
    lo = -math.inf if x_min is None else float(x_min)
    hi = math.inf if x_max is None else float(x_max)
    if math.isnan(lo) or math.isnan(hi) or not (lo <= min(0.0, d) and hi >= max(0.0, d)):
        raise ValueError(
            f"design_move: parameters `x_min`, `x_max` [m, positions from the start] must hold the start 0 and the "
            f"end {d:g}: x_min <= {min(0.0, d):g} and x_max >= {max(0.0, d):g}; got x_min={x_min!r}, x_max={x_max!r}"
        )
    return lo, hi


@dataclasses.dataclass(frozen=True)
class MoveRequest:
    """`design_move`'s arguments, checked (`validate`).

    - `user`: the user's axis; `axis`: the axis every residual is judged on (with a damping range, each mode of
      `user` once per damping sample, `per` copies each); `nominal`: the axis the classic shapers and the
      pseudo-polynomials are designed on (the user's, or at Klipper's 0.1 with `damping="unknown"`);
    - `distance` [m], `move_time` [s] or None, `t_min` [s] and `ref_cmd`: the time-optimal unshaped move's time and
      command (what a planner runs without shaping, `fastest_move`); `ref` [m]: per mode of `axis`, the worst
      residual over the band that this move leaves (every row's reference), and `ref_nominal` the same on `nominal`
      where the pseudo-polynomials are designed there with damping copies (else `ref`); `unshaped`: at a given
      move time, the gentlest trapezoid (S-curve) that ends there (the table's unshaped row), else None; `v_max`, `a_max`,
      `j_max`; `uncertainty`; `band`: the frequency factors of the band;
    - `include`, `progress`; `auto` (`smooth="auto"`), `smooth` (the first minimax design is the spline),
      `smooth_arg` (as given), `certify_rtol`; `damping`: the range or None; `rate_hz`: the drive's setpoint
      rate [Hz], `interpolation` between the setpoints; `resolution`: its position step [m] or None;
      `x_range`: the travel [m] or None;
    - `lp`: at a given move time with "minimax" in `include`, the minimax LP's setup (`far_modes.lp_setup`: the
      modes it leaves out, refused at once where it would weigh none; its options), else None; `prepared`: the
      future of its programs' preparation (`far_modes.prepare_lp`, queued first on the minimax worker where the
      smooth design is surely feasible; `minimax_solve.solving` waits for it), else None."""

    user: ModalAxis
    axis: ModalAxis
    nominal: ModalAxis
    per: int
    distance: float
    move_time: float | None
    t_min: float
    ref_cmd: PiecewiseMove
    ref: np.ndarray
    ref_nominal: np.ndarray
    unshaped: PiecewiseMove | None
    v_max: float
    a_max: float
    j_max: float | None
    uncertainty: float
    band: np.ndarray
    include: tuple
    progress: bool
    auto: bool
    smooth: bool
    smooth_arg: Any
    certify_rtol: float | None
    damping: tuple[float, float] | None
    rate_hz: float
    interpolation: str
    resolution: float | None
    x_range: tuple[float, float] | None
    lp: LPSetup | None
    prepared: Any = None

    @property
    def limits(self):
        """`(v_max, a_max, j_max)`."""
        return (self.v_max, self.a_max, self.j_max)

    @property
    def clearly(self) -> bool:
        """A given move time well above the time-optimal move's: the smooth design is surely feasible there."""
        return self.move_time is not None and self.move_time >= SURELY_FEASIBLE * self.t_min


def _check_smooth(smooth, progress, certify_rtol, j_max) -> float | None:
    """`design_move`'s `smooth`, `progress` and `certify_rtol` checked by name; `certify_rtol` as a float or None."""
    auto = isinstance(smooth, str) and smooth == "auto"
    if not (auto or isinstance(smooth, bool | np.bool_)):
        raise ValueError(f"design_move: parameter `smooth` must be True, False or 'auto'; got {smooth!r}")
    if not isinstance(progress, bool | np.bool_):
        raise TypeError(f"design_move: parameter `progress` must be True or False; got {progress!r}")
    if certify_rtol is None:
        return None
    if not auto and bool(smooth):
        raise ValueError(
            "design_move: `certify_rtol` needs `smooth=False` or 'auto' (the continuous certificate bounds the "
            "steps design, which 'auto' then adds beside the smooth one; the spline's multipliers bound next to "
            f"nothing); got certify_rtol={certify_rtol!r} with smooth={smooth!r}"
        )
    if isinstance(certify_rtol, bool) or not isinstance(certify_rtol, int | float | np.floating | np.integer):
        raise ValueError(f"design_move: parameter `certify_rtol` must be a number in (0, 1); got {certify_rtol!r}")
    if not (math.isfinite(float(certify_rtol)) and 0.0 < float(certify_rtol) < 1.0):
        raise ValueError(f"design_move: parameter `certify_rtol` must lie in (0, 1); got {certify_rtol!r}")
    if j_max is not None:
        raise ValueError(
            "design_move: `certify_rtol` needs `j_max=None` (the continuous certificate bounds the steps design, "
            f"whose jerk is unbounded; with a jerk limit the design has ramps); got certify_rtol={certify_rtol!r} "
            f"with j_max={j_max!r}"
        )
    return float(certify_rtol)


def _judged_axes(axis: ModalAxis, damping, damp):
    """`(axis judged on, nominal axis, damping copies per mode)` for the damping argument `damping` (checked: `damp`).

    With a range, the axis judged on holds each mode of `axis` once per damping sample (`damping_samples`; frequency
    and gain kept), mode by mode: the copies of mode i are i * n ... (i + 1) * n - 1."""
    if damp is None:
        return axis, axis, 1
    zs = np.asarray(axis.damping_ratios, dtype=float)
    if not isinstance(damping, str) and (np.any(zs < damp[0]) or np.any(zs > damp[1])):
        raise ValueError(
            f"design_move: parameter `damping` {damp} must contain the axis' own damping ratios "
            f"{np.round(zs, 6).tolist()} (the classic shapers are designed at them): widen the range, or give "
            "damping='unknown' (0.01-0.1, the shapers at 0.1)"
        )
    z = np.asarray(damping_samples(*damp), dtype=float)
    n = z.size
    f, g = np.asarray(axis.frequencies, dtype=float), np.asarray(axis.gains, dtype=float)
    judged = modes_axis(axis, np.repeat(f, n), np.tile(z, axis.n_modes), np.repeat(g, n))
    if isinstance(damping, str):  # "unknown": Klipper's practice
        return judged, modes_axis(axis, f, np.full(axis.n_modes, UNKNOWN_SHAPER_DAMPING), g), n
    return judged, axis, n


def validate(axis, distance, move_time, *, v_max, a_max, j_max, uncertainty, include, progress, smooth, certify_rtol,
             damping, rate_hz, interpolation, x_min, x_max, resolution=None) -> MoveRequest:  # fmt: skip
    """`design_move`'s arguments checked by name (see its docstring) into a `MoveRequest`."""
    _check_axis(axis)
    d, t_min = _check_inputs(distance, move_time, v_max, a_max, j_max, uncertainty, include)
    rtol = _check_smooth(smooth, progress, certify_rtol, j_max)
    damp = _check_damping(damping)
    rate = _check_execution(rate_hz, interpolation)
    x_range = _check_range(x_min, x_max, d)
    step = _check_resolution(resolution, d)
    judged, nominal, per = _judged_axes(axis, damping, damp)
    auto = isinstance(smooth, str)
    u = float(uncertainty)
    T = None if move_time is None else float(move_time)
    j = None if j_max is None else float(j_max)
    lp = prepared = None
    if "minimax" in include and T is not None:  # the modes the LP leaves out: refused here where it keeps none
        # the spline's knots capped except near the time-optimal move (`design.knot_cap`)
        lp = lp_setup(judged, T, u, j, True, auto or bool(smooth), per, cap=knot_cap(T, t_min))
        if T >= SURELY_FEASIBLE * t_min:  # first in the minimax worker: traced there while the caller goes on (the
            # reference, the candidates), each compiled in the compile threads while the next is traced
            prepared = worker.submit(prepare_lp, lp, d, float(v_max), float(a_max), j, u, T)
    ref_cmd, band = fastest_move(d, float(v_max), float(a_max), j), band_factors(u)
    both = per > 1 and "pseudo-polynomial" in include  # the pseudo-polynomials' references at the nominal damping
    curves = [closed_curve(axis, ref_cmd, band) for axis in (judged, nominal)[: 1 + both]]
    ref, ref_nominal = (np.max(np.asarray(curves[k]), axis=1) for k in (0, -1))
    return MoveRequest(
        user=axis,
        axis=judged,
        nominal=nominal,
        per=per,
        distance=d,
        move_time=T,
        t_min=t_min,
        ref_cmd=ref_cmd,
        ref=ref,
        ref_nominal=ref_nominal,
        unshaped=None if T is None else _trapezoid_move(d, T, float(v_max), float(a_max), j),
        v_max=float(v_max),
        a_max=float(a_max),
        j_max=j,
        uncertainty=u,
        band=band,
        include=tuple(include),
        progress=bool(progress),
        auto=auto,
        smooth=auto or bool(smooth),
        smooth_arg=smooth,
        certify_rtol=rtol,
        damping=damp,
        rate_hz=rate,
        interpolation=interpolation,
        resolution=step,
        x_range=x_range,
        lp=lp,
        prepared=prepared,
    )
