"""Compile once, import fast: repeated calls reuse their compiled programs, `import jaxbelt` loads no
plotting library, and the persistent compilation cache stores programs where it is told to."""

import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import count_compiles

import jaxbelt as jb
from jaxbelt import _compat
from jaxbelt.optimise import pid as pid_mod

ROOT = Path(__file__).resolve().parents[1]


def _subprocess(code, **env):
    full = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **env)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


# The paper's window and a limited regulator, as in test_fourbar.py's tuning test and the four-bar
# notebook: the same programs (conftest.py runs these tests in the same worker).
TUNE_PID = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
TUNE_WINDOW = dict(t0=0.375, t1=0.5)


def test_tune_pid_compiles_its_step_once():
    drive = jb.FourBarDrive()
    pid = TUNE_PID
    kw = dict(TUNE_WINDOW, steps=2, progress=False)
    first = jb.tune_pid(drive, pid, **kw)
    # whether the bounds are given is the program's structure (an absent bound's penalty is left out of it)
    jb.tune_pid(drive, pid, **dict(kw, steps=1), v_max=50.0, i_max=30.0)
    traces = dict(pid_mod.TRACE_COUNT)
    # new values of the same shapes: learning rate, window start, bounds, tolerances, gains
    with count_compiles() as c:
        second = jb.tune_pid(
            drive,
            jb.PID(kp=60.0, v_limit=45.0),
            t0=0.4,
            t1=0.5,
            steps=3,
            progress=False,
            learning_rate=0.05,
            v_max=44.0,
            i_max=20.0,
            rtol=1e-8,
        )
        third = jb.tune_pid(drive, pid, **kw)
    assert pid_mod.TRACE_COUNT == traces
    assert c["n"] == 0
    # same inputs, same numbers; a different learning rate takes a different path
    np.testing.assert_array_equal(first.history["loss"], third.history["loss"])
    assert first.chi == third.chi
    assert second.history["loss"].shape == (3,)
    assert not np.allclose(second.history["kp"][:2], first.history["kp"])


def test_tune_pid_learning_rate_matches_plain_adam():
    # the default optimiser (adam with the rate in its state) takes the steps of optax.adam(rate)
    import optax

    drive, pid = jb.FourBarDrive(), TUNE_PID
    kw = dict(TUNE_WINDOW, steps=3, progress=False)
    a = jb.tune_pid(drive, pid, learning_rate=0.07, **kw)
    b = jb.tune_pid(drive, pid, optimizer=optax.adam(0.07), **kw)
    np.testing.assert_allclose(a.history["kp"], b.history["kp"], rtol=1e-12)
    np.testing.assert_allclose(a.history["loss"], b.history["loss"], rtol=1e-12)


def test_residual_energy_eager_is_one_program():
    plat = jb.BeltPlatform()
    cmd = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
    h = jb.residual_energy(plat, cmd)
    h_jit = jax.jit(lambda p, c: jb.residual_energy(p, c))(plat, cmd)
    np.testing.assert_allclose(h, h_jit, rtol=1e-13)
    with count_compiles() as c:
        h2 = jb.residual_energy(plat, jb.PseudoPolynomial(jnp.array([3.5, 4.5, 6.0])))
    assert c["n"] == 0
    assert float(h2) != float(h)
    # the ODE evaluation agrees (independent method), and a new tolerance does not recompile
    h_ode = jb.residual_energy(plat, cmd, method="ode")
    with count_compiles() as c:
        h_ode2 = jb.residual_energy(plat, cmd, method="ode", rtol=1e-11, atol=1e-14)
    assert c["n"] == 0
    np.testing.assert_allclose([h_ode, h_ode2], [h, h], rtol=1e-8)
    with pytest.raises(ValueError, match="method"):
        jb.residual_energy(plat, cmd, method="euler")


