"""No recompiles for the same program: public functions that take a user's function key their compiled
programs by its code and values (`jaxbelt._callables.by_value`), not by the function object; time grids of
any spacing are data. The tests count XLA compilations (`compiles.count_compiles`), not time."""

import functools

import equinox as eqx
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


def _highs_minimax_value(problem, opts, scale):
    """The minimax LP's optimal value by scipy's HiGHS, in units of `scale`: independent of jaxbelt's interior point
    method (`references.highs_lp_value`)."""
    from references import highs_lp_value

    from jaxbelt.shaping import design as dsg

    return highs_lp_value(*dsg.lp_data(problem, opts, scale)) * scale


@pytest.mark.slow
def test_minimax_designs_whose_starting_grids_differ_share_one_program():
    # design_move's rule grows the starting grid with the move time: on a 6 Hz axis 15 points at 0.82 s, 17 at
    # 0.83 s (and another exchange); both pad to the same rows, so the second design compiles nothing
    from jaxbelt.shaping import design as dsg
    from jaxbelt.shaping.residual import reference_residuals

    axis = jb.ModalAxis([6.0], [0.02])
    ref, _ = reference_residuals(axis, 0.1, 0.3, 1.2, None, 0.2)
    designs = []
    for k, T in enumerate((0.82, 0.83)):
        opts = dsg.default_options(axis.frequencies, T, 0.2, False)
        assert opts.n_freq == (15, 17)[k]
        prob = dsg.make_problem(axis, 0.1, T, 0.3, 1.2, None, 0.2, ref, opts)
        with count_compiles() as c:
            designs.append((dsg.minimax_design(prob, opts), opts))
        if k == 1:
            assert c["n"] == 0
    for des, opts in designs:
        assert des.converged
        # the padding rows (mask 0) are never active: the optimum is HiGHS's on the same LP
        highs = _highs_minimax_value(des.problem, opts, float(des.worst))
        assert abs(float(des.worst) - highs) <= max(2e-6, 2 * float(des.gap)) * highs
        # the rows in use: the starting grid's n_freq points and those the exchange added, none in the padding
        mask = np.asarray(des.problem.mask)
        assert mask.shape[1] % dsg.GRID_BUCKET == 0 and not mask[:, opts.n_freq + opts.n_extra :].any()


@pytest.mark.slow
def test_minimax_designs_whose_knot_counts_differ_share_one_program():
    # the knot count follows the move time (on a 6 Hz axis 48 intervals at 1.1 s, 64 at 1.3 s; the starting grids,
    # 21 and 25 points, padded to `MAX_FREQ` = 41 and the extra rows): both LPs are padded to the slot of 128
    # (`design.knot_slots`), so the second design (its LP, feasibility LP and fine-grid check) compiles nothing, and
    # each is the optimum of its own unpadded LP. |a| <= 0.4 m/s^2: the time-optimal move takes 1 s, so the least
    # residuals are well above the LP's resolution (HiGHS checks them)
    from references import highs_lp_value

    from jaxbelt.shaping import design as dsg
    from jaxbelt.shaping.residual import reference_residuals

    axis = jb.ModalAxis([6.0], [0.02])
    ref, _ = reference_residuals(axis, 0.1, 0.3, 0.4, None, 0.2)
    designs = []
    for k, T in enumerate((1.1, 1.3)):
        opts = dsg.default_options(axis.frequencies, T, 0.2, False)
        assert (opts.n_knots, opts.n_freq) == ((48, 21), (64, 25))[k]
        assert dsg.knot_slots(opts.n_knots) == 128 and dsg.grid_slots(opts) == 56
        prob = dsg.make_problem(axis, 0.1, T, 0.3, 0.4, None, 0.2, ref, opts)
        with count_compiles() as c:
            assert dsg.max_distance(prob, opts) > 1.0
            designs.append((dsg.minimax_design(prob, opts), opts))
        if k == 1:
            assert c["n"] == 0
    for des, opts in designs:
        assert des.converged and float(des.worst) > 1e-6
        assert des.command.coefficients.shape == (opts.n_knots - 3,)
        # the multipliers come back in the unpadded LP's rows: the cut rows, +-a, +-v of the design's own size
        assert des.lp.z.shape == (opts.n_angles * des.problem.factors.size + 4 * (opts.n_knots - 3) - 2,)
        # HiGHS on the design's own (unpadded) LP
        scale = float(des.worst)
        highs = highs_lp_value(*dsg.lp_data(des.problem, opts, scale)) * scale
        assert abs(float(des.worst) - highs) <= max(2e-6, 2 * float(des.gap)) * highs


