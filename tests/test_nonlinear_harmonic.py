"""Harmonic balance, continuation, stability, folds and speed ramps of the non-linear belt
(Moon & Wickert, 1997). References: the diffrax time-domain steady states and sweeps, central
finite differences, the KBM cubic (eq. 31), closed-form ramp integrals; tolerances stated."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.models.nonlinear.kbm import kbm_amplitudes
from jaxbelt.models.nonlinear.model import distance_travelled


def old_belt(**kw):
    """The former default (v_t = 41 m/s, xi = 0.015): a narrow band near 9.3-9.4 m/s."""
    base = dict(wave_speed=41.0, v_l=50.0, runout=(0.355e-3, 0.21e-3), phase=jnp.deg2rad(240.0), damping=0.015,
                n_modes=1, sensor_pulley="drive", travel="drive_to_idle")
    base.update(kw)
    return jb.NonlinearBelt(**base)


@pytest.fixture(scope="module")
def curve():
    return jb.response_curve(old_belt(), (8.5, 10.0), 3)


def test_harmonic_balance_matches_time_domain():
    """HB (3 harmonics) against the diffrax steady state off the band: 1e-4 relative (measured ~1e-5)."""
    b = old_belt()
    for speed in (8.0, 10.0):
        hb = jb.harmonic_balance(b, speed, 3)
        td = jb.nonlinear_steady_state(b, speed, rtol=1e-6)
        assert abs(float(hb.pp) / float(td.pp) - 1) < 1e-4, (speed, hb.pp, td.pp)
        np.testing.assert_allclose(hb.amplitude, td.amplitude, rtol=1e-3)


def _branch_state(curve, speed, direction):
    """HB solution at `speed` on the stable branch an up/down sweep follows (guess from the curve)."""
    s, st = np.asarray(curve.speed), np.asarray(curve.stable)
    bs, _ = curve.branch(direction)
    idx = [i for i in range(s.size) if st[i] and s[i] in bs]
    i = idx[int(np.argmin(np.abs(s[idx] - speed)))]
    return jb.harmonic_balance(old_belt(), speed, 3, guess=curve.coefficients[i])


def test_curve_folds_and_stability_match_time_domain_sweeps(curve):
    """The time domain (diffrax) is the independent check of the continuation:
    - up/down quasi-static sweeps (0.02 m/s steps) agree with HB on the branch they follow to 1e-3;
    - the sweeps jump within 0.06 m/s inside the folds (near a fold the basin thins, a finite speed
      step leaves it early);
    - started on the HB upper branch 0.01 m/s below the upper fold, the time domain stays there
      (pp within 1e-3); 0.01 m/s above it, no upper branch exists and it falls to the lower one;
    - the unstable (saddle) points lie between the folds."""
    b = old_belt()
    lo, hi = (float(f) for f in curve.folds)
    speeds = jnp.round(jnp.arange(9.20, 9.5001, 0.02), 6)
    ru = jb.nonlinear_sweep(b, speeds, rtol=1e-6)
    rd = jb.nonlinear_sweep(b, speeds[::-1], rtol=1e-6)
    assert bool(np.all(ru.converged)) and bool(np.all(rd.converged))
    s = np.asarray(speeds)
    au, ad = np.asarray(ru.steady.amplitude[:, 0]), np.asarray(rd.steady.amplitude[:, 0])[::-1]
    k_up = int(np.argmin(np.diff(au)))  # the up-sweep's drop of the modal amplitude
    assert hi - 0.06 <= s[k_up] <= hi < s[k_up + 1] + 0.06, (s[k_up], hi)
    k_dn = int(np.argmin(np.diff(ad)))  # ascending order: large below the lower fold, small above
    assert s[k_dn] - 0.06 < lo <= s[k_dn + 1] <= lo + 0.06, (s[k_dn], lo)
    for res, direction in ((ru, "up"), (rd, "down")):
        for sp, pp in zip(np.asarray(res.speeds)[::3], np.asarray(res.pp)[::3]):
            hb = _branch_state(curve, float(sp), direction)
            if abs(float(hb.amplitude[0]) / float(res.steady.amplitude[list(np.asarray(res.speeds)).index(sp), 0]) - 1) < 0.05:
                assert abs(float(hb.pp) / pp - 1) < 1e-3, (direction, sp, float(hb.pp), pp)
    top = _branch_state(curve, hi - 0.01, "up")
    z0 = top.coefficients @ np.r_[1.0, np.ones(3), np.zeros(3)]  # state at phase 0
    stay = jb.nonlinear_steady_state(b, hi - 0.01, z0, rtol=1e-6)
    assert abs(float(stay.pp) / float(top.pp) - 1) < 1e-3
    fall = jb.nonlinear_steady_state(b, hi + 0.01, z0, rtol=1e-6)
    assert float(fall.amplitude[0]) < 0.8 * float(top.amplitude[0])
    un = np.asarray(curve.speed)[~np.asarray(curve.stable)]
    assert un.size > 0 and un.min() >= lo - 1e-6 and un.max() <= hi + 1e-6


def test_hb_branches_at_one_speed_match_kbm_roots(curve):
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
    kbm = np.sort(np.asarray(kbm_amplitudes(old_belt(), v)))
    np.testing.assert_allclose(np.sort(amps), kbm, rtol=0.10)
    mid = int(np.argsort(amps)[1])
    assert not stab[mid] and sum(stab) == 2


def test_fold_speed_gradient_matches_finite_differences():
    """jax.grad of the up-sweep jump speed (upper fold) w.r.t. damping, v_l and v_t against
    central differences (h = 1e-4 relative): 1e-4 relative."""
    b = old_belt()
    f = lambda bb: jb.fold_speeds(bb, (8.5, 10.0), 3)[1]  # noqa: E731
    g = jax.grad(f)(b)
    for name in ("damping", "v_l", "wave_speed"):
        x = float(getattr(b, name))
        h = 1e-4 * x
        fp = float(f(jax.tree_util.tree_map(lambda a: a, b.__class__(**{**_fields(b), name: x + h}))))
        fm = float(f(b.__class__(**{**_fields(b), name: x - h})))
        fd = (fp - fm) / (2 * h)
        assert abs(float(getattr(g, name)) - fd) <= 1e-4 * abs(fd) + 1e-9, (name, float(getattr(g, name)), fd)


def _fields(b):
    return dict(span=b.span, wave_speed=b.wave_speed, v_l=b.v_l, pulley_radii=b.pulley_radii, runout=b.runout,
                phase=b.phase, damping=b.damping, n_modes=b.n_modes, sensor_pulley=b.sensor_pulley, travel=b.travel)


def test_speed_ramp_record_and_scene():
    """A ramp 9.0 -> 9.6 m/s in 6 s starts on the HB response (pp of the first revolutions within
    1 %), ends on the low branch (last revolutions within 5 % of HB at 9.6 m/s; the ramp lags a
    little: measured 4.3 % while the transient after the jump decays), and `simulate` of the `SpeedRamp` scene returns the same record (1e-6 of the run-out)."""
    b = old_belt()
    rec = jb.speed_ramp(b, 9.0, 9.6, 6.0)
    t, w = np.asarray(rec.t), np.asarray(rec.w)
    T = 2 * np.pi * 0.063 / 9.0
    first = w[t < 3 * T]
    last = w[t > t[-1] - 3 * 2 * np.pi * 0.063 / 9.6]
    assert abs(np.ptp(first) / float(jb.harmonic_balance(b, 9.0, 5).pp) - 1) < 0.01
    assert abs(np.ptp(last) / float(jb.harmonic_balance(b, 9.6, 5).pp) - 1) < 0.05
    ts = jnp.asarray(t[::50])
    sol = jb.simulate(jb.Scene(b, jb.SpeedRamp(9.0, 9.6, 6.0), ts, y0=rec.z[0], observe=("w_sensor",)),
                      method="ode", rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.asarray(sol["w_sensor"]),
                               w[::50], atol=1e-6 * 0.565e-3 * 2)


def test_ramp_distance_closed_form_and_quadrature():
    """The pulley travel of a ramp, closed form vs 24-point Gauss quadrature of its speed: 1e-12."""
    r = jb.SpeedRamp(8.4, 9.2, 2.0)

    class Generic(jb.AbstractRunningSpeed):
        def speed_at(self, t):
            return r.speed_at(t)

    for t in (0.5, 1.3):  # inside the ramp (quadrature exact for the linear speed)
        assert abs(float(r.distance_at(t)) - float(distance_travelled(Generic(), t))) < 1e-12
    assert abs(float(r.distance_at(3.0)) - (8.8 * 2.0 + 9.2 * 1.0)) < 1e-12


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
def test_default_belt_jumps_at_measured_speeds():
    """The default (identified) belt: the increasing sweep jumps at 8.9 +- 0.15 m/s and the
    decreasing one at 8.5 +- 0.15 m/s, the measured jumps of Moon & Wickert (1997), Sec. 2."""
    f = np.asarray(jb.fold_speeds(jb.NonlinearBelt(), (7.0, 11.0), 3))
    m = {x.quantity: x for x in jb.MEASUREMENTS}
    assert abs(f[1] - m["up_jump_speed"].value) <= m["up_jump_speed"].tolerance
    assert abs(f[0] - m["down_jump_speed"].value) <= m["down_jump_speed"].tolerance
