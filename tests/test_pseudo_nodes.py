"""The pseudo-polynomial designs' quadrature (`pseudo.design_nodes`): accurate at the edge of each bucket, and one
program for the benchmarks' 1-3 mode axes over 0.8-1.7 s moves."""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import pseudo as P
from jaxbelt.shaping import quadrature as Q

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
    # the largest omega T a bucket takes, on one mode: the ratios against a rule of twice the nodes (a finer solve),
    # 1e-11
    wT = (n_nodes - Q.NODES_EXTRA) / Q.NODES_PER_RAD
    assert P.design_nodes(wT) == n_nodes
    assert P.design_nodes(wT * 1.01) == 2 * n_nodes
    T = 1.0
    f = wT / (2 * np.pi * (1 + U) * T)
    ax = jb.ModalAxis([f], [0.01])
    factors = np.concatenate([np.linspace(1 - U, 1 + U, 401), [1.0]])
    ref = np.array([1e-3])
    G, A = _batch()
    got, _ = P._evaluate_np(P._kernels_np(ax, T, factors, ref, n_nodes), 1, n_nodes, 0.1, T, G, A)
    fine, _ = P._evaluate_np(P._kernels_np(ax, T, factors, ref, 2 * n_nodes), 1, 2 * n_nodes, 0.1, T, G, A)
    assert np.max(np.abs(got - fine)) <= 1e-11 * np.max(fine)


def test_design_nodes_one_program_for_the_benchmark_axes():
    # the quadrature size is the designs' program's only shape that follows the move time: one size for 0.8-1.7 s
    # (256 nodes on 1 mode, 512 on 2-3 modes; `n_nodes_for` asked 1024 at 1.7 s there)
    for f, z in AXES.values():
        ax = jb.ModalAxis(f, z)
        w = float(np.max(np.asarray(ax.omega))) * (1 + U)
        assert len({P.design_nodes(w * T) for T in (0.8, 1.0, 1.3, 1.7)}) == 1


@pytest.mark.slow  # the designs' program and the curve's compile first: ~15 s
def test_pseudo_candidates_at_other_move_times_compile_nothing():
    # the pseudo-polynomial candidates of a 3-mode axis (`pseudo.designs_for`, then their rows' curves on the band
    # and the wide grid, as `measure._measure` computes them) at 0.8, 1.3 and 1.7 s after 1.0 s: no program compiles
    # (the designs' 512-node rule, the curve's `_curve_nodes`, the commands' exponents put on the device)
    from compiles import count_compiles

    from jaxbelt.shaping.bands import measure_grids
    from jaxbelt.shaping.residual import measured_curve, reference_residuals

    ax = jb.ModalAxis(*AXES[3])
    ref = np.asarray(reference_residuals(ax, 0.1, 0.3, 1.2, None, U)[0])
    grids = measure_grids(U)

    def candidates(T):
        designs = P.designs_for(ax, 0.1, T, (0.3, 1.2, None), ref, U)
        return {k: [measured_curve(ax, d.command, g) for g in grids] for k, d in designs.items()}, designs

    candidates(1.0)
    for T in (0.8, 1.3, 1.7):
        with count_compiles() as c:
            curves, designs = candidates(T)
        assert c["n"] == 0, T
        # the curves are the designs' own: the robust design's worst over the band (its 401 factors) is the one
        # the designs report, computed by another rule (the designs' kernels, another node count), to 1e-6: the
        # rounding of its clustered exponents' cancelling terms (measured 6e-8 at 1.3 s)
        band = curves[P.ROBUST][0] / ref[:, None]
        assert abs(float(band.max()) - designs[P.ROBUST].worst) <= 1e-6 * designs[P.ROBUST].worst
