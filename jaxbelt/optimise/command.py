"""Optimisation of pseudo-polynomial motion commands (Incerti, pseudo-polynomial commands, section V, and beyond).

`optimise_command` minimises the paper's target, the residual *energy* $\\mathcal H(\\gamma)$ of eq. (32), over
the exponents (optax L-BFGS, one jitted step per iteration). `optimise_robust` minimises the residual *amplitude*
over a band of natural frequencies (the measure of input-shaping practice: the platform's residual deflection
$|\\lambda||W|/\\omega_d$, as a fraction of a reference command's), with the exponent optimiser of
`jaxbelt.shaping.pseudo` (L-BFGS directions from optax, an Armijo line search, the band a `vmap`). Both report
progress with tqdm.

Feasibility by reparametrisation. The exponents must be distinct and each exceed $b = \\max(n, 2)$. The
optimisers work on unconstrained $\\theta\\in\\mathbb R^{n+1}$: every $\\theta$ maps to sorted exponents with
$\\gamma_0 > b$, gaps at least $\\delta$ and increments at most $\\delta + s$ (`margin` ε, `gap` δ, `max_step` s);
no iterate, line-search trials included, is ever infeasible and nothing is clipped; the cap $s$ keeps trial points
from running to exponents so large that $\\gamma + \\delta = \\gamma$ in floating point. `optimise_command` uses
$\\gamma_0 = b + \\epsilon + s\\,\\sigma(\\theta_0)$, $\\gamma_i = \\gamma_{i-1} + \\delta + s\\,\\sigma(\\theta_i)$
($\\sigma$ the logistic function): the zero set of $\\mathcal H$ it looks for lies inside the box. `optimise_robust`
uses the sine map of `jaxbelt.shaping.pseudo` ($s\\sin^2\\theta_i$ for $s\\,\\sigma(\\theta_i)$): the band optimum
lies on the faces of the box, which the logistic map puts at θ = ±∞, where the robust optimiser used to freeze short
of the optimum (see `jaxbelt.shaping.pseudo`). The objectives are symmetric under permutation of the exponents, so
sorting loses nothing.

Sensitivity tools (`sensitivity_curve`, `tolerance_band`) evaluate a command's residual amplitude (or, as in the
paper, the energy $E(T) = h\\mathcal H$ [J]) on platforms whose belt stiffness is scaled so that the natural
frequency sweeps a band around the design value, and `shaped_commands` gives the ZV/ZVD shapers of a base command
at the same total move time.
"""

from __future__ import annotations

import functools
import warnings
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._checks import check_int, check_nonnegative, check_penalised_limits, check_positive, check_range, is_concrete
from .._display import Display, Table
from .._guard import host_checked, prepare
from .._threads import blas_limited
from .._xla import QUICK_COMPILE
from ..commands import MIN_EXPONENT_GAP, PseudoPolynomial, ShapedCommand
from ..models.platform import BeltPlatform
from ..objectives.residual import _w_quadrature, residual_energy, residual_energy_joules


# --------------------------------------------------------------------------------------------
# Reparametrisation
# --------------------------------------------------------------------------------------------
def gammas_from_params(theta, lower, margin, gap, max_step):
    """Map unconstrained `theta` to sorted exponents: $\\gamma_0 >$ `lower`, gaps > `gap` (the logistic map of
    `optimise_command`)."""
    inc = max_step * jax.nn.sigmoid(theta)
    steps = jnp.concatenate([jnp.stack([lower + margin]), jnp.full((theta.shape[0] - 1,), gap)])
    return jnp.cumsum(steps + inc)


def params_from_gammas(gammas, lower, margin, gap, max_step):
    """Inverse of `gammas_from_params` (the start point must lie inside its box)."""
    g = jnp.sort(jnp.asarray(gammas, dtype=float))
    d = jnp.diff(jnp.concatenate([jnp.stack([jnp.asarray(lower, dtype=float)]), g]))
    steps = jnp.concatenate([jnp.stack([jnp.asarray(margin, dtype=float)]), jnp.full((g.shape[0] - 1,), gap)])
    x = (d - steps) / max_step
    return jnp.log(x) - jnp.log1p(-x)


