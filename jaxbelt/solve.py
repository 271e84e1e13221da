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

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_concrete
from .commands import AbstractExponentialVoltage, ExponentialVoltage
from .fast import batched_exponential_scene
from .modal import expm_solve, modal_solve
from .models.base import AbstractLinearModel
from .scene import Scene

_CLOSED = ("closed", "expm", "modal")
_METHODS = ("auto", "ode", "rk4") + _CLOSED


_batched_exponential_scene = eqx.filter_jit(batched_exponential_scene)


class SolveError(RuntimeError):
    """A simulation failed (solver did not reach the final time, or produced non-finite values)."""


class Solution(eqx.Module):
    """Result of `simulate`.

    - `ts` (N,): output times [s];
    - `ys` (N, n_states): state history in the model's order (None if `Scene(state=False)`);
    - `outputs`: dict of observed outputs, each (N,) (integrals: value at each output time);
    - `success`: bool (array; per element under `vmap`);
    - `stats`: solver statistics (`num_steps` for ODE methods).

    Named access: `sol.current`, `sol["omega2"]`, `sol.electric_power` for any state or
    observed output.
    """

    ts: jnp.ndarray
    ys: jnp.ndarray | None
    outputs: dict
    success: jnp.ndarray
    stats: dict
    state_names: tuple = eqx.field(static=True, default=())
    method: str = eqx.field(static=True, default="")

    def __getitem__(self, name: str):
        if name in self.outputs:
            return self.outputs[name]
        if self.ys is not None and name in self.state_names:
            return self.ys[..., self.state_names.index(name)]
        raise KeyError(
            f"{name!r} is not in this solution; states: {self.state_names}, outputs: {tuple(self.outputs)}. "
            "Derived outputs are computed only when named in Scene(observe=...)."
        )

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("ts", "ys", "outputs", "success", "stats", "state_names", "method"):
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError as e:
            raise AttributeError(str(e)) from None

    @property
    def y_final(self):
        """State at the last output time."""
        return None if self.ys is None else self.ys[..., -1, :]


def _rk4_substeps(max_spacing: float, dt) -> int:
    """RK4 steps per output interval so that no step exceeds `dt` [s]."""
    return max(int(np.ceil(max_spacing / float(dt) - 1e-9)), 1)


def _rk4(f, y0, ts, n_sub: int, inp):
    """Fixed-step RK4, `n_sub` equal steps between successive output times."""
    if ts.shape[0] < 2:
        return y0[None]

    def one(y, t, h):
        k1 = f(t, y, inp)
        k2 = f(t + h / 2, y + h / 2 * k1, inp)
        k3 = f(t + h / 2, y + h / 2 * k2, inp)
        k4 = f(t + h, y + h * k3, inp)
        return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def interval(y, tt):
        ta, tb = tt
        h = (tb - ta) / n_sub
        y = jax.lax.fori_loop(0, n_sub, lambda i, yy: one(yy, ta + i * h, h), y)
        return y, y

    ts = jnp.asarray(ts)
    _, ys = jax.lax.scan(interval, y0, (ts[:-1], ts[1:]))
    return jnp.concatenate([y0[None], ys], axis=0)


