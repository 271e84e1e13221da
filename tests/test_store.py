"""The program store (`enable_compilation_cache(programs=True)`): a later process calls jaxbelt's stored
programs without tracing them, with the results of the traced path, and never for code jaxbelt cannot
fingerprint."""

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt import _store, solve
from jaxbelt._guard import error_if, host_checked
from jaxbelt.cache import disable_compilation_cache

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


def _fourbar_scene(n=41, **kw):
    return jb.Scene(jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0),
                    ts=jnp.linspace(0.0, 0.2, n), **kw)


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
        assert sol.method == reference.method and sol.state_names == reference.state_names
        assert set(sol.outputs) == set(reference.outputs)
        # the same XLA program: equal to rounding (tolerance: a few ulps of the speeds, ~30 rad/s)
        np.testing.assert_allclose(np.asarray(sol.ys), np.asarray(reference.ys), rtol=1e-12, atol=0)
        assert bool(sol.success)


def _startup_scene(n=21, gamma=0.04, **kw):
    return jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, gamma), ts=jnp.linspace(0.0, 0.3, n), **kw)


def test_new_values_reuse_the_stored_program_and_new_structure_gets_its_own(tmp_path):
    with store_in(tmp_path / "xla") as folder:
        jb.simulate(_startup_scene())
        # new parameter values and times of the same shapes: the same program
        scene = jb.Scene(jb.BeltStartup(k=2.0e5), jb.ExponentialVoltage(20.0, 0.02), ts=jnp.linspace(0.0, 0.5, 21))
        sol = jb.simulate(scene)
        assert len(_programs(folder)) == 1
        # another grid length, another observed set, another method: new programs
        jb.simulate(_startup_scene(n=11))
        jb.simulate(_startup_scene(observe=("current",)))
        jb.simulate(_startup_scene(), method="modal")
        assert len(_programs(folder)) == 4
    ref = jb.simulate(scene)
    np.testing.assert_allclose(np.asarray(sol.ys), np.asarray(ref.ys), rtol=1e-12, atol=0)


class _OwnStartup(jb.BeltStartup):
    """A user's subclass: jaxbelt cannot fingerprint its code, so it is never stored."""


def test_classes_from_outside_jaxbelt_are_never_stored(tmp_path):
    scene = jb.Scene(_OwnStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0.0, 0.3, 21))
    with store_in(tmp_path / "xla") as folder:
        sol = jb.simulate(scene)
        assert _programs(folder) == []
    ref = jb.simulate(scene)
    np.testing.assert_allclose(np.asarray(sol.ys), np.asarray(ref.ys), rtol=1e-12, atol=0)


def test_a_damaged_file_is_replaced(tmp_path):
    scene = _startup_scene()
    with store_in(tmp_path / "xla") as folder:
        jb.simulate(scene)
        (path,) = _programs(folder)
        path.write_bytes(b"not a program")
        _store.forget()
        sol = jb.simulate(scene)
        assert path.stat().st_size > 1000  # written again
    ref = jb.simulate(scene)
    np.testing.assert_allclose(np.asarray(sol.ys), np.asarray(ref.ys), rtol=1e-12, atol=0)


@host_checked(store=True)
def _checked_sqrt(x):
    return jnp.sqrt(error_if(x, x < 0, "x must be >= 0 (got a negative value)"))


def test_a_stored_checked_program_still_raises_its_message(tmp_path):
    with store_in(tmp_path / "xla") as folder:
        assert float(_checked_sqrt(jnp.asarray(4.0))) == 2.0
        assert len(_programs(folder)) == 1
        _store.forget()  # from the file: the check's message travels with the program
        assert float(_checked_sqrt(jnp.asarray(9.0))) == 3.0
        with pytest.raises(ValueError, match="x must be >= 0"):
            _checked_sqrt(jnp.asarray(-1.0))


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
        np.testing.assert_allclose(np.asarray(s.ys), np.asarray(ref.ys), rtol=1e-12, atol=0)


def test_off_unless_the_cache_is_on(tmp_path):
    jb.enable_compilation_cache(tmp_path / "xla", programs=False)
    try:
        jb.simulate(_startup_scene(n=11))
        assert not (tmp_path / "xla" / "jaxbelt-programs").exists() or _programs(tmp_path / "xla" / "jaxbelt-programs") == []
    finally:
        disable_compilation_cache()
    assert _store.folder() is None


def test_a_new_process_runs_the_stored_closed_form(tmp_path):
    # the start-up closed form calls LAPACK (a matrix exponential): a stored program must bind LAPACK's
    # kernels itself, since nothing is lowered in the process that loads it
    code = (
        "import jax.numpy as jnp, numpy as np, equinox as eqx, jaxbelt as jb\n"
        "from jaxbelt import solve\n"
        f"jb.enable_compilation_cache({str(tmp_path / 'xla')!r})\n"
        "sol = jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0, 0.5, 51),"
        " observe=('current',)))\n"
        "print(eqx.debug.get_num_traces(solve._run_traced), float(sol.current[-1]), float(sol.ys[-1, 3]))\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    outs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
        assert out.returncode == 0, out.stderr
        outs.append(out.stdout.split())
    assert outs[0][0] == "1" and outs[1][0] == "0"  # traced once, then loaded
    ref = jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=jnp.linspace(0, 0.5, 51),
                               observe=("current",)))
    for o in outs:
        np.testing.assert_allclose([float(o[1]), float(o[2])], [float(ref.current[-1]), float(ref.ys[-1, 3])],
                                   rtol=1e-12)
