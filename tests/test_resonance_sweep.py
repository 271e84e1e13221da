"""The raw record of a resonance sweep (`identify_axis_from_sweep`), against independent references: the exact
simulation `sweep_response` against scipy's `solve_ivp` segment by segment; the fit of the record's transfer
function against scipy's `least_squares` on the same frequency-domain model (the input's transform summed edge by
edge, from the true delay); the truth within the standard errors; one compiled program per length."""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import resonance_test as rt

AXIS = ([35.0, 52.0], [0.04, 0.03], [1.0, 0.4])
SWEEP = dict(freq_start=20.0, freq_end=70.0, hz_per_sec=5.0)  # 10 s of record: a short sweep for quick tests
RATE, NOISE, LEAD = 3200.0, 200.0, 0.1


def record(seed, axis=AXIS, lead=LEAD):
    """A sweep's record as Klipper writes it: mm/s^2, sensor noise, `%.6f` time stamps 100 s into its clock."""
    sweep = jb.klipper_sweep(**SWEEP)
    t, y = rt.sweep_response(jb.ModalAxis(*axis), RATE, *sweep, lead=lead)
    y = 1e3 * y + NOISE * np.random.default_rng(seed).standard_normal(t.size)
    return np.round(t + 100.0, 6), y, sweep


@pytest.mark.slow
def test_sweep_response_matches_solve_ivp():
    """Exact propagation against scipy's RK45 at rtol 1e-11, segment by segment (the acceleration constant on
    each): the payload's acceleration within 1e-7 of its peak."""
    from scipy.integrate import solve_ivp

    ends, accel = jb.klipper_sweep(freq_start=30.0, freq_end=32.0, hz_per_sec=4.0, sweeping_period=0.2)
    (f1, f2), (z1, z2), (g1, g2) = AXIS
    t, y = rt.sweep_response(jb.ModalAxis(*AXIS), RATE, ends, accel, lead=0.05)
    w = 2 * np.pi * np.array([f1, f2])
    z, g = np.array([z1, z2]), np.array([g1, g2])

    def rhs(_, x, a):
        q, v = x[:2], x[2:]
        return np.concatenate([v, -(w**2) * q - 2 * z * w * v - g * a])

    bounds = np.concatenate([[-0.05, 0.0], ends])
    levels = np.concatenate([[0.0], accel])
    x, ref = np.zeros(4), np.empty_like(y)
    for lo, hi, a in zip(bounds[:-1], bounds[1:], levels):
        inside = (t >= lo) & (t < hi)
        times = np.append(t[inside], hi)
        sol = solve_ivp(rhs, (lo, hi), x, args=(a,), t_eval=times, rtol=1e-11, atol=1e-14, method="RK45")
        q, v = sol.y[:2, :-1], sol.y[2:, :-1]
        ref[inside] = a + np.sum(-(w[:, None] ** 2) * q - 2 * (z * w)[:, None] * v - g[:, None] * a, axis=0)
        x = sol.y[:, -1]
    last = t >= bounds[-1]
    assert np.all(~last[:-1])  # the record ends at the sweep's end
    np.testing.assert_allclose(y[~last], ref[~last], atol=1e-7 * np.max(np.abs(ref)))


