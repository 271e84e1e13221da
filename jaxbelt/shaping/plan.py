"""`design_move`: every command for the user's axis under the same limits and move time, ranked, with a recommendation.

The candidates (all rest to rest over the same distance, all within the same |v|, |a| (|jerk|) limits):

- **minimax** — the convex design (`jaxbelt.shaping.design`): the least worst-case residual over the band that
  a move of its space can leave (a cubic B-spline acceleration; with `smooth=False`, an acceleration that may
  jump between N equal intervals, or, with `j_max`, a continuous piecewise linear acceleration whose jerk may jump
  between them), solved to a certified optimum; with `smooth=False` and no jerk limit also a rigorous lower bound
  on what any command can leave (`jaxbelt.shaping.certify`);
- **ZV, MZV, ZVD, EI, 2-hump EI, 3-hump EI** — the classic input shapers as Klipper's shaper definitions give
  them (`jaxbelt.shaping.shapers`; an EI fit outside its damping range is listed, not built), one per mode and
  convolved, applied to the gentlest trapezoidal (or, with `j_max`, S-curve) base move that ends at the same
  total time: the base is shortened by the shaper's length, never the whole move lengthened;
- **pseudo-polynomial (optimal / robust)** — Incerti's commands (eq. 17-23) with exponents optimised for the axis
  (`jaxbelt.shaping.pseudo`);
- **unshaped** — the gentlest trapezoid (S-curve) of the same time.

**The measure** (the one input-shaping practice uses): the residual vibration amplitude of each mode after the
move, over the band $f_i(1 \\pm u)$ (frequency error $\\pm u$, damping ratio kept), in length units and in % of the
unshaped move: of the worst residual over the band that the *time-optimal unshaped move* (what a planner runs
without shaping, `fastest_move`) leaves on that mode. The 5 % band of a mode is the contiguous frequency range
around its nominal value where the residual stays within 5 % of that reference.

With `damping=(lo, hi)` (or `"unknown"`), every mode's damping ratio may also be anywhere in [lo, hi]: each residual
is judged on the band times `N_DAMPING` damping samples of the range (`damping_samples`), each sample against the
unshaped move's residual at that damping, and the minimax design minimises the worst of them all.

With `move_time=None`, each classic shaper runs at its own shortest time (time-optimal base + shaper length),
the best of them (least worst residual) sets the target, and the minimax design is placed at the shortest move
time at which it reaches that target (bisection on the time).
"""

import csv
import dataclasses
import math
import warnings
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._checks import check_positive, check_range, device_array
from .._display import Display, Table, fmt, fmt_list, require, with_unit
from .._io import IMAGE_FORMATS, atomic_open, check_output_path, save_figure
from .._threads import blas_limited
from ..commands import AbstractMotionCommand
from ..models.axis import ModalAxis
from . import design as _design
from .certify import continuous_lower_bound
from .moves import (
    PiecewiseMove,
    SplineMove,
    check_move_limits,
    executable_samples,
    fastest_move,
    fastest_time,
    limited_samples,
    padded,
    peaks,
    prepare_peaks,
    sampled_peaks,
    shape_move,
    trapezoid_move,
)
from .residual import prepare_curve, residual_curve, tolerance_band
from .shapers import SHAPERS, ShaperRangeError, shaper_for_axis

#: move time, relative to the time-optimal move's, above which the smooth design is feasible (measured: it needs
#: 3-7 % more with 48-96 knots; the design's convergence is checked, and the feasibility LP decides otherwise)
_SURELY_FEASIBLE = 1.15

#: frequency factors of the curves the table and the figure are computed on: the band, and a wider view
_N_BAND = 401
_WIDE = (0.5, 1.5)
_N_WIDE = 501

#: units of the sampled move (`MovePlan.samples_to_pandas`)
_SAMPLE_UNITS = {"t": "s", "x": "m", "v": "m/s", "a": "m/s²"}

#: damping samples per mode with `design_move(..., damping=(lo, hi))`: the worst residual of a design over the damping
#: range lies within 2 % of the worst over these samples (1.9 % measured on a 25-sample grid of (0.01, 0.1) for a
#: 7.3 Hz minimax design, whose residual the LP equalises over the samples; tests/test_damping_range.py)
N_DAMPING = 5
#: the damping range `damping="unknown"` stands for, and the damping ratio the classic shapers are then designed at
#: (Klipper's default for an axis whose damping is not measured)
UNKNOWN_DAMPING = (0.01, 0.1)
UNKNOWN_SHAPER_DAMPING = 0.1


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