# --------------------------------------------------------------------------------------------
# The problem (an eqx.Module so that one compiled step serves every call with the same shapes)
# --------------------------------------------------------------------------------------------
class ShapingProblem(eqx.Module):
    """Objective of `optimise_command` as a function of the unconstrained parameters: the paper's residual energy
    $\\mathcal H(\\gamma)/\\mathcal H_0$ (eq. 32) on the nominal platform. Soft limits add
    $w\\,\\max(0, x/x_{max} - 1)^2$ for the peak motor speed and acceleration (sampled on `n_peak` times).
    """

    plat: BeltPlatform
    displacement: jnp.ndarray
    duration: jnp.ndarray
    lower: float = eqx.field(static=True)
    margin: jnp.ndarray
    gap: jnp.ndarray
    max_step: jnp.ndarray
    scale: jnp.ndarray
    max_speed: jnp.ndarray | None = None
    max_accel: jnp.ndarray | None = None
    penalty: jnp.ndarray = eqx.field(default_factory=lambda: jnp.asarray(10.0))
    n_nodes: int = eqx.field(static=True, default=128)
    n_peak: int = eqx.field(static=True, default=401)

    def gammas(self, theta):
        return gammas_from_params(theta, self.lower, self.margin, self.gap, self.max_step)

    def command(self, theta):
        return PseudoPolynomial(self.gammas(theta), self.displacement, self.duration)

    def raw(self, theta):
        """Unscaled objective: the residual energy H [rad²/s⁴]."""
        return residual_energy(self.plat, self.command(theta), n_nodes=self.n_nodes)

    def penalties(self, theta):
        cmd = self.command(theta)
        ts = jnp.linspace(0.0, 1.0, self.n_peak) * self.duration
        out = jnp.asarray(0.0)
        if self.max_speed is not None:
            peak = jnp.max(jnp.abs(cmd.velocity(ts)))
            out = out + self.penalty * jax.nn.relu(peak / self.max_speed - 1.0) ** 2
        if self.max_accel is not None:
            peak = jnp.max(jnp.abs(cmd.acceleration(ts)))
            out = out + self.penalty * jax.nn.relu(peak / self.max_accel - 1.0) ** 2
        return out

    def __call__(self, theta):
        return self.raw(theta) / self.scale + self.penalties(theta)


class CommandOptimResult(eqx.Module):
    """Result of `optimise_command` / `optimise_robust`.

    - `gammas`: final exponents (sorted); `command`: the optimised `PseudoPolynomial`;
    - `value`: final objective: $\\mathcal H$ [rad²/s⁴] for `optimise_command`, the band
      measure for `optimise_robust`; `initial_value`: the same at the start point;
    - `history`: objective after each iteration (index 0: start), `gammas_history` likewise;
      the result is the best iterate (lowest objective), normally the last;
    - `n_steps`, `converged` (a stopping test met: gradient or objective below its tolerance, or, for
      `optimise_robust`, no descent left at the objective's rounding level); `message`: why the run stopped;
    - `peak_speed` [rad/s], `peak_accel` [rad/s²] of the final motor command;
    - `objective`, `objective_unit`: what `value` is, and its unit (for the displays).

    In a notebook the result shows as an HTML table (objective and exponents, start and final); `str()` is the
    same as text.
    """

    gammas: jnp.ndarray
    value: jnp.ndarray
    initial_value: jnp.ndarray
    history: jnp.ndarray
    gammas_history: jnp.ndarray
    command: PseudoPolynomial
    n_steps: int = eqx.field(static=True)
    converged: bool = eqx.field(static=True)
    peak_speed: jnp.ndarray | None = None
    peak_accel: jnp.ndarray | None = None
    message: str = eqx.field(static=True, default="")
    objective: str = eqx.field(static=True, default="objective")
    objective_unit: str = eqx.field(static=True, default="")

    @property
    def relative(self):
        """`value / initial_value`."""
        return self.value / self.initial_value

    def _display(self) -> Display:
        g0 = (
            np.asarray(self.gammas_history)[0]
            if np.ndim(self.gammas_history) == 2
            else np.full(np.shape(self.gammas), np.nan)
        )
        rows = [(self.objective, float(self.initial_value), float(self.value), self.objective_unit)]
        rows += [(f"γ{i + 1}", float(a), float(b), "–") for i, (a, b) in enumerate(zip(g0, np.asarray(self.gammas)))]
        fields = [
            ("objective / start", float(self.relative), ""),
            ("steps", self.n_steps, ""),
            ("converged", self.converged, ""),
        ]
        if self.message:
            fields.append(("message", self.message, ""))
        if self.peak_speed is not None:
            fields.append(("peak motor speed", float(self.peak_speed), "rad/s"))
        if self.peak_accel is not None:
            fields.append(("peak motor acceleration", float(self.peak_accel), "rad/s²"))
        table = Table(("quantity", "start", "final", "unit"), tuple(rows), caption="objective and exponents")
        return Display("jaxbelt CommandOptimResult", tuple(fields), (table,))

    def _repr_html_(self):
        return self._display().html() if is_concrete(self) else None

    def __str__(self) -> str:
        return self._display().text() if is_concrete(self) else repr(self)


def _check_run_options(owner: str, optimizer, max_steps, tol, gtol, progress) -> int:
    """The loop's options, before anything is built: `optimizer` (see `_check_optimizer`), `max_steps` an integer
    >= 0 (0: the start), `tol` and `gtol` finite and >= 0 (NaN would never stop the loop by them), `progress` a
    bool. Returns `max_steps`."""
    _check_optimizer(owner, optimizer)
    max_steps = check_int(owner, "max_steps", max_steps, 0)
    check_nonnegative("tol", tol, owner=owner)
    check_nonnegative("gtol", gtol, owner=owner)
    if not isinstance(progress, bool | np.bool_):
        raise TypeError(f"{owner}: parameter `progress` must be True or False; got {progress!r}")
    return max_steps


def _check_optimizer(owner: str, optimizer) -> None:
    """`optimizer`: "lbfgs", "adam" or an optax `GradientTransformation` (anything with `init` and `update`)."""
    if isinstance(optimizer, str):
        if optimizer not in ("lbfgs", "adam"):
            raise ValueError(
                f"{owner}: parameter `optimizer` must be 'lbfgs' or 'adam' (or an optax transformation); got "
                f"{optimizer!r}"
            )
    elif not (callable(getattr(optimizer, "init", None)) and callable(getattr(optimizer, "update", None))):
        raise TypeError(
            f"{owner}: parameter `optimizer` must be 'lbfgs', 'adam' or an optax GradientTransformation; got "
            f"{type(optimizer).__name__}"
        )


