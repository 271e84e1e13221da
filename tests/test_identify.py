"""Parameter identification (`jb.identify`) on synthetic noisy data with known truth.

References: the closed-form ordinary least squares of a straight line (estimates and covariance
$s^2 (X^T X)^{-1}$); the true parameters of the start-up model (Incerti, 2014, Table I) and of the
platform (Incerti, pseudo-polynomial commands, Table III) recovered within 3 standard errors;
the scatter of the estimates over a Monte-Carlo of noise draws against the reported stderr.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb

# --- exact reference: a straight line -------------------------------------------------------
X = np.linspace(-1.0, 2.0, 40)


def _line(p):
    return p["a"] + p["b"] * X


def test_line_matches_closed_form_ols():
    rng = np.random.default_rng(3)
    y = 1.5 - 0.7 * X + 0.1 * rng.standard_normal(X.size)
    res = jb.identify(_line, {"a": 1.0, "b": -1.0}, y)  # a > 0: log space; b < 0: relative
    A = np.stack([np.ones_like(X), X], -1)
    coef, rss, *_ = np.linalg.lstsq(A, y, rcond=None)
    s2 = float(rss[0]) / (X.size - 2)
    cov = s2 * np.linalg.inv(A.T @ A)
    np.testing.assert_allclose([res.params["a"], res.params["b"]], coef, rtol=1e-9)
    np.testing.assert_allclose(res.covariance, cov, rtol=1e-6)
    assert abs(res.sigma - np.sqrt(s2)) < 1e-9
    np.testing.assert_allclose(res.residuals, A @ coef - y, atol=1e-9)
    # a known sigma: the covariance is sigma^2 (X^T X)^-1, whatever the residuals
    res2 = jb.identify(_line, {"a": 1.0, "b": -1.0}, y, sigma=0.2, solver="gn")
    np.testing.assert_allclose(res2.covariance, 0.04 * np.linalg.inv(A.T @ A), rtol=1e-6)


def test_bad_inputs_raise():
    y = np.zeros(X.size)
    with pytest.raises(ValueError, match="params0"):
        jb.identify(_line, {}, y)
    with pytest.raises(ValueError, match="sigma"):
        jb.identify(_line, {"a": 1.0, "b": 1.0}, y, sigma=0.0)
    with pytest.raises(ValueError, match="more\\s+data points"):
        jb.identify(_line, {"a": 1.0, "b": 1.0}, y[:2])
    with pytest.raises(ValueError, match="solver"):
        jb.identify(_line, {"a": 1.0, "b": 1.0}, y, solver="bfgs")
    with pytest.raises(ValueError, match="finite"):
        jb.identify(_line, {"a": 1.0, "b": 1.0}, y + np.nan)


def test_unidentifiable_combination_warns():
    # only a + b is seen at x = 1: the difference has infinite variance, and we say so
    with pytest.warns(RuntimeWarning, match="do not identify"):
        res = jb.identify(lambda p: jnp.full(5, p["a"] + p["b"]), {"a": 1.0, "b": 2.0}, np.full(5, 4.0), sigma=0.1)
    assert np.isinf(res.stderr["a"]) and np.isinf(res.stderr["b"])


# --- start-up of a belt drive (Incerti, 2014): belt stiffness, damping, armature resistance -----
ST_TS = jnp.linspace(0.0, 0.3, 301)
ST_CMD = jb.ExponentialVoltage(24.0, 0.02)
ST_TRUE = {"k": 120e3, "c": 20.0, "R": 0.15}  # Table I
ST_SIGMA = np.array([0.02, 0.5])  # noise on the driven-pulley speed [rad/s] and current [A]


def _startup(p):
    m = jb.BeltStartup(k=p["k"], c=p["c"], R=p["R"])
    sol = jb.simulate(jb.Scene(m, ST_CMD, ts=ST_TS))
    return jnp.stack([sol["omega2"], sol["current"]], -1)


def test_startup_recovers_known_parameters():
    clean = np.asarray(_startup(ST_TRUE))
    noise = np.random.default_rng(0).standard_normal(clean.shape)
    res = jb.identify(_startup, {"k": 80e3, "c": 30.0, "R": 0.2}, clean + ST_SIGMA * noise, sigma=ST_SIGMA)
    for name, true in ST_TRUE.items():
        assert abs(res.params[name] - true) < 3 * res.stderr[name], (name, res.params[name], res.stderr[name])
    # the noise is well described: weighted chi-square per degree of freedom near 1 (N = 602)
    assert abs(res.cost / res.dof - 1.0) < 3 * np.sqrt(2 / res.dof)
    # linearised stderr scales with the noise: doubling the same noise draw doubles it (2 %)
    res2 = jb.identify(_startup, res.params, clean + 2 * ST_SIGMA * noise, sigma=2 * ST_SIGMA)
    for name in ST_TRUE:
        assert abs(res2.stderr[name] / res.stderr[name] - 2.0) < 0.04, name


@pytest.mark.parametrize("jac", ["fwd", "bwd"])
def test_identify_runs_the_users_predict_once_per_compilation(jac):
    # the solver evaluates the residuals and their Jacobian at several places of one program: the user's `predict`
    # is traced once (its Python runs once), not once per place; the fit is that of the plain line's OLS
    calls = []
    x = np.linspace(0.0, 1.0, 11)
    y = 2.0 + 3.0 * x + 0.01 * np.sin(7 * x)

    def line(p, mode=jac):  # `mode`: a function of its own per case (an equal one would reuse the traced program)
        calls.append(1)
        return p["a"] + p["b"] * jnp.asarray(x)

    res = jb.identify(line, {"a": 1.0, "b": 1.0}, y, sigma=0.01, jac=jac)
    # twice: once abstractly at the concrete start values (which refuses an invalid start before compiling,
    # see test_reliability4.py), once to trace the fit
    assert len(calls) == 2
    b, a = np.polyfit(x, y, 1)
    np.testing.assert_allclose([res.params["a"], res.params["b"]], [a, b], rtol=1e-8)


# --- belt-driven platform (Incerti, pseudo-polynomial commands): stiffness and damping ----------
PL_TS = jnp.linspace(0.0, 1.5, 201)
PL_CMD = jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]))
PL_TRUE = {"k": 9e4, "c": 150.0}  # Table III


def _platform(p):
    plat = jb.BeltPlatform(k=p["k"], c=p["c"])
    sol = jb.simulate(jb.Scene(plat, PL_CMD, ts=PL_TS, observe=("alpha",), state=False), adjoint="forward")
    return sol.outputs["alpha"]


@pytest.fixture(scope="module")
def platform_clean():
    return np.asarray(_platform(PL_TRUE))


def test_platform_recovers_stiffness_and_damping(platform_clean):
    sig = 0.02 * np.max(np.abs(platform_clean))  # 2 % of the peak belt deflection [rad]
    data = platform_clean + sig * np.random.default_rng(1).standard_normal(platform_clean.shape)
    res = jb.identify(_platform, {"k": 6e4, "c": 300.0}, data)  # sigma estimated from the residuals
    for name, true in PL_TRUE.items():
        assert abs(res.params[name] - true) < 3 * res.stderr[name], (name, res.params[name], res.stderr[name])
    # the estimated noise level: relative sampling error of s is ~ 1/sqrt(2 dof) = 5 %
    assert abs(res.sigma / sig - 1.0) < 0.15


def test_platform_stderr_matches_monte_carlo(platform_clean):
    """Scatter of 30 estimates (fixed seeds) vs the mean reported stderr: equal within 35 %
    (the sampling error of a standard deviation from 30 draws is ~13 %)."""
    sig = 0.05 * np.max(np.abs(platform_clean))
    rng = np.random.default_rng(7)
    est, se = [], []
    for _ in range(30):
        data = platform_clean + sig * rng.standard_normal(platform_clean.shape)
        r = jb.identify(_platform, PL_TRUE, data, sigma=sig)
        est.append([r.params["k"], r.params["c"]])
        se.append([r.stderr["k"], r.stderr["c"]])
    est, se = np.array(est), np.array(se)
    ratio = est.std(axis=0, ddof=1) / se.mean(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.35), ratio
    # no bias beyond the Monte-Carlo error of the mean (3 / sqrt(30) standard errors)
    bias = (est.mean(axis=0) - np.array([9e4, 150.0])) / se.mean(axis=0)
    assert np.all(np.abs(bias) < 3 / np.sqrt(30)), bias
