"""Non-linear belt (Moon & Wickert, 1997): Galerkin model, steady state, sweeps, KBM results.

References: closed-form modal integrals, the exact linear travelling-string solution, a
frequency-domain solve of the linear modal model, the KBM (averaging) cubic and backbone, and
central differences of nothing: each test states its tolerance.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from nonlinear_reference import modal_harmonic_pp, string_exact_pp

import jaxbelt as jb
from jaxbelt.models.nonlinear.kbm import kappa, kbm_amplitudes

XI = 0.015  # modal damping ratio used for the 004 acceptance checks


def belt(**kw):
    base = dict(
        span=0.86,
        wave_speed=41.0,
        v_l=50.0,
        pulley_radii=(0.063, 0.063),
        runout=(0.355e-3, 0.21e-3),
        phase=jnp.deg2rad(240.0),
        damping=XI,
        n_modes=1,
        sensor_pulley="drive",
    )
    base.update(kw)
    return jb.NonlinearBelt(**base)


# --- model: closed forms ----------------------------------------------------------------------
def test_modal_constants_closed_form():
    """mu_n = (n pi)^2 (1 - v^2) and int |psi_n'|^2 = (n pi)^2 (1 + v^2) (A-norms of the modes)."""
    b = belt(n_modes=3)
    sys = b.modal(12.0)
    v = 12.0 / 41.0
    k = np.pi * np.arange(1, 4)
    np.testing.assert_allclose(sys.mu, k**2 * (1 - v**2), rtol=1e-12)
    S = np.asarray(sys.S)
    np.testing.assert_allclose(np.diag(S)[:3] + np.diag(S)[3:], k**2 * (1 + v**2), rtol=1e-12)
    # linear crossing of the drive-pulley load line with omega_1, omega_2 (Fig. 5): 9.0 and 16.0 m/s
    np.testing.assert_allclose(b.crossing_speeds(2), [8.98, 16.0], atol=0.02)


def test_forcing_from_boundary_shift_matches_exact_string():
    """The modal forcing derived from w = u + b converges to the exact travelling-string
    solution with moving ends (undamped, away from resonance): 0.2 % with 24 modes."""
    b = belt(v_l=0.0, damping=0.0)
    for speed in (3.0, 6.0, 12.0):
        for at in (0.01, 0.43):
            ref = string_exact_pp(b, speed, at=at)
            got = modal_harmonic_pp(b, speed, at=at, n_modes=24)
            assert abs(got / ref - 1) < 2e-3, (speed, at, got, ref)


def test_backbone_coefficient_from_inner_products():
    """kappa of eq. (33) (closed form) equals (omega/mu)(v_l^2/2)(sbar^2 + (p^2+q^2)/2) built from
    the quadrature matrix S of the Galerkin model."""
    b = belt()
    for speed in (5.0, 9.0, 15.0):
        sys = b.modal(speed)
        S = np.asarray(sys.S)
        sbar = 0.5 * (S[0, 0] + S[1, 1])
        p, q = 0.5 * (S[0, 0] - S[1, 1]), S[0, 1]
        ref = float(sys.omega[0] / sys.mu[0]) * 50.0**2 / 2 * (sbar**2 + (p**2 + q**2) / 2)
        assert abs(float(kappa(sys.v, 50.0)) / ref - 1) < 1e-10


def test_backbone_sign_free_oscillation():
    """Free undamped single-mode oscillation at amplitude a: its frequency (zero crossings of the
    simulated trajectory) rises by the backbone shift kappa a^2 of eq. (33) (hardening, + sign):
    0.5 % of the shift at a = 1e-3, and the relative error falls as a^2 (first-order theory)."""
    b = belt(runout=(0.0, 0.0), damping=0.0)
    speed = 9.0
    sys = b.modal(speed)
    errs = []
    for a in (2e-3, 1e-3):
        ts, zs = jb.nonlinear_trajectory(b, speed, jnp.array([a, 0.0]), periods=40, steps_per_period=200)
        tau = np.asarray(ts) * 41.0 / 0.86
        zr = np.asarray(zs[:, 0])
        idx = np.nonzero((zr[:-1] > 0) & (zr[1:] <= 0))[0]
        tc = tau[idx] - zr[idx] * (tau[idx + 1] - tau[idx]) / (zr[idx + 1] - zr[idx])
        omega_sim = 2 * np.pi * (len(tc) - 1) / (tc[-1] - tc[0])
        shift_ref = float(jb.backbone_frequency(sys.v, a, 50.0)) - float(sys.omega[0])
        assert shift_ref > 0
        errs.append(abs((omega_sim - float(sys.omega[0])) / shift_ref - 1))
    assert errs[1] < 5e-3
    assert 3.0 < errs[0] / errs[1] < 5.0


