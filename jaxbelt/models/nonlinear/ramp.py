"""The belt speed ramped through resonance: time records at the sensor (Moon & Wickert (1997), Fig. 3).

`speed_ramp(belt, v_start, v_end, duration)` starts on the steady periodic response at
`v_start` (harmonic balance), then integrates the model's vector field in physical time with
diffrax while $V(t)$ rises or falls linearly to `v_end` over `duration` (the `SpeedRamp` input;
the pulley angles are the integral of the pulley speeds). The same record is what
`jb.simulate(jb.Scene(belt, SpeedRamp(v_start, v_end, duration), ts, y0=...))` returns as the
`"w_sensor"` output.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._checks import check_int, check_positive, check_scalar, is_concrete
from ..._threads import blas_limited
from ...scene import Scene
from ...solve import simulate
from .harmonic import _basis, harmonic_balance
from .model import NonlinearBelt, SpeedRamp

__all__ = ["RampRecord", "speed_ramp", "ramp_initial_state"]


class RampRecord(eqx.Module):
    """A speed-ramp time record: `t` [s], `speed` [m/s], `w` [m] displacement 1 cm from the sensor
    pulley, `z` (len(t), 2N) modal state."""

    t: jnp.ndarray
    speed: jnp.ndarray
    w: jnp.ndarray
    z: jnp.ndarray


def ramp_initial_state(belt: NonlinearBelt, speed, n_harmonics: int = 5):
    """Modal state (2N,) on the steady periodic response at `speed` [m/s], at pulley angle 0
    (harmonic balance from rest, i.e. the branch reached away from the hysteresis band)."""
    hb = harmonic_balance(belt, speed, n_harmonics)
    return hb.coefficients @ _basis(n_harmonics, jnp.zeros(1))[:, 0]


@blas_limited
def speed_ramp(
    belt: NonlinearBelt,
    v_start,
    v_end,
    duration,
    *,
    hold: float = 0.0,
    samples_per_period: int = 24,
    rtol: float = 1e-8,
    z0=None,
) -> RampRecord:
    """Displacement at the sensor while the belt speed ramps linearly from `v_start` to `v_end`
    [m/s] in `duration` [s] (Moon & Wickert (1997), Fig. 3), then held at `v_end` for `hold` [s].
    Starts on the steady response at `v_start` (or at modal state `z0`); sampled
    `samples_per_period` times per pulley revolution."""
    o = "speed_ramp"
    if not isinstance(belt, NonlinearBelt):
        raise TypeError(f"{o}: parameter `belt` must be a NonlinearBelt; got {type(belt).__name__}")
    if not (is_concrete(duration) and is_concrete(v_start) and is_concrete(v_end)):
        raise ValueError(f"{o}: `v_start`, `v_end` and `duration` must be concrete (they set the sampling)")
    for name, value in (("v_start", v_start), ("v_end", v_end), ("duration", duration), ("hold", hold)):
        check_scalar(name, value, "s" if name in ("duration", "hold") else "m/s", o)
    check_positive("duration", duration, "s", o)
    if not (is_concrete(hold) and float(hold) >= 0 and np.isfinite(float(hold))):
        raise ValueError(f"{o}: parameter `hold` must be a concrete finite number >= 0 [s]; got {hold!r}")
    samples_per_period = check_int(o, "samples_per_period", samples_per_period, _MIN_SAMPLES)
    check_positive("rtol", rtol, owner=o)
    belt.check_speed(jnp.asarray([v_start, v_end], float))
    if z0 is not None and np.shape(z0) != (2 * belt.n_modes,):
        raise ValueError(
            f"{o}: parameter `z0` (initial modal state) must have shape ({2 * belt.n_modes},) for a belt of "
            f"{belt.n_modes} mode(s); got shape {np.shape(z0)}"
        )
    vmax = max(float(v_start), float(v_end))
    t_end = float(duration) + float(hold)
    n = int(np.ceil(t_end * vmax / (2 * np.pi * float(belt.pulley_radii[0])) * samples_per_period)) + 1
    if n > _MAX_SAMPLES:
        raise ValueError(
            f"{o}: the record would hold {n:.3g} samples ({t_end:g} s at up to {vmax:g} m/s, {samples_per_period} "
            f"per revolution); at most {_MAX_SAMPLES:.0e}: shorten `duration` + `hold` or lower `samples_per_period`"
        )
    ramp = SpeedRamp(v_start, v_end, duration)
    if z0 is None:
        z0 = ramp_initial_state(belt, v_start)
    ts = jnp.linspace(0.0, t_end, n)
    atol = 1e-9 * float((belt.runout[0] + belt.runout[1]) / belt.span)
    # the ramp is a scene like any other: one protocol, the same guards and failure policy
    scene = Scene(belt, ramp, ts=ts, y0=jnp.asarray(z0, float), observe=("w_sensor",))
    sol = simulate(
        scene, "ode", solver=diffrax.Tsit5(), rtol=jnp.asarray(rtol), atol=jnp.asarray(atol), max_steps=_RAMP_MAX_STEPS
    )
    assert sol.ys is not None  # the scene keeps its state (Scene(state=True), the default)
    return RampRecord(t=ts, speed=ramp.speed_at(ts), w=sol.outputs["w_sensor"], z=sol.ys)


#: fewest samples per pulley revolution (a revolution's peaks need at least four), most samples of a record
_MIN_SAMPLES, _MAX_SAMPLES = 4, 10_000_000

#: step budget of a ramp solve (static: one compiled program for every ramp of the same sampling)
_RAMP_MAX_STEPS = 400_000
