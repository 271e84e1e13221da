"""Incerti's pseudo-polynomial commands as candidates on the user's axis, and the exponent optimiser they share with
`jaxbelt.optimise_robust`.

A pseudo-polynomial command (`PseudoPolynomial`, Incerti eq. 17-23) of order n moves the distance D in the time T
with its n + 1 exponents $\\gamma_i$ as the only freedom: the coefficients follow from the rest-to-rest conditions
(eq. 21), in closed form the Lagrange weights $C_i = \\prod_{j\\ne i}\\gamma_j/(\\gamma_j - \\gamma_i)$.
`pseudo_polynomial_designs` chooses the exponents for a `ModalAxis`, judged by the residual *amplitude* $A_i$ of
every mode (`jaxbelt.shaping.residual`; never the energy), as a fraction of each mode's reference $R_i$ (by default
the worst residual of the unshaped time-optimal move over the band, `reference_residuals`):

- **optimal**: the least $\\sum_i (A_i/R_i)^2$ at the nominal frequencies, from the classical polynomials: (3, 4, 5)
  for one mode (Incerti's start) and the orders above it ($n+1, \\dots, 2n+1$ for order n; with m modes the lowest
  order is n = m + 1, so that n + 1 >= m + 2 exponents meet the 2m conditions of a zero residual on a curve of
  solutions, as in the paper). The lowest order whose residual vanishes (below 1e-9 of the reference) is returned,
  else the least residual found. A zero is not always within reach: on a 3 Hz mode and a 1 s move no three
  exponents cancel it, four do; with several modes there may be none.
- **robust**: the least worst $A_i/R_i$ over the band $f_i(1 \\pm u)$ of every mode (damping ratios kept), from the
  classical polynomials of orders 2 to 6 ((3, 4, 5) included, so that it never does worse than the paper's start):
  a power mean $(\\sum_k w_k r_k^p)^{1/p}$ of the ratios on a 41-point grid per mode, minimised on a log scale, with
  p raised 4 → 16 → 64 → 256 so that it converges to the maximum (at p = 256 it exceeds the grid's maximum by at
  most $K^{1/p}$, 1.5 %). The order with the least worst residual on a 401-point grid is returned.

Both respect the limits $|v| \\le v_{max}$, $|a| \\le a_{max}$ (and $|j| \\le j_{max}$; then every exponent is
kept >= 3, so that the jerk stays finite) where a pseudo-polynomial of those orders can: the peaks (a smooth
$\\ell^{1024}$ norm of 128 samples) enter as penalties $w\\max(0, x/x_{max} - 1 + \\delta)^2$ with a margin
$\\delta$ = 0.2 %, and a start that breaks a limit is first moved inside them by minimising the violation alone.
Where that fails the design with the least violation is returned with `within_limits=False` and a message. The
returned peaks are measured as `jaxbelt.shaping.moves.peaks` measures them (20001 instants).

**The optimiser.** L-BFGS (optax's `scale_by_lbfgs` gives the direction) with an Armijo backtracking line search,
vmapped over the runs (every order of both designs is one batch). A stage stops, converged, when the largest
gradient component is below its tolerance (1e-4 on the log of the robust measure, 1e-8 on the optimal design's
objective relative to its start), when the residual is cancelled, or when no decrease is left at the objective's
rounding level with the gradient below a loose tolerance; otherwise it reports the iteration limit or the stall,
not converged (`PseudoDesign.message`). The designs' stages run in one compiled while loop per call (`run_chain`:
the feasibility stage, then the four powers), each run moving to its next stage on its own, so that a batch costs
the most iterations one run takes over all its stages; the optimal design's objective is the same at every power,
and a run of it that met its stopping test is not restarted at the next.

**The exponent map, and why the paper's robust optimiser collapsed.** The optimiser works on unconstrained
$\\theta$ with $\\gamma_0 = b + \\epsilon + s\\sin^2\\theta_0$ and $\\gamma_i = \\gamma_{i-1} + \\delta_{min} +
s\\sin^2\\theta_i$: sorted exponents above the bound $b$, gaps at least $\\delta_{min}$, increments at most
$\\delta_{min} + s$ (`max_step`). Each face of that box is reached at a *finite* $\\theta$ (0 or π/2), where the
objective has an ordinary stationary point. The band optimum of a pseudo-polynomial lies on such faces: the lowest
exponent at its bound, the others clustered at the minimum gap, sometimes an increment at its cap (the start of the
move leaves a jerk jump of $\\prod_i\\gamma_i\\,D/T^{n+1}$, which small exponents keep small, and the family's closure
holds $u^\\gamma\\log^k u$ terms). Three things made the previous robust optimiser end short of it, on the 3 Hz,
ζ = 0.02 platform at 37-48 % of the 3-4-5 command's worst residual even at the design frequency:

1. its map $s\\,\\sigma(\\theta)$ (logistic σ) put those faces at θ = ±∞: the iterates ran to |θ| of 30 to ∞, where
   $\\sigma' < 10^{-13}$, those coordinates froze wherever they were, the line search stopped making progress and the
   run ended by its stall rule, reported as not converged. With the sine map the same optimum is a regular
   stationary point (n = 4 from (5, ..., 9): 34.6 % of the 3-4-5 worst, converged; the best any order reaches is
   33.6 %);
2. its objective, the $L^{16}$ mean of the residual *energy* (an $L^{32}$ mean of the amplitude weighted by
   $\\omega^2$), was a badly scaled proxy of the worst amplitude; here the amplitude itself, on a log scale;
3. clustered exponents make the coefficients grow like $(\\bar\\gamma/\\delta_{min})^n/n!$ (1e7 for 7 exponents 0.2
   apart), and the computed residual, a small difference of large terms, carries rounding noise up to 1e-4 of
   itself: no line search progresses below that. The robust design keeps its exponents 0.5 apart (coefficients
   below about 1e5, noise below 1e-8) at no measurable cost (16.9 % against 16.6 % at 0.2 on the 4.96 Hz platform).

**One compiled program.** All orders share one program: exponent slots beyond a run's order are masked out of the
Lagrange weights. Every value that changes between calls (frequencies, damping ratios, gains, distance, time,
limits, band, reference, weights, the power p, the order) is a traced array; a new program is compiled only for
another number of modes or quadrature size (a bucket of the highest frequency times the move time). The programs
compile with XLA's classic CPU emitters (`COMPILER_OPTIONS`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from numpy.typing import ArrayLike

from .. import _store
from .._checks import check_positive, check_range, device_array
from .._guard import eager
from .._xla import LazyJit, quick_compile
from ..commands import PseudoPolynomial, lagrange_weights_np
from ..models.axis import ModalAxis
from .quadrature import REACH_OMEGA_T, SINGLE_MAX_OMEGA_T, rule_nodes
from .quadrature import gauss_legendre_01 as _gauss_legendre

#: substitution power u = v**p of the Gauss-Legendre rule (as in `jaxbelt.shaping.residual`)
_P = 4
#: instants (uniform over the move) on which the optimiser measures the peaks of v, a, j, and the norm that smooths
#: their maximum (`_smooth_max`)
N_PEAK = 128
PEAK_Q = 1024.0
#: points per mode of the robust design's frequency grid, and of the fine grid the designs are judged on
N_BAND = 41
N_FINE = 401
_STRIDE = (N_FINE - 1) // (N_BAND - 1)  # the band grid is every _STRIDE-th point of the fine grid
#: the powers of the robust design's power mean, in order, and the iterations each stage may take
POWERS = (4.0, 16.0, 64.0, 256.0)
STAGE_STEPS = (60, 80, 100, 200)
#: iterations of the optimal design's stages (alongside the first robust ones), and of the feasibility stage
OPTIMAL_STEPS = (150, 150, 100, 100)
OPTIMAL_GTOL = 1e-8
OPTIMAL_GTOL_LOOSE = 1e-3
#: orders tried by the optimal design (m + 1 upward), and by the robust one (2 upward)
N_ORDERS = 4
N_ROBUST = 5
FEASIBILITY_STEPS = 200
#: gradient tolerance of the robust design's stages (its objective is the log of the power mean)
ROBUST_GTOL = 1e-4
ROBUST_GTOL_LOOSE = 1e-2
#: the names of the two designs
OPTIMAL = "pseudo-polynomial (optimal)"
ROBUST = "pseudo-polynomial (robust)"
#: minimum gap between exponents and largest increment of the exponent map, per design
GAP = {"optimal": 0.2, "robust": 0.5}
MAX_STEP = 10.0
MARGIN = 1e-3
#: weight of the limit penalties, and their margin
PENALTY = 1e4
SLACK = 2e-3
#: the residual below which the optimal design counts as a zero (fraction of the reference)
ZERO = 1e-9


# --------------------------------------------------------------------------------------------
# Exponents: the map from unconstrained parameters, the coefficients
# --------------------------------------------------------------------------------------------
def exponents_from_params(theta, lower, margin, gap, max_step):
    """Sorted exponents from unconstrained `theta` (n + 1,): $\\gamma_0 = b + \\epsilon + s\\sin^2\\theta_0$,
    $\\gamma_i = \\gamma_{i-1} + \\delta + s\\sin^2\\theta_i$ (`lower` b, `margin` ε, `gap` δ, `max_step` s)."""
    theta = jnp.asarray(theta)
    inc = max_step * jnp.sin(theta) ** 2
    first = jnp.reshape(jnp.asarray(lower + margin, dtype=theta.dtype), (1,))
    rest = jnp.broadcast_to(jnp.asarray(gap, dtype=theta.dtype), (theta.shape[0] - 1,))
    return jnp.cumsum(jnp.concatenate([first, rest]) + inc)


def params_from_exponents(gammas, lower, margin, gap, max_step, inset: float = 1e-9):
    """Inverse of `exponents_from_params`, in $[0, \\pi/2]$. A start on a face of the box (an increment of exactly 0
    or `max_step`) is moved `inset` × `max_step` inside: there the sine map is stationary in every direction."""
    g = jnp.sort(jnp.asarray(gammas, dtype=float))
    d = jnp.diff(jnp.concatenate([jnp.reshape(jnp.asarray(lower, dtype=float), (1,)), g]))
    steps = jnp.concatenate(
        [jnp.reshape(jnp.asarray(margin, dtype=float), (1,)), jnp.full((g.shape[0] - 1,), gap, dtype=float)]
    )
    x = jnp.clip((d - steps) / max_step, inset, 1.0 - inset)
    return jnp.arcsin(jnp.sqrt(x))


def _exponents_np(theta, lower, margin, gap, max_step):
    """`exponents_from_params` on the host (numpy)."""
    theta = np.asarray(theta, dtype=float)
    inc = max_step * np.sin(theta) ** 2
    steps = np.concatenate([[lower + margin], np.full(theta.shape[-1] - 1, gap)])
    return np.cumsum(steps + inc, axis=-1)


def _params_np(gammas, lower, margin, gap, max_step, inset: float = 1e-9):
    """`params_from_exponents` on the host (numpy)."""
    g = np.sort(np.asarray(gammas, dtype=float))
    d = np.diff(np.concatenate([[lower], g])) - np.concatenate([[margin], np.full(g.shape[0] - 1, gap)])
    return np.arcsin(np.sqrt(np.clip(d / max_step, inset, 1.0 - inset)))


def lagrange_coefficients(gammas, active=None):
    """$C_i = \\prod_{j \\ne i}\\gamma_j/(\\gamma_j - \\gamma_i)$ over the active exponents (all when `active` is
    None; 0 for an inactive one): the solution of Incerti's eq. (21) in closed form, the Lagrange basis polynomials
    of the nodes $\\gamma$ at 0. Each factor is exact to rounding, so $C$ is exact to a few ulps where the linear
    solve of eq. (23) loses digits with the condition number of $\\bar Z$."""
    g = jnp.asarray(gammas)
    n = g.shape[0]
    eye = jnp.eye(n, dtype=bool)
    skip = eye if active is None else eye | (jnp.asarray(active)[None, :] <= 0)
    diff = jnp.where(eye, 1.0, g[None, :] - g[:, None])  # row i: gamma_j - gamma_i
    C = jnp.prod(jnp.where(skip, 1.0, g[None, :] / diff), axis=1)
    return C if active is None else C * (jnp.asarray(active) > 0)


# --------------------------------------------------------------------------------------------
# The objective
# --------------------------------------------------------------------------------------------
def n_nodes_for(max_omega_t: float) -> int:
    """Gauss-Legendre nodes that resolve $e^{i\\omega T u}$ under the substitution $u = v^4$ (a host decision,
    bucketed so that nearby axes share the program): about $2.5\\,\\omega T + 64$, at least 256."""
    need = int(2.5 * float(max_omega_t) + 64)
    for n in (256, 512, 1024, 2048):
        if n >= need:
            return n
    return 4096


def design_nodes(max_omega_t: float) -> int:
    """The Gauss-Legendre nodes of the designs' rule (`designs_for`, a host decision): `n_nodes_for`'s
    $2.5\\,\\omega T + 64$, capped at $0.75\\,\\omega T + 64$ rounded up to a power of two, at least 512. Measured
    against a 4096-node rule, the ratios of `_evaluate_np` (orders 2 to 8, 401 factors) agree to 5e-13 wherever
    about $0.55\\,\\omega T$ nodes are given (256 nodes at $\\omega T$ = 385, 384 at 603, 512 at 905; 192 at 385:
    5e-6), so the cap keeps a margin of 1.35 or more. Below 512 nodes the designs are those of `n_nodes_for` (fewer
    nodes move the optimiser's path at the rounding level, which can turn a converged stage into a stalled one);
    above, one program of 512 nodes serves every move up to $\\omega T$ = 597 (a 17 Hz mode, band +20 %, up to
    4.6 s), where `n_nodes_for`'s 1024-node program compiled anew as the move time crossed its bucket (a 3-mode axis
    at 1.0 s, then 1.7 s: 3 s). On the 1-3 mode benchmark axes the designs at 0.8-1.3 s are `n_nodes_for`'s; at
    1.7 s (512 nodes against 1024) every design still converges, the robust ones' worst residuals agree to 1e-5 and
    the optimal ones' move by the optimiser's path on a flat objective (2 modes: 0.0525 -> 0.0520 %, 3 modes:
    0.8738 -> 0.8741 % of the unshaped move's residual; measured). The cap is `quadrature.rule_nodes`, the residual
    curves' rule, also above $\\omega T$ = `quadrature.SINGLE_MAX_OMEGA_T`, where it is composite (more than 4096
    nodes, which one rule would not resolve); beyond `quadrature.REACH_OMEGA_T` its largest size (the designs' objective
    then resolves that mode less well; the table's rows measure it in closed form, `jaxbelt.shaping.residual`)."""
    if float(max_omega_t) > SINGLE_MAX_OMEGA_T:  # beyond the rules' reach the largest (the rows are measured exactly)
        return rule_nodes(min(float(max_omega_t), REACH_OMEGA_T))
    return min(n_nodes_for(max_omega_t), rule_nodes(max_omega_t))


def residual_kernels(axis: ModalAxis, move_time, factors, reference, n_nodes: int):
    """Shape (2 M K, n_nodes): the rule for the residual ratio of a pseudo-polynomial of unit distance, real parts
    (first M K rows) and imaginary parts. Mode i at frequency factor k has $A_i/R_i = |\\sum_j \\kappa_{ikj} f_j|$
    with $f_j = \\sum_l C_l\\gamma_l(\\gamma_l - 1)v_j^{p(\\gamma_l - 1)}$ ($u = 1 - t/T = v^p$, p = 4) and
    $\\kappa_{ikj} = p\\,w_j v_j^{-1} e^{sTv_j^p}|g_i|/(\\omega_d R_i T)$, the Gauss-Legendre rule of
    $W = -(D/T)\\int_0^1 \\sum_l C_l\\gamma_l(\\gamma_l-1)u^{\\gamma_l-2}e^{sTu}du$."""
    v, w = _gauss_legendre(n_nodes)
    r = jnp.asarray(factors)
    om = axis.omega[:, None] * r[None, :]
    z = axis.damping_ratios[:, None]
    wd = om * jnp.sqrt(1.0 - z**2)
    sT = (-z * om + 1j * wd) * move_time
    kern = jnp.exp(sT[..., None] * jnp.asarray(v**_P)) * jnp.asarray(_P * w / v)
    scale = jnp.abs(axis.gains)[:, None] / (wd * jnp.asarray(reference)[:, None] * move_time)
    kern = (kern * scale[..., None]).reshape(-1, n_nodes)
    return jnp.concatenate([jnp.real(kern), jnp.imag(kern)], axis=0)


def _kernels_np(axis: ModalAxis, move_time: float, factors, reference, n_nodes: int) -> np.ndarray:
    """`residual_kernels` on the host (numpy: no program to compile)."""
    v, w = _gauss_legendre(n_nodes)
    f = np.asarray(axis.frequencies, dtype=float)
    z = np.asarray(axis.damping_ratios, dtype=float)[:, None]
    om = 2.0 * np.pi * f[:, None] * np.asarray(factors, dtype=float)[None, :]
    wd = om * np.sqrt(1.0 - z**2)
    sT = (-z * om + 1j * wd) * move_time
    kern = np.exp(sT[..., None] * v**_P) * (_P * w / v)
    scale = np.abs(np.asarray(axis.gains, dtype=float))[:, None] / (wd * np.asarray(reference)[:, None] * move_time)
    kern = (kern * scale[..., None]).reshape(-1, n_nodes)
    return np.concatenate([kern.real, kern.imag], axis=0)


def _evaluate_np(kern, n_modes, n_nodes, distance, move_time, gammas, active, n_peak: int = N_PEAK):
    """`evaluate` on the host (numpy), for a batch of padded exponents (B, S): ratios (B, M, K), peaks (B, 3). The
    batch in one product with the kernel (a pass over it for all runs, not one per run)."""
    v, _ = _gauss_legendre(n_nodes)
    u = np.arange(1, n_peak + 1) / n_peak
    x = np.concatenate([_P * np.log(v), np.log(u)])
    g, a = np.atleast_2d(np.asarray(gammas, dtype=float)), np.atleast_2d(np.asarray(active, dtype=float))
    C = np.stack([lagrange_weights_np(gi, ai) for gi, ai in zip(g, a)])
    pw = np.exp(x[None, :, None] * (g - 1.0)[:, None, :])  # (B, N + P, S)
    c1 = C * g
    c2 = c1 * (g - 1.0)
    y = kern @ (pw[:, :n_nodes] @ c2[:, :, None])[..., 0].T  # (2 M K, B)
    y = y.T.reshape(g.shape[0], 2, n_modes, -1)
    d = abs(distance)
    ratios = d * np.hypot(y[:, 0], y[:, 1])
    inv = 1.0 / u
    vaj = pw[:, n_nodes:] @ np.stack([c1, c2, c2 * (g - 2.0)], axis=2)  # (B, P, 3): the u^(gamma-k) terms
    vaj = vaj * np.stack([np.ones_like(inv), inv, inv * inv], axis=1)
    scale = np.array([d / move_time, d / move_time**2, d / move_time**3])
    return ratios, np.stack([_smooth_max(np, np.abs(q)) for q in vaj]) * scale


class Shared(eqx.Module):
    """The data every run of a batch shares (arrays, traced):

    - `kern` (2 M K, N): `residual_kernels` for M modes at K frequency factors, the last factor the nominal one (1);
    - `x` (N + P,): $p\\log v_j$ for the rule's nodes, then $\\log u_k$ for the P instants where the peaks are
      measured ($u_k = k/P$, k = 1..P: t from T - T/P to 0); `inv_u` (P,): $1/u_k$;
    - `band_w` (M, K): weights of the band's power mean (summing to 1); `nom_w` (M,): weights of the nominal sum of
      squares; `guard` (M,): nominal ratios not to exceed (inf: none);
    - `distance` D, `move_time` T; `inv_limits` (3,): $1/v_{max}, 1/a_{max}, 1/j_{max}$ (0: no limit);
    - `margin`, `max_step`: the exponent map; `penalty`, `slack`: weight and margin of the limits.
    """

    kern: jax.Array
    x: jax.Array
    inv_u: jax.Array
    band_w: jax.Array
    nom_w: jax.Array
    guard: jax.Array
    distance: jax.Array
    move_time: jax.Array
    inv_limits: jax.Array
    margin: jax.Array
    max_step: jax.Array
    penalty: jax.Array
    slack: jax.Array


class Run(eqx.Module):
    """One run of a batch at one stage (arrays, traced): `active` (S,) 1 for the exponent slots of its order;
    `lower` the bound b and `gap` the least gap of the exponent map; `p` the power; `w_band`, `w_nom`, `w_guard`, `w_limits` the weights; `gtol`, `ftol` the
    stopping tests, `gtol_loose` the gradient below which a run that can no longer decrease the objective counts as
    converged (to the objective's rounding level); `max_iter` the iterations allowed."""

    active: jax.Array
    lower: jax.Array
    gap: jax.Array
    p: jax.Array
    w_band: jax.Array
    w_nom: jax.Array
    w_guard: jax.Array
    w_limits: jax.Array
    gtol: jax.Array
    gtol_loose: jax.Array
    ftol: jax.Array
    max_iter: jax.Array


def exponents(shared: Shared, run: Run, theta):
    return exponents_from_params(theta, run.lower, shared.margin, run.gap, shared.max_step)


def evaluate(shared: Shared, gammas, active):
    """`(ratios (M, K), peaks (3,))`: every mode's residual over its reference at every factor, and the peak |v|,
    |a|, |jerk| on the P instants, from one matrix of powers and one product."""
    C = lagrange_coefficients(gammas, active)
    g1 = gammas - 1.0
    pw = jnp.exp(shared.x[:, None] * g1[None, :])  # v^(p(gamma-1)) on the nodes, u^(gamma-1) on the instants
    c1 = C * gammas
    c2 = c1 * g1
    R = pw @ jnp.stack([c2, c1, c2, c2 * (gammas - 2.0)], axis=1)  # (N + P, 4)
    N = shared.kern.shape[1]
    M = shared.nom_w.shape[0]
    y = (shared.kern @ R[:N, 0]).reshape(2, M, -1)
    # a floor far below any meaningful ratio keeps the modulus differentiable at an exact zero
    r = jnp.abs(shared.distance) * jnp.sqrt(y[0] ** 2 + y[1] ** 2 + 1e-60)
    inv = shared.inv_u[:, None]
    d, T = jnp.abs(shared.distance), shared.move_time
    scale = jnp.stack([d / T, d / T**2, d / T**3])
    vaj = R[N:, 1:] * jnp.concatenate([jnp.ones_like(inv), inv, inv * inv], axis=1)  # u^(gamma-k) terms
    return r, _smooth_max(jnp, jnp.abs(vaj)) * scale


def _smooth_max(xp, a):
    r"""A smooth upper bound of the largest entry of each column of `a` (P, 3) (entries >= 0): the $\ell^q$ norm,
    q = `PEAK_Q`, which exceeds the maximum by a factor of at most $P^{1/q}$ (0.5 % for 128 samples, about 0.1 % at
    a smooth peak) and, unlike the maximum, has a continuous gradient (the line search needs one)."""
    m = xp.max(a, axis=0)
    if xp is jnp:
        m = jax.lax.stop_gradient(m)
    m = xp.where(m > 0, m, 1.0)
    return m * xp.sum((a / m) ** PEAK_Q, axis=0) ** (1.0 / PEAK_Q)


def parts(shared: Shared, run: Run, theta):
    """`(log power mean over the band, nominal ratios (M,), peaks (3,), exponents (S,))`."""
    g = exponents(shared, run, theta)
    r, pk = evaluate(shared, g, run.active)
    logm = jax.nn.logsumexp(run.p * jnp.log(r), b=shared.band_w) / run.p
    return logm, r[:, -1], pk, g


def objective(shared: Shared, run: Run, theta):
    """$F = w_{band}\\log M_p + w_{nom}\\sum_i n_i r_i^2 + w_{guard}\\sum_i\\max(0, r_i/G_i - 1 + \\delta)^2 +
    w\\sum_x\\max(0, x/x_{max} - 1 + \\delta)^2$ ($r_i$ the nominal ratios, $M_p$ the band's power mean)."""
    logm, nom, pk, _ = parts(shared, run, theta)
    f = run.w_band * logm + run.w_nom * jnp.sum(shared.nom_w * nom**2)
    f = f + run.w_guard * jnp.sum(jax.nn.relu(nom / shared.guard - 1.0 + shared.slack) ** 2)
    over = jax.nn.relu(pk * shared.inv_limits - 1.0 + shared.slack)
    return f + run.w_limits * shared.penalty * jnp.sum(over**2)


# --------------------------------------------------------------------------------------------
# Compilation: XLA's classic CPU emitters
# --------------------------------------------------------------------------------------------
#: Compiler options of the optimiser's programs: XLA's classic CPU emitters compile its loop in about half the time
#: of the fusion emitters (1.3 s against 2.8 s of CPU time for the designs' program) and run it as fast (measured:
#: 56 ms for a stage of 9 runs either way). The same HLO; a backend that does not know the option gets plain jit.
COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def _jit(fun, static_argnums=()):
    """`jax.jit(fun)` with `COMPILER_OPTIONS` as far as the running backend knows them (`jaxbelt._xla`)."""
    return LazyJit(jax.jit, fun, COMPILER_OPTIONS, static_argnums=static_argnums)


# --------------------------------------------------------------------------------------------
# The optimiser: one stage of one run, vmapped over a batch of runs
# --------------------------------------------------------------------------------------------
#: the L-BFGS direction (optax's two-loop recursion, memory 10, the first step scaled to unit length); the step
#: length comes from the Armijo backtracking line search of `_stage_one`
LBFGS = optax.chain(optax.scale_by_lbfgs(memory_size=10), optax.scale(-1.0))
#: halvings the line search may take, and its sufficient-decrease constant
LINESEARCH_STEPS = 20
ARMIJO = 1e-4
#: successive iterations without decrease after which a stage stops
STALL = 4

#: why a stage stopped (0, 1 and 3 count as converged)
REASONS = {
    0: "largest gradient component below its tolerance",
    1: "objective below its tolerance (residual cancelled)",
    2: "iteration limit reached",
    3: f"stationary to the objective's rounding level: no decrease along the steepest descent in {STALL} successive "
    "iterations, with the gradient below its loose tolerance",
    4: "the objective became non-finite",
    5: f"no decrease in {STALL} successive iterations with the gradient above its loose tolerance",
}
CONVERGED = (0, 1, 3)


class StageOut(NamedTuple):
    """What a stage returns per run: the best iterate `theta` and its `value`, `gmax` (largest gradient component
    there), `reason` (a key of `REASONS`), `n_iter`, `history` (objective after each iteration, NaN beyond
    `n_iter`)."""

    theta: jax.Array
    value: jax.Array
    gmax: jax.Array
    reason: jax.Array
    n_iter: jax.Array
    history: jax.Array


def _trial_step(opt, vg, started, theta, d, t, slope, f, g, state, k, linesearch: bool):
    """One trial of `_stage_one`'s (and `_chain_one`'s) loop at `theta + t d`: with `linesearch`, accepted by the
    Armijo condition (failed after `LINESEARCH_STEPS` halvings: the optimiser's memory restarts), the next direction
    `opt`'s, or the steepest descent of unit length where that is not one of descent; without, every trial accepted
    and `opt`'s update the next step. Returns `(accept, failed, theta, f, g, state, direction, slope)`."""
    trial = theta + t * d
    f_t, g_t = vg(trial)
    f_t = jnp.where(jnp.isnan(f_t), jnp.inf, f_t)
    if linesearch:
        accept = ~started | (f_t <= f + ARMIJO * t * slope)
        failed = started & ~accept & (k + 1 >= LINESEARCH_STEPS)
    else:
        accept = jnp.asarray(True)
        failed = jnp.asarray(False)
    new_theta = jnp.where(accept, trial, theta)
    new_f = jnp.where(accept, f_t, f)
    new_g = jnp.where(accept, g_t, g)
    upd, new_state = opt.update(new_g, state, new_theta)
    new_state = jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), new_state, state)
    if not linesearch:
        return accept, failed, new_theta, new_f, new_g, new_state, upd, jnp.asarray(0.0, dtype=f.dtype)
    new_state = jax.tree_util.tree_map(lambda a, b: jnp.where(failed, a, b), opt.init(new_theta), new_state)
    nd = jnp.where(accept, upd, d)
    s = jnp.vdot(new_g, nd)
    steep = -new_g / jnp.maximum(jnp.linalg.norm(new_g), 1e-300)
    bad = ~(s < 0) | failed
    nd = jnp.where(bad, steep, nd)
    s = jnp.where(bad, jnp.vdot(new_g, steep), s)
    return accept, failed, new_theta, new_f, new_g, new_state, nd, s


