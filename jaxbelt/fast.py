"""Fast batched closed forms: many exponential inputs through one linear time-invariant system.

A sweep over the time constant $\\gamma$ of the start-up command (Incerti, 2014, eq. 30) shares the
state matrix A: only the input rate $s_b = -1/\\gamma_b$ changes from one trajectory to the next.
With the modal decomposition $A = X\\Lambda X^{-1}$ computed once (Incerti, 2014, eq. 14-29), the
response to $f_b e^{s_b t}$ is, mode by mode (eq. 27 with $q_{bi} = (X^{-1} f_b)_i$),

$\\eta_{bi}(\\tau) = q_{bi}\\,\\dfrac{e^{s_b\\tau} - e^{\\lambda_i\\tau}}{s_b - \\lambda_i}$,

so that, with $w_{bi} = q_{bi}/(s_b - \\lambda_i)$,

$x_b(\\tau) = x_{shared}(\\tau) + e^{s_b\\tau}\\,\\mathrm{Re}(X w_b)
  - \\mathrm{Re}\\big(E(\\tau)\\,(X\\,\\mathrm{diag}(w_b))^T\\big)$, $E_{ti} = e^{\\lambda_i\\tau_t}$.

$x_{shared}$ (free response + constant inputs) and $E$ are computed once for the whole batch;
per trajectory there remain N real exponentials and one real matrix product
$(N\\times 2m)(2m\\times n)$, which XLA runs as a single GEMM over the batch. This is about
20-50x cheaper per trajectory than a per-$\\gamma$ matrix exponential and time-stepping scan.

**Resonance.** The separated form loses accuracy when $s_b \\to \\lambda_i$ (cancellation error
$O(\\epsilon/|s_b-\\lambda_i|)$). For a mode with $|s_b-\\lambda_i| < 10^{-2}\\max(|\\lambda_i|,|s_b|,1/T)$
the separated term is dropped and replaced by the cancellation-free
$e^{\\lambda_i\\tau}\\,\\tau\\,\\varphi_1((s_b-\\lambda_i)\\tau)$ (real arithmetic: only a real
eigenvalue can be that close to a real rate), evaluated only for the elements concerned
(up to `n_fix` per chunk of `chunk` elements; beyond that for the whole chunk). Anything less regular (two modes near one rate, a nearly real
complex pair) takes the exact per-element form of `jaxbelt.modal`; a defective or ill-conditioned A
(e.g. a critically damped belt) falls back to a per-element matrix exponential. Both fall-backs run
element by element (`lax.map`), so that their memory stays that of one trajectory.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .modal import MODAL_COND_LIMIT, exp_convolution, expm_solve, modal_decomposition, phi1

RESONANCE_REL = 1e-2


def _shared_response(lam, X, Yt, F, s, x0, t0, tau):
    """Free response plus the shared exponential inputs (eq. 27), shape (N, n)."""
    eta0 = Yt @ x0.astype(complex)
    qw = (Yt @ F.astype(complex)) * jnp.exp(s * t0)[None, :]
    conv = exp_convolution(lam[None, :, None], s[None, None, :], tau[:, None, None])  # (N, m, j)
    eta = eta0[None, :] * jnp.exp(lam[None, :] * tau[:, None]) + jnp.sum(qw[None] * conv, axis=2)
    return jnp.real(eta @ X.T)


def _exact_one(lam, X, q, s_b, tau):
    """Cancellation-free response of one element to $q e^{s_b t}$ (modal coordinates q), (N, n)."""
    conv = exp_convolution(lam[None, :], s_b, tau[:, None])  # (N, m)
    return jnp.real((conv * q[None, :]) @ X.T)


def exp_input_batch(
    A, F, s, x0, t0, ts, f_var, s_var, *, uniform: bool | None = None, n_fix: int = 8, chunk: int = 256
):
    """States of $\\dot x = A x + \\sum_j F_{:,j}e^{s_j t} + f_b e^{s_b t}$ for a batch of $(f_b, s_b)$.

    - `A` (n, n), `F` (n, J), `s` (J,): the system and the inputs shared by the batch
      (as returned by `model.exponential_form`, minus the varying term);
    - `x0` (n,), `t0`: initial state at time `t0` [s]; `ts` (N,) output times;
    - `f_var` (n,) or (B, n): amplitude vector of the varying term; `s_var` (B,) its real
      rates [1/s] (e.g. $-1/\\gamma_b$);
    - `uniform`: whether `ts` is evenly spaced (`None`: decided from its values in the program; used by
      the expm fall-back only);
    - `n_fix`: near-resonant elements per chunk corrected one by one (with more, the correction
      is evaluated for the whole chunk);
    - `chunk`: batch elements per chunk of the separated form (memory locality).

    Returns (B, N, n). Differentiable with respect to `f_var`, `s_var` (and `x0`, `F`, `s`);
    not with respect to A (JAX does not differentiate eigenvectors).
    """
    A = jnp.asarray(A, dtype=float)
    s_var = jnp.asarray(s_var, dtype=float)
    f_var = jnp.asarray(f_var, dtype=float)
    nb = s_var.shape[0]
    f_var = jnp.broadcast_to(f_var, (nb, A.shape[0]))
    tau = jnp.asarray(ts, dtype=float) - t0
    lam, X, Yt, cond = modal_decomposition(A)
    q = (f_var.astype(complex) @ Yt.T) * jnp.exp(s_var * t0)[:, None]  # (B, m), eq. 25
    delta = s_var[:, None] - lam[None, :]
    scale = jnp.maximum(jnp.maximum(jnp.abs(lam)[None, :], jnp.abs(s_var)[:, None]), 1.0 / jnp.max(tau))
    near = jnp.abs(delta) < RESONANCE_REL * scale  # (B, m)
    is_real = jnp.imag(lam) == 0
    n_near = jnp.sum(near, axis=1)
    # a cheap real correction handles one near-resonant real mode per element; anything else
    # (a nearly real complex pair, two modes near one rate) takes the exact per-element form
    simple = jnp.all((n_near <= 1) & ~jnp.any(near & ~is_real[None, :], axis=1))
    n_chunks = -(-nb // chunk)
    size = -(-nb // n_chunks)
    shared = _shared_response(lam, X, Yt, F, s, x0, t0, tau)
    E = jnp.exp(lam[None, :] * tau[:, None])  # (N, m)
    G = jnp.concatenate([jnp.real(E), -jnp.imag(E)], axis=1)  # (N, 2m)

    def separated_chunk(s_c, q_c):
        nc = s_c.shape[0]
        delta = s_c[:, None] - lam[None, :]
        scale = jnp.maximum(jnp.maximum(jnp.abs(lam)[None, :], jnp.abs(s_c)[:, None]), 1.0 / jnp.max(tau))
        near = jnp.abs(delta) < RESONANCE_REL * scale
        w = jnp.where(near, 0.0, q_c / jnp.where(near, 1.0, delta))  # (B, m)
        v = jnp.real(w @ X.T)  # (B, n)
        M = X[None, :, :] * w[:, None, :]  # (B, n, m)
        W = jnp.concatenate([jnp.real(M), jnp.imag(M)], axis=2)  # (B, n, 2m)
        # (B, n, N) then transposed: XLA's CPU GEMM is several times faster in this layout
        xs = jnp.einsum("tk,bnk->bnt", G, W).transpose(0, 2, 1)
        xs = shared[None] + jnp.exp(s_c[:, None] * tau[None, :])[:, :, None] * v[:, None, :] - xs

        # near-resonant real mode i: conv = e^{lam tau} tau phi1((s - lam) tau), all real
        i_star = jnp.argmax(near, axis=1)
        lam_b = jnp.real(lam[i_star])
        coef = jnp.real(X[:, i_star].T * q_c[jnp.arange(nc), i_star][:, None])  # (B, n)
        has = jnp.any(near, axis=1)

        def correction(sel):
            d = s_c[sel] - lam_b[sel]
            tt = tau[None, :]
            c = jnp.exp(lam_b[sel][:, None] * tt) * tt * phi1(d[:, None] * tt)  # (K, N)
            return jnp.where(has[sel][:, None, None], c[:, :, None] * coef[sel][:, None, :], 0.0)

        # usually a handful of elements per chunk are near resonance: correct only those
        k = min(n_fix, nc)
        _, idx = jax.lax.top_k(has.astype(float), k)
        return jax.lax.cond(
            jnp.sum(has) > k,
            lambda x: x + correction(jnp.arange(nc)),
            lambda x: x.at[idx].add(correction(idx)),
            xs,
        )

    def separated():
        if n_chunks == 1:
            return separated_chunk(s_var, q)
        # chunks keep the intermediates of one GEMM in cache instead of streaming B x N x n
        # arrays through memory several times. Each chunk is written into the output in place
        # (a loop of dynamic_update_slice): no padded copy of the batch. The last chunk starts at
        # B - size, overlapping its predecessor when `size` does not divide B; the overlap is
        # recomputed from the same inputs and written with the same values.
        out = jnp.zeros((nb, tau.shape[0], A.shape[0]), dtype=shared.dtype)

        def body(i, out):
            start = jnp.minimum(i * size, nb - size)
            s_c = jax.lax.dynamic_slice_in_dim(s_var, start, size)
            q_c = jax.lax.dynamic_slice_in_dim(q, start, size)
            return jax.lax.dynamic_update_slice_in_dim(out, separated_chunk(s_c, q_c), start, axis=0)

        return jax.lax.fori_loop(0, n_chunks, body, out)

    def exact():
        return shared[None] + jax.lax.map(lambda a: _exact_one(lam, X, a[0], a[1], tau), (q, s_var))

    def expm_path():
        def one(a):
            f, sv = a
            return expm_solve(
                A, jnp.concatenate([F, f[:, None]], axis=1), jnp.concatenate([s, sv[None]]), x0, t0, ts, uniform
            )

        return jax.lax.map(one, (f_var, s_var))

    ok = jnp.isfinite(cond) & (cond < MODAL_COND_LIMIT)
    branch = jnp.where(ok, jnp.where(simple, 0, 1), 2)
    return jax.lax.switch(branch, [separated, exact, expm_path])


def startup_gamma_batch(
    model, gammas, ts, v_max: ArrayLike = 24.0, y0=None, *, t0=None, n_fix: int = 8, chunk: int = 256
):
    """State histories of a belt start-up model for a batch of voltage time constants.

    $V_b(t) = V_{max}(1 - e^{-t/\\gamma_b})$ (Incerti, 2014, eq. 30) drives `model` (a `BeltStartup`
    or `BeltChain`) from rest (or `y0`) at t = `ts[0]`. Equivalent to
    `jax.vmap(lambda g: simulate(Scene(model, ExponentialVoltage(v_max, g), ts=ts)).ys)(gammas)`
    with shape (B, N, n_states), but with the modal decomposition and the shared responses
    computed once for the batch (see module docstring).
    """
    from .commands import ConstantVoltage

    gammas = jnp.asarray(gammas, dtype=float)
    ts = jnp.asarray(ts, dtype=float)
    A, F, s = model.exponential_form(ConstantVoltage(v_max))  # load torque + constant V_max
    f_var = -jnp.asarray(v_max, dtype=float) * model.linear_system()[1]
    x0 = jnp.zeros((A.shape[0],)) if y0 is None else jnp.asarray(y0, dtype=float)
    uniform = None  # decided from the values in the program (the expm fall-back only)
    t0 = ts[0] if t0 is None else jnp.asarray(t0, dtype=float)
    return exp_input_batch(A, F, s, x0, t0, ts, f_var, -1.0 / gammas, uniform=uniform, n_fix=n_fix, chunk=chunk)


def batched_exponential_scene(scene):
    """Solve a start-up scene whose command carries a *batch* of time constants, or return None.

    `Scene(model, ExponentialVoltage(v_max, gammas), ts=ts)` with `gammas` of shape (B,) (a scalar
    `v_max`, scalar model parameters) is B start-up runs sharing A: they are solved together by
    `startup_gamma_batch`. The result is a `Solution` with `ys` (B, N, n) and each observed output
    (B, N); `success` (B,) is False where a trajectory is not finite. Anything else returns None
    (the caller solves the scene as usual).
    """
    from ._model import AbstractLinearModel
    from .commands import ExponentialVoltage
    from .solution import Solution

    model, inp = scene.model, scene.input
    if scene.ts is None or not isinstance(inp, ExponentialVoltage) or not isinstance(model, AbstractLinearModel):
        return None
    if jnp.ndim(inp.gamma) != 1 or jnp.ndim(inp.v_max) != 0:
        return None
    if any(jnp.ndim(leaf) != 0 for leaf in jax.tree_util.tree_leaves(model)):
        return None
    if any(n in model.integral_names() for n in scene.observe):
        return None
    ys = startup_gamma_batch(model, inp.gamma, scene.ts, v_max=inp.v_max, y0=scene.y0, t0=scene.start_time)
    outputs = {}
    for name in scene.observe:

        def one(g, yb, name=name):
            cmd = ExponentialVoltage(inp.v_max, g)
            return jax.vmap(lambda t, y: model.output(name, t, y, cmd))(scene.ts, yb)

        outputs[name] = jax.vmap(one)(inp.gamma, ys)
    success = jnp.all(jnp.isfinite(ys), axis=(1, 2))
    return Solution(
        ts=scene.ts,
        ys=ys if scene.state else None,
        outputs=outputs,
        success=success,
        stats={},
        state_names=tuple(model.state_names),
        method="fast",
    )
