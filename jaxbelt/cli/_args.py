"""Argument types of the `jaxbelt` command: every value is checked before anything is computed.

argparse turns an `argparse.ArgumentTypeError` into a one-line `error:` and exit status 2.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

_IMAGE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def _number(text: str, kind=float):
    try:
        v = kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if kind is float and not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def finite_float(text: str) -> float:
    """Any finite real number."""
    return _number(text)


def positive_float(text: str) -> float:
    """A finite number > 0."""
    return float_above(0.0)(text)


def float_above(lo: float, why: str = ""):
    """A finite number > lo (`why`: the reason, added to the message in parentheses)."""

    def parse(text: str) -> float:
        v = _number(text)
        if not v > lo:
            raise argparse.ArgumentTypeError(f"must be > {lo:g}{f' ({why})' if why else ''}, got {text}")
        return v

    parse.__name__ = "number"
    return parse


def nonnegative_float(text: str) -> float:
    """A finite number >= 0."""
    v = _number(text)
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def float_in(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False):
    """A finite number in the interval (lo|[lo, hi]|hi)."""

    def parse(text: str) -> float:
        v = _number(text)
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
            raise argparse.ArgumentTypeError(f"must lie in {interval}, got {text}")
        return v

    parse.__name__ = "number"
    return parse


def int_at_least(lo: int):
    """An integer >= lo."""

    def parse(text: str) -> int:
        v = int(_number(text, int))
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lo}, got {text}")
        return v

    parse.__name__ = "integer"
    return parse


def int_in(lo: int, hi: int, why: str = ""):
    """An integer in [lo, hi] (`why`: the reason for the upper end, added in parentheses)."""

    def parse(text: str) -> int:
        v = int(_number(text, int))
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(
                f"must be an integer in [{lo}, {hi}]{f' ({why})' if why else ''}, got {text}"
            )
        return v

    parse.__name__ = "integer"
    return parse


def signed_peak(x):
    """The value of largest magnitude along the last axis, with its sign (what a printed "peak" means: a
    current that reaches -37 A peaks at -37 A, not at the largest value, 0)."""
    import numpy as np

    x = np.asarray(x, dtype=float)
    i = np.argmax(np.abs(x), axis=-1)
    return np.take_along_axis(x, np.expand_dims(i, -1), axis=-1)[..., 0]


def image_path(text: str) -> Path:
    """An output image path whose folder exists and is writable; the suffix names the format.

    A name without a suffix gets `.png` (so the printed name is the written one).
    """
    p = Path(text).expanduser()
    if p.suffix == "" and not p.is_dir():
        p = p.with_suffix(".png")
    return _writable(p, _IMAGE_SUFFIXES, "image format")


def csv_or_image_path(text: str) -> Path:
    """An output path for a command (`.csv`) or a figure (an image format), whose folder exists and is writable."""
    p = Path(text).expanduser()
    if p.suffix.lower() == ".csv":
        return _writable(p, (".csv",), "format")
    return image_path(text)


def _writable(p: Path, formats, what: str) -> Path:
    from .._io import output_path_problem

    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{str(p)!r} is a folder, not a file")
    if p.suffix.lower() not in formats:
        raise argparse.ArgumentTypeError(f"{what} {p.suffix!r} is not one of {', '.join(formats)}")
    problem = output_path_problem(p)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return p


def given(args, name: str) -> bool:
    """Whether the option `name` (its `dest`) was given on the command line: the options whose use depends on
    another one default to None, and the command fills in their defaults once it has refused the unused ones."""
    return getattr(args, name, None) is not None


def refuse_unused(args, names, why: str) -> str | None:
    """The one-line error for the first option of `names` (dests) that was given although `why` says it is not
    used, or None."""
    for name in names:
        if given(args, name):
            return f"argument --{name.replace('_', '-')}: not used {why}"
    return None


def fill_defaults(args, defaults: dict) -> None:
    """Set each option of `defaults` that was not given to its default."""
    for name, value in defaults.items():
        if getattr(args, name, None) is None:
            setattr(args, name, value)