# --- linear limit -----------------------------------------------------------------------------
def test_linear_sweeps_coincide_and_match_linear_response():
    """v_l = 0: up and down sweeps coincide and equal the frequency-domain steady state (2 %),
    and the exact undamped string off resonance (2 %)."""
    b = belt(v_l=0.0, n_modes=2)
    speeds = jnp.array([5.0, 7.5, 8.5, 8.9, 9.0, 9.1, 9.5, 10.5, 12.0])
    up = np.asarray(jb.speed_sweep(b, speeds))
    down = np.asarray(jb.speed_sweep(b, speeds[::-1]))[::-1]
    ref = np.array([modal_harmonic_pp(b, s) for s in np.asarray(speeds)])
    np.testing.assert_allclose(up, down, rtol=2e-3)
    np.testing.assert_allclose(up, ref, rtol=0.02)
    assert np.max(np.abs(up / ref - 1)) < 2e-3  # what the criterion actually delivers
    for i in (0, 8):  # away from resonance the damping hardly matters
        assert abs(up[i] / string_exact_pp(b, float(speeds[i])) - 1) < 0.02


# --- the 004 test stand -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def stand_sweeps():
    b = belt()
    speeds = jnp.arange(8.9, 9.71, 0.05)
    up = jb.nonlinear_sweep(b, speeds)
    dn = jb.nonlinear_sweep(b, speeds[::-1])
    dn = jax.tree_util.tree_map(lambda a: a[::-1], dn)
    return b, np.asarray(speeds), up, dn


def test_jump_and_hysteresis_004(stand_sweeps):
    b, speeds, up, dn = stand_sweeps
    au, ad = np.asarray(up.steady.amplitude[:, 0]), np.asarray(dn.steady.amplitude[:, 0])
    assert bool(np.all(up.converged)) and bool(np.all(dn.converged))
    band = np.abs(au - ad) > 0.2 * np.maximum(au, ad)
    assert band.sum() >= 1
    j = int(np.argmax(au[:-1] - au[1:]))  # biggest drop of the increasing sweep
    assert au[j] > 2 * au[j + 1]
    assert 8.3 <= speeds[j] and speeds[j + 1] <= 9.5
    # the decreasing sweep jumps up (read downwards) at a lower speed than the increasing one
    k = int(np.argmax(ad[:-1] - ad[1:]))
    assert ad[k] > 1.5 * ad[k + 1] and speeds[k] < speeds[j]
    pp = np.concatenate([np.asarray(up.pp), np.asarray(dn.pp)])
    assert 0.5e-3 <= pp.min() and pp.max() <= 2.0e-3


def test_simulated_branches_match_kbm_and_backbone_between(stand_sweeps):
    """Stable roots of the KBM cubic eq. (31) agree with the simulated branches (5 %), and the
    backbone eq. (33) lies between the two branches inside the hysteresis band."""
    b, speeds, up, dn = stand_sweeps
    au, ad = np.asarray(up.steady.amplitude[:, 0]), np.asarray(dn.steady.amplitude[:, 0])
    nband = 0
    for s, u, d in zip(speeds, au, ad):
        roots = kbm_amplitudes(b, s)
        if abs(u - d) > 0.2 * max(u, d):
            nband += 1
            assert len(roots) == 3
            assert abs(d / roots[0] - 1) < 0.05 and abs(u / roots[2] - 1) < 0.05
            assert d < float(jb.backbone_amplitude(b, s)) < u
        else:
            assert np.min(np.abs(roots / u - 1)) < 0.05
    assert nband >= 1


def test_basins_two_branches(stand_sweeps):
    """Fig. 6: at one speed in the band, rest and a large start reach the two stable branches."""
    b, speeds, up, dn = stand_sweeps
    au, ad = np.asarray(up.steady.amplitude[:, 0]), np.asarray(dn.steady.amplitude[:, 0])
    i = int(np.argmax(au - ad))
    z0s = jnp.stack([jnp.zeros(2), 1.1 * up.steady.z[i]])
    ss = jb.nonlinear_basins(b, speeds[i], z0s)
    roots = kbm_amplitudes(b, speeds[i])
    a = np.asarray(ss.amplitude[:, 0])
    assert abs(a[0] / roots[0] - 1) < 0.05 and abs(a[1] / roots[2] - 1) < 0.05


def test_contract_call_and_vmap_over_damping():
    """The issue's contract runs; a vmap over damping equals the one-by-one sweeps."""
    b = belt(damping=0.01)
    speeds = jnp.linspace(7.5, 10.5, 13)
    up = jb.speed_sweep(b, speeds)
    down = jb.speed_sweep(b, speeds[::-1])
    assert up.shape == down.shape == (13,)
    dampings = jnp.array([0.01, 0.03])
    many = jax.vmap(lambda d: jb.speed_sweep(belt(damping=d), speeds))(dampings)
    np.testing.assert_allclose(many[0], up, rtol=1e-9)
    np.testing.assert_allclose(many[1], jb.speed_sweep(belt(damping=0.03), speeds), rtol=1e-9)
    # more damping, lower resonant peak (linear estimate: peak ~ 1/damping for the modal part)
    assert float(jnp.max(many[1])) < float(jnp.max(many[0]))


