"""The certificate of the continuous problem (`jaxbelt.shaping.certify`) and the minimax design whose acceleration
may jump (`design_move(..., smooth=False)`), against an independent LP solved by scipy's HiGHS."""

import math

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
    assert jumps.note.startswith("added: ZV leaves")  # the smooth design alone leaves more than ZV
    assert jumps.worst_percent < 0.2 * zv_eq.worst_percent
    # the minimax row's command space holds the design with jumps and ZV: it leaves no more than either
    assert "the design alone" in smooth.note and smooth.worst_percent <= jumps.worst_percent * (1 + 1e-9)
    assert plan.best.worst_percent <= jumps.worst_percent * (1 + 1e-9) and plan.minimax.options.basis == "steps"
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
    """A 5.5 Hz axis at 0.8 s, the default command space (`smooth="auto"`): `certify_rtol` adds the design with
    jumps, which carries the certificate. The optimum is near zero, the bound 0, so no relative tolerance can be
    proved; that design is within `CERTIFY_ATOL` (0.01 % of the unshaped move's residual) of the least any command
    can leave at once, with no refinement, and its note says which tolerance was met. The smooth row's note states
    the same bound, which lies below its worst. An independent HiGHS LP on 4x the steps (a finer command space
    holding the design's) lies between the bound and the design's LP value."""
    plan = jb.design_move(
        jb.ModalAxis([5.5], [0.02]), 0.1, 0.8, v_max=0.3, a_max=1.2, uncertainty=0.2, include=("minimax",),
        certify_rtol=0.01,
    )  # fmt: skip
    row, smooth, bound = plan.candidate(JUMPS), plan.candidate("minimax"), plan.continuous_bound
    assert row.ok and row.note.startswith("added: `certify_rtol` asks for the continuous certificate")
    assert "(absolute, at most CERTIFY_ATOL" in row.note and "not within" not in row.note
    assert smooth.ok and "(continuous bound, from the design with jumps)" in smooth.note
    assert bound <= smooth.worst_percent / 100
    mm = plan.minimax  # the better of the two rows: here the design with jumps (0.0053 % against 0.071 %)
    # the minimax row's command space holds the design with jumps: the recommendation leaves what it leaves
    assert mm.options.basis == "steps" and plan.best.worst_percent == pytest.approx(row.worst_percent, rel=1e-9)
    assert mm.options.n_angles == 16  # not refined
    worst = row.worst_percent / 100
    assert 0.0 <= bound <= worst and worst - bound <= CERTIFY_ATOL
    fine = highs_steps_lp(mm, 4 * mm.options.n_knots)
    assert bound <= fine + 1e-9 and float(mm.worst) >= fine - 1e-9


@pytest.mark.parametrize(
    "worst_percent, bound, says",
    [
        (12.0, 0.0125, "any command leaves >= 1.25 % (continuous bound, from the design with jumps): this one at most 11 percentage points above"),
        (0.004, math.nan, "within 0.004 percentage points of the least any command can leave (its worst is below CERTIFY_ATOL"),
        (0.5, math.nan, None),
    ],
)  # fmt: skip
def test_the_smooth_rows_note_states_what_is_proved(worst_percent, bound, says):
    """The smooth row's place against any command: the bound of the design with jumps where there is one (then the
    gap in percentage points, worst - bound); with none, a worst below `CERTIFY_ATOL` (0.01 %) is within that of
    the least any command can leave (a residual is never below 0); otherwise nothing is claimed."""
    from types import SimpleNamespace

    from jaxbelt.shaping.plan import _smooth_certificate

    note = _smooth_certificate(SimpleNamespace(worst_percent=worst_percent), bound)
    assert (says in note) if says else note == ""


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(smooth=True, certify_rtol=0.01), "`certify_rtol` needs `smooth=False` or 'auto'"),
        (dict(smooth=False, certify_rtol=0.0), r"`certify_rtol` must lie in \(0, 1\); got 0.0"),
        (dict(smooth=False, certify_rtol="1%"), r"`certify_rtol` must be a number in \(0, 1\)"),
    ],
)
def test_bad_certify_rtol_is_refused_by_name(kw, message):
    with pytest.raises(ValueError, match=message):
        jb.design_move(jb.ModalAxis([5.5], [0.02]), 0.1, 1.0, v_max=0.3, a_max=1.2, **kw)


class _Stop(Exception):
    """Raised by the stand-in of design_move: the CLI stops there, nothing is designed."""


def _cli_until_design_move(monkeypatch, tmp_path, extra):
    """Run `jaxbelt shaping` on a 5.5 Hz axis with `extra` options, design_move replaced by a stand-in that records
    its keyword arguments and stops: `(exit code or None where it stopped at design_move, the keywords seen)`."""
    from jaxbelt.cli import main
    from jaxbelt.shaping import plan as plan_module

    seen = {}

    def capture(*args, **kwargs):
        seen.update(kwargs)
        raise _Stop

    monkeypatch.setattr(plan_module, "design_move", capture)
    argv = ["--no-cache", "shaping", "--mode", "5.5:0.02", "--distance", "0.1", "--move-time", "0.8", "--v-max", "0.3"]
    argv += ["--a-max", "1.2", "--out", str(tmp_path / "m.csv"), "--no-progress", *extra]
    try:
        return main(argv), seen
    except _Stop:
        return None, seen
    except SystemExit as e:  # argparse's own refusal (a value outside the type's range)
        return e.code, seen


@pytest.mark.parametrize("flag, value", [("auto", "auto"), ("true", True), ("false", False)])
def test_cli_smooth_reaches_design_move(flag, value, monkeypatch, tmp_path):
    """`jaxbelt shaping --smooth {auto,true,false}` hands design_move `smooth` = "auto", True or False (stopped
    there: nothing is designed)."""
    code, seen = _cli_until_design_move(monkeypatch, tmp_path, ["--smooth", flag])
    assert code is None and seen["smooth"] == value and type(seen["smooth"]) is type(value)


@pytest.mark.parametrize(
    "extra, expect",
    [
        (["--certify", "0.05"], 0.05),
        (["--certify", "0.05", "--smooth", "true"], "argument --certify: the continuous certificate bounds"),
        (["--certify", "0.05", "--j-max", "20"], "not with --j-max"),
        (["--certify", "1"], "argument --certify: must lie in (0, 1)"),
    ],
)
def test_cli_certify_reaches_design_move_or_is_refused_by_name(extra, expect, monkeypatch, tmp_path, capsys):
    """`jaxbelt shaping --certify RTOL` hands design_move `certify_rtol` = RTOL (stopped there: nothing is
    designed); with `--smooth true`, `--j-max` or outside (0, 1) it is refused in one line naming the option."""
    code, seen = _cli_until_design_move(monkeypatch, tmp_path, extra)
    if isinstance(expect, float):
        assert code is None and seen["certify_rtol"] == expect
    else:
        assert code == 2 and expect in capsys.readouterr().err and not seen
