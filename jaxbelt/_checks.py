"""Parameter checks shared by every model and command.

Checks run when values are concrete (construction outside `jit`/`vmap`) and raise
`ValueError` naming the parameter and its valid range. Under a transformation the values are
tracers: the check is then *recorded* (when `jaxbelt._guard.traced_checks` is collecting) as a
boolean array and a message, and `simulate` and the objectives attach it with `eqx.error_if` to
the values they return, so an invalid traced parameter still raises at run time (or is flagged
with `throw=False`).
"""

from __future__ import annotations

import contextlib
import math
import threading

import jax
import jax.numpy as jnp
import numpy as np


_SCALARS: dict = {}
_SCALARS_MAX = 4096


def as_float_array(x):
    """Field converter of every model and command: parameters become float arrays (float64 with x64),
    so they are traced under jit instead of being baked in as constants.

    A construction converts ~30 fields; `jnp.asarray` costs tens of microseconds each, so the two
    common cases are short-cut: an array that already has the float dtype is returned as is, and
    Python scalars (defaults, literals) come from a cache of immutable device arrays."""
    dtype = jax.dtypes.canonicalize_dtype(float)
    if isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and x.dtype == dtype and not x.weak_type:
        return x
    if type(x) in (float, int):
        key = (x, math.copysign(1.0, x), dtype)
        hit = _SCALARS.get(key)
        if hit is None:
            # made outside any trace: a cached tracer would leak into later, unrelated programs
            with jax.ensure_compile_time_eval():
                hit = jnp.asarray(x, dtype=dtype)
            if isinstance(hit, jax.core.Tracer):
                return hit
            if len(_SCALARS) >= _SCALARS_MAX:
                _SCALARS.clear()
            _SCALARS[key] = hit
        return hit
    return jnp.asarray(x, dtype=float)


def is_concrete(x) -> bool:
    """True when `x` holds values (not a tracer inside jit/vmap/grad)."""
    leaves = jax.tree_util.tree_leaves(x)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


_collector = threading.local()


def record(ok, message: str) -> None:
    """Record a traced check while `collecting()` is active (see `jaxbelt._guard.traced_checks`)."""
    found = getattr(_collector, "found", None)
    if found is not None:
        found.append((jnp.asarray(ok, dtype=bool), message))


@contextlib.contextmanager
def collecting():
    """Collect the checks recorded inside the block as a list of `(ok, message)`."""
    prev = getattr(_collector, "found", None)
    _collector.found = found = []
    try:
        yield found
    finally:
        _collector.found = prev


_record = record


def _interval(lo, hi, lo_open, hi_open) -> str:
    lb = "-inf" if lo is None else f"{lo:g}"
    ub = "inf" if hi is None else f"{hi:g}"
    return f"{'(' if lo_open or lo is None else '['}{lb}, {ub}{')' if hi_open or hi is None else ']'}"


def _values(x):
    return np.asarray(jax.device_get(x), dtype=float)


