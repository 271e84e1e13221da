"""The one place where jaxbelt reads the private internals of JAX, jaxlib, equinox and scipy.

Everything here saves time (tracing, compiling, a later process's start), never correctness: each function
returns what a private module holds *only* on the versions it was written and tested for (`WRITTEN_FOR`), and
its fallback (`None`, `False`, an empty list) on any other version, on any failure, or when the environment
variable `JAXBELT_PRIVATE_APIS=0` is set (`0`, `false`, `no`, `off`: off; unset, `1`, `true`, `yes`, `on`: on;
any other value: off, with a warning naming these). Every caller has a public path for the fallback that computes the same
results, only slower:

| function | what it saves | fallback in the caller |
|---|---|---|
| `equinox_missing` | stored programs whose arguments hold equinox modules with unset fields | such programs are traced |
| `trace_context` | the store's key covers all of JAX's trace settings | the key holds the settings jaxbelt knows of |
| `traceback_type` | stored programs whose outputs carry a checkify error | such programs are kept in-process only |
| `checkify_counter` | a later process's programs hit JAX's persistent cache | one more compilation, once |
| `checkify_rules` | checkify's pass steps over loops without checks (a third of a checked solve's tracing) | checkify's own pass |
| `equinox_internal` | diffrax's own checks become values, so programs stay cacheable | those programs are not stored |
| `peek` | a batch's or a derivative's invalid input refused on the host (ms), before a program is compiled (seconds) | the compiled check |
| `private_apis("scipy")` | scipy's LAPACK tables load without `scipy.linalg` (`jaxbelt._lapack`) | the usual import |

`tests/test_compat.py` runs jaxbelt's entry points both ways and compares the results. When a new release of
JAX or equinox comes out, the fast paths switch themselves off until `WRITTEN_FOR` is widened after the suite
passed on it.
"""

from __future__ import annotations

import importlib
import importlib.metadata as _md
import os
import re

#: distribution -> (oldest, newest) (major, minor) the private uses below were written and tested for
WRITTEN_FOR = {
    "jax": ((0, 10), (0, 10)),
    "jaxlib": ((0, 10), (0, 10)),
    "equinox": ((0, 13), (0, 13)),
    "scipy": ((1, 17), (1, 17)),  # its LAPACK tables' extension modules, loaded by file (`jaxbelt._lapack`)
}

_state: dict = {}


def _version(dist: str) -> tuple[int, int] | None:
    try:
        found = re.match(r"(\d+)\.(\d+)", _md.version(dist))
    except _md.PackageNotFoundError:
        return None
    return (int(found.group(1)), int(found.group(2))) if found else None


#: the values of `JAXBELT_PRIVATE_APIS` (case-insensitive, blanks around ignored); unset or empty is on
_ON = ("1", "true", "yes", "on")
_OFF = ("0", "false", "no", "off")


def _switch() -> bool:
    """`JAXBELT_PRIVATE_APIS` read: True for unset, empty or one of `_ON`, False for one of `_OFF`. Any other value
    is read as off (the public paths: the same results, only slower) with a `UserWarning` naming the accepted
    values, once per value."""
    raw = os.environ.get("JAXBELT_PRIVATE_APIS", "")
    value = raw.strip().lower()
    if value in ("", *_ON):
        return True
    if value in _OFF:
        return False
    if _state.get("warned") != raw:
        _state["warned"] = raw
        import warnings

        warnings.warn(
            f"jaxbelt: environment variable JAXBELT_PRIVATE_APIS={raw!r} is not one of {', '.join(_ON)} (on) or "
            f"{', '.join(_OFF)} (off); read as off (public APIs only: the same results, slower)",
            UserWarning,
            stacklevel=3,
        )
    return False


def private_apis(*dists: str) -> bool:
    """Whether the private layouts of `dists` (default: all of `WRITTEN_FOR`) may be used: each installed version
    within its `WRITTEN_FOR` range, and `JAXBELT_PRIVATE_APIS` not set to 0."""
    if not _switch():
        return False
    for dist in dists or tuple(WRITTEN_FOR):
        key = f"ok:{dist}"
        if key not in _state:
            v = _version(dist)
            low, high = WRITTEN_FOR[dist]
            _state[key] = v is not None and low <= v <= high
        if not _state[key]:
            return False
    return True


