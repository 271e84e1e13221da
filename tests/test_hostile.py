"""Hostile inputs, one by one: what a user who tries to break jaxbelt meets at every public entry point.

Each case below was found by probing `jaxbelt.__all__` and every CLI sub-command with bad values, shapes
and types (the probe of the "Reliability round 3" issue). The contract (docs/errors.md):

- bad arguments are refused **before anything is traced or compiled**, with a `ValueError`/`TypeError`
  that names the parameter, its valid range and the value (checked here by the message, and for the
  functions that run a compiled program by replacing that program with one that fails the test);
- a check that can only run inside a compiled program (a model built by the user's `predict`) raises
  with the parameter first, not JAX's stack;
- an infeasible or degenerate request is flagged on its result (`status`, `message`) and warned about;
  a failure says why (NaN in the model, the step limit, a bound) and what to do.

Known failures in modules other engineers own are pinned as `xfail(strict=True)` at the end: each reason
names the module and the fix (a strict xfail fails the suite once the bug is fixed, so the pin is removed
with it).
"""

import math
import re
import types
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxbelt as jb

nan, inf = math.nan, math.inf
RUNTIME = (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, ValueError)


def named(name):
    return re.escape(f"`{name}`")


def _sol(speed, ts=None):
    """A `Solution` holding a motor speed record (no simulation needed)."""
    speed = np.asarray(speed, dtype=float)
    ts = np.linspace(0.0, 1.0, speed.shape[-1]) if ts is None else ts
    return jb.Solution(
        ts=jnp.asarray(ts), ys=None, outputs={"motor_speed": jnp.asarray(speed)}, success=jnp.array(True), stats={}
    )


PP = jb.PseudoPolynomial([3.0, 4.0, 5.0])
SOL = _sol(30.0 + np.sin(np.linspace(0.0, 20.0, 101)))

# =====================================================================================
# 1. Refused at the call, naming the parameter: (id, call, exception, the name in the message)
# =====================================================================================

