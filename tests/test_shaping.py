"""Command shaping (Incerti, pseudo-polynomial commands): pseudo-polynomial commands, residual energy H, optimisation.

Every number is checked against an independent reference: the paper's tables, closed forms
(Lagrange coefficients, the classical 3-4-5 polynomial), scipy.integrate.quad at tight
tolerance, a diffrax solve of eq. (4), a simulate() run of the platform model, or central
finite differences.
"""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

import jaxbelt as jb
from jaxbelt.commands import PseudoPolynomial
from jaxbelt.objectives.residual import convolution_integrals
from jaxbelt.optimise.command import gammas_from_params, params_from_gammas, shaped_commands

PHI = 15 * 2 * np.pi
G345 = jnp.array([3.0, 4.0, 5.0])
PAPER_OPT = jnp.array([3.024, 4.565, 5.874])


def _cmd(g, **kw):
    return PseudoPolynomial(jnp.asarray(g, dtype=float), **kw)


def _lagrange(g):
    g = np.asarray(g, dtype=float)
    return np.array([np.prod([g[j] / (g[j] - g[i]) for j in range(len(g)) if j != i]) for i in range(len(g))])


def _random_gammas(rng, n, lo):
    while True:
        g = np.sort(rng.uniform(lo + 0.2, lo + 7.0, n + 1))
        if np.min(np.diff(g)) > 0.3:
            return g


def _h_scipy(plat, g, phi=PHI, T=1.0):
    """H of eq. (30)-(32) by adaptive quadrature of the convolution integrals."""
    g = np.asarray(g, dtype=float)
    C = _lagrange(g)
    P2 = g * (g - 1)
    sigma = float(plat.damping_ratio * plat.omega_n)
    wd, wn = float(plat.omega_d), float(plat.omega_n)
    acc = lambda t: -phi / T**2 * np.sum(P2 * C * (1 - t / T) ** (g - 2))  # noqa: E731
    kw = dict(epsabs=0.0, epsrel=1e-13, limit=400)
    with warnings.catch_warnings():
        # quad warns that 1e-13 is at the roundoff floor; its result is still accurate to ~1e-13
        warnings.simplefilter("ignore")
        F = quad(lambda t: acc(t) * np.exp(-sigma * (T - t)) * np.sin(wd * (T - t)), 0, T, **kw)[0]
        Cc = quad(lambda t: acc(t) * np.exp(-sigma * (T - t)) * np.cos(wd * (T - t)), 0, T, **kw)[0]
    G = wd * Cc - sigma * F
    return G**2 + wn**2 * F**2


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------
def test_coefficients_paper_table_ii():
    # Table II (3 decimals)
    np.testing.assert_allclose(_cmd(G345).coefficients, [10.0, -15.0, 6.0], atol=1e-12)
    np.testing.assert_allclose(_cmd([4.5, 6.2, 8.4]).coefficients, [7.855, -10.107, 3.252], atol=6e-4)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_coefficients_match_lagrange_closed_form(n):
    # The system (21) says sum_i C_i q(gamma_i) = q(0) for every polynomial q of degree <= n,
    # so C_i is the Lagrange basis polynomial at 0: prod_{j != i} gamma_j / (gamma_j - gamma_i).
    g = _random_gammas(np.random.default_rng(n), n, max(n, 2))
    np.testing.assert_allclose(_cmd(g).coefficients, _lagrange(g), rtol=1e-10)


def test_integer_case_is_the_classical_polynomial():
    cmd = _cmd(G345, displacement=2.0, duration=0.5)
    t = np.linspace(-0.1, 0.6, 71)
    s = np.clip(t / 0.5, 0, 1)
    pos = 2.0 * (10 * s**3 - 15 * s**4 + 6 * s**5)
    vel = 2.0 / 0.5 * (30 * s**2 - 60 * s**3 + 30 * s**4)
    acc = 2.0 / 0.25 * (60 * s - 180 * s**2 + 120 * s**3)
    np.testing.assert_allclose(cmd(t), pos, atol=1e-12)
    np.testing.assert_allclose(cmd.velocity(t), vel, atol=1e-11)
    np.testing.assert_allclose(cmd.acceleration(t), acc, atol=1e-10)


