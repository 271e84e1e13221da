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
import numbers
import threading

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

#: what the first use of jaxbelt with JAX's 64-bit mode off says (see `require_x64`)
X64_MESSAGE = (
    "jaxbelt computes in float64, and JAX's 64-bit mode is off. Add the line\n\n"
    '    jax.config.update("jax_enable_x64", True)\n\n'
    "right after `import jax`, before any array is made (arrays made before it stay float32). jaxbelt does "
    "not switch it on itself: importing a library leaves the process's configuration alone."
)

_F64 = np.dtype(np.float64)


def require_x64(owner: str = "jaxbelt") -> None:
    """Raise `RuntimeError` (`X64_MESSAGE`) unless JAX makes float64 arrays (`jax_enable_x64`, also inside
    a `jax.enable_x64(False)` block). A config read: the first call that builds a model, a command or an
    array (`as_float_array`), and the public functions that take raw arrays, call it."""
    if jax.dtypes.canonicalize_dtype(float) != _F64:
        raise RuntimeError(f"{owner}: {X64_MESSAGE}")


_SCALARS: dict = {}
_SCALARS_MAX = 4096
#: id -> (array, its value) of the arrays in `_SCALARS`: checks read a cached default without a transfer
_HOST: dict = {}


def as_float_array(x):
    """Field converter of every model and command: parameters become float64 arrays, so they are traced
    under jit instead of being baked in as constants. With JAX's 64-bit mode off it raises `RuntimeError`
    naming the line to add (`require_x64`): every model, command and scene is built through here.

    A construction converts ~30 fields; `jnp.asarray` costs tens of microseconds each, so the common
    cases are short-cut: an array that already has the float dtype is returned as is, Python scalars
    (defaults, literals) come from a cache of immutable device arrays, and numpy arrays are
    converted on the host and transferred (`jnp.asarray` would compile a small program for each new
    shape: ~10 ms in a fresh process)."""
    dtype = jax.dtypes.canonicalize_dtype(float)
    if dtype != _F64:
        require_x64()
    t = type(x)
    if t is not np.ndarray and concrete_array_type(t) and x.dtype == dtype and not x.weak_type:
        return x
    if t is float or t is int:
        key = (x, math.copysign(1.0, x), dtype)
        hit = _SCALARS.get(key)
        if hit is None:
            # made outside any trace: a cached tracer would leak into later, unrelated programs
            with jax.ensure_compile_time_eval():
                hit = jax.device_put(np.asarray(x, dtype=dtype))
            if isinstance(hit, Tracer):
                return hit
            if len(_SCALARS) >= _SCALARS_MAX:
                _SCALARS.clear()
                _HOST.clear()
            _SCALARS[key] = hit
            _HOST[id(hit)] = (hit, float(x))
        return hit
    if t is tuple and x and all(type(e) is float or type(e) is int for e in x):
        # a tuple of numbers (a default such as two pulley radii): cached like a number
        key = (x, tuple(math.copysign(1.0, e) for e in x), dtype)
        hit = _SCALARS.get(key)
        if hit is None:
            host = np.asarray(x, dtype=dtype)
            with jax.ensure_compile_time_eval():
                hit = jax.device_put(host)
            if isinstance(hit, Tracer):
                return hit
            if len(_SCALARS) >= _SCALARS_MAX:
                _SCALARS.clear()
                _HOST.clear()
            host = host.astype(float)
            host.flags.writeable = False  # shared by every check that reads it
            _SCALARS[key] = hit
            _HOST[id(hit)] = (hit, host)
        return hit
    if (t is np.ndarray and x.dtype.kind in "fiub") or (
        t is list and all(type(e) is float or type(e) is int for e in x)  # `ModalAxis([7.3], ...)`
    ):
        # converted on the host and transferred: `jnp.asarray` would run a small program per shape
        return jax.device_put(np.asarray(x, dtype=dtype))
    return jnp.asarray(x, dtype=float)


