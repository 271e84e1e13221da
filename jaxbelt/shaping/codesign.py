"""What no input shaper gives: how the best achievable residual, and the shortest move, change with the axis.

The minimax design's optimal value $V(\\theta, T)$ (the least worst-case residual, as a fraction of the
references, over the design's final frequency grid) is differentiable in the axis $\\theta$ (mode
frequencies, damping ratios, gains; through `BeltPlatform.to_axis()` the belt stiffness, the payload inertia
and the pulley radii of Incerti's platform) and in the move time $T$, by the envelope theorem on the LP
(`jaxbelt.shaping.lp`). The shortest move time at a residual target $V^*$ is the root $T^*(\\theta)$ of
$V(\\theta, T) = V^*$; implicit differentiation gives
$\\dfrac{dT^*}{d\\theta} = -\\dfrac{\\partial V/\\partial\\theta}{\\partial V/\\partial T}$.

Both functions take the grid, references and discretisation of a solved design (`plan.minimax` of a
`jaxbelt.design_move` plan, or `jaxbelt.shaping.design.minimax_design`): the derivative is that of the
discretised optimum, which the tests check against central finite differences.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._threads import blas_limited
from ..models.axis import ModalAxis
from .design import MinimaxDesign, minimax_value


def _problem(design: MinimaxDesign, axis, move_time):
    p = design.problem
    return eqx.tree_at(lambda q: (q.axis, q.move_time), p, (axis, jnp.asarray(move_time, dtype=float)))


@blas_limited
def best_residual(axis: ModalAxis, move_time, design: MinimaxDesign):
    """The least worst-case residual (fraction of the references) any smooth move of the design's distance and
    limits can leave on `axis` in `move_time` [s], on the frequency grid of `design`. Differentiable in the axis'
    arrays and `move_time` (`jax.grad`, forward mode too); the references are held fixed."""
    if not isinstance(axis, ModalAxis) or axis.n_modes != design.problem.axis.n_modes:
        raise ValueError(
            f"best_residual: `axis` must be a ModalAxis with {design.problem.axis.n_modes} modes, like the design's"
        )
    return minimax_value(_problem(design, axis, move_time), design.options, tau=jax.lax.stop_gradient(design.worst))


def _root_time(axis, target, design, t_lo, t_hi, iters=60):
    """Host root of V(axis, T) = target on [t_lo, t_hi] (V decreasing in T): Newton steps on T with the exact
    derivative dV/dT, kept inside a shrinking bisection bracket."""
    value_and_slope = jax.value_and_grad(lambda T: best_residual(axis, T, design))
    lo, hi = float(t_lo), float(t_hi)
    v_lo, v_hi = float(best_residual(axis, lo, design)), float(best_residual(axis, hi, design))
    if not (v_lo >= target >= v_hi):
        raise ValueError(
            f"shortest_move_time: the target {target:g} is not reached within the bracket [{lo:g}, {hi:g}] s "
            f"(worst residual {v_lo:.4g} .. {v_hi:.4g}); pass a wider `bracket`"
        )
    T = 0.5 * (lo + hi)
    for _ in range(iters):
        v, dv = (float(q) for q in value_and_slope(T))
        if v > target:
            lo = T
        else:
            hi = T
        if abs(v - target) <= 1e-12 * max(abs(target), 1e-300) or hi - lo <= 1e-12 * hi:
            return T
        step = T - (v - target) / dv if dv < 0 else None
        T = step if step is not None and lo < step < hi else 0.5 * (lo + hi)
    return T


@blas_limited
def shortest_move_time(axis: ModalAxis, target, design: MinimaxDesign, *, bracket=None):
    """The least move time [s] at which the minimax design on `axis` reaches the worst residual `target` (a
    fraction of the references; e.g. `design.worst`), on the frequency grid of `design`.

    Differentiable with respect to the axis by the implicit function theorem (`jax.grad`, `jax.jvp` called
    eagerly: the root is found by bisection on concrete values, so not inside `jax.jit`). `bracket`: the search
    interval [s] (default: 0.9 to 1.5 times the design's move time; it must hold the root, and only feasible
    move times: the limits must allow the distance at its lower end)."""
    T0 = float(design.command.duration)
    lo, hi = bracket if bracket is not None else (0.9 * T0, 1.5 * T0)
    leaves, treedef = jax.tree_util.tree_flatten(axis)
    return _shortest(tuple(leaves), float(target), treedef, design, float(lo), float(hi))


def _shortest(leaves, target, treedef, design, lo, hi):
    @jax.custom_jvp
    def f(leaves):
        axis = jax.tree_util.tree_unflatten(treedef, leaves)
        return jnp.asarray(_root_time(axis, target, design, lo, hi))

    @f.defjvp
    def f_jvp(primals, tangents):
        (lv,), (tv,) = primals, tangents
        T = f(lv)

        def V(lv_, T_):
            return best_residual(jax.tree_util.tree_unflatten(treedef, lv_), T_, design)

        _, dV_theta = jax.jvp(lambda l_: V(l_, T), (lv,), (tv,))
        dV_T = jax.grad(lambda T_: V(lv, T_))(T)
        return T, -dV_theta / dV_T

    return f(leaves)
