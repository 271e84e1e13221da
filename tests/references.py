"""Independent references shared by the tests: numpy/scipy only, no jaxbelt solver code.

The start-up model enters only through its matrices A and B, which `test_startup.py` checks
entry by entry against eq. (10)-(11) of Incerti (2014).
"""

import numpy as np
import scipy.linalg as sl
from scipy.optimize import linprog


def expm_reference(A, F, s, x0, ts):
    """States of $x' = A x + \\sum_j F_{:,j} e^{s_j t}$, $x(t_0) = x_0$ at `ts` ($t_0$ = ts[0]), by
    scipy's matrix exponential of the system augmented with the exponential generators."""
    A, F, s = np.asarray(A, float), np.asarray(F, float), np.asarray(s, float)
    n, m = F.shape
    Aa = np.zeros((n + m, n + m))
    Aa[:n, :n], Aa[:n, n:], Aa[n:, n:] = A, F, np.diag(s)
    ts = np.asarray(ts, dtype=float)
    t0 = float(ts[0])
    z0 = np.concatenate([np.asarray(x0, float), np.exp(s * t0)])
    return np.array([sl.expm(Aa * (t - t0)) @ z0 for t in ts])[:, :n]


def startup_reference(model, ts, v_max=24.0, gamma=None, x0=None):
    """Start-up states for $V = V_{max}(1 - e^{-t/\\gamma})$ (or a constant $V_{max}$ when gamma
    is None) and the model's constant load torque, from rest unless `x0` is given."""
    A, B = (np.asarray(a, dtype=float) for a in model.matrices())
    const = B[:, 0] * float(model.tau_r0) + float(v_max) * B[:, 1]
    x0 = np.zeros(A.shape[0]) if x0 is None else x0
    if gamma is None:
        return expm_reference(A, const[:, None], np.array([0.0]), x0, ts)
    F = np.stack([const, -float(v_max) * B[:, 1]], axis=1)
    return expm_reference(A, F, np.array([0.0, -1.0 / float(gamma)]), x0, ts)


