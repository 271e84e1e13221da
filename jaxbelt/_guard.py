"""Guards that survive `jax.jit`, `jax.vmap` and `jax.grad`.

Parameter checks (`jaxbelt._checks`) raise at construction when values are concrete. When they
are traced, `traced_checks(*modules)` re-runs every `__check_init__` of the modules (and of the
modules inside them) and collects each check as `(ok, message)`, `ok` a boolean array.
`guard(value, checks, throw)` then attaches them to the values a caller consumes:

- `throw=True`: `eqx.error_if(value, ~ok, message)` — the program raises at run time, naming the
  parameter and its range, whatever part of the result the caller keeps (under `vmap`, if any
  element is bad, naming the first bad element's index);
- `throw=False`: the bad elements are set to NaN and reported through the returned flag.

`eqx.error_if` raises through a host callback, and JAX's persistent compilation cache never stores
a program that holds one: every new process (a CLI run, a notebook kernel) would compile it again.
The programs jaxbelt runs eagerly on the caller's behalf are therefore `host_checked`: called
outside any trace they run a version whose guards are `checkify` checks (values, no callback) and
raise the failed check's message on the host; inside a caller's jit/vmap/grad they are the plain
program with `eqx.error_if` guards.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import re
import threading
from collections.abc import Callable
from typing import Any, Literal, TypeVar, overload

import equinox as eqx
import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np
from jax.experimental import checkify

from . import _compat, _lapack, _store, _xla
from ._checks import collecting, is_concrete

# jaxbelt's first use: scipy's LAPACK tables for jaxlib's kernels, without the scipy.linalg package (`jaxbelt._lapack`)
_lapack.bind_tables()


def _modules(tree):
    out = []

    def visit(x):
        if isinstance(x, eqx.Module):
            out.append(x)
            for f in dataclasses.fields(x):
                visit(getattr(x, f.name, None))
        elif isinstance(x, (list, tuple)):
            for y in x:
                visit(y)
        elif isinstance(x, dict):
            for y in x.values():
                visit(y)

    visit(tree)
    return out


def traced_checks(*trees) -> list:
    """`[(ok, message)]` of the parameter checks of every module in `trees` whose values are traced.

    Concrete modules were checked when they were built and add nothing here.
    """
    if is_concrete(trees):
        return []
    with collecting() as found:
        for m in _modules(trees):
            if is_concrete(m):
                continue
            for klass in type(m).__mro__:
                check = klass.__dict__.get("__check_init__")
                if check is not None:
                    check(m)
    return found


#: the batch elements an error under `vmap` names one by one (one message each in the program); beyond, the error
#: says "element >= BATCH_INDEX_CAP"
BATCH_INDEX_CAP = 1024


@functools.lru_cache(maxsize=4096)
def _element_messages(message: str) -> tuple[str, ...]:
    """`message` as `_error_naming_element` raises it: unbatched (index 0), naming element i of a batch (i + 1), and
    beyond `BATCH_INDEX_CAP`."""
    named = tuple(f"{message} (element {i} of the batch)" for i in range(BATCH_INDEX_CAP))
    return (message, *named, f"{message} (element >= {BATCH_INDEX_CAP} of the batch)")


@jax.custom_batching.custom_vmap
def _first_bad(pred):
    """0 outside `vmap`; under `vmap`, 1 + the index of the first element whose `pred` holds anywhere (capped at
    `BATCH_INDEX_CAP`), 0 when none: a `custom_vmap` rule sees the batch axis the function inside cannot. Its
    output is never batched, and it takes only the predicate (no value that derivatives flow through)."""
    return jnp.zeros((), jnp.int32)


@_first_bad.def_vmap
def _first_bad_rule(axis_size, in_batched, pred):
    (batched,) = in_batched
    if not batched:
        return _first_bad(pred), False
    bad = jnp.reshape(pred, (axis_size, -1)).any(axis=1)
    first = jnp.minimum(jnp.argmax(bad), BATCH_INDEX_CAP) + 1
    return jnp.where(bad.any(), first, 0).astype(jnp.int32), False


def _error_naming_element(x, pred, message: str):
    """`eqx.error_if(x, pred, message)`, and under `jax.vmap` the message names the first invalid element of the
    batch: "... (element 3 of the batch)" (nested vmaps: the index along the innermost axis)."""
    return eqx.branched_error_if(x, pred, _first_bad(pred), _element_messages(message))


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _checked(x, pred, message):
    return _error_naming_element(x, pred, message)


@_checked.defjvp
def _checked_jvp(message, primals, tangents):
    x, pred = primals
    tx, _ = tangents
    # The tangent is scaled by a guarded 1: the backward pass of `grad` needs that factor, so the
    # check runs even when the caller keeps only the gradient (a check on the primal output alone
    # would be removed as dead code in `jit(grad(f))`).
    one = _error_naming_element(jnp.ones((), dtype=x.dtype), pred, message)
    return _error_naming_element(x, pred, message), tx * one


class _Off:
    """Stand-in for `_host_checks` where JAX has no user contexts (jax < 0.6): host checks are off."""

    value = False

    def __call__(self, value):  # not entered: the callers leave host checks out when they find `_Off`
        return contextlib.nullcontext()


#: True while jaxbelt traces or runs a `host_checked` program (part of JAX's jit cache keys, so that a
#: program traced with checkify checks is never reused where the caller expects `eqx.error_if`).
_host_checks = jax.make_user_context(default_value=False) if hasattr(jax, "make_user_context") else _Off()
#: True while jaxbelt traces a diffrax solve whose inputs it has checked itself (see `validated_inputs`).
_validated = jax.make_user_context(default_value=False) if hasattr(jax, "make_user_context") else _Off()
_store.CONTEXTS.append(lambda: (bool(_host_checks.value), bool(_validated.value)))

#: diffrax's own checks of `SaveAt(ts=...)`, which `Scene` and `simulate` make too (strictly increasing
#: finite output times, start time <= the first of them; traced values: recorded checks on the results)
_VALIDATED_BY_JAXBELT = frozenset(
    {
        "saveat.ts must be increasing or decreasing.",
        "saveat.ts must lie between t0 and t1.",
    }
)
#: and the start of diffrax's check of the sign of `dt0` (its message goes on with the values), which
#: `simulate` makes too (`dt`, `dt0` finite and > 0, t0 < t1) and jaxbelt's own fixed-step solves satisfy
_VALIDATED_PREFIX = "Must have (t1 - t0) * dt0 >= 0"


def validated_inputs():
    """Context of a diffrax solve whose output times jaxbelt has checked: diffrax's repeat of those
    checks (`_VALIDATED_BY_JAXBELT`, matched by message) is left out of the program.

    Each would be an `eqx.error_if`, i.e. a host callback, and a program holding one is never stored by
    the persistent compilation cache. Any other check stays; an unknown message (another diffrax
    version) keeps its check, so the only cost of a mismatch is a program that is not cached.
    """
    if isinstance(_validated, _Off):
        return contextlib.nullcontext()
    _equinox_errors_as_checks()
    return _validated(True)


def has_host_callbacks(jaxpr) -> bool:
    """Whether a (closed) jaxpr holds a host callback anywhere, sub-programs included."""
    todo = [getattr(jaxpr, "jaxpr", jaxpr)]
    while todo:
        j = todo.pop()
        for eqn in j.eqns:
            if "callback" in eqn.primitive.name:
                return True
            for param in eqn.params.values():
                for sub in param if isinstance(param, (list, tuple)) else (param,):
                    if hasattr(sub, "eqns"):
                        todo.append(sub)
                    elif hasattr(getattr(sub, "jaxpr", None), "eqns"):
                        todo.append(sub.jaxpr)
    return False


def _eager_trace_type():
    # JAX's trace context is per thread: a new thread sees the trace outside every transformation, even
    # when this module is imported inside a caller's jit (`jaxbelt` imports its modules on first use)
    found = []
    reader = threading.Thread(target=lambda: found.append(type(jax.extend.core.find_top_trace(()))))
    reader.start()
    reader.join()
    return found[0]


_EAGER_TRACE = _eager_trace_type()


def eager() -> bool:
    """True outside every jit/vmap/grad trace."""
    return type(jax.extend.core.find_top_trace(())) is _EAGER_TRACE


def host_checked(
    fun=None,
    *,
    jit=eqx.filter_jit,
    store: bool = False,
    compiler_options: dict | None = None,
    checks: bool = True,
    **jit_kwargs,
) -> Callable[..., Any]:
    """`jit(fun, **jit_kwargs)` for a program jaxbelt runs eagerly: its guards come back as values.

    Called outside any trace, the program that runs is `checkify`-transformed: `error_if` (and so
    `guard`) record checkify checks instead of host callbacks, so the compiled program is stored by
    the persistent compilation cache, and the first failed check raises here with its message
    (checkify's `JaxRuntimeError`, a `ValueError`). Inside a caller's jit/vmap/grad, or inside
    another `host_checked` program, it is the plain program.

    `store=True` (with the default `eqx.filter_jit`): the checked program is also kept in the
    program store (`jaxbelt._store`) while the compilation cache is on. Left off where a program's
    callers trace other checked programs that share its inner functions: checkify numbers its
    checks from one process-wide counter, so skipping this program's trace would renumber theirs
    and make them miss the persistent cache once.

    `compiler_options`: XLA's options for the checked (top-level) program and its stored form only; the plain
    program, inlined into a caller's trace, compiles with the caller's.

    `checks=False`: for a program that records no check (its solves and checks made with `throw=False`): the
    same, without checkify's pass over the traced program (a third of a diffrax solve's tracing time); a check
    it did record would fail its tracing (`checkify.check` outside `checkify`), never pass unseen.
    """
    if fun is None:
        return functools.partial(
            host_checked, jit=jit, store=store, compiler_options=compiler_options, checks=checks, **jit_kwargs
        )
    plain = jit(fun, **jit_kwargs)
    if isinstance(_host_checks, _Off):
        return plain
    checkified = _lean(checkify.checkify(fun, errors=checkify.user_checks)) if checks else fun
    # XLA's options as far as the running backend knows them, found at the first call (`jaxbelt._xla`)
    checked = _xla.LazyJit(jit, checkified, compiler_options, **jit_kwargs)
    name = f"{getattr(fun, '__module__', '?')}.{getattr(fun, '__qualname__', '?')}"
    # the store's static/dynamic split is filter_jit's; only jaxbelt's own module-level functions are stored
    storable = store and jit is eqx.filter_jit and _store.storable_function(fun)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        if _host_checks.value or not eager():
            return plain(*args, **kwargs)
        _equinox_errors_as_checks()
        with _host_checks(True):
            if storable and not kwargs and _store.folder() is not None:
                result = _store.call(name, checkified, args, checked, checked.options())
            else:
                result = checked(*args, **kwargs)
        if not checks:
            return result
        err, out = result
        # read on the host first: checkify's `throw` indexes and compares the (per-device) error arrays with JAX
        # operations, a small compiled program each (a dozen for a sharded sweep); it runs only when a check failed
        err = jax.device_get(err)
        if err.get() is not None:
            err.throw()
        return out

    def prepare(*args):
        """Start compiling the program `call(*args)` will run, in the background, and return its output's types
        (outside any trace; else None): through the program store while it is on (`jaxbelt._store.prepare`),
        else in memory (`_compile_ahead`)."""
        if _host_checks.value or not eager():
            return None
        _equinox_errors_as_checks()
        with _host_checks(True):
            if storable and _store.folder() is not None:
                types = _store.prepare(name, checkified, args, checked.options())
            else:
                types = _compile_ahead(checked, args)
        return types[1] if checks and types is not None else types  # without checkify's error

    call.prepare = prepare  # pyright: ignore[reportAttributeAccessIssue]
    return call


def _compile_ahead(jitted, args):
    """Trace `jitted(*args)` here (a `LazyJit` of an `eqx.filter_jit` function; an array argument may be given by
    its type, `jax.ShapeDtypeStruct`: zeros stand in) and compile it in the store's compile threads
    (`jaxbelt._store.compile_in_background`; XLA releases the GIL): JAX keeps one compilation per jitted function
    and input types, so the later call with inputs of these types finds it compiled, or waits for it
    (`LazyJit.compiling`: a call made meanwhile would compile it a second time). Returns the output's types, or
    None (and nothing started) where it cannot be traced here: the call then compiles it as before."""
    args = jax.tree_util.tree_map(
        lambda x: jax.device_put(np.zeros(x.shape, x.dtype)) if isinstance(x, jax.ShapeDtypeStruct) else x, args
    )
    try:
        lowered = jitted.lower(*args)  # equinox's `Lowered`: JAX's, and the output's static parts
        types = lowered.postprocess(lowered.lowered.out_info)
    except Exception:  # noqa: BLE001 - compiling ahead only saves time
        return None
    jitted.compiling(_store.compile_in_background(lowered.lowered))
    return types


def prepare(fn, *args):
    """Start compiling the program `fn(*args)` will run, in the background, and return its output's types
    (`jax.ShapeDtypeStruct`s) where `fn` is a `host_checked` or `stored_jit` function called outside any trace
    (through the program store while it is on, else in memory: `_compile_ahead`); else do nothing and return
    None. An array argument may be given by its type."""
    start = getattr(fn, "prepare", None)
    return None if start is None else start(*args)


_F = TypeVar("_F", bound=Callable[..., Any])


@overload
def stored_jit(fun: _F, *, compiler_options: dict | None = None) -> _F: ...
@overload
def stored_jit(fun: None = None, *, compiler_options: dict | None = None) -> Callable[[_F], _F]: ...
def stored_jit(fun: Any = None, *, compiler_options: dict | None = None) -> Any:  # noqa: E302
    """`eqx.filter_jit(fun)` whose calls outside any trace go through the program store
    (`jaxbelt._store`) while the compilation cache is on: a later process runs it untraced.

    `compiler_options`: XLA's options of the program called at top level (and of its stored form); inside a
    caller's trace it is inlined and compiles with the caller's."""
    if fun is None:
        return functools.partial(stored_jit, compiler_options=compiler_options)
    plain = eqx.filter_jit(fun)
    top = _xla.LazyJit(eqx.filter_jit, fun, compiler_options)  # the options the running backend knows
    name = f"{fun.__module__}.{fun.__qualname__}"
    storable = _store.storable_function(fun)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        if not eager():
            return plain(*args, **kwargs)
        if kwargs or not storable or _store.folder() is None:
            return top(*args, **kwargs)
        return _store.call(name, fun, args, top, top.options())

    def prepare(*args):
        """Start compiling the program `wrapper(*args)` will run, in the background, and return its output's types
        (outside any trace; else None): through the program store while it is on (`jaxbelt._store.prepare`), else
        in memory (`_compile_ahead`)."""
        if not eager():
            return None
        if storable and _store.folder() is not None:
            return _store.prepare(name, fun, args, top.options())
        return _compile_ahead(top, args)

    wrapper.prepare = prepare  # pyright: ignore[reportAttributeAccessIssue]
    return wrapper


def _as_check(pred, message: str) -> None:
    """A checkify check that fails where any element of `pred` is True (inside a `host_checked` program)."""
    checkify.check(~jnp.any(jnp.asarray(pred)), message.replace("{", "{{").replace("}", "}}"))


#: per checkify pass: whether a (sub-)jaxpr holds a check anywhere, by the jaxpr's id (the jaxpr is kept beside
#: its answer, so an id is never reused while its entry lives; cleared after each pass)
_HOLDS_CHECK: dict = {}
_state: dict = {"lean": None}


def _sub_jaxprs(params):
    for param in params.values():
        for sub in param if isinstance(param, (list, tuple)) else (param,):
            if isinstance(sub, jax.extend.core.ClosedJaxpr):
                yield sub.jaxpr
            elif isinstance(sub, jax.extend.core.Jaxpr):
                yield sub


def _holds_check(jaxpr, check_p) -> bool:
    hit = _HOLDS_CHECK.get(id(jaxpr))
    if hit is not None and hit[0] is jaxpr:
        return hit[1]
    found = any(
        eqn.primitive is check_p or any(_holds_check(sub, check_p) for sub in _sub_jaxprs(eqn.params))
        for eqn in jaxpr.eqns
    )
    if len(_HOLDS_CHECK) >= 100_000:  # a caller's own checkify passes (the rules serve them too) are not cleared
        _HOLDS_CHECK.clear()
    _HOLDS_CHECK[id(jaxpr)] = (jaxpr, found)
    return found


def _lean(checkified):
    """`checkified` (a `checkify.checkify` function) traced with `_lean_checkify`'s rules."""

    @functools.wraps(checkified)
    def traced(*args, **kwargs):
        _lean_checkify()
        try:
            return checkified(*args, **kwargs)
        finally:
            _HOLDS_CHECK.clear()

    return traced


