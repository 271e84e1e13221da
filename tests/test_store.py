"""The program store (`enable_compilation_cache(programs=True)`): a later process calls jaxbelt's stored
programs without tracing them, with the results of the traced path, and never for code jaxbelt cannot
fingerprint."""

import contextlib
import json
import math
import os
import subprocess
import sys
import threading
import types
from pathlib import Path

import equinox as eqx
import jax
import jax.monitoring
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt import _compat, _store, solve
from jaxbelt._guard import error_if, host_checked
from jaxbelt.cache import disable_compilation_cache

#: Programs are written to the store only on the releases `jaxbelt._compat` was written for: elsewhere (a newer JAX,
#: equinox or scipy, or `JAXBELT_PRIVATE_APIS=0`) a checked program's error and diffrax's own checks cannot be
#: written, so those programs are traced in each process, as without the store; tests/test_compat.py checks that
#: both paths give the same results
stored_programs = pytest.mark.skipif(
    not _compat.private_apis(), reason="programs are stored only where jaxbelt._compat's private layouts are known"
)

ROOT = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def store_in(folder):
    jb.enable_compilation_cache(folder)
    try:
        yield folder / "jaxbelt-programs"
    finally:
        disable_compilation_cache()


def _programs(folder):
    return sorted(folder.glob("*.jaxbelt-program"))


def _same(sol, ref):
    """Two results with the same structure and values equal to rounding (the same XLA program)."""
    assert jax.tree_util.tree_structure(sol) == jax.tree_util.tree_structure(ref)
    for a, b in zip(jax.tree_util.tree_leaves(sol), jax.tree_util.tree_leaves(ref)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=0)


def _fourbar_scene(n=41, **kw):
    return jb.Scene(
        jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0), ts=jnp.linspace(0.0, 0.2, n), **kw
    )


@stored_programs
def test_stored_simulation_is_the_traced_one_and_loads_untraced(tmp_path):
    scene = _fourbar_scene()
    reference = jb.simulate(scene)  # the traced path (store off)
    with store_in(tmp_path / "xla") as folder:
        first = jb.simulate(scene)  # exported, written, run
        assert len(_programs(folder)) == 1
        _store.forget()  # as in a new process: the program comes from the file
        traces = eqx.debug.get_num_traces(solve._run_traced)
        second = jb.simulate(_fourbar_scene())
        assert eqx.debug.get_num_traces(solve._run_traced) == traces  # not traced again
    for sol in (first, second):
        # times, states, outputs, success and solver statistics: equal to rounding (the same XLA program)
        _same(sol, reference)
        assert bool(sol.success)


def _startup_scene(n=21, gamma=0.04, **kw):
    return jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, gamma), ts=jnp.linspace(0.0, 0.3, n), **kw)


@stored_programs
def test_new_values_reuse_the_stored_program_and_new_structure_gets_its_own(tmp_path):
    # new parameter values and times of the same shapes: the same program
    same = jb.Scene(jb.BeltStartup(k=2.0e5), jb.ExponentialVoltage(20.0, 0.02), ts=jnp.linspace(0.0, 0.5, 21))
    # another grid length, another observed set, another method: new programs
    calls = [
        (same, {}),
        (_startup_scene(n=11), {}),
        (_startup_scene(observe=("current",)), {}),
        (_startup_scene(), {"method": "modal"}),
    ]
    with store_in(tmp_path / "xla") as folder:
        jb.simulate(_startup_scene())
        stored = [jb.simulate(scene, **kw) for scene, kw in calls[:1]]
        assert len(_programs(folder)) == 1
        stored += [jb.simulate(scene, **kw) for scene, kw in calls[1:]]
        assert len(_programs(folder)) == 4
    for sol, (scene, kw) in zip(stored, calls):
        _same(sol, jb.simulate(scene, **kw))


class _OwnStartup(jb.BeltStartup):
    """A user's subclass: jaxbelt cannot fingerprint its code, so it is never stored."""


def test_classes_from_outside_jaxbelt_are_never_stored(tmp_path):
    scene = jb.Scene(_OwnStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0.0, 0.3, 21))
    with store_in(tmp_path / "xla") as folder:
        sol = jb.simulate(scene)
        assert _programs(folder) == []
    _same(sol, jb.simulate(scene))


