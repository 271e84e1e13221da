"""Start-up of a belt drive driven by a DC motor (Incerti, 2014): accuracy against independent references.

References: scipy.linalg.expm of the exponential-augmented system (exact up to round-off),
steady-state closed forms, scipy solve_ivp, central finite differences.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from references import expm_reference, startup_reference
from scipy.integrate import solve_ivp

import jaxbelt as jb
from jaxbelt.modal import modal_decomposition, modal_solve, modal_solve_raw

TS = jnp.linspace(0.0, 0.5, 501)


def reference(model, cmd, ts, x0=None):
    """States for an `ExponentialVoltage` or `ConstantVoltage` command (scipy expm, tests/references.py)."""
    if isinstance(cmd, jb.ExponentialVoltage):
        return startup_reference(model, ts, float(cmd.v_max), float(cmd.gamma), x0)
    return startup_reference(model, ts, float(cmd.voltage), None, x0)


def rel_err(x, ref):
    """Worst over states of max|x - ref| / max|ref| (per state)."""
    x, ref = np.asarray(x), np.asarray(ref)
    return np.max(np.max(np.abs(x - ref), axis=0) / np.max(np.abs(ref), axis=0))


def test_matrices_match_paper_eq10_eq11():
    m = jb.BeltStartup()
    A, B = (np.asarray(a) for a in m.matrices())
    J1s = 0.018 + 15**2 * 4e-4
    k, c, r1, r2, J2, mu, z, km, L, R = 120e3, 20.0, 0.08, 0.16, 0.25, 5.0, 15.0, 0.09, 0.2e-3, 0.15
    A_ref = np.array(
        [
            [0, 0, 1, 0, 0],
            [0, 0, 0, 1, 0],
            [-2 * k * r1**2 / J1s, 2 * k * r1 * r2 / J1s, -2 * c * r1**2 / J1s, 2 * c * r1 * r2 / J1s, z * km / J1s],
            [2 * k * r1 * r2 / J2, -2 * k * r2**2 / J2, 2 * c * r1 * r2 / J2, -(2 * c * r2**2 + mu) / J2, 0],
            [0, 0, -z * km / L, 0, -R / L],
        ]
    )
    B_ref = np.array([[0, 0], [0, 0], [0, 0], [-1 / J2, 0], [0, 1 / L]])
    np.testing.assert_allclose(A, A_ref, rtol=1e-14)
    np.testing.assert_allclose(B, B_ref, rtol=1e-14)
    # rigid-body rotation (r2, r1) of the pulleys is a null vector of A: eigenvalue exactly 0
    np.testing.assert_allclose(A @ np.array([r2, r1, 0, 0, 0]), 0.0, atol=1e-9)


@pytest.mark.parametrize("method", ["expm", "modal"])
@pytest.mark.parametrize("gamma", [0.02, 0.04, 0.06])
def test_closed_forms_against_expm_reference(method, gamma):
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(v_max=24.0, gamma=gamma)
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS), method=method)
    assert sol.ys.shape == (501, 5)
    assert rel_err(sol.ys, reference(model, cmd, TS)) < 1e-9


def test_default_method_is_closed_form_and_contract():
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(v_max=24.0, gamma=0.02)
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS))
    assert sol.method == "expm" and sol.stats == {}
    ref = reference(model, cmd, TS)
    for i, name in enumerate(("theta1", "theta2", "omega1", "omega2", "current")):
        np.testing.assert_allclose(getattr(sol, name), ref[:, i], rtol=0, atol=1e-9 * np.max(np.abs(ref[:, i])))


def test_diffrax_against_reference():
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(v_max=24.0, gamma=0.02)
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS), method="ode", rtol=1e-10, atol=1e-12)
    assert rel_err(sol.ys, reference(model, cmd, TS)) < 1e-7


def test_rk4_paper_check_step_0p1ms():
    """The paper's verification: RK4 at 0.1 ms agrees with the modal solution."""
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(v_max=24.0, gamma=0.02)
    rk4 = jb.simulate(jb.Scene(model, cmd, ts=TS), method="rk4", dt=1e-4)
    modal = jb.simulate(jb.Scene(model, cmd, ts=TS), method="modal")
    err = rel_err(rk4.ys, modal.ys)
    assert err < 1e-6  # measured ~1.5e-8 (current is the stiffest state)
    # fourth order: halving the step divides the error by ~16
    rk4h = jb.simulate(jb.Scene(model, cmd, ts=TS), method="rk4", dt=5e-5)
    ratio = err / rel_err(rk4h.ys, modal.ys)
    assert 12 < ratio < 20


