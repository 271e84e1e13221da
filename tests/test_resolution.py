"""The drive's resolution (`design_move(..., resolution=)`): the floor that rounding the setpoints to a position step
leaves, against a simulation of that rounding (scipy's exact propagator, no jaxbelt evaluator), and the ranking of the
rows below it by their peaks."""

import numpy as np
import pytest
from references import executed_residual_reference
from scipy.linalg import expm

import jaxbelt as jb
from jaxbelt.shaping.hull import resolution_floor

RATE = 1000.0
STEP = 12.5e-6  # a printer's 0.0125 mm step


def _rounded_rms(t, x, f, z, step, trials, seed=0):
    """RMS over `trials` random start positions (uniform within a step) of the residual amplitude [m] that rounding
    the setpoints `x` to `step` adds on the mode (f [Hz], z), the move's ends kept exact: the mode driven by the
    rounding errors alone (linear between setpoints; each velocity jump kicks q', the exact propagator between)."""
    rng = np.random.default_rng(seed)
    off = rng.uniform(0.0, step, trials)
    xq = np.round((x[None, :] + off[:, None]) / step) * step - off[:, None]
    xq[:, 0], xq[:, -1] = x[0], x[-1]
    e = xq - x[None, :]
    h = t[1] - t[0]
    dv = np.diff(np.concatenate([np.zeros((trials, 1)), np.diff(e, axis=1) / h, np.zeros((trials, 1))], axis=1), axis=1)
    w = 2 * np.pi * f
    P = expm(np.array([[0.0, 1.0], [-w * w, -2 * z * w]]) * h)
    y = np.zeros((trials, 2))
    for k in range(t.size):
        y[:, 1] -= dv[:, k]
        if k < t.size - 1:
            y = y @ P.T
    wd = w * np.sqrt(1 - z * z)
    amp = np.hypot(y[:, 0], (y[:, 1] + z * w * y[:, 0]) / wd)
    return float(np.sqrt(np.mean(amp**2)))


@pytest.mark.parametrize("f, z", [(40.0, 0.05), (60.0, 0.1), (20.0, 0.01)])
def test_floor_is_the_rms_of_a_simulated_rounding(f, z):
    """ZV-shaped moves rounded to 0.0125 mm steps from 400 random start positions: the RMS residual the rounding
    adds lies within 0.45-1.0 of the floor (the model's independent errors: the creeping ends of a move round
    coherently, so the simulation stays below it; measured 0.55-0.87)."""
    axis = jb.ModalAxis([f], [z])
    zv = jb.design_move(axis, 0.1, None, v_max=0.3, a_max=3.0, include=("ZV",)).candidate("ZV")
    t, x, _, _ = zv.sample(RATE)
    floor = float(resolution_floor(axis, STEP, RATE, zv.move_time)[0])
    rms = _rounded_rms(np.asarray(t), np.asarray(x), f, z, STEP, 400)
    assert 0.45 * floor <= rms <= 1.0 * floor, (rms, floor)


def test_floor_scales_with_the_step_and_the_gain():
    axis = jb.ModalAxis([30.0, 45.0], [0.05, 0.02], [1.0, 0.5])
    one = resolution_floor(axis, STEP, RATE, 0.4)
    np.testing.assert_allclose(resolution_floor(axis, 2 * STEP, RATE, 0.4), 2 * one, rtol=1e-12)
    single = resolution_floor(jb.ModalAxis([45.0], [0.02]), STEP, RATE, 0.4)
    assert one[1] == pytest.approx(0.5 * single[0], rel=1e-12)


@pytest.fixture(scope="module")
def printer():
    """A printer-like axis at ZV's own time and peaks, with a 0.1 mm step: the floor (about 40 um) lies above ZV's
    and the minimax design's residual, below the unshaped move's on one mode at least."""
    axis = jb.ModalAxis([48.0, 62.0], [0.08, 0.1])
    zv = jb.design_move(axis, 0.05, None, v_max=0.3, a_max=5.0, include=("ZV",)).candidate("ZV")
    T, lim = zv.move_time * (1 + 1e-9), dict(v_max=zv.peak_v, a_max=zv.peak_a)
    include = ("minimax", "ZV", "ZVD", "unshaped")
    return axis, jb.design_move(axis, 0.05, T, include=include, resolution=1e-4, **lim), T, lim, include


