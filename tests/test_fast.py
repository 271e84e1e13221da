"""The batched closed form of `jaxbelt.fast` against scipy's matrix exponential (independent)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from references import expm_reference, startup_reference

import jaxbelt as jb
from jaxbelt.fast import exp_input_batch, startup_gamma_batch

# one compilation per shape, shared by the tests (the model is a pytree argument)
gamma_batch = jax.jit(startup_gamma_batch, static_argnames=("n_fix", "chunk"))
exp_input_batch_jit = jax.jit(exp_input_batch)
TS = jnp.linspace(0.0, 0.3, 61)


def rel(x, ref):
    scale = np.maximum(np.max(np.abs(ref), axis=0), 1e-300)
    return float(np.max(np.max(np.abs(np.asarray(x) - ref), axis=0) / scale))


@pytest.mark.parametrize("params", [{}, {"L": 1e-7}, {"tau_r0": 2.0, "k": 1e8}], ids=["tableI", "L=1e-7H", "k=1e8"])
def test_gamma_batch_matches_expm_reference_including_resonance(params):
    model = jb.BeltStartup(**params)
    lam = np.linalg.eigvals(np.asarray(model.matrices()[0]))
    real_modes = sorted(-1.0 / lam[(np.imag(lam) == 0) & (np.real(lam) < -1)].real)
    g_res = real_modes[-1]  # gamma = -1/lambda: the input rate equals a real mode exactly
    gammas = np.array([0.02, 0.04, 0.06, g_res, g_res * (1 + 1e-6), g_res * (1 + 3e-3), 0.1, 0.005])
    xs = np.asarray(gamma_batch(model, jnp.asarray(gammas), TS))
    for i, g in enumerate(gammas):
        assert rel(xs[i], startup_reference(model, np.asarray(TS), 24.0, g)) < 1e-10, g


def test_gamma_batch_equals_vmapped_simulate():
    model = jb.BeltStartup(tau_r0=2.0)
    gammas = jnp.linspace(0.01, 0.08, 8)
    ref = jax.vmap(lambda g: jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=TS), method="expm").ys)(
        gammas
    )
    fast = gamma_batch(model, gammas, TS)
    assert rel(fast.reshape(-1, 5), np.asarray(ref).reshape(-1, 5)) < 1e-10


def test_many_near_resonant_elements_and_chunking():
    # more near-resonant elements than n_fix: the correction covers the whole chunk; chunks of 3
    # (8 = 3 x 3 - 1: one padded element) give the same numbers as one chunk
    model = jb.BeltStartup()
    lam = np.linalg.eigvals(np.asarray(model.matrices()[0]))
    g_res = -1.0 / sorted(lam[(np.imag(lam) == 0) & (np.real(lam) < -1)].real)[-1]
    gammas = g_res * (1 + jnp.linspace(-1e-3, 1e-3, 8))
    xs = np.asarray(gamma_batch(model, gammas, TS, n_fix=2))
    for i, g in enumerate(np.asarray(gammas)):
        assert rel(xs[i], startup_reference(model, np.asarray(TS), 24.0, g)) < 1e-10
    chunked = np.asarray(gamma_batch(model, gammas, TS, n_fix=2, chunk=3))
    assert chunked.shape == xs.shape
    assert np.max(np.abs(chunked - xs)) <= 1e-13 * np.max(np.abs(xs))


def test_a_large_batch_is_written_by_chunks_with_the_same_numbers(monkeypatch):
    # a batch whose exponentials exceed one pass's budget is written by equal chunks (the last one overlapping its
    # predecessor): the same numbers as one pass, and each element the independent reference's, resonance included
    from jaxbelt import fast

    model = jb.BeltStartup()
    lam = np.linalg.eigvals(np.asarray(model.matrices()[0]))
    g_res = -1.0 / sorted(lam[(np.imag(lam) == 0) & (np.real(lam) < -1)].real)[-1]
    gammas = jnp.asarray(np.r_[np.linspace(0.005, 0.1, 36), g_res])  # 37 elements
    one_pass = np.asarray(jax.jit(lambda g: startup_gamma_batch(model, g, TS))(gammas))
    monkeypatch.setattr(fast, "_PASS_ELEMENTS", 10 * TS.shape[0])  # 4 chunks of 10: the last overlaps by 3
    chunked = np.asarray(jax.jit(lambda g: startup_gamma_batch(model, g, TS))(gammas))
    np.testing.assert_allclose(chunked, one_pass, rtol=0, atol=1e-13 * np.max(np.abs(one_pass)))
    for i in (0, 29, 35, 36):
        assert rel(chunked[i], startup_reference(model, np.asarray(TS), 24.0, float(gammas[i]))) < 1e-10


def test_a_batch_of_100_000_needs_little_memory_beside_its_output():
    # XLA keeps the input's exponentials e^{s_b t} whole in one pass (a fifth of the output for 10^5 x 501):
    # the chunks bound them; the compiled program's temporaries stay under 10 % of its output
    ts = jnp.linspace(0.0, 0.5, 501)
    g = jax.ShapeDtypeStruct((100_000,), jnp.float64)
    compiled = jax.jit(lambda g: startup_gamma_batch(jb.BeltStartup(), g, ts)).lower(g).compile()
    mem = compiled.memory_analysis()
    assert mem.temp_size_in_bytes < 0.1 * mem.output_size_in_bytes, (mem.temp_size_in_bytes, mem.output_size_in_bytes)


@pytest.mark.parametrize(
    "A, s_var",
    [
        (np.array([[-10.0, 0.0], [0.0, -10.02]]), np.array([-10.01, -3.0])),  # two modes near one rate: exact form
        (np.array([[-5.0, 1.0], [0.0, -5.0]]), np.array([-5.0, -1.0])),  # defective A (Jordan block): expm form
    ],
)
def test_fallbacks_match_reference(A, s_var):
    F = np.array([[1.0], [0.5]])
    s = np.array([0.0])
    f = np.array([0.3, -1.0])
    x0 = np.array([0.2, 0.1])
    ts = np.linspace(0.0, 1.0, 21)
    xs = np.asarray(
        exp_input_batch_jit(  # one program for both cases (as `simulate` runs it), not ~hundreds of eager ops
            jnp.asarray(A),
            jnp.asarray(F),
            jnp.asarray(s),
            jnp.asarray(x0),
            0.0,
            jnp.asarray(ts),
            jnp.asarray(f),
            jnp.asarray(s_var),
        )
    )
    for i, sv in enumerate(s_var):
        ref = expm_reference(A, np.concatenate([F, f[:, None]], axis=1), np.array([0.0, sv]), x0, ts)
        assert rel(xs[i], ref) < 1e-10


def test_gamma_batch_gradient_matches_finite_differences():
    model = jb.BeltStartup()

    @jax.jit
    def f(gs):
        return jnp.sum(startup_gamma_batch(model, gs, TS)[:, -1, 3])

    gs = jnp.array([0.02, 0.03])
    g = jax.jit(jax.grad(f))(gs)
    h = 1e-6
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        fd = (f(gs + e) - f(gs - e)) / (2 * h)
        assert abs(g[i] - fd) < 1e-6 * abs(fd)


def test_batched_command_scene_equals_vmapped_simulate():
    from jaxbelt.fast import batched_exponential_scene

    model = jb.BeltStartup()
    gammas = jnp.array([0.02, 0.04, 0.06])
    # compiled as `simulate` compiles it (eqx.filter_jit): one program instead of ~220 eager operations
    sol = eqx.filter_jit(batched_exponential_scene)(
        jb.Scene(model, jb.ExponentialVoltage(24.0, gammas), ts=TS, observe=("electric_power", "alpha2"))
    )
    ref = jax.vmap(
        lambda g: jb.simulate(
            jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=TS, observe=("electric_power", "alpha2")), method="expm"
        )
    )(gammas)
    assert sol.ys.shape == (3, 61, 5) and sol.method == "fast"
    assert rel(sol.ys.reshape(-1, 5), np.asarray(ref.ys).reshape(-1, 5)) < 1e-10
    for name in ("electric_power", "alpha2"):
        np.testing.assert_allclose(sol[name], ref[name], rtol=1e-9, atol=1e-9 * float(np.max(np.abs(ref[name]))))
    assert np.asarray(sol.success).tolist() == [True, True, True]
    # a scalar gamma is not a batch: the caller solves it as usual
    assert batched_exponential_scene(jb.Scene(model, jb.ExponentialVoltage(24.0, 0.02), ts=TS)) is None


def test_simulate_routes_a_batch_of_gammas_to_the_fast_path():
    """`ExponentialVoltage(v, gammas)` with a 1-D gammas array is a batch: `simulate` solves it at
    once; each element equals the scalar closed form, outputs included; other methods say how."""
    model = jb.BeltStartup()
    gammas = jnp.array([0.01, 0.0105, 0.03, 0.06])  # 0.0105 s: next to the -95.27 1/s eigenvalue
    sol = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, gammas), ts=TS, observe=("electric_power",)))
    assert sol.method == "fast" and sol.ys.shape == (4, TS.shape[0], 5)
    for i, g in enumerate(np.asarray(gammas)):
        one = jb.simulate(
            jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=TS, observe=("electric_power",)), method="expm"
        )
        np.testing.assert_allclose(sol.ys[i], one.ys, rtol=0, atol=1e-10 * float(jnp.max(jnp.abs(one.ys))))
        np.testing.assert_allclose(
            sol.electric_power[i], one.electric_power, rtol=0, atol=1e-10 * float(jnp.max(jnp.abs(one.electric_power)))
        )
    with pytest.raises(ValueError, match="jax.vmap over scalar commands"):
        jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, gammas), ts=TS), method="ode")


def test_expm1_from_exp_is_as_accurate_as_expm1():
    # e^x - 1 from the exponential the batch's pass computes anyway: against numpy's expm1 (an independent
    # implementation), relative error no larger than XLA's own expm1 on the same points (2.9e-16 and 6.2e-16
    # measured over negative x; the pass sees x = -(t - t0)/gamma <= 0)
    from jaxbelt.fast import expm1_from_exp

    ours = jax.jit(lambda x: expm1_from_exp(x, jnp.exp(x)))
    for x in (-np.logspace(-14, 2.5, 200_001), np.logspace(-14, 0.5, 50_001)):
        ref = np.expm1(x)
        err = np.max(np.abs(np.asarray(ours(x)) - ref) / np.abs(ref))
        xla = np.max(np.abs(np.asarray(jax.jit(jnp.expm1)(x)) - ref) / np.abs(ref))
        assert err <= max(xla, 2.3e-16) and err < 4e-16, (err, xla)
    # the polynomial never sees a large argument: finite values and derivatives everywhere
    x = jnp.array([0.0, -0.3, -0.5, -1e3, -1e300])
    np.testing.assert_array_equal(np.isfinite(jax.vmap(jax.grad(lambda x: expm1_from_exp(x, jnp.exp(x))))(x)), True)


def _power_reference(model, ts, gamma, t0=0.0, v_max=24.0):
    """Electric power V I of a start-up from rest at t0 under V = V_max (1 - e^{-t/gamma}) (absolute t), from the
    matrix exponential reference and numpy's expm1."""
    A, B = (np.asarray(a, dtype=float) for a in model.matrices())
    const = B[:, 0] * float(model.tau_r0) + v_max * B[:, 1]
    F = np.stack([const, -v_max * np.exp(-t0 / gamma) * B[:, 1]], axis=1)
    xs = expm_reference(A, F, np.array([0.0, -1.0 / gamma]), np.zeros(A.shape[0]), ts - t0)
    return -v_max * np.expm1(-ts / gamma) * xs[:, -1]


