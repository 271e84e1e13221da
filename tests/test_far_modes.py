"""Modes far above the move's bandwidth in `design_move` (a 1 MHz mode beside 7.3 Hz; a 2 kHz mode).

- the minimax design leaves a mode whose band lies above the Nyquist frequency of its finest knot grid out of its LP
  (the spline basis) and computes its residual for the command exactly: the design converges, is recommended, its
  note names the mode, and the residual agrees with an independent evaluator (tests/references.py);
- the LP on the kept modes is the design on those modes alone;
- every mode far: a `ValueError` naming `axis`;
- the steps basis keeps a far mode in its LP where its rows are representable (its acceleration jumps excite it);
- a pseudo-polynomial's residual on a far mode (closed form where the start of the move is damped away) agrees with
  the independent evaluator.
"""

import numpy as np
import pytest
from references import modal_residual_reference, spline_move_reference

import jaxbelt as jb
from jaxbelt.shaping.design import MinimaxDesign
from jaxbelt.shaping.moves import SplineMove
from jaxbelt.shaping.plan import _far_modes
from jaxbelt.shaping.residual import residual_curve

D, T = 0.1, 0.8


def _plan(axis, include=("minimax",), smooth=True):
    return jb.design_move(axis, D, T, v_max=0.3, a_max=3.0, uncertainty=0.2, include=include, smooth=smooth)


def _windowed(acc, breaks, T, sigma):
    """The acceleration on the last 300/sigma s of the move only (zero before) and its breaks there: the part of the
    move before is damped by e^-300 at its end, below float64's resolution of the residual."""
    start = T - 300.0 / sigma
    breaks = np.asarray(breaks, float)
    return (lambda t: np.where(np.asarray(t) >= start, acc(t), 0.0)), np.r_[start, breaks[breaks > start]]


def test_a_1_mhz_mode_is_left_out_of_the_lp_and_its_residual_computed_exactly():
    axis = jb.ModalAxis([7.3, 1e6], [0.05, 0.02])  # was: "not converged (gap nan)", ZVD recommended
    plan = _plan(axis, include=("minimax", "ZVD"))
    row = plan.candidate("minimax")
    assert row.command is not None and isinstance(plan.minimax, MinimaxDesign)
    assert row.ok and plan.best is not None and plan.best.name == "minimax", row.note
    assert "left out of the LP" in row.note and "mode 2 (1e+06 Hz" in row.note and "Nyquist" in row.note
    # the table's residual of the far mode (the closed form `_measure` runs) against Duhamel's integral by quadrature
    factors = np.linspace(0.8, 1.2, 5)  # the band's worst is at its low edge (the residual falls as omega^-4)
    mine = np.asarray(residual_curve(axis, row.command, np.linspace(0.8, 1.2, 401)))[1]
    assert int(np.argmax(mine)) == 0
    cmd = plan.minimax.command
    assert isinstance(cmd, SplineMove)
    acc, _, _, breaks = spline_move_reference(np.asarray(cmd.coefficients), float(cmd.duration))
    acc, breaks = _windowed(acc, breaks, T, 0.02 * 2 * np.pi * 1e6 * 0.8)
    ref = modal_residual_reference([1e6], [0.02], [1.0], acc, breaks, T, factors)[0]
    got = np.asarray(residual_curve(axis, row.command, factors))[1]
    # 1e-6: the quadrature sums ~5e5 terms of size 1e7 times the result; its rounding is ~1e-7 of it (measured 8e-8)
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    assert float(np.max(got) / plan.reference_m[1]) < 1e-12  # a smooth move does not excite it

    # the same LP as the design on the 7.3 Hz mode alone: the same command, the same residual on that mode
    alone = _plan(jb.ModalAxis([7.3], [0.05])).minimax
    assert isinstance(alone, MinimaxDesign) and isinstance(alone.command, SplineMove)
    np.testing.assert_allclose(
        np.asarray(cmd.coefficients), np.asarray(alone.command.coefficients), rtol=1e-9, atol=1e-12
    )
    kept = jb.ModalAxis([7.3], [0.05])
    band = np.linspace(0.8, 1.2, 401)
    np.testing.assert_allclose(
        np.asarray(residual_curve(kept, cmd, band)), np.asarray(residual_curve(kept, alone.command, band)),
        rtol=1e-9,
    )  # fmt: skip


@pytest.mark.parametrize("smooth, axis", [(True, ([2000.0], [0.02])), (False, ([1e6], [0.1]))])
def test_every_mode_far_is_refused_naming_axis(smooth, axis):
    # the steps keep a lone 1 MHz mode of damping 0.02 (their LP weighs the last step); at 0.1 it is damped within
    # a step, beyond what the LP represents
    with pytest.raises(ValueError, match=r"every mode of parameter `axis` \((2000|1e\+06) Hz\) lies far above"):
        _plan(jb.ModalAxis(*axis), include=("minimax", "ZV"), smooth=smooth)


def test_the_steps_keep_a_far_mode_their_lp_can_weigh():
    axis = jb.ModalAxis([7.3, 2000.0, 1e6], [0.05, 0.02, 0.02])
    spline = _far_modes(axis, T, 0.2, None, True, True)
    assert spline.kept == (0,) and spline.far == (1, 2) and [i for i, _ in spline.left_out] == [1, 2]
    steps = _far_modes(axis, T, 0.2, None, True, False)  # each acceleration jump excites them
    assert steps.kept == (0, 1) and [i for i, _ in steps.left_out] == [2]  # 1 MHz: damped within a step


def test_a_pseudo_polynomial_on_a_far_mode_matches_the_reference():
    cmd = jb.PseudoPolynomial(np.array([3.0, 4.0, 5.0]), D, T)
    factors = np.linspace(0.8, 1.2, 3)
    g = np.array([3.0, 4.0, 5.0])
    C = np.asarray(cmd.coefficients)

    def acc(t):  # phi'' of phi = D (1 - sum C u^g), u = 1 - t / T
        u = np.clip(1.0 - np.asarray(t)[..., None] / T, 0.0, 1.0)
        return -(D / T**2) * np.sum(C * g * (g - 1) * u ** (g - 2), axis=-1)

    for f in (2000.0, 1e6):  # closed form (zeta omega T > 700), both
        axis = jb.ModalAxis([f], [0.02])
        a, breaks = _windowed(acc, np.linspace(0.0, T, 9), T, 0.02 * 2 * np.pi * f * 0.8)
        ref = modal_residual_reference([f], [0.02], [1.0], a, breaks, T, factors, nodes=16)[0]
        np.testing.assert_allclose(np.asarray(residual_curve(axis, cmd, factors))[0], ref, rtol=1e-6)