def test_rows_below_the_floor_rank_by_their_peaks(printer):
    axis, plan, T, lim, include = printer
    floor = resolution_floor(axis, 1e-4, RATE, T)
    band = np.linspace(0.8, 1.2, 401)
    for c in plan.table:
        if c.command is None:
            assert not c.at_resolution
            continue
        t, x, _, _ = plan.samples(RATE, c.name)  # the replayed CSV, per mode, against the floor
        worst = executed_residual_reference(axis.frequencies, axis.damping_ratios, axis.gains, t, x, band).max(axis=1)
        assert c.at_resolution == bool(np.all(worst <= floor)), c.name
        assert ("at the drive's resolution" in c.note) == c.at_resolution
    usable = [c for c in plan.table if c.ok]
    at = [c for c in usable if c.at_resolution]
    assert len(at) >= 2 and usable[: len(at)] == at  # below the floor first
    assert [c.peak_a for c in at] == sorted(c.peak_a for c in at)  # by their peak |a|
    rest = [c.worst_percent for c in usable[len(at) :]]
    assert rest == sorted(rest)
    assert plan.best is at[0] and plan.resolution == 1e-4
    # without a resolution: by the worst residual, nothing at the floor
    free = jb.design_move(axis, 0.05, T, include=include, **lim)
    assert not any(c.at_resolution for c in free.table)
    worsts = [c.worst_percent for c in free.table if c.ok]
    assert worsts == sorted(worsts) and free.best.worst_percent == min(worsts)


@pytest.mark.parametrize("bad", [0.0, -1e-5, float("nan"), float("inf"), 2.5, "1e-5", True, np.True_, [1e-5]])
def test_resolution_is_checked(bad):
    """Refused by name with its range; a bool (1.0 would lie in range here: the distance is 2 m) as well."""
    axis = jb.ModalAxis([40.0], [0.05])
    with pytest.raises(ValueError, match=r"`resolution`.*\(0, 2\]"):
        jb.design_move(axis, 2.0, 10.0, v_max=0.3, a_max=3.0, resolution=bad)


def test_cli_passes_the_resolution_and_the_rate(printer, tmp_path, capsys):
    """`jaxbelt shaping --resolution STEP --rate R`: the printed table marks the rows below the floor, the
    recommendation is the library's at that resolution and rate, and the CSV holds that plan's setpoints."""
    import csv

    from jaxbelt.cli import main

    axis, _, T, lim, include = printer
    out = tmp_path / "move.csv"
    argv = ["--no-cache", "shaping", "--mode", "48:0.08", "--mode", "62:0.1", "--distance", "0.05"]
    argv += ["--move-time", repr(T), "--v-max", repr(lim["v_max"]), "--a-max", repr(lim["a_max"])]
    argv += ["--resolution", "1e-4", "--rate", "2000", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    plan = jb.design_move(axis, 0.05, T, resolution=1e-4, rate_hz=2000.0, **lim)
    assert plan.best is not None and f"recommended: {plan.best.name}," in printed
    # the table is the one at 2 kHz: its unshaped row's worst differs from the 1 kHz plan's in the fourth digit
    at_1k = jb.design_move(axis, 0.05, T, resolution=1e-4, **lim).candidate("unshaped").worst_percent
    at_2k = plan.candidate("unshaped").worst_percent
    assert f"{at_2k:9.4f}" != f"{at_1k:9.4f}"
    line = next(ln for ln in printed.splitlines() if ln[1:].startswith("unshaped"))
    assert f"{at_2k:9.4f}" in line
    assert printed.count("at the drive's resolution") == sum(c.at_resolution for c in plan.table) > 0
    with open(out) as fh:
        rows = list(csv.reader(fh))[1:]
    x = np.array([float(r[1]) for r in rows])
    np.testing.assert_allclose(x, plan.samples(2000.0)[1], rtol=0, atol=1e-15)