def test_modal_vectors_are_left_and_right_eigenvectors():
    A = jb.BeltStartup().matrices()[0]
    lam, X, Yt, cond = modal_decomposition(A)
    A = np.asarray(A, dtype=complex)
    np.testing.assert_allclose(np.asarray(Yt) @ np.asarray(X), np.eye(5), atol=1e-10)  # eq. (20)
    np.testing.assert_allclose(
        np.asarray(Yt) @ A @ np.asarray(X), np.diag(np.asarray(lam)), atol=1e-7 * np.abs(lam).max()
    )
    np.testing.assert_allclose(
        np.asarray(Yt) @ A, np.asarray(lam)[:, None] * np.asarray(Yt), atol=1e-9 * np.abs(lam).max()
    )
    assert np.min(np.abs(np.asarray(lam))) < 1e-9 * np.max(np.abs(np.asarray(lam)))  # rigid-body mode


def test_rigid_body_mode_limit_is_exact():
    """With lambda = 0 exactly, the convolution of a constant input is tau (no division by lambda)."""
    from jaxbelt.modal import exp_convolution

    tau = jnp.array([0.0, 1e-6, 0.3, 2.0])
    np.testing.assert_allclose(np.real(exp_convolution(0.0, 0.0, tau)), np.asarray(tau), rtol=1e-15)
    lam, s = -3.0 + 2.0j, -5.0
    t = np.asarray(tau)[2:]  # the naive formula cancels for small tau: there use its Taylor series
    expected = (np.exp(s * t) - np.exp(lam * t)) / (s - lam)
    np.testing.assert_allclose(np.asarray(exp_convolution(lam, s, tau))[2:], expected, rtol=1e-13)
    t = 1e-6
    taylor = t + (lam + s) * t**2 / 2 + (lam**2 + lam * s + s**2) * t**3 / 6
    np.testing.assert_allclose(complex(exp_convolution(lam, s, t)), taylor, rtol=1e-15)
    # resonance lambda = s: tau e^{s tau}
    np.testing.assert_allclose(
        np.real(exp_convolution(-5.0, -5.0, tau)), np.asarray(tau) * np.exp(-5 * np.asarray(tau)), rtol=1e-14
    )
    # stiff pole: no overflow
    assert np.all(np.isfinite(np.asarray(exp_convolution(-1e9, 0.0, tau))))


def _critical_damping():
    """Belt damping c at which the belt's complex pair merges (repeated real eigenvalue)."""

    def imag(c):
        A = np.asarray(jb.BeltStartup(c=c).matrices()[0])
        return np.max(np.abs(np.linalg.eigvals(A).imag))

    lo, hi = 20.0, 1e5
    assert imag(lo) > 0 and imag(hi) == 0
    for _ in range(200):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if imag(mid) > 0 else (lo, mid)
    return hi


@pytest.mark.parametrize(
    "params",
    [
        {"c": "critical"},
        {"L": 1e-8},
        {"L": 2.0, "R": 5.0},
        {"k": 5e3, "mu": 0.0, "tau_r0": 2.0},
        {"j2": 2.0, "r2": 0.4, "c": 0.0},
    ],
    ids=["critically_damped", "tiny_inductance", "large_inductance", "soft_belt_load_torque", "undamped_belt"],
)
@pytest.mark.parametrize("method", ["expm", "modal"])
def test_other_parameter_sets(params, method):
    params = dict(params)
    if params.get("c") == "critical":
        params["c"] = _critical_damping()
    model = jb.BeltStartup(**params)
    cmd = jb.ExponentialVoltage(24.0, 0.03)
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS), method=method)
    assert rel_err(sol.ys, reference(model, cmd, TS)) < 1e-9