@dataclasses.dataclass(frozen=True)
class MovePlan:
    """The result of `design_move`: `table` (candidates ranked, best first), `best` (the recommended
    `Candidate`; None when no candidate is feasible, converged and within the limits), the axis, the move's data, `reference_m` (per mode, the unshaped move's worst residual over the
    band [m]) and the minimax design's details (`minimax`: a `MinimaxDesign` or None); `continuous_bound`: a rigorous
    lower bound on the least worst residual any command within the plan's limits, distance and time can leave over
    the band, as a fraction of the references (the minimax rows' worst % are at least 100x this; NaN without a
    converged minimax design with steps, `smooth=False` or the row `smooth="auto"` adds, without a jerk limit;
    `jaxbelt.shaping.certify`).

    `damping`: the damping range `(lo, hi)` every residual was judged over (`design_move(..., damping=...)`), or
    None (the axis' own damping ratios). With a range, `axis` is the user's axis, `reference_m` per mode the largest
    of its damping samples' references, and `measure_axis`, `measure_reference_m` the expanded axis (each mode once
    per damping sample, `damping_samples`) and its references, on which every residual of the table, the curves and
    the exported samples' correction are computed."""

    axis: ModalAxis
    distance: float
    move_time: float
    v_max: float
    a_max: float
    j_max: float | None
    uncertainty: float
    reference_m: np.ndarray
    table: tuple
    best: Candidate | None
    minimax: object = None
    continuous_bound: float = math.nan
    damping: tuple[float, float] | None = None
    measure_axis: ModalAxis | None = None
    measure_reference_m: np.ndarray | None = None

    def _measured(self) -> tuple[ModalAxis, np.ndarray, int]:
        """The axis every residual is computed on, its references [m], and its copies per mode of `axis`."""
        if self.measure_axis is None or self.measure_reference_m is None:
            return self.axis, np.asarray(self.reference_m), 1
        return self.measure_axis, np.asarray(self.measure_reference_m), self.measure_axis.n_modes // self.axis.n_modes

    def __str__(self) -> str:
        return self.format_table()

    def format_table(self) -> str:
        """The ranked table as text (what `jaxbelt shaping` prints)."""
        n = self.axis.n_modes
        head = f"{'candidate':28s} {'T [s]':>7s} {'worst %':>9s} {'mean %':>9s} {'worst [m]':>10s} {'outside %':>9s} "
        head += " ".join(f"{'5% band m' + str(i + 1) + ' [Hz]':>19s}" for i in range(n))
        head += f" {'peak v':>8s} {'peak a':>8s}  note"
        lines = [head]
        for c in self.table:
            bands = " ".join(f"{'-':>19s}" if not np.isfinite(lo) else f"{lo:8.3f}-{hi:<10.3f}" for lo, hi in c.band_hz)
            mark = "*" if c is self.best else " "
            lines.append(
                f"{mark}{c.name:27s} {c.move_time:7.3f} {c.worst_percent:9.4f} {c.mean_percent:9.4f} "
                f"{c.worst_m:10.3e} {c.outside_percent:9.3g} {bands} {c.peak_v:8.4f} {c.peak_a:8.4f}  {c.note}"
            )
        if self.damping is not None:
            lines.append(f"band: ±{100 * self.uncertainty:g} % of each frequency{self._damping_words()}")
        return "\n".join(lines)

    def to_csv(self, path, rate_hz: float, candidate: str | None = None) -> tuple[float, float, float]:
        """Write the recommended command (or the candidate named `candidate`) sampled at `rate_hz` [Hz] as CSV
        columns `t,x,v,a` (s, m, m/s, m/s²) with that header line. A drive that executes the acceleration
        linearly between samples reproduces the table's residual (the design's acceleration is continuous), and
        the samples respect the plan's limits (see `samples`).

        `path`: a `.csv` file in an existing, writable folder; `rate_hz` must exceed twice the highest frequency
        of the band (the samples must carry the modes). Both are checked before anything is computed. The file
        is written atomically: to a temporary file in the same folder, then renamed over `path`, so a failed
        write leaves the previous file as it was. Returns the written samples' `(peak |v| [m/s], peak |a|
        [m/s²], peak |jerk| [m/s³])` (the jerk: the slope of the acceleration between samples)."""
        path = check_output_path(path, "path", "MovePlan.to_csv", formats=(".csv",))
        self._check_rate(rate_hz, "MovePlan.to_csv")
        c = self._chosen(candidate, "MovePlan.to_csv")
        t, x, v, a = self.samples(rate_hz, c.name)
        with atomic_open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", "x", "v", "a"])
            for row in zip(t, x, v, a):
                w.writerow([repr(float(q)) for q in row])
        return sampled_peaks(t, v, a)

    def nyquist_hz(self) -> float:
        """Twice the highest frequency of the band [Hz]: the sample rate a CSV export must exceed."""
        return nyquist_hz(self.axis.frequencies, self.uncertainty)

    def _check_rate(self, rate_hz, owner: str) -> None:
        check_positive("rate_hz", rate_hz, "Hz", owner)
        check_rate(rate_hz, self.nyquist_hz(), owner)

    def samples(self, rate_hz: float, candidate: str | None = None):
        """`(t, x, v, a)` of the recommended command (or `candidate`) sampled at `rate_hz` [Hz], as `to_csv` writes
        them: for the smooth minimax design, corrected so that a drive that executes the acceleration linearly
        between samples leaves the residual the table states (`jaxbelt.shaping.moves.executable_samples`); for
        the others, the exact samples.

        Every sample respects the plan's limits to a relative 1e-9: |v| <= v_max [m/s], |a| <= a_max [m/s²] and,
        with j_max, |a_k+1 - a_k| rate_hz <= j_max [m/s³]. The design's correction includes them as constraints
        (the least change of the acceleration that restores the residual and keeps them; a scaled-down copy
        would change the distance); another command that exceeds them by a rounding is stretched in time by the
        least factor that brings it within them (same distance, same rate; `jaxbelt.shaping.moves.limited_samples`)."""
        c = self._chosen(candidate, "MovePlan.samples")
        limits = (self.v_max, self.a_max, self.j_max)
        cmd = c.command
        assert cmd is not None  # `_chosen` refuses a candidate without a command
        if isinstance(cmd, SplineMove):
            axis, ref, _ = self._measured()  # the residual the table states: over the band (and damping range)
            return executable_samples(cmd, rate_hz, axis, ref, self.uncertainty, limits=limits)
        return limited_samples(cmd, rate_hz, limits)

    def _chosen(self, name: str | None, owner: str) -> Candidate:
        if name is not None:
            c = self.candidate(name)
        elif self.best is None:
            raise ValueError(
                f"{owner}: no candidate is feasible, converged and within the limits, so none is recommended (see "
                f"the table's notes); name one with `candidate` to export it anyway"
            )
        else:
            c = self.best
        if c.command is None:
            raise ValueError(f"{owner}: candidate {c.name!r} has no command ({c.note})")
        return c

    def candidate(self, name: str) -> Candidate:
        for c in self.table:
            if c.name == name:
                return c
        raise ValueError(f"MovePlan: no candidate named {name!r}; candidates: {[c.name for c in self.table]}")

    def curves(self, factors=None):
        """`(factors, {name: residual % of shape (n_modes, len(factors))})` for every candidate with a command; with
        a damping range, per mode the worst over its damping samples."""
        f = np.linspace(*_WIDE, _N_WIDE) if factors is None else np.asarray(factors, dtype=float)
        axis, ref, per = self._measured()
        out = {}
        for c in self.table:
            if c.command is not None:
                pct = 100.0 * np.asarray(residual_curve(axis, c.command, f)) / ref[:, None]
                out[c.name] = pct.reshape(self.axis.n_modes, per, -1).max(axis=1)
        return f, out

    def plot(self, path=None):
        """The figure a firmware calibration prints: residual % against frequency for every candidate (one panel
        per mode, the band shaded), and the commands' velocity and acceleration. Returns the figure; saved to
        `path` when given (an image: .png, .pdf, .svg, .jpg; its folder must exist and be writable, checked before
        the figure is computed; written atomically, so a failed save leaves the previous file)."""
        from ..plots.plan import plan_figure

        if path is not None:  # before the figure's curves are computed
            path = check_output_path(path, "path", "MovePlan.plot", formats=IMAGE_FORMATS)
        fig = plan_figure(self)
        if path is not None:
            save_figure(fig, path, dpi=120)  # atomically: a failed save leaves the previous file
        return fig

    # --- display and labelled data ----------------------------------------------------------------------------
    def _display(self) -> Display:
        axis = self.axis
        limits = f"|v| ≤ {fmt(self.v_max)} m/s, |a| ≤ {fmt(self.a_max)} m/s²"
        if self.j_max is not None:
            limits += f", |j| ≤ {fmt(self.j_max)} m/s³"
        fields = (
            (
                "axis",
                f"{axis.n_modes} mode(s): f = {fmt_list(axis.frequencies, '.4g')} Hz, "
                f"ζ = {fmt_list(axis.damping_ratios, '.3g')}",
                "",
            ),
            ("distance", self.distance, "m"),
            ("move time", self.move_time, "s"),
            ("limits", limits, ""),
            ("band", f"±{100 * self.uncertainty:g} % of each frequency" + self._damping_words(), ""),
            ("recommended", self.best.name if self.best is not None else "none (see the notes)", ""),
        )
        n = axis.n_modes
        headers = (
            "candidate",
            with_unit("T", "s"),
            with_unit("worst", "%"),
            with_unit("mean", "%"),
            with_unit("worst", "m"),
            with_unit("outside band", "%"),
            *(with_unit(f"5 % band, mode {i + 1}", "Hz") for i in range(n)),
            with_unit("peak v", "m/s"),
            with_unit("peak a", "m/s²"),
            "ok",
            "note",
        )
        rows = []
        for c in self.table:
            bands = tuple(f"{lo:.3f} – {hi:.3f}" if np.isfinite(lo) else None for lo, hi in c.band_hz)
            rows.append(
                (c.name, c.move_time, c.worst_percent, c.mean_percent, c.worst_m, c.outside_percent)
                + bands
                + (c.peak_v, c.peak_a, c.ok, c.note)
            )
        marked = next((i for i, c in enumerate(self.table) if c is self.best), None)
        table = Table(headers, tuple(rows), caption="candidates, best first", marked=marked, mark="recommended")
        return Display("jaxbelt MovePlan", fields, (table,))

    def _damping_words(self) -> str:
        if self.damping is None:
            return ""
        n = self._measured()[2]
        return f", × damping ratio {self.damping[0]:g} – {self.damping[1]:g} ({n} samples)"

    def _repr_html_(self) -> str:
        return self._display().html()

    def to_pandas(self):
        """The ranked table as a `pandas.DataFrame`, one row per candidate (index `candidate`, best first):
        `rank`, `best` (the recommendation), `ok`, `move_time` [s], `worst_percent`, `mean_percent`,
        `outside_percent` [%], `worst_m` [m], `band5_low_mode{i}`, `band5_high_mode{i}` [Hz] (the 5 % band of
        mode i, NaN where there is none), `peak_v` [m/s], `peak_a` [m/s²], `peak_j` [m/s³], `note`; the units in
        `df.attrs["units"]`. Needs pandas (`pip install "jaxbelt[notebook]"`)."""
        pd = require("pandas")
        columns, units = self._columns()
        df = pd.DataFrame(columns, index=pd.Index([c.name for c in self.table], name="candidate"))
        df.attrs["units"] = units
        return df

    def to_xarray(self):
        """The ranked table as an `xarray.Dataset` over the dimensions `candidate` (best first; the names as the
        coordinate) and `mode` (1..n): the columns of `to_pandas`, the 5 % bands as `band5_low`, `band5_high`
        (candidate, mode) [Hz] and the unshaped reference `reference_m` (mode) [m]; units in each variable's
        `attrs["units"]`, the move's data (distance, move time, limits, uncertainty, recommendation) in the
        dataset's `attrs`. Needs xarray (`pip install "jaxbelt[notebook]"`)."""
        xr = require("xarray")
        columns, units = self._columns(bands=False)
        data: dict[str, tuple] = {
            k: ("candidate", np.asarray(v), {"units": units[k]} if units.get(k) else {}) for k, v in columns.items()
        }
        for side, k in (("low", 0), ("high", 1)):
            vals = np.array([[b[k] for b in c.band_hz] for c in self.table], dtype=float).reshape(len(self.table), -1)
            data[f"band5_{side}"] = (("candidate", "mode"), vals, {"units": "Hz"})
        data["reference_m"] = ("mode", np.asarray(self.reference_m, dtype=float), {"units": "m"})
        coords = {"candidate": [c.name for c in self.table], "mode": np.arange(1, self.axis.n_modes + 1)}
        attrs = dict(
            distance=self.distance,
            move_time=self.move_time,
            v_max=self.v_max,
            a_max=self.a_max,
            j_max=math.nan if self.j_max is None else self.j_max,
            uncertainty=self.uncertainty,
            best="" if self.best is None else self.best.name,
        )
        if self.damping is not None:
            attrs.update(damping_low=self.damping[0], damping_high=self.damping[1])
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def _columns(self, bands: bool = True):
        t = self.table
        cols: dict = {
            "rank": np.arange(1, len(t) + 1),
            "best": np.array([c is self.best for c in t], dtype=bool),
            "ok": np.array([c.ok for c in t], dtype=bool),
        }
        units = {"move_time": "s", "worst_percent": "%", "mean_percent": "%", "outside_percent": "%", "worst_m": "m"}
        for k in units:
            cols[k] = np.array([getattr(c, k) for c in t], dtype=float)
        if bands:
            for i in range(self.axis.n_modes):
                cols[f"band5_low_mode{i + 1}"] = np.array([c.band_hz[i][0] for c in t], dtype=float)
                cols[f"band5_high_mode{i + 1}"] = np.array([c.band_hz[i][1] for c in t], dtype=float)
                units[f"band5_low_mode{i + 1}"] = units[f"band5_high_mode{i + 1}"] = "Hz"
        for k, unit in (("peak_v", "m/s"), ("peak_a", "m/s²"), ("peak_j", "m/s³")):
            cols[k] = np.array([getattr(c, k) for c in t], dtype=float)
            units[k] = unit
        cols["note"] = np.array([c.note for c in t], dtype=object)
        return cols, units

    def samples_to_pandas(self, rate_hz: float, candidate: str | None = None):
        """The sampled move of the recommended command (or `candidate`) at `rate_hz` [Hz], what `samples` and
        `to_csv` give, as a `pandas.DataFrame` indexed by `t` [s] with the columns `x` [m], `v` [m/s] and `a`
        [m/s²]; units, candidate and rate in `df.attrs`. Needs pandas (`pip install "jaxbelt[notebook]"`)."""
        pd = require("pandas")
        name, (t, x, v, a) = self._sampled(rate_hz, candidate, "MovePlan.samples_to_pandas")
        df = pd.DataFrame({"x": x, "v": v, "a": a}, index=pd.Index(t, name="t"))
        df.attrs.update(units=dict(_SAMPLE_UNITS), candidate=name, rate_hz=float(rate_hz))
        return df

    def samples_to_xarray(self, rate_hz: float, candidate: str | None = None):
        """`samples_to_pandas` as an `xarray.Dataset`: `x`, `v`, `a` over the coordinate `t` [s], units in each
        variable's `attrs["units"]`. Needs xarray (`pip install "jaxbelt[notebook]"`)."""
        xr = require("xarray")
        name, (t, x, v, a) = self._sampled(rate_hz, candidate, "MovePlan.samples_to_xarray")
        u = _SAMPLE_UNITS
        data = {k: ("t", np.asarray(val), {"units": u[k]}) for k, val in (("x", x), ("v", v), ("a", a))}
        coords = {"t": ("t", np.asarray(t), {"units": "s"})}
        return xr.Dataset(data, coords=coords, attrs={"candidate": name, "rate_hz": float(rate_hz)})

    def _sampled(self, rate_hz, candidate, owner: str):
        self._check_rate(rate_hz, owner)
        c = self._chosen(candidate, owner)
        return c.name, tuple(np.asarray(q, dtype=float) for q in self.samples(rate_hz, c.name))