def test_optimise_command_reuses_its_step():
    plat = jb.BeltPlatform()
    jb.optimise_command(plat, jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])), max_steps=3, progress=False)
    with count_compiles() as c:
        res = jb.optimise_command(plat, jb.PseudoPolynomial(jnp.array([3.2, 4.1, 5.3])), max_steps=3, progress=False)
    assert c["n"] == 0
    assert float(res.relative) < 1.0


def test_import_loads_no_plotting_library():
    out = _subprocess(
        "import sys, jaxbelt as jb; print('matplotlib' in sys.modules, 'jaxbelt.plots' in sys.modules); "
        "jb.plots.draw_startup; print('jaxbelt.plots' in sys.modules)"
    )
    assert out.split() == ["False", "False", "True"]


def test_compilation_cache_writes_to_the_folder(tmp_path):
    code = (
        "import jax, jax.numpy as jnp, jaxbelt as jb; "
        f"d = jb.enable_compilation_cache({str(tmp_path / 'xla')!r}); print(d); "
        "jax.jit(lambda x: jnp.sin(x) ** 2 + x)(jnp.arange(3.0)).block_until_ready()"
    )
    out = _subprocess(code)
    assert out.strip() == str(tmp_path / "xla")
    assert any((tmp_path / "xla").iterdir())


@pytest.mark.skipif(
    _compat.equinox_internal() is None,
    reason="diffrax's checks become values only through equinox's internals, which jaxbelt._compat withholds here",
)
def test_eager_programs_hold_no_host_callback(tmp_path):
    # JAX's persistent cache never stores a program that holds a host callback (eqx.error_if): the
    # programs jaxbelt runs eagerly return their checks as values instead, so a second process loads them
    code = (
        "import jax, jax.numpy as jnp, jaxbelt as jb; jax.config.update('jax_enable_x64', True); "
        f"jb.enable_compilation_cache({str(tmp_path / 'xla')!r}); "
        "jax.config.update('jax_explain_cache_misses', True); "
        "jb.simulate_fig4(jb.FourBarDrive(), n=201); "
        "plat, cmd = jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])); "
        "jb.residual_energy(plat, cmd); jb.optimise_command(plat, cmd, max_steps=2, progress=False); "
        "jb.crossing_speeds(jb.RunoutRig(), n_modes=2); jb.MovingString().galerkin_frequencies(20.0, 8, 3); "
        # a sweep: the checks of the user's function (here the command's traced gamma) come back as values too
        "jb.sweep(lambda g: jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, g), "
        "ts=jnp.linspace(0.0, 0.1, 11))).ys, jnp.array([0.01, 0.02]))"
    )
    full = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "Writing" in out.stderr  # the explanations are on
    assert "host callbacks" not in out.stderr, [line for line in out.stderr.splitlines() if "host callbacks" in line]


def test_host_checked_programs_raise_on_the_host():
    import equinox as eqx

    from jaxbelt._guard import error_if, host_checked

    own = host_checked(lambda x: error_if(x, x < 0, "x must be >= 0 {sic}"))
    third_party = host_checked(lambda x: eqx.error_if(x, x > 1, "x must be <= 1"))
    assert float(own(0.5)) == float(third_party(0.5)) == 0.5
    with pytest.raises(ValueError, match="x must be >= 0 {sic}"):  # checkify's JaxRuntimeError
        own(-1.0)
    with pytest.raises(ValueError, match="x must be <= 1"):
        third_party(2.0)
    # inside the caller's jit: the plain program, whose eqx.error_if raises at run time
    with pytest.raises((eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError), match="x must be >= 0"):
        jax.block_until_ready(jax.jit(own)(-1.0))
    with pytest.raises((eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError), match="x must be <= 1"):
        jax.block_until_ready(jax.jit(lambda x: eqx.error_if(x, x > 1, "x must be <= 1"))(2.0))


