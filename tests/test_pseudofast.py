"""The faster paths of the design pipeline against independent references: the positions of a piecewise move as
executed (`moves.positions`) against the defining sum, the pseudo-polynomial peaks on the host (`pseudo._peaks_np`)
against the command's own derivatives, the batched host evaluation (`pseudo._evaluate_np`) against a run-by-run
computation from the definition, and the chained stages (`pseudo.run_chain`) against the stages run one by one."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import hull, moves
from jaxbelt.shaping import pseudo as P
from jaxbelt.shaping.moves import PiecewiseMove, fastest_time, padded
from jaxbelt.shaping.shaped import gentlest_shaped

jax.config.update("jax_enable_x64", True)


def _direct_positions(move, t):
    """$x(t) = \\sum_k \\alpha_k (t - t_k)_+^2/2 + \\beta_k (t - t_k)_+^3/6$ with t held at the duration: the definition,
    term by term, summed with math.fsum (correctly rounded)."""
    import math

    T = float(move.duration)
    tk, al, be = (np.asarray(q, dtype=float) for q in (move.times, move.steps, move.ramps))
    out = []
    for ti in np.minimum(np.asarray(t, dtype=float), T):
        d = np.maximum(ti - tk, 0.0)
        out.append(math.fsum(list(al * d**2 / 2) + list(be * d**3 / 6)))
    return np.array(out)


@pytest.mark.parametrize("jerk", [False, True])
def test_piecewise_positions_match_the_defining_sum(jerk):
    """A shaped trapezoid (ZVD on 7 Hz) and an S-curve (with a jerk limit), padded with zero terms at t = 0: the
    knot-to-knot positions at 1 kHz setpoints, off-grid times and past the end agree with the defining sum (math.fsum)
    to 1e-14 m (the distance 0.1 m; a relative 1e-13)."""
    base = jb.ModalAxis([7.0], [0.02])
    j_max = 40.0 if jerk else None
    cmd, _, _ = gentlest_shaped("ZVD", base, 0.1, 1.2, fastest_time(0.1, 0.3, 1.2, j_max), 0.3, 1.2, j_max)
    assert isinstance(cmd, PiecewiseMove)
    cmd = padded(cmd, int(cmd.times.shape[0]) + 7)
    T = float(cmd.duration)
    t = np.concatenate([moves.sample_times(T, 1000.0), np.linspace(0.0, T, 37) + 1e-4, [T, T + 0.3]])
    x = moves.positions(cmd, t)
    ref = _direct_positions(cmd, t)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-14)
    assert abs(x[-1] - 0.1) < 1e-14  # held at the distance after the end


def test_host_peaks_match_the_commands_derivatives():
    """`_peaks_np` (one power per instant and exponent) against `PseudoPolynomial.derivative` (the coefficients from
    the linear solve of eq. 22) on the same 20001 instants: the 3-4-5 polynomial (closed form: peak v = 1.875 D/T,
    a = 5.7735 D/T^2, jerk = 60 D/T^3) and a clustered robust-like set."""
    D, T = 0.1, 0.8
    pk = P._peaks_np(np.array([3.0, 4.0, 5.0]), D, T)
    np.testing.assert_allclose(pk, [1.875 * D / T, 10 / np.sqrt(3) * D / T**2, 60 * D / T**3], rtol=1e-7)
    g = np.array([4.19, 7.43, 7.93, 8.43, 8.93])
    cmd = jb.PseudoPolynomial(jnp.asarray(g), D, T)
    ts = jnp.linspace(0.0, T, 20001)
    ref = [float(jnp.max(jnp.abs(cmd.derivative(ts, k)))) for k in (1, 2, 3)]
    np.testing.assert_allclose(P._peaks_np(g, D, T), ref, rtol=1e-9)


def test_batched_host_evaluation_matches_the_definition():
    """`_evaluate_np` on a batch of padded exponents (two orders) against each run computed alone from the
    definition: ratios $|\\sum_j \\kappa_j f_j|$ with $f_j = \\sum_l C_l\\gamma_l(\\gamma_l - 1)v_j^{4(\\gamma_l-1)}$
    and the peaks' smooth maxima, to 1e-12 (relative to the largest ratio)."""
    axis = jb.ModalAxis([3.1, 9.7], [0.03, 0.02])
    n = 256
    kern = P._kernels_np(axis, 1.0, np.linspace(0.8, 1.2, 9), np.array([1e-3, 2e-3]), n)
    g = np.array([[3.0, 4.0, 5.0, 6.5, 8.0], [4.2, 7.4, 7.9, 8.4, 8.9]])
    act = np.array([[1.0, 1.0, 1.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]])
    r, pk = P._evaluate_np(kern, 2, n, 0.1, 1.0, g, act)
    v, _ = P._gauss_legendre(n)
    for b in range(2):
        gb = g[b][act[b] > 0]
        C = np.array([np.prod([gj / (gj - gi) for gj in gb if gj != gi]) for gi in gb])
        f = (v[:, None] ** (4 * (gb - 1))) @ (C * gb * (gb - 1))
        y = (kern @ f).reshape(2, 2, -1)
        ref = 0.1 * np.hypot(y[0], y[1])
        np.testing.assert_allclose(r[b], ref, rtol=0, atol=1e-12 * ref.max())
        u = np.arange(1, P.N_PEAK + 1) / P.N_PEAK
        vel = (u[:, None] ** (gb - 1)) @ (C * gb)
        q = np.abs(vel)
        smooth = q.max() * np.sum((q / q.max()) ** P.PEAK_Q) ** (1 / P.PEAK_Q)
        np.testing.assert_allclose(pk[b, 0], smooth * 0.1 / 1.0, rtol=1e-12)