@pytest.mark.slow
def test_best_residual_after_design_move_runs_the_designs_own_program():
    # the LP's value at another move time runs the program the design compiled (its scalars typed alike: a weakly
    # typed tolerance keyed a second compilation of the interior point method, 17-30 s on two cores)
    from jaxbelt.shaping.codesign import _problem

    axis = jb.ModalAxis([6.0], [0.02])
    des = jb.design_move(axis, 0.1, 0.8, include=("minimax",), v_max=0.3, a_max=1.2, uncertainty=0.2).minimax
    with count_compiles() as c:
        v = float(jb.best_residual(axis, 0.82, des))
    assert c["n"] == 0
    # the value is the optimum of the LP on the design's grid at 0.82 s: HiGHS's on the same LP
    highs = _highs_minimax_value(_problem(des, axis, 0.82), des.options, float(des.worst))
    assert v == pytest.approx(highs, rel=1e-6)


@pytest.mark.slow
def test_shortest_move_time_warm_calls_with_other_targets_compile_nothing():
    # the answers 0.830 s and 0.789 s re-make the design with starting grids of 17 and 15 points (the given design,
    # at 0.8 s, has 15): one program for both
    axis = jb.ModalAxis([6.0], [0.02])
    lim = dict(v_max=0.3, a_max=1.2, uncertainty=0.2)
    des = jb.design_move(axis, 0.1, 0.8, include=("minimax",), **lim).minimax
    fw = float(des.fine_worst)
    jb.shortest_move_time(axis, 0.8 * fw, des)
    with count_compiles() as c:
        times = [float(jb.shortest_move_time(axis, k * fw, des)) for k in (0.5, 1.5)]
    assert c["n"] == 0
    assert times[0] > 0.8 > times[1]
    # each answer lands: design_move's own design there leaves the target within 1 % (fine grid)
    for k, T in zip((0.5, 1.5), times):
        again = jb.design_move(axis, 0.1, T, include=("minimax",), **lim).minimax
        assert float(again.fine_worst) == pytest.approx(k * fw, rel=1e-2)


@pytest.mark.slow
def test_residual_curves_of_pseudo_polynomials_of_any_order_up_to_8_share_one_program():
    # design_move's pseudo-polynomial candidates change order with the distance and the limits: the residual's
    # program pads the exponents, so a new order compiles nothing
    from references import modal_residual_reference

    from jaxbelt.shaping.residual import residual_curve

    axis = jb.ModalAxis([6.0, 17.0], [0.02, 0.01])
    factors = np.linspace(0.8, 1.2, 9)
    D, T = 0.1, 0.8
    orders = ([3.0, 4.0, 5.0], [3.2, 4.5, 5.1, 6.3], [8.0, 9.0, 10.2, 11.0, 12.5, 13.9, 15.0, 16.5])
    cmds = [jb.PseudoPolynomial(jnp.array(g), D, T) for g in orders]
    got = [np.asarray(residual_curve(axis, cmds[0], factors))]
    with count_compiles() as c:
        got += [np.asarray(residual_curve(axis, cmd, factors)) for cmd in cmds[1:]]
    assert c["n"] == 0
    for g, curve in zip(orders, got):
        g = np.asarray(g)
        # eq. (23) solved by numpy, the acceleration of phi = D (1 - sum C_i u^g_i), u = 1 - t / T
        Z = np.stack([np.prod([g - r for r in range(k)], axis=0) if k else np.ones_like(g) for k in range(g.size)])
        C = np.linalg.solve(Z, np.eye(g.size)[0])

        def accel(t, g=g, C=C):
            u = np.clip(1.0 - np.asarray(t)[..., None] / T, 0.0, 1.0)
            return -D / T**2 * np.sum(C * g * (g - 1) * u ** (g - 2), axis=-1)

        ref = modal_residual_reference([6.0, 17.0], [0.02, 0.01], [1.0, 1.0], accel, [], T, factors, nodes=16)
        # the Gauss-Legendre rule's accuracy: 1e-8 of the curve's largest value (the 17 Hz mode's residual is
        # 1e-4 of the 6 Hz mode's here)
        np.testing.assert_allclose(curve, ref, rtol=1e-6, atol=1e-7 * float(np.max(ref)))
    # and the curve's program is the plain integral (`residual_integral`, whose rule `_nodes_for` is the curve's
    # `NODE_SLOT` nodes here), to the rounding of its sums (the order-8 command's terms cancel to 1e-9 of the curve,
    # so its last bits show at 2e-9 of the curve's largest value, 5x below the rule's own accuracy checked above)
    from jaxbelt.shaping.residual import residual_integral

    w = 2 * np.pi * np.array([6.0, 17.0])[:, None] * factors
    z = np.array([0.02, 0.01])[:, None]
    wd = w * np.sqrt(1 - z**2)
    for cmd, curve in zip(cmds, got):
        plain = np.abs(np.asarray(residual_integral(cmd, jnp.asarray(-z * w + 1j * wd)))) / wd
        np.testing.assert_allclose(curve, plain, rtol=1e-12, atol=1e-8 * float(np.max(plain)))


