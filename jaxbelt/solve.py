"""`simulate(scene)`: the single entry point that turns a `Scene` into a `Solution`.

Method choice (`method=`):

- `"auto"` (default): closed form when the model is linear time-invariant and its input a
  sum of exponentials (e.g. `BeltStartup` + `ExponentialVoltage`) and no integral output is
  requested; diffrax otherwise.
- `"closed"`: the preferred closed form (`"expm"`); `"expm"`: matrix exponential of the
  augmented system; `"modal"`: the modal solution of Incerti (2014) (eq. 14-29), with an automatic
  fall-back to `"expm"` when the eigenvector matrix is ill-conditioned.
- `"ode"`: diffrax, `solver=` any diffrax solver (default: the model's choice, Tsit5 for
  non-stiff models), adaptive step with `rtol`/`atol` (arrays: changing them does not recompile).
- `"rk4"`: classical fixed-step fourth-order Runge-Kutta with step `dt` (the papers' check).

A start-up scene whose `ExponentialVoltage` carries a 1-D array of time constants is a batch:
`simulate` solves all of them at once with the batched closed form of `jaxbelt.fast` and returns
`ys` of shape (B, N, n).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.typing import ArrayLike

from . import _store
from ._checks import as_float_array, concrete_array_type, is_concrete, positive_checks
from ._guard import (
    _modules,
    all_ok,
    eager,
    error_if,
    guard,
    has_host_callbacks,
    host_checked,
    nan_where,
    reraising,
    traced_checks,
    validated_inputs,
)
from ._model import AbstractLinearModel
from ._params import declared
from ._threads import blas_limited
from .commands import AbstractExponentialVoltage
from .fast import batched_exponential_scene
from .modal import CLOSED_FORM_TOL, closed_form_error, expm_solve, modal_solve
from .scene import Scene
from .solution import Solution, SolveError

_CLOSED = ("closed", "expm", "modal")
_METHODS = ("auto", "ode", "rk4") + _CLOSED


_batched_exponential_scene = eqx.filter_jit(batched_exponential_scene)


#: |R(h lambda)| of RK4 may exceed max(1, |exp(h lambda)|) by this much before the step is called unstable.
_RK4_GROWTH_TOL = 1e-6


def _rk4_stable(model, inp, ts, ys, dt):
    """`(stable, spectral radius)` of RK4 steps `dt` at the states `ys` at the times `ts` (the run's first and last):
    stable where no step amplifies more than the exact flow (`rk4_growth`) at any of them."""
    growth, rho = zip(*(rk4_growth(model, t, y, inp, dt) for t, y in zip(ts, ys)))
    g = jnp.stack(growth)
    return jnp.all(jnp.isfinite(g)) & (jnp.max(g) <= _RK4_GROWTH_TOL), jnp.max(jnp.stack(rho))


def rk4_growth(model, t, y, inp, dt):
    """Largest excess amplification of one RK4 step over the exact flow, from the Jacobian's eigenvalues.

    $R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24$ with $z = \\Delta t\\,\\lambda_i$ for the eigenvalues
    $\\lambda_i$ of $\\partial f/\\partial y$ at `(t, y)`; the step is stable for the linearised
    dynamics when $|R(z)| \\le \\max(1, |e^{z}|)$ for every eigenvalue. Returns
    `max_i |R(z_i)| - max(1, |e^{z_i}|)` and the spectral radius of the Jacobian [1/s].
    """
    J = jax.lax.stop_gradient(jax.jacfwd(lambda yy: model.vector_field(t, yy, inp))(y))
    lam = jnp.linalg.eigvals(J)
    z = jnp.asarray(dt, dtype=lam.dtype) * lam
    R = 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24
    bound = jnp.maximum(1.0, jnp.abs(jnp.exp(z)))
    return jnp.max(jnp.abs(R) - bound), jnp.max(jnp.abs(lam))


def _closed(model, inp, y0, t0, times, method, uniform):
    A, F, s = model.exponential_form(inp)
    solve = modal_solve if method == "modal" else expm_solve
    return solve(A, F, s, y0, t0, times, uniform)


def _closed_form_ok(model, inp, t0, times):
    """Whether the output times lie within the closed form's accuracy (`jaxbelt.modal.closed_form_error`)."""
    return closed_form_error(model.exponential_form(inp)[0], t0, times) <= CLOSED_FORM_TOL


def _run_impl(scene: Scene, method: str, solver, rtol, atol, dt0, max_steps: int, progress: bool, adjoint):
    model, inp = scene.model, scene.input
    integrals = tuple(n for n in scene.observe if n in type(model).integral_names())
    pointwise = tuple(n for n in scene.observe if n not in integrals)
    y0 = scene.y0 if scene.y0 is not None else model.initial_state(inp)
    times = scene.times
    t0 = scene.start_time
    stats = {}
    integral_vals = {}
    success = jnp.array(True)
    saved_outputs = None
    if method in _CLOSED:
        ys = _closed(model, inp, y0, t0, times, method, scene.uniform)
        success = _closed_form_ok(model, inp, t0, times)
    else:
        if integrals:

            def augmented(t, y, args):  # the state and the integrands of the integral outputs
                x, _ = y
                return model.vector_field(t, x, args), jnp.stack([model.rate(n, t, x, args) for n in integrals])

            vf, y_init = augmented, (y0, jnp.zeros((len(integrals),)))
        else:
            vf, y_init = (lambda t, y, args: model.vector_field(t, y, args)), y0
        import diffrax

        from ._rk4 import RK4

        outputs_only = not scene.state  # the states are never stored: only the outputs asked for, and the last state
        if outputs_only:

            def asked(t, y, args):  # the observed outputs (and running integrals) at one output time
                x, acc = y if integrals else (y, None)
                return {n: model.output(n, t, x, args) for n in pointwise}, acc

            saveat = diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=times, fn=asked), diffrax.SubSaveAt(t1=True)])
        else:
            saveat = diffrax.SaveAt(t1=True) if scene.final_only else diffrax.SaveAt(ts=times)
        if isinstance(solver, diffrax.AbstractAdaptiveSolver) and not isinstance(solver, RK4):
            controller = diffrax.PIDController(rtol=rtol, atol=atol)
        else:
            controller = diffrax.ConstantStepSize()
        meter = diffrax.TqdmProgressMeter() if progress else diffrax.NoProgressMeter()
        with validated_inputs():  # the output times were checked by Scene (or are checked on the results)
            sol = diffrax.diffeqsolve(
                diffrax.ODETerm(vf),
                solver,
                t0,
                times[-1],
                dt0,
                y_init,
                args=inp,
                saveat=saveat,
                stepsize_controller=controller,
                max_steps=max_steps,
                throw=False,
                progress_meter=meter,
                adjoint=adjoint,
            )
        assert sol.ys is not None  # saved at `times` (or t1)
        if outputs_only:
            (saved, acc), last = sol.ys
            last = last[0] if integrals else last
            ys = last  # the last state only: it decides `success` with the outputs (below)
            saved_outputs = saved
        else:
            ys, acc = sol.ys if integrals else (sol.ys, None)
            saved_outputs = None
        if integrals:
            assert acc is not None  # the augmented state's running integrals
            integral_vals = {n: acc[:, i] for i, n in enumerate(integrals)}
        success = sol.result == diffrax.RESULTS.successful
        stats = {
            "num_steps": sol.stats["num_steps"],
            "num_rejected_steps": sol.stats["num_rejected_steps"],
            "result": _result_code(sol.result),
            "t_final": jax.lax.stop_gradient(_time_reached(sol.ts, t0, scene.final_only or outputs_only)),
        }
        if method == "rk4":
            stable, stats["spectral_radius"] = _rk4_stable(model, inp, (t0, times[-1]), (y0, ys[-1]), dt0)
            stats["rk4_stable"] = stable
            success = success & stable
    success = success & jnp.all(jnp.isfinite(ys))
    outputs = dict(integral_vals)
    for name in pointwise:
        if saved_outputs is not None:
            outputs[name] = saved_outputs[name]
        else:
            outputs[name] = jax.vmap(lambda t, y, name=name: model.output(name, t, y, inp))(times, ys)
    for v in outputs.values():
        success = success & jnp.all(jnp.isfinite(v))
    return Solution(
        ts=times,
        ys=ys if scene.state else None,
        outputs=outputs,
        success=success,
        stats=stats,
        state_names=tuple(model.state_names),
        method=method,
        model=type(model).__name__,
    )


