"""`Scene`: what the user wants computed — model, input, times and observed outputs.

`simulate(scene)` reads the scene and does the least work that answers it: closed form for
linear time-invariant scenes, the final state only when no time grid is asked for, derived
outputs only when named in `observe`, integrals as augmented states.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import is_concrete


def _as_tuple(observe):
    if observe is None:
        return ()
    if isinstance(observe, str):
        return (observe,)
    return tuple(observe)


class Scene(eqx.Module):
    """A simulation request.

    - `model`: a jaxbelt model (e.g. `BeltStartup()`).
    - `input`: its command or controller (e.g. `ExponentialVoltage(24.0, 0.02)`, `PID(...)`).
    - `ts`: increasing output times [s], shape (N,). The initial state holds at `ts[0]`.
    - `t1`: final time [s] when `ts` is not given: only the state at `t1` is returned
      (no dense buffer). `t0` is then the start time (default 0).
    - `observe`: names of outputs to compute besides the state (e.g. `("current",
      "electric_power", "alpha2")`, or integral outputs such as `"electric_energy"`).
      Nothing that is not named is computed. `"state"` is implied unless `state=False`.
    - `y0`: initial state (default: the model's rest state).
    - `state`: whether the full state history `ys` is returned (set `False` to get only
      the observed outputs).
    """

    model: eqx.Module
    input: eqx.Module
    ts: jnp.ndarray | None = None
    t0: jnp.ndarray | None = None
    t1: jnp.ndarray | None = None
    observe: tuple[str, ...] = eqx.field(static=True, default=())
    y0: jnp.ndarray | None = None
    state: bool = eqx.field(static=True, default=True)
    uniform: bool = eqx.field(static=True, default=False)
    max_spacing: float | None = eqx.field(static=True, default=None)

    def __init__(self, model, input, ts=None, *, t0=None, t1=None, observe=None, y0=None, state=True):
        types = getattr(type(model), "input_types", None)
        if types is None:
            raise TypeError(f"Scene: `model` must be a jaxbelt model (an AbstractModel); got {type(model).__name__}")
        if not isinstance(input, types):
            kinds = " or ".join(t.__name__ for t in types)
            raise TypeError(
                f"Scene: {type(model).__name__} is driven by an input of kind {kinds}; got {type(input).__name__}"
            )
        self.model = model
        self.input = input
        self.observe = _as_tuple(observe)
        self.state = bool(state)
        self.y0 = None if y0 is None else jnp.asarray(y0, dtype=float)
        if ts is None and t1 is None:
            raise ValueError("Scene needs either `ts` (output times, s) or `t1` (final time, s)")
        if ts is not None and t1 is not None:
            raise ValueError("Scene takes `ts` (output times) or `t1` (final time only), not both")
        if ts is not None:
            # Check the values before converting: inside `jit` even a numpy constant becomes a tracer
            # once passed through jnp, and the grid's spacing must stay known (RK4 substeps, uniform grids).
            raw = ts
            ts = jnp.asarray(ts, dtype=float)
            if ts.ndim != 1 or ts.shape[0] < 1:
                raise ValueError(f"Scene: `ts` must be a 1-D array of output times; got shape {ts.shape}")
            uniform = False
            max_spacing = None
            if is_concrete(raw):
                tv = np.asarray(raw, dtype=float)
                d = np.diff(tv)
                if not np.all(np.isfinite(tv)):
                    raise ValueError("Scene: `ts` must be finite")
                if np.any(d <= 0):
                    i = int(np.argmax(d <= 0))
                    raise ValueError(
                        f"Scene: `ts` must be strictly increasing; ts[{i}] = {tv[i]} >= ts[{i + 1}] = {tv[i + 1]}"
                    )
                uniform = bool(d.size > 0 and np.allclose(d, d[0], rtol=1e-12, atol=0.0))
                max_spacing = float(d.max()) if d.size else 0.0
            self.ts = ts
            self.uniform = uniform
            self.max_spacing = max_spacing
            self.t0 = ts[0] if t0 is None else jnp.asarray(t0, dtype=float)
            self.t1 = None
        else:
            self.ts = None
            self.uniform = False
            self.max_spacing = None
            self.t0 = jnp.asarray(0.0 if t0 is None else t0, dtype=float)
            self.t1 = jnp.asarray(t1, dtype=float)
            if is_concrete(self.t1) and is_concrete(self.t0) and not float(self.t1) > float(self.t0):
                raise ValueError(f"Scene: `t1` must be > t0 = {float(self.t0)} s; got {float(self.t1)}")
        if self.y0 is not None and is_concrete(self.y0):
            n = getattr(model, "n_states", None)
            if n is not None and self.y0.shape != (n,):
                raise ValueError(f"Scene: `y0` must have shape ({n},) for {type(model).__name__}; got {self.y0.shape}")

    @property
    def final_only(self) -> bool:
        return self.ts is None

    @property
    def times(self):
        """Output times: `ts`, or `[t1]` for a final-state scene."""
        return self.ts if self.ts is not None else self.t1[None]
