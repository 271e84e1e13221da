"""The interior point method on the normal equations' Cholesky factor (`solve_lp_data(..., normal=True)`, the
minimax exchange's coarse and intermediate solves): scipy's HiGHS optimum of the same LP within its rigorous bracket
(lower bound, value) at the tolerance it is used at (1e-6), as the QR factorisation's, and the same certified vertex."""

import jax.numpy as jnp
import numpy as np
import pytest
from references import highs_lp_value

import jaxbelt as jb
from jaxbelt.shaping import design as dsg
from jaxbelt.shaping.lp import solve_lp_data
from jaxbelt.shaping.residual import reference_residuals


@pytest.mark.slow  # the interior point method's compilation: 5-20 s on two cores
@pytest.mark.parametrize(
    "freqs, zetas, T, tau",
    [([3.1, 9.7, 17.0], [0.03, 0.02, 0.01], 1.0, 0.0047), ([7.3, 18.0], [0.015, 0.01], 0.8, 0.01)],
)
def test_normal_equations_solve_the_minimax_lp_to_highs_optimum(freqs, zetas, T, tau):
    # the minimax LP of a design_move (u = 0.2) on its starting grid, padded to its knot slot, posed in units of about
    # its optimum (`tau`, as the exchange poses it): the Cholesky factor of the formed normal matrix reaches HiGHS's optimum of the
    # unpadded LP to 1e-6 (relative), as the QR factorisation does, and a certified vertex is the same vertex
    ax = jb.ModalAxis(freqs, zetas)
    opts = dsg.default_options(ax.frequencies, T, 0.2, False)
    slot = dsg._program_options(opts)
    ref, _ = reference_residuals(ax, 0.1, 0.3, 1.2, None, 0.2)
    prob = dsg.make_problem(ax, 0.1, T, 0.3, 1.2, None, 0.2, ref, opts)
    knots = dsg._knots(opts)
    c1, G1, h1, A1, b1, groups = dsg.lp_data_grouped(prob, slot, tau, knots)
    xb = dsg._x_bound(prob, slot, tau, knots)
    used = dsg._used_variables(slot, knots)
    highs = highs_lp_value(*(np.asarray(v) for v in dsg.lp_data(prob, opts, tau)))
    fast = solve_lp_data(c1, G1, h1, A1, b1, xb, 1e-6, 100, groups, used, True)
    exact = solve_lp_data(c1, G1, h1, A1, b1, xb, 1e-6, 100, groups, used, False)
    assert bool(fast.converged) and bool(exact.converged)
    # HiGHS's optimum lies in the rigorous bracket [lower_bound, value] of each, a bracket of at most 1e-4 (relative:
    # the dual bound is weak duality over a box), and the two factorisations agree to 1e-7
    for res in (fast, exact):
        lo, val = float(res.lower_bound), float(res.value)
        assert lo - 1e-12 <= highs <= val + 1e-9 * abs(val)
        assert val - lo <= 1e-4 * abs(val)
    assert float(fast.value) == pytest.approx(float(exact.value), rel=1e-7)
    x = np.asarray(fast.x)
    assert np.all(x[~np.asarray(used)] == 0.0)
    if bool(fast.vertex) and bool(exact.vertex):
        np.testing.assert_allclose(x, np.asarray(exact.x), rtol=1e-8, atol=1e-10)


@pytest.mark.slow  # the interior point method's compilation
def test_normal_equations_on_a_random_lp():
    # a random bounded LP (a box and 30 random cuts, two equalities): HiGHS's optimum to 1e-9 at tol 1e-10 (the
    # crossover certifies its vertex whatever the factorisation's accuracy)
    rng = np.random.default_rng(11)
    n, m = 12, 30
    G = np.concatenate([rng.normal(size=(m, n)), np.eye(n), -np.eye(n)])
    h = np.concatenate([rng.uniform(0.5, 2.0, m), np.full(2 * n, 3.0)])
    A = rng.normal(size=(2, n))
    b = A @ (0.05 * rng.normal(size=n))
    c = rng.normal(size=n)
    res = solve_lp_data(c, G, h, A, b, jnp.full(n, 3.0), 1e-10, 100, (), None, True)
    assert bool(res.converged) and bool(res.vertex)
    assert float(res.value) == pytest.approx(highs_lp_value(c, G, h, A, b), rel=1e-9)
