"""`jb.load_spectrum` and `jb.identify_axis_from_psd`: the modes of an axis from a power spectral density (PSD),
such as a firmware's resonance test writes (Klipper: `freq,psd_x,psd_y,psd_z,psd_xyz`).

References: synthetic spectra of known modes (the analytic modal terms A_i / ((1 - r_i^2)^2 + (2 zeta_i r_i)^2)
plus a floor, times the chi-square scatter of a Welch average of K segments, seeded): frequencies within 1 % and
3 standard errors, damping ratios within 15 % and 3 standard errors; the standard errors against the scatter of
the estimates over noise seeds; a Welch estimate (written here in numpy, checked against scipy's `welch`) of two
modal responses simulated by scipy (an independent path, with the window's smearing and correlated bins); the
committed example files of docs/examples; the command line. Every fit below has 2 modes on 5-200 Hz (391 points,
padded to 448), so the file compiles one fit program.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import psd as psd_fit

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from compiles import count_compiles  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
PSD_EXAMPLE, RAW_EXAMPLE = EXAMPLES / "klipper_psd_example.csv", EXAMPLES / "klipper_raw_example.csv"
FREQS, ZETAS = np.array([38.0, 92.0]), np.array([0.05, 0.03])  # the axis of the examples and of the tests
PEAKS, FLOOR = np.array([2.0e5, 1.0e5]), 300.0  # (mm/s^2)^2/Hz
GRID = np.arange(5.0, 200.0 + 1e-9, 0.5)  # Hz
SEGMENTS = 32  # Welch segments: the scatter is chi-square of 64 degrees of freedom, about 18 % in ln PSD


def spectrum(f=GRID, *, seed=None, segments=SEGMENTS, freqs=FREQS, zetas=ZETAS, peaks=PEAKS, floor=FLOOR):
    """The model's PSD at `f` [Hz]: modes of peak height `peaks` over `floor`, times the scatter of a Welch
    average of `segments` segments (chi-square of 2 * segments degrees of freedom, normalised) when `seed` is given."""
    freqs, zetas, peaks = (np.asarray(v, dtype=float) for v in (freqs, zetas, peaks))
    r = f[:, None] / freqs[None, :]
    psd = floor + np.sum(peaks * (2 * zetas) ** 2 / ((1 - r**2) ** 2 + (2 * zetas * r) ** 2), axis=1)
    if seed is not None:
        psd = psd * np.random.default_rng(seed).chisquare(2 * segments, f.size) / (2 * segments)
    return psd


def rel(estimate, truth):
    return np.abs(np.asarray(estimate) / np.asarray(truth) - 1.0)


def within(axis, freqs=FREQS, zetas=ZETAS, *, f_rel=0.01, z_rel=0.15, sigmas=3.0):
    f, z = np.asarray(axis.frequencies), np.asarray(axis.damping_ratios)
    assert np.all(rel(f, freqs) < f_rel), f
    assert np.all(rel(z, zetas) < z_rel), z
    if sigmas is not None:
        assert np.all(np.abs(f - freqs) < sigmas * np.asarray(axis.frequency_std)), (f, axis.frequency_std)
        assert np.all(np.abs(z - zetas) < sigmas * np.asarray(axis.damping_std)), (z, axis.damping_std)


# --- the target: two modes in a noisy spectrum -------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_modes_from_a_noisy_spectrum(seed):
    ax = jb.identify_axis_from_psd(GRID, spectrum(seed=seed), 2)
    assert isinstance(ax, jb.ModalAxis) and ax.n_modes == 2
    np.testing.assert_array_equal(np.asarray(ax.gains), [1.0, 1.0])  # unit gains: a PSD does not fix them
    within(ax)  # measured: f within 0.12 %, zeta within 6 %, all within 1.6 standard errors


def test_noise_free_spectrum_is_fitted_exactly():
    ax = jb.identify_axis_from_psd(GRID, spectrum(), 2)
    np.testing.assert_allclose(np.asarray(ax.frequencies), FREQS, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(ax.damping_ratios), ZETAS, rtol=1e-8)
    assert np.all(np.asarray(ax.frequency_std) < 1e-8) and np.all(np.asarray(ax.damping_std) < 1e-8)


def test_standard_errors_match_the_scatter_over_noise_seeds():
    fs, zs, f_std, z_std = [], [], [], []
    for seed in range(100, 116):
        ax = jb.identify_axis_from_psd(GRID, spectrum(seed=seed), 2)
        fs.append(np.asarray(ax.frequencies))
        zs.append(np.asarray(ax.damping_ratios))
        f_std.append(np.asarray(ax.frequency_std))
        z_std.append(np.asarray(ax.damping_std))
    ratio_f = np.std(fs, axis=0, ddof=1) / np.mean(f_std, axis=0)
    ratio_z = np.std(zs, axis=0, ddof=1) / np.mean(z_std, axis=0)
    # 16 draws: the sample spread is itself uncertain by ~18 %; measured ratios 0.7-1.1
    assert np.all((ratio_f > 0.5) & (ratio_f < 2.0)), ratio_f
    assert np.all((ratio_z > 0.5) & (ratio_z < 2.0)), ratio_z


def test_a_second_spectrum_of_a_nearby_length_compiles_nothing():
    jb.identify_axis_from_psd(GRID, spectrum(seed=5), 2)
    with count_compiles() as compiles:
        ax = jb.identify_axis_from_psd(GRID, 1e-6 * spectrum(seed=6), 2, band=(6.0, 199.0))  # other units, 387 points
    assert compiles["n"] == 0
    within(ax)


# --- an independent path: Welch's estimate of simulated responses ----------------------------------------------
def welch(x, fs, nperseg):
    """One-sided PSD of `x` sampled at `fs` [Hz] by Welch's method (Welch, 1967): periodic Hann window, segments
    of `nperseg` samples overlapping by half, each segment's mean removed, averaged periodograms scaled to a
    density (units of x^2/Hz). Returns `(f [Hz], psd)`."""
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(nperseg) / nperseg)
    starts = np.arange(0, x.size - nperseg + 1, nperseg // 2)
    segments = x[starts[:, None] + np.arange(nperseg)[None, :]]
    segments = (segments - segments.mean(axis=1, keepdims=True)) * window
    psd = np.mean(np.abs(np.fft.rfft(segments, axis=1)) ** 2, axis=0) / (fs * np.sum(window**2))
    psd[1:-1] *= 2.0  # the negative frequencies' share, except at 0 Hz and Nyquist (even nperseg)
    return np.fft.rfftfreq(nperseg, 1.0 / fs), psd


def modal_response(f, zeta, a, dt):
    """The modal coordinate q of $\\ddot q + 2\\zeta\\omega\\dot q + \\omega^2 q = -a(t)$, `a` held over each step
    `dt` [s] (exact discretisation by scipy), from rest."""
    from scipy.signal import cont2discrete, lfilter, ss2tf

    w = 2 * np.pi * f
    system = (
        np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]]),
        np.array([[0.0], [-1.0]]),
        np.eye(1, 2),
        np.zeros((1, 1)),
    )
    num, den = ss2tf(*cont2discrete(system, dt, method="zoh")[:4])
    return lfilter(num[0], den, a)


def test_welch_estimate_of_simulated_modal_responses():
    """Two channels, each a mode's response to white-noise acceleration (simulated at 3200 Hz, read at 400 Hz)
    plus white sensor noise, summed as psd_xyz sums Klipper's axes: the PSD is the model's, smeared by the Hann
    window over ~1.5 bins and with neighbouring bins correlated (the standard errors are then too small, so only
    the 1 % and 15 % targets are checked)."""
    from scipy.signal import welch as scipy_welch

    fs, nperseg, up = 400.0, 800, 8  # 0.5 Hz bins, as the example
    rng = np.random.default_rng(3)
    n = nperseg * (SEGMENTS + 1) // 2 + nperseg  # 32 segments after a settling segment
    total = np.zeros(nperseg // 2 + 1)
    for f, z, gain in zip(FREQS, ZETAS, (1.0, 2.5)):
        q = modal_response(f, z, gain * rng.standard_normal(n * up), 1.0 / (fs * up))[nperseg * up :: up]
        y = q + 0.05 * np.std(q) * rng.standard_normal(q.size)
        freq, psd = welch(y, fs, nperseg)
        np.testing.assert_allclose(psd, scipy_welch(y, fs, nperseg=nperseg)[1], rtol=1e-10)  # the estimate itself
        total += psd
    ax = jb.identify_axis_from_psd(freq, total, 2, band=(5.0, 200.0))
    within(ax, sigmas=None)  # measured: f within 0.3 %, zeta within 6 %


# --- the committed example files -----------------------------------------------------------------------------
@pytest.mark.slow
def test_example_psd_files_identify_to_their_stated_modes():
    """Klipper's two calibration CSV forms of one simulated sweep (docs/examples/make_examples.py): the kind follows
    the file; frequencies within 2 % and damping within 30 % (the issue's target; measured: 0.03 % and 3-8 %),
    within 3 standard errors in frequency."""
    text = PSD_EXAMPLE.read_text()
    assert (
        text.startswith("#") and "ModalAxis([38 Hz, 92 Hz], damping ratios [0.05, 0.03]" in text and len(text) < 200_000
    )
    for path, kind in ((PSD_EXAMPLE, "klipper-normalised"), (EXAMPLES / "klipper_resonances_example.csv", "klipper")):
        assert jb.shaping.readers.spectrum_kind(path) == kind
        ax, what = jb.identify_measurement(path, 2)
        assert kind in what
        within(ax, f_rel=0.02, z_rel=0.30, sigmas=None)
        assert np.all(np.abs(np.asarray(ax.frequencies) - FREQS) < 3 * np.asarray(ax.frequency_std))
    f, psd = jb.load_spectrum(PSD_EXAMPLE)  # psd_xyz
    f, psd_x = jb.load_spectrum(PSD_EXAMPLE, channel="PSD_X")
    assert np.all(psd_x <= psd)


def test_example_rrf_file_identifies_to_its_stated_modes():
    t, y = jb.load_record(EXAMPLES / "rrf_accelerometer_example.csv", channel="X")
    np.testing.assert_allclose(np.diff(t), 1 / 1344, rtol=1e-12)
    within(jb.identify_axis(t, y, 2), z_rel=0.15)  # measured: f within 0.3 %, zeta within 11 % (2 standard errors)


def test_example_raw_file_identifies_to_its_stated_modes():
    text = RAW_EXAMPLE.read_text()
    assert text.startswith("#time,accel_x,accel_y,accel_z\n") and len(text) < 200_000
    t, y = jb.load_record(RAW_EXAMPLE, channel="accel_x")
    assert t.size == 2000  # the record length of tests/test_identify_axis.py: the same compiled fit
    within(jb.identify_axis(t, y, 2))  # measured: f within 0.04 %, zeta within 8 % (1 standard error)


def test_load_record_refuses_the_example_spectrum_and_points_to_load_spectrum():
    for channel in (None, "psd_x"):
        with pytest.raises(ValueError, match=r"klipper_psd_example.csv:5: the first column is 'freq': a spectrum.*"):
            jb.load_record(PSD_EXAMPLE, channel=channel)
    with pytest.raises(
        ValueError, match=r"read it with load_spectrum and identify its modes with identify_axis_from_psd"
    ):
        jb.load_record(PSD_EXAMPLE)


# --- bad input: refused by name before anything is compiled ----------------------------------------------------
GOOD = spectrum(seed=0)


@pytest.mark.parametrize(
    "f, psd, n_modes, kw, match",
    [
        (GRID.reshape(17, 23), GOOD.reshape(17, 23), 2, {}, r"`f` must be a 1-D array of frequencies \[Hz\]"),
        (GRID, GOOD[:-1], 2, {}, r"`psd` must have the shape of `f`, \(391,\); got shape \(390,\)"),
        (np.where(np.arange(391) == 7, np.nan, GRID), GOOD, 2, {}, r"`f` must be finite.*nan at index 7"),
        (GRID, np.where(np.arange(391) == 9, np.inf, GOOD), 2, {}, r"`psd` must be finite.*inf at index 9"),
        (GRID[::-1], GOOD, 2, {}, r"`f` must be strictly increasing; got f\[0\]"),
        (np.where(np.arange(391) == 50, GRID[49], GRID), GOOD, 2, {}, r"`f` must be strictly increasing.*f\[49\]"),
        (GRID - 10.0, GOOD, 2, {}, r"`f` must be >= 0 Hz"),
        (
            GRID,
            np.where(np.arange(391) == 30, -1.0, GOOD),
            2,
            {},
            r"`psd` must be >= 0.*-1.0 at index 30 \(f = 20 Hz\)",
        ),
        (
            GRID,
            np.where(np.arange(391) == 30, 0.0, GOOD),
            2,
            {},
            r"`psd` must be > 0 where it is fitted.*20 Hz.*`band`",
        ),
        (
            GRID[:69],
            GOOD[:69],
            2,
            {},
            r"too short: 2 mode\(s\) and the level\(s\) are 7 parameters.*at least 70 points.*got 69",
        ),
        (GRID, GOOD, 2, {"band": (30.0, 60.0)}, r"too short.*within `band` = \(30, 60\) Hz.*got 61"),
        (GRID, GOOD, 2, {"band": (60.0, 30.0)}, r"`band` must be finite with 0 <= low < high"),
        (GRID, GOOD, 2, {"band": 50.0}, r"`band` must be a pair \(low, high\)"),
        (GRID, GOOD, 0, {}, r"`n_modes` must be an integer >= 1; got 0"),
        (GRID, GOOD, 2.0, {}, r"`n_modes` must be an integer >= 1; got 2.0"),
        (GRID, GOOD, True, {}, r"`n_modes` must be an integer >= 1; got True"),
        (GRID, GOOD, 3, {}, r"holds 2 distinct peak\(s\) \(38(\.\d+)? Hz, 92(\.\d+)? Hz\), fewer than `n_modes` = 3"),
        (GRID, np.full(391, 2.0), 1, {}, r"`psd` is constant"),
        (
            GRID,
            spectrum(seed=0, freqs=[38.0], zetas=[0.05], peaks=[0.0]),
            1,
            {},
            r"no distinct peak \(it may be noise\)",
        ),
        (GRID, GOOD, 2, {"band": (40.0, 200.0)}, r"peak at 40 Hz is at the edge of the frequency range.*low side"),
        (GRID, GOOD, 2, {"rtol": 0.0}, r"`rtol` must be finite and > 0"),
        (GRID, GOOD, 2, {"max_steps": 0}, r"`max_steps` must be an integer >= 1; got 0"),
    ],
    ids=[
        "f-2d",
        "psd-shape",
        "f-nan",
        "psd-inf",
        "f-decreasing",
        "f-repeated",
        "f-negative",
        "psd-negative",
        "psd-zero",
        "too-short",
        "band-too-narrow",
        "band-reversed",
        "band-scalar",
        "n0",
        "nfloat",
        "nbool",
        "more-modes-than-peaks",
        "constant",
        "noise",
        "peak-at-edge",
        "rtol",
        "max-steps",
    ],
)
def test_bad_spectra_raise_before_compiling(f, psd, n_modes, kw, match):
    with count_compiles() as compiles, pytest.raises(ValueError, match=match):
        jb.identify_axis_from_psd(f, psd, n_modes, **kw)
    assert compiles["n"] == 0


def test_float32_mode_is_refused_before_fitting():
    import jax

    with jax.enable_x64(False), pytest.raises(RuntimeError, match=r"(?s)identify_axis_from_psd: .*jax_enable_x64"):
        jb.identify_axis_from_psd(GRID, GOOD, 2)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_mode_the_spectrum_does_not_hold_is_refused(seed):
    # one mode (38 Hz) in a noisier spectrum (8 segments), fitted with two: the second is a peak of noise
    psd = spectrum(seed=seed, segments=8, freqs=[38.0], zetas=[0.05], peaks=[2.0e5])
    with pytest.raises(ValueError, match=r"standard errors \(at least 8 are needed\).*fewer than `n_modes` = 2"):
        jb.identify_axis_from_psd(GRID, psd, 2)


def test_a_damping_narrower_than_the_frequency_grid_is_refused():
    # 38 Hz at zeta 0.004: a half-power bandwidth of 0.3 Hz, under two 0.5 Hz steps
    psd = spectrum(seed=4, zetas=[0.004, 0.03])
    with pytest.raises(
        ValueError, match=r"mode 1 \(3[78]\.\d+ Hz.* half-power bandwidth of 0.3\d* Hz, under 2 step\(s\).*`f`: 0.5 Hz"
    ):
        jb.identify_axis_from_psd(GRID, psd, 2)


def test_a_damping_ratio_outside_zero_one_is_refused(monkeypatch):
    # the coordinates keep 0 < zeta < 1, but a logit beyond ~37 rounds the ratio to 1.0 in float64
    true_fit = psd_fit._fit_psd

    def saturated(*args, **kw):
        u, *rest = true_fit(*args, **kw)
        return (np.asarray(u).copy() + np.array([0, 0, 800.0, 0, 0, 0, 0]), *rest)

    monkeypatch.setattr(psd_fit, "_fit_psd", saturated)
    with pytest.raises(ValueError, match=r"a damping ratio comes out outside \(0, 1\).*`psd`"):
        jb.identify_axis_from_psd(GRID, GOOD, 2)


# --- load_spectrum -----------------------------------------------------------------------------------------
def _write(path, header, rows, comments=()):
    path.write_text("".join(f"{c}\n" for c in comments) + header + "\n" + "".join(",".join(r) + "\n" for r in rows))
    return path


def test_load_spectrum_reads_klipper_files(tmp_path):
    psd = GOOD
    rows = [(f"{f:.1f}", f"{0.5 * p:.6e}", f"{0.3 * p:.6e}", f"{0.2 * p:.6e}", f"{p:.6e}") for f, p in zip(GRID, psd)]
    # Klipper's file: no comment line, freq,psd_x,psd_y,psd_z,psd_xyz; the default column is psd_xyz
    path = _write(tmp_path / "calibration_data_x.csv", "freq,psd_x,psd_y,psd_z,psd_xyz", rows)
    f, p = jb.load_spectrum(path)
    np.testing.assert_array_equal(f, GRID)
    np.testing.assert_allclose(p, psd, rtol=1e-6)
    for channel in ("psd_y", "PSD_Y", 2):
        np.testing.assert_allclose(jb.load_spectrum(str(path), channel=channel)[1], 0.3 * psd, rtol=1e-6)
    # newer Klipper: accel_per_hz and the shapers' responses after the PSDs (not read)
    newer = [(*r, "75.0", "0.123", "0.456") for r in rows]
    path = _write(tmp_path / "newer.csv", "freq,psd_x,psd_y,psd_z,psd_xyz,accel_per_hz,mzv(53.2),ei(60.1/70.2)", newer)
    np.testing.assert_allclose(jb.load_spectrum(path)[1], psd, rtol=1e-6)
    # comment lines and blank lines before the header and between rows; a header written as a comment; a BOM
    path = _write(tmp_path / "commented.csv", "frequency_Hz,PSD", [(r[0], r[4]) for r in rows], ("# made by x, y", ""))
    np.testing.assert_allclose(jb.load_spectrum(path)[1], psd, rtol=1e-6)
    text = "\ufeff# a comment\n#hz,psd\n" + "".join(f"{r[0]},{r[4]}\n\n# between\n" for r in rows)
    path.write_text(text, encoding="utf-8")
    f, p = jb.load_spectrum(path)
    np.testing.assert_array_equal(f, GRID)


def test_load_spectrum_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"load_spectrum: no file '.*missing.csv'"):
        jb.load_spectrum(tmp_path / "missing.csv")
    with pytest.raises(IsADirectoryError, match=r"is a folder"):
        jb.load_spectrum(tmp_path)
    bad = tmp_path / "bad.csv"
    cases = [
        (
            "freq,psd_x,psd_y\n5,1,2\n6,1,2\n",
            {},
            r"bad.csv:1: 2 columns after the frequency \(\['psd_x', 'psd_y'\]\).*`channel`",
        ),
        (
            "freq,psd_x,psd_y\n5,1,2\n6,1,2\n",
            {"channel": "psd_q"},
            r"no column 'psd_q'; the channels are \['psd_x', 'psd_y'\]",
        ),
        (
            "freq,psd_x,psd_y\n5,1,2\n6,1,2\n",
            {"channel": 3},
            r"`channel` 3 is out of range.*the frequency and 2 channel",
        ),
        ("freq,psd\n5,1\n", {"channel": 0}, r"`channel` must be >= 1 \(column 0 holds the frequency\)"),
        ("freq,psd\n5,1\n6,abc\n", {}, r"bad.csv:3: the frequency and psd must be numbers; got '6,abc'"),
        ("freq,psd\n5,1\n6,nan\n", {}, r"bad.csv:3: the values must be finite"),
        ("freq,psd\n5,1\n6,-1e-3\n", {}, r"bad.csv:3: psd must be >= 0 \(a power spectral density\); got -0.001"),
        ("freq,psd\n5,1\n5,2\n", {}, r"bad.csv:3: the frequencies must be strictly increasing; got 5.0 after 5.0"),
        (
            "freq,psd\n5,1,2\n",
            {},
            r"bad.csv:2: expected 2 comma-separated columns as in the header \(freq,psd\); got 3",
        ),
        ("freq,psd\n5,1\n", {}, r"holds 1 line\(s\) of data; a spectrum needs at least 2"),
        (
            "t,y\n0,1\n0.1,2\n",
            {},
            r"bad.csv:1: expected a header line whose first column names the frequency.*load_record",
        ),
        ("5,1\n6,2\n", {}, r"bad.csv:1: expected a header line"),
        ("freq\n5\n", {}, r"has no PSD column"),
        ("# only a comment\n", {}, r"holds no data"),
    ]
    for text, kw, match in cases:
        bad.write_text(text)
        with pytest.raises(ValueError, match=match):
            jb.load_spectrum(bad, **kw)
    bad.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(ValueError, match=r"is not a text \(CSV\) file"):
        jb.load_spectrum(bad)


# --- the command line -----------------------------------------------------------------------------------------
AXIS_ARGS = ["--distance", "0.01", "--v-max", "0.1", "--a-max", "2", "--move-time", "0.2", "--no-progress"]


def test_cli_designs_a_move_from_the_example_psd(tmp_path, capsys, monkeypatch):
    from jaxbelt.cli import main
    from jaxbelt.shaping import plan

    true_design = plan.design_move
    seen = {}

    def cheap(axis, *args, **kw):  # the CLI's own design path, with two candidates to keep the test short
        seen["axis"] = axis
        return true_design(axis, *args, **{**kw, "include": ("ZV", "unshaped")})

    monkeypatch.setattr(plan, "design_move", cheap)
    figures = []  # the figure is drawn but not rendered to a file (4-6 s; tests/test_shaping_axis.py writes one)
    monkeypatch.setattr("jaxbelt._io.save_figure", lambda fig, path, **kw: figures.append(path))
    out = tmp_path / "move.csv"
    code = main(
        ["--no-cache", "shaping", "--measured", str(PSD_EXAMPLE), "--n-modes", "2", *AXIS_ARGS, "--out", str(out)]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "(power spectral density, 'klipper-normalised')" in text and "mode 1: 38.0" in text and "mode 2: 92." in text
    within(seen["axis"], f_rel=0.02, z_rel=0.30, sigmas=None)
    assert out.exists() and figures == [out.with_suffix(".png")]
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data["x"][-1] == pytest.approx(0.01)


def test_cli_reads_a_column_of_a_raw_accelerometer_file(tmp_path, capsys, monkeypatch):
    from jaxbelt.cli import main
    from jaxbelt.shaping import plan
    from jaxbelt.solution import SolveError

    seen = {}

    def stop(axis, *args, **kw):  # the routing is under test here, not the design
        seen["axis"] = axis
        raise SolveError("stopped by the test")

    monkeypatch.setattr(plan, "design_move", stop)
    args = ["--no-cache", "shaping", "--measured", str(RAW_EXAMPLE), "--n-modes", "2", *AXIS_ARGS]
    assert main([*args, "--column", "accel_x", "--out", str(tmp_path / "m.csv")]) == 1
    assert "(free decay, column accel_x)" in capsys.readouterr().out
    within(seen["axis"])
    # without --column the four columns are ambiguous: one line, status 2
    assert main([*args, "--out", str(tmp_path / "m.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "choose one with --column" in err[0] and "channel`" not in err[0]
    # a spectrum's kind for a time record: refused naming --kind
    assert main([*args, "--column", "accel_x", "--kind", "klipper", "--out", str(tmp_path / "m.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--kind 'klipper' is not a time record's" in err[0] and "'decay', 'sweep'" in err[0]


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--mode", "5:0.01", "--column", "psd_x", *AXIS_ARGS], "argument --column: only with --measured"),
        (["--column", "2"], "argument --column: only with --measured"),
        (["--kind", "sweep"], "argument --kind: only with --measured"),
        (["--measured", str(PSD_EXAMPLE), "--kind", "decay", *AXIS_ARGS], "--kind 'decay' is not a spectrum's"),
        (["--measured", str(PSD_EXAMPLE), "--column", "psd_q", *AXIS_ARGS], "--column: no column 'psd_q'"),
        (["--measured", str(PSD_EXAMPLE), "--column", "0", *AXIS_ARGS], "an index must be >= 1"),
    ],
)
def test_cli_refuses_column_in_one_line(extra, needle, capsys):
    from jaxbelt.cli import main

    try:
        code = main(["--no-cache", "shaping", *extra])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
