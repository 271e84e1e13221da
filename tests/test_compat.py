"""jaxbelt wherever JAX runs: private internals in one adapter with a tested fallback, XLA options only where the
running XLA knows them, and BLAS threads limited by the library itself (no environment variable needed)."""

import json
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_coldstart import _subprocess

import jaxbelt as jb
from jaxbelt import _compat, _threads, _xla

ROOT = Path(__file__).resolve().parent.parent
PRIVATE = re.compile(r"jax\._src|equinox\._|equinox\.internal")


def test_private_modules_are_named_only_in_the_adapter():
    """`grep -rE "jax\\._src|equinox\\._|equinox\\.internal" jaxbelt` finds the adapter module alone."""
    found = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in sorted((ROOT / "jaxbelt").rglob("*.py"))
        if p.name != "_compat.py"
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if PRIVATE.search(line)
    ]
    assert found == []


def test_the_adapter_withholds_every_private_layout_outside_its_versions(monkeypatch):
    """On a release it was not written for (here: JAX 0.99), every function of the adapter returns its fallback;
    on this machine's versions (inside `WRITTEN_FOR`) they return the private objects."""
    monkeypatch.delenv("JAXBELT_PRIVATE_APIS", raising=False)  # the versions decide here (a run may set it to 0)
    monkeypatch.setattr(_compat, "_state", {})
    if _compat.private_apis():
        assert _compat.checkify_rules() is not None
        assert _compat.trace_context() is not None
        assert _compat.equinox_missing() is not None
    monkeypatch.setattr(_compat, "_state", {})
    monkeypatch.setattr(_compat, "_version", lambda dist: (0, 99) if dist in ("jax", "jaxlib") else (0, 13))
    assert not _compat.private_apis()
    assert _compat.checkify_rules() is None
    assert _compat.trace_context() is None
    assert _compat.traceback_type() is None
    assert _compat.checkify_counter() is None
    assert _compat.equinox_missing() is not None  # equinox 0.13 is still inside its range
    monkeypatch.setattr(_compat, "_state", {})
    monkeypatch.setenv("JAXBELT_PRIVATE_APIS", "0")
    assert _compat.equinox_missing() is None and _compat.equinox_internal() is None


# Each entry point that raised on JAX 0.11 (XLA options, checkify's internals) and the program store, run with
# every private path off and with an XLA option that this XLA does not know: the same numbers as this process.
FALLBACK_PROBE = r"""
import json, os, tempfile
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
from jaxbelt import _compat, _guard, _xla
_xla.QUICK_COMPILE["xla_no_such_option_in_any_xla"] = True  # refused by every XLA: left out, no error
jb.enable_compilation_cache(os.environ.get("PROBE_CACHE_DIR") or tempfile.mkdtemp())
out = {"private": _compat.private_apis(), "lean": None}
res = jb.optimise_command(jb.BeltPlatform(), jb.PseudoPolynomial(gammas=jnp.array([3.0, 4.0, 5.0])), progress=False)
out["optimise_command"] = [float(g) for g in res.command.gammas]
out["lean"] = _guard._state["lean"]
plan = jb.design_move(jb.ModalAxis(frequencies=[7.3], damping_ratios=[0.015]), distance=0.1, move_time=0.8,
                      v_max=0.3, a_max=1.2, uncertainty=0.2, include=("minimax", "ZV"))
out["design_move"] = float(plan.best.worst_m)
drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
tuned = jb.tune_pid(drive, pid, t0=0.375, t1=0.5, steps=2, progress=False)
out["tune_pid"] = [float(tuned.pid.kp), float(tuned.pid.ki)]
try:
    jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(gammas=jnp.array([3.0, 3.0, 5.0])))
    out["error"] = None
except ValueError as e:
    out["error"] = str(e).splitlines()[0]
print("RESULT " + json.dumps(out))
"""


def _probe(**env) -> dict:
    stdout = _subprocess(FALLBACK_PROBE, **env)
    return json.loads(next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))[len("RESULT ") :])


@pytest.mark.slow
def test_entry_points_agree_with_and_without_private_internals(tmp_path):
    # the two runs share one persistent cache: a program whose HLO is the same either way compiles once (its key
    # is the HLO), a program that differs compiles in each run
    fast = _probe(PROBE_CACHE_DIR=str(tmp_path))
    slow = _probe(JAXBELT_PRIVATE_APIS="0", PROBE_CACHE_DIR=str(tmp_path))
    assert slow["private"] is False and slow["lean"] is False
    if fast["private"]:
        assert fast["lean"] is True
    np.testing.assert_allclose(slow["optimise_command"], fast["optimise_command"], rtol=1e-12)
    np.testing.assert_allclose(slow["design_move"], fast["design_move"], rtol=1e-9)
    np.testing.assert_allclose(slow["tune_pid"], fast["tune_pid"], rtol=1e-9)
    # the same check fails, with the same first line, through checkify's own pass
    assert fast["error"] is not None and slow["error"] == fast["error"]
    # and the answer is the paper's optimum (Incerti: gammas ~ 3.02, 4.59, 5.84)
    np.testing.assert_allclose(fast["optimise_command"], [3.022, 4.590, 5.839], atol=2e-3)