@functools.cache
def _named_optimizer(name: str, learning_rate):
    # cached so that repeated runs reuse the same transformation object (and the compiled step)
    if name == "lbfgs":
        return optax.lbfgs(learning_rate=learning_rate)
    if name == "adam":
        return optax.adam(learning_rate if learning_rate is not None else 0.05)
    raise ValueError(f"optimiser name must be 'lbfgs' or 'adam' (or pass an optax transformation); got {name!r}")


def _transformation(opt, learning_rate):
    # the programs take a named optimiser by its name (a plain static value: the program store keeps them)
    return _named_optimizer(opt, learning_rate) if isinstance(opt, str) else opt


def _peaks(cmd):
    ts = jnp.linspace(0.0, 1.0, 2001) * cmd.duration
    return jnp.max(jnp.abs(cmd.velocity(ts))), jnp.max(jnp.abs(cmd.acceleration(ts)))


def _report(problem, theta):
    """What the result reports at `theta`: the command, H [rad²/s⁴] and its peak motor speed and acceleration."""
    cmd = problem.command(theta)
    return (cmd, problem.raw(theta)) + _peaks(cmd)


def _start_impl(opt, learning_rate, problem, cmd):
    # one program for the start: the parameters of `cmd`, the scale H0, the optimiser state and the start's report
    theta = params_from_gammas(cmd.gammas, problem.lower, problem.margin, problem.gap, problem.max_step)
    h0 = residual_energy(problem.plat, cmd, n_nodes=problem.n_nodes)
    problem = eqx.tree_at(lambda p: p.scale, problem, h0)
    state = _transformation(opt, learning_rate).init(theta)
    # strong-typed leaves: optax initialises some line-search statistics as weak-typed Python
    # scalars, which would make the first update's state differ in type and compile the step twice
    state = jax.tree_util.tree_map(lambda x: jax.lax.convert_element_type(x, x.dtype) if eqx.is_array(x) else x, state)
    return theta, h0, state, problem(theta), problem.gammas(theta), _report(problem, theta)


def _step_impl(opt, learning_rate, problem, theta, state, use_state_value: bool):
    fn = _transformation(opt, learning_rate)
    if use_state_value:
        value, grad = optax.value_and_grad_from_state(problem)(theta, state=state)
    else:
        value, grad = jax.value_and_grad(problem)(theta)
    if isinstance(fn, optax.GradientTransformationExtraArgs):
        updates, state = fn.update(grad, state, theta, value=value, grad=grad, value_fn=problem)
    else:
        updates, state = fn.update(grad, state, theta)
    theta = optax.apply_updates(theta, updates)
    return (
        theta,
        state,
        problem(theta),
        jnp.max(jnp.abs(cast(jax.Array, grad))),
        problem.gammas(theta),
        _report(problem, theta),
    )


# Compiled once per structure, checks returned as values (`host_checked`): JAX's persistent cache and jaxbelt's
# program store (`jb.enable_compilation_cache`) keep them, so a later process neither traces nor compiles them.
#: XLA's quicker compilation for these top-level programs (LLVM level 0, the classic CPU emitters, as
#: `jaxbelt.shaping.design`): the cold first call compiles them in half the time; the same HLO, results equal to
#: rounding, and the run time (about ten steps) is not what a first call waits for
_COMPILE = QUICK_COMPILE
_start = host_checked(_start_impl, store=True, compiler_options=_COMPILE)
_step = host_checked(_step_impl, store=True, compiler_options=_COMPILE)


def _prepare_programs(problem, cmd, optimizer, learning_rate, use_state_value: bool, max_steps: int) -> None:
    """Trace the start program and start compiling it in the background (`jaxbelt._guard.prepare`), then trace the
    step program from the start's output types while the start compiles (XLA releases the GIL: on two cores the two
    overlap).
    The calls that follow find the programs compiled or compiling."""
    types = prepare(_start, optimizer, learning_rate, problem, cmd)
    if types is None or max_steps == 0:
        return
    theta, h0, state = types[:3]
    prepare(_step, optimizer, learning_rate, eqx.tree_at(lambda p: p.scale, problem, h0), theta, state, use_state_value)