def _step_kept(started, accept, failed, new_f, it, bf, stall):
    """After a trial: `(step_done, iterations, better, stall)`: a step is done when its trial was accepted or its
    search failed; `better` when the accepted value is below the best `bf`; `stall` counts the steps without an
    improvement of more than a rounding of `bf`."""
    step_done = accept | failed
    it = it + jnp.where(started & step_done, 1, 0)
    better = accept & (new_f < bf)
    improved = new_f < bf - 1e-15 * jnp.abs(bf)
    stall = jnp.where(started & step_done, jnp.where(accept & improved, 0, stall + 1), stall)
    return step_done, it, better, stall


def _reason(run, finite, bf, bg, stall):
    """Why a stage stopped (a key of `REASONS`), from its last value's finiteness and its best value `bf` and
    gradient `bg`: 4 not finite, 0 gradient test, 1 value test, 3 or 5 stalled (gradient within or above its loose
    tolerance), 2 iteration limit."""
    gm = jnp.max(jnp.abs(bg))
    return jnp.where(
        ~finite,
        4,
        jnp.where(
            gm <= run.gtol,
            0,
            jnp.where(bf <= run.ftol, 1, jnp.where(stall >= STALL, jnp.where(gm <= run.gtol_loose, 3, 5), 2)),
        ),
    )


