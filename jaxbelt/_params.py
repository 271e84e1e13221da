"""Parameters declared once: unit, default, valid range and meaning in one `param(...)` field.

A model's physical parameter is written once, as a field:

```python
k: FloatParam = param(9e4, unit="N/m", check="positive", doc="stiffness of each belt branch")
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
`shape=(2,)` declares a fixed shape, `shape=None` any shape (the class checks the relations between
its arrays' shapes), and `batch=True` a parameter that may also carry one leading batch axis (the time
constants of `ExponentialVoltage`, solved together by the batched closed form).

A switch (an integer size or a choice among names, a static field) is declared with `option(...)`:
checked at construction and listed in the same table.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, NamedTuple

import equinox as eqx
import jax
import numpy as np
from jax.core import Tracer

from ._checks import _HOST, _RULES, _enforce, _message, _Scalar, as_float_array

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    class FloatParam:
        """The type of a `param` field for type checkers: built from numbers, numpy arrays or tuples of
        numbers (what the float converter takes), read as a JAX array. (A descriptor type: its `__set__`
        gives the constructor's argument type, its `__get__` the attribute's; equinox fields converted by
        a function of ours are otherwise typed by their annotation alone.)"""

        def __get__(self, obj: Any, owner: Any = None) -> jax.Array: ...
        def __set__(self, obj: Any, value: ArrayLike | tuple[float, ...]) -> None: ...

    class OptionalFloatParam:
        """`FloatParam` that may be None (`param(optional=True)`)."""

        def __get__(self, obj: Any, owner: Any = None) -> jax.Array | None: ...
        def __set__(self, obj: Any, value: ArrayLike | tuple[float, ...] | None) -> None: ...

else:  # at run time the annotation says what the field holds
    FloatParam = jax.Array
    OptionalFloatParam = jax.Array | None


#: metadata keys of a declared parameter and of a declared option
_KEY = "jaxbelt_param"
_OPT = "jaxbelt_option"

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
    batch: bool = False  # one leading batch axis allowed on top of `shape`
    optional: bool = False  # None allowed (and not checked)
    valid: str = ""  # the valid values in words, where the class checks them (check="none")


class Option(NamedTuple):
    """What an option declaration says: a static switch (`choices`) or a static integer (`minimum`)."""

    doc: str
    choices: tuple | None
    minimum: int | None
    symbol: str


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
    batch: bool = False,
    optional: bool = False,
    converter=None,
    valid: str = "",
    symbol: str = "",
    default_note: str = "",
) -> Any:
    """A float parameter field: `default` in SI units `unit`, valid values by `check`.

    - `check`: `"positive"` (finite, > 0), `"nonnegative"` (finite, >= 0), `"finite"`, `"range"`
      (finite and within `lo`/`hi`, open or closed ends), or `"none"` (checked by the class itself, in its
      `_check_relations`; `valid` then says the valid values in words for the table).
    - `shape`: `()` for a scalar (default), a tuple for a fixed shape, `None` for any shape;
      `batch=True`: one more leading axis is allowed (a batch of values).
    - `optional`: the value may be None (e.g. "no limiter"); None is not checked.
    - `converter`: the field's converter (default: the float converter of every model).
    - `symbol`: the paper's symbol, in Markdown math (`"$J$"`); `default_note`: said after the default
      in the table (e.g. "Table III").
    """
    if check not in ("positive", "nonnegative", "finite", "range", "none"):
        raise ValueError(f"param: unknown check {check!r}")
    meta = {
        _KEY: Param(unit, doc, check, lo, hi, lo_open, hi_open, shape, symbol, default_note, batch, optional, valid)
    }
    convert = _Convert(as_float_array if converter is None else converter, optional, unit)
    if default is dataclasses.MISSING:
        return eqx.field(converter=convert, metadata=meta)
    return eqx.field(converter=convert, default=default, metadata=meta)


def _describe(x) -> str:
    """A value in a message: short, with its type."""
    text = repr(x)
    if len(text) > 60:
        text = text[:57] + "..."
    dtype = getattr(x, "dtype", None)
    return f"{text} ({type(x).__name__}{'' if dtype is None else f' of dtype {dtype}'})"


class _Convert:
    """The converter of a declared parameter: `base` (the float converter of every model, or the field's
    own) after refusing what is not a real number or an array of them, by the parameter's name.

    A string, a complex number, a bool or None (of a parameter that is not optional) would otherwise fail
    inside JAX's conversion with a message that names no parameter (`could not convert string to float`),
    or pass silently (a bool as 1.0, a complex value without its imaginary part). The field's name and its
    class are filled in when the class is made (`Parametrised.__init_subclass__`)."""

    __slots__ = ("base", "optional", "unit", "name", "owner")

    def __init__(self, base, optional: bool, unit: str):
        self.base, self.optional, self.unit = base, optional, unit
        self.name, self.owner = "?", ""

    def refuse(self, x, why: str = ""):
        where = f"{self.owner}: " if self.owner else ""
        unit = f" [{self.unit}]" if self.unit not in ("", "–", "-") else ""
        raise TypeError(
            f"{where}parameter `{self.name}` must be a real number or an array of real numbers{unit}"
            f"{'' if not why else ' (' + why + ')'}; got {_describe(x)}"
        )

    def __call__(self, x):
        t = type(x)
        if t is float or t is int:  # the common case (defaults, literals): nothing to refuse
            return self.base(x)
        if x is None:
            if self.optional:
                return None
            self.refuse(x)
        if isinstance(x, bool | complex | str | bytes):
            self.refuse(x)
        kind = getattr(getattr(x, "dtype", None), "kind", "f")
        if kind not in "fiu":  # bool, complex, strings, objects
            self.refuse(x, "complex values would lose their imaginary part" if kind == "c" else "")
        try:
            return self.base(x)
        except (TypeError, ValueError) as e:
            if "parameter `" in str(e):  # the field's own converter names it already
                raise
            self.refuse(x)


def converted(cls, name: str, value):
    """`value` through the converter of `cls`'s declared parameter `name` (for a class with an `__init__` of
    its own that reshapes its arguments before the fields are set: the type is refused by the parameter's
    name, as in a generated `__init__`)."""
    field = next(f for f in dataclasses.fields(cls) if f.name == name)
    convert = field.metadata.get("converter", as_float_array)
    return convert(value)


def option(
    default: Any = dataclasses.MISSING,
    *,
    doc: str,
    choices: tuple | None = None,
    minimum: int | None = None,
    symbol: str = "",
) -> Any:
    """A static field: one of `choices` (e.g. `("hard", "smooth")`), or an integer >= `minimum` (a size).

    Checked at construction (`ValueError` naming it), listed in the parameter table; static, so a new
    value compiles a new program (sizes and switches only, never values)."""
    if (choices is None) == (minimum is None):
        raise ValueError("option: give exactly one of `choices` and `minimum`")
    meta = {_OPT: Option(doc, None if choices is None else tuple(choices), minimum, symbol)}
    if default is dataclasses.MISSING:
        return eqx.field(static=True, metadata=meta)
    return eqx.field(static=True, default=default, metadata=meta)


class _Spec(NamedTuple):
    params: tuple  # ((name, Param), ...) in field order
    options: tuple  # ((name, Option), ...)
    defaults: dict  # name -> default
    relations: Any  # the class's `_check_relations`, or None
    relations_take_host: bool


_SPECS: dict = {}


def _spec(cls) -> _Spec:
    spec = _SPECS.get(cls)
    if spec is None:
        params, options, defaults = [], [], {}
        for f in dataclasses.fields(cls):
            if _KEY in f.metadata:
                params.append((f.name, f.metadata[_KEY]))
            elif _OPT in f.metadata:
                options.append((f.name, f.metadata[_OPT]))
            else:
                continue
            defaults[f.name] = f.default
        relations = getattr(cls, "_check_relations", None)
        takes_host = relations is not None and relations.__code__.co_argcount >= 2
        spec = _SPECS[cls] = _Spec(tuple(params), tuple(options), defaults, relations, takes_host)
    return spec


def declared(cls) -> dict[str, tuple[Param, Any]]:
    """`{field name: (Param, default)}` of the parameters a class declares with `param`, in field order."""
    spec = _spec(cls)
    return {name: (p, spec.defaults[name]) for name, p in spec.params}


def declared_options(cls) -> dict[str, tuple[Option, Any]]:
    """`{field name: (Option, default)}` of the options a class declares with `option`, in field order."""
    spec = _spec(cls)
    return {name: (o, spec.defaults[name]) for name, o in spec.options}


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
        "none": p.valid or "see below",
    }[p.check]


def _shape_words(p: Param) -> str:
    """What a parameter's shape must be, after "must": "be a scalar", "have shape (2,)", ..."""
    if p.shape is None:
        return "be an array"
    one = "be a scalar" if p.shape == () else f"have shape {tuple(p.shape)}"
    return f"{one} or a 1-D batch of them" if p.batch else one


