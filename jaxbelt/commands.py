"""Inputs of the models, one abstract class per kind, and the concrete commands.

Every model declares which kinds of input it accepts (`Model.input_types`); `Scene` raises a
`TypeError` for a wrong pairing (a four-bar driven by a motion command, say). The kinds:

| kind | meaning | evaluated as | concrete classes |
|---|---|---|---|
| `AbstractVoltageCommand` | open-loop armature voltage [V] | `cmd(t)` | `ConstantVoltage`, `ExponentialVoltage` |
| `AbstractController` | closed-loop armature voltage from the motor state [V] | `ctrl.voltage_at(t, motor)` | `PID` |
| `AbstractMotionCommand` | motor position command [rad] and its derivatives | `cmd.derivative(t, k)` | `PseudoPolynomial`, `ShapedCommand` |
| `AbstractRunningSpeed` | belt running speed [m/s] | `inp.speed_at(t)` | `RunningSpeed`, `SpeedRamp` |

A voltage command that is a sum of exponentials, $u(t) = \\sum_j a_j e^{s_j t}$, is an
`AbstractExponentialVoltage`: with a linear time-invariant model (`AbstractLinearModel`) the
scene is solved in closed form (no time stepping). The question is answered by the types alone.
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_positive, check_range, record
from ._params import FloatParam, Parametrised, document, param


class AbstractInput(Parametrised):
    """Base class of every model input (command, controller or running speed); its parameters are
    declared with `jaxbelt._params.param` (checked at construction, listed in the docs)."""


class MotorState(NamedTuple):
    """Motor-shaft kinematics a drive hands to its voltage source at time t.

    - `angle` $\\varphi$ [rad], `speed` $\\dot\\varphi$ [rad/s], `acceleration` $\\ddot\\varphi$ [rad/s²];
    - `angle0`: $\\varphi$ at the start of the scene [rad] (a controller's angle reference starts there).
    """

    angle: jnp.ndarray
    speed: jnp.ndarray
    acceleration: jnp.ndarray
    angle0: jnp.ndarray


class AbstractVoltageSource(AbstractInput):
    """Anything that sets a DC motor's armature voltage: `voltage_at(t, motor)` [V]."""

    @abc.abstractmethod
    def voltage_at(self, t, motor: MotorState) -> jax.Array:
        """Armature voltage [V] at time `t` [s] for the motor state `motor`."""


class AbstractVoltageCommand(AbstractVoltageSource):
    """An open-loop voltage command $V(t)$ [V]: `cmd(t)`; the motor state is not used."""

    @abc.abstractmethod
    def __call__(self, t) -> jax.Array:
        """$V(t)$ [V]."""

    def voltage_at(self, t, motor: MotorState):
        return self(t)


class AbstractExponentialVoltage(AbstractVoltageCommand):
    """A voltage command that is a finite sum of exponentials, $V(t) = \\sum_j a_j e^{s_j t}$."""

    @abc.abstractmethod
    def exp_terms(self) -> tuple[jax.Array, jax.Array]:
        """`(amplitudes, rates)`, each of shape (J,): $a_j$ [V] and $s_j$ [1/s]."""


class AbstractController(AbstractVoltageSource):
    """A feedback law: the armature voltage depends on the motor state (e.g. `PID`)."""


class AbstractMotionCommand(AbstractInput):
    """A motor displacement command $\\varphi_m(t)$ [rad] with derivatives of any order.

    Subclasses implement `derivative(t, k)` (k-th time derivative, rad/s^k) and `end_time` [s].
    """

    @abc.abstractmethod
    def derivative(self, t, k: int = 0) -> jax.Array:
        """k-th time derivative of the command [rad/s^k]."""

    @property
    @abc.abstractmethod
    def end_time(self) -> jax.Array:
        """Time at which the motion ends [s] (the command holds its final position after it)."""

    def __call__(self, t):
        return self.derivative(t, 0)

    def velocity(self, t):
        """$\\dot\\varphi_m(t)$ [rad/s]."""
        return self.derivative(t, 1)

    def acceleration(self, t):
        """$\\ddot\\varphi_m(t)$ [rad/s²]."""
        return self.derivative(t, 2)

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` numpy arrays of the command sampled every `1 / rate_hz` seconds from t = 0 through the
        end of the move (the last sample at or after `end_time`, where the command holds still): what a drive's
        motion table takes. `rate_hz` [Hz] finite and > 0."""
        import math

        check_positive("rate_hz", rate_hz, "Hz", f"{type(self).__name__}.sample")
        n = int(math.ceil(float(self.end_time) * float(rate_hz) - 1e-9))
        t = np.arange(n + 1) / float(rate_hz)
        tj = jnp.asarray(t)
        x, v, a = (np.asarray(jax.device_get(self.derivative(tj, k))) for k in (0, 1, 2))
        return t, x, v, a


class AbstractRunningSpeed(AbstractInput):
    """The running speed of a belt, $v(t)$ [m/s]: `speed_at(t)`."""

    @abc.abstractmethod
    def speed_at(self, t) -> jax.Array:
        """Belt speed [m/s] at time `t` [s]."""


#: Smallest time constant of `ExponentialVoltage` [s]: the closed form (matrix exponential of the drive with the
#: input's rate 1/gamma) keeps a relative error below 1e-12 down to it, and loses digits as 1/gamma below it
#: (5e-11 at 1e-8 s, 5 % at 1e-15 s, measured against diffrax at rtol 1e-12). A microsecond is far below any
#: motor's electrical time constant L/R: a shorter ramp is a step, `ConstantVoltage`.
MIN_TIME_CONSTANT = 1e-6


@document
class ConstantVoltage(AbstractExponentialVoltage):
    """Constant armature voltage $V(t) = V_0$ [V] (a step applied at t = 0).

    {parameters}
    """

    voltage: FloatParam = param(unit="V", check="finite", symbol="$V_0$", doc="the constant voltage")

    def __call__(self, t):
        return self.voltage * jnp.ones_like(jnp.asarray(t, dtype=float))

    def exp_terms(self):
        return jnp.stack([self.voltage]), jnp.zeros((1,))


@document
class ExponentialVoltage(AbstractExponentialVoltage):
    """Exponential voltage ramp of Incerti (2014), eq. (30).

    $V(t) = V_{max}\\,(1 - e^{-t/\\gamma})$

    {parameters}

    A 1-D array of time constants makes a batch (the paper uses 0.02, 0.04, 0.06 s): `simulate`
    solves all of them at once (batched closed form).
    """

    v_max: FloatParam = param(
        24.0, unit="V", check="finite", symbol="$V_{max}$", default_note="Table I", doc="final voltage"
    )
    gamma: FloatParam = param(
        0.02,
        unit="s",
        check="range",
        lo=MIN_TIME_CONSTANT,
        batch=True,
        symbol="$\\gamma$",
        doc="time constant (a shorter one is a step: use `ConstantVoltage`)",
    )

    def __call__(self, t):
        t = jnp.asarray(t, dtype=float)
        return self.v_max * (-jnp.expm1(-t / self.gamma))

    def exp_terms(self):
        amps = jnp.stack([self.v_max, -self.v_max])
        rates = jnp.stack([jnp.zeros_like(self.gamma), -1.0 / self.gamma])
        return amps, rates


# --------------------------------------------------------------------------------------------
# Motion commands for servo axes (Incerti, pseudo-polynomial commands): pseudo-polynomial profiles and input shapers.
# --------------------------------------------------------------------------------------------


def _safe_pow(u, e):
    """$u^e$ for $u \\ge 0$, with value 0 and finite derivatives (w.r.t. both) at $u = 0$.

    The double `where` keeps `log(0)` out of the gradient: at u = 0 the exponent derivative
    $u^e \\log u$ tends to 0 for e > 0, which is what the command's limit at t = T needs.
    """
    pos = u > 0
    us = jnp.where(pos, u, 1.0)
    return jnp.where(pos, jnp.exp(e * jnp.log(us)), 0.0)


def lagrange_weights_np(gammas, active=None) -> np.ndarray:
    """The coefficients $C_i$ of a pseudo-polynomial (Incerti, eq. 22-23) on the host (numpy), as the Lagrange
    weights at 0 of its exponents: $C_i = \\prod_{j \\ne i} \\gamma_j / (\\gamma_j - \\gamma_i)$, the solution of
    $\\sum_i C_i P(\\gamma_i, k) = [k = 0]$, k = 0..n (the falling factorials $P(\\gamma, k)$, k >= 1, span the
    polynomials of degree <= n that vanish at 0). As accurate as the linear solve of `PseudoPolynomial.coefficients`
    or more (no pivoting of a Vandermonde-like matrix). `active` (1-D, 1 or 0 per exponent; default all): the
    inactive exponents (padding) take 0 and are left out of the others' products."""
    g = np.asarray(gammas, dtype=float)
    on = np.ones(g.shape[0]) if active is None else np.asarray(active, dtype=float)
    eye = np.eye(g.shape[0], dtype=bool)
    skip = eye | (on[None, :] <= 0)
    diff = np.where(eye, 1.0, g[None, :] - g[:, None])
    return np.prod(np.where(skip, 1.0, g[None, :] / diff), axis=1) * (on > 0)


def falling_factorial(gammas, k: int):
    """$P(\\gamma, k) = \\prod_{r=0}^{k-1} (\\gamma - r)$ (Incerti, pseudo-polynomial commands, eq. 19); $P(\\gamma, 0) = 1$."""
    gammas = jnp.asarray(gammas, dtype=float)
    out = jnp.ones_like(gammas)
    for r in range(k):
        out = out * (gammas - r)
    return out


#: Smallest distance between two exponents of a `PseudoPolynomial`: the condition number of eq. (23)
#: grows as 1/gap (about 4e5 at 1e-3), and the gradient of H keeps ~1e-6 relative accuracy down to it.
MIN_EXPONENT_GAP = 1e-3


def exponents_apart(gammas) -> bool:
    """Whether the (host) exponents `gammas` differ pairwise by at least `MIN_EXPONENT_GAP` (to rounding)."""
    g = np.sort(np.asarray(gammas, dtype=float))
    return bool(np.min(np.diff(g)) >= MIN_EXPONENT_GAP * (1 - 1e-9))


def _record_check(ok, message):
    record(ok, message)


@document
class PseudoPolynomial(AbstractMotionCommand):
    """Pseudo-polynomial rest-to-rest motion command of order n (Incerti, pseudo-polynomial commands, eq. 17-23).

    $\\varphi_m(t) = \\Phi\\,[1 - \\sum_{i=0}^{n} C_i (1 - t/T)^{\\gamma_i}]$ (eq. 17)

    $\\varphi_m^{(k)}(t) = (-1)^{k+1}\\frac{\\Phi}{T^k}\\sum_i P(\\gamma_i, k)\\,C_i\\,(1 - t/T)^{\\gamma_i - k}$
    (eq. 18-19)

    The coefficients solve the $(n+1)\\times(n+1)$ system $\\bar Z \\bar c = (1, 0, \\dots, 0)^T$ with
    $\\bar Z_{ki} = P(\\gamma_i, k)$ (eq. 21-23), so that $\\varphi_m$ and its first n derivatives
    vanish at t = 0 and $\\varphi_m(T) = \\Phi$ with n derivatives zero at T. Integer exponents
    give the classical polynomials: (3, 4, 5) → C = (10, −15, 6).

    {parameters}

    The n + 1 exponents `gammas` are at least `MIN_EXPONENT_GAP` = 1e-3 apart and each > max(n, 2):
    > 2 keeps the acceleration finite at t = T, > n keeps the n-th derivative so.

    `cmd(t)` is the position [rad]; before t = 0 the axis is at 0, after T it holds at $\\Phi$.
    Everything is differentiable with respect to `gammas` (and Φ, T).
    """

    gammas: FloatParam = param(
        unit="–", check="none", shape=None, symbol="$\\gamma_i$", doc="the n + 1 >= 2 exponents (shape parameters), 1-D"
    )
    displacement: FloatParam = param(
        15 * 2 * 3.141592653589793,
        unit="rad",
        check="range",
        lo=-1e9,
        hi=1e9,
        symbol="$\\Phi$",
        default_note="15 rev",
        doc="total motor displacement",
    )
    duration: FloatParam = param(
        1.0,
        unit="s",
        check="range",
        lo=1e-6,
        hi=1e6,
        symbol="$T$",
        doc="motion time",
    )

    def _check_relations(self, host):
        o = "PseudoPolynomial"
        if self.gammas.ndim != 1 or self.gammas.shape[0] < 2:
            raise ValueError(
                f"{o}: `gammas` must be a 1-D array of n + 1 >= 2 exponents; got shape {self.gammas.shape}"
            )
        g = host.get("gammas", self.gammas)  # host values, or the tracer
        lo = float(max(self.order, 2))
        check_range("gammas", g, lo=lo, lo_open=True, owner=o)
        msg = (
            f"{o}: parameter `gammas` must differ pairwise by at least {MIN_EXPONENT_GAP:g} (eq. 23 is singular "
            "for equal exponents; closer ones make the coefficients grow as 1/gap, and H and its gradient lose "
            "their accuracy)"
        )
        if "gammas" in host:
            if not exponents_apart(g):
                raise ValueError(f"{msg}; got {np.asarray(g).tolist()}")
        else:
            diff = jnp.abs(g[:, None] - g[None, :]) + MIN_EXPONENT_GAP * jnp.eye(g.shape[0])
            _record_check(jnp.all(diff >= MIN_EXPONENT_GAP * (1 - 1e-9)), msg)

    @property
    def order(self) -> int:
        """n: the order of the highest derivative that vanishes at both ends."""
        return self.gammas.shape[0] - 1

    @property
    def min_exponent(self) -> float:
        """Feasibility bound: every exponent must exceed max(n, 2)."""
        return float(max(self.order, 2))

    def system_matrix(self):
        """$\\bar Z$ of eq. (23): row k holds $P(\\gamma_i, k)$, k = 0..n."""
        return jnp.stack([falling_factorial(self.gammas, k) for k in range(self.order + 1)])

    @property
    def coefficients(self):
        """$C_i$ from $\\bar Z \\bar c = \\bar u$ (eq. 22)."""
        rhs = jnp.zeros((self.order + 1,)).at[0].set(1.0)
        return jnp.linalg.solve(self.system_matrix(), rhs)

    def derivative(self, t, k: int = 0):
        """k-th time derivative $\\varphi_m^{(k)}(t)$ [rad/s^k] (eq. 17 for k = 0, eq. 18 for k >= 1).

        Exact for 0 <= k <= n on the whole line; for k > n the value at t = T is the limit 0 only
        when every exponent exceeds k.
        """
        if k < 0:
            raise ValueError(f"PseudoPolynomial.derivative: order `k` must be >= 0; got {k}")
        t = jnp.asarray(t, dtype=float)
        T = self.duration
        u = jnp.clip(1.0 - t / T, 0.0, 1.0)
        C = self.coefficients
        pk = falling_factorial(self.gammas, k)
        terms = pk * C * _safe_pow(u[..., None], self.gammas - k)
        s = jnp.sum(terms, axis=-1)
        if k == 0:
            val = self.displacement * (1.0 - s)
        else:
            val = (-1.0) ** (k + 1) * self.displacement / T**k * s
        return jnp.where(t < 0, 0.0, val)

    @property
    def end_time(self):
        """Time at which the motion ends [s] (= T)."""
        return self.duration


def _damped_half_period_and_ratio(omega_n, zeta):
    """$(\\pi/\\omega_d, K = e^{-\\zeta\\pi/\\sqrt{1-\\zeta^2}})$ of a mode, shared by ZV and ZVD."""
    check_positive("omega_n", omega_n, "rad/s", owner="ShapedCommand")
    check_range("zeta", zeta, lo=0.0, hi=1.0, hi_open=True, owner="ShapedCommand")
    omega_n = jnp.asarray(omega_n, dtype=float)
    zeta = jnp.asarray(zeta, dtype=float)
    wd = omega_n * jnp.sqrt(1.0 - zeta**2)
    # traced invalid values (not checked above) give NaN times, which the shaper's recorded checks refuse
    valid = jnp.isfinite(omega_n) & (omega_n > 0) & jnp.isfinite(zeta) & (zeta >= 0) & (zeta < 1)
    half = jnp.where(valid, jnp.pi / wd, jnp.nan)
    return half, jnp.exp(-zeta * jnp.pi / jnp.sqrt(1.0 - zeta**2))


@document
class ShapedCommand(AbstractMotionCommand):
    """A motion command passed through an input shaper (impulse sequence).

    $\\varphi_s(t) = \\sum_j A_j\\,\\varphi(t - t_j)$ with $\\sum_j A_j = 1$, so the total
    displacement is kept and the move lasts $T + t_{last}$. `ShapedCommand.zv(...)` and
    `ShapedCommand.zvd(...)` build the classical zero-vibration shapers for a mode of natural
    frequency $\\omega_n$ [rad/s] and damping ratio $\\zeta$:
    $K = e^{-\\zeta\\pi/\\sqrt{1-\\zeta^2}}$, $t_2 = \\pi/\\omega_d$; ZV: $A = (1, K)/(1+K)$ at
    $(0, t_2)$; ZVD: $A = (1, 2K, K^2)/(1+K)^2$ at $(0, t_2, 2t_2)$.

    - `base`: a command with `derivative(t, k)` and `end_time` (e.g. `PseudoPolynomial`).

    {parameters}

    `times` and `amplitudes` are 1-D of equal length; the times are non-decreasing and the
    amplitudes sum to 1.
    """

    base: AbstractMotionCommand
    times: FloatParam = param(unit="s", check="nonnegative", shape=None, symbol="$t_j$", doc="impulse times")
    amplitudes: FloatParam = param(
        unit="–", check="finite", shape=None, symbol="$A_j$", doc="impulse amplitudes (summing to 1)"
    )

    def _check_relations(self, host):
        o = "ShapedCommand"
        if not isinstance(self.base, AbstractMotionCommand):
            raise TypeError(
                f"{o}: parameter `base` must be a motion command (PseudoPolynomial, a move of jaxbelt.shaping, ...); "
                f"got {type(self.base).__name__}"
            )
        if self.times.ndim != 1 or self.times.shape != self.amplitudes.shape:
            raise ValueError(
                f"{o}: `times` and `amplitudes` must be 1-D of equal length; got {self.times.shape}, {self.amplitudes.shape}"
            )
        order_msg = (
            f"{o}: parameter `times` must be non-decreasing (impulse times in order, the last one ends the move)"
        )
        sum_msg = f"{o}: parameter `amplitudes` must sum to 1"
        if "times" in host and "amplitudes" in host:
            t = np.atleast_1d(host["times"])
            if t.size > 1 and not np.all(np.diff(t) >= 0):
                raise ValueError(f"{order_msg}; got {t.tolist()}")
            a = np.atleast_1d(host["amplitudes"])
            if abs(float(np.sum(a)) - 1.0) > 1e-9:
                raise ValueError(f"{sum_msg}; got {a.tolist()}")
        else:
            if self.times.shape[0] > 1:
                _record_check(jnp.all(jnp.diff(self.times) >= 0), order_msg)
            tol = max(1e-9, 100 * float(jnp.finfo(self.amplitudes.dtype).eps))
            _record_check(jnp.abs(jnp.sum(self.amplitudes) - 1.0) <= tol, sum_msg)

    @classmethod
    def zv(cls, base, omega_n, zeta=0.0):
        """Zero-vibration (two-impulse) shaper for the mode $(\\omega_n, \\zeta)$."""
        t2, K = _damped_half_period_and_ratio(omega_n, zeta)
        return cls(base, jnp.stack([0.0 * t2, t2]), jnp.stack([1.0 + 0 * K, K]) / (1.0 + K))

    @classmethod
    def zvd(cls, base, omega_n, zeta=0.0):
        """Zero-vibration-derivative (three-impulse) shaper for the mode $(\\omega_n, \\zeta)$."""
        t2, K = _damped_half_period_and_ratio(omega_n, zeta)
        return cls(base, jnp.stack([0.0 * t2, t2, 2 * t2]), jnp.stack([1.0 + 0 * K, 2 * K, K**2]) / (1.0 + K) ** 2)

    def derivative(self, t, k: int = 0):
        t = jnp.asarray(t, dtype=float)
        vals = jax.vmap(lambda tj: self.base.derivative(t - tj, k))(self.times)
        return jnp.tensordot(self.amplitudes, vals, axes=(0, 0))

    @property
    def end_time(self):
        """Time at which the shaped motion ends [s]: base end time + last impulse time."""
        return self.base.end_time + self.times[-1]
