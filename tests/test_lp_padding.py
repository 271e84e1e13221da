"""The interior point LP with padded columns (`solve_lp_data(..., used=...)`) and the minimax LP padded to its knot
slot (`design.knot_slots`): the same optimum as the unpadded LP, by scipy's HiGHS, with the padding exactly 0."""

import jax.numpy as jnp
import numpy as np
import pytest
from references import highs_lp_value
from scipy.optimize import linprog

import jaxbelt as jb
from jaxbelt.shaping import design as dsg
from jaxbelt.shaping.lp import solve_lp_data
from jaxbelt.shaping.residual import reference_residuals


@pytest.mark.slow  # the interior point method's compilation: 5-20 s on two cores
def test_padded_columns_give_the_unpadded_lps_solution():
    # a random LP of 10 variables (bounded: a box and random cuts), its columns scattered among 16 with zero
    # columns between them (zero in c, G and A): the padded solve is HiGHS's optimum of the unpadded LP, its used
    # columns the unpadded solve's vertex, the padding exactly 0
    rng = np.random.default_rng(5)
    n, m = 10, 30
    G = np.concatenate([rng.normal(size=(m, n)), np.eye(n), -np.eye(n)])
    h = np.concatenate([rng.uniform(0.5, 2.0, m), np.full(2 * n, 3.0)])
    A = rng.normal(size=(2, n))
    b = A @ (0.05 * rng.normal(size=n))
    c = rng.normal(size=n)
    ref = linprog(c, A_ub=G, b_ub=h, A_eq=A, b_eq=b, bounds=[(None, None)] * n, method="highs")
    assert ref.status == 0
    cols = np.array([0, 1, 3, 4, 7, 8, 9, 12, 13, 15])  # the used columns among 16
    used = np.zeros(16, dtype=bool)
    used[cols] = True

    def pad(M):
        out = np.zeros((*M.shape[:-1], 16))
        out[..., cols] = M
        return out

    xb = np.full(16, 3.0) * used
    got = solve_lp_data(pad(c), pad(G), h, pad(A), b, jnp.asarray(xb), 1e-10, 100, (), jnp.asarray(used))
    plain = solve_lp_data(c, G, h, A, b, jnp.full(n, 3.0), 1e-10, 100)
    assert bool(got.converged) and bool(got.vertex) and bool(plain.vertex)
    assert float(got.value) == pytest.approx(ref.fun, rel=1e-9, abs=1e-12)
    x = np.asarray(got.x)
    assert np.all(x[~used] == 0.0)
    np.testing.assert_allclose(x[used], ref.x, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(x[used], np.asarray(plain.x), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(got.z), np.asarray(plain.z), rtol=1e-8, atol=1e-10)
    assert float(got.lower_bound) == pytest.approx(float(plain.lower_bound), rel=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("basis, jerk", [("spline", None), ("ramps", 40.0)])
def test_minimax_lp_padded_to_its_slot_is_the_unpadded_lp(basis, jerk):
    # a 3-mode design of 96 knot intervals (spline) or 160 (ramps) posed in its slot's program (128, 192 intervals):
    # the padded data hold the unpadded LP's rows and columns exactly and zeros elsewhere, and the padded solve's
    # value is HiGHS's optimum of the unpadded LP, the padding exactly 0
    ax = jb.ModalAxis([3.1, 9.7, 17.0], [0.03, 0.02, 0.01])
    T = 0.7 if basis == "spline" else 1.3
    opts = dsg.default_options(ax.frequencies, T, 0.2, jerk is not None, basis=basis)
    assert opts.n_knots == (96 if basis == "spline" else 160)
    slot = dsg._program_options(opts)
    assert slot.n_knots == dsg.knot_slots(opts.n_knots) == (128 if basis == "spline" else 192)
    ref, _ = reference_residuals(ax, 0.1, 0.3, 1.2, jerk, 0.2)
    prob = dsg.make_problem(ax, 0.1, T, 0.3, 1.2, jerk, 0.2, ref, opts)
    tau = 0.05
    c0, G0, h0, A0, b0 = (np.asarray(v) for v in dsg.lp_data(prob, opts, tau))
    knots = dsg._knots(opts)
    c1, G1, h1, A1, b1, groups = dsg.lp_data_grouped(prob, slot, tau, knots)
    J, Jp = dsg.n_coefficients(opts), dsg.n_coefficients(slot)
    cols = np.r_[np.arange(J), Jp]
    n_res = opts.n_angles * prob.factors.size
    sizes = [(J, Jp)] * 2 + [(J - 1, Jp - 1)] * 2 + ([(J + 1, Jp + 1)] * 2 if jerk is not None else [])
    rows, off = [np.arange(n_res)], n_res
    for keep, size in sizes:
        rows.append(off + np.arange(keep))
        off += size
    rows = np.concatenate(rows)
    G1, h1, A1, c1 = (np.asarray(v) for v in (G1, h1, A1, c1))
    assert G1.shape == (off, Jp + 1)
    np.testing.assert_allclose(G1[np.ix_(rows, cols)], G0, rtol=1e-13, atol=0)
    assert not np.delete(G1, cols, axis=1).any() and not np.delete(G1[:, cols], rows, axis=0).any()
    np.testing.assert_array_equal(h1[rows], h0)
    np.testing.assert_allclose(A1[:, cols], A0, rtol=1e-13, atol=0)
    assert not np.delete(A1, cols, axis=1).any() and not np.delete(c1, cols).any()
    xb = dsg._x_bound(prob, slot, tau, knots)
    used = dsg._used_variables(slot, knots)
    # tolerance 1e-8: on this first round's grid the interior point's dual residual stalls near 1e-9 on some CPUs
    # under XLA's quick options (design_move's own designs of this axis and time, with the exchange's grids, converge
    # there); the value is then checked against HiGHS's to 1e-7
    res = solve_lp_data(c1, G1, h1, A1, b1, xb, 1e-8, 100, groups, used)
    assert bool(res.converged)
    x = np.asarray(res.x)
    assert np.all(np.delete(x, cols) == 0.0)
    highs = highs_lp_value(c0, G0, h0, A0, b0)
    assert float(res.value) == pytest.approx(highs, rel=1e-7)
    # the padded LP's optimum is feasible for the unpadded one (to the solver's tolerance)
    assert np.max(G0 @ x[cols] - h0) <= 1e-8 and np.max(np.abs(A0 @ x[cols] - b0)) <= 1e-9


@pytest.mark.slow  # the LP data's and the fine check's compilations: ~8 s on two cores
def test_padded_lp_data_stay_finite_at_a_long_move_time():
    # the padded columns' basis functions would lie beyond the move's end, where e^{s(T - t)} grows as
    # e^{zeta omega (t - T)}: at T = 1e4 s on a 7.3 Hz mode that is e^{~1e4} (inf, and inf * 0 = NaN in the data).
    # Their exponent is held at 0: the padded data are finite and hold the unpadded LP's data exactly (the unpadded
    # LP, whose basis never leaves [0, T], is the reference), and the fine-grid check of padded coefficients is finite
    # and equals the unpadded command's
    ax = jb.ModalAxis([7.3, 18.0], [0.015, 0.01])
    T = 1.0e4
    opts = dsg.default_options(ax.frequencies, 0.8, 0.2, False)._replace(n_knots=96)
    slot = dsg._program_options(opts)
    assert slot.n_knots == 128
    ref, _ = reference_residuals(ax, 0.1, 0.3, 1.2, None, 0.2)
    prob = dsg.make_problem(ax, 0.1, T, 0.3, 1.2, None, 0.2, ref, opts)
    knots = dsg._knots(opts)
    G0 = np.asarray(dsg.lp_data(prob, opts, 0.05)[1])
    G1 = np.asarray(dsg.lp_data_grouped(prob, slot, 0.05, knots)[1])
    assert np.isfinite(G0).all() and np.isfinite(G1).all()
    J, Jp = dsg.n_coefficients(opts), dsg.n_coefficients(slot)
    n_res = opts.n_angles * prob.factors.size
    np.testing.assert_array_equal(G1[:n_res, :J], G0[:n_res, :J])
    assert not G1[:n_res, J:Jp].any()
    coef = np.random.default_rng(3).normal(size=J)
    padded = np.concatenate([coef, np.full(Jp - J, 7.0)])  # whatever the padding holds, it is not used
    f1, r1 = dsg._fine_ratios_program(prob, slot, jnp.asarray(padded), knots)
    f0, r0 = dsg._fine_ratios_program(prob, opts, jnp.asarray(coef), float(opts.n_knots))
    assert np.isfinite(np.asarray(r1)).all()
    np.testing.assert_allclose(np.asarray(r1), np.asarray(r0), rtol=1e-9, atol=0)  # sums of ~1e-12 terms: rounding


@pytest.mark.parametrize(
    "freqs", [[6.0], [7.3, 18.0], [3.1, 9.7, 17.0]], ids=["1 mode", "2 modes", "3 modes"]
)  # benchmarks/shaping_axis.py's axes
def test_knot_count_keeps_one_slot_from_0_8_to_1_7_s(freqs):
    # issue 54 item 5: a design at another move time of the same axis runs the LP compiled before. The rule's knot count
    # (6 per period of the band's top frequency, 20 % band) of the spline is capped at the least slot that keeps
    # KNOT_FILL of them: from 0.8 to 1.7 s every smooth design of these axes is posed in the slot of 128 intervals, with
    # at least 0.56 x 6 = 3.36 knots per period (the smallest here: 128 intervals over 1.7 s of 21.6 Hz, 3.49)
    for T in (0.8, 1.0, 1.3, 1.7):
        for jerk in (False, True):
            opts = dsg.default_options(freqs, T, 0.2, jerk)
            assert dsg.knot_slots(opts.n_knots) == 128, (T, jerk)
            assert opts.n_knots / (max(freqs) * 1.2 * T) >= 3.36
    # the knot count of the rule before the cap, where it fits: 6 per period rounded up to `KNOT_COUNTS`
    assert dsg.default_options(freqs, 0.8, 0.2, False).n_knots == (48 if len(freqs) == 1 else 128)
