"""The suite compiles with XLA's quicker CPU settings (conftest.py: classic emitters, LLVM level 0).
Each kind of program gives the same numbers, to rounding, in a process with XLA's default settings:
the matrix-exponential closed form, an adaptive ODE solve, fixed-step RK4, the Gauss-Legendre
residual energy, the non-linear four-bar under PID."""

import json
import os

import numpy as np
import pytest

# one program of each kind; leaves a dict of lists of floats in `out`
PROBE = r"""
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb

out = {}
ts = jnp.linspace(0.0, 0.3, 61)
scene = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.04), ts=ts)
for method in ("expm", "ode", "rk4"):
    kw = dict(dt=1e-4) if method == "rk4" else {}
    sol = jb.simulate(scene, method=method, **kw)
    out[f"startup_{method}"] = [float(sol["omega1"][-1]), float(sol["current"][20])]
plat = jb.BeltPlatform()
cmd = jb.PseudoPolynomial(gammas=jnp.array([3.0, 4.3, 5.1]))
out["residual_energy"] = [float(jb.residual_energy(plat, cmd))]
fb = jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(), ts=jnp.linspace(0.0, 0.5, 101)))
out["fourbar_pid"] = [float(fb.alpha_dot[-1]), float(jb.fluctuation_index(fb, 0.375, 0.5))]
"""


def _run_with_xla_flags(flags: str) -> dict:
    from test_coldstart import _subprocess

    stdout = _subprocess(PROBE + '\nimport json\nprint("RESULT " + json.dumps(out))\n', XLA_FLAGS=flags)
    line = next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def test_fast_compile_flags_change_results_only_by_rounding():
    """The probe in this test process (the suite's flags) against a process with the caller's XLA
    settings (XLA's defaults unless the caller set XLA_FLAGS). Measured: 1e-15 to 2e-13 relative."""
    from jaxbelt._xla import FAST_COMPILE_FLAGS

    if not set(FAST_COMPILE_FLAGS) <= set(os.environ.get("XLA_FLAGS", "").split()):
        pytest.skip(
            "the suite runs with XLA's default settings (JAXBELT_TEST_XLA_DEFAULTS=1, or an XLA without these flags)"
        )
    ns = {}
    exec(PROBE, ns)  # noqa: S102 - the probe above, in this process
    quick = ns["out"]
    default = _run_with_xla_flags(os.environ.get("JAXBELT_TEST_CALLER_XLA_FLAGS", ""))
    assert default.keys() == quick.keys()
    for k in default:
        # adaptive solvers could take another step after a last-bit difference (their tolerance,
        # 1e-8 relative and below, then bounds the change); the other programs agree to 1e-11
        rtol = 1e-8 if k in ("startup_ode", "fourbar_pid") else 1e-11
        np.testing.assert_allclose(quick[k], default[k], rtol=rtol, atol=1e-14, err_msg=k)