def test_unknown_xla_options_are_left_out_without_an_error(monkeypatch):
    monkeypatch.setattr(_xla, "_ACCEPTED", {})
    wanted = {"xla_backend_optimization_level": 0, "xla_no_such_option_in_any_xla": True}
    kept = _xla.supported_options(wanted)
    assert kept == {"xla_backend_optimization_level": 0}
    assert _xla.supported_options({"xla_no_such_option_in_any_xla": True}) is None

    def f(x):
        return jnp.sin(x) * x

    quick = _xla.LazyJit(jax.jit, f, wanted)
    np.testing.assert_allclose(quick(jnp.arange(3.0)), np.sin(np.arange(3.0)) * np.arange(3.0), rtol=1e-15)
    assert quick.lower(1.0).compile() is not None  # the AOT methods of the jitted function


def test_quick_cpu_options_go_to_a_cpu_backend_only(monkeypatch):
    monkeypatch.setattr(_xla, "_ACCEPTED", {})
    if jax.default_backend() == "cpu":
        assert _xla.quick_compile() is not None
    else:  # the suite on a GPU machine: its programs compile with XLA's defaults
        assert _xla.quick_compile() is None
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert _xla.quick_compile() is None


# A user's process: OPENBLAS_NUM_THREADS unset. Inside an entry point BLAS runs one thread; outside it, the
# user's numpy keeps the threads it had.
THREADS_PROBE = r"""
import json
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxbelt as jb
from jaxbelt import _threads
from threadpoolctl import threadpool_info, threadpool_limits
threadpool_limits(2, user_api="blas")  # a user's numpy with two threads (the machine may have more cores)
seen = []
def model_vector_field_probe(x):
    seen.append(sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}))
    return x
with _threads.limited_blas():
    model_vector_field_probe(0)
    with _threads.limited_blas():  # nested: one limit
        model_vector_field_probe(0)
    model_vector_field_probe(0)
model_vector_field_probe(0)
plan = jb.design_move(jb.ModalAxis(frequencies=[7.3], damping_ratios=[0.015]), distance=0.1, move_time=0.8,
                      v_max=0.3, a_max=1.2, uncertainty=0.2, include=("minimax", "ZV"))
model_vector_field_probe(0)
print("RESULT " + json.dumps(seen))
"""


def test_blas_threads_are_limited_inside_jaxbelt_and_restored_outside():
    stdout = _subprocess(THREADS_PROBE, OPENBLAS_NUM_THREADS="", JAXBELT_BLAS_THREADS="1")
    seen = json.loads(next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))[len("RESULT ") :])
    assert seen == [[1], [1], [1], [2], [2]]


def test_public_entry_points_limit_blas_threads(monkeypatch):
    calls = []
    monkeypatch.setattr(_threads, "_enter", lambda: calls.append("enter"))
    monkeypatch.setattr(_threads, "_exit", lambda: calls.append("exit"))
    jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(gammas=jnp.array([3.0, 4.0, 5.0])))
    assert calls == ["enter", "exit"]


def test_bad_blas_thread_setting_is_named(monkeypatch):
    monkeypatch.setenv("JAXBELT_BLAS_THREADS", "-2")
    with pytest.raises(ValueError, match="JAXBELT_BLAS_THREADS must be a whole number >= 0"):
        jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(gammas=jnp.array([3.0, 4.0, 5.0])))
    monkeypatch.setenv("JAXBELT_BLAS_THREADS", "0")
    assert _threads.blas_thread_limit() is None


def test_quick_options_are_probed_only_on_a_release_not_known(monkeypatch):
    """On the jaxlib release the suite runs on, the quick CPU options are known (no probe compilation in a user's
    first call); on any other release they are probed once, and the options kept are those this XLA accepts, each
    checked alone. A GPU or TPU gets none and probes nothing."""
    probes = []
    real = _xla._accepts
    monkeypatch.setattr(_xla, "_accepts", lambda options: probes.append(dict(options)) or real(options))
    monkeypatch.setattr(_xla, "_ACCEPTED", {})
    if jax.default_backend() != "cpu":  # the suite on a GPU machine
        assert _xla.quick_compile() is None and probes == []
        return
    quick = _xla.QUICK_COMPILE
    accepted = {k: v for k, v in quick.items() if real({k: v})} or None  # each option alone, unrecorded
    if _xla._known("cpu", quick):
        assert _xla.quick_compile() == quick == accepted
        assert probes == []
    monkeypatch.setattr(_xla, "_ACCEPTED", {})
    monkeypatch.setattr(_xla, "_KNOWN", {})
    probes.clear()
    assert _xla.quick_compile() == accepted
    assert probes[0] == quick and len(probes) in (1, 1 + len(quick))  # all at once, then each alone if refused