def test_kth_derivative_matches_autodiff_and_boundary_conditions():
    g = [4.3, 5.1, 6.7, 9.2]  # n = 3
    cmd = _cmd(g, displacement=3.0, duration=1.3)
    ts = jnp.linspace(0.05, 1.25, 13)
    f = lambda t: cmd(t)  # noqa: E731
    f1 = jax.grad(f)
    f2 = jax.grad(f1)
    f3 = jax.grad(f2)

    @jax.jit
    def both(ts):
        auto = jnp.stack([jax.vmap(fk)(ts) for fk in (f1, f2, f3)])
        ours = jnp.stack([cmd.derivative(ts, k) for k in (1, 2, 3)])
        ends = jnp.stack([cmd.derivative(jnp.array([0.0, 1.3]), k) for k in range(4)])
        return auto, ours, ends

    auto, ours, ends = both(ts)
    np.testing.assert_allclose(ours, auto, rtol=1e-9, atol=1e-9)
    # eq. (20) and (11): the command starts at rest and ends at Phi, n derivatives zero at both ends
    np.testing.assert_allclose(ends[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(ends[:, 1], [3.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_coefficient_gradient_matches_finite_differences():
    g = jnp.array([3.3, 4.9, 6.1])
    jac = jax.jacfwd(lambda x: _cmd(x).coefficients)(g)
    h = 1e-6
    for i in range(3):
        e = jnp.zeros(3).at[i].set(h)
        fd = (_cmd(g + e).coefficients - _cmd(g - e).coefficients) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, rtol=1e-7)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(gammas=[2.0, 4.0, 5.0]), "gammas"),
        (dict(gammas=[1.5, 4.0, 5.0]), "gammas"),
        (dict(gammas=[3.0, 4.0, 4.0]), "at least 0.001"),
        (dict(gammas=[2.5, 4.0, 5.0, 6.0]), "gammas"),  # n = 3 needs every exponent > 3
        (dict(gammas=[3.0, 4.0, 5.0], duration=0.0), "duration"),
        (dict(gammas=[3.0, 4.0, 5.0], duration=-1.0), "duration"),
        (dict(gammas=[[3.0, 4.0, 5.0]]), "1-D"),
    ],
)
def test_bad_command_parameters_raise(kwargs, match):
    kwargs = dict(kwargs)
    g = jnp.asarray(kwargs.pop("gammas"), dtype=float)
    with pytest.raises(ValueError, match=match):
        PseudoPolynomial(g, **kwargs)


@pytest.mark.parametrize("field, value", [("J", 0.0), ("J", -6.0), ("k", 0.0), ("R", -0.1), ("c", -1.0)])
def test_bad_platform_parameters_raise(field, value):
    with pytest.raises(ValueError, match=field):
        jb.BeltPlatform(**{field: value})


def test_overdamped_platform_raises():
    with pytest.raises(ValueError, match="underdamped"):
        jb.BeltPlatform(c=1e4)


def test_infeasible_exponents_under_jit_raise():
    plat = jb.BeltPlatform()
    f = jax.jit(lambda g: jb.residual_energy(plat, PseudoPolynomial(g)))
    with pytest.raises(Exception, match="at least 0.001 apart and each > 2"):
        f(jnp.array([3.0, 3.0, 5.0])).block_until_ready()


# --------------------------------------------------------------------------------------------
# Platform and residual energy
# --------------------------------------------------------------------------------------------
def test_platform_table_iii_derived_constants():
    p = jb.BeltPlatform()
    assert float(p.lam) == pytest.approx(0.1 * 0.06 / 0.18, rel=1e-15)
    # 15 motor revolutions turn the platform by 180 degrees (section V)
    assert float(p.lam * PHI) == pytest.approx(np.pi, rel=1e-14)
    assert float(p.omega_n) == pytest.approx(np.sqrt(2 * 9e4 * 0.18**2 / 6), rel=1e-14)
    assert float(p.damping_ratio) == pytest.approx(float(2 * 150 * 0.18**2 / (2 * 6 * p.omega_n)), rel=1e-14)


