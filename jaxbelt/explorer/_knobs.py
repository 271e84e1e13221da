"""The sliders' declarations (`Knob`): ranges and units from the parameters' declarations, options checked by name."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np


@dataclasses.dataclass(frozen=True)
class Knob:
    """One slider: `name` (the key of `Explorer.controls` and `Explorer.update`), its `label`, `unit`, range
    `[lo, hi]` in that unit, start `value`, `log` (a logarithmic slider), `doc` (the parameter's meaning) and
    `valid`, the values the parameter's declaration allows (what the option `ranges` is checked against)."""

    name: str
    label: str
    unit: str
    lo: float
    hi: float
    value: float
    log: bool = False
    doc: str = ""
    valid: tuple[float, float, bool] = (-math.inf, math.inf, False)  # (lowest, highest, lowest excluded) allowed

    def check(self, value, owner: str) -> float:
        """`value` as a float, or a `ValueError` naming the slider and its range."""
        unit = f" {self.unit}" if self.unit and self.unit not in ("-", "–") else ""
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise TypeError(
                f"{owner}: parameter `{self.name}` must be a real number{f' [{self.unit}]' if unit else ''}; got {value!r}"
            ) from None
        if not (self.lo <= v <= self.hi):  # NaN fails too
            raise ValueError(
                f"{owner}: parameter `{self.name}` must lie in [{self.lo:.6g}, {self.hi:.6g}]{unit} (the slider's "
                f"range; pass `ranges={{'{self.name}': (lo, hi)}}` to `explore` for another); got {v!r}"
            )
        return v


def _interval(valid: tuple[float, float, bool]) -> str:
    """`(lo, hi]`-style text of a `(lowest, highest, lowest excluded)` triple (an infinite end is open)."""
    lo, hi, open_lo = valid
    return f"{'(' if open_lo or math.isinf(lo) else '['}{lo:g}, {hi:g}{')' if math.isinf(hi) else ']'}"


def _bounds_of(p) -> tuple[float, float, bool]:
    """`(lowest, highest, lowest excluded)` that a declared parameter `p` (a `jaxbelt._params.Param`) allows."""
    if p.check == "positive":
        return 0.0, math.inf, True
    if p.check == "nonnegative":
        return 0.0, math.inf, False
    if p.check == "range":
        lo = -math.inf if p.lo is None else float(p.lo)
        hi = math.inf if p.hi is None else float(p.hi)
        if p.hi_open and math.isfinite(hi):
            hi = hi - 1e-6 * max(abs(hi), 1.0)
        return lo, hi, bool(p.lo_open)
    return -math.inf, math.inf, False


#: the memory a view may take per output time [bytes]: its curves and the solver's saved states, with room for the
#: intermediate arrays (measured: 136 bytes per point for the start-up's closed form, more for the ODE scenes)
BYTES_PER_POINT = 2048


def max_points() -> int:
    """The most output times a view takes: those whose arrays (`BYTES_PER_POINT` each) fit in a quarter of this
    machine's memory (1e7 where the memory cannot be read)."""
    import os

    try:
        memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return 10**7
    return max(int(memory // 4 // BYTES_PER_POINT), 1000)


#: the span [s] of a time-domain view (`t_end`): a start-up's electrical time constant is ~1 ms and its mechanical
#: one ~0.1 s, a platform's move ~1 s; 1 us to 1000 s reaches three decades beyond each, and far beyond (1e300 s)
#: the closed form's accuracy, eps ||A|| t, is lost (a `SolveError` after seconds of work, not a named option)
T_END_RANGE_S = (1e-6, 1e3)
#: the most steps of a view's "tune" button (`tune_steps`): each is a simulation and a gradient (~0.1 s), so 1000
#: steps already keep the view busy for minutes
MAX_TUNE_STEPS = 1000


def check_t_end(owner: str, t_end) -> float:
    """`t_end` [s] as a float within `T_END_RANGE_S`, or a `ValueError` naming the option and the range."""
    lo, hi = T_END_RANGE_S
    try:
        value = float(t_end)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: option `t_end` (s) must be a number in [{lo:g}, {hi:g}] s; got {t_end!r}") from None
    if isinstance(t_end, bool) or not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(
            f"{owner}: option `t_end` (s) must be > 0 and within [{lo:g}, {hi:g}] s (the span of a view: from "
            f"well below a start-up's electrical time constant to far beyond a move); got {t_end!r}"
        )
    return value


def _time_grid(owner: str, t_end: float, n_points, least: int = 2):
    """The view's output times `(ts on the device, t on the host)`: `n_points` (an integer in [`least`,
    `max_points()`]: refused before anything is allocated) equally spaced from 0 to `t_end` [s] (checked by the
    caller)."""
    if isinstance(n_points, bool) or not isinstance(n_points, int | np.integer) or n_points < least:
        raise ValueError(f"{owner}: option `n_points` must be an integer >= {least}; got {n_points!r}")
    most = max_points()
    if n_points > most:
        raise ValueError(
            f"{owner}: option `n_points` must lie in [{least}, {most}] (the output times whose arrays fit in a quarter "
            f"of this machine's memory, {BYTES_PER_POINT} bytes each; a figure shows a few thousand); got {n_points!r}"
        )
    import jax

    ts = jax.device_put(np.linspace(0.0, t_end, int(n_points)))
    return ts, np.asarray(ts)


def _declared_knob(
    cls,
    field: str,
    value: float,
    label: str,
    *,
    factors: tuple[float, float] = (0.25, 4.0),
    lo: float | None = None,
    hi: float | None = None,
    log: bool = False,
    name: str | None = None,
) -> Knob:
    """A slider for the declared parameter `field` of `cls`: its unit and meaning from the declaration, its range
    `value` x `factors` (or `lo`, `hi`) within the values the declaration allows."""
    from .._params import declared

    p, _ = declared(cls)[field]
    return _knob(name or field, label, p.unit, value, p, factors=factors, lo=lo, hi=hi, log=log, doc=p.doc)


def _knob(
    name, label, unit, value, p=None, *, factors=(0.25, 4.0), lo=None, hi=None, log=False, doc="", valid=None
) -> Knob:
    """A slider over `value` x `factors` (or `[lo, hi]`), within the values the declaration `p` (or `valid`, a
    `(lowest, highest, lowest excluded)` triple) allows."""
    value = float(value)
    lo = value * factors[0] if lo is None else float(lo)
    hi = value * factors[1] if hi is None else float(hi)
    if lo > hi:
        lo, hi = hi, lo
    valid = _bounds_of(p) if p is not None else (valid or (-math.inf, math.inf, False))
    dlo, dhi, open_lo = valid
    if not ((value > dlo if open_lo else value >= dlo) and value <= dhi):
        units = f" {unit}" if unit and unit not in ("-", "–") else ""
        raise ValueError(f"explore: parameter `{name}` must lie in {_interval(valid)}{units}; got {value}")
    if open_lo and lo <= dlo:
        lo = dlo + 1e-3 * (hi - dlo if math.isfinite(hi) else 1.0)
    lo, hi = max(lo, dlo), min(hi, dhi)
    lo, hi = min(lo, value), max(hi, value)
    if log and not lo > 0:
        raise ValueError(f"explore: the logarithmic slider `{name}` needs a positive range; got [{lo}, {hi}]")
    if not hi > lo:
        hi = lo + (abs(lo) or 1.0)
    return Knob(name, label, unit, lo, hi, value, log, doc, valid)


def _with_ranges(knobs: list[Knob], ranges, owner: str) -> list[Knob]:
    """`knobs` with the ranges of the option `ranges` ({name: (lo, hi)}), checked against the declarations."""
    if not ranges:
        return knobs
    if not isinstance(ranges, dict):
        raise TypeError(f"{owner}: option `ranges` must be a dict {{slider name: (lo, hi)}}; got {ranges!r}")
    names = [k.name for k in knobs]
    out = []
    for k in knobs:
        if k.name not in ranges:
            out.append(k)
            continue
        r = ranges[k.name]
        try:
            lo, hi = (float(x) for x in r)
        except (TypeError, ValueError):
            raise ValueError(f"{owner}: `ranges[{k.name!r}]` must be a pair (lo, hi) of numbers; got {r!r}") from None
        dlo, dhi, open_lo = k.valid
        unit = f" {k.unit}" if k.unit and k.unit not in ("-", "–") else ""
        valid = _interval(k.valid)
        if not (lo < hi and (lo > dlo if open_lo else lo >= dlo) and hi <= dhi and math.isfinite(lo + hi)):
            raise ValueError(
                f"{owner}: `ranges[{k.name!r}]` must be (lo, hi) with lo < hi inside the valid values {valid}{unit} "
                f"of parameter `{k.name}`; got {(lo, hi)}"
            )
        if k.log and not lo > 0:
            raise ValueError(f"{owner}: `ranges[{k.name!r}]` is a logarithmic slider: lo must be > 0; got {lo}")
        out.append(dataclasses.replace(k, lo=lo, hi=hi, value=min(max(k.value, lo), hi)))
    unknown = sorted(set(ranges) - set(names))
    if unknown:
        raise ValueError(f"{owner}: `ranges` names no slider {unknown}; sliders: {names}")
    return out


def _options(owner: str, given: dict, allowed: Sequence[str]) -> None:
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise TypeError(f"{owner}: unknown option(s) {unknown}; options: {sorted(allowed)}")
