"""Measured values of Moon & Wickert (1997) and the identification of the model's unknowns.

The paper gives the test stand's geometry and run-out (Sec. 2) and the measured jumps
(Sec. 2, Figs. 2-3), but not the belt tension (hence the transverse wave speed $v_t$), the
damping, nor which pulley the sensor sits at, the travel direction and the sign of the run-out
phase. `calibrate` identifies $v_t$, the per-mode damping ratios and optionally $v_l$ by
Levenberg-Marquardt (`optimistix`) on the four measured jump speeds (and optionally the jump
amplitudes), for a given choice of the discrete unknowns (`layout_choices`, `with_layout`).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..._checks import check_int, is_concrete
from ..._guard import reraise_checks
from ..._threads import blas_limited
from .harmonic import check_harmonics, fold_speeds, jumps
from .model import NonlinearBelt

__all__ = [
    "Measurement",
    "MEASUREMENTS",
    "calibrate",
    "Calibration",
    "jump_residuals",
    "model_fold_speeds",
    "two_mode",
    "MODE1_RANGE",
    "MODE2_RANGE",
]


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One measured value: `quantity`, `value` [SI], `tolerance` (reading uncertainty) [SI], `source`."""

    quantity: str
    value: float
    tolerance: float
    source: str


#: Measured values (peak-to-peak displacements 1 cm from the driven pulley; speeds of the jumps).
#: The speed tolerances are the reading uncertainty of "near 8.9 m/s"; amplitudes are read to 0.01 mm.
MEASUREMENTS: tuple[Measurement, ...] = (
    Measurement("up_jump_speed", 8.9, 0.15, "Moon & Wickert (1997), Sec. 2 and Fig. 3(a)"),
    Measurement("up_jump_pp_before", 1.98e-3, 0.01e-3, "Moon & Wickert (1997), Sec. 2 and Fig. 3(a)"),
    Measurement("up_jump_pp_after", 0.57e-3, 0.01e-3, "Moon & Wickert (1997), Sec. 2 and Fig. 3(a)"),
    Measurement("down_jump_speed", 8.5, 0.15, "Moon & Wickert (1997), Sec. 2 and Fig. 3(b)"),
    Measurement("down_jump_pp_before", 0.52e-3, 0.01e-3, "Moon & Wickert (1997), Sec. 2 and Fig. 3(b)"),
    Measurement("down_jump_pp_after", 1.51e-3, 0.01e-3, "Moon & Wickert (1997), Sec. 2 and Fig. 3(b)"),
    Measurement("mode2_band_low", 15.7, 0.2, "Moon & Wickert (1997), Sec. 2 (second mode)"),
    Measurement("mode2_band_high", 16.1, 0.2, "Moon & Wickert (1997), Sec. 2 (second mode)"),
    Measurement("runout_drive_pp", 0.71e-3, 0.0, "Moon & Wickert (1997), Sec. 2"),
    Measurement("runout_idle_pp", 0.42e-3, 0.0, "Moon & Wickert (1997), Sec. 2"),
    Measurement("runout_phase_deg", 240.0, 0.0, "Moon & Wickert (1997), Sec. 2 (sign not stated)"),
)


def measured(quantity: str) -> float:
    """The measured value of `quantity` (see `MEASUREMENTS`)."""
    for m in MEASUREMENTS:
        if m.quantity == quantity:
            return m.value
    raise ValueError(f"unknown measured quantity {quantity!r}; known: {[m.quantity for m in MEASUREMENTS]}")


def _speed_targets():
    """(measured fold speeds [m/s], their tolerances): mode 1 down/up jump, mode 2 band low/high."""
    names = ("down_jump_speed", "up_jump_speed", "mode2_band_low", "mode2_band_high")
    m = {x.quantity: x for x in MEASUREMENTS}
    return jnp.array([m[q].value for q in names]), jnp.array([m[q].tolerance for q in names])


