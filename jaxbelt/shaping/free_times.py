"""A shaper of at most K impulses whose times are free: amplitudes and times optimised together by gradient.

With the impulse times fixed, the least worst residual over the band is a linear programme in the amplitudes
(`jaxbelt.shaping.firmware_shaper`); with few impulses (RepRapFirmware's 5) the times matter most, and the worst
residual is not convex in them. Here both are optimised from several starts at once (`jax.vmap`), by Adam (optax)
on a smooth maximum of the residual ratios $V_g = |\\sum_k A_k e^{s_g(t_{K} - t_k)}|$ over the band's poles $s_g$:

$L_p = \\frac1p \\log \\sum_g V_g^p$ (above $\\max_g V_g$ by at most $\\log(G)/p$, relatively), $p$ raised
geometrically from 8 to 1024 over the run.

The variables are unconstrained: amplitudes $A = \\mathrm{softmax}(a)$ (>= 0, adding to 1); times from K gaps
$g = \\tau\\,\\mathrm{softmax}(z)$ of which the first K-1 separate the impulses and the last is the slack, so
$0 = t_1 \\le \\dots \\le t_K \\le \\tau$ (the shaper is never longer than its duration $\\tau$). Each start keeps
the iterate of least true worst residual (the start itself included), so no start is made worse. The amplitudes
at each run's best times are then polished by the LP at those fixed times.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

#: Adam's steps and learning rate per run
STEPS = 500
_LR = 0.03
_FLOOR = 1e-7  # smallest gap / amplitude fraction a start maps to (log of zero is not a start)


def to_params(A, T, tau: float, K: int):
    """Unconstrained `(z, a)` of the shaper `(A, T)` (at most K impulses, within `tau`): a shorter one has its
    largest impulses split in two at the same time (the same shaper, K impulses)."""
    A, T = list(np.asarray(A, dtype=float)), list(np.asarray(T, dtype=float))
    while len(A) < K:
        i = int(np.argmax(A))
        A[i] *= 0.5
        A.insert(i + 1, A[i])
        T.insert(i + 1, T[i])
    A_ = np.asarray(A) / np.sum(A)
    T_ = np.asarray(T) - T[0]
    gaps = np.r_[np.diff(T_), max(tau - T_[-1], 0.0)] / tau
    return np.log(np.maximum(gaps, _FLOOR)), np.log(np.maximum(A_, _FLOOR))


def from_params(z, a, tau, xp=np):
    """`(A, T)` of the unconstrained variables (see the module docstring)."""
    g = tau * _softmax(z, xp)
    T = xp.concatenate([xp.zeros(1), xp.cumsum(g[:-1])])
    return _softmax(a, xp), T


def _softmax(x, xp):
    e = xp.exp(x - xp.max(x))
    return e / xp.sum(e)


def ratios(A, T, s, xp=np):
    """Residual ratios $|\\sum_k A_k e^{s(t_K - t_k)}|$ at the poles `s` (G,)."""
    lag = T[-1] - T
    return xp.abs(xp.sum(A[None, :] * xp.exp(s[:, None] * lag[None, :]), axis=1))


def _apply(params, updates) -> tuple:
    """Adam's step applied to the tuple of variables (optax's `apply_updates`, typed as a tuple)."""
    return tuple(p + d for p, d in zip(params, updates))


@functools.partial(jax.jit, static_argnames=("steps",))
def _runs(z0, a0, tau, s, steps: int = STEPS):
    """Adam on $L_p$ from each start (rows of `z0`, `a0`): the best `(z, a)` of each run and its worst ratio."""
    opt = optax.adam(_LR)
    ps = 8.0 * (1024.0 / 8.0) ** (jnp.arange(steps) / max(steps - 1, 1))

    def one(z, a):
        def worst(z, a):
            A, T = from_params(z, a, tau, jnp)
            return jnp.max(ratios(A, T, s, jnp))

        def loss(params, p):
            A, T = from_params(params[0], params[1], tau, jnp)
            v = ratios(A, T, s, jnp)
            return jax.nn.logsumexp(p * jnp.log(v + 1e-300)) / p

        def step(carry, p):
            params, state, best, best_w = carry
            w = worst(*params)
            better = w < best_w
            best = jax.tree.map(lambda n, o: jnp.where(better, n, o), params, best)
            best_w = jnp.where(better, w, best_w)
            g = jax.grad(loss)(params, p)
            upd, state = opt.update(g, state, params)
            return (_apply(params, upd), state, best, best_w), None

        params = (z, a)
        carry = (params, opt.init(params), params, jnp.asarray(jnp.inf))
        (params, _, best, best_w), _ = jax.lax.scan(step, carry, ps)
        w = worst(*params)
        better = w < best_w
        best = jax.tree.map(lambda n, o: jnp.where(better, n, o), params, best)
        return best[0], best[1], jnp.minimum(w, best_w)

    return jax.vmap(one)(z0, a0)


def optimise(starts, tau: float, s, K: int):
    """Run Adam from every start `(A, T)` (each at most K impulses, within `tau`) against the poles `s`;
    returns `[(A, T), ...]` of each run's best iterate, in the order of `starts`."""
    zs, as_ = zip(*(to_params(A, T, tau, K) for A, T in starts))
    n = len(zs)
    pad = (-n) % 8  # runs in blocks of 8: one compile for a number of starts up to the next multiple
    z0 = np.array(list(zs) + [zs[0]] * pad)
    a0 = np.array(list(as_) + [as_[0]] * pad)
    z, a, _ = _runs(jnp.asarray(z0), jnp.asarray(a0), jnp.asarray(float(tau)), jnp.asarray(s))
    z, a = np.asarray(z), np.asarray(a)
    return [from_params(z[i], a[i], tau) for i in range(n)]