@pytest.mark.parametrize("g", [G345, PAPER_OPT, jnp.array([2.05, 2.6, 7.3]), jnp.array([4.5, 6.2, 8.4])])
def test_residual_energy_quadrature_matches_scipy(g):
    p = jb.BeltPlatform()
    ref = _h_scipy(p, g)
    tol = 1e-10 if ref > 1.0 else 1e-7  # near the optimum H is a cancellation residue
    assert float(jb.residual_energy(p, _cmd(g))) == pytest.approx(ref, rel=tol)


def test_two_h_computations_agree_at_345_and_random_exponents():
    p = jb.BeltPlatform()
    rng = np.random.default_rng(3)
    gs = jnp.asarray(np.stack([np.asarray(G345)] + [_random_gammas(rng, 2, 2.0) for _ in range(4)]))
    hq = jax.vmap(lambda g: jb.residual_energy(p, PseudoPolynomial(g)))(gs)
    ho = jax.jit(jax.vmap(lambda g: jb.residual_energy(p, PseudoPolynomial(g), method="ode")))(gs)
    np.testing.assert_allclose(hq, ho, rtol=1e-8)


def test_paper_optimum_reduces_h_by_a_million():
    p = jb.BeltPlatform()
    h0 = jb.residual_energy(p, _cmd(G345))
    h1 = jb.residual_energy(p, _cmd(PAPER_OPT))
    assert float(h1) <= 1e-6 * float(h0)


def test_platform_simulation_energy_at_T_matches_h_times_h():
    # simulate() integrates eq. (2) in (theta, omega); the residual energy at T must equal h*H
    # from the convolution integrals (eq. 31).
    p = jb.BeltPlatform()
    for g in (G345, jnp.array([4.5, 6.2, 8.4])):
        cmd = _cmd(g)
        sol = jb.simulate(
            jb.Scene(p, cmd, ts=jnp.array([0.0, 0.5, 1.0]), observe=("kinetic_energy", "elastic_energy")),
            method="ode",
            rtol=1e-12,
            atol=1e-13,
        )
        e_sim = sol.kinetic_energy[-1] + sol.elastic_energy[-1]
        e_ref = jb.residual_energy_joules(p, cmd)
        assert float(e_sim) == pytest.approx(float(e_ref), rel=1e-6)
        # half way the platform lags the rigid command; its angle is the command plus alpha
        assert float(sol.theta[-1]) == pytest.approx(np.pi, abs=1e-2)


def test_residual_energy_gradient_matches_finite_differences_also_under_vmap():
    p = jb.BeltPlatform()
    H = lambda g: jb.residual_energy(p, PseudoPolynomial(g))  # noqa: E731
    gs = jnp.array([[3.0, 4.0, 5.0], [3.3, 4.9, 6.1], [4.5, 6.2, 8.4]])
    grads = jax.jit(jax.vmap(jax.grad(H)))(gs)
    h = 1e-5
    steps = jnp.concatenate([jnp.eye(3) * h, -jnp.eye(3) * h])  # (6, 3)
    Hs = jax.jit(jax.vmap(jax.vmap(H, in_axes=0), in_axes=0))(gs[:, None, :] + steps[None, :, :])
    fd = (Hs[:, :3] - Hs[:, 3:]) / (2 * h)
    np.testing.assert_allclose(grads, fd, rtol=1e-5)
    np.testing.assert_allclose(jax.jit(jax.grad(H))(gs[1]), grads[1], rtol=1e-12)


def test_residual_energy_gradient_wrt_platform_stiffness_under_vmap():
    cmd = _cmd(G345)
    E = lambda k: jb.residual_energy_joules(jb.BeltPlatform(k=k), cmd)  # noqa: E731
    ks = jnp.array([7e4, 9e4, 1.1e5])
    grads = jax.jit(jax.vmap(jax.grad(E)))(ks)
    Ev = jax.jit(jax.vmap(E))
    fd = (Ev(ks * (1 + 1e-6)) - Ev(ks * (1 - 1e-6))) / (2e-6 * ks)
    np.testing.assert_allclose(grads, fd, rtol=1e-5)


