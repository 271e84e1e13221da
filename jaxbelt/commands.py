"""Inputs: voltage commands for DC motors and motion commands for servo axes.

A command is an `eqx.Module` evaluated as `cmd(t)`. Commands that are sums of
exponentials, $u(t) = \\sum_j a_j e^{s_j t}$, also expose `exp_terms()` so that a
linear time-invariant scene can be solved in closed form (no time stepping).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from ._checks import check_finite, check_positive


def _arr(x):
    return jnp.asarray(x, dtype=float)


class AbstractCommand(eqx.Module):
    """Base class of all inputs. `__call__(t)` gives the input at time `t` [s]."""

    def __call__(self, t):
        raise NotImplementedError

    def exp_terms(self):
        """Return `(amplitudes, rates)` with $u(t)=\\sum_j a_j e^{s_j t}$, or `None`."""
        return None


class ConstantVoltage(AbstractCommand):
    """Constant armature voltage $V(t) = V_0$ [V] (a step applied at t = 0)."""

    voltage: jnp.ndarray = eqx.field(converter=_arr)

    def __check_init__(self):
        check_finite("voltage", self.voltage, owner="ConstantVoltage")

    def __call__(self, t):
        return self.voltage * jnp.ones_like(jnp.asarray(t, dtype=float))

    def exp_terms(self):
        return jnp.stack([self.voltage]), jnp.zeros((1,))


class ExponentialVoltage(AbstractCommand):
    """Exponential voltage ramp of seed 000, eq. (30).

    $V(t) = V_{max}\\,(1 - e^{-t/\\gamma})$

    - `v_max`: final voltage $V_{max}$ [V] (Table I: 24 V).
    - `gamma`: time constant $\\gamma$ [s], > 0 (the paper uses 0.02, 0.04, 0.06 s).
    """

    v_max: jnp.ndarray = eqx.field(converter=_arr, default=24.0)
    gamma: jnp.ndarray = eqx.field(converter=_arr, default=0.02)

    def __check_init__(self):
        check_finite("v_max", self.v_max, owner="ExponentialVoltage")
        check_positive("gamma", self.gamma, "s", owner="ExponentialVoltage")

    def __call__(self, t):
        t = jnp.asarray(t, dtype=float)
        return self.v_max * (-jnp.expm1(-t / self.gamma))

    def exp_terms(self):
        amps = jnp.stack([self.v_max, -self.v_max])
        rates = jnp.stack([jnp.zeros_like(self.gamma), -1.0 / self.gamma])
        return amps, rates
