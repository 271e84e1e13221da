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

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .modal import (
    CLOSED_FORM_TOL,
    MODAL_COND_LIMIT,
    closed_form_error,
    exp_convolution,
    expm_solve,
    modal_decomposition,
    phi1,
)

RESONANCE_REL = 1e-2


def _shared_response(lam, X, Yt, F, s, x0, t0, tau):
    """Free response plus the shared exponential inputs (eq. 27), shape (N, k) for the k rows of X."""
    eta0 = Yt @ x0.astype(complex)
    qw = (Yt @ F.astype(complex)) * jnp.exp(s * t0)[None, :]
    conv = exp_convolution(lam[None, :, None], s[None, None, :], tau[:, None, None])  # (N, m, j)
    eta = eta0[None, :] * jnp.exp(lam[None, :] * tau[:, None]) + jnp.sum(qw[None] * conv, axis=2)
    return jnp.real(eta @ X.T)


def _exact_one(lam, X, q, s_b, tau):
    """Cancellation-free response of one element to $q e^{s_b t}$ (modal coordinates q), (N, k)."""
    conv = exp_convolution(lam[None, :], s_b, tau[:, None])  # (N, m)
    return jnp.real((conv * q[None, :]) @ X.T)


def _real_basis(lam, tau):
    r"""The real functions spanning $\mathrm{Re}\sum_i c_i e^{\lambda_i\tau}$, one per eigenvalue, (N, m), and the
    map from complex coefficients to theirs.

    A real A has real eigenvalues and complex conjugate pairs with conjugate eigenvectors (LAPACK returns them
    exactly so). For a pair, $c e^{\lambda\tau} + \bar c e^{\bar\lambda\tau} = 2\,\mathrm{Re}(c)\,
    \mathrm{Re}(e^{\lambda\tau}) - 2\,\mathrm{Im}(c)\,\mathrm{Im}(e^{\lambda\tau})$: the member with
    $\mathrm{Im}\lambda > 0$ carries the cosine-like function, its partner the sine-like one
    ($\mathrm{Im}\,e^{\bar\lambda\tau} = -\mathrm{Im}\,e^{\lambda\tau}$). So m real functions instead of 2m:
    the batch's matrix product does half the work."""
    E = jnp.exp(lam[None, :] * tau[:, None])  # (N, m)
    lower = jnp.imag(lam) < 0
    G = jnp.where(lower[None, :], jnp.imag(E), jnp.real(E))
    upper = jnp.imag(lam) > 0

    def coefficients(c):  # c (..., m) complex, summed as Re(sum_i c_i e^{lam_i tau}) -> (..., m) real
        return jnp.where(lower, -2.0 * jnp.imag(c), jnp.where(upper, 2.0, 1.0) * jnp.real(c))

    return G, coefficients


def expm1_from_exp(x, e):
    """$e^x - 1$ from $e = e^x$ (computed anyway): `e - 1` where $|x| \\ge 1/2$ (for $x > -\\ln 2$ the subtraction is
    exact, Sterbenz), the degree-16 Taylor polynomial where $|x| < 1/2$ (truncation below $2^{-60}|x|$). Measured over
    $x \\in [-40, 0]$: at most 2.9e-16 relative error, `jnp.expm1` 6.2e-16 (both measured in the tests). Costs a few
    products instead of a second exponential: XLA's CPU `expm1` is slower than `exp` and, with an exponential
    already in the loop, nearly doubles the loop's time."""
    small = jnp.abs(x) < 0.5
    xs = jnp.where(small, x, 0.0)  # the polynomial never sees a large x (no overflow, finite derivatives)
    p = jnp.full_like(x, 1.0 / math.factorial(16))
    for k in range(15, 0, -1):
        p = p * xs + 1.0 / math.factorial(k)
    return jnp.where(small, p * xs, e - 1.0)


def _input_em1(s, tau):
    """$e^{s_b\\tau_t} - 1$ of each element b and time t, (B, N), for rates `s` (B,) and times `tau` (N,)."""
    x = s[:, None] * tau[None, :]
    return expm1_from_exp(x, jnp.exp(x))