def xp(x):
    """The array module of `x`: numpy for host values (a model's `jax.device_get` copy: its derived constants
    then cost no compiled program), `jax.numpy` otherwise."""
    return np if isinstance(x, (np.ndarray, np.generic, float, int)) else jnp


def atleast_1d(x):
    """`jnp.atleast_1d(x)`, without a compiled program where `x` is concrete (see `device_array`)."""
    if isinstance(x, Tracer):
        return jnp.atleast_1d(x)
    if isinstance(x, jax.Array) and x.ndim >= 1:
        return x
    return device_array(np.atleast_1d(np.asarray(x)))


def device_array(x, dtype=None):
    """`jnp.asarray(x, dtype)` without a compiled program where `x` is concrete: converted on the host and
    transferred. (`jnp.asarray` of a host value, and any eager `jnp` operation, compiles a small program for
    each new shape and dtype in a fresh process: 10-20 ms each, a dozen in a first call.) A tracer goes
    through `jnp.asarray`; a JAX array of that dtype is returned as it is."""
    if isinstance(x, Tracer):
        return jnp.asarray(x, dtype=dtype)
    want = None if dtype is None else jax.dtypes.canonicalize_dtype(dtype)
    if isinstance(x, jax.Array) and (want is None or x.dtype == want):
        return x
    if want is None and type(x) in (bool, int, float, complex):
        return jax.device_put(x)  # weakly typed, as `jnp.asarray` makes a Python number
    return jax.device_put(np.asarray(x, dtype=want))


#: leaf types known to be concrete arrays (jax's array types are added when first seen)
_ARRAY_TYPES: set = {np.ndarray}


def concrete_array_type(t) -> bool:
    """True when `t` is the type of a concrete array (numpy, or a jax array that is not a tracer)."""
    if t in _ARRAY_TYPES:
        return True
    if issubclass(t, jax.Array) and not issubclass(t, Tracer):
        _ARRAY_TYPES.add(t)
        return True
    return False


def is_concrete(x) -> bool:
    """True when `x` holds values (not a tracer inside jit/vmap/grad)."""
    leaves = jax.tree_util.tree_leaves(x)
    return not any(isinstance(leaf, Tracer) for leaf in leaves)


_collector = threading.local()


def recording() -> bool:
    """Whether a `collecting()` block is active: traced checks computed outside one are thrown away (a model built
    inside the caller's `vmap`/`grad` is checked again where jaxbelt consumes it, `jaxbelt._guard.traced_checks`)."""
    return getattr(_collector, "found", None) is not None


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


def _interval(lo, hi, lo_open, hi_open) -> str:
    lb = "-inf" if lo is None else f"{lo:g}"
    ub = "inf" if hi is None else f"{hi:g}"
    return f"{'(' if lo_open or lo is None else '['}{lb}, {ub}{')' if hi_open or hi is None else ']'}"


def _values(x):
    return np.asarray(jax.device_get(x), dtype=float)


def _message(name: str, what: str, unit: str, owner: str) -> str:
    where = f"{owner}: " if owner else ""
    shown = unit not in ("", "–", "-")  # a dimensionless quantity has no unit to print
    return f"{where}parameter `{name}` {what}{(' ' + unit) if shown else ''}"


def _check_host(name: str, v, what: str, unit: str, owner: str, ok) -> None:
    """Raise `ValueError` ("parameter `name` what unit; got ...") unless `ok(v, numpy)` for host values `v`."""
    if not bool(ok(v, np)):
        raise ValueError(f"{_message(name, what, unit, owner)}; got {v.tolist() if v.ndim else float(v)}")


class _Scalar:
    """The `xp` of a check on one Python float (a scalar parameter: no numpy call per check)."""

    all = staticmethod(bool)
    isfinite = staticmethod(math.isfinite)


