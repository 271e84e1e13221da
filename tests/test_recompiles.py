"""No recompiles for the same program: public functions that take a user's function key their compiled
programs by its code and values (`jaxbelt._callables.by_value`), not by the function object; time grids of
any spacing are data. The tests count XLA compilations (`compiles.count_compiles`), not time."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from compiles import count_compiles

import jaxbelt as jb
from jaxbelt._callables import ByValue, by_value

TS = jnp.linspace(0.0, 0.3, 31)
MODEL = jb.BeltStartup()


def _swept(gammas):
    # a fresh lambda at every call, as a loop or a re-run notebook cell makes it
    return jb.sweep(lambda g: jb.simulate(jb.Scene(MODEL, jb.ExponentialVoltage(24.0, g), ts=TS)).ys, gammas)


def test_sweep_with_a_fresh_lambda_of_the_same_code_compiles_once():
    gammas = jnp.linspace(0.01, 0.05, 8)
    first = _swept(gammas)
    new = gammas * 1.5
    with count_compiles() as c:
        again = _swept(gammas)
        other = _swept(new)  # new values of the same shape: data
    assert c["n"] == 0
    np.testing.assert_array_equal(first, again)
    ref = jax.vmap(lambda g: jb.simulate(jb.Scene(MODEL, jb.ExponentialVoltage(24.0, g), ts=TS)).ys)(new)
    np.testing.assert_allclose(other, ref, rtol=1e-12, atol=1e-12)


def test_sweep_of_the_documented_pattern_compiles_once_and_sees_new_closure_values():
    # docs/sweeps.md: chi of PID gain sets, the drive and regulator closed over
    drive = jb.FourBarDrive()
    gains = jnp.array([80.0, 32.0, 0.015]) * jnp.exp(jnp.linspace(-0.3, 0.3, 4))[:, None]

    def chi(pid):
        return jb.sweep(
            lambda g: jb.fluctuation_objective(drive, pid.with_gains(g), smooth=False, rtol=1e-6, atol=1e-6), gains
        )

    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
    a = chi(pid)
    with count_compiles() as c:
        b = chi(jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0))  # an equal regulator, a new object
    assert c["n"] == 0
    np.testing.assert_array_equal(a, b)
    # a different value closed over is never served the old program: here the set point changes chi
    other = chi(jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=25.0))
    assert not np.allclose(other, a)


def test_keys_follow_code_and_values():
    a, b = jnp.arange(3.0), jnp.arange(3.0)

    def make(x, k):
        return lambda t: jnp.sin(t) * x + k

    assert by_value(make(a, 2.0)) == by_value(make(b, 2.0))  # equal arrays, equal numbers
    assert by_value(make(a, 2.0)) != by_value(make(a, 3.0))
    assert by_value(make(a, 2.0)) != by_value(make(a + 1, 2.0))
    assert by_value(make(a, 2)) != by_value(make(a, 2.0))  # an int is not a float
    assert by_value(lambda t: t + 1) != by_value(lambda t: t + 2)  # other code
    # defaults, keyword defaults, partials and the user's helpers count too
    assert by_value(functools.partial(jnp.add, 1.0)) == by_value(functools.partial(jnp.add, 1.0))
    assert by_value(functools.partial(jnp.add, 1.0)) != by_value(functools.partial(jnp.add, 2.0))

    def helper(scale):
        return lambda t: t * scale

    def outer(h):
        return lambda t: h(t) + 1

    assert by_value(outer(helper(2.0))) == by_value(outer(helper(2.0)))
    assert by_value(outer(helper(2.0))) != by_value(outer(helper(3.0)))
    # optax transformations are closures of the library: keyed by their hyperparameters
    assert jax.tree_util.tree_map(by_value, optax.adam(0.1)) == jax.tree_util.tree_map(by_value, optax.adam(0.1))
    # the wrapped function is the function
    f = by_value(make(a, 2.0))
    assert isinstance(f, ByValue)
    np.testing.assert_array_equal(f(1.0), jnp.sin(1.0) * a + 2.0)


W = jnp.array(2.0)


def _reads_w():
    return lambda t: t * W  # one code object: each call makes a new function of it


def test_globals_are_part_of_the_key():
    global W
    f1 = by_value(_reads_w())
    assert by_value(_reads_w()) == f1
    W = jnp.array(3.0)
    assert by_value(_reads_w()) != f1  # a global read by the function changed: a new key
    W = jnp.array(2.0)
    assert by_value(_reads_w()) == f1


def test_values_that_cannot_be_keyed_keep_the_identity():
    class Opaque:
        __hash__ = None  # unhashable and no attributes to read

        __slots__ = ()

    o = Opaque()
    f = lambda t: (t, o)  # noqa: E731
    assert by_value(f) is f
    # a tracer of the caller's jit: the function as it is
    seen = []
    jax.jit(lambda x: seen.append(by_value(lambda t: t + x)) or x)(1.0)
    assert not isinstance(seen[0], ByValue)


def test_identify_with_a_fresh_lambda_compiles_once():
    ts = jnp.linspace(0.0, 0.5, 51)
    obs = ("omega2",)

    def data_for(R):
        scene = jb.Scene(jb.BeltStartup(R=R), jb.ExponentialVoltage(24.0, 0.02), ts=ts, observe=obs, state=False)
        return jb.simulate(scene).outputs["omega2"]

    data = data_for(0.15)

    def fit(r0, y):
        return jb.identify(lambda q: data_for(q["R"]), {"R": r0}, y).params["R"]

    assert fit(0.2, data) == pytest.approx(0.15, rel=1e-9)
    noisy = np.asarray(data) * (1 + 1e-4 * np.sin(np.arange(data.size)))
    with count_compiles() as c:
        r = fit(0.25, noisy)  # other start, other data: the same program
    assert c["n"] == 0
    assert r == pytest.approx(0.15, rel=1e-3)


def test_identify_second_identical_call_traces_and_compiles_nothing():
    """The start-up fit of the first-call table, its grid built inside `predict` (traced there): a second
    identical call runs the stored program (no trace, no compilation) and finds the fit of a closed-over grid."""
    data = np.asarray(
        jb.simulate(
            jb.Scene(
                jb.BeltStartup(k=120e3, c=20.0, R=0.15),
                jb.ExponentialVoltage(24.0, 0.02),
                ts=jnp.linspace(0.0, 0.3, 301),
            )
        ).ys[:, :2]
    )
    data = data + 1e-3 * np.sin(np.arange(data.size)).reshape(data.shape)

    def fit(inside):
        def predict(p):
            ts = jnp.linspace(0.0, 0.3, 301) if inside else TS301
            scene = jb.Scene(
                jb.BeltStartup(k=p["k"], c=p["c"], R=p["R"]),
                jb.ExponentialVoltage(24.0, 0.02),
                ts=ts,
                uniform=None if inside else True,
            )
            return jb.simulate(scene).ys[:, :2]

        return jb.identify(predict, {"k": 80e3, "c": 30.0, "R": 0.2}, data, sigma=1e-3)

    with pytest.warns(jb.TracedGridWarning):
        first = fit(True)
    with count_compiles() as c:
        second = fit(True)
    assert (c["n"], c["traces"]) == (0, 0)
    assert second.params == first.params
    ref = fit(False)
    for name in ref.params:
        assert abs(first.params[name] - ref.params[name]) < 1e-6 * ref.stderr[name], name


TS301 = np.linspace(0.0, 0.3, 301)


def test_tune_pid_with_a_new_optax_transformation_of_the_same_rate_compiles_nothing():
    drive, pid = jb.FourBarDrive(), jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    kw = dict(t0=0.375, t1=0.5, steps=2, progress=False)
    a = jb.tune_pid(drive, pid, optimizer=optax.adam(0.07), **kw)
    with count_compiles() as c:
        b = jb.tune_pid(drive, pid, optimizer=optax.adam(0.07), **kw)
    assert c["n"] == 0
    np.testing.assert_array_equal(a.history["loss"], b.history["loss"])


@pytest.mark.parametrize("method", ["auto", "modal", "ode"])
def test_time_grids_of_any_spacing_are_data(method):
    rng = np.random.default_rng(0)
    uniform = np.linspace(0.0, 0.3, 41)
    grids = [uniform] + [np.sort(np.concatenate([[0.0, 0.3], rng.uniform(0.0, 0.3, 39)])) for _ in range(2)]
    cmd = jb.ExponentialVoltage(24.0, 0.02)
    kw = dict(rtol=1e-10, atol=1e-12) if method == "ode" else {}
    out = [jb.simulate(jb.Scene(MODEL, cmd, ts=grids[0]), method=method, **kw).ys]
    with count_compiles() as c:
        out += [jb.simulate(jb.Scene(MODEL, cmd, ts=g), method=method, **kw).ys for g in grids[1:]]
    assert c["n"] == 0
    # each grid's states are those of the exact solution at its own times
    for g, ys in zip(grids, out):
        ref = jb.simulate(jb.Scene(MODEL, cmd, ts=g, uniform=False), method="expm").ys
        np.testing.assert_allclose(ys, ref, rtol=1e-8, atol=1e-9 * float(np.max(np.abs(ref))))
