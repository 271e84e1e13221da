"""Candidates: the commands other than the convex design, each built on its own: the classic shapers, Incerti's
pseudo-polynomials and the unshaped move (`design_move`'s table rows).
"""

import math

import jax.numpy as jnp
import numpy as np

from .far_modes import _far_modes, _sub_axis
from .measure import _row
from .moves import (
    _trapezoid_move,
    fastest_time,
    peaks,
    shape_move,
)
from .request import MoveRequest
from .residual import residual_curve
from .shapers import SHAPERS, ShaperRangeError, shaper_for_axis


def _shaped(axis, name, distance, T, v_max, a_max, j_max):
    """The classic shaper `name` on the gentlest base that ends at T, or (None, shortest time).

    The base is the gentlest within the limits; where none is, the gentlest whose *shaped* move is within them (a
    shaper spreads the base's acceleration over its impulses: ZV halves the peak acceleration of a base whose
    acceleration phase is shorter than its delay, so at a ZV-shaped move's own time and peaks the base exceeds
    `a_max` while the shaped move does not)."""
    A, tau = shaper_for_axis(name, axis.frequencies, axis.damping_ratios)
    t_short = fastest_time(distance, v_max, a_max, j_max) + float(tau[-1])
    if not T > tau[-1]:
        return None, t_short
    base = _trapezoid_move(distance, T - tau[-1], v_max, a_max, j_max)
    if base is not None:
        return shape_move(base, A, tau), t_short
    relax = 1.0 / float(np.min(np.asarray(A)))  # a shaped peak is at least min(A) times the base's
    base = _trapezoid_move(distance, T - tau[-1], v_max, a_max * relax, None if j_max is None else j_max * relax)
    if base is None:
        return None, t_short
    cmd = shape_move(base, A, tau)
    pv, pa, pj = peaks(cmd)
    tol = 1 + 1e-9
    if pv > v_max * tol or pa > a_max * tol or (j_max is not None and pj > j_max * tol):
        return None, t_short
    return cmd, t_short


def _members(nominal, d, T, v_max, a_max, j_max) -> dict:
    """The candidates the minimax design's command space holds at move time `T` [s]: every classic shaper buildable
    on `nominal` within the limits (`_shaped`), and the unshaped move: `{name: command}`."""
    out = {}
    for name in SHAPERS:
        try:
            cmd, _ = _shaped(nominal, name, d, T, v_max, a_max, j_max)
        except ShaperRangeError:
            continue
        if cmd is not None:
            out[name] = cmd
    base = _trapezoid_move(d, T, v_max, a_max * (1 + 1e-9), j_max)
    if base is not None:
        out["unshaped"] = base
    return out


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


def classic_rows(req: MoveRequest, ref) -> list:
    """The rows of the classic shapers `req.include` names, each on the gentlest base that ends at the move time
    (with `move_time` None: at its own shortest time); a firmware fit beyond its damping range is listed, not built."""
    rows = []
    for name in (n for n in SHAPERS if n in req.include):
        try:
            tau_end = float(shaper_for_axis(name, req.nominal.frequencies, req.nominal.damping_ratios)[1][-1])
        except ShaperRangeError as e:
            T = math.nan if req.move_time is None else req.move_time
            rows.append(_row(name, req.axis, None, T, ref, req.uncertainty, req.limits, e.note, False, req.per))
            continue
        T = req.move_time
        if T is None:  # its own shortest time
            T = fastest_time(req.distance, req.v_max, req.a_max, req.j_max) + tau_end
        cmd, t_short = _shaped(req.nominal, name, req.distance, T * (1 + 1e-12 * (req.move_time is None)),
                               req.v_max, req.a_max, req.j_max)  # fmt: skip
        note = "" if cmd is not None else f"infeasible: needs a move time >= {t_short:.4g} s"
        T = T if cmd is not None else t_short
        rows.append(_row(name, req.axis, cmd, T, ref, req.uncertainty, req.limits, note, cmd is not None, req.per))
    return rows


def pseudo_rows(req: MoveRequest, ref, ref_cmd, T: float) -> list:
    """Incerti's commands at move time `T` [s], designed at the nominal damping (the references there)."""
    if "pseudo-polynomial" not in req.include:
        return []
    nominal, per = req.nominal, req.per
    ref_nominal = ref if per == 1 else np.max(np.asarray(residual_curve(nominal, ref_cmd, req.band)), axis=1)
    return _pseudo_rows(nominal, ref_nominal, req.axis, ref, per, req.distance, T, req.v_max, req.a_max, req.j_max,
                        req.uncertainty, req.limits, req.progress)  # fmt: skip


def unshaped_rows(req: MoveRequest, ref, ref_cmd, T: float) -> list:
    """The unshaped move: the time-optimal one with `move_time` None, else the gentlest trapezoid (S-curve) of `T`."""
    if "unshaped" not in req.include:
        return []
    if req.move_time is None:
        T_ref = float(ref_cmd.duration)
        return [
            _row("unshaped (time-optimal)", req.axis, ref_cmd, T_ref, ref, req.uncertainty, req.limits, per=req.per)
        ]
    base = _trapezoid_move(req.distance, T, req.v_max, req.a_max, req.j_max)
    return [_row("unshaped", req.axis, base, T, ref, req.uncertainty, req.limits, per=req.per)]
