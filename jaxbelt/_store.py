"""Stored programs: the lowered form of jaxbelt's eager programs kept on disk, called untraced.

JAX's persistent compilation cache (`jaxbelt.cache`) skips XLA compilation in a later process, but
not tracing and lowering: JAX must rebuild the program to compute the cache key. For a diffrax
solve that is most of a warm run (~0.7 s for one four-bar simulation). The store keeps, next to
that cache, each program jaxbelt runs eagerly as a `jax.export.Exported` (its StableHLO module,
input and output types), keyed by everything that determines it; a later process calls the stored
module directly (`Exported.call`): no Python tracing, and XLA's compilation comes from JAX's own
persistent cache as before (0.25 s instead of 0.7 s for that simulation).

Each program is compiled in a background thread (XLA releases the GIL while it compiles). A call that runs
several programs `prepare`s them first: each is traced (or loaded) in turn, given its inputs' types (the
outputs' types of the programs before it), and compiles while the next is traced and the first ones run.

The key is the function's name, the tree structure and static values of its arguments, the shapes
and dtypes of its arrays, a fingerprint of jaxbelt's own source and of the versions of its
dependencies, and the JAX settings that change a traced program (x64, matmul precision, XLA flags,
jaxbelt's check contexts). A program is stored only when every node type in its arguments comes
from jaxbelt, equinox, diffrax or optax and every static value is a plain number, string or tuple of
them, a user's function with a lasting key (`jaxbelt._callables.lasting_key`: its code and the values
it reads, for `sweep` and `identify`) or a CPU `Mesh`: a user's own model class (whose code jaxbelt
cannot fingerprint) always takes the traced path. A program JAX cannot export (a host callback) is
marked so, and later processes trace it as before. Any failure to load or call a stored program falls
back to the traced path, which computes the same result.

Used only on a CPU backend (one device, or the devices of the `Mesh` a sharded program takes, its inputs
sharded as they were when it was stored), and only while `jaxbelt.enable_compilation_cache` is on.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import io
import os
import pickle
import sys
from pathlib import Path

import jax
import numpy as np
from jax.sharding import Mesh

from . import _compat, _io
from ._callables import ByValue

_FORMAT = 1
_state = {"folder": None, "usable": None, "fingerprint": None, "lapack": False, "generation": 0}
_MEMO: dict = {}  # (name, structure, input types, static values, settings) -> _Entry, or False: not storable
_MEMO_MAX = 1024

_TRUSTED_PREFIXES = ("jaxbelt.", "equinox.", "diffrax.", "optax.")
_PLAIN_TYPES = (str, int, float, bool, complex, type(None))
#: equinox's marker of absent fields of a module's flattened form (None on another equinox layout: programs taking
#: such modules are then never stored)
_MISSING = _compat.equinox_missing()


def enable(folder) -> None:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if folder != _state["folder"]:
        forget()
    _state["folder"] = folder
    _state["usable"] = None


def disable() -> None:
    _state["folder"] = None
    forget()


def forget() -> None:
    """Drop this process's loaded programs (the next call reads the folder again)."""
    _MEMO.clear()
    _state["generation"] += 1


def generation() -> int:
    return _state["generation"]


def folder():
    return _state["folder"]


def _usable(mesh: bool = False) -> bool:
    """The store serves a CPU backend: a program on one device, or one that shards over a `Mesh` it takes (the
    mesh, its devices included, is part of the key)."""
    if _state["folder"] is None:
        return False
    if _state["usable"] is None:
        try:
            _state["usable"] = (jax.default_backend() == "cpu", jax.device_count() == 1)
        except Exception:  # noqa: BLE001
            _state["usable"] = (False, False)
    cpu, single = _state["usable"]
    return cpu and (single or mesh)


def _fingerprint() -> str:
    """jaxbelt's source and the versions of everything that shapes a compiled program."""
    if _state["fingerprint"] is None:
        import importlib.metadata as md

        h = hashlib.sha256()
        root = Path(__file__).resolve().parent
        for p in sorted(root.rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
        for dist in ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "lineax", "optax", "numpy"):
            try:
                h.update(f"{dist}={md.version(dist)};".encode())
            except md.PackageNotFoundError:
                h.update(f"{dist}=?;".encode())
        h.update(sys.version.encode())
        h.update(repr(jax.devices()[0].device_kind).encode())
        _state["fingerprint"] = h.hexdigest()
    return _state["fingerprint"]