def _lean_checkify() -> bool:
    """Make checkify's pass for user checks (`checkify.user_checks`, the only errors `host_checked` asks for)
    step over every loop, branch, call and custom derivative whose body holds no check: it binds that equation
    as it is instead of rebuilding its body (twice, for a while loop). A diffrax solve's loop holds none of
    jaxbelt's checks (they are made on the parameters, outside it), and its rebuild was a third of the tracing
    of a checked simulation. The result is the same program; other error sets (NaN, index checks), which any
    equation may raise, take checkify's own rules. Installed once; False where `jaxbelt._compat` withholds
    checkify's private table (another JAX release: the pass is then checkify's own, the same program traced
    more slowly)."""
    if _state.get("lean") is not None:
        return _state["lean"]
    found = _compat.checkify_rules()  # a private table: None on a JAX layout it was not written for
    if found is None:
        _state["lean"] = False
        return False
    rules, check_p, prims = found
    user = checkify.user_checks

    def lean(prim, rule):
        def rule_or_bind(error, enabled_errors, *invals, **params):
            if enabled_errors <= user and not any(_holds_check(sub, check_p) for sub in _sub_jaxprs(params)):
                return error, prim.bind(*invals, **prim.get_bind_params(params))  # as `jax.core.eval_jaxpr` does
            return rule(error, enabled_errors, *invals, **params)

        rule_or_bind._jaxbelt_lean = True  # pyright: ignore[reportFunctionMemberAccess]
        return rule_or_bind

    for prim in prims:
        rule = rules.get(prim)
        if rule is not None and not getattr(rule, "_jaxbelt_lean", False):
            rules[prim] = lean(prim, rule)
    _state["lean"] = True
    return True