#: exponentials e^{s_b tau_t} one pass of the batched closed form keeps on a CPU (2^23: 64 MiB): a batch with more
#: is written by chunks (on a GPU they are never stored: one pass)
_PASS_ELEMENTS = 1 << 23


def exp_input_batch(
    A,
    F,
    s,
    x0,
    t0,
    ts,
    f_var,
    s_var,
    *,
    uniform: bool | None = None,
    n_fix: int = 8,
    chunk: int = 256,
    components: tuple[int, ...] | None = None,
    post=None,
    post_args=None,
):
    """States of $\\dot x = A x + \\sum_j F_{:,j}e^{s_j t} + f_b e^{s_b t}$ for a batch of $(f_b, s_b)$.

    - `A` (n, n), `F` (n, J), `s` (J,): the system and the inputs shared by the batch
      (as returned by `model.exponential_form`, minus the varying term);
    - `x0` (n,), `t0`: initial state at time `t0` [s]; `ts` (N,) output times;
    - `f_var` (n,) or (B, n): amplitude vector of the varying term; `s_var` (B,) its real
      rates [1/s] (e.g. $-1/\\gamma_b$);
    - `uniform`: whether `ts` is evenly spaced (`None`: decided from its values in the program; used by
      the expm fall-back only);
    - `n_fix`, `chunk`: up to `n_fix` near-resonant elements per `chunk` elements of the batch are
      corrected one by one in the separated form (with more, the batch takes the exact per-element form);
    - `components`: the state components to compute (static indices; default all): the others are
      never computed nor stored (an output that needs only the current costs a fifth of the state);
    - `post`, `post_args`: what is returned instead of the states: `post(xs, args, em1)` maps the states of
      some elements, xs (b, N, k), `args` (`post_args`, a pytree of arrays with a leading batch axis, sliced to
      those elements) and their input's $e^{s_b\\tau} - 1$, em1 (b, N) (`expm1_from_exp`: as accurate as
      `jnp.expm1`), to a pytree of arrays with leading axes (b, N). It runs in the pass that computes the
      states, which are then never stored unless `post` returns them (an output of the current is written
      once, and the input's exponential is not computed again). `post` must treat each element on its own.

    Returns (B, N, k), k = `len(components)` (default n), or `post`'s pytree for the whole batch. Differentiable
    with respect to `f_var`, `s_var` (and `x0`, `F`, `s`); not with respect to A (JAX does not differentiate
    eigenvectors).
    """
    A = jnp.asarray(A, dtype=float)
    s_var = jnp.asarray(s_var, dtype=float)
    f_var = jnp.asarray(f_var, dtype=float)
    post_args = jax.tree.map(jnp.asarray, post_args)
    nb = s_var.shape[0]
    n = A.shape[0]
    rows = tuple(range(n)) if components is None else tuple(int(i) for i in components)
    f_var = jnp.broadcast_to(f_var, (nb, n))
    tau = jnp.asarray(ts, dtype=float) - t0
    lam, X_all, Yt, cond = modal_decomposition(A)
    X = X_all[jnp.asarray(rows, dtype=int)] if rows != tuple(range(n)) else X_all  # (k, m): the rows asked for
    q = (f_var.astype(complex) @ Yt.T) * jnp.exp(s_var * t0)[:, None]  # (B, m), eq. 25
    delta = s_var[:, None] - lam[None, :]
    scale = jnp.maximum(jnp.maximum(jnp.abs(lam)[None, :], jnp.abs(s_var)[:, None]), 1.0 / jnp.max(tau))
    near = jnp.abs(delta) < RESONANCE_REL * scale  # (B, m)
    is_real = jnp.imag(lam) == 0
    n_near = jnp.sum(near, axis=1)
    # a cheap real correction handles one near-resonant real mode per element; anything else
    # (a nearly real complex pair, two modes near one rate) takes the exact per-element form
    simple = jnp.all((n_near <= 1) & ~jnp.any(near & ~is_real[None, :], axis=1))
    # the cheap correction takes up to n_fix near-resonant elements per `chunk` of the batch; more (a sweep
    # that dwells on a resonance) take the exact per-element form
    n_sel = min(n_fix * -(-nb // chunk), nb)
    simple = simple & (jnp.sum(jnp.any(near, axis=1)) <= n_sel)
    shared = _shared_response(lam, X, Yt, F, s, x0, t0, tau)  # (N, k)
    G, coefficients = _real_basis(lam, tau)  # (N, m)

    def separated():
        w = jnp.where(near, 0.0, q / jnp.where(near, 1.0, delta))  # (B, m)
        # v = Re(X w) and W[b, :, i] = coefficients(X[:, i] w_i), as one real matrix product (B, 2m) x (2m, k + km):
        # a product is never fused into the output's loop, where these would be recomputed at every time
        k, m = X.shape
        eye = jnp.eye(m)
        re_part = coefficients(X[:, :, None] * eye[None])  # (k, m, m): from Re w
        im_part = coefficients(1j * X[:, :, None] * eye[None])  # from Im w
        M = jnp.concatenate(
            [
                jnp.concatenate([jnp.real(X).T, re_part.transpose(2, 0, 1).reshape(m, k * m)], axis=1),
                jnp.concatenate([-jnp.imag(X).T, im_part.transpose(2, 0, 1).reshape(m, k * m)], axis=1),
            ],
            axis=0,
        )  # (2m, k + km)
        vW = jnp.concatenate([jnp.real(w), jnp.imag(w)], axis=1) @ M
        v, W = vW[:, :k], vW[:, k:].reshape(nb, k, m)

        def rows(s_c, v_c, W_c, a_c, fix=None):
            # one pass over these rows of the output: each element is its shared part, the input's own
            # exponential and m products of the real basis (unrolled; XLA fuses them into the loop that writes
            # the output, which is faster than a matrix product whose (B, k, N) result is written, read back and
            # transposed), then `post`
            rate_time = s_c[:, None] * tau[None, :]
            e = jnp.exp(rate_time)
            xs = shared[None] + e[:, :, None] * v_c[:, None, :]
            for i in range(m):
                xs = xs - G[None, :, i, None] * W_c[:, None, :, i]
            xs = xs if fix is None else xs + fix
            return xs if post is None else post(xs, a_c, expm1_from_exp(rate_time, e))

        # XLA does not fuse the exponential e^{s_b tau} (B, N) into a loop that broadcasts it over the k components:
        # a single pass keeps it whole (400 MB for 10^5 elements of 501 times, a fifth of the output). A batch whose
        # exponentials exceed `_PASS_ELEMENTS` is written in place by equal chunks (the exponentials of one chunk at
        # a time); a smaller one in one pass, which is faster (the chunks' loop writes the output twice). The last
        # chunk starts at B - size, overlapping its predecessor when `size` does not divide B: the overlap is
        # recomputed from the same inputs.
        # On a GPU, XLA fuses the exponential into the loop (recomputing it per component costs nothing there): one
        # pass, which wrote 10^6 x 501 outputs 1.24x faster than equal chunks on an H100 (447 against 360 GB/s),
        # with 1.08x the output's memory at its peak
        n_chunks = -(-nb * tau.shape[0] // _PASS_ELEMENTS) if jax.default_backend() == "cpu" else 1
        size = -(-nb // n_chunks)
        if n_chunks == 1:
            xs = rows(s_var, v, W, post_args)
        else:

            def body(c, out):
                start = jnp.minimum(c * size, nb - size)
                part = jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, start, size), (s_var, v, W, post_args))
                return jax.tree.map(
                    lambda o, r: jax.lax.dynamic_update_slice_in_dim(o, r, start, axis=0), out, rows(*part)
                )

            shape = jax.eval_shape(lambda: rows(s_var, v, W, post_args))
            xs = jax.lax.fori_loop(0, n_chunks, body, jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), shape))

        # near-resonant real mode i: conv = e^{lam tau} tau phi1((s - lam) tau), all real
        i_star = jnp.argmax(near, axis=1)
        lam_b = jnp.real(lam[i_star])
        coef = jnp.real(X[:, i_star].T * q[jnp.arange(nb), i_star][:, None])  # (B, k)
        has = jnp.any(near, axis=1)

        def correction(sel):
            d = s_var[sel] - lam_b[sel]
            tt = tau[None, :]
            c = jnp.exp(lam_b[sel][:, None] * tt) * tt * phi1(d[:, None] * tt)  # (K, N)
            return jnp.where(has[sel][:, None, None], c[:, :, None] * coef[sel][:, None, :], 0.0)

        # a handful of elements are near resonance (`simple` holds at most `n_sel`): correct only those, in
        # place (the output is never copied)
        def corrected(xs):
            _, idx = jax.lax.top_k(has.astype(float), n_sel)
            if post is None:
                return xs.at[idx].add(correction(idx))
            # through `post`, those elements are computed again, corrected
            fixed = rows(*jax.tree.map(lambda a: a[idx], (s_var, v, W, post_args)), fix=correction(idx))
            return jax.tree.map(lambda o, f: o.at[idx].set(f), xs, fixed)

        # always, in place: the correction of an element that is not near resonance is zero. A `cond` that returned
        # the pass's output unchanged when none is near made XLA copy it on a GPU (a batch's peak device memory
        # was 2.0x its output on an H100, 1.04x without the `cond`; the same on a CPU, where it was not copied)
        return corrected(xs)

    def exact():
        return shared[None] + jax.lax.map(lambda a: _exact_one(lam, X, a[0], a[1], tau), (q, s_var))

    def expm_path():
        def one(a):
            f, sv = a
            xs = expm_solve(
                A, jnp.concatenate([F, f[:, None]], axis=1), jnp.concatenate([s, sv[None]]), x0, t0, ts, uniform
            )
            return xs[:, jnp.asarray(rows, dtype=int)] if rows != tuple(range(n)) else xs

        return jax.lax.map(one, (f_var, s_var))

    forms = [separated, exact, expm_path]
    if post is not None:  # the other forms compute the states, then `post`

        def then_post(form):
            return post(form(), post_args, _input_em1(s_var, tau))

        forms[1:] = [lambda f=f: then_post(f) for f in forms[1:]]
    ok = jnp.isfinite(cond) & (cond < MODAL_COND_LIMIT)
    branch = jnp.where(ok, jnp.where(simple, 0, 1), 2)
    return jax.lax.switch(branch, forms)