def _run(problem: ShapingProblem, cmd, optimizer, learning_rate, max_steps, tol, gtol, progress, desc):
    max_steps = _check_run_options(desc, optimizer, max_steps, tol, gtol, progress)
    if isinstance(optimizer, str):
        use_state_value = optimizer == "lbfgs"
        _named_optimizer(optimizer, learning_rate)
    else:
        use_state_value = False
    _prepare_programs(problem, cmd, optimizer, learning_rate, use_state_value, max_steps)
    theta, h0, state, f0, g0, start = _start(optimizer, learning_rate, problem, cmd)
    problem = eqx.tree_at(lambda p: p.scale, problem, h0)
    hist = [float(f0)]
    ghist = [np.asarray(g0)]
    converged = False
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_steps, desc=desc, leave=False)
    n = 0
    stall = 0
    best_f, best = hist[0], start
    for n in range(1, max_steps + 1):
        theta, state, f, gmax, g, report = _step(optimizer, learning_rate, problem, theta, state, use_state_value)
        f = float(f)
        if not np.isfinite(f):
            raise FloatingPointError(f"{desc}: the objective became non-finite at iteration {n}")
        stall = stall + 1 if f >= best_f * (1 - 1e-12) else 0
        if f < best_f:
            best_f, best = f, report
        hist.append(f)
        ghist.append(np.asarray(g))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(objective=f"{f:.3e}")
        # first-order methods (adam) oscillate by design and run to max_steps
        if f <= tol or float(gmax) <= gtol or (use_state_value and stall >= 5):
            converged = f <= tol or float(gmax) <= gtol
            if f <= tol:
                message = f"converged: objective {f:.2e} <= tol {tol:g}"
            elif float(gmax) <= gtol:
                message = f"converged: largest gradient component {float(gmax):.1e} <= gtol {gtol:g}"
            else:
                message = f"stopped: no decrease in 5 iterations, largest gradient component {float(gmax):.1e}"
            break
    else:
        message = f"stopped at the iteration limit (max_steps = {max_steps})"
    if bar is not None:
        bar.close()
    # a line search that fails may still move; report the best iterate, not the last
    cmd_best, value, vmax, amax = best
    return CommandOptimResult(
        gammas=cmd_best.gammas,
        value=value,
        initial_value=start[1],
        # recorded on the scaled objective (penalties included); reported in the units of `value`
        history=_device(np.asarray(hist) * float(h0)),
        gammas_history=_device(np.stack(ghist)),
        command=cmd_best,
        n_steps=int(n),
        converged=bool(converged),
        peak_speed=vmax,
        peak_accel=amax,
        message=message,
        objective="residual energy H",
        objective_unit="rad²/s⁴",
    )


def _device(x):
    """A host value as a float array on the device (`jax.device_put`: no program compiled, unlike `jnp.asarray`)."""
    return jax.device_put(np.asarray(x, dtype=float))


def _check_options(owner, margin, gap, max_speed, max_accel, penalty, learning_rate):
    """The optimisers' scalar options: a limit <= 0 would switch its penalty off, a negative penalty would
    reward breaking it, and a margin or gap below the exponents' own minimum would let an iterate leave
    the commands `PseudoPolynomial` accepts."""
    check_penalised_limits(owner, penalty, (("max_speed", max_speed, "rad/s"), ("max_accel", max_accel, "rad/s^2")))
    check_positive("margin", margin, owner=owner)
    if not float(gap) >= MIN_EXPONENT_GAP:
        raise ValueError(
            f"{owner}: parameter `gap` must be >= {MIN_EXPONENT_GAP:g} (the least distance between "
            f"exponents that PseudoPolynomial accepts); got {gap}"
        )
    if learning_rate is not None:
        check_positive("learning_rate", learning_rate, owner=owner)


def _warn_at_bounds(owner: str, g: np.ndarray, lower: float, margin: float) -> None:
    """`UserWarning` where the start exponents `g` (sorted) lie a hair from the bounds `PseudoPolynomial` sets:
    the lowest closer than `margin` to max(n, 2), or two closer than 2 x `MIN_EXPONENT_GAP`. The start is
    valid, but the optimiser's box then reaches (nearly) to the bound, where the command's acceleration at
    t = T (γ -> 2) or its coefficients (γ_i -> γ_j, growing as 1/gap) are unbounded and the objective and its
    gradient lose their accuracy; an iterate may also fall below the least gap, which fails at run time."""
    d0 = float(g[0] - lower)
    if d0 < margin:
        warnings.warn(
            f"{owner}: the lowest start exponent gammas[0] = {float(g[0])!r} is {d0:.3g} above its lower bound "
            f"max(n, 2) = {lower:g}, less than `margin` = {margin:g}: the optimiser's box reaches to within "
            f"{0.5 * d0:.3g} of the bound, where the acceleration at t = T grows without bound. Start from "
            f"gammas[0] >= {lower + margin:g} (e.g. {lower + 1.0:g}), or pass a smaller `margin`",
            UserWarning,
            stacklevel=5,
        )
    diffs = np.diff(g)
    k = int(np.argmin(diffs))
    if diffs[k] < 2 * MIN_EXPONENT_GAP:
        warnings.warn(
            f"{owner}: the start exponents gammas = {float(g[k])!r} and {float(g[k + 1])!r} differ by {float(diffs[k]):.3g}, "
            f"less than twice the least gap {MIN_EXPONENT_GAP:g} that PseudoPolynomial accepts: the optimiser's "
            "box reaches to the bound, where the coefficients grow as 1/gap (an iterate below the least gap fails "
            f"at run time). Spread the start exponents at least {2 * MIN_EXPONENT_GAP:g} apart (e.g. one apart)",
            UserWarning,
            stacklevel=5,
        )