@pytest.mark.parametrize("t0", [0.0, 0.05])
def test_one_output_in_the_pass_matches_the_reference_at_resonance_and_by_chunks(monkeypatch, t0):
    # without the state, the output is computed in the pass (its voltage from the pass's exponential): each element
    # against the independent reference, an element at resonance (corrected, computed again) and a start at t0 > 0
    # included; the same numbers when the batch is written by chunks
    from jaxbelt import fast

    model = jb.BeltStartup()
    lam = np.linalg.eigvals(np.asarray(model.matrices()[0]))
    g_res = -1.0 / sorted(lam[(np.imag(lam) == 0) & (np.real(lam) < -1)].real)[-1]
    gammas = jnp.asarray(np.r_[np.linspace(0.005, 0.1, 36), g_res])
    ts = TS + t0

    def power(g):
        scene = jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts, observe=("electric_power",), state=False)
        return fast.batched_exponential_scene(scene)["electric_power"]

    one_pass = np.asarray(jax.jit(power)(gammas))
    for i in (0, 17, 35, 36):
        ref = _power_reference(model, np.asarray(ts), float(gammas[i]), t0)
        np.testing.assert_allclose(one_pass[i], ref, rtol=0, atol=1e-10 * np.max(np.abs(ref)))
    monkeypatch.setattr(fast, "_PASS_ELEMENTS", 10 * TS.shape[0])  # 4 chunks of 10: the last overlaps by 3
    chunked = np.asarray(jax.jit(power)(gammas))
    np.testing.assert_allclose(chunked, one_pass, rtol=0, atol=1e-13 * np.max(np.abs(one_pass)))


