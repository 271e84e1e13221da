"""`jb.identify_axis`: the modes of a belt-driven axis from a measured free decay or step response.

References: the true modes of synthetic noisy free decays (the target: frequencies within 1 %, damping
ratios within 15 % at 5 % noise); a step response of a `ModalAxis` integrated by scipy's `solve_ivp`
(DOP853 at rtol 1e-12, an integrator independent of the package) recovered to 1e-8; the reported standard
errors against the Monte-Carlo spread of the estimates over 20 noise draws. Every record below has 2000
samples and 2 modes, so that the whole file compiles one fit program (and a second one for `offset=False`).
"""

import sys

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import identify as ident

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from compiles import count_compiles  # noqa: E402

RATE, N = 1000.0, 2000  # 2 s at 1 kHz
AXIS_A = ([7.3, 18.0], [0.015, 0.01])
AXIS_B = ([3.1, 11.5], [0.04, 0.02])
AMPS, PHASES = (1.0, 0.6), (0.3, -1.1)
NOISE = 0.05  # standard deviation, as a fraction of max|y|


def decay(freqs, zetas, *, seed=None, noise=NOISE, t0=0.0, rate=RATE, n=N, offset=0.0):
    """A free decay of the modes `freqs` [Hz], `zetas` (amplitudes AMPS, phases PHASES) sampled at `rate`
    [Hz] from `t0` [s], plus Gaussian noise of standard deviation `noise` * max|y|."""
    t = t0 + np.arange(n) / rate
    tau = t - t0
    y = np.zeros(n)
    for f, z, a, ph in zip(freqs, zetas, AMPS, PHASES):
        w = 2 * np.pi * f
        y += a * np.exp(-z * w * tau) * np.cos(w * np.sqrt(1 - z * z) * tau + ph)
    if seed is not None:
        y += noise * np.max(np.abs(y)) * np.random.default_rng(seed).standard_normal(n)
    return t, y + offset


def rel(estimate, truth):
    return np.abs(np.asarray(estimate) / np.asarray(truth) - 1.0)


