"""Argument types of the `jaxbelt` command: every value is checked before anything is computed.

argparse turns an `argparse.ArgumentTypeError` into a one-line `error:` and exit status 2.
"""

from __future__ import annotations

import argparse
import math
import os
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
    if p.suffix == "":
        p = p.with_suffix(".png")
    if p.suffix.lower() not in _IMAGE_SUFFIXES:
        raise argparse.ArgumentTypeError(f"image format {p.suffix!r} is not one of {', '.join(_IMAGE_SUFFIXES)}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK):
        raise argparse.ArgumentTypeError(f"folder {str(folder)!r} is not writable")
    if p.exists() and p.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a folder, not a file")
    return p
