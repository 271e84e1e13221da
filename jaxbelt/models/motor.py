"""Speed controller of a DC motor: the PID law with constant or time-varying proportional gain (Incerti, 2012).

The controller is not a command: a command is a known function of time (`ConstantVoltage`,
`inp(t)`), whereas the controller's voltage depends on the state of the drive it is attached to.
Both are voltage sources: a motor-driven model (e.g. `FourBarDrive`) calls
`inp.voltage_at(t, motor)` with its motor angle, speed and acceleration (`MotorState`), and a
command simply ignores the state.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .._checks import check_nonnegative
from .._params import FloatParam, OptionalFloatParam, document, option
from ..commands import AbstractController, MotorState
from . import _ranges as _r
from ._ranges import ranged

_LIMITERS = ("hard", "smooth")
_GAINS = ("ramped", "constant")


@document
class PID(AbstractController):
    """PID speed regulator with a ramped or constant proportional gain (Incerti, 2012, eq. 14-16).

    For a constant speed set point $\\dot\\varphi_{ref} = \\omega_0$ (Sec. II-D) the reference angle
    starts at the motor angle $\\varphi_0$ of the scene start, $\\varphi_{ref} = \\varphi_0 + \\omega_0 t$,
    and $\\ddot\\varphi_{ref} = 0$:

    - `gain="ramped"` (default, the paper's regulator, eq. 15-16):
      $V_a(t) = K_p t\\,(\\omega_0 - \\dot\\varphi) + K_i(\\omega_0 t - (\\varphi - \\varphi_0)) - K_d\\ddot\\varphi$;
    - `gain="constant"` (the textbook PID, eq. 14):
      $V_a(t) = K_p(\\omega_0 - \\dot\\varphi) + K_i(\\omega_0 t - (\\varphi - \\varphi_0)) - K_d\\ddot\\varphi$.

    $K_i(\\omega_0 t - (\\varphi - \\varphi_0)) = K_i\\int_0^t e\\,dt$ is the integral of the speed error
    $e = \\omega_0 - \\dot\\varphi$ (eq. 14), so no extra state is needed; it vanishes at $t = 0$
    whatever the initial angle. $\\varphi = z\\alpha$ is the motor angle and $\\varphi_0$ is handed
    over by the drive (`MotorState.angle0`; `FourBarDrive` takes it from its `alpha0`). Time $t$
    is measured from the start of the regulation, $t = 0$. The derivative term needs the motor
    acceleration, which the drive supplies from its equation of motion (eq. 10-11; it does not
    depend on $V_a$, so there is no algebraic loop).

    Voltage limiter (Fig. 3, value not stated in the paper: default none):

    - `limiter="hard"`: $\\mathrm{clip}(V_a, -V_{lim}, V_{lim})$;
    - `limiter="smooth"`: $V_a - s\\,\\mathrm{softplus}((V_a - V_{lim})/s)
      + s\\,\\mathrm{softplus}((-V_a - V_{lim})/s)$ with width $s$ = `v_smooth`; it is strictly
      inside $(-V_{lim}, V_{lim})$, tends to the hard clip as $s \\to 0$, and has a non-zero
      gradient everywhere (use it for gradient-based tuning).

    Parameters (the paper's regulator as defaults, Incerti (2012), Sec. II-D):

    {parameters}

    `kp` is in V/rad for the ramped gain (it multiplies $t$) and in V s/rad for the constant one.
    """

    kp: FloatParam = ranged(
        80.0, _r.GAIN, unit="V/rad", symbol="$K_p$", doc="proportional gain (ramped: multiplies $t$)", signed=True
    )
    ki: FloatParam = ranged(32.0, _r.GAIN, unit="V/rad", symbol="$K_i$", doc="integral gain", signed=True)
    kd: FloatParam = ranged(0.015, _r.GAIN, unit="V s²/rad", symbol="$K_d$", doc="derivative gain", signed=True)
    omega_ref: FloatParam = ranged(
        30.0, _r.MOTOR_SPEED_RAD_S, unit="rad/s", symbol="$\\omega_0$", doc="motor speed set point", signed=True
    )
    v_limit: OptionalFloatParam = ranged(
        None, _r.VOLTAGE_V, unit="V", optional=True, symbol="$V_{lim}$", doc="voltage limit (None: no limiter; Fig. 3)"
    )
    limiter: str = option("hard", choices=_LIMITERS, doc="the limiter's shape: clip or smooth")
    v_smooth: FloatParam = ranged(0.5, _r.VOLTAGE_V, unit="V", symbol="$s$", doc="width of the smooth limiter")
    gain: str = option("ramped", choices=_GAINS, doc="proportional gain $K_p t$ (eq. 16) or $K_p$ (eq. 14)")

    def proportional_gain(self, t):
        """Proportional gain at time `t`: $K_p t$ (ramped, eq. 16) or $K_p$ (constant, eq. 14) [V s/rad]."""
        return self.kp * t if self.gain == "ramped" else self.kp * jnp.ones_like(jnp.asarray(t, dtype=float))

    def raw_voltage(self, t, phi, phi_dot, phi_ddot, phi0: ArrayLike = 0.0):
        """Regulator output before the limiter [V] (eq. 14 or 16 with the constant set point);
        `phi0` is the motor angle at $t = 0$ [rad]."""
        w0 = self.omega_ref
        return self.proportional_gain(t) * (w0 - phi_dot) + self.ki * (w0 * t - (phi - phi0)) - self.kd * phi_ddot

    def limit(self, v):
        """Apply the voltage limiter (identity when `v_limit is None`)."""
        if self.v_limit is None:
            return v
        vl = self.v_limit
        if self.limiter == "hard":
            return jnp.clip(v, -vl, vl)
        s = self.v_smooth
        return v - s * jax.nn.softplus((v - vl) / s) + s * jax.nn.softplus((-v - vl) / s)

    def voltage_at(self, t, motor: MotorState):
        """Armature voltage $V_a$ [V] at time `t` for the motor state `motor`."""
        return self.limit(self.raw_voltage(t, motor.angle, motor.speed, motor.acceleration, motor.angle0))

    def with_limiter(self, limiter: str) -> PID:
        """The same regulator with the `"hard"` or `"smooth"` limiter."""
        return PID(self.kp, self.ki, self.kd, self.omega_ref, self.v_limit, limiter, self.v_smooth, self.gain)

    @property
    def gains(self):
        """`(kp, ki, kd)` stacked as one array."""
        return jnp.stack([self.kp, self.ki, self.kd])

    def with_gains(self, gains) -> PID:
        """The same regulator with gains `(kp, ki, kd)`."""
        gains = jnp.asarray(gains, dtype=float)
        return eqx.tree_at(lambda p: (p.kp, p.ki, p.kd), self, (gains[0], gains[1], gains[2]))

    def __call__(self, t):
        raise TypeError(
            "PID is a feedback controller, not a time command: its voltage depends on the motor state. "
            "Use it as the input of a model that accepts a controller (e.g. FourBarDrive), which calls "
            "PID.voltage_at(t, motor_state)."
        )


def check_pid_nonnegative(pid: PID) -> None:
    """Raise `ValueError` if a gain is negative (the tuning works in log-gains)."""
    for name in ("kp", "ki", "kd"):
        check_nonnegative(name, getattr(pid, name), owner="PID")
