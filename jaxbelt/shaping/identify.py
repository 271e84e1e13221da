"""The modes of the user's axis from a measurement: `identify_axis` and `load_record` for a time record,
`identify_axis_from_psd` and `load_spectrum` for a power spectral density (a firmware's resonance test; the fit
is described in `identify_axis_from_psd`).

A free decay (tap the payload, let it ring) or the end of a step response (a short move, then the payload
rings about its final position), recorded with an accelerometer or an encoder at a uniform rate, is a sum
of damped oscillations

$y(t) = c_0 + \\sum_{i=1}^{n} e^{-\\sigma_i \\tau}\\,\\big(a_i\\cos\\omega_{d,i}\\tau + b_i\\sin\\omega_{d,i}\\tau\\big)$,
$\\tau = t - t_0$,

with $\\omega_i = 2\\pi f_i$, $\\sigma_i = \\zeta_i\\omega_i$, $\\omega_{d,i} = \\omega_i\\sqrt{1-\\zeta_i^2}$ and $t_0$ the
first sample (the constant $c_0$ only with `offset=True`). `identify_axis` fits it in two steps:

1. **Matrix pencil** (Hua and Sarkar, 1990, IEEE Trans. Acoust. Speech Signal Process. 38(5), 814-824):
   the Hankel matrix $Y_{kj} = y_{k+j}$ of the samples (mean-removed with `offset=True`), $j = 0..L$ with
   the pencil parameter $L = N/3$ (at most 500), has rank $2n$ (+1 for the offset) without noise. Its $M$
   dominant right singular vectors $V$ (by subspace iteration) span the sampled exponentials $z^j$, so the
   eigenvalues of $V_1^{+}V_2$ ($V$ without its last, resp. first, row) are the poles $z_k = e^{s_k\\Delta t}$.
   Amplitudes by linear least squares on the poles; the $n$ stable complex-conjugate pairs with the largest
   RMS over the record are kept (real poles, i.e. the offset or drifts, and unstable ones are dropped; a
   pole's angle in $(0, \\pi)$ keeps its frequency below Nyquist). This is the start point.
2. **Nonlinear least squares** on all $4n$ (+1) parameters with Levenberg-Marquardt
   (`optimistix.least_squares`), in coordinates that keep every mode physical: $\\ln f_i$ (so $f_i > 0$),
   $\\operatorname{logit}\\zeta_i$ (so $0 < \\zeta_i < 1$), the amplitudes and the offset in units of the
   record's spread. One compiled program per record length, `n_modes` and `offset`: a second record of
   the same length runs without compiling.

**Standard errors** from the Jacobian $J$ of the residuals at the optimum: $C = s^2 (J^TJ)^{-1}$ with
$s^2 = \\mathrm{SSR}/(N - p)$, mapped to $f_i$ and $\\zeta_i$ by the delta method
($\\mathrm{d}f = f\\,\\mathrm{d}\\ln f$, $\\mathrm{d}\\zeta = \\zeta(1-\\zeta)\\,\\mathrm{d}\\operatorname{logit}\\zeta$), as in
`jaxbelt.identify`. They are linearised (Cramér-Rao-type) errors for white noise.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .._checks import check_int, device_array
from .._threads import blas_limited
from ..models.axis import FREQUENCY_RANGE_HZ
from .readers import is_spectrum_file as is_spectrum_file
from .readers import load_record as load_record
from .readers import load_spectrum as load_spectrum

__all__ = ["identify_axis", "load_record", "load_spectrum"]

_OWNER = "identify_axis"
#: largest deviation of a time stamp from the uniform grid, in units of the step (see `identify_axis`)
UNIFORM_RTOL = 1e-3
#: samples needed per fitted parameter
SAMPLES_PER_PARAMETER = 10
#: the peak-to-peak of a record (its units) the fit accepts: the pencil and the least squares form products of
#: powers of the samples; a decay of 20 Hz is identified to 1e-15 from 1e-60 to 1e60 and fails beyond 1e80 (numpy's
#: LinAlgError, "infs or NaNs" or "Singular matrix"); 1e-50 to 1e50 keeps a margin (metres to nanometres, or
#: counts, lie far inside)
Y_RANGE = (1e-50, 1e50)
#: periods of the lowest mode the record must hold
MIN_PERIODS = 2.0
#: a mode's amplitude must exceed this many of its standard errors (a fit to noise does not)
MIN_SIGNIFICANCE = 8.0
#: largest pencil parameter L and number of Hankel rows (the cost of the singular vectors is rows x L^2)
_PENCIL_MAX_L = 500
_PENCIL_MAX_ROWS = 2500
#: extra model orders the pencil tries when the first one holds fewer than n stable pairs
_PENCIL_EXTRA_ORDERS = 4
#: subspace iteration of the pencil's singular vectors: extra vectors in the block, and iterations
_PENCIL_OVERSAMPLE = 6
_PENCIL_ITERATIONS = 12
_RESULT_NAMES = (
    "successful",
    "max_steps_reached",
    "nonlinear_max_steps_reached",
    "nonlinear_divergence",
    "nonfinite",
    "singular",
)


# --------------------------------------------------------------------------------------------
# checks of the record
# --------------------------------------------------------------------------------------------
def _require_x64(owner: str = _OWNER) -> None:
    """`RuntimeError` unless JAX's 64-bit mode is on: the fit needs float64 (the noise-free records of the
    tests are fitted to 1e-13). `jaxbelt._checks.require_x64` says so where the package has it."""
    from .. import _checks

    require = getattr(_checks, "require_x64", None)
    if require is not None:
        require(owner)
    elif jax.dtypes.canonicalize_dtype(float) != np.dtype(np.float64):
        raise RuntimeError(
            f"{owner}: the fit computes in float64, and JAX's 64-bit mode is off: add "
            '`jax.config.update("jax_enable_x64", True)` right after `import jax`'
        )


def _first_bad(name: str, x: np.ndarray, owner: str = _OWNER) -> None:
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        k = int(bad[0])
        raise ValueError(
            f"{owner}: parameter `{name}` must be finite (no NaN or inf); got {x[k]} at index {k} "
            f"({bad.size} non-finite value{'s' if bad.size > 1 else ''} in all)"
        )


def _time_rounding(t: np.ndarray) -> float:
    """Half a unit of the last decimal the times `t` were written with (`%.6f`: 5e-7 s), found from the values
    (the fewest decimals, 0-9, that every time is a whole number of); 0 where they hold more (not rounded)."""
    scale = float(np.max(np.abs(t))) if t.size else 0.0
    for d in range(10):
        unit = 10.0**-d
        x = t / unit
        if np.all(np.abs(x - np.round(x)) <= 1e-6 + 8 * np.finfo(float).eps * scale / unit):
            return 0.5 * unit
    return 0.0


def _decimals(rounding: float) -> int:
    return round(-math.log10(2 * rounding))


def _check_record(t, y, n_modes, offset):
    """Validated host arrays `(t, y)`, the step `dt` [s] and the number of parameters `p`."""
    n = check_int(_OWNER, "n_modes", n_modes, lo=1)
    if not isinstance(offset, (bool, np.bool_)):
        raise ValueError(f"{_OWNER}: parameter `offset` must be True or False; got {offset!r}")
    for name, x in (("t", t), ("y", y)):
        if np.iscomplexobj(x):
            raise TypeError(f"{_OWNER}: parameter `{name}` must be real; got complex values (take .real or abs first)")
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(
            f"{_OWNER}: parameter `t` must be a 1-D array of times [s]; got {type(t).__name__} ({e})"
        ) from None
    try:
        y = np.asarray(y, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(
            f"{_OWNER}: parameter `y` must be a 1-D array of samples; got {type(y).__name__} ({e})"
        ) from None
    if t.ndim != 1:
        raise ValueError(f"{_OWNER}: parameter `t` must be a 1-D array of times [s]; got shape {t.shape}")
    if y.shape != t.shape:
        raise ValueError(f"{_OWNER}: parameter `y` must have the shape of `t`, {t.shape}; got shape {y.shape}")
    p = 4 * n + int(bool(offset))
    n_min = SAMPLES_PER_PARAMETER * p
    if t.size < n_min:
        raise ValueError(
            f"{_OWNER}: the record (parameters `t`, `y`) is too short: {n} mode(s){' and an offset' if offset else ''} "
            f"are {p} parameters, which need at least {n_min} samples ({SAMPLES_PER_PARAMETER} per parameter); "
            f"got {t.size}"
        )
    _first_bad("t", t)
    _first_bad("y", y)
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(
            f"{_OWNER}: parameter `t` must be strictly increasing; got t[{k}] = {t[k]!r} >= t[{k + 1}] = {t[k + 1]!r}"
        )
    # the grid t0 + k dt by least squares: time stamps rounded by their writer scatter about it by up to half a
    # unit of their last decimal, on both ends as in the middle
    k = np.arange(t.size, dtype=float)
    kc = k - k.mean()
    dt = float(kc @ (t - t.mean()) / (kc @ kc))
    grid = t.mean() + dt * kc
    rounding = _time_rounding(t)
    allowed = UNIFORM_RTOL * dt + rounding
    dev = np.abs(t - grid)
    i = int(np.argmax(dev))
    if dev[i] > allowed:
        written = f" plus the rounding of its {_decimals(rounding)} decimals ({rounding:.3g} s)" if rounding else ""
        raise ValueError(
            f"{_OWNER}: parameter `t` must be uniformly sampled: every time within {UNIFORM_RTOL:g} of a step{written} "
            f"of the grid t0 + k*dt (dt = {dt:.6g} s, fitted); the largest deviation is {dev[i] / dt:.3g} steps at "
            f"index {i} (t = {t[i]!r} s). A gap (lost samples) or a changing rate: keep one uninterrupted part, or "
            "resample the record to a uniform rate first"
        )
    if np.ptp(y) == 0.0:
        raise ValueError(f"{_OWNER}: parameter `y` is constant ({y[0]!r}): the record holds no vibration to identify")
    lo_hz, hi_hz = FREQUENCY_RANGE_HZ
    span = float(t[-1] - t[0])
    if 0.5 / dt < lo_hz or 1.0 / span > hi_hz:
        # the cause named here, not the ModalAxis' refusal of the frequency fitted from it (after seconds of work)
        raise ValueError(
            f"{_OWNER}: parameter `t` (times, s) resolves no frequency of an axis' range [{lo_hz:g}, {hi_hz:g}] Hz: "
            f"its step dt = {dt:.3g} s and span {span:.3g} s resolve {1.0 / span:.3g} to {0.5 / dt:.3g} Hz "
            "(from one cycle over the record to the Nyquist frequency); are the times in seconds?"
        )
    size = float(np.ptp(y))
    if not Y_RANGE[0] <= size <= Y_RANGE[1]:
        raise ValueError(
            f"{_OWNER}: parameter `y` must have a peak-to-peak within [{Y_RANGE[0]:g}, {Y_RANGE[1]:g}] (its units); "
            f"got {size:.3g}: the fit's products of samples would over- or underflow float64"
        )
    return t, y, float(dt), n, p


# --------------------------------------------------------------------------------------------
# step 1: the matrix pencil (Hua and Sarkar, 1990)
# --------------------------------------------------------------------------------------------
def _orthonormal(A):
    """Orthonormal columns spanning those of `A` (classical Gram-Schmidt, twice: as accurate as Householder
    QR for the few columns here, and plain matrix products in XLA)."""

    def column(j, Q):
        v = A[:, j]
        v = v - Q @ (Q.T @ v)  # the columns of Q after j are still zero
        v = v - Q @ (Q.T @ v)
        return Q.at[:, j].set(v / jnp.maximum(jnp.linalg.norm(v), 1e-300))

    return jax.lax.fori_loop(0, A.shape[1], column, jnp.zeros_like(A))


@functools.partial(jax.jit, static_argnames=("iters",))
def _dominant_right_vectors(Y, Q0, *, iters):
    """The dominant right singular vectors of `Y`, as columns, dominant first (as many as `Q0` has columns):
    block subspace iteration on the Gram matrix $G = Y^TY$ from the start `Q0` ($Q \\leftarrow
    \\mathrm{orth}(GQ)$, `iters` times), then a Rayleigh-Ritz step (the eigenvectors of $Q^TGQ$).

    The signal's singular values stand far above the noise's (the ratio of their squares, about
    $L A^2/4\\sigma^2$ for a mode of amplitude $A$ in noise $\\sigma$, is 10^3-10^4 at 5 % noise), so a few
    products with $G$ find them to rounding; the noise's vectors, kept only to fill the model order, need
    no accuracy. Matrix products only, plus an eigensolver of the block's size: a full SVD or eigensolver
    of size L (LAPACK over a multi-threaded BLAS) takes seconds instead of milliseconds on a busy machine.
    One compilation per record length and `n_modes` (the shapes)."""
    G = Y.T @ Y
    Q = jax.lax.fori_loop(0, iters, lambda _, Q: _orthonormal(G @ Q), _orthonormal(Q0))
    H = Q.T @ G @ Q
    _, W = jnp.linalg.eigh(0.5 * (H + H.T))
    return (Q @ W)[:, ::-1]


def _pencil_poles(V: np.ndarray, order: int) -> np.ndarray:
    """The `order` poles $z_k$ of the total-least-squares matrix pencil from the right singular vectors `V`
    (dominant first) of the Hankel matrix: the eigenvalues of $V_1^{+}V_2$ ($V_1$, nearly orthonormal,
    by its normal equations)."""
    V = V[:, :order]  # (L + 1, order): the signal subspace in the shift direction
    V1, V2 = V[:-1], V[1:]
    return np.linalg.eigvals(np.linalg.solve(V1.T @ V1, V1.T @ V2))


def _hankel_vectors(x: np.ndarray, k: int) -> np.ndarray:
    """The `k` dominant right singular vectors of the Hankel matrix $Y_{kj} = x_{k+j}$, $j = 0..L$,
    $L = \\min(N/3, 500)$ (in Hua and Sarkar's range N/3..N/2 for noisy data, capped for the cost). Any set
    of rows spans the same row space of exponentials: beyond 2500 rows every m-th is used."""
    N = x.size
    L = int(min(N // 3, _PENCIL_MAX_L))
    rows = np.arange(N - L)
    if rows.size > _PENCIL_MAX_ROWS:
        rows = rows[:: int(math.ceil(rows.size / _PENCIL_MAX_ROWS))]
    Y = x[rows[:, None] + np.arange(L + 1)[None, :]]
    Q0 = np.random.default_rng(0).standard_normal((L + 1, min(k, L + 1)))  # a fixed start: reproducible
    return np.asarray(_dominant_right_vectors(Y, Q0, iters=_PENCIL_ITERATIONS))


def _pencil(y: np.ndarray, dt: float, n: int, offset: bool):
    """Start point of the fit from the matrix pencil: `(f [Hz], zeta, a, b, c0)` with the modes sorted by
    frequency, amplitudes in the units of `y` at the first sample (`c0` = 0 with `offset=False`).
    Raises `ValueError` when the record holds fewer than `n` stable oscillating poles."""
    N = y.size
    mean = float(np.mean(y)) if offset else 0.0
    x = y - mean
    k = np.arange(N)
    base = 2 * n + int(offset)
    found = 0
    V = _hankel_vectors(x, base + 2 * _PENCIL_EXTRA_ORDERS + _PENCIL_OVERSAMPLE)
    max_order = min(V.shape[1], V.shape[0] - 2)
    for extra in range(_PENCIL_EXTRA_ORDERS + 1):
        order = min(base + 2 * extra, max_order)
        z = _pencil_poles(V, order)
        z = z[np.log(np.abs(z)) * N < 20.0]  # for the least squares only: a growing pole's z^k would overflow
        logz = np.log(z.astype(complex))
        basis = np.exp(k[:, None] * logz[None, :])
        c, *_ = np.linalg.lstsq(basis, x.astype(complex), rcond=None)
        rms = np.abs(c) * np.linalg.norm(basis, axis=0) / math.sqrt(N)
        angle = np.imag(logz)
        # one member of each oscillating pair (angle in (0, pi): below Nyquist, not real), decaying
        good = (angle > 1e-9) & (angle < math.pi - 1e-9) & (np.abs(z) < 1.0)
        found = int(good.sum())
        if found >= n:
            break
        if order >= max_order:
            break
    if found < n:
        raise ValueError(
            f"{_OWNER}: the matrix pencil finds {found} decaying oscillation(s) in the record, fewer than "
            f"`n_modes` = {n}: the record (`y`) may be noise, growing, or hold fewer modes; try a smaller "
            f"`n_modes` or a record of the free decay only (after the excitation has ended)"
        )
    idx = np.flatnonzero(good)
    idx = idx[np.argsort(-rms[idx])][:n]
    s = logz[idx] / dt
    sigma, wd = -s.real, s.imag
    w = np.abs(s)
    f, zeta = w / (2 * math.pi), sigma / w
    order_f = np.argsort(f)
    f, zeta, sigma, wd = f[order_f], zeta[order_f], sigma[order_f], wd[order_f]
    # amplitudes (and offset) by linear least squares at these poles: the fit's start point
    tau = k * dt
    env = np.exp(-np.outer(tau, sigma))
    cols = [env * np.cos(np.outer(tau, wd)), env * np.sin(np.outer(tau, wd))]
    if offset:
        cols.append(np.ones((N, 1)))
    A = np.concatenate(cols, axis=1)
    coef, *_ = np.linalg.lstsq(A, x, rcond=None)
    a, b = coef[:n], coef[n : 2 * n]
    c0 = mean + (coef[2 * n] if offset else 0.0)
    return f, zeta, a, b, float(c0)


# --------------------------------------------------------------------------------------------
# step 2: Levenberg-Marquardt on all parameters
# --------------------------------------------------------------------------------------------
def _model(theta, tau, n: int, offset: bool):
    """The record model at the coordinates `theta` = (ln f, logit zeta, a, b[, c]), times `tau` [s]."""
    f = jnp.exp(theta[:n])
    lz = theta[n : 2 * n]
    zeta = jax.nn.sigmoid(lz)
    w = 2.0 * jnp.pi * f
    sigma = zeta * w
    wd = w * jnp.sqrt(jax.nn.sigmoid(-lz) * (1.0 + zeta))  # 1 - zeta^2 = (1 - zeta)(1 + zeta), no cancellation
    a, b = theta[2 * n : 3 * n], theta[3 * n : 4 * n]
    ph = tau[:, None] * wd[None, :]
    y = jnp.sum(jnp.exp(-tau[:, None] * sigma[None, :]) * (a * jnp.cos(ph) + b * jnp.sin(ph)), axis=1)
    return y + theta[4 * n] if offset else y


@functools.partial(jax.jit, static_argnames=("n", "offset", "rtol", "atol", "max_steps"))
def _fit(tau, yn, theta0, scale, *, n, offset, rtol, atol, max_steps):
    """LM on `u` with `theta = theta0 + scale * u` (`scale` conditions the Jacobian's columns).
    Returns (u, residuals, the singular values and right singular vectors (rows) of the Jacobian d r / d u,
    dominant first, the result's index in `_RESULT_NAMES`, steps).

    Matrix products and LAPACK calls of the parameters' size only (the damped steps by their normal
    equations, the Jacobian's singular vectors from $J^TJ$): LAPACK's QR or SVD of the tall Jacobian runs
    over a multi-threaded BLAS, which takes 10x longer on a busy machine. $J$'s columns are scaled to
    comparable norms, so squaring its condition number costs nothing that matters."""

    def resid(u, _):
        return _model(theta0 + scale * u, tau, n, offset) - yn

    return _levenberg_marquardt(resid, jnp.zeros_like(theta0), rtol=rtol, atol=atol, max_steps=max_steps)


def _levenberg_marquardt(resid, u0, *, rtol, atol, max_steps):
    """Inside a jitted fit: Levenberg-Marquardt on `resid(u, None)` from `u0`, and what the standard errors need.
    Returns (u, residuals, the singular values and right singular vectors (rows) of the Jacobian d r / d u,
    dominant first, the result's index in `_RESULT_NAMES`, steps)."""
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(resid, solver, u0, options={"jac": "fwd"}, max_steps=max_steps, throw=False)
    u = sol.value
    jac, r = jax.jacfwd(lambda v: (resid(v, None),) * 2, has_aux=True)(u)
    lam, W = jnp.linalg.eigh(jac.T @ jac)
    sv, vt = jnp.sqrt(jnp.maximum(lam[::-1], 0.0)), W[:, ::-1].T
    hits = jnp.stack([sol.result == getattr(optx.RESULTS, name) for name in _RESULT_NAMES])
    code = jnp.where(jnp.any(hits), jnp.argmax(hits), -1)
    return u, r, sv, vt, code, sol.stats["num_steps"]


def _standard_errors(theta, r, sv, vt, scale, n: int, p: int):
    """Standard errors of f [Hz] and zeta, and each mode's significance (amplitude at t0 over its standard
    error), from the residuals `r` and the singular values `sv` and vectors `vt` of the Jacobian dr/du at the
    optimum ($\\theta = \\theta_0 + $ `scale` $u$): $C_u = s^2 (J^TJ)^{-1}$ (a direction whose singular value is
    below 1e-7 of the largest is unidentified: infinite variance), $s^2 = \\mathrm{SSR}/(N - p)$, mapped by the delta method."""
    cov = _covariance(r, sv, vt, scale, p, r.size)  # in theta = (ln f, logit zeta, a, b[, c])
    var = np.diag(cov)
    f = np.exp(theta[:n])
    zeta = 1.0 / (1.0 + np.exp(-theta[n : 2 * n]))
    f_std = f * np.sqrt(var[:n])
    z_std = zeta * (1.0 - zeta) * np.sqrt(var[n : 2 * n])
    ia, ib = slice(2 * n, 3 * n), slice(3 * n, 4 * n)
    a, b = theta[ia], theta[ib]
    amp = np.hypot(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        amp_var = (a**2 * var[ia] + b**2 * var[ib] + 2 * a * b * np.diag(cov[ia, ib])) / amp**2
        significance = amp / np.sqrt(amp_var)
    return f_std, z_std, np.nan_to_num(significance, nan=0.0, posinf=np.inf)


def _covariance(r, sv, vt, scale, p: int, n_obs: int) -> np.ndarray:
    """The covariance of the fit's coordinates $\\theta = \\theta_0 + $ `scale` $u$ from the residuals `r` and the
    singular values `sv` and vectors `vt` of the Jacobian dr/du at the optimum: $C_u = s^2 (J^TJ)^{-1}
    = s^2 \\sum_k v_k v_k^T / \\sigma_k^2$, $s^2 = \\mathrm{SSR}/(N - p)$ with $N$ = `n_obs` observations.

    A direction whose singular value is below 1e-7 of the largest is nearly unidentified (e.g. a noise floor
    fitted to 0): it adds its term in full, so the coordinates it is made of get their large variance and the
    others, which it touches only by a rounding-level mixing, keep theirs (marking every coordinate the direction
    touches by more than 1e-8 as unidentified made a well-resolved mode's amplitude "0 standard errors" at some
    bin widths). A singular value of 0 (or one whose term overflows) gives an infinite variance to the
    coordinates it holds by more than 1e-8."""
    s2 = float(r @ r) / (n_obs - p)
    keep = sv > 1e-7 * sv[0]
    cov_u = (vt[keep].T / sv[keep] ** 2) @ vt[keep] * s2
    for k in np.flatnonzero(~keep):
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            w = vt[k] / sv[k]
            term = np.outer(w, w) * s2
        if np.all(np.isfinite(term)):
            cov_u = cov_u + term
        else:
            free = np.abs(vt[k]) > 1e-8
            cov_u[np.ix_(free, free)] = np.inf
    return cov_u * np.outer(scale, scale)


def _fit_outcome(out, theta0, scale, n: int):
    """The solver's outputs `(u, r, sv, vt, code, steps)` on the host, and what both fits read from them:
    `(r, sv, vt, code, steps, finite, theta, f [Hz], zeta)` with $\theta = \theta_0 + $ `scale` $u$ in
    (ln f, logit zeta, ...)."""
    u, r, sv, vt, code, steps = jax.device_get(out)
    finite = bool(
        np.all(np.isfinite(r)) and np.all(np.isfinite(sv)) and np.all(np.isfinite(vt)) and np.all(np.isfinite(u))
    )
    theta = theta0 + scale * u
    f = np.exp(theta[:n])
    zeta = 1.0 / (1.0 + np.exp(-theta[n : 2 * n]))
    return r, sv, vt, int(code), int(steps), finite, theta, f, zeta


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in np.atleast_1d(v)) + "]"


@blas_limited
def identify_axis(
    t,
    y,
    n_modes: int,
    *,
    t_start: float | None = None,
    offset: bool = True,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 256,
):
    """The modes of a belt-driven axis from a measured free decay or step response: a `ModalAxis` with the
    frequencies [Hz], damping ratios and their standard errors.

    ```python
    t, y = jb.load_record("response.csv")          # t [s], y: any unit (m, m/s², counts)
    axis = jb.identify_axis(t, y, n_modes=2)
    axis.frequencies, axis.frequency_std            # Hz
    ```

    - `t`: sample times [s], 1-D, strictly increasing and uniform: every time within `UNIFORM_RTOL` = 1e-3
      of a step, plus the rounding of its writer, of the grid $t_0 + k\\Delta t$ fitted to the times by least
      squares. The rounding is half a unit of the last decimal the times hold (found from the values:
      Klipper's raw accelerometer file writes `%.6f`, 0.5 µs, 1.6e-3 of a step at 3.2 kHz); the fit uses the
      exact grid. Any start time $t_0$; a rate off its nominal value (a sensor's clock) is the fitted one.
    - `y`: the samples, same shape, any unit: a free decay, or a step response from the end of the move on
      (the model holds only where nothing drives the axis: crop the move away).
    - `t_start`: the time [s] from which the record is a free decay (the end of the move, or of the tap); the
      samples before it are left out. None: the whole record, checked for a start that does not follow a free
      decay (below).
    - `n_modes`: number of modes $n \\ge 1$ to fit. The record needs at least
      `SAMPLES_PER_PARAMETER` = 10 samples per parameter ($4n$, +1 with the offset).
    - `offset`: fit a constant $c_0$ (the final value of a step response, an encoder's position, a sensor
      bias); `False` for a record that decays to zero.
    - `rtol`, `atol`: step tolerances of the Levenberg-Marquardt solver (relative, absolute, in the fit's
      coordinates); `max_steps`: its step budget.

    The model, $y(t) = c_0 + \\sum_i e^{-\\sigma_i\\tau}(a_i\\cos\\omega_{d,i}\\tau + b_i\\sin\\omega_{d,i}\\tau)$ with
    $\\tau = t - t_0$, $\\sigma_i = \\zeta_i\\omega_i$, $\\omega_{d,i} = \\omega_i\\sqrt{1-\\zeta_i^2}$,
    $\\omega_i = 2\\pi f_i$, starts from a matrix-pencil estimate (Hua and Sarkar, 1990) and is refined by
    Levenberg-Marquardt on all parameters; see the module's documentation.

    **A record that holds the move.** A step response logged from the start of the move holds the move itself,
    which no sum of free decays follows. Without `t_start`, the residuals of the fit are cut in 10 blocks: where
    the first ones stand out (RMS over `_HEAD_RATIO` = 2 times the median block's, within the first half), the
    record is fitted again after them, with a `UserWarning` that says from when, and that `t_start` chooses it.
    Residuals still structured after the fit (a start that stands out, or a lag-1 autocorrelation over 0.5:
    a trend, a mode left out, the move) are named in a `UserWarning` with what to pass. The standard errors are
    widened by the residuals' long-run variance factor (Newey and West, 1987; 1 for white noise).

    Returns `ModalAxis(frequencies, damping_ratios, gains=None, frequency_std=..., damping_std=...)`, the
    modes sorted by frequency, with the linearised standard errors $\\sqrt{\\mathrm{diag}\\,C}$,
    $C = s^2(J^TJ)^{-1}$, $s^2 = \\mathrm{SSR}/(N-p)$. **The gains are unit gains**: a free decay fixes each
    mode's frequency and damping, not how strongly the commanded acceleration drives it (that would need
    the excitation as well); unit gains are the form input shapers assume.

    Raises `ValueError` for a bad record (shapes, NaN or inf, non-uniform or non-increasing times, too few
    samples, `n_modes` not an integer >= 1) before anything is compiled, and after the fit when a result
    cannot be trusted: a frequency at or above the record's Nyquist frequency $1/(2\\Delta t)$, fewer than
    `MIN_PERIODS` = 2 periods of the lowest mode in the record, a damping ratio outside [0, 1), or a mode
    whose amplitude is below `MIN_SIGNIFICANCE` = 8 standard errors (a fit to noise, or more `n_modes`
    than the record holds; also when the fit did not converge, or when the matrix pencil finds fewer than
    `n_modes` decaying oscillations). Raises `RuntimeError` when Levenberg-Marquardt does not converge
    although every mode stands out of the noise (the reason, and what to change), and when JAX's 64-bit mode
    is off (the fit needs float64).
    """
    _require_x64()
    t, y = _crop(t, y, t_start)
    axis, r, dt = _fit_record(t, y, n_modes, offset, rtol, atol, max_steps)
    if t_start is not None:
        _warn_structure(r, dt, t[0], cropped=None)
        return axis
    head = _head_blocks(r)
    if head and _noisy(r):
        # the record's start does not follow a free decay (the move, the tap): fit after it, once
        keep = int(round(head * r.size / _BLOCKS))
        t2, y2 = t[keep:], y[keep:]
        try:
            axis2, r2, _ = _fit_record(t2, y2, n_modes, offset, rtol, atol, max_steps)
        except ValueError:
            axis2 = None
        if axis2 is not None:
            _warn_structure(r2, dt, t2[0], cropped=(t[0], t2[0]))
            return axis2
    _warn_structure(r, dt, t[0], cropped=None)
    return axis


#: the residuals' blocks of the check for structure (the record's start, the move)
_BLOCKS = 10
#: a block whose RMS residual exceeds this many times the median block's holds what the model does not
_HEAD_RATIO = 2.0
#: lag-1 autocorrelation of the residuals above which they hold structure (white noise: about 1/sqrt(N))
_STRUCTURE_RHO = 0.5


def _crop(t, y, t_start):
    """`(t, y)` from `t_start` [s] on (all of it for None); `t_start` must lie within the record."""
    if t_start is None:
        return t, y
    try:
        t_start = float(t_start)
    except (TypeError, ValueError):
        raise ValueError(f"{_OWNER}: parameter `t_start` must be a time [s] or None; got {t_start!r}") from None
    tt = np.asarray(t, dtype=float)
    yy = np.asarray(y, dtype=float)
    if tt.ndim != 1 or yy.shape != tt.shape:
        return t, y  # `_check_record` says what is wrong
    if not (math.isfinite(t_start) and tt.size and tt[0] <= t_start < tt[-1]):
        raise ValueError(
            f"{_OWNER}: parameter `t_start` must lie within the record, {tt[0]:.6g} <= t_start < {tt[-1]:.6g} s; "
            f"got {t_start!r}"
        )
    keep = tt >= t_start
    return tt[keep], yy[keep]


def _head_blocks(r: np.ndarray) -> int:
    """How many of the residuals' first `_BLOCKS` blocks (at most half) stand above the rest: a block whose RMS
    exceeds `_HEAD_RATIO` times the median block's, and every block before it. 0 where the start is like the rest."""
    rms = np.array([math.sqrt(float(np.mean(b**2))) for b in np.array_split(r, _BLOCKS)])
    median = float(np.median(rms))
    if median <= 0:
        return 0
    high = rms > _HEAD_RATIO * median
    if not high[0]:
        return 0
    last = int(np.flatnonzero(high[: _BLOCKS // 2])[-1])
    return last + 1


def _lag1(r: np.ndarray) -> float:
    r = r - r.mean()
    c0 = float(r @ r)
    return float(r[1:] @ r[:-1]) / c0 if c0 > 0 else 0.0


def _long_run_factor(r: np.ndarray, lags: int = 4) -> float:
    """$1 + 2\\sum_{l=1}^{L}(1 - l/(L+1))\\rho_l$ (at least 1) of the residuals `r` (Newey and West, 1987,
    Econometrica 55(3)): the variance of a least-squares estimate under correlated residuals, over its value
    for white ones."""
    r = r - r.mean()
    c0 = float(r @ r)
    if c0 <= 0:
        return 1.0
    total = 1.0
    for lag in range(1, lags + 1):
        total += 2.0 * (1.0 - lag / (lags + 1)) * float(r[lag:] @ r[:-lag]) / c0
    return max(total, 1.0)


def _noisy(r: np.ndarray) -> bool:
    """Whether the residuals (in units of the record's spread) are more than rounding: a noise-free record fitted
    to 1e-12 has no structure worth a word."""
    return math.sqrt(float(np.mean(r**2))) > _RESIDUAL_FLOOR


#: RMS residual, in units of the record's spread, below which the fit is exact to rounding (no check of structure)
_RESIDUAL_FLOOR = 1e-7


def _warn_structure(r: np.ndarray, dt: float, t0: float, cropped) -> None:
    """Warnings that name what the residuals hold and what to pass: the start cut off (`cropped` = (first time,
    new first time)), a start that still stands out, or residuals correlated from sample to sample."""
    import warnings

    if cropped is not None:
        warnings.warn(
            f"{_OWNER}: the record's start ({cropped[0]:.6g}-{cropped[1]:.6g} s) does not follow a free decay (the move "
            f"or the excitation, still in the record): the modes are fitted from t = {cropped[1]:.6g} s on; pass "
            "`t_start` (the end of the move) to choose where the free decay starts",
            UserWarning,
            stacklevel=4,
        )
    if not _noisy(r):
        return
    if _head_blocks(r):
        warnings.warn(
            f"{_OWNER}: the residuals of the fit from t = {t0:.6g} s stand out at its start: the record there holds "
            "what the fit does not (the move, the excitation, or a fast-decaying mode left out): pass a later "
            "`t_start`, or another `n_modes`",
            UserWarning,
            stacklevel=4,
        )
        return
    rho = _lag1(r)
    if rho > _STRUCTURE_RHO:
        warnings.warn(
            f"{_OWNER}: the residuals hold structure (lag-1 autocorrelation {rho:.2f}; white noise: about "
            f"{1 / math.sqrt(r.size):.2g}): a trend, another mode, or the move is in the record: try another "
            "`n_modes`, `offset=True`, or a later `t_start`; the standard errors are widened for it (Newey-West) "
            "but a model that misses part of the record is biased",
            UserWarning,
            stacklevel=4,
        )


def _fit_record(t, y, n_modes, offset, rtol, atol, max_steps):
    """The fit of `identify_axis` on the record as given: `(ModalAxis, residuals in units of the record's spread,
    dt [s])`."""
    t, y, dt, n, p = _check_record(t, y, n_modes, offset)
    offset = bool(offset)
    rtol, atol = float(rtol), float(atol)
    if not (math.isfinite(rtol) and rtol > 0):
        raise ValueError(f"{_OWNER}: parameter `rtol` must be finite and > 0; got {rtol}")
    if not (math.isfinite(atol) and atol >= 0):
        raise ValueError(f"{_OWNER}: parameter `atol` must be finite and >= 0; got {atol}")
    max_steps = check_int(_OWNER, "max_steps", max_steps, lo=1)
    N = t.size
    duration = (N - 1) * dt  # t[-1] - t[0]
    nyquist = 0.5 / dt

    f0, z0, a0, b0, c0 = _pencil(y, dt, n, offset)
    if duration * float(np.min(f0)) < 0.5 * MIN_PERIODS:  # far too short already by the start values: before the fit
        f_low = float(np.min(f0))
        raise ValueError(
            f"{_OWNER}: the record (`t`) lasts {duration:.6g} s, about {duration * f_low:.3g} periods of the lowest "
            f"mode (about {f_low:.6g} Hz, the matrix-pencil estimate); at least {MIN_PERIODS:g} periods are needed, "
            f"i.e. a record of at least {MIN_PERIODS / f_low:.6g} s"
        )
    # coordinates: amplitudes and offset in units of the record's spread, about its mean
    mean = float(np.mean(y)) if offset else 0.0  # without an offset the model has no constant to take the mean
    spread = float(np.max(np.abs(y - mean)))
    w0 = 2 * math.pi * f0
    theta0 = np.concatenate(
        [np.log(f0), np.log(z0) - np.log1p(-z0), a0 / spread, b0 / spread]
        + ([np.array([(c0 - mean) / spread])] if offset else [])
    )
    # column scaling: a change 1 of u moves every mode's phase (or decay) by about one radian over the
    # time the mode rings in the record, and the amplitudes by the spread
    ring = np.minimum(duration, 1.0 / (z0 * w0))
    scale = np.concatenate([1.0 / (w0 * ring), np.ones(n), np.ones(2 * n)] + ([np.ones(1)] if offset else []))
    tau = dt * np.arange(N)
    yn = (y - mean) / spread
    out = _fit(
        device_array(tau),
        device_array(yn),
        device_array(theta0),
        device_array(scale),
        n=n,
        offset=offset,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
    )
    r, sv, vt, code, steps, finite, theta, f, zeta = _fit_outcome(out, theta0, scale, n)
    start = f"started from the matrix-pencil estimate f = {_fmt(f0)} Hz, zeta = {_fmt(z0)}"
    if finite:
        f_std, z_std, significance = _standard_errors(theta, r, sv, vt, scale, n, p)
    if code != 0:
        reason = _RESULT_NAMES[code] if code >= 0 else "unknown solver failure"
        hint = {
            "max_steps_reached": f"give a larger `max_steps` (now {max_steps})",
            "nonlinear_max_steps_reached": f"give a larger `max_steps` (now {max_steps})",
        }.get(reason, "check that the record is a free decay of the axis")
        failed = f"the Levenberg-Marquardt fit of {n} mode(s) did not converge ({reason}) after {steps} steps"
        if finite and np.any(~(significance >= MIN_SIGNIFICANCE)):
            # the record, not the solver: a mode of the last iterate is lost in the noise
            i = int(np.argmin(significance))
            raise ValueError(
                f"{_OWNER}: {failed}, and its last iterate has a mode ({f[i]:.6g} Hz) of only "
                f"{significance[i]:.3g} standard errors (at least {MIN_SIGNIFICANCE:g} are needed): the record (`y`) "
                f"may be noise, or hold fewer than `n_modes` = {n} modes: try a smaller `n_modes` ({start})"
            )
        raise RuntimeError(
            f"{_OWNER}: {failed}, {start}. {hint[0].upper() + hint[1:]}, try another `n_modes` (the record may "
            f"hold fewer or more modes), or pass `t_start`: the end of the move, where the axis rings freely"
        )
    if not finite:
        raise RuntimeError(
            f"{_OWNER}: the fit of {n} mode(s) ended at non-finite values ({start}); try another `n_modes` "
            f"or a record of the free decay only"
        )
    order = np.argsort(f)
    f, zeta, f_std, z_std, significance = (v[order] for v in (f, zeta, f_std, z_std, significance))
    found = f"identified f = {_fmt(f)} Hz, zeta = {_fmt(zeta)}"
    if np.any(f >= nyquist):
        i = int(np.argmax(f))
        raise ValueError(
            f"{_OWNER}: mode {i + 1} comes out at {f[i]:.6g} Hz, not below the record's Nyquist frequency "
            f"{nyquist:.6g} Hz (1/(2 dt), dt = {dt:.6g} s of `t`): sample faster, or fit fewer `n_modes` "
            f"({found})"
        )
    periods = duration * f[0]
    if periods < MIN_PERIODS:
        raise ValueError(
            f"{_OWNER}: the record (`t`) lasts {duration:.6g} s, {periods:.3g} periods of the lowest mode "
            f"({f[0]:.6g} Hz); at least {MIN_PERIODS:g} periods are needed, i.e. a record of at least "
            f"{MIN_PERIODS / f[0]:.6g} s ({found})"
        )
    if not np.all((zeta >= 0.0) & (zeta < 1.0)):
        raise ValueError(f"{_OWNER}: a damping ratio comes out outside [0, 1) ({found}): the record is not underdamped")
    weak = np.flatnonzero(~(significance >= MIN_SIGNIFICANCE))
    if weak.size:
        i = int(weak[0])
        raise ValueError(
            f"{_OWNER}: mode {i + 1} ({f[i]:.6g} Hz, zeta = {zeta[i]:.3g}) is not resolved above the noise: its "
            f"amplitude is {significance[i]:.3g} standard errors (at least {MIN_SIGNIFICANCE:g} are needed): the "
            f"record (`y`) may be noise, or hold fewer than `n_modes` = {n} modes: try a smaller `n_modes` ({found})"
        )
    from ..models.axis import ModalAxis

    # correlated residuals (structure the model misses, a coloured noise) carry less information than white ones
    widen = math.sqrt(_long_run_factor(np.asarray(r))) if _noisy(np.asarray(r)) else 1.0
    return ModalAxis(f, zeta, None, frequency_std=f_std * widen, damping_std=z_std * widen), np.asarray(r), dt