def startup_gamma_batch(
    model,
    gammas,
    ts,
    v_max: ArrayLike = 24.0,
    y0=None,
    *,
    t0=None,
    n_fix: int = 8,
    chunk: int = 256,
    components: tuple[int, ...] | None = None,
    post=None,
    post_args=None,
):
    """State histories of a belt start-up model for a batch of voltage time constants.

    $V_b(t) = V_{max}(1 - e^{-t/\\gamma_b})$ (Incerti, 2014, eq. 30) drives `model` (a `BeltStartup`
    or `BeltChain`) from rest (or `y0`) at t = `ts[0]`. Equivalent to
    `jax.vmap(lambda g: simulate(Scene(model, ExponentialVoltage(v_max, g), ts=ts)).ys)(gammas)`
    with shape (B, N, n_states), but with the modal decomposition and the shared responses
    computed once for the batch (see module docstring). `components`: only these states (static
    indices), shape (B, N, len(components)). `post`, `post_args`: what is returned instead of the states, as in
    `exp_input_batch`.
    """
    from .commands import ConstantVoltage

    gammas = jnp.asarray(gammas, dtype=float)
    ts = jnp.asarray(ts, dtype=float)
    A, F, s = model.exponential_form(ConstantVoltage(v_max))  # load torque + constant V_max
    f_var = -jnp.asarray(v_max, dtype=float) * model.linear_system()[1]
    x0 = jnp.zeros((A.shape[0],)) if y0 is None else jnp.asarray(y0, dtype=float)
    uniform = None  # decided from the values in the program (the expm fall-back only)
    t0 = ts[0] if t0 is None else jnp.asarray(t0, dtype=float)
    return exp_input_batch(
        A,
        F,
        s,
        x0,
        t0,
        ts,
        f_var,
        -1.0 / gammas,
        uniform=uniform,
        n_fix=n_fix,
        chunk=chunk,
        components=components,
        post=post,
        post_args=post_args,
    )