def _bounds(cmd: PseudoPolynomial, margin, gap, max_step, owner: str = "optimise_command"):
    g = np.sort(np.asarray(cmd.gammas, dtype=float))
    lower = float(max(cmd.order, 2))
    _warn_at_bounds(owner, g, lower, float(margin))
    margin = min(float(margin), 0.5 * (g[0] - lower))
    gap = min(float(gap), 0.5 * float(np.min(np.diff(g))))
    if not float(max_step) > 0:
        raise ValueError(f"`max_step` must be > 0; got {max_step}")
    d = np.diff(np.concatenate([[lower], g])) - np.array([margin] + [gap] * (len(g) - 1))
    if np.any(d >= float(max_step)):
        raise ValueError(
            f"start exponents {g.tolist()} need increments up to {float(np.max(d)):.3g} above the minimum gaps; "
            f"raise `max_step` (now {max_step}) above that"
        )
    return lower, margin, gap


@blas_limited
def optimise_command(
    plat,
    cmd: PseudoPolynomial,
    *,
    optimizer="lbfgs",
    learning_rate=None,
    max_steps: int = 200,
    tol: float = 1e-14,
    gtol: float = 1e-15,
    margin: float = 1e-3,
    gap: float = 1e-3,
    max_step: float = 10.0,
    max_speed=None,
    max_accel=None,
    penalty: float = 10.0,
    n_nodes: int = 128,
    progress: bool = True,
) -> CommandOptimResult:
    """Minimise the residual energy $\\mathcal H(\\gamma)$ (eq. 32) over the exponents of `cmd`.

    Starts from `cmd.gammas` (the paper: (3, 4, 5)); keeps Φ and T. The objective is
    $\\mathcal H/\\mathcal H_0$ (+ optional soft limits `max_speed` [rad/s] and `max_accel`
    [rad/s²] on the motor command, weight `penalty`). Stops when the scaled objective drops below
    `tol`, the largest gradient component below `gtol`, after 5 iterations without decrease, or
    after `max_steps`.

    - `optimizer`: `"lbfgs"` (default, `optax.lbfgs` with zoom line search), `"adam"`, or any
      optax `GradientTransformation`.
    - `margin`, `gap`, `max_step`: bounds of the reparametrisation (module docstring).
    - `progress`: tqdm bar.

    Returns a `CommandOptimResult`; `value` is $\\mathcal H$ [rad²/s⁴]. The zero set of
    $\\mathcal H$ is a curve, so judge success by `value / initial_value`, not by the exponents.
    """
    if not isinstance(cmd, PseudoPolynomial):
        raise ValueError(f"optimise_command: `cmd` must be a PseudoPolynomial; got {type(cmd).__name__}")
    _check_options("optimise_command", margin, gap, max_speed, max_accel, penalty, learning_rate)
    _check_run_options("optimise_command", optimizer, max_steps, tol, gtol, progress)
    lower, margin, gap = _bounds(cmd, margin, gap, max_step)
    problem = ShapingProblem(
        plat=plat,
        displacement=cmd.displacement,
        duration=cmd.duration,
        lower=lower,
        margin=_device(margin),
        gap=_device(gap),
        max_step=_device(max_step),
        scale=_device(1.0),  # H0, set by the start program
        max_speed=None if max_speed is None else _device(max_speed),
        max_accel=None if max_accel is None else _device(max_accel),
        penalty=_device(penalty),
        n_nodes=n_nodes,
    )
    return _run(problem, cmd, optimizer, learning_rate, max_steps, tol, gtol, progress, "optimise_command")


