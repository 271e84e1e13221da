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

**Damping ranges** (`damping`): None (default): every mode at its own damping ratio. `(lo, hi)` (damping ratios, 0
<= lo <= hi < 1): every mode's damping ratio may be anywhere in [lo, hi]; the axis' own one, which must lie in it,
is then used only to design the classic shapers and the pseudo-polynomials. Each mode is judged at `N_DAMPING` = 5
damping samples spanning the range (both ends; geometric spacing when lo > 0, `damping_samples`), each against the
unshaped move's worst residual at that damping, so `worst_percent` is the worst over band × damping range and the
minimax design minimises it. `"unknown"`: the range (0.01, 0.1) (`UNKNOWN_DAMPING`), and the classic shapers and
pseudo-polynomials are designed at damping ratio 0.1 for every mode, as Klipper does for an axis whose damping is
not measured (its `damping_ratio` default). A mode's 5 % band is then where the residual stays within 5 % at every
damping sample; `plan.damping` records the range, `plan.axis` stays the user's axis. The minimax LP weighs 5 copies
of each mode: about 5 times its rows (a 1-mode design costs about what a 5-mode one does, compile included).

**Execution and travel** (`rate_hz`, `interpolation`, `x_min`, `x_max`): `rate_hz` [Hz] (default 1000, as the CLI's
export; at most `MAX_RATE_HZ`) and `interpolation` (`"linear"`): how the user's drive executes the command, position
setpoints at `rate_hz`, linear between them (what `MovePlan.to_csv` writes). Every residual of the table, of
`MovePlan.curves` and of the figure is that of the command *as executed so*: of the very setpoints `to_csv` writes at
that rate (`jaxbelt.shaping.moves.drive_positions`), so an exact replay of the CSV finds the stated residual (to 1e-6,
tests/test_shaping_space.py). It differs from the command's own, continuous residual: linear steps scale a mode's
excitation by about $\\mathrm{sinc}^2(\\omega h/2) \\approx 1 - (\\omega h)^2/12$ (h = 1 / `rate_hz`; 1.2 % for a 60 Hz
mode at 1 kHz), which a minimax design's cancellation can make a large part of its own. The minimax rows are chosen on
the same residual (`jaxbelt.shaping.hull`); their certificates (below) concern the command itself, continuous. `x_min`,
`x_max` [m, positions from the start] (optional): the axis' travel. A candidate whose positions, as executed, leave it
is marked not ok; any candidate that leaves the segment between its start and its end by more than `EXCURSION_RTOL`
(1 %) of the distance is noted so (a long move's design may back off behind its start).

**The drive's resolution** (`resolution` [m], optional): a drive rounds every setpoint to its position step q (a
motor step or an encoder count), and that rounding leaves a residual of its own, whatever the command:
`jaxbelt.shaping.hull.resolution_floor` states its RMS per mode, the rounding errors modelled as independent and
uniform in ±q/2 (simulated rounding of ZV moves from random start positions leaves 0.55-0.87 of it,
tests/test_resolution.py). A row whose every mode lies below that floor is marked `at_resolution` and its note says
so: its residual cannot be told from the drive's own, so it does not decide the ranking. Such rows rank first, by
their peaks (|a|, then |jerk|, then |v|), before the rows above the floor, which rank by their worst residual. On a
48 + 62 Hz axis at ZV's time and peaks, a 0.0125 mm step puts the floor at 4.9 µm: the minimax design (0.5 µm) lies
below it, ZV (14 µm) above.

