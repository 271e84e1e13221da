"""Four-bar linkage + DC motor + PID (Incerti, 2012): kinematics, dynamics, χ, tuning.

References: loop closure and autodiff of the closed-form angles; a direct Lagrangian
(kinetic energy summed over the links from the centre-of-mass velocities); central finite
differences; an independent numpy implementation integrated by scipy (LSODA, rtol 1e-10);
the energy balance; the paper's χ values.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxbelt as jb
from jaxbelt.models.fourbar import ASSUMED_PARAMETERS, IDENTIFIED_PARAMETERS
from jaxbelt.objectives import chi_from_samples

ALPHA = jnp.linspace(0.0, 2 * np.pi, 721)


@pytest.fixture(scope="module")
def drive():
    return jb.FourBarDrive()


@pytest.fixture(scope="module")
def skew():
    """A second geometry with off-line centres of mass and the other assembly mode."""
    return jb.FourBarDrive(
        a=0.08,
        b=0.32,
        c=0.25,
        hx=0.28,
        hy=-0.04,
        f1=0.03,
        f2=0.12,
        f3=0.1,
        theta1=0.3,
        theta2=-0.4,
        theta3=0.7,
        m1=0.3,
        m2=0.5,
        m3=0.2,
        assembly=-1,
    )


# --- kinematics -----------------------------------------------------------------------------
@pytest.mark.parametrize("k", [1, -1])
def test_loop_closure_full_turn(k):
    d = jb.FourBarDrive(assembly=k)
    p = d.points(ALPHA)
    # A + AB + BC - D - DC = 0 (closure of the vector loop), and the coupler keeps its length b
    beta, gamma = d.angles(ALPHA)
    c_vec = d.c * jnp.stack([jnp.cos(gamma), jnp.sin(gamma)], -1)
    gap = p["C"] - p["D"] - c_vec
    assert float(jnp.max(jnp.abs(gap))) < 1e-12
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(p["C"] - p["B"], axis=-1) - d.b))) < 1e-12


def test_assembly_modes_are_mirror_images(drive):
    # the two solutions for C are reflections of each other about the line BD
    other = jb.FourBarDrive(assembly=-1)
    p1, p2 = drive.points(ALPHA), other.points(ALPHA)
    bd = p1["D"] - p1["B"]
    u = bd / jnp.linalg.norm(bd, axis=-1, keepdims=True)
    r1, r2 = p1["C"] - p1["B"], p2["C"] - p2["B"]
    along1, along2 = jnp.sum(r1 * u, -1), jnp.sum(r2 * u, -1)
    cross1 = r1[:, 0] * u[:, 1] - r1[:, 1] * u[:, 0]
    cross2 = r2[:, 0] * u[:, 1] - r2[:, 1] * u[:, 0]
    assert float(jnp.max(jnp.abs(along1 - along2))) < 1e-12
    assert float(jnp.max(jnp.abs(cross1 + cross2))) < 1e-12
    assert float(jnp.min(jnp.abs(cross1))) > 1e-3


@pytest.mark.parametrize("which", ["drive", "skew"])
def test_velocity_ratios_equal_autodiff(which, request):
    d = request.getfixturevalue(which)
    Q, R = d.velocity_ratios(ALPHA)
    dbeta = jax.vmap(jax.grad(lambda a: d.angles(a)[0]))(ALPHA)
    dgamma = jax.vmap(jax.grad(lambda a: d.angles(a)[1]))(ALPHA)
    np.testing.assert_allclose(Q, dbeta, rtol=0, atol=1e-12)
    np.testing.assert_allclose(R, dgamma, rtol=0, atol=1e-12)


@pytest.mark.parametrize("which", ["drive", "skew"])
def test_inertia_equals_direct_lagrangian(which, request):
    """J(α) of Appendix C against 2 Ek / α̇² summed link by link from autodiff velocities."""
    d = request.getfixturevalue(which)

    def ek_unit(a):  # kinetic energy at α̇ = 1
        vel = jax.jacfwd(lambda x: d.points(x))(a)
        dbeta, dgamma = jax.grad(lambda x: d.angles(x)[0])(a), jax.grad(lambda x: d.angles(x)[1])(a)
        sq = {k: jnp.sum(v**2) for k, v in vel.items()}
        return 0.5 * (
            d.m1 * sq["G1"] + d.jg1 + d.m2 * sq["G2"] + d.jg2 * dbeta**2 + d.m3 * sq["G3"] + d.jg3 * dgamma**2
        )

    J_direct = 2 * jax.vmap(ek_unit)(ALPHA)
    np.testing.assert_allclose(d.inertia(ALPHA), J_direct, rtol=1e-12)
    # Ep from the centre-of-mass heights of points()
    p = d.points(ALPHA)
    ep_direct = d.g * (d.m1 * p["G1"][:, 1] + d.m2 * p["G2"][:, 1] + d.m3 * p["G3"][:, 1])
    np.testing.assert_allclose(d.potential_energy(ALPHA), ep_direct, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("which", ["drive", "skew"])
def test_dJ_dEp_against_finite_differences(which, request):
    d = request.getfixturevalue(which)
    h = 1e-5
    _, _, dJ, dEp = d.inertia_and_potential(ALPHA)
    fd_J = (d.inertia(ALPHA + h) - d.inertia(ALPHA - h)) / (2 * h)
    fd_E = (d.potential_energy(ALPHA + h) - d.potential_energy(ALPHA - h)) / (2 * h)
    np.testing.assert_allclose(dJ, fd_J, rtol=1e-7, atol=1e-9 * float(jnp.max(jnp.abs(fd_J))))
    np.testing.assert_allclose(dEp, fd_E, rtol=1e-7, atol=1e-9 * float(jnp.max(jnp.abs(fd_E))))


# --- construction checks --------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(a=0.4), "cannot be assembled"),
        (dict(b=0.05, c=0.05), "cannot be assembled"),
        # change-point linkage (s + l = p + q) nudged by 1e-9 m: coupler and rocker align
        (dict(a=0.1, b=0.2, c=0.2 + 1e-9, hx=0.3, hy=0.0), "dead point"),
        (dict(L=0.0), "`L`"),
        (dict(L=-9e-3), "`L`"),
        (dict(jm=0.0), "`jm`"),
        (dict(jg2=-1.0), "`jg2`"),
        (dict(R=0.0), "`R`"),
        (dict(assembly=0), "assembly"),
    ],
)
def test_bad_parameters_raise(kw, match):
    with pytest.raises(ValueError, match=match):
        jb.FourBarDrive(**kw)


def test_pid_rejects_bad_limiter():
    with pytest.raises(ValueError, match="v_limit"):
        jb.PID(v_limit=0.0)
    with pytest.raises(ValueError, match="limiter"):
        jb.PID(v_limit=10.0, limiter="soft")
    with pytest.raises(TypeError, match="controller"):
        jb.PID()(0.1)


def test_smooth_limiter_bounds():
    v = jnp.linspace(-200.0, 200.0, 4001)
    hard = jb.PID(v_limit=60.0, limiter="hard").limit(v)
    for s in (2.0, 0.5, 0.05):
        soft = jb.PID(v_limit=60.0, limiter="smooth", v_smooth=s).limit(v)
        assert float(jnp.max(jnp.abs(soft))) <= 60.0
        # |softclip - clip| <= s log 2, reached at the corners
        assert float(jnp.max(jnp.abs(soft - hard))) <= s * np.log(2) * (1 + 1e-12)


# --- dynamics against an independent numpy/scipy implementation ------------------------------
P = {
    **ASSUMED_PARAMETERS,
    **IDENTIFIED_PARAMETERS,
    "hy": 0.05,
    "jg1": 3.5e-4,
    "jg2": 1.7e-2,
    "jg3": 1.7e-2,
    "L": 9e-3,
    "km": 0.48,
    "jm": 13e-4,
    "ja": 9.8e-5,
    "jb": 9.8e-5,
    "z": 1.0,
    "T0": 0.0,
    "lam": 0.08,
    "g": 9.81,
}


def _np_kin(al, p=P):
    """β, γ by intersecting the circle of radius b about B with the circle of radius c about D."""
    bx, by = p["a"] * math.cos(al), p["a"] * math.sin(al)
    dx, dy = p["hx"] - bx, p["hy"] - by
    d = math.hypot(dx, dy)
    x = (d**2 + p["b"] ** 2 - p["c"] ** 2) / (2 * d)
    yy = math.sqrt(p["b"] ** 2 - x**2)
    ux, uy = dx / d, dy / d
    sgn = -p["assembly"]
    cx, cy = bx + x * ux - sgn * yy * uy, by + x * uy + sgn * yy * ux
    return math.atan2(cy - by, cx - bx), math.atan2(cy - p["hy"], cx - p["hx"])


def _np_energy_coeffs(al, p=P):
    """J, dJ/dα, dEp/dα by the textbook velocity and acceleration analysis (α̇ = 1, α̈ = 0).

    Loop a e(α) + b e(β) = h + c e(γ), differentiated twice and projected on e(γ), e(β);
    then J = Σ m|r_G'|² + J_G θ'², J' = 2 Σ m r_G'·r_G'' + 2 J_G θ' θ'', Ep' = g Σ m y_G'.
    """
    a, b, c = p["a"], p["b"], p["c"]
    be, ga = _np_kin(al, p)
    s = math.sin(ga - be)
    Q = a * math.sin(al - ga) / (b * s)
    R = a * math.sin(al - be) / (c * s)
    Q2 = (a * math.cos(al - ga) + b * Q**2 * math.cos(be - ga) - c * R**2) / (b * s)
    R2 = (-a * math.cos(al - be) - b * Q**2 + c * R**2 * math.cos(ga - be)) / (-c * s)

    def e(x):
        return np.array([math.cos(x), math.sin(x)])

    def ep(x):
        return np.array([-math.sin(x), math.cos(x)])

    # (mass, r', r'', inertia, θ', θ'')
    links = [
        (p["m1"], p["f1"] * ep(al), -p["f1"] * e(al), p["jg1"], 1.0, 0.0),
        (
            p["m2"],
            a * ep(al) + p["f2"] * Q * ep(be),
            -a * e(al) + p["f2"] * (Q2 * ep(be) - Q**2 * e(be)),
            p["jg2"],
            Q,
            Q2,
        ),
        (p["m3"], p["f3"] * R * ep(ga), p["f3"] * (R2 * ep(ga) - R**2 * e(ga)), p["jg3"], R, R2),
    ]
    J = sum(m * v @ v + jg * w**2 for m, v, _, jg, w, _ in links)
    dJ = sum(2 * m * v @ acc + 2 * jg * w * dw for m, v, acc, jg, w, dw in links)
    dEp = p["g"] * sum(m * v[1] for m, v, *_ in links)
    return J, dJ, dEp


def _np_rhs(t, y, ctrl, p=P, phi0=0.0):
    al, w, i = y
    J, dJ, dEp = _np_energy_coeffs(al, p)
    jeq = p["jb"] + (p["jm"] + p["ja"]) * p["z"] ** 2
    acc = (p["z"] * (p["km"] * i - p["T0"] - p["z"] * p["lam"] * w) - dEp - 0.5 * dJ * w**2) / (jeq + J)
    if ctrl[0] == "const":
        v = ctrl[1]
    else:
        kp, ki, kd, w0 = ctrl[1:5]
        gain = kp * t if ctrl[0] == "pid" else kp  # eq. 16 (ramped) or eq. 14 (constant)
        v = gain * (w0 - p["z"] * w) + ki * (w0 * t - (p["z"] * al - phi0)) - kd * p["z"] * acc
    return [w, acc, (v - p["R"] * i - p["km"] * p["z"] * w) / p["L"]]


def test_numpy_reference_coefficients_agree(drive):
    al = np.linspace(0, 2 * np.pi, 13)
    ref = np.array([_np_energy_coeffs(a) for a in al])
    J, _, dJ, dEp = drive.inertia_and_potential(jnp.asarray(al))
    np.testing.assert_allclose(J, ref[:, 0], rtol=1e-12)
    np.testing.assert_allclose(dJ, ref[:, 1], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(dEp, ref[:, 2], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize(
    "ctrl, alpha0",
    [
        (("const", 25.0), 0.0),
        (("pid", 80.0, 32.0, 0.015, 30.0), 0.0),
        (("pid", 80.0, 32.0, 0.015, 30.0), 1.0),
        (("pid_constant", 20.0, 32.0, 0.015, 30.0), 0.7),
    ],
    ids=["open", "pid", "pid-alpha0", "pid-constant-gain"],
)
def test_simulation_matches_scipy(drive, ctrl, alpha0):
    import diffrax

    ts = np.linspace(0.0, 0.5, 251)
    if ctrl[0] == "const":
        inp = jb.ConstantVoltage(ctrl[1])
    else:
        inp = jb.PID(*ctrl[1:], gain="ramped" if ctrl[0] == "pid" else "constant")
    d = eqx.tree_at(lambda m: m.alpha0, drive, jnp.asarray(alpha0))
    sol = jb.simulate(jb.Scene(d, inp, ts=ts), solver=diffrax.Dopri8(), rtol=1e-11, atol=1e-11)
    ref = solve_ivp(
        _np_rhs,
        (0, 0.5),
        [alpha0, 0.0, 0.0],
        method="LSODA",
        t_eval=ts,
        rtol=1e-10,
        atol=1e-10,
        args=(ctrl, P, P["z"] * alpha0),
    )
    assert ref.success
    ys = np.asarray(sol.ys)
    for j in range(3):
        err = np.max(np.abs(ys[:, j] - ref.y[j])) / np.max(np.abs(ref.y[j]))
        assert err < 1e-6, (j, err)


def test_contract_shapes_and_rk4_order(drive):
    ts = jnp.linspace(0.0, 1.0, 2001)
    closed = jb.simulate(jb.Scene(drive, jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0), ts=ts))
    assert closed.ys.shape == (2001, 3)
    # the paper's fixed-step RK4 at 1 ms: fourth order, error ratio 2^4 when halving the step
    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
    ts = np.linspace(0.0, 0.5, 126)
    fine = jb.simulate(jb.Scene(drive, pid, ts=ts), rtol=1e-11, atol=1e-11).ys
    e1 = np.max(np.abs(jb.simulate(jb.Scene(drive, pid, ts=ts), method="rk4", dt=1e-3).ys - fine), axis=0)
    e2 = np.max(np.abs(jb.simulate(jb.Scene(drive, pid, ts=ts), method="rk4", dt=5e-4).ys - fine), axis=0)
    ratio = e1 / e2
    assert np.all((ratio > 12) & (ratio < 20)), ratio


def test_energy_balance_closed_loop(drive):
    names = ("electric_energy", "copper_loss", "friction_loss", "kinetic_energy", "potential_energy", "magnetic_energy")
    ts = jnp.linspace(0.0, 1.0, 11)
    sol = jb.simulate(jb.Scene(drive, jb.PID(v_limit=40.0), ts=ts, observe=names), rtol=1e-10, atol=1e-10)
    stored = sol.kinetic_energy + sol.potential_energy + sol.magnetic_energy
    residual = sol.electric_energy - sol.copper_loss - sol.friction_loss - (stored - stored[0])
    assert float(jnp.max(jnp.abs(residual))) < 1e-7 * float(jnp.max(sol.electric_energy))
    assert float(sol.electric_energy[-1]) > 10.0  # a non-trivial amount of energy went through


# --- the paper's indices --------------------------------------------------------------------
def test_default_drive_reproduces_both_published_indices(drive):
    """Incerti (2012), Sec. III: 54.3 % open loop (25 V, 0.5-1 s), 2.6 % closed loop (0.375-0.5 s)."""
    ts = jnp.linspace(0.0, 1.0, 2001)
    sol = jb.simulate(jb.Scene(drive, jb.ConstantVoltage(25.0), ts=ts))
    chi_open = float(jb.fluctuation_index(sol, t0=0.5, t1=1.0))
    assert abs(chi_open - 0.543) < 0.01, chi_open
    sol = jb.simulate(jb.Scene(drive, jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0), ts=ts))
    chi_closed = float(jb.fluctuation_index(sol, t0=0.375, t1=0.5))
    assert abs(chi_closed - 0.026) < 0.003, chi_closed


def test_assumed_table_keeps_the_first_guess():
    old = jb.FourBarDrive.assumed_table()
    assert float(old.a) == 0.10 and float(old.R) == 1.5
    ts = jnp.linspace(0.0, 0.5, 1001)
    sol = jb.simulate(jb.Scene(old, jb.PID(), ts=ts))
    # the value the assumed set gave before identification (5.6 %, twice the paper's 2.6 %)
    assert abs(float(jb.fluctuation_index(sol, 0.375, 0.5)) - 0.056) < 0.001


@pytest.mark.slow
def test_documented_defaults_are_the_least_squares_fit_of_the_published_indices():
    """The defaults a, R (`IDENTIFIED_PARAMETERS`) are the weighted least-squares fit of the two published
    indices (χ = 0.543 open loop, 0.026 closed loop; Incerti, 2012), with the rounding of the published
    figures as noise (σ = 0.05 %/√3): at the defaults the Gauss-Newton step is below a quarter of a
    standard error (their rounding) and the standard errors are the documented ones (`IDENTIFIED_STDERR`)
    to 20 %. The Jacobian is an independent one: central differences of the fixed-step solve (relative
    step 1e-4; truncation ~1e-8, far below the 20 % asked). `jb.identify` itself is tested against known
    parameters in test_identify.py."""
    from jaxbelt.models.fourbar import IDENTIFIED_STDERR
    from jaxbelt.objectives import closed_loop_metrics

    base = jb.FourBarDrive()

    @jax.jit
    def indices(a, R):
        d = eqx.tree_at(lambda m: (m.a, m.R), base, (a, R))
        o = closed_loop_metrics(d, jb.ConstantVoltage(25.0), 0.5, 1.0, method="rk4", dt=1e-3, max_steps=1024)["chi"]
        c = closed_loop_metrics(d, jb.PID(), 0.375, 0.5, method="rk4", dt=1e-3, max_steps=1024)["chi"]
        return jnp.stack([o, c])

    data, sigma = np.array([0.543, 0.026]), 0.0005 / np.sqrt(3)
    names = ("a", "R")
    p = np.array([IDENTIFIED_PARAMETERS[k] for k in names])
    r = (np.asarray(indices(*p)) - data) / sigma
    cols = []
    for i in range(2):
        h = np.zeros(2)
        h[i] = 1e-4 * p[i]
        cols.append((np.asarray(indices(*(p + h))) - np.asarray(indices(*(p - h)))) / (2 * h[i] * sigma))
    J = np.stack(cols, axis=1)
    step = -np.linalg.solve(J, r)  # two residuals, two parameters: the Gauss-Newton step
    stderr = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    for i, k in enumerate(names):
        assert abs(step[i]) < 0.25 * IDENTIFIED_STDERR[k], (k, step[i])
        assert abs(stderr[i] / IDENTIFIED_STDERR[k] - 1.0) < 0.2, (k, stderr[i])


def test_closed_loop_chi_falls_with_time(drive):
    ts = jnp.linspace(0.0, 1.5, 3001)
    sol = jb.simulate(jb.Scene(drive, jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0), ts=ts))
    period = 2 * np.pi / 30.0  # one crank turn at the set point (z = 1)
    chis = [float(jb.fluctuation_index(sol, t0=k * period, t1=(k + 1) * period)) for k in range(2, 7)]
    assert all(b < a for a, b in zip(chis, chis[1:])), chis
    assert chis[0] < 0.1  # "a few percent"
    # average speed over a turn sits on the set point
    m = (sol.ts >= 5 * period) & (sol.ts <= 6 * period)
    assert abs(float(jnp.mean(sol.alpha_dot[m])) - 30.0) < 0.3


def test_alpha0_shifts_the_scene_and_the_integral_reference():
    """A linkage-free drive (no masses, negligible coupler and rocker inertias, no gravity) is
    invariant under a rotation: starting at alpha0 = 1 rad gives the same speed history as at 0
    and an angle shifted by 1 rad, only if the integral term starts its reference at the start angle."""
    free = jb.FourBarDrive(m1=0.0, m2=0.0, m3=0.0, jg2=1e-12, jg3=1e-12, g=0.0)
    pid = jb.PID()
    ts = jnp.linspace(0.0, 0.5, 101)
    s0 = jb.simulate(jb.Scene(free, pid, ts=ts, observe=("voltage",)), rtol=1e-11, atol=1e-11)
    s1 = jb.simulate(
        jb.Scene(eqx.tree_at(lambda m: m.alpha0, free, jnp.asarray(1.0)), pid, ts=ts, observe=("voltage",)),
        rtol=1e-11,
        atol=1e-11,
    )
    np.testing.assert_allclose(s1.alpha_dot, s0.alpha_dot, atol=1e-6)
    np.testing.assert_allclose(s1.alpha - 1.0, s0.alpha, atol=1e-7)
    # integral term zero at t = 0 for any start angle: V(0) = -Kd z F(alpha0, 0, 0) with the real linkage
    d = jb.FourBarDrive(alpha0=1.0)
    sol = jb.simulate(jb.Scene(d, pid, ts=ts, observe=("voltage",)), rtol=1e-11, atol=1e-11)
    assert float(sol.voltage[0]) == pytest.approx(-0.015 * float(d.accel(1.0, 0.0, 0.0)), rel=1e-12)
    assert float(pid.raw_voltage(0.0, 3.0, 0.0, 0.0, 3.0)) == 0.0


def test_pid_constant_gain_is_eq14():
    # constant gain: Kp e + Ki (w0 t - (phi - phi0)) - Kd phi''; ramped: Kp t e + ...
    c, r = jb.PID(kp=5.0, gain="constant"), jb.PID(kp=5.0)
    args = (0.3, 10.0, 25.0, 4.0, 1.0)  # t, phi, phi', phi'', phi0
    assert float(c.raw_voltage(*args)) == pytest.approx(5.0 * 5.0 + 32.0 * (9.0 - 9.0) - 0.015 * 4.0, rel=1e-14)
    assert float(r.raw_voltage(*args)) == pytest.approx(0.3 * 5.0 * 5.0 - 0.015 * 4.0, rel=1e-14)
    with pytest.raises(ValueError, match="gain"):
        jb.PID(gain="ramp")
    assert c.with_limiter("smooth").gain == "constant"


def test_chi_average_options_closed_form():
    # v = e^t on [0, 1]: max - min = e - 1; time mean e - 1; mid-range (e + 1)/2
    ts = jnp.linspace(0.0, 1.0, 4001)
    v = jnp.exp(ts)
    e = np.e
    assert abs(float(chi_from_samples(ts, v)) - 1.0) < 1e-7
    assert abs(float(chi_from_samples(ts, v, average="midrange")) - 2 * (e - 1) / (e + 1)) < 1e-12
    sm = float(chi_from_samples(ts, v, smooth=True, temperature=1e-4, average="midrange"))
    assert abs(sm - 2 * (e - 1) / (e + 1)) < 2e-3
    with pytest.raises(ValueError, match="average"):
        chi_from_samples(ts, v, average="median")


def test_exact_chi_closed_form():
    # v = 1 + eps sin(2 pi t) over a whole period: max - min = 2 eps, average 1
    ts = jnp.linspace(0.0, 1.0, 4001)
    v = 1.0 + 0.1 * jnp.sin(2 * np.pi * ts)
    assert abs(float(chi_from_samples(ts, v)) - 0.2) < 1e-12
    # smooth version: log-mean-exp of a sinusoid, tau * log I0(eps/tau) per extreme (Bessel I0)
    from scipy.special import i0e

    tau = 1e-2
    smax = 1.0 + tau * np.log(i0e(0.1 / tau)) + 0.1
    assert abs(float(chi_from_samples(ts, v, smooth=True, temperature=tau)) - 2 * (smax - 1.0)) < 1e-8


def test_fluctuation_objective_is_closed_loop_metrics_chi(drive):
    """The objective stores only the window's samples; its χ (exact and smooth) is the full run's to rounding."""
    from jaxbelt.objectives import closed_loop_metrics

    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
    m = closed_loop_metrics(drive, pid, 0.375, 0.5, rtol=1e-6, atol=1e-6, average="midrange")
    for smooth, key in ((False, "chi"), (True, "chi_smooth")):
        chi = jb.fluctuation_objective(drive, pid, 0.375, 0.5, smooth=smooth, rtol=1e-6, atol=1e-6, average="midrange")
        assert abs(float(chi) - float(m[key])) <= 1e-12 * abs(float(m[key])), (key, float(chi), float(m[key]))
    with pytest.raises(TypeError, match="rtl"):
        jb.fluctuation_objective(drive, pid, rtl=1e-6)


# --- gradients ------------------------------------------------------------------------------
def _obj(drive, x):
    """Smooth χ over 0.1-0.2 s (paper's RK4, 1 ms) as a function of x = (Kp, Ki, Kd, R)."""
    pid = jb.PID(v_limit=60.0, limiter="smooth").with_gains(x[:3])
    return jb.fluctuation_objective(eqx.tree_at(lambda d: d.R, drive, x[3]), pid, 0.1, 0.2, method="rk4", dt=1e-3)


@pytest.mark.slow
def test_smooth_chi_gradient_fd_under_vmap(drive):
    """Gradient of the smooth χ w.r.t. the gains and the resistance, for a batch, vs central FD."""
    x0 = jnp.array([80.0, 32.0, 0.015, 1.5])
    batch = jnp.stack([x0, x0 * jnp.array([2.0, 0.5, 3.0, 0.7])])
    h = jnp.array([1e-3, 1e-3, 1e-7, 1e-6])
    steps = jnp.concatenate([jnp.diag(h), -jnp.diag(h)])  # (8, 4)
    pts = (batch[:, None, :] + steps[None]).reshape(-1, 4)
    # one compiled program: gradients at the batch and values at its 16 neighbours
    vals, grads = jax.jit(jax.vmap(jax.value_and_grad(lambda x: _obj(drive, x))))(jnp.concatenate([batch, pts]))
    grads, vals = np.asarray(grads[:2]), np.asarray(vals[2:]).reshape(2, 8)
    fd = (vals[:, :4] - vals[:, 4:]) / (2 * np.asarray(h))
    np.testing.assert_allclose(grads, fd, rtol=1e-5)
    assert np.all(np.abs(grads[:, 2]) > 1e-3)  # the Kd sensitivity is not trivially zero


@pytest.mark.slow
def test_tune_pid_halves_chi(drive):
    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    res = jb.tune_pid(drive, pid, t0=0.375, t1=0.5, steps=12, progress=False)
    # independent check of the tuned gains with the hard limiter on a fresh simulation
    ts = jnp.linspace(0.0, 0.5, 1001)
    sol = jb.simulate(jb.Scene(drive, res.pid, ts=ts, observe=("voltage",)), rtol=1e-10, atol=1e-10)
    base = jb.simulate(jb.Scene(drive, pid, ts=ts), rtol=1e-10, atol=1e-10)
    chi_new = float(jb.fluctuation_index(sol, 0.375, 0.5))
    chi_old = float(jb.fluctuation_index(base, 0.375, 0.5))
    assert chi_new < 0.5 * chi_old, (chi_new, chi_old)
    assert abs(chi_new - res.chi) < 1e-5 and abs(chi_old - res.chi_initial) < 1e-5
    assert float(jnp.max(jnp.abs(sol.voltage))) <= 60.0 + 1e-9
    assert res.history["loss"].shape == (12,)


def test_bad_tuning_and_window_inputs(drive):
    with pytest.raises(ValueError, match="kd"):
        jb.tune_pid(drive, jb.PID(kd=0.0), progress=False)
    with pytest.raises(ValueError, match="t0 < t1"):
        jb.tune_pid(drive, jb.PID(), t0=0.5, t1=0.4, progress=False)
    ts = jnp.linspace(0.0, 1.0, 11)
    with pytest.raises(ValueError, match="two output times"):
        chi_from_samples(ts, jnp.ones(11), 0.31, 0.39)
