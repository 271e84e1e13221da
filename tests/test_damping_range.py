"""`design_move(..., damping=(lo, hi) | "unknown")`: designs judged over a damping range as well as the band.

Every residual is checked against an independent evaluator (`references.modal_residual_reference`: Duhamel's
integral of $q'' + 2\\zeta\\omega q' + \\omega^2 q = -a(t)$ by Gauss-Legendre quadrature on the commands'
pieces, exact to rounding for piecewise-polynomial accelerations) on a dense damping grid, 25 damping ratios of
the range, and 401 frequencies of the band; the references are those of an unshaped trapezoid built here.
"""

import numpy as np
import pytest
from references import modal_residual_reference, piecewise_move_reference, spline_move_reference

import jaxbelt as jb
from jaxbelt.shaping.moves import PiecewiseMove, SplineMove

F, ZETA = 7.3, 0.05
D, T, V, A, U = 0.1, 0.8, 0.3, 1.2, 0.2
KW = dict(v_max=V, a_max=A, uncertainty=U, include=("minimax", "ZV", "EI"))
#: the dense damping grid: 25 geometric samples of Klipper's range (0.01, 0.1) (every 6th is one of the plan's 5)
DENSE = np.geomspace(0.01, 0.1, 25)
BAND = np.linspace(1 - U, 1 + U, 401)


def _trapezoid_accel(d, v, a):
    """The time-optimal rest-to-rest move within |v| <= v, |a| <= a (a cruise here: v^2/a < d), built here."""
    ta = v / a
    tc = (d - v * v / a) / v
    assert tc > 0
    Tm = 2 * ta + tc

    def acc(t):
        t = np.asarray(t, float)
        return np.where(t < ta, a, np.where(t < ta + tc, 0.0, np.where(t <= Tm, -a, 0.0)))

    return acc, np.array([0.0, ta, ta + tc, Tm]), Tm


def _residuals(acc, breaks, Tm, zetas, factors=BAND):
    """(len(zetas), len(factors)) residual amplitudes [m] of the 7.3 Hz mode at each damping ratio."""
    z = np.asarray(zetas, float)
    return modal_residual_reference(np.full(z.size, F), z, np.ones(z.size), acc, breaks, Tm, factors)


def _command_accel(cmd):
    if isinstance(cmd, SplineMove):
        acc, _, _, breaks = spline_move_reference(np.asarray(cmd.coefficients), float(cmd.duration))
    else:
        assert isinstance(cmd, PiecewiseMove)
        acc, _, _, breaks = piecewise_move_reference(cmd.times, cmd.steps, cmd.ramps, cmd.duration)
    return acc, breaks, float(cmd.duration)


@pytest.fixture(scope="module")
def reference():
    """Per dense damping ratio, the unshaped time-optimal move's worst residual over the band [m]."""
    return _residuals(*_trapezoid_accel(D, V, A), DENSE).max(axis=1)


def _dense_worst(cmd, reference):
    """The command's worst residual over band x dense damping grid, in % of the unshaped references."""
    return 100.0 * float(np.max(_residuals(*_command_accel(cmd), DENSE) / reference[:, None]))


@pytest.fixture(scope="module")
def plans():
    axis = jb.ModalAxis([F], [ZETA])
    return {
        "unknown": jb.design_move(axis, D, T, damping="unknown", **KW),
        "nominal": jb.design_move(axis, D, T, **KW),
    }


def test_plan_records_the_range(plans):
    p = plans["unknown"]
    assert p.damping == (0.01, 0.1)
    assert p.axis.n_modes == 1 and all(len(c.band_hz) == 1 for c in p.table)
    np.testing.assert_allclose(np.asarray(p.measure_axis.damping_ratios), np.geomspace(0.01, 0.1, 5), rtol=1e-12)
    assert "damping ratio 0.01 – 0.1" in dict((k, v) for k, v, _ in p._display().fields)["band"]
    assert p.format_table().splitlines()[-1] == "band: ±20 % of each frequency, × damping ratio 0.01 – 0.1 (5 samples)"
    assert plans["nominal"].damping is None and plans["nominal"].measure_axis is None


@pytest.mark.parametrize("name", ["minimax", "ZV", "EI"])
def test_reported_worst_covers_the_dense_damping_grid(plans, reference, name):
    # the 5 samples are part of the dense grid: the reported worst is at most the dense one (to the evaluators'
    # agreement, 1e-6); an interior maximum between samples exceeds it by at most 5 % (measured: 1.9 % for the
    # minimax design, whose residual is equalised over the samples; 0 for ZV and EI, worst at an end of the range)
    row = plans["unknown"].candidate(name)
    dense = _dense_worst(row.command, reference)
    assert row.worst_percent <= dense * (1 + 1e-6)
    assert dense <= row.worst_percent * 1.05