def _equinox_errors_as_checks() -> None:
    """Inside a `host_checked` program, `eqx.error_if` records a checkify check as well; inside
    `validated_inputs`, diffrax's repeat of jaxbelt's own checks is left out.

    diffrax, optimistix and the models call `eqx.error_if` (diffrax through equinox's internal namespace) for
    their checks: traced, each is a host callback, and a program holding one is never stored by the
    persistent compilation cache. Installed once, the wrapper leaves every call outside those two
    contexts (another thread, the caller's own jit) to equinox unchanged: the contexts are
    thread-local and part of JAX's jit cache keys. A check whose condition is a concrete value (not part
    of the program: e.g. optimistix checking a solver's options at its import, which a first call may
    trigger while tracing) is decided at once: nothing where it is False, the `ValueError` of a failed check
    where it is True.
    """
    if getattr(eqx.error_if, "_jaxbelt_checks", False):
        return
    eqxi = _compat.equinox_internal()  # None on an equinox it was not written for: diffrax's checks stay callbacks
    original = eqx.error_if

    @functools.wraps(original)
    def error_if(x, pred, msg, *, on_error: Literal["default", "raise", "breakpoint", "nan", "off"] = "default"):
        if on_error in ("default", "raise"):
            if _validated.value and (msg in _VALIDATED_BY_JAXBELT or str(msg).startswith(_VALIDATED_PREFIX)):
                return x
            if _host_checks.value:
                if is_concrete(pred):
                    # a value known now, not a check of the program (another library's eager check: optimistix
                    # checks its solvers' options as its modules are imported, which a first call may do while
                    # tracing): decided now, with the error a failed check of the program raises
                    if np.any(np.asarray(pred)):
                        raise ValueError(str(msg))
                    return x
                _as_check(pred, msg)
                return x
        return original(x, pred, msg, on_error=on_error)

    setattr(error_if, "_jaxbelt_checks", True)  # noqa: B010 - a mark on a function object
    eqx.error_if = error_if
    if eqxi is not None and getattr(eqxi, "error_if", None) is original:
        eqxi.error_if = error_if