@blas_limited
def optimise_robust(
    plat,
    cmd: PseudoPolynomial,
    *,
    band=(0.8, 1.2),
    n_freq: int = 25,
    mode: str = "mean",
    reference: PseudoPolynomial | None = None,
    optimizer="lbfgs",
    learning_rate=None,
    max_steps: int = 400,
    tol: float = 0.0,
    gtol: float = 1e-4,
    margin: float = 1e-3,
    gap: float = 0.5,
    max_step: float = 10.0,
    max_speed=None,
    max_accel=None,
    penalty: float = 1e4,
    n_nodes: int = 128,
    progress: bool = True,
) -> CommandOptimResult:
    """Minimise the residual vibration *amplitude* over a band of natural frequencies (robust shaping).

    $A(\\omega) = |\\lambda||W(s)|/\\omega_d$ [rad] is the amplitude of the platform's residual deflection after the
    move on the platform with its belt stiffness scaled to natural frequency ω (`BeltPlatform.with_natural_frequency`:
    J and c kept, so ξ scales as 1/ω), for `n_freq` frequencies in `band` × $\\omega_n$. Objective:
    `mode="mean"`: $\\overline{A_\\gamma}/\\overline{A_{ref}}$; `mode="max"`: the worst $A_\\gamma/\\max A_{ref}$, as a
    power mean of the ratios with the power raised 4 → 16 → 64 → 256 (a smooth maximum that converges to the
    maximum). The reference is the 3-4-5 polynomial (or `reference`) with the same Φ and T. The amplitude, not the
    energy: the energy weighs the band by $\\omega^2$ and squares the amplitude (its "5 %" is a 22 % amplitude).

    Guarantees: the result is never worse than the start, neither by the band measure (the best iterate is returned)
    nor at the design frequency: the amplitude at $\\omega_n$ is held at or below the start's (a penalty, checked
    on the result; were it broken the start is returned, not converged). `converged` is True only when a stopping
    test is met (largest gradient component of the log of the measure <= `gtol`, the measure <= `tol`, or no
    descent left at the objective's rounding level with the gradient <= 1e-2), and `message` says why it stopped.

    - `cmd`: the start (its order n; every exponent > max(n, 2)); higher orders (4 to 6 exponents) give more freedom;
    - `optimizer`: `"lbfgs"` (default: optax's L-BFGS direction with an Armijo backtracking line search), `"adam"`
      (`learning_rate`, default 0.05), or any optax `GradientTransformation` (its update taken as the step);
    - `max_steps`: iterations in all (shared by the stages); `margin`, `gap`, `max_step`: the exponent map (module
      docstring; the gap defaults to 0.5: clustered exponents make the coefficients grow like gap$^{-n}$, and the
      objective's rounding noise with them, which stalls the line search);
    - `max_speed` [rad/s], `max_accel` [rad/s²]: limits on the motor command, as penalties of weight `penalty`;
    - `n_nodes`: Gauss-Legendre nodes, raised where the band's highest frequency needs more (about
      $2.5\\omega T + 64$).

    `value` is the final band measure (for `"max"` the worst ratio on the grid), `initial_value` the start's;
    `history` the smoothed measure (penalties included) after each iteration, stage after stage; `gammas_history`
    the exponents at the start and at the end of each stage.
    """
    from ..models.axis import ModalAxis
    from ..shaping import pseudo as _pp

    o = "optimise_robust"
    if not isinstance(cmd, PseudoPolynomial):
        raise ValueError(f"{o}: `cmd` must be a PseudoPolynomial; got {type(cmd).__name__}")
    if mode not in ("mean", "max"):
        raise ValueError(f"{o}: `mode` must be 'mean' or 'max'; got {mode!r}")
    lo_b, hi_b = float(band[0]), float(band[1])
    if not (0 < lo_b < hi_b):
        raise ValueError(f"{o}: `band` must satisfy 0 < low < high (fractions of omega_n); got {band}")
    _check_options(o, margin, gap, max_speed, max_accel, penalty, learning_rate)
    n_freq = check_int(o, "n_freq", n_freq, 2)
    n_nodes = check_int(o, "n_nodes", n_nodes, 8)
    max_steps = _check_run_options(o, optimizer, max_steps, tol, gtol, progress)
    check_positive("gtol", gtol, owner=o)
    # the reference's exponents (the 3-4-5 polynomial by default: no command built, no program run)
    g_ref = np.array([3.0, 4.0, 5.0]) if reference is None else np.sort(np.asarray(reference.gammas, dtype=float))
    lower, margin, gap = _bounds(cmd, margin, gap, max_step, o)
    # the band as modes of one axis: frequency omega_k, damping ratio xi * omega_n / omega_k (c kept), gain lambda;
    # the last mode is the nominal platform (the design frequency)
    wn, xi, lam = (float(x) for x in _platform_scalars(plat))
    omegas = np.linspace(lo_b, hi_b, n_freq) * wn
    if not float(np.max(xi * wn / omegas)) < 1.0:
        raise ValueError(f"{o}: the band reaches an overdamped platform (xi >= 1 at {lo_b:g} omega_n); raise `band`")
    w_all = np.concatenate([omegas, [wn]])
    axis = ModalAxis(w_all / (2 * np.pi), xi * wn / w_all, np.full(w_all.shape, lam))
    T, phi = float(cmd.duration), float(cmd.displacement)
    n_nodes = max(n_nodes, _pp.n_nodes_for(float(np.max(w_all)) * T))  # the rule must resolve the band
    kern1 = _pp._kernels_np(axis, T, np.ones(1), np.ones(n_freq + 1), n_nodes)
    pad = np.ones((1, g_ref.shape[0]))
    a_ref, _ = _pp._evaluate_np(kern1, n_freq + 1, n_nodes, phi, T, g_ref[None], pad)
    a_ref = a_ref[0, :n_freq, 0]
    scale = float(np.max(a_ref)) if mode == "max" else float(np.mean(a_ref))
    kern = _pp._kernels_np(axis, T, np.ones(1), np.full(n_freq + 1, scale), n_nodes)
    band_w = np.concatenate([np.full(n_freq, 1.0 / n_freq), [0.0]])[:, None]
    g0 = np.sort(np.asarray(cmd.gammas, dtype=float))
    # exponent slots padded to a fixed count (inactive ones masked out): one compiled program for orders up to 7
    slots = max(_SLOTS, g0.shape[0])
    act = (np.arange(slots) < g0.shape[0]).astype(float)[None]
    g0_pad = np.concatenate([g0, g0[-1] + (1.0 + gap) * np.arange(1, slots - g0.shape[0] + 1)])
    r0, _ = _pp._evaluate_np(kern, n_freq + 1, n_nodes, phi, T, g0_pad[None], act)
    nominal0 = float(r0[0, -1, 0])
    guard = np.concatenate([np.full(n_freq, np.inf), [nominal0]])
    limits = (None if max_speed is None else float(max_speed), None if max_accel is None else float(max_accel), None)
    shared = _pp.make_shared(
        _device(kern), n_nodes, band_w, np.zeros(n_freq + 1), guard, phi, T, limits, max_step=float(max_step),
        margin=margin, penalty=float(penalty),
    )  # fmt: skip
    theta = _device(_pp._params_np(g0_pad, lower, margin, gap, float(max_step))[None])
    if isinstance(optimizer, str):
        opt = _pp.LBFGS if optimizer == "lbfgs" else _adam(learning_rate)
        linesearch = optimizer == "lbfgs"
    else:
        opt, linesearch = optimizer, False
    powers = (1.0,) if mode == "mean" else _pp.POWERS
    budget = [max_steps // len(powers)] * len(powers)
    budget[-1] += max_steps - sum(budget)
    hist, ghist = [], [g0]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(powers), desc=o, leave=False)
    n_steps, reason, gmax = 0, 2, float("nan")
    ftol = float(np.log(tol)) if tol > 0 else -np.inf
    try:
        for p, k in zip(powers, budget):
            runs = _pp.make_runs(
                act, lower, gap, p=p, w_band=1.0, w_guard=_pp.PENALTY, gtol=gtol, gtol_loose=_pp.ROBUST_GTOL_LOOSE, ftol=ftol,
                max_iter=k,
            )  # fmt: skip
            st = _pp.run_stage(opt, shared, runs, theta, n_hist=_N_HIST, linesearch=linesearch)
            theta = st.theta
            n_iter, history, st_reason, st_gmax = jax.device_get((st.n_iter, st.history, st.reason, st.gmax))
            done = int(n_iter[0])
            n_steps += done
            hist += np.exp(np.asarray(history[0, : min(done, _N_HIST)])).tolist()
            ghist.append(_pp._exponents_np(np.asarray(theta)[0], lower, margin, gap, float(max_step))[: g0.shape[0]])
            reason, gmax = int(st_reason[0]), float(st_gmax[0])
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    g = ghist[-1]
    r, _ = _pp._evaluate_np(kern, n_freq + 1, n_nodes, phi, T, g[None], np.ones((1, g.shape[0])))
    r = r[0, :, 0]
    measure = (lambda x: float(np.max(x))) if mode == "max" else (lambda x: float(np.mean(x)))
    value, value0 = measure(r[:n_freq]), measure(r0[0, :n_freq, 0])
    converged = reason in _pp.CONVERGED
    message = f"{_pp.REASONS[reason]} (largest gradient component {gmax:.1e})"
    if not (value <= value0 and r[-1] <= nominal0 * (1 + 1e-12)):
        # never end worse than the start, by the band measure or at the design frequency
        g, value, converged = g0, value0, False
        message = f"returned the start: the end point was worse than it ({message})"
    out, vmax, amax = _command_report(_device(g), cmd.displacement, cmd.duration)
    return CommandOptimResult(
        gammas=out.gammas,
        value=_device(value),
        initial_value=_device(value0),
        history=_device([value0] + hist),
        gammas_history=_device(np.stack(ghist)),
        command=out,
        n_steps=n_steps,
        converged=bool(converged),
        peak_speed=vmax,
        peak_accel=amax,
        message=message,
        objective="band measure (ratio to the reference)",
        objective_unit="–",
    )


