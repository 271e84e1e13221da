"""A dense linear programme solver in JAX: primal-dual interior point with Mehrotra's predictor-corrector.

$\\min_x c^T x$ subject to $G x \\le h$, $A x = b$ (x free).

Why jaxbelt solves its LPs itself: the minimax command design (`jaxbelt.shaping.design`) is a dense LP of
a few hundred variables and a few thousand inequalities, most of them inactive at the optimum, and the
design's claim of a global optimum needs a duality gap near round-off. Of the JAX-native solvers,
qpax (0.1.4) floors every slack and multiplier at $\\sqrt{\\varepsilon}$ on each iteration (to keep float32
Cholesky factorisations alive), so on this LP its dual residual never falls below ~1e-5 and it stops
at its iteration limit 1 % off the optimum; mpax's first-order PDHG (raPDHG) needed minutes and millions
of iterations for 1e-4 on the same problem. An interior point method on the normal equations
$G^TWG$ (W the diagonal scaling $z/s$) converges in 20-40 iterations to a relative gap of 1e-10 here.

The method (Wright, 1997, Primal-Dual Interior-Point Methods, ch. 10; Mehrotra, 1992, SIAM J. Optim.
2(4)): each iteration factorises $H = G^T W G + \\delta I$ once (the triangular factor of the QR decomposition
of $W^{1/2} G$, which keeps the accuracy that forming $H$ loses), solves the affine-scaling
(predictor) step, takes the centring parameter $\\sigma = (\\mu_{aff}/\\mu)^3$, and solves the combined
step with the second-order correction; primal and dual step lengths are taken separately (0.99 of the
distance to the boundary). The equality constraints are eliminated through the Schur complement
$A H^{-1} A^T$. Rows of G and A are scaled to unit infinity norm first.

Stops when the relative primal and dual residuals and the relative duality gap are all below `tol`.
`LPResult.converged` says whether it did; an infeasible or unbounded problem is not detected as such
(its residuals stall): callers pose only problems they know to be feasible and bounded.

The optimal value differentiates (forward and reverse mode) by the envelope theorem: with the optimal
primal and dual variables held fixed, $dV = \\dot c^Tx + z^T(\\dot G x - \\dot h) + y^T(\\dot A x - \\dot b)$
(the derivative of the Lagrangian), exact where the optimum's multipliers are unique.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jaxtyping import Array, Float

#: relative regularisation of the normal matrix's diagonal, and rounds of iterative refinement per solve
_REG = 1e-15
_REFINE = 1
_REG_RETRIES = (1e-11, 1e-7)  # larger regularisations tried in turn when a factorisation is not finite


class LPResult(NamedTuple):
    """Solution of `solve_lp`: primal `x`, slacks `s` ($h - Gx$), inequality multipliers `z` (>= 0),
    equality multipliers `y`, the objective `value` $c^Tx$, the relative duality `gap`, the relative
    primal and dual residuals, the iteration count, whether the tolerances were met (`converged`) and whether
    the answer is the certified optimal vertex of the crossover (`vertex`)."""

    x: Float[Array, " n"]
    s: Float[Array, " m"]
    z: Float[Array, " m"]
    y: Float[Array, " p"]
    value: Float[Array, ""]
    gap: Float[Array, ""]
    primal_residual: Float[Array, ""]
    dual_residual: Float[Array, ""]
    iterations: Array
    converged: Array
    vertex: Array
    lower_bound: Float[Array, ""]


def _max_step(v, dv):
    """Largest alpha <= 1 with v + alpha dv >= 0 (v > 0)."""
    ratio = jnp.where(dv < 0, -v / jnp.where(dv < 0, dv, -1.0), jnp.inf)
    return jnp.minimum(1.0, jnp.min(ratio))


class RowGroups(NamedTuple):
    """Rows of G that come in groups sharing a small basis: row `idx[g, p]` of G is `U[g, p] @ V[g]` (`idx`
    (groups, P) a host integer array, `U` (groups, P, q), `V` (groups, q, n)). The interior point method then
    factorises the q rows of each group in place of its P rows: $\\sum_p w_p g_p g_p^T = V^T R^T R V$ with R the
    triangular factor of the (P, q) matrix $W^{1/2} U$ (a modulus cut into P angles spans q = 3 columns; a pair of
    rows $\\pm g$, q = 1). Same factor, fewer rows: the QR decomposition costs rows x n²."""

    idx: np.ndarray
    U: jax.Array
    V: jax.Array


def _group_rows(groups, w, gs, cs):
    """The compressed rows $R_g V_g$ of every group (scaled as the solver scales G), stacked."""
    out = []
    for grp in groups:
        sw = jnp.sqrt(w[grp.idx])[..., None] * (grp.U / gs[grp.idx][..., None])  # (groups, P, q)
        q = sw.shape[-1]
        if q == 1:
            R = jnp.sqrt(jnp.sum(sw * sw, axis=1))[..., None]  # (groups, 1, 1)
        else:
            R = jnp.linalg.qr(sw, mode="r")  # (groups, q, q)
        out.append((R @ (grp.V / cs)).reshape(-1, cs.shape[0]))
    return out


def _solve_impl(c, G, h, A, b, x_bound, tol, max_iter, groups=(), used=None):
    n = c.shape[0]
    m = G.shape[0]
    # padded columns (`used` False: zero in c, G and A): held at exactly 0, outside the factorisation and the vertex
    used = jnp.ones((n,), dtype=bool) if used is None else jnp.asarray(used, dtype=bool)
    grouped = np.concatenate([g.idx.ravel() for g in groups]) if groups else np.zeros(0, dtype=int)
    free = np.setdiff1d(np.arange(m), grouped)  # rows outside every group, factorised as they are
    # row scaling (each constraint to unit infinity norm); the multipliers are scaled back at the end
    gs = jnp.max(jnp.abs(G), axis=1)
    gs = jnp.where(gs > 0, gs, 1.0)
    G, h = G / gs[:, None], h / gs
    as_ = jnp.max(jnp.abs(A), axis=1)
    as_ = jnp.where(as_ > 0, as_, 1.0)
    A, b = A / as_[:, None], b / as_
    # column scaling (each variable to unit infinity norm over the inequalities): x = x~ / cs
    cs = jnp.max(jnp.abs(G), axis=0)
    cs = jnp.where(cs > 0, cs, 1.0)
    G, A, c = G / cs, A / cs, c / cs
    # G^T materialised once, outside the iterations (written as `Gt @ v` inside them, XLA copies G into its transpose at
    # every iteration: 0.4 M numbers for the 3-mode design's LP, a fifth of an iteration's time at the LP programs'
    # compiler options); the barrier keeps the transpose where it is made
    Gt = jax.lax.optimization_barrier(G.T)
    scale_h = 1.0 + jnp.max(jnp.abs(h))
    scale_c = 1.0 + jnp.max(jnp.abs(c))
    reg = _REG

    def factor(w):
        # H = B^T B with B = W^(1/2) G: its triangular factor from the QR decomposition of B (regularised by
        # rows sqrt(r d_j)), without forming H, whose condition number is the square of B's (near the optimum W
        # spans 16 orders of magnitude: the Cholesky factor of the formed H left dual residuals of 1e-7 and
        # gradients 1-3 % off; this one 1e-9 and 0.2 %)
        B = jnp.concatenate([*_group_rows(groups, w, gs, cs), jnp.sqrt(w[free])[:, None] * G[free]], axis=0)
        d0 = jnp.sum(B * B, axis=0)

        def factorise(r):
            # a padded column's normal matrix is the identity (its right-hand sides are zero: its step is 0)
            Bq = jnp.concatenate([B, jnp.diag(jnp.where(used, jnp.sqrt(r * d0 + 1e-300), 1.0))], axis=0)
            L = jnp.linalg.qr(Bq, mode="r").T
            S = A @ jsl.cho_solve((L, True), A.T)
            return L, jnp.linalg.cholesky(S)

        def finite(f):
            return jnp.all(jnp.isfinite(f[0])) & jnp.all(jnp.isfinite(f[1]))

        # near the optimum W spreads over many orders of magnitude and the triangular factor may become
        # numerically singular (the Schur complement A H^-1 A^T, then its Cholesky factor, not finite): then
        # factorise again with a larger regularisation (the refinement step recovers the accuracy it costs). A loop
        # over the regularisations: one factorisation in the program, not one per regularisation (XLA compiles each)
        regs = jnp.asarray((reg, *_REG_RETRIES), dtype=w.dtype)

        def again(st):
            i, f = st
            return (i == 0) | ((i < regs.shape[0]) & ~finite(f))

        def attempt(st):
            i, _ = st
            return i + 1, factorise(regs[i])

        blank = jax.eval_shape(factorise, regs[0])
        f0 = jax.tree_util.tree_map(lambda sd: jnp.zeros(sd.shape, sd.dtype), blank)
        return jax.lax.while_loop(again, attempt, (jnp.asarray(0), f0))[1]

    def newton(L, Ls, r1, r2):
        """Solve H dx + A^T dy = r1, A dx = r2 (L, Ls: lower Cholesky factors of H and of A H^-1 A^T)."""
        Hr = jsl.cho_solve((L, True), r1)
        dy = jsl.cho_solve((Ls, True), A @ Hr - r2)
        dx = jsl.cho_solve((L, True), r1 - A.T @ dy)
        return jnp.where(used, dx, 0.0), dy

    # start (as in CVXOPT, Vandenberghe 2010): x minimises ||h - Gx|| subject to Ax = b, s = h - Gx; z = Gw has
    # the least norm with G^T z + A^T y + c = 0; both shifted into the positive orthant when they are not in it
    L0, Ls0 = factor(jnp.ones((m,), dtype=c.dtype))
    x, _ = newton(L0, Ls0, Gt @ h, b)
    s = h - G @ x
    wv, y = newton(L0, Ls0, -c, jnp.zeros_like(b))
    z = G @ wv
    s = jnp.where(jnp.min(s) > 0, s, s + 1.0 - jnp.min(s))
    z = jnp.where(jnp.min(z) > 0, z, z + 1.0 - jnp.min(z))

    def residuals(x, s, z, y):
        rd = c + Gt @ z + A.T @ y
        rp = G @ x + s - h
        re = A @ x - b
        return rd, rp, re

    def measures(x, s, z, y):
        rd, rp, re = residuals(x, s, z, y)
        pres = jnp.maximum(jnp.max(jnp.abs(rp)), jnp.max(jnp.abs(re), initial=0.0)) / scale_h
        dres = jnp.max(jnp.abs(rd)) / scale_c
        gap = jnp.abs(s @ z) / (1.0 + jnp.abs(c @ x))
        return pres, dres, gap

    p = A.shape[0]
    k_act = n - p
    # the vertex's rows are picked from G's and, for each padded column j, the row x_j = 0 (rows m + j: always
    # picked, never left, their multipliers dropped), so the vertex of the used columns is the unpadded LP's
    G_ext = jnp.concatenate([G, jnp.diag((~used).astype(G.dtype))], axis=0)
    h_ext = jnp.concatenate([h, jnp.zeros((n,), h.dtype)])
    pinned = jnp.where(used, -jnp.inf, jnp.inf)

    def vertex_at(act):
        extra = act >= m  # a padded column's row
        K = jnp.concatenate([G_ext[act], A], axis=0)
        lu = jsl.lu_factor(K)  # one factorisation for both systems
        xv = jsl.lu_solve(lu, jnp.concatenate([h_ext[act], b]))
        xv = jnp.where(used, xv, 0.0)
        mult = jsl.lu_solve(lu, -c, trans=1)
        m_ineq = jnp.where(extra, 0.0, mult[:k_act])
        mult = jnp.concatenate([m_ineq, mult[k_act:]])
        sv = h - G @ xv
        feas = jnp.min(sv) >= -tol * scale_h
        dual_ok = jnp.min(m_ineq) >= -tol * (1.0 + jnp.max(jnp.abs(mult)))
        zv = jnp.zeros((m + n,), z.dtype).at[act].set(jnp.maximum(m_ineq, 0.0))[:m]
        yv = mult[k_act:]
        vgap = jnp.abs(c @ xv + h @ zv + b @ yv) / (jnp.abs(c @ xv) + tol * scale_c)
        ok = feas & dual_ok & jnp.all(jnp.isfinite(xv)) & jnp.all(jnp.isfinite(mult)) & (vgap < tol)
        return ok, (xv, jnp.maximum(sv, 0.0), zv, yv), sv, mult

    def repaired(act, repairs):
        """Up to `repairs` exchanges of the active-set guess: the most violated inequality enters, the active one
        with the least multiplier leaves (the interior point iterate may rank a few constraints wrongly). One
        vertex solve in the program: a loop whose first pass solves the guess and each later one exchanges a pair
        of rows (from the previous pass' slacks and multipliers) and solves again."""
        if repairs == 0:
            ok, vert, _, _ = vertex_at(act)
            return ok, vert

        def step(carry):
            act, _, _, sv, mult, i = carry
            inside = jnp.zeros((m + n,), dtype=bool).at[act].set(True)[:m]
            enter = jnp.argmin(jnp.where(inside, jnp.inf, sv))
            leave = jnp.argmin(jnp.where(act >= m, jnp.inf, mult[:k_act]))
            act = jnp.where(i > 0, act.at[leave].set(enter.astype(act.dtype)), act)
            ok, vert, sv, mult = vertex_at(act)
            return act, ok, vert, sv, mult, i + 1

        blank = jax.eval_shape(vertex_at, act)
        init = (act, *jax.tree_util.tree_map(lambda sd: jnp.zeros(sd.shape, sd.dtype), blank), 0)
        _, ok, vert, _, _, _ = jax.lax.while_loop(lambda cr: (cr[5] == 0) | (~cr[1] & (cr[5] <= repairs)), step, init)
        return ok, vert

    def crossover(x, s, z, y, repairs=8):
        """The vertex of the n - p inequalities marked active (largest z/s) and the equalities, solved exactly for
        x and the multipliers (and repaired by up to `repairs` exchanges); certified when primal feasible with
        non-negative multipliers and a zero duality gap (to `tol`). Inside the iterations without repairs (one
        factorisation each: a repaired crossover at every iteration cost more than the iteration itself), with
        them once at the end."""
        return repaired(jax.lax.top_k(jnp.concatenate([z / s, pinned]), k_act)[1], repairs)

    # a rigorous lower bound of the optimum from any dual iterate (z >= 0, y), valid even where its residual
    # rd = c + G^T z + A^T y is not zero: for feasible x, c^T x >= rd^T x - h^T z - b^T y. Terms of variables
    # with a finite bound |x_j| <= x_bound_j are bounded by |rd_j| x_bound_j; where c has one non-zero entry
    # (the objective is one variable t, as in a minimax problem) t's own term moves to the left:
    # t (c_t - rd_t) >= -h^T z - b^T y - sum_(j != t) |rd_j| x_bound_j
    xb_s = x_bound * cs
    t_idx = jnp.argmax(jnp.abs(c))
    single = jnp.sum(c != 0) == 1
    not_t = jnp.arange(n) != t_idx

    def dual_bound(z, y):
        rd = c + Gt @ z + A.T @ y
        dual = -(h @ z) - (b @ y)
        box = jnp.where(rd == 0, 0.0, jnp.abs(rd) * xb_s)
        generic = dual - jnp.sum(box)
        ct, rt = c[t_idx], rd[t_idx]
        one_var = (dual - jnp.sum(jnp.where(not_t, box, 0.0))) * ct / jnp.where(ct - rt != 0, ct - rt, 1.0)
        use = single & ((ct - rt) * ct > 0)
        return jnp.where(use, jnp.maximum(one_var, jnp.where(jnp.isfinite(generic), generic, -jnp.inf)), generic)

    def merit(x, s, z, y):
        pres, dres, gap = measures(x, s, z, y)
        m_ = jnp.maximum(jnp.maximum(pres, dres), gap)
        return jnp.where(jnp.all(jnp.isfinite(x)) & jnp.isfinite(m_), m_, jnp.inf)

    def gap_of(x, s, z, y):
        return measures(x, s, z, y)[2]

    def cond(state):
        it, done = state[4], state[5]
        return (it < max_iter) & ~done

    def body(state):
        x, s, z, y, it, _, best, best_merit, stall, best_lb = state
        rd, rp, re = residuals(x, s, z, y)
        mu = (s @ z) / m
        w = z / s
        L, Ls = factor(w)

        def direction(rc):
            # G^T W G dx + A^T dy = -rd - G^T (W rp - rc / s) ; A dx = -re, then two rounds of iterative
            # refinement on the full Newton system (the normal equations lose accuracy as W spreads over
            # many orders of magnitude near the optimum)
            r1 = -rd - Gt @ (w * rp - rc / s)

            def refine(k, d):
                # pass 0 solves from zero; each later pass refines (one Newton solve in the program)
                dx, dy = d
                ds = -rp - G @ dx
                dz = -(rc + z * ds) / s
                first = k == 0
                ddx, ddy = newton(
                    L, Ls, jnp.where(first, r1, -rd - Gt @ dz - A.T @ dy), jnp.where(first, -re, -re - A @ dx)
                )
                return dx + ddx, dy + ddy

            dx, dy = jax.lax.fori_loop(0, _REFINE + 1, refine, (jnp.zeros_like(c), jnp.zeros_like(b)))
            ds = -rp - G @ dx
            dz = -(rc + z * ds) / s
            return dx, ds, dz, dy

        def predict_correct(k, d):
            # pass 0: the predictor (affine scaling); pass 1: the corrector with centring, from the predictor's
            # step (a loop of two passes: one Newton solve in the program, not two)
            _, ds_a, dz_a, _ = d
            ap = _max_step(s, ds_a)
            ad = _max_step(z, dz_a)
            mu_aff = ((s + ap * ds_a) @ (z + ad * dz_a)) / m
            sigma = jnp.clip(mu_aff / mu, 0.0, 1.0) ** 3
            return direction(jnp.where(k == 0, s * z, s * z + ds_a * dz_a - sigma * mu))

        zero = (jnp.zeros_like(x), jnp.zeros_like(s), jnp.zeros_like(z), jnp.zeros_like(y))
        dx, ds, dz, dy = jax.lax.fori_loop(0, 2, predict_correct, zero)
        ap = 0.99 * _max_step(s, ds)
        ad = 0.99 * _max_step(z, dz)
        x, s = x + ap * dx, s + ap * ds
        z, y = z + ad * dz, y + ad * dy
        s = jnp.maximum(s, 1e-300)
        z = jnp.maximum(z, 1e-300)
        m_now = merit(x, s, z, y)
        better = m_now < best_merit
        best = jax.tree_util.tree_map(lambda new, old: jnp.where(better, new, old), (x, s, z, y), best)
        best_merit = jnp.where(better, m_now, best_merit)
        # near round-off the normal equations break down and the iterates drift away again: stop after 5
        # iterations without a new best merit, and keep the best iterate
        stall = jnp.where(better, 0, stall + 1)
        # once near the optimum, try the crossover at every iteration: a certified vertex ends the solve
        ok, vert = jax.lax.cond(
            gap_of(x, s, z, y) < 1e-3,
            lambda *a: crossover(*a, repairs=0),
            lambda *a: (jnp.asarray(False), a),
            x,
            s,
            z,
            y,
        )
        best = jax.tree_util.tree_map(lambda v, o: jnp.where(ok, v, o), vert, best)
        best_merit = jnp.where(ok, -1.0, best_merit)  # a certified vertex beats every interior point
        done = (best_merit < tol) | (stall >= 15)
        lb = dual_bound(z, y)
        best_lb = jnp.where(jnp.isfinite(lb), jnp.maximum(best_lb, lb), best_lb)
        return x, s, z, y, it + 1, done, best, best_merit, stall, best_lb

    m0 = merit(x, s, z, y)
    init = (x, s, z, y, jnp.asarray(0), jnp.asarray(False), (x, s, z, y), m0, jnp.asarray(0), jnp.asarray(-jnp.inf))
    out = jax.lax.while_loop(cond, body, init)
    it = out[4]
    x, s, z, y = out[6]
    certified_in_loop = out[7] < 0
    ok, vert = crossover(x, s, z, y)
    vertex = certified_in_loop | ok
    x, s, z, y = jax.tree_util.tree_map(lambda v, o: jnp.where(ok & ~certified_in_loop, v, o), vert, (x, s, z, y))
    pres, dres, gap = measures(x, s, z, y)
    gap = jnp.where(vertex, jnp.abs(c @ x + h @ z + b @ y) / (jnp.abs(c @ x) + tol * scale_c), gap)
    converged = vertex | ((pres < tol) & (dres < tol) & (gap < tol) & jnp.all(jnp.isfinite(x)))
    # the best rigorous lower bound met on the way (see `dual_bound`), and the final iterate's
    lower = jnp.maximum(out[9], dual_bound(z, y))
    value = c @ x
    lower = jnp.where(vertex, value, jnp.minimum(lower, value))
    return LPResult(
        x=x / cs,
        s=s * gs,
        z=z / gs,
        y=y / as_,
        value=value,
        gap=gap,
        primal_residual=pres,
        dual_residual=dres,
        iterations=it,
        converged=converged,
        vertex=vertex,
        lower_bound=lower,
    )


@jax.custom_jvp
def lp_value(c, G, h, A, b, x, z, y):
    """$c^Tx$ at a solved LP's optimum `(x, z, y)`, whose derivative with respect to the data is the envelope
    theorem's: $\\dot c^Tx + z^T(\\dot G x - \\dot h) + y^T(\\dot A x - \\dot b)$ (the optimum held fixed)."""
    return c @ x


@lp_value.defjvp
def _lp_value_jvp(primals, tangents):
    c, G, h, A, b, x, z, y = primals
    dc, dG, dh, dA, dB, _, _, _ = tangents
    return c @ x, dc @ x + z @ (dG @ x - dh) + y @ (dA @ x - dB)


def solve_lp(c, G, h, A, b, *, x_bound=None, tol=1e-9, max_iter: int = 100) -> LPResult:
    """Solve $\\min c^Tx$ s.t. $Gx \\le h$, $Ax = b$ (see the module docstring).

    Shapes: `c` (n,), `G` (m, n), `h` (m,), `A` (p, n) with p >= 1, `b` (p,). `G` must have full
    column rank (every variable bounded by some inequality). `x_bound` (n,): bounds on |x| that hold at the
    optimum (from the constraints), for the rigorous `lower_bound` (default: infinite, the bound is then
    only finite at a certified vertex). Pure JAX: jit, vmap compose; `value` differentiates (envelope
    theorem); the other fields carry no derivative.
    """
    c, G, h, A, b = (jnp.asarray(v, dtype=float) for v in (c, G, h, A, b))
    if c.ndim != 1 or G.ndim != 2 or G.shape[1] != c.shape[0] or h.shape != (G.shape[0],):
        raise ValueError(f"solve_lp: shapes c (n,), G (m, n), h (m,) expected; got {c.shape}, {G.shape}, {h.shape}")
    if A.ndim != 2 or A.shape[1] != c.shape[0] or b.shape != (A.shape[0],) or A.shape[0] < 1:
        raise ValueError(f"solve_lp: shapes A (p, n), b (p,) with p >= 1 expected; got {A.shape}, {b.shape}")
    xb = jnp.full(c.shape, jnp.inf) if x_bound is None else jnp.broadcast_to(jnp.asarray(x_bound, dtype=float), c.shape)
    return _solve_lp_program(c, G, h, A, b, xb, jnp.asarray(tol, dtype=float), jnp.asarray(max_iter))


def solve_lp_data(c, G, h, A, b, x_bound, tol, max_iter, groups=(), used=None):
    """`solve_lp` on arrays of the right shapes, with `tol` and `max_iter` as (traceable) values: the interior
    point method runs on the data with its derivatives stopped; `value` carries the envelope derivative.
    `groups`: `RowGroups` of G's rows (the factorisation's shortcut; G itself holds every row).

    `used` (n,) booleans (traceable; default all True): the columns in use. A column not in use is padding (zero
    in `c`, `G` and `A`, so that LPs of different sizes share one compiled program): its value is exactly 0, its
    normal equations are the identity, and the optimal vertex is picked among the rows of the used columns, so
    the result is the LP without those columns (the same x, s, z, y, value and bound, to round-off)."""
    stop = jax.lax.stop_gradient
    c_, G_, h_, A_, b_, xb_ = (stop(v) for v in (c, G, h, A, b, x_bound))
    groups = tuple(RowGroups(g.idx, stop(g.U), stop(g.V)) for g in groups)
    used = None if used is None else stop(jnp.asarray(used, dtype=bool))
    res = _solve_impl(c_, G_, h_, A_, b_, xb_, jnp.asarray(tol, dtype=float), max_iter, groups, used)
    value = lp_value(c, G, h, A, b, stop(res.x), stop(res.z), stop(res.y))
    return res._replace(value=value, lower_bound=stop(res.lower_bound))


# one compiled program per shape of the data: called eagerly, the solver's loops would be traced and compiled anew
# at every call (inside a caller's jit this is inlined as any jitted function)
_solve_lp_program = jax.jit(solve_lp_data)


def simplex_minimax(cuts, sizes=(8, 17, 33, 65, 129, 257), tol: float = 1e-10):
    """The least worst row over the simplex: $\\min_{x, t}\\ t$ subject to $C x \\le t$, $x \\ge 0$, $\\sum x = 1$
    (`cuts` C of shape (m, K), rows that are cuts of a modulus, so that $t \\ge 0$), by `solve_lp`. Where a weighting of K given columns (amplitudes of impulses, weights
    of moves) minimises a worst case over cut rows. The columns are padded with copies of the last one up to the
    first of `sizes` that holds K (a copy is the same column: the optimum is unchanged and the copies' weights
    are added back), so that one compiled program serves every call of that size.

    Returns `(x, value, z, converged)`: the weights (K,), the optimal t, the multipliers of the cut rows (m,),
    normalised to add to 1 (weak duality: $\\min_k (z^TC)_k$ is a lower bound on t whatever the solver's
    tolerances), and whether the solver met its tolerance."""
    C = np.asarray(cuts, dtype=float)
    m, K = C.shape
    n = next((s for s in sizes if s >= K), K)
    C = np.hstack([C, np.repeat(C[:, -1:], n - K, axis=1)])
    eye = np.eye(n)
    G = np.vstack(
        [
            np.hstack([C, -np.ones((m, 1))]),
            np.hstack([-eye, np.zeros((n, 1))]),  # x >= 0
            np.hstack([eye, np.zeros((n, 1))]),  # x <= 1 (implied; bounds every variable)
            np.r_[np.zeros(n), -1.0][None],  # t >= 0 (valid where every row is a cut of a modulus; bounds t)
        ]
    )
    h = np.r_[np.zeros(m), np.zeros(n), np.ones(n), 0.0]
    c = np.r_[np.zeros(n), 1.0]
    A = np.r_[np.ones(n), 0.0][None]
    res = solve_lp(c, G, h, A, np.ones(1), x_bound=np.r_[np.ones(n), np.abs(C).max(initial=1.0)], tol=tol)
    x = np.clip(np.asarray(res.x)[:n], 0.0, None)
    x = np.r_[x[: K - 1], x[K - 1 :].sum()]
    z = np.clip(np.asarray(res.z)[:m], 0.0, None)
    z = z / z.sum() if z.sum() > 0 else np.full(m, 1.0 / m)
    return x, float(res.value), z, bool(res.converged)
