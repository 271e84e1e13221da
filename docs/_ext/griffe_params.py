"""Griffe extension for the jaxbelt documentation: the parameter tables of the classes.

A class whose parameters are declared with `jaxbelt._params.param` writes the marker `{parameters}` in
its docstring; `jaxbelt._params.document` fills it with the table of the declarations (field, symbol,
unit, default, valid values, meaning) when the class is created, so `help()` shows the table. The docs
read the source statically (griffe), where the marker is still unfilled: this extension imports the
live class and takes its filled docstring instead. The table is thus written once, by the declarations,
for `help()` and for the site alike. It changes nothing in the package itself.
"""

from __future__ import annotations

import importlib
import inspect

from griffe import Extension

MARKER = "{parameters}"


def filled_docstring(module: str, name: str) -> str | None:
    """The cleaned docstring of the live class `module.name`, or None when it has no filled table."""
    cls = getattr(importlib.import_module(module), name, None)
    doc = inspect.getdoc(cls) if cls is not None else None
    if not doc or MARKER in doc:
        return None
    return doc


class ParameterTables(Extension):
    """Replace the docstring of every class that writes `{parameters}` by its live, filled one."""

    def on_instance(self, *, obj, **kwargs) -> None:  # noqa: D102
        doc = obj.docstring
        if doc is None or MARKER not in doc.value or not getattr(obj, "is_class", False):
            return
        filled = filled_docstring(obj.module.path, obj.name)
        if filled is None:
            raise RuntimeError(f"{obj.path}: the docstring's {MARKER} is not filled in the live class (@document?)")
        doc.value = filled
