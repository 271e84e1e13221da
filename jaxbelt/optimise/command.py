"""Optimisation of pseudo-polynomial motion commands (Incerti, pseudo-polynomial commands, section V, and beyond).

`optimise_command` minimises the residual energy $\\mathcal H(\\gamma)$ of eq. (32) over the
exponents; `optimise_robust` minimises the residual over a band of natural frequencies (a
`vmap` inside the objective). Both use optax (`optax.lbfgs` by default, any optax
transformation accepted) with one jitted step per iteration and a tqdm progress bar.

Feasibility by reparametrisation. The exponents must be distinct and each exceed
$b = \\max(n, 2)$. The optimiser works on unconstrained $\\theta\\in\\mathbb R^{n+1}$ with
$\\gamma_0 = b + \\epsilon + s\\,\\sigma(\\theta_0)$ and
$\\gamma_i = \\gamma_{i-1} + \\delta + s\\,\\sigma(\\theta_i)$ ($\\sigma$ the logistic function): every
$\\theta$ maps to sorted exponents with $\\gamma_0 > b$, gaps $> \\delta$ and increments below
$\\delta + s$ (defaults $\\epsilon = \\delta = 10^{-3}$, shrunk when the start point is closer than
that; `max_step` $s = 10$). No iterate, line-search trials included, is ever infeasible and
nothing is clipped; the cap $s$ keeps trial points from running to exponents so large that
$\\gamma + \\delta = \\gamma$ in floating point. H is symmetric under permutation of the
exponents, so sorting loses nothing.

Sensitivity tools (`sensitivity_curve`, `tolerance_band`) evaluate the residual energy
$E(T) = h\\mathcal H$ [J] of a command on platforms whose belt stiffness is scaled so that the
natural frequency sweeps a band around the design value, and compare with ZV/ZVD input shapers.
"""

from __future__ import annotations

import functools
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._checks import check_int, check_penalised_limits, check_positive, check_range
from .._guard import host_checked
from ..commands import MIN_EXPONENT_GAP, PseudoPolynomial, ShapedCommand
from ..models.platform import BeltPlatform
from ..objectives.residual import residual_energy, residual_energy_joules


# --------------------------------------------------------------------------------------------
# Reparametrisation
# --------------------------------------------------------------------------------------------
def gammas_from_params(theta, lower, margin, gap, max_step):
    """Map unconstrained `theta` to sorted exponents: $\\gamma_0 >$ `lower`, gaps > `gap`."""
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
    """Objective of the command optimisation as a function of the unconstrained parameters.

    `kind="nominal"`: $\\mathcal H(\\gamma)/\\mathcal H_0$. `kind="band"`: with residual energies
    $E(\\omega)$ on the frequency grid `omegas`, `mode="mean"` gives
    $\\overline{E_\\gamma}/\\overline{E_{ref}}$ (mean over the band, relative to the reference
    command's mean) and `mode="max"` a smooth maximum, the $L^{16}$ mean of
    $E_\\gamma(\\omega)/\\max E_{ref}$. Normalising by the reference's band mean or maximum, not
    pointwise, keeps the near-zeros of the reference's own residual curve from dominating.
    Soft limits add $w\\,\\max(0, x/x_{max} - 1)^2$ for the peak motor speed and acceleration
    (sampled on `n_peak` times).
    """

    plat: BeltPlatform
    displacement: jnp.ndarray
    duration: jnp.ndarray
    lower: float = eqx.field(static=True)
    margin: jnp.ndarray
    gap: jnp.ndarray
    max_step: jnp.ndarray
    scale: jnp.ndarray
    omegas: jnp.ndarray | None = None
    ref_energy: jnp.ndarray | None = None
    max_speed: jnp.ndarray | None = None
    max_accel: jnp.ndarray | None = None
    penalty: jnp.ndarray = eqx.field(default_factory=lambda: jnp.asarray(10.0))
    kind: str = eqx.field(static=True, default="nominal")
    mode: str = eqx.field(static=True, default="mean")
    n_nodes: int = eqx.field(static=True, default=128)
    n_peak: int = eqx.field(static=True, default=401)

    def gammas(self, theta):
        return gammas_from_params(theta, self.lower, self.margin, self.gap, self.max_step)

    def command(self, theta):
        return PseudoPolynomial(self.gammas(theta), self.displacement, self.duration)

    def raw(self, theta):
        """Unscaled objective: H [rad²/s⁴] (nominal) or the band measure (dimensionless)."""
        cmd = self.command(theta)
        if self.kind == "nominal":
            return residual_energy(self.plat, cmd, n_nodes=self.n_nodes)
        assert self.omegas is not None and self.ref_energy is not None  # a band problem has both
        e = jax.vmap(lambda w: residual_energy_joules(self.plat.with_natural_frequency(w), cmd, n_nodes=self.n_nodes))(
            self.omegas
        )
        if self.mode == "max":
            r = e / jnp.max(self.ref_energy)
            return jnp.mean(r**16) ** (1.0 / 16)
        return jnp.mean(e) / jnp.mean(self.ref_energy)

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
    - `n_steps`, `converged` (stopping test met before `max_steps`);
    - `peak_speed` [rad/s], `peak_accel` [rad/s²] of the final motor command.
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

    @property
    def relative(self):
        """`value / initial_value`."""
        return self.value / self.initial_value