def nyquist_hz(frequencies, uncertainty: float) -> float:
    """Twice the highest frequency of the band [Hz]: `2 max(f_i) (1 + uncertainty)`, `frequencies` [Hz]."""
    return 2.0 * float(np.max(np.asarray(frequencies, dtype=float))) * (1.0 + float(uncertainty))


def check_rate(rate_hz, nyquist: float, owner: str) -> None:
    """A `ValueError` naming `rate_hz` unless it exceeds `nyquist` [Hz] (the samples must carry the modes)."""
    if not float(rate_hz) > nyquist:
        raise ValueError(
            f"{owner}: parameter `rate_hz` must exceed twice the highest frequency of the band "
            f"(Nyquist: > {nyquist:g} Hz); got {rate_hz}"
        )


def _check_inputs(axis, distance, move_time, v_max, a_max, j_max, uncertainty, include):
    o = "design_move"
    if not isinstance(axis, ModalAxis):
        raise TypeError(
            f"{o}: `axis` must be a jaxbelt.ModalAxis (or BeltPlatform(...).to_axis()); got {type(axis).__name__}"
        )
    check_move_limits(o, distance, v_max, a_max, j_max)
    d = float(np.asarray(distance))
    check_range("uncertainty", uncertainty, lo=0.0, hi=0.9, hi_open=True, owner=o)
    valid = ("minimax", *SHAPERS, "pseudo-polynomial", "unshaped")
    if isinstance(include, str) or not all(isinstance(n, str) for n in include):
        raise TypeError(f"{o}: parameter `include` must be a tuple of candidate names out of {valid}; got {include!r}")
    unknown = [n for n in include if n not in valid]
    if unknown or not include:
        raise ValueError(
            f"{o}: parameter `include` must name at least one candidate out of {valid}; got {tuple(include)!r}"
            + (f" ({', '.join(map(repr, unknown))} unknown)" if unknown else "")
        )
    if move_time is None and not any(n in SHAPERS for n in include):
        raise ValueError(
            f"{o}: with `move_time` None the shortest time is the one at which the minimax design reaches the best "
            f"classic shaper's residual, so parameter `include` must name at least one of {SHAPERS}; got "
            f"{tuple(include)!r} (or give `move_time`)"
        )
    t_min = fastest_time(d, v_max, a_max, j_max)
    if move_time is not None:
        check_positive("move_time", move_time, "s", o)
        if float(move_time) < t_min * (1 - 1e-12):
            raise ValueError(
                f"{o}: parameter `move_time` = {float(move_time):g} s is shorter than the limits allow: the shortest "
                f"rest-to-rest move of {d:g} m with v_max = {float(v_max):g}, a_max = {float(a_max):g}"
                + (f", j_max = {float(j_max):g}" if j_max is not None else "")
                + f" takes {t_min:.6g} s"
            )
    return d, t_min