@stored_programs
def test_a_damaged_file_is_replaced(tmp_path):
    scene = _startup_scene()
    with store_in(tmp_path / "xla") as folder:
        jb.simulate(scene)
        (path,) = _programs(folder)
        path.write_bytes(b"not a program")
        _store.forget()
        sol = jb.simulate(scene)
        assert path.stat().st_size > 1000  # written again
    _same(sol, jb.simulate(scene))


@stored_programs
def test_a_stored_checked_program_still_raises_its_message(tmp_path):
    from jaxbelt.models.string import _roots  # a checked program of jaxbelt's, kept in the store

    k, c, s = (jnp.array([1.0, 2.0]) for _ in range(3))
    bad = jnp.array([jnp.nan, 1.0])  # Newton cannot converge on NaN: the program's check fails
    with store_in(tmp_path / "xla") as folder:
        good = _roots(k, c, s)
        assert len(_programs(folder)) == 1
        _store.forget()  # from the file: the check's message travels with the program
        np.testing.assert_array_equal(np.asarray(_roots(k, c, s)), np.asarray(good))
        with pytest.raises(ValueError, match="Newton's method did not converge"):
            _roots(bad, c, s)
        assert any(isinstance(e, _store._Entry) for e in _store._MEMO.values())  # ran the loaded program
    # the root of k c (1 - V^2/c^2) = s V with k = c = s: V = c (sqrt(5) - 1) / 2
    np.testing.assert_allclose(np.asarray(good), np.asarray(c) * (np.sqrt(5.0) - 1) / 2, rtol=1e-12)


def test_only_jaxbelt_functions_are_stored(tmp_path):
    own = host_checked(lambda x: jnp.sqrt(error_if(x, x < 0, "x must be >= 0")), store=True)

    def closure(x):
        return x * 2.0

    assert not _store.storable_function(own) and not _store.storable_function(closure)
    from jaxbelt.models.string import _galerkin_frequencies, _roots

    assert _store.storable_function(_roots.__wrapped__) and _store.storable_function(_galerkin_frequencies.__wrapped__)
    with store_in(tmp_path / "xla") as folder:
        assert float(own(jnp.asarray(4.0))) == 2.0
        assert _programs(folder) == []


@stored_programs
def test_belt_span_functions_through_the_store(tmp_path):
    rig, span = jb.RunoutRig(), jb.MovingString()
    speeds = jnp.linspace(1.0, 20.0, 7)

    def run():
        return (
            span.galerkin_frequencies(20.0, 8, 3),
            jb.linear_runout_response(rig, speeds, n_modes=8),
            jb.crossing_speeds(rig, n_modes=2),
        )

    reference = run()
    with store_in(tmp_path / "xla") as folder:
        run()
        assert len(_programs(folder)) == 3
        _store.forget()
        stored = run()
    _same(stored, reference)


@stored_programs
def test_nonlinear_harmonic_balance_through_the_store(tmp_path):
    # the harmonic-balance programs (one point, the continuation, the fold refinement) and a speed ramp
    # are stored like the other simulations: a later process runs them untraced
    belt = jb.NonlinearBelt(n_modes=1)

    def run():  # a ramp's simulate holds no host callback either (the speed is checked by input_checks)
        return (
            jb.harmonic_balance(belt, 7.0, 1).pp,
            jb.fold_speeds(belt, (7.5, 10.5), 1),
            jb.speed_ramp(belt, 8.0, 8.2, 0.1, z0=jnp.zeros(2)).w,
        )

    reference = run()
    with store_in(tmp_path / "xla") as folder:
        run()
        written = len(_programs(folder))
        assert written == 4
        _store.forget()
        stored = run()
        assert len(_programs(folder)) == written  # loaded, not exported again
    _same(stored, reference)
    assert np.all(np.isfinite(np.asarray(stored[1])))