@eqx.filter_jit
def _run(scene: Scene, method: str, solver, rtol, atol, dt0, n_sub: int, max_steps: int, progress: bool, adjoint):
    model, inp = scene.model, scene.input
    integrals = tuple(n for n in scene.observe if n in model.integral_names())
    pointwise = tuple(n for n in scene.observe if n not in integrals)
    y0 = scene.y0 if scene.y0 is not None else model.initial_state(inp)
    times = scene.times
    t0 = scene.t0
    stats = {}
    integral_vals = {}
    success = jnp.array(True)
    if method in _CLOSED:
        A, F, s = model.exponential_form(inp)
        if method == "modal":
            ys = modal_solve(A, F, s, y0, t0, times, scene.uniform)
        else:
            ys = expm_solve(A, F, s, y0, t0, times, scene.uniform)
    elif method == "rk4":
        if scene.final_only:
            raise ValueError("method='rk4' needs output times `ts` (use Scene(..., ts=...))")
        ys = _rk4(model.vector_field, y0, times, n_sub, inp)
    else:
        if integrals:
            def vf(t, y, args):
                x, _ = y
                return model.vector_field(t, x, args), jnp.stack([model.rate(n, t, x, args) for n in integrals])

            y_init = (y0, jnp.zeros((len(integrals),)))
        else:
            vf = lambda t, y, args: model.vector_field(t, y, args)  # noqa: E731
            y_init = y0
        t_end = times[-1]
        if scene.final_only:
            saveat = diffrax.SaveAt(t1=True)
        else:
            saveat = diffrax.SaveAt(ts=times)
        if isinstance(solver, diffrax.AbstractAdaptiveSolver):
            controller = diffrax.PIDController(rtol=rtol, atol=atol)
        else:
            controller = diffrax.ConstantStepSize()
        meter = diffrax.TqdmProgressMeter() if progress else diffrax.NoProgressMeter()
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(vf), solver, t0, t_end, dt0, y_init, args=inp, saveat=saveat,
            stepsize_controller=controller, max_steps=max_steps, throw=False, progress_meter=meter,
            adjoint=adjoint,
        )
        if integrals:
            ys, acc = sol.ys
            integral_vals = {n: acc[:, i] for i, n in enumerate(integrals)}
        else:
            ys = sol.ys
        success = sol.result == diffrax.RESULTS.successful
        stats = {"num_steps": sol.stats["num_steps"]}
    success = success & jnp.all(jnp.isfinite(ys))
    outputs = dict(integral_vals)
    for name in pointwise:
        outputs[name] = jax.vmap(lambda t, y: model.output(name, t, y, inp))(times, ys)
    return Solution(
        ts=times, ys=ys if scene.state else None, outputs=outputs, success=success, stats=stats,
        state_names=tuple(model.state_names), method=method,
    )


