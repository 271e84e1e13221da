"""The certificate of the continuous problem (`jaxbelt.shaping.certify`) and the minimax design whose acceleration
may jump (`design_move(..., smooth=False)`), against an independent LP solved by scipy's HiGHS."""

import numpy as np
import pytest
from references import highs_steps_lp, modal_residual_reference, piecewise_move_reference

import jaxbelt as jb
from jaxbelt.shaping.certify import continuous_lower_bound
from jaxbelt.shaping.plan import CERTIFY_ATOL, JUMPS


@pytest.fixture(scope="module")
def plan_55():
    """A 5.5 Hz axis, damping 0.02, at ZV's shortest time under v 0.3 m/s, a 1.2 m/s^2, band +-20 %."""
    return jb.design_move(
        jb.ModalAxis([5.5], [0.02]), 0.1, 0.6743, v_max=0.3, a_max=1.2, uncertainty=0.2, smooth=False,
        include=("minimax", "ZV"),
    )  # fmt: skip


def test_continuous_bound_brackets_the_optimum_of_an_independent_finer_lp(plan_55):
    """HiGHS at 4x the design's intervals (a finer command space that holds the design's): the rigorous lower bound
    is below it (tolerance 1e-9, HiGHS's own), the design's LP value above it, and all three within 5 %."""
    mm = plan_55.minimax
    fine = highs_steps_lp(mm, 4 * mm.options.n_knots)
    lower = continuous_lower_bound(mm)
    assert lower == pytest.approx(plan_55.continuous_bound, rel=1e-12)
    assert lower <= fine + 1e-9
    assert float(mm.worst) >= fine - 1e-9
    assert float(mm.worst) <= 1.05 * fine and lower >= 0.95 * fine
    # the table's worst (the command on the fine frequency grid) is at least the bound, and within 5 % of HiGHS's
    row = plan_55.candidate("minimax")
    assert lower <= row.worst_percent / 100 <= 1.05 * fine * (1 + 0.03)  # 3 %: the exchange's own tolerance
    assert "continuous bound" in row.note


def test_steps_design_respects_its_limits_exactly_and_moves_the_distance(plan_55):
    """Its acceleration is constant on each interval: |a| at those values, |v| at the interval ends (where a
    piecewise linear velocity peaks) are the exact peaks; checked on a grid 64x finer than the intervals."""
    cmd = plan_55.minimax.command
    t = np.linspace(0.0, float(cmd.duration), 64 * plan_55.minimax.options.n_knots + 1)
    v = np.asarray(cmd.derivative(t, 1))
    a = np.asarray(cmd.derivative(t, 2))
    assert np.max(np.abs(v)) <= 0.3 * (1 + 1e-9) and np.max(np.abs(a)) <= 1.2 * (1 + 1e-9)
    assert float(cmd.derivative(np.asarray(float(cmd.duration) + 1.0), 0)) == pytest.approx(0.1, rel=1e-12)
    assert abs(float(cmd.derivative(np.asarray(float(cmd.duration)), 1))) < 1e-12


def test_the_default_adds_the_design_with_jumps_where_a_shaper_beats_the_smooth_one():
    """A 40 Hz, damping 0.003 axis (where the smooth design leaves more than ZV) at ZV's own shortest time and
    peak velocity and acceleration as the limits, one plan, one reference: the default (`smooth="auto"`) adds the
    minimax design with jumps, which leaves less than ZV (measured 0.10x; asserted < 0.2x), is recommended and is
    `plan.minimax`; its continuous bound is below its worst, and its worst matches an independent evaluation
    (exact modal propagation of its acceleration, 401 band points; 3 %: the design's own grid against the dense
    one)."""
    axis = jb.ModalAxis([40.0], [0.003])
    first = jb.design_move(axis, 0.1, None, v_max=0.3, a_max=1.2, uncertainty=0.2, include=("ZV",))
    zv = first.candidate("ZV")
    plan = jb.design_move(
        axis, 0.1, zv.move_time * (1 + 1e-9), v_max=zv.peak_v, a_max=zv.peak_a, uncertainty=0.2,
        include=("minimax", "ZV"),
    )  # fmt: skip
    smooth, jumps, zv_eq = plan.candidate("minimax"), plan.candidate(JUMPS), plan.candidate("ZV")
    assert zv_eq.ok and jumps.ok, (zv_eq.note, jumps.note)
    assert smooth.worst_percent >= zv_eq.worst_percent  # why it was added, as its note says
    assert jumps.note.startswith("added: ZV leaves")
    assert jumps.worst_percent < 0.2 * zv_eq.worst_percent
    assert plan.best is jumps and plan.minimax.options.basis == "steps"
    assert 0.0 < plan.continuous_bound <= jumps.worst_percent / 100
    cmd = jumps.command
    acc, _, _, breaks = piecewise_move_reference(cmd.times, cmd.steps, cmd.ramps, cmd.duration)
    dense = modal_residual_reference(
        [40.0], [0.003], [1.0], acc, breaks, float(cmd.duration), np.linspace(0.8, 1.2, 401)
    )
    assert 100 * np.max(dense) / plan.reference_m[0] == pytest.approx(jumps.worst_percent, rel=0.03)


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(smooth="no"), "`smooth` must be True, False or 'auto'"),
        (dict(smooth=1), "`smooth` must be True, False or 'auto'"),
    ],
)
def test_bad_smooth_is_refused_before_any_work(kw, message):
    with pytest.raises(ValueError, match=message):
        jb.design_move(jb.ModalAxis([5.5], [0.02]), 0.1, 1.0, v_max=0.3, a_max=1.2, **kw)