def _check_damping(damping) -> tuple[float, float] | None:
    """`design_move`'s `damping` as `(lo, hi)`, or None; a `ValueError` naming it otherwise."""
    if damping is None:
        return None
    if isinstance(damping, str) and damping == "unknown":
        return UNKNOWN_DAMPING
    msg = (
        "design_move: parameter `damping` must be None, 'unknown' or (lo, hi) with 0 <= lo <= hi < 1 (damping "
        f"ratios); got {damping!r}"
    )
    if isinstance(damping, str | bytes) or not hasattr(damping, "__len__") or len(damping) != 2:
        raise ValueError(msg)
    try:
        lo, hi = (float(x) for x in damping)
    except (TypeError, ValueError):
        raise ValueError(msg) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi < 1.0):
        raise ValueError(msg)
    return lo, hi


def damping_samples(lo: float, hi: float, n: int = N_DAMPING) -> np.ndarray:
    """The damping ratios a range [lo, hi] is judged at: `n` samples including both ends, spaced geometrically when
    lo > 0 (the residual of a lightly damped mode changes with log zeta), evenly from 0; one when lo == hi."""
    if hi == lo:
        return np.array([lo])
    return np.geomspace(lo, hi, n) if lo > 0 else np.linspace(lo, hi, n)


def _damping_axis(axis: ModalAxis, zetas) -> ModalAxis:
    """Each mode of `axis` once per damping ratio of `zetas` (frequency and gain kept), mode by mode: the copies
    of mode i are i * len(zetas) ... (i + 1) * len(zetas) - 1."""
    z = np.asarray(zetas, dtype=float)
    n = z.size
    return ModalAxis(
        np.repeat(np.asarray(axis.frequencies, dtype=float), n),
        np.tile(z, axis.n_modes),
        np.repeat(np.asarray(axis.gains, dtype=float), n),
    )


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


def _shaped(axis, name, distance, T, v_max, a_max, j_max):
    """The classic shaper `name` on the gentlest base that ends at T, or (None, shortest time)."""
    A, tau = shaper_for_axis(name, axis.frequencies, axis.damping_ratios)
    base = trapezoid_move(distance, T - tau[-1], v_max, a_max, j_max) if T > tau[-1] else None
    t_short = fastest_time(distance, v_max, a_max, j_max) + float(tau[-1])
    if base is None:
        return None, t_short
    return shape_move(base, A, tau), t_short


def _minimax_options(axis, T_guess: float, u: float, j_max, fixed_time: bool, smooth: bool = True):
    """The minimax design's options: 6 knots per cycle of the highest mode at a given move time, 12 when the
    shortest time is searched; the spline basis (`smooth`), else acceleration ramps (piecewise-constant jerk) with a
    jerk limit `j_max`, acceleration steps without one."""
    basis = "spline" if smooth else ("steps" if j_max is None else "ramps")
    return _design.default_options(axis.frequencies, T_guess, u, j_max is not None, 6.0 if fixed_time else 12.0, basis)


class _Minimax:
    """The convex design at a move time, with its feasibility (one problem structure per axis size)."""

    def __init__(self, axis, distance, v_max, a_max, j_max, u, ref, opts):
        self.args = (axis, distance, v_max, a_max, j_max, u, ref)
        self.opts = opts

    def problem(self, T):
        axis, distance, v_max, a_max, j_max, u, ref = self.args
        return _design.make_problem(axis, distance, T, v_max, a_max, j_max, u, ref, self.opts)

    def feasible(self, T) -> bool:
        return _design.max_distance(self.problem(T), self.opts) >= 1.0

    def shortest_feasible(self, t_min):
        """The least time at which the spline can move the distance within the limits (bisection)."""
        lo, hi = t_min, t_min * 1.05
        while not self.feasible(hi):
            lo, hi = hi, hi * 1.2
        for _ in range(30):
            if hi - lo <= 1e-4 * hi:
                break
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if self.feasible(mid) else (mid, hi)
        return hi

    def design(self, T):
        return _design.minimax_design(self.problem(T), self.opts)

    def prepare(self, T) -> None:
        """While the program store is on: start compiling, in the background, the programs a design at T runs and
        those `_measure` runs on its command, each traced while the ones before compile (on two cores the LP's
        compilation, the longest, overlaps the others' tracing and compiling). Nothing otherwise."""
        problem = self.problem(T)
        coef = _design.prepare_design(problem, self.opts)
        if coef is None:
            return
        axis, u = self.args[0], self.args[5]
        cmd = _design.design_command(device_array(np.zeros(coef.shape, coef.dtype)), problem.move_time, self.opts)
        for factors in _measure_grids(u):
            prepare_curve(axis, cmd, factors)
        prepare_peaks(cmd)


#: the damping exponent (zeta omega (1 + u) h, times d + 1 for a basis of degree d) beyond which the steps leave a far
#: mode out of their LP: it is damped within one interval, so only the last one excites it. Set when the LP's kernel
#: held e^{-sh} and overflowed there; the kernel is now written without overflow (`design.lp_data_grouped`), so this
#: is a choice (the mode's residual is computed exactly instead), no longer a limit of the LP
_LP_EXPONENT = 600.0


@dataclasses.dataclass(frozen=True)
class _FarModes:
    """How the minimax design treats the modes of an axis at a move time (`_far_modes`).

    - `kept`: indices of the modes the LP weighs; `far`: of the modes far above the finest knot grid's Nyquist
      frequency; `left_out`: those of `far` the LP does not weigh (all of them for the spline basis; for the
      steps, only those whose LP rows cannot be represented), each with its reason;
    - `nyquist_hz`: `KNOT_COUNTS[-1] / (2 T)` [Hz], the Nyquist frequency of the finest grid."""

    kept: tuple[int, ...]
    far: tuple[int, ...]
    left_out: tuple[tuple[int, str], ...]
    nyquist_hz: float


def _sub_axis(axis: ModalAxis, idx) -> ModalAxis:
    """The `ModalAxis` of the modes `idx` of `axis` (frequencies, damping ratios and gains kept)."""
    idx = np.asarray(idx, dtype=int)
    return ModalAxis(
        np.asarray(axis.frequencies)[idx], np.asarray(axis.damping_ratios)[idx], np.asarray(axis.gains)[idx]
    )


def _far_modes(axis: ModalAxis, T: float, u: float, j_max, fixed_time: bool, smooth: bool) -> _FarModes:
    """Split the modes of `axis` for the minimax design at the move time `T` [s] (band ±`u`).

    A mode is *far* when its whole band lies above the Nyquist frequency of the finest knot grid the design has,
    $f_i(1 - u) > N_{max}/(2T)$, $N_{max}$ = `KNOT_COUNTS[-1]`: no basis of the design resolves it (a 1 MHz or a
    2 kHz mode in a 0.8 s move: 160 Hz), and it does not set the knots (the other modes do).

    - spline basis (`smooth`): the acceleration and its jerk are continuous, so a far mode sees only the spline's
      smoothed ends: its residual falls like $(\\omega h)^{-3}$ of the unshaped move's (1e-15 at 1 MHz beside
      7.3 Hz), so it would only weigh on the LP with rows near zero. Every far mode is left out of the LP;
      `design_move` computes its residual exactly for the command and says so.
    - steps (or any basis whose acceleration jumps): each jump excites a far mode as the trapezoid's do (the last
      one is not damped away before the end), so the LP keeps it unless it is damped within one interval
      ($\\zeta\\omega(1 + u)\\,h$ above `_LP_EXPONENT`: only the last interval excites it); those are left out,
      with their exact residual.
    """
    f = np.asarray(axis.frequencies, dtype=float)
    z = np.asarray(axis.damping_ratios, dtype=float)
    nyq = _design.KNOT_COUNTS[-1] / (2.0 * T)
    far = tuple(int(i) for i in np.flatnonzero(f * (1.0 - u) > nyq))
    resolved = [i for i in range(f.size) if i not in far]
    if smooth:
        why = (
            f"its band {{lo:.4g}}-{{hi:.4g}} Hz lies above {nyq:.4g} Hz, the Nyquist frequency of the finest knot grid"
        )
        left = tuple((i, why.format(lo=f[i] * (1 - u), hi=f[i] * (1 + u))) for i in far)
        return _FarModes(tuple(resolved), far, left, nyq)
    # the steps' intervals: those the resolved modes set (the least count without them)
    sub = _sub_axis(axis, resolved) if resolved else axis
    opts = _minimax_options(sub, T, u, j_max, fixed_time, smooth)
    h = T / opts.n_knots
    power = _design._DEGREE[opts.basis] + 1.0  # the kernel's phi1 power (`design.lp_data_grouped`)
    expo = power * z * 2.0 * np.pi * f * (1.0 + u) * h
    left = tuple(
        (
            i,
            f"its damping time 1/(zeta omega) = {1.0 / (z[i] * 2 * np.pi * f[i]):.3g} s is far below one of the "
            f"{opts.n_knots} steps ({h:.3g} s): only the last step excites it",
        )
        for i in far
        if expo[i] > _LP_EXPONENT
    )
    out = {i for i, _ in left}
    return _FarModes(tuple(i for i in range(f.size) if i not in out), far, left, nyq)