@pytest.mark.slow  # two optimiser programs compiled: ~10 s
def test_chained_stages_reach_what_the_stages_one_by_one_reach():
    """`run_chain` (two powers in one loop per run) against `run_stage` (the optimiser `optimise_robust` shares) called
    once per power from the stage before's best iterate: the robust measure of orders 2 and 3 on a 4.96 Hz mode
    (ζ = 0.026, ±20 %) ends at the same value to 1e-6 (the stopping tests' resolution: gradient 1e-4 on the log), the
    same reasons, within 5 iterations."""
    axis = jb.ModalAxis([4.96], [0.026])
    D, T, u, n = 0.1, 1.0, 0.2, 256
    factors = np.concatenate([np.linspace(1 - u, 1 + u, P.N_BAND), [1.0]])
    ref = np.array([1e-3])
    kern = P._f(P._kernels_np(axis, T, factors, ref, n))
    band_w = np.zeros((1, P.N_BAND + 1))
    band_w[:, : P.N_BAND] = 1.0 / P.N_BAND
    sh = P.make_shared(kern, n, band_w, np.ones(1), np.full(1, np.inf), D, T, (10.0, 100.0, None))
    slots = 5
    act = np.array([[1.0] * 3 + [0.0] * 2, [1.0] * 4 + [0.0] * 1])
    lower, gap = np.array([2.0, 3.0]), 0.5
    theta0 = P._f(np.stack([P._params_np(P.classical_start(k, b, gap, slots), b, P.MARGIN, gap, P.MAX_STEP)
                            for k, b in zip((2, 3), lower)]))  # fmt: skip
    powers, steps = (4.0, 16.0), (60, 80)
    th = theta0
    one_by_one = []
    for p, k in zip(powers, steps):
        runs = P.make_runs(act, lower, gap, p=p, w_band=1.0, gtol=P.ROBUST_GTOL, gtol_loose=P.ROBUST_GTOL_LOOSE,
                           max_iter=k)  # fmt: skip
        st = P.run_stage(P.LBFGS, sh, runs, th)
        th = st.theta
        one_by_one.append(st)
    N = P.N_CHAIN
    per = np.zeros((2, N))
    per[:, :2] = powers
    it = np.zeros((2, N), dtype=np.int32)
    it[:, :2] = steps
    chain = P.make_chain(act, lower, gap, p=per, w_band=1.0, gtol=P.ROBUST_GTOL, gtol_loose=P.ROBUST_GTOL_LOOSE,
                         max_iter=it)  # fmt: skip
    zeros = P._f(np.zeros((2, N)))
    out = P.run_chain(sh, chain, zeros, theta0, jnp.full((2,), 2, dtype=jnp.int32), P._f(np.full(2, np.nan)))
    last = one_by_one[-1]
    np.testing.assert_allclose(np.asarray(out.value), np.asarray(last.value), rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(out.reason), np.asarray(last.reason))
    total = sum(np.asarray(s.n_iter) for s in one_by_one)
    assert np.all(np.abs(np.asarray(out.n_iter) - total) <= 5), (out.n_iter, total)