def test_sampling_moves_of_other_durations_compiles_nothing():
    # a move of another duration has another sample count (1 kHz: 801, 811, 1001 samples): the times are padded to
    # a power of two, so the program that evaluates the command is compiled once
    rng = np.random.default_rng(3)

    def move(T):
        times = np.sort(rng.uniform(0.0, 0.5 * T, 6))
        return jb.PiecewiseMove(times, rng.normal(size=6), rng.normal(size=6), T)

    moves = [move(T) for T in (0.8, 0.81, 1.0)]
    got = [moves[0].sample(1000.0)]
    with count_compiles() as c:
        got += [m.sample(1000.0) for m in moves[1:]]
    assert c["n"] == 0
    for m, (t, x, v, a) in zip(moves, got):
        assert t.size == round(float(m.duration) * 1000.0) + 1
        # the steps and ramps summed by numpy: x = sum alpha d^2 / 2 + beta d^3 / 6, d = (min(t, T) - t_k)_+
        d = np.maximum(np.minimum(t, float(m.duration))[:, None] - np.asarray(m.times), 0.0)
        al, be = np.asarray(m.steps), np.asarray(m.ramps)
        np.testing.assert_allclose(x, (al * d**2 / 2 + be * d**3 / 6).sum(1), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(v, (al * d + be * d**2 / 2).sum(1), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(a, (al * (d > 0) + be * d).sum(1), rtol=1e-12, atol=1e-14)


def test_peaks_and_samples_of_pseudo_polynomials_of_any_order_up_to_8_share_one_program():
    # design_move's pseudo-polynomials change order with the move time: their peaks and samples pad the exponents,
    # so a new order compiles nothing
    from jaxbelt.shaping.moves import derivatives_at, peaks

    D, T = 0.1, 0.8
    orders = ([3.0, 4.0, 5.0], [3.2, 4.5, 5.1, 6.3], [8.0, 9.0, 10.2, 11.0, 12.5, 13.9, 15.0, 16.5])
    cmds = [jb.PseudoPolynomial(jnp.array(g), D, T) for g in orders]
    t = np.linspace(0.0, T, 801)
    got = [(peaks(cmds[0]), derivatives_at(cmds[0], t))]
    with count_compiles() as c:
        got += [(peaks(m), derivatives_at(m, t)) for m in cmds[1:]]
    assert c["n"] == 0
    # the exponents (3, 4, 5) are the quintic x = D (10 s^3 - 15 s^4 + 6 s^5), s = t / T: peak |v| 15 D / (8 T) at
    # s = 1/2, |a| 10 D / (sqrt(3) T^2) at s = 1/2 -+ sqrt(3)/6, |jerk| 60 D / T^3 at both ends
    (pv, pa, pj), (x, v, a) = got[0]
    s = t / T
    # (eq. 17 forms D (1 - sum C u^g): rounding of 1e-16 D near the start)
    np.testing.assert_allclose(x, D * (10 * s**3 - 15 * s**4 + 6 * s**5), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(v, D / T * (30 * s**2 - 60 * s**3 + 30 * s**4), rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(a, D / T**2 * (60 * s - 180 * s**2 + 120 * s**3), rtol=1e-10, atol=1e-12)
    assert pv == pytest.approx(15 * D / (8 * T), rel=1e-12)
    assert pa == pytest.approx(10 * D / (np.sqrt(3) * T**2), rel=1e-7)  # 20001 samples: within h^2 of the peak
    assert pj == pytest.approx(60 * D / T**3, rel=1e-12)
    # every order: the unpadded command's own derivatives (eq. 18-19), to the rounding of eq. (23)'s solve (its
    # condition number grows with the order: 1e-11 of the largest value at order 8)
    for m, (_, vals) in zip(cmds, got):
        for k, val in enumerate(vals):
            ref = np.asarray(m.derivative(jnp.asarray(t), k))
            np.testing.assert_allclose(val, ref, rtol=1e-9, atol=1e-10 * float(np.max(np.abs(ref))))


def _spline(n_knots, seed=0, T=1.0):
    # a rest-to-rest spline move of `n_knots` intervals: coefficients with sum 0 (end velocity 0)
    c = np.random.default_rng(seed).normal(size=n_knots - 3)
    return jb.SplineMove(c - c.mean(), T)


def test_padded_spline_is_the_spline():
    # `moves.PaddedSpline`: 45 coefficients (48 intervals) padded to the slot of 64 intervals; its derivatives and
    # residual integral equal the unpadded move's to round-off, and its residual integral is a quadrature of
    # a(t) e^{s(T - t)} (an independent reference for the new code), also for a damped mode far above the knot rate
    # (the padding's kernels are masked: e^{s(T - t_j - 4h)} overflows for a B-spline starting past T)
    from scipy.interpolate import BSpline

    from jaxbelt.shaping.moves import PaddedSpline, padded_command

    cmd = _spline(48)
    pad = padded_command(cmd)
    assert isinstance(pad, PaddedSpline) and pad.coefficients.shape == (61,)
    t = np.linspace(-0.1, 1.2, 1301)
    s = np.array([-0.1 + 2j * np.pi * 6.0, -2.0 + 2j * np.pi * 17.0, -3e5 + 2j * np.pi * 1e6])

    @eqx.filter_jit  # one program per form (eager operations would compile dozens)
    def values(m):
        return [m.derivative(t, k) for k in range(4)], m.residual_integral(s), m.distance

    (d_pad, w_pad, x_pad), (d_ref, w_ref, x_ref) = values(pad), values(cmd)
    for got, ref in zip(d_pad, d_ref):
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    w_pad = np.asarray(w_pad)
    np.testing.assert_allclose(w_pad, w_ref, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(float(x_pad), float(x_ref), rtol=1e-13)
    # the acceleration as scipy's B-spline on the knots jh (h = T/48), integrated knot interval by knot interval by a
    # 24-point Gauss-Legendre rule (a cubic times an exponential: exact to rounding on each interval)
    T = 1.0
    knots = np.linspace(0.0, T, 49)
    z3 = np.zeros(3)  # B_j starts at jh: zero B-splines before and after make [0, T] scipy's base interval
    acc = BSpline(np.arange(-3, 52) / 48.0, np.concatenate([z3, np.asarray(cmd.coefficients), z3]), 3)
    x, wq = np.polynomial.legendre.leggauss(24)
    lo, hi = knots[:-1, None], knots[1:, None]
    tq = (lo + hi) / 2 + (hi - lo) / 2 * x  # (48, 24)
    for i, sk in enumerate(s[:2]):
        w_ref = np.sum((hi - lo) / 2 * wq * acc(tq) * np.exp(sk * (T - tq)))
        assert abs(w_pad[i] - w_ref) <= 1e-11 * abs(w_ref)
    assert np.all(np.isfinite(w_pad)) and abs(w_pad[2]) < 1e-3 * abs(w_pad[0])


@pytest.mark.slow
def test_splines_of_one_knot_slot_share_peaks_samples_and_residual_programs():
    # the minimax design's knot count follows the move time (48 intervals at 1.1 s, 64 at 1.3 s on a 6 Hz axis):
    # its command's peaks, samples and residual curves (band and wide grids) run the programs of its slot
    # (`moves.INTERVAL_SLOT`), so a warm design at another move time of the slot compiles none of them; the values
    # are the unpadded spline's own (the derivative at the same times, its closed-form residual)
    from jaxbelt.shaping.moves import peaks
    from jaxbelt.shaping.residual import measured_curve

    axis = jb.ModalAxis([6.0, 17.0], [0.02, 0.01])
    band = np.linspace(0.8, 1.2, 401)

    def run(cmd):
        return peaks(cmd), cmd.sample(1000.0), np.asarray(measured_curve(axis, cmd, band))

    run(_spline(64, 1, 1.3))
    cmd = _spline(48, 2, 1.1)
    with count_compiles() as c:
        pk, (t, x, v, a), res = run(cmd)
    assert c["n"] == 0
    ts = np.linspace(0.0, 1.1, 20001)
    for got, k in zip(pk, (1, 2, 3)):
        assert got == pytest.approx(np.max(np.abs(np.asarray(cmd.derivative(ts, k)))), rel=1e-12)
    for got, k in zip((x, v, a), (0, 1, 2)):
        ref = np.asarray(cmd.derivative(t, k))
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-13 * np.max(np.abs(ref)))
    s = -axis.damping_ratios[:, None] * axis.omega[:, None] * band + 1j * axis.omega_d[:, None] * band
    ref = np.abs(axis.gains)[:, None] / (axis.omega_d[:, None] * band) * np.abs(cmd.residual_integral(s))
    np.testing.assert_allclose(res, ref, rtol=1e-11)


@pytest.mark.slow
def test_design_move_warm_at_another_move_time_of_its_knot_slot_compiles_nothing():
    # issue 54: after a first call at 1.0 s, calls at 0.8 and 1.3 s (32 to 64 knot intervals: one slot of the LP) run
    # the programs compiled before: the minimax design, the classic shapers (their moves convolved on the host), the
    # blends, the measuring of every row. The pseudo-polynomials are left out (their optimiser's batch follows the
    # order count)
    axis = jb.ModalAxis([6.0], [0.02])
    inc = ("minimax", "ZV", "MZV", "ZVD", "EI", "2-hump EI", "3-hump EI", "unshaped")
    lim = dict(v_max=0.3, a_max=1.2, uncertainty=0.2, include=inc)
    jb.design_move(axis, 0.1, 1.0, **lim)
    for T in (0.8, 1.3):
        with count_compiles() as c:
            plan = jb.design_move(axis, 0.1, T, **lim)
        assert c["n"] == 0, T
        assert plan.minimax is not None and plan.minimax.converged


@pytest.mark.slow
def test_residual_curves_of_pseudo_polynomials_of_other_move_times_share_one_program():
    # the curve's Gauss-Legendre rule is data of `_curve_nodes` nodes (0.75 |s|T + 64, at least `NODE_SLOT` = 512:
    # 512 for all three move times here, where the designs' older rule `_nodes_for` asked 256, 512 and 1024), so a
    # pseudo-polynomial at another move time compiles nothing; the curve is the plain integral
    # (`residual_integral`, the test above checks that against an independent quadrature) of the same size to
    # round-off
    from jaxbelt.shaping.residual import NODE_SLOT, _curve_nodes, _nodes_for, residual_curve, residual_integral

    axis = jb.ModalAxis([6.0, 17.0], [0.02, 0.01])
    factors = np.linspace(0.8, 1.2, 9)
    w = 2 * np.pi * np.array([6.0, 17.0])[:, None] * factors
    z = np.array([0.02, 0.01])[:, None]
    wd = w * np.sqrt(1 - z**2)
    s = -z * w + 1j * wd
    cmds = [jb.PseudoPolynomial(np.array([3.2, 4.5, 5.1, 6.3]), 0.1, T) for T in (0.3, 0.8, 2.0)]
    assert [_nodes_for(cmd, s) for cmd in cmds] == [256, 512, 1024]
    assert [_curve_nodes(cmd, s) for cmd in cmds] == [NODE_SLOT] * 3
    got = [np.asarray(residual_curve(axis, cmds[0], factors))]
    with count_compiles() as c:
        got += [np.asarray(residual_curve(axis, cmd, factors)) for cmd in cmds[1:]]
    assert c["n"] == 0
    for cmd, curve in zip(cmds, got):
        plain = np.abs(np.asarray(residual_integral(cmd, jnp.asarray(s)))) / wd
        np.testing.assert_allclose(curve, plain, rtol=1e-11, atol=1e-13 * float(np.max(plain)))


@pytest.mark.slow  # about 10 s: it compiles the programs of four commands
def test_a_blend_in_its_canonical_structure_is_the_same_move():
    # `moves.padded_command` puts a blend's PiecewiseMoves into one (weights folded in, padded to INTERVAL_SLOT
    # terms): blends of other shaped moves share one program. Checked against the blend itself, member by member
    from jaxbelt.shaping.moves import BlendMove, PiecewiseMove, SplineMove, padded_command

    T = 1.0
    spline = SplineMove(jnp.asarray(np.sin(np.arange(20.0))), T)
    a = PiecewiseMove([0.0, 0.25, 0.5, 0.75], [1.0, -1.0, -1.0, 1.0], [0.0] * 4, T)
    b = PiecewiseMove([0.0, 0.1, 0.9, 1.0], [0.0] * 4, [2.0, -2.0, -2.0, 2.0], T)
    blend = BlendMove((a, spline, b), jnp.asarray([0.2, 0.5, 0.3]), T)
    canon = padded_command(blend)
    assert [type(m).__name__ for m in canon.members][-1] == "PiecewiseMove" and len(canon.members) == 2
    t = jnp.linspace(0.0, T, 257)
    for k in range(4):
        ref = sum(w * m.derivative(t, k) for w, m in zip((0.2, 0.5, 0.3), (a, spline, b)))
        np.testing.assert_allclose(canon.derivative(t, k), ref, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(ref))))
    s = jnp.asarray([-0.3 + 40j, -1.0 + 90j])
    ref = sum(w * m.residual_integral(s) for w, m in zip((0.2, 0.5, 0.3), (a, spline, b)))
    np.testing.assert_allclose(canon.residual_integral(s), ref, rtol=1e-11)
    only = padded_command(BlendMove((spline,), jnp.asarray([1.0]), T))  # no PiecewiseMove: zero terms added
    np.testing.assert_allclose(only.derivative(t, 0), spline.derivative(t, 0), rtol=1e-13, atol=1e-15)


@pytest.mark.slow
def test_design_move_at_0_8_to_1_7_s_after_1_s_compiles_no_lp():
    # issue 54 item 5: on the 3-mode axis of benchmarks/shaping_axis.py the knot count at 0.8, 1.3 and 1.7 s (6 per
    # period of 20.4 Hz: 128, 160 and 256 intervals) is capped at the slot of 128 (`design.KNOT_FILL`), so after a
    # first call at 1.0 s the minimax design (its LP, fine-grid check, measuring) compiles nothing
    axis = jb.ModalAxis([3.1, 9.7, 17.0], [0.03, 0.02, 0.01])
    lim = dict(v_max=0.3, a_max=1.2, uncertainty=0.2, include=("minimax",))
    jb.design_move(axis, 0.1, 1.0, **lim)
    for T in (0.8, 1.3, 1.7):
        with count_compiles() as c:
            plan = jb.design_move(axis, 0.1, T, **lim)
        assert c["n"] == 0, T
        assert plan.minimax is not None and plan.minimax.converged
        assert plan.minimax.options.n_knots == 128


def test_design_move_compiles_the_programs_it_prepares_once_in_the_compile_threads():
    # at a given move time the minimax worker first traces the LP's, the fine check's and the programs that measure
    # the design (far_modes.prepare_lp), before it runs them; each compiles in a compile thread and its call waits
    # for it: compiled once, in that thread (a prepared type that differed from the call's, or a call that did not
    # wait, would compile it a second time, in the worker)
    import threading

    import jax.monitoring

    jax.clear_caches()
    seen = []

    def listener(name, duration, **kw):
        if name == "/jax/core/compile/backend_compile_duration":
            seen.append((kw.get("fun_name"), threading.current_thread().name))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        jb.design_move(jb.ModalAxis([5.3, 13.1], [0.02, 0.012]), 0.1, 0.93, v_max=0.3, a_max=1.2)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    for name in ("_solve_round_impl", "_fine_ratios_program", "_derivatives"):
        where = [thread for fun, thread in seen if fun == f"jit({name})"]
        assert len(where) == 1 and where[0].startswith("jaxbelt-compile"), (name, seen)
