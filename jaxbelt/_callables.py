"""A user's function keyed by what it computes, not by its identity: compiled programs are reused.

`jax.jit` and `eqx.filter_jit` key a program by the *function object* they are given: `jb.sweep(lambda g:
..., gains)` called twice makes two lambdas, two keys, two compilations, although both compute the same
thing. `by_value(fn)` wraps `fn` in a callable whose hash and equality are those of

- its code object (bytecode, constants, names; two lambdas written at the same place share it),
- every value it closes over, takes as a default or reads as a global of its module: numbers by type and
  value, arrays by shape, dtype and contents, pytrees (tuples, dicts, equinox modules such as a
  `jb.FourBarDrive()`) by structure and leaves, functions of the user recursively by the same rule, objects
  of the user by their attributes, anything else (modules, classes, library functions) by its own hash.

So a new lambda with the same code and equal values shares the first one's program, while any change of a
value (a new gain, another array) is a new key: no stale program. The values keep their meaning: an array
closed over is a constant of the program, as it is for `jax.jit` (nothing becomes traced that was not).
Functions of libraries (JAX, jaxbelt, optax, the standard library...) are keyed by their closures and
defaults only (so `optax.adam(0.1)` made twice is one key); their module globals are taken as fixed.
A value that cannot be keyed (a tracer of the caller's own `jit`, an unhashable object) leaves `fn` keyed
by identity, as before.

`lasting_key(fn)` is the same key in terms that mean the same in a later process (no identities; a library's
function, class or module by its name, for the libraries whose versions the program store's key holds): the
program store (`jaxbelt._store`) keeps the programs of `sweep` and `identify` under it, and a later process
runs them without tracing `fn`. Where `fn` holds the user's own object, class or module, there is none.
"""

from __future__ import annotations

import enum
import functools
import hashlib
import sys
import types
import weakref

import jax
import numpy as np
from jax.core import Tracer

from ._compat import equinox_missing  # the module, not the package's lazy attribute (that loads _guard first)

__all__ = ["by_value", "ByValue", "lasting_key"]

#: equinox's private marker of absent fields in a module's flattened form (None on another equinox layout: such
#: a field is not keyed)
_MISSING = equinox_missing()

#: top-level packages whose functions are library code: their module globals are taken as fixed
_LIBRARY_ROOTS = frozenset(
    {
        "jax",
        "jaxlib",
        "jaxbelt",
        "equinox",
        "diffrax",
        "optax",
        "optimistix",
        "lineax",
        "numpy",
        "scipy",
        "jaxtyping",
        "chex",
        "builtins",
    }
)
_MAX_DEPTH = 12
_NUMBERS = (bool, int, float, complex)


class _Unkeyable(Exception):
    """A value the key cannot be made of (a tracer): the function keeps its identity."""


def _rooted(module, roots) -> bool:
    """Whether `module` (a name) belongs to one of the packages `roots` or to the standard library."""
    if not isinstance(module, str) or not module:
        return False
    root = module.partition(".")[0]
    return root in roots or root in getattr(sys, "stdlib_module_names", ())


def _library(module) -> bool:
    return _rooted(module, _LIBRARY_ROOTS)


def _global_names(code: types.CodeType) -> set:
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _global_names(c)
    return names


# digests of immutable JAX arrays by identity (a sweep's closure hashes the same arrays at every call)
_DIGESTS: dict = {}


def _digest(x) -> bytes:
    if isinstance(x, jax.Array):
        hit = _DIGESTS.get(id(x))
        if hit is not None and hit[0]() is x:
            return hit[1]
        d = hashlib.blake2b(np.ascontiguousarray(np.asarray(x)).view(np.uint8).data, digest_size=16).digest()
        key = id(x)
        try:
            ref = weakref.ref(x, lambda _: _DIGESTS.pop(key, None))
            _DIGESTS[key] = (ref, d)
        except TypeError:  # not weakly referenceable: hashed at each call
            pass
        return d
    # numpy arrays are mutable: hashed at each call
    return hashlib.blake2b(np.ascontiguousarray(x).view(np.uint8).data, digest_size=16).digest()


