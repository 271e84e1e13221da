"""The minimax design's exchange (`design.minimax_design`): its early stop below `EXCHANGE_ATOL` and its rounds of up
to `PER_ROUND` frequencies per mode leave the design within the tolerances it states, on a grid 10x finer than the
exchange's own check, by a residual computed independently of jaxbelt (Duhamel's integral, Gauss-Legendre)."""

import numpy as np
import pytest
from references import modal_residual_reference, spline_move_reference

import jaxbelt as jb
from jaxbelt.shaping import design as dsg
from jaxbelt.shaping.residual import reference_residuals

D, V, A, U = 0.1, 0.3, 1.2, 0.2


def _problem(freqs, zetas, T):
    ax = jb.ModalAxis(freqs, zetas)
    opts = dsg.default_options(ax.frequencies, T, U, False)
    ref, _ = reference_residuals(ax, D, V, A, None, U)
    return ax, dsg.make_problem(ax, D, T, V, A, None, U, ref, opts), opts, np.asarray(ref)


def _independent_worst(ax, design, ref, n=4001):
    """The design's worst residual over [1 - u, 1 + u] on n factors per mode, as a fraction of each mode's reference
    (the unshaped move's worst), by `modal_residual_reference` of the command's B-spline acceleration (scipy)."""
    cmd = design.command
    acc, _, _, breaks = spline_move_reference(np.asarray(cmd.coefficients), float(cmd.duration))
    factors = np.linspace(1 - U, 1 + U, n)
    amp = modal_residual_reference(ax.frequencies, ax.damping_ratios, ax.gains, acc, breaks, cmd.duration, factors)
    return float(np.max(amp / ref[:, None]))


@pytest.mark.slow  # the LP's and the fine check's compilations (~10 s on two cores), then 4 exchange rounds
def test_exchange_stops_once_the_fine_worst_is_below_its_absolute_tolerance():
    # a lightly damped two-mode axis whose optimum is ~8e-7 of the unshaped move's residual: the exchange stops after
    # its first LP (its fine worst, 1.2e-6, is below EXCHANGE_ATOL = 1e-5), where refining to exchange_tol alone
    # (atol=0) took 4 rounds. The stopped design's worst on a 10x finer grid, computed independently, is at most
    # EXCHANGE_ATOL, and it is within EXCHANGE_ATOL of the refined design's LP value (a lower bound of the least worst
    # residual of the spline space over the band, up to the cuts' polygon)
    ax, prob, opts, ref = _problem([7.3, 18.0], [0.015, 0.01], 1.0)
    fast = dsg.minimax_design(prob, opts)
    full = dsg.minimax_design(prob, opts, atol=0.0)
    assert fast.rounds == 0 and full.rounds >= 2
    assert fast.converged and full.converged
    assert float(fast.fine_worst) <= dsg.EXCHANGE_ATOL
    worst = _independent_worst(ax, fast, ref)
    assert worst == pytest.approx(float(fast.fine_worst), rel=0.02)  # a 10x finer grid than the exchange's check
    assert worst <= dsg.EXCHANGE_ATOL
    # the refined design is what exchange_tol promises: its fine worst within 3 % of its LP value
    assert float(full.fine_worst) <= float(full.worst) * (1 + opts.exchange_tol)


@pytest.mark.slow  # the LP's and the fine check's compilations (~10 s on two cores)
def test_exchange_rounds_of_more_peaks_reach_the_same_design():
    # the three-mode axis of benchmarks/shaping_axis.py: up to PER_ROUND = 6 peaks per mode and round end the exchange
    # in 2 rounds (3 took 3), at the same optimum to 1e-4 (relative), the fine worst within exchange_tol (3 %) of the
    # LP value; checked independently on a 10x finer grid (the fine grid misses a peak by at most 0.1 %)
    ax, prob, opts, ref = _problem([3.1, 9.7, 17.0], [0.03, 0.02, 0.01], 1.0)
    six = dsg.minimax_design(prob, opts)
    three = dsg.minimax_design(prob, opts, per_round=3)
    assert dsg.PER_ROUND == 6 and six.rounds == 2 and three.rounds == 3
    assert six.converged and three.converged
    assert float(six.worst) == pytest.approx(float(three.worst), rel=1e-4)
    worst = _independent_worst(ax, six, ref)
    assert worst == pytest.approx(float(six.fine_worst), rel=1e-3)
    assert worst <= float(six.worst) * (1 + opts.exchange_tol) * (1 + 1e-3)
    assert worst == pytest.approx(_independent_worst(ax, three, ref), rel=1e-3)