@stored_programs
def test_the_key_holds_module_names_and_error_mode(monkeypatch):
    tree = jax.tree_util.tree_structure(_startup_scene())
    names = [n for n, _ in _store._describe_tree(tree)]
    assert "jaxbelt.scene.Scene" in names and "jaxbelt.models.startup.BeltStartup" in names
    assert (
        _store._describe_tree(
            jax.tree_util.tree_structure(
                jb.Scene(_OwnStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0.0, 0.3, 3))
            )
        )
        is None
    )
    before = _store.settings()
    monkeypatch.setenv("EQX_ON_ERROR", "nan")  # equinox's checks become NaNs: another program
    assert _store.settings() != before


@stored_programs
def test_programs_holding_a_host_callback_are_marked_and_traced(tmp_path):
    scene = _startup_scene(n=11)
    with store_in(tmp_path / "xla") as folder:
        sol = jb.simulate(scene, method="ode", progress=True)  # a tqdm bar: host callbacks, not exportable
        (mark,) = _programs(folder)
        with open(mark, "rb") as f:
            assert _store._Unpickler(f).load()[3] is None  # marked: not storable, nothing to load
        _store.forget()
        sol2 = jb.simulate(scene, method="ode", progress=True)
        assert _programs(folder) == [mark]
    ref = jb.simulate(scene, method="ode")
    for s in (sol, sol2):
        _same(s, ref)


def test_off_unless_the_cache_is_on(tmp_path):
    jb.enable_compilation_cache(tmp_path / "xla", programs=False)
    try:
        jb.simulate(_startup_scene(n=11))
        assert (
            not (tmp_path / "xla" / "jaxbelt-programs").exists()
            or _programs(tmp_path / "xla" / "jaxbelt-programs") == []
        )
    finally:
        disable_compilation_cache()
    assert _store.folder() is None


