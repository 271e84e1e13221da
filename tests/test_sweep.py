"""`jb.sweep`: sharded over 4 CPU devices it gives the same numbers as one device; failures are reported."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = textwrap.dedent(
    """
    import json, sys
    import diffrax, jax, jax.numpy as jnp, numpy as np
    jax.config.update("jax_enable_x64", True)
    import jaxbelt as jb
    assert jb.cpu_devices(4) == 4          # before any JAX work: 4 CPU devices
    try:
        jb.cpu_devices(3)                  # too late to change: a clear error
        late = None
    except RuntimeError as e:
        late = str(e)
    model = jb.BeltStartup()
    ts = jnp.linspace(0.0, 0.3, 31)
    def run(g):
        return jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts), method="ode", rtol=1e-9, atol=1e-11,
                           solver=diffrax.Tsit5(), throw=False)
    gammas = jnp.linspace(0.01, 0.08, 10)   # 10 is not a multiple of 4: padding is exercised
    sharded = jb.sweep(run, gammas)
    one = jb.sweep(run, gammas, devices=jax.local_devices()[:1])
    print(json.dumps({
        "n_devices": len(jax.local_devices()),
        "late": late,
        "shards": len(sharded.ys.sharding.device_set) if hasattr(sharded.ys, "sharding") else 1,
        "shape": list(sharded.ys.shape),
        "max_rel_diff": float(np.max(np.abs(np.asarray(sharded.ys) - np.asarray(one.ys)) / np.max(np.abs(np.asarray(one.ys)), axis=(0, 1)))),
        "ys": np.asarray(sharded.ys)[:, -1, :].tolist(),
    }))
    """
)


def test_sharded_sweep_over_4_cpu_devices_equals_unsharded():
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["n_devices"] == 4
    assert out["late"] is not None and "already started with 4 device(s)" in out["late"], out["late"]
    assert out["shards"] == 4
    assert out["shape"] == [10, 31, 5]
    # the same program on each slice: equal to rounding (XLA may fuse differently per batch size)
    assert out["max_rel_diff"] <= 1e-12
    # and both equal an independent closed-form solve of the same scenes (in this process)
    model = jb.BeltStartup()
    ts = jnp.linspace(0.0, 0.3, 31)
    for g, y in zip(np.linspace(0.01, 0.08, 10), out["ys"]):
        ref = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts), method="modal").ys[-1]
        np.testing.assert_allclose(y, np.asarray(ref), rtol=1e-6, atol=1e-9)


def test_a_small_sweep_compiles_quick_and_a_large_one_with_xlas_defaults(monkeypatch):
    # at most QUICK_PER_DEVICE elements per device: XLA's quick options (the first call's compilation dominates);
    # more: XLA's defaults (the run dominates). The two programs give the same values to rounding, and both the
    # exact closed form's to the solver's tolerance
    from jaxbelt import batch

    used = []
    for name in ("_vmapped", "_vmapped_quick"):
        program = getattr(batch, name)
        monkeypatch.setattr(batch, name, lambda *a, _p=program, _n=name: used.append(_n) or _p(*a))
    model, ts = jb.BeltStartup(), jnp.linspace(0.0, 0.3, 31)

    def run(g):
        scene = jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts)
        return jb.simulate(scene, method="ode", rtol=1e-10, atol=1e-12, solver=diffrax.Tsit5(), throw=False).ys[-1]

    n = batch.QUICK_PER_DEVICE
    large = np.linspace(0.01, 0.08, n + 1)
    small_out = np.asarray(jb.sweep(run, jnp.asarray(large[:n]), devices=[jax.devices()[0]]))
    large_out = np.asarray(jb.sweep(run, jnp.asarray(large), devices=[jax.devices()[0]]))
    assert used == ["_vmapped_quick", "_vmapped"]
    np.testing.assert_allclose(small_out, large_out[:n], rtol=1e-12, atol=1e-12 * np.max(np.abs(large_out)))
    for g, y in zip(large[:: n // 4], large_out[:: n // 4]):
        ref = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts), method="modal").ys[-1]
        np.testing.assert_allclose(y, np.asarray(ref), rtol=1e-7, atol=1e-9)


def test_sweep_reports_failing_elements():
    ts = jnp.linspace(0.0, 0.2, 5)

    def run(p):
        gamma, L = p
        # an explicit solver on a 1e-8 H armature (pole -R/L = -1.5e7 1/s) exhausts its step
        # budget: those elements must fail and be named, the others succeed
        return jb.simulate(
            jb.Scene(jb.BeltStartup(L=L), jb.ExponentialVoltage(24.0, gamma), ts=ts),
            method="ode",
            solver=diffrax.Tsit5(),
            max_steps=2000,
            throw=False,
        )

    gammas = jnp.array([0.02, 0.03, 0.04, 0.05])
    inductances = jnp.array([2e-4, 1e-8, 2e-4, 1e-8])
    with pytest.raises(jb.SolveError) as e:
        jb.sweep(run, (gammas, inductances), name="start-up")
    msg = str(e.value)
    assert "2 of 4 elements failed" in msg
    assert "[1] (0.03, 1e-08)" in msg and "[3] (0.05, 1e-08)" in msg
    assert list(e.value.indices) == [1, 3]
    out = jb.sweep(run, (gammas, inductances), check=False)
    assert np.asarray(out.success).tolist() == [True, False, True, False]


def test_sweep_plain_function_and_bad_params():
    out = jb.sweep(lambda x: jnp.sin(x) ** 2, jnp.linspace(0.0, 1.0, 7))
    np.testing.assert_allclose(out, np.sin(np.linspace(0.0, 1.0, 7)) ** 2, rtol=1e-15)
    with pytest.raises(ValueError, match="different batch sizes"):
        jb.sweep(lambda p: p[0] + p[1], (jnp.ones(3), jnp.ones(4)))
    with pytest.raises(ValueError, match="leading batch axis"):
        jb.sweep(lambda p: p, jnp.asarray(1.0))


def test_sweep_with_an_out_of_range_parameter_raises_naming_it():
    # the user's function builds a command with a traced gamma: the element with gamma < 0 fails its check inside
    # the compiled sweep, which comes back as a ValueError naming the parameter and the sweep
    ts = jnp.linspace(0.0, 0.1, 11)

    def run(g):
        return jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, g), ts=ts)).ys

    with pytest.raises(ValueError, match=r"sweep: .*gamma.*in 'run'"):
        jb.sweep(run, jnp.array([0.02, -0.01]))
    np.testing.assert_allclose(  # the valid elements alone give the closed form's values
        np.asarray(jb.sweep(run, jnp.array([0.02]))[0]),
        np.asarray(jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.02), ts=ts)).ys),
        rtol=1e-12,
    )