def test_checks_inside_loops_branches_and_custom_derivatives_still_raise():
    # checkify's pass steps over the loops, branches, calls and custom derivatives that hold no check
    # (`_lean_checkify`); one that holds a check keeps it, however deep
    from jax.experimental import checkify as jax_checkify

    from jaxbelt import _guard
    from jaxbelt._guard import error_if, host_checked

    def loop(x):  # a check in a while loop's body, at its third step, under a jit and a custom derivative
        @jax.custom_jvp
        def step(c):
            i, v = c
            return i + 1, error_if(v * 2.0, (i == 2) & (v > 10.0), "the loop's value must stay <= 10")

        step.defjvp(lambda p, t: (step(p[0]), t[0]))
        body = jax.jit(lambda c: step(c))
        plain = jax.lax.fori_loop(0, 5, lambda i, v: v + 1.0, x)  # a loop without a check beside it
        return jax.lax.while_loop(lambda c: c[0] < 4, body, (0, plain))[1]

    def branch(x):  # a check in one branch of a cond inside a scan
        def f(c, _):
            c = jax.lax.cond(
                c > 0, lambda v: error_if(v, v > 100.0, "the branch's value must stay <= 100"), jnp.negative, c
            )
            return c * 3.0, c

        return jax.lax.scan(f, x, None, length=4)[0]

    for fun, good, bad, message in ((loop, -3.0, 1.0, "loop's value"), (branch, 1.0, 5.0, "branch's value")):
        checked = host_checked(fun)
        np.testing.assert_allclose(float(checked(good)), float(jax.jit(fun)(good)), rtol=0)  # the same program
        with pytest.raises(ValueError, match=message):
            checked(bad)
    # the lean rules are installed on the JAX they were written for (`jaxbelt._compat`); elsewhere checkify's own
    assert _guard._lean_checkify() == (_compat.checkify_rules() is not None)
    # the rules step over nothing for other error sets: checkify's NaN checks still see inside a check-free loop
    nan_in_loop = jax_checkify.checkify(
        lambda x: jax.lax.fori_loop(0, 2, lambda i, v: jnp.log(v), x), errors=jax_checkify.nan_checks
    )
    err, _ = jax.jit(nan_in_loop)(-1.0)
    assert err.get() is not None and "nan" in err.get().lower()


_ONE_PROGRAM = r"""
import jax, jax.numpy as jnp, numpy as np
import jaxbelt as jb
jb.cpu_devices(2)
jax.config.update("jax_enable_x64", True)
import jax.monitoring
from jaxbelt._guard import error_if
n = {"compiles": 0}
def listener(name, secs, **kw):
    if name == "/jax/core/compile/backend_compile_duration":
        n["compiles"] += 1
good, bad = np.arange(1.0, 5.0), np.array([1.0, -1.0, 2.0, 3.0])
jax.monitoring.register_event_duration_secs_listener(listener)
jb.sweep(lambda x: error_if(jnp.sqrt(x), x < 0, "x must be >= 0"), good)
first = n["compiles"]
try:
    jb.sweep(lambda x: error_if(jnp.sqrt(x), x < 0, "x must be >= 0"), bad)
    raised = ""
except ValueError as e:
    raised = str(e).splitlines()[0]
print(first, repr(raised))
"""


def test_a_sharded_sweep_compiles_its_program_only():
    # the checks come back as values, read on the host: the first sweep over two devices compiles its program and
    # nothing else (checkify's own reading indexes and compares the per-device error arrays, a small compiled
    # program each: 17 compilations in all for a four-bar sweep); a failed check still raises its message
    first, raised = _subprocess(_ONE_PROGRAM).split(" ", 1)
    assert int(first) == 1
    assert "x must be >= 0" in raised