# --------------------------------------------------------------------------------------------
# Input shapers and sensitivity
# --------------------------------------------------------------------------------------------
def test_zv_zvd_cancel_the_design_mode_and_agree_with_ode_off_design():
    """At equal move time (the default): the shaped commands end at T = 1 s like the base, whose pseudo-polynomial
    is shortened by the shaper's length (pi/omega_d for ZV, 2 pi/omega_d for ZVD, Singer and Seering 1990); they
    cancel the design mode, keep the displacement, and off design follow the ODE of eq. (4). `equal_time=False`
    lengthens the move instead."""
    p = jb.BeltPlatform()
    base = _cmd(G345)
    e0 = float(jb.residual_energy_joules(p, base))
    shapers = shaped_commands(p, base)
    half = np.pi / float(p.omega_d)
    for (name, cmd), length in zip(shapers.items(), (half, 2 * half)):
        assert float(cmd.end_time) == pytest.approx(1.0, rel=1e-14), name
        assert float(cmd.base.duration) == pytest.approx(1.0 - length, rel=1e-12)
        assert float(jb.residual_energy_joules(p, cmd)) < 1e-20 * e0
        assert float(cmd(cmd.end_time)) == pytest.approx(PHI, rel=1e-14)
    for (name, cmd), length in zip(shaped_commands(p, base, equal_time=False).items(), (half, 2 * half)):
        assert float(cmd.end_time) == pytest.approx(1.0 + length, rel=1e-12), name
    # off design the shaper's residual follows from linearity; check it against the ODE
    q = p.with_natural_frequency(1.2 * p.omega_n)
    assert float(q.omega_n) == pytest.approx(1.2 * float(p.omega_n), rel=1e-14)
    both = eqx.filter_jit(lambda q, c: (jb.residual_energy(q, c), jb.residual_energy(q, c, method="ode")))
    for cmd in shapers.values():
        hq, ho = both(q, cmd)
        assert float(hq) == pytest.approx(float(ho), rel=1e-7)
    with pytest.raises(ValueError, match="ZVD shaper lasts"):
        shaped_commands(p, _cmd(G345, duration=0.15))


def _amplitude_scipy(plat, omega, acc, T):
    """Residual amplitude of the platform's deflection after a move of motor acceleration `acc(t)` ending at T, on
    the platform with its stiffness scaled to natural frequency `omega` (J, c kept): solve_ivp of eq. (4)."""
    xi = float(plat.damping_ratio) * float(plat.omega_n) / omega
    lam = float(plat.lam)
    sol = solve_ivp(
        lambda t, y: [y[1], -2 * xi * omega * y[1] - omega**2 * y[0] - lam * acc(t)],
        (0.0, T),
        [0.0, 0.0],
        method="DOP853",
        rtol=1e-12,
        atol=1e-15,
    )
    a, ad = sol.y[:, -1]
    wd = omega * np.sqrt(1 - xi**2)
    return float(np.hypot(a, (ad + xi * omega * a) / wd))