def _stage_one(opt, shared, run, theta, n_hist: int, linesearch: bool) -> StageOut:
    """Iterations of `opt` from `theta` until a stopping test of `run` holds.

    One while loop whose body evaluates the objective and its gradient once, at a trial point (the objective is
    traced once: the program stays small). With `linesearch`, `opt` gives the direction (L-BFGS) and the trial steps
    are 1, 1/2, 1/4, ... along it until the Armijo condition holds; a direction that is not one of descent is
    replaced by the steepest descent of unit length, and a search that fails restarts the optimiser's memory (the
    curvature pairs gave a direction it could not use). Without, `opt`'s update is the step and every trial is
    accepted (adam and the like). Returns the best iterate."""
    vg = jax.value_and_grad(lambda th: objective(shared, run, th))
    zero = jnp.zeros_like(theta)
    f_inf = jnp.asarray(jnp.inf, dtype=theta.dtype)

    def gmax(g):
        return jnp.max(jnp.abs(g))

    def cond(c):
        started, it, k, theta, d, t, slope, f, g, state, stall, bf, bt, bg, hist = c
        done = started & ((gmax(g) <= run.gtol) | (f <= run.ftol) | (it >= run.max_iter) | (stall >= STALL))
        return ~done & (jnp.isfinite(f) | ~started)

    def body(c):
        started, it, k, theta, d, t, slope, f, g, state, stall, bf, bt, bg, hist = c
        accept, failed, new_theta, new_f, new_g, new_state, nd, s = _trial_step(
            opt, vg, started, theta, d, t, slope, f, g, state, k, linesearch
        )
        if linesearch:
            t_next = jnp.where(accept | failed, 1.0, 0.5 * t)
            k_next = jnp.where(accept | failed, 0, k + 1)
        else:
            t_next, k_next = jnp.asarray(1.0, dtype=f.dtype), k
        step_done, it_next, better, stall = _step_kept(started, accept, failed, new_f, it, bf, stall)
        bt = jnp.where(better, new_theta, bt)
        bg = jnp.where(better, new_g, bg)
        bf = jnp.where(better, new_f, bf)
        hist = jnp.where(started & step_done, hist.at[jnp.minimum(it, n_hist - 1)].set(new_f), hist)
        return (jnp.asarray(True), it_next, k_next, new_theta, nd, t_next, s, new_f, new_g, new_state, stall, bf, bt,
                bg, hist)  # fmt: skip

    state = opt.init(theta)
    hist = jnp.full((n_hist,), jnp.nan, dtype=theta.dtype)
    one = jnp.asarray(1.0, dtype=theta.dtype)
    init = (jnp.asarray(False), jnp.asarray(0), jnp.asarray(0), theta, zero, one, -one, f_inf, zero, state,
            jnp.asarray(0), f_inf, theta, zero, hist)  # fmt: skip
    c = jax.lax.while_loop(cond, body, init)
    _, it, _, _, _, _, _, f_last, _, _, stall, bf, bt, bg, hist = c
    reason = _reason(run, jnp.isfinite(f_last), bf, bg, stall)
    return StageOut(bt, bf, gmax(bg), reason, it, hist)


