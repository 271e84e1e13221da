"""Measure: every candidate's command judged the same way, a row of the table (`Candidate`).

The residual of each mode over its band (and damping samples) in % of the unshaped move's, the 5 % bands, the peaks
against the limits, and the positions as executed against the travel.
"""

import dataclasses
import math
from typing import Any

import numpy as np

from ..commands import AbstractMotionCommand
from ..models.axis import ModalAxis
from .hull import positions, sample_times
from .moves import (
    PiecewiseMove,
    fastest_move,
    padded,
    peaks,
)
from .request import _N_BAND, MoveRequest
from .residual import residual_curve, tolerance_band

_WIDE = (0.5, 1.5)


_N_WIDE = 501


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One row of a `MovePlan`'s table.

    - `name`; `command`: the motion command (None when the candidate is infeasible at this move time);
    - `move_time` [s];
    - `worst_percent`, `mean_percent`: worst and mean residual over every mode's band, in % of the unshaped
      move's worst residual on that mode; `worst_m`: the worst residual amplitude in length units [m];
    - `band_hz`: per mode, `(low, high)` [Hz] of the 5 % band (NaN when the nominal residual is above 5 %); with a
      damping range, the band within which the residual stays within 5 % at every damping sample (the
      intersection of the samples' bands);
    - `peak_v` [m/s], `peak_a` [m/s²], `peak_j` [m/s³];
    - `ok`: feasible, converged and within the limits; `note`: why not, or what to know;
    - `outside_percent`: the worst residual outside the band, between 0.5 and 1.5 times each mode's frequency,
      in % of the same references (what an unmodelled or mistaken mode there would see; the ranking ignores it).
    """

    name: str
    command: AbstractMotionCommand | None
    move_time: float
    worst_percent: float
    mean_percent: float
    worst_m: float
    band_hz: tuple
    peak_v: float
    peak_a: float
    peak_j: float
    ok: bool
    note: str = ""
    outside_percent: float = math.nan

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` of the command sampled at `rate_hz` [Hz] (see `AbstractMotionCommand.sample`)."""
        if self.command is None:
            raise ValueError(f"{self.name}: no command ({self.note})")
        return self.command.sample(rate_hz)

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("name", "move_time", "worst_percent", "mean_percent", "worst_m")}
        d.update(outside_percent=self.outside_percent)
        d.update(peak_v=self.peak_v, peak_a=self.peak_a, peak_j=self.peak_j, ok=self.ok, note=self.note)
        for i, (lo, hi) in enumerate(self.band_hz):
            d[f"band5_mode{i + 1}_hz"] = (lo, hi)
        return d


def _mode_label(axis: ModalAxis, i: int, per: int) -> str:
    """Mode `i` of an axis with `per` damping copies per mode of the user's, as the user numbers it."""
    if per == 1:
        return f"mode {i + 1}"
    return f"mode {i // per + 1} at ζ = {float(np.asarray(axis.damping_ratios)[i]):.3g}"


def _measure_grids(u: float):
    """The frequency factors `_measure` evaluates a command's residual on: the band ±u, and the wide range."""
    return (np.linspace(1 - u, 1 + u, _N_BAND) if u > 0 else np.ones(1)), np.linspace(*_WIDE, _N_WIDE)