def simulate(
    scene: Scene,
    method: str = "auto",
    *,
    solver=None,
    rtol=1e-8,
    atol=1e-10,
    dt0=None,
    dt: float = 1e-4,
    max_steps: int = 100_000,
    throw: bool = True,
    progress: bool = False,
    adjoint=None,
) -> Solution:
    """Simulate a `Scene` and return a `Solution`.

    Parameters
    ----------
    scene: what to compute (model, input, times, observed outputs).
    method: `"auto"`, `"closed"`, `"expm"`, `"modal"`, `"ode"` or `"rk4"` (see module docs).
    solver: diffrax solver for `method="ode"` (default: `scene.model.default_solver()`).
    rtol, atol: tolerances of the adaptive step-size controller (ODE method).
    dt0: initial step [s] for the ODE method (default: chosen automatically; required for
        fixed-step diffrax solvers).
    dt: step [s] of `method="rk4"` (default 0.1 ms, the check of Incerti (2014)).
    max_steps: step budget of the ODE method.
    throw: raise `SolveError` when the solve fails (outside `jit`/`vmap`), or an
        `eqx.error_if` runtime error inside them. With `throw=False`, check `sol.success`.
    progress: show a tqdm progress bar for the ODE method.
    adjoint: how the ODE method is differentiated: `None` (reverse mode with recursive
        checkpointing, diffrax's default), `"forward"` (`diffrax.ForwardMode()`: use with
        `jax.jacfwd`/`jax.jvp`; cheaper when there are few parameters) or any diffrax adjoint.

    Works under `jax.jit`, `jax.vmap` and `jax.grad` (the modal method differentiates with
    respect to the input's parameters only: JAX does not differentiate eigenvectors).
    """
    if method not in _METHODS:
        raise ValueError(f"simulate: `method` must be one of {_METHODS}; got {method!r}")
    if not isinstance(scene, Scene):
        raise ValueError(f"simulate expects a jaxbelt.Scene; got {type(scene).__name__}")
    model, inp = scene.model, scene.input
    if isinstance(inp, ExponentialVoltage) and jnp.ndim(inp.gamma) == 1:
        # A batch of time constants in one command: solved together by the batched closed form
        # (shared modal decomposition, only the exp(-t/gamma) response differs per element).
        if method not in ("auto", "closed"):
            raise ValueError(
                f"simulate: a command with a batch of gammas (shape {jnp.shape(inp.gamma)}) is solved by the "
                f"batched closed form (method='auto'); for method={method!r} use jax.vmap over scalar gammas"
            )
        batched = _batched_exponential_scene(scene)
        if batched is None:
            raise ValueError(
                "simulate: a batch of gammas needs a belt start-up model with scalar parameters, output times `ts` "
                "and no integral outputs; otherwise use jax.vmap over scalar gammas"
            )
        if throw and is_concrete(batched.success) and not bool(np.all(np.asarray(batched.success))):
            bad = np.flatnonzero(~np.asarray(batched.success))
            raise SolveError(f"simulate: non-finite values in the batched start-up scene at elements {bad.tolist()}")
        return batched
    integrals = [n for n in scene.observe if n in model.integral_names()]
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
    if method == "rk4":
        if scene.ts is None:
            raise ValueError("simulate: method='rk4' needs output times `ts` (use Scene(..., ts=...))")
        if scene.max_spacing is None:
            raise ValueError(
                "simulate: method='rk4' needs output times whose values are known when the Scene is built "
                "(a numpy array or a concrete jax array, not a traced one)"
            )
        if not is_concrete(dt) or not float(dt) > 0:
            raise ValueError(f"simulate: `dt` (RK4 step, s) must be a concrete number > 0; got {dt}")
    if solver is None and method == "ode":
        solver = model.default_solver()
    if method == "ode" and dt0 is None and not isinstance(solver, diffrax.AbstractAdaptiveSolver):
        raise ValueError(f"simulate: fixed-step solver {type(solver).__name__} needs `dt0` (step, s)")
    for name in ("rtol", "atol"):
        v = rtol if name == "rtol" else atol
        if is_concrete(v) and not float(np.asarray(v)) > 0:
            raise ValueError(f"simulate: `{name}` must be > 0; got {v}")
    if adjoint is None:
        adjoint = diffrax.RecursiveCheckpointAdjoint()
    elif adjoint == "forward":
        adjoint = diffrax.ForwardMode()
    elif not isinstance(adjoint, diffrax.AbstractAdjoint):
        raise ValueError(f"simulate: `adjoint` must be None, 'forward' or a diffrax adjoint; got {adjoint!r}")
    sol = _run(
        scene, method, solver, jnp.asarray(rtol, dtype=float), jnp.asarray(atol, dtype=float),
        None if dt0 is None else jnp.asarray(dt0, dtype=float),
        _rk4_substeps(scene.max_spacing, dt) if method == "rk4" else 1,
        int(max_steps), bool(progress), adjoint,
    )
    if throw:
        what = f"{type(model).__name__} driven by {type(inp).__name__} (method={method!r})"
        if is_concrete(sol.success):
            if not bool(np.all(np.asarray(sol.success))):
                raise SolveError(
                    f"simulate failed for the scene {what}: the solver did not reach the final time or produced "
                    "non-finite values. Try method='ode' with an implicit solver (diffrax.Kvaerno5()), "
                    "looser tolerances or a larger max_steps."
                )
        else:
            msg = f"jaxbelt.simulate failed for the scene {what} (non-finite values or step budget exhausted)"
            sol = eqx.tree_at(lambda s: s.success, sol, eqx.error_if(sol.success, ~sol.success, msg))
    return sol
