"""Harmonic balance, continuation, stability, folds and speed ramps of the non-linear belt
(Moon & Wickert, 1997). References: the diffrax time-domain steady states and sweeps, central
finite differences, the KBM cubic (eq. 31), closed-form ramp integrals; tolerances stated."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles

import jaxbelt as jb
from jaxbelt.models.nonlinear.calibration import MODE2_RANGE, model_fold_speeds
from jaxbelt.models.nonlinear.kbm import kbm_amplitudes
from jaxbelt.models.nonlinear.model import distance_travelled


def old_belt(**kw):
    """The former default (v_t = 41 m/s, xi = 0.015, sensor at the drive pulley)."""
    base = dict(
        wave_speed=41.0,
        v_l=50.0,
        runout=(0.355e-3, 0.21e-3),
        phase=jnp.deg2rad(240.0),
        damping=0.015,
        n_modes=1,
        sensor_pulley="drive",
        travel="drive_to_idle",
    )
    base.update(kw)
    return jb.NonlinearBelt(**base)


RANGE = (7.5, 10.5)  # the benchmark's range: one compiled continuation serves every test below


@pytest.fixture(scope="module")
def belt():
    return jb.NonlinearBelt()


@pytest.fixture(scope="module")
def curve(belt):
    return jb.response_curve(belt, RANGE, 3)


@pytest.fixture(scope="module")
def sweeps(belt, curve):
    """Time-domain (diffrax) quasi-static sweeps in 0.01 m/s steps across each fold."""
    lo, hi = (float(f) for f in curve.folds)
    # grids offset by half a step from the folds (exactly at a fold the transient decays algebraically)
    up_s = jnp.asarray(hi - 0.085 + 0.01 * np.arange(13))
    dn_s = jnp.asarray(lo + 0.085 - 0.01 * np.arange(13))
    z_up = _branch_state(belt, curve, float(up_s[0]), "up").coefficients @ np.r_[1.0, np.ones(3), np.zeros(3)]
    ru = jb.nonlinear_sweep(belt, up_s, z_up, rtol=1e-6)
    rd = jb.nonlinear_sweep(belt, dn_s, rtol=1e-6)
    return np.asarray(up_s), ru, np.asarray(dn_s), rd


def test_harmonic_balance_matches_time_domain(belt):
    """HB (3 harmonics) against the diffrax steady state off the band: 1e-4 relative (measured ~1e-5)."""
    for speed in RANGE:
        hb = jb.harmonic_balance(belt, speed, 3)
        td = jb.nonlinear_steady_state(belt, speed, rtol=1e-6)
        assert abs(float(hb.pp) / float(td.pp) - 1) < 1e-4, (speed, hb.pp, td.pp)
        np.testing.assert_allclose(hb.amplitude, td.amplitude, rtol=1e-3)


def _branch_state(belt, curve, speed, direction, throw=True):
    """HB solution at `speed` on the stable branch an up/down sweep follows (guess from the curve)."""
    s, st = np.asarray(curve.speed), np.asarray(curve.stable)
    bs, _ = curve.branch(direction)
    idx = [i for i in range(s.size) if st[i] and s[i] in bs]
    i = idx[int(np.argmin(np.abs(s[idx] - speed)))]
    return jb.harmonic_balance(belt, speed, 3, guess=curve.coefficients[i], throw=throw)


def test_default_belt_jumps_at_measured_speeds(belt, curve):
    """The default (identified) belt: the increasing sweep jumps at 8.9 +- 0.15 m/s and the
    decreasing one at 8.5 +- 0.15 m/s (Moon & Wickert (1997), Sec. 2); `fold_speeds` (the
    refined, differentiable folds) equals the curve's folds to 1e-8 m/s."""
    f = np.asarray(curve.folds)
    m = {x.quantity: x for x in jb.MEASUREMENTS}
    assert f.shape == (2,)
    assert abs(f[1] - m["up_jump_speed"].value) <= m["up_jump_speed"].tolerance
    assert abs(f[0] - m["down_jump_speed"].value) <= m["down_jump_speed"].tolerance
    np.testing.assert_allclose(np.asarray(jb.fold_speeds(belt, RANGE, 3)), f, atol=1e-8)


