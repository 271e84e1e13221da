"""The minimax design whose acceleration is continuous and piecewise linear, its jerk constant on each of N equal
intervals and jumping between them (basis "ramps": `design_move(..., smooth=False, j_max=...)`).

Checked against independent references: the LP's residual kernel against scipy's adaptive quadrature of the hat
function times $e^{s(T-t)}$; the design's residual against the Duhamel integral of `tests/references.py` (numpy
only), next to the best classic shaper's on the same S-curve limits; its limits on a dense grid of the command
evaluated by the reference's own formulas.
"""

import numpy as np
import pytest
from references import modal_residual_reference, piecewise_move_reference
from scipy.integrate import quad

import jaxbelt as jb
from jaxbelt.shaping import design as dsg
from jaxbelt.shaping.moves import PiecewiseMove, piecewise_peaks
from jaxbelt.shaping.shapers import SHAPERS


def _hat_integral(s: complex, t0: float, h: float, T: float) -> complex:
    """$\\int$ of the hat on $[t_0, t_0 + 2h]$ (peak 1 at $t_0 + h$) times $e^{s(T-t)}$, by scipy's quad, each half
    separately (the hat is smooth there), real and imaginary parts apart."""
    total = 0.0j
    for lo, up in ((t0, 1.0), (t0 + h, -1.0)):

        def f(t, part, lo=lo, up=up):
            hat = (t - lo) / h if up > 0 else 1.0 - (t - lo) / h
            v = hat * np.exp(s * (T - t))
            return v.real if part == 0 else v.imag

        re = quad(f, lo, lo + h, args=(0,), epsabs=0.0, epsrel=1e-13, limit=200)[0]
        im = quad(f, lo, lo + h, args=(1,), epsabs=0.0, epsrel=1e-13, limit=200)[0]
        total += re + 1j * im
    return total