class _Keyer:
    def __init__(self):
        self.active: set = set()

    def value(self, v, depth: int):
        if depth > _MAX_DEPTH:
            raise _Unkeyable
        t = type(v)
        if t in _NUMBERS or t is str or v is None or t is bytes:
            return (t, v)
        if isinstance(v, Tracer):
            raise _Unkeyable
        if isinstance(v, (jax.Array, np.ndarray)):
            return ("array", v.shape, str(v.dtype), bool(getattr(v, "weak_type", False)), _digest(v))
        if isinstance(v, np.generic):
            return ("scalar", str(v.dtype), v.tobytes())
        if isinstance(v, (types.FunctionType, functools.partial, types.MethodType)):
            return self.function(v, depth)
        if isinstance(v, (types.ModuleType, type)):
            return ("id", v)
        leaves, treedef = jax.tree_util.tree_flatten(v)
        if not (treedef.num_nodes == 1 and treedef.num_leaves == 1):  # a pytree: structure and leaves
            return ("tree", treedef, tuple(self.value(x, depth + 1) for x in leaves))
        return self.other(v, depth)

    def other(self, v, depth: int):
        t = type(v)
        user_object = not _library(getattr(t, "__module__", None)) and hasattr(v, "__dict__")
        if user_object and t.__hash__ is object.__hash__:  # keyed by identity, but its attributes may change
            if id(v) in self.active:
                return ("cycle", id(v))
            self.active.add(id(v))
            try:
                attrs = tuple(sorted((k, self.value(a, depth + 1)) for k, a in vars(v).items()))
            finally:
                self.active.discard(id(v))
            return ("object", t, id(v), attrs)
        try:
            hash(v)
        except TypeError:
            raise _Unkeyable from None
        return ("hash", t, v)

    def function(self, fn, depth: int):
        if id(fn) in self.active:  # a recursive helper: its code is in the key already
            return ("cycle", id(fn))
        self.active.add(id(fn))
        try:
            if isinstance(fn, functools.partial):
                return (
                    "partial",
                    self.value(fn.func, depth + 1),
                    tuple(self.value(a, depth + 1) for a in fn.args),
                    tuple(sorted((k, self.value(a, depth + 1)) for k, a in fn.keywords.items())),
                )
            if isinstance(fn, types.MethodType):
                return ("method", self.value(fn.__func__, depth + 1), self.value(fn.__self__, depth + 1))
            return self.plain(fn, depth)
        finally:
            self.active.discard(id(fn))

    def plain(self, fn: types.FunctionType, depth: int):
        module = getattr(fn, "__module__", None)
        library = _library(module)
        closure = fn.__closure__ or ()
        if library and not closure and not fn.__defaults__ and not fn.__kwdefaults__:
            return self.library_function(fn)  # a library's module-level function: its identity is its meaning
        cells = []
        for cell in closure:
            try:
                contents = cell.cell_contents
            except ValueError:  # an empty cell (a name bound later)
                cells.append(("empty",))
                continue
            cells.append(self.value(contents, depth + 1))
        defaults = tuple(self.value(d, depth + 1) for d in fn.__defaults__ or ())
        kwdefaults = tuple(sorted((k, self.value(d, depth + 1)) for k, d in (fn.__kwdefaults__ or {}).items()))
        glob = fn.__globals__
        if library:
            used = ()
        else:
            used = tuple((n, self.value(glob[n], depth + 1)) for n in sorted(_global_names(fn.__code__)) if n in glob)
        attrs = tuple(sorted((k, self.value(a, depth + 1)) for k, a in vars(fn).items()))
        return ("function", *self.code(fn), module, fn.__qualname__, tuple(cells), defaults, kwdefaults, used, attrs)

    def library_function(self, fn) -> tuple:
        return ("id", fn)

    def code(self, fn) -> tuple:
        """The function's code, and where its globals live."""
        return (fn.__code__, id(fn.__globals__))


