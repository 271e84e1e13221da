"""Scene shortcuts give the same answer as the full computation (speed-ups: benchmarks/startup.py).

- final state only (`Scene(..., t1=T)`, no dense buffer) == last row of the dense solve;
- closed form (no stepping) == time stepping at tight tolerance;
- outputs not named in `observe` are never computed (traced) and the state is unchanged.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sl

import jaxbelt as jb

V, GAMMA, T = 24.0, 0.02, 0.5
TS = jnp.linspace(0.0, T, 101)


def reference_final(model):
    """x(T) by scipy.linalg.expm of the augmented system (independent)."""
    A, B = (np.asarray(a) for a in model.matrices())
    Aa = np.zeros((7, 7))
    Aa[:5, :5] = A
    Aa[:5, 5] = V * B[:, 1]
    Aa[:5, 6] = -V * B[:, 1]
    Aa[6, 6] = -1.0 / GAMMA
    z0 = np.zeros(7)
    z0[5] = z0[6] = 1.0
    return (sl.expm(Aa * T) @ z0)[:5]


@pytest.mark.parametrize("method", ["expm", "modal", "ode"])
def test_final_state_only_equals_last_row_of_dense_solve(method):
    model = jb.BeltStartup()
    kw = dict(solver=diffrax.Tsit5(), rtol=1e-10, atol=1e-12) if method == "ode" else {}
    dense = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V, GAMMA), ts=TS), method=method, **kw)
    final = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V, GAMMA), t1=T), method=method, **kw)
    assert final.ys.shape == (1, 5)
    scale = np.max(np.abs(np.asarray(dense.ys)), axis=0)
    # ode and modal: the same steps / formula either way, equal to rounding; expm: one exponential
    # e^{A T} instead of a 100-step product, equal to its rounding (measured 2e-12)
    same = 1e-11 if method == "expm" else 1e-12
    assert np.max(np.abs(np.asarray(final.ys[-1] - dense.ys[-1])) / scale) < same
    tol = 1e-8 if method == "ode" else 1e-11
    assert np.max(np.abs(np.asarray(final.ys[-1]) - reference_final(model)) / scale) < tol


def test_closed_form_equals_stepping():
    model = jb.BeltStartup()
    scene = jb.Scene(model, jb.ExponentialVoltage(V, GAMMA), ts=TS)
    closed = jb.simulate(scene)
    assert closed.method == "expm"  # the default for this linear scene: no stepping
    modal = jb.simulate(scene, method="modal")
    stepped = jb.simulate(scene, method="ode", solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-14)
    scale = np.max(np.abs(np.asarray(stepped.ys)), axis=0)
    assert np.max(np.max(np.abs(np.asarray(closed.ys - stepped.ys)), axis=0) / scale) < 1e-9
    assert np.max(np.max(np.abs(np.asarray(modal.ys - closed.ys)), axis=0) / scale) < 1e-10


def test_unobserved_outputs_are_not_computed(monkeypatch):
    calls = {"electric_power": 0, "alpha2": 0}
    orig_p, orig_a = jb.BeltStartup._out_electric_power, jb.BeltStartup._out_alpha

    def spy_p(self, t, y, inp):
        calls["electric_power"] += 1
        return orig_p(self, t, y, inp)

    def spy_a(self, t, y, inp):  # the family alpha1, alpha2 (one method for the vector)
        calls["alpha2"] += 1
        return orig_a(self, t, y, inp)

    monkeypatch.setattr(jb.BeltStartup, "_out_electric_power", spy_p)
    monkeypatch.setattr(jb.BeltStartup, "_out_alpha", spy_a)
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(V, GAMMA + 1e-3)  # a gamma no other test compiled for
    only = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=("current",)))
    assert calls == {"electric_power": 0, "alpha2": 0}
    assert set(only.outputs) == {"current"}
    both = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=("current", "electric_power", "alpha2")))
    assert calls["electric_power"] >= 1 and calls["alpha2"] >= 1
    np.testing.assert_array_equal(np.asarray(only.ys), np.asarray(both.ys))
    # the observed outputs against their definitions (Incerti, 2014, Fig. 3c, 3h), from the state
    I = np.asarray(both.ys[:, 4])
    v = V * (1 - np.exp(-np.asarray(TS) / (GAMMA + 1e-3)))
    np.testing.assert_allclose(both.electric_power, v * I, rtol=1e-12, atol=1e-12)
    A, _ = model.matrices()
    alpha2 = np.asarray(both.ys) @ np.asarray(A)[3]  # tau_r0 = 0: no constant term
    np.testing.assert_allclose(both.alpha2, alpha2, rtol=1e-9, atol=1e-9 * np.max(np.abs(alpha2)))


def test_unobserved_outputs_shrink_the_program():
    model = jb.BeltStartup()

    def size(observe):
        f = lambda g: jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V, g), ts=TS, observe=observe))  # noqa: E731
        jaxpr = jax.make_jaxpr(f)(jnp.asarray(GAMMA))
        return sum(
            len(e.params["jaxpr"].eqns) if "jaxpr" in e.params and hasattr(e.params["jaxpr"], "eqns") else 1
            for e in jaxpr.eqns
        )

    n0 = size(())
    n_all = size(("electric_power", "mechanical_power", "alpha1", "alpha2", "kinetic_energy", "elastic_energy"))
    assert n_all > n0 + 10


# --- asked-only outputs: a scene without the state computes and stores only what its outputs read ------------


def test_output_components_read_from_the_outputs_program():
    from jaxbelt.fast import output_components

    model, cmd = jb.BeltStartup(), jb.ExponentialVoltage(V, GAMMA)
    # state order: theta1, theta2, omega1, omega2, current
    assert output_components(model, ("current",), cmd, 0.1) == (4,)
    assert output_components(model, ("electric_power",), cmd, 0.1) == (4,)  # V(t) I: the voltage reads no state
    assert output_components(model, ("mechanical_power",), cmd, 0.1) == (2, 4)
    assert output_components(model, ("kinetic_energy", "theta2"), cmd, 0.1) == (1, 2, 3)
    assert output_components(model, ("voltage",), cmd, 0.1) == ()
    assert output_components(model, ("alpha2",), cmd, 0.1) == (0, 1, 2, 3, 4)  # A @ y: every component
    assert output_components(model, (), cmd, 0.1) == (0, 1, 2, 3, 4)


@pytest.mark.parametrize(
    "model", [jb.BeltStartup(), jb.BeltStartup(tau_r0=2.0, L=1e-7)], ids=["tableI", "load,L=1e-7H"]
)
def test_batch_without_state_equals_the_full_state_run(model):
    gammas = jnp.concatenate([jnp.linspace(0.005, 0.1, 37), jnp.array([0.02])])
    names = tuple(n for n in model.available_outputs() if n not in model.integral_names())
    full = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V, gammas), ts=TS, observe=names))
    # one output of each way an output reads the state (`test_output_components` above): a state component, the
    # current, none (the voltage), a product with the input, a quadratic form of several, every component (A @ y);
    # each is one compiled program, and the rest read the state the same ways
    for name in ("theta2", "current", "voltage", "electric_power", "mechanical_power", "kinetic_energy", "alpha2"):
        assert name in names
        one = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(V, gammas), ts=TS, observe=(name,), state=False))
        assert one.ys is None and set(one.outputs) == {name}
        np.testing.assert_array_equal(np.asarray(one.success), np.asarray(full.success))
        ref = np.asarray(full.outputs[name])
        np.testing.assert_allclose(one.outputs[name], ref, rtol=1e-13, atol=1e-13 * np.max(np.abs(ref)))


def test_batch_success_is_false_where_what_is_returned_is_not_finite():
    # the batched closed form itself (no parameter checks: those come with simulate): a NaN time constant gives a
    # NaN trajectory; without the state, `success` reads the outputs it returns
    from jaxbelt.fast import batched_exponential_scene

    gammas = jnp.array([0.02, jnp.nan, 0.05])

    def run(observe, state):
        return jax.jit(
            lambda g: batched_exponential_scene(
                jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(V, g), ts=TS, observe=observe, state=state)
            )
        )(gammas)

    for observe, state in (((), True), (("electric_power",), False), (("current", "omega2"), False)):
        sol = run(observe, state)
        np.testing.assert_array_equal(np.asarray(sol.success), [True, False, True])


def test_batch_without_state_computes_only_the_components_read():
    from jaxbelt.fast import batched_exponential_scene

    model, gammas = jb.BeltStartup(), jnp.linspace(0.01, 0.1, 16)

    def largest_array(observe, state):
        scene = jb.Scene(model, jb.ExponentialVoltage(V, gammas), ts=TS, observe=observe, state=state)
        text = jax.jit(batched_exponential_scene).lower(scene).compile().as_text()
        return max(text.count(f"f64[16,{TS.shape[0]},{k}]") and k for k in range(1, 6))

    assert largest_array(("electric_power",), False) == 1  # the current alone
    assert largest_array(("mechanical_power",), False) == 2
    assert largest_array(("electric_power",), True) == 5


@pytest.mark.parametrize("method", ["ode", "rk4"])
def test_ode_without_state_stores_only_the_outputs(method):
    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    ts = jnp.linspace(0.0, 0.5, 101)
    names = ("motor_speed", "voltage")
    full = jb.simulate(jb.Scene(drive, pid, ts=ts, observe=names), method=method, dt=1e-3)
    one = jb.simulate(jb.Scene(drive, pid, ts=ts, observe=names, state=False), method=method, dt=1e-3)
    assert one.ys is None
    assert int(one.stats["num_steps"]) == int(full.stats["num_steps"])  # the same solve
    for n in names:
        ref = np.asarray(full.outputs[n])
        np.testing.assert_allclose(one.outputs[n], ref, rtol=1e-13, atol=1e-13 * np.max(np.abs(ref)))
    # integrals: running values at the output times, as with the state
    model, cmd = jb.BeltStartup(), jb.ExponentialVoltage(V, GAMMA)
    names = ("current", "electric_energy", "copper_loss")
    full = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=names), method="ode")
    one = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=names, state=False), method="ode")
    for n in names:
        np.testing.assert_array_equal(one.outputs[n], full.outputs[n])