def test_default_cache_folder_respects_xdg(tmp_path, monkeypatch):
    from jaxbelt.cache import default_cache_dir

    monkeypatch.delenv("JAXBELT_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert default_cache_dir() == tmp_path / "jaxbelt" / "xla"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert default_cache_dir() == Path.home() / ".cache" / "jaxbelt" / "xla"
    monkeypatch.setenv("JAXBELT_CACHE_DIR", str(tmp_path / "x"))
    assert default_cache_dir() == tmp_path / "x"


def test_cli_has_a_no_cache_switch():
    from jaxbelt.cli import build_parser

    args = build_parser().parse_args(["--no-cache", "startup"])
    assert args.no_cache and args.command == "startup"
    assert not build_parser().parse_args(["startup"]).no_cache


def _reference_energy(d, alpha):
    # the textbook route (Appendix A-C): angles by arctan2, J and Ep from sines of the angle
    # differences, derivatives by nested autodiff; the model's algebraic form must agree with it
    def coeffs(al):
        sa, ca = jnp.sin(al), jnp.cos(al)
        A = 2 * d.c * (d.hy - d.a * sa)
        B = 2 * d.c * (d.hx - d.a * ca)
        C = d.a**2 - d.b**2 + d.c**2 + d.hx**2 + d.hy**2 - 2 * d.a * (d.hx * ca + d.hy * sa)
        D = jnp.sqrt(A**2 + B**2 - C**2)
        k = float(d.assembly)
        gam = jnp.arctan2(-(A * C + k * B * D), -(B * C - k * A * D))
        bet = jnp.arctan2(d.hy + d.c * jnp.sin(gam) - d.a * sa, d.hx + d.c * jnp.cos(gam) - d.a * ca)
        s = jnp.sin(gam - bet)
        Q = d.a * jnp.sin(al - gam) / (d.b * s)
        R = d.a * jnp.sin(al - bet) / (d.c * s)
        J = (
            d.jg1
            + d.m1 * d.f1**2
            + (d.jg3 + d.m3 * d.f3**2) * R**2
            + d.m2 * d.a**2
            + (d.jg2 + d.m2 * d.f2**2) * Q**2
            + 2 * d.a * d.f2 * d.m2 * Q * jnp.cos(al - bet - d.theta2)
        )
        Ep = d.g * (
            d.m1 * d.f1 * jnp.sin(al + d.theta1)
            + d.m2 * (d.a * sa + d.f2 * jnp.sin(bet + d.theta2))
            + d.m3 * (d.hy + d.f3 * jnp.sin(gam + d.theta3))
        )
        return J, Ep

    J, Ep = jax.vmap(coeffs)(alpha)
    dJ, dEp = jax.vmap(jax.grad(lambda al: coeffs(al)[0]))(alpha), jax.vmap(jax.grad(lambda al: coeffs(al)[1]))(alpha)
    return J, Ep, dJ, dEp


@pytest.mark.parametrize("kw", [{}, {"theta1": 0.3, "theta2": -0.2, "theta3": 0.5, "hy": -0.02}, {"assembly": -1}])
def test_fourbar_algebraic_vector_field_matches_arctan2_route(kw):
    d = jb.FourBarDrive(**kw)
    alpha = jnp.linspace(0.0, 2 * np.pi, 257)
    got = d.inertia_and_potential(alpha)
    ref = _reference_energy(d, alpha)
    for g, r in zip(got, ref):
        np.testing.assert_allclose(g, r, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(r))))


_FIRST_TUNE = r"""
import jax
jax.config.update("jax_enable_x64", True)
import jax.monitoring
import jaxbelt as jb
n = {"compiles": 0}
def listener(name, secs, **kw):
    if name == "/jax/core/compile/backend_compile_duration":
        n["compiles"] += 1
jax.monitoring.register_event_duration_secs_listener(listener)
jb.enable_compilation_cache()
drive = jb.FourBarDrive()
pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
jb.tune_pid(drive, pid, steps=3, progress=False)
first = n["compiles"]
jb.tune_pid(drive, pid, steps=3, progress=False)
print(first, n["compiles"] - first)
"""