def test_executed_ratios_kept_are_those_of_the_same_command_and_reference():
    """`executed_ratios` keeps its last results by identity of command and axis: the same call again returns the
    same numbers, a doubled reference half of them (the ratio's definition), a rebuilt equal command the same, and a
    new rate its own (against `executed_integral` of the positions, computed here)."""
    axis = jb.ModalAxis([7.0, 18.0], [0.02, 0.01])
    cmd, _, _ = gentlest_shaped("ZV", axis, 0.1, 1.0, fastest_time(0.1, 0.3, 1.2, None), 0.3, 1.2, None)
    fac, ref = np.linspace(0.8, 1.2, 5), np.array([1e-3, 2e-3])
    a = hull.executed_ratios(axis, cmd, ref, fac, 1000.0)
    np.testing.assert_array_equal(hull.executed_ratios(axis, cmd, ref, fac, 1000.0), a)
    np.testing.assert_allclose(hull.executed_ratios(axis, cmd, 2 * ref, fac, 1000.0), a / 2, rtol=1e-15)
    twin = PiecewiseMove(cmd.times, cmd.steps, cmd.ramps, cmd.duration)
    np.testing.assert_allclose(hull.executed_ratios(axis, twin, ref, fac, 1000.0), a, rtol=1e-15)
    for rate in (1000.0, 250.0):
        t = moves.sample_times(float(cmd.end_time), rate)
        w = np.asarray(axis.omega)[:, None] * fac[None, :]
        z = np.asarray(axis.damping_ratios)[:, None]
        wd = w * np.sqrt(1 - z**2)
        W = hull.executed_integral(t, _direct_positions(cmd, t), -z * w + 1j * wd)
        ref_r = np.abs(np.asarray(axis.gains))[:, None] * W / (wd * ref[:, None])
        np.testing.assert_allclose(hull.executed_ratios(axis, cmd, ref, fac, rate), ref_r, rtol=1e-9, atol=1e-12)


def test_a_one_stage_chain_runs_its_first_slot_only():
    # `make_chain` with `max_iter` a scalar or one value per run is one stage (the feasibility stage's use): the
    # other slots get 0 iterations, so a run that ends its stage is not restarted N_CHAIN - 1 more times
    act = np.ones((3, 4))
    for it in (200, np.array([200, 0, 50])):
        got = np.asarray(P.make_chain(act, 0.0, 1.0, max_iter=it).max_iter)
        assert got.shape == (3, P.N_CHAIN)
        assert np.array_equal(got[:, 0], np.broadcast_to(it, (3,)))
        assert not got[:, 1:].any()
    per_slot = np.arange(3 * P.N_CHAIN).reshape(3, P.N_CHAIN)
    assert np.array_equal(np.asarray(P.make_chain(act, 0.0, 1.0, max_iter=per_slot).max_iter), per_slot)


def test_positions_of_a_move_without_terms_are_zero():
    move = PiecewiseMove(jnp.zeros(0), jnp.zeros(0), jnp.zeros(0), 1.0)
    assert np.array_equal(moves.positions(move, np.linspace(0.0, 1.5, 7)), np.zeros(7))