def _two_processes(code: str) -> list:
    """The standard output of `code` run in two fresh processes one after the other (the second finds what the
    first stored)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    outs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        outs.append(out.stdout)
    return outs


@stored_programs
def test_a_new_process_runs_the_stored_closed_form(tmp_path):
    # the start-up closed form calls LAPACK (a matrix exponential): a stored program must bind LAPACK's
    # kernels itself, since nothing is lowered in the process that loads it
    code = (
        "import jax, jax.numpy as jnp, numpy as np, equinox as eqx, jaxbelt as jb\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "from jaxbelt import solve\n"
        f"jb.enable_compilation_cache({str(tmp_path / 'xla')!r})\n"
        "sol = jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0, 0.5, 51),"
        " observe=('current',)))\n"
        "print(eqx.debug.get_num_traces(solve._run_traced), float(sol.current[-1]), float(sol.ys[-1, 3]))\n"
    )
    outs = [out.split() for out in _two_processes(code)]
    assert outs[0][0] == "1" and outs[1][0] == "0"  # traced once, then loaded
    ref = jb.simulate(
        jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0, 0.5, 51), observe=("current",))
    )
    for o in outs:
        np.testing.assert_allclose(
            [float(o[1]), float(o[2])], [float(ref.current[-1]), float(ref.ys[-1, 3])], rtol=1e-12
        )


@stored_programs
def test_minimax_design_through_the_store(tmp_path):
    # the minimax LP's round (the interior point method, the largest shaping program) is stored: a later process
    # runs it untraced and designs the same command
    axis = jb.ModalAxis([6.0], [0.02])

    def run():
        plan = jb.design_move(axis, 0.1, 0.8, v_max=0.3, a_max=1.2, include=("minimax",))
        return plan.minimax.command.coefficients, plan.minimax.worst, plan.candidate("minimax").worst_percent

    reference = run()
    with store_in(tmp_path / "xla") as folder:
        run()
        written = len(_programs(folder))
        assert written >= 1
        _store.forget()
        stored = run()
        assert len(_programs(folder)) == written  # loaded, not exported again
    for a, b in zip(stored, reference):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=0)


@stored_programs
def test_robust_pseudo_polynomial_stage_through_the_store(tmp_path, monkeypatch):
    # the L-BFGS stage of optimise_robust (jaxbelt.shaping.pseudo) is stored: a later process runs it untraced and
    # ends at the same exponents
    from jaxbelt.shaping import pseudo

    plat, cmd = jb.BeltPlatform(), jb.PseudoPolynomial(jnp.arange(5.0, 10.0))

    def run():
        res = jb.optimise_robust(plat, cmd, max_steps=40, progress=False)
        return res.gammas, res.value, res.n_steps

    reference = run()
    with store_in(tmp_path / "xla") as folder:
        run()
        written = len(_programs(folder))
        _store.forget()

        def traced(*args):
            raise AssertionError("the stage was traced, not loaded from the store")

        monkeypatch.setattr(pseudo, "_run_stage_jit", traced)
        stored = run()
        assert len(_programs(folder)) == written  # loaded, not exported again
    np.testing.assert_allclose(np.asarray(stored[0]), np.asarray(reference[0]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(float(stored[1]), float(reference[1]), rtol=1e-12, atol=0)
    assert stored[2] == reference[2]


@stored_programs
def test_a_new_process_runs_the_stored_fold_speeds_without_the_solver_libraries(tmp_path):
    # a process that loads the harmonic-balance programs from the store traces nothing, so it never imports the
    # libraries only tracing needs (optimistix, lineax; diffrax for the Floquet multipliers: a third of a second);
    # the folds are the traced ones
    code = (
        "import json, sys, jax, numpy as np, jaxbelt as jb\n"
        "jax.config.update('jax_enable_x64', True)\n"
        f"jb.enable_compilation_cache({str(tmp_path / 'xla')!r})\n"
        "v = jb.fold_speeds(jb.NonlinearBelt(n_modes=1), (7.5, 10.5), 1)\n"
        "loaded = [m for m in ('diffrax', 'optimistix', 'lineax') if m in sys.modules]\n"
        "print(json.dumps({'loaded': loaded, 'folds': np.asarray(v).tolist()}))\n"
    )
    outs = [json.loads(out.strip().splitlines()[-1]) for out in _two_processes(code)]
    # the first process traced (and imported them), the second loaded the programs
    assert {"optimistix", "lineax"} <= set(outs[0]["loaded"]) and outs[1]["loaded"] == []
    ref = np.asarray(jb.fold_speeds(jb.NonlinearBelt(n_modes=1), (7.5, 10.5), 1))
    for o in outs:
        np.testing.assert_allclose(np.asarray(o["folds"]), ref, rtol=1e-12)


@stored_programs
def test_prepared_programs_are_traced_once_and_serve_the_calls(tmp_path, monkeypatch):
    # response_curve traces its three programs before running any (the last two from the continuation's output
    # types) and compiles them in the background: each is exported once, the calls run them, and the results are
    # the traced path's
    from jaxbelt._guard import prepare
    from jaxbelt.models.nonlinear import harmonic

    belt = jb.NonlinearBelt(n_modes=1)
    reference = jb.response_curve(belt, (7.5, 10.5), 1)
    names = []
    export = _store._export
    monkeypatch.setattr(_store, "_export", lambda fun, name, *a, **k: names.append(name) or export(fun, name, *a, **k))
    # store off: compiled ahead in memory, in a compile thread, with the output's types; the call compiles nothing
    # itself (it waits for that compilation)
    args = (belt, jnp.zeros((4, 7)), jnp.ones(4, bool), 1)
    jax.clear_caches()
    threads = []

    def listener(name, duration, **kw):
        if name == "/jax/core/compile/backend_compile_duration" and kw.get("fun_name") == "jit(_curve_post_jit)":
            threads.append(threading.current_thread().name)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        ahead = prepare(harmonic._curve_post_jit, *args)
        out = harmonic._curve_post_jit(*args)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert len(threads) == 1 and threads[0].startswith("jaxbelt-compile"), threads
    assert [(t.shape, t.dtype) for t in jax.tree_util.tree_leaves(ahead)] == [
        (o.shape, o.dtype) for o in jax.tree_util.tree_leaves(out)
    ]
    with store_in(tmp_path / "xla") as folder:
        stored = jb.response_curve(belt, (7.5, 10.5), 1)
        assert sorted(n.rsplit(".", 1)[-1] for n in names) == ["_continue_jit", "_curve_post_jit", "_folds_jit"]
        assert len(_programs(folder)) == 3
        # the types `prepare` gives are those of the outputs
        us, ts, acc = harmonic._trace(belt, 7.5, 10.5, 1, 200, 0.05, 0.25)
        types = prepare(harmonic._curve_post_jit, belt, us, acc, 1)
        out = harmonic._curve_post_jit(belt, us, acc, 1)
        assert len(names) == 3  # nothing exported again
    assert [(t.shape, t.dtype) for t in jax.tree_util.tree_leaves(types)] == [
        (o.shape, o.dtype) for o in jax.tree_util.tree_leaves(out)
    ]
    _same(stored, reference)


def _exports(monkeypatch):
    """The names of the programs the store exports from now on (each export is a trace and a lowering)."""
    names = []
    export = _store._export
    monkeypatch.setattr(_store, "_export", lambda fun, name, *a, **k: names.append(name) or export(fun, name, *a, **k))
    return names


@stored_programs
def test_design_move_prepares_its_programs_once_with_the_calls_types(tmp_path, monkeypatch):
    # at a given move time, design_move starts the minimax LP's compilation first, then traces the fine-grid check
    # and the programs that take the designed command's peaks (from the LP's output types) while it compiles: each
    # program is exported once (a prepared type that differed from the call's would export it twice), and the
    # design is the traced path's
    axis = jb.ModalAxis([6.0], [0.02])

    def run():
        plan = jb.design_move(axis, 0.1, 0.8, v_max=0.3, a_max=1.2, include=("minimax",))
        row = plan.candidate("minimax")
        return plan.minimax.command.coefficients, plan.minimax.worst, row.worst_percent, row.peak_a, row.band_hz

    reference = run()
    names = _exports(monkeypatch)
    with store_in(tmp_path / "xla") as folder:
        stored = run()
        assert len(_programs(folder)) == len(names)
    assert sorted(n.rsplit(".", 1)[-1] for n in names) == [
        "_derivatives",  # the command sampled at the drive's rate and its peaks (every order in one program)
        "_fine_ratios_program",
        "_grid_curve",  # the reference (time-optimal) move's residual: steps and ramps on a uniform grid of factors
        "_solve_round_impl",
    ]
    for a, b in zip(jax.tree_util.tree_leaves(stored), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=0)


@stored_programs
def test_optimise_command_prepares_its_step_while_the_start_compiles(tmp_path, monkeypatch):
    # the step program is traced from the start program's output types before the start runs: both are exported
    # once, and the optimisation is the traced path's
    plat, cmd = jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))

    def run():
        res = jb.optimise_command(plat, cmd, max_steps=20, progress=False)
        return res.gammas, res.value, res.n_steps

    reference = run()
    names = _exports(monkeypatch)
    with store_in(tmp_path / "xla"):
        stored = run()
    assert sorted(n.rsplit(".", 1)[-1] for n in names) == ["_start_impl", "_step_impl"]
    np.testing.assert_allclose(np.asarray(stored[0]), np.asarray(reference[0]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(float(stored[1]), float(reference[1]), rtol=1e-12, atol=0)
    assert stored[2] == reference[2]


@stored_programs
def test_tune_pid_prepares_its_update_while_its_run_compiles(tmp_path, monkeypatch):
    # the step is two programs, the update traced from the run's output types before either runs: both are
    # exported once, and the tuning is the traced path's
    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)

    def run():
        res = jb.tune_pid(drive, pid, steps=2, progress=False)
        return res.history["loss"], res.chi, res.pid.kp

    reference = run()
    names = _exports(monkeypatch)
    with store_in(tmp_path / "xla"):
        stored = run()
    assert sorted(n.rsplit(".", 1)[-1] for n in names) == ["_tune_run_impl", "_tune_update_impl"]
    for a, b in zip(stored, reference):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=0)


# --- a user's function (`jb.sweep`, `jb.identify`): stored under its lasting key ---------------------------------


def _belt_speeds(scale):
    """A user's sweep function: the driven pulley's speed at 21 times for one stiffness, scaled by a closed-over
    value. `jb.simulate` is looked up on the module when it is traced (the tests count those lookups)."""
    ts = jnp.linspace(0.0, 0.3, 21)

    def speeds(k):
        sol = jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(24.0, 0.04), ts=ts))
        return sol["omega2"] * scale

    return speeds


@pytest.fixture
def counted_simulate(monkeypatch):
    """`jb.simulate`, counting the times a user's function calls it (each trace of that function)."""
    calls = []
    original = jb.simulate

    def simulate(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(jb, "simulate", simulate)
    return calls


def test_lasting_key_of_a_users_function():
    from jaxbelt._callables import lasting_key

    k = jnp.array([1.0, 2.0])
    # the same code and values: the same key, whatever the function object
    assert lasting_key(_belt_speeds(2.0)) == lasting_key(_belt_speeds(2.0)) is not None
    assert lasting_key(lambda x: x * k) == lasting_key(lambda x: x * k) is not None  # one line: one code object
    # another closed-over value (a number, an array's contents), another key
    assert lasting_key(_belt_speeds(2.0)) != lasting_key(_belt_speeds(3.0))
    keys = {lasting_key(lambda x, k=k: x * k) for k in (jnp.array([1.0, 2.0]), jnp.array([1.0, 2.5]))}
    assert len(keys) == 2
    # what jaxbelt cannot key lastingly: the user's own objects, classes and modules

    class Gain:
        value = 2.0

    g = Gain()
    assert lasting_key(lambda x: x * g.value) is None
    assert lasting_key(lambda x: x * Gain.value) is None
    own = types.ModuleType("own_models")  # a module of the user's: its code is not in the store's fingerprint
    own.gain = 2.0
    assert lasting_key(lambda x: x * own.gain) is None
    assert lasting_key(lambda x: x * math.pi) is not None  # the standard library's, by name


@stored_programs
def test_a_users_sweep_function_is_stored_by_its_code_and_values(tmp_path, counted_simulate):
    ks = jnp.array([1.0e5, 1.2e5, 1.5e5])
    reference = jb.sweep(_belt_speeds(2.0), ks)  # the traced path (store off)
    assert len(counted_simulate) == 1
    with store_in(tmp_path / "xla") as folder:
        first = jb.sweep(_belt_speeds(2.0), ks)  # traced, exported, written
        assert len(counted_simulate) == 2 and len(_programs(folder)) == 1
        _store.forget()  # as in a new process
        jax.clear_caches()
        second = jb.sweep(_belt_speeds(2.0), ks * 1.1)  # a new function of the same code and values, new data
        assert len(counted_simulate) == 2  # not traced: the stored program ran
        # another closed-over value: another program (a value is a constant of the program, as for jax.jit)
        third = jb.sweep(_belt_speeds(3.0), ks)
        assert len(counted_simulate) == 3 and len(_programs(folder)) == 2
    np.testing.assert_allclose(np.asarray(first), np.asarray(reference), rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(third), 1.5 * np.asarray(reference), rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(second), np.asarray(jb.sweep(_belt_speeds(2.0), ks * 1.1)), rtol=1e-12)


def test_a_function_holding_the_users_own_object_is_traced_not_stored(tmp_path, counted_simulate):
    class Scale:  # the user's class: its code could change between processes without changing any key
        def __init__(self, v):
            self.v = v

    s = Scale(2.0)
    ts = jnp.linspace(0.0, 0.3, 21)

    def speeds(k):
        return jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(24.0, 0.04), ts=ts))["omega2"] * s.v

    ks = jnp.array([1.0e5, 1.5e5])
    with store_in(tmp_path / "xla") as folder:
        out = jb.sweep(speeds, ks)
        assert _programs(folder) == []
    np.testing.assert_allclose(np.asarray(out), np.asarray(jb.sweep(_belt_speeds(2.0), ks)), rtol=1e-12, atol=0)


