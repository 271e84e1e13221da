"""The pseudo-polynomial designs' quadrature (`pseudo.design_nodes`): accurate at the edge of each bucket, and one
program for the benchmarks' 1-3 mode axes over 0.8-1.7 s moves."""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import pseudo as P

#: the axes of `benchmarks/shaping_axis.py`'s `speed_every_candidate`
AXES = {1: ([6.0], [0.02]), 2: ([7.3, 18.0], [0.015, 0.01]), 3: ([3.1, 9.7, 17.0], [0.03, 0.02, 0.01])}
U = 0.2


def _batch():
    """Padded exponents of orders 2 to 8 (classical and clustered), their activity masks."""
    gs = [
        np.array([3.0, 4.0, 5.0]),
        np.array([2.3, 2.8, 3.3, 3.8, 4.3, 4.8, 5.3, 5.8]),
        np.array([5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0]),
        np.arange(2.0, 6.5, 0.5),
    ]
    S = max(g.size for g in gs)
    G = np.stack([np.r_[g, g[-1] + np.arange(1, S - g.size + 1)] for g in gs])
    A = np.stack([np.r_[np.ones(g.size), np.zeros(S - g.size)] for g in gs])
    return G, A


@pytest.mark.parametrize("n_nodes", [512, 1024])
def test_design_nodes_accurate_at_the_top_of_each_bucket(n_nodes):
    # the largest omega T a bucket takes, on one mode: the ratios against a 2048-node rule (a finer solve), 1e-11
    wT = (n_nodes - P.DESIGN_NODES_EXTRA) / P.DESIGN_NODES_PER_RAD
    assert P.design_nodes(wT) == n_nodes
    assert P.design_nodes(wT * 1.01) == 2 * n_nodes
    T = 1.0
    f = wT / (2 * np.pi * (1 + U) * T)
    ax = jb.ModalAxis([f], [0.01])
    factors = np.concatenate([np.linspace(1 - U, 1 + U, 401), [1.0]])
    ref = np.array([1e-3])
    G, A = _batch()
    got, _ = P._evaluate_np(P._kernels_np(ax, T, factors, ref, n_nodes), 1, n_nodes, 0.1, T, G, A)
    fine, _ = P._evaluate_np(P._kernels_np(ax, T, factors, ref, 2048), 1, 2048, 0.1, T, G, A)
    assert np.max(np.abs(got - fine)) <= 1e-11 * np.max(fine)


def test_design_nodes_one_program_for_the_benchmark_axes():
    # the quadrature size is the designs' program's only shape that follows the move time: one size for 0.8-1.7 s
    for f, z in AXES.values():
        ax = jb.ModalAxis(f, z)
        w = float(np.max(np.asarray(ax.omega))) * (1 + U)
        assert {P.design_nodes(w * T) for T in (0.8, 1.0, 1.3, 1.7)} == {512}
