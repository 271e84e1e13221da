"""`jb.load_record` on the files firmware writes, and `identify_axis`'s acceptance of their rounded time stamps.

Formats as their writers produce them (facts from the writers' sources): Klipper's raw accelerometer file
(`#time,accel_x,accel_y,accel_z`, every value `%.6f`), RepRapFirmware's accelerometer file (`Sample,X,Y,Z`, the
sample number then the values in g, a last line `Rate <Hz>, overflows <n>`), Klipper's two calibration CSV forms.
References: the true modes of synthetic free decays written in those formats (frequencies within 1 %, damping
within 10 %, as the issue asks of a raw free decay), and the same record with exact times.
"""

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import identify as ident
from jaxbelt.shaping import readers

RATE, N = 3200.0, 2000
FREQS, ZETAS = (38.0, 92.0), (0.05, 0.03)


def decay(t, noise=0.01, seed=0):
    """A free decay of two modes [mm/s^2] at the times `t`, with Gaussian noise of `noise` times its peak."""
    tau = t - t[0]
    y = sum(
        a * np.exp(-z * 2 * np.pi * f * tau) * np.cos(2 * np.pi * f * np.sqrt(1 - z * z) * tau + ph)
        for f, z, a, ph in zip(FREQS, ZETAS, (3000.0, 1500.0), (0.3, -1.1))
    )
    return y + noise * np.max(np.abs(y)) * np.random.default_rng(seed).standard_normal(t.size)


def klipper_lines(t, y):
    return ["#time,accel_x,accel_y,accel_z"] + [f"{a:.6f},{b:.6f},{0.05 * b:.6f},{9806.65:.6f}" for a, b in zip(t, y)]


def write(path, lines):
    path.write_text("\n".join(lines) + "\n")
    return path


def test_klipper_raw_file_with_six_decimals_identifies(tmp_path):
    """`%.6f` times at 3.2 kHz are rounded by 1.6e-3 of a step, over `UNIFORM_RTOL`: accepted as uniform within the
    writer's rounding, at a rate off its nominal value (3203.7 Hz, a sensor's own clock), from any start time.
    The modes come out within 1 % and 10 % and within 3 standard errors, as from the exact times."""
    t = 12.345678 + np.arange(N) / 3203.7
    y = decay(t)
    path = write(tmp_path / "raw_data_x.csv", klipper_lines(t, y))
    tr, yr = jb.load_record(path, channel="accel_x")
    assert np.max(np.abs(tr - t)) <= 5e-7 + 1e-12
    assert ident._time_rounding(tr) == pytest.approx(5e-7)
    axis = jb.identify_axis(tr, yr, 2)
    f, z = np.asarray(axis.frequencies), np.asarray(axis.damping_ratios)
    assert np.all(np.abs(f / FREQS - 1) < 0.01) and np.all(np.abs(z / ZETAS - 1) < 0.10)
    assert np.all(np.abs(f - FREQS) < 3 * np.asarray(axis.frequency_std))
    exact = jb.identify_axis(t, np.round(y, 6), 2)
    np.testing.assert_allclose(f, np.asarray(exact.frequencies), rtol=1e-4)


def test_rounding_is_found_from_the_values():
    t = np.arange(100) / 3200.0
    assert ident._time_rounding(np.round(t, 6)) == pytest.approx(5e-7)
    assert ident._time_rounding(np.round(t, 3)) == pytest.approx(5e-4)
    assert ident._time_rounding(t + 1e-11 * np.sqrt(2)) == 0.0  # not rounded: no allowance


def test_a_time_off_the_grid_by_more_than_the_rounding_is_refused():
    """A time 2 µs off the grid, with times written to 6 decimals (half a unit: 0.5 µs), is not rounding."""
    t = np.round(np.arange(N) / RATE, 6)
    t[700] += 2e-6
    with pytest.raises(ValueError, match=r"`t` must be uniformly sampled.*rounding of its 6 decimals.*index 700"):
        jb.identify_axis(t, decay(t), 2)


def test_a_gap_is_refused_naming_the_line(tmp_path):
    """Samples lost (a buffer overflow) leave a jump of whole steps: refused, naming the line after it."""
    t = np.arange(N) / RATE
    y = decay(t)
    keep = np.r_[0:900, 903:N]  # 3 samples lost: lines 902 (= sample 900 + header + 1) is the one after the gap
    path = write(tmp_path / "raw_gap.csv", klipper_lines(t[keep], y[keep]))
    with pytest.raises(
        ValueError, match=r"raw_gap.csv:902: a gap in the record: .*line 901.*3.99 steps.*about 3 sample"
    ):
        jb.load_record(path, channel="accel_x", check_times=True)
    t2, y2 = jb.load_record(path, channel="accel_x")  # as written: identify_axis refuses it, by index
    with pytest.raises(ValueError, match=r"`t` must be uniformly sampled.*A gap \(lost samples\)"):
        jb.identify_axis(t2, y2, 2)


