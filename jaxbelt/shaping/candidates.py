"""Build the candidates: the commands other than the convex design, each built on its own, none measured (the
classic shapers, Incerti's pseudo-polynomials and the unshaped move: `design_move`'s table rows).

Each builder returns `(name, command or None, move time [s], note, ok)` per row, which
`jaxbelt.shaping.measure.measure_rows` measures.
"""

import math

import numpy as np

from .far_modes import _far_modes, _sub_axis
from .request import MoveRequest
from .shaped import gentlest_shaped
from .shapers import SHAPERS, ShaperRangeError


def classic_commands(req: MoveRequest) -> list:
    """The classic shapers `req.include` names, each on the gentlest base that ends at the move time (with
    `move_time` None: at its own shortest time); a firmware fit beyond its damping range is listed, not built."""
    out = []
    for name in (n for n in SHAPERS if n in req.include):
        try:
            cmd, T, t_short = gentlest_shaped(name, req.nominal, req.distance, req.move_time, req.t_min, req.v_max,
                                              req.a_max, req.j_max)  # fmt: skip
        except ShaperRangeError as e:
            out.append((name, None, math.nan if req.move_time is None else req.move_time, e.note, False))
            continue
        note = "" if cmd is not None else f"infeasible: needs a move time >= {t_short:.4g} s"
        out.append((name, cmd, T if cmd is not None else t_short, note, cmd is not None))
    return out


def common_time(req: MoveRequest, mm, classic: list) -> float:
    """The move time of the pseudo-polynomials and the unshaped move [s]: the given one, else the minimax design's
    (`mm`), else the shortest usable classic shaper's (measured rows `classic`; twice the time-optimal move's
    without one)."""
    if req.move_time is not None:
        return req.move_time
    if mm is not None:
        return float(mm.command.duration)
    return min((r.move_time for r in classic if r.ok and r.name in SHAPERS), default=2 * req.t_min)


def timed_commands(req: MoveRequest, ref_nominal, T: float) -> list:
    """The candidates of the common move time `T` [s] (`common_time`): Incerti's commands (`pseudo_commands`) and
    the unshaped move: the time-optimal one with `move_time` None, else the gentlest trapezoid (S-curve) of `T`."""
    out = pseudo_commands(req, ref_nominal, T)
    if "unshaped" not in req.include:
        return out
    if req.move_time is None:
        return [*out, ("unshaped (time-optimal)", req.ref_cmd, float(req.ref_cmd.duration), "", True)]
    return [*out, ("unshaped", req.unshaped, T, "", True)]


def pseudo_commands(req: MoveRequest, ref_nominal, T: float) -> list:
    """Incerti's commands at move time `T` [s], designed on `req.nominal` (references `ref_nominal` [m], at the
    nominal damping; with a damping range the design on the expanded axis would cost a program per size for
    little: the exponents are few)."""
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
    limits = (req.v_max, req.a_max, req.j_max)
    designs = designs_for(axis, req.distance, T, limits, np.asarray(ref_nominal)[kept], req.uncertainty, req.progress)
    out = []
    for name, pd in designs.items():
        ok = bool(pd.converged) and bool(pd.within_limits)
        note = "; ".join(q for q in ("" if ok else pd.message, without) if q)
        out.append((name, pd.command, T, note, ok))
    return out
