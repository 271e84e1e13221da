"""`Scene`: what the user wants computed — model, input, times and observed outputs.

`simulate(scene)` reads the scene and does the least work that answers it: closed form for
linear time-invariant scenes, the final state only when no time grid is asked for, derived
outputs only when named in `observe`, integrals as augmented states.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import as_float_array, check_fits, check_real, is_concrete
from ._model import AbstractModel
from .commands import AbstractInput


def _as_tuple(observe):
    """`observe` as a tuple of output names: a bare string (whose letters would be the names) is refused."""
    if observe is None:
        return ()
    message = (
        "Scene: parameter `observe` must be a tuple (or list) of output names, e.g. "
        f"observe=('current',); got {observe!r} ({type(observe).__name__})"
    )
    if isinstance(observe, (str, bytes)):
        raise TypeError(message)
    try:
        return tuple(observe)
    except TypeError:
        raise TypeError(message) from None


def _check_real(name: str, value, unit: str) -> None:
    """`TypeError` naming `name` unless it holds real numbers (a string or complex times would fail in NumPy
    without naming it, or lose their imaginary part); a list of tracers is left to the conversion."""
    if value is not None and (is_concrete(value) or hasattr(value, "dtype")):
        check_real(name, value, unit, "Scene")


class TracedGridWarning(UserWarning):
    """A scene's output times are traced, so `simulate` cannot see that they are evenly spaced."""


_START_MESSAGE = (
    "Scene: the start time (`t0`, or `ts[0]` without it) must be >= 0 s: times count from the start "
    "of the input command (t = 0), which is not defined before it"
)


def _check_start(start: float, name: str) -> None:
    if start < 0:
        raise ValueError(f"{_START_MESSAGE}; got {name} = {start}")