def test_klipper_shapers_are_designed_at_zeta_0_1(plans):
    # a ZV shaper zeroes the residual at its design frequency and damping: here 7.3 Hz at 0.1, not the axis' 0.05
    acc, breaks, Tm = _command_accel(plans["unknown"].candidate("ZV").command)
    res = _residuals(acc, breaks, Tm, [0.1, ZETA], factors=[1.0])[:, 0]
    unshaped = _residuals(*_trapezoid_accel(D, V, A), [0.1, ZETA], factors=[1.0])[:, 0]
    assert res[0] < 1e-6 * unshaped[0]
    assert res[1] > 1e-3 * unshaped[1]


def test_unknown_minimax_beats_every_klipper_shaper(plans, reference):
    # over band x damping range, independently evaluated: the minimax design against ZV and EI at zeta 0.1 (same time,
    # same limits); measured 0.075 % against 8.9 % (EI) and 20 % (ZV)
    p = plans["unknown"]
    mm = _dense_worst(p.candidate("minimax").command, reference)
    for name in ("ZV", "EI"):
        assert mm < 0.1 * _dense_worst(p.candidate(name).command, reference)


def test_range_design_beats_the_nominal_design_over_the_range(plans, reference):
    # the design made at zeta 0.05 only leaves more over the range than the one made for it (measured: 0.076 % against
    # 0.204 %)
    ranged = _dense_worst(plans["unknown"].candidate("minimax").command, reference)
    nominal = _dense_worst(plans["nominal"].candidate("minimax").command, reference)
    assert ranged < 0.5 * nominal


def test_exported_samples_leave_the_stated_residual(plans, reference):
    # a drive that executes the acceleration linearly between the samples (200 Hz) leaves the stated worst over
    # band x damping range (the correction restores it at every damping sample): within 5 % (measured: 0.0762 %
    # against the stated 0.0749 %, the interior maximum of the continuous design)
    p = plans["unknown"]
    t, _, _, a = (np.asarray(q, float) for q in p.samples(200.0, "minimax"))

    def acc(s):
        return np.interp(s, t, a, left=0.0, right=0.0)

    dense = 100.0 * float(np.max(_residuals(acc, t, float(t[-1]), DENSE) / reference[:, None]))
    assert dense <= p.candidate("minimax").worst_percent * 1.05


def test_damping_none_is_unchanged(plans):
    axis = jb.ModalAxis([F], [ZETA])
    p = jb.design_move(axis, D, T, damping=None, **KW)
    assert p.format_table() == plans["nominal"].format_table()
    for a, b in zip(p.table, plans["nominal"].table, strict=True):
        assert (a.name, a.worst_percent, a.mean_percent, a.band_hz) == (
            b.name,
            b.worst_percent,
            b.mean_percent,
            b.band_hz,
        )
    np.testing.assert_array_equal(p.reference_m, plans["nominal"].reference_m)


def test_a_range_without_the_axis_damping_is_refused():
    # the classic shapers are designed at the axis' own damping ratio: a range that leaves it out is a contradiction
    with pytest.raises(
        ValueError, match=r"`damping` \(0\.06, 0\.1\) must contain the axis' own damping ratios \[0\.05\]"
    ):
        jb.design_move(jb.ModalAxis([F], [ZETA]), D, T, damping=(0.06, 0.1), **KW)


@pytest.mark.parametrize("bad", [(0.2, 0.1), (-0.1, 0.1), (0.1, 1.0), "foo", (0.1,), (0.01, float("nan"))])
def test_bad_damping_raises(bad):
    with pytest.raises(ValueError, match=r"`damping`.*0 <= lo <= hi < 1"):
        jb.design_move(jb.ModalAxis([F], [ZETA]), D, T, damping=bad, **KW)


def test_cli_damping_reaches_the_design(plans, tmp_path, capsys, monkeypatch):
    # `jaxbelt shaping --damping unknown` designs what design_move(..., damping="unknown") does: the same rows (the
    # candidates narrowed to the fixture's, so that its programs serve), and the CSV of the recommended command
    from jaxbelt.cli import main
    from jaxbelt.shaping import plan as plan_module

    real = plan_module.design_move
    seen = {}

    def narrowed(*args, **kwargs):
        seen.update(kwargs)
        return real(*args, **(kwargs | dict(include=KW["include"])))

    monkeypatch.setattr(plan_module, "design_move", narrowed)
    out = tmp_path / "move.csv"
    args = ["--no-cache", "shaping", "--mode", f"{F}:{ZETA}", "--distance", str(D), "--move-time", str(T)]
    args += ["--v-max", str(V), "--a-max", str(A), "--damping", "unknown", "--out", str(out), "--no-progress"]
    assert main(args) == 0
    assert seen["damping"] == "unknown"
    text = capsys.readouterr().out
    rows = {c.name: c for c in plans["unknown"].table}
    found = 0
    for line in text.splitlines():
        name = line[1:28].strip()
        if name in rows and rows[name].ok:
            assert float(line[28:].split()[1]) == pytest.approx(rows[name].worst_percent, rel=1e-3, abs=1e-4), name
            found += 1
    assert found == len([c for c in plans["unknown"].table if c.ok])
    data = np.genfromtxt(out, delimiter=",", names=True)
    np.testing.assert_allclose(data["a"], plans["unknown"].samples(1000.0)[3], rtol=1e-9, atol=1e-12)