def _measure(axis, cmd, ref, u, limits, per: int = 1) -> tuple[dict[str, Any], bool]:
    """The table's numbers for one command (`per`: damping copies of each user mode in `axis`)."""
    band, wide = _measure_grids(u)
    res = np.asarray(residual_curve(axis, cmd, band))  # (modes, K)
    ratio = res / ref[:, None]
    wr = np.asarray(residual_curve(axis, cmd, wide)) / ref[:, None]
    f = np.asarray(axis.frequencies)
    bands = []
    for i in range(0, axis.n_modes, per):
        # with damping copies: the band within which every copy stays within 5 % (each contains the nominal
        # frequency, so the intersection is empty only when one of them is, NaN)
        sides = np.array([tolerance_band(wide, wr[k], 0.05) for k in range(i, i + per)], dtype=float)
        lo, hi = float(np.max(sides[:, 0])), float(np.min(sides[:, 1]))  # NaN propagates
        bands.append((lo * f[i], hi * f[i]) if per == 1 or lo <= hi else (math.nan, math.nan))
    pv, pa, pj = peaks(cmd)
    v_max, a_max, j_max = limits
    within = pv <= v_max * (1 + 1e-6) and pa <= a_max * (1 + 1e-6) and (j_max is None or pj <= j_max * (1 + 1e-6))
    outside = (wide < 1.0 - u) | (wide > 1.0 + u)
    return dict(
        outside_percent=100.0 * float(wr[:, outside].max()) if outside.any() else math.nan,
        worst_percent=100.0 * float(ratio.max()),
        mean_percent=100.0 * float(ratio.mean()),
        worst_m=float(res.max()),
        band_hz=tuple(bands),
        peak_v=pv,
        peak_a=pa,
        peak_j=pj,
    ), within


def _pad_size(n_modes: int, jerk: bool, terms: int) -> int:
    """One padded size for the piecewise moves of a plan, so that they share their compiled programs: up to 3
    modes the longest shaped move's (3-hump EI, 5 impulses per mode, 4 terms per impulse without a jerk limit, 8
    with one); beyond, `terms` rounded up to a power of two (the sizes grow as 5**modes)."""
    if n_modes <= 3:
        return (8 if jerk else 4) * 5**n_modes
    return 1 << max(int(terms) - 1, 1).bit_length()


def _row(name, axis, cmd, T, ref, u, limits, note="", ok=True, per: int = 1):
    """One candidate measured on `axis` (with `per` damping copies of each of the user's modes)."""
    n_user = axis.n_modes // per
    if isinstance(cmd, PiecewiseMove):  # shaped on the user's modes: padded to their size
        cmd = padded(cmd, _pad_size(n_user, limits[2] is not None, cmd.times.shape[0]))
    if cmd is None:
        nan = math.nan
        return Candidate(
            name, None, T, nan, nan, nan, tuple((nan, nan) for _ in range(n_user)), nan, nan, nan, False, note
        )
    m, within = _measure(axis, cmd, ref, u, limits, per)
    if not within:
        ok = False
        note = (note + "; " if note else "") + "exceeds the limits"
    return Candidate(name, cmd, float(T), ok=ok, note=note, **m)


#: how far [fraction of the distance] a command may leave the segment between its start and its end before the
#: table notes it
EXCURSION_RTOL = 0.01


def _within_range(row, d: float, x_range, rate: float):
    """`row` with its note saying where its command, as executed at `rate` [Hz], leaves the segment between the start
    and the end by more than `EXCURSION_RTOL` of the distance, and marked not ok where it leaves `x_range`."""
    if row.command is None:
        return row
    t = sample_times(float(row.command.end_time), rate)
    x = positions(row.command, t)
    lo, hi = float(np.min(x)), float(np.max(x))
    below, above = min(0.0, d) - lo, hi - max(0.0, d)
    notes, ok = [], row.ok
    if max(below, above) > EXCURSION_RTOL * abs(d):
        notes.append(f"leaves the segment from start to end: positions {lo:.4g} to {hi:.4g} m")
    if x_range is not None and (lo < x_range[0] or hi > x_range[1]):
        ok = False
        notes.append(f"leaves the position range [{x_range[0]:g}, {x_range[1]:g}] m")
    if not notes:
        return row
    return dataclasses.replace(row, ok=ok, note="; ".join([row.note, *notes] if row.note else notes))


def reference(req: MoveRequest):
    """The time-optimal unshaped move (what a planner runs without shaping) and its worst residual over the band of
    each mode of `req.axis` [m]: `(move, references)`, every row's reference."""
    ref_cmd = fastest_move(req.distance, req.v_max, req.a_max, req.j_max)
    return ref_cmd, np.max(np.asarray(residual_curve(req.axis, ref_cmd, req.band)), axis=1)