def test_modal_falls_back_for_a_defective_matrix():
    """A Jordan block has no eigenvector basis: the raw modal formula is wrong, the solver is not."""
    A = jnp.array([[-2.0, 1.0, 0.0], [0.0, -2.0, 1.0], [0.0, 0.0, -2.0]])
    F = jnp.array([[0.0], [0.0], [1.0]])
    s = jnp.array([0.0])
    ts = jnp.linspace(0.0, 3.0, 31)
    x0 = jnp.array([1.0, 0.0, 0.0])
    ref = expm_reference(A, F, s, x0, ts)
    _, cond = modal_solve_raw(A, F, s, x0, 0.0, ts)
    assert cond > 1e6
    xs = modal_solve(A, F, s, x0, 0.0, ts)
    np.testing.assert_allclose(np.asarray(xs), ref, atol=1e-12)


def test_energy_balance():
    """V I = R I^2 + belt damping + load power + d/dt (kinetic + elastic + magnetic), integrated."""
    model = jb.BeltStartup(tau_r0=1.5)
    cmd = jb.ExponentialVoltage(24.0, 0.04)
    names = (
        "electric_energy",
        "copper_loss",
        "damping_loss",
        "load_work",
        "kinetic_energy",
        "elastic_energy",
        "magnetic_energy",
    )
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=names), method="ode", rtol=1e-11, atol=1e-12)
    stored = sol.kinetic_energy + sol.elastic_energy + sol.magnetic_energy
    rhs = sol.copper_loss + sol.damping_loss + sol.load_work + stored
    e_in = np.asarray(sol.electric_energy)
    assert e_in[-1] > 100.0  # a real energy flow is being checked
    assert np.max(np.abs(e_in - np.asarray(rhs))) / e_in[-1] < 1e-6
    # magnetic energy is not negligible here: without it the balance fails
    assert np.max(np.abs(e_in - np.asarray(rhs - sol.magnetic_energy))) / e_in[-1] > 1e-4