def test_sensitivity_curve_amplitudes_match_scipy_and_energy_is_labelled():
    """The sensitivity curve's default measure is the residual amplitude of the platform's deflection [rad]: against
    solve_ivp of eq. (4) for the 3-4-5 polynomial and its ZV-shaped version (equal time) at 0.8, 1 and 1.2 omega_n;
    measure="energy" is the paper's E(T) = h H."""
    p = jb.BeltPlatform()
    base = _cmd(G345)
    zv = shaped_commands(p, base)["ZV"]
    omegas, amp = jb.sensitivity_curve(p, {"345": base, "ZV": zv}, rel=0.2, n=3)
    _, energy = jb.sensitivity_curve(p, {"345": base}, rel=0.2, n=3, measure="energy")

    def acc345(t, T=1.0):
        s = np.clip(t / T, 0, 1)
        return PHI / T**2 * (60 * s - 180 * s**2 + 120 * s**3) if 0 <= t <= T else 0.0

    Tb = float(zv.base.duration)

    def acczv(t):
        return sum(float(A) * acc345(t - float(tj), Tb) for A, tj in zip(zv.amplitudes, zv.times))

    for i, w in enumerate(np.asarray(omegas)):
        assert float(amp["345"][i]) == pytest.approx(_amplitude_scipy(p, w, acc345, 1.0), rel=1e-7)
        ref = _amplitude_scipy(p, w, acczv, 1.0)
        assert float(amp["ZV"][i]) == pytest.approx(ref, rel=1e-6, abs=1e-9 * float(amp["345"][i]))
        q = p.with_natural_frequency(w)
        assert float(energy["345"][i]) == pytest.approx(float(jb.residual_energy_joules(q, base)), rel=1e-12)
    with pytest.raises(ValueError, match="parameter `measure`"):
        jb.sensitivity_curve(p, {"345": base}, measure="H")


def test_tolerance_band_on_a_parabola():
    w = np.linspace(0.7, 1.3, 601)
    ratio = ((w - 1.0) / 0.1) ** 2
    width = jb.tolerance_band(w, ratio, np.ones_like(w), 1.0, level=0.05)
    assert width == pytest.approx(2 * 0.1 * np.sqrt(0.05), rel=1e-3)
    assert jb.tolerance_band(w, 1 + ratio, np.ones_like(w), 1.0) == 0.0


# --------------------------------------------------------------------------------------------
# Optimisation
# --------------------------------------------------------------------------------------------
def test_reparametrisation_round_trip_and_feasibility():
    g = jnp.array([3.0, 4.0, 5.0])
    th = params_from_gammas(g, 2.0, 1e-3, 1e-3, 10.0)
    np.testing.assert_allclose(gammas_from_params(th, 2.0, 1e-3, 1e-3, 10.0), g, rtol=1e-13)
    for th in (jnp.array([-50.0, -50.0, -50.0]), jnp.array([300.0, -40.0, 5.0]), jnp.array([1e6, 1e6, 1e6])):
        gg = np.asarray(gammas_from_params(th, 2.0, 1e-3, 1e-3, 10.0))
        assert gg[0] > 2.0 and np.all(np.diff(gg) >= 1e-3 * (1 - 1e-12)) and gg[-1] <= 2 + 3 * 10.001 + 1e-9
    with pytest.raises(ValueError, match="max_step"):
        jb.optimise_command(jb.BeltPlatform(), _cmd([3.0, 4.0, 25.0]), max_step=10.0, progress=False)


@pytest.mark.slow
def test_optimise_command_reaches_the_zero_set_from_345():
    p = jb.BeltPlatform()
    cmd = jb.PseudoPolynomial(gammas=jnp.array([3.0, 4.0, 5.0]), displacement=15 * 2 * jnp.pi, duration=1.0)
    h0 = jb.residual_energy(p, cmd)
    res = jb.optimise_command(p, cmd, progress=False)
    assert float(res.value) < 1e-8 * float(h0)
    assert float(res.initial_value) == pytest.approx(float(h0), rel=1e-12)  # via the reparametrisation
    assert float(res.history[0]) == pytest.approx(float(h0), rel=1e-12)
    assert float(res.history[-1]) == pytest.approx(float(res.value), rel=1e-6, abs=1e-12 * float(h0))
    g = np.asarray(res.gammas)
    assert g[0] > 2 and np.all(np.diff(g) > 0)
    # independent check of the end point: the ODE of eq. (4) and scipy quadrature
    h_ode = jb.residual_energy(p, res.command, method="ode")
    assert float(h_ode) < 1e-8 * float(h0)
    assert _h_scipy(p, g) < 1e-8 * float(h0)
    # the paper's quasi-Newton run ends at (3.024, 4.565, 5.874); ours lies on the same curve nearby
    np.testing.assert_allclose(g, PAPER_OPT, atol=0.06)