@pytest.mark.slow
def test_mode_convergence():
    """Peak amplitude of the increasing sweep: N = 2 vs N = 4 within 5 %; N = 1 reported."""
    speeds = jnp.arange(8.9, 9.51, 0.05)
    peaks = {}
    for n in (1, 2, 4):
        up = jb.nonlinear_sweep(belt(n_modes=n), speeds)
        assert bool(np.all(up.converged))
        peaks[n] = float(jnp.max(up.pp))
    assert abs(peaks[2] / peaks[4] - 1) < 0.05
    print(f"N=1 peak-to-peak error vs N=4: {100 * (peaks[1] / peaks[4] - 1):+.2f} %")
    assert abs(peaks[1] / peaks[4] - 1) < 0.05


# --- bad input --------------------------------------------------------------------------------
def test_bad_inputs():
    with pytest.raises(ValueError, match="damping"):
        belt(damping=-0.01)
    with pytest.raises(ValueError, match="n_modes"):
        belt(n_modes=0)
    with pytest.raises(ValueError, match="sub-critical"):
        jb.speed_sweep(belt(), jnp.array([9.0, 45.0]))
    with pytest.raises(ValueError, match="sub-critical"):
        belt().modal(41.0)
    with pytest.raises(ValueError, match="> 0"):
        jb.speed_sweep(belt(), jnp.array([0.0, 1.0]))


def test_nonconvergence_names_speed():
    b = belt(damping=1e-4, v_l=0.0)
    with pytest.raises(jb.SteadyStateError, match=r"9\.0"):
        jb.speed_sweep(b, jnp.array([9.0]))


def test_simulate_scene_matches_sweep_integrator():
    """`simulate` (diffrax Tsit5, rtol 1e-10, physical time) of the model's vector field agrees
    with the fixed-step RK4 of the sweeps (128 steps per forcing period) to 1e-5 of the amplitude."""
    b = belt()
    t2, zs = jb.nonlinear_trajectory(b, 9.0, periods=20, steps_per_period=128)
    idx = np.arange(0, t2.shape[0], 128)
    sol = jb.simulate(jb.Scene(b, jb.RunningSpeed(9.0), t2[idx]), method="ode", rtol=1e-10, atol=1e-14)
    scale = float(jnp.max(jnp.abs(zs)))
    np.testing.assert_allclose(np.asarray(sol.ys), np.asarray(zs[idx]), atol=1e-5 * scale)


def _fd5(f, x, h):
    """Fourth-order central difference (the reference of the two tests below)."""
    return (-f(x + 2 * h) + 8 * f(x + h) - 8 * f(x - h) + f(x - 2 * h)) / (12 * h)


def test_backbone_speed_gradients_match_finite_differences():
    """The bisection carries no derivative: jax.grad was exactly 0 w.r.t. a, v_l, span and the pulley radii
    (finite differences: 764.8, 0.153, -12.7). Now the implicit-function derivative, eagerly and under jit."""
    import equinox as eqx

    belt = jb.NonlinearBelt()
    cases = [
        (lambda a: jb.backbone_speed(belt, a), 0.01, 1e-5),
        (lambda vl: jb.backbone_speed(eqx.tree_at(lambda b: b.v_l, belt, vl), 0.01), 50.0, 1e-3),
        (lambda L: jb.backbone_speed(eqx.tree_at(lambda b: b.span, belt, L), 0.01), 0.86, 1e-5),
        (
            lambda r: jb.backbone_speed(eqx.tree_at(lambda b: b.pulley_radii, belt, jnp.stack([r, r])), 0.01),
            0.063,
            1e-6,
        ),
    ]
    for f, x, h in cases:
        ref = float(_fd5(f, x, h))
        assert abs(ref) > 1e-3
        assert float(jax.grad(f)(x)) == pytest.approx(ref, rel=1e-7)
        assert float(jax.jit(jax.grad(f))(x)) == pytest.approx(ref, rel=1e-7)


def test_backbone_amplitude_gradient_is_zero_below_the_crossing():
    """Below the linear crossing the amplitude is 0 on an open interval: its derivative is 0 (it was NaN)."""
    belt = jb.NonlinearBelt()
    f = lambda v: jb.backbone_amplitude(belt, v)  # noqa: E731
    speeds = jnp.array([7.0, 8.0, 9.5, 10.0])
    grads = np.asarray(jax.vmap(jax.grad(f))(speeds))
    ref = np.array([float(_fd5(f, float(v), 1e-4)) for v in speeds])
    np.testing.assert_array_equal(grads[:2], [0.0, 0.0])
    np.testing.assert_allclose(grads[2:], ref[2:], rtol=1e-7)
