"""The frequency grids `design_move` judges every residual on, and how a mode of the judged axis is named.

A lower-level module of the pipeline (validate → build the candidates → measure → rank): every stage that needs a
grid or a mode's name takes it from here, so that none calls back into another stage's module.
"""

import numpy as np

#: the name of the row `design_move` adds, with `smooth="auto"`, for the minimax design whose acceleration may jump
JUMPS = "minimax (jumps)"

#: frequency points of the band $f_i(1 \\pm u)$ the table is computed on
_N_BAND = 401

#: the wide range, as factors of each mode's frequency, of the 5 % bands and of the residual outside the band
_WIDE = (0.5, 1.5)

#: frequency points of the wide range
_N_WIDE = 501


def band_factors(u: float) -> np.ndarray:
    """The frequency factors of the band ±`u`: `_N_BAND` points of [1 - u, 1 + u], or the nominal one for u = 0."""
    return np.linspace(1 - u, 1 + u, _N_BAND) if u > 0 else np.ones(1)


def measure_grids(u: float):
    """The frequency factors a command's residual is measured on: the band ±`u` (`band_factors`), and the wide
    range `_WIDE` (`_N_WIDE` points)."""
    return band_factors(u), np.linspace(*_WIDE, _N_WIDE)


def mode_label(axis, i: int, per: int) -> str:
    """Mode `i` of an axis with `per` damping copies per mode of the user's, as the user numbers it."""
    if per == 1:
        return f"mode {i + 1}"
    return f"mode {i // per + 1} at ζ = {float(np.asarray(axis.damping_ratios)[i]):.3g}"