def test_tune_pid_first_call_compiles_each_program_once(tmp_path):
    # A fresh process, an empty cache folder (the README's cold first call): the step's two programs (the run with
    # its sensitivities, the update) are compiled once each (not again for the committed arrays the step feeds
    # itself), the report takes the step's, no small eager programs around the loop; two tiny programs inside
    # diffrax's set-up remain. It was 15 compilations. A fifth (the checked report program, 11 s of compilation on a
    # busy machine) compiled while the report's stand-in for the hard clip had a width below `PID.v_smooth`'s range.
    first, second = map(int, _subprocess(_FIRST_TUNE, JAXBELT_CACHE_DIR=str(tmp_path)).split())
    assert first <= 4, first
    assert second == 0


def test_tune_pid_default_adam_state_is_adams_init():
    # the host-made initial state (no small programs to compile) is optax's own
    state = pid_mod._default_adam().init(jnp.zeros(3))
    host = pid_mod._default_adam_state()
    host.hyperparams["learning_rate"] = np.asarray(0.1)  # set by `tune_pid` from its argument
    assert jax.tree_util.tree_structure(state) == jax.tree_util.tree_structure(host)
    for a, b in zip(jax.tree_util.tree_leaves(state), jax.tree_util.tree_leaves(host), strict=True):
        assert np.asarray(a).dtype == np.asarray(b).dtype
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_tune_pid_report_with_a_non_finite_value_reruns_the_checked_program(monkeypatch):
    # the report runs the steps' program first (no checks); a non-finite value (a failed solve or check) runs the
    # checked report program, which raises what failed, or here (nothing failed) gives the same numbers to the
    # tolerances (it simulates the clip at the tuning's rtol 1e-7, the steps' program at a hundredth of it)
    kw = dict(TUNE_WINDOW, steps=1, progress=False)
    ref = jb.tune_pid(jb.FourBarDrive(), TUNE_PID, **kw)
    calls = []

    def failed(*args):
        calls.append(1)
        return {k: jnp.nan for k in ("chi", "chi_smooth", "v_peak", "i_peak", "mean_speed")}

    monkeypatch.setattr(pid_mod, "_report_metrics", failed)
    res = jb.tune_pid(jb.FourBarDrive(), TUNE_PID, **kw)
    assert len(calls) == 2
    np.testing.assert_allclose(
        [res.chi, res.chi_initial, res.v_peak], [ref.chi, ref.chi_initial, ref.v_peak], rtol=1e-5
    )


def test_tune_pid_reports_a_hard_clip_with_the_steps_program():
    # a hard clip is reported through the steps' own program (its smooth limit, 1 uV wide, at a hundredth of the
    # tolerances): no second program, and the clip's metrics within 1e-6 of a rtol-1e-12 solve of the clip itself
    # (measured <= 1.3e-7 for chi; the tuning's own rtol-1e-7 solve of the clip is off by up to 3e-6)
    from jaxbelt.objectives.fluctuation import closed_loop_metrics

    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=25.0)
    kw = dict(TUNE_WINDOW, steps=2, progress=False)
    jb.tune_pid(drive, pid, **kw)  # compiles the step
    traces = dict(pid_mod.TRACE_COUNT)
    with count_compiles() as c:
        res = jb.tune_pid(drive, pid, **kw)
    assert c["n"] == 0 and pid_mod.TRACE_COUNT == traces  # no report program traced or compiled
    g0 = np.array([80.0, 32.0, 0.015])
    for gains, chi, v_peak, i_peak in (
        (g0, res.chi_initial, None, None),
        (np.array([res.pid.kp, res.pid.ki, res.pid.kd]), res.chi, res.v_peak, res.i_peak),
    ):
        ref = closed_loop_metrics(drive, pid.with_gains(gains), rtol=1e-12, atol=1e-12, **TUNE_WINDOW)
        np.testing.assert_allclose(chi, float(ref["chi"]), rtol=1e-6)
        if v_peak is not None:
            # the clip's peak: 25 V; the stand-in's within its width times log 2 (0.7 uV)
            assert abs(v_peak - 25.0) < 7e-7 and float(ref["v_peak"]) == pytest.approx(25.0, rel=1e-12)
            np.testing.assert_allclose(i_peak, float(ref["i_peak"]), rtol=1e-7)


