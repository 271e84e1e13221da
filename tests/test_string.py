"""Belt spans (seeds 002 and 004): each test checks jaxbelt against an independent reference."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles
from scipy.optimize import brentq

import jaxbelt as jb
from jaxbelt.models.string import TABLE2_COMPUTED_RPM, _exact_phasor

RPM = 30.0 / np.pi
T, RHO, L, RU = 140.0, 0.05, 0.2621, 0.1166


@pytest.fixture(scope="module")
def span():
    return jb.MovingString(tension=T, density=RHO, length=L)


# --- moving string (belt-vibration report) ---------------------------------------------------------------------
def test_contract_calls(span):
    assert float(span.critical_speed) == pytest.approx(np.sqrt(140.0 / 0.05), rel=1e-14)
    V = np.linspace(0, 50, 1001)
    w = span.natural_frequencies(speed=jnp.asarray(V), n_modes=3)
    assert w.shape == (1001, 3)
    vc = np.sqrt(T / RHO)
    ref = np.outer(vc * (1 - V**2 / vc**2), np.arange(1, 4) * np.pi / L)  # eq. (39) in numpy
    np.testing.assert_allclose(np.asarray(w), ref, rtol=1e-13)
    # vmap over speed gives the same numbers as the broadcast call
    wv = jax.vmap(lambda v: span.natural_frequencies(v, 3))(jnp.asarray(V))
    np.testing.assert_allclose(np.asarray(wv), ref, rtol=1e-13)
    assert float(jb.exciting_speeds(span, pulley_radius=0.1166, n=1, m=8)) * RPM == pytest.approx(735, abs=1.0)


@pytest.mark.parametrize("nm", sorted(TABLE2_COMPUTED_RPM))
def test_table2_computed_column(span, nm):
    n, m = nm
    got = float(jb.exciting_speeds(span, RU, n, m)) * RPM
    assert abs(got - TABLE2_COMPUTED_RPM[nm]) <= 1.0


def test_exciting_speeds_solve_eq54(span):
    n = np.array([1, 1, 2, 3, 5])[:, None]
    m = np.array([1, 3, 9, 40])[None, :]
    wu = np.asarray(jb.exciting_speeds(span, RU, n, m))
    assert wu.shape == (5, 4)
    vc = np.sqrt(T / RHO)
    rhs = n * np.pi / L * vc * (1 - (wu * RU) ** 2 / vc**2)  # eq. (51) at V = omega_U R_U
    np.testing.assert_allclose(m * wu, rhs, rtol=1e-12)


def test_galerkin_converges_to_eq39(span):
    V = 30.0
    exact = np.asarray(span.natural_frequencies(V, 3))
    errs = []
    for N in (6, 12, 24, 48):
        g = np.asarray(span.galerkin_frequencies(V, N, 3))
        errs.append(np.max(np.abs(g - exact) / exact))
    errs = np.array(errs)
    assert errs[-1] < 2e-5
    assert np.all(np.diff(errs) < 0)
    order = np.log2(errs[:-1] / errs[1:])
    assert np.all(order > 2.5)  # observed ~3 (sine coefficients of the gyroscopic coupling fall as 1/k)
    # at rest G = 0 and the sine basis is exact
    np.testing.assert_allclose(
        np.asarray(span.galerkin_frequencies(0.0, 6, 3)), np.asarray(span.natural_frequencies(0.0, 3)), rtol=1e-12
    )


def test_galerkin_vs_scipy_quadratic_eigenproblem(span):
    from scipy.linalg import eig

    V, N = 25.0, 12
    M, G, K = (np.asarray(a) for a in span.galerkin_matrices(V, N))
    Z, I = np.zeros((N, N)), np.eye(N)
    # generalised linearisation [[0, I], [-K, -G]] x = lam [[I, 0], [0, M]] x
    lam = eig(np.block([[Z, I], [-K, -G]]), np.block([[I, Z], [Z, M]]), right=False)
    ref = np.sort(np.abs(lam.imag))[::2][:3]
    np.testing.assert_allclose(np.asarray(span.galerkin_frequencies(V, N, 3)), ref, rtol=1e-10)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_mode_shape_solves_eq24(span, n):
    V = 21.0
    vc = float(span.critical_speed)

    def y(x, t):
        return span.mode_shape(x, t, V, n, b1=0.7, b2=-0.3)

    y_t = jax.grad(y, 1)
    y_x = jax.grad(y, 0)
    y_tt = jax.grad(y_t, 1)
    y_xt = jax.grad(y_t, 0)
    y_xx = jax.grad(y_x, 0)
    for x, t in [(0.05, 0.0), (0.13, 0.011), (0.2, 0.3)]:
        res = y_tt(x, t) + 2 * V * y_xt(x, t) + (V**2 - vc**2) * y_xx(x, t)
        scale = abs(y_tt(x, t)) + abs(vc**2 * y_xx(x, t))
        assert abs(float(res)) < 1e-10 * float(scale)
    for t in (0.0, 0.004, 0.17):
        assert abs(float(y(0.0, t))) < 1e-12 and abs(float(y(L, t))) < 1e-12


# --- crossing diagram (Moon & Wickert, 1997) ------------------------------------------------------------------
def test_crossing_speeds_moon_wickert():
    vc = np.asarray(jb.crossing_speeds(jb.RunoutRig(), n_modes=2))
    assert vc.shape == (2, 2, 1)
    np.testing.assert_allclose(vc[0], 9.0, atol=0.05)
    np.testing.assert_allclose(vc[1], 16.0, atol=0.1)


def test_crossing_speeds_vs_brentq():
    Lm, r, vt = 0.86, (0.063, 0.045), 41.0
    vc = np.asarray(
        jb.crossing_speeds(jb.RunoutRig(length=Lm, pulley_radii=r, wave_speed=vt), n_modes=4, harmonics=(1, 2, 3))
    )
    for i, n in enumerate(range(1, 5)):
        for j, rj in enumerate(r):
            for k, h in enumerate((1, 2, 3)):
                ref = brentq(
                    lambda V, n=n, h=h, rj=rj: n * np.pi / Lm * vt * (1 - V**2 / vt**2) - h * V / rj, 0, vt, xtol=1e-14
                )
                assert vc[i, j, k] == pytest.approx(ref, rel=1e-12)


def test_crossing_is_exciting_speed(span):
    # harmonic m of a pulley of radius R_U meets mode n at V = omega_U R_U (eq. 50 + 55)
    vc = np.asarray(
        jb.crossing_speeds(
            jb.RunoutRig(length=L, pulley_radii=(RU,), wave_speed=span.critical_speed), n_modes=3, harmonics=9
        )
    )
    wu = np.asarray(jb.exciting_speeds(span, RU, np.arange(1, 4)[:, None], np.arange(1, 10)[None, :]))
    np.testing.assert_allclose(vc[:, 0, :], wu * RU, rtol=1e-12)


def test_crossing_gradient_fd_and_vmap():
    @jax.jit
    def f(vt):
        return jb.crossing_speeds(jb.RunoutRig(wave_speed=vt), 2)[1, 0, 0]

    g = jax.grad(f)(41.0)
    h = 1e-4
    fd = (f(41.0 + h) - f(41.0 - h)) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=1e-7)
    vts = jnp.array([35.0, 41.0, 48.0])
    gv = jax.vmap(jax.grad(f))(vts)
    fdv = jnp.array([(f(v + h) - f(v - h)) / (2 * h) for v in vts])
    np.testing.assert_allclose(np.asarray(gv), np.asarray(fdv), rtol=1e-7)


def test_runout_rig_defaults_are_the_moon_wickert_stand():
    r = jb.RunoutRig()
    np.testing.assert_allclose(float(r.length), 0.86)
    np.testing.assert_allclose(np.asarray(r.pulley_radii), [0.063, 0.063])
    np.testing.assert_allclose(2 * np.asarray(r.runouts), [0.71e-3, 0.42e-3])  # peak-to-peak run-out
    np.testing.assert_allclose(float(r.phase), np.radians(240.0), rtol=1e-6)
    assert float(r.damping_ratio) == 0.0 and float(r.position) == 0.01


def test_crossings_batched_over_rigs_match_the_quadratic():
    """vmap over a batch of rigs (eqx.Module) vs the positive root of (n pi / L) v_t (1 - V^2/v_t^2) = V / r."""
    vts = jnp.array([35.0, 41.0, 48.0])
    rigs = jax.vmap(lambda vt: jb.RunoutRig(wave_speed=vt))(vts)
    vc = np.asarray(jax.vmap(lambda r: jb.crossing_speeds(r, 3))(rigs))
    for b, vt in enumerate(np.asarray(vts)):
        for i, n in enumerate((1, 2, 3)):
            a, s, c = n * np.pi / 0.86 / vt, 1 / 0.063, n * np.pi / 0.86 * vt  # a V^2 + s V - c = 0
            ref = 2 * c / (s + np.sqrt(s * s + 4 * a * c))
            np.testing.assert_allclose(vc[b, i, :, 0], ref, rtol=1e-13)


def test_crossing_diagram_shapes_and_values():
    V = jnp.linspace(0, 20, 7)
    nat, load = jb.crossing_diagram(jb.RunoutRig(pulley_radii=(0.063, 0.05)), V, n_modes=5, harmonics=3)
    assert nat.shape == (7, 5) and load.shape == (7, 2, 3)
    np.testing.assert_allclose(np.asarray(load[:, 1, 2]), 3 * np.asarray(V) / 0.05, rtol=1e-14)
    ref = 5 * np.pi / 0.86 * 41.0 * (1 - (np.asarray(V) / 41) ** 2)
    np.testing.assert_allclose(np.asarray(nat[:, 4]), ref, rtol=1e-13)


# --- linear forced response -----------------------------------------------------------------------
MW = dict(length=0.86, wave_speed=41.0, pulley_radii=(0.063, 0.063), runouts=(0.355e-3, 0.21e-3), phase=np.radians(240))


def rig(**kw):
    """The Moon & Wickert stand with the given changes."""
    return jb.RunoutRig(**{**MW, **kw})


@pytest.mark.parametrize("V", [2.0, 6.5, 12.0, 19.0])
@pytest.mark.parametrize("x", [0.01, 0.3, 0.61])
def test_modal_response_matches_travelling_wave_solution(V, x):
    """Undamped modal sum vs the exact two-wave solution of the boundary-value problem (numpy)."""
    Lm, vt, r, e, ph = MW["length"], MW["wave_speed"], MW["pulley_radii"][0], MW["runouts"], MW["phase"]
    v, Om = V / vt, V / r * Lm / vt
    ref = _exact_phasor(v, Om, -1j * e[0] / Lm, -1j * e[1] * np.exp(1j * ph) / Lm, x / Lm) * Lm
    W0, W1 = jb.runout_phasors(rig(position=x, damping_ratio=0.0), V, n_modes=256)
    assert abs(complex(W0 + W1) - complex(ref)) < 1e-5 * abs(ref)
    pp = float(jb.linear_runout_response(rig(position=x), V, n_modes=256))
    assert pp == pytest.approx(float(2 * abs(ref)), rel=1e-5)
    W0, W1 = jb.runout_phasors(rig(position=x, damping_ratio=0.0), V, n_modes=64)
    assert abs(complex(W0 + W1) - complex(ref)) < 1e-4 * abs(ref)


def test_modal_response_at_the_pulley_is_the_runout():
    # at x = 0 only pulley 0 moves the belt: peak-to-peak = 2 e0
    pp = jb.linear_runout_response(rig(position=0.0, damping_ratio=0.02), jnp.array([3.0, 11.0]))
    np.testing.assert_allclose(np.asarray(pp), 0.71e-3, rtol=1e-12)


def test_response_gradient_fd():
    @jax.jit
    def f(V):
        return jb.linear_runout_response(rig(position=0.2, damping_ratio=0.02), V, n_modes=16)

    for V in (5.0, 12.0):
        h = 1e-4
        fd = (f(V + h) - f(V - h)) / (2 * h)
        assert float(jax.jit(jax.grad(f))(V)) == pytest.approx(float(fd), rel=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("V", [4.0, 12.5])
def test_modal_response_matches_galerkin_time_simulation(V):
    """Formula vs a diffrax run of the 24-mode Galerkin model to steady state: within 1 % (off resonance)."""
    r = rig(damping_ratio=0.05, position=0.25)
    ref = float(jb.simulate_runout_response(r, V, n_basis=24))
    got = float(jb.linear_runout_response(r, V))
    assert got == pytest.approx(ref, rel=0.01)


@pytest.mark.slow
def test_runout_time_simulation_compiles_once_for_every_rig_and_speed():
    """The diffrax run of the Galerkin model is one program per n_basis: another rig at another speed
    compiles nothing (it re-traced and re-compiled on every call, ~1 s each), and still solves the new
    problem (the modal formula within 1 %)."""
    jb.simulate_runout_response(rig(damping_ratio=0.05, position=0.25), 4.0, n_basis=24)
    other = rig(damping_ratio=0.08, position=0.3, runouts=(1.0e-4, 0.6e-4))
    with count_compiles() as compiles:
        ref = float(jb.simulate_runout_response(other, 9.0, n_basis=24))
    assert compiles["n"] == 0
    assert float(jb.linear_runout_response(other, 9.0)) == pytest.approx(ref, rel=0.01)


def test_different_radii_peak_to_peak_is_sum_of_amplitudes():
    r = rig(pulley_radii=(0.063, 0.05), damping_ratio=0.01, position=0.3)
    W0, W1 = jb.runout_phasors(r, 7.0)
    pp = jb.linear_runout_response(r, 7.0)
    # long-time max - min of Re(W0 e^{i a t} + W1 e^{i b t}) with incommensurate a, b
    t = np.linspace(0, 4000, 2_000_001)
    sig = np.real(complex(W0) * np.exp(1j * t) + complex(W1) * np.exp(1j * np.sqrt(2) * t))
    assert float(pp) == pytest.approx(sig.max() - sig.min(), rel=1e-3)


# --- contact (belt-vibration report) ---------------------------------------------------------------------------
def test_contact_pressure_and_separation():
    c = jb.BeltPulleyContact(radius=0.025)
    w = 15000 / RPM
    tc = 0.05 * 0.025**2 * w**2
    assert float(c.centrifugal_tension(w)) == pytest.approx(tc, rel=1e-14)
    a = np.linspace(0, 2.094, 9)
    tension = 120 + (140 - 120) * a / 2.094  # eq. (9)
    np.testing.assert_allclose(np.asarray(c.pressure(a, w)), (tension - tc) / 0.025, rtol=1e-13)
    assert np.all(np.asarray(c.pressure(a, w)) > 0)  # Fig. 40: no separation at 15000 rpm
    ws = float(c.separation_speed())
    ref = brentq(lambda om: float(c.pressure(0.0, om)), 1.0, 1e5, xtol=1e-12)
    assert ws == pytest.approx(ref, rel=1e-10)
    assert float(c.separation_angle()) == 0.0


def test_slip_margin_and_report():
    c = jb.BeltPulleyContact(radius=0.025)
    lim = np.exp(0.2 * 2.094)
    for w in (0.0, 800.0, 1570.8):
        tc = 0.05 * 0.025**2 * w**2
        assert float(c.slip_margin(w)) == pytest.approx((120 - tc) * lim - (140 - tc), rel=1e-12)
        rep = c.check_slip(w)
        assert rep.ok and rep.ratio == pytest.approx((140 - tc) / (120 - tc), rel=1e-12)
    # the speed at which eq. (8) becomes an equality, by scipy
    w_slip = brentq(lambda om: (140 - 0.05 * 0.025**2 * om**2) / (120 - 0.05 * 0.025**2 * om**2) - lim, 1.0, 1700.0)
    assert c.slip_report(0.999 * w_slip).ok
    with pytest.raises(jb.SlipError, match=r"slips.*N too high.*at least"):
        c.check_slip(1.001 * w_slip)
    # tight tension beyond the limit: the report says by how much (in N and in needed friction)
    c2 = jb.BeltPulleyContact(radius=0.025, tight_tension=200.0)
    rep = c2.slip_report(0.0)
    assert not rep.ok
    assert -rep.margin == pytest.approx(200 - 120 * lim, rel=1e-12)
    assert rep.required_friction == pytest.approx(np.log(200 / 120) / 2.094, rel=1e-12)
    with pytest.raises(jb.SlipError, match="too high"):
        c2.check_slip(0.0)
    # beyond separation of the slack side: no friction left at all
    with pytest.raises(jb.SlipError, match="no friction"):
        c.check_slip(1.1 * float(c.separation_speed()))


def test_slip_margin_gradient_fd():
    def f(R):
        return jb.BeltPulleyContact(radius=R).slip_margin(1500.0)

    h = 1e-7
    assert float(jax.grad(f)(0.025)) == pytest.approx(float((f(0.025 + h) - f(0.025 - h)) / (2 * h)), rel=1e-6)


# --- errors ---------------------------------------------------------------------------------------
def test_errors_speed_at_or_above_critical(span):
    vc = float(span.critical_speed)
    for bad in (vc, 60.0, -vc):
        with pytest.raises(ValueError, match="critical speed"):
            span.natural_frequencies(bad, 2)
    with pytest.raises(ValueError, match="critical speed"):
        span.natural_frequencies(jnp.array([1.0, 70.0]), 2)
    with pytest.raises(ValueError, match="critical speed"):
        jb.linear_runout_response(rig(), 41.0)
    with pytest.raises(ValueError, match="critical speed"):
        jb.crossing_diagram(jb.RunoutRig(pulley_radii=(0.063,)), jnp.array([50.0]))
    with pytest.raises(Exception, match="critical speed"):
        jax.jit(lambda v: span.natural_frequencies(v, 2))(60.0).block_until_ready()


@pytest.mark.parametrize(
    "kw,name",
    [
        (dict(tension=0.0), "tension"),
        (dict(tension=-5.0), "tension"),
        (dict(density=0.0), "density"),
        (dict(density=-0.05), "density"),
        (dict(length=0.0), "length"),
    ],
)
def test_errors_string_parameters(kw, name):
    with pytest.raises(ValueError, match=name):
        jb.MovingString(**kw)


@pytest.mark.parametrize("theta", [0.0, -0.1, 2 * np.pi, 7.0])
def test_errors_wrap_angle(theta):
    with pytest.raises(ValueError, match=r"wrap_angle.*\(0, 6.28319\)"):
        jb.BeltPulleyContact(radius=0.03, wrap_angle=theta)


@pytest.mark.parametrize(
    "kw,name",
    [
        (dict(slack_tension=0.0), "slack_tension"),
        (dict(tight_tension=-1.0), "tight_tension"),
        (dict(density=0.0), "density"),
        (dict(radius=0.0), "radius"),
    ],
)
def test_errors_contact_parameters(kw, name):
    args = dict(radius=0.03)
    args.update(kw)
    with pytest.raises(ValueError, match=name):
        jb.BeltPulleyContact(**args)


def test_errors_response_inputs():
    with pytest.raises(ValueError, match="position"):
        rig(position=1.0)
    with pytest.raises(ValueError, match="damping_ratio"):
        rig(damping_ratio=-0.1)
    with pytest.raises(ValueError, match="pulley_radii"):
        jb.RunoutRig(pulley_radii=(0.063, 0.0))
    with pytest.raises(ValueError, match="runouts"):
        rig(runouts=(-1e-3, 0.0))
    with pytest.raises(ValueError, match="two values"):
        jb.linear_runout_response(jb.RunoutRig(pulley_radii=(0.063,)), 5.0)


def test_table1_observations_and_table2_measured():
    """Belt-vibration report, Table 1 (9 observed speeds) and Table 2 (the 7 with a transverse vibration)."""
    from jaxbelt.models.string import TABLE1_OBSERVATIONS, TABLE2_MEASURED_RPM

    rpm = [r for r, _ in TABLE1_OBSERVATIONS]
    assert rpm == [730, 810, 910, 1020, 1090, 1180, 1271, 1400, 1720]
    relevant = [r for r, what in TABLE1_OBSERVATIONS if what != "Not relevant vibration"]
    assert relevant == [r for r, _ in TABLE2_MEASURED_RPM]
    assert dict(TABLE1_OBSERVATIONS)[1090] == dict(TABLE1_OBSERVATIONS)[1271] == "Not relevant vibration"


def test_critical_rotor_speed_eq53(span):
    w_cr = float(span.critical_rotor_speed(0.1166))
    assert w_cr == pytest.approx(np.sqrt(140.0 / 0.05) / 0.1166, rel=1e-14)  # eq. 53
    # eq. (51) at omega_U -> omega_CR: omega_n = (n pi / L) V_cr (1 - x^2) with x = 0.999
    wn = np.asarray(span.natural_frequencies(0.999 * w_cr * 0.1166, 3))
    np.testing.assert_allclose(wn, np.arange(1, 4) * np.pi / 0.2621 * np.sqrt(2800.0) * (1 - 0.999**2), rtol=1e-12)
    # every exciting speed of eq. (55) lies below omega_CR
    assert all(float(jb.exciting_speeds(span, 0.1166, n, m)) < w_cr for n in (1, 2, 3) for m in (1, 5, 9))
    with pytest.raises(ValueError, match="pulley_radius"):
        span.critical_rotor_speed(0.0)


def test_mode_shape_refuses_positions_off_the_span(span):
    # the ends are part of the span (y = 0 there); a point beyond either end, or NaN, is refused by name
    # eagerly, and under jit where the position is traced
    import equinox as eqx

    L = float(span.length)
    ends = np.asarray(span.mode_shape(jnp.array([0.0, L]), 0.01, 20.0))
    assert np.all(np.abs(ends) < 1e-12)
    for bad in (-1e-3, L + 1e-3, float("nan")):
        with pytest.raises(ValueError, match=r"mode_shape: parameter `x` must lie on the span \[0, 0.2621\] m"):
            span.mode_shape(bad, 0.0, 20.0)
    shape = jax.jit(lambda x: span.mode_shape(x, 0.0, 20.0))
    assert float(shape(0.1)) == pytest.approx(float(span.mode_shape(0.1, 0.0, 20.0)), rel=1e-14)
    with pytest.raises((eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, ValueError), match="must lie on the span"):
        jax.block_until_ready(shape(L + 1e-3))