@pytest.fixture(scope="module")
def belt2():
    return jb.NonlinearBelt(n_modes=2)


@pytest.fixture(scope="module")
def curve2(belt2):
    """The two-mode default belt over the second resonance."""
    return jb.response_curve(belt2, MODE2_RANGE, 3, max_points=400)


def _monodromy_reference(belt, speed, X, H):
    """The monodromy matrix of the variational equation about the periodic solution with Fourier coefficients
    `X` (2N, 2H+1) at `speed`, by scipy's DOP853 at rtol 1e-12 (an independent integrator)."""
    from scipy.integrate import solve_ivp

    from jaxbelt.models.nonlinear.harmonic import _basis

    sys = belt._modal_v(speed / belt.wave_speed)
    W, m = float(sys.Omega[0]), X.shape[0]

    @jax.jit
    def jac(tau):
        phi = W * tau
        z = jnp.asarray(X) @ _basis(H, jnp.atleast_1d(phi))[:, 0]
        return jax.jacfwd(lambda zz: sys.rhs_angles(zz, phi, phi + sys.phase))(z)

    def rhs(t, y):
        return (np.asarray(jac(t)) @ y.reshape(m, m)).ravel()

    sol = solve_ivp(rhs, (0.0, 2 * np.pi / W), np.eye(m).ravel(), method="DOP853", rtol=1e-12, atol=1e-14)
    return sol.y[:, -1].reshape(m, m)


