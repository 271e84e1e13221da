"""Rank: the rows ordered by their worst residual (usable ones first), the recommendation, and the notes of a minimax
row that another row beats.
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
        if best is not None and r.ok and r.name in ("minimax", JUMPS) and r.worst_percent > best.worst_percent:
            r = dataclasses.replace(
                r,
                note=r.note + f"; not the least of this table: {best.name} leaves {best.worst_percent:.3g} % (its "
                "certificate holds within its own command space only)",
            )
        out.append(r)
    return out


def rank(rows: list):
    """`(ranked, best)`: the rows usable first, each group by its worst residual, and the recommendation (the first
    usable row; a `RuntimeWarning` where there is none)."""
    key = lambda r: (not r.ok, r.worst_percent if math.isfinite(r.worst_percent) else math.inf)  # noqa: E731
    ranked = _not_beaten(sorted(rows, key=key))
    best = next((r for r in ranked if r.ok), None)
    if best is None:
        warnings.warn(
            "design_move: no candidate is feasible, converged and within the limits; nothing is recommended (the "
            "table's notes say why)",
            RuntimeWarning,
            stacklevel=3,
        )
    return tuple(ranked), best
