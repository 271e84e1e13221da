"""Forward sensitivities (`jaxbelt.solve.forward_sensitivities`) and the metrics linearised with them, which
`tune_pid`'s step differentiates. References: central finite differences of `simulate` and of
`closed_loop_metrics` at tight tolerances; tolerances stated at each assertion."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.objectives.fluctuation import closed_loop_metrics, linearised_closed_loop_metrics
from jaxbelt.solve import forward_sensitivities

G0 = np.array([80.0, 32.0, 0.015])
PID = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0, limiter="smooth")
TS = jnp.linspace(0.0, 0.2, 81)


def pid_of(q):
    return PID.with_gains(G0 * jnp.exp(q))


def states(q, **kw):
    sol = jb.simulate(jb.Scene(jb.FourBarDrive(), pid_of(q), ts=TS, t0=0.0), **kw)
    return np.asarray(sol.ys)


def central(f, p, h):
    """Central differences of `f` along each entry of `p` (last axis: the entry)."""
    cols = []
    for k in range(p.size):
        e = np.zeros_like(p)
        e[k] = h
        cols.append((f(p + e) - f(p - e)) / (2 * h))
    return np.stack(cols, axis=-1)


P = np.array([0.1, -0.2, 0.3])


@pytest.mark.parametrize(
    ("method", "options"),
    [("ode", dict(rtol=1e-11, atol=1e-11)), ("rk4", dict(dt=2e-4))],
)
def test_sensitivities_match_central_differences_of_simulate(method, options):
    ys, sens, ok = forward_sensitivities(jb.FourBarDrive(), pid_of, jnp.asarray(P), TS, method=method, **options)
    assert bool(ok)
    # the trajectory is simulate's to rounding: the same steps (the error control reads the trajectory alone)
    ref = states(P, method=method, **options)
    err = np.max(np.abs(np.asarray(ys) - ref), axis=0) / np.max(np.abs(ref), axis=0)
    assert np.all(err < 1e-12), err  # per state component, relative to its largest value; measured <= 3e-15
    # h = 1e-4 on log-gains: truncation ~h^2 ~ 1e-8, rounding ~1e-11 / h ~ 1e-7 of each sensitivity's scale
    fd = central(lambda q: states(q, method=method, **options), P, 1e-4)
    scale = np.max(np.abs(fd), axis=0)  # (state component, gain): each sensitivity on its own scale
    err = np.max(np.abs(np.asarray(sens) - fd), axis=0) / scale
    assert np.all(err < 1e-6), err  # measured: <= 4e-8
    assert np.all(np.max(np.abs(fd), axis=0) > 0)  # every gain moves the trajectory


def test_sensitivities_of_a_failed_run_are_nan():
    ys, sens, ok = forward_sensitivities(jb.FourBarDrive(), pid_of, jnp.asarray(P), TS, max_steps=4)
    assert not bool(ok)
    assert np.all(np.isnan(np.asarray(ys))) and np.all(np.isnan(np.asarray(sens)))


def test_linearised_metrics_value_and_derivative():
    kw = dict(rtol=1e-11, atol=1e-11)
    linear = linearised_closed_loop_metrics(jb.FourBarDrive(), pid_of, jnp.asarray(P), **kw)
    # `linear` evaluated as tune_pid's step evaluates it, compiled (one program, not ~100 eager operations)
    at_p = jax.device_get(jax.jit(linear)(jnp.asarray(P)))
    ref = jax.device_get(closed_loop_metrics(jb.FourBarDrive(), pid_of(jnp.asarray(P)), **kw))
    assert at_p.keys() == ref.keys()
    for name in ref:  # the same metrics of two solves to 1e-11: equal to ~1e-9 relative
        np.testing.assert_allclose(at_p[name], ref[name], rtol=1e-8, err_msg=name)
    # the derivative at p (what tune_pid's step takes) against central differences of the exact metrics
    names = ("chi_smooth", "v_peak_smooth", "i_peak_smooth", "mean_speed")
    jac = jax.jit(jax.jacfwd(lambda q: jnp.stack([linear(q)[n] for n in names])))(jnp.asarray(P))

    def exact(q):
        m = closed_loop_metrics(jb.FourBarDrive(), pid_of(jnp.asarray(q)), **kw)
        return np.array([float(m[n]) for n in names])

    fd = central(exact, P, 1e-4)
    for i, name in enumerate(names):
        np.testing.assert_allclose(np.asarray(jac)[i], fd[i], rtol=1e-5, atol=1e-6 * np.abs(fd[i]).max(), err_msg=name)
    assert np.all(np.abs(fd[0]) > 1e-6)  # chi_smooth depends on every gain


def test_tune_step_gradient_is_the_derivative_of_the_smooth_objective():
    # the step's gradient of chi_smooth (no penalty) against central differences of `fluctuation_objective`
    from jaxbelt.optimise import pid as pid_mod

    cfg = pid_mod._Config(
        t0=np.asarray(0.375),
        v_max=np.asarray(np.inf),
        i_max=np.asarray(np.inf),
        penalty=np.asarray(10.0),
        temperature=np.asarray(3e-4),
        rtol=np.asarray(1e-10),
        atol=np.asarray(1e-10),
        t1=0.5,
        method="ode",
        dt=1e-3,
    )
    state = pid_mod._default_adam_state()
    state.hyperparams["learning_rate"] = np.asarray(0.0)  # p unchanged: the update reads the gradient only
    _, state, loss, m, _ = pid_mod._tune_step("adam", jb.FourBarDrive(), PID, G0, cfg, P, state)
    grad = np.asarray(state.inner_state[0].mu) / 0.1  # Adam's first moment after one step: (1 - b1) * grad

    def chi(q):
        return float(
            jb.fluctuation_objective(jb.FourBarDrive(), pid_of(jnp.asarray(q)), 0.375, 0.5, rtol=1e-10, atol=1e-10)
        )

    np.testing.assert_allclose(float(loss), chi(P), rtol=1e-8)
    np.testing.assert_allclose(grad, central(chi, P, 1e-4), rtol=1e-5)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(method="closed"), "`method` must be 'ode' or 'rk4'"),
        (dict(p=jnp.zeros((1, 3))), "`p` must be a non-empty vector"),
        (dict(max_steps=0), "`max_steps` must be an integer >= 1"),
    ],
)
def test_bad_arguments_are_named(kw, match):
    p = kw.pop("p", jnp.asarray(P))
    with pytest.raises(ValueError, match=match):
        forward_sensitivities(jb.FourBarDrive(), pid_of, p, TS, **kw)
