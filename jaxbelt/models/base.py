"""The model protocol that `simulate` relies on.

A model is an `eqx.Module` of SI parameters. `simulate` needs:

- `state_names` (class attribute): names of the state components, in the papers' order;
- `vector_field(t, y, inp)`: $\\dot y = f(t, y, u)$ for the input `inp` (a command or controller);
  `model(t, y, args)` calls it, so `diffrax.ODETerm(model)` works;
- `initial_state(inp)`: the state at the scene's first time (default: zeros, at rest);
- optional `is_linear_for(inp)` and `linear_form(inp)`: `(A, F, s)` when the scene is linear
  time-invariant with an exponential-sum input, $\\dot x = A x + \\sum_j F_{:,j} e^{s_j t}$; `simulate` then solves in
  closed form;
- derived outputs: methods `_out_<name>(t, y, inp)` for each name in `output_names`
  (evaluated at one time; `simulate` maps them over the saved times);
- integral outputs: methods `_rate_<name>(t, y, inp)` for each name in `integral_names`;
  `simulate` integrates them as extra states (no dense buffer is needed).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp


class AbstractModel(eqx.Module):
    """Base class of jaxbelt models (see module docstring for the protocol)."""

    state_names: ClassVar[tuple[str, ...]] = ()
    output_names: ClassVar[tuple[str, ...]] = ()
    integral_names: ClassVar[tuple[str, ...]] = ()

    def vector_field(self, t, y, inp):
        raise NotImplementedError

    def __call__(self, t, y, args):
        return self.vector_field(t, y, args)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    def initial_state(self, inp):
        return jnp.zeros((self.n_states,))

    def is_linear_for(self, inp) -> bool:
        """Whether `linear_form(inp)` gives a closed form; decided from types, nothing computed."""
        return False

    def linear_form(self, inp):
        """`(A, F, s)` for an LTI scene with exponential-sum input, else `None`."""
        return None

    def default_solver(self):
        """The diffrax solver `simulate(..., method="ode")` uses when none is given."""
        import diffrax

        return diffrax.Tsit5()

    def output(self, name: str, t, y, inp):
        """Value of the named output at one time `t` and state `y`."""
        if name in self.state_names:
            return y[self.state_names.index(name)]
        fn = getattr(self, f"_out_{name}", None)
        if fn is None:
            raise ValueError(
                f"{type(self).__name__} has no output {name!r}; available: "
                f"{self.state_names + self.output_names}"
            )
        return fn(t, y, inp)

    def rate(self, name: str, t, y, inp):
        fn = getattr(self, f"_rate_{name}", None)
        if fn is None:
            raise ValueError(
                f"{type(self).__name__} has no integral output {name!r}; available: {self.integral_names}"
            )
        return fn(t, y, inp)