def _startup_predict(ts):
    def predict(p):
        sol = jb.simulate(jb.Scene(jb.BeltStartup(k=p["k"], c=p["c"]), jb.ExponentialVoltage(24.0, 0.02), ts=ts))
        return jnp.stack([sol["omega2"], sol["current"]], -1)

    return predict


@stored_programs
def test_identify_through_the_store(tmp_path, counted_simulate):
    ts = jnp.linspace(0.0, 0.3, 61)
    data = np.asarray(_startup_predict(ts)({"k": 1.2e5, "c": 20.0}))
    p0 = {"k": 0.8e5, "c": 30.0}
    reference = jb.identify(_startup_predict(ts), p0, data, sigma=1e-3)
    jax.clear_caches()  # the reference's program is not reused in-process
    traced = len(counted_simulate)
    with store_in(tmp_path / "xla") as folder:
        first = jb.identify(_startup_predict(ts), p0, data, sigma=1e-3)
        assert len(_programs(folder)) == 1 and len(counted_simulate) == traced + 1  # `predict` traced once
        _store.forget()
        jax.clear_caches()
        second = jb.identify(_startup_predict(ts), p0, data, sigma=1e-3)
        assert len(counted_simulate) == traced + 1  # not traced
    for fit in (first, second):
        for name in p0:
            np.testing.assert_allclose(fit.params[name], reference.params[name], rtol=1e-12)
            np.testing.assert_allclose(fit.stderr[name], reference.stderr[name], rtol=1e-10)
    # noise-free data: the fit recovers the true values
    np.testing.assert_allclose([second.params["k"], second.params["c"]], [1.2e5, 20.0], rtol=1e-8)