@pytest.mark.parametrize("which", ["one mode", "two modes"])
def test_floquet_multipliers_match_an_independent_integration(which, belt, curve, belt2, curve2):
    # the curve's multipliers (classic RK4, 192 steps per period and mode) against the eigenvalues of a DOP853
    # monodromy matrix: measured <= 5e-7 of the largest multiplier; on both sides of the folds (stable and not)
    b, c = (belt, curve) if which == "one mode" else (belt2, curve2)
    unstable = np.flatnonzero(~np.asarray(c.stable))
    assert unstable.size > 0
    picks = np.r_[np.linspace(0, c.speed.shape[0] - 1, 4).astype(int), unstable[[0, unstable.size // 2]]]
    for i in picks:
        ref = np.linalg.eigvals(_monodromy_reference(b, float(c.speed[i]), np.asarray(c.coefficients[i]), 3))
        mu = np.asarray(c.multipliers[i])
        err = max(np.min(np.abs(ref - m)) for m in mu) + max(np.min(np.abs(mu - r)) for r in ref)
        assert err < 2e-6 * np.max(np.abs(ref)), (i, mu, ref)
        assert bool(c.stable[i]) == bool(np.max(np.abs(ref)) < 1.0)


def test_default_two_mode_belt_meets_all_four_measured_jump_speeds(belt2, curve2):
    """The identified defaults, two modes: first-mode jumps at 8.5 / 8.9 +- 0.15 m/s and the
    second-mode hysteresis inside the measured band 15.5-16.3 m/s (15.7 / 16.1 +- 0.2; Moon &
    Wickert (1997), Sec. 2); the refined folds equal the curve's folds to 1e-8 m/s."""
    m = {x.quantity: x for x in jb.MEASUREMENTS}
    f = np.asarray(model_fold_speeds(belt2))
    for value, q in zip(f, ("down_jump_speed", "up_jump_speed", "mode2_band_low", "mode2_band_high")):
        assert abs(value - m[q].value) <= m[q].tolerance, (q, value)
    assert 15.5 <= f[2] < f[3] <= 16.3
    np.testing.assert_allclose(np.asarray(curve2.folds), f[2:], atol=1e-8)
    # between the folds the middle branch is unstable (Floquet), outside there is one stable branch
    s, st = np.asarray(curve2.speed), np.asarray(curve2.stable)
    assert not np.all(st) and np.all(st[(s < f[2] - 0.02) | (s > f[3] + 0.02)])


def test_second_mode_bistability_matches_time_domain(belt2, curve2):
    """Independent check of the second-mode hysteresis: at a speed between the folds the diffrax
    time-domain steady states started on the two stable HB branches stay there, with the HB
    peak-to-peak to 1e-3 relative, and the two differ (two coexisting stable responses)."""
    lo, hi = (float(x) for x in curve2.folds)
    speed = 0.5 * (lo + hi)
    pps = []
    for direction in ("up", "down"):
        hb = _branch_state(belt2, curve2, speed, direction)
        z0 = np.asarray(hb.coefficients) @ np.r_[1.0, np.ones(3), np.zeros(3)]  # the state at phase 0
        td = jb.nonlinear_steady_state(belt2, speed, z0, rtol=1e-7)
        assert bool(td.converged)
        assert abs(float(td.pp) / float(hb.pp) - 1) < 1e-3, (direction, td.pp, hb.pp)
        pps.append(float(td.pp))
    assert abs(pps[0] / pps[1] - 1) > 0.2, pps


def test_calibrate_refuses_options_it_would_truncate():
    # checked before any work: a fractional count is refused by name, not rounded by int()
    for kw, name in ((dict(n_harmonics=2.5), "n_harmonics"), (dict(max_steps=0), "max_steps")):
        with pytest.raises(ValueError, match=f"calibrate: parameter `{name}` must be an integer"):
            jb.calibrate(**kw)


@pytest.mark.slow
def test_calibrate_recovers_the_identified_defaults():
    """`calibrate` (Levenberg-Marquardt through the implicit fold derivatives) from the former
    defaults (v_t 37.44 m/s, xi (0.0112, 0.0255)) lands on the defaults of `NonlinearBelt` to
    their rounding (5e-4 relative), with the four fold speeds inside the measured tolerances."""
    start = jb.NonlinearBelt(wave_speed=37.44, damping=(0.0112, 0.0255))
    fit = jb.calibrate(start)
    d = jb.NonlinearBelt()
    assert bool(fit.success)
    np.testing.assert_allclose(float(fit.belt.wave_speed), float(d.wave_speed), rtol=5e-4)
    np.testing.assert_allclose(np.asarray(fit.belt.damping), np.asarray(d.damping), rtol=5e-4)
    assert np.all(np.abs(np.asarray(fit.residuals)) < 1.0)  # each speed within its reading tolerance
    assert float(fit.cost) < 0.5
    # a second fit of the same problem (from the defaults) reuses the compiled solve: no compilation
    with count_compiles() as compiles:
        again = jb.calibrate(d)
    assert compiles["n"] == 0
    np.testing.assert_allclose(float(again.belt.wave_speed), float(fit.belt.wave_speed), rtol=5e-4)
    assert bool(again.success)


def test_curve_folds_and_stability_match_time_domain_sweeps(belt, curve, sweeps):
    """The time domain (diffrax) is the independent check of the continuation:
    - quasi-static sweeps in 0.01 m/s steps jump between the two speeds that bracket the fold
      (up: s_k <= upper fold < s_k+1; down: s_k+1 < lower fold <= s_k);
    - on the branch they follow, the sweeps' pp agree with HB to 1e-3;
    - started on the HB upper branch 0.01 m/s below the upper fold the time domain stays there
      (pp within 1e-3); 0.01 m/s above it there is no upper branch and it falls to the lower one;
    - the unstable (saddle) points lie between the folds."""
    lo, hi = (float(f) for f in curve.folds)
    up_s, ru, dn_s, rd = sweeps
    assert bool(np.all(ru.converged)) and bool(np.all(rd.converged))
    au, ad = np.asarray(ru.steady.amplitude[:, 0]), np.asarray(rd.steady.amplitude[:, 0])
    k = int(np.argmin(np.diff(au)))  # the up-sweep's drop of the modal amplitude
    assert au[k + 1] < 0.7 * au[k] and up_s[k] <= hi < up_s[k + 1], (up_s[k], hi)
    k = int(np.argmax(np.diff(ad)))  # the down-sweep's rise
    assert ad[k + 1] > 1.4 * ad[k] and dn_s[k + 1] < lo <= dn_s[k], (dn_s[k], lo)
    compared = 0
    for res, speeds, direction in ((ru, up_s, "up"), (rd, dn_s, "down")):
        for i in range(0, speeds.size, 3):
            hb = _branch_state(belt, curve, float(speeds[i]), direction, throw=False)
            if (
                bool(hb.success) and abs(float(hb.amplitude[0]) / float(res.steady.amplitude[i, 0]) - 1) < 0.05
            ):  # same branch
                assert abs(float(hb.pp) / float(res.pp[i]) - 1) < 1e-3, (direction, speeds[i])
                compared += 1
    assert compared >= 6
    top = _branch_state(belt, curve, hi - 0.01, "up")
    z0 = top.coefficients @ np.r_[1.0, np.ones(3), np.zeros(3)]  # state at phase 0
    stay = jb.nonlinear_steady_state(belt, hi - 0.01, z0, rtol=1e-6)
    assert abs(float(stay.pp) / float(top.pp) - 1) < 1e-3
    fall = jb.nonlinear_steady_state(belt, hi + 0.01, z0, rtol=1e-6)
    assert float(fall.amplitude[0]) < 0.8 * float(top.amplitude[0])
    un = np.asarray(curve.speed)[~np.asarray(curve.stable)]
    assert un.size > 0 and un.min() >= lo - 1e-6 and un.max() <= hi + 1e-6


def test_jump_amplitudes_match_time_domain(belt, curve, sweeps):
    """`jumps`: the fold speeds equal the curve's folds (1e-8 m/s); the pp each sweep lands on
    equals the diffrax steady state at the fold speed started from the sweep's first state after
    the jump (1e-3), and the pp before each jump lies within 5 % of the last sweep point, 0.005 m/s
    before the fold."""
    j = jb.jumps(belt, RANGE, 3)
    np.testing.assert_allclose(np.asarray(j.speed), np.asarray(curve.folds), atol=1e-8)
    assert np.all(np.isfinite(np.asarray(j.pp_after))) and np.all(np.isfinite(np.asarray(j.pp_before)))
    up_s, ru, dn_s, rd = sweeps
    au, ad = np.asarray(ru.steady.amplitude[:, 0]), np.asarray(rd.steady.amplitude[:, 0])
    ku = int(np.argmin(np.diff(au))) + 1  # first up-sweep point after the jump
    kd = int(np.argmax(np.diff(ad))) + 1  # first down-sweep point after the jump
    for idx, (res, k) in ((1, (ru, ku)), (0, (rd, kd))):
        land = jb.nonlinear_steady_state(belt, float(j.speed[idx]), res.steady.z[k], rtol=1e-7)
        assert abs(float(j.pp_after[idx]) / float(land.pp) - 1) < 1e-3, (idx, float(j.pp_after[idx]), float(land.pp))
        # near a fold pp varies as sqrt(V_fold - V): 0.005 m/s before it, measured 1.7 % (up), 3.7 % (down)
        assert abs(float(j.pp_before[idx]) / float(res.pp[k - 1]) - 1) < 0.05, (idx, float(j.pp_before[idx]))


def test_hb_branches_at_one_speed_match_kbm_roots(belt, curve):
    """Inside the band the curve has three points at one speed; their modal amplitudes match the
    three real roots of the KBM cubic (eq. 31) to 10 % (first-order averaging; measured 7.7 % on the
    saddle, < 5 % on the stable ones), the middle one unstable."""
    lo, hi = (float(f) for f in curve.folds)
    v = 0.5 * (lo + hi)
    s, a, st = (np.asarray(x) for x in (curve.speed, curve.amplitude[:, 0], curve.stable))
    cross = np.nonzero((s[:-1] - v) * (s[1:] - v) <= 0)[0]
    assert cross.size == 3
    amps = [a[i] + (v - s[i]) / (s[i + 1] - s[i]) * (a[i + 1] - a[i]) for i in cross]
    stab = [st[i] and st[i + 1] for i in cross]
    kbm = np.sort(np.asarray(kbm_amplitudes(belt, v)))
    np.testing.assert_allclose(np.sort(amps), kbm, rtol=0.10)
    mid = int(np.argsort(amps)[1])
    assert not stab[mid] and sum(stab) == 2


@pytest.mark.slow
def test_fold_speed_gradient_matches_finite_differences(belt):
    """jax.grad of the up-sweep jump speed (upper fold) w.r.t. damping, v_l and v_t against
    central differences of `fold_speeds` (h = 1e-4 relative): 1e-4 relative."""
    f = lambda bb: jb.fold_speeds(bb, RANGE, 3)[1]  # noqa: E731
    g = jax.grad(f)(belt)
    # the one-mode belt uses the first of the per-mode damping ratios only
    assert float(g.damping[1]) == 0.0
    for name in ("damping", "v_l", "wave_speed"):
        x0 = np.asarray(getattr(belt, name), dtype=float)
        x = float(x0.ravel()[0])
        h = 1e-4 * x

        def at(xx, x0=x0):  # the parameter with its first entry replaced
            return np.r_[xx, x0.ravel()[1:]].reshape(x0.shape)

        fp = float(f(belt.__class__(**{**_fields(belt), name: at(x + h)})))
        fm = float(f(belt.__class__(**{**_fields(belt), name: at(x - h)})))
        fd = (fp - fm) / (2 * h)
        gi = float(np.ravel(getattr(g, name))[0])
        assert abs(gi - fd) <= 1e-4 * abs(fd) + 1e-9, (name, gi, fd)


def _fields(b):
    return dict(
        span=b.span,
        wave_speed=b.wave_speed,
        v_l=b.v_l,
        pulley_radii=b.pulley_radii,
        runout=b.runout,
        phase=b.phase,
        damping=b.damping,
        n_modes=b.n_modes,
        sensor_pulley=b.sensor_pulley,
        travel=b.travel,
    )


@pytest.mark.slow
def test_speed_ramp_record_and_scene(belt, curve):
    """A ramp 8.7 -> 9.1 m/s in 3 s through the upper fold, then 4 s held at 9.1 m/s: the first
    revolutions are on the HB response at 8.7 m/s (pp within 0.5 %), the record drops from the
    upper to the lower branch inside the band, at most 0.01 m/s past the upper fold (Fig. 3(a)), and the last revolutions are on the
    HB response at 9.1 m/s (within 0.5 %: the transient after the jump decays as
    exp(-xi omega_1 t), 4 s ~ 6 time constants). `simulate` of the `SpeedRamp` scene returns the
    same record (1e-6 of the run-out)."""
    hi = float(curve.folds[1])
    rec = jb.speed_ramp(belt, 8.7, 9.1, 3.0, hold=4.0)
    t, w, v = np.asarray(rec.t), np.asarray(rec.w), np.asarray(rec.speed)
    rev = lambda V: 2 * np.pi * 0.063 / V  # noqa: E731
    first = w[t < 3 * rev(8.7)]
    last = w[t > t[-1] - 3 * rev(9.1)]
    assert abs(np.ptp(first) / float(jb.harmonic_balance(belt, 8.7, 5).pp) - 1) < 5e-3
    assert abs(np.ptp(last) / float(jb.harmonic_balance(belt, 9.1, 5).pp) - 1) < 5e-3
    # per-revolution pp: the drop happens inside the hysteresis band, not past the upper fold
    # (a ramp leaves the thinning basin a little before the static fold)
    n = 24
    m = w.size // n
    pp_rev = np.ptp(w[: m * n].reshape(m, n), axis=1)
    v_rev = v[: m * n].reshape(m, n).mean(axis=1)
    k = int(np.argmin(np.diff(pp_rev)))
    assert float(curve.folds[0]) <= v_rev[k] <= hi + 0.01, (v_rev[k], hi)
    ts = jnp.asarray(t[: t.size // 2 : 50])
    sol = jb.simulate(
        jb.Scene(belt, jb.SpeedRamp(8.7, 9.1, 3.0), ts, y0=rec.z[0], observe=("w_sensor",)),
        method="ode",
        rtol=1e-10,
        atol=1e-14,
    )
    np.testing.assert_allclose(np.asarray(sol["w_sensor"]), w[: t.size // 2 : 50], atol=1e-6 * 0.565e-3 * 2)


def test_ramp_distance_closed_form_and_quadrature():
    """The pulley travel of a ramp, closed form vs 24-point Gauss quadrature of its speed: 1e-12."""
    r = jb.SpeedRamp(8.4, 9.2, 2.0)

    class Generic(jb.AbstractRunningSpeed):
        def speed_at(self, t):
            return r.speed_at(t)

    for t in (0.5, 1.3):  # inside the ramp (quadrature exact for the linear speed)
        assert abs(float(r.distance_at(t)) - float(distance_travelled(Generic(), t))) < 1e-12
    assert abs(float(r.distance_at(3.0)) - (8.8 * 2.0 + 9.2 * 1.0)) < 1e-12


def test_a_speed_profile_of_ones_own_is_checked_at_each_output_time():
    """`input_checks` covers a constant speed and a ramp whole (its ends); another profile is checked at
    t = 0 there and at each output time by the `w_sensor` observable: this one passes the wave speed
    (37.94 m/s) at t = 0.36 s and is refused by name."""

    class Surge(jb.AbstractRunningSpeed):
        def speed_at(self, t):
            return 9.0 + 80.0 * jnp.asarray(t, dtype=float)

    belt = jb.NonlinearBelt()
    scene = jb.Scene(belt, Surge(), ts=jnp.linspace(0.0, 0.5, 6), observe=("w_sensor",))
    with pytest.raises(Exception, match="sub-critical"):
        jb.simulate(scene, method="ode")
    ok = jb.simulate(jb.Scene(belt, Surge(), ts=jnp.linspace(0.0, 0.3, 4), observe=("w_sensor",)), method="ode")
    assert np.all(np.isfinite(np.asarray(ok["w_sensor"])))


def test_bad_inputs():
    with pytest.raises(ValueError, match="pulley_radii"):
        jb.response_curve(old_belt(pulley_radii=(0.063, 0.05)), (8.0, 9.0))
    with pytest.raises(ValueError, match="n_harmonics"):
        jb.harmonic_balance(old_belt(), 9.0, 0)
    with pytest.raises(ValueError, match="speed_range"):
        jb.fold_speeds(old_belt(), (10.0, 8.0))
    with pytest.raises(ValueError, match="duration"):
        jb.SpeedRamp(8.0, 9.0, -1.0)
    with pytest.raises(ValueError, match="sensor_pulley"):
        jb.NonlinearBelt(sensor_pulley="left")


@pytest.mark.slow
def test_cli_nonlinear_quick(tmp_path, curve, capsys):
    """`jaxbelt nonlinear --quick --out F` exits 0, prints the written name exactly and the fold
    speeds, which equal the library's `response_curve` folds to the printed 1e-4 m/s. (Run in this
    process, without the compilation cache: the `jaxbelt` command as a fresh process is tested by
    test_guarantees.py, and timed with and without the cache by benchmarks/coldstart.py.)"""
    import re

    from jaxbelt.cli import main

    out = tmp_path / "nl.png"
    assert main(["--no-cache", "nonlinear", "--quick", "--out", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert f"wrote {out}" in stdout.splitlines()
    assert out.stat().st_size > 10_000
    folds = [float(x) for x in re.search(r"folds ([\d.]+), ([\d.]+) m/s", stdout).groups()]
    np.testing.assert_allclose(folds, np.asarray(curve.folds), atol=1.5e-4)