# --- the target: 2 modes at 5 % noise, f within 1 %, zeta within 15 % --------------------------------------
@pytest.mark.parametrize("axis", [AXIS_A, AXIS_B], ids=["7.3+18Hz", "3.1+11.5Hz"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_modes_at_five_percent_noise(axis, seed):
    freqs, zetas = axis
    t, y = decay(freqs, zetas, seed=seed, t0=12.5, offset=0.2)  # any start time, a sensor bias
    ax = jb.identify_axis(t, y, 2)
    assert isinstance(ax, jb.ModalAxis) and ax.n_modes == 2
    np.testing.assert_array_equal(np.asarray(ax.gains), [1.0, 1.0])  # unit gains: a free decay does not fix them
    assert np.all(rel(ax.frequencies, freqs) < 0.01), np.asarray(ax.frequencies)  # measured: < 0.08 %
    assert np.all(rel(ax.damping_ratios, zetas) < 0.15), np.asarray(ax.damping_ratios)  # measured: < 2.5 %
    # and within 4 of their own standard errors
    assert np.all(np.abs(np.asarray(ax.frequencies) - freqs) < 4 * np.asarray(ax.frequency_std))
    assert np.all(np.abs(np.asarray(ax.damping_ratios) - zetas) < 4 * np.asarray(ax.damping_std))


def test_free_decay_without_offset():
    # an accelerometer's decay to zero, fitted without the constant (its own compiled program)
    freqs, zetas = AXIS_A
    t, y = decay(freqs, zetas, seed=7)
    ax = jb.identify_axis(t, y, 2, offset=False)
    assert np.all(rel(ax.frequencies, freqs) < 0.01)
    assert np.all(rel(ax.damping_ratios, zetas) < 0.15)
    # noise-free: exact (the record's mean is part of the decay, not a constant to remove)
    ax = jb.identify_axis(*decay(freqs, zetas), 2, offset=False)
    np.testing.assert_allclose(np.asarray(ax.frequencies), freqs, rtol=1e-10)  # measured ~1e-15
    np.testing.assert_allclose(np.asarray(ax.damping_ratios), zetas, rtol=1e-10)


# --- an independent reference: the step response of a ModalAxis by scipy's solve_ivp -------------------------
def step_response(axis, distance=0.05, move=0.05):
    """The payload position (command + deflection) of `axis` after a 3-4-5 polynomial move of `distance` [m]
    in `move` [s], sampled at 1 kHz for 2 s from the end of the move, by scipy's DOP853 at rtol 1e-12."""
    from scipy.integrate import solve_ivp

    f, z, g = (np.asarray(v) for v in (axis.frequencies, axis.damping_ratios, axis.gains))
    w, n = 2 * np.pi * f, f.size

    def rhs(t, x, moving):
        s = t / move
        acc = distance / move**2 * (60 * s - 180 * s**2 + 120 * s**3) if moving else 0.0
        q, qd = x[:n], x[n:]
        return np.concatenate([qd, -2 * z * w * qd - w**2 * q - g * acc])

    opts = {"method": "DOP853", "rtol": 1e-12, "atol": 1e-15}
    during = solve_ivp(rhs, (0.0, move), np.zeros(2 * n), args=(True,), **opts)
    t = move + np.arange(N) / RATE
    after = solve_ivp(rhs, (move, t[-1]), during.y[:, -1], args=(False,), t_eval=t, **opts)
    return t, distance + after.y[:n].sum(axis=0)


def test_step_response_matches_solve_ivp_reference():
    axis = jb.ModalAxis(frequencies=[5.2, 14.0], damping_ratios=[0.03, 0.012], gains=[1.0, 0.7])
    t, y = step_response(axis)
    ax = jb.identify_axis(t, y, 2)  # offset=True: the payload settles at the move's distance
    assert np.all(rel(ax.frequencies, axis.frequencies) < 1e-8)  # measured ~1e-13
    assert np.all(rel(ax.damping_ratios, axis.damping_ratios) < 1e-8)  # measured ~2e-12
    assert np.all(np.asarray(ax.frequency_std) < 1e-10) and np.all(np.asarray(ax.damping_std) < 1e-10)


# --- standard errors against the Monte-Carlo spread ----------------------------------------------------------
def test_standard_errors_match_monte_carlo_spread():
    freqs, zetas = AXIS_A
    fs, zs, f_std, z_std = [], [], [], []
    for seed in range(100, 120):
        ax = jb.identify_axis(*decay(freqs, zetas, seed=seed), 2)
        fs.append(np.asarray(ax.frequencies))
        zs.append(np.asarray(ax.damping_ratios))
        f_std.append(np.asarray(ax.frequency_std))
        z_std.append(np.asarray(ax.damping_std))
    ratio_f = np.std(fs, axis=0, ddof=1) / np.mean(f_std, axis=0)
    ratio_z = np.std(zs, axis=0, ddof=1) / np.mean(z_std, axis=0)
    # 20 draws: the sample spread itself is uncertain by ~16 %, so a factor 1.5 is ~2.5 of its sigmas
    assert np.all((ratio_f > 1 / 1.5) & (ratio_f < 1.5)), ratio_f
    assert np.all((ratio_z > 1 / 1.5) & (ratio_z < 1.5)), ratio_z
    # and the estimates are unbiased within the Monte-Carlo error of their mean
    assert np.all(np.abs(np.mean(fs, 0) - freqs) < 3 * np.mean(f_std, 0) / np.sqrt(20) + 1e-12)
    assert np.all(np.abs(np.mean(zs, 0) - zetas) < 3 * np.mean(z_std, 0) / np.sqrt(20) + 1e-12)


# --- the matrix pencil alone: the least squares starts in the right basin ------------------------------------
@pytest.mark.parametrize("axis", [AXIS_A, AXIS_B], ids=["7.3+18Hz", "3.1+11.5Hz"])
def test_matrix_pencil_start_is_within_a_few_percent(axis):
    freqs, zetas = axis
    t, y = decay(freqs, zetas, seed=3)
    f0, z0, a0, b0, c0 = ident._pencil(y, 1.0 / RATE, 2, True)
    assert np.all(rel(f0, freqs) < 0.005), f0  # measured < 0.15 %
    assert np.all(rel(z0, zetas) < 0.05), z0  # measured < 3 %
    # amplitudes at t0 (a = A cos(phase), b = -A sin(phase)) within 10 % of the largest
    np.testing.assert_allclose(np.hypot(a0, b0), AMPS, atol=0.1)
    # noise-free: the pencil is exact (to the SVD's rounding)
    f0, z0, *_ = ident._pencil(decay(freqs, zetas)[1], 1.0 / RATE, 2, False)
    np.testing.assert_allclose(f0, freqs, rtol=1e-9)
    np.testing.assert_allclose(z0, zetas, rtol=1e-7)


# --- one compilation per record length and n_modes -----------------------------------------------------------
def test_second_record_of_the_same_length_does_not_compile():
    freqs, zetas = AXIS_B
    jb.identify_axis(*decay(freqs, zetas, seed=11), 2)
    with count_compiles() as compiles:
        ax = jb.identify_axis(*decay(freqs, zetas, seed=12, t0=3.0, offset=-1.0), 2)
    assert compiles["n"] == 0
    assert np.all(rel(ax.frequencies, freqs) < 0.01)


# --- bad records ------------------------------------------------------------------------------------------
GOOD_T, GOOD_Y = decay(*AXIS_A, seed=0)


@pytest.mark.parametrize(
    "t, y, n_modes, match",
    [
        (GOOD_T.reshape(40, 50), GOOD_Y.reshape(40, 50), 2, r"`t` must be a 1-D array.*shape \(40, 50\)"),
        (GOOD_T, GOOD_Y[:-1], 2, r"`y` must have the shape of `t`, \(2000,\); got shape \(1999,\)"),
        (np.where(np.arange(N) == 17, np.nan, GOOD_T), GOOD_Y, 2, r"`t` must be finite.*nan at index 17"),
        (GOOD_T, np.where(np.arange(N) >= 1500, np.inf, GOOD_Y), 2, r"`y` must be finite.*inf at index 1500 \(500 "),
        (GOOD_T[::-1], GOOD_Y, 2, r"`t` must be strictly increasing.*t\[0\]"),
        (
            np.where(np.arange(N) == 900, GOOD_T + 2e-4, GOOD_T),
            GOOD_Y,
            2,
            r"`t` must be uniformly sampled.*within 0.001.*largest deviation is 0.2 steps at index 900",
        ),
        (GOOD_T[:89], GOOD_Y[:89], 2, r"too short.*9 parameters.*at least 90 samples.*got 89"),
        (GOOD_T, GOOD_Y, 0, r"`n_modes` must be an integer >= 1; got 0"),
        (GOOD_T, GOOD_Y, 1.0, r"`n_modes` must be an integer >= 1; got 1.0"),
        (GOOD_T, GOOD_Y, True, r"`n_modes` must be an integer >= 1; got True"),
        (GOOD_T, GOOD_Y, "2", r"`n_modes` must be an integer >= 1; got '2'"),
        (GOOD_T, np.full(N, 0.3), 2, r"`y` is constant"),
        (GOOD_T, [str(v) + "x" for v in GOOD_Y[:N]], 2, r"`y` must be a 1-D array of samples"),
    ],
    ids=[
        "t-2d",
        "y-shape",
        "t-nan",
        "y-inf",
        "t-decreasing",
        "t-nonuniform",
        "too-short",
        "n0",
        "nfloat",
        "nbool",
        "nstr",
        "constant",
        "y-text",
    ],
)
def test_bad_records_raise_before_compiling(t, y, n_modes, match):
    with count_compiles() as compiles, pytest.raises(ValueError, match=match):
        jb.identify_axis(t, y, n_modes)
    assert compiles["n"] == 0


def test_float32_mode_is_refused_before_fitting():
    import jax

    with jax.enable_x64(False), pytest.raises(RuntimeError, match=r"jax_enable_x64"):
        jb.identify_axis(GOOD_T, GOOD_Y, 2)


def test_bad_options_raise():
    with pytest.raises(ValueError, match=r"`offset` must be True or False; got 1"):
        jb.identify_axis(GOOD_T, GOOD_Y, 2, offset=1)
    with pytest.raises(ValueError, match=r"`max_steps` must be an integer >= 1; got 0"):
        jb.identify_axis(GOOD_T, GOOD_Y, 2, max_steps=0)
    with pytest.raises(ValueError, match=r"`rtol` must be finite and > 0"):
        jb.identify_axis(GOOD_T, GOOD_Y, 2, rtol=0.0)


def test_record_shorter_than_two_periods_of_the_lowest_mode():
    # 1 s at 2 kHz (2000 samples): 1.5 periods of a 1.5 Hz mode. The fit finds it exactly (no noise),
    # but the damping of a mode seen for less than 2 periods is not to be trusted: refused, with the minimum.
    t, y = decay([1.5, 30.0], [0.02, 0.01], rate=2000.0)
    with pytest.raises(
        ValueError,
        match=r"lasts 0.9995 s, 1.5 periods of the lowest mode \(1.5 Hz\); at least 2 periods.*at least 1.33333 s",
    ):
        jb.identify_axis(t, y, 2)


def test_fit_above_nyquist_is_refused(monkeypatch):
    # a start at the alias f' = fs - f of the 18 Hz mode: the fit converges there, above the Nyquist
    # frequency (500 Hz), and is refused rather than reported
    t, y = decay(*AXIS_A)
    true_pencil = ident._pencil

    def aliased(y, dt, n, offset):
        f, z, a, b, c = true_pencil(y, dt, n, offset)
        w = 2 * np.pi * f[1]
        f_alias = RATE - f[1] * np.sqrt(1 - z[1] ** 2)  # the damped frequency's alias
        z_alias = z[1] * w / (2 * np.pi * f_alias)  # same decay rate
        return np.array([f[0], f_alias]), np.array([z[0], z_alias]), a, np.array([b[0], -b[1]]), c

    monkeypatch.setattr(ident, "_pencil", aliased)
    with pytest.raises(
        ValueError, match=r"mode 2 comes out at 98\d\.\d+ Hz, not below the record's Nyquist frequency 500 Hz"
    ):
        jb.identify_axis(t, y, 2)


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_pure_noise_is_an_error_not_a_number(seed):
    t = np.arange(N) / RATE
    y = np.random.default_rng(seed).standard_normal(N)
    # converged or not, a fit whose modes do not stand out of the noise is refused as a bad record
    with pytest.raises(ValueError, match=r"standard errors.*the record \(`y`\) may be noise"):
        jb.identify_axis(t, y, 2)


def test_more_modes_than_the_record_holds_is_an_error():
    t, y = decay([7.3], [0.015], seed=2)  # one mode, fitted with two
    with pytest.raises(ValueError, match=r"may be noise, or hold fewer than `n_modes` = 2 modes: try a smaller"):
        jb.identify_axis(t, y, 2)


def test_non_convergence_says_why_and_what_to_do():
    with pytest.raises(
        RuntimeError, match=r"did not converge \(.*max_steps_reached\) after 2 steps.*larger `max_steps` \(now 2\)"
    ):
        jb.identify_axis(GOOD_T, GOOD_Y, 2, max_steps=2)


# --- load_record ----------------------------------------------------------------------------------------
def test_load_record_round_trip(tmp_path):
    t, y = decay(*AXIS_A, seed=5)
    path = tmp_path / "response.csv"
    np.savetxt(path, np.stack([t, y], 1), delimiter=",", header="t,y", comments="")
    t2, y2 = jb.load_record(path)
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_array_equal(y2, y)
    a, b = jb.identify_axis(t, y, 2), jb.identify_axis(t2, y2, 2)
    np.testing.assert_array_equal(np.asarray(a.frequencies), np.asarray(b.frequencies))
    # no header, comments, blank lines, spaces, a byte-order mark, rounded time stamps (6 digits)
    text = "\ufeff# measured on the x axis\n\n" + "".join(f" {ti:.6g} , {float(yi)!r}\n" for ti, yi in zip(t, y))
    path.write_text(text, encoding="utf-8")
    t3, y3 = jb.load_record(str(path))
    np.testing.assert_allclose(t3, t, atol=5e-7)
    np.testing.assert_array_equal(y3, y)


def test_load_record_reads_one_channel_of_a_firmware_accelerometer_file(tmp_path):
    """Klipper's raw accelerometer file: a commented header `#time,accel_x,accel_y,accel_z`, three channels. The
    channel is chosen by name (any case) or index; the record identifies as the two-column file does."""
    t, y = decay(*AXIS_A, seed=5)
    other = 0.5 * y[::-1]
    path = tmp_path / "raw_data_x.csv"
    rows = "".join(f"{float(ti)!r},{float(a)!r},{float(b)!r},{float(c)!r}\n" for ti, a, b, c in zip(t, other, y, -y))
    path.write_text("#time,accel_x,accel_y,accel_z\n" + rows)
    for channel in ("accel_y", "ACCEL_Y", 2):
        t2, y2 = jb.load_record(path, channel=channel)
        np.testing.assert_array_equal(t2, t)
        np.testing.assert_array_equal(y2, y)
    np.testing.assert_array_equal(jb.load_record(path, channel="accel_x")[1], other)
    with pytest.raises(ValueError, match=r"no column 'accel_q'; the channels are \['accel_x', 'accel_y', 'accel_z'\]"):
        jb.load_record(path, channel="accel_q")
    with pytest.raises(ValueError, match=r"`channel` 4 is out of range: the file has 4 columns.*\(1-3\)"):
        jb.load_record(path, channel=4)
    with pytest.raises(ValueError, match=r"`channel` must be >= 1 \(column 0 holds the time\)"):
        jb.load_record(path, channel=0)
    with pytest.raises(ValueError, match=r"got 4 in .*choose one with `channel`"):
        jb.load_record(path)
    a, b = jb.identify_axis(t, y, 2), jb.identify_axis(*jb.load_record(path, channel="accel_y"), 2)
    np.testing.assert_array_equal(np.asarray(a.frequencies), np.asarray(b.frequencies))


def test_load_record_refuses_a_spectrum(tmp_path):
    """The power spectral density of a firmware's resonance test (`freq,psd_x,psd_y,psd_z,psd_xyz`) is not a time
    record: read as one, its columns gave a 0.0175 Hz "mode" without a word."""
    path = tmp_path / "calibration_data_x.csv"
    f = np.linspace(5.0, 200.0, 40)
    path.write_text("freq,psd_x,psd_y,psd_z,psd_xyz\n" + "".join(f"{v},1e-3,2e-3,3e-3,6e-3\n" for v in f))
    for channel in (None, "psd_x"):
        with pytest.raises(
            ValueError,
            match=r":1: the first column is 'freq': a spectrum .*not a time record: read it with load_spectrum",
        ):
            jb.load_record(path, channel=channel)
    path.write_text("freq,psd_x\n" + "".join(f"{v},1e-3\n" for v in f))
    with pytest.raises(ValueError, match=r"a spectrum"):
        jb.load_record(path)


def test_load_record_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"no file '.*missing.csv'"):
        jb.load_record(tmp_path / "missing.csv")
    with pytest.raises(IsADirectoryError, match=r"is a folder"):
        jb.load_record(tmp_path)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,y\n0.0,1.0\n0.001,abc\n")
    with pytest.raises(ValueError, match=r"bad.csv:3: the values must be numbers; got '0.001,abc'"):
        jb.load_record(bad)
    bad.write_text("t,ax,ay\n0.0,1.0,2.0\n")
    with pytest.raises(
        ValueError, match=r"bad.csv:1: expected 2 comma-separated columns t,y; got 3.*drop the other columns"
    ):
        jb.load_record(bad)
    bad.write_text("0.0;1.0\n0.001;2.0\n")
    with pytest.raises(ValueError, match=r"bad.csv:1: expected 2 comma-separated columns t,y; got 1"):
        jb.load_record(bad)
    bad.write_text("t,y\n0.0,1.0\n")
    with pytest.raises(ValueError, match=r"holds 1 sample\(s\); a record needs at least 2"):
        jb.load_record(bad)
    bad.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(ValueError, match=r"is not a text \(CSV\) file"):
        jb.load_record(bad)


def test_the_fit_matches_scipy_least_squares_on_the_same_model():
    """The module's model (damped cosines and sines and an offset) fitted by scipy's `least_squares` (an
    independent solver, trust-region reflective): the same frequencies and damping ratios to 1e-6, the same
    standard errors $s^2(J^TJ)^{-1}$ to 1 %."""
    from scipy.optimize import least_squares

    t, y = decay(*AXIS_A, seed=4)
    ax = jb.identify_axis(t, y, 2)
    tau = t - t[0]

    def resid(p):
        f, z, a, b, c = p[:2], p[2:4], p[4:6], p[6:8], p[8]
        w = 2 * np.pi * f
        wd = w * np.sqrt(1 - z**2)
        e = np.exp(-np.outer(tau, z * w))
        return c + np.sum(e * (a * np.cos(np.outer(tau, wd)) + b * np.sin(np.outer(tau, wd))), axis=1) - y

    amps, phases = np.array(AMPS), np.array(PHASES)
    p0 = np.concatenate([AXIS_A[0], AXIS_A[1], amps * np.cos(phases), -amps * np.sin(phases), [0.0]])
    ref = least_squares(resid, p0, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    s2 = float(ref.fun @ ref.fun) / (y.size - p0.size)
    std = np.sqrt(np.diag(np.linalg.inv(ref.jac.T @ ref.jac)) * s2)
    np.testing.assert_allclose(np.asarray(ax.frequencies), ref.x[:2], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ax.damping_ratios), ref.x[2:4], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ax.frequency_std), std[:2], rtol=0.01)
    np.testing.assert_allclose(np.asarray(ax.damping_std), std[2:4], rtol=0.01)
