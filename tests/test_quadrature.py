"""The pseudo-polynomials' Gauss-Legendre rule (`jaxbelt.shaping.quadrature`) above what one rule resolves: the
composite rule of `rule_nodes` against closed forms and scipy, and a clear error beyond its reach."""

import numpy as np
import pytest
from scipy import integrate

import jaxbelt as jb
from jaxbelt.shaping import quadrature as Q
from jaxbelt.shaping import residual
from jaxbelt.shaping.residual import residual_curve


def _moment_closed_form(gamma, wt):
    """$\\int_0^1 u^{\\gamma-2} e^{i\\omega T u} du$ for gamma = 2 and 3 (integration by parts)."""
    e = np.exp(1j * wt)
    if gamma == 2:
        return (e - 1.0) / (1j * wt)
    return e / (1j * wt) + (e - 1.0) / wt**2


@pytest.mark.parametrize("wt", [7500.0, 15000.0, 38000.0])
@pytest.mark.parametrize("gamma", [2, 3])
def test_composite_rule_resolves_the_residual_moments(wt, gamma):
    # the rule in v (u = v^4) as the residual curves use it, against the closed form: 1e-12 absolute (the integrand
    # is at most 4 in v, the moments 3e-5 to 1e-4: rounding of the ~1e4-term sum)
    n = Q.rule_nodes(wt)
    assert n > Q.MAX_NODES and n % Q.PANEL_NODES == 0
    v, w = Q.gauss_legendre_01(n)
    assert v.shape == w.shape == (n,) and abs(float(np.sum(w)) - 1.0) <= 1e-13
    got = np.sum(w * 4.0 * v ** (4 * (gamma - 1) - 1) * np.exp(1j * wt * v**4))
    assert abs(got - _moment_closed_form(gamma, wt)) <= 1e-12


def test_rule_nodes_below_the_composite_range_unchanged_and_refused_beyond_it():
    # one rule up to SINGLE_MAX_OMEGA_T: 0.75 wT + 64 rounded up to a power of two in [512, 4096]
    for wt in (0.0, 500.0, 597.0, 1000.0, 3000.0, 5376.0, 7000.0):
        need = 0.75 * wt + 64
        want = next((n for n in (512, 1024, 2048, 4096) if n >= need), 4096)
        assert Q.rule_nodes(wt) == want
    assert Q.rule_nodes(7001.0) == 16 * Q.PANEL_NODES  # 16 panels of 438 rad
    assert Q.rule_nodes(9601.0) == 32 * Q.PANEL_NODES  # 32 panels of 300 rad
    assert Q.rule_nodes(38400.0) == Q.MAX_COMPOSITE_NODES
    with pytest.raises(ValueError, match=r"omega\*T = 38401 rad .* above 38400 rad"):
        Q.rule_nodes(38401.0)


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # QAWO at rounding: 1e-12 asked
@pytest.mark.slow  # scipy's QAWO to 1e-12 and the curve's 16384-node program: ~10 s
def test_residual_of_a_pseudo_polynomial_on_a_fast_lightly_damped_mode_against_scipy():
    # a 1200 Hz, zeta 0.001 mode after a 1.5 s 3-4-5 move: omega T = 11310 rad at the nominal frequency, 13572 at +20 %
    # (one 4096-node rule resolved up to ~7500). Reference: scipy's QAWO (weights cos, sin) of
    # int_0^T a(T - s) e^{-zeta w s} e^{i wd s} ds, the residual amplitude gain / wd |W| (1e-7 relative)
    D, T, f, z = 0.1, 1.5, 1200.0, 0.001
    cmd = jb.PseudoPolynomial(np.array([3.0, 4.0, 5.0]), D, T)
    ax = jb.ModalAxis([f], [z])
    for r in (1.0, 1.2):
        w = 2 * np.pi * f * r
        wd = w * np.sqrt(1 - z**2)

        def env(s, w=w):
            return float(cmd.acceleration(T - s)) * np.exp(-z * w * s)

        re = integrate.quad(env, 0.0, T, weight="cos", wvar=wd, limit=2000, epsabs=0.0, epsrel=1e-12)[0]
        im = integrate.quad(env, 0.0, T, weight="sin", wvar=wd, limit=2000, epsabs=0.0, epsrel=1e-12)[0]
        ref = abs(complex(re, im)) / wd
        got = float(np.asarray(residual_curve(ax, cmd, r))[0, 0])
        assert abs(got - ref) <= 1e-7 * ref, (r, got, ref)


@pytest.mark.parametrize("wt", [12000.0, 30000.0])
def test_asymptotic_closed_form_beyond_the_rules_reach_agrees_with_the_rule(monkeypatch, wt):
    # `_pseudo_polynomial_w` beyond `REACH_OMEGA_T` takes Gamma(a, p)'s asymptotic series: with the reach lowered
    # to 10000 rad it must agree with the composite rule (valid to 38400) on a 3-4-5 and a fractional move: 1e-13 m/s
    # absolute, the rule's own rounding (W, 1e-10 to 1e-7 m/s, is 1e3-1e6 times below the terms the rule sums; a wrong
    # series term is off by W itself)
    D, T = 0.1, 1.0
    s = np.array([-0.002 * wt + 1j * wt, -0.0 + 1j * wt * 1.1, -0.05 * wt + 1j * wt * 0.9]) / T
    for g in ([3.0, 4.0, 5.0], [3.3, 4.7, 5.9, 7.2]):
        cmd = jb.PseudoPolynomial(np.array(g), D, T)
        rule = residual._rule(Q.rule_nodes(1.1 * wt))
        by_rule = np.asarray(residual._pseudo_polynomial_w(cmd, s, rule))
        monkeypatch.setattr(residual, "REACH_OMEGA_T", 10000.0)
        closed = np.asarray(residual._pseudo_polynomial_w(cmd, s, rule))
        monkeypatch.undo()
        assert np.max(np.abs(closed - by_rule)) <= 1e-13


@pytest.mark.slow  # a first design_move: ~12 s
def test_design_move_on_a_fast_lightly_damped_mode_beyond_the_rules_reach():
    # a 1500 Hz, zeta 0.002 mode in a 3 s move: omega T up to 42400 rad over the wide range (was a ValueError); the
    # table holds every row, each finite
    ax = jb.ModalAxis([8.0, 1500.0], [0.02, 0.002])
    p = jb.design_move(ax, 0.2, 3.0, v_max=0.5, a_max=2.0, include=("ZV", "pseudo-polynomial"))
    names = {r.name for r in p.table}
    assert "ZV" in names and any(n.startswith("pseudo-polynomial") for n in names)
    assert all(np.isfinite(r.worst_percent) for r in p.table)