def _knots_axis(axis: ModalAxis, far: _FarModes) -> ModalAxis:
    """The modes that set the minimax design's discretisation (knots, grid): those the knots resolve, when there are
    any (a far mode the steps keep in their LP does not force the finest grid, which resolves it no better)."""
    resolved = [i for i in range(axis.n_modes) if i not in far.far]
    return _sub_axis(axis, resolved) if far.far and resolved else axis


def _refuse_all_far(axis: ModalAxis, T: float, u: float, far: _FarModes, per: int = 1) -> None:
    """The `ValueError` of `design_move` when the minimax LP would weigh no mode of `axis`."""
    if far.kept:
        return
    freqs = ", ".join(f"{float(x):.6g}" for x in np.asarray(axis.frequencies)[::per])
    raise ValueError(
        f"design_move: every mode of parameter `axis` ({freqs} Hz) lies far above what the minimax design resolves "
        f"in a {T:.4g} s move (band ±{u:g}; Nyquist frequency of its finest grid {far.nyquist_hz:.4g} Hz): "
        + "; ".join(f"{_mode_label(axis, i, per)}: {why}" for i, why in far.left_out)
        + ". Leave 'minimax' out of `include` (the classic shapers still apply), give a longer `move_time`, or "
        "check the frequencies' unit (Hz)"
    )


def _far_note(axis: ModalAxis, cmd, ref, u: float, far: _FarModes, per: int = 1) -> str:
    """The minimax row's words on the modes left out of its LP: which, why, and the worst residual the command leaves
    them over their band, computed exactly (closed form) on the full axis, in % of the unshaped move's."""
    if not far.left_out:
        return ""
    band = _measure_grids(u)[0]
    ratio = np.asarray(residual_curve(axis, cmd, band)) / np.asarray(ref)[:, None]
    f = np.asarray(axis.frequencies, dtype=float)
    parts = [
        f"{_mode_label(axis, i, per)} ({f[i]:.6g} Hz; {why}): {100.0 * float(np.max(ratio[i])):.2g} % (exact)"
        for i, why in far.left_out
    ]
    return "left out of the LP, their residual computed for this command: " + "; ".join(parts)