def test_ramps_kernel_is_the_integral_of_the_hat():
    """The LP's residual rows for the ramps basis, $h e^{s(T-t_j)}\\varphi_1(-sh)^2$ times the row's weight
    $|g|/(\\omega_d R)\\,D/T^2$, against quad of the j-th hat (support $[jh, (j + 2)h]$) for two modes (one lightly,
    one strongly damped) at three frequency factors, to 1e-10 relative."""
    N, T, D = 16, 0.2, 0.1
    h = T / N
    opts = dsg.DesignOptions(n_knots=N, n_freq=3, n_extra=0, n_rounds=0, n_fine=3, jerk=True, basis="ramps")
    assert dsg.n_coefficients(opts) == N - 1
    axis = jb.ModalAxis([40.0, 7.0], [0.003, 0.1])
    problem = dsg.make_problem(axis, D, T, 1.0, 10.0, 500.0, 0.2, np.ones(2), opts)
    _, G, _, _, _ = dsg.lp_data(problem, opts)
    G = np.asarray(G)
    J, P = N - 1, opts.n_angles
    K = dsg.grid_slots(opts)  # the 3 factors in use, then the padding slots (never used) up to GRID_BUCKET
    MK = 2 * K
    # row p * MK + i K + k is Re(e^{-i theta_p} k_ik), theta_p = 2 pi p / P: p = 0 gives Re k, p = P/4 gives Im k
    kern = G[:MK, :J] + 1j * G[(P // 4) * MK : (P // 4 + 1) * MK, :J]
    gains = np.abs(np.asarray(axis.gains, float))
    for i, (f, z) in enumerate(((40.0, 0.003), (7.0, 0.1))):
        for k, r in enumerate((0.8, 1.0, 1.2)):
            g = i * K + k
            w = 2 * np.pi * f * r
            wd = w * np.sqrt(1 - z * z)
            s = -z * w + 1j * wd
            weight = gains[i] / wd * D / T**2  # references R = 1
            for j in (0, 6, J - 1):
                want = weight * _hat_integral(s, j * h, h, T)
                assert abs(kern[g, j] - want) <= 1e-10 * abs(want), (f, r, j, kern[g, j], want)


def _worst_m(axis, cmd: PiecewiseMove, factors):
    """The worst residual [m] over `factors` of every mode, by the independent Duhamel integral."""
    acc, _, _, breaks = piecewise_move_reference(cmd.times, cmd.steps, cmd.ramps, cmd.duration)
    res = modal_residual_reference(
        axis.frequencies, axis.damping_ratios, axis.gains, acc, breaks, float(cmd.duration), factors
    )
    return float(np.max(res))


def test_ramps_design_beats_the_best_shaper_on_its_own_s_curve_terms():
    """A 40 Hz, damping 0.003 axis, 0.1 m under |v| 0.3 m/s, |a| 1.2 m/s², |jerk| 20 m/s³: the best of Klipper's
    shapers (least worst residual over ±20 %) on the S-curve at its own shortest time; then the ramps design at that
    time with the shaper's own peak velocity, acceleration and jerk as its limits. By the independent evaluator, the
    design leaves no more than the shaper over the band; it respects the three limits (dense samples, 1e-6
    relative; `piecewise_peaks` equals the dense peaks) and moves the distance rest to rest."""
    axis = jb.ModalAxis([40.0], [0.003])
    d = 0.1
    first = jb.design_move(axis, d, None, v_max=0.3, a_max=1.2, j_max=20.0, uncertainty=0.2, include=SHAPERS)
    best = min((r for r in first.table if r.ok), key=lambda r: r.worst_percent)
    plan = jb.design_move(
        axis, d, best.move_time * (1 + 1e-9), v_max=best.peak_v, a_max=best.peak_a, j_max=best.peak_j,
        uncertainty=0.2, smooth=False, include=("minimax",),
    )  # fmt: skip
    row, mm = plan.candidate("minimax"), plan.minimax
    assert row.ok, row.note
    assert isinstance(mm, dsg.MinimaxDesign) and isinstance(row.command, PiecewiseMove)
    assert isinstance(best.command, PiecewiseMove)
    assert mm.options.basis == "ramps" and mm.options.jerk
    assert not np.isfinite(plan.continuous_bound)  # the steps design's certificate is not computed for ramps
    cmd = row.command
    factors = np.linspace(0.8, 1.2, 401)
    ramps_worst, shaper_worst = _worst_m(axis, cmd, factors), _worst_m(axis, best.command, factors)
    assert ramps_worst <= shaper_worst, (ramps_worst, shaper_worst, best.name)
    # the limits, on a dense grid (64 points per interval and the nodes) by the reference's formulas
    acc, vel, pos, _ = piecewise_move_reference(cmd.times, cmd.steps, cmd.ramps, cmd.duration)
    T = float(cmd.duration)
    t = np.linspace(0.0, T, 64 * mm.options.n_knots + 1)
    v, a = vel(t), acc(t)
    jerk = np.diff(a) / np.diff(t)
    peaks = (np.max(np.abs(v)), np.max(np.abs(a)), np.max(np.abs(jerk)))
    for got, lim in zip(peaks, (best.peak_v, best.peak_a, best.peak_j)):
        assert got <= lim * (1 + 1e-6), (got, lim)
    assert np.allclose(piecewise_peaks(cmd), peaks, rtol=1e-6, atol=0.0)
    assert float(pos(T + 1.0)) == pytest.approx(d, rel=1e-9)
    assert abs(float(vel(T))) <= 1e-9 * best.peak_v and abs(float(acc(T))) <= 1e-9 * best.peak_a


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(smooth=False, j_max=5.0, certify_rtol=0.01), "`certify_rtol` needs `j_max=None`"),
        (dict(smooth=False, j_max=-5.0), "j_max"),
    ],
)
def test_invalid_ramps_combinations_are_refused_by_name(kw, message):
    """`smooth=False` with a jerk limit is accepted (the ramps basis, above); the certificate's refinement, which
    bounds the steps design, is refused with it, and a jerk limit outside (0, inf) is refused by name."""
    with pytest.raises(ValueError, match=message):
        jb.design_move(jb.ModalAxis([5.5], [0.02]), 0.1, 1.0, v_max=0.3, a_max=1.2, **kw)
