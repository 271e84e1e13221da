"""Measure: every candidate's command judged the same way, a row of the table (`Candidate`).

The residual of each mode over its band (and damping samples) in % of the unshaped move's, the 5 % bands, the peaks
against the limits, and the positions as executed against the travel.
"""

import dataclasses
import math
from typing import Any

import numpy as np

from .._display import fmt_list
from ..commands import AbstractMotionCommand
from .bands import _N_WIDE as _N_WIDE
from .bands import _WIDE as _WIDE
from .bands import JUMPS, measure_grids, mode_label
from .hull import best_blend, blend_moves, resolution_floor, sampled_ratios
from .moves import EXCURSION_RTOL as EXCURSION_RTOL
from .moves import PiecewiseMove, drive_positions, padded, peaks, sample_times, travel_notes
from .request import MoveRequest
from .residual import tolerance_band


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One row of a `MovePlan`'s table.

    - `name`; `command`: the motion command (None when the candidate is infeasible at this move time);
    - `move_time` [s];
    - `worst_percent`, `mean_percent`: worst and mean residual over every mode's band, in % of the unshaped
      move's worst residual on that mode; `worst_m`: the worst residual amplitude in length units [m]; each of
      the command as the drive executes it (the position setpoints `MovePlan.to_csv` writes at the plan's
      `rate_hz`, linear between them);
    - `band_hz`: per mode, `(low, high)` [Hz] of the 5 % band (NaN when the nominal residual is above 5 %); with a
      damping range, the band within which the residual stays within 5 % at every damping sample (the
      intersection of the samples' bands);
    - `peak_v` [m/s], `peak_a` [m/s²], `peak_j` [m/s³];
    - `ok`: feasible, converged and within the limits; `note`: why not, or what to know;
    - `outside_percent`: the worst residual outside the band, between 0.5 and 1.5 times each mode's frequency,
      in % of the same references (what an unmodelled or mistaken mode there would see; the ranking ignores it);
    - `at_resolution`: with `design_move(..., resolution=)`, every mode's worst residual lies below what the
      drive's rounding of its setpoints to that step leaves (`hull.resolution_floor`): the ranking then takes it as
      no residual and prefers the lower peaks (False without a resolution).
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
    at_resolution: bool = False

    def sample(self, rate_hz: float):
        """`(t, x, v, a)` of the command sampled at `rate_hz` [Hz] (see `AbstractMotionCommand.sample`)."""
        if self.command is None:
            raise ValueError(f"{self.name}: no command ({self.note})")
        return self.command.sample(rate_hz)

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("name", "move_time", "worst_percent", "mean_percent", "worst_m")}
        d.update(outside_percent=self.outside_percent, at_resolution=self.at_resolution)
        d.update(peak_v=self.peak_v, peak_a=self.peak_a, peak_j=self.peak_j, ok=self.ok, note=self.note)
        for i, (lo, hi) in enumerate(self.band_hz):
            d[f"band5_mode{i + 1}_hz"] = (lo, hi)
        return d