@functools.cache
def _named_optimizer(name: str, learning_rate):
    # cached so that repeated runs reuse the same transformation object (and the compiled step)
    if name == "lbfgs":
        return optax.lbfgs(learning_rate=learning_rate)
    if name == "adam":
        return optax.adam(learning_rate if learning_rate is not None else 0.05)
    raise ValueError(f"optimiser name must be 'lbfgs' or 'adam' (or pass an optax transformation); got {name!r}")


@eqx.filter_jit
def _init(opt, problem, theta):
    # strong-typed leaves: optax initialises some line-search statistics as weak-typed Python
    # scalars, which would make the first update's state differ in type and compile the step twice
    state = opt.init(theta)
    return jax.tree_util.tree_map(lambda x: jax.lax.convert_element_type(x, x.dtype) if eqx.is_array(x) else x, state)


@host_checked
def _evaluate(problem, theta):
    return problem(theta), problem.gammas(theta)


@host_checked
def _step(opt, problem, theta, state, use_state_value: bool):
    if use_state_value:
        value, grad = optax.value_and_grad_from_state(problem)(theta, state=state)
    else:
        value, grad = jax.value_and_grad(problem)(theta)
    if isinstance(opt, optax.GradientTransformationExtraArgs):
        updates, state = opt.update(grad, state, theta, value=value, grad=grad, value_fn=problem)
    else:
        updates, state = opt.update(grad, state, theta)
    theta = optax.apply_updates(theta, updates)
    return theta, state, problem(theta), jnp.max(jnp.abs(cast(jax.Array, grad))), problem.gammas(theta)


def _run(problem: ShapingProblem, theta0, optimizer, learning_rate, max_steps, tol, gtol, progress, desc):
    if isinstance(optimizer, str):
        use_state_value = optimizer == "lbfgs"
        opt = _named_optimizer(optimizer, learning_rate)
    else:
        use_state_value = False
        opt = optimizer
    if max_steps < 0:
        raise ValueError(f"`max_steps` must be >= 0; got {max_steps}")
    theta = theta0
    state = _init(opt, problem, theta)
    f0, g0 = _evaluate(problem, theta)
    hist = [float(f0)]
    ghist = [np.asarray(g0)]
    converged = False
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_steps, desc=desc, leave=False)
    n = 0
    stall = 0
    best_f, best_theta = hist[0], theta
    for n in range(1, max_steps + 1):
        theta, state, f, gmax, g = _step(opt, problem, theta, state, use_state_value)
        f = float(f)
        if not np.isfinite(f):
            raise FloatingPointError(f"{desc}: the objective became non-finite at iteration {n}")
        stall = stall + 1 if f >= best_f * (1 - 1e-12) else 0
        if f < best_f:
            best_f, best_theta = f, theta
        hist.append(f)
        ghist.append(np.asarray(g))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(objective=f"{f:.3e}")
        # a line-search method that no longer decreases has converged as far as float64 allows;
        # first-order methods (adam) oscillate by design and run to max_steps
        if f <= tol or float(gmax) <= gtol or (use_state_value and stall >= 5):
            converged = f <= tol or float(gmax) <= gtol
            break
    if bar is not None:
        bar.close()
    # a line search that fails may still move; report the best iterate, not the last
    return best_theta, np.asarray(hist), np.stack(ghist), n, converged


@host_checked
def _final(problem, theta, theta0):
    cmd = problem.command(theta)
    ts = jnp.linspace(0.0, 1.0, 2001) * cmd.duration
    return (
        cmd,
        problem.raw(theta),
        problem.raw(theta0),
        jnp.max(jnp.abs(cmd.velocity(ts))),
        jnp.max(jnp.abs(cmd.acceleration(ts))),
    )