**The minimax design's command space** (`smooth`): True: a continuous acceleration (cubic B-spline, continuous
jerk). False: an acceleration that is constant on each of N equal intervals and jumps between them, as a shaped
trapezoid's does; its limits are exact rather than a little conservative, so it can come closer to the least
residual any command can leave (a 40 Hz, damping 0.003 axis at ZV's own time and peaks: 2.3 % against 32 % for the
smooth design and 22 % for ZV). With `j_max` [m/s³], False gives an acceleration that is continuous and linear on
each of N equal intervals (piecewise-constant jerk that jumps between them, as a shaped S-curve's does): |a| and
|jerk| limits exact, |v| guaranteed everywhere through the velocity's B-spline coefficients (conservative by at most
j_max h²/8 [m/s], h = move time / N). `"auto"` (default): the smooth design, and, at a given `move_time`, also the
design with jumps (a second row, `"minimax (jumps)"`, its note saying why) where the smooth one is not feasible or
not converged, or where a classic shaper of the table leaves no more than it: then the table always holds a minimax
design whose command space includes the shaped moves (measured: at most 0.81x each of Klipper's six shapers at their
own time and peaks). The smooth design costs that margin: on lightly damped high modes it can leave more than ZV
(1.45x on a 40 Hz, damping 0.003 axis at ZV's time and peaks); its exported samples are corrected for a drive that
interpolates linearly (see `MovePlan.samples`), those of a design with jumps are exact samples whose jumps such a
drive smooths over one sample. `plan.minimax` is the design of the better of the two rows. With `"auto"` or False,
the command space holds every candidate: each minimax row is the least worst blend (`jaxbelt.shaping.hull`: $\\sum_m
w_m x_m(t)$, $w \\ge 0$, $\\sum w = 1$, within the same limits) of its design, the design with jumps where the table
has it, every classic shaped move buildable at its time and the unshaped move, built whatever `include` shows and
judged as executed: so at any classic shaper's own time and peaks the minimax row leaves no more than that shaper,
by construction (its note names the blend). `smooth=True` keeps the continuous acceleration as a constraint (no
blend with jumps), at its cost: the smooth row may leave more than a shaper, and its note then says so.

**Certificates** (`certify_rtol`). The minimax row's note states its certificate: the LP's own gap (its command is
the least residual of its command space: splines of its knots, or steps or ramps of its intervals) and, for a design
with steps (no jerk limit; `smooth=False`, or the row `smooth="auto"` adds), a rigorous lower bound on the least
worst residual *any* command within the same limits, distance and time can leave over the band
(`jaxbelt.shaping.certify`; also `plan.continuous_bound`): the design is then proved within (worst - bound) of the
best any command can do, smooth or not, classic shapers included. The smooth row's note states the same bound where
the design with jumps is made beside it (how far the smooth command is from the best any command can do, in
percentage points of the unshaped move's residual), or, where its worst is below `CERTIFY_ATOL`, that it is within
that of the best (a residual is never below 0); otherwise it claims nothing beyond its own command space (the
spline's own multipliers bound next to nothing; `certify_rtol` makes the bound).

`certify_rtol` (with `smooth=False` or `"auto"`, and `j_max=None`; default None: no refinement; with `"auto"` the
design with jumps is then always made beside the smooth one, at the smooth design's time where `move_time` is None,
its note saying why): the design with jumps is refined until it is certified within this fraction of its own worst
residual, (worst - bound) <= certify_rtol * worst, or within `CERTIFY_ATOL` = 0.01 % of the unshaped move's
residual, absolute, whichever is larger (near a zero optimum the bound is 0 and no relative tolerance can be proved;
the note says which one was met): first the modulus cuts and the frequency grid are refined (16 cuts let a residual
exceed the LP's value by 2 %), then the number of steps doubles (up to 1024, `CERTIFY_MAX_STEPS`); the best bound
met is kept. The row's note gives both numbers, and says so when the limit is reached first. Each refinement costs
one more compiled LP (about 10 s for a 5.5 Hz mode within 1 %; a minute or more for several hundred steps).

**The pipeline.** `design_move` composes one module per stage, each taking the checked request
(`jaxbelt.shaping.request.MoveRequest`) and the previous stage's output: validate (`request`: every check, and every
quantity derived from the arguments once: the judged and nominal axes as checked arrays, the minimax LP's setup with
its programs started compiling, the unshaped moves and their references) → build the classic shapers' candidates
(`shaped`) and measure them (`measure`) → place the common move time and solve the minimax design
(`minimax_solve.solving`: at a given time in a worker thread beside the next two stages, else at the shortest time
that reaches the best classic row) → build the candidates of that time (`candidates`) and measure them the same way
(`measure`) → the minimax rows (`minimax_rows`: the design's rows, the design with jumps, the command space in
`hull`) → rank (`rank`). The stages take plain data from the request: none re-enters the axis' checks or an earlier
stage.
"""

import csv
import dataclasses
import math

import numpy as np

from .._checks import available_bytes, check_positive
from .._display import Display, Table, fmt, fmt_list, require, with_unit
from .._io import IMAGE_FORMATS, atomic_open, check_output_path, save_figure
from .._threads import blas_limited
from ..models.axis import ModalAxis
from .bands import _N_WIDE, _WIDE
from .candidates import timed_commands
from .certificate import CERTIFY_ATOL as CERTIFY_ATOL  # noqa: E402
from .certificate import CERTIFY_MAX_STEPS as CERTIFY_MAX_STEPS  # noqa: E402
from .far_modes import _far_modes as _far_modes  # noqa: E402
from .hull import sampled_ratios

# names of the pipeline's stages that users and tests reach through this module
from .measure import EXCURSION_RTOL as EXCURSION_RTOL  # noqa: E402
from .measure import Candidate, measure_rows
from .measure import _row as _row  # noqa: E402
from .minimax_rows import JUMPS as JUMPS  # noqa: E402
from .minimax_rows import _smooth_certificate as _smooth_certificate  # noqa: E402
from .minimax_rows import minimax_rows
from .minimax_solve import solving
from .moves import drive_positions, drive_samples, sampled_peaks
from .rank import rank
from .request import MAX_RATE_HZ as MAX_RATE_HZ  # noqa: E402
from .request import N_DAMPING as N_DAMPING  # noqa: E402
from .request import UNKNOWN_DAMPING as UNKNOWN_DAMPING  # noqa: E402
from .request import UNKNOWN_SHAPER_DAMPING as UNKNOWN_SHAPER_DAMPING  # noqa: E402
from .request import damping_samples as damping_samples  # noqa: E402
from .request import validate
from .shaped import classic_commands
from .shapers import SHAPERS

#: units of the sampled move (`MovePlan.samples_to_pandas`)
_SAMPLE_UNITS = {"t": "s", "x": "m", "v": "m/s", "a": "m/s²"}


@dataclasses.dataclass(frozen=True)
class MovePlan:
    """The result of `design_move`: `table` (candidates ranked, best first), `best` (the recommended
    `Candidate`; None when no candidate is feasible, converged and within the limits), the axis, the move's data,
    `reference_m` (per mode, the unshaped move's worst residual over the band [m]) and the minimax design's details
    (`minimax`: a `MinimaxDesign` or None); `continuous_bound`: a rigorous lower bound on the least worst residual any
    command within the plan's limits, distance and time can leave over the band, as a fraction of the references (the
    minimax designs' own, continuous worst % are at least 100x this, the table's as executed may lie a little below; NaN without a converged minimax design with steps, `smooth=False` or
    the row `smooth="auto"` adds, without a jerk limit; `jaxbelt.shaping.certify`).

    `damping`: the damping range `(lo, hi)` every residual was judged over (`design_move(..., damping=...)`), or
    None (the axis' own damping ratios). With a range, `axis` is the user's axis, `reference_m` per mode the largest
    of its damping samples' references, and `measure_axis`, `measure_reference_m` the expanded axis (each mode once
    per damping sample, `damping_samples`) and its references, on which every residual of the table, the curves and
    the exported samples' correction are computed.

    `rate_hz` [Hz], `interpolation`: how the user's drive executes a command (`design_move(..., rate_hz=,
    interpolation=)`): every residual of the table and of `curves` is that of the position setpoints `to_csv` writes
    at this rate, executed linear between them. `resolution` [m]: the drive's position step, or None
    (`design_move(..., resolution=)`)."""

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
    rate_hz: float = 1000.0
    interpolation: str = "linear"
    resolution: float | None = None

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
        """Write the recommended command (or the candidate named `candidate`) sampled at `rate_hz` [Hz] as CSV columns
        `t,x,v,a` (s, m, m/s, m/s²) with that header line. The position column `x` is the command: a drive that executes
        it as position setpoints, linear between them, at the plan's rate (`design_move(..., rate_hz=)`, `plan.rate_hz`,
        1 kHz by default) leaves the residual the table states for that row (an exact, independent replay of the file
        finds it to 1e-6, tests/test_shaping_space.py); at another rate, another. The `v` and `a` columns are the
        command's own velocity and acceleration at the samples, for feed-forward only: a drive that interpolates the `a`
        column instead of following `x` runs another command (for a design whose acceleration jumps, one that can leave
        many times the stated residual). The samples respect the plan's limits (see `samples`).

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
        check_sample_count(rate_hz, max((c.move_time for c in self.table if c.command is not None), default=0.0), owner)

    def samples(self, rate_hz: float, candidate: str | None = None):
        """`(t, x, v, a)` of the recommended command (or `candidate`) sampled at `rate_hz` [Hz], as `to_csv` writes
        them, and as the table measured them (`jaxbelt.shaping.moves.drive_samples`): the smooth minimax design's
        corrected so that a drive that executes the acceleration linearly between samples leaves its continuous
        residual (`jaxbelt.shaping.moves.executable_samples`; in a blend of the command space, that member's), the
        others' exact. The table states the residual of these positions executed linearly between samples.

        Every sample respects the plan's limits to a relative 1e-9: |v| <= v_max [m/s], |a| <= a_max [m/s²] and,
        with j_max, |a_k+1 - a_k| rate_hz <= j_max [m/s³]. The design's correction includes them as constraints
        (the least change of the acceleration that restores the residual and keeps them; a scaled-down copy
        would change the distance); another command that exceeds them by a rounding is stretched in time by the
        least factor that brings it within them (same distance, same rate; `jaxbelt.shaping.moves.limited_samples`)."""
        c = self._chosen(candidate, "MovePlan.samples")
        check_sample_count(rate_hz, c.move_time, "MovePlan.samples")
        limits = (self.v_max, self.a_max, self.j_max)
        cmd = c.command
        assert cmd is not None  # `_chosen` refuses a candidate without a command
        axis, ref, _ = self._measured()  # the residual the table states: over the band (and damping range)
        return drive_samples(cmd, rate_hz, axis, ref, (self.uncertainty, limits))  # what the table measured

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
        """`(factors, {name: residual % of shape (n_modes, len(factors))})` for every candidate with a command, as
        the table measures it: the position setpoints `to_csv` writes at `rate_hz`, executed linear between them;
        with a damping range, per mode the worst over its damping samples."""
        f = np.linspace(*_WIDE, _N_WIDE) if factors is None else np.asarray(factors, dtype=float)
        axis, ref, per = self._measured()
        limits = (self.v_max, self.a_max, self.j_max)
        out = {}
        for c in self.table:
            if c.command is not None:
                t, x = drive_positions(c.command, self.rate_hz, axis, ref, (self.uncertainty, limits))
                pct = 100.0 * np.abs(sampled_ratios(axis, t, x, ref, f))
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
            ("executed as", self._execution_words(), ""),
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

    def _execution_words(self) -> str:
        words = f"position setpoints at {self.rate_hz:g} Hz, {self.interpolation} between them"
        return words + ("" if self.resolution is None else f", rounded to {self.resolution:g} m steps")

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


#: bytes an export holds per sample at its peak, an upper estimate: the four columns, and for the smooth design the
#: banded basis of `executable_samples` (4 columns, values, indices, knot positions) and its temporaries
BYTES_PER_SAMPLE = 512


def check_sample_count(rate_hz, duration: float, owner: str) -> None:
    """A `ValueError` naming `rate_hz` [Hz] where the samples of a `duration` [s] move would need more than half the
    memory available (`BYTES_PER_SAMPLE` each), stating the rates that fit, before anything is allocated."""
    check_positive("rate_hz", rate_hz, "Hz", owner)
    n = float(duration) * float(rate_hz) + 1.0
    avail = available_bytes()
    if n * BYTES_PER_SAMPLE > avail / 2:
        top = (avail / 2 / BYTES_PER_SAMPLE - 1.0) / max(float(duration), 1e-300)
        raise ValueError(
            f"{owner}: parameter `rate_hz` = {float(rate_hz):g} Hz makes {n:.3g} samples of the {float(duration):.4g} "
            f"s move, about {n * BYTES_PER_SAMPLE / 1e9:.3g} GB, more than half the memory available "
            f"({avail / 1e9:.3g} GB): give rate_hz in (0, {top:.4g}] Hz"
        )


def check_rate(rate_hz, nyquist: float, owner: str) -> None:
    """A `ValueError` naming `rate_hz` unless it exceeds `nyquist` [Hz] (the samples must carry the modes)."""
    if not float(rate_hz) > nyquist:
        raise ValueError(
            f"{owner}: parameter `rate_hz` must exceed twice the highest frequency of the band "
            f"(Nyquist: > {nyquist:g} Hz); got {rate_hz}"
        )


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
    rate_hz: float = 1000.0,
    interpolation: str = "linear",
    x_min=None,
    x_max=None,
    resolution=None,
) -> MovePlan:
    """Design the move of `distance` [m] on `axis` every way jaxbelt knows, under the same limits and move time,
    and rank them (see the module docstring: the candidates, the measure, damping ranges, execution and travel, the
    minimax design's command space, certificates).

    - `axis`: a `ModalAxis` (`jb.ModalAxis([f1, f2], [z1, z2])`, `jb.identify_axis(t, y, 2)`,
      `jb.BeltPlatform().to_axis()`); `distance` [m] (or rad: the units of the axis' command), finite, non-zero;
    - `move_time` [s]: every candidate ends at this time (at least the time-optimal move's, which an error states);
      `None`: the shortest time at which the minimax design reaches the best classic shaper's worst residual;
    - `v_max` [m/s], `a_max` [m/s²], `j_max` [m/s³] (optional): limits every candidate respects;
    - `uncertainty` u in [0, 0.9): the band $f_i(1 \\pm u)$ every residual is judged on; `include`: which
      candidates to build; `progress`: print the stages;
    - `smooth`: True (cubic B-spline acceleration), False (steps, or ramps with `j_max`) or `"auto"` (default);
      `certify_rtol` (None or in (0, 1)): refine the design with jumps until certified within it;
    - `damping`: None, `(lo, hi)` or `"unknown"`: the damping range every residual is judged over;
    - `rate_hz` [Hz] (default 1000, at most `MAX_RATE_HZ`), `interpolation` (`"linear"`): the drive's position
      setpoints; `x_min`, `x_max` [m, positions from the start] (optional): the axis' travel; `resolution` [m]
      (optional, in (0, |distance|]): the drive's position step (a motor step or an encoder count in length units).

    Returns a `MovePlan`: `plan.table` (ranked), `plan.best` (the recommendation: the least worst residual among
    the candidates that are feasible, converged and within the limits; a design the solver did not converge on
    is reported in the table, never recommended), `plan.to_csv(path, rate_hz)`, `plan.plot()`.
    """
    req = validate(axis, distance, move_time, v_max=v_max, a_max=a_max, j_max=j_max, uncertainty=uncertainty,
                   include=include, progress=progress, smooth=smooth, certify_rtol=certify_rtol, damping=damping,
                   rate_hz=rate_hz, interpolation=interpolation, x_min=x_min, x_max=x_max,
                   resolution=resolution)  # fmt: skip
    classic = measure_rows(req, classic_commands(req))
    with solving(req, classic) as (T, design, beside):  # at a given move time the minimax LP and its rows run
        minimax = beside(minimax_rows, req, design, T)  # in the worker, beside the timed candidates
        timed = measure_rows(req, timed_commands(req, T))
    minimax, mm, bound = minimax.result()
    table, best = rank(classic + minimax + timed)  # as executed, on the travel
    user, per, ref, damped = req.user, req.per, req.ref, req.damping is not None
    return MovePlan(axis=user, distance=req.distance, move_time=T, v_max=req.v_max, a_max=req.a_max, j_max=req.j_max,
                    uncertainty=req.uncertainty, table=table, best=best, minimax=mm, continuous_bound=bound,
                    reference_m=ref if per == 1 else ref.reshape(user.n_modes, per).max(axis=1), damping=req.damping,
                    measure_axis=req.axis if damped else None, measure_reference_m=ref if damped else None,
                    rate_hz=req.rate_hz, interpolation=req.interpolation, resolution=req.resolution)  # fmt: skip