def _measure(req: MoveRequest, cmd, size: int = 0, pk=None) -> tuple[Any, dict[str, Any], bool, Any, tuple]:
    """The table's numbers for one command on `req.axis` (`req.per` damping copies of each user mode), a
    `PiecewiseMove` padded to `size` terms first: `(command, numbers, within the limits, worst ratio over the band per
    mode of `req.axis`, the travel of its setpoints: `(notes, inside)`, `moves.travel_notes`)`. Every residual is that of the command *as executed*: the position setpoints `to_csv` writes
    at `req.rate_hz`, linear between them (`moves.drive_positions`, `hull.sampled_ratios`). `pk`: the command's `(peak
    |v|, peak |a|, peak |jerk|)` where its builder measured them (a pseudo-polynomial's design: on 20001 instants on
    the host), else measured here (`moves.peaks`)."""
    axis, ref, u, limits, per = req.axis, req.ref, req.uncertainty, req.limits, req.per
    if isinstance(cmd, PiecewiseMove):  # shaped on the user's modes: padded to their size
        cmd = padded(cmd, size)
    pv, pa, pj = peaks(cmd) if pk is None else pk
    band, wide = measure_grids(u)
    t, x = drive_positions(cmd, req.rate_hz, axis, ref, (u, limits))
    travel = travel_notes(x, req.distance, req.x_range)
    if t.size > sample_times(float(cmd.end_time), req.rate_hz).size:  # stretched to keep the limits
        travel[0].append(f"measured as exported: its samples stretched in time to {t[-1]:.6g} s to keep the limits")
    r = np.abs(sampled_ratios(axis, t, x, ref, np.concatenate([band, wide])))
    ratio, wr = r[:, : band.size], r[:, band.size :]
    res = ratio * ref[:, None]  # (modes, K) [m]
    f = np.asarray(axis.frequencies)
    bands = []
    for i in range(0, axis.n_modes, per):
        # with damping copies: the band within which every copy stays within 5 % (each contains the nominal
        # frequency, so the intersection is empty only when one of them is, NaN)
        sides = np.array([tolerance_band(wide, wr[k], 0.05) for k in range(i, i + per)], dtype=float)
        lo, hi = float(np.max(sides[:, 0])), float(np.min(sides[:, 1]))  # NaN propagates
        bands.append((lo * f[i], hi * f[i]) if per == 1 or lo <= hi else (math.nan, math.nan))
    v_max, a_max, j_max = limits
    within = pv <= v_max * (1 + 1e-6) and pa <= a_max * (1 + 1e-6) and (j_max is None or pj <= j_max * (1 + 1e-6))
    outside = (wide < 1.0 - u) | (wide > 1.0 + u)
    return (
        cmd,
        dict(
            outside_percent=100.0 * float(wr[:, outside].max()) if outside.any() else math.nan,
            worst_percent=100.0 * float(ratio.max()),
            mean_percent=100.0 * float(ratio.mean()),
            worst_m=float(res.max()),
            band_hz=tuple(bands),
            peak_v=pv,
            peak_a=pa,
            peak_j=pj,
        ),
        within,
        ratio.max(axis=1),
        travel,
    )


def _pad_size(n_modes: int, jerk: bool, terms: int) -> int:
    """One padded size for the piecewise moves of a plan, so that they share their compiled programs: up to 3
    modes the longest shaped move's (3-hump EI, 5 impulses per mode, 4 terms per impulse without a jerk limit, 8
    with one); beyond, `terms` rounded up to a power of two (the sizes grow as 5**modes)."""
    if n_modes <= 3:
        return (8 if jerk else 4) * 5**n_modes
    return 1 << max(int(terms) - 1, 1).bit_length()


def _row(req: MoveRequest, name, cmd, T, note="", ok=True, left_out=(), pk=None):
    """One candidate measured on `req.axis` (with `req.per` damping copies of each of the user's modes; `pk`: its
    peaks where its builder measured them, `_measure`); its note then names the modes `left_out` (`(index, why)`
    pairs: those a minimax design's LP left out) with their residual as executed, and where its setpoints leave the
    segment from start to end or the travel (not ok then), and where it lies below the drive's resolution."""
    axis, per, limits = req.axis, req.per, req.limits
    n_user = axis.n_modes // per
    size = _pad_size(n_user, limits[2] is not None, cmd.times.shape[0]) if isinstance(cmd, PiecewiseMove) else 0
    if cmd is None:
        nan = math.nan
        return Candidate(
            name, None, T, nan, nan, nan, tuple((nan, nan) for _ in range(n_user)), nan, nan, nan, False, note
        )
    cmd, m, within, mode_worst, (travel, inside) = _measure(req, cmd, size, pk)
    if not within:
        ok = False
        note = (note + "; " if note else "") + "exceeds the limits"
    floor = (
        None
        if req.resolution is None or not (ok and inside)
        else resolution_floor(axis, req.resolution, req.rate_hz, T)
    )
    at_floor = floor is not None and bool(np.all(mode_worst * req.ref <= floor))  # a usable row only
    if at_floor:
        note = (note + "; " if note else "") + (
            f"at the drive's resolution: every mode's residual lies below what rounding the setpoints to "
            f"{req.resolution:g} m leaves ({fmt_list(floor, '.2g')} m RMS), so the ranking prefers the lower peaks"
        )
    if left_out:
        f = np.asarray(axis.frequencies, dtype=float)
        parts = [
            f"{mode_label(axis, i, per)} ({f[i]:.6g} Hz; {why}): {100.0 * float(mode_worst[i]):.2g} % (as executed)"
            for i, why in left_out
        ]
        note += "; left out of the LP, their residual computed for this command: " + "; ".join(parts)
    note = "; ".join([note, *travel] if note else travel)
    return Candidate(name, cmd, float(T), ok=ok and inside, note=note, at_resolution=at_floor, **m)