def test_certify_rtol_refines_until_the_continuous_bound_is_within_the_tolerance():
    """`certify_rtol=0.01`: the design is proved within 1 % of the least worst residual any command can leave
    (the table's worst against the rigorous bound), and an independent HiGHS LP on 4x the design's intervals, with
    the design's own cuts and frequencies, lies between the bound and the design's LP value."""
    plan = jb.design_move(
        jb.ModalAxis([5.5], [0.02]), 0.1, 0.6743, v_max=0.3, a_max=1.2, uncertainty=0.2, smooth=False,
        include=("minimax",), certify_rtol=0.01,
    )  # fmt: skip
    row, mm, bound = plan.candidate("minimax"), plan.minimax, plan.continuous_bound
    assert row.ok and "of the least any command can leave" in row.note and "not within" not in row.note
    worst = row.worst_percent / 100
    assert bound <= worst and worst - bound <= 0.01 * worst
    fine = highs_steps_lp(mm, 4 * mm.options.n_knots)
    assert bound <= fine + 1e-9 and float(mm.worst) >= fine - 1e-9
    # the default design (16 cuts) is not within 1 %: the refinement did something
    assert mm.options.n_angles > 16


def test_certify_rtol_near_a_zero_optimum_stops_at_the_absolute_floor():
    """A 5.5 Hz axis at 0.8 s: the optimum is near zero, the bound 0, so no relative tolerance can be proved; the
    design is within `CERTIFY_ATOL` (0.01 % of the unshaped move's residual) of the least any command can leave at
    once, with no refinement, and the note says which tolerance was met. An independent HiGHS LP on 4x the steps (a
    finer command space holding the design's) lies between the bound and the design's LP value."""
    plan = jb.design_move(
        jb.ModalAxis([5.5], [0.02]), 0.1, 0.8, v_max=0.3, a_max=1.2, uncertainty=0.2, smooth=False,
        include=("minimax",), certify_rtol=0.01,
    )  # fmt: skip
    row, mm, bound = plan.candidate("minimax"), plan.minimax, plan.continuous_bound
    assert row.ok and "(absolute, at most CERTIFY_ATOL" in row.note and "not within" not in row.note
    assert mm.options.n_angles == 16  # not refined
    worst = row.worst_percent / 100
    assert 0.0 <= bound <= worst and worst - bound <= CERTIFY_ATOL
    fine = highs_steps_lp(mm, 4 * mm.options.n_knots)
    assert bound <= fine + 1e-9 and float(mm.worst) >= fine - 1e-9


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(certify_rtol=0.01), "`certify_rtol` needs `smooth=False`"),
        (dict(smooth=False, certify_rtol=0.0), r"`certify_rtol` must lie in \(0, 1\); got 0.0"),
        (dict(smooth=False, certify_rtol="1%"), r"`certify_rtol` must be a number in \(0, 1\)"),
    ],
)
def test_bad_certify_rtol_is_refused_by_name(kw, message):
    with pytest.raises(ValueError, match=message):
        jb.design_move(jb.ModalAxis([5.5], [0.02]), 0.1, 1.0, v_max=0.3, a_max=1.2, **kw)


@pytest.mark.parametrize("flag, value", [("auto", "auto"), ("true", True), ("false", False)])
def test_cli_smooth_reaches_design_move(flag, value, monkeypatch, tmp_path):
    """`jaxbelt shaping --smooth {auto,true,false}` hands design_move `smooth` = "auto", True or False (stopped
    there: nothing is designed)."""
    from jaxbelt.cli import main
    from jaxbelt.shaping import plan as plan_module

    seen = {}

    class Stop(Exception):
        pass

    def capture(*args, **kwargs):
        seen.update(kwargs)
        raise Stop

    monkeypatch.setattr(plan_module, "design_move", capture)
    argv = ["--no-cache", "shaping", "--mode", "5.5:0.02", "--distance", "0.1", "--move-time", "0.8", "--v-max", "0.3"]
    argv += ["--a-max", "1.2", "--smooth", flag, "--out", str(tmp_path / "m.csv"), "--no-progress"]
    with pytest.raises(Stop):
        main(argv)
    assert seen["smooth"] == value and type(seen["smooth"]) is type(value)