def _amplitude_targets():
    # order of Jumps (ascending speed): index 0 = decreasing sweep's jump, 1 = increasing sweep's jump
    before = jnp.array([measured("down_jump_pp_before"), measured("up_jump_pp_before")])
    after = jnp.array([measured("down_jump_pp_after"), measured("up_jump_pp_after")])
    return before, after


#: speed ranges [m/s] that hold the first- and second-mode folds of the belt of the test stand
MODE1_RANGE, MODE2_RANGE = (7.5, 10.5), (14.0, 19.0)
_MODE2_POINTS = 400  # continuation points for MODE2_RANGE (the second-mode curve bends far)
_REL_PP = 0.10  # amplitude residuals: 10 % of the measured value


def two_mode(belt: NonlinearBelt) -> NonlinearBelt:
    """`belt` with `n_modes=2` (the smallest model that has the second-mode resonance)."""
    if belt.n_modes == 2:
        return belt
    return NonlinearBelt(
        span=belt.span,
        wave_speed=belt.wave_speed,
        v_l=belt.v_l,
        pulley_radii=belt.pulley_radii,
        runout=belt.runout,
        phase=belt.phase,
        damping=belt.damping,
        n_modes=2,
        sensor_pulley=belt.sensor_pulley,
        travel=belt.travel,
    )


def model_fold_speeds(belt: NonlinearBelt, n_harmonics: int = 3):
    """Fold speeds [m/s] of the two-mode model of `belt` that the measurements name, shape (4,):
    first mode (lower, upper fold; a decreasing sweep jumps up at the lower one, an increasing
    sweep jumps down at the upper one), then second mode (lower, upper). NaN where the model has
    no such fold. Differentiable in every array field of `belt`."""
    b = two_mode(belt)
    f1 = fold_speeds(b, MODE1_RANGE, n_harmonics, 2, throw=False)
    f2 = fold_speeds(b, MODE2_RANGE, n_harmonics, 2, max_points=_MODE2_POINTS, throw=False)
    return jnp.concatenate([f1, f2])


def jump_residuals(belt: NonlinearBelt, n_harmonics: int = 3, *, amplitudes: bool = False):
    """Weighted residuals (model - measured) / tolerance of the four measured jump speeds (first
    mode 8.5 and 8.9 m/s, second-mode band 15.7-16.1 m/s, `MEASUREMENTS`) and, with `amplitudes`,
    of the first-mode peak-to-peak before/after each jump / (10 % of the measured value).
    Differentiable in `belt`; a missing fold gives a large finite residual (1e3)."""
    V, sig = _speed_targets()
    r = [(model_fold_speeds(belt, n_harmonics) - V) / sig]
    if amplitudes:
        j = jumps(belt, MODE1_RANGE, n_harmonics, 2, throw=False)
        before, after = _amplitude_targets()
        r += [(j.pp_before - before) / (_REL_PP * before), (j.pp_after - after) / (_REL_PP * after)]
    r = jnp.concatenate(r)
    return jnp.where(jnp.isfinite(r), r, 1e3)


class Calibration(eqx.Module):
    """Result of `calibrate`: the identified `belt`, the weighted residuals `residuals`, `cost`
    (half the sum of squares), the model's four `fold_speeds` [m/s] (as `model_fold_speeds`) and
    the solver `success`; `message` says why it failed and what to do ("" on success; a failure is also
    warned about, `RuntimeWarning`)."""

    belt: NonlinearBelt
    residuals: jnp.ndarray
    cost: jnp.ndarray
    fold_speeds: jnp.ndarray
    success: jnp.ndarray
    message: str = eqx.field(static=True, default="")


_FREE = ("wave_speed", "damping", "v_l")


@functools.lru_cache(maxsize=64)
def _log_problem(free: tuple, shapes: tuple, n_harmonics: int, amplitudes: bool):
    """`(build, residuals)` of `calibrate`'s least-squares problem in the logs of the `free` fields:
    the same two functions for the same problem, so that optimistix's compiled solve (keyed by the
    function it is given) is reused by every later call instead of compiled again (~15 s)."""
    sizes = [int(np.prod(sh)) for sh in shapes]

    def build(p, b):  # one flat vector of logs -> the belt
        parts = jnp.split(p, np.cumsum(sizes)[:-1])
        return eqx.tree_at(
            lambda bb: [getattr(bb, f) for f in free], b, [jnp.exp(x).reshape(sh) for x, sh in zip(parts, shapes)]
        )

    def residuals(p, b):
        return jump_residuals(build(p, b), n_harmonics, amplitudes=amplitudes)

    return build, residuals