def _depends_on(jaxpr, n: int):
    """The components of the first input (a vector of n) that the outputs of `jaxpr` read, or None where that
    cannot be told (then all of them). Follows `y[i]` (a slice, then a squeeze or reshape) element by element;
    any other operation depends on everything its operands depend on (an over-estimate, never an under-one)."""
    from jax.extend.core import Literal

    y = jaxpr.invars[0]
    elems: dict = {y: [frozenset((i,)) for i in range(n)]}  # vectors whose elements are tracked one by one
    whole: dict = {}  # any other variable -> the components it depends on

    def deps(v):
        if isinstance(v, Literal):
            return frozenset()
        if v in elems:
            return frozenset().union(*elems[v])
        return whole.get(v, frozenset())

    for eqn in jaxpr.eqns:
        prim = eqn.primitive.name
        src = eqn.invars[0] if eqn.invars else None
        if prim == "slice" and src in elems and len(eqn.params["start_indices"]) == 1:
            start, stop = eqn.params["start_indices"][0], eqn.params["limit_indices"][0]
            step = (eqn.params.get("strides") or (1,))[0]
            elems[eqn.outvars[0]] = elems[src][start:stop:step]
        elif prim in ("squeeze", "reshape") and src in elems and len(elems[src]) == 1:
            whole[eqn.outvars[0]] = elems[src][0]
        else:
            d = frozenset().union(*(deps(v) for v in eqn.invars))
            for out in eqn.outvars:
                whole[out] = d
    return frozenset().union(*(deps(v) for v in jaxpr.outvars))