#: functions returning the values of jaxbelt's tracing contexts (registered by `_guard`): they change
#: what a traced program holds, so they are part of the key
CONTEXTS: list = []


def settings() -> tuple:
    """JAX's settings that change a traced program (its trace context: x64, dtype and rank promotion,
    jaxbelt's own check contexts...), XLA's flags and equinox's error mode."""
    c = jax.config
    context = _compat.trace_context()
    if context is not None:
        # its plain values and enums; an object without a value repr (the axis environment, empty
        # outside a trace, where the store is used) by its type
        trace = tuple(v if _plain(v) or isinstance(v, enum.Enum) else type(v).__qualname__ for v in context)
    else:  # another JAX layout: the settings jaxbelt knows of
        names = (
            "jax_enable_x64",
            "jax_default_matmul_precision",
            "jax_numpy_dtype_promotion",
            "jax_numpy_rank_promotion",
        )
        trace = tuple(str(getattr(c, name)) for name in names)  # the values in effect (context managers too)
    return (
        trace,
        os.environ.get("XLA_FLAGS", ""),
        os.environ.get("EQX_ON_ERROR", "raise"),
        tuple(f() for f in CONTEXTS),
    )


def _trusted_type(t) -> bool:
    module = getattr(t, "__module__", None) or ""
    return (
        t in (tuple, list, dict, type(None))
        or module.startswith(_TRUSTED_PREFIXES)
        or (module in ("jaxbelt", "equinox", "diffrax", "optax"))
    )


def _plain(v) -> bool:
    if v is _MISSING and _MISSING is not None:
        return True
    if type(v) in _PLAIN_TYPES:
        return True
    if type(v) in (tuple, list, frozenset):
        return all(map(_plain, v))
    return False


def _describe_tree(treedef):
    """Every node of `treedef` as (module.qualname, repr of its static data), or None when a node type
    comes from outside jaxbelt, equinox and diffrax or its static data is not plain. (The tree's own
    repr names classes by their short name: `jaxbelt.Solution` and `diffrax.Solution` would look alike.)"""
    nodes, todo = [], [treedef]
    while todo:
        t = todo.pop()
        node = t.node_data()
        if node is not None:
            typ, aux = node
            if not _trusted_type(typ) or not _plain(aux):
                return None
            nodes.append((f"{typ.__module__}.{typ.__qualname__}", repr(aux)))
        todo.extend(t.children())
    return tuple(nodes)


def storable_function(fun) -> bool:
    """A module-level function of jaxbelt (its code is in the fingerprint; a closure or a function defined
    elsewhere could change without changing the key)."""
    module, qualname = getattr(fun, "__module__", None) or "", getattr(fun, "__qualname__", None) or ""
    return (
        (module == "jaxbelt" or module.startswith("jaxbelt."))
        and "<locals>" not in qualname
        and (getattr(fun, "__closure__", None) is None)
        and callable(fun)
        and hasattr(fun, "__code__")
    )


def _static(v):
    """A static argument as it enters the key (a string), or None where it cannot: a plain value by its repr, a
    user's function (`jaxbelt._callables.ByValue`) by its lasting key, a CPU `Mesh` by its shape, axis names and
    device ids."""
    if _plain(v):
        return repr(v)
    if isinstance(v, ByValue):
        key = v.lasting_key()
        return None if key is None else f"by_value:{key}"
    if isinstance(v, Mesh):
        devices = list(v.devices.flat)
        if not all(d.platform == "cpu" for d in devices):
            return None
        return f"mesh:{v.devices.shape}:{v.axis_names!r}:{[d.id for d in devices]}"
    return None


def _is_array(x) -> bool:
    """An input of the program (a `jax.ShapeDtypeStruct` stands for one in `prepare`)."""
    return isinstance(x, (jax.Array, np.ndarray, jax.ShapeDtypeStruct))


def aval(x) -> tuple:
    return (x.shape, str(x.dtype), bool(getattr(x, "weak_type", False))) + _layout(x)


