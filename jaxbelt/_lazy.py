"""Lazy re-exports: a package's public names are imported on first use, not by `import jaxbelt`.

A package lists its public names once, as relative imports inside `if typing.TYPE_CHECKING:` (what
type checkers, IDEs and the documentation read). `attach(__name__, __file__)` reads that block
from the package's source and returns the module `__getattr__` and `__dir__` (PEP 562) that import
a name's module the first time the name is used, and the names for `__all__`. A sub-module is
imported when it is first used as an attribute (`jaxbelt.models.fourbar`), as an eager import
would have made it available.

So `import jaxbelt` costs next to nothing (not even JAX's import): the start-up scene never loads the ODE solvers,
optimisers or plotting libraries that the other scenes need.

A module may then be imported for the first time inside a caller's `jit`: its import-time code must
not depend on the trace it runs in (no JAX arrays at module level; `_guard` finds the eager trace
from a fresh thread). tests/test_import_graph.py checks first uses inside `jit`.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import sys
from pathlib import Path


def _is_type_checking(test: ast.expr) -> bool:
    if isinstance(test, ast.Name):
        return test.id == "TYPE_CHECKING"
    return isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"


def exports(path) -> dict:
    """`{public name: (relative module, attribute)}` from the `if TYPE_CHECKING:` block of `path`;
    the attribute is None where the name is a sub-module (`from . import modal as modal`)."""
    tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    table = {}
    for node in tree.body:
        if not (isinstance(node, ast.If) and _is_type_checking(node.test)):
            continue
        for stmt in node.body:
            if not (isinstance(stmt, ast.ImportFrom) and stmt.level == 1):
                raise ImportError(f"{path}: the TYPE_CHECKING block may hold only `from .x import y as y` lines")
            for alias in stmt.names:
                public = alias.asname or alias.name
                table[public] = (alias.name, None) if stmt.module is None else (stmt.module, alias.name)
    return table


def attach(package: str, path):
    """`(__getattr__, __dir__, names)` for the package `package` whose `__init__.py` is `path`."""
    table = exports(path)

    def __getattr__(name):
        if name in table:
            module, attr = table[name]
        elif not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
            module, attr = name, None  # a sub-module: `jaxbelt.models.fourbar` works without an import
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        # jaxbelt's tracing contexts first (`_guard`: JAX user contexts, part of every jit cache key): made
        # while a first program is being traced, they would change the key under it and every program
        # compiled before would be compiled again at its next call
        importlib.import_module("jaxbelt._guard")
        mod = importlib.import_module(f".{module}", package)  # may run inside a caller's jit (module docstring)
        value = mod if attr is None else getattr(mod, attr)
        setattr(sys.modules[package], name, value)  # later uses skip this function
        return value

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__, list(table)


class _LazyModule:
    """A stand-in for the module `name`, imported at the first attribute read (see `lazy_module`)."""

    __slots__ = ("_name",)

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        module = sys.modules.get(self._name)
        if module is None:
            import jax

            # often first read while a program is traced: the library's import-time arrays must be concrete
            # values, not tracers of that program (they would leak out of it)
            with jax.ensure_compile_time_eval():
                module = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self):
        return f"<lazy module {self._name!r}>"


def lazy_module(name: str):
    """The module `name`, imported when one of its attributes is first read: a library only a traced program
    needs (an ODE solver, a root finder) is never imported by a process that loads that program from the
    store (`jaxbelt._store`). Write it as `if TYPE_CHECKING: import x` / `else: x = lazy_module("x")` so that
    type checkers see the module itself."""
    return _LazyModule(name)
