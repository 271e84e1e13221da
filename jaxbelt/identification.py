"""Parameter identification: gradient-based weighted least squares on any differentiable prediction.

`identify(predict, params0, data, sigma=None)` finds the parameters $p$ (a dict of named
scalars) that minimise

$S(p) = \\sum_k \\left(\\dfrac{\\text{predict}(p)_k - \\text{data}_k}{\\sigma_k}\\right)^2$

with Levenberg-Marquardt (default) or Gauss-Newton from `optimistix`, the Jacobian of the
prediction coming from JAX through the simulation.

**Scaling.** The solver works in dimensionless coordinates $u$: a parameter whose initial
value is positive is fitted in its logarithm, $p = p_0 e^{u}$ (it stays positive; a step in $u$
is a relative change), any other one relative to its initial magnitude,
$p = p_0 + s\\,u$ with $s = |p_0|$ (or 1 if $p_0 = 0$). Parameters of very different sizes
(a stiffness of $10^5$ N/m next to a resistance of 0.15 Ω) are then equally well conditioned.

**Uncertainty.** With $J_u = \\partial r/\\partial u$ at the optimum ($r$ the weighted residuals)
the covariance in $u$ is $C_u = s^2 (J_u^T J_u)^{-1}$ and, by the delta method, in physical
units $C_p = D C_u D$, $D = \\mathrm{diag}(dp/du)$. If `sigma` is given, $s^2 = 1$ (the noise
level is known); if it is `None`, the residuals are unweighted and $s^2 = S/(N - n)$ is the
noise variance estimated from the $N$ residuals with $n$ fitted parameters (this needs
$N > n$). `stderr` is $\\sqrt{\\mathrm{diag}\\,C_p}$. These are linearised (Cramér-Rao-type)
uncertainties: reliable when the noise is small compared with the curvature scale of the model.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._callables import by_value
from ._checks import check_int, check_nonnegative, check_positive, device_array, require_x64
from ._display import Display, Table, with_unit
from ._guard import host_checked, reraise_checks
from ._threads import blas_limited
from ._xla import QUICK_COMPILE

__all__ = ["identify", "IdentifyResult"]

_SOLVERS = ("lm", "gn")


@dataclass(frozen=True)
class IdentifyResult:
    """Outcome of `identify`.

    - `params`: fitted values (dict, same keys and units as `params0`);
    - `stderr`: standard errors (dict, physical units): $\\sqrt{\\mathrm{diag}\\,C_p}$;
    - `covariance`: $C_p$, shape (n, n), rows and columns in the order of `names`
      (the order of `params0`);
    - `residuals`: `predict(params) - data`, shape of `data` (unweighted, data units);
    - `sigma`: the noise level used: the given one, or the estimate $\\sqrt{S/(N-n)}$ in data units;
    - `cost`: $S$ at the optimum (weighted sum of squares; with `sigma=None` the unweighted one);
    - `dof`: $N - n$; `n_steps`: solver steps; `names`: parameter names in covariance order.

    In a notebook the result shows as an HTML table of the estimates with their standard errors; `str()` is the
    same as text.
    """

    params: dict
    stderr: dict
    covariance: np.ndarray
    residuals: np.ndarray
    sigma: object
    cost: float
    dof: int
    n_steps: int
    names: tuple = field(default=())

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the estimates, (n, n)."""
        s = np.sqrt(np.diag(self.covariance))
        return self.covariance / np.outer(s, s)

    def interval(self, k: float = 2.0) -> dict:
        """`{name: (p - k·stderr, p + k·stderr)}` (k = 2: about 95 % for Gaussian noise)."""
        return {n: (self.params[n] - k * self.stderr[n], self.params[n] + k * self.stderr[n]) for n in self.names}

    def _display(self) -> Display:
        rows = []
        for n in self.names or tuple(self.params):
            p, s = float(np.asarray(self.params[n])), float(np.asarray(self.stderr[n]))
            rows.append((n, p, s, 100.0 * abs(s / p) if p != 0 else math.nan))
        sigma = np.asarray(self.sigma, dtype=float)
        fields = (
            ("noise level σ", float(sigma) if sigma.ndim == 0 else f"array of shape {sigma.shape}", "data units"),
            ("cost S", self.cost, ""),
            ("degrees of freedom", self.dof, ""),
            ("solver steps", self.n_steps, ""),
        )
        headers = ("parameter", "estimate", "standard error", with_unit("relative error", "%"))
        table = Table(headers, tuple(rows), caption="estimates (units of params0)")
        return Display("jaxbelt IdentifyResult", fields, (table,))

    def _repr_html_(self) -> str:
        return self._display().html()

    def __str__(self) -> str:
        return self._display().text()