def test_tune_pid_without_a_limiter_reports_the_steps_own_metrics(monkeypatch):
    # a regulator without a limiter is the one the step simulates: the report takes the step's metrics at the start
    # and at the best gains (no report program to compile), equal to the report program's own to rounding (the step
    # controls the error of the trajectory alone: the report's steps)
    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
    drive = jb.FourBarDrive()
    kw = dict(TUNE_WINDOW, steps=2, progress=False)
    calls = []
    monkeypatch.setattr(pid_mod, "_report", lambda *a: calls.append(1))
    res = jb.tune_pid(drive, pid, **kw)
    assert calls == []
    monkeypatch.undo()
    g0 = np.array([80.0, 32.0, 0.015])
    cfg = pid_mod._Config(
        t0=np.asarray(0.375), v_max=np.asarray(np.inf), i_max=np.asarray(np.inf), penalty=np.asarray(10.0),
        temperature=np.asarray(3e-4), rtol=np.asarray(1e-7), atol=np.asarray(1e-7), t1=0.5, method="ode", dt=1e-3,
    )  # fmt: skip
    start = jax.device_get(pid_mod._tune_report(drive, pid, g0, cfg, np.zeros(3)))
    best = jax.device_get(
        pid_mod._tune_report(drive, pid, g0, cfg, np.log(np.array([res.pid.kp, res.pid.ki, res.pid.kd]) / g0))
    )
    np.testing.assert_allclose(res.chi_initial, start["chi"], rtol=1e-9)
    np.testing.assert_allclose(
        [res.chi, res.v_peak, res.i_peak, res.mean_speed],
        [best["chi"], best["v_peak"], best["i_peak"], best["mean_speed"]],
        rtol=1e-9,
    )


def test_tune_pid_first_call_in_a_fresh_process_imports_its_solvers_while_tracing():
    # without the cache, the first ODE solve of the process is traced inside the tuning step's checked program:
    # diffrax, optimistix and lineax are imported there, and optimistix checks its solvers' options with
    # `eqx.error_if` on concrete values as it is imported (decided at once, not made a check of the program)
    code = (
        "import sys, jax; jax.config.update('jax_enable_x64', True)\n"
        "import jaxbelt as jb\n"
        "pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)\n"
        "before = 'optimistix' in sys.modules\n"
        "res = jb.tune_pid(jb.FourBarDrive(), pid, steps=1, progress=False)\n"
        "print(before, 'optimistix' in sys.modules, bool(0 < res.chi < 1))\n"
    )
    assert _subprocess(code).split() == ["False", "True", "True"]


def test_a_concrete_equinox_check_inside_a_checked_program_is_decided_at_once():
    import equinox as eqx

    from jaxbelt._guard import host_checked

    def f(x):
        eqx.error_if(0.0, False, "never")  # concrete and False: nothing recorded, nothing raised
        return eqx.error_if(x, x < 0, "x must be >= 0")  # traced: a check of the program

    checked = host_checked(f)
    assert float(checked(jnp.asarray(2.0))) == 2.0
    with pytest.raises(Exception, match="x must be >= 0"):
        checked(jnp.asarray(-1.0))
    # a program compiled without jaxbelt's checks (`checks=False`, as the tuning step) takes the concrete check too
    assert float(host_checked(lambda x: eqx.error_if(x, False, "never") * 2.0, checks=False)(jnp.asarray(2.0))) == 4.0

    def g(x):
        return eqx.error_if(x, True, "concrete and true")  # the error of a failed check of the program

    with pytest.raises(ValueError, match="concrete and true"):
        host_checked(g)(jnp.asarray(1.0))
    with pytest.raises(ValueError, match="concrete and true"):
        host_checked(g, checks=False)(jnp.asarray(1.0))