def _finish(problem, theta, theta0, hist, ghist, n, converged):
    cmd, value, v0, vmax, amax = _final(problem, theta, theta0)
    return CommandOptimResult(
        gammas=cmd.gammas,
        value=value,
        initial_value=v0,
        # recorded on the scaled objective (penalties included); reported in the units of `value`
        history=jnp.asarray(hist) * problem.scale,
        gammas_history=jnp.asarray(ghist),
        command=cmd,
        n_steps=int(n),
        converged=bool(converged),
        peak_speed=vmax,
        peak_accel=amax,
    )


_params_jit = jax.jit(params_from_gammas)


@host_checked
def _raw(problem, theta):
    return problem.raw(theta)


@host_checked
def _residual_jit(plat, cmd, n_nodes):
    return residual_energy(plat, cmd, n_nodes=n_nodes)


@host_checked
def _band_reference(plat, reference, omegas, n_nodes):
    return jax.vmap(lambda w: residual_energy_joules(plat.with_natural_frequency(w), reference, n_nodes=n_nodes))(
        omegas
    )


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


def _bounds(cmd: PseudoPolynomial, margin, gap, max_step):
    g = np.sort(np.asarray(cmd.gammas, dtype=float))
    lower = float(max(cmd.order, 2))
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
    lower, margin, gap = _bounds(cmd, margin, gap, max_step)
    theta0 = _params_jit(cmd.gammas, lower, margin, gap, max_step)
    h0 = _residual_jit(plat, cmd, n_nodes)
    problem = ShapingProblem(
        plat=plat,
        displacement=cmd.displacement,
        duration=cmd.duration,
        lower=lower,
        margin=jnp.asarray(margin),
        gap=jnp.asarray(gap),
        max_step=jnp.asarray(max_step, dtype=float),
        scale=h0,
        max_speed=None if max_speed is None else jnp.asarray(max_speed, dtype=float),
        max_accel=None if max_accel is None else jnp.asarray(max_accel, dtype=float),
        penalty=jnp.asarray(penalty, dtype=float),
        kind="nominal",
        n_nodes=n_nodes,
    )
    theta, hist, ghist, n, conv = _run(
        problem, theta0, optimizer, learning_rate, max_steps, tol, gtol, progress, "optimise_command"
    )
    return _finish(problem, theta, theta0, hist, ghist, n, conv)


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
    max_steps: int = 150,
    tol: float = 0.0,
    gtol: float = 1e-12,
    margin: float = 1e-3,
    gap: float = 0.25,
    max_step: float = 10.0,
    max_speed=None,
    max_accel=None,
    penalty: float = 10.0,
    n_nodes: int = 128,
    progress: bool = True,
) -> CommandOptimResult:
    """Minimise the residual energy over a band of natural frequencies (robust shaping).

    $E(\\omega)$ is the residual energy [J] on the platform with its belt stiffness scaled to
    natural frequency ω (`BeltPlatform.with_natural_frequency`), for `n_freq` frequencies in
    `band` × $\\omega_n$ (a `vmap` inside the objective). Objective (`ShapingProblem`):
    `mode="mean"`: $\\overline{E_\\gamma}/\\overline{E_{ref}}$; `mode="max"`: the $L^{16}$ mean of
    $E_\\gamma/\\max E_{ref}$ (a smooth worst case). The reference is the 3-4-5 polynomial (or
    `reference`) with the same Φ and T. Higher orders (4 or 5 exponents; each must exceed n)
    give more freedom.

    The minimum gap between exponents defaults to 0.25 here: the band optimum pushes exponents
    together, and clustered exponents make the $C_i$ grow like gap$^{-n}$ and cancel in floating
    point. `max_step` bounds each increment (module docstring).
    `value` is the final band measure; `initial_value` the start point's.
    """
    if not isinstance(cmd, PseudoPolynomial):
        raise ValueError(f"optimise_robust: `cmd` must be a PseudoPolynomial; got {type(cmd).__name__}")
    if mode not in ("mean", "max"):
        raise ValueError(f"optimise_robust: `mode` must be 'mean' or 'max'; got {mode!r}")
    lo_b, hi_b = float(band[0]), float(band[1])
    if not (0 < lo_b < hi_b):
        raise ValueError(f"optimise_robust: `band` must satisfy 0 < low < high (fractions of omega_n); got {band}")
    _check_options("optimise_robust", margin, gap, max_speed, max_accel, penalty, learning_rate)
    n_freq = check_int("optimise_robust", "n_freq", n_freq, 2)
    if reference is None:
        reference = PseudoPolynomial(jnp.array([3.0, 4.0, 5.0]), cmd.displacement, cmd.duration)
    omegas = jnp.linspace(lo_b, hi_b, n_freq) * plat.omega_n
    e_ref = _band_reference(plat, reference, omegas, n_nodes)
    lower, margin, gap = _bounds(cmd, margin, gap, max_step)
    theta0 = _params_jit(cmd.gammas, lower, margin, gap, max_step)
    problem = ShapingProblem(
        plat=plat,
        displacement=cmd.displacement,
        duration=cmd.duration,
        lower=lower,
        margin=jnp.asarray(margin),
        gap=jnp.asarray(gap),
        max_step=jnp.asarray(max_step, dtype=float),
        scale=jnp.asarray(1.0),
        omegas=omegas,
        ref_energy=e_ref,
        max_speed=None if max_speed is None else jnp.asarray(max_speed, dtype=float),
        max_accel=None if max_accel is None else jnp.asarray(max_accel, dtype=float),
        penalty=jnp.asarray(penalty, dtype=float),
        kind="band",
        mode=mode,
        n_nodes=n_nodes,
    )
    problem = eqx.tree_at(lambda p: p.scale, problem, _raw(problem, theta0))
    theta, hist, ghist, n, conv = _run(
        problem, theta0, optimizer, learning_rate, max_steps, tol, gtol, progress, "optimise_robust"
    )
    return _finish(problem, theta, theta0, hist, ghist, n, conv)


