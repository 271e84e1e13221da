"""`Solution`: what `simulate` returns, and `SolveError`, what it raises."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np


class SolveError(RuntimeError):
    """A simulation failed (solver did not reach the final time, or produced non-finite values).

    `indices`: the failing elements of a `jb.sweep` (None otherwise)."""

    indices: np.ndarray | None = None


class Solution(eqx.Module):
    """Result of `simulate`.

    - `ts` (N,): output times [s];
    - `ys` (N, n_states): state history in the model's order (None if `Scene(state=False)`);
    - `outputs`: dict of observed outputs, each (N,) (integrals: value at each output time);
    - `success`: bool (array; per element under `vmap`);
    - `stats`: solver statistics of the ODE and RK4 methods (empty for the closed forms): `num_steps`,
      `num_rejected_steps`, `result` (why the solver stopped: 0 at the final time, 1 the step budget
      `max_steps` reached, 2 the step size at the controller's minimum, 3 another stop of diffrax) and
      `t_final` (the time reached [s]: where the solve stopped when the scene keeps no state history or
      has no output times, otherwise the last output time reached); RK4 adds `rk4_stable` and
      `spectral_radius`.

    Named access: `sol.current`, `sol["omega2"]`, `sol.electric_power` for any state or
    observed output.
    """

    ts: jnp.ndarray
    ys: jnp.ndarray | None
    outputs: dict
    success: jnp.ndarray
    stats: dict
    state_names: tuple = eqx.field(static=True, default=())
    method: str = eqx.field(static=True, default="")

    def __getitem__(self, name: str):
        if name in self.outputs:
            return self.outputs[name]
        if self.ys is not None and name in self.state_names:
            return self.ys[..., self.state_names.index(name)]
        raise KeyError(
            f"{name!r} is not in this solution; states: {self.state_names}, outputs: {tuple(self.outputs)}. "
            "Derived outputs are computed only when named in Scene(observe=...)."
        )

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("ts", "ys", "outputs", "success", "stats", "state_names", "method"):
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError as e:
            raise AttributeError(str(e)) from None

    @property
    def y_final(self):
        """State at the last output time."""
        return None if self.ys is None else self.ys[..., -1, :]
