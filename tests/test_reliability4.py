"""Reliability round 4: no late errors, no silent acceptance (the cases of the issue, one test each).

- an invalid start value of `identify` is refused at the call, before the fit is compiled; NaN from the user's
  `predict` at the start values is a `ValueError` naming `predict` and the first bad point;
- under `vmap`, a parameter out of its range in one element raises a `ValueError` whose first line names the
  parameter and its range (not JAX's stack banner): `residual_energy`, `speed_sweep`, χ;
- χ of a drive that stands in the window (average speed ~0, a set point of 0) is refused, never a number;
- a pseudo-polynomial start exponent a hair above its bound is warned about before `optimise_command` runs;
- `best_residual` refuses move times no command can meet and a missing design; `shortest_move_time` its bad
  arguments;
- a minimax design on an axis with a mode far outside the move's bandwidth warns what to change.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles

import jaxbelt as jb


def first_line(e: pytest.ExceptionInfo) -> str:
    return str(e.value).splitlines()[0]


class _Reached(Exception):
    """Raised by a stand-in of a compiled program: reaching it means nothing refused the call before."""


def _fail(*args, **kwargs):
    raise _Reached


# --- 1. identify: invalid start values at the call; NaN from `predict` at the start ----------------------------
TS = jnp.linspace(0.0, 0.3, 31)


def _startup(p):
    m = jb.BeltStartup(k=p["k"], c=p["c"], R=p["R"])
    sol = jb.simulate(jb.Scene(m, jb.ExponentialVoltage(24.0, 0.02), ts=TS))
    return jnp.stack([sol["omega2"], sol["current"]], -1)


def test_identify_refuses_an_invalid_start_value_before_compiling(monkeypatch):
    import jaxbelt.identification as ident

    monkeypatch.setattr(ident, "_fit", _fail)  # the compiled fit is never reached
    with count_compiles() as box, pytest.raises(ValueError) as e:
        jb.identify(_startup, {"k": -80e3, "c": 30.0, "R": 0.2}, np.zeros((31, 2)), sigma=1.0)
    line = first_line(e)
    assert line.startswith("identify: BeltStartup: parameter `k` must lie in [0.001, 1e+12] N/m; got -80000.0"), line
    assert "start values {'k': -80000.0, 'c': 30.0, 'R': 0.2}" in line
    assert box["n"] == 0, box  # refused before compiling anything
    # a prediction of the wrong shape: refused at the call too
    with pytest.raises(ValueError, match=r"shape of `data` \(31, 3\); got shape \(31, 2\)"):
        jb.identify(_startup, {"k": 80e3, "c": 30.0, "R": 0.2}, np.zeros((31, 3)), sigma=1.0)


def test_identify_nan_from_predict_at_the_start_is_a_value_error_naming_the_point():
    def predict(p):
        return p["a"] * jnp.array([1.0, 2.0, jnp.nan, 4.0])

    with pytest.raises(ValueError) as e:
        jb.identify(predict, {"a": 1.0}, np.ones(4), 1.0)
    line = first_line(e)
    assert line.startswith("identify: `predict` returned non-finite values"), line
    assert "first at flat index 2, data index (2,)" in line and "at the start values, parameters {'a': 1.0}" in line
    assert isinstance(e.value, RuntimeError)  # what it was before: callers catching RuntimeError still do


# --- 2. errors from inside a program under vmap: the parameter and its range first ----------------------------
def test_residual_energy_under_vmap_names_the_platform_parameter_first():
    cmd = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
    with pytest.raises(ValueError) as e:
        jax.vmap(lambda k: jb.residual_energy(jb.BeltPlatform(k=k), cmd))(jnp.array([9e4, -1.0]))
    line = first_line(e)
    assert line.startswith("residual_energy: BeltPlatform: parameter `k` must lie in [0.001, 1e+12] N/m"), line
    assert "(element 1 of the batch)" in line, line  # the invalid element's index
    assert "Above is the stack" not in str(e.value)


def test_speed_sweep_under_vmap_names_the_damping_first_not_the_missing_steady_state():
    speeds = jnp.array([5.0, 10.0])
    with pytest.raises(ValueError) as e:
        jax.vmap(lambda d: jb.speed_sweep(jb.NonlinearBelt(damping=d), speeds, max_periods=20))(jnp.array([0.05, -0.1]))
    line = first_line(e)
    assert line.startswith("speed_sweep: NonlinearBelt: parameter `damping` must lie in [0, 1)"), line
    assert "(element 1 of the batch)" in line, line
    assert "steady state" not in line


# --- 3. χ of a drive that stands in the window -----------------------------------------------------------------
WINDOW_TS = jnp.linspace(0.0, 1.0, 101)


def test_chi_of_a_standing_drive_is_refused_or_nan_never_a_number():
    from jaxbelt.objectives import chi_from_samples

    with pytest.raises(ValueError) as e:
        chi_from_samples(WINDOW_TS, jnp.zeros(101))
    assert first_line(e).startswith("fluctuation index: the mean motor speed over the window [t0, t1] is 0 rad/s")
    # a speed about 0 (average 1e-5 of the swing): refused as well, naming the element of a batch
    swing = jnp.stack([30.0 + jnp.sin(6 * WINDOW_TS), jnp.cos(2 * jnp.pi * WINDOW_TS)])
    with pytest.raises(ValueError, match=r"element \(1,\) of the batch"):
        chi_from_samples(WINDOW_TS, swing)
    # traced: NaN with throw=False, a ValueError with the reason first under vmap
    got = jax.vmap(lambda s: chi_from_samples(WINDOW_TS, s, throw=False))(jnp.stack([jnp.zeros(101), swing[0]]))
    assert np.isnan(got[0]) and np.isfinite(got[1])
    with pytest.raises(ValueError) as e:
        jax.vmap(lambda s: chi_from_samples(WINDOW_TS, s))(jnp.stack([jnp.zeros(101), swing[0]]))
    assert first_line(e).startswith("fluctuation index: the average motor speed over the window [t0, t1] is ~0")
    # a running drive: unchanged
    assert 0.0 < float(chi_from_samples(WINDOW_TS, swing[0])) < 0.1


def test_fluctuation_objective_refuses_a_set_point_of_zero_before_simulating(monkeypatch):
    import jaxbelt.objectives.fluctuation as fl

    monkeypatch.setattr(fl, "_run_from_rest", _fail)
    for call in (
        lambda: jb.fluctuation_objective(jb.FourBarDrive(), jb.PID(omega_ref=0.0)),
        lambda: fl.closed_loop_metrics(jb.FourBarDrive(), jb.PID(omega_ref=0.0)),
    ):
        with pytest.raises(ValueError) as e:
            call()
        assert first_line(e).startswith("fluctuation index: parameter `omega_ref`"), first_line(e)
        assert "must be != 0 rad/s" in first_line(e) and "got 0.0" in first_line(e)


# --- 4. a pseudo-polynomial exponent a hair above its bound ---------------------------------------------------
def test_optimise_command_warns_of_an_exponent_at_its_bound(monkeypatch):
    import jaxbelt.optimise.command as oc

    monkeypatch.setattr(oc, "_run", _fail)
    cmd = jb.PseudoPolynomial(jnp.array([2.0 + 1e-9, 4.0, 5.0]))  # valid: > max(n, 2) = 2
    with pytest.warns(UserWarning, match=r"gammas\[0\] = 2\.000000001 is 1e-09 above its lower bound max\(n, 2\) = 2"):
        with pytest.raises(_Reached):
            jb.optimise_command(jb.BeltPlatform(), cmd, progress=False)
    close = jb.PseudoPolynomial(jnp.array([3.0, 3.0015, 5.0]))
    with pytest.warns(UserWarning, match=r"differ by 0\.0015, less than twice the least gap"):
        with pytest.raises(_Reached):
            jb.optimise_command(jb.BeltPlatform(), close, progress=False)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the paper's exponents: no word
        with pytest.raises(_Reached):
            jb.optimise_command(jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])), progress=False)


# --- 5. best_residual / shortest_move_time: move times no command can meet -------------------------------------
AXIS = jb.ModalAxis([7.3, 18.0], [0.015, 0.01])


@pytest.fixture(scope="module")
def design():
    """A design's data without its solve (the checks read only the problem and the options): distance 0.1 m,
    v_max 0.3 m/s, a_max 1.2 m/s², whose time-optimal move takes 0.1/0.3 + 0.3/1.2 = 0.5833 s."""
    from jaxbelt.shaping import design as dsg

    opts = dsg.default_options(AXIS.frequencies, 0.8, 0.2, False)
    prob = dsg.make_problem(AXIS, 0.1, 0.8, 0.3, 1.2, None, 0.2, np.ones(2), opts)
    nan = jnp.asarray(np.nan)
    return dsg.MinimaxDesign(
        command=jb.trapezoid_move(0.1, 0.8, 0.3, 1.2),
        worst=nan,
        fine_worst=nan,
        lower_bound=nan,
        lp=None,
        problem=prob,
        rounds=0,
        options=opts,
    )


@pytest.mark.parametrize("T", [0.5, 0.0, -0.8, float("nan")])
def test_best_residual_refuses_infeasible_move_times_at_the_call(design, T):
    with count_compiles() as box, pytest.raises(ValueError) as e:
        jb.best_residual(AXIS, T, design)
    line = first_line(e)
    assert line.startswith("best_residual: parameter `move_time`"), line
    assert "0.583333 s" in line
    assert box["n"] == 0, box  # refused at the call: nothing compiled


def test_best_residual_refuses_a_move_time_the_designs_spline_cannot_meet(design):
    # above the time-optimal move (0.5833 s) but too short for a smooth spline: the LP is infeasible there and
    # its value was 1.9e5 (a "worst residual" of 19 million %)
    with pytest.raises(ValueError, match=r"`move_time` = 0\.5834 s is too short for the design's command"):
        jb.best_residual(AXIS, 0.5834, design)


def test_best_residual_and_shortest_move_time_refuse_a_missing_design(design):
    for call in (lambda: jb.best_residual(AXIS, 0.8, None), lambda: jb.shortest_move_time(AXIS, 0.01, None)):
        with pytest.raises(ValueError, match=r"parameter `design` must be a solved minimax design .* got NoneType"):
            call()
    with pytest.raises(ValueError, match=r"parameter `target` .* > 0; got -1"):
        jb.shortest_move_time(AXIS, -1.0, design)
    with pytest.raises(ValueError, match=r"parameter `bracket` \(lower end of the bracket\) = 0\.5 s is shorter"):
        jb.shortest_move_time(AXIS, 0.01, design, bracket=(0.5, 1.0))
    with pytest.raises(ValueError, match=r"parameter `bracket` must be \(lo, hi\) with 0 < lo < hi"):
        jb.shortest_move_time(AXIS, 0.01, design, bracket=(1.0, 0.7))


# --- 6. a mode far outside the move's bandwidth ---------------------------------------------------------------
def test_minimax_problem_warns_of_a_mode_far_outside_the_bandwidth():
    from jaxbelt.shaping import design as dsg
    from jaxbelt.shaping.residual import reference_residuals

    axis = jb.ModalAxis([7.3, 1e6], [0.015, 0.01])  # was: "not converged (gap nan)" after 70 s
    ref, _ = reference_residuals(axis, 0.1, 0.3, 1.2, None, 0.2)
    opts = dsg.default_options([7.3], 0.8, 0.2, False)
    with pytest.warns(UserWarning, match=r"mode 2 \(1e\+06 Hz.* far outside the move's bandwidth.*Drop the mode"):
        dsg.make_problem(axis, 0.1, 0.8, 0.3, 1.2, None, 0.2, ref, opts)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a 300 Hz mode is within reach: no word
        near = jb.ModalAxis([7.3, 300.0], [0.015, 0.01])
        ref, _ = reference_residuals(near, 0.1, 0.3, 1.2, None, 0.2)
        dsg.make_problem(near, 0.1, 0.8, 0.3, 1.2, None, 0.2, ref, opts)


# --- 7. the hostile probe's findings (benchmarks/hostile_probe.py), one test each -------------------------------
def test_simulate_names_a_scene_of_the_wrong_type_and_refuses_non_bool_switches():
    scene = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=TS)
    with count_compiles() as box:
        with pytest.raises(TypeError, match=r"simulate: parameter `scene` must be a jaxbelt.Scene; got str"):
            jb.simulate("scene")
        for name in ("throw", "progress"):  # "no" was read as True
            with pytest.raises(TypeError, match=rf"simulate: parameter `{name}` must be True or False; got 'no'"):
                jb.simulate(scene, **{name: "no"})
    assert box["n"] == 0


def test_closed_form_refuses_a_span_beyond_its_accuracy():
    # the start-up's current at t = 1e12 s was 17.7 A instead of its steady 14.93 A (the rounding of the rigid-body
    # eigenvalue 0 grows as e^(1e-12 t)), and -347 A at 1e14 s, without a flag
    from references import startup_reference

    long = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=jnp.linspace(0.0, 1e12, 31))
    with pytest.raises(
        jb.SolveError, match=r"eps \* \|\|A\|\|_1 \* \(t_last - t0\) = 12 > 1e-06.*`ts` spanning at most"
    ):
        jb.simulate(long)
    assert not bool(jb.simulate(long, throw=False).success)
    batch = jb.Scene(
        jb.BeltStartup(), jb.ExponentialVoltage(24.0, jnp.array([0.02, 0.04])), ts=jnp.linspace(0.0, 1e12, 31)
    )
    assert not np.any(np.asarray(jb.simulate(batch, throw=False).success))  # the batched closed form too
    # within the span: the steady state of the independent reference (scipy's expm at 10 s)
    ok = jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=jnp.linspace(0.0, 1e4, 31)))
    ref = startup_reference(jb.BeltStartup(), [0.0, 10.0], 24.0, 0.02)[-1]
    np.testing.assert_allclose(np.asarray(ok.ys[-1, 2:]), ref[2:], rtol=1e-6)


def test_sweep_names_a_function_that_is_not_callable_and_an_empty_batch():
    with pytest.raises(TypeError, match=r"sweep: parameter `fn` must be a function"):
        jb.sweep("f", {"k": jnp.ones(2)})
    with pytest.raises(ValueError, match=r"sweep: parameter `params` must hold at least one element"):
        jb.sweep(lambda p: p["k"], {"k": jnp.ones(0)})


def test_optimise_command_refuses_its_loop_options_by_name_before_working(monkeypatch):
    import jaxbelt.optimise.command as oc

    monkeypatch.setattr(oc, "_run", _fail)
    plat, cmd = jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
    cases = [
        (dict(optimizer="sgd!"), ValueError, "optimizer"),  # was: "optimiser name must be ..." (no argument named)
        (dict(optimizer=3), TypeError, "optimizer"),
        (dict(tol=float("nan")), ValueError, "tol"),  # was: run to max_steps, converged=False
        (dict(gtol=-1.0), ValueError, "gtol"),
        (dict(max_steps=2.5), ValueError, "max_steps"),
        (dict(progress="yes"), TypeError, "progress"),
    ]
    with count_compiles() as box:
        for kw, error, name in cases:
            for call in (jb.optimise_command, jb.optimise_robust):
                with pytest.raises(error, match=rf"{call.__name__}: parameter `{name}`"):
                    call(plat, cmd, **({"progress": False} | kw))
    assert box["n"] == 0


def test_identify_names_the_non_finite_start_value():
    with pytest.raises(
        ValueError,
        match=r"identify: parameter `params0\['a'\]` must be finite \(the initial values must be finite\); got nan",
    ):
        jb.identify(lambda p: p["a"] * jnp.arange(1.0, 4.0), {"a": float("nan")}, np.ones(3), 1.0)


def test_fluctuation_index_of_a_successful_solution_with_nan_speeds_is_refused():
    # was: NaN, no error, no flag
    ts = np.linspace(0.0, 1.0, 101)
    speed = 30.0 + np.sin(20.0 * ts)
    speed[50] = np.nan

    def sol(success):
        return jb.Solution(
            ts=jnp.asarray(ts),
            ys=None,
            outputs={"motor_speed": jnp.asarray(speed)},
            success=jnp.array(success),
            stats={},
        )

    with pytest.raises(ValueError, match=r"parameter `sol` holds a non-finite motor speed .* t = 0.5 s, sample 50"):
        jb.fluctuation_index(sol(True))
    assert np.isnan(float(jb.fluctuation_index(sol(False))))  # a failed run: NaN, its flag says why
    # a NaN outside the window is not read (it was: the time mean's zero weight times NaN)
    ok = speed[60:]
    expected = (ok.max() - ok.min()) / (np.trapezoid(ok, ts[60:]) / 0.4)
    assert float(jb.fluctuation_index(sol(True), 0.6, 1.0)) == pytest.approx(expected, rel=1e-12)


def test_residual_energy_refuses_a_move_no_rule_of_its_nodes_resolves_before_its_program(monkeypatch):
    import jaxbelt.objectives.residual as res

    monkeypatch.setattr(res, "_residual_energy_jit", _fail)  # was: refused after compiling and running the rule
    move = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]), duration=1e3)  # omega_d T = 31166 rad
    with pytest.raises(ValueError, match=r"more half periods than the rule's 128 nodes\); pass `method='ode'`"):
        jb.residual_energy(jb.BeltPlatform(), move)


def test_steady_state_options_refused_by_name_before_compiling():
    belt = jb.NonlinearBelt()
    with pytest.raises(ValueError, match=r"`min_periods` must be <= `max_periods`.*min_periods=10, max_periods=5"):
        jb.speed_sweep(belt, [8.0], min_periods=10, max_periods=5)  # was: SteadyStateError after the sweep
    with count_compiles() as box:
        with pytest.raises(ValueError, match=r"`min_periods` must be <= `max_periods`"):
            jb.nonlinear_steady_state(belt, 8.0, min_periods=10, max_periods=5)
        with pytest.raises(ValueError, match=r"parameter `rtol` must be finite and >= 0"):
            jb.nonlinear_steady_state(belt, 8.0, rtol=-1e-4)
        with pytest.raises(ValueError, match=r"`rtol` and `atol` must not both be 0"):
            jb.speed_sweep(belt, [8.0], rtol=0.0, atol=0.0)
    assert box["n"] == 0


def test_a_minimax_design_that_does_not_converge_says_which_solver_stopped_and_what_to_try(monkeypatch):
    """The note of a non-converged minimax row names the LP solver, its iterations and residuals, and the arguments
    to change (the solver's own outcome, made to fail here by declaring no design converged)."""
    from jaxbelt.shaping import design as dsg

    monkeypatch.setattr(dsg.MinimaxDesign, "converged", property(lambda self: False))
    plan = jb.design_move(jb.ModalAxis([5.5], [0.02]), 0.1, 1.0, v_max=0.3, a_max=1.2, include=("minimax", "ZV"))
    row = plan.candidate("minimax")
    assert not row.ok and plan.best.name == "ZV"
    assert re.match(
        r"not converged \(gap .*; the LP's interior-point solver stopped after \d+ iterations, primal residual .*, "
        r"dual .*\): try a longer `move_time` or `smooth=False`",  # far modes: design_move leaves them out itself
        row.note,
    ), row.note