def test_derived_outputs():
    model = jb.BeltStartup()
    cmd = jb.ExponentialVoltage(24.0, 0.02)
    obs = ("voltage", "electric_power", "mechanical_power", "alpha1", "alpha2")
    sol = jb.simulate(jb.Scene(model, cmd, ts=TS, observe=obs))
    t = np.asarray(TS)
    V = 24.0 * (1 - np.exp(-t / 0.02))
    np.testing.assert_allclose(sol.voltage, V, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(sol.electric_power, V * np.asarray(sol.current), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(
        sol.mechanical_power, 0.09 * 15 * np.asarray(sol.current) * np.asarray(sol.omega1), rtol=1e-12, atol=1e-9
    )
    # accelerations: derivative of the speeds (central differences on a fine grid)
    tf = jnp.linspace(0.1, 0.2, 2001)
    fine = jb.simulate(jb.Scene(model, cmd, ts=tf, observe=("alpha1", "alpha2")))
    h = float(tf[1] - tf[0])
    for a, w in (("alpha1", "omega1"), ("alpha2", "omega2")):
        fd = (np.asarray(fine[w])[2:] - np.asarray(fine[w])[:-2]) / (2 * h)
        np.testing.assert_allclose(np.asarray(fine[a])[1:-1], fd, atol=2e-3 * np.max(np.abs(fd)))
    # nothing unrequested was computed
    assert set(sol.outputs) == set(obs)
    with pytest.raises(AttributeError, match="observe"):
        _ = jb.simulate(jb.Scene(model, cmd, ts=TS)).electric_power


def test_steady_state_closed_form():
    """At steady state: V = R I + z km w1, z km I w1 = mu w2^2 + tau_r0 w2, w2 = w1 r1/r2."""
    model = jb.BeltStartup(tau_r0=0.7)
    V = 24.0
    sol = jb.simulate(jb.Scene(model, jb.ConstantVoltage(V), t1=20.0))
    z, km, R, mu, rho, t0 = 15.0, 0.09, 0.15, 5.0, 0.5, 0.7
    # z km I = rho (mu rho w1 + t0); V = R I + z km w1
    w1 = (V - R * rho * t0 / (z * km)) / (z * km + R * rho**2 * mu / (z * km))
    I = rho * (mu * rho * w1 + t0) / (z * km)
    y = np.asarray(sol.ys[-1])
    np.testing.assert_allclose(y[2:], [w1, rho * w1, I], rtol=1e-9)


@pytest.mark.parametrize("method", ["expm", "modal", "ode", "rk4"])
def test_vmap_over_gamma_matches_loop(method):
    model = jb.BeltStartup()
    ts = jnp.linspace(0.0, 0.2, 101)
    gammas = jnp.array([0.02, 0.04, 0.06])

    def run(g):
        return jb.simulate(
            jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=ts), method=method, rtol=1e-10, atol=1e-12
        ).ys

    batched = jax.vmap(run)(gammas)
    assert batched.shape == (3, 101, 5)
    for i, g in enumerate(gammas):
        np.testing.assert_allclose(
            batched[i], reference(model, jb.ExponentialVoltage(24.0, g), ts), rtol=0, atol=2e-7 * 200
        )


def test_vmap_over_model_parameter():
    ts = jnp.linspace(0.0, 0.2, 101)
    ks = jnp.array([60e3, 120e3, 240e3])
    cmd = jb.ExponentialVoltage(24.0, 0.02)
    out = jax.vmap(lambda k: jb.simulate(jb.Scene(jb.BeltStartup(k=k), cmd, ts=ts)).ys)(ks)
    for i, k in enumerate(np.asarray(ks)):
        assert rel_err(out[i], reference(jb.BeltStartup(k=float(k)), cmd, ts)) < 1e-9


def test_gradients_against_finite_differences():
    """d(omega2 at 0.1 s)/d gamma and d/dk by autodiff through the closed form."""
    ts = jnp.linspace(0.0, 0.1, 51)

    def w2(g, k):
        return jb.simulate(jb.Scene(jb.BeltStartup(k=k), jb.ExponentialVoltage(24.0, g), ts=ts)).omega2[-1]

    g0, k0 = 0.03, 120e3
    dg, dk = jax.grad(w2, argnums=(0, 1))(g0, k0)
    hg, hk = 1e-6, 1.0
    fd_g = (w2(g0 + hg, k0) - w2(g0 - hg, k0)) / (2 * hg)
    fd_k = (w2(g0, k0 + hk) - w2(g0, k0 - hk)) / (2 * hk)
    np.testing.assert_allclose(dg, fd_g, rtol=1e-6)
    np.testing.assert_allclose(dk, fd_k, rtol=1e-5)
    # modal path: gradient w.r.t. the command (the eigen-decomposition does not depend on gamma)
    dgm = jax.grad(
        lambda g: jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, g), ts=ts), method="modal").omega2[
            -1
        ]
    )(g0)
    np.testing.assert_allclose(dgm, fd_g, rtol=1e-6)
    # and under vmap
    gs = jnp.array([0.02, 0.03, 0.05])
    vg = jax.vmap(jax.grad(lambda g: w2(g, k0)))(gs)
    for i, g in enumerate(np.asarray(gs)):
        np.testing.assert_allclose(vg[i], (w2(g + hg, k0) - w2(g - hg, k0)) / (2 * hg), rtol=1e-6)


def _chain_reference_rhs(model):
    A, B = (np.asarray(a) for a in model.matrices())
    return A, B