@blas_limited
def design_move(
    axis: ModalAxis,
    distance,
    move_time=None,
    *,
    v_max,
    a_max,
    j_max=None,
    uncertainty=0.2,
    include=("minimax", *SHAPERS, "pseudo-polynomial", "unshaped"),
    progress: bool = False,
    smooth: bool | str = "auto",
    certify_rtol: float | None = None,
    damping=None,
) -> MovePlan:
    """Design the move of `distance` [m] on `axis` every way jaxbelt knows, under the same limits and move time,
    and rank them (see the module docstring).

    - `axis`: a `ModalAxis` (`jb.ModalAxis([f1, f2], [z1, z2])`, `jb.identify_axis(t, y, 2)`,
      `jb.BeltPlatform().to_axis()`);
    - `distance` [m] (or rad: the units of the axis' command), finite and non-zero;
    - `move_time` [s]: every candidate ends at this time (it must be at least the time-optimal move's, which an
      error states); `None`: the shortest time at which the minimax design reaches the best classic shaper's
      worst residual (each shaper at its own shortest time);
    - `v_max` [m/s], `a_max` [m/s²], `j_max` [m/s³] (optional): limits every candidate respects;
    - `uncertainty` u in [0, 0.9): the band $f_i(1 \\pm u)$ every residual is judged on (damping ratio kept);
    - `include`: which candidates to build;
    - `damping`: None (default): every mode at its own damping ratio. `(lo, hi)` (damping ratios,
      0 <= lo <= hi < 1): every mode's damping ratio may be anywhere in [lo, hi]; the axis' own one, which must
      lie in it, is then used only to design the classic shapers and the pseudo-polynomials. Each mode is judged
      at `N_DAMPING` = 5 damping samples spanning the range (both ends; geometric spacing when lo > 0,
      `damping_samples`), each against the unshaped move's worst residual at that damping, so `worst_percent` is
      the worst over band × damping range and the minimax design minimises it. `"unknown"`: the range
      (0.01, 0.1) (`UNKNOWN_DAMPING`), and the classic shapers and pseudo-polynomials are designed at damping
      ratio 0.1 for every mode, as Klipper does for an axis whose damping is not measured (its `damping_ratio`
      default). A mode's 5 % band is then where the residual stays within 5 % at every damping sample;
      `plan.damping` records the range, `plan.axis` stays the user's axis. The minimax LP weighs 5 copies of each
      mode: about 5 times its rows (a 1-mode design costs about what a 5-mode one does, compile included);
    - `smooth`: the minimax design's command space. True: a continuous acceleration (cubic B-spline, continuous
      jerk). False: an acceleration that is constant on each of N equal intervals and jumps between them, as a
      shaped trapezoid's does; its limits are exact rather than a little conservative, so it can come closer to
      the least residual any command can leave (a 40 Hz, damping 0.003 axis at ZV's own time and peaks: 2.3 %
      against 32 % for the smooth design and 22 % for ZV). With `j_max` [m/s³], False gives an acceleration that
      is continuous and linear on each of N equal intervals (piecewise-constant jerk that jumps between them, as a
      shaped S-curve's does): |a| and |jerk| limits exact, |v| guaranteed everywhere through the velocity's
      B-spline coefficients (conservative by at most j_max h²/8 [m/s], h = move time / N).
      `"auto"` (default): the smooth design, and, at a given `move_time`, also the design with jumps (a second
      row, `"minimax (jumps)"`, its note saying why) where the smooth one is not feasible or not converged, or
      where a classic shaper of the table leaves no more than it: then the table always holds a minimax design
      whose command space includes the shaped moves (measured: at most 0.81x each of Klipper's six shapers at
      their own time and peaks). The smooth design costs that margin: on lightly damped high modes it can leave
      more than ZV (1.45x on a 40 Hz, damping 0.003 axis at ZV's time and peaks); its exported samples are
      corrected for a drive that interpolates linearly (see `MovePlan.samples`), those of a design with jumps are
      exact samples whose jumps such a drive smooths over one sample. `plan.minimax` is the design of the better
      of the two rows.

    The minimax row's note states its certificate: the LP's own gap (its command is the least residual of its
    command space: splines of its knots, or steps or ramps of its intervals) and, for a design with steps (no jerk
    limit; `smooth=False`, or the row `smooth="auto"` adds), a rigorous lower bound on the least worst residual
    *any* command within the same limits, distance and time can leave over the band (`jaxbelt.shaping.certify`;
    also `plan.continuous_bound`): the design is then proved within (worst - bound) of the best any command can
    do, smooth or not, classic shapers included. The smooth row's note states the same bound where the design with
    jumps is made beside it (how far the smooth command is from the best any command can do, in percentage points
    of the unshaped move's residual), or, where its worst is below `CERTIFY_ATOL`, that it is within that of the
    best (a residual is never below 0); otherwise it claims nothing beyond its own command space (the spline's
    own multipliers bound next to nothing; `certify_rtol` makes the bound).

    `certify_rtol` (with `smooth=False` or `"auto"`, and `j_max=None`; default None: no refinement; with `"auto"`
    the design with jumps is then always made beside the smooth one, at the smooth design's time where `move_time`
    is None, its note saying why): the design with jumps is refined until it is
    certified within this fraction of its own worst residual, (worst - bound) <= certify_rtol * worst, or within
    `CERTIFY_ATOL` = 0.01 % of the unshaped move's residual, absolute, whichever is larger (near a zero optimum the
    bound is 0 and no relative tolerance can be proved; the note says which one was met): first the modulus
    cuts and the frequency grid are refined (16 cuts let a residual exceed the LP's value by 2 %), then the number
    of steps doubles (up to 1024, `CERTIFY_MAX_STEPS`); the best bound met is kept. The row's note gives both
    numbers, and says so when the limit is reached first. Each refinement costs one more compiled LP (about 10 s
    for a 5.5 Hz mode within 1 %; a minute or more for several hundred steps).

    Returns a `MovePlan`: `plan.table` (ranked), `plan.best` (the recommendation: the least worst residual among
    the candidates that are feasible, converged and within the limits; a design the solver did not converge on
    is reported in the table, never recommended), `plan.to_csv(path, rate_hz)`, `plan.plot()`.
    """
    d, t_min = _check_inputs(axis, distance, move_time, v_max, a_max, j_max, uncertainty, include)
    auto = isinstance(smooth, str) and smooth == "auto"
    if not (auto or isinstance(smooth, bool | np.bool_)):
        raise ValueError(f"design_move: parameter `smooth` must be True, False or 'auto'; got {smooth!r}")
    if not isinstance(progress, bool | np.bool_):
        raise TypeError(f"design_move: parameter `progress` must be True or False; got {progress!r}")
    smooth_arg = smooth
    smooth = auto or bool(smooth)  # the first (or only) minimax design's basis: the spline unless smooth=False
    if certify_rtol is not None:
        if smooth and not auto:
            raise ValueError(
                "design_move: `certify_rtol` needs `smooth=False` or 'auto' (the continuous certificate bounds the "
                "steps design, which 'auto' then adds beside the smooth one; the spline's multipliers bound next to "
                f"nothing); got certify_rtol={certify_rtol!r} with smooth={smooth_arg!r}"
            )
        if isinstance(certify_rtol, bool) or not isinstance(certify_rtol, int | float | np.floating | np.integer):
            raise ValueError(f"design_move: parameter `certify_rtol` must be a number in (0, 1); got {certify_rtol!r}")
        if not (math.isfinite(float(certify_rtol)) and 0.0 < float(certify_rtol) < 1.0):
            raise ValueError(f"design_move: parameter `certify_rtol` must lie in (0, 1); got {certify_rtol!r}")
        certify_rtol = float(certify_rtol)
        if j_max is not None:
            raise ValueError(
                "design_move: `certify_rtol` needs `j_max=None` (the continuous certificate bounds the steps design, "
                f"whose jerk is unbounded; with a jerk limit the design has ramps); got certify_rtol={certify_rtol!r} "
                f"with j_max={j_max!r}"
            )
    damp = _check_damping(damping)
    u = float(uncertainty)
    v_max, a_max = float(v_max), float(a_max)
    j_max = None if j_max is None else float(j_max)
    limits = (v_max, a_max, j_max)
    t_fixed = None if move_time is None else float(move_time)
    clearly = t_fixed is not None and t_fixed >= _SURELY_FEASIBLE * t_min
    # `nominal`: the damping the classic shapers and the pseudo-polynomials are designed at; `user`: the axis the
    # residuals are judged on (with a damping range, each mode once per damping sample, `per` copies each)
    user = axis
    nominal, per = axis, 1
    if damp is not None and not isinstance(damping, str):
        zs = np.asarray(axis.damping_ratios, dtype=float)
        if np.any(zs < damp[0]) or np.any(zs > damp[1]):
            raise ValueError(
                f"design_move: parameter `damping` {damp} must contain the axis' own damping ratios "
                f"{np.round(zs, 6).tolist()} (the classic shapers are designed at them): widen the range, or give "
                "damping='unknown' (0.01-0.1, the shapers at 0.1)"
            )
    if damp is not None:
        if isinstance(damping, str):  # "unknown": Klipper's practice
            nominal = ModalAxis(axis.frequencies, np.full(axis.n_modes, UNKNOWN_SHAPER_DAMPING), axis.gains)
        zetas = damping_samples(*damp)
        per = zetas.size
        axis = _damping_axis(axis, zetas)
    far = None  # the modes the minimax LP leaves out (`_far_modes`): at a given time, known (and refused) at once
    if "minimax" in include and t_fixed is not None:
        far = _far_modes(axis, t_fixed, u, j_max, True, smooth)
        _refuse_all_far(axis, t_fixed, u, far, per)
    if "minimax" in include and t_fixed is not None and clearly and far is not None:
        # the minimax design's programs start compiling now, in the background, while the reference and the other
        # candidates are computed (their types only: a stand-in reference of the right shape)
        stand_in = np.ones(axis.n_modes)
        _minimax_solver(axis, far, d, v_max, a_max, j_max, u, stand_in, t_fixed, True, smooth).prepare(t_fixed)
    ref_cmd = fastest_move(d, v_max, a_max, j_max)
    band = _measure_grids(u)[0]
    ref = np.max(np.asarray(residual_curve(axis, ref_cmd, band)), axis=1)
    rows = []
    # --- classic shapers
    shaped = {}
    for name in SHAPERS:
        if name not in include:
            continue
        try:
            tau_end = float(shaper_for_axis(name, nominal.frequencies, nominal.damping_ratios)[1][-1])
        except ShaperRangeError as e:  # a firmware fit asked for beyond its damping range: listed, not built
            shaped[name] = (None, math.nan if move_time is None else float(move_time), e.note)
            continue
        if move_time is None:
            T_s = fastest_time(d, v_max, a_max, j_max) + tau_end
            cmd, _ = _shaped(nominal, name, d, T_s * (1 + 1e-12), v_max, a_max, j_max)
            shaped[name] = (cmd, T_s, "")
        else:
            cmd, t_short = _shaped(nominal, name, d, float(move_time), v_max, a_max, j_max)
            shaped[name] = (cmd, float(move_time) if cmd is not None else t_short, "")
    for name, (cmd, T_s, why) in shaped.items():
        note = why or ("" if cmd is not None else f"infeasible: needs a move time >= {T_s:.4g} s")
        rows.append(_row(name, axis, cmd, T_s, ref, u, limits, note=note, ok=cmd is not None, per=per))
    classic = [r for r in rows if r.ok]
    target = min((r.worst_percent for r in classic), default=math.nan)
    # --- the minimax design
    mm = None
    bound = math.nan  # the continuous certificate's lower bound (a fraction of the references)
    if "minimax" in include:
        T_guess = (
            float(move_time) if move_time is not None else (min(r.move_time for r in classic) if classic else 2 * t_min)
        )
        if far is None:
            far = _far_modes(axis, T_guess, u, j_max, False, smooth)
            _refuse_all_far(axis, T_guess, u, far, per)
        # modes far above the knots' reach are left out of the LP (`_far_modes`); every row is measured on `axis`
        solver = _minimax_solver(axis, far, d, v_max, a_max, j_max, u, ref, T_guess, move_time is not None, smooth)
        if move_time is not None:
            T = float(move_time)
            mm, t_f = _design_at(solver, T, t_min, clearly)
            if mm is None:
                note = f"infeasible for the {'smooth' if smooth else 'steps'} design: needs a move time >= {t_f:.4g} s"
                rows.append(_row("minimax", axis, None, T, ref, u, limits, ok=False, note=note, per=per))
        else:
            mm = _shortest_minimax(solver, t_min, target, progress)
        if mm is not None:
            row, mm, bound = _minimax_row("minimax", solver, mm, axis, ref, u, limits, far, per, certify_rtol, progress)
            rows.append(row)
        primary = next((r for r in rows if r.name == "minimax"), None)
        # `smooth="auto"`: the design with jumps beside the smooth one, at the given time (or, to certify, the
        # smooth design's)
        T_j = float(move_time) if move_time is not None else (float(mm.command.duration) if mm is not None else None)
        why = _jumps_reason(primary, classic) if move_time is not None else ""
        if auto and T_j is not None and (why or certify_rtol is not None):
            why = (
                why or "added: `certify_rtol` asks for the continuous certificate, which the design with jumps carries"
            )
            clearly_j = T_j >= _SURELY_FEASIBLE * t_min
            jrow, jmm, jbound = _jumps_minimax(axis, d, T_j, v_max, a_max, j_max, u, ref, limits, per, t_min,
                                                clearly_j, why, certify_rtol, progress)  # fmt: skip
            rows.append(jrow)
            if jmm is not None and jrow.ok:
                bound = jbound
                if primary is None or not primary.ok or jrow.worst_percent < primary.worst_percent:
                    mm = jmm  # `plan.minimax`: the design of the better minimax row
        if primary is not None and primary.ok and smooth:  # the smooth row's place against any command
            k = rows.index(primary)
            rows[k] = dataclasses.replace(primary, note=primary.note + _smooth_certificate(primary, bound))
    # --- Incerti's pseudo-polynomial commands
    T_common = (
        float(move_time)
        if move_time is not None
        else (float(mm.command.duration) if mm is not None else min((r.move_time for r in classic), default=2 * t_min))
    )
    if "pseudo-polynomial" in include:
        # designed at the nominal damping: the references there (the expanded axis' ones where there is no range)
        ref_nominal = ref if per == 1 else np.max(np.asarray(residual_curve(nominal, ref_cmd, band)), axis=1)
        rows += _pseudo_rows(
            nominal, ref_nominal, axis, ref, per, d, T_common, v_max, a_max, j_max, u, limits, progress
        )
    if "unshaped" in include:
        if move_time is None:
            T_ref = float(ref_cmd.duration)
            rows.append(_row("unshaped (time-optimal)", axis, ref_cmd, T_ref, ref, u, limits, per=per))
        else:
            base = trapezoid_move(d, T_common, v_max, a_max, j_max)
            rows.append(_row("unshaped", axis, base, T_common, ref, u, limits, per=per))
    ranked = sorted(rows, key=lambda r: (not r.ok, r.worst_percent if math.isfinite(r.worst_percent) else math.inf))
    best = next((r for r in ranked if r.ok), None)
    if best is None:
        warnings.warn(
            "design_move: no candidate is feasible, converged and within the limits; nothing is recommended (the "
            "table's notes say why)",
            RuntimeWarning,
            stacklevel=2,
        )
    return MovePlan(
        axis=user,
        distance=d,
        move_time=T_common,
        v_max=v_max,
        a_max=a_max,
        j_max=j_max,
        uncertainty=u,
        reference_m=ref if per == 1 else ref.reshape(user.n_modes, per).max(axis=1),
        table=tuple(ranked),
        best=best,
        minimax=mm,
        continuous_bound=bound,
        damping=damp,
        measure_axis=None if damp is None else axis,
        measure_reference_m=None if damp is None else ref,
    )


