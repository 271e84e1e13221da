"""The model protocol that `simulate` relies on (the ground floor: it imports no other part of jaxbelt
but the parameter declarations).

A model is an `eqx.Module` of SI parameters deriving from `AbstractModel`, in equinox's
abstract-or-final style: the abstract classes declare what a model must give (`AbstractVar`,
`AbstractClassVar`, `abc.abstractmethod`), the concrete ones are final and override no concrete method.

- `input_types` (class attribute): the input kinds it accepts (classes from `jaxbelt.commands`);
  `Scene` raises `TypeError` for any other input;
- `state_names`: names of the state components, in the papers' order;
- `vector_field(t, y, inp)`: $\\dot y = f(t, y, u)$; `model(t, y, args)` calls it, so
  `diffrax.ODETerm(model)` works;
- `initial_state(inp)`: the state at the scene's first time;
- `input_checks(inp)`: checks that need the model and its input together, as `[(ok, message)]`;
- `default_solver()`: the diffrax solver `simulate(..., method="ode")` uses when none is given;
- derived outputs: methods decorated with `@observable("name")`, `fn(t, y, inp)` evaluated at one
  time (`simulate` maps them over the saved times); a family of numbered outputs
  (`alpha1`, `alpha2`, ... of a belt chain) with `@observable_family("alpha", size="n_shafts")`, whose
  method returns the vector; integral outputs: methods decorated with `@integrand("name")` returning
  the integrand, integrated as extra states by `simulate`. The names are collected from the decorators.

A linear time-invariant model derives from `AbstractLinearModel` and gives
$\\dot x = A x + b\\,u(t) + c$ through `linear_system()`; driven by an
`AbstractExponentialVoltage` it is solved in closed form.
"""

import abc
from typing import Any

import jax.numpy as jnp
from equinox import AbstractClassVar
from jaxtyping import Array, Float

from ._params import Parametrised

_KIND = "_jaxbelt_output"

#: a state vector of n components / its time derivative
State = Float[Array, " n"]
#: a time [s] (a scalar array or a Python float)
Time = Float[Array, ""] | float


def observable(name: str):
    """Declare a method `fn(self, t, y, inp)` as the derived output `name` of its model."""

    def mark(fn):
        setattr(fn, _KIND, ("point", name, None))
        return fn

    return mark


def observable_family(prefix: str, size: str):
    """Declare a method `fn(self, t, y, inp)` returning a vector as the numbered outputs `prefix1`,
    `prefix2`, ... `prefix{N}` of its model, N the value of the model's attribute `size`."""

    def mark(fn):
        setattr(fn, _KIND, ("family", prefix, size))
        return fn

    return mark


def integrand(name: str):
    """Declare a method `fn(self, t, y, inp)` as the integrand of the integral output `name`."""

    def mark(fn):
        setattr(fn, _KIND, ("integral", name, None))
        return fn

    return mark


def _collect(cls) -> dict:
    found = {}
    for klass in reversed(cls.__mro__):
        for attr, val in vars(klass).items():
            tag = getattr(val, _KIND, None)
            if tag is not None:
                found[tag[1]] = (tag[0], attr, tag[2])
    return found