#: libraries whose versions the program store's fingerprint holds (`jaxbelt._store`): their functions, classes
#: and modules are named by module and qualified name in a key that outlives the process
_VERSIONED_ROOTS = frozenset(
    {"jax", "jaxlib", "jaxbelt", "equinox", "diffrax", "optax", "optimistix", "lineax", "numpy"}
)


def _versioned(module) -> bool:
    return _rooted(module, _VERSIONED_ROOTS)


def _code(code: types.CodeType) -> tuple:
    """What a code object computes, by value (its bytecode, constants, names and exception table; not its line
    numbers or file), nested code objects (inner functions, comprehensions) included."""
    consts = []
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            consts.append(_code(c))
        else:
            consts.append(_constant(c))
    return (
        "code",
        code.co_name,
        code.co_code.hex(),
        tuple(consts),
        code.co_names,
        code.co_varnames,
        code.co_freevars,
        code.co_cellvars,
        code.co_argcount,
        code.co_posonlyargcount,
        code.co_kwonlyargcount,
        code.co_flags,
        getattr(code, "co_exceptiontable", b"").hex(),
    )


def _constant(c):
    t = type(c)
    if t in _NUMBERS or t is str or c is None or c is Ellipsis:
        return (t.__name__, repr(c))
    if t is bytes:
        return ("bytes", c.hex())
    if t is tuple:
        return ("tuple", tuple(map(_constant, c)))
    if t is frozenset:
        return ("frozenset", tuple(sorted(map(repr, map(_constant, c)))))
    raise _Unkeyable


class _Lasting(_Keyer):
    """The key of a function by value in terms that mean the same in another process (see `lasting_key`):
    no identities; a module, class or function named by module and qualified name only where it comes from a
    library whose version the store's fingerprint holds; anything else of the user's own that is not a value
    (an object, a class, a module) cannot be keyed."""

    def value(self, v, depth: int):
        if depth > _MAX_DEPTH:
            raise _Unkeyable
        t = type(v)
        if t in _NUMBERS or t is str or v is None:
            return (t.__name__, repr(v))
        if t is bytes:
            return ("bytes", v.hex())
        if isinstance(v, Tracer):
            raise _Unkeyable
        if isinstance(v, (jax.Array, np.ndarray)):
            return ("array", v.shape, str(v.dtype), bool(getattr(v, "weak_type", False)), _digest(v).hex())
        if isinstance(v, np.generic):
            return ("scalar", str(v.dtype), v.tobytes().hex())
        if isinstance(v, (types.FunctionType, functools.partial, types.MethodType)):
            return self.function(v, depth)
        if isinstance(v, types.ModuleType):
            if not _versioned(v.__name__):
                raise _Unkeyable
            return ("module", v.__name__)
        if isinstance(v, type):
            return ("class", self.named(v))
        if isinstance(v, np.dtype):
            return ("dtype", str(v))
        leaves, treedef = jax.tree_util.tree_flatten(v)
        if not (treedef.num_nodes == 1 and treedef.num_leaves == 1):
            return ("tree", self.structure(treedef, depth), tuple(self.value(x, depth + 1) for x in leaves))
        return self.other(v, depth)

    @staticmethod
    def named(v) -> tuple:
        """A library's class, function or callable object, by module and qualified name."""
        module, qualname = getattr(v, "__module__", None), getattr(v, "__qualname__", None)
        if not _versioned(module) or not isinstance(qualname, str) or "<locals>" in qualname:
            raise _Unkeyable
        return (module, qualname)

    def structure(self, treedef, depth: int) -> tuple:
        nodes, todo = [], [treedef]
        while todo:
            t = todo.pop()
            node = t.node_data()
            children = t.children()
            if node is not None:
                typ, aux = node
                nodes.append((self.named(typ), self.aux(aux, depth + 1), len(children)))
            else:
                nodes.append(("leaf" if t.num_leaves else "none",))
            todo.extend(reversed(children))
        return tuple(nodes)

    def aux(self, a, depth: int):
        """A node's static data (field names, a dict's keys, equinox's marker of absent fields...)."""
        if _MISSING is not None and a is _MISSING:
            return ("missing",)
        if type(a) in (tuple, list):
            return (type(a).__name__, tuple(self.aux(x, depth + 1) for x in a))
        return self.value(a, depth)

    def other(self, v, depth: int):
        t = type(v)
        if isinstance(v, enum.Enum):
            return ("enum", self.named(t), v.name)
        if callable(v) and not hasattr(v, "__dict__") or type(v).__name__ == "PjitFunction":
            return ("callable", self.named(v))  # a builtin, a ufunc, a library's jitted function
        if _MISSING is not None and v is _MISSING:
            return ("missing",)
        raise _Unkeyable

    def function(self, fn, depth: int):
        if id(fn) in self.active:
            return ("cycle", getattr(fn, "__qualname__", "?"))
        return super().function(fn, depth)

    def plain(self, fn: types.FunctionType, depth: int):
        module = getattr(fn, "__module__", None)
        if _library(module) and not _versioned(module):  # another library's function: its code could change
            raise _Unkeyable
        return super().plain(fn, depth)

    def library_function(self, fn) -> tuple:
        return ("libfn", self.named(fn))

    def code(self, fn) -> tuple:
        return (_code(fn.__code__),)  # by value; its module's globals are keyed where it reads them


