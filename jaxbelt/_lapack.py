"""scipy's BLAS and LAPACK pointer tables for jaxlib, loaded without the `scipy.linalg` package.

jaxlib binds its CPU linear-algebra kernels (LU, QR, eig, Cholesky...) to the LAPACK that scipy ships: the
first linear-algebra operation JAX lowers imports `scipy.linalg.cython_blas` and `scipy.linalg.cython_lapack`.
Imported the usual way, they first run `scipy.linalg`'s package initialisation: 0.11-0.2 s on 2 cores (its
array-API layer imports numpy.f2py, pydoc and a hundred other modules), inside the first call of almost every
jaxbelt entry point, for a package jaxbelt never uses.

`bind_tables()` loads the two extension modules on their own, under their own names (the very files the usual
import loads), so that jaxlib finds them in `sys.modules`: about 10 ms. It runs when jaxbelt is first used
(`jaxbelt._guard`) and in the `jaxbelt` command's process, and does nothing where `scipy.linalg` is already
imported. A later `import scipy.linalg` in the same process imports the package as usual; a one-time import hook
then gives the package its two sub-modules as attributes, as the usual import would have (`scipy.linalg.cython_blas`
works; tests/test_guarantees.py). On any failure nothing is left behind and jaxlib imports them the usual way.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys

from ._compat import private_apis

_PACKAGE = "scipy.linalg"
_TABLES = ("cython_blas", "cython_lapack")


class _Linking:
    """The loader of the `scipy.linalg` package, which after running the package gives it the table modules loaded
    before it as attributes. It puts the package's own loader back on the module first: nothing of it stays."""

    def __init__(self, loader):
        self._loader = loader

    def __getattr__(self, name):
        return getattr(self._loader, name)

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        module.__loader__ = self._loader
        if module.__spec__ is not None:
            module.__spec__.loader = self._loader
        self._loader.exec_module(module)
        for name in _TABLES:
            table = sys.modules.get(f"{_PACKAGE}.{name}")
            if table is not None and not hasattr(module, name):
                setattr(module, name, table)


class _LinkOnImport:
    """A one-time import hook: the spec of `scipy.linalg` from the finders after it, with the loader `_Linking`."""

    def find_spec(self, name, path=None, target=None):
        if name != _PACKAGE:
            return None
        _remove_hook()
        for finder in list(sys.meta_path):
            find = getattr(finder, "find_spec", None)
            spec = None if find is None else find(name, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                    spec.loader = _Linking(spec.loader)
                return spec
        return None


_HOOK = _LinkOnImport()


def _remove_hook() -> None:
    try:
        sys.meta_path.remove(_HOOK)
    except ValueError:
        pass


def bind_tables() -> None:
    """Load scipy's BLAS and LAPACK tables as `scipy.linalg.cython_blas` and `scipy.linalg.cython_lapack` without
    the `scipy.linalg` package (see the module docstring); nothing where the package or the tables are loaded, where
    scipy is missing, or where its layout differs (jaxlib then imports them the usual way)."""
    if _PACKAGE in sys.modules or all(f"{_PACKAGE}.{name}" in sys.modules for name in _TABLES):
        return
    if not private_apis("scipy"):  # a scipy whose layout this was not written for: the usual import
        return
    added = []
    try:
        spec = importlib.util.find_spec("scipy")
        if spec is None or spec.origin is None:
            return  # no scipy: jaxlib's own import fails or falls back, as without this function
        folder = os.path.join(os.path.dirname(spec.origin), "linalg")
        for name in _TABLES:
            full = f"{_PACKAGE}.{name}"
            if full in sys.modules:
                continue
            paths = [os.path.join(folder, name + s) for s in importlib.machinery.EXTENSION_SUFFIXES]
            path = next(p for p in paths if os.path.isfile(p))
            mod_spec = importlib.util.spec_from_file_location(full, path)
            if mod_spec is None or mod_spec.loader is None:
                raise ImportError(full)
            module = importlib.util.module_from_spec(mod_spec)
            mod_spec.loader.exec_module(module)
            sys.modules[full] = module
            added.append(full)
        if _HOOK not in sys.meta_path:
            sys.meta_path.insert(0, _HOOK)
    except Exception:  # noqa: BLE001 - another scipy layout: the usual import, 0.1 s slower
        for full in added:
            sys.modules.pop(full, None)