def error_if(value, pred, message: str):
    """`eqx.error_if` on every inexact leaf of `value` that also guards derivatives.

    Under `jax.grad`/`jax.jacfwd` the check runs in the derivative program too, so an invalid
    value raises whether the caller keeps the value, its gradient or both. Inside a `host_checked`
    program it is a checkify check (the whole program, derivatives included, is checked).
    """
    pred = jnp.asarray(pred)
    if _host_checks.value:
        _as_check(pred, message)
        return value

    def one(x):
        if isinstance(x, (jax.Array, np.ndarray)) and jnp.issubdtype(x.dtype, jnp.inexact) and x.size:
            return _checked(x, pred, message)
        return x

    return jax.tree_util.tree_map(one, value)


_RUNTIME_MESSAGE = re.compile(r"EquinoxRuntimeError: (.*?)\n\s*\n\s*-{5,}", re.DOTALL)


def runtime_message(error: BaseException) -> str | None:
    """The message of the check that failed inside a compiled program, from the run-time error JAX raises
    (`equinox.EquinoxRuntimeError` under `eqx.filter_jit`, `JaxRuntimeError` wrapping it under `jax.jit`,
    checkify's `JaxRuntimeError` in a `host_checked` program); None when `error` is not such an error.

    Their text starts with the stack of the program ("Above is the stack outside of JIT", a host callback's
    traceback); a caller that runs a program for the user re-raises with this message first (`reraise_checks`).
    """
    text = str(error)
    found = _RUNTIME_MESSAGE.search(text)
    if found:
        return found.group(1).strip()
    if type(error).__name__ == "JaxRuntimeError" and "Traceback" not in text and text.strip():
        return text.strip().splitlines()[0].split(" (`check` failed")[0]  # a checkify check: its message first
    return None