def _sharded(x):
    """`x`'s sharding where it spans several devices (a sharded program's input), else None."""
    sharding = getattr(x, "sharding", None)
    try:
        return sharding if sharding is not None and len(sharding.device_set) > 1 else None
    except Exception:  # noqa: BLE001 - a type's abstract sharding (no devices): a one-device input
        return None


def _layout(x) -> tuple:
    sharding = _sharded(x)
    if sharding is None:
        return ()
    return (repr(getattr(sharding, "spec", sharding)), tuple(sorted(d.id for d in sharding.device_set)))


#: what a checkify error keeps of the Python stack where its check was written (None on another jaxlib layout:
#: such outputs are not written, only used in-process)
_TRACEBACK = _compat.traceback_type()


class _Pickler(pickle.Pickler):
    """Pickles the output structure of a program: equinox's marker of absent fields by name, and the
    Python traceback a checkify error carries (where its check was traced) as a placeholder: a
    loaded program's error shows the stack of the process that loaded it."""

    def persistent_id(self, obj):
        if obj is _MISSING and _MISSING is not None:
            return "equinox.MISSING"
        if _TRACEBACK is not None and type(obj) is _TRACEBACK:
            return "traceback"
        return None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid):
        if pid == "equinox.MISSING" and _MISSING is not None:
            return _MISSING
        if pid == "traceback":  # checkify formats one when it raises: the loading process's own stack
            tb = _TRACEBACK.get_traceback() if _TRACEBACK is not None else None
            if tb is None:
                raise pickle.UnpicklingError("no traceback to stand in for the stored one")
            return tb
        raise pickle.UnpicklingError(f"unknown persistent id {pid!r}")