@pytest.mark.slow
def test_optimise_command_with_adam_and_speed_limit():
    p = jb.BeltPlatform()
    cmd = _cmd(G345)
    h0 = float(jb.residual_energy(p, cmd))
    import optax

    res = jb.optimise_command(p, cmd, optimizer=optax.adam(0.02), max_steps=150, progress=False)
    assert float(res.value) < 0.2 * h0
    # peak motor speed of the 3-4-5 is 1.875 Phi / T; keep the optimised one within 2 % of it
    vmax = 1.02 * 1.875 * PHI
    res2 = jb.optimise_command(p, cmd, max_speed=vmax, penalty=1e3, progress=False)
    ts = jnp.linspace(0, 1, 20001)
    assert float(jnp.max(jnp.abs(res2.command.velocity(ts)))) <= vmax * 1.001
    assert float(res2.value) < 1e-3 * h0


def test_platform_free_vibration_after_the_move_matches_closed_form():
    # After T the motor is locked at Phi: alpha obeys the free damped oscillator from the state
    # alpha(T) = -lambda F / omega_d, alpha'(T) = -lambda G / omega_d (eq. 5, 28, 30).
    p = jb.BeltPlatform()
    cmd = _cmd(G345)
    F, G = convolution_integrals(p, cmd)
    lam, wd, wn, xi = p.lam, p.omega_d, p.omega_n, p.damping_ratio
    a0, ad0 = -lam * F / wd, -lam * G / wd
    ts = jnp.linspace(1.0, 1.5, 11)
    s = ts - 1.0
    sig = xi * wn
    alpha = jnp.exp(-sig * s) * (a0 * jnp.cos(wd * s) + (ad0 + sig * a0) / wd * jnp.sin(wd * s))
    sol = jb.simulate(
        jb.Scene(p, cmd, ts=jnp.concatenate([jnp.zeros(1), ts]), observe=("alpha",)),
        method="ode",
        rtol=1e-12,
        atol=1e-14,
    )
    np.testing.assert_allclose(sol.alpha[1:], alpha, rtol=0, atol=1e-7 * float(jnp.max(jnp.abs(alpha))))
    np.testing.assert_allclose(sol.theta[1:], PHI * lam + alpha, rtol=1e-9)


