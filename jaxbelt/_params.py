"""Parameters declared once: unit, default, valid range and meaning in one `param(...)` field.

A model's physical parameter is written once, as a field:

```python
k: FloatScalar = param(9e4, unit="N/m", check="positive", doc="stiffness of each belt branch")
```

and from that single declaration follow

- the field itself (`eqx.field` with the float converter of every model, so values are traced under jit);
- the construction check (`check_declared`, run by `Parametrised.__check_init__` for every subclass):
  a `ValueError` naming the parameter, its range, its unit and the value when values are concrete,
  a recorded check attached to the results when they are traced (see `jaxbelt._guard`);
- the parameter table of the documentation (`parameter_table`), which the class docstring shows where
  it writes the marker `{parameters}` (filled in at class creation, so `help()` and the docs site
  read the same table).

`shape=()` declares a scalar: a concrete array of another shape is refused by name at construction
(an array inertia would otherwise broadcast through the equations and fail later, far from its cause).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import equinox as eqx
import numpy as np

from ._checks import as_float_array, check_fields, host_values, is_concrete

#: metadata key of a declared parameter
_KEY = "jaxbelt_param"

#: the marker a class docstring writes where its parameter table goes
MARKER = "{parameters}"


class Param(NamedTuple):
    """What a parameter declaration says (read by the checks and the documentation)."""

    unit: str
    doc: str
    check: str  # "positive" | "nonnegative" | "finite" | "range" | "none"
    lo: float | None
    hi: float | None
    lo_open: bool
    hi_open: bool
    shape: tuple | None  # None: any shape; () a scalar
    symbol: str
    default_note: str


def param(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    doc: str,
    check: str = "positive",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    shape: tuple | None = (),
    symbol: str = "",
    default_note: str = "",
):
    """A float parameter field: `default` in SI units `unit`, valid values by `check`.

    - `check`: `"positive"` (finite, > 0), `"nonnegative"` (finite, >= 0), `"finite"`, `"range"`
      (finite and within `lo`/`hi`, open or closed ends), or `"none"` (checked by the class itself).
    - `shape`: `()` for a scalar (default), a tuple for a fixed shape, `None` for any shape.
    - `symbol`: the paper's symbol, in Markdown math (`"$J$"`); `default_note`: said after the default
      in the table (e.g. "Table III").
    """
    if check not in ("positive", "nonnegative", "finite", "range", "none"):
        raise ValueError(f"param: unknown check {check!r}")
    meta = {_KEY: Param(unit, doc, check, lo, hi, lo_open, hi_open, shape, symbol, default_note)}
    if default is dataclasses.MISSING:
        return eqx.field(converter=as_float_array, metadata=meta)
    return eqx.field(converter=as_float_array, default=default, metadata=meta)


def declared(cls) -> dict[str, tuple[Param, Any]]:
    """`{field name: (Param, default)}` of the parameters a class declares with `param`, in field order."""
    out = {}
    for f in dataclasses.fields(cls):
        p = f.metadata.get(_KEY)
        if p is not None:
            out[f.name] = (p, f.default)
    return out


def _interval(p: Param) -> str:
    lb = "-inf" if p.lo is None else f"{p.lo:g}"
    ub = "inf" if p.hi is None else f"{p.hi:g}"
    return f"{'(' if p.lo_open or p.lo is None else '['}{lb}, {ub}{')' if p.hi_open or p.hi is None else ']'}"


def valid_range(p: Param) -> str:
    """The valid values of a parameter in words (for messages and tables)."""
    return {
        "positive": "> 0",
        "nonnegative": ">= 0",
        "finite": "finite",
        "range": _interval(p),
        "none": "see the class",
    }[p.check]


def _range_ok(p: Param):
    def ok(v, xp):
        good = xp.all(xp.isfinite(v))
        if p.lo is not None:
            good = good & (xp.all(v > p.lo) if p.lo_open else xp.all(v >= p.lo))
        if p.hi is not None:
            good = good & (xp.all(v < p.hi) if p.hi_open else xp.all(v <= p.hi))
        return good

    return ok


def check_declared(module, owner: str | None = None) -> list | None:
    """Check every declared parameter of `module` (one device transfer for all of them).

    Raises `ValueError` naming the first parameter out of its range or shape (concrete values);
    traced values are recorded (`jaxbelt._checks.record`). Returns the host values in declaration
    order, or None under a trace.
    """
    owner = owner or type(module).__name__
    table = declared(type(module))
    simple, ranged = [], []
    for name, (p, _) in table.items():
        value = getattr(module, name)
        if p.shape is not None and tuple(np.shape(value)) != tuple(p.shape):
            want = "a scalar" if p.shape == () else f"shape {tuple(p.shape)}"
            raise ValueError(
                f"{owner}: parameter `{name}` must be {want} [{p.unit or '-'}]; got an array of shape {np.shape(value)}"
            )
        if p.check in ("positive", "nonnegative", "finite"):
            simple.append((name, value, p.check, p.unit))
        elif p.check == "range":
            ranged.append((name, value, p))
    vals = check_fields(owner, simple)
    if ranged:
        from ._checks import _enforce

        host = host_values([v for _, v, _ in ranged]) if is_concrete([v for _, v, _ in ranged]) else None
        for k, (name, value, p) in enumerate(ranged):
            _enforce(
                name, value if host is None else host[k], f"must lie in {_interval(p)}", p.unit, owner, _range_ok(p)
            )
    return vals


class Parametrised(eqx.Module):
    """Base of every module whose fields are declared with `param`.

    Construction checks the declarations (concrete values raise, traced ones are recorded), then the
    relations between parameters that a class states in a method `_check_relations(self)` of its own
    (e.g. a platform that must be underdamped): first each parameter alone, so that a bad value is
    named as such and not through a relation it breaks. Subclasses do not define `__check_init__`.
    """

    def __check_init__(self):
        check_declared(self)
        relations = getattr(type(self), "_check_relations", None)
        if relations is not None:
            relations(self)


def _fmt_default(d) -> str:
    if d is dataclasses.MISSING:
        return "required"
    if isinstance(d, float | int):
        return f"{d:g}" if not (isinstance(d, float) and math.isnan(d)) else "nan"
    return str(d)


def parameter_table(cls) -> str:
    """The Markdown table of the parameters `cls` declares: field, symbol, unit, default, valid range, meaning."""
    rows = ["| field | symbol | unit | default | valid | meaning |", "|---|---|---|---|---|---|"]
    for name, (p, d) in declared(cls).items():
        default = _fmt_default(d) + (f" ({p.default_note})" if p.default_note else "")
        rows.append(f"| `{name}` | {p.symbol or '–'} | {p.unit or '–'} | {default} | {valid_range(p)} | {p.doc} |")
    return "\n".join(rows)


def document(cls):
    """Class decorator: fill the `{parameters}` marker of the docstring with `parameter_table(cls)`."""
    doc = cls.__doc__
    if doc and MARKER in doc:
        # the marker's indentation is the docstring's: indent every table row alike
        line = next(ln for ln in doc.splitlines() if MARKER in ln)
        indent = line[: len(line) - len(line.lstrip())]
        table = parameter_table(cls).replace("\n", "\n" + indent)
        cls.__doc__ = doc.replace(MARKER, table)
    return cls


def recheck(module) -> None:
    """Run every `__check_init__` of `module`'s classes (as construction does): for a module made by
    `eqx.tree_at`, which skips them."""
    for klass in type(module).__mro__:
        check = klass.__dict__.get("__check_init__")
        if check is not None:
            check(module)