def _dumps(obj) -> bytes:
    with io.BytesIO() as f:
        _Pickler(f, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
        return f.getvalue()


def _ensure_lapack() -> None:
    # LAPACK's kernels are bound when JAX lowers a linear-algebra op from Python; a stored module
    # that calls them must bind them itself before it runs (else a null kernel is called)
    if not _state["lapack"]:
        from jaxlib import lapack

        lapack.prepare_lapack_call("getrf_ffi", np.dtype("float64"))
        _state["lapack"] = True


def _lapack_checks_off() -> list:
    """JAX exports a program for any later JAX and refuses the LAPACK kernels whose interface it does not promise
    to keep (QR's `ormqr`, `orgqr`...): the store's key holds jaxlib's version, so every LAPACK kernel is allowed."""
    if "lapack_checks" not in _state:
        try:
            from jaxlib import lapack

            # only the names of jaxlib's LAPACK kernels are read (each platform's list of (name, kernel, api))
            names = sorted({entry[0] for entries in lapack.registrations().values() for entry in entries})
            _state["lapack_checks"] = [jax.export.DisabledSafetyCheck.custom_call(n) for n in names]
        except Exception:  # noqa: BLE001 - another jaxlib layout: such programs are traced, as before
            _state["lapack_checks"] = []
    return _state["lapack_checks"]


def _executor():
    """The threads that compile stored programs: XLA releases the GIL while it compiles, so a program compiles
    while the caller traces the next one (`prepare`) or runs another."""
    if _state.get("executor") is None:
        from concurrent.futures import ThreadPoolExecutor

        _state["executor"] = ThreadPoolExecutor(
            max_workers=max(1, min(4, os.cpu_count() or 1)), thread_name_prefix="jaxbelt-compile"
        )
    return _state["executor"]


def compile_in_background(lowered):
    """Compile a lowered program (`jax.stages.Lowered`) in the compile threads and return the future: a later call
    of its jitted function on inputs of the same types finds it compiled (see `jaxbelt._xla.LazyJit.compiling` for
    a call made while it compiles). Errors are left to that call."""
    return _executor().submit(lowered.compile)


def _after_fork_in_child() -> None:
    # a forked process has none of its parent's threads: a new pool, and the programs compiled anew (a
    # compilation pending in the parent would never finish here)
    _state["executor"] = None
    forget()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


class _Entry:
    """A stored program: the exported module's call, lowered here for its input types and compiled in a
    background thread (JAX's persistent cache serves that compilation in a later process); the structure of
    its output."""

    __slots__ = ("compiled", "out_tree", "placement", "out_types")

    def __init__(self, exported, out_tree, lapack, specs, compiler_options=None):
        fn = jax.jit(exported.call, compiler_options=compiler_options) if compiler_options else jax.jit(exported.call)
        if lapack:
            _ensure_lapack()  # before it is compiled, and so before it runs
        self.out_tree = out_tree
        # each input on the first device, or as it is sharded (a sharded program's inputs)
        device = jax.sharding.SingleDeviceSharding(jax.devices()[0])
        self.placement = [_sharded(x) or device for x in specs]
        self.out_types = jax.tree_util.tree_unflatten(out_tree, [_spec(a) for a in exported.out_avals])
        # lowered in the caller's thread (JAX's settings are per thread), compiled in another
        lowered = fn.trace(*specs).lower()
        self.compiled = _executor().submit(lowered.compile)

    def __call__(self, dynamic):
        # committed arguments, on the device the program was compiled for
        out = self.compiled.result()(*jax.device_put(list(dynamic), self.placement))
        return jax.tree_util.tree_unflatten(self.out_tree, out)


def _spec(x):
    return jax.ShapeDtypeStruct(x.shape, x.dtype, weak_type=bool(getattr(x, "weak_type", False)), sharding=_sharded(x))


def _codes_used(before=None) -> int:
    """checkify numbers the checks it traces from one process-wide counter, so the program traced
    after a stored one would differ (and miss JAX's persistent cache) if loading the stored one
    skipped its numbers: read the counter (`before=None`), or how many numbers were used since."""
    next_code = _compat.checkify_counter()
    if next_code is None:  # another JAX layout: at worst one more compilation, once
        return 0
    now = next_code()
    return now if before is None else now - before + 1


def _skip_codes(n: int) -> None:
    next_code = _compat.checkify_counter()
    if next_code is not None:
        for _ in range(n):
            next_code()


def _exported_fields(exported) -> dict:
    fields = {f.name: getattr(exported, f.name) for f in dataclasses.fields(exported)}
    fields["_get_vjp"] = None  # jaxbelt differentiates its traced programs, never a stored one
    return fields


def _load(path: Path, key: str, specs, compiler_options=None):
    with open(path, "rb") as f:
        data = _Unpickler(f).load()
    if data[0] != _FORMAT or data[1] != key:
        return None
    _skip_codes(data[2])  # the numbers the first process used tracing this program
    if data[3] is None:  # marked: this program cannot be stored
        return False
    fields, out_tree, lapack = data[3:]
    return _Entry(jax.export.Exported(**fields), out_tree, lapack, specs, compiler_options)


def _write(path: Path, data) -> None:
    _io.write_bytes(path, _dumps(data))


def _debug(message: str) -> None:
    if os.environ.get("JAXBELT_STORE_DEBUG"):
        print(f"jaxbelt store: {message}", file=sys.stderr)


def _export(fun, name, static_leaves, treedef, dynamic, key, path, compiler_options=None):
    """Trace and export `fun` at these arguments and write it; False (and a mark on disk) when JAX
    cannot export it."""
    positions = [i for i, v in enumerate(static_leaves) if v is _DYNAMIC]
    out_box = []

    def flat(*dyn):
        leaves = list(static_leaves)
        for i, v in zip(positions, dyn):
            leaves[i] = v
        out = fun(*jax.tree_util.tree_unflatten(treedef, leaves))
        out_leaves, out_tree = jax.tree_util.tree_flatten(out)
        out_box.append(out_tree)
        return out_leaves

    before = _codes_used()
    try:
        exported = jax.export.export(jax.jit(flat), disabled_checks=_lapack_checks_off())(*dynamic)
    except Exception as e:  # noqa: BLE001 - a host callback (a progress bar, an eqx.error_if), or an error the
        # traced path raises as well (it runs next): later processes skip the attempt
        _debug(f"{name}: not exportable: {type(e).__name__}: {e}")
        try:
            _write(path, (_FORMAT, key, _codes_used(before), None))
        except OSError:
            pass
        return False
    codes = _codes_used(before)
    out_tree = out_box[-1]
    # the serialized module names the kernels it calls (its text form would cost a parse and print: ~60 ms)
    lapack = b"lapack_" in exported.mlir_module_serialized
    try:
        _write(path, (_FORMAT, key, codes, _exported_fields(exported), out_tree, lapack))
    except Exception as e:  # noqa: BLE001 - not picklable or not writable: this process still uses it
        _debug(f"{name}: not written: {type(e).__name__}: {e}")
    return _Entry(exported, out_tree, lapack, [_spec(x) for x in dynamic], compiler_options)


class _Dynamic:
    def __repr__(self):
        return "<array>"


_DYNAMIC = _Dynamic()


def lookup(name: str, fun, args: tuple):
    """The stored program of `fun(*args)`, or False where it cannot be stored (or the store is off).

    `name` identifies `fun` (module and qualified name; `storable_function(fun)` must hold); array
    leaves of `args` are the program's inputs (`entry(dynamic)` takes them in their flattened order),
    every other leaf a static value of the key. Call it outside any trace only. Never raises.
    """
    return _resolve(name, fun, args)[0]


def _resolve(name: str, fun, args: tuple, compiler_options=None):
    """`(lookup(name, fun, args), the program's inputs)`: the arguments are flattened once."""
    if not _usable(mesh=True):
        return False, None
    try:
        leaves, treedef = jax.tree_util.tree_flatten(args)
        dynamic = [v for v in leaves if _is_array(v)]
        static_leaves = [_DYNAMIC if _is_array(v) else v for v in leaves]
        statics = tuple(repr(v) if v is _DYNAMIC else _static(v) for v in static_leaves)
        if None in statics or not _usable(mesh=any(isinstance(v, Mesh) for v in static_leaves)):
            return False, None
        memo_key = (name, treedef, tuple(map(aval, dynamic)), statics, settings())
        entry = _MEMO.get(memo_key)
        if entry is None:
            entry = _lookup(name, fun, treedef, static_leaves, dynamic, memo_key, compiler_options)
            if len(_MEMO) >= _MEMO_MAX:
                _MEMO.clear()
            _MEMO[memo_key] = entry
        return entry, dynamic
    except Exception as e:  # noqa: BLE001 - the store never stands between the user and the traced path
        _debug(f"{name}: {type(e).__name__}: {e}")
        return False, None


def prepare(name: str, fun, args: tuple, compiler_options=None):
    """Trace (or load) the stored program of `fun(*args)` and start compiling it in the background: a later
    `call` with inputs of the same types finds it compiled, or compiling while the caller did other work. An
    input may be given by its type (`jax.ShapeDtypeStruct`). Returns the types of the program's outputs (as
    `jax.ShapeDtypeStruct`s in their structure), or None where it cannot be stored. Never raises."""
    entry = _resolve(name, fun, args, compiler_options)[0]
    return entry.out_types if isinstance(entry, _Entry) else None


def call(name: str, fun, args: tuple, fallback, compiler_options=None):
    """`fun(*args)` through its stored program (see `lookup`); `fallback(*args)` (the traced path, same
    result) where there is none. Call it outside any trace only. `compiler_options`: XLA's, for compiling the
    stored program (fixed per `name`)."""
    entry, dynamic = _resolve(name, fun, args, compiler_options)
    if entry is False:
        return fallback(*args)
    try:
        return entry(dynamic)
    except Exception as e:  # noqa: BLE001 - e.g. an argument committed to another device: the traced path
        _debug(f"{name}: call failed, traced instead: {type(e).__name__}: {e}")
        return fallback(*args)


def _lookup(name, fun, treedef, static_leaves, dynamic, memo_key, compiler_options=None):
    nodes = _describe_tree(treedef)
    folder = _state["folder"]
    if nodes is None or folder is None:
        _debug(f"{name}: arguments from outside jaxbelt or not plain: {treedef}")
        return False
    key = repr((_FORMAT, _fingerprint(), memo_key[0], nodes, repr(treedef), memo_key[2], memo_key[3], memo_key[4]))
    path = folder / (hashlib.sha256(key.encode()).hexdigest() + ".jaxbelt-program")
    if path.exists():
        try:
            entry = _load(path, key, [_spec(x) for x in dynamic], compiler_options)
            if entry is not None:
                return entry
        except Exception as e:  # noqa: BLE001 - unreadable or from another build: export it again
            _debug(f"{name}: not loaded: {type(e).__name__}: {e}")
    return _export(fun, name, static_leaves, treedef, dynamic, key, path, compiler_options)