def _guarded(dists, load):
    """`load()` where `dists`' private layouts may be used and it succeeds, else None (memoised per name)."""
    if not private_apis(*dists):
        return None
    name = getattr(load, "__name__", repr(load))
    if name not in _state:
        try:
            _state[name] = load()
        except Exception:  # noqa: BLE001 - another layout: the public fallback
            _state[name] = None
    return _state[name]


def _missing():
    from equinox._module._flatten import MISSING

    return MISSING


def equinox_missing():
    """equinox's marker of an absent field in a module's flattened form, or None."""
    return _guarded(("equinox",), _missing)


def _trace_context_fn():
    return importlib.import_module("jax._src.config").trace_context


def trace_context() -> tuple | None:
    """JAX's trace-context tuple (every setting that changes a traced program), or None."""
    fn = _guarded(("jax",), _trace_context_fn)
    if fn is None:
        return None
    try:
        return tuple(fn())
    except Exception:  # noqa: BLE001
        return None


def _traceback():
    return importlib.import_module("jax._src.lib")._jax.Traceback


def traceback_type():
    """jaxlib's Traceback type (held by a checkify error), or None."""
    return _guarded(("jax", "jaxlib"), _traceback)


def _checkify_module():
    module = importlib.import_module("jax._src.checkify")
    module.next_code  # noqa: B018 - the counter this layout has
    return module


def checkify_counter():
    """checkify's process-wide counter of check codes (`next_code()` returns the next one), or None."""
    module = _guarded(("jax",), _checkify_module)
    return None if module is None else module.next_code


def _rules():
    checkify_private = importlib.import_module("jax._src.checkify")
    pjit = importlib.import_module("jax._src.pjit")
    ad_checkpoint = importlib.import_module("jax._src.ad_checkpoint")
    custom = importlib.import_module("jax._src.custom_derivatives")
    control_flow = importlib.import_module("jax._src.lax.control_flow")
    prims = [control_flow.while_p, control_flow.cond_p, control_flow.scan_p, pjit.jit_p, ad_checkpoint.remat_p]
    prims += [custom.custom_jvp_call_p, custom.custom_vjp_call_p]
    return checkify_private.error_checks, checkify_private.check_p, prims


def checkify_rules():
    """`(rules, check_p, primitives)`: checkify's table of rules by primitive (each called as `rule(error,
    enabled_errors, *invals, **params)`), its check primitive, and the primitives that hold sub-programs (loops,
    branches, calls, custom derivatives); or None."""
    return _guarded(("jax",), _rules)


def _eqxi():
    module = importlib.import_module("equinox.internal")
    module.error_if  # noqa: B018
    return module


def equinox_internal():
    """`equinox.internal` (diffrax calls its `error_if`), or None."""
    return _guarded(("equinox",), _eqxi)


def _tracer_types():
    batching = importlib.import_module("jax._src.interpreters.batching")
    ad = importlib.import_module("jax._src.interpreters.ad")
    return batching.BatchTracer, (ad.JVPTracer, ad.LinearizeTracer)


def peek(x):
    """The values behind `x` when it is traced only by an eager `jax.vmap` (one level) and/or `jax.grad`/`jax.jvp`
    (no `jit` above): `(values, batched)`, `values` a numpy array with the batch axis first where `batched`; a
    concrete `x` gives `(np.asarray(x), False)`. None where the values are not known before the program runs
    (under `jit`, nested `vmap`s) or on an untested version."""
    types = _guarded(("jax",), _tracer_types)
    if types is None:
        return None
    batch_tracer, derivative_tracers = types
    import numpy as np
    from jax.core import Tracer

    batch_dim = None
    try:
        while isinstance(x, Tracer):
            if isinstance(x, batch_tracer):
                if batch_dim is not None:
                    return None  # nested vmaps
                dim = x.batch_dim
                if dim is not None:  # None: not mapped
                    if type(dim) is not int:
                        return None
                    batch_dim = dim
                x = x.val
            elif isinstance(x, derivative_tracers):
                x = x.primal  # the same shape: a batch axis found above stays where it is
            else:
                return None  # jit's tracers hold no values
        values = np.asarray(x)
    except Exception:  # noqa: BLE001 - a layout this version does not have: the compiled check
        return None
    if batch_dim is None:
        return values, False
    return np.moveaxis(values, batch_dim, 0), True