def _range_ok(p: Param):
    def ok(v, xp):
        good = xp.all(xp.isfinite(v))
        if p.lo is not None:
            good = good & (xp.all(v > p.lo) if p.lo_open else xp.all(v >= p.lo))
        if p.hi is not None:
            good = good & (xp.all(v < p.hi) if p.hi_open else xp.all(v <= p.hi))
        return good

    return ok


_OK: dict = {}


def _rule(p: Param):
    """`(what the message says, ok(v, xp))` of a declared check."""
    rule = _OK.get(p)
    if rule is None:
        rule = _RULES[p.check] if p.check in _RULES else (f"must lie in {_interval(p)}", _range_ok(p))
        _OK[p] = rule
    return rule


def _check_option(owner: str, name: str, o: Option, value) -> None:
    if o.choices is not None:
        if value not in o.choices:
            raise ValueError(f"{owner}: parameter `{name}` must be one of {o.choices}; got {value!r}")
    elif isinstance(value, bool) or not isinstance(value, int | np.integer) or value < (o.minimum or 0):
        raise ValueError(f"{owner}: parameter `{name}` must be an integer >= {o.minimum}; got {value!r}")


def _shape_ok(p: Param, shape: tuple) -> bool:
    if p.shape is None or shape == p.shape:
        return True
    return p.batch and shape[1:] == p.shape and len(shape) == len(p.shape) + 1