class PredictError(ValueError, RuntimeError):
    """`predict` returned NaN or inf at the start values: a `ValueError` (the input, `predict` or `params0`,
    is at fault), and a `RuntimeError` as well, what `identify` raised for it before."""


#: (predict's key, names, start values) already checked by `_check_start` in this process (a Monte-Carlo over
#: noise draws starts every fit at the same values: checked once)
_STARTS_CHECKED: dict = {}
_STARTS_MAX = 256


def _check_start(predict, names: tuple, p0: np.ndarray, data_shape: tuple) -> None:
    """Run `predict` at the concrete start values, abstractly (`jax.eval_shape`: traced, nothing compiled or
    computed), before the fit is compiled: a model that `predict` builds from the start values then runs its
    parameter checks on concrete values and raises at once (a negative stiffness, ...), and a prediction of the
    wrong shape is refused, instead of either failing inside the compiled fit after its compilation (seconds).

    The start values are 0-d float64 JAX arrays, as in the fit (`.shape`, `.astype` and JAX operations work on
    them). Only a `ValueError` (a parameter check, a shape) is reported here; any other error of the abstract
    run is left to the fit, which reports it as before. A check on a value that `predict` computes from a start
    value (`BeltStartup(k=1e3 * p["k"])`) is traced, not concrete: it still fails in the fit, with its
    message first."""
    try:
        key = (by_value(predict), names, p0.tobytes(), data_shape)
        hash(key)
    except TypeError:
        key = None
    if key is not None and key in _STARTS_CHECKED:
        return
    start = {n: jax.device_put(np.float64(v)) for n, v in zip(names, p0)}
    values = dict(zip(names, p0.tolist()))
    try:
        out = jax.eval_shape(lambda: predict(start))
    except ValueError as e:
        first, _, rest = str(e).partition("\n")
        raise ValueError(
            f"identify: {first} (inside `predict`, at the start values {values}: refused before the fit was "
            f"compiled; give start values `params0` inside the model's ranges){chr(10) + rest if rest else ''}"
        ) from e
    except Exception:  # noqa: BLE001 - not a parameter check: the fit runs `predict` and reports it
        return
    if isinstance(out, jax.ShapeDtypeStruct) and tuple(out.shape) != tuple(data_shape):
        raise ValueError(
            f"identify: `predict(params)` must return an array of the shape of `data` {tuple(data_shape)}; got "
            f"shape {tuple(out.shape)} (at the start values params0 = {values})"
        )
    if key is not None:
        if len(_STARTS_CHECKED) >= _STARTS_MAX:
            _STARTS_CHECKED.clear()
        _STARTS_CHECKED[key] = True


def _transform(p0: np.ndarray):
    """(is_log, scale) per parameter: log for positive initial values, relative otherwise."""
    is_log = p0 > 0
    scale = np.where(p0 != 0, np.abs(p0), 1.0)
    return is_log, scale


def _to_params(u, p0, is_log, scale):
    return jnp.where(is_log, p0 * jnp.exp(u), p0 + scale * u)


def _traced_once(fun, *args):
    """`fun`, traced here once to a jaxpr that every call evaluates: its Python (a user's `predict` and its
    derivative) runs once however many places of the program call it. (A `jax.jit` of it would be traced again
    where optimistix calls it under another tracing context.)"""
    closed, shape = jax.make_jaxpr(fun, return_shape=True)(*args)
    run = jax.extend.core.jaxpr_as_fun(closed)
    tree = jax.tree_util.tree_structure(shape)
    return lambda *a: jax.tree_util.tree_unflatten(tree, run(*jax.tree_util.tree_leaves(a)))