def _run_stage(opt, shared: Shared, runs: Run, thetas, n_hist: int, linesearch: bool) -> StageOut:
    return jax.vmap(lambda r, t: _stage_one(opt, shared, r, t, n_hist, linesearch))(runs, thetas)


def _run_stage_lbfgs(shared: Shared, runs: Run, thetas, n_hist: int, linesearch: bool) -> StageOut:
    return _run_stage(LBFGS, shared, runs, thetas, n_hist, linesearch)


def run_stage(opt, shared: Shared, runs: Run, thetas, *, n_hist: int = 8, linesearch: bool = True) -> StageOut:
    """One stage of every run of the batch `runs` (leading axis B) from `thetas` (B, S), each until a stopping test
    of its `Run` holds: one compiled program per (optimizer, shapes, `n_hist`, `linesearch`).

    With jaxbelt's own L-BFGS, called outside any trace while the compilation cache is on, the program comes from
    the program store (`jaxbelt._store`): a later process neither traces nor lowers it (0.3 s of a 1 s first call).
    """
    if opt is LBFGS and _store.folder() is not None and eager():
        args = (shared, runs, thetas, n_hist, linesearch)
        return _store.call(
            f"{__name__}._run_stage_lbfgs",
            _run_stage_lbfgs,
            args,
            lambda *a: _run_stage_jit(LBFGS, *a),
            quick_compile(COMPILER_OPTIONS),
        )
    return _run_stage_jit(opt, shared, runs, thetas, n_hist, linesearch)