def _enforce(name: str, value, what: str, unit: str, owner: str, ok) -> None:
    """The one rule of every check: concrete values raise `ValueError`; traced ones are recorded (see
    `collecting`). `ok(v, xp)` tests all elements with `xp` = numpy (host values) or jax.numpy (tracers).

    A model's construction checks a dozen scalar fields: numbers and concrete 0-d arrays are tested as
    one Python float (a jax array keeps its host copy after the first read, so a cached default costs no
    transfer)."""
    t = type(value)
    if t is not float and t is not int:
        check_real(name, value, unit, owner)
    known = _HOST.get(id(value))
    if known is not None and known[0] is value:
        v = known[1]
    elif t is float or t is int or (concrete_array_type(t) and value.ndim == 0):
        v = float(value)
    else:
        v = None
    if v is not None:
        if type(v) is not float:  # the host copy of a cached tuple (`as_float_array`)
            _check_host(name, v, what, unit, owner, ok)
        elif not ok(v, _Scalar):
            raise ValueError(f"{_message(name, what, unit, owner)}; got {v}")
        return
    if not is_concrete(value):
        if recording():  # else nobody keeps it: under an eager `vmap` each operation would compile a program
            record(ok(jnp.asarray(value), jnp), _message(name, what, unit, owner))
        return
    _check_host(name, _values(value), what, unit, owner, ok)


def _describe(value) -> str:
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    dtype = getattr(value, "dtype", None)
    return f"{text} ({type(value).__name__}{'' if dtype is None else f' of dtype {dtype}'})"


def check_real(name: str, value, unit: str = "", owner: str = "") -> None:
    """Raise `TypeError` naming `name` unless `value` is a real number or an array (or sequence) of them: a
    string, bytes, a complex number, a bool, None or a mapping would otherwise fail inside NumPy or JAX with a
    message that names nothing, or pass silently (True as 1, a complex value without its imaginary part)."""
    bad = value is None or isinstance(value, bool | np.bool_ | str | bytes | complex | dict | set)
    if not bad:
        kind = getattr(getattr(value, "dtype", None), "kind", None)
        if kind is not None:
            bad = kind not in "fiu"
        elif isinstance(value, list | tuple):
            bad = not all(
                isinstance(v, numbers.Real) and not isinstance(v, bool)
                for v in np.ravel(np.asarray(value, dtype=object))
            )
        else:
            bad = not isinstance(value, numbers.Real)
    if bad:
        where = f"{owner}: " if owner else ""
        raise TypeError(
            f"{where}parameter `{name}` must be a real number or an array of real numbers"
            f"{(' [' + unit + ']') if unit else ''}; got {_describe(value)}"
        )


def check_scalar(name: str, value, unit: str = "", owner: str = "") -> None:
    """`check_real`, and `ValueError` naming `name` unless `value` is a single number (a 0-d array or tracer)."""
    check_real(name, value, unit, owner)
    if np.ndim(value) != 0:
        where = f"{owner}: " if owner else ""
        raise ValueError(
            f"{where}parameter `{name}` must be a scalar{(' [' + unit + ']') if unit else ''}; got an array of shape "
            f"{np.shape(value)}"
        )


def _positive(v, xp):
    return xp.all(xp.isfinite(v) & (v > 0))


def _nonnegative(v, xp):
    return xp.all(xp.isfinite(v) & (v >= 0))


def _finite(v, xp):
    return xp.all(xp.isfinite(v))


#: kind -> (what the message says, test) for `check_fields`
_RULES = {
    "positive": ("must be finite and > 0", _positive),
    "nonnegative": ("must be finite and >= 0", _nonnegative),
    "finite": ("must be finite", _finite),
}


