"""The residual curve of a move whose acceleration is steps and ramps, on a uniform grid of frequency factors, by
blocks of phasors (`jaxbelt.shaping.residual._grid_curve`): the same amplitudes as Duhamel's integral taken by
Gauss-Legendre panels (`references.modal_residual_reference`, independent of jaxbelt's closed forms)."""

import numpy as np
import pytest
from references import modal_residual_reference

import jaxbelt as jb
from jaxbelt.shaping import residual as R
from jaxbelt.shaping.hull import blend_moves
from jaxbelt.shaping.moves import PiecewiseMove, fastest_move, shape_move
from jaxbelt.shaping.shapers import shaper_for_axis

AXIS = jb.ModalAxis([3.1, 9.7, 17.0], [0.03, 0.02, 0.01], [1.0, 0.5, 2.0])


def _reference(move, factors):
    t, al, be = (np.asarray(x, dtype=float) for x in (move.times, move.steps, move.ramps))
    T = float(move.duration)

    def accel(tau):
        d = np.maximum(np.asarray(tau)[:, None] - t, 0.0)
        return (al * (d > 0) + be * d).sum(axis=1)

    f, z, g = (np.asarray(getattr(AXIS, k)) for k in ("frequencies", "damping_ratios", "gains"))
    return modal_residual_reference(f, z, g, accel, t, T, factors, nodes=16)


def _shaped(name):
    amps, delays = shaper_for_axis(name, [3.1, 9.7, 17.0], [0.03, 0.02, 0.01])
    return shape_move(fastest_move(0.1, 0.3, 1.2), amps, delays)


@pytest.mark.parametrize("factors", [np.linspace(0.8, 1.2, 401), np.linspace(0.5, 1.5, 51)])
def test_grid_curve_of_shaped_moves_and_their_blend_matches_duhamel_quadrature(factors):
    zv, ei = _shaped("ZV"), _shaped("EI")
    moves = [zv, ei, blend_moves([zv, ei], [0.3, 0.7])]
    for move in moves:
        assert R._uniform_grid(AXIS, move, factors) is not None  # the blocks of phasors are what is checked
        got = np.asarray(R.measured_curve(AXIS, move, factors))
        ref = _reference(move, factors)
        # rounding: the reference's panels sum ~1e5 terms; the curve's largest value sets the scale
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-11 * float(ref.max()))


def test_grid_curve_of_many_terms_matches_the_direct_form_and_falls_back_off_the_grid():
    # 500 terms at random times (some at 0, some within 1e-9 s of the end): the blocks' sums against the
    # quadrature; a grid that is not uniform, or a mode with |s|T < 1, takes the direct form (same numbers)
    rng = np.random.default_rng(0)
    K, T = 500, 1.0
    t = np.sort(rng.uniform(0.0, T, K))
    t[:10], t[-4:] = 0.0, T - np.array([1e-2, 1e-3, 1e-6, 1e-9])
    move = PiecewiseMove(t, rng.normal(size=K), 10.0 * rng.normal(size=K), T)
    r = np.linspace(0.8, 1.2, 41)
    got = np.asarray(R.measured_curve(AXIS, move, r))
    ref = _reference(move, r)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-11 * float(ref.max()))
    uneven = np.r_[r[:20], r[20:] + 1e-4]
    assert R._uniform_grid(AXIS, move, uneven) is None
    np.testing.assert_allclose(np.asarray(R.measured_curve(AXIS, move, uneven)), _reference(move, uneven), rtol=1e-9)
    slow = jb.ModalAxis([0.1], [0.02])  # |s|T = 0.5 at factor 0.8
    assert R._uniform_grid(slow, move, r) is None