@contextlib.contextmanager
def reraise_checks(owner: str, context: str = ""):
    """Inside the block, a check that fails at run time inside a compiled program (a parameter out of its
    range in a model the user's function builds, ...) is re-raised as `ValueError` whose message leads with
    the check's own (the parameter, its range), then `context` (what was being run), instead of JAX's
    stack. Any other error passes unchanged."""
    try:
        yield
    except (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, checkify.JaxRuntimeError) as e:
        message = runtime_message(e)
        if message is None:
            raise
        raise ValueError(f"{owner}: {message}{f' ({context})' if context else ''}") from e


def all_ok(checks):
    """Conjunction of the checks' flags (True when there are none)."""
    ok = jax.device_put(np.bool_(True))  # not `jnp.array`: that compiles a small program in a fresh process
    for c, _ in checks:
        ok = ok & c
    return ok


def guard(value, checks, throw: bool = True):
    """Attach `checks` to the pytree `value`: raise at run time (`throw`) or NaN the bad values.

    Returns `(value, ok)`.
    """
    ok = all_ok(checks)
    if not checks:
        return value, ok
    if throw:
        for c, msg in checks:
            value = error_if(value, ~c, msg)
        return value, ok
    return nan_where(value, ok), ok


def checked(value, *modules, checks=()):
    """`value` with the parameter checks of the traced `modules` and the recorded `checks` attached
    (`guard(..., throw=True)`): under jit/vmap/grad an invalid parameter raises at run time, naming it.
    With concrete modules and no checks, `value` itself. The modules' checks come first (a bad parameter
    is reported as such, not through an argument check it makes fail)."""
    found = traced_checks(*modules) + list(checks)
    return guard(value, found, throw=True)[0] if found else value


