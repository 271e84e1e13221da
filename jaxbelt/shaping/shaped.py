"""Shaped moves of a given end time: a classic shaper's impulses convolved with the gentlest base move that ends
there; the classic shapers' rows of `design_move`'s table (`classic_commands`, the first candidates built: at a
given move time or each at its own), and the set of such moves (with the unshaped move) that the minimax design's
command space holds (`shaped_members`).

It builds commands only (no measuring): `jaxbelt.shaping.measure` measures them, the minimax rows blend them.
"""

import math

import numpy as np

from .._recent import Recent
from .moves import _trapezoid_move, convolved, peaks
from .request import MoveRequest
from .shapers import SHAPERS, ShaperRangeError, shaper_for_axis


def gentlest_shaped(name: str, axis, distance, T, t_min, v_max, a_max, j_max):
    """The classic shaper `name` (`shapers.shaper_for_axis` on `axis`; its `ShaperRangeError` passes through) on the
    gentlest base that ends at `T` [s], or, with `T` None, at its own shortest time $t_{min} + \tau_{end}$ (`t_min`
    [s]: the time-optimal unshaped move's; built a relative 1e-12 later, so that the base is not refused by a
    rounding): `(command or None, move time [s], shortest time [s])`.

    The base is the gentlest within the limits; where none is, the gentlest whose *shaped* move is within them (a
    shaper spreads the base's acceleration over its impulses: ZV halves the peak acceleration of a base whose
    acceleration phase is shorter than its delay, so at a ZV-shaped move's own time and peaks the base exceeds
    `a_max` while the shaped move does not)."""
    key = None if T is None else _key(name, axis, distance, T, v_max, a_max, j_max)
    hit = _RECENT.get(key)
    if hit is not None:
        cmd, tau_end = hit
        return cmd, T, t_min + tau_end
    A, tau = shaper_for_axis(name, axis.frequencies, axis.damping_ratios)
    tau_end = float(tau[-1])
    cmd = _build(A, tau, distance, T, t_min, v_max, a_max, j_max)
    _RECENT.put(key, (cmd, tau_end))
    return cmd, (t_min + tau_end if T is None else T), t_min + tau_end


#: the last shaped moves of a given end time, by the shaper, the axis' values, the distance, the time and the
#: limits: the candidates' classic rows and the minimax design's command space (`shaped_members`) build the same
#: moves of a `design_move` call (0.04-0.09 s of eager operations on 1-3 modes); commands are immutable
_RECENT = Recent(32)


def _key(name, axis, distance, T, v_max, a_max, j_max):
    vals = (axis.frequencies, axis.damping_ratios)
    return (name, *(np.asarray(v, dtype=float).tobytes() for v in vals), *(float(x) for x in (distance, T, v_max,
            a_max)), None if j_max is None else float(j_max))  # fmt: skip


def _build(A, tau, distance, T, t_min, v_max, a_max, j_max):
    """`gentlest_shaped`'s command (or None) of the shaper's impulses `A` at `tau`."""
    t_short = t_min + float(tau[-1])
    T_build = t_short * (1 + 1e-12) if T is None else T
    if not T_build > tau[-1]:
        return None
    base = _trapezoid_move(distance, T_build - tau[-1], v_max, a_max, j_max)
    if base is not None:
        return convolved(base, A, tau)
    relax = 1.0 / float(np.min(np.asarray(A)))  # a shaped peak is at least min(A) times the base's
    base = _trapezoid_move(distance, T_build - tau[-1], v_max, a_max * relax, None if j_max is None else j_max * relax)
    if base is None:
        return None
    cmd = convolved(base, A, tau)
    pv, pa, pj = peaks(cmd)
    tol = 1 + 1e-9
    if pv > v_max * tol or pa > a_max * tol or (j_max is not None and pj > j_max * tol):
        return None
    return cmd


def shaped_moves(axis, distance, T, t_min, v_max, a_max, j_max, names=SHAPERS) -> dict:
    """Every classic shaper of `names` on the gentlest base that ends at `T` [s] (`gentlest_shaped`; with `T` None at
    its own shortest time), and, at a given `T`, the gentlest trapezoid (S-curve) of `T` (a relative 1e-9 of `a_max`
    spared, so that a move at the time-optimal time is built), as `"unshaped"`: `{name: (command or None, move time
    [s], note)}`. A shaper that cannot be built has no command and a note saying why: a firmware fit beyond its
    damping range (its `ShaperRangeError`'s note; move time `T`, NaN with `T` None), or a move time below its own
    shortest one (move time: that shortest time)."""
    out = {}
    for name in names:
        try:
            cmd, T_row, t_short = gentlest_shaped(name, axis, distance, T, t_min, v_max, a_max, j_max)
        except ShaperRangeError as e:
            out[name] = (None, math.nan if T is None else T, e.note)
            continue
        note = "" if cmd is not None else f"infeasible: needs a move time >= {t_short:.4g} s"
        out[name] = (cmd, T_row if cmd is not None else t_short, note)
    if T is not None:
        out["unshaped"] = (_trapezoid_move(distance, T, v_max, a_max * (1 + 1e-9), j_max), T, "")
    return out


def shaped_members(nominal, distance, T, v_max, a_max, j_max) -> dict:
    """The moves the minimax design's command space holds at move time `T` [s]: every classic shaper buildable on
    the axis `nominal` within the limits, and the unshaped move (`shaped_moves`): `{name: command}`."""
    moves = shaped_moves(nominal, distance, T, 0.0, v_max, a_max, j_max)
    return {name: cmd for name, (cmd, _, _) in moves.items() if cmd is not None}


def classic_commands(req: MoveRequest) -> list:
    """The classic shapers `req.include` names, each on the gentlest base that ends at the move time (with
    `move_time` None: at its own shortest time); a firmware fit beyond its damping range is listed, not built
    (`shaped.shaped_moves`)."""
    names = tuple(n for n in SHAPERS if n in req.include)
    built = shaped_moves(req.nominal, req.distance, req.move_time, req.t_min, req.v_max, req.a_max, req.j_max, names)
    return [(name, *built[name], built[name][0] is not None, None) for name in names]
