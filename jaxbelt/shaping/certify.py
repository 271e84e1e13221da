"""A lower bound on the least worst residual that *any* command can leave: the certificate of the continuous problem.

The minimax design (`jaxbelt.shaping.design`) solves a linear programme over cubic B-spline accelerations on N knot
intervals, and its duality gap certifies that programme: no spline of those knots does better. A command outside the
spline space (finer knots, an acceleration that jumps, as a shaped trapezoid's does) may do better. This module
bounds what any command can do.

**The continuous problem.** Over every acceleration $a \\in L^\\infty(0, T)$ with $|a| \\le a_{max}$, $|v(t)| \\le
v_{max}$, $\\int_0^T a = 0$ (rest to rest) and $\\int_0^T (T - t)\\,a\\,dt = D$, minimise the worst residual $t$ with
$\\mathrm{Re}(e^{-i\\theta_p} w_g W_g(a)) \\le t$ for the design's frequencies g and cut angles p, where
$W_g(a) = \\int_0^T e^{s_g(T-t)} a(t)\\,dt$ is the residual integral of mode and frequency g and $w_g$ its weight
($|g_i| / (\\omega_d R_i)$, R the unshaped move's worst residual). Keeping only the design's frequencies and cuts and
the velocity limit at finitely many times $\\tau_j$ relaxes it (a jerk limit is dropped as well), so the relaxation's
optimum is at most the least worst residual over the whole band of any command, smooth or not.

**Weak duality** (Luenberger, 1969, *Optimization by Vector Space Methods*, ch. 8). For multipliers $z \\ge 0$ of the
cuts with $\\sum z = 1$, $\\mu^\\pm \\ge 0$ of the velocity limits and $y$ of the two equalities, the Lagrangian's
infimum over $|a| \\le a_{max}$ is

$d = -a_{max}\\int_0^T |\\varphi(t)|\\,dt - v_{max}\\sum_j(\\mu_j^+ + \\mu_j^-) - y_2$,
$\\varphi(t) = \\mathrm{Re}\\sum_g \\zeta_g w_g e^{s_g(T-t)} + \\sum_j (\\mu_j^+ - \\mu_j^-)\\,[t < \\tau_j] + y_1 +
y_2 (T - t)/D$, $\\zeta_g = \\sum_p z_{gp} e^{-i\\theta_p}$,

a lower bound of the relaxation for *any* such multipliers. They are taken from the design's own LP (its cut,
velocity and equality multipliers, normalised so that the cuts' sum to 1; the velocity row j stands for
$v(\\tau_j)$: $\\tau_j = (j + 2)h$ for the spline's coefficient, $(j + 1)h$, exactly, for the steps basis). The integral is bounded from above, so the bound stays rigorous:
on each cell of a grid aligned with the knots (where $\\varphi$ is smooth), $\\int|\\varphi| = |\\int\\varphi|$ in
closed form where $\\varphi$ cannot change sign ($|\\varphi(m)| > L\\delta/2$ at the cell's midpoint m, L a bound on
$|\\varphi'|$), else at most $\\delta|\\varphi(m)| + L\\delta^2/4$ on cells refined 64 times.

The bound is as good as the multipliers: at a design whose spline is near the continuous optimum it is near that
optimum; at a coarse design it can be far below it (then more knots make both the design and the bound better).

**A jerk limit** (the spline or the ramps basis with `j_max`): the bound stays rigorous (the multipliers are any,
the relaxation drops the jerk limit, which only raises the least residual), but it bounds the problem without the
jerk limit, and the LP's jerk multipliers are left out: where the jerk limit binds, the bound can lie far below the
design. `design_move` computes it for the steps basis only (no jerk limit); for the ramps basis (its velocity row j
is the middle Bernstein coefficient of $v$ on $[(j + 1)h, (j + 2)h]$, not a value of $v$) $\tau_j = (j + 1)h$ is
taken, which any multiplier allows.
"""

from __future__ import annotations

import numpy as np

from .design import n_coefficients


