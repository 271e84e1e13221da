"""Measured values of Moon & Wickert (1997) and the identification of the model's unknowns.

The paper gives the test stand's geometry and run-out (Sec. 2) and the measured jumps
(Sec. 2, Figs. 2-3), but not the belt tension (hence the transverse wave speed $v_t$), the
damping, nor which pulley the sensor sits at, the travel direction and the sign of the run-out
phase. `calibrate` identifies $v_t$, the modal damping ratio and $v_l$ by Levenberg-Marquardt
(`optimistix`) on the fold speeds and jump amplitudes, for a given choice of the discrete
unknowns; `identify_layout` compares the choices.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .harmonic import jumps
from .model import NonlinearBelt

__all__ = ["Measurement", "MEASUREMENTS", "calibrate", "Calibration", "jump_residuals"]


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


def _targets():
    # order of Jumps (ascending speed): index 0 = decreasing sweep's jump, 1 = increasing sweep's jump
    V = jnp.array([measured("down_jump_speed"), measured("up_jump_speed")])
    before = jnp.array([measured("down_jump_pp_before"), measured("up_jump_pp_before")])
    after = jnp.array([measured("down_jump_pp_after"), measured("up_jump_pp_after")])
    return V, before, after


# weights: speeds to 0.05 m/s, amplitudes to 10 % of the measured value
_SIGMA_V, _REL_PP = 0.05, 0.10


def jump_residuals(belt: NonlinearBelt, speed_range=(7.0, 11.0), n_harmonics: int = 3, *, amplitudes=True):
    """Weighted residuals (model - measured) of the first-mode jumps: speeds / 0.05 m/s and, with
    `amplitudes`, peak-to-peak before/after / (10 % of measured). Differentiable in `belt`."""
    j = jumps(belt, speed_range, n_harmonics, 2, throw=False)
    V, before, after = _targets()
    r = [(j.speed - V) / _SIGMA_V]
    if amplitudes:
        r += [(j.pp_before - before) / (_REL_PP * before), (j.pp_after - after) / (_REL_PP * after)]
    r = jnp.concatenate(r)
    return jnp.where(jnp.isfinite(r), r, 1e3)  # no jump in range: a large, finite misfit


class Calibration(eqx.Module):
    """Result of `calibrate`: the identified `belt`, the weighted residuals `residuals`, `cost`
    (half the sum of squares) and the solver `success`."""

    belt: NonlinearBelt
    residuals: jnp.ndarray
    cost: jnp.ndarray
    success: jnp.ndarray


_FREE = ("wave_speed", "damping", "v_l")


def calibrate(belt: NonlinearBelt | None = None, *, free=_FREE, amplitudes: bool = True,
              speed_range=(7.0, 11.0), n_harmonics: int = 3, max_steps: int = 40) -> Calibration:
    """Identify the parameters named in `free` (any of `wave_speed`, `damping`, `v_l`) from the
    measured jumps by Levenberg-Marquardt (`optimistix.LevenbergMarquardt`), in log coordinates
    (positive by construction). The residuals are those of `jump_residuals`; the Jacobian comes
    from the implicit differentiation of the folds and branches."""
    belt = NonlinearBelt() if belt is None else belt
    for f in free:
        if f not in _FREE:
            raise ValueError(f"calibrate: parameter `free` may name {_FREE}; got {f!r}")
    free = tuple(free)

    def build(p, b):
        return eqx.tree_at(lambda bb: [getattr(bb, f) for f in free], b, [jnp.exp(x) for x in p])

    def fn(p, b):
        return jump_residuals(build(p, b), speed_range, n_harmonics, amplitudes=amplitudes)

    p0 = tuple(jnp.log(jnp.asarray(getattr(belt, f), float)) for f in free)
    sol = optx.least_squares(fn, optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6), p0, args=belt,
                             max_steps=max_steps, throw=False)
    out = build(sol.value, belt)
    r = fn(sol.value, belt)
    return Calibration(belt=out, residuals=r, cost=0.5 * jnp.sum(r**2),
                       success=sol.result == optx.RESULTS.successful)


def layout_choices():
    """The eight discrete choices: (sensor_pulley, travel, phase sign)."""
    return [(s, t, sg) for s in ("drive", "idle") for t in ("drive_to_idle", "idle_to_drive") for sg in (1, -1)]


def with_layout(belt: NonlinearBelt, sensor_pulley, travel, sign):
    """`belt` with the given sensor pulley, travel direction and sign of the measured 240° phase."""
    return NonlinearBelt(span=belt.span, wave_speed=belt.wave_speed, v_l=belt.v_l, pulley_radii=belt.pulley_radii,
                         runout=belt.runout, phase=sign * float(np.deg2rad(240.0)), damping=belt.damping,
                         n_modes=belt.n_modes, sensor_pulley=sensor_pulley, travel=travel)


del jax