def design_row(name: str, mm, T: float, note: str, ok: bool, far, req: MoveRequest) -> Candidate:
    """The table row of a minimax design `mm` (`note`, `ok`: its certificate, `certificate.certificate`; None: no
    design at move time `T` [s], `note` says why), measured as every candidate is (`_row`), its note then naming the
    modes its LP left out (`far`, a `far_modes._FarModes`) with their residual, as executed, for this command."""
    cmd, T = (None, T) if mm is None else (mm.command, float(mm.command.duration))
    return _row(req, name, cmd, T, note, ok, far.left_out)


def blended_rows(req: MoveRequest, rows: list, space: dict) -> list:
    """`rows` with each minimax row replaced by the least worst residual, as executed at `req.rate_hz` [Hz], of the
    blends of its design with the designs with jumps of the table and the members of `space`
    (`shaped.shaped_members`; `jaxbelt.shaping.hull`): at most what each of them leaves, by construction. The row's
    note says which blend it is. A minimax row whose design is infeasible or did not converge is kept as it is (not
    ok, its note says why): a blend of the other candidates alone is not that design, and the table shows those
    candidates' own rows."""
    axis, ref, band, rate = req.axis, req.ref, req.band, req.rate_hz
    designs = {r.name: r.command for r in rows if r.name in ("minimax", JUMPS) and r.ok and r.command is not None}
    out = []
    for r in rows:
        if r.name not in designs:  # not a minimax row, or one whose design failed: it keeps its own verdict
            out.append(r)
            continue
        keys = [n for n in designs if n in (r.name, JUMPS)]
        names, cmds = keys + list(space), [designs[n] for n in keys] + list(space.values())
        w, worst, each = best_blend(axis, cmds, ref, band, rate, (req.uncertainty, req.limits))
        parts = ", ".join(f"{names[i]} {w[i]:.3g}" for i in np.flatnonzero(w))
        note = (
            f"its command space holds every classic shaped move and the unshaped move: the blend {parts} leaves "
            f"{100 * worst:.3g} % as executed at {rate:g} Hz (the design alone {100 * each[0]:.3g} %; the least of "
            f"the others {100 * float(np.min(each[1:])):.3g} %)"
        )
        if w[0] == 1.0:
            out.append(dataclasses.replace(r, note=r.note + "; " + note))
            continue
        cmd = blend_moves(cmds, w)
        out.append(_row(req, r.name, cmd, float(cmd.end_time), note=r.note + "; " + note))
    return out


def measure_rows(req: MoveRequest, built) -> list:
    """Every built candidate measured the same way (`_row`) on `req.axis` against the references `req.ref` [m]:
    `built` holds `(name, command or None, move time [s], note, ok, peaks or None)` (`jaxbelt.shaping.candidates`)."""
    return [_row(req, name, cmd, T, note, ok, (), pk) for name, cmd, T, note, ok, pk in built]