def check_positive(name: str, value, unit: str = "", owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite and > 0 (recorded when traced)."""
    _enforce(name, value, _RULES["positive"][0], unit, owner, _positive)


def check_nonnegative(name: str, value, unit: str = "", owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite and >= 0 (recorded when traced)."""
    _enforce(name, value, _RULES["nonnegative"][0], unit, owner, _nonnegative)


def check_finite(name: str, value, owner: str = "") -> None:
    """Raise `ValueError` unless every element of `value` is finite (recorded when traced)."""
    _enforce(name, value, _RULES["finite"][0], "", owner, _finite)


def check_range(name: str, value, lo=None, hi=None, *, lo_open=False, hi_open=False, unit="", owner="") -> None:
    """Raise `ValueError` unless lo (<|<=) value (<|<=) hi elementwise (recorded when traced)."""

    def ok(v, xp):
        good = xp.all(xp.isfinite(v))
        if lo is not None:
            good = good & (xp.all(v > lo) if lo_open else xp.all(v >= lo))
        if hi is not None:
            good = good & (xp.all(v < hi) if hi_open else xp.all(v <= hi))
        return good

    _enforce(name, value, f"must lie in {_interval(lo, hi, lo_open, hi_open)}", unit, owner, ok)


def available_bytes() -> int:
    """The memory available to this process now [bytes] (Linux `sysconf`; 8 GiB where it cannot be read)."""
    import os

    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Linux
        return 8 << 30


def check_fits(owner: str, name: str, nbytes: float, what: str) -> None:
    """A `ValueError` naming parameter `name` where `what` would need `nbytes` [bytes], more than half the memory
    available now: said at the call, before anything is allocated (not XLA's or numpy's out-of-memory error after
    seconds of work)."""
    avail = available_bytes()
    if nbytes > avail / 2:
        raise ValueError(
            f"{owner}: parameter `{name}` makes {what} of about {nbytes / 1e9:.3g} GB, more than half the memory "
            f"available ({avail / 1e9:.3g} GB): give a smaller `{name}`"
        )


def check_int(owner: str, name: str, value, lo: int = 1) -> int:
    """Refuse anything but an integer >= lo (a float or a bool is refused, not truncated); return it."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)) or int(value) < lo:
        raise ValueError(f"{owner}: parameter `{name}` must be an integer >= {lo}; got {value!r}")
    return int(value)


def check_penalised_limits(owner: str, penalty, limits) -> None:
    """An optimiser's bounds and the weight of their quadratic penalty: each given `(name, value, unit)`
    of `limits` finite and > 0 (a bound <= 0 would switch its penalty off, max(0, peak/bound - 1) = 0;
    None: no bound), `penalty` finite and >= 0 (a negative weight would reward breaking the bounds)."""
    for name, value, unit in limits:
        if value is not None:
            check_positive(name, value, unit, owner=owner)
    check_nonnegative("penalty", penalty, owner=owner)


def positive_checks(owner: str, **values) -> list:
    """`check_positive` on each named value: raises when concrete; returns the checks recorded for
    the traced ones (to attach with `jaxbelt._guard.guard`)."""
    with collecting() as found:
        for name, v in values.items():
            check_positive(name, v, owner=owner)
    return found


def host_values(values):
    """Host copies (float numpy arrays) of a list of concrete values, in one transfer; None under a trace."""
    if not is_concrete(values):
        return None
    return [None if v is None else np.asarray(v, dtype=float) for v in jax.device_get(list(values))]


def check_fields(owner: str, checks) -> list | None:
    """Check many fields at once: `checks` is a sequence of `(name, value, kind, unit)` with kind
    `"positive"`, `"nonnegative"` or `"finite"`. One transfer for all the values (a construction costs
    one device round trip, not one per field); the first failure raises the `ValueError` of the
    corresponding `check_*`. Returns the host values (None under a trace, where the checks are recorded).
    """
    checks = list(checks)
    vals = host_values([c[1] for c in checks])
    for k, (name, value, kind, unit) in enumerate(checks):
        what, ok = _RULES[kind]
        if vals is None:
            _enforce(name, value, what, unit, owner, ok)  # traced: recorded
        else:
            _check_host(name, vals[k], what, unit, owner, ok)  # the host copy: no transfer per field
    return vals