def _platform_scalars_impl(plat):
    return plat.omega_n, plat.damping_ratio, plat.lam


def _command_report_impl(gammas, displacement, duration):
    cmd = PseudoPolynomial(gammas, displacement, duration)
    return (cmd,) + _peaks(cmd)


# optimise_robust's programs around the optimiser's own (`jaxbelt.shaping.pseudo`): one each, stored like
# optimise_command's, instead of a compiled program per eager operation
_platform_scalars = host_checked(_platform_scalars_impl, store=True)
_command_report = host_checked(_command_report_impl, store=True, compiler_options=_COMPILE)


#: iterations of optimise_robust's history kept per stage, and its exponent slots
_N_HIST = 512
_SLOTS = 8


@functools.cache
def _adam(learning_rate):
    return optax.adam(learning_rate if learning_rate is not None else 0.05)


# --------------------------------------------------------------------------------------------
# Sensitivity to the natural frequency, and input-shaper comparison
# --------------------------------------------------------------------------------------------
@blas_limited
def shaped_commands(plat, base: PseudoPolynomial, *, equal_time: bool = True) -> dict:
    """ZV and ZVD shapers (Singer and Seering, 1990) of `base`, tuned to the platform's $(\\omega_n, \\xi)$.

    `equal_time=True` (default): the comparison on equal terms: each shaped command ends at the same total time
    T as `base`: the base is the same pseudo-polynomial shortened by the shaper's length ($\\pi/\\omega_d$ for ZV,
    $2\\pi/\\omega_d$ for ZVD), so its peaks rise as $(T/T')$ and $(T/T')^2$. `equal_time=False`: the shaper is
    applied to `base` itself and lengthens the move by its own length. Raises ValueError when the shaper is as long
    as the move."""
    if not isinstance(equal_time, bool | np.bool_):
        raise TypeError(f"shaped_commands: parameter `equal_time` must be True or False; got {equal_time!r}")
    T = float(base.duration)
    out = {}
    for name, make in (("ZV", ShapedCommand.zv), ("ZVD", ShapedCommand.zvd)):
        probe = make(base, plat.omega_n, plat.damping_ratio)
        length = float(probe.times[-1])
        if not equal_time:
            out[name] = probe
            continue
        if not length < T:
            raise ValueError(
                f"shaped_commands: the {name} shaper lasts {length:.4g} s, not less than the move time {T:g} s; "
                "no shortened base can end at the same time"
            )
        short = PseudoPolynomial(base.gammas, base.displacement, T - length)
        out[name] = make(short, plat.omega_n, plat.damping_ratio)
    return out