_run_stage_jit = _jit(_run_stage, static_argnums=(0, 4, 5))


# --------------------------------------------------------------------------------------------
# Every stage of a run in one loop: the designs' program
# --------------------------------------------------------------------------------------------
#: stage slots of `run_chain` (the feasibility stage or the four powers; a slot with no iterations is skipped)
N_CHAIN = len(POWERS) + 1


class ChainOut(NamedTuple):
    """What `run_chain` returns per run: the best iterate `theta` of the last stage run and its `value`, `gmax` and
    `reason` there (the ones given when no stage ran), `n_iter` (iterations over every stage)."""

    theta: jax.Array
    value: jax.Array
    gmax: jax.Array
    reason: jax.Array
    n_iter: jax.Array


def _chain_one(opt, shared: Shared, chain: Run, settle, theta, reason0, gmax0) -> ChainOut:
    """The stages of one run in one while loop: `chain` a `Run` whose fields other than `active`, `lower`, `gap` hold
    one value per stage slot (N,); each stage L-BFGS with the Armijo line search of `_stage_one`, from the best
    iterate of the stage before with a fresh memory, until its stopping test holds (the same tests, the same
    reasons). A slot with `max_iter` 0 is skipped, and so is one with `settle` > 0 when the last stage run met its
    stopping test (`CONVERGED`; the objective is then the same as that stage's: nothing is left to do).

    Each run moves to its next stage on its own, so a batch (vmapped) costs the most iterations one run takes over
    every stage, not the sum over the stages of the most one run takes in each."""
    n_st = chain.max_iter.shape[0]
    zero = jnp.zeros_like(theta)
    f_inf = jnp.asarray(jnp.inf, dtype=theta.dtype)
    one = jnp.asarray(1.0, dtype=theta.dtype)
    slots = jnp.arange(n_st)

    def at(s):
        return Run(active=chain.active, lower=chain.lower, gap=chain.gap, p=chain.p[s], w_band=chain.w_band[s],
                   w_nom=chain.w_nom[s], w_guard=chain.w_guard[s], w_limits=chain.w_limits[s], gtol=chain.gtol[s],
                   gtol_loose=chain.gtol_loose[s], ftol=chain.ftol[s], max_iter=chain.max_iter[s])  # fmt: skip

    def next_stage(after, reason):
        conv = (reason == 0) | (reason == 1) | (reason == 3)
        runs = (slots > after) & (chain.max_iter > 0) & ~((settle > 0) & conv)
        return jnp.where(jnp.any(runs), jnp.argmax(runs), n_st)

    def gmax(g):
        return jnp.max(jnp.abs(g))

    def fresh(s, theta, reason, gm, value, n_iter):
        return dict(stage=s, started=jnp.asarray(False), it=jnp.asarray(0), k=jnp.asarray(0), theta=theta, d=zero,
                    t=one, slope=-one, f=f_inf, g=zero, state=opt.init(theta), stall=jnp.asarray(0), bf=f_inf,
                    bt=theta, bg=zero, reason=reason, gm=gm, value=value, n_iter=n_iter)  # fmt: skip

    def cond(c):
        return c["stage"] < n_st

    def body(c):
        run = at(jnp.minimum(c["stage"], n_st - 1))
        vg = jax.value_and_grad(lambda th: objective(shared, run, th))
        started, t, d, f, g, state, k = c["started"], c["t"], c["d"], c["f"], c["g"], c["state"], c["k"]
        accept, failed, new_theta, new_f, new_g, new_state, nd, s = _trial_step(
            opt, vg, started, c["theta"], d, t, c["slope"], f, g, state, k, True
        )
        step_done, it, better, stall = _step_kept(started, accept, failed, new_f, c["it"], c["bf"], c["stall"])
        bt = jnp.where(better, new_theta, c["bt"])
        bg = jnp.where(better, new_g, c["bg"])
        bf = jnp.where(better, new_f, c["bf"])
        stepped = dict(stage=c["stage"], started=jnp.asarray(True), it=it, k=jnp.where(step_done, 0, k + 1),
                       theta=new_theta, d=nd, t=jnp.where(step_done, 1.0, 0.5 * t), slope=s, f=new_f, g=new_g,
                       state=new_state, stall=stall, bf=bf, bt=bt, bg=bg, reason=c["reason"], gm=c["gm"],
                       value=c["value"], n_iter=c["n_iter"])  # fmt: skip
        # the stage's stopping tests (`_stage_one`'s loop condition), on the state after this step
        finite = jnp.isfinite(new_f)
        done = (gmax(new_g) <= run.gtol) | (new_f <= run.ftol) | (it >= run.max_iter) | (stall >= STALL) | ~finite
        reason = _reason(run, finite, bf, bg, stall)
        reason = reason.astype(c["reason"].dtype)
        moved = fresh(next_stage(c["stage"], reason), bt, reason, gmax(bg), bf, c["n_iter"] + it)
        return jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), moved, stepped)

    first = next_stage(-1, reason0)
    c = jax.lax.while_loop(cond, body, fresh(first, theta, reason0, gmax0, f_inf, jnp.asarray(0)))
    return ChainOut(c["theta"], c["value"], c["gm"], c["reason"], c["n_iter"])


