"""The README's snippets run as written, and what they claim holds.

The Python blocks of README.md are executed in order in one namespace (as a reader pastes them into one
notebook), in a temporary folder (the shaping snippet writes `move.csv`). Each block's result is then checked
against an independent computation: the exported CSV replayed through scipy, the batched sweep against one
unbatched solve of the same element, the live view's χ against `fluctuation_index` on a fresh simulation.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_the_readme_is_short_and_opens_with_its_commands():
    """A newcomer reads the README in two minutes: at most 120 lines, the two commands first, a snippet for each
    use (shape a move and export it, a sweep, the live view)."""
    text = README.read_text()
    assert len(text.splitlines()) <= 120
    blocks = python_blocks(text)
    assert len(blocks) == 3
    assert "design_move" in blocks[0] and "to_csv" in blocks[0] and "to_firmware" in blocks[0]
    assert "simulate" in blocks[1] and "explore" in blocks[2]


@pytest.fixture(scope="module")
def readme_namespace(tmp_path_factory):
    import os

    pytest.importorskip("ipywidgets")
    folder = tmp_path_factory.mktemp("readme")
    here = os.getcwd()
    os.chdir(folder)
    ns: dict = {}
    try:
        for block in python_blocks(README.read_text()):
            exec(compile(block, "README.md", "exec"), ns)  # noqa: S102 - the README's own snippets
    finally:
        os.chdir(here)
    ns["__folder__"] = folder
    return ns


def _replayed_worst_percent(axis, t, x, uncertainty, reference_m):
    """The worst residual amplitude over ±`uncertainty` of each mode (9 frequencies a mode) of the position
    setpoints `x` executed linearly between samples, in % of `reference_m` per mode. Each mode is
    $\\ddot q + 2\\zeta\\omega\\dot q + \\omega^2 q = -\\ddot x(t)$; with positions interpolated linearly
    $\\ddot x$ is a train of impulses (the velocity jumps at the samples), so $\\dot q$ jumps by minus each
    jump and the mode vibrates freely between samples: propagated exactly with scipy's `expm`."""
    from scipy.linalg import expm

    worst = 0.0
    dt = float(np.median(np.diff(t)))
    assert np.allclose(np.diff(t), dt)
    jumps = np.diff(np.concatenate([[0.0], np.diff(x) / dt, [0.0]]))  # the velocity jumps at every sample [m/s]
    for f0, z, ref in zip(np.asarray(axis.frequencies), np.asarray(axis.damping_ratios), reference_m):
        for f in np.linspace(f0 * (1 - uncertainty), f0 * (1 + uncertainty), 9):
            w = 2 * np.pi * f
            step = expm(np.array([[0.0, 1.0], [-w * w, -2 * z * w]]) * dt)
            y = np.zeros(2)
            for dv in jumps[:-1]:
                y = step @ (y - np.array([0.0, dv]))
            y = y - np.array([0.0, jumps[-1]])  # the carriage stops at the last sample
            wd = w * np.sqrt(1 - z * z)
            worst = max(worst, 100 * float(np.hypot(y[0], (y[1] + z * w * y[0]) / wd)) / float(ref))
    return worst


@pytest.mark.slow
def test_the_shaping_snippet_exports_what_its_table_states(readme_namespace):
    plan, axis = readme_namespace["plan"], readme_namespace["axis"]
    best = plan.best
    assert best is not None and best.ok
    unshaped = next(c for c in plan.table if c.name == "unshaped")
    assert best.worst_percent < unshaped.worst_percent
    with open(readme_namespace["__folder__"] / "move.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "x", "v", "a"]
    data = np.array(rows[1:], dtype=float)
    t, x = data[:, 0], data[:, 1]
    assert t[0] == 0.0 and abs(t[-1] - best.move_time) < 1e-3 and np.allclose(np.diff(t), 1e-3)
    assert x[0] == pytest.approx(0.0, abs=1e-12) and x[-1] == pytest.approx(plan.distance, rel=1e-9)
    # replayed as a drive executes position setpoints (linear between the 1 kHz samples), the worst residual over
    # the band is the table's within 5 % (a coarser 9-point band here; the table's grid is finer)
    replayed = _replayed_worst_percent(axis, t, x, plan.uncertainty, np.asarray(plan.reference_m))
    assert replayed == pytest.approx(best.worst_percent, rel=0.05)


@pytest.mark.slow
def test_the_firmware_line_gives_back_the_shaper_whose_residual_is_stated(readme_namespace):
    """The M593 line, read back by a reader written here from RepRapFirmware's rules (`H`: the amplitudes of every
    impulse but the last, which is 1 minus their sum; `T`: the delays of the later impulses [s]), gives impulses
    whose worst residual ratio over ±`uncertainty` of each mode, evaluated here in closed form, is `worst`."""
    shaper, axis = readme_namespace["shaper"], readme_namespace["axis"]
    line = shaper.to_firmware()
    assert line.startswith('M593 P"custom"')
    fields = dict(re.findall(r"\b([HT])([-0-9.e:]+)", line))
    H = [float(v) for v in fields["H"].split(":")]
    T = [float(v) for v in fields["T"].split(":")]
    assert len(H) == len(T) <= 4
    A, times = np.r_[H, 1.0 - sum(H)], np.r_[0.0, T]
    worst = 0.0
    for f0, z in zip(np.asarray(axis.frequencies), np.asarray(axis.damping_ratios)):
        for f in np.linspace(0.8 * f0, 1.2 * f0, 241):
            w = 2 * np.pi * f
            wd = w * np.sqrt(1 - z * z)
            terms = A * np.exp(z * w * (times - times[-1]))
            worst = max(worst, float(np.hypot(terms @ np.cos(wd * times), terms @ np.sin(wd * times))))
    assert worst == pytest.approx(shaper.worst, rel=2e-3)


def test_the_sweep_snippet_equals_one_unbatched_solve(readme_namespace):
    import jax.numpy as jnp

    import jaxbelt as jb

    ns = readme_namespace
    peak, gammas = np.asarray(ns["peak_current"]), np.asarray(ns["gammas"])
    assert peak.shape == (1000,)
    one = jb.simulate(jb.Scene(ns["model"], jb.ExponentialVoltage(24.0, gammas[500]), ts=ns["ts"]), method="ode")
    assert peak[500] == pytest.approx(float(jnp.max(one.current)), rel=1e-6)


@pytest.mark.slow
def test_the_live_view_snippet_shows_the_papers_index(readme_namespace):
    import jax.numpy as jnp

    import jaxbelt as jb

    view = readme_namespace["view"]
    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    closed = jb.simulate(jb.Scene(drive, pid, ts=jnp.linspace(0.0, 1.0, 2001), observe=("motor_speed",)))
    chi = float(jb.fluctuation_index(closed, 0.375, 0.5))
    assert view.values["chi"] == pytest.approx(chi, rel=1e-3)
    assert chi == pytest.approx(0.026, abs=0.0005)  # Incerti (2012): χ = 2.6 %