# checks inside `predict` (a model's parameter ranges) come back as values (`host_checked`): the program holds no
# host callback, so the persistent compilation cache stores it and a later process loads it instead of compiling.
# QUICK_COMPILE: a fit is small work beside its compilation (start-up k, c, R from 301 samples: 1.7 s to compile
# instead of 2.7 on 2 cores, 32 ms to run instead of 29; the same HLO, parameters equal to 1e-12)
@host_checked(store=True, compiler_options=QUICK_COMPILE)
def _fit(predict, names, p0, data, w, is_log, scale, solver_kind, jac_mode, rtol, atol, max_steps):
    # traced once: the solver and the Jacobians below call it several times, each a re-trace otherwise
    predict_once = jax.jit(predict)

    def resid_of(u, p0, data, w, is_log, scale):  # the traced arrays as arguments: jit programs of it are reused
        p = _to_params(u, p0, is_log, scale)
        pred = jnp.asarray(predict_once({n: p[i] for i, n in enumerate(names)}), dtype=float)
        if pred.shape != data.shape:  # broadcasting would fit a scalar to every point without a word
            raise ValueError(
                f"identify: `predict(params)` must return an array of the shape of `data` "
                f"{tuple(data.shape)}; got shape {tuple(pred.shape)}"
            )
        return jnp.ravel((pred - data) * w)

    consts = (p0, data, w, is_log, scale)
    # traced once (`_traced_once`): the solver evaluates the residuals in several places of its program
    resid_once = _traced_once(resid_of, p0, *consts)

    def resid(u, _):
        return resid_once(u, *consts)

    if jac_mode == "fwd":
        # the solver linearises the residuals at every step and applies the linear map several times (to
        # materialise the Jacobian, in the damped solve): here that map is the Jacobian itself, computed once per
        # step by forward mode (n tangents through `predict`, batched), so the map is a matrix product instead
        # of a replay of the linearised prediction (a scan in a closed form, an ODE solve) per application.
        # The Jacobian and the residuals are traced once: the solver's steps and the final covariance below share
        # them instead of tracing the forward-mode derivative of `predict` at each place
        jac_and_resid = _traced_once(jax.jacfwd(lambda v, *c: (resid_of(v, *c),) * 2, has_aux=True), p0, *consts)

        @jax.custom_jvp
        def resid_fwd(u):
            return resid_once(u, *consts)

        @resid_fwd.defjvp
        def _resid_jvp(primals, tangents):
            (u,), (du,) = primals, tangents
            jac, r = jac_and_resid(u, *consts)
            return r, jac @ du

        def resid(u, _):
            return resid_fwd(u)

    if solver_kind == "lm":
        solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    else:
        solver = optx.GaussNewton(rtol=rtol, atol=atol)
    sol = optx.least_squares(
        resid, solver, jnp.zeros_like(p0), options={"jac": jac_mode}, max_steps=max_steps, throw=False
    )
    u = sol.value
    # the residual at the solution comes with its Jacobian (one evaluation of the prediction)
    if jac_mode == "fwd":
        jac, r = jac_and_resid(u, *consts)
    else:
        jac, r = jax.jacrev(lambda v: (resid(v, None),) * 2, has_aux=True)(u)
    # the residuals at the start values (one more evaluation of the prediction): NaN there is the user's
    # `predict` (or its start values), not the solver, and is reported as such
    r0 = resid(jnp.zeros_like(p0), None)
    return u, r, jac, sol.result == optx.RESULTS.successful, sol.stats["num_steps"], sol.result, r0