# One compiled program per shape and static option; `eqx.debug.get_num_traces(_run_traced)` counts them.
_run_traced = eqx.debug.assert_max_traces(_run_impl, max_traces=None)
_run = eqx.filter_jit(_run_traced)


# diffrax is imported where an ODE is integrated (the closed forms never load it)
def _is_diffrax(obj, name: str) -> bool:
    """`isinstance(obj, diffrax.<name>)`; an object cannot be one while diffrax is not imported."""
    module = sys.modules.get("diffrax")
    return module is not None and isinstance(obj, getattr(module, name))


@functools.cache
def _rk4():
    from ._rk4 import RK4

    return RK4()


@functools.cache
def _default_adjoint():
    import diffrax

    return diffrax.RecursiveCheckpointAdjoint()


@functools.cache
def _forward():
    import diffrax

    return diffrax.ForwardMode()


def _describe(scene: Scene, method: str) -> str:
    return f"{type(scene.model).__name__} driven by {type(scene.input).__name__} (method={method!r})"


#: `Solution.stats["result"]` of an ODE or RK4 solve: why diffrax stopped, by index (3: another stop of diffrax)
_RESULTS = ("successful", "max_steps_reached", "dt_min_reached")


def _result_code(result):
    """diffrax's result as an integer (`_RESULTS`): a plain array, kept in `Solution.stats`."""
    import diffrax

    code = jnp.asarray(len(_RESULTS), dtype=jnp.int32)
    for i, name in reversed(list(enumerate(_RESULTS))):
        code = jnp.where(result == getattr(diffrax.RESULTS, name), jnp.int32(i), code)
    return code


def _time_reached(ts, t0, final_saved: bool):
    """The time a solve reached: where it stopped when its final state is saved (`SaveAt(t1=True)`, the last
    of the saves), otherwise the last output time it reached (diffrax fills the others with inf), or `t0`."""
    if final_saved:
        last = ts[-1] if isinstance(ts, (list, tuple)) else ts
        return last[-1]
    return jnp.max(jnp.where(jnp.isfinite(ts), ts, t0))