def _reference_fit(t, y, sweep, tau):
    """The frequency-domain model of `identify_axis_from_sweep` fitted by scipy's `least_squares`, the sampled input
    at the delay `tau` and shifted from there as a band-limited signal (a phase): the input's transform summed over the schedule's edges, the DFT of the sampled input by numpy; the
    record cut to the fast FFT length the module fits."""
    from scipy.optimize import least_squares

    ends, accel = sweep
    h = float(np.mean(np.diff(t)))
    n = rt._smooth_length(y.size, up=False)
    y = y[:n]
    T = n * h
    m = np.arange(int(np.ceil(5.0 * T)), int(135.0 * T) + 1)
    w = 2 * np.pi * m / T
    levels = np.concatenate([[0.0], accel, [0.0]])
    edges = np.concatenate([[0.0], ends]) + tau
    jumps = np.diff(levels)
    inside = (edges > 0) & (edges < T)
    tail = levels[np.searchsorted(edges, T, side="right")] if edges[-1] > T else 0.0
    A = (-tail + np.exp(-1j * np.outer(w, edges[inside])) @ jumps[inside]) / (1j * w) / h
    s_time = np.arange(n) * h - tau
    idx = np.searchsorted(ends, s_time, side="right")
    a = np.where((s_time >= 0) & (idx < ends.size), accel[np.minimum(idx, ends.size - 1)], 0.0)
    S = np.fft.rfft(a)[m]
    Y = np.fft.rfft(y)[m]
    wr = 2 * np.pi * 50.0

    def model(p):
        f, z = p[:2], p[2:4]
        d0, b, al, be, k = p[4], p[5:7], p[7:9], p[9:11], p[11:14]
        delay = np.exp(-1j * w * h * p[14])  # a shift of the input by p[14] samples
        out = d0 * S * delay + k[0] / (1j * w / wr) + k[1] + 1j * k[2] * w / wr
        for i in range(2):
            x = w / (2 * np.pi * f[i])
            den = 1 - x**2 + 2j * z[i] * x
            out = out + (b[i] * (1 + 2j * z[i] * x) * A * delay + al[i] + 1j * be[i] * x) / den
        return out

    def resid(p):
        e = (model(p) - Y) / 1e6
        return np.concatenate([e.real, e.imag])

    p0 = np.array([34.8, 52.2, 0.045, 0.028, -400.0, 1000.0, 400.0] + [0.0] * 8)
    ref = least_squares(resid, p0, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    J = ref.jac
    s2 = float(ref.fun @ ref.fun) / (ref.fun.size - p0.size)
    std = np.sqrt(np.diag(np.linalg.inv(J.T @ J)) * s2)
    return ref.x[:2], ref.x[2:4], std[:2], std[2:4]


@pytest.mark.slow
def test_the_fit_matches_scipy_least_squares_and_the_truth():
    """The same model fitted by scipy's `least_squares` (from the true delay): frequencies and damping
    ratios within half a standard error of it, its standard errors within 10 %; the truth within 3 standard
    errors (measured: f within 1e-5, zeta within 1e-3 of the truth)."""
    t, y, sweep = record(3)
    ax = jb.identify_axis_from_sweep(t, y, 2, sweep=sweep)
    f, z = np.asarray(ax.frequencies), np.asarray(ax.damping_ratios)
    sf, sz = np.asarray(ax.frequency_std), np.asarray(ax.damping_std)
    rf, rz, rsf, rsz = _reference_fit(t, y, sweep, LEAD)
    # the module fits the delay too: its sampled input flips a sample wherever a switch lies within the delay's
    # last thousandth of a sample of a sample time (measured: 0.2 standard errors apart)
    assert np.all(np.abs(f - rf) < 0.5 * sf), (f, rf, sf)
    assert np.all(np.abs(z - rz) < 0.5 * sz), (z, rz, sz)
    np.testing.assert_allclose(sf, rsf, rtol=0.1)
    np.testing.assert_allclose(sz, rsz, rtol=0.1)
    assert np.all(np.abs(f - AXIS[0]) < 3 * sf) and np.all(np.abs(z - AXIS[1]) < 3 * sz)
    assert np.all(np.abs(f / AXIS[0] - 1) < 0.01) and np.all(np.abs(z / AXIS[1] - 1) < 0.10)  # the targets


@pytest.mark.slow
def test_a_second_record_of_the_same_length_compiles_nothing():
    """Another sweep's record of the same length (other noise, other modes, another clock) runs the compiled fit:
    no compilation at all, and its modes within 0.1 %."""
    from compiles import count_compiles

    t, y, sweep = record(5)
    jb.identify_axis_from_sweep(t, y, 2, sweep=sweep)
    axis = ([36.0, 55.0], [0.05, 0.02], [1.0, 0.3])
    t2, y2, _ = record(6, axis=axis)
    with count_compiles() as compiles:
        ax = jb.identify_axis_from_sweep(t2 + 50.0, y2, 2, sweep=sweep)
    assert compiles["n"] == 0
    np.testing.assert_allclose(np.asarray(ax.frequencies), axis[0], rtol=1e-3)


@pytest.mark.slow
def test_the_sweep_is_found_wherever_the_record_starts():
    """A record that starts 0.7 s before the sweep and one that starts with it: the same modes, within a standard
    error of each other (the delay is found from the record, not from its time stamps)."""
    t, y, sweep = record(8, lead=0.7)
    t0, y0, _ = record(8, lead=0.0)
    a = jb.identify_axis_from_sweep(t, y, 2, sweep=sweep)
    b = jb.identify_axis_from_sweep(t0, y0, 2, sweep=sweep)
    for ax in (a, b):
        assert np.all(np.abs(np.asarray(ax.frequencies) - AXIS[0]) < 4 * np.asarray(ax.frequency_std))
        assert np.all(np.abs(np.asarray(ax.damping_ratios) - AXIS[1]) < 4 * np.asarray(ax.damping_std))


def test_bad_sweeps_and_bands_are_refused_naming_them():
    sweep = jb.klipper_sweep(freq_start=20.0, freq_end=30.0, hz_per_sec=20.0)
    t, y = rt.sweep_response(jb.ModalAxis(*AXIS), RATE, *sweep)
    ends, accel = sweep
    for bad in ((ends[::-1], accel), (ends, accel[:-1]), "sweep", (ends[:1], accel[:1])):
        with pytest.raises(ValueError, match=r"identify_axis_from_sweep: parameter `sweep` must be a pair"):
            jb.identify_axis_from_sweep(t, y, 2, sweep=bad)
    for band in ((50.0, 20.0), (5.0, 2000.0), "wide"):
        with pytest.raises(ValueError, match=r"identify_axis_from_sweep: parameter `band` must be"):
            jb.identify_axis_from_sweep(t, y, 2, sweep=sweep, band=band)
    with pytest.raises(ValueError, match=r"does not hold the sweep"):
        jb.identify_axis_from_sweep(t, y, 1, sweep=jb.klipper_sweep())


@pytest.mark.slow
def test_more_modes_than_the_record_holds_is_an_error_naming_n_modes():
    t, y, sweep = record(12)
    with pytest.raises(ValueError, match=r"may hold fewer than `n_modes` = 3 modes"):
        jb.identify_axis_from_sweep(t, y, 3, sweep=sweep)