def _run_chain(shared: Shared, chains: Run, settle, thetas, reasons, gmaxs) -> ChainOut:
    return jax.vmap(lambda ch, se, t, r, g: _chain_one(LBFGS, shared, ch, se, t, r, g))(
        chains, settle, thetas, reasons, gmaxs
    )


_run_chain_jit = _jit(_run_chain)


def run_chain(shared: Shared, chains: Run, settle, thetas, reasons, gmaxs) -> ChainOut:
    """Every stage of every run of the batch `chains` (a `Run` per run whose fields but `active`, `lower` and `gap`
    hold one value per stage slot, `make_chain`) from `thetas` (B, S) in one program call (`_chain_one`); `settle`
    (B, N) marks the slots skipped after a stage that met its stopping test, `reasons`, `gmaxs` (B,) are reported
    for a run no stage of which runs. Through the program store as `run_stage` (`jaxbelt._store`)."""
    args = (shared, chains, settle, thetas, reasons, gmaxs)
    if _store.folder() is not None and eager():
        name = f"{__name__}._run_chain"
        return _store.call(name, _run_chain, args, _run_chain_jit, quick_compile(COMPILER_OPTIONS))
    return _run_chain_jit(*args)


def make_chain(active, lower, gap, n_slots: int = N_CHAIN, **stages) -> Run:
    """A batch of chained runs (`run_chain`): `active` (B, S); `lower`, `gap` scalars or (B,); the `make_runs`
    keywords scalars, (B,) or (B, `n_slots`) (one value per stage slot); `max_iter` given as a scalar or (B,) is
    the first slot's, the other slots' 0 (one stage), and a slot not given has `max_iter` 0."""
    B = np.asarray(active).shape[0]
    defaults = dict(p=1.0, w_band=0.0, w_nom=0.0, w_guard=0.0, w_limits=1.0, gtol=1e-9, gtol_loose=0.0,
                    ftol=-np.inf, max_iter=0)  # fmt: skip

    def cols(x, dtype: Any = float):
        x = np.asarray(x, dtype=dtype)
        x = x[:, None] if x.ndim == 1 else x
        return device_array(np.broadcast_to(x, (B, n_slots)).copy())

    def col(x):
        return device_array(np.broadcast_to(np.asarray(x, dtype=float), (B,)).copy())

    it = np.asarray(stages.get("max_iter", 0), dtype=np.int32)
    if it.ndim < 2:  # one stage: the first slot's iterations only
        stages["max_iter"] = np.concatenate(
            [np.broadcast_to(it, (B,))[:, None], np.zeros((B, n_slots - 1), np.int32)], 1
        )
    kw = {k: cols(stages.get(k, v), np.int32 if k == "max_iter" else float) for k, v in defaults.items()}
    return Run(active=_f(active), lower=col(lower), gap=col(gap), **kw)


# --------------------------------------------------------------------------------------------
# The designs on a ModalAxis
# --------------------------------------------------------------------------------------------
class PseudoDesign(NamedTuple):
    """One pseudo-polynomial design on an axis.

    - `command`: the `PseudoPolynomial` (displacement = the distance, duration = the move time);
    - `objective`: the value minimised: $\\sum_i (A_i/R_i)^2$ at the nominal frequencies (optimal), or the worst
      $A_i/R_i$ on the design's band grid (robust, 41 points per mode);
    - `converged`: the optimiser met its stopping test in its last stage; `message`: why it stopped, or why the
      limits cannot be met;
    - `within_limits`: peak |v|, |a| (and |jerk| when limited) of the command, measured with `peaks`, within the
      limits (to a relative 1e-9);
    - `worst`: the worst $A_i/R_i$ over the band on a fine grid (401 points per mode); `nominal` (n_modes,): $A_i/R_i$
      at the nominal frequencies; `peaks`: `(peak |v|, peak |a|, peak |jerk|)`; `n_steps`: optimiser iterations of
      the returned run; `order`: n.
    """

    command: PseudoPolynomial
    objective: float
    converged: bool
    message: str
    within_limits: bool
    worst: float = math.nan
    nominal: np.ndarray | None = None
    peaks: tuple = ()
    n_steps: int = 0
    order: int = 0


def _check(axis, distance, move_time, v_max, a_max, j_max, uncertainty, reference):
    o = "pseudo_polynomial_designs"
    if not isinstance(axis, ModalAxis):
        raise TypeError(f"{o}: `axis` must be a ModalAxis; got {type(axis).__name__}")
    d = float(distance)
    if not (math.isfinite(d) and d != 0.0):
        raise ValueError(f"{o}: parameter `distance` must be finite and non-zero; got {distance}")
    check_positive("move_time", move_time, "s", o)
    check_positive("v_max", v_max, "", o)
    check_positive("a_max", a_max, "", o)
    if j_max is not None:
        check_positive("j_max", j_max, "", o)
    check_range("uncertainty", uncertainty, lo=0.0, hi=0.9, hi_open=True, owner=o)
    if reference is not None:
        ref = np.asarray(reference, dtype=float)
        if ref.shape != (axis.n_modes,) or not np.all(np.isfinite(ref)) or not np.all(ref > 0):
            raise ValueError(
                f"{o}: parameter `reference` must hold one finite residual > 0 per mode, shape ({axis.n_modes},); "
                f"got {ref.tolist()}"
            )


def _f(x):
    return device_array(x, dtype=float)  # strong float64 leaves: one program for every value


def make_shared(kern, n_nodes, band_w, nom_w, guard, distance, move_time, limits, max_step=MAX_STEP, margin=MARGIN,
                penalty=PENALTY):  # fmt: skip
    """A `Shared` from host values (`kern` from `residual_kernels`; `limits` = (v_max, a_max, j_max), None for no
    limit)."""
    v, _ = _gauss_legendre(n_nodes)
    u = np.arange(1, N_PEAK + 1) / N_PEAK
    inv = np.array([0.0 if x is None else 1.0 / float(x) for x in limits])
    return Shared(
        kern=kern, x=_f(np.concatenate([_P * np.log(v), np.log(u)])), inv_u=_f(1.0 / u), band_w=_f(band_w),
        nom_w=_f(nom_w), guard=_f(guard), distance=_f(distance), move_time=_f(move_time), inv_limits=_f(inv),
        margin=_f(margin), max_step=_f(max_step), penalty=_f(penalty), slack=_f(SLACK),
    )  # fmt: skip