def _closed_form_span(scene) -> str | None:
    """The reason of a closed-form failure where the time span is beyond its accuracy (concrete values), or None."""
    if scene is None or not is_concrete(scene):
        return None
    try:
        A = np.asarray(scene.model.exponential_form(scene.input)[0], dtype=float)
    except Exception:  # noqa: BLE001 - a model without an exponential form: not this cause
        return None
    t0 = float(np.asarray(scene.start_time))
    times = np.asarray(scene.times, dtype=float)
    err = float(closed_form_error(A, t0, times))
    if not err > CLOSED_FORM_TOL:
        return None
    span = float(np.max(np.abs(times - t0)))
    norm = float(np.max(np.sum(np.abs(A), axis=0)))
    return (
        f"The closed form is not accurate over the output times: eps * ||A||_1 * (t_last - t0) = {err:.2g} > "
        f"{CLOSED_FORM_TOL:g}, with ||A||_1 = {norm:.3g} 1/s (the model's fastest rates) and a span of {span:.4g} s "
        "(the rounding of the system's eigenvalues grows with both). Check the parameters, or give `ts` spanning at "
        f"most {CLOSED_FORM_TOL / (err / span):.4g} s (a transient settles long before)."
    )


def _failure_hint(method: str, sol: Solution | None = None, *, scene=None, max_steps=None, dt=None) -> str:
    """Why a solve failed and what to do. Without a concrete solution (under a transformation, where the
    message is fixed when the program is traced) the possible causes; with one (eager), the cause diffrax
    reports (`stats["result"]`), where it stopped (`stats["t_final"]`) and the way out."""
    if method in _CLOSED:
        span = _closed_form_span(scene)
        if span is not None:
            return span
        return (
            "The closed form produced non-finite values (check the parameters), or its time span is beyond its "
            f"accuracy (eps * ||A||_1 * (t_last - t0) > {CLOSED_FORM_TOL:g})."
        )
    known = sol is not None and scene is not None and "result" in sol.stats and is_concrete(sol.stats)
    if sol is None or scene is None or not known or np.ndim(sol.success) != 0:
        if method == "rk4":
            return (
                "The RK4 solve stopped at its step budget (`max_steps` below the (t1 - t0) / dt steps it takes), "
                "its fixed step is too large for the fastest mode of this scene (dt * spectral radius beyond "
                "RK4's stability region), or the solution is not finite. Raise max_steps for the budget; use a "
                "smaller `dt` or method='ode' for the step. Called with throw=False, `stats['result']` (1: "
                "max_steps reached) and `stats['rk4_stable']` say which."
            )
        return (
            "The solver did not reach the final time (step budget `max_steps` exhausted or step size collapsed) "
            "or produced non-finite values. Try an implicit solver (diffrax.Kvaerno5()), looser tolerances or a "
            "larger max_steps. Called with throw=False, `stats['result']` (1: max_steps reached, 2: minimum step "
            "size reached) and `stats['t_final']` say which and where."
        )
    stats = jax.device_get(sol.stats)
    step = math.nan if dt is None else float(dt)  # the RK4 step [s]
    code, tf = int(stats["result"]), float(stats["t_final"])
    n, rejected = int(stats["num_steps"]), int(stats["num_rejected_steps"])
    t0, t1 = float(scene.start_time), float(scene.times[-1])
    exact = scene.final_only or not scene.state  # the solve saved its final state: the time it stopped
    if method == "rk4" and code == 1 and step > 0:  # fixed steps, all of them taken
        tf, exact = min(t0 + n * step, t1), True
    if exact:
        where = f"at t = {tf:.6g} s (the final time is {t1:.6g} s)"
    else:  # the last output time it reached (the time it stopped is not saved)
        ts = np.asarray(scene.times, dtype=float)
        later = ts[ts > tf]
        nxt = f" and t = {float(later[0]):.6g} s" if later.size else ""
        where = f"between t = {tf:.6g} s{nxt} (output times; the final time is {t1:.6g} s)"
    if code == 1 and method == "rk4":
        need = math.ceil((t1 - t0) / step - 1e-9) if step > 0 else None
        if need is None:
            return f"The step budget `max_steps` = {max_steps} was reached {where}. Raise max_steps."
        return (
            f"The step budget `max_steps` = {max_steps} was reached {where}: RK4 with dt = {step:g} s takes {need} "
            f"steps from t0 to t1. Raise max_steps to at least {need}."
        )
    if code == 1:
        text = f"The step budget `max_steps` = {max_steps} was reached {where}: {n} steps, {rejected} of them rejected."
        if 2 * rejected > n:
            return (
                f"{text} Most steps were rejected: the step size collapsed (a stiff or singular model, or a vector "
                "field that is not finite there). Try an implicit solver (diffrax.Kvaerno5()) or check the "
                "parameters; a larger max_steps rarely helps."
            )
        pace = f" (at this pace about {n * (t1 - t0) / (tf - t0):.3g} steps)" if exact and tf > t0 else ""
        return (
            f"{text} Raise max_steps{pace}, loosen rtol/atol, or, for a stiff model, take an implicit solver "
            "(diffrax.Kvaerno5())."
        )
    if code == 2:
        return (
            f"The step size collapsed to the step-size controller's minimum (diffrax: dt_min_reached) {where}: a "
            "stiff or singular model, or a vector field that is not finite there. Try an implicit solver "
            "(diffrax.Kvaerno5()), looser tolerances, or check the parameters."
        )
    if code != 0:
        return (
            f"diffrax stopped the solve before the final time {where} (a result other than max_steps_reached and "
            "dt_min_reached)."
        )
    if method == "rk4" and not bool(stats.get("rk4_stable", True)):
        product = step * float(stats["spectral_radius"])
        return (
            f"The fixed RK4 step dt = {step:g} s is too large for the fastest mode of this scene (dt * spectral "
            f"radius = {product:.3g}, beyond RK4's stability region). Use a smaller `dt` or method='ode'."
        )
    return (
        f"The solution is not finite (NaN or inf){_first_nonfinite(sol)}: the model diverges or a parameter makes "
        "it singular; check the parameters and the input"
        + (
            " (or take a smaller `dt`: the RK4 step is checked for stability at the first and last state only)."
            if method == "rk4"
            else "."
        )
    )