class AbstractModel(Parametrised):
    """Base class of jaxbelt models (see the module docstring for the protocol)."""

    input_types: AbstractClassVar[tuple[type, ...]]

    @property
    @abc.abstractmethod
    def state_names(self) -> tuple[str, ...]:
        """Names of the state components, in the papers' order."""

    @abc.abstractmethod
    def vector_field(self, t: Time, y: State, inp: Any) -> State:
        """$\\dot y$ at time `t` [s] and state `y` for the input `inp`."""

    @abc.abstractmethod
    def initial_state(self, inp: Any) -> State:
        """The state at the scene's first time."""

    @abc.abstractmethod
    def input_checks(self, inp: Any) -> list:
        """Checks that need the model and its input together (e.g. a running speed below the belt's
        critical speed), as `[(ok, message)]`; `ok` a boolean array. `Scene` raises `ValueError` for a
        concrete failure; `simulate` attaches traced ones to its results."""

    @abc.abstractmethod
    def default_solver(self) -> Any:
        """The diffrax solver `simulate(..., method="ode")` uses when none is given."""

    def __call__(self, t: Time, y: State, args: Any) -> State:
        return self.vector_field(t, y, args)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @classmethod
    def declared_outputs(cls) -> dict:
        """`{name: kind}` of the outputs declared with `@observable` ("point"), `@observable_family`
        ("family", keyed by prefix) and `@integrand` ("integral")."""
        cache = cls.__dict__.get("_outputs_cache")
        if cache is None:
            cache = _collect(cls)
            type.__setattr__(cls, "_outputs_cache", cache)
        return {k: v[0] for k, v in cache.items()}

    @classmethod
    def output_names(cls) -> tuple[str, ...]:
        """The names of the single derived outputs (`@observable`)."""
        return tuple(k for k, v in cls.declared_outputs().items() if v == "point")

    @classmethod
    def integral_names(cls) -> tuple[str, ...]:
        return tuple(k for k, v in cls.declared_outputs().items() if v == "integral")

    def _family_member(self, name: str):
        """`(method, index)` when `name` is member k of a declared family (`alpha3`), else None."""
        self.declared_outputs()
        for prefix, (kind, attr, size) in type(self).__dict__["_outputs_cache"].items():
            if kind != "family" or not name.startswith(prefix) or not name[len(prefix) :].isdigit():
                continue
            k = int(name[len(prefix) :])
            if 1 <= k <= int(getattr(self, size)):
                return getattr(self, attr), k - 1
        return None

    def available_outputs(self) -> tuple[str, ...]:
        """Every name `Scene(observe=...)` accepts for this model: states, outputs (families expanded),
        integrals."""
        self.declared_outputs()
        fam = []
        for prefix, (kind, _, size) in type(self).__dict__["_outputs_cache"].items():
            if kind == "family":
                fam += [f"{prefix}{k}" for k in range(1, int(getattr(self, size)) + 1)]
        return tuple(self.state_names) + self.output_names() + tuple(fam) + self.integral_names()

    def accepts_output(self, name: str) -> bool:
        return name in self.available_outputs()

    def output(self, name: str, t, y: State, inp: Any):
        """Value of the named output (a state, an `@observable` or a family member) at one time `t` and state `y`."""
        if name in self.state_names:
            return y[self.state_names.index(name)]
        self.declared_outputs()
        entry = type(self).__dict__["_outputs_cache"].get(name)
        if entry is not None and entry[0] == "point":
            return getattr(self, entry[1])(t, y, inp)
        member = self._family_member(name)
        if member is not None:
            return member[0](t, y, inp)[member[1]]
        raise ValueError(f"{type(self).__name__} has no output {name!r}; available: {self.available_outputs()}")

    def rate(self, name: str, t, y: State, inp: Any):
        """Integrand of the named `@integrand` output at one time."""
        self.declared_outputs()
        entry = type(self).__dict__["_outputs_cache"].get(name)
        if entry is None or entry[0] != "integral":
            raise ValueError(
                f"{type(self).__name__} has no integral output {name!r}; available: {self.integral_names()}"
            )
        return getattr(self, entry[1])(t, y, inp)


class AbstractLinearModel(AbstractModel):
    """A linear time-invariant model $\\dot x = A x + b\\,u(t) + c$ with a scalar input $u$.

    `linear_system()` returns `(A, b, c)` with shapes (n, n), (n,), (n,). With an input that is a
    sum of exponentials (`AbstractExponentialVoltage`) `simulate` solves the scene in closed form.
    """

    @abc.abstractmethod
    def linear_system(self) -> tuple[Float[Array, "n n"], Float[Array, " n"], Float[Array, " n"]]:
        """`(A, b, c)` of $\\dot x = A x + b\\,u(t) + c$."""

    def vector_field(self, t: Time, y: State, inp: Any) -> State:
        A, b, c = self.linear_system()
        return A @ y + b * inp(t) + c

    def exponential_form(self, inp: Any):
        """`(A, F, s)` with $\\dot x = A x + \\sum_j F_{:,j} e^{s_j t}$ for an exponential-sum input."""
        A, b, c = self.linear_system()
        amps, rates = inp.exp_terms()
        F = jnp.concatenate([b[:, None] * amps[None, :], c[:, None]], axis=1)
        s = jnp.concatenate([rates, jnp.zeros((1,), dtype=rates.dtype)])
        return A, F, s
