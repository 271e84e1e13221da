"""`shortest_move_time` (refine=True) lands in one or two re-made designs (issue #54, item 4).

The answer is checked against an independent reference: `design_move`'s own design at that move time, its spline
command rebuilt with scipy's `BSpline` and its residual integrated by Gauss-Legendre quadrature (8 nodes per knot
interval: exact to round-off for the cubic pieces times the smooth exponential) on 2001 frequencies per mode over
the band f(1 ± u), as a fraction of the plan's reference (the unshaped move's worst residual): within 1 % of the
target. The work of a warm call is counted: at most two re-made designs (their exchange is most of a call's time)
and a few forward LPs on the design's grid.
"""

import numpy as np
import pytest
from scipy.interpolate import BSpline

import jaxbelt as jb
from jaxbelt.shaping import codesign

LIMITS = dict(v_max=0.3, a_max=1.2, uncertainty=0.2)
D = 0.1


def _worst_on_a_fine_band(plan, n_band: int = 2001) -> float:
    """Worst residual over each mode's band f(1 ± u) (n_band points), as a fraction of that mode's reference, of
    the plan's minimax spline: $A = |g| |\\int_0^T a(t) e^{s(T - t)} dt| / \\omega_d$, $s = -\\zeta\\omega + i\\omega_d$
    (the free vibration after a rest-to-rest move of q'' + 2ζωq' + ω²q = -g a(t))."""
    cmd = plan.minimax.command
    c = np.asarray(cmd.coefficients, dtype=float)
    T = float(cmd.duration)
    N = c.size + 3
    h = T / N
    # the j-th cubic B-spline on [jh, (j + 4) h]; three zero coefficients on each side make [0, T] scipy's base
    # interval (where the sum is the spline's, ends included)
    a = BSpline(h * np.arange(-3, N + 4), np.r_[np.zeros(3), c, np.zeros(3)], 3, extrapolate=False)
    x, w = np.polynomial.legendre.leggauss(8)
    t = (h * (np.arange(N)[:, None] + 0.5 * (x[None, :] + 1.0))).ravel()
    wt = np.tile(0.5 * h * w, N)
    at = a(t)
    worst = 0.0
    for f, z, g, ref in zip(
        np.asarray(plan.axis.frequencies),
        np.asarray(plan.axis.damping_ratios),
        np.asarray(plan.axis.gains),
        np.asarray(plan.reference_m),
        strict=True,
    ):
        om = 2 * np.pi * f * np.linspace(1 - LIMITS["uncertainty"], 1 + LIMITS["uncertainty"], n_band)
        wd = om * np.sqrt(1 - z * z)
        s = -z * om + 1j * wd
        W = np.exp(s[:, None] * (T - t[None, :])) @ (wt * at)
        worst = max(worst, float(np.max(abs(g) * np.abs(W) / wd / ref)))
    return worst


@pytest.mark.slow
def test_warm_calls_remake_at_most_two_designs_and_land_on_an_independent_fine_band(monkeypatch):
    axis = jb.ModalAxis([7.3], [0.015])
    design = jb.design_move(axis, D, 0.8, include=("minimax",), **LIMITS).minimax
    fw = float(design.fine_worst)
    jb.shortest_move_time(axis, 0.8 * fw, design)  # a first call: its grid values and re-made design are kept
    count = {"remade": 0, "lp": 0}
    redesign, value = codesign._redesign, codesign.minimax_value

    def counted_redesign(*a, **k):
        count["remade"] += 1
        return redesign(*a, **k)

    def counted_value(*a, **k):
        count["lp"] += 1
        return value(*a, **k)

    monkeypatch.setattr(codesign, "_redesign", counted_redesign)
    monkeypatch.setattr(codesign, "minimax_value", counted_value)
    for k in (0.5, 1.5):
        count.update(remade=0, lp=0)
        target = k * fw
        T = float(jb.shortest_move_time(axis, target, design))
        # was: 2-3 re-made designs and 4-7 LPs per warm call
        assert count["remade"] <= 2 and count["lp"] <= 5, count
        assert (T > 0.8) == (k < 1.0)
        plan = jb.design_move(axis, D, T, include=("minimax",), **LIMITS)
        fine = _worst_on_a_fine_band(plan)
        # the independent band agrees with the design's own fine grid (401 points), and meets the target
        assert fine == pytest.approx(float(plan.minimax.fine_worst), rel=2e-3)
        assert fine == pytest.approx(target, rel=1e-2)
        # the least such time: design_move's design 0.5 % sooner leaves more than the target
        sooner = jb.design_move(axis, D, T * 0.995, include=("minimax",), **LIMITS)
        assert _worst_on_a_fine_band(sooner) > target
