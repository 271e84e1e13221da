"""Gradient tuning of the PID speed regulator of a motor-driven mechanism (Incerti, 2012, Sec. IV).

The paper tuned $K_p, K_i, K_d$ by trial and error and names optimisation of χ with respect to
them as future work; `tune_pid` does it by descending the smooth fluctuation index through the
simulation (diffrax, reverse-mode) with optax.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import warnings
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._callables import by_value
from .._checks import check_int, check_penalised_limits, check_positive, check_scalar
from .._display import Display, Table
from .._guard import host_checked, prepare
from .._params import declared
from .._xla import QUICK_COMPILE
from ..models._ranges import VOLTAGE_V
from ..models.motor import PID, check_pid_nonnegative
from ..objectives.fluctuation import closed_loop_metrics, linearisation_run, linearised_metrics


@dataclasses.dataclass(frozen=True)
class PIDTuneResult:
    """Result of `tune_pid`.

    - `pid`: the tuned regulator (with the caller's limiter kind restored);
    - `chi`: exact χ over the window with `pid` (hard limiter if the input had one);
    - `chi_initial`: exact χ of the starting gains, same conditions;
    - `v_peak`, `i_peak`: peak |voltage| [V] and |current| [A] over [0, t1] with `pid`;
    - `history`: dict of arrays per iteration: `loss`, `chi_smooth`, `v_peak`, `i_peak`,
      `kp`, `ki`, `kd`;
    - `best_step`: iteration whose gains were returned (lowest loss seen);
    - `mean_speed`: time mean of the motor speed over [t0, t1] with `pid` [rad/s];
    - `status`: `"ok"`, or what the request could not get (`"v_max not met"`, `"i_max not met"`,
      `"set point not held"`, `"no improvement"`; several joined by `"; "`), each also warned about
      (`RuntimeWarning`) with `message` saying why and what to do.

    In a notebook the result shows as an HTML table (gains and χ, start and tuned, with units); `str()` is the
    same as text.
    """

    pid: PID
    chi: float
    chi_initial: float
    v_peak: float
    i_peak: float
    history: dict
    best_step: int
    mean_speed: float = float("nan")
    status: str = "ok"
    message: str = ""

    def _display(self) -> Display:
        units = {name: p.unit for name, (p, _) in declared(PID).items()}
        if self.pid.gain == "constant":
            units["kp"] = "V s/rad"  # the declared unit is the ramped gain's (it multiplies t)
        h = self.history
        rows = []
        for name in ("kp", "ki", "kd"):
            start = float(h[name][0]) if len(h.get(name, ())) else math.nan
            rows.append((name, start, float(getattr(self.pid, name)), units.get(name, "")))
        rows.append(("χ (exact)", self.chi_initial, self.chi, "–"))
        fields = [
            ("status", self.status, ""),
            ("steps", len(h.get("loss", ())), ""),
            ("best step", self.best_step, ""),
            ("peak |voltage|", self.v_peak, "V"),
            ("peak |current|", self.i_peak, "A"),
            ("mean motor speed", self.mean_speed, "rad/s"),
        ]
        if self.message:
            fields.append(("message", self.message, ""))
        table = Table(("quantity", "start", "tuned", "unit"), tuple(rows), caption="gains and fluctuation index")
        return Display("jaxbelt PIDTuneResult", tuple(fields), (table,))

    def _repr_html_(self) -> str:
        return self._display().html()

    def __str__(self) -> str:
        return self._display().text()


#: the most optimiser steps `tune_pid` takes (each a simulation and its gradient: 1e5 steps are hours)
MAX_TUNE_STEPS = 100_000


def tune_pid(
    drive,
    pid: PID,
    t0: float = 0.375,
    t1: float = 0.5,
    *,
    steps: int = 60,
    learning_rate: float = 0.1,
    optimizer: optax.GradientTransformation | None = None,
    v_max: float | None = None,
    i_max: float | None = None,
    penalty: float = 10.0,
    temperature: float = 3e-4,
    method: str = "ode",
    rtol: float = 1e-7,
    atol: float = 1e-7,
    dt: float = 1e-3,
    progress: bool = True,
) -> PIDTuneResult:
    """Minimise the fluctuation index χ over [t0, t1] [s] with respect to $(K_p, K_i, K_d)$.

    Loss, on log-gains $p = \\log(K/K^{(0)})$ (gains stay positive, steps are relative):

    $\\ell = \\chi_{smooth} + w\\,[\\max(0, |V|_{max}/V_{max} - 1)^2 + \\max(0, |I|_{max}/I_{max} - 1)^2]$

    - `pid`: starting gains, set point and limiter. With a hard clip (`limiter="hard"`, the default), the
      tuner simulates the smooth limiter of `pid.v_smooth` (gradients through saturation) and reports with
      the clip itself, simulated as the clip's smooth limit (width 1 µV: the same voltage to 7e-7 V) at a
      hundredth of `rtol`/`atol` in the steps' own compiled program.
    - `v_max` [V], `i_max` [A]: bounds on peak |voltage| and |current| over [0, t1], imposed by
      the quadratic penalty of weight `penalty` (default `v_max`: none; with a limiter the voltage
      bound holds by construction).
    - `optimizer`: any optax transformation (default `optax.adam(learning_rate)`), updated inside
      one jitted step. Each step is one simulation with forward sensitivities to the three log-gains
      (`jaxbelt.solve.forward_sensitivities`): the gradient is the exact solution's, to `rtol`/`atol`.
    - `temperature`: of the smooth χ (relative to the average speed).
    - `method`, `rtol`, `atol`, `dt`: the simulation (see `simulate`).
    - `progress`: tqdm progress bar.

    Returns a `PIDTuneResult` (the gains with the lowest loss seen). What the request cannot get is said
    before any work (a `RuntimeWarning` when `v_max` or the PID's `v_limit` is below the back-emf at the set
    point, $k_m\\omega_0$: no gains hold the set point within it) and after it, on the result (`status`,
    `message`) and as a warning.
    """
    _check_tune_arguments(drive, pid, t0, t1, steps, learning_rate, optimizer, temperature, method, rtol, atol, dt)
    o = "tune_pid"
    for name, value in (("v_max", v_max), ("i_max", i_max), ("penalty", penalty)):
        if value is not None:
            check_scalar(name, value, owner=o)
    check_penalised_limits(o, penalty, (("v_max", v_max, "V"), ("i_max", i_max, "A")))
    _warn_unreachable_set_point(drive, pid, v_max)
    # the regulator the steps simulate: `pid` itself, or a hard clip's smooth counterpart (gradients through saturation)
    train_pid = pid.with_limiter("smooth") if pid.v_limit is not None and pid.limiter == "hard" else pid
    # host values: the gains and the optimizer's state are the step's inputs, made without compiling small programs
    g0 = np.array([float(pid.kp), float(pid.ki), float(pid.kd)])
    if optimizer is None:
        # one transformation object for every call; the learning rate lives in its state, so a
        # new rate reuses the compiled step
        opt = _DEFAULT_OPTIMIZER  # named: the compiled step can be stored (`jaxbelt.cache`)
        state: Any = _default_adam_state()  # inject_hyperparams' state (optax types a union)
        state.hyperparams["learning_rate"] = np.asarray(learning_rate, dtype=float)
    else:
        # keyed by its functions' code and values: `optax.adam(0.07)` made anew reuses the compiled step
        opt = jax.tree_util.tree_map(by_value, optimizer)
        state = opt.init(jnp.zeros(3))
    # Values travel as arrays (traced: a new value reuses the compiled step); only what fixes the
    # shapes or the program is static: t1 (the output grid), the method, and the RK4 step.
    f = functools.partial(np.asarray, dtype=float)
    cfg = _Config(
        t0=f(t0),
        v_max=f(np.inf if v_max is None else v_max),
        i_max=f(np.inf if i_max is None else i_max),
        penalty=f(penalty),
        temperature=f(temperature),
        rtol=f(rtol),
        atol=f(atol),
        t1=float(t1),
        method=str(method),
        dt=float(dt) if method == "rk4" else 1e-3,
        bound_v=v_max is not None,
        bound_i=i_max is not None,
    )
    p = np.zeros(3)
    hist = {k: [] for k in ("loss", "chi_smooth", "v_peak", "i_peak", "kp", "ki", "kd")}
    best = (np.inf, p, 0)
    # the metrics the step computed at the start and at the best gains (host values): they are the report's when
    # the step simulates the regulator itself (no limiter to smooth)
    m_start, m_best = None, None
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(range(steps), desc="tune_pid", leave=False)
    _prepare_step(opt, drive, train_pid, g0, cfg, p, state)
    for k in range(steps) if bar is None else bar:
        p_new, state, loss, m, gains = _tune_step(opt, drive, train_pid, g0, cfg, p, state)
        loss, m, gains = jax.device_get((loss, m, gains))
        loss = float(loss)
        if not np.isfinite(loss):
            raise FloatingPointError(
                f"tune_pid: the loss is not finite at step {k} (NaN in the simulation, not a convergence problem) "
                f"with gains (kp, ki, kd) = {gains.tolist()}: the closed loop with these gains cannot be simulated "
                "(unstable, or a step the solver cannot take). Lower `learning_rate`, start from gains that give a "
                "finite χ, or bound the voltage (`v_max`, or a limiter: PID(v_limit=...))"
            )
        for name, val in (
            ("loss", loss),
            ("chi_smooth", m["chi_smooth"]),
            ("v_peak", m["v_peak"]),
            ("i_peak", m["i_peak"]),
            ("kp", gains[0]),
            ("ki", gains[1]),
            ("kd", gains[2]),
        ):
            hist[name].append(float(val))
        if k == 0:
            m_start = m
        if loss < best[0]:
            best = (loss, p, k)
            m_best = m
        if bar is not None:
            bar.set_postfix(chi_smooth=f"{float(m['chi_smooth']):.4f}")
        p = p_new
    _, p_best, k_best = best
    if train_pid is pid and m_start is not None and m_best is not None and _finite(m_start) and _finite(m_best):
        # the step simulated `pid` itself at these gains, on the report's steps: its metrics are the report's (to
        # rounding), and no report program is compiled (a third of a cold first call)
        m0, mb = m_start, m_best
    else:  # the steps simulated a hard clip's smooth counterpart: the report simulates the clip itself
        m0, mb = (_report(opt, drive, pid, g0, cfg, q, state) for q in (np.zeros(3), p_best))
    status, message = _tune_status(pid, mb, m0, v_max, i_max, int(k_best), steps)
    if status != "ok":
        warnings.warn(message, RuntimeWarning, stacklevel=2)
    return PIDTuneResult(
        pid=_with_gains(pid, g0 * np.exp(np.asarray(p_best))),
        chi=float(mb["chi"]),
        chi_initial=float(m0["chi"]),
        v_peak=float(mb["v_peak"]),
        i_peak=float(mb["i_peak"]),
        history={k: np.asarray(v) for k, v in hist.items()},
        best_step=int(k_best),
        mean_speed=float(mb["mean_speed"]),
        status=status,
        message=message,
    )


_METHODS = ("ode", "rk4")


def _check_tune_arguments(drive, pid, t0, t1, steps, learning_rate, optimizer, temperature, method, rtol, atol, dt):
    """Every argument of `tune_pid` that can be checked before anything is traced (`ValueError` or
    `TypeError` naming it, its valid range and the value)."""
    from ..models.fourbar import FourBarDrive
    from ..objectives.fluctuation import _check_temperature, _check_window_on_grid, _grid

    o = "tune_pid"
    if not isinstance(pid, PID):
        raise TypeError(f"{o}: parameter `pid` must be a jaxbelt.PID (the regulator to tune); got {type(pid).__name__}")
    if not isinstance(drive, FourBarDrive):
        raise TypeError(f"{o}: parameter `drive` must be a jaxbelt.FourBarDrive; got {type(drive).__name__}")
    check_pid_nonnegative(pid)
    for name in ("kp", "ki", "kd"):
        if not float(getattr(pid, name)) > 0:
            raise ValueError(
                f"{o}: starting gain `{name}` must be > 0 (the tuner works on log-gains); got {float(getattr(pid, name))}"
            )
    if check_int(o, "steps", steps, 1) > MAX_TUNE_STEPS:  # each step is a simulation and its gradient
        raise ValueError(f"{o}: parameter `steps` must lie in [1, {MAX_TUNE_STEPS}]; got {steps}")
    if not (isinstance(method, str) and method in _METHODS):
        raise ValueError(f"{o}: parameter `method` must be one of {_METHODS}; got {method!r}")
    for name, value in (("learning_rate", learning_rate), ("rtol", rtol), ("atol", atol), ("dt", dt)):
        check_scalar(name, value, "s" if name == "dt" else "", o)
        check_positive(name, value, "s" if name == "dt" else "", owner=o)
    _check_temperature(temperature)
    if optimizer is not None and not (hasattr(optimizer, "init") and hasattr(optimizer, "update")):
        raise TypeError(
            f"{o}: parameter `optimizer` must be an optax.GradientTransformation (or None); got {type(optimizer).__name__}"
        )
    for name, value in (("t0", t0), ("t1", t1)):
        check_scalar(name, value, "s", o)
        if not np.isfinite(float(value)):
            raise ValueError(f"{o}: parameter `{name}` must be finite [s]; got {value!r}")
    if not 0 <= t0 < t1:
        raise ValueError(f"{o}: the window must satisfy 0 <= t0 < t1 [s]; got t0={t0}, t1={t1}")
    ts = _grid(t1, *((dt, "dt") if method == "rk4" else (5e-4, "dt_save")))
    _check_window_on_grid(ts, t0, t1, o, "the tuner saves the speed every 0.5 ms, or every `dt` with method='rk4'")


def _back_emf(drive, pid) -> float:
    """The back-emf at the set point, $k_m\\omega_0$ [V]: the mean voltage that holds the motor at $\\omega_0$ is
    this plus $R\\bar I$, the loss in the armature (the load's friction makes the mean current positive)."""
    return abs(float(drive.km) * float(pid.omega_ref))


def _warn_unreachable_set_point(drive, pid, v_max) -> None:
    """Warn, before any work, of a voltage bound that no gains can meet at the set point."""
    need = _back_emf(drive, pid)
    for name, bound in (("v_max", v_max), ("the PID's `v_limit`", pid.v_limit)):
        if bound is not None and float(bound) < need:
            warnings.warn(
                f"tune_pid: {name} = {float(bound):g} V is below the back-emf at the set point, k_m * omega_ref = "
                f"{float(drive.km):g} * {float(pid.omega_ref):g} = {need:.4g} V: no gains hold the motor at "
                f"omega_ref = {float(pid.omega_ref):g} rad/s within it, so the tuner can only trade χ against the "
                "bound. Raise the bound above the back-emf (plus the armature loss R * I), or lower the set point",
                RuntimeWarning,
                stacklevel=3,
            )


#: the tuned run misses the set point when its mean speed over the window is further than this from it (relative)
_SET_POINT_RTOL = 0.05
#: a peak over its bound by more than this (relative) is not met
_BOUND_RTOL = 1e-3


def _tune_status(pid, mb, m0, v_max, i_max, best_step: int, steps: int) -> tuple[str, str]:
    """`(status, message)` of a tuning run: what the request did not get, why, and what to do."""
    found, why = [], []
    for name, bound, peak, unit in (("v_max", v_max, mb["v_peak"], "V"), ("i_max", i_max, mb["i_peak"], "A")):
        if bound is not None and float(peak) > float(bound) * (1 + _BOUND_RTOL):
            found.append(f"{name} not met")
            why.append(
                f"the peak |{'voltage' if unit == 'V' else 'current'}| {float(peak):.4g} {unit} exceeds {name} = "
                f"{float(bound):g} {unit} (the bound is a penalty: raise `penalty`, or `steps`, or relax the bound)"
            )
    ref, mean = float(pid.omega_ref), float(mb["mean_speed"])
    if abs(mean - ref) > _SET_POINT_RTOL * abs(ref):
        found.append("set point not held")
        limit = "" if pid.v_limit is None else f", the limiter v_limit = {float(pid.v_limit):g} V"
        why.append(
            f"the mean motor speed over the window is {mean:.4g} rad/s against the set point omega_ref = {ref:g} "
            f"rad/s (the voltage available{limit} or the bounds keep the drive from it; χ then measures another "
            "motion). Raise the voltage bounds, or start from gains that reach the set point"
        )
    if steps > 1 and best_step == 0:
        found.append("no improvement")
        why.append(
            f"no step lowered the loss below that of the starting gains (χ = {float(m0['chi']):.4g}): lower "
            "`learning_rate`, or the bounds leave nothing to gain"
        )
    if not found:
        return "ok", ""
    return "; ".join(found), "tune_pid: " + "; ".join(why)


class _Config(eqx.Module):
    # host arrays as built by `tune_pid` (the programs' inputs), traced arrays inside them
    t0: jax.Array | np.ndarray
    v_max: jax.Array | np.ndarray
    i_max: jax.Array | np.ndarray
    penalty: jax.Array | np.ndarray
    temperature: jax.Array | np.ndarray
    rtol: jax.Array | np.ndarray
    atol: jax.Array | np.ndarray
    t1: float = eqx.field(static=True)
    method: str = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    # whether `v_max` / `i_max` were given: an absent bound's penalty is exactly zero, and its derivative (the
    # voltage's or current's along the trajectory's sensitivities) a third of the step's compilation
    bound_v: bool = eqx.field(static=True, default=True)
    bound_i: bool = eqx.field(static=True, default=True)


@functools.cache
def _default_adam():
    return optax.inject_hyperparams(optax.adam)(learning_rate=0.1)


@functools.cache
def _default_adam_shapes():
    return jax.eval_shape(_default_adam().init, jax.ShapeDtypeStruct((3,), jnp.float64))


def _default_adam_state():
    """`_default_adam().init(zeros(3))` made on the host (`init` run eagerly would compile four small programs):
    Adam's count and moments start at zero, its hyperparameters at `optax.adam`'s defaults (the learning rate is
    set by the caller)."""
    state = jax.tree_util.tree_map(lambda s: np.zeros(s.shape, s.dtype), _default_adam_shapes())
    defaults = inspect.signature(optax.adam).parameters
    for name, value in state.hyperparams.items():
        if name != "learning_rate":
            state.hyperparams[name] = np.asarray(defaults[name].default, dtype=value.dtype)
    return state


def _with_gains(pid: PID, gains) -> PID:
    """`pid.with_gains(gains)` for host gains, without compiling the indexing of a device array."""
    return eqx.tree_at(lambda q: (q.kp, q.ki, q.kd), pid, tuple(jax.device_put(np.float64(g)) for g in gains))


#: the default optimizer's name in the step's arguments (a string is a plain static value: the program is storable)
_DEFAULT_OPTIMIZER = "adam"


def _run_options(cfg: _Config) -> dict:
    """The simulation's options from the tuning's configuration (its output grid ends at t1)."""
    return dict(t1=cfg.t1, method=cfg.method, rtol=cfg.rtol, atol=cfg.atol, dt=cfg.dt)


def _metric_options(cfg: _Config) -> dict:
    """The metrics' window and smoothing, and what fixes their output grid, from the tuning's configuration."""
    return dict(t0=cfg.t0, t1=cfg.t1, temperature=cfg.temperature, method=cfg.method, dt=cfg.dt)


def _options(cfg: _Config) -> dict:
    """The metrics' window, smoothing and simulation options from the tuning's configuration."""
    return _run_options(cfg) | _metric_options(cfg)


def _regulator(pid: PID, g0):
    """The map from the log-gains `q` to `pid` with the gains `g0 * exp(q)`."""
    return lambda q: pid.with_gains(g0 * jnp.exp(q))


def _metrics(drive, which, g0, cfg: _Config, p, throw: bool = True):
    # not differentiated: diffrax's plain loop (`adjoint="forward"`), smaller than its checkpointed one
    return closed_loop_metrics(drive, _regulator(which, g0)(p), adjoint="forward", throw=throw, **_options(cfg))


#: Number of times the tuning step's programs have been traced (tests check that repeated calls reuse them).
TRACE_COUNT = {"run": 0, "step": 0, "report": 0}


def _tune_run_impl(drive, train_pid, g0, cfg: _Config, p):
    TRACE_COUNT["run"] += 1
    # One simulation with forward sensitivities to the three log-gains, at `p`. A failed solve gives NaN, which
    # `tune_pid` refuses on the host as a NaN loss; the program holds no run-time check, which keeps it in the caches.
    return linearisation_run(drive, _regulator(train_pid, g0), p, **_run_options(cfg))


def _tune_update_impl(opt, drive, train_pid, g0, cfg: _Config, p, state, ys, sens):
    TRACE_COUNT["step"] += 1
    if isinstance(opt, str):
        opt = _default_adam()

    # the metrics to first order about `p` from the run `(ys, sens)`: their derivative at `p` is the gradient
    linear = linearised_metrics(drive, _regulator(train_pid, g0), p, ys, sens, **_metric_options(cfg))

    def loss_aux(q):
        m = linear(q)
        loss = m["chi_smooth"]
        if cfg.bound_v:
            loss = loss + cfg.penalty * jnp.maximum(0.0, m["v_peak"] / cfg.v_max - 1.0) ** 2
        if cfg.bound_i:
            loss = loss + cfg.penalty * jnp.maximum(0.0, m["i_peak"] / cfg.i_max - 1.0) ** 2
        return loss, (loss, m)

    grad, (loss, m) = jax.jacfwd(loss_aux, has_aux=True)(p)
    updates, state = opt.update(grad, state, p)
    p_new = cast(jax.Array, optax.apply_updates(p, updates))  # optax types a pytree; here one array
    return p_new, state, loss, m, g0 * jnp.exp(p)


def _tune_report_impl(drive, pid, g0, cfg: _Config, p):
    TRACE_COUNT["report"] += 1
    return _metrics(drive, pid, g0, cfg, p)


def _finite(m: dict) -> bool:
    return all(np.isfinite(v) for v in m.values())


#: the width [V] of the smooth limiter that stands in for a hard clip in the report: the clip is the smooth
#: limiter's limit as the width goes to 0, the two voltages differ by at most width * log 2 (7e-7 V). The least width
#: `PID.v_smooth` accepts (its declared range, checked inside the programs too): a width below it (1e-9 V) made the
#: step's program return NaN metrics, and every report fell back to compiling the checked report program
_CLIP_WIDTH = VOLTAGE_V[0]
#: the report's tolerances, relative to the tuning's (and at least 1e-12): the stand-in's steps differ from the
#: clip's where the limiter acts, and a tighter solve makes either's error negligible
_REPORT_TOL = 1e-2


def _clip_stand_in(pid: PID) -> PID:
    """`pid` with its hard clip replaced by the smooth limiter of width `_CLIP_WIDTH` (the same voltage to 7e-7 V):
    the structure of the regulator the steps simulate, so that the report runs the steps' own compiled program."""
    return eqx.tree_at(lambda q: q.v_smooth, pid.with_limiter("smooth"), jax.device_put(np.float64(_CLIP_WIDTH)))


def _report_metrics(opt, drive, pid, g0, cfg: _Config, p, state) -> dict:
    """The metrics of `pid` (a hard clip) at the log-gains `p` (host values), from the step's own program: one
    program for the steps and the report (a second one would be a third of a cold first call)."""
    tight = eqx.tree_at(
        lambda c: (c.rtol, c.atol),
        cfg,
        tuple(np.asarray(np.maximum(_REPORT_TOL * np.asarray(x), 1e-12), dtype=float) for x in (cfg.rtol, cfg.atol)),
    )
    return jax.device_get(_tune_step(opt, drive, _clip_stand_in(pid), g0, tight, p, state)[3])


def _report(opt, drive, pid, g0, cfg: _Config, p, state) -> dict:
    """The report's metrics (host values) for a regulator with a hard clip: from the steps' program where every one
    is finite; else from the checked report program, which raises what failed (or gives the non-finite values)."""
    m = _report_metrics(opt, drive, pid, g0, cfg, p, state)
    if _finite(m):
        return m
    return jax.device_get(_tune_report(drive, pid, g0, cfg, p))


#: XLA options of the step's and the report's programs (called at top level only: inside a caller's trace they are
#: the caller's): XLA's classic CPU emitters at LLVM level 0 compile them 2-3x faster; the same HLO, results equal
#: to rounding (~1e-13 relative), each step runs a few ms slower
_COMPILE = QUICK_COMPILE

# Compiled once per structure; their checks come back as values (`host_checked`), so that JAX's persistent cache
# and jaxbelt's program store (`jb.enable_compilation_cache`) keep them: a later process neither traces nor
# compiles them again.
_tune_run = host_checked(_tune_run_impl, store=True, compiler_options=_COMPILE, checks=False)
_tune_update = host_checked(_tune_update_impl, store=True, compiler_options=_COMPILE, checks=False)
_tune_report = host_checked(_tune_report_impl, store=True, compiler_options=_COMPILE)


def _tune_step(opt, drive, train_pid, g0, cfg: _Config, p, state):
    """One step of the tuning, `(p_new, state, loss, metrics, gains)`, in two programs: the simulation with its
    sensitivities, then the linearised metrics with the optimiser's update. Compiled apart, the second compiles
    while the first does (`_prepare_step`), and the two compile in less time than the one program that held both:
    a cold first `tune_pid` took 2.9 s instead of 3.9 s (median of four alternating fresh processes each, 2 cores)."""
    ys, sens = _tune_run(drive, train_pid, g0, cfg, p)
    return _tune_update(opt, drive, train_pid, g0, cfg, p, state, ys, sens)


def _prepare_step(opt, drive, train_pid, g0, cfg: _Config, p, state) -> None:
    """Trace the step's simulation and start compiling it in the background (`jaxbelt._guard.prepare`), then trace
    the update from the simulation's output types while it compiles."""
    types = prepare(_tune_run, drive, train_pid, g0, cfg, p)
    if types is not None:
        prepare(_tune_update, opt, drive, train_pid, g0, cfg, p, state, *types)
