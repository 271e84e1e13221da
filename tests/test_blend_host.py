"""A blend's numbers member by member (`moves.blend_derivatives`, `moves.piecewise_derivatives`): the same as the
blend's own program, with no program of its own."""

import numpy as np
import pytest

from jaxbelt.shaping.moves import (
    BlendMove,
    PiecewiseMove,
    SplineMove,
    blend_derivatives,
    derivatives_at,
    peaks,
    piecewise_derivatives,
)


def _moves():
    T = 1.0
    a = PiecewiseMove([0.0, 0.25, 0.5, 0.75, 0.75], [1.0, -1.0, -1.0, 0.5, 0.5], [0.0] * 5, T)
    b = PiecewiseMove([0.0, 0.1, 0.9, 1.0], [0.0] * 4, [2.0, -2.0, -2.0, 2.0], T)
    return T, a, b


@pytest.mark.parametrize("which", [1, 2])
def test_piecewise_derivatives_match_the_defining_sum(which):
    # every order at times before 0, on the knots (a step counts from its knot on), between them and after T,
    # against `PiecewiseMove.derivative` (the defining sums), 1e-13 of the largest value
    T, a, b = _moves()
    move = a if which == 1 else b
    t = np.concatenate([[-0.1, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.2], np.linspace(-0.05, 1.05, 301)])
    got = piecewise_derivatives(move, t, (0, 1, 2, 3))
    for k, g in enumerate(got):
        ref = np.asarray(move.derivative(t, k))
        np.testing.assert_allclose(g, ref, rtol=0, atol=1e-13 * max(float(np.max(np.abs(ref))), 1.0))
    with pytest.raises(ValueError, match="order"):
        piecewise_derivatives(move, t, (4,))


@pytest.mark.slow  # compiles the blend's own program (the reference): ~3 s
def test_blend_peaks_member_by_member_are_the_blends():
    # a blend of a spline and two piecewise moves: its derivatives member by member against the blend's own
    # (`derivatives_at` of the BlendMove: the merged program), 1e-12; `peaks` takes the member-by-member ones
    T, a, b = _moves()
    spline = SplineMove(np.sin(np.arange(20.0)), T)
    blend = BlendMove((a, spline, b), np.array([0.2, 0.5, 0.3]), T)
    t = np.linspace(0.0, T, 2001)
    mine = blend_derivatives(blend, t, (0, 1, 2, 3))
    own = derivatives_at(blend, t, (0, 1, 2, 3))
    for m, o in zip(mine, own):
        np.testing.assert_allclose(m, o, rtol=0, atol=1e-12 * float(np.max(np.abs(o))))
    ts = np.linspace(0.0, T, 20001)
    ref = [float(np.max(np.abs(x))) for x in derivatives_at(blend, ts, (1, 2, 3))]
    np.testing.assert_allclose(peaks(blend), ref, rtol=1e-12)