def output_components(model, names, inp, t) -> tuple[int, ...]:
    """The state components that the outputs `names` of `model` read (at time `t`, input `inp`), in order; all of
    them where that cannot be told; none for outputs that read no state (the voltage of a command). Decided from the
    traced program of the outputs, nothing is computed."""
    n = model.n_states
    if not names:
        return tuple(range(n))
    try:
        import equinox as eqx

        def outputs(y, model, inp, t):
            return [model.output(name, t, y, inp) for name in names]

        closed = eqx.filter_make_jaxpr(outputs)(jax.ShapeDtypeStruct((n,), jnp.float64), model, inp, t)[0]
        needed = _depends_on(closed.jaxpr, n)
    except Exception:  # noqa: BLE001 - an output the analysis cannot trace alone: every component
        return tuple(range(n))
    return tuple(sorted(needed))


def _all_finite(x):
    """Whether each element of the batch `x` (leading axis) is finite everywhere, in one read of `x`: a sum of
    `x * 0` is 0 where every value is finite and NaN otherwise, and XLA fuses the product into the sum (`isfinite`
    then `all` writes a boolean array of the size of `x` and reads it back)."""
    return jnp.isfinite(jnp.sum(x * 0.0, axis=tuple(range(1, x.ndim))))


class _InputAt(eqx.Module):
    """The command of one batch element at one time, its value there known (computed in the batch's pass):
    an output reads `value` instead of evaluating the command again. An output that needs anything else of its
    command takes the command itself (`batched_exponential_scene`)."""

    value: jax.Array
    command: Any  # the batch element's `ExponentialVoltage`

    def __call__(self, t):
        return self.value


