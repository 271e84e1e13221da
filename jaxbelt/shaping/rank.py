"""Rank: the rows ordered by their worst residual (usable ones first; with a drive resolution, those whose residual
lies below it first, by their peaks), the recommendation, and the notes of a minimax row that another row beats.
"""

import dataclasses
import math
import warnings

from .bands import JUMPS


def _not_beaten(ranked: list) -> list:
    """`ranked` (least worst first) with the note of each minimax row that leaves more than another usable row
    saying so: its certificate holds within its own command space only."""
    best = next((r for r in ranked if r.ok), None)
    out = []
    for r in ranked:
        beaten = best is not None and r.ok and r.worst_percent > best.worst_percent and not r.at_resolution
        if best is not None and beaten and r.name in ("minimax", JUMPS):
            r = dataclasses.replace(
                r,
                note=r.note + f"; not the least of this table: {best.name} leaves {best.worst_percent:.3g} % (its "
                "certificate holds within its own command space only)",
            )
        out.append(r)
    return out


def _key(r):
    """Usable rows first; among them those at the drive's resolution (`Candidate.at_resolution`) by their move time
    (with `move_time` None the rows' times differ), then their peaks (|a|, then |jerk|, then |v|; their residuals
    cannot be told from the drive's rounding), then the others by their worst residual."""
    worst = r.worst_percent if math.isfinite(r.worst_percent) else math.inf
    if r.ok and r.at_resolution:
        jerk = math.inf if math.isnan(r.peak_j) else r.peak_j  # a jump: infinite
        return (False, 0, r.move_time, r.peak_a, jerk, r.peak_v, worst)
    return (not r.ok, 1, worst, 0.0, 0.0, 0.0, 0.0)


def rank(rows: list):
    """`(ranked, best)`: the rows usable first, each group by its worst residual (rows at the drive's resolution
    first, by their peaks: `_key`), and the recommendation (the first usable row; a `RuntimeWarning` where there is
    none)."""
    ranked = _not_beaten(sorted(rows, key=_key))
    best = next((r for r in ranked if r.ok), None)
    if best is None:
        warnings.warn(
            "design_move: no candidate is feasible, converged and within the limits; nothing is recommended (the "
            "table's notes say why)",
            RuntimeWarning,
            stacklevel=3,
        )
    return tuple(ranked), best
