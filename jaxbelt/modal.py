"""Closed-form solutions of linear time-invariant scenes.

The scenes solved here have the form $\\dot x = A x + \\sum_j F_{:,j} e^{s_j t}$, i.e. an LTI
model driven by a sum of exponentials (constants are $s_j = 0$). Two independent closed forms:

- **modal** (Incerti, 2014, eq. 14-29): right eigenvectors X, left eigenvectors $Y^T = X^{-1}$
  (eq. 20, 42: normalised so that $Y^T X = I$), modal coordinates
  $\\eta_i(t) = \\eta_i(0)e^{\\lambda_i t} + \\int_0^t q_i(\\tau) e^{\\lambda_i(t-\\tau)}d\\tau$ (eq. 27)
  with the convolution integral taken analytically, including its $\\lambda\\to 0$ limit
  (the rigid-body mode of the belt drive has $\\lambda = 0$ exactly);
- **expm**: the exponential generators are appended to the state, $w_j' = s_j w_j$, and the
  augmented homogeneous system is advanced by its matrix exponential. On a uniform time grid one
  exponential $\\Phi = e^{A_a\\Delta t}$ is computed and applied step by step (decided from the values
  of the grid inside the program: grids of any spacing share one program).

The modal form needs a diagonalisable A. When the eigenvector matrix is ill-conditioned
(repeated eigenvalues, e.g. a critically damped belt) `modal_solve` falls back to the expm form.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.scipy.linalg import expm as _jexpm

from ._checks import require_x64

# Above this condition number of the eigenvector matrix the modal solution may lose more than
# about 1e-9 relative accuracy; the expm path is used instead.
MODAL_COND_LIMIT = 1e6


def balance_scaling(M, sweeps: int = 8):
    r"""Powers of two d such that $D^{-1} M D$ has balanced row and column norms.

    Balancing (Parlett-Reinsch) lowers the norm that drives the number of squarings in the
    matrix exponential; for the start-up model with a tiny inductance it cuts the error of
    $e^{A\Delta t}$ tenfold. Powers of two make the similarity exact in floating point.
    """
    M0 = jnp.abs(jax.lax.stop_gradient(M))
    M0 = M0 - jnp.diag(jnp.diag(M0))

    def sweep(_, d):
        Mb = M0 * d[None, :] / d[:, None]
        c = jnp.sum(Mb, axis=0)
        r = jnp.sum(Mb, axis=1)
        ok = (c > 0) & (r > 0)
        f = jnp.where(ok, jnp.exp2(jnp.round(0.5 * jnp.log2(jnp.where(ok, r / jnp.where(ok, c, 1.0), 1.0)))), 1.0)
        return d * f

    return jax.lax.fori_loop(0, sweeps, sweep, jnp.ones(M.shape[0], M.dtype))


def expm(M):
    """Matrix exponential of a balanced copy of M, with room for the squarings stiff scenes need.

    `jax.scipy.linalg.expm` returns NaN beyond `max_squarings` (default 16, a norm of about
    3.5e5); 64 squarings cover any finite float64 norm. $e^M = D e^{D^{-1}MD} D^{-1}$.
    """
    d = balance_scaling(M)
    E = _jexpm(M * d[None, :] / d[:, None], max_squarings=64)
    return E * d[:, None] / d[None, :]


def phi1(z):
    """$\\varphi_1(z) = (e^z - 1)/z$ with its limit 1 at z = 0; real or complex, grad-safe."""
    z = jnp.asarray(z)
    small = jnp.abs(z) < 1e-2
    zs = jnp.where(small, jnp.ones_like(z), z)
    far = jnp.expm1(zs) / zs
    zt = jnp.where(small, z, jnp.zeros_like(z))
    # Taylor series to z^6: truncation error < 1e-17 for |z| < 1e-2
    near = 1 + zt * (1 / 2 + zt * (1 / 6 + zt * (1 / 24 + zt * (1 / 120 + zt * (1 / 720 + zt / 5040)))))
    return jnp.where(small, near, far)


def exp_convolution(lam, s, tau):
    """$\\int_0^\\tau e^{\\lambda(\\tau-\\sigma)} e^{s\\sigma} d\\sigma = (e^{s\\tau}-e^{\\lambda\\tau})/(s-\\lambda)$.

    Evaluated without cancellation or overflow: the exponent with the larger real part is
    factored out, so the remaining $\\varphi_1$ has an argument with non-positive real part. The
    limits $\\lambda \\to s$ (resonance) and $\\lambda \\to 0$, $s = 0$ (rigid-body mode under a
    constant input, giving $\\tau$) are exact.
    """
    lam = jnp.asarray(lam, dtype=complex)
    s = jnp.asarray(s, dtype=complex)
    lam_hi = jnp.real(lam) >= jnp.real(s)
    hi = jnp.where(lam_hi, lam, s)
    lo = jnp.where(lam_hi, s, lam)
    return jnp.exp(hi * tau) * tau * phi1((lo - hi) * tau)


def augmented_matrix(A, F, s):
    """$A_a = [[A, F], [0, diag(s)]]$ of the exponential-generator augmentation."""
    n, m = F.shape
    top = jnp.concatenate([A, F], axis=1)
    bot = jnp.concatenate([jnp.zeros((m, n), A.dtype), jnp.diag(s)], axis=1)
    return jnp.concatenate([top, bot], axis=0)


#: largest `closed_form_error` a closed-form solve accepts (its relative accuracy over the time span)
CLOSED_FORM_TOL = 1e-6


def closed_form_error(A, t0, times):
    """$\\varepsilon\\,\\|A\\|_1\\,\\max|t - t_0|$: the relative error the closed form's matrix exponential (or
    eigendecomposition) may reach over the span, from the rounding of the system matrix's eigenvalues (a rigid-body
    eigenvalue 0 computed as ~1e-12 grows as $e^{10^{-12} t}$: the start-up's current at $t = 10^{12}$ s was 17.7 A
    instead of 14.93 A, no flag). Above `CLOSED_FORM_TOL` the solve fails (`success` False, `SolveError`)."""
    span = jnp.max(jnp.abs(jnp.asarray(times) - t0))
    return jnp.finfo(jnp.result_type(A)).eps * jnp.max(jnp.sum(jnp.abs(A), axis=0)) * span


#: a grid is evenly spaced when every step is within this fraction of the first (as `Scene` decides)
UNIFORM_RTOL = 1e-12


def is_uniform(ts):
    """Whether the times `ts` (N,) are evenly spaced to `UNIFORM_RTOL` (a traced boolean)."""
    d = jnp.diff(ts)
    return jnp.max(jnp.abs(d - d[0])) <= UNIFORM_RTOL * jnp.abs(d[0])


def expm_solve(A, F, s, x0, t0, ts, uniform: bool | None = False):
    """States at times `ts` (shape (N, n)) by the matrix exponential of the augmented system.

    The state is stepped from one output time to the next by matrix-vector products (a scan). On an evenly
    spaced grid one exponential $\\Phi = e^{A_a\\Delta t}$ serves every step; otherwise each step that
    differs from the last one computed (by more than `UNIFORM_RTOL`) gets its own exponential.
    `uniform`: `True`, a static promise that `ts` is evenly spaced (the step is taken as
    `(ts[-1] - ts[0]) / (N - 1)`); `False`, the general path; `None`, decided from the values of `ts`
    inside the program (one program for grids of any spacing).
    """
    require_x64("jaxbelt.modal.expm_solve")
    n = A.shape[0]
    Aa = augmented_matrix(A, F, s)
    z0 = jnp.concatenate([x0, jnp.exp(s * t0)])
    ts = jnp.asarray(ts)

    def general():
        # stepped from the start to each output time in turn; a step equal (to UNIFORM_RTOL) to the one the
        # transition matrix was computed for reuses it, so an evenly spaced grid costs two exponentials, not one
        # per output time, whether or not its spacing was known when the program was traced
        steps = ts - jnp.concatenate([jnp.reshape(jnp.asarray(t0, ts.dtype), (1,)), ts[:-1]])

        def step(carry, dt):
            z, Phi, dt_phi = carry
            same = jnp.abs(dt - dt_phi) <= UNIFORM_RTOL * jnp.abs(dt_phi)
            Phi, dt_phi = jax.lax.cond(same, lambda: (Phi, dt_phi), lambda: (expm(Aa * dt), dt))
            z_next = Phi @ z
            return (z_next, Phi, dt_phi), z_next

        start = (z0, jnp.eye(Aa.shape[0], dtype=Aa.dtype), jnp.full((), jnp.nan, ts.dtype))
        return jax.lax.scan(step, start, steps)[1]

    def stepped():
        dt = (ts[-1] - ts[0]) / (ts.shape[0] - 1)
        Phi = expm(Aa * dt)
        z_first = expm(Aa * (ts[0] - t0)) @ z0

        def step(z, _):
            z_next = Phi @ z
            return z_next, z_next

        _, zs = jax.lax.scan(step, z_first, None, length=ts.shape[0] - 1)
        return jnp.concatenate([z_first[None], zs], axis=0)

    if ts.shape[0] < 2 or uniform is False:
        zs = general()
    elif uniform:
        zs = stepped()
    else:
        zs = jax.lax.cond(is_uniform(ts), stepped, general)
    return zs[:, :n]


#: what a derivative of the modal solution says (JAX gives none of a non-symmetric matrix's eigenvectors)
MODAL_GRAD_MESSAGE = (
    "simulate(method='modal'): the modal solution is not differentiable: JAX gives no derivative of the "
    "eigenvectors of a non-symmetric matrix (Incerti's state matrix is one). Under jax.grad/jax.jvp use "
    "method='expm' (or 'closed', or the default 'auto'): the same closed form by the matrix exponential, "
    "differentiable, equal to the modal solution to rounding"
)


@jax.custom_jvp
def _eig(A):
    """`jnp.linalg.eig(A)`, whose derivative is refused with `MODAL_GRAD_MESSAGE` (JAX's own error names neither
    the method nor what to use instead)."""
    return jnp.linalg.eig(A)


@_eig.defjvp
def _eig_jvp(primals, tangents):
    raise NotImplementedError(MODAL_GRAD_MESSAGE)


def modal_decomposition(A):
    """Eigenvalues Λ, right eigenvectors X and left eigenvectors $Y^T = X^{-1}$ of A.

    Rows of $X^{-1}$ are left eigenvectors ($y_i^T A = \\lambda_i y_i^T$) normalised as in
    Incerti (2014) eq. (40): $y_i^T x_i = 1$. Also returns the condition number of X.
    """
    require_x64("jaxbelt.modal.modal_decomposition")
    lam, X = _eig(A)
    Yt = jnp.linalg.inv(X)
    return lam, X, Yt, jnp.linalg.cond(X)


def modal_solve_raw(A, F, s, x0, t0, ts):
    """The modal solution (eq. 22-29) without a conditioning check; returns (xs, cond(X))."""
    require_x64("jaxbelt.modal.modal_solve_raw")
    lam, X, Yt, cond = modal_decomposition(A)
    eta0 = Yt @ x0.astype(complex)
    q = Yt @ F.astype(complex)  # (n, m): modal participation of each input term (eq. 25)
    qw = q * jnp.exp(s * t0)[None, :]
    tau = jnp.asarray(ts) - t0

    def at(tt):
        conv = exp_convolution(lam[:, None], s[None, :], tt)  # (n, m)
        eta = eta0 * jnp.exp(lam * tt) + jnp.sum(qw * conv, axis=1)
        return jnp.real(X @ eta)

    return jax.vmap(at)(tau), cond


def modal_solve(A, F, s, x0, t0, ts, uniform: bool | None = False):
    """Modal closed form, falling back to `expm_solve` when X is ill-conditioned."""
    require_x64("jaxbelt.modal.modal_solve")
    xs, cond = modal_solve_raw(A, F, s, x0, t0, ts)
    # The test depends on A only: under a vmap over the input (e.g. gamma) it stays unbatched, so
    # lax.cond runs one branch instead of turning into a select that computes both. Non-finite
    # results are caught by `simulate`'s success check.
    ok = jnp.isfinite(cond) & (cond < MODAL_COND_LIMIT)
    return jax.lax.cond(ok, lambda: xs, lambda: expm_solve(A, F, s, x0, t0, ts, uniform))