def test_fig2_profiles_drawn_from_the_commands(tmp_path):
    """Fig. 2 (T = 1 s, Phi = 1 rad): the 3-4-5 polynomial peaks at 15/8 rad/s and 10/sqrt(3) rad/s²
    (closed form of 10u^3 - 15u^4 + 6u^5); the figure draws exactly the arrays it is given; the CLI writes it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxbelt.cli import main
    from jaxbelt.plots.shaping import plot_profiles

    t = jnp.linspace(0.0, 1.0, 2001)
    c = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]), 1.0, 1.0)
    assert float(jnp.max(c.velocity(t))) == pytest.approx(15 / 8, rel=1e-12)
    assert float(jnp.max(c.acceleration(t))) == pytest.approx(10 / np.sqrt(3), rel=1e-6)
    p = jb.PseudoPolynomial(jnp.array([4.5, 6.2, 8.4]), 1.0, 1.0)
    profiles = {
        "3-4-5": (c(t), c.velocity(t), c.acceleration(t)),
        "4.5-6.2-8.4": (p(t), p.velocity(t), p.acceleration(t)),
    }
    axes = plot_profiles(t, profiles)
    np.testing.assert_array_equal(axes[2].lines[1].get_ydata(), np.asarray(p.acceleration(t)))
    plt.close("all")
    assert main(["--no-cache", "shaping", "--figure", "profiles", "--out", str(tmp_path / "fig2.png")]) == 0
    assert (tmp_path / "fig2.png").stat().st_size > 10_000


# --------------------------------------------------------------------------------------------
# Robust optimisation by the residual amplitude (the collapse of issue #26 fixed)
# --------------------------------------------------------------------------------------------
def _platform_hz(freq, zeta):
    """Table III's platform with the belt stiffness and damping set for a natural frequency `freq` [Hz] and damping
    ratio `zeta`."""
    J, R = 6.0, 0.18
    w = 2 * np.pi * freq
    return jb.BeltPlatform(k=J * w**2 / (2 * R**2), c=zeta * 2 * J * w / (2 * R**2))


def test_optimise_robust_no_longer_collapses_on_a_3hz_platform():
    """On a 3 Hz, zeta = 0.02 platform (1 s move) the previous robust optimiser left 37-48 % of the 3-4-5 command's
    worst residual even at the design frequency, its exponents frozen on the minimum spacing (a logistic map puts
    the faces of the feasible box at theta = -inf), never meeting its stopping test. From (5, ..., 9), mode "max":
    the worst residual amplitude over +-20 % (201 frequencies, an independent grid) is now <= 36 % of the 3-4-5's
    (34.6 % reached; the best of any order is 33.6 %, tests/test_pseudo_axis.py), converged by its gradient test,
    the lowest exponent on its bound, and no worse than the start at the design frequency."""
    plat = _platform_hz(3.0, 0.02)
    start = _cmd([5.0, 6.0, 7.0, 8.0, 9.0])
    res = jb.optimise_robust(plat, start, mode="max", progress=False)
    assert res.converged and res.message.startswith("largest gradient component"), res.message
    cmds = {"robust": res.command, "start": start, "345": _cmd(G345)}
    omegas, amp = jb.sensitivity_curve(plat, cmds, rel=0.2, n=201)
    worst345 = float(np.max(amp["345"]))
    assert float(np.max(amp["robust"])) <= 0.36 * worst345
    assert float(amp["robust"][100]) <= float(amp["start"][100])  # the design frequency (the centre of the grid)
    assert float(res.gammas[0]) == pytest.approx(4.001, abs=1e-6)  # on the face gamma_0 = n + margin
    assert float(res.value) <= float(res.initial_value)
    assert float(res.value) == pytest.approx(float(np.max(amp["robust"])) / worst345, rel=0.02)  # 25-point grid


def test_optimise_robust_never_ends_worse_than_its_start_at_the_design_frequency():
    """A start that is good at the design frequency (6, ..., 11 on the 3 Hz platform: 7 % of the 3-4-5's worst
    there, 184 % over the band): the band measure improves while the amplitude at omega_n stays at or below the
    start's (a penalty, checked on the result); the run says why it stopped whether or not it converged."""
    plat = _platform_hz(3.0, 0.02)
    start = _cmd([6.0, 7.0, 8.0, 9.0, 10.0, 11.0])
    for mode in ("mean", "max"):
        res = jb.optimise_robust(plat, start, mode=mode, progress=False)
        omegas, amp = jb.sensitivity_curve(plat, {"r": res.command, "s": start}, rel=0.2, n=5)
        assert float(amp["r"][2]) <= float(amp["s"][2])
        assert float(res.value) <= float(res.initial_value)
        assert res.message
        if not res.converged:
            assert not res.message.startswith(("largest gradient", "stationary"))
        assert len(res.history) >= 1 and float(res.history[0]) == pytest.approx(float(res.initial_value))


def test_paper_figure_compares_amplitudes_at_equal_move_time(tmp_path, capsys):
    """`jaxbelt shaping` without an axis: the paper's H labelled as energy, then every command's residual amplitude
    in % of the 3-4-5 command's worst over the band, each ending at the same move time (ZV/ZVD on a shortened
    base), and the figure (Fig. 3 and the sensitivity plot in amplitude %)."""
    from jaxbelt.cli import main

    out = tmp_path / "shaping.png"
    assert main(["--no-cache", "shaping", "--robust-order", "--no-progress", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "residual energy (Incerti eq. 32" in text and "residual vibration amplitude" in text
    rows = [ln for ln in text.splitlines() if "+ ZV" in ln]
    assert len(rows) == 2 and all("1.000 s" in ln for ln in rows)
    assert "(base 0.899 s)" in text and "(base 0.798 s)" in text
    assert out.stat().st_size > 30_000
