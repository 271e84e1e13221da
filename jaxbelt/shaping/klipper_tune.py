"""Klipper's shaper types tuned to an identified axis: the frequency and damping ratio of each type chosen by
gradient for every mode, the band and the uncertainty, within a duration.

Klipper's calibration tests each type at damping 0.1 on a 0.2 Hz grid of frequencies and scores the PSD of one
resonance test; with the axis' modes known, each type's two parameters can be chosen for the whole band instead.
For a type with impulses $(A_k(f, \\zeta), t_k(f, \\zeta))$ (`jaxbelt.shaping.klipper.impulses`, differentiable)
the duration is $t_K(f, \\zeta) = c(\\zeta)/f$; the variables $(u, v)$ map to
$\\zeta = \\zeta_{max}\\,\\sigma(v)$ and $f = (c(\\zeta)/\\tau)\\,e^{\\mathrm{softplus}(u)}$, so every iterate lasts at
most $\\tau$ and its damping stays in the type's range. Adam (optax) minimises the smooth maximum $L_p$ of
`jaxbelt.shaping.free_times` over the band's poles from the best points of a coarse grid of $(f, \\zeta)$; each run
keeps its iterate of least true worst residual.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .free_times import ratios
from .klipper import KLIPPER_SHAPERS, impulses

STEPS = 300
_LR = 0.05
_ZETA_CAP = 0.9  # zv/mzv/zvd accept damping ratios to 0.99; above 0.9 the search only meets overdamped nonsense


def zeta_max(kind: str) -> float:
    return min(KLIPPER_SHAPERS[kind][1], _ZETA_CAP)


def length_factor(kind: str, zeta, xp=np):
    """$c(\\zeta)$: the type's duration [s] at 1 Hz (its duration at f is $c/f$)."""
    return impulses(kind, 1.0, zeta, xp)[1][-1]


def _shaper(kind, u, v, tau, xp):
    zeta = zeta_max(kind) / (1.0 + xp.exp(-v))
    f = length_factor(kind, zeta, xp) / tau * xp.exp(xp.logaddexp(0.0, u))
    return f, zeta


def to_params(kind: str, freq: float, zeta: float, tau: float):
    zm = zeta_max(kind)
    q = min(max(zeta / zm, 1e-6), 1 - 1e-6)
    f0 = float(length_factor(kind, zeta)) / tau
    r = max(math.log(max(freq / f0, 1.0)), 1e-6)
    return math.log(math.expm1(r)), math.log(q / (1 - q))


def _normalised(kind, f, zeta, xp):
    A, T = impulses(kind, f, zeta, xp)
    A = xp.stack(A) if xp is jnp else np.array(A, dtype=float)
    T = xp.stack(T) if xp is jnp else np.array(T, dtype=float)
    return A / xp.sum(A), T


def _apply(params, updates) -> tuple:
    """Adam's step applied to the tuple of variables (optax's `apply_updates`, typed as a tuple)."""
    return tuple(p + d for p, d in zip(params, updates))


@functools.partial(jax.jit, static_argnames=("kind", "steps"))
def _runs(kind: str, u0, v0, tau, s, steps: int = STEPS):
    opt = optax.adam(_LR)
    ps = 8.0 * (1024.0 / 8.0) ** (jnp.arange(steps) / max(steps - 1, 1))

    def vals(params):
        f, z = _shaper(kind, params[0], params[1], tau, jnp)
        A, T = _normalised(kind, f, z, jnp)
        return ratios(A, T, s, jnp)

    def one(u, v):
        def loss(params, p):
            return jax.nn.logsumexp(p * jnp.log(vals(params) + 1e-300)) / p

        def step(carry, p):
            params, state, best, best_w = carry
            w = jnp.max(vals(params))
            better = w < best_w
            best = jax.tree.map(lambda n, o: jnp.where(better, n, o), params, best)
            best_w = jnp.where(better, w, best_w)
            upd, state = opt.update(jax.grad(loss)(params, p), state, params)
            return (_apply(params, upd), state, best, best_w), None

        params = (u, v)
        (params, _, best, best_w), _ = jax.lax.scan(step, (params, opt.init(params), params, jnp.inf), ps)
        w = jnp.max(vals(params))
        better = w < best_w
        return jnp.where(better, params[0], best[0]), jnp.where(better, params[1], best[1])

    u, v = jax.vmap(one)(u0, v0)
    return _shaper(kind, u, v, tau, jnp)


def grid(kind: str, tau: float, s, modes):
    """`[(worst, freq, zeta), ...]` sorted: the type `kind` on a coarse grid within `tau` [s] (each mode's
    frequency times 0.6 … 1.6, at the modes' damping ratios and 0.02, 0.05, 0.1, 0.2), scored against the
    poles `s`. `modes`: `[(f, zeta), ...]` of the axis."""
    zm = zeta_max(kind)
    zetas = sorted({min(z, zm) for _, z in modes} | {min(v, zm) for v in (0.02, 0.05, 0.1, 0.2)})
    pts = {(float(length_factor(kind, zm / 2)) / tau, zm / 2)}
    for f, z in modes:  # the type at each mode's own frequency and damping, where it fits
        if float(length_factor(kind, min(z, zm))) / f <= tau:
            pts.add((f, min(z, zm)))
    for f, _ in modes:
        for r in np.geomspace(0.6, 1.6, 21):
            for z in zetas:
                pts.add((max(f * r, float(length_factor(kind, z)) / tau), z))
    scored = [(float(np.max(ratios(*_normalised(kind, f, z, np), s))), f, z) for f, z in pts]
    return sorted(scored)


def tune(kind: str, tau: float, s, starts):
    """`[(freq, zeta), ...]`: the type `kind` tuned by gradient from each of `starts` (`[(freq, zeta), ...]`),
    within `tau` [s], against the poles `s`."""
    u0, v0 = zip(*(to_params(kind, f, z, tau) for f, z in starts))
    f, z = _runs(kind, jnp.asarray(u0), jnp.asarray(v0), jnp.asarray(float(tau)), jnp.asarray(s))
    return [(float(fi), float(zi)) for fi, zi in zip(np.asarray(f), np.asarray(z))]
