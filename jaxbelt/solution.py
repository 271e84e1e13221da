"""`Solution`: what `simulate` returns, and `SolveError`, what it raises."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import is_concrete
from ._display import Display, Table, fmt, output_unit, require


class SolveError(RuntimeError):
    """A simulation failed (solver did not reach the final time, or produced non-finite values).

    `indices`: the failing elements of a `jb.sweep` (None otherwise)."""

    indices: np.ndarray | None = None


class BatchAxis(eqx.Module):
    """The parameter a batched `Solution` sweeps along its leading axis: `values` (B,) of the parameter `name`,
    in `unit` (e.g. the time constants γ [s] of an `ExponentialVoltage` carrying an array)."""

    values: jnp.ndarray
    name: str = eqx.field(static=True)
    unit: str = eqx.field(static=True, default="")


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
      `spectral_radius`;
    - `model`: the name of the scene's model class ('' when not recorded); `method`: the method that solved it;
    - `batch`: for a batch solved at once (a command carrying an array of parameters, e.g.
      `ExponentialVoltage(24.0, gammas)`: `ys` (B, N, n)), the swept parameter as a `BatchAxis`; None otherwise
      (a batch made by `jax.vmap` or `jb.sweep` has a leading axis of its own but no record of the parameter).

    Named access: `sol.current`, `sol["omega2"]`, `sol.electric_power` for any state or
    observed output.

    In a notebook a solution shows as a table of its states and outputs with their units; `str(sol)` is the
    same as text. `sol.to_xarray()` and `sol.to_pandas()` give the labelled data (the extra `jaxbelt[notebook]`).
    """

    ts: jnp.ndarray
    ys: jnp.ndarray | None
    outputs: dict
    success: jnp.ndarray
    stats: dict
    state_names: tuple = eqx.field(static=True, default=())
    method: str = eqx.field(static=True, default="")
    model: str = eqx.field(static=True, default="")
    batch: BatchAxis | None = None

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
        if name.startswith("_") or name in (
            "ts",
            "ys",
            "outputs",
            "success",
            "stats",
            "state_names",
            "method",
            "model",
            "batch",
        ):
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError as e:
            raise AttributeError(str(e)) from None

    @property
    def y_final(self):
        """State at the last output time."""
        return None if self.ys is None else self.ys[..., -1, :]

    # --- labelled data ----------------------------------------------------------------------------------------
    def _series(self) -> dict:
        """`{name: (host array, unit)}` of the states (when kept) and the observed outputs, in that order."""
        out = {}
        if self.ys is not None:
            ys = np.asarray(self.ys)
            for i, name in enumerate(self.state_names):
                out[name] = (ys[..., i], output_unit(self.model, name))
        for name, v in self.outputs.items():
            if name not in out:
                out[name] = (np.asarray(v), output_unit(self.model, name))
        return out

    def _times(self, owner: str) -> np.ndarray:
        """The output times (N,) [s]; one row of a batch's (the same for every element: `vmap` repeats them)."""
        ts = np.asarray(self.ts)
        if ts.ndim > 1:
            first = ts.reshape(-1, ts.shape[-1])[0]
            if not np.array_equal(ts, np.broadcast_to(first, ts.shape)):
                raise ValueError(f"Solution.{owner}: the elements of this batch have different output times")
            ts = first
        return ts

    def _batch_dims(self, batch, owner: str) -> list[tuple[str, np.ndarray | None, str]]:
        """`[(dimension name, coordinate values or None, unit)]` of the leading batch axes (outermost first)."""
        shape = np.shape(self.success)
        if not shape:
            return []
        if batch is None and self.batch is not None:
            batch = (self.batch.name, self.batch.values, self.batch.unit)
        inner: tuple[str, np.ndarray | None, str]
        if batch is None:
            inner = ("batch", None, "")
        elif isinstance(batch, str):
            inner = (batch, None, "")
        elif isinstance(batch, tuple) and len(batch) in (2, 3) and isinstance(batch[0], str):
            values = np.asarray(batch[1])
            if values.shape != shape[-1:]:
                raise ValueError(
                    f"Solution.{owner}: the values of `batch` {batch[0]!r} must have the batch's length "
                    f"{shape[-1]}; got shape {values.shape}"
                )
            inner = (batch[0], values, str(batch[2]) if len(batch) == 3 else "")
        else:
            raise TypeError(
                f"Solution.{owner}: `batch` must be None, a dimension name, or (name, values) / (name, values, unit); "
                f"got {batch!r}"
            )
        outer: list[tuple[str, np.ndarray | None, str]] = [(f"batch{i}", None, "") for i in range(len(shape) - 1)]
        return outer + [inner]

    def to_xarray(self, batch=None):
        """The solution as an `xarray.Dataset`: one variable per state and observed output over the dimension `t`
        (the output times [s], a coordinate), each with its unit in `attrs["units"]`; `success` as a variable; the
        model and the method in the dataset's `attrs`.

        A batched solution has a leading dimension too, named after the swept parameter with its values as the
        coordinate: the one `simulate` recorded (`sol.batch`: `gamma` [s] for `ExponentialVoltage(24.0, gammas)`),
        or the one given as `batch=("gamma", gammas)` (or `("gamma", gammas, "s")` with the unit) for a batch made
        by `jax.vmap` or `jb.sweep`; a name alone (`batch="gamma"`) names the dimension without coordinate
        values; otherwise the dimension is `batch`. Needs xarray (`pip install "jaxbelt[notebook]"`).
        """
        xr = require("xarray")
        ts = self._times("to_xarray")
        dims = self._batch_dims(batch, "to_xarray")
        names = [d[0] for d in dims]
        coords = {"t": ("t", ts, {"units": "s", "long_name": "time"})}
        for name, values, unit in dims:
            if values is not None:
                coords[name] = (name, values, {"units": unit} if unit else {})
        data = {}
        for name, (v, unit) in self._series().items():
            vdims = names + (["t"] if v.ndim == len(names) + 1 and v.shape[-1] == ts.shape[0] else [])
            vdims += [f"{name}_dim{i}" for i in range(v.ndim - len(vdims))]
            data[name] = (vdims, v, {"units": unit} if unit else {})
        data["success"] = (names, np.asarray(self.success), {})
        return xr.Dataset(data, coords=coords, attrs={"model": self.model, "method": self.method})

    def to_pandas(self, batch=None):
        """The solution as a `pandas.DataFrame`: one column per state and observed output, indexed by the output
        times `t` [s]; the units in `df.attrs["units"]` (`{column: unit}`), the model and the method in
        `df.attrs`. A batched solution is a long table indexed by (batch parameter, `t`): see `to_xarray` for
        how the batch dimension is named (`batch=`). Needs pandas (`pip install "jaxbelt[notebook]"`)."""
        pd = require("pandas")
        ts = self._times("to_pandas")
        dims = self._batch_dims(batch, "to_pandas")
        shape = np.shape(self.success)
        columns, units = {}, {}
        for name, (v, unit) in self._series().items():
            if v.shape != shape + ts.shape:
                raise ValueError(f"Solution.to_pandas: {name!r} of shape {v.shape} is not one value per output time")
            columns[name] = v.reshape(-1)
            units[name] = unit
        if dims:
            levels = [values if values is not None else np.arange(n) for (_, values, _), n in zip(dims, shape)]
            index = pd.MultiIndex.from_product([*levels, ts], names=[d[0] for d in dims] + ["t"])
            units.update({d[0]: d[2] for d in dims if d[2]})
        else:
            index = pd.Index(ts, name="t")
        df = pd.DataFrame(columns, index=index)
        df.attrs.update(units={"t": "s", **units}, model=self.model, method=self.method)
        return df

    # --- display ----------------------------------------------------------------------------------------------
    def _display(self) -> Display:
        ts = np.asarray(self.ts)
        ok = np.asarray(self.success)
        shape = ok.shape
        fields: list[tuple] = [("model", self.model or "–", ""), ("method", self.method or "–", "")]
        if ts.size:
            fields.append(("time span", f"{fmt(ts.min())} – {fmt(ts.max())}", "s"))
            fields.append(("output times", int(ts.shape[-1]), ""))
        if shape:
            b = self.batch
            if b is not None and np.ndim(b.values) == 1:
                v = np.asarray(b.values)
                what = f"{b.name}: {v.size} values, {fmt(v.min())} – {fmt(v.max())}"
                fields.append(("batch", what, b.unit))
            else:
                fields.append(("batch", " × ".join(map(str, shape)) + " elements", ""))
            fields.append(("success", "yes" if ok.all() else f"{int(ok.sum())} of {ok.size} elements", ""))
        else:
            fields.append(("success", bool(ok), ""))
        headers = ("name", "kind", "unit", "shape", "min", "max") + (() if shape else ("final",))
        rows = []
        for name, (v, unit) in self._series().items():
            kind = "state" if self.ys is not None and name in self.state_names else "output"
            finite = v[np.isfinite(v)] if v.size else v
            lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
            row = (name, kind, unit or "–", "×".join(map(str, v.shape)) or "()", lo, hi)
            rows.append(row + (() if shape else (float(v.reshape(-1)[-1]) if v.size else np.nan,)))
        return Display("jaxbelt Solution", tuple(fields), (Table(headers, tuple(rows), caption="states and outputs"),))

    def _repr_html_(self):
        if not is_concrete(self):
            return None  # traced (inside jit/vmap/grad): the plain repr
        return self._display().html()

    def __str__(self) -> str:
        if not is_concrete(self):
            return repr(self)
        return self._display().text()
