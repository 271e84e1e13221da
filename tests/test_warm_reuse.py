"""Work a warm `design_move` no longer does twice: a spline's derivatives at the same instants (`moves.derivatives_at`
keeps its last results: the design's row and its blend's peaks sample the same 20001 instants) and the classic shaped
moves of a move time (`shaped.gentlest_shaped`: the classic rows and the minimax design's command space). Each
reuse must give the values a fresh computation gives, to the last bit, and never another command's."""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import moves, shaped
from jaxbelt.shaping.moves import SplineMove, derivatives_at
from jaxbelt.shaping.shapers import shaper_for_axis


def _spline(scale=1.0):
    # a rest-to-rest B-spline acceleration (sum of coefficients 0), 12 knot intervals over 0.8 s
    c = scale * np.array([1.0, 2.0, 1.5, 0.0, -1.5, -2.0, -1.0, 0.5, -0.5])
    return SplineMove(c - c.mean(), 0.8)


def _counting(monkeypatch):
    calls = []
    program = moves._derivatives

    def counted(*args):
        calls.append(1)
        return program(*args)

    monkeypatch.setattr(moves, "_derivatives", counted)
    return calls


def test_derivatives_at_the_same_instants_are_computed_once_and_equal_the_defining_sums(monkeypatch):
    """A spline sampled twice at 20001 instants runs its program for the first call only (20 blocks of 1024); both
    calls equal `SplineMove.derivative` (the defining B-spline sums, evaluated whole; every 7th instant) to 1e-13 of
    the largest value, and each other; a copy is handed out (changing it leaves the kept values alone)."""
    moves._MEMO.clear()
    calls = _counting(monkeypatch)
    cmd = _spline()
    t = np.linspace(0.0, 0.8, 20001)
    first = derivatives_at(cmd, t, (1, 2, 3))
    n_first = len(calls)
    assert n_first == 20
    first[0][:] = np.nan  # the caller's copy
    second = derivatives_at(cmd, t, (1, 2, 3))
    assert len(calls) == n_first
    third = derivatives_at(cmd, t, (3, 1))  # other orders of the same program: the kept values too
    assert len(calls) == n_first
    for k, got in zip((1, 2, 3), second):  # every 7th instant (the blocks' edges among them)
        ref = np.asarray(cmd.derivative(t[::7], k))
        np.testing.assert_allclose(got[::7], ref, rtol=0, atol=1e-13 * float(np.max(np.abs(ref))))
    np.testing.assert_array_equal(third[0], second[2])
    np.testing.assert_array_equal(third[1], second[0])


def test_derivatives_at_keeps_nothing_for_another_command_or_other_instants(monkeypatch):
    """Another spline (other coefficients, same shapes), or the same one at other instants, runs the program again
    and gets its own values (the keys are the padded command's values and the times, not the shapes)."""
    moves._MEMO.clear()
    calls = _counting(monkeypatch)
    t = np.linspace(0.0, 0.8, 20001)
    a = derivatives_at(_spline(), t, (2,))[0]
    b = derivatives_at(_spline(2.0), t, (2,))[0]
    assert len(calls) == 40
    np.testing.assert_allclose(b, 2.0 * a, rtol=1e-13, atol=1e-13 * float(np.max(np.abs(a))))
    t2 = np.linspace(0.0, 0.8, 20000)
    c = derivatives_at(_spline(), t2, (2,))[0]
    assert len(calls) == 60
    np.testing.assert_allclose(c, np.asarray(_spline().derivative(t2, 2)), rtol=0, atol=1e-13 * np.max(np.abs(a)))
    few = np.linspace(0.0, 0.8, 1001)  # below `_MEMO_MIN`: computed every time
    derivatives_at(_spline(), few, (2,))
    derivatives_at(_spline(), few, (2,))
    assert len(calls) == 62


def test_gentlest_shaped_of_a_move_time_is_built_once_and_is_the_fresh_build():
    """The same shaper, axis, distance, time and limits give the command built the first time (one object), whose
    values equal a fresh build's; another time, distance or limit builds anew; the shortest time follows `t_min`
    (with a given time, the command does not)."""
    ax = jb.ModalAxis([7.3, 18.0], [0.015, 0.01])
    args = (ax, 0.1, 1.0, 0.5, 0.3, 1.2, None)
    shaped._RECENT.clear()
    cmd, T, t_short = shaped.gentlest_shaped("ZVD", *args)
    again, T2, t_short2 = shaped.gentlest_shaped("ZVD", ax, 0.1, 1.0, 0.0, 0.3, 1.2, None)
    assert again is cmd and T == T2 == 1.0
    _, tau = shaper_for_axis("ZVD", ax.frequencies, ax.damping_ratios)
    assert t_short == 0.5 + float(tau[-1]) and t_short2 == 0.0 + float(tau[-1])
    shaped._RECENT.clear()
    fresh = shaped.gentlest_shaped("ZVD", *args)[0]
    assert cmd is not None and fresh is not None and fresh is not cmd
    for x, y in zip((cmd.times, cmd.steps, cmd.ramps), (fresh.times, fresh.steps, fresh.ramps)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    other_T = shaped.gentlest_shaped("ZVD", ax, 0.1, 1.1, 0.5, 0.3, 1.2, None)[0]
    other_a = shaped.gentlest_shaped("ZVD", ax, 0.1, 1.0, 0.5, 0.3, 1.3, None)[0]
    assert other_T is not None and other_T is not fresh and other_a is not fresh
    assert float(other_T.duration) == pytest.approx(1.1, rel=1e-15)