def modal_residual_reference(frequencies, damping_ratios, gains, accel, breaks, T, factors=(1.0,), nodes=12):
    """Residual amplitude [m] of each mode of $q'' + 2\\zeta\\omega q' + \\omega^2 q = -g\\,a(t)$ after a move of
    acceleration `accel` (a vectorised callable of numpy times) that ends at `T`, from rest, at the mode
    frequencies scaled by each of `factors`: shape (n_modes, len(factors)).

    Duhamel's integral of the impulse response $h(t) = e^{-\\sigma t}\\sin(\\omega_d t)/\\omega_d$ gives $q(T)$ and
    $q'(T)$; the amplitude is the envelope $\\sqrt{q^2 + ((q' + \\sigma q)/\\omega_d)^2}$. The integrals are taken by
    Gauss-Legendre on panels between the command's `breaks` (where the acceleration or its derivatives jump), each
    panel at most 0.5 rad of the fastest oscillation long: the integrand is smooth on a panel, so the rule is exact
    to rounding for the piecewise-polynomial moves."""
    f = np.asarray(frequencies, float)
    z = np.asarray(damping_ratios, float)
    g = np.asarray(gains, float)
    r = np.atleast_1d(np.asarray(factors, float))
    T = float(T)
    edges = np.unique(np.clip(np.r_[0.0, np.asarray(breaks, float).ravel(), T], 0.0, T))
    w_max = 2 * np.pi * f.max() * r.max()
    panels = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a <= 0 or not np.any(np.asarray(accel(np.linspace(a, b, 7)[1:-1]), float)):
            continue  # a piece of a piecewise-cubic acceleration that is 0 at 5 points is 0 (a cruise)
        k = max(1, int(np.ceil(w_max * (b - a) / 0.5)))
        panels.append(np.linspace(a, b, k + 1))
    if not panels:
        return np.zeros((f.size, r.size))
    lo = np.concatenate([p[:-1] for p in panels])
    hi = np.concatenate([p[1:] for p in panels])
    x, wq = np.polynomial.legendre.leggauss(nodes)
    tau = (0.5 * (hi - lo)[:, None] * (x + 1) + lo[:, None]).ravel()
    weight = (0.5 * (hi - lo)[:, None] * wq).ravel()
    wa = weight * np.asarray(accel(tau), float)
    u = T - tau
    out = np.empty((f.size, r.size))
    chunk = max(1, int(2e6 // tau.size))  # factors at a time: arrays of at most ~2e6 entries
    for i in range(f.size):
        for j in range(0, r.size, chunk):
            w = 2 * np.pi * f[i] * r[j : j + chunk, None]
            sigma, wd = z[i] * w, w * np.sqrt(1 - z[i] ** 2)
            env = np.exp(-sigma * u)
            s, c = np.sin(wd * u), np.cos(wd * u)
            q = -g[i] * np.sum(env * s / wd * wa, axis=-1)
            qd = -g[i] * np.sum(env * (c - sigma / wd * s) * wa, axis=-1)
            out[i, j : j + chunk] = np.sqrt(q**2 + ((qd + sigma[:, 0] * q) / wd[:, 0]) ** 2)
    return out


def executed_residual_reference(frequencies, damping_ratios, gains, t, x, factors=(1.0,)):
    """Residual amplitude [m] of each mode of $q'' + 2\\zeta\\omega q' + \\omega^2 q = -g\\,x''(t)$ after a drive
    executes the position setpoints `x` [m] at the uniform times `t` [s], linear between them (at rest before the
    first and after the last), at the mode frequencies scaled by each of `factors`: shape (n_modes, len(factors)).

    The velocity is constant between setpoints, so $x''$ is a train of impulses, the velocity's jumps: each kicks
    $q'$ by $-g\\,\\Delta v_k$, and the exact propagator $e^{Ah}$ of the mode (scipy's `expm`, stacked over the
    factors) carries $(q, q')$ from one setpoint to the next. No jaxbelt evaluator is involved."""
    f, z, g = (np.asarray(a, float) for a in (frequencies, damping_ratios, gains))
    r = np.atleast_1d(np.asarray(factors, float))
    t, x = np.asarray(t, float), np.asarray(x, float)
    h = float(t[1] - t[0])
    dv = np.diff(np.concatenate([[0.0], np.diff(x) / h, [0.0]]))
    out = np.empty((f.size, r.size))
    for i in range(f.size):
        w = 2 * np.pi * f[i] * r
        A = np.zeros((r.size, 2, 2))
        A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = 1.0, -(w**2), -2 * z[i] * w
        P = sl.expm(A * h)
        y = np.zeros((r.size, 2))
        for k in range(t.size):
            y[:, 1] -= g[i] * dv[k]
            if k < t.size - 1:
                y = np.einsum("kij,kj->ki", P, y)
        wd = w * np.sqrt(1 - z[i] ** 2)
        out[i] = np.hypot(y[:, 0], (y[:, 1] + z[i] * w * y[:, 0]) / wd)
    return out


def spline_move_reference(coefficients, duration):
    """`(acceleration, velocity, position, breaks)` of a move whose acceleration is $\\sum_j c_j B_j(t)$, $B_j$ the
    cubic B-spline on the knots $jh .. (j+4)h$, $h = T/N$, N = len(c) + 3 (scipy's `BSpline`; the acceleration and
    velocity zero outside [0, T], the position held after T)."""
    from scipy.interpolate import BSpline

    c = np.asarray(coefficients, float)
    T = float(duration)
    n = c.size + 3
    h = T / n
    acc = BSpline(h * np.arange(-3, n + 4), np.r_[0.0, 0.0, 0.0, c, 0.0, 0.0, 0.0], 3, extrapolate=False)
    vel = acc.antiderivative()
    pos = vel.antiderivative()

    def inside(f, hold=False):
        def at(t):
            t = np.asarray(t, float)
            v = np.nan_to_num(f(np.clip(t, 0.0, T)))
            return np.where(t < 0, 0.0, v if hold else np.where(t <= T, v, 0.0))

        return at

    return inside(acc), inside(vel), inside(pos, hold=True), h * np.arange(n + 1)


def fastest_time_reference(distance, v_max, a_max, j_max=None):
    """The time-optimal rest-to-rest time [s] in closed form: bang-coast-bang without `j_max`; with it the
    symmetric double-S (seven-segment) profile of Biagiotti & Melchiorri (2008), "Trajectory Planning for Automatic
    Machines and Robots", eqs. (3.19)-(3.30) with v0 = v1 = 0 (cruise if the distance allows, else the acceleration
    phase of eq. (3.26), else no constant-acceleration segment)."""
    D, v, a = abs(float(distance)), float(v_max), float(a_max)
    if j_max is None:
        return D / v + v / a if D >= v * v / a else 2.0 * np.sqrt(D / a)
    j = float(j_max)
    # acceleration phase reaching v: with a constant-acceleration segment when v j >= a^2
    Ta = a / j + v / a if v * j >= a * a else 2.0 * np.sqrt(v / j)
    if D / v >= Ta:  # the distance allows cruising at v: T = Ta + Tv + Td with Tv = D / v - Ta
        return D / v + Ta
    Tj = a / j  # no cruise, a_max reached: eq. (3.26)
    Ta = (a * a / j + np.sqrt(a**4 / j**2 + 4.0 * a * D)) / (2.0 * a)
    if Ta < 2.0 * Tj:  # a_max not reached: two jerk phases only
        Ta = 2.0 * (D / (2.0 * j)) ** (1.0 / 3.0)
    return 2.0 * Ta


def piecewise_move_reference(times, steps, ramps, duration):
    """`(acceleration, velocity, position, breaks)` of $a(t) = \\sum_k \\alpha_k H(t - t_k) + \\beta_k (t - t_k)_+$
    on [0, T] (at rest after T)."""
    tk, st, rp = (np.asarray(x, float) for x in (times, steps, ramps))
    T = float(duration)

    def acc(t):
        t = np.asarray(t, float)
        d = np.maximum(t[..., None] - tk, 0.0)
        return np.where((t >= 0) & (t <= T), np.sum(st * (t[..., None] >= tk) + rp * d, axis=-1), 0.0)

    def vel(t):
        t = np.asarray(t, float)
        d = np.maximum(np.minimum(t, T)[..., None] - tk, 0.0)
        return np.where((t >= 0) & (t <= T), np.sum(st * d + rp * d**2 / 2, axis=-1), 0.0)

    def pos(t):
        t = np.asarray(t, float)
        d = np.maximum(np.minimum(t, T)[..., None] - tk, 0.0)
        return np.sum(st * d**2 / 2 + rp * d**3 / 6, axis=-1)

    return acc, vel, pos, tk


def highs_lp_value(c, G, h, A, b) -> float:
    """The optimal value of min c x s.t. G x <= h, A x = b (x free) by scipy's HiGHS at tight tolerances: the
    independent reference of jaxbelt's interior point method on the same LP."""
    ref = linprog(
        np.asarray(c),
        A_ub=np.asarray(G),
        b_ub=np.asarray(h),
        A_eq=np.asarray(A),
        b_eq=np.asarray(b),
        bounds=[(None, None)] * len(c),
        method="highs",
        options=dict(primal_feasibility_tolerance=1e-10, dual_feasibility_tolerance=1e-10),
    )
    assert ref.status == 0, ref.message
    return float(ref.fun)


def highs_steps_lp(design, cells: int) -> float:
    """The least worst residual over `design`'s own frequencies and cuts of a piecewise-constant acceleration on
    `cells` equal intervals, within the design's |a| and |v| limits (exact: |v| at the interval ends), distance and
    rest to rest: an LP written here from the definitions and solved by HiGHS. Every such command is a command of
    the continuous problem, so the value bounds its optimum (on these frequencies) from above."""
    p, o = design.problem, design.options
    T, D, A, V = (float(np.asarray(x)) for x in (p.move_time, p.distance, p.a_max, p.v_max))
    mask = np.asarray(p.mask) > 0
    w = np.asarray(p.axis.omega)[:, None] * np.asarray(p.factors)
    z = np.asarray(p.axis.damping_ratios)[:, None] * np.ones_like(w)
    wd = w * np.sqrt(1 - z**2)
    s = (-z * w + 1j * wd)[mask]
    gains = np.abs(np.asarray(p.axis.gains))[:, None] * np.ones_like(w)
    weight = (gains / (wd * np.asarray(p.reference)[:, None]))[mask]
    d = T / cells
    u = np.arange(cells) * d
    # int over [u, u + d] of e^{s (T - t)} dt, weighted
    k = np.exp(np.multiply.outer(s, T - u - d)) * ((np.exp(s * d) - 1.0) / s)[:, None] * weight[:, None]
    theta = 2 * np.pi * np.arange(o.n_angles) / o.n_angles
    cuts = np.real(np.exp(-1j * theta)[:, None, None] * k[None]).reshape(-1, cells)
    vel = np.tril(np.ones((cells, cells))) * d
    G = np.vstack(
        [
            np.hstack([cuts, -np.ones((cuts.shape[0], 1))]),
            np.hstack([vel, np.zeros((cells, 1))]),
            np.hstack([-vel, np.zeros((cells, 1))]),
        ]
    )
    h = np.r_[np.zeros(cuts.shape[0]), np.full(2 * cells, V)]
    A_eq = np.array([np.r_[np.full(cells, d), 0.0], np.r_[d * (T - u - d / 2), 0.0]])
    r = linprog(
        np.r_[np.zeros(cells), 1.0],
        A_ub=G,
        b_ub=h,
        A_eq=A_eq,
        b_eq=[0.0, D],
        bounds=[(-A, A)] * cells + [(0, None)],
        method="highs",
    )
    assert r.status == 0, r.message
    return float(r.fun)