REFUSED = [
    # parameters of the wrong type: refused by name, not by JAX's conversion (or silently cast)
    ("model-str", lambda: jb.FourBarDrive(a="x"), TypeError, "a"),
    ("model-complex", lambda: jb.FourBarDrive(a=1 + 1j), TypeError, "a"),
    ("model-bool", lambda: jb.FourBarDrive(a=True), TypeError, "a"),
    ("model-None", lambda: jb.FourBarDrive(a=None), TypeError, "a"),
    ("model-bool-array", lambda: jb.BeltStartup(k=np.array([True])), TypeError, "k"),
    ("model-complex-tuple", lambda: jb.NonlinearBelt(runout=(1e-3, 2e-3j)), TypeError, "runout"),
    ("command-str", lambda: jb.PseudoPolynomial("abc"), TypeError, "gammas"),
    ("optional-str", lambda: jb.PID(v_limit="a"), TypeError, "v_limit"),
    # a time constant below the closed form's accuracy (5 % off at 1e-15 s before)
    ("gamma-tiny", lambda: jb.ExponentialVoltage(24.0, 1e-9), ValueError, "gamma"),
    ("shaped-base", lambda: jb.ShapedCommand(jb.ConstantVoltage(1.0), [0.0], [1.0]), TypeError, "base"),
    # the fluctuation index
    ("chi-sol", lambda: jb.fluctuation_index(np.ones(10), 0.1, 0.2), TypeError, "sol"),
    ("chi-smooth", lambda: jb.fluctuation_index(SOL, 0.1, 0.2, smooth="yes"), TypeError, "smooth"),
    ("chi-t0-array", lambda: jb.fluctuation_index(SOL, np.array([0.1, 0.2]), 0.3), ValueError, "t0"),
    (
        "chi-temperature",
        lambda: jb.fluctuation_index(SOL, 0.1, 0.2, smooth=True, temperature=1e9),
        ValueError,
        "temperature",
    ),
    ("chi-average", lambda: jb.fluctuation_index(SOL, average=3), ValueError, "average"),
    # the residual energy: a rule of 10^7 nodes asked for 728 TiB
    ("H-n_nodes", lambda: jb.residual_energy(jb.BeltPlatform(), PP, n_nodes=10**7), ValueError, "n_nodes"),
    # the backbone of the non-linear belt returned NaN or negative frequencies
    ("backbone-v", lambda: jb.backbone_frequency(nan, 1e-3, 50.0), ValueError, "v"),
    ("backbone-v-super", lambda: jb.backbone_frequency(1.5, 1e-3, 50.0), ValueError, "v"),
    ("backbone-a", lambda: jb.backbone_frequency(0.2, -1e-3, 50.0), ValueError, "a"),
    ("backbone-v_l", lambda: jb.backbone_frequency(0.2, 1e-3, -1.0), ValueError, "v_l"),
    ("backbone-n", lambda: jb.backbone_frequency(0.2, 1e-3, 50.0, n=0), ValueError, "n"),
    # calibrate
    ("calibrate-belt", lambda: jb.calibrate(jb.RunoutRig()), TypeError, "belt"),
    ("calibrate-free-str", lambda: jb.calibrate(free="damping"), ValueError, "free"),
    ("calibrate-free-empty", lambda: jb.calibrate(free=()), ValueError, "free"),
    ("calibrate-free-twice", lambda: jb.calibrate(free=("damping", "damping")), ValueError, "free"),
    ("calibrate-log-of-0", lambda: jb.calibrate(jb.NonlinearBelt(v_l=0.0), free=("v_l",)), ValueError, "v_l"),
    ("calibrate-supercritical", lambda: jb.calibrate(jb.NonlinearBelt(wave_speed=15.0)), ValueError, "wave_speed"),
    ("calibrate-amplitudes", lambda: jb.calibrate(amplitudes="yes"), TypeError, "amplitudes"),
    # speed ramps of the non-linear belt
    ("ramp-belt", lambda: jb.speed_ramp(jb.RunoutRig(), 8.0, 9.0, 1.0), TypeError, "belt"),
    (
        "ramp-samples",
        lambda: jb.speed_ramp(jb.NonlinearBelt(), 8.0, 9.0, 1.0, samples_per_period=1),
        ValueError,
        "samples_per_period",
    ),
    ("ramp-z0", lambda: jb.speed_ramp(jb.NonlinearBelt(), 8.0, 9.0, 1.0, z0=np.ones(3)), ValueError, "z0"),
    ("ramp-hold", lambda: jb.speed_ramp(jb.NonlinearBelt(), 8.0, 9.0, 1.0, hold=nan), ValueError, "hold"),
    ("ramp-huge", lambda: jb.speed_ramp(jb.NonlinearBelt(), 8.0, 9.0, 1e9), ValueError, "speed_ramp"),
    ("ramp-rtol", lambda: jb.speed_ramp(jb.NonlinearBelt(), 8.0, 9.0, 1.0, rtol=-1.0), ValueError, "rtol"),
    # steady states, trajectories and response curves of the non-linear belt (a wrong z0 was named nowhere, a
    # speed array failed in JAX's broadcasting, periods=0 raised IndexError, 3 speeds 'too many values to unpack')
    ("steady-z0", lambda: jb.nonlinear_steady_state(jb.NonlinearBelt(), 8.0, z0=np.ones(3)), ValueError, "z0"),
    ("steady-speed-array", lambda: jb.nonlinear_steady_state(jb.NonlinearBelt(), np.full(3, 8.0)), ValueError, "speed"),
    (
        "steady-max_periods",
        lambda: jb.nonlinear_steady_state(jb.NonlinearBelt(), 8.0, max_periods=2.5),
        ValueError,
        "max_periods",
    ),
    ("basins-z0s", lambda: jb.nonlinear_basins(jb.NonlinearBelt(), 8.0, np.ones((2, 3))), ValueError, "z0s"),
    (
        "basins-speed-array",
        lambda: jb.nonlinear_basins(jb.NonlinearBelt(), np.full(2, 8.0), np.zeros((1, 2))),
        ValueError,
        "speed",
    ),
    ("sweep-speeds-super", lambda: jb.nonlinear_sweep(jb.NonlinearBelt(), [8.0, 50.0]), ValueError, "speeds"),
    ("trajectory-periods", lambda: jb.nonlinear_trajectory(jb.NonlinearBelt(), 8.0, periods=0), ValueError, "periods"),
    (
        "trajectory-steps",
        lambda: jb.nonlinear_trajectory(jb.NonlinearBelt(), 8.0, steps_per_period=0),
        ValueError,
        "steps_per_period",
    ),
    ("trajectory-speed-array", lambda: jb.nonlinear_trajectory(jb.NonlinearBelt(), [8.0, 9.0]), ValueError, "speed"),
    ("curve-range-3", lambda: jb.response_curve(jb.NonlinearBelt(), (7.5, 8.0, 9.0)), ValueError, "speed_range"),
    ("curve-range-super", lambda: jb.response_curve(jb.NonlinearBelt(), (7.5, 50.0)), ValueError, "speed_range"),
    ("folds-range-str", lambda: jb.fold_speeds(jb.NonlinearBelt(), ("a", "b")), TypeError, "speed_range"),
    # scenes: a bare string was read as one name, complex times lost their imaginary part, text failed in NumPy
    (
        "scene-observe-str",
        lambda: jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=np.linspace(0.0, 1.0, 3), observe="current"),
        TypeError,
        "observe",
    ),
    (
        "scene-ts-complex",
        lambda: jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=np.linspace(0.0, 1.0, 3) + 1j),
        TypeError,
        "ts",
    ),
    ("scene-ts-str", lambda: jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts="abc"), TypeError, "ts"),
    # the papers' runs: a fractional number of points was truncated (1.5 -> a 1-sample record)
    ("startup_curves-n_points", lambda: jb.startup_curves(n_points=1.5), ValueError, "n_points"),
    ("fig4-n", lambda: jb.simulate_fig4(n=1.5), ValueError, "n"),
    ("platform-n", lambda: jb.platform_response(jb.BeltPlatform(), PP, n=1), ValueError, "n"),
]