def nan_where(value, ok):
    """`value` with every inexact leaf set to NaN where `ok` is False (ok broadcasts from the left)."""

    def one(x):
        if not (isinstance(x, jax.Array) or hasattr(x, "dtype")) or not jnp.issubdtype(x.dtype, jnp.inexact):
            return x
        o = jnp.reshape(ok, jnp.shape(ok) + (1,) * (jnp.ndim(x) - jnp.ndim(ok))) if jnp.ndim(x) >= jnp.ndim(ok) else ok
        return jnp.where(o, x, jnp.nan)

    return jax.tree_util.tree_map(one, value)


def reraising(owner: str):
    """Decorator of a public entry point: a check that fails at run time inside a program it runs (under the
    caller's `vmap`/`grad` without `jit`, the program runs inside the call) is re-raised as `ValueError` whose
    first line is the check's message (the parameter and its range), prefixed with `owner` unless it already
    names it, instead of JAX's stack banner (see `reraise_checks`). Inside a caller's `jit` the program runs
    at the caller's call, not here: nothing to catch."""

    def decorate(fun):
        @functools.wraps(fun)
        def call(*args, **kwargs):
            batched = not eager()
            try:
                return fun(*args, **kwargs)
            except (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, checkify.JaxRuntimeError) as e:
                message = runtime_message(e)
                if message is None:
                    raise
                lead = message if message.startswith(f"{owner}:") else f"{owner}: {message}"
                where = (
                    " (checked at run time inside vmap/grad)"
                    if "of the batch)" in message
                    else " (checked at run time inside vmap/grad: under vmap, in at least one element of the batch)"
                )
                raise ValueError(lead + (where if batched else "")) from e

        return call

    return decorate