def _first_nonfinite(sol: Solution) -> str:
    """` from t = ... s`: the first output time where a state or an output is not finite ('' if none is)."""
    n = np.shape(sol.ts)[0]
    rows = [np.asarray(v) for v in (sol.ys, *sol.outputs.values()) if v is not None]
    rows = [r.reshape(n, -1) for r in rows if r.ndim and r.shape[0] == n]
    if not rows:
        return ""
    bad = ~np.all(np.isfinite(np.concatenate(rows, axis=1)), axis=1)
    return f" from t = {float(np.asarray(sol.ts)[np.argmax(bad)]):.6g} s" if bad.any() else ""


def forward_sensitivities(
    model,
    input_of: Callable,
    p,
    ts,
    *,
    method: str = "ode",
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-8,
    dt: ArrayLike = 1e-3,
    max_steps: int = 100_000,
):
    """The trajectory of `model` driven by `input_of(p)` from rest at t = 0 and its forward sensitivities.

    Integrates $\\dot y = f(t, y, u(p))$ together with $\\dot S = \\partial_y f\\,S + \\partial_p f$,
    $S(0) = 0$ (one column per entry of the vector `p`; $\\partial f$ by JAX's forward mode, the input's
    derivative taken once), with the solver `simulate` uses for `method` ("ode": the model's default solver
    under `rtol`/`atol`, its error control reading $y$ alone, so that the steps and the trajectory are
    `simulate`'s to rounding; "rk4": fixed steps `dt` [s], refused as `simulate` refuses them when a step
    amplifies more than the exact flow), saved at the times `ts` [s] (the last one ends the run).

    Differentiating the solver's loop itself (`simulate(..., adjoint="forward")` under `jax.jacfwd`) gives
    the same derivative to the tolerance; this form is half as long to trace (no JVP or batching of
    diffrax's loop) and runs faster. Returns `(ys, S, success)`: `ys` (N, n), `S` (N, n, P); both NaN where
    the run failed (`success` False), as `simulate(..., throw=False)` gives them.
    """
    import diffrax
    import optimistix as optx

    if method not in ("ode", "rk4"):
        raise ValueError(f"forward_sensitivities: `method` must be 'ode' or 'rk4'; got {method!r}")
    p = jnp.asarray(p, dtype=float)
    if p.ndim != 1 or p.shape[0] == 0:
        raise ValueError(f"forward_sensitivities: `p` must be a non-empty vector (P,); got shape {p.shape}")
    _check_max_steps(max_steps, "forward_sensitivities")
    n_p = p.shape[0]
    inp = input_of(p)
    y0 = model.initial_state(inp)
    n = y0.shape[0]

    # the input's derivative along each parameter, once: the vector field differentiates the input itself (the
    # map p -> input is not traced again at every evaluation)
    inp_dyn, inp_static = eqx.partition(inp, eqx.is_inexact_array)
    d_inp = jax.vmap(lambda e: jax.jvp(lambda q: eqx.partition(input_of(q), eqx.is_inexact_array)[0], (p,), (e,))[1])(
        jnp.eye(n_p, dtype=p.dtype)
    )

    # the state is the pair (y, S): a flat vector holding both runs 2.5x slower (XLA copies it at every stage)
    def vf(t, z, args):
        y, s = z

        def f(y, u):
            return model.vector_field(t, y, eqx.combine(u, inp_static))

        def column(s_k, du_k):
            return jax.jvp(f, (y, inp_dyn), (s_k, du_k))

        return jax.vmap(column, in_axes=(1, 0), out_axes=(None, 1))(s, d_inp)

    rtol, atol, dt = (jnp.asarray(x, dtype=float) for x in (rtol, atol, dt))
    if method == "rk4":
        solver, controller, dt0 = _rk4(), diffrax.ConstantStepSize(), dt
    else:
        # the error control of the trajectory alone (the norm of its components): the steps of `simulate`'s solve,
        # whose trajectory this one is to rounding; the sensitivities ride along on the same steps
        def norm(scaled_error):
            return optx.rms_norm(scaled_error[0])  # the norm diffrax uses by default, of the trajectory's part

        solver, dt0 = model.default_solver(), None
        controller = diffrax.PIDController(rtol=rtol, atol=atol, norm=norm)
    with validated_inputs():
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(vf),
            solver,
            0.0,
            ts[-1],
            dt0,
            (y0, jnp.zeros((n, n_p), dtype=y0.dtype)),
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=controller,
            max_steps=max_steps,
            throw=False,
            adjoint=_forward(),  # never differentiated through (the sensitivities are the derivative): a plain loop
        )
    assert sol.ys is not None
    ys, s = sol.ys
    success = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(ys)) & jnp.all(jnp.isfinite(s))
    if method == "rk4":
        success = success & _rk4_stable(model, inp, (0.0, ts[-1]), (y0, ys[-1]), dt)[0]
    checks = traced_checks(model, inp)
    if not is_concrete((model, inp)):
        checks = checks + model.input_checks(inp)
    success = success & all_ok(checks)  # a failed check makes the run's values NaN, as a failed solve does
    ys, s = nan_where((ys, s), success)
    return ys, s, success


