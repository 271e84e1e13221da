"""The model protocol that `simulate` relies on.

A model is an `eqx.Module` of SI parameters deriving from `AbstractModel`:

- `state_names` (class attribute): names of the state components, in the papers' order;
- `input_types` (class attribute): the input kinds it accepts (classes from `jaxbelt.commands`,
  e.g. `(AbstractVoltageSource,)`); `Scene` raises `TypeError` for any other input;
- `vector_field(t, y, inp)` (abstract): $\\dot y = f(t, y, u)$; `model(t, y, args)` calls it, so
  `diffrax.ODETerm(model)` works;
- `initial_state(inp)`: the state at the scene's first time (default: zeros, at rest);
- derived outputs: methods decorated with `@observable("name")`, `fn(t, y, inp)` evaluated at one
  time (`simulate` maps them over the saved times); integral outputs: methods decorated with
  `@integrand("name")` returning the integrand, integrated as extra states by `simulate`.
  The names are collected from the decorators: there is no list to keep by hand.

A linear time-invariant model derives from `AbstractLinearModel` and gives
$\\dot x = A x + b\\,u(t) + c$ through `linear_system()`; driven by an
`AbstractExponentialVoltage` it is solved in closed form.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

_KIND = "_jaxbelt_output"


def observable(name: str):
    """Declare a method `fn(self, t, y, inp)` as the derived output `name` of its model."""

    def mark(fn):
        setattr(fn, _KIND, ("point", name))
        return fn

    return mark


def integrand(name: str):
    """Declare a method `fn(self, t, y, inp)` as the integrand of the integral output `name`."""

    def mark(fn):
        setattr(fn, _KIND, ("integral", name))
        return fn

    return mark


def _collect(cls) -> dict:
    found = {}
    for klass in reversed(cls.__mro__):
        for attr, val in vars(klass).items():
            tag = getattr(val, _KIND, None)
            if tag is not None:
                found[tag[1]] = (tag[0], attr)
    return found


class AbstractModel(eqx.Module):
    """Base class of jaxbelt models (see the module docstring for the protocol)."""

    state_names: ClassVar[tuple[str, ...]] = ()
    input_types: ClassVar[tuple[type, ...]] = ()

    @abc.abstractmethod
    def vector_field(self, t, y, inp):
        """$\\dot y$ at time `t` [s] and state `y` for the input `inp`."""

    def __call__(self, t, y, args):
        return self.vector_field(t, y, args)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    def initial_state(self, inp):
        return jnp.zeros((self.n_states,))

    def input_checks(self, inp) -> list:
        """Checks that need the model and its input together (e.g. a running speed below the belt's
        critical speed), as `[(ok, message)]`; `ok` a boolean array. `Scene` raises `ValueError` for a
        concrete failure; `simulate` attaches traced ones to its results. Default: none."""
        return []

    def default_solver(self):
        """The diffrax solver `simulate(..., method="ode")` uses when none is given."""
        import diffrax

        return diffrax.Tsit5()

    @classmethod
    def declared_outputs(cls) -> dict:
        """`{name: kind}` of the outputs declared with `@observable` ("point") and `@integrand` ("integral")."""
        cache = cls.__dict__.get("_outputs_cache")
        if cache is None:
            cache = _collect(cls)
            type.__setattr__(cls, "_outputs_cache", cache)
        return {k: v[0] for k, v in cache.items()}

    @classmethod
    def output_names(cls) -> tuple[str, ...]:
        return tuple(k for k, v in cls.declared_outputs().items() if v == "point")

    @classmethod
    def integral_names(cls) -> tuple[str, ...]:
        return tuple(k for k, v in cls.declared_outputs().items() if v == "integral")

    def _method_for(self, name: str, kind: str):
        self.declared_outputs()
        entry = type(self).__dict__["_outputs_cache"].get(name)
        if entry is None or entry[0] != kind:
            names = self.output_names() if kind == "point" else self.integral_names()
            extra = self.state_names if kind == "point" else ()
            what = "output" if kind == "point" else "integral output"
            raise ValueError(f"{type(self).__name__} has no {what} {name!r}; available: {extra + names}")
        return getattr(self, entry[1])

    def output(self, name: str, t, y, inp):
        """Value of the named output (a state or an `@observable`) at one time `t` and state `y`."""
        if name in self.state_names:
            return y[self.state_names.index(name)]
        return self._method_for(name, "point")(t, y, inp)

    def rate(self, name: str, t, y, inp):
        """Integrand of the named `@integrand` output at one time."""
        return self._method_for(name, "integral")(t, y, inp)


class AbstractLinearModel(AbstractModel):
    """A linear time-invariant model $\\dot x = A x + b\\,u(t) + c$ with a scalar input $u$.

    `linear_system()` returns `(A, b, c)` with shapes (n, n), (n,), (n,). With an input that is a
    sum of exponentials (`AbstractExponentialVoltage`) `simulate` solves the scene in closed form.
    """

    @abc.abstractmethod
    def linear_system(self):
        """`(A, b, c)` of $\\dot x = A x + b\\,u(t) + c$."""

    def vector_field(self, t, y, inp):
        A, b, c = self.linear_system()
        return A @ y + b * inp(t) + c

    def exponential_form(self, inp):
        """`(A, F, s)` with $\\dot x = A x + \\sum_j F_{:,j} e^{s_j t}$ for an exponential-sum input."""
        A, b, c = self.linear_system()
        amps, rates = inp.exp_terms()
        F = jnp.concatenate([b[:, None] * amps[None, :], c[:, None]], axis=1)
        s = jnp.concatenate([rates, jnp.zeros((1,), dtype=rates.dtype)])
        return A, F, s