class Scene(eqx.Module):
    """A simulation request.

    - `model`: a jaxbelt model (e.g. `BeltStartup()`).
    - `input`: its input, of a kind the model accepts (`model.input_types`), e.g.
      `ExponentialVoltage(24.0, 0.02)` or `PID(...)`; any other kind raises `TypeError`.
    - `ts`: strictly increasing output times [s], shape (N,).
    - `t0`: start time [s], where the initial state holds (default `ts[0]`; must be <= `ts[0]`);
      `scene.start_time` is the start in either case. Times count from the start of the input
      command (t = 0, where a voltage step or a motion begins), so the start must be >= 0.
    - `t1`: final time [s] when `ts` is not given: only the state at `t1` is returned
      (no dense buffer); `t0` then defaults to 0.
    - `observe`: names of outputs to compute besides the state (e.g. `("current",
      "electric_power", "alpha2")`, or integral outputs such as `"electric_energy"`; see
      `model.available_outputs()`). Nothing that is not named is computed.
    - `y0`: initial state (default: the model's rest state), shape `(model.n_states,)`.
    - `state`: whether the full state history `ys` is returned (set `False` to get only
      the observed outputs).
    - `uniform`: whether `ts` is evenly spaced. Default `None`: for concrete times the closed form reads
      the spacing from the values inside its compiled program (one program for grids of any spacing;
      an evenly spaced grid is stepped with one transition matrix). Under `jax.jit` with a traced `ts`
      the closed form compares each step with the last in its program (one matrix exponential per distinct
      step, a test per output time) and a `TracedGridWarning` says so, unless you pass `uniform=True` (a promise: the spacing is taken as
      `(ts[-1] - ts[0]) / (N - 1)`) or `uniform=False` (explicitly the general path, no warning).

    Times and the initial state are data: a new grid, start time or initial state of the same
    shape does not recompile `simulate`.
    """

    model: AbstractModel
    input: AbstractInput
    ts: jnp.ndarray | None = None
    t0: jnp.ndarray | None = None
    t1: jnp.ndarray | None = None
    observe: tuple[str, ...] = eqx.field(static=True, default=())
    y0: jnp.ndarray | None = None
    state: bool = eqx.field(static=True, default=True)
    uniform: bool | None = eqx.field(static=True, default=False)

    def __init__(self, model, input, ts=None, *, t0=None, t1=None, observe=None, y0=None, state=True, uniform=None):
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
        if is_concrete((model, input)):
            for ok, message in model.input_checks(input):
                if not bool(np.all(np.asarray(ok))):
                    raise ValueError(message)
        self.observe = observe = _as_tuple(observe)
        for name in observe:
            if not isinstance(name, str):
                raise TypeError(f"Scene: `observe` holds output names (str); got {name!r}")
        if observe:
            known = model.available_outputs()
            unknown = [n for n in observe if n not in known]
            if unknown:
                raise ValueError(f"Scene: {type(model).__name__} has no output {unknown[0]!r}; available: {known}")
        self.state = bool(state)
        if ts is not None and np.ndim(ts) == 1:
            # bounded before anything is converted or allocated: each saved time holds the state and the observed
            # outputs (float64) in the solver's buffer, its host copy, the result's arrays and the time itself
            n_times = int(np.shape(ts)[0])
            columns = int(getattr(model, "n_states", 8)) + len(observe or ()) + 1
            check_fits("Scene", "ts", 4 * 8.0 * columns * n_times, f"{n_times:.3g} saved times")
        for name, v, unit in (("ts", ts, "s"), ("t0", t0, "s"), ("t1", t1, "s"), ("y0", y0, "")):
            _check_real(name, v, unit)
        if y0 is None:
            self.y0 = None
        else:
            n = model.n_states
            self.y0 = y0 = jnp.asarray(y0, dtype=float)
            if y0.shape != (n,):
                raise ValueError(f"Scene: `y0` must have shape ({n},) for {type(model).__name__}; got {y0.shape}")
            if is_concrete(y0) and not np.all(np.isfinite(np.asarray(y0))):
                raise ValueError(f"Scene: `y0` must be finite; got {np.asarray(y0).tolist()}")
        if ts is None and t1 is None:
            raise ValueError("Scene needs either `ts` (output times, s) or `t1` (final time, s)")
        if ts is not None and t1 is not None:
            raise ValueError("Scene takes `ts` (output times) or `t1` (final time only), not both")
        if ts is not None:
            raw = ts
            ts = as_float_array(ts)
            if ts.ndim != 1 or ts.shape[0] < 1:
                raise ValueError(f"Scene: `ts` must be a 1-D array of output times [s]; got shape {ts.shape}")
            if is_concrete(raw):
                tv = np.asarray(raw, dtype=float)
                if not np.isfinite(tv).all():
                    raise ValueError("Scene: `ts` must be finite")
                d = np.diff(tv)
                if d.size and d.min() <= 0:
                    i = int(np.argmax(d <= 0))
                    raise ValueError(
                        f"Scene: `ts` must be strictly increasing; ts[{i}] = {tv[i]} >= ts[{i + 1}] = {tv[i + 1]}"
                    )
                if uniform:
                    # evenly spaced to 1e-12 relative (np.allclose(d, d[0], rtol=1e-12, atol=0), without its overhead)
                    if not (d.size > 0 and np.abs(d - d[0]).max() <= 1e-12 * abs(d[0])):
                        raise ValueError("Scene: `uniform=True` but `ts` is not evenly spaced")
                # uniform=None: the closed form reads the spacing from the values inside its program, so that
                # grids of any spacing are data (one program), and takes one transition matrix where it is even
            elif uniform is None:
                if ts.shape[0] > 2:
                    warnings.warn(
                        "Scene: `ts` is traced, so its spacing cannot be checked; a closed-form solve compares each "
                        "step with the last in its program (a new matrix exponential wherever the step changes). Pass uniform=True if the grid is evenly spaced "
                        "(or uniform=False to silence this warning).",
                        TracedGridWarning,
                        stacklevel=2,
                    )
                uniform = False
            self.ts = ts
            self.uniform = None if uniform is None else bool(uniform)
            # None: the start is ts[0], taken inside the compiled program (no device op here)
            self.t0 = start = None if t0 is None else jnp.asarray(t0, dtype=float)
            if start is not None and jnp.ndim(start) != 0:
                raise ValueError(f"Scene: `t0` must be a scalar time [s]; got shape {jnp.shape(start)}")
            if start is not None and is_concrete(start) and is_concrete(raw):
                if not np.isfinite(float(start)) or float(start) > float(np.asarray(raw)[0]):
                    raise ValueError(
                        f"Scene: `t0` (start time, s) must be finite and <= ts[0] = {float(np.asarray(raw)[0])}; "
                        f"got {float(start)}"
                    )
            if is_concrete(raw) and (start is None or is_concrete(start)):
                _check_start(
                    float(np.asarray(raw)[0]) if start is None else float(start), "ts[0]" if start is None else "t0"
                )
            self.t1 = None
        else:
            self.ts = None
            self.uniform = False
            self.t0 = jnp.asarray(0.0 if t0 is None else t0, dtype=float)
            self.t1 = jnp.asarray(t1, dtype=float)
            for name, v in (("t0", self.t0), ("t1", self.t1)):
                if jnp.ndim(v) != 0:
                    raise ValueError(f"Scene: `{name}` must be a scalar time [s]; got shape {jnp.shape(v)}")
            if is_concrete(self.t0):
                _check_start(float(self.t0), "t0")
            if is_concrete(self.t1) and is_concrete(self.t0):
                if not (
                    np.isfinite(float(self.t0)) and np.isfinite(float(self.t1)) and float(self.t1) > float(self.t0)
                ):
                    raise ValueError(
                        f"Scene: `t1` (final time, s) must be finite and > t0 = {float(self.t0)}; got {float(self.t1)}"
                    )

    @property
    def final_only(self) -> bool:
        return self.ts is None

    @property
    def start_time(self):
        """Time [s] at which the initial state holds: `t0`, or `ts[0]` when `t0` was not given."""
        if self.t0 is not None:
            return self.t0
        assert self.ts is not None  # a final-state scene always has its `t0` (`__init__`)
        return self.ts[0]

    @property
    def times(self):
        """Output times: `ts`, or `[t1]` for a final-state scene."""
        if self.ts is not None:
            return self.ts
        assert self.t1 is not None  # `__init__`: `ts` or `t1`
        return self.t1[None]

    def time_errors(self):
        """`[(ok, message)]` for the time checks that values decide (evaluated under `jit` too)."""
        t_first = self.times[0]
        t0 = self.start_time
        checks = [
            (jnp.isfinite(t0) & (t0 <= t_first), "Scene: `t0` must be finite and <= the first output time"),
            (t0 >= 0, _START_MESSAGE),
        ]
        if self.ts is not None and self.ts.shape[0] > 1:
            checks.append(
                (
                    jnp.all(jnp.diff(self.ts) > 0) & jnp.all(jnp.isfinite(self.ts)),
                    "Scene: `ts` must be finite and strictly increasing",
                )
            )
        elif self.ts is None:
            t1 = self.times[0]
            checks.append((jnp.isfinite(t1) & (t1 > t0), "Scene: `t1` must be finite and > t0"))
        if self.y0 is not None:
            checks.append((jnp.all(jnp.isfinite(self.y0)), "Scene: `y0` must be finite"))
        return checks
