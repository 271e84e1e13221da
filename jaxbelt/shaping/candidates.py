"""Build the candidates of the common move time: Incerti's pseudo-polynomials and the unshaped move (`design_move`'s
table rows beside the classic shapers, `jaxbelt.shaping.shaped.classic_commands`, and the minimax rows), each built
on its own, none measured.

Each builder (here and `shaped.classic_commands`) returns `(name, command or None, move time [s], note, ok, peaks or
None)` per row, which `jaxbelt.shaping.measure.measure_rows` measures (`peaks`: the command's `(peak |v|, peak |a|,
peak |jerk|)` where its builder measured them already, as the pseudo-polynomials' design does).
"""

import numpy as np

from .far_modes import _far_modes, _sub_axis
from .request import MoveRequest


def timed_commands(req: MoveRequest, T: float) -> list:
    """The candidates of the common move time `T` [s] (the given one, else the minimax design's,
    `minimax_solve.solving`): Incerti's commands (`pseudo_commands`) and the unshaped move: the time-optimal one with
    `move_time` None, else the gentlest trapezoid (S-curve) of `T`."""
    out = pseudo_commands(req, T)
    if "unshaped" not in req.include:
        return out
    if req.move_time is None:
        return [*out, ("unshaped (time-optimal)", req.ref_cmd, float(req.ref_cmd.duration), "", True, None)]
    return [*out, ("unshaped", req.unshaped, T, "", True, None)]


def pseudo_commands(req: MoveRequest, T: float) -> list:
    """Incerti's commands at move time `T` [s], designed on `req.nominal` (references `req.ref_nominal` [m], at the
    nominal damping; with a damping range the design on the expanded axis would cost a program per size for
    little: the exponents are few), with the peaks their design measured."""
    if "pseudo-polynomial" not in req.include:
        return []
    try:
        from .pseudo import designs_for
    except ImportError:  # pragma: no cover - the module is part of the package
        return []
    axis = req.nominal
    # a pseudo-polynomial is smooth: its exponents are optimised on the modes within the knots' reach (as the smooth
    # minimax design's), the far ones measured with the others (their quadrature needs ~2.5 omega T nodes: a 1 MHz
    # mode would cap it, and slow it, for nothing)
    far = _far_modes(axis, T, req.uncertainty, req.j_max, True, True)
    kept = np.asarray(far.kept if far.kept else range(axis.n_modes), dtype=int)
    without = ""
    if far.kept and far.far:
        without = f"exponents optimised without mode(s) {', '.join(str(i + 1) for i in far.far)}"
        axis = _sub_axis(axis, kept)
    ref = np.asarray(req.ref_nominal)[kept]
    designs = designs_for(axis, req.distance, T, req.limits, ref, req.uncertainty, req.progress)
    out = []
    for name, pd in designs.items():
        ok = bool(pd.converged) and bool(pd.within_limits)
        note = "; ".join(q for q in ("" if ok else pd.message, without) if q)
        out.append((name, pd.command, T, note, ok, tuple(float(x) for x in pd.peaks)))
    return out