def test_belt_chain_n1_equals_startup_and_n3_against_scipy():
    m = jb.BeltStartup()
    chain = jb.BeltChain.from_startup(m)
    A1, B1 = m.matrices()
    A2, B2 = chain.matrices()
    np.testing.assert_array_equal(np.asarray(A1), np.asarray(A2))
    np.testing.assert_array_equal(np.asarray(B1), np.asarray(B2))
    # three stages in series: 4 shafts, 9 states; compare with scipy Radau on hand-written equations
    ch = jb.BeltChain(
        inertias=[0.018, 0.05, 0.08, 0.25],
        k=[120e3, 90e3, 60e3],
        c=[20.0, 15.0, 10.0],
        r_drive=[0.08, 0.06, 0.05],
        r_driven=[0.16, 0.12, 0.1],
    )
    assert ch.state_names == ("theta1", "theta2", "theta3", "theta4", "omega1", "omega2", "omega3", "omega4", "current")
    cmd = jb.ExponentialVoltage(24.0, 0.02)
    ts = jnp.linspace(0.0, 0.3, 61)
    sol = jb.simulate(jb.Scene(ch, cmd, ts=ts))
    J = np.array([0.018 + 225 * 4e-4, 0.05, 0.08, 0.25])
    k, c = np.array([120e3, 90e3, 60e3]), np.array([20.0, 15.0, 10.0])
    ra, rb = np.array([0.08, 0.06, 0.05]), np.array([0.16, 0.12, 0.1])

    def rhs(t, x):
        th, w, I = x[:4], x[4:8], x[8]
        tq = np.zeros(4)
        for i in range(3):  # belt force of stage i (two branches): 2k delta + 2c delta_dot
            f = 2 * k[i] * (ra[i] * th[i] - rb[i] * th[i + 1]) + 2 * c[i] * (ra[i] * w[i] - rb[i] * w[i + 1])
            tq[i] -= ra[i] * f
            tq[i + 1] += rb[i] * f
        tq[0] += 15 * 0.09 * I
        tq[3] -= 5.0 * w[3]
        V = 24 * (1 - np.exp(-t / 0.02))
        return np.concatenate([w, tq / J, [(V - 0.15 * I - 15 * 0.09 * w[0]) / 0.2e-3]])

    ref = solve_ivp(rhs, (0, 0.3), np.zeros(9), method="Radau", t_eval=np.asarray(ts), rtol=1e-11, atol=1e-12).y.T
    assert rel_err(sol.ys, ref) < 1e-6


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"j1": 0.0}, "j1"),
        ({"k": -1.0}, "k"),
        ({"R": 0.0}, "R"),
        ({"L": -1e-3}, "L"),
        ({"jm": float("nan")}, "jm"),
        ({"c": -1.0}, "c"),
    ],
)
def test_bad_model_parameters(kwargs, name):
    # the physical range of each (jaxbelt.models._ranges): zero, negative and NaN lie outside it
    with pytest.raises(ValueError, match=rf"`{name}` must lie in \[(0|[0-9.e+-]+), [0-9.e+]+\]"):
        jb.BeltStartup(**kwargs)


def test_bad_inputs():
    model = jb.BeltStartup()
    with pytest.raises(ValueError, match=r"`gamma` must lie in \[1e-06, inf\) s"):
        jb.ExponentialVoltage(24.0, 0.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        jb.Scene(model, jb.ExponentialVoltage(), ts=jnp.array([0.0, 0.2, 0.1]))
    with pytest.raises(ValueError, match="1-D"):
        jb.Scene(model, jb.ExponentialVoltage(), ts=jnp.zeros((3, 2)))
    with pytest.raises(ValueError, match="`y0` must have shape \\(5,\\)"):
        jb.Scene(model, jb.ExponentialVoltage(), ts=TS, y0=jnp.zeros(3))
    with pytest.raises(ValueError, match="`ts`.*or `t1`"):
        jb.Scene(model, jb.ExponentialVoltage())
    with pytest.raises(ValueError, match="`method` must be one of"):
        jb.simulate(jb.Scene(model, jb.ExponentialVoltage(), ts=TS), method="euler")
    with pytest.raises(ValueError, match=r"`k` must have shape \(1,\) for 1 stages"):
        jb.BeltChain(inertias=[1.0, 1.0], k=[1.0, 2.0], c=[0.0], r_drive=[0.1], r_driven=[0.1])


def test_failed_solve_raises_clear_error():
    scene = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(), ts=TS)
    with pytest.raises(jb.SolveError, match="BeltStartup driven by ExponentialVoltage"):
        jb.simulate(scene, method="ode", max_steps=10)
    sol = jb.simulate(scene, method="ode", max_steps=10, throw=False)
    assert not bool(sol.success)