def test_a_repeated_sample_is_dropped_with_a_warning_and_a_time_going_back_is_refused(tmp_path):
    t = np.arange(N) / RATE
    y = decay(t)
    lines = klipper_lines(t, y)
    repeated = lines[:501] + [lines[500]] + lines[501:]  # sample 499 (line 501) written twice: line 502
    path = write(tmp_path / "raw_repeat.csv", repeated)
    with pytest.warns(UserWarning, match=r"line\(s\) 502 repeat the line before exactly.*1 line\(s\) dropped"):
        tr, yr = jb.load_record(path, channel="accel_x", check_times=True)
    tc, yc = jb.load_record(write(tmp_path / "raw.csv", lines), channel="accel_x")
    np.testing.assert_array_equal(tr, tc)
    np.testing.assert_array_equal(yr, yc)
    other = lines[:501] + [lines[500].replace(lines[500].split(",")[1], "1.000000")] + lines[501:]
    with pytest.raises(ValueError, match=r"raw_back.csv:502: the time must increase from line to line"):
        jb.load_record(write(tmp_path / "raw_back.csv", other), channel="accel_x", check_times=True)


def rrf_lines(y_g, rate=1344, overflows=0, axes="XYZ"):
    cols = {"X": y_g, "Y": 0.05 * y_g, "Z": np.full_like(y_g, 1.0)}
    body = [f"{k}," + ",".join(f"{cols[a][k]:.4f}" for a in axes) for k in range(y_g.size)]
    return ["Sample," + ",".join(axes)] + body + [f"Rate {rate}, overflows {overflows}"]


def test_reprapfirmware_accelerometer_file(tmp_path):
    """M956's file: sample numbers, values in g (`%.4f` at 10-bit resolution... any decimals), `Rate` at the end:
    times n/rate exactly; the modes within 1 % and 10 %. An overflow, a missing Rate line, a missing sample number
    are refused, naming the line."""
    rate = 1344
    t = np.arange(1500) / rate
    y = decay(t, noise=0.005) / 9806.65  # g
    path = write(tmp_path / "accel.csv", rrf_lines(y, rate))
    tr, yr = jb.load_record(path, channel="X")
    np.testing.assert_allclose(tr, t, rtol=0, atol=1e-15)
    np.testing.assert_allclose(yr, np.round(y, 4), atol=1e-12)
    axis = jb.identify_axis(tr, yr, 2)
    assert np.all(np.abs(np.asarray(axis.frequencies) / FREQS - 1) < 0.01)
    assert np.all(np.abs(np.asarray(axis.damping_ratios) / ZETAS - 1) < 0.10)
    one = write(tmp_path / "accel_x.csv", rrf_lines(y, rate, axes="X"))
    np.testing.assert_array_equal(jb.load_record(one)[1], yr)  # one axis: two columns, no `channel` needed
    with pytest.raises(ValueError, match=r"accel_o.csv:1502: 'Rate 1344, overflows 2': the accelerometer's buffer"):
        jb.load_record(write(tmp_path / "accel_o.csv", rrf_lines(y, rate, overflows=2)), channel="X")
    with pytest.raises(ValueError, match=r"ends with the line 'Rate <Hz>, overflows <n>'.*none \(cut short\?\)"):
        jb.load_record(write(tmp_path / "accel_c.csv", rrf_lines(y, rate)[:-1]), channel="X")
    lines = rrf_lines(y, rate)
    with pytest.raises(ValueError, match=r"accel_g.csv:12: a gap in the record: the sample number jumps"):
        jb.load_record(write(tmp_path / "accel_g.csv", lines[:11] + lines[12:]), channel="X", check_times=True)


def test_spectrum_kind_follows_klipper_files(tmp_path):
    """TEST_RESONANCES writes `freq,psd_x,psd_y,psd_z,psd_xyz` (not normalised); SHAPER_CALIBRATE adds `shapers:`
    and a column per shaper, the row holding an empty field under `shapers:` (normalised)."""
    res = write(tmp_path / "resonances_x.csv", ["freq,psd_x,psd_y,psd_z,psd_xyz", "5.0,1e-3,1e-3,1e-3,3e-3"])
    cal = write(
        tmp_path / "calibration_data_x.csv",
        ["freq,psd_x,psd_y,psd_z,psd_xyz,shapers:,zv(59.2),mzv(51.0)", "5.0,1e-3,1e-3,1e-3,3e-3,,0.100,0.200"],
    )
    other = write(tmp_path / "bench.csv", ["freq,psd", "5.0,1e-3"])
    assert readers.spectrum_kind(res) == "klipper"
    assert readers.spectrum_kind(cal) == "klipper-normalised"
    assert readers.spectrum_kind(other) is None
    assert readers.spectrum_kind(tmp_path / "missing.csv") is None