def _minimax_solver(axis, far: _FarModes, d, v_max, a_max, j_max, u, ref, T, fixed_time: bool, smooth: bool):
    """The minimax design's `_Minimax` on `axis` at (about) move time `T` [s]: the LP weighs the modes `far` keeps
    (`ref`, the references of every mode of `axis`, taken for those), its knots set by the modes they resolve."""
    lp_axis = _sub_axis(axis, far.kept) if far.left_out else axis
    kept = np.asarray(far.kept, dtype=int)
    opts = _minimax_options(_knots_axis(axis, far), T, u, j_max, fixed_time=fixed_time, smooth=smooth)
    return _Minimax(lp_axis, d, v_max, a_max, j_max, u, np.asarray(ref)[kept], opts)


def _design_at(solver: _Minimax, T: float, t_min: float, clearly: bool):
    """`solver`'s design at move time `T` [s], and NaN; or None and the shortest move time its basis can make
    (bisection) where it cannot make this one. A smooth (B-spline) move needs a little more time than the
    time-optimal one (`t_min`): well above that (`clearly`), the feasibility LP (its program costs a compile) is
    skipped unless the design then fails to converge."""
    mm = solver.design(T) if clearly else None
    if (mm is None or not mm.converged) and not solver.feasible(T):
        return None, solver.shortest_feasible(t_min)
    return (solver.design(T) if mm is None else mm), math.nan


#: the name of the row `design_move` adds, with `smooth="auto"`, for the minimax design whose acceleration may jump
JUMPS = "minimax (jumps)"


def _minimax_row(name, solver, mm, axis, ref, u, limits, far, per, certify_rtol, progress):
    """The table row of a solved minimax design `mm` (its note states the certificate: the LP's gap and, for the
    steps basis, the continuous bound, refined to `certify_rtol` if given), and the (possibly refined) design and
    the continuous bound (NaN but for the steps basis): `(row, mm, bound)`."""
    bound = math.nan
    note = f"certified gap {float(mm.gap):.1e}"
    if float(mm.gap) > _design.CERTIFIED_GAP:  # accepted by the absolute gap (an optimum near zero)
        note = f"certified within {100 * float(mm.worst - mm.lower_bound):.1e} % of the optimum"
    ok = mm.converged
    if not ok:
        lp = mm.lp
        note = (
            f"not converged (gap {float(mm.gap):.1e}; the LP's interior-point solver stopped after "
            f"{int(np.asarray(lp.iterations))} iterations, primal residual {float(np.asarray(lp.primal_residual)):.1e}, "
            f"dual {float(np.asarray(lp.dual_residual)):.1e}): try a longer `move_time` or `smooth=False`"
        )
    elif mm.options.basis == "steps":  # the spline's multipliers bound next to nothing: steps only
        bound = continuous_lower_bound(mm)
        if certify_rtol is not None:
            mm, bound, note = _certify(solver, mm, bound, certify_rtol, progress)
        note += f"; any command leaves >= {100 * bound:.3g} % (continuous bound)"
    T_mm = float(mm.command.duration)
    row = _row(name, axis, mm.command, T_mm, ref, u, limits, note=note, ok=ok, per=per)
    if far.left_out:  # the left-out modes' residual, exact for this command (the program `_row` ran)
        row = dataclasses.replace(row, note=row.note + "; " + _far_note(axis, row.command, ref, u, far, per))
    return row, mm, bound


def _jumps_reason(primary, classic) -> str:
    """Why `smooth="auto"` adds the design with jumps ("" when it does not): the smooth minimax row is missing, not
    feasible or not converged, or a classic shaper of the table leaves no more than it."""
    if primary is None or not primary.ok or not math.isfinite(primary.worst_percent):
        return "added: the smooth design is not feasible or not converged at this time"
    beaten = [r for r in classic if r.worst_percent <= primary.worst_percent]
    if not beaten:
        return ""
    r = min(beaten, key=lambda r: r.worst_percent)
    return f"added: {r.name} leaves {r.worst_percent:.3g} % <= the smooth design's {primary.worst_percent:.3g} %"


def _smooth_certificate(row, bound: float) -> str:
    """What the smooth row's note says of its place against any command: the continuous bound where the design with
    jumps gave one, or, where its worst is below `CERTIFY_ATOL`, that it is within that of the least any command can
    leave (a residual is never below 0); "" otherwise (no bound is computed: `certify_rtol` makes one)."""
    worst = row.worst_percent / 100
    if math.isfinite(bound):
        return (
            f"; any command leaves >= {100 * bound:.3g} % (continuous bound, from the design with jumps): this one "
            f"at most {100 * max(worst - bound, 0.0):.2g} percentage points above the least any command can leave"
        )
    if worst <= CERTIFY_ATOL:
        return (
            f"; within {100 * worst:.2g} percentage points of the least any command can leave (its worst is below CERTIFY_ATOL = "
            f"{100 * CERTIFY_ATOL:g} %)"
        )
    return ""