@reraising("simulate")
@blas_limited
def simulate(
    scene: Scene,
    method: str = "auto",
    *,
    solver=None,
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-10,
    dt0: ArrayLike | None = None,
    dt: ArrayLike = 1e-4,
    max_steps: int = 100_000,
    throw: bool = True,
    progress: bool = False,
    adjoint=None,
) -> Solution:
    """Simulate a `Scene` and return a `Solution`.

    - `scene`: what to compute (model, input, times, observed outputs).
    - `method`: `"auto"`, `"closed"`, `"expm"`, `"modal"`, `"ode"` or `"rk4"` (see "Method
      choice" under `jaxbelt.solve` below).
    - `solver`: diffrax solver for `method="ode"` (default: `scene.model.default_solver()`).
    - `rtol`, `atol`: tolerances of the adaptive step-size controller (ODE method), > 0. Arrays: a
      new value does not recompile.
    - `dt0`: initial step [s] for the ODE method (default: chosen automatically; required for
      fixed-step diffrax solvers).
    - `dt`: step [s] of `method="rk4"` (default 0.1 ms, the check of Incerti, 2014), > 0; a new
      value does not recompile. The step is checked against RK4's stability region using the
      eigenvalues of the Jacobian at the first and last state: an unstable step fails the solve.
    - `max_steps`: step budget of the ODE and RK4 methods (static: a new value recompiles).
    - `throw`: what a failure does (see "Errors and guarantees" in the docs).
      `True`: raise `SolveError` when called eagerly; under `jit`/`vmap`/`grad` the states and
      outputs carry an `eqx.error_if`, so the program raises at run time whichever of them the
      caller keeps. Invalid traced parameters (e.g. a negative stiffness inside `jit`) raise the
      same way, naming the parameter and its range.
      `False`: never raise for values: failed elements get `success=False` and NaN states and
      outputs (never finite garbage); shape and type errors still raise.
    - `progress`: show a tqdm progress bar for the ODE method.
    - `adjoint`: how the ODE method is differentiated: `None` (reverse mode with recursive
      checkpointing, diffrax's default), `"forward"` (`diffrax.ForwardMode()`: use with
      `jax.jacfwd`/`jax.jvp`; cheaper when there are few parameters) or any diffrax adjoint.

    Works under `jax.jit`, `jax.vmap` and `jax.grad` (the modal method differentiates with
    respect to the input's parameters only: JAX does not differentiate eigenvectors).
    Compiles once per shape and static option: new times, tolerances, steps or parameter values
    of the same shapes reuse the compiled program.
    """
    if method not in _METHODS:
        raise ValueError(f"simulate: `method` must be one of {_METHODS}; got {method!r}")
    if not isinstance(scene, Scene):
        raise TypeError(f"simulate: parameter `scene` must be a jaxbelt.Scene; got {type(scene).__name__}")
    for name, flag in (("throw", throw), ("progress", progress)):
        if not isinstance(flag, bool | np.bool_):
            raise TypeError(f"simulate: parameter `{name}` must be True or False; got {flag!r}")
    if method == "rk4":
        _check_rk4_budget(scene, dt, max_steps)
    sol = _simulate_concrete(scene, method, solver, rtol, atol, dt0, dt, max_steps, progress, adjoint)
    if sol is not None:
        if throw and not isinstance(sol.success, Tracer) and bool(np.all(np.asarray(sol.success))):
            return sol  # the common eager case: nothing to attach, nothing to raise
        hint = functools.partial(_failure_hint, sol.method, scene=scene, max_steps=max_steps, dt=dt)
        return _finish(sol, [], throw, _describe(scene, sol.method), hint)
    model, inp = scene.model, scene.input
    if isinstance(inp, AbstractExponentialVoltage) and _batched_input(inp):
        return _simulate_batch(scene, method, throw)
    method, adjoint = _structure(scene, method, adjoint)
    step_checks = []
    if method == "rk4":
        if jnp.ndim(dt) != 0:
            raise ValueError(f"simulate: `dt` (RK4 step, s) must be a scalar; got shape {jnp.shape(dt)}")
        step_checks = positive_checks("simulate (RK4 step, s)", dt=dt)  # raises now, or recorded when traced
        solver, dt0 = _rk4(), dt
    elif method == "ode" and dt0 is not None:
        if jnp.ndim(dt0) != 0:
            raise ValueError(f"simulate: `dt0` (initial step, s) must be a scalar; got shape {jnp.shape(dt0)}")
        step_checks = positive_checks("simulate (initial step, s)", dt0=dt0)  # raises now, or recorded when traced
    if solver is None and method == "ode":
        solver = model.default_solver()
    _check_fixed_step(method, solver, dt0)
    for name, v in (("rtol", rtol), ("atol", atol)):
        if jnp.ndim(v) != 0:
            raise ValueError(f"simulate: `{name}` must be a scalar; got shape {jnp.shape(v)}")
    tol_checks = positive_checks("simulate", rtol=rtol, atol=atol)  # raises now, or recorded when traced
    _check_max_steps(max_steps)
    checks = traced_checks(model, inp) + _time_checks(scene) + (tol_checks if method == "ode" else []) + step_checks
    if not is_concrete((model, inp)):
        checks = checks + model.input_checks(inp)
    if dt0 is not None and not is_concrete(dt0):
        # a traced invalid step is refused by the recorded check; diffrax gets a harmless stand-in
        # (one step over the whole span) instead of failing inside on `(t1 - t0) * dt0 >= 0`
        dt0 = jnp.asarray(dt0, dtype=float)
        dt0 = jnp.where(jnp.isfinite(dt0) & (dt0 > 0), dt0, 1.0)
    sol = _run(
        scene,
        method,
        solver,
        jnp.asarray(rtol, dtype=float),
        jnp.asarray(atol, dtype=float),
        None if dt0 is None else jnp.asarray(dt0, dtype=float),
        int(max_steps),
        bool(progress),
        adjoint,
    )
    hint = functools.partial(_failure_hint, method, scene=scene, max_steps=max_steps, dt=dt)
    return _finish(sol, checks, throw, _describe(scene, method), hint)