def batched_exponential_scene(scene):
    """Solve a start-up scene whose command carries a *batch* of time constants, or return None.

    `Scene(model, ExponentialVoltage(v_max, gammas), ts=ts)` with `gammas` of shape (B,) (a scalar
    `v_max`, scalar model parameters) is B start-up runs sharing A: they are solved together by
    `startup_gamma_batch`. The result is a `Solution` with `ys` (B, N, n) and each observed output
    (B, N); `success` (B,) is False where a trajectory is not finite (its state; without the state, its
    outputs). Without the state (`state=False`), only the components the outputs read are computed, and the
    outputs in the same pass: those components are never stored, and an output that reads the voltage takes
    it from the pass's own exponential (no second one). Anything else returns None (the caller solves the
    scene as usual).
    """
    from ._model import AbstractLinearModel
    from .commands import ExponentialVoltage
    from .solution import BatchAxis, Solution

    model, inp = scene.model, scene.input
    if scene.ts is None or not isinstance(inp, ExponentialVoltage) or not isinstance(model, AbstractLinearModel):
        return None
    if jnp.ndim(inp.gamma) != 1 or jnp.ndim(inp.v_max) != 0:
        return None
    if any(jnp.ndim(leaf) != 0 for leaf in jax.tree_util.tree_leaves(model)):
        return None
    if any(n in model.integral_names() for n in scene.observe):
        return None
    n = model.n_states
    # without the state, only the components the observed outputs read are computed (and never stored)
    comps = tuple(range(n))
    if not scene.state and scene.observe:
        one_cmd = ExponentialVoltage(inp.v_max, inp.gamma[0])
        comps = output_components(model, scene.observe, one_cmd, scene.ts[0])
    part = None if comps == tuple(range(n)) else comps
    where = {c: k for k, c in enumerate(comps)}
    t0 = jnp.asarray(scene.start_time, dtype=float)  # `t0`, or `ts[0]` when not given

    def state(yk):  # the full state vector of one time, zeros where a component was not computed
        zero = jnp.zeros((), yk.dtype)
        return jnp.stack([yk[where[i]] if i in where else zero for i in range(n)])

    def output(name, g, u, t, y):  # one output of one element at one time, its voltage u known when not None
        cmd = ExponentialVoltage(inp.v_max, g)
        return model.output(name, t, state(y), cmd if u is None else _InputAt(u, cmd))

    # the outputs read the voltage the pass has at hand (from the input's e^{-(t - t0)/gamma} - 1) where they
    # trace with it: V(t) = -V_max expm1(-t/gamma) = -V_max (expm1(a) + e^a em1), a = -t0/gamma, no cancellation
    def reads_known(name):
        one = jnp.zeros((), float)
        try:
            jax.eval_shape(lambda: output(name, inp.gamma[0], one, scene.ts[0], jnp.zeros((len(comps),))))
        except Exception:  # noqa: BLE001 - an output that needs more of its command than its value: the command
            return False
        return True

    known = {name: reads_known(name) for name in scene.observe}

    def post(ys, gammas, em1):  # states ys (b, N, k) of the elements `gammas` -> their outputs {name: (b, N)}
        a = -t0 / gammas
        u = -inp.v_max * (jnp.expm1(a)[:, None] + jnp.exp(a)[:, None] * em1)  # (b, N)
        got = {}
        for name in scene.observe:

            def each(g, ub, yb, name=name):
                return jax.vmap(lambda uu, t, y: output(name, g, uu if known[name] else None, t, y))(ub, scene.ts, yb)

            got[name] = jax.vmap(each)(gammas, u, ys)
        return got

    def batch(**kw):
        return startup_gamma_batch(
            model, inp.gamma, scene.ts, v_max=inp.v_max, y0=scene.y0, t0=scene.start_time, components=part, **kw
        )

    if scene.state or not scene.observe:
        # the outputs (if any) from the stored states: one pass that returns both would compute the input's
        # exponential in each of XLA's two loops, and run slower
        ys = batch()
        outputs = post(ys, inp.gamma, _input_em1(-1.0 / inp.gamma, scene.ts - t0)) if scene.observe else {}
    elif comps:  # without the state, the outputs in the pass that computes the components they read
        ys, outputs = None, batch(post=post, post_args=inp.gamma)
    else:  # the outputs read no state at all
        nothing = jnp.zeros((inp.gamma.shape[0], scene.ts.shape[0], 0))
        ys, outputs = None, post(nothing, inp.gamma, _input_em1(-1.0 / inp.gamma, scene.ts - t0))
    if scene.state or not outputs:
        success = _all_finite(ys)
    else:  # what is returned: the outputs (a pass over the components they read would be one more read of them)
        success = jnp.ones(inp.gamma.shape, dtype=bool)
        for v in outputs.values():
            success = success & _all_finite(v)
    # the span within the closed form's accuracy (`jaxbelt.modal.closed_form_error`), as `simulate` requires
    success = success & (closed_form_error(model.linear_system()[0], t0, scene.ts) <= CLOSED_FORM_TOL)
    return Solution(
        ts=scene.ts,
        ys=ys if scene.state else None,
        outputs=outputs,
        success=success,
        stats={},
        state_names=tuple(model.state_names),
        method="fast",
        model=type(model).__name__,
        batch=BatchAxis(inp.gamma, name="gamma", unit="s"),
    )