def _jumps_minimax(axis, d, T, v_max, a_max, j_max, u, ref, limits, per, t_min, clearly, why, certify_rtol, progress):
    """The minimax design at move time `T` whose acceleration may jump (steps; with `j_max`, ramps whose jerk may
    jump), as `smooth=False` designs it: `(row, design or None, continuous bound)`. Its command space holds what a
    classic shaper makes of the time-optimal move (a shaped trapezoid or S-curve), so at equal time and limits it
    leaves no more than the shapers (measured: `benchmarks/shaping_every_shaper.py`)."""
    if progress:
        print(f"design_move: {why}; designing the minimax command with jumps ...", flush=True)
    far = _far_modes(axis, T, u, j_max, True, False)  # keeps every mode the spline's LP keeps (`_refuse_all_far`)
    solver = _minimax_solver(axis, far, d, v_max, a_max, j_max, u, ref, T, True, False)
    mm, t_f = _design_at(solver, T, t_min, clearly)
    if mm is None:
        note = f"{why}; infeasible with {solver.opts.n_knots} equal steps: needs a move time >= {t_f:.4g} s"
        return _row(JUMPS, axis, None, T, ref, u, limits, ok=False, note=note, per=per), None, math.nan
    row, mm, bound = _minimax_row(JUMPS, solver, mm, axis, ref, u, limits, far, per, certify_rtol, progress)
    return dataclasses.replace(row, note=why + "; " + row.note), mm, bound


def _pseudo_rows(axis, ref_design, measure_axis, ref, per, d, T, v_max, a_max, j_max, u, limits, progress):
    """Incerti's commands designed on `axis` (references `ref_design`), measured on `measure_axis` (`ref`; with a
    damping range, `per` damping copies of each mode of `axis`; the design on the expanded axis would cost a
    program per size for little: the exponents are few)."""
    try:
        from .pseudo import pseudo_polynomial_designs
    except ImportError:  # pragma: no cover - the module is part of the package
        return []
    out = []
    # a pseudo-polynomial is smooth: its exponents are optimised on the modes within the knots' reach (as the smooth
    # minimax design's), the far ones measured with the others (their quadrature needs ~2.5 omega T nodes: a 1 MHz
    # mode would cap it, and slow it, for nothing)
    far = _far_modes(axis, T, u, j_max, True, True)
    kept = np.asarray(far.kept if far.kept else range(axis.n_modes), dtype=int)
    designs = pseudo_polynomial_designs(
        _sub_axis(axis, kept) if far.kept and far.far else axis,
        d,
        T,
        v_max=v_max,
        a_max=a_max,
        j_max=j_max,
        uncertainty=u,
        reference=jnp.asarray(ref_design[kept]),
        progress=progress,
    )
    for name, pd in designs.items():
        ok = bool(pd.converged) and bool(pd.within_limits)
        note = "" if ok else pd.message
        if far.kept and far.far:
            note = "; ".join(
                [
                    *([note] if note else []),
                    f"exponents optimised without mode(s) {', '.join(str(i + 1) for i in far.far)}",
                ]
            )
        out.append(_row(name, measure_axis, pd.command, T, ref, u, limits, note=note, ok=ok, per=per))
    return out


#: the most acceleration steps `design_move(..., certify_rtol=...)` refines to
CERTIFY_MAX_STEPS = 1024
#: the absolute floor of `certify_rtol`'s proof (a fraction of the references: 0.01 % of the unshaped move's
#: residual): where the optimum is near zero the bound is 0 and no relative tolerance can be proved, but a design
#: within this of the least any command can leave needs no refining
CERTIFY_ATOL = 1e-4


def _certify_options(opts, rtol: float):
    """The discretisation a certificate within `rtol` needs besides the steps: the modulus |r| <= t is imposed by
    P cuts (a P-gon that lets |r| exceed t by 1/cos(pi/P) - 1: 2 % for the default 16), so P grows until that is
    below rtol/4, and the exchange refines the frequency grid until the fine grid is within rtol/4 of the LP's."""
    P = opts.n_angles
    while 1.0 / math.cos(math.pi / P) - 1.0 > rtol / 4:
        P *= 2
    return opts._replace(
        n_angles=P,
        exchange_tol=min(opts.exchange_tol, rtol / 4),
        n_rounds=max(opts.n_rounds, 8),
        n_extra=max(opts.n_extra, 24),
    )


def _certify(solver: _Minimax, mm, bound: float, rtol: float, progress: bool):
    """Refine the steps design until (worst - bound) <= max(rtol * worst, `CERTIFY_ATOL`) (the worst on the fine
    grid): first the cuts
    and the frequency grid (`_certify_options`), then the number of steps, doubled up to `CERTIFY_MAX_STEPS`. The
    least-residual design met on the way, the best bound so far, and the row's note."""
    T = float(mm.command.duration)

    def within(d, b):
        return float(d.fine_worst) - b <= max(rtol * float(d.fine_worst), CERTIFY_ATOL)

    opts = _certify_options(mm.options, rtol)
    tried = mm.options.n_knots  # the most steps designed so far
    stopped = ""  # why the refinement stopped short, where a finer design did not converge
    while not within(mm, bound) and opts.n_knots <= CERTIFY_MAX_STEPS:
        if progress:
            print(f"design_move: certifying with {opts.n_knots} steps, {opts.n_angles} cuts ...", flush=True)
        finer = _Minimax(*solver.args, opts).design(T)
        if not finer.converged:
            stopped = f"the design with {opts.n_knots} steps did not converge"
            break
        tried = opts.n_knots
        bound = max(bound, continuous_lower_bound(finer))
        if float(finer.fine_worst) <= float(mm.fine_worst):
            mm = finer
        opts = opts._replace(n_knots=2 * opts.n_knots)
    stopped = stopped or f"{tried} steps, the most within CERTIFY_MAX_STEPS = {CERTIFY_MAX_STEPS}"
    gap = float(mm.fine_worst) - bound
    rel = gap / float(mm.fine_worst)
    how = f"{100 * rel:.2g} % (relative)"
    if rel > rtol and gap <= CERTIFY_ATOL:  # met by the absolute floor (an optimum near zero)
        how = f"{100 * gap:.2g} % of the unshaped move's residual (absolute, at most CERTIFY_ATOL = {100 * CERTIFY_ATOL:g} %)"
    note = (
        f"certified gap {float(mm.gap):.1e}; {mm.options.n_knots} steps, {mm.options.n_angles} cuts: within "
        f"{how} of the least any command can leave"
        + ("" if within(mm, bound) else f" (not within certify_rtol: {stopped})")
    )
    return mm, bound, note


def _shortest_minimax(solver: _Minimax, t_min, target, progress):
    """The minimax design at the least move time whose worst residual (fine grid) reaches `target` (%):
    bisection between the least feasible time and a time where the target is met."""
    if not math.isfinite(target):
        return None
    lo = solver.shortest_feasible(t_min)
    d_lo = solver.design(lo)
    if 100 * float(d_lo.fine_worst) <= target:
        return d_lo
    hi = lo * 1.25
    d_hi = solver.design(hi)
    while 100 * float(d_hi.fine_worst) > target:
        lo, hi = hi, hi * 1.25
        if hi > 20 * t_min:
            return d_hi
        d_hi = solver.design(hi)
    for _ in range(12):
        if hi - lo <= 2e-3 * hi:
            break
        mid = 0.5 * (lo + hi)
        d_mid = solver.design(mid)
        if 100 * float(d_mid.fine_worst) <= target:
            hi, d_hi = mid, d_mid
        else:
            lo = mid
    return d_hi