class ByValue:
    """`fn`, hashed and compared by its code and values (see the module docstring); calling it calls `fn`."""

    __slots__ = ("fn", "key", "_hash", "_lasting", "__weakref__")

    def __init__(self, fn, key):
        self.fn, self.key = fn, key
        self._hash = hash(key)
        self._lasting = ""  # not computed yet

    def lasting_key(self) -> str | None:
        """A digest of `fn`'s code and values that means the same in another process, or None (see
        `lasting_key`)."""
        if self._lasting == "":
            self._lasting = lasting_key(self.fn)
        return self._lasting

    def __call__(self, *args, **kwargs):
        return self.fn(*args, **kwargs)

    def __hash__(self):
        return self._hash

    def __eq__(self, other):
        return type(other) is ByValue and self._hash == other._hash and self.key == other.key

    @property
    def __name__(self):  # jax.jit names its program after it
        return getattr(self.fn, "__name__", "fn")

    def __repr__(self):
        return f"by_value({self.fn!r})"


def lasting_key(fn) -> str | None:
    """A digest (hex) of what `fn` computes that a later process computes alike for the same code and values, or
    None: the key by which the program store (`jaxbelt._store`) keeps a program that calls a user's function.

    It is `by_value`'s key in lasting terms: the function's code by value (bytecode, constants, names; not its
    line numbers), and every value it closes over, takes as a default or reads as a global (numbers, strings,
    arrays by contents, pytrees of library types, the user's functions recursively); a function, class or module
    of a library whose version the store's fingerprint holds (JAX, NumPy, equinox, diffrax, optax, optimistix,
    lineax, jaxbelt, the standard library) by its name. None where any of it is the user's own object, class or
    module (their code could change without changing the key), another library's function, or a tracer."""
    if not isinstance(fn, (types.FunctionType, functools.partial, types.MethodType)):
        return None
    try:
        key = _Lasting().function(fn, 0)
    except (_Unkeyable, RecursionError):
        return None
    except Exception:  # noqa: BLE001 - a value whose flattening fails: not stored
        return None
    return hashlib.sha256(repr(key).encode()).hexdigest()


def by_value(fn):
    """`fn` keyed by its code and values (a `ByValue`), or `fn` itself where that key cannot be made (a closed
    over tracer, an unhashable value) or `fn` is not a Python function, `functools.partial` or bound method."""
    if not isinstance(fn, (types.FunctionType, functools.partial, types.MethodType)):
        return fn
    try:
        return ByValue(fn, _Keyer().function(fn, 0))
    except (_Unkeyable, RecursionError):
        return fn
    except Exception:  # noqa: BLE001 - a value whose flattening or hashing fails: keyed by identity, as before
        return fn