def make_runs(
    active,
    lower,
    gap,
    *,
    p: ArrayLike = 1.0,
    w_band: ArrayLike = 0.0,
    w_nom: ArrayLike = 0.0,
    w_guard: ArrayLike = 0.0,
    w_limits: ArrayLike = 1.0,
    gtol: ArrayLike = 1e-9,
    gtol_loose: ArrayLike = 0.0,
    ftol: ArrayLike = -np.inf,
    max_iter: ArrayLike = 100,
) -> Run:
    """A batch of `Run`s: `active` (B, S); `lower`, `gap` and the rest scalars or (B,)."""
    B = np.asarray(active).shape[0]

    def col(x, dtype: Any = float):
        return device_array(np.broadcast_to(np.asarray(x, dtype=dtype), (B,)))

    return Run(
        active=_f(active),
        lower=col(lower),
        gap=col(gap),
        p=col(p),
        w_band=col(w_band),
        w_nom=col(w_nom),
        w_guard=col(w_guard),
        w_limits=col(w_limits),
        gtol=col(gtol),
        gtol_loose=col(gtol_loose),
        ftol=col(ftol),
        max_iter=col(max_iter, np.int32),
    )


def classical_start(order: int, lower: float, gap: float, slots: int):
    """The exponents of the classical rest-to-rest polynomial of `order` (n+1, ..., 2n+1), raised where they would
    sit below the bound, padded to `slots` with inactive exponents."""
    g = np.arange(order + 1, 2 * order + 2, dtype=float)
    g = np.maximum(g, lower + MARGIN + 0.1 + (gap + 0.1) * np.arange(order + 1))
    pad = g[-1] + (1.0 + gap) * np.arange(1, slots - order)
    return np.concatenate([g, pad])


def _limit_message(pk, limits, order):
    names = ("|v|", "|a|", "|jerk|")
    bad = [
        f"peak {names[k]} {pk[k]:.4g} > {limits[k]:.4g}"
        for k in range(3)
        if limits[k] is not None and pk[k] > float(limits[k]) * (1 + 1e-9)
    ]
    return (
        f"no pseudo-polynomial of order {order} within the limits found at this distance and move time "
        f"({'; '.join(bad)})"
    )


def _designs_batch(axis, D, T, limits, reference, u, n_nodes, bar):
    """Every order of both designs as one batch through one program, one call per stage; per-run host results."""
    m = axis.n_modes
    n_min = m + 1
    rob_orders = list(range(2, 2 + N_ROBUST))
    slots = max(n_min + N_ORDERS, rob_orders[-1]) + 1
    jerk = limits[2] is not None
    # optimal: orders m + 1 .. m + 4 ((3, 4, 5) first for one mode); robust: m + 2 .. m + 5
    kinds = ["optimal"] * N_ORDERS + ["robust"] * N_ROBUST
    orders = [n_min + k for k in range(N_ORDERS)] + rob_orders
    lower = np.array([float(max(n, 2, 3 if jerk else 0)) for n in orders])
    gap = np.array([GAP[k] for k in kinds])
    act = np.array([[1.0 if s <= n else 0.0 for s in range(slots)] for n in orders])
    rob = np.array([k == "robust" for k in kinds])
    factors = np.concatenate([np.linspace(1 - u, 1 + u, N_BAND), [1.0]])
    band_w = np.zeros((m, N_BAND + 1))
    band_w[:, :N_BAND] = 1.0 / (m * N_BAND)
    kern_np = _kernels_np(axis, T, factors, reference, n_nodes)
    sh = make_shared(_f(kern_np), n_nodes, band_w, np.ones(m), np.full(m, np.inf), D, T, limits)
    theta0 = np.stack(
        [_params_np(classical_start(n, b, g, slots), b, MARGIN, g, MAX_STEP) for n, b, g in zip(orders, lower, gap)]
    )
    theta = _f(theta0)
    steps = np.zeros(len(orders), dtype=int)
    reason = np.full(len(orders), 2)
    gmax = np.full(len(orders), np.nan)

    # stage 0: inside the limits (the penalty alone), for the starts that break one
    def evaluated(thetas):
        exps = np.stack([_exponents_np(t, b, MARGIN, g, MAX_STEP) for t, b, g in zip(thetas, lower, gap)])
        return _evaluate_np(kern_np, m, n_nodes, D, T, exps, act)

    # r0: the ratios after stage 0, which the optimal design's objective is relative to (its tests are then relative)
    r0, pk0 = evaluated(theta0)
    inv = np.array([0.0 if x is None else 1.0 / x for x in limits])
    over = np.any(pk0 * inv > 1.0 - SLACK, axis=1)
    feasible = ~over
    if np.any(over):
        runs = make_chain(act, lower, gap, ftol=0.0, gtol=1e-12, gtol_loose=1e-3,
                          max_iter=np.where(over, FEASIBILITY_STEPS, 0))  # fmt: skip
        st = run_chain(
            sh, runs, _f(np.zeros((len(orders), N_CHAIN))), theta, device_array(reason.astype(np.int32)), _f(gmax)
        )
        theta, steps = st.theta, steps + np.asarray(st.n_iter)
        r0, pk1 = evaluated(np.asarray(theta))
        # The penalty is squared, so its gradient fades at the boundary: L-BFGS can stop (gradient below its
        # tolerance) with the penalty a rounding above zero, the peaks at 1 - SLACK of their limits plus ~1e-13
        # (seen on a GPU, whose sums round otherwise). Such a start is inside the limits with room to spare: the
        # peaks decide, at half the slack.
        feasible = ~over | (np.asarray(st.value) <= 0.0) | np.all(pk1 * inv <= 1.0 - SLACK / 2, axis=1)
        reason = np.where(feasible, reason, np.asarray(st.reason))
        gmax = np.where(feasible, gmax, np.asarray(st.gmax))
    if bar is not None:
        bar.update(1)
    s0 = np.maximum(np.sum(r0[:, :, -1] ** 2, axis=1), 1e-300)
    # the four powers as the first four stage slots of one chain per run (`run_chain`). The optimal design's
    # objective is the same at every stage (the power is the robust design's): a run that met its stopping test is
    # left where it is (`settle`), not restarted to meet it again (a restart at the rounding level only spends its
    # stall iterations there, 4 line searches of 20 halvings each). A run that cannot be brought inside the limits
    # keeps the least violation the feasibility stage found.
    n = len(POWERS)

    def per_slot(robust, optimal):
        out = np.zeros((len(orders), N_CHAIN))
        out[:, :n] = np.where(rob[:, None], np.asarray(robust, dtype=float), np.asarray(optimal, dtype=float))
        return out

    steps_rob, steps_opt = np.asarray(STAGE_STEPS), np.asarray(OPTIMAL_STEPS)
    runs = make_chain(
        act, lower, gap, p=per_slot(POWERS, 1.0), w_band=per_slot(1.0, 0.0), w_nom=per_slot(0.0, 1.0 / s0[:, None]),
        gtol=per_slot(ROBUST_GTOL, OPTIMAL_GTOL), gtol_loose=per_slot(ROBUST_GTOL_LOOSE, OPTIMAL_GTOL_LOOSE),
        ftol=per_slot(-np.inf, ZERO**2 / s0[:, None]),
        max_iter=per_slot(steps_rob, steps_opt).astype(np.int32) * feasible[:, None],
    )  # fmt: skip
    settle = np.zeros((len(orders), N_CHAIN))
    settle[:, 1:n] = (~rob)[:, None]
    st = run_chain(sh, runs, _f(settle), theta, device_array(reason.astype(np.int32)), _f(gmax))
    theta, steps = st.theta, steps + np.asarray(st.n_iter)
    reason, gmax = np.asarray(st.reason), np.asarray(st.gmax)  # as given where no stage ran (not feasible)
    if bar is not None:
        bar.update(len(POWERS))
    gam = np.stack([_exponents_np(t, b, MARGIN, g, MAX_STEP) for t, b, g in zip(np.asarray(theta), lower, gap)])
    out = {}
    for kind in ("optimal", "robust"):
        i = np.array([k == kind for k in kinds])
        out[kind] = dict(
            orders=[o for o, k in zip(orders, kinds) if k == kind], active=act[i], gammas=gam[i], reason=reason[i],
            gmax=gmax[i], steps=steps[i], feasible=feasible[i],
        )  # fmt: skip
    return out