def _structure(scene: Scene, method: str, adjoint):
    """The decisions and checks of `simulate` that depend on types, static fields and shapes only
    (never on values): the method, the adjoint, scalar parameters. Returns `(method, adjoint)`."""
    model, inp = scene.model, scene.input
    _check_scalar_fields(model)
    _check_scalar_fields(inp)
    integrals = [n for n in scene.observe if n in type(model).integral_names()]
    lin = isinstance(model, AbstractLinearModel) and isinstance(inp, AbstractExponentialVoltage)
    if method == "auto":
        method = "closed" if (lin and not integrals) else "ode"
    if method == "closed":
        method = "expm"
    if method in _CLOSED:
        if not lin:
            raise ValueError(
                f"simulate: method={method!r} needs a linear time-invariant model driven by a sum of exponentials; "
                f"{type(model).__name__} with {type(inp).__name__} is not. Use method='ode'."
            )
        if integrals:
            raise ValueError(f"simulate: integral outputs {integrals} need method='ode' (they are augmented states)")
    if adjoint is None:
        adjoint = None if method in _CLOSED else _default_adjoint()
    elif isinstance(adjoint, str) and adjoint == "forward":
        adjoint = _forward()
    elif not _is_diffrax(adjoint, "AbstractAdjoint"):
        raise ValueError(f"simulate: `adjoint` must be None, 'forward' or a diffrax adjoint; got {adjoint!r}")
    return method, adjoint


def _check_fixed_step(method: str, solver, dt0) -> None:
    if method == "ode" and dt0 is None and not _is_diffrax(solver, "AbstractAdaptiveSolver"):
        raise ValueError(f"simulate: fixed-step solver {type(solver).__name__} needs `dt0` (step, s)")


def _check_rk4_budget(scene: Scene, dt, max_steps) -> None:
    """Refuse at the call a fixed RK4 step `dt` [s] that needs more than `max_steps` steps over the scene's span,
    $\\lceil (t_1 - t_0) / dt \\rceil > $ `max_steps`, when all three are concrete: the run would stop at the budget
    after stepping through all of it (seconds to minutes for dt = 1e-300 s) and say the same thing then."""
    if not (_number(dt) and isinstance(max_steps, (int, np.integer)) and not isinstance(max_steps, bool)):
        return  # traced or malformed: the recorded checks and `_check_max_steps` answer
    if not (_positive_number(dt) and max_steps >= 1 and is_concrete((scene.start_time, scene.times))):
        return
    t0, t1 = float(scene.start_time), float(np.asarray(scene.times)[-1])
    span, step = t1 - t0, float(dt)
    need = span / step
    if need > max_steps and math.ceil(need - 1e-9) > max_steps:
        raise ValueError(
            f"simulate: parameter `dt` = {step:g} s (RK4 step) needs {need:.3g} steps over the scene's span "
            f"{span:g} s, more than `max_steps` = {max_steps}: give `dt` >= {span / max_steps:.3g} s, or raise "
            f"max_steps to at least {need:.3g}"
        )


def _check_max_steps(max_steps, owner: str = "simulate") -> None:
    if not isinstance(max_steps, (int, np.integer)) or isinstance(max_steps, bool) or max_steps < 1:
        raise ValueError(f"{owner}: `max_steps` must be an integer >= 1; got {max_steps!r}")


# ------------------------------------------------------------------------------------------------
# The eager fast path: a scene whose leaves are all concrete arrays, called with plain numbers.
#
# `eqx.filter_jit` partitions the scene, the solver and the adjoint into arrays and static parts on
# every call, and the checks above re-read the whole scene: for a closed-form solve that costs two
# to three times the compiled program itself. Here everything that depends only on the structure
# (tree definition, static fields, shapes, method and options) is decided once and kept with a
# `jax.jit` program that takes the flat array leaves; a call flattens the scene, checks the few
# per-call numbers (tolerances, step) and runs the program. Values stay data: a new grid, tolerance,
# step or parameter of the same shape reuses the program. Anything else (tracers, leaves that are
# not arrays, traced or non-scalar tolerances) takes the general path above.
# ------------------------------------------------------------------------------------------------

_PLANS: dict = {}
_PROGRAMS: dict = {}
_PLANS_MAX = 512


class _Plan:
    """What `simulate` decided once for one structure: the resolved method, whether the solver is the
    model's (value-dependent) default, and the compiled program over the flat leaves."""

    __slots__ = ("batched", "method", "solver", "default_solver", "program")

    def __init__(self, batched, method=None, solver=None, default_solver=False, program=None):
        self.batched, self.method, self.solver = batched, method, solver
        self.default_solver, self.program = default_solver, program


def _concrete_leaves(leaves) -> bool:
    return all(map(concrete_array_type, set(map(type, leaves))))


def _number(v) -> bool:
    """A plain number or a concrete 0-d array (a tolerance or step on the fast path)."""
    t = type(v)
    return t is float or t is int or (concrete_array_type(t) and v.ndim == 0)