def test_one_output_gradient_matches_finite_differences():
    model = jb.BeltStartup()

    @jax.jit
    def f(gs):
        scene = jb.Scene(model, jb.ExponentialVoltage(24.0, gs), ts=TS, observe=("electric_power",), state=False)
        return jnp.sum(jb.simulate(scene)["electric_power"][:, 10])

    # one program gives the gradient and the values the differences take (f's own value, the same function)
    value_and_grad = jax.jit(jax.value_and_grad(f))
    gs = np.array([0.02, 0.03])
    g = value_and_grad(gs)[1]
    h = 1e-6
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        fd = (value_and_grad(gs + e)[0] - value_and_grad(gs - e)[0]) / (2 * h)
        assert abs(g[i] - fd) < 1e-6 * abs(fd)


def _second_state_scaled(xs, a, em1):
    return {"y": xs[..., 1] * a[:, None], "em1": em1}


exp_input_batch_post = jax.jit(exp_input_batch, static_argnames="post")


@pytest.mark.parametrize(
    "A, s_var",
    [
        (np.array([[-10.0, 0.0], [0.0, -10.02]]), np.array([-10.01, -3.0])),  # two modes near one rate: exact form
        (np.array([[-5.0, 1.0], [0.0, -5.0]]), np.array([-5.0, -1.0])),  # defective A (Jordan block): expm form
    ],
)
def test_fallbacks_apply_post_to_their_states(A, s_var):
    # `post` receives the states and the input's e^{s tau} - 1 in every form, the fall-backs included
    F, s, f, x0 = np.array([[1.0], [0.5]]), np.array([0.0]), np.array([0.3, -1.0]), np.array([0.2, 0.1])
    ts = np.linspace(0.0, 1.0, 21)
    args = [jnp.asarray(a) for a in (A, F, s, x0)] + [0.0, jnp.asarray(ts), jnp.asarray(f), jnp.asarray(s_var)]
    got = exp_input_batch_post(*args, post=_second_state_scaled, post_args=2 * s_var)  # one program for both cases
    for i, sv in enumerate(s_var):
        ref = expm_reference(A, np.concatenate([F, f[:, None]], axis=1), np.array([0.0, sv]), x0, ts)
        np.testing.assert_allclose(got["y"][i], 2 * sv * ref[:, 1], rtol=0, atol=1e-10 * np.max(np.abs(ref)))
        np.testing.assert_allclose(got["em1"][i], np.expm1(sv * ts), rtol=4e-16, atol=0)


def test_an_output_that_reads_more_of_its_command_than_its_value():
    # an output that reads a command's parameter (not only its value) is computed with the command itself
    from jaxbelt._model import observable

    class Drive(jb.BeltStartup):
        @observable("voltage_over_gamma")
        def _out_voltage_over_gamma(self, t, y, inp):
            return inp(t) / inp.gamma * y[-1]

    model, gammas = Drive(), jnp.array([0.02, 0.05])
    one = jb.simulate(
        jb.Scene(model, jb.ExponentialVoltage(24.0, gammas), ts=TS, observe=("voltage_over_gamma",), state=False)
    )
    full = jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, gammas), ts=TS, observe=("electric_power",)))
    np.testing.assert_allclose(
        one["voltage_over_gamma"], full["electric_power"] / gammas[:, None], rtol=1e-13, atol=1e-13 * 24 * 100
    )