def check_declared(module, owner: str | None = None) -> dict:
    """Check every declared option and parameter of `module`, in declaration order.

    Concrete values out of their range or shape raise `ValueError` naming the parameter, its range, its
    unit and the value; traced values are recorded (`jaxbelt._checks.record`). Cheap: a value made from
    a Python number is known on the host already (`jaxbelt._checks.as_float_array` keeps it), the others
    come over in one device transfer for all of them. Returns `{name: host value}` of the concrete
    parameters (a float, or a numpy array), for the class's relation checks.
    """
    owner = owner or type(module).__name__
    spec = _spec(type(module))
    for name, o in spec.options:
        _check_option(owner, name, o, getattr(module, name))
    host: dict = {}
    fetch, traced = [], []
    for name, p in spec.params:
        value = getattr(module, name)
        if value is None:  # an optional parameter left out (the converter refuses None elsewhere)
            continue
        shape = tuple(value.shape)
        if not _shape_ok(p, shape):
            raise ValueError(
                f"{owner}: parameter `{name}` must {_shape_words(p)} [{p.unit or '-'}]; got an array of shape {shape}"
            )
        known = _HOST.get(id(value))
        if known is not None and known[0] is value:
            host[name] = known[1]
        elif isinstance(value, Tracer):
            traced.append((name, value, p))
        else:
            fetch.append((name, value))
    if fetch:  # one transfer for every value not known on the host
        for (name, _), v in zip(fetch, jax.device_get([v for _, v in fetch])):
            v = np.asarray(v, dtype=float)
            host[name] = float(v) if v.ndim == 0 else v
    for name, p in spec.params:
        if p.check == "none" or name not in host:
            continue
        v = host[name]
        what, ok = _rule(p)
        if not bool(ok(v, _Scalar if isinstance(v, float) else np)):
            got = v if isinstance(v, float) else v.tolist()
            raise ValueError(f"{_message(name, what, p.unit, owner)}; got {got}")
    for name, value, p in traced:
        if p.check != "none":
            what, ok = _rule(p)
            _enforce(name, value, what, p.unit, owner, ok)  # traced: recorded
    return host