@blas_limited
def calibrate(
    belt: NonlinearBelt | None = None,
    *,
    free=("wave_speed", "damping"),
    amplitudes: bool = False,
    n_harmonics: int = 3,
    max_steps: int = 40,
) -> Calibration:
    """Identify the parameters named in `free` (any of `wave_speed`, `damping`, `v_l`) from the
    measured jumps of Moon & Wickert (1997), Sec. 2, by Levenberg-Marquardt
    (`optimistix.LevenbergMarquardt`) in log coordinates (positive by construction).

    The residuals are those of `jump_residuals`: the four measured jump speeds (first mode 8.5 /
    8.9 m/s, second-mode band 15.7 / 16.1 m/s) weighted by their reading tolerances, computed on
    the two-mode model (the first mode alone has no second-mode band); `damping` is fitted per
    mode (give it as a 2-array, or a scalar to fit one ratio for both). The Jacobian comes from
    the implicit differentiation of the folds (reverse mode). From the default belt's start the
    fit takes about 8 Levenberg-Marquardt steps. The solve is compiled once per problem (`free`,
    the shapes of those fields, `n_harmonics`, `amplitudes`, `max_steps`): a later call of the same
    problem, from any start, reuses it (about 5 s on 2 CPU cores, against about 35 s for the first).

    - With the default `free`, $v_l$ stays at the paper's 50 and the fit is the default of
      `NonlinearBelt` ($v_t$ = 37.94 m/s, $\\xi$ = (0.01219, 0.02713)): folds 8.61 / 8.90 m/s and
      15.59 / 16.11 m/s.
    - Freeing `v_l` too (four unknowns, four speeds) meets all four speeds exactly, but at
      $v_l \\approx 193$ (against the paper's $v_l \\approx 50$) and with still smaller jump amplitudes.
    - `amplitudes=True` adds the first-mode peak-to-peak values before and after each jump. They
      are not reachable by this model: 1 cm from a pulley the mode shape is $\\approx 0.05$ of its
      peak, so the modal part of the measured 1.98 mm would need a mid-span amplitude the measured
      fold speeds exclude (the amplitudes at a fold are set by how far the fold lies above the
      crossing, i.e. by the fold speeds themselves).
    """
    o = "calibrate"
    belt = NonlinearBelt() if belt is None else belt
    if not isinstance(belt, NonlinearBelt):
        raise TypeError(f"{o}: parameter `belt` must be a NonlinearBelt (or None); got {type(belt).__name__}")
    if isinstance(free, str) or not isinstance(free, tuple | list) or not free:
        raise ValueError(f"{o}: parameter `free` must be a non-empty tuple of names among {_FREE}; got {free!r}")
    for f in free:
        if f not in _FREE:
            raise ValueError(f"{o}: parameter `free` may name {_FREE}; got {f!r}")
    free = tuple(free)
    if len(set(free)) != len(free):
        raise ValueError(f"{o}: parameter `free` names a field twice; got {free!r}")
    if not isinstance(amplitudes, bool):
        raise TypeError(f"{o}: parameter `amplitudes` must be True or False; got {amplitudes!r}")
    n_harmonics = check_harmonics(o, n_harmonics, belt.n_modes if isinstance(belt, NonlinearBelt) else 1)
    max_steps = check_int(o, "max_steps", max_steps)
    if not is_concrete(belt):
        raise ValueError(f"{o}: the start `belt` must hold concrete values (calibrate is not traced)")
    for f in free:  # fitted in log coordinates: a start at 0 has no logarithm
        v = np.asarray(getattr(belt, f), dtype=float)
        if not np.all(v > 0):
            raise ValueError(
                f"{o}: the start value of the free field `{f}` must be > 0 (the fit works on its logarithm); got "
                f"{v.tolist()}"
            )
    top = max(MODE1_RANGE[1], MODE2_RANGE[1])
    if float(belt.wave_speed) <= top:
        raise ValueError(
            f"{o}: parameter `wave_speed` of the start belt must exceed the running speeds the measurements are "
            f"matched over (up to {top:g} m/s: the jumps lie there, and the belt must be sub-critical); got "
            f"{float(belt.wave_speed):g} m/s"
        )
    belt = two_mode(belt)
    shapes = tuple(tuple(int(d) for d in jnp.shape(getattr(belt, f))) for f in free)
    build, fn = _log_problem(free, shapes, n_harmonics, bool(amplitudes))

    p0 = jnp.concatenate([jnp.log(jnp.ravel(jnp.asarray(getattr(belt, f), float))) for f in free])
    # reverse-mode Jacobian: four residuals, one backward pass each
    with reraise_checks(o, "at a step of the fit: the free fields left their valid range"):
        sol = optx.least_squares(
            fn,
            optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8),
            p0,
            args=belt,
            max_steps=max_steps,
            throw=False,
            options=dict(jac="bwd"),
        )
        out = build(sol.value, belt)
        r = fn(sol.value, belt)
        folds = model_fold_speeds(out, n_harmonics)
    success = sol.result == optx.RESULTS.successful
    message = "" if bool(success) else _failure(sol, r, folds, max_steps, free)
    if message:
        warnings.warn(message, RuntimeWarning, stacklevel=2)
    return Calibration(
        belt=out, residuals=r, cost=0.5 * jnp.sum(r**2), fold_speeds=folds, success=success, message=message
    )