def _phi_parts(design):
    """The terms of $\\varphi$ (see the module docstring) from the design's LP multipliers, in the units of the
    design's worst residual, or None where the multipliers say nothing (no positive cut multiplier)."""
    p, o = design.problem, design.options
    N, J = o.n_knots, n_coefficients(o)
    T, D = float(p.move_time), float(p.distance)
    h = T / N
    aref = D / T**2
    mask = np.asarray(p.mask, dtype=float)
    n_modes, K = mask.shape
    P = o.n_angles
    MK = n_modes * K
    z = np.maximum(np.asarray(design.lp.z, dtype=float), 0.0)  # multipliers of inequalities are >= 0
    y = np.asarray(design.lp.y, dtype=float)
    zc = z[: P * MK].reshape(P, n_modes, K) * mask[None]  # an unused row's multiplier dropped (0 is allowed)
    S = float(zc.sum())
    if not (np.isfinite(S) and S > 0.0):
        return None
    theta = 2.0 * np.pi * np.arange(P) / P
    zeta = np.tensordot(np.exp(-1j * theta), zc, axes=(0, 0)) / S  # (modes, K)
    ax = p.axis
    w = np.asarray(ax.omega, dtype=float)[:, None] * np.asarray(p.factors, dtype=float)
    zr = np.asarray(ax.damping_ratios, dtype=float)[:, None]
    wd = w * np.sqrt(1.0 - zr**2)
    s = -zr * w + 1j * wd
    weight = mask * np.abs(np.asarray(ax.gains, dtype=float))[:, None] / (wd * np.asarray(p.reference, float)[:, None])
    coef = (zeta * weight).reshape(-1)
    s = s.reshape(-1)
    keep = coef != 0
    coef, s = coef[keep], s[keep]
    # velocity rows: after the cuts, +a (J rows), -a (J), +v (J - 1), -v (J - 1)
    off = P * MK + 2 * J
    zv_p, zv_m = z[off : off + J - 1] / S, z[off + J - 1 : off + 2 * (J - 1)] / S
    mu = zv_p - zv_m
    # velocity row j bounds v(tau_j), tau_j = (j + first) h (ramps: rigorous for any tau_j, see the module docstring)
    first = 2 if o.basis == "spline" else 1
    # equalities: sum c / (h aref) ... the first is sum c_hat = int a / (h aref), the second x(T) / D
    y1 = y[0] / (S * h * aref)
    y2 = y[1] / S
    const_penalty = float(p.v_max) * float(np.sum(zv_p + zv_m)) + y2  # the terms of d outside the integral
    tail = np.concatenate([np.cumsum(mu[::-1])[::-1], [0.0]])  # tail[i] = sum of mu_j over j >= i
    return dict(T=T, D=D, h=h, N=N, coef=coef, s=s, tail=tail, first=first, y1=y1, y2=y2, penalty=const_penalty)


def _steps(parts, step):
    """$\\sum_j (\\mu_j^+ - \\mu_j^-)[t < \\tau_j]$ for t inside knot interval `step` ($[step\\,h, (step+1)h)$):
    the j with $(j + first)h > t$, i.e. $j \\ge step + 1 - first$."""
    tail = parts["tail"]
    return tail[np.clip(step + 1 - parts["first"], 0, tail.size - 1)]


def _phi(parts, t, step):
    """$\\varphi$ at times t (each inside knot interval `step`: the velocity steps counted from that interval)."""
    coef, s = parts["coef"], parts["s"]
    T = parts["T"]
    cut = np.real(np.exp(np.multiply.outer(T - t, s)) @ coef) if coef.size else np.zeros_like(t)
    return cut + _steps(parts, step) + parts["y1"] + parts["y2"] * (T - t) / parts["D"]


def _phi_integral(parts, u, delta, step):
    """$\\int_u^{u+\\delta}\\varphi$ in closed form (cells inside knot intervals)."""
    coef, s = parts["coef"], parts["s"]
    T = parts["T"]
    if coef.size:
        e = np.exp(np.multiply.outer(T - u - delta, s)) * np.expm1(s * delta) / s
        cut = np.real(e @ coef)
    else:
        cut = np.zeros_like(u)
    steps = _steps(parts, step)
    mid = u + 0.5 * delta
    return cut + delta * (steps + parts["y1"]) + parts["y2"] * delta * (T - mid) / parts["D"]


def _abs_integral(parts, cells_per_knot: int = 32, refine: int = 64) -> float:
    """An upper bound of $\\int_0^T|\\varphi|$ (see the module docstring)."""
    h, N = parts["h"], parts["N"]
    # |phi'| <= sum |coef| |s| (|e^{s(T - t)}| <= 1 for Re s <= 0) + |y2| / D
    L = float(np.sum(np.abs(parts["coef"]) * np.abs(parts["s"]))) + abs(parts["y2"]) / parts["D"]

    def cells(u, delta, step):
        m = u + 0.5 * delta
        fm = _phi(parts, m, step)
        sure = np.abs(fm) > 0.5 * L * delta  # no sign change in the cell
        exact = np.abs(_phi_integral(parts, u[sure], delta, step[sure]))
        return float(exact.sum()), ~sure, fm

    delta = h / cells_per_knot
    k = np.arange(N * cells_per_knot)
    u = k * delta
    step = k // cells_per_knot
    total, unsure, _ = cells(u, delta, step)
    if np.any(unsure):  # the cells where phi may cross zero, refined
        d2 = delta / refine
        u2 = (u[unsure][:, None] + d2 * np.arange(refine)[None, :]).reshape(-1)
        s2 = np.repeat(step[unsure], refine)
        sub, unsure2, fm2 = cells(u2, d2, s2)
        total += sub + float(np.sum(d2 * np.abs(fm2[unsure2]) + 0.25 * L * d2 * d2))
    return total


def continuous_lower_bound(design) -> float:
    """A rigorous lower bound, in the units of the design's `worst` (a fraction of the unshaped move's worst residual,
    mode by mode), on the least worst residual that any command within the same limits, distance and time can
    leave over the design's band: smooth or not, of any basis (see the module docstring; a jerk limit is dropped, so
    for a jerk-limited design it may lie far below the least residual). `design`: a solved
    `MinimaxDesign` (`plan.minimax`). The bound is 0 where the design's multipliers give nothing better (it is never
    negative: a residual is not)."""
    parts = _phi_parts(design)
    if parts is None:
        return 0.0
    integral = _abs_integral(parts)
    d = -float(design.problem.a_max) * integral - float(parts["penalty"])
    return max(0.0, d) if np.isfinite(d) else 0.0