def check_positive(name: str, value, unit: str = "", owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite and > 0."""
    if not is_concrete(value):
        v = jnp.asarray(value)
        where = f"{owner}: " if owner else ""
        _record(jnp.all(jnp.isfinite(v) & (v > 0)), f"{where}parameter `{name}` must be finite and > 0{(' ' + unit) if unit else ''}")
        return
    v = _values(value)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        where = f"{owner}: " if owner else ""
        raise ValueError(
            f"{where}parameter `{name}` must be finite and > 0{(' ' + unit) if unit else ''}; "
            f"got {v.tolist() if v.ndim else float(v)}"
        )


def check_nonnegative(name: str, value, unit: str = "", owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite and >= 0."""
    if not is_concrete(value):
        v = jnp.asarray(value)
        where = f"{owner}: " if owner else ""
        _record(jnp.all(jnp.isfinite(v) & (v >= 0)), f"{where}parameter `{name}` must be finite and >= 0{(' ' + unit) if unit else ''}")
        return
    v = _values(value)
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        where = f"{owner}: " if owner else ""
        raise ValueError(
            f"{where}parameter `{name}` must be finite and >= 0{(' ' + unit) if unit else ''}; "
            f"got {v.tolist() if v.ndim else float(v)}"
        )


def check_finite(name: str, value, owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite."""
    if not is_concrete(value):
        where = f"{owner}: " if owner else ""
        _record(jnp.all(jnp.isfinite(jnp.asarray(value))), f"{where}parameter `{name}` must be finite")
        return
    v = _values(value)
    if not np.all(np.isfinite(v)):
        where = f"{owner}: " if owner else ""
        raise ValueError(f"{where}parameter `{name}` must be finite; got {v.tolist() if v.ndim else float(v)}")


def check_range(name: str, value, lo=None, hi=None, *, lo_open=False, hi_open=False, unit="", owner="") -> None:
    """Raise `ValueError` unless lo (<|<=) value (<|<=) hi elementwise."""
    if not is_concrete(value):
        v = jnp.asarray(value)
        ok = jnp.all(jnp.isfinite(v))
        if lo is not None:
            ok &= jnp.all(v > lo) if lo_open else jnp.all(v >= lo)
        if hi is not None:
            ok &= jnp.all(v < hi) if hi_open else jnp.all(v <= hi)
        where = f"{owner}: " if owner else ""
        _record(ok, f"{where}parameter `{name}` must lie in {_interval(lo, hi, lo_open, hi_open)}{(' ' + unit) if unit else ''}")
        return
    v = _values(value)
    ok = np.all(np.isfinite(v))
    if lo is not None:
        ok &= bool(np.all(v > lo) if lo_open else np.all(v >= lo))
    if hi is not None:
        ok &= bool(np.all(v < hi) if hi_open else np.all(v <= hi))
    if not ok:
        interval = _interval(lo, hi, lo_open, hi_open)
        where = f"{owner}: " if owner else ""
        raise ValueError(
            f"{where}parameter `{name}` must lie in {interval}{(' ' + unit) if unit else ''}; "
            f"got {v.tolist() if v.ndim else float(v)}"
        )


_KINDS = {
    "positive": (lambda v: np.all(np.isfinite(v)) and not np.any(v <= 0), "must be finite and > 0"),
    "nonnegative": (lambda v: np.all(np.isfinite(v)) and not np.any(v < 0), "must be finite and >= 0"),
    "finite": (lambda v: np.all(np.isfinite(v)), "must be finite"),
}


def host_values(values):
    """Host copies (float numpy arrays) of a list of concrete values, in one transfer; None under a trace."""
    if not is_concrete(values):
        return None
    return [None if v is None else np.asarray(v, dtype=float) for v in jax.device_get(list(values))]


def check_fields(owner: str, checks) -> list | None:
    """Check many fields at once: `checks` is a sequence of `(name, value, kind, unit)` with kind
    `"positive"`, `"nonnegative"` or `"finite"`. One transfer for all the values (a construction costs
    one device round trip, not one per field); the first failure raises the `ValueError` of the
    corresponding `check_*`. Returns the host values (None under a trace: nothing is checked).
    """
    checks = list(checks)
    vals = host_values([c[1] for c in checks])
    if vals is None:
        # traced: record each check (see `jaxbelt._guard.traced_checks`), so it is enforced at run time
        single = {"positive": check_positive, "nonnegative": check_nonnegative}
        for name, value, kind, unit in checks:
            if kind == "finite":
                check_finite(name, value, owner=owner)
            else:
                single[kind](name, value, unit, owner=owner)
        return None
    for (name, _, kind, unit), v in zip(checks, vals):
        ok, what = _KINDS[kind]
        if not ok(v):
            where = f"{owner}: " if owner else ""
            raise ValueError(
                f"{where}parameter `{name}` {what}{(' ' + unit) if unit else ''}; "
                f"got {v.tolist() if v.ndim else float(v)}"
            )
    return vals