def _positive_number(v) -> bool:
    v = float(v)
    return math.isfinite(v) and v > 0


def _as_scalar(v):
    """A tolerance or step as a float array (a Python number from the cache of `as_float_array`)."""
    return as_float_array(float(v) if type(v) is int else v)


def _run_flat(treedef, method, max_steps, progress, adjoint, leaves, rtol, atol, dt0, solver):
    scene = jax.tree_util.tree_unflatten(treedef, leaves)
    # through `_run`, a nested program: XLA compiles it apart, which runs the closed forms ~20% faster
    return _run(scene, method, solver, rtol, atol, dt0, max_steps, progress, adjoint)


def _run_stored(scene, rtol, atol, dt0, solver, adjoint, method, max_steps, progress):
    return _run(scene, method, solver, rtol, atol, dt0, max_steps, progress, adjoint)


def _make_plan(scene, treedef, method, solver, dt0, adjoint, max_steps, progress) -> _Plan:
    inp = scene.input
    if isinstance(inp, AbstractExponentialVoltage) and _batched_input(inp):
        return _Plan(batched=True)
    method, adjoint = _structure(scene, method, adjoint)
    default_solver = False
    if method == "rk4":
        solver = _rk4()
    elif method == "ode":
        default_solver = solver is None
        if not default_solver:
            _check_fixed_step(method, solver, dt0)
    if method in _CLOSED:
        solver, adjoint = None, None  # not used by the closed forms
    else:
        # nothing on this path is differentiated (every input is a concrete value): the plain forward
        # loop, which traces and compiles faster than a checkpointed one and takes the same steps
        adjoint = _forward()
    return _Plan(
        False, method, solver, default_solver, _program(treedef, method, int(max_steps), bool(progress), adjoint)
    )


class _Program:
    """The compiled program of one structure (shared by the plans that resolve to it), in two versions:
    plain, and `host_checked` for a program that holds a host callback (an `eqx.error_if` in a model,
    or a diffrax check jaxbelt does not make itself), which the persistent cache would not store."""

    __slots__ = ("plain", "checked", "callbacks", "static", "stored", "stored_generation")

    def __init__(self, fun, static):
        self.static = static  # (treedef, method, max_steps, progress, adjoint)
        self.plain = jax.jit(fun, static_argnums=(4,))
        self.checked = host_checked(fun, jit=jax.jit, static_argnums=(4,))
        self.callbacks = {}  # solver -> whether the traced program holds a host callback
        self.stored = {}  # (solver, input types, options, settings) -> stored program or False
        self.stored_generation = None  # the store's generation `stored` belongs to

    def __call__(self, *args):
        if _store.folder() is not None and eager():  # (a concrete scene closed over inside a user's jit: traced)
            return self._stored(*args)
        return self._traced(*args)

    def _stored(self, leaves, rtol, atol, dt0, solver):
        """Through the program store (`jaxbelt.cache`): a program stored by an earlier process runs untraced."""
        try:
            key = (solver, tuple(map(_store.aval, leaves)), rtol is None, dt0 is None, _store.settings())
            if self.stored_generation != _store.generation():  # the store was switched or forgotten
                self.stored, self.stored_generation = {}, _store.generation()
            entry = self.stored.get(key)
        except (TypeError, AttributeError):  # an unhashable solver, a leaf that is not an array
            return self._traced(leaves, rtol, atol, dt0, solver)
        if entry is None:
            treedef, method, max_steps, progress, adjoint = self.static
            scene = jax.tree_util.tree_unflatten(treedef, leaves)
            args = (scene, rtol, atol, dt0, solver, adjoint, method, max_steps, progress)
            # the stored program's inputs are the array leaves in order: here the scene's leaves, then the numbers
            arrays = all(isinstance(leaf, (jax.Array, np.ndarray)) for leaf in leaves)
            entry = _store.lookup("jaxbelt.solve.simulate", _run_stored, args) if arrays else False
            self.stored[key] = entry
        if entry is not False:
            try:
                return entry([*leaves, *(v for v in (rtol, atol, dt0) if v is not None)])
            except Exception:  # noqa: BLE001 - the traced path, which computes the same
                self.stored[key] = False
        return self._traced(leaves, rtol, atol, dt0, solver)

    def _traced(self, *args):
        solver = args[4]
        callbacks = self.callbacks.get(solver)
        if callbacks is None:  # first call with this solver: trace (the call below reuses the trace)
            callbacks = self.callbacks[solver] = has_host_callbacks(self.plain.trace(*args).jaxpr)
        return (self.checked if callbacks else self.plain)(*args)


def _program(*static) -> _Program:
    program = _PROGRAMS.get(static)
    if program is None:
        program = _Program(functools.partial(_run_flat, *static), static)
        if len(_PROGRAMS) >= _PLANS_MAX:
            _PROGRAMS.clear()
        _PROGRAMS[static] = program
    return program