# --------------------------------------------------------------------------------------------
# Sensitivity to the natural frequency, and input-shaper comparison
# --------------------------------------------------------------------------------------------
def shaped_commands(plat, base: PseudoPolynomial) -> dict:
    """ZV and ZVD shapers of `base` tuned to the platform's $(\\omega_n, \\xi)$."""
    return {
        "ZV": ShapedCommand.zv(base, plat.omega_n, plat.damping_ratio),
        "ZVD": ShapedCommand.zvd(base, plat.omega_n, plat.damping_ratio),
    }


def sensitivity_curve(plat, commands: dict, *, rel: float = 0.3, n: int = 121, n_nodes: int = 128):
    """Residual energy $E(T)$ [J] of each command against the actual natural frequency.

    The belt stiffness is scaled so that $\\omega$ sweeps $[1-rel, 1+rel]\\,\\omega_n$ (`n`
    points; the design value sits at the centre when `n` is odd). `rel` in (0, 1), `n` >= 2.
    Returns `(omegas, {name: E})`.
    """
    o = "sensitivity_curve"
    check_range("rel", rel, 0.0, 1.0, lo_open=True, hi_open=True, owner=o)  # 1 - rel > 0: omega stays > 0
    n = check_int(o, "n", n, 2)
    omegas = jnp.linspace(1.0 - rel, 1.0 + rel, n) * plat.omega_n
    out = {}
    for name, cmd in commands.items():
        out[name] = _band_reference(plat, cmd, omegas, n_nodes)
    return omegas, out


def tolerance_band(omegas, energy, reference, omega0, level: float = 0.05):
    """Width of the frequency band around `omega0` where `energy / reference < level`.

    Returns the width as a fraction of `omega0` (0 when the ratio at `omega0` is not below the
    level), with the band edges found by linear interpolation of the ratio on the grid; a band
    that reaches the end of the grid is cut there. `omegas` [rad/s]: a strictly increasing grid;
    `energy` of its shape, `reference` of its shape or a scalar; `omega0` within the grid; `level` > 0.
    """
    o = "tolerance_band"
    w = np.asarray(omegas, dtype=float)
    e, ref = np.asarray(energy, dtype=float), np.asarray(reference, dtype=float)
    if w.ndim != 1 or w.size < 2 or not np.all(np.isfinite(w)) or not np.all(np.diff(w) > 0):
        raise ValueError(f"{o}: `omegas` must be a finite, strictly increasing 1-D grid of >= 2 frequencies [rad/s]")
    if e.shape != w.shape or ref.shape not in ((), w.shape):
        raise ValueError(
            f"{o}: `energy` must have the shape of `omegas` {w.shape} and `reference` that shape or "
            f"none (a scalar); got {e.shape} and {ref.shape}"
        )
    check_positive("level", level, owner=o)
    check_positive("omega0", omega0, "rad/s", owner=o)
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