@pytest.mark.parametrize("call, error, name", [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_refused_at_the_call_naming_the_parameter(call, error, name):
    with pytest.raises(error, match=named(name) if name != "speed_ramp" else "speed_ramp: the record would hold"):
        call()


# --- identify: arguments, failures with their reason ------------------------------------------------------


def _line(p):
    return p["a"] * jnp.arange(1.0, 4.0)


@pytest.mark.parametrize(
    "kw, error, name",
    [
        (dict(predict=3.0), TypeError, "predict"),
        (dict(params0={"a": np.ones(2)}), ValueError, "params0['a']"),
        (dict(params0={"a": "x"}), ValueError, "params0['a']"),
        (dict(params0={1: 1.0}), TypeError, "params0"),
        (dict(data="abc"), ValueError, "data"),
        (dict(data=np.ones(3) * (1 + 1j)), ValueError, "data"),
        (dict(sigma=np.ones(4)), ValueError, "sigma"),
    ],
)
def test_identify_refuses_bad_arguments_by_name(kw, error, name):
    args = dict(predict=_line, params0={"a": 1.0}, data=np.ones(3), sigma=1.0) | kw
    with pytest.raises(error, match=named(name)):
        jb.identify(args.pop("predict"), args.pop("params0"), args.pop("data"), args.pop("sigma"))


def test_identify_on_a_model_returning_nan_says_so_not_convergence():
    # was: "the LM solver did not converge in 1 steps"
    with pytest.raises(
        RuntimeError,
        match=r"non-finite values .* at the start values, parameters .*: NaN in the model, not a convergence problem",
    ):
        jb.identify(lambda p: p["a"] * jnp.full(3, jnp.nan), {"a": 1.0}, np.ones(3), 1.0)


def test_identify_at_its_step_limit_says_so_and_what_to_do():
    with pytest.raises(RuntimeError, match=r"step limit max_steps=1 .* raise `max_steps`"):
        jb.identify(
            lambda p: jnp.exp(p["a"]) * jnp.arange(1.0, 4.0), {"a": 1.0}, np.array([1e3, 2e3, 3e3]), 1.0, max_steps=1
        )


def test_identify_invalid_start_inside_predict_leads_with_the_parameter():
    # a negative start value builds an invalid model inside the compiled fit: was "Above is the stack
    # outside of JIT" after the compilation; now the check's message first, then where it happened
    def predict(p):
        return jb.MovingString(tension=p["T"]).natural_frequencies(0.0, 2)

    with pytest.raises(ValueError) as e:
        jb.identify(predict, {"T": -140.0}, np.array([300.0, 600.0]), 1.0)
    first = str(e.value).splitlines()[0]
    assert first.startswith("identify: MovingString: parameter `tension` must lie in [0.001, 1e+07] N"), first
    assert "start values {'T': -140.0}" in first and "Above is the stack" not in str(e.value)


# --- tune_pid: every argument before the compiled step; infeasible bounds warned and flagged ----------------


class _Traced(Exception):
    """Raised by the stand-in of `tune_pid`'s compiled step: reaching it means nothing refused the call."""


@pytest.fixture
def no_tuning(monkeypatch):
    import jaxbelt.optimise.pid as pid_module

    def fail(*args, **kwargs):
        raise _Traced

    monkeypatch.setattr(pid_module, "_tune_step", fail)


@pytest.mark.parametrize(
    "kw, error, name",
    [
        (dict(rtol=-1.0), ValueError, "rtol"),  # was: a run-time error after a 17 s compilation
        (dict(atol=nan), ValueError, "atol"),
        (dict(steps=2.5), ValueError, "steps"),
        (dict(steps=0), ValueError, "steps"),
        (dict(pid=jb.ConstantVoltage(3.0)), TypeError, "pid"),
        (dict(drive=jb.BeltStartup()), TypeError, "drive"),
        (dict(t0=0.4, t1=0.4001), ValueError, "window"),
        (dict(t0=nan), ValueError, "t0"),
        (dict(t1=np.array([0.4, 0.5])), ValueError, "t1"),
        (dict(method="auto"), ValueError, "method"),
        (dict(optimizer="adam"), TypeError, "optimizer"),
        (dict(learning_rate=-0.1), ValueError, "learning_rate"),
        (dict(temperature=2.0), ValueError, "temperature"),
        (dict(method="rk4", dt=-1e-3), ValueError, "dt"),
        (dict(v_max=0.0), ValueError, "v_max"),
        (dict(penalty=-1.0), ValueError, "penalty"),
    ],
)
def test_tune_pid_refuses_before_anything_is_traced(no_tuning, kw, error, name):
    args = dict(drive=jb.FourBarDrive(), pid=jb.PID()) | kw
    with pytest.raises(error, match=named(name) if name != "window" else "window"):
        jb.tune_pid(args.pop("drive"), args.pop("pid"), progress=False, **args)


@pytest.mark.parametrize("kw", [dict(v_max=5.0), dict(pid=jb.PID(v_limit=5.0))])
def test_tune_pid_warns_of_a_voltage_bound_below_the_back_emf_before_working(no_tuning, kw):
    args = dict(pid=jb.PID()) | kw
    with pytest.warns(RuntimeWarning, match=r"below the back-emf at the set point, k_m \* omega_ref = 0.48 \* 30"):
        with pytest.raises(_Traced):
            jb.tune_pid(jb.FourBarDrive(), args.pop("pid"), progress=False, **args)


def test_tune_pid_status_says_what_was_not_met_and_why():
    from jaxbelt.optimise.pid import _tune_status

    good = {"v_peak": 30.0, "i_peak": 10.0, "mean_speed": 30.1, "chi": 0.02}
    assert _tune_status(jb.PID(), good, good, None, None, 3, 5) == ("ok", "")
    bad = good | {"v_peak": 33.7, "mean_speed": 0.3}
    status, message = _tune_status(jb.PID(v_limit=1.0), bad, good, 5.0, None, 0, 5)
    assert status == "v_max not met; set point not held; no improvement"
    assert "33.7 V exceeds v_max = 5 V" in message and "mean motor speed over the window is 0.3 rad/s" in message
    assert "v_limit = 1 V" in message and "lower `learning_rate`" in message


# --- calibrate: a fit that does not converge says why ------------------------------------------------------


def test_calibrate_failure_message_names_the_cause():
    from jaxbelt.models.nonlinear.calibration import _failure

    stop = types.SimpleNamespace(result=optx.RESULTS.max_steps_reached, stats={"num_steps": 3})
    msg = _failure(stop, np.ones(4), np.array([8.6, 8.9, 15.6, 16.1]), 3, ("wave_speed",))
    assert "step limit max_steps=3" in msg and "raise `max_steps`" in msg
    msg = _failure(stop, np.ones(4), np.array([nan, 8.9, 15.6, 16.1]), 3, ("wave_speed",))
    assert "no first-mode lower fold" in msg and "Start nearer" in msg


# --- the fluctuation index of a drive that does not run ------------------------------------------------------


def test_fluctuation_index_warns_when_the_speed_changes_sign_in_the_window():
    # a drive at rest (the four-bar at 0 V after 10 s: speeds of +-4e-6 rad/s) gave chi = 13.7, no word
    standing = _sol(1e-6 * np.sin(np.linspace(0.0, 30.0, 201)))
    with pytest.warns(RuntimeWarning, match=r"motor speed changes sign inside the window .* reverses or stands"):
        chi = float(jb.fluctuation_index(standing))
    assert chi > 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jb.fluctuation_index(SOL)  # runs one way: no warning
        jb.fluctuation_index(_sol(np.linspace(0.0, 30.0, 101)))  # from rest: runs one way
        jb.fluctuation_index(_sol(-30.0 - np.sin(np.linspace(0.0, 20.0, 101))))  # backwards: one way


def test_fluctuation_objective_checks_the_window_before_simulating(monkeypatch):
    import jaxbelt.objectives.fluctuation as fl

    def fail(*args, **kwargs):
        raise _Traced

    monkeypatch.setattr(fl, "_run_from_rest", fail)
    drive, pid = jb.FourBarDrive(), jb.PID()
    for call in (
        lambda: jb.fluctuation_objective(drive, pid, 0.4, 0.40001),
        lambda: fl.closed_loop_metrics(drive, pid, 0.4, 0.40001),
    ):
        with pytest.raises(ValueError, match=r"window \[t0, t1\] must contain at least two output times; .* holds 1"):
            call()
    for kw, name in ((dict(dt_save=np.ones(2)), "dt_save"), (dict(peak_temperature=-1.0), "peak_temperature")):
        with pytest.raises(ValueError, match=named(name)):
            jb.fluctuation_objective(drive, pid, **kw)
    with pytest.raises(TypeError, match=named("smooth")):
        jb.fluctuation_objective(drive, pid, smooth="no")


# --- an invalid element of a vmapped non-linear sweep is NaN, never a number --------------------------------


def test_nonlinear_modal_system_of_an_invalid_traced_belt_is_nan():
    # a vmapped speed_sweep over damping ratios returned finite amplitudes for damping = 1.5
    damping = jnp.array([0.01, 1.5, -0.1, nan])
    sys = jax.jit(jax.vmap(lambda d: jb.NonlinearBelt(damping=d).modal(8.0)))(damping)
    for leaf in jax.tree_util.tree_leaves(sys):
        leaf = np.asarray(leaf)
        if np.issubdtype(leaf.dtype, np.floating) and leaf.ndim:
            assert np.all(np.isfinite(leaf[0])) and np.all(np.isnan(leaf[1:]))
    ref = jb.NonlinearBelt(damping=0.01).modal(8.0)
    np.testing.assert_array_equal(np.asarray(sys.omega[0]), np.asarray(ref.omega))


@pytest.mark.slow
def test_vmapped_speed_sweep_with_an_invalid_damping_is_nan():
    damping = jnp.array([0.01, 1.5])
    pp = jax.vmap(lambda d: jb.speed_sweep(jb.NonlinearBelt(damping=d), jnp.array([8.0]), throw=False, max_periods=40))(
        damping
    )
    pp = np.asarray(pp)
    assert np.all(np.isfinite(pp[0])) and np.all(np.isnan(pp[1]))


# --- the CLI: errors of a computation in one line --------------------------------------------------------------


def test_cli_reports_a_failed_computation_in_one_line(monkeypatch, capsys, tmp_path):
    import jaxbelt.runs
    from jaxbelt.cli import main

    def failing(*args, **kwargs):
        raise jb.SolveError("simulate failed for the scene BeltStartup driven by ExponentialVoltage (method='rk4').")

    monkeypatch.setattr(jaxbelt.runs, "startup_curves", failing)
    assert main(["--no-cache", "startup", "--out", str(tmp_path / "s.png")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "jaxbelt startup: error: simulate failed for the scene BeltStartup driven by ExponentialVoltage (method='rk4')."
    ]


def test_cli_failure_of_a_check_inside_a_program_is_its_message():
    from jaxbelt.cli import _failure

    f = jax.jit(lambda k: jb.MovingString(tension=k).natural_frequencies(0.0, 1))
    with pytest.raises(RUNTIME) as e:
        jax.block_until_ready(f(-1.0))
    message, code = _failure(e.value)
    assert code == 1 and message == "MovingString: parameter `tension` must lie in [0.001, 1e+07] N"
    assert _failure(KeyError("x")) is None  # a bug keeps its traceback


def test_solve_error_says_which_cause_and_the_time_reached():
    scene = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=jnp.linspace(0.0, 0.5, 11))
    with pytest.raises(jb.SolveError, match=r"max_steps.*reached.* t = "):
        jb.simulate(scene, "ode", max_steps=10)
    ok = jb.simulate(scene, "ode")
    assert int(ok.stats["result"]) == 0 and float(ok.stats["t_final"]) == 0.5
    # a scene that saves its final state knows where the solve stopped
    final = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), t1=0.5)
    with pytest.raises(jb.SolveError, match=r"`max_steps` = 10 was reached at t = "):
        jb.simulate(final, "ode", max_steps=10)
    sol = jb.simulate(final, "ode", max_steps=10, throw=False)
    assert int(sol.stats["result"]) == 1 and 0.0 < float(sol.stats["t_final"]) < 0.5
    # RK4: a budget that cannot cover the span is refused at the call (steps needed against max_steps, the dt that
    # fits), not blamed on the step's stability; an unstable step is
    with pytest.raises(ValueError, match=r"`dt` = 0\.0001 s \(RK4 step\) needs 5e\+03 steps .* `max_steps` = 10") as e:
        jb.simulate(scene, "rk4", max_steps=10)
    assert "stability" not in str(e.value) and "dt` >= 0.05 s" in str(e.value)
    with pytest.raises(jb.SolveError, match=r"RK4 step dt = 1 s is too large .*spectral radius"):
        jb.simulate(scene, "rk4", dt=1.0)
    # under jit the message is fixed when the program is traced: the possible causes
    f = jax.jit(
        lambda g: (
            jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, g), ts=scene.ts), "ode", max_steps=10).ys
        )
    )
    with pytest.raises(RUNTIME, match="max_steps"):
        jax.block_until_ready(f(0.02))


# =====================================================================================
# 2. Known failures in modules owned elsewhere (strict xfail: remove the pin with the fix)
# =====================================================================================


def _xfail(reason):
    return pytest.mark.xfail(strict=True, reason=reason)


def test_design_move_include_named():
    with pytest.raises(ValueError, match=named("include")):
        jb.design_move(jb.ModalAxis([10.0], [0.01]), 0.1, v_max=1.0, a_max=10.0, include=("foo",))


def test_fastest_move_distance_named():
    with pytest.raises(ValueError, match=named("distance")):
        jb.fastest_move(nan, 1.0, 10.0)