class Parametrised(eqx.Module):
    """Base of every module whose fields are declared with `param` (and `option`).

    Construction checks the declarations (concrete values raise, traced ones are recorded), then the
    relations between parameters that a class states in a method `_check_relations(self)` of its own
    (e.g. a platform that must be underdamped), or `_check_relations(self, host)` to receive the host
    values `check_declared` already fetched (`{name: value}`, concrete parameters only): first each
    parameter alone, so that a bad value is named as such and not through a relation it breaks.
    Subclasses do not define `__check_init__`.
    """

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        # the converters of the fields declared here learn their names (for the messages of `_Convert`)
        for name, value in list(vars(cls).items()):
            if isinstance(value, dataclasses.Field) and _KEY in value.metadata:
                convert = value.metadata.get("converter")
                if isinstance(convert, _Convert):
                    convert.name, convert.owner = name, cls.__name__

    def __check_init__(self):
        spec = _spec(type(self))
        host = check_declared(self)
        if spec.relations is not None:
            if spec.relations_take_host:
                spec.relations(self, host)
            else:
                spec.relations(self)


def _fmt_default(d) -> str:
    if d is dataclasses.MISSING:
        return "required"
    if d is None:
        return "None"
    if isinstance(d, bool):
        return str(d)
    if isinstance(d, float | int):
        return f"{d:g}" if not (isinstance(d, float) and math.isnan(d)) else "nan"
    if isinstance(d, str):
        return f'`"{d}"`'
    if isinstance(d, tuple | list):
        return "(" + ", ".join(_fmt_default(x) for x in d) + ")"
    return str(d)


def _valid_cell(p: Param) -> str:
    words = valid_range(p)
    if p.shape is None:
        words += "; an array"
    elif p.shape != ():
        words += f"; shape {tuple(p.shape)}"
    if p.batch:
        words += "; or a 1-D batch"
    if p.optional:
        words += "; or None"
    return words


def parameter_table(cls) -> str:
    """The Markdown table of what `cls` declares (`param` and `option` fields): field, symbol, unit,
    default, valid values, meaning."""
    rows = ["| field | symbol | unit | default | valid | meaning |", "|---|---|---|---|---|---|"]
    spec = _spec(cls)
    params, options = dict(spec.params), dict(spec.options)
    for name, d in spec.defaults.items():  # field order
        if name in params:
            p = params[name]
            default = _fmt_default(d) + (f" ({p.default_note})" if p.default_note else "")
            rows.append(f"| `{name}` | {p.symbol or '–'} | {p.unit or '–'} | {default} | {_valid_cell(p)} | {p.doc} |")
        else:
            o = options[name]
            valid = (
                "one of " + ", ".join(_fmt_default(c) for c in o.choices)
                if o.choices is not None
                else f"integer >= {o.minimum}"
            )
            rows.append(f"| `{name}` | {o.symbol or '–'} | – | {_fmt_default(d)} | {valid} (static) | {o.doc} |")
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