@blas_limited
def sensitivity_curve(plat, commands: dict, *, rel: float = 0.3, n: int = 121, n_nodes: int = 128, measure="amplitude"):
    """The residual vibration of each command against the actual natural frequency.

    The belt stiffness is scaled so that $\\omega$ sweeps $[1-rel, 1+rel]\\,\\omega_n$ (`n` points; the design value
    sits at the centre when `n` is odd). `measure="amplitude"` (default): the amplitude of the platform's residual
    deflection $A = |\\lambda||W|/\\omega_d$ [rad] (the measure of input-shaping practice); `measure="energy"`: the
    paper's residual energy $E(T) = h\\mathcal H$ [J] (eq. 31). `rel` in (0, 1), `n` >= 2, `n_nodes` >= 1 (an
    integer: the quadrature's nodes).
    Returns `(omegas, {name: values})`.
    """
    o = "sensitivity_curve"
    check_range("rel", rel, 0.0, 1.0, lo_open=True, hi_open=True, owner=o)  # 1 - rel > 0: omega stays > 0
    n = check_int(o, "n", n, 2)
    n_nodes = check_int(o, "n_nodes", n_nodes, 1)
    if measure not in ("amplitude", "energy"):
        raise ValueError(f"{o}: parameter `measure` must be 'amplitude' or 'energy'; got {measure!r}")
    omegas = jnp.linspace(1.0 - rel, 1.0 + rel, n) * plat.omega_n
    f = _band_amplitude if measure == "amplitude" else _band_energy
    return omegas, {name: f(plat, cmd, omegas, n_nodes) for name, cmd in commands.items()}


@host_checked
def _band_energy(plat, cmd, omegas, n_nodes):
    return jax.vmap(lambda w: residual_energy_joules(plat.with_natural_frequency(w), cmd, n_nodes=n_nodes))(omegas)


@host_checked
def _band_amplitude(plat, cmd, omegas, n_nodes):
    def one(w):
        q = plat.with_natural_frequency(w)
        re, im = _w_quadrature(q, cmd, n_nodes)
        return jnp.abs(q.lam) / q.omega_d * jnp.hypot(re, im)

    return jax.vmap(one)(omegas)


@blas_limited
def tolerance_band(omegas, values, reference, omega0, level: float = 0.05):
    """Width of the frequency band around `omega0` where `values / reference < level`: with residual amplitudes
    (`sensitivity_curve`'s default) and the unshaped command's amplitude as `reference`, the "5 % band" of
    input-shaping practice (with energies, `level` = 0.05 is a 22 % amplitude).

    Returns the width as a fraction of `omega0` (0 when the ratio at `omega0` is not below the
    level), with the band edges found by linear interpolation of the ratio on the grid; a band
    that reaches the end of the grid is cut there. `omegas` [rad/s]: a strictly increasing grid;
    `values` of its shape, `reference` of its shape or a scalar; `omega0` within the grid; `level` > 0.
    """
    o = "tolerance_band"
    w = np.asarray(omegas, dtype=float)
    e, ref = np.asarray(values, dtype=float), np.asarray(reference, dtype=float)
    if w.ndim != 1 or w.size < 2 or not np.all(np.isfinite(w)) or not np.all(np.diff(w) > 0):
        raise ValueError(f"{o}: `omegas` must be a finite, strictly increasing 1-D grid of >= 2 frequencies [rad/s]")
    if e.shape != w.shape or ref.shape not in ((), w.shape):
        raise ValueError(
            f"{o}: `values` must have the shape of `omegas` {w.shape} and `reference` that shape or "
            f"none (a scalar); got {e.shape} and {ref.shape}"
        )
    check_positive("level", level, owner=o)
    check_positive("omega0", omega0, "rad/s", owner=o)
    if not (np.all(np.isfinite(e)) and np.all(e >= 0)):
        raise ValueError(f"{o}: parameter `values` must be finite and >= 0 (amplitudes or energies)")
    check_positive("reference", ref, owner=o)  # the ratio's denominator (0 divided by zero)
    if not w[0] <= float(omega0) <= w[-1]:
        raise ValueError(f"{o}: parameter `omega0` must lie within the grid [{w[0]:g}, {w[-1]:g}] rad/s; got {omega0}")
    r = e / ref
    i0 = int(np.argmin(np.abs(w - float(omega0))))
    if not r[i0] < level:
        return 0.0
    lo = i0
    while lo > 0 and r[lo - 1] < level:
        lo -= 1
    hi = i0
    while hi < len(w) - 1 and r[hi + 1] < level:
        hi += 1

    def cross(a, b):
        # the ratio crosses `level` between grid points a (below) and b (above)
        t = (level - r[a]) / (r[b] - r[a])
        return w[a] + t * (w[b] - w[a])

    w_lo = w[0] if lo == 0 else cross(lo, lo - 1)
    w_hi = w[-1] if hi == len(w) - 1 else cross(hi, hi + 1)
    return float((w_hi - w_lo) / float(omega0))