def _real_array(name: str, value) -> np.ndarray:
    """`value` as a float numpy array, refusing what is not real numbers (complex, strings, bools) by name."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        arr = np.asarray(value, dtype=object)
    if arr.dtype.kind not in "fiu":
        raise ValueError(
            f"identify: parameter `{name}` must be an array of real numbers; got {type(value).__name__} of dtype "
            f"{arr.dtype}"
        )
    return arr.astype(float)


@blas_limited
def identify(
    predict,
    params0: dict,
    data,
    sigma=None,
    *,
    solver: str = "lm",
    jac: str = "fwd",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 200,
) -> IdentifyResult:
    """Fit the named parameters `params0` of `predict` to `data` by least squares.

    - `predict(params) -> array`: a JAX-differentiable function of a dict of scalar parameters,
      returning an array of the shape of `data` (a time series, or a few scalar features);
      fixed parameters are closed over. Repeated calls (e.g. a Monte-Carlo over noise draws) compile
      once: a function with the same code and equal closed-over values reuses the program, a new lambda
      included (`data`, `sigma` and `params0` are data: new values of the same shapes reuse it). With
      `enable_compilation_cache()` on, a later process runs the stored fit without tracing `predict`.
    - `params0`: initial values, `{name: float}`; positive ones are fitted in log space.
    - `data`: the measurements, array of any shape.
    - `sigma`: standard deviation of the noise on `data` [data units]: a scalar or an array
      broadcastable to `data` (per-point weights $1/\\sigma_k$); `None` estimates one common
      level from the residuals (then `data` needs more points than parameters).
    - `solver`: `"lm"` (`optimistix.LevenbergMarquardt`) or `"gn"` (`optimistix.GaussNewton`);
      `jac`: `"fwd"` (forward-mode Jacobian: few parameters; a diffrax simulation inside `predict`
      then needs `simulate(..., adjoint="forward")`) or `"bwd"` (reverse mode: few outputs);
      `rtol`, `atol`: its step tolerances (in the scaled coordinates); `max_steps`: its budget.

    Returns an `IdentifyResult` (`params`, `stderr`, `covariance`, `residuals`, ...). Raises
    `ValueError` on bad input before anything is compiled: the arguments, and the start values as `predict`
    uses them (`predict` is run abstractly at `params0` first, so a model it builds from an invalid start
    value, e.g. a negative stiffness, is refused at the call, naming the parameter, its value and its range;
    so is a prediction of the wrong shape). Raises `ValueError` (also a `RuntimeError`) when `predict`
    returns NaN or inf at the start values, naming the first bad point; `RuntimeError` when the solver does
    not converge or the prediction is not finite at a later step or at the optimum.
    """
    require_x64("identify")
    if not callable(predict):
        raise TypeError(
            f"identify: parameter `predict` must be a function params -> array; got {type(predict).__name__}"
        )
    if not isinstance(params0, dict) or not params0:
        raise ValueError("identify: `params0` must be a non-empty dict {name: initial value}")
    for name, value in params0.items():
        if not isinstance(name, str):
            raise TypeError(f"identify: the keys of `params0` must be parameter names (str); got {name!r}")
        if isinstance(value, bool | complex | str | bytes) or np.ndim(value) != 0:
            raise ValueError(
                f"identify: parameter `params0[{name!r}]` (an initial value) must be a real number; got {value!r}"
            )
    if solver not in _SOLVERS:
        raise ValueError(f"identify: `solver` must be one of {_SOLVERS}; got {solver!r}")
    if jac not in ("fwd", "bwd"):
        raise ValueError(f"identify: `jac` must be 'fwd' or 'bwd'; got {jac!r}")
    check_positive("rtol", rtol, owner="identify")
    check_nonnegative("atol", atol, owner="identify")
    check_int("identify", "max_steps", max_steps)
    names = tuple(params0)
    try:
        p0 = np.array([float(params0[n]) for n in names])
    except (TypeError, ValueError):
        raise ValueError(f"identify: the initial values `params0` must be real numbers; got {params0!r}") from None
    if not np.all(np.isfinite(p0)):
        bad = [n for n, v in zip(names, p0) if not np.isfinite(v)]
        raise ValueError(
            f"identify: parameter `params0[{bad[0]!r}]` must be finite (the initial values must be finite); got "
            f"{params0[bad[0]]!r} (non-finite: {bad})"
        )
    data = _real_array("data", data)
    if data.size == 0 or not np.all(np.isfinite(data)):
        raise ValueError("identify: parameter `data` must be a non-empty array of finite values")
    n, N = len(names), data.size
    if sigma is None:
        if N <= n:
            raise ValueError(
                f"identify: with sigma=None the noise level is estimated from the residuals, which needs more "
                f"data points ({N}) than parameters ({n}); give `sigma` (the data's standard deviation)"
            )
        w = np.ones_like(data)
    else:
        sig = _real_array("sigma", sigma)
        try:
            sig = np.broadcast_to(sig, data.shape)
        except ValueError:
            raise ValueError(
                f"identify: parameter `sigma` must be a scalar or an array broadcastable to the shape of `data` "
                f"{data.shape}; got shape {sig.shape}"
            ) from None
        if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise ValueError("identify: `sigma` (noise standard deviation, data units) must be finite and > 0")
        w = 1.0 / sig
    # a model that `predict` builds from invalid start values is refused now, before the fit is compiled
    _check_start(predict, names, p0, data.shape)
    is_log, scale = _transform(p0)
    args = (
        by_value(predict),  # keyed by its code and values: a new lambda of the same code reuses the program
        names,
        device_array(p0),
        device_array(data),
        device_array(w),
        device_array(is_log),
        device_array(scale),
        solver,
    )
    # a check inside `predict` (a model built from the parameters, ...) fails inside the compiled fit: its
    # message comes first, not JAX's stack
    context = (
        f"inside `predict`, at the start values {dict(zip(names, p0.tolist()))} or at a step of the fit: a "
        "parameter that starts > 0 is fitted in log space and stays > 0, one that starts <= 0 is fitted linearly "
        "and may cross zero"
    )
    with reraise_checks("identify", context):
        try:
            u, r, jmat, ok, steps, result, r0 = _fit(*args, jac, rtol, atol, int(max_steps))
        except TypeError as e:
            if jac != "fwd" or "custom_vjp" not in str(e):
                raise
            # `predict` holds a reverse-mode-only solve (diffrax's default adjoint): use a reverse Jacobian
            warnings.warn(
                "identify: `predict` cannot be differentiated in forward mode (a simulate(...) with the default "
                "reverse-mode adjoint); using jac='bwd'. Pass adjoint='forward' to simulate for the faster forward "
                "Jacobian.",
                stacklevel=2,
            )
            u, r, jmat, ok, steps, result, r0 = _fit(*args, "bwd", rtol, atol, int(max_steps))
    u, r, jmat, r0 = np.asarray(u), np.asarray(r), np.asarray(jmat), np.asarray(r0)
    p = np.where(is_log, p0 * np.exp(u), p0 + scale * u)  # `_to_params` on the host: no eager device ops
    at = dict(zip(names, p.tolist()))
    for residuals, where, values, error in (
        (r0, "at the start values", dict(zip(names, p0.tolist())), PredictError),
        (r, "at a step of the fit", at, RuntimeError),
    ):
        if not np.all(np.isfinite(residuals)):
            bad = np.flatnonzero(~np.isfinite(residuals))
            point = np.unravel_index(int(bad[0]), data.shape)
            raise error(
                f"identify: `predict` returned non-finite values (NaN or inf at {bad.size} of {residuals.size} "
                f"points, the first at flat index {int(bad[0])}, data index {tuple(int(i) for i in point)}) "
                f"{where}, parameters {values}: NaN in the model, not a convergence problem. Check `predict` at "
                "these values (a parameter outside the model's range, a failed simulation inside it: "
                "simulate(..., throw=False) returns NaN for it), or start elsewhere"
            )
    if not bool(ok):
        reason = optx.RESULTS[result]
        steps = int(steps)
        if bool(result == optx.RESULTS.max_steps_reached) or bool(result == optx.RESULTS.nonlinear_max_steps_reached):
            what = (
                f"reached the step limit max_steps={int(max_steps)} without converging (cost "
                f"{float(r @ r):.6g}); raise `max_steps`, or start nearer the optimum"
            )
        else:
            what = f"stopped after {steps} steps: {reason} Try other initial values or the other solver"
        raise RuntimeError(f"identify: the {solver.upper()} solver {what} (parameters at the stop: {at})")
    if not np.all(np.isfinite(jmat)):
        raise RuntimeError(
            f"identify: the Jacobian of `predict` is not finite at the optimum {at} (a parameter at which the "
            "model is not differentiable, or an overflow in its derivative)"
        )
    cost = float(r @ r)
    dof = N - n
    s2 = cost / dof if sigma is None else 1.0
    # Covariance in u from the SVD of the Jacobian (stable where J^T J is badly conditioned).
    _, sv, vt = np.linalg.svd(jmat, full_matrices=False)
    keep = sv > 1e-12 * sv[0] if sv.size else sv > 0
    cov_u = (vt[keep].T / sv[keep] ** 2) @ vt[keep] * s2
    if keep.sum() < n:
        warnings.warn(
            f"identify: the data do not identify all of {names} (Jacobian singular values {sv}); "
            "the standard errors of the parameters in the unidentified combinations are infinite",
            RuntimeWarning,
            stacklevel=2,
        )
        free = np.ones(n, bool) if len(sv) < n else np.any(np.abs(vt[~keep]) > 1e-8, axis=0)
        cov_u[np.ix_(free, free)] = np.inf
    d = np.where(is_log, p, scale)  # dp/du
    cov = cov_u * np.outer(d, d)
    stderr = np.sqrt(np.diag(cov))
    residuals = np.asarray(r).reshape(data.shape) / w
    return IdentifyResult(
        params={nm: float(v) for nm, v in zip(names, p)},
        stderr={nm: float(v) for nm, v in zip(names, stderr)},
        covariance=cov,
        residuals=residuals,
        sigma=float(np.sqrt(s2)) if sigma is None else sigma,
        cost=cost,
        dof=dof,
        n_steps=int(steps),
        names=names,
    )