def _failure(sol, r, folds, max_steps: int, free) -> str:
    """Why `calibrate` did not converge, and what to do."""
    r, folds = np.asarray(r), np.asarray(folds)
    missing = np.flatnonzero(~np.isfinite(folds))
    if missing.size:
        names = ("first-mode lower fold", "first-mode upper fold", "second-mode lower fold", "second-mode upper fold")
        return (
            f"calibrate: the model has no {', '.join(names[i] for i in missing)} in the measured speed ranges "
            f"{MODE1_RANGE}, {MODE2_RANGE} m/s at the last step (residual 1e3 each): the fit cannot see the "
            "measurements from there. Start nearer (the default belt's wave_speed and damping), or free fewer fields"
        )
    steps = int(np.asarray(sol.stats["num_steps"]))
    if bool(sol.result == optx.RESULTS.max_steps_reached) or bool(
        sol.result == optx.RESULTS.nonlinear_max_steps_reached
    ):
        return (
            f"calibrate: Levenberg-Marquardt reached the step limit max_steps={max_steps} without converging "
            f"(cost {0.5 * float(r @ r):.4g}, fold speeds {np.round(folds, 4).tolist()} m/s); raise `max_steps` or "
            "start nearer the measured folds"
        )
    return (
        f"calibrate: Levenberg-Marquardt stopped after {steps} steps: {optx.RESULTS[sol.result]} (free {free}, cost "
        f"{0.5 * float(r @ r):.4g}); start elsewhere or free fewer fields"
    )


def layout_choices():
    """The eight discrete choices: (sensor_pulley, travel, phase sign)."""
    return [(s, t, sg) for s in ("drive", "idle") for t in ("drive_to_idle", "idle_to_drive") for sg in (1, -1)]


def with_layout(belt: NonlinearBelt, sensor_pulley, travel, sign):
    """`belt` with the given sensor pulley, travel direction and sign of the measured 240° phase."""
    return NonlinearBelt(
        span=belt.span,
        wave_speed=belt.wave_speed,
        v_l=belt.v_l,
        pulley_radii=belt.pulley_radii,
        runout=belt.runout,
        phase=sign * float(np.deg2rad(240.0)),
        damping=belt.damping,
        n_modes=belt.n_modes,
        sensor_pulley=sensor_pulley,
        travel=travel,
    )
