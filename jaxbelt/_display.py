"""Rich displays and labelled data out: the parts the result classes share.

A result describes itself once, as a `Display` (a title, a few labelled values with their units and some
tables), and renders it two ways: `Display.html()` for a notebook's `_repr_html_` (every text escaped with
`html.escape`) and `Display.text()` for `__str__`. `require("pandas")` / `require("xarray")` import the
optional packages of the extra `jaxbelt[notebook]` where `to_pandas` / `to_xarray` need them, with an
`ImportError` that names the extra when they are missing. `output_unit` gives the unit of a state or an
output of a `Solution` by the model that produced it.
"""

from __future__ import annotations

import dataclasses
import html
import importlib
import math
import re
from typing import Any

import numpy as np

#: what `pip` installs for `to_pandas` / `to_xarray`
NOTEBOOK_EXTRA = 'pip install "jaxbelt[notebook]"'


def require(module: str) -> Any:
    """The optional package `module` ("pandas" or "xarray"), or an `ImportError` naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise ImportError(
            f"jaxbelt: this needs the optional package {module!r}, which is not installed; install jaxbelt's notebook "
            f"extra: {NOTEBOOK_EXTRA}"
        ) from e


# --- numbers as text ------------------------------------------------------------------------------------------
def fmt(value, spec: str = ".6g") -> str:
    """A cell as text: numbers by `spec` (NaN and None as '–'), booleans as 'yes'/'no', the rest by `str`."""
    if value is None:
        return "–"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)) or (isinstance(value, np.ndarray) and value.ndim == 0):
        v = float(value)
        return "–" if math.isnan(v) else format(v, spec)
    return str(value)


def fmt_list(values, spec: str = ".6g") -> str:
    """`a, b, c` of the numbers in `values`."""
    return ", ".join(fmt(float(v), spec) for v in np.ravel(np.asarray(values, dtype=float)))


def with_unit(label: str, unit: str) -> str:
    """`label [unit]`, or `label` alone when the quantity has no unit."""
    return f"{label} [{unit}]" if unit and unit not in ("-", "–") else label


#: the style of an HTML cell of text: it wraps at spaces and, in a long word, anywhere (never widens its table)
_WRAP = "text-align:left;white-space:normal;overflow-wrap:anywhere;max-width:32em"


# --- the shared structure and its two renderings --------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Table:
    """One table: `headers` (with their units, `with_unit`), `rows` of cells (numbers, booleans, text; formatted by
    `fmt`), an optional `caption`, and `marked`: the index of the row to mark (a plan's recommendation), whose
    marker column says `mark`."""

    headers: tuple
    rows: tuple
    caption: str = ""
    marked: int | None = None
    mark: str = "best"


@dataclasses.dataclass(frozen=True)
class Display:
    """A result as a title, labelled values `fields` ((label, value, unit) triples) and `tables`; numbers are written
    by the format `spec` (`fmt`; the live view's `".4g"`: 3-4 significant digits). In the HTML, text cells wrap
    (a long note makes a taller row, not a wider table)."""

    title: str
    fields: tuple = ()
    tables: tuple = ()
    spec: str = ".6g"

    def html(self) -> str:
        """HTML for a notebook (`_repr_html_`): a heading, the labelled values and the tables; text escaped."""
        e = html.escape
        parts = ['<div class="jaxbelt-display">', f"<strong>{e(self.title)}</strong>"]
        if self.fields:
            parts.append('<table class="jaxbelt-fields"><tbody>')
            for label, value, unit in self.fields:
                text = fmt(value, self.spec) + (f" {unit}" if unit and unit not in ("-", "–") else "")
                parts.append(f'<tr><th style="text-align:left">{e(label)}</th><td style="{_WRAP}">{e(text)}</td></tr>')
            parts.append("</tbody></table>")
        for t in self.tables:
            parts.append('<table class="jaxbelt-table">')
            if t.caption:
                parts.append(f'<caption style="text-align:left">{e(t.caption)}</caption>')
            mark_col = t.marked is not None
            head = ('<th title="marked row"></th>' if mark_col else "") + "".join(f"<th>{e(h)}</th>" for h in t.headers)
            parts.append(f"<thead><tr>{head}</tr></thead><tbody>")
            for i, row in enumerate(t.rows):
                marked = mark_col and i == t.marked
                cells = "".join(
                    f'<td style="{_WRAP}">{e(fmt(c, self.spec))}</td>'
                    if isinstance(c, str)
                    else f"<td>{e(fmt(c, self.spec))}</td>"
                    for c in row
                )
                if mark_col:
                    cells = (f'<td title="{e(t.mark)}">★</td>' if marked else "<td></td>") + cells
                attrs = ' class="jaxbelt-best" style="font-weight:bold"' if marked else ""
                parts.append(f"<tr{attrs}>{cells}</tr>")
            parts.append("</tbody></table>")
        parts.append("</div>")
        return "\n".join(parts)

    def text(self) -> str:
        """The same as plain text: the title, `label: value unit` lines, and each table in aligned columns (the
        marked row starts with `*`)."""
        lines = [self.title]
        width = max((len(label) for label, _, _ in self.fields), default=0)
        for label, value, unit in self.fields:
            text = fmt(value, self.spec) + (f" {unit}" if unit and unit not in ("-", "–") else "")
            lines.append(f"  {label + ':':{width + 1}s} {text}")
        for t in self.tables:
            lines.append("")
            if t.caption:
                lines.append(t.caption)
            lines += text_table(t.headers, t.rows, t.marked, self.spec)
        return "\n".join(lines)


def text_table(headers, rows, marked: int | None = None, spec: str = ".6g") -> list[str]:
    """Aligned plain-text lines of a table (numbers right-aligned by `spec`, text left), a `*` before the `marked`
    row."""
    cells = [[fmt(c, spec) for c in row] for row in rows]
    numeric = [all(_is_number(row[j]) for row in rows) for j in range(len(headers))]
    widths = [max([len(h)] + [len(r[j]) for r in cells]) for j, h in enumerate(headers)]

    def line(values, prefix):
        out = [v.rjust(w) if num else v.ljust(w) for v, w, num in zip(values, widths, numeric)]
        return (prefix + "  ".join(out)).rstrip()

    pre = marked is not None
    out = [line(list(headers), "  " if pre else "")]
    for i, r in enumerate(cells):
        out.append(line(r, ("* " if i == marked else "  ") if pre else ""))
    return out


def _is_number(v) -> bool:
    return v is None or (isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)))


# --- units of the states and outputs of a `Solution` ----------------------------------------------------------
#: units by name, for every model; a model's own entries (`_MODEL_UNITS`) take precedence
_UNITS = {
    "current": "A",
    "voltage": "V",
    "electric_power": "W",
    "mechanical_power": "W",
    "motor_speed": "rad/s",
    "kinetic_energy": "J",
    "elastic_energy": "J",
    "magnetic_energy": "J",
    "potential_energy": "J",
    "total_energy": "J",
    "electric_energy": "J",
    "copper_loss": "J",
    "damping_loss": "J",
    "load_work": "J",
    "friction_loss": "J",
    "alpha": "rad",
    "alpha_dot": "rad/s",
    "alpha_ddot": "rad/s²",
    "beta": "rad",
    "gamma": "rad",
    "inertia": "kg m²",
    "theta": "rad",
    "omega": "rad/s",
    "acceleration": "rad/s²",
    "command_angle": "rad",
    "command_position": "m",
    "command_velocity": "m/s",
    "command_acceleration": "m/s²",
    "deflection": "m",
    "w_sensor": "m",
    "speed": "m/s",
}
_MODEL_UNITS = {
    "BeltPlatform": {"command_velocity": "rad/s", "command_acceleration": "rad/s²"},
}
#: numbered states and output families: angles, speeds, accelerations of the shafts, modal coordinates
_PATTERNS = (
    (re.compile(r"theta\d+"), "rad"),
    (re.compile(r"omega\d+"), "rad/s"),
    (re.compile(r"alpha\d+"), "rad/s²"),
    (re.compile(r"q\d+"), "m"),
    (re.compile(r"qd\d+"), "m/s"),
    (re.compile(r"zeta_[ri]\d+"), "–"),
)


def output_unit(model: str, name: str) -> str:
    """The unit of the state or output `name` of the model class named `model` ('' when unknown)."""
    unit = _MODEL_UNITS.get(model, {}).get(name) or _UNITS.get(name)
    if unit is not None:
        return unit
    return next((u for pattern, u in _PATTERNS if pattern.fullmatch(name)), "")