def _simulate_concrete(scene, method, solver, rtol, atol, dt0, dt, max_steps, progress, adjoint):
    """`simulate`'s run on the fast path (see above), before the failure policy; None where it does not apply."""
    if not (_number(rtol) and _number(atol) and _number(dt) and (dt0 is None or _number(dt0))):
        return None
    _check_max_steps(max_steps)
    leaves, treedef = jax.tree_util.tree_flatten(scene)
    if not _concrete_leaves(leaves):
        return None
    key = (treedef, tuple([leaf.shape for leaf in leaves]), method, solver, dt0 is None, adjoint, max_steps, progress)
    try:
        plan = _PLANS.get(key)
    except TypeError:  # an unhashable solver or adjoint (e.g. holding arrays)
        return None
    if plan is None:
        plan = _make_plan(scene, treedef, method, solver, dt0, adjoint, max_steps, progress)
        if len(_PLANS) >= _PLANS_MAX:
            _PLANS.clear()
        _PLANS[key] = plan
    if plan.batched:
        return None
    method = plan.method
    if not (_positive_number(rtol) and _positive_number(atol)):
        positive_checks("simulate", rtol=rtol, atol=atol)  # raises
    solver = plan.solver
    if method == "rk4":
        if not _positive_number(dt):
            positive_checks("simulate (RK4 step, s)", dt=dt)  # raises
        dt0 = dt
    elif method == "ode":
        if dt0 is not None and not _positive_number(dt0):
            positive_checks("simulate (initial step, s)", dt0=dt0)  # raises
        if plan.default_solver:
            solver = scene.model.default_solver()
            _check_fixed_step(method, solver, dt0)
    if method in _CLOSED:
        rtol = atol = dt0 = None  # not used: the program takes no tolerances
    else:
        rtol, atol = _as_scalar(rtol), _as_scalar(atol)
        dt0 = None if dt0 is None else _as_scalar(dt0)
    assert plan.program is not None  # every plan that is not batched holds its program (`_make_plan`)
    return plan.program(leaves, rtol, atol, dt0, solver)


def _check_scalar_fields(obj) -> None:
    """Parameters are scalars inside `simulate` (a batch is a `jax.vmap`/`jb.sweep` over them).

    Parameters declared with a shape other than a scalar (`param(shape=None)`, e.g. the frequencies
    of a `ModalAxis` or the exponents of a `PseudoPolynomial`) are exempt, and so are the fields a class
    lists in a class variable `array_fields` (arrays that are not declared parameters); nested modules
    are checked too."""
    if all(jnp.ndim(leaf) == 0 for leaf in jax.tree_util.tree_leaves(obj)):
        return
    for m in _modules(obj):
        allowed = set(getattr(type(m), "array_fields", ())) | {
            name for name, (p, _) in declared(type(m)).items() if p.shape != ()
        }
        for f in dataclasses.fields(m):
            v = getattr(m, f.name, None)
            if v is None or f.name in allowed or not hasattr(v, "shape") or isinstance(v, eqx.Module):
                continue
            if jnp.ndim(v) != 0:
                raise ValueError(
                    f"simulate: parameter `{f.name}` of {type(m).__name__} must be a scalar; got shape {jnp.shape(v)}. "
                    "For a batch of values use jax.vmap or jaxbelt.sweep over scalar parameters."
                )


def _time_checks(scene):
    """Checks of times and initial state that may be traced (concrete ones were checked by `Scene`)."""
    return [] if is_concrete((scene.ts, scene.t0, scene.t1, scene.y0)) else scene.time_errors()


def _finish(sol: Solution, checks, throw: bool, what: str, hint: Callable[[Solution | None], str]) -> Solution:
    """Apply the failure policy to a solution (see `simulate`'s `throw`). `hint(sol)`: why it failed, read
    from a concrete solution; `hint(None)`: the possible causes (the fixed message of a traced check)."""
    if throw and not checks and is_concrete(sol.success):
        if bool(np.all(np.asarray(sol.success))):
            return sol  # the common eager case: nothing to attach, nothing to raise
    values = (sol.ys, sol.outputs)
    values, ok = guard(values, checks, throw)
    success = sol.success & ok
    if throw:
        if is_concrete(success):
            if not bool(np.all(np.asarray(success))):
                bad = np.flatnonzero(~np.asarray(success).ravel())
                where = f" (batch elements {bad.tolist()[:10]})" if np.ndim(success) else ""
                raise SolveError(f"simulate failed for the scene {what}{where}. {hint(sol)}")
        else:
            # only where the parameters are valid: an invalid one raises its own, more precise error
            values = error_if(values, ~sol.success & ok, f"jaxbelt.simulate failed for the scene {what}. {hint(None)}")
    else:
        values = nan_where(values, success)
    ys, outputs = values
    return eqx.tree_at(lambda s: (s.ys, s.outputs, s.success), sol, (ys, outputs, success), is_leaf=lambda x: x is None)


def _batched_input(inp) -> bool:
    """A command whose parameters carry a leading batch axis (decided from shapes, nothing computed): a
    parameter declared with `batch=True` that holds one (e.g. the time constants of an `ExponentialVoltage`)."""
    return any(
        p.batch and v is not None and jnp.ndim(v) > len(p.shape or ())
        for name, (p, _) in declared(type(inp)).items()
        for v in (getattr(inp, name),)
    )


def _simulate_batch(scene: Scene, method: str, throw: bool) -> Solution:
    """A command carrying a batch of exponential inputs: one batched closed form (`jaxbelt.fast`)."""
    if method not in ("auto", "closed"):
        raise ValueError(
            f"simulate: a command with a batch of parameters is solved by the batched closed form "
            f"(method='auto'); for method={method!r} use jax.vmap over scalar commands"
        )
    sol = _batched_exponential_scene(scene)
    if sol is None:
        raise ValueError(
            "simulate: a batched command needs a linear model (AbstractLinearModel) with scalar parameters, "
            "output times `ts` and no integral outputs; otherwise use jax.vmap over scalar commands"
        )
    checks = traced_checks(scene.model, scene.input)
    return _finish(sol, checks, throw, _describe(scene, "closed"), functools.partial(_failure_hint, "closed"))