def _peaks_np(gammas, distance, move_time, n: int = 20001) -> np.ndarray:
    """`(peak |v|, peak |a|, peak |jerk|)` of the pseudo-polynomial of exponents `gammas` (n + 1,), measured as
    `jaxbelt.shaping.moves.peaks` measures it (`n` equally spaced instants over the move, the derivatives of
    eq. 18, a term $u^{\\gamma - k}$ taken as 0 at u = 0), on the host: one power per instant and exponent,
    $u^{\\gamma-3}$, the others from it."""
    g = np.asarray(gammas, dtype=float)
    C = lagrange_weights_np(g)
    u = np.clip(1.0 - np.linspace(0.0, 1.0, n), 0.0, 1.0)[1:-1]  # the instants with 0 < u < 1 (u = 1 below)
    e3 = np.exp(np.log(u)[:, None] * (g - 3.0)[None, :])  # (n - 2, n + 1)
    out = []
    for k in (1, 2, 3):
        pk = np.prod([g - r for r in range(k)], axis=0)
        val = (e3 * u[:, None] ** (3 - k)) @ (pk * C)
        ends = np.sum(pk * C)  # u = 1 (t = 0); u = 0 (t = T) contributes 0
        out.append(max(float(np.max(np.abs(val))), abs(float(ends))) * abs(distance) / move_time**k)
    return np.array(out)


def _within(pk, limits):
    return all(lim is None or pk[k] <= float(lim) * (1 + 1e-9) for k, lim in enumerate(limits))


def pseudo_polynomial_designs(
    axis: ModalAxis,
    distance,
    move_time,
    *,
    v_max,
    a_max,
    j_max=None,
    uncertainty=0.2,
    reference=None,
    progress: bool = False,
) -> dict[str, PseudoDesign]:
    """Incerti's pseudo-polynomial commands designed for `axis`: `{"pseudo-polynomial (optimal)": PseudoDesign,
    "pseudo-polynomial (robust)": PseudoDesign}` (see the module docstring).

    - `axis`: a `ModalAxis` (m modes); `distance` D [m] (finite, non-zero), `move_time` T [s] > 0;
    - `v_max` [m/s], `a_max` [m/s²], `j_max` [m/s³] (optional): limits on the command's peaks;
    - `uncertainty` u in [0, 0.9): the band $f_i(1 \\pm u)$ of the robust design (and of `worst`);
    - `reference` (m,) [m]: each mode's reference residual (the denominator of "% of the unshaped move"); None:
      `reference_residuals` (the time-optimal unshaped move's worst residual over the band);
    - `progress`: a tqdm bar over the stages.

    One compiled program per number of modes (and quadrature bucket): a new axis of the same size, a new distance,
    time, limits, band or reference reuse it.
    """
    _check(axis, distance, move_time, v_max, a_max, j_max, uncertainty, reference)
    D, T, u = float(distance), float(move_time), float(uncertainty)
    limits = (float(v_max), float(a_max), None if j_max is None else float(j_max))
    if reference is None:
        from .residual import reference_residuals

        reference = reference_residuals(axis, D, *limits, uncertainty=u)[0]
    return designs_for(axis, D, T, limits, reference, u, progress)


def designs_for(axis: ModalAxis, D: float, T: float, limits, reference, u: float, progress: bool = False):
    """`pseudo_polynomial_designs` for arguments already checked (`design_move`'s request validated the axis, the
    move and the limits once): distance `D` [m], move time `T` [s], `limits` = (v_max, a_max, j_max or None),
    `reference` (m,) [m] given, band ±`u`; the same designs without the checks."""
    reference = np.asarray(reference, dtype=float)
    wT = float(np.max(np.asarray(axis.omega))) * (1 + u) * T
    n_nodes = design_nodes(wT)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=1 + len(POWERS), desc="pseudo-polynomial designs", leave=False)
    try:
        res = _designs_batch(axis, D, T, limits, reference, u, n_nodes, bar)
    finally:
        if bar is not None:
            bar.close()
    fine = np.concatenate([np.linspace(1 - u, 1 + u, N_FINE), [1.0]])
    kern = _kernels_np(axis, T, fine, reference, n_nodes)
    # every run of both designs judged on the fine grid in one product
    every = np.concatenate([res["optimal"]["gammas"], res["robust"]["gammas"]])
    acts = np.concatenate([res["optimal"]["active"], res["robust"]["active"]])
    ratio_all, _ = _evaluate_np(kern, axis.n_modes, n_nodes, D, T, every, acts)
    n_opt = res["optimal"]["gammas"].shape[0]
    inv = np.array([0.0 if x is None else 1.0 / x for x in limits])
    pks: dict[tuple[str, int], np.ndarray] = {}
    out = {}
    for kind, name in (("optimal", OPTIMAL), ("robust", ROBUST)):
        r = res[kind]
        ratio = ratio_all[:n_opt] if kind == "optimal" else ratio_all[n_opt:]
        worst = ratio[:, :, :-1].max(axis=(1, 2))
        nominal = ratio[:, :, -1]
        score = np.sum(nominal**2, axis=1)

        # the runs in the order of preference: (optimal) the lowest order that cancels the residual, then the least
        # score; (robust) the least worst residual. The first within the limits is the design; the peaks (20001
        # instants) are measured run by run until it is found, and for every run where none is
        def peaks_of(i, r=r, kind=kind):
            if (kind, i) not in pks:
                pks[kind, i] = _peaks_np(r["gammas"][i, : r["orders"][i] + 1], D, T)
            return pks[kind, i]

        def ok(i, r=r):
            return bool(r["feasible"][i]) and _within(peaks_of(i), limits)

        if kind == "optimal":
            zero = score <= (ZERO**2) * nominal.shape[1]
            prefer = [i for i in range(len(score)) if zero[i]] + sorted(range(len(score)), key=lambda i: score[i])
        else:
            prefer = sorted(range(len(worst)), key=lambda i: worst[i])
        i = next((i for i in prefer if ok(i)), None)
        if i is None:  # none within the limits: the least violation
            i = int(np.argmin([np.max(peaks_of(k) * inv) for k in range(len(score))]))
        objective = float(score[i]) if kind == "optimal" else float(ratio[i, :, :-1][:, ::_STRIDE].max())
        n = r["orders"][i]
        g = r["gammas"][i, : n + 1]
        # `jax.device_put`: `jnp.asarray` of a host array compiles a small program per shape (per order)
        cmd = PseudoPolynomial(jax.device_put(np.ascontiguousarray(g)), D, T)
        pk = tuple(float(x) for x in peaks_of(i))
        within = ok(i)
        reason = int(r["reason"][i])
        converged = reason in CONVERGED
        message = f"order {n}: {REASONS[reason]} (gradient {float(r['gmax'][i]):.1e})"
        if not within:
            orders = r["orders"]
            message = _limit_message(pk, limits, f"{orders[0]} to {orders[-1]}") + f"; the closest, {message}"
        out[name] = PseudoDesign(
            command=cmd, objective=objective, converged=converged, message=message, within_limits=within,
            worst=float(worst[i]), nominal=nominal[i], peaks=pk, n_steps=int(r["steps"][i]), order=n,
        )  # fmt: skip
    return out