@stored_programs
def test_a_new_process_runs_the_stored_sharded_sweep(tmp_path):
    # two CPU devices: the sweep shards over a mesh, which the key holds; the stored program is called with the
    # inputs sharded as they were when it was exported
    code = (
        "import jax, jax.numpy as jnp, numpy as np, jaxbelt as jb\n"
        "jb.cpu_devices(2)\n"
        "jax.config.update('jax_enable_x64', True)\n"
        f"jb.enable_compilation_cache({str(tmp_path / 'xla')!r})\n"
        "calls = []\n"
        "original = jb.simulate\n"
        "def counted(*a, **k):\n"
        "    calls.append(1)\n"
        "    return original(*a, **k)\n"
        "jb.simulate = counted\n"
        "ts = jnp.linspace(0.0, 0.3, 21)\n"
        "def speeds(k):\n"
        "    sol = jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(24.0, 0.04), ts=ts))\n"
        "    return sol['omega2'][-1]\n"
        "out = jb.sweep(speeds, jnp.array([1.0e5, 1.2e5, 1.5e5]))\n"
        "print(len(calls), len(out.sharding.device_set), *np.asarray(out).tolist())\n"
    )
    outs = [out.split() for out in _two_processes(code)]
    assert outs[0][:2] == ["1", "2"] and outs[1][:2] == ["0", "2"]  # traced, then loaded; sharded over 2 devices
    ref = jb.sweep(_belt_speeds(1.0), jnp.array([1.0e5, 1.2e5, 1.5e5]))[:, -1]
    for o in outs:
        np.testing.assert_allclose(np.array(o[2:], float), np.asarray(ref), rtol=1e-12)


def test_a_users_function_that_fails_raises_its_own_error_through_the_store(tmp_path):
    def bad(k):  # the wrong shape for `jb.BeltStartup(k=...)`: the model's check names the parameter
        return jb.simulate(jb.Scene(jb.BeltStartup(k=jnp.stack([k, k])), jb.ExponentialVoltage(24.0, 0.04)))

    def negative(k):  # a check that fails at run time, inside the stored program
        ts = jnp.linspace(0, 0.1, 5)
        return jb.simulate(jb.Scene(jb.BeltStartup(k=-k), jb.ExponentialVoltage(24.0, 0.04), ts=ts, uniform=True))

    ks = jnp.array([1.0e5, 1.5e5])
    with store_in(tmp_path / "xla"):
        for _ in range(2):  # traced (not exportable: marked on disk), then traced again from the mark
            with pytest.raises(ValueError, match=r"parameter `k` must be a scalar"):
                jb.sweep(bad, ks)
            _store.forget()
        for _ in range(2):  # exported, then loaded: the check's message travels with the program
            with pytest.raises(ValueError, match=r"parameter `k` must lie in \[0\.001, 1e\+12\] N/m \(in 'negative'\)"):
                jb.sweep(negative, ks)
            _store.forget()
