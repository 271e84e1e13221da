"""Gradient tuning of the PID speed regulator of a motor-driven mechanism (Incerti, 2012, Sec. IV).

The paper tuned $K_p, K_i, K_d$ by trial and error and names optimisation of χ with respect to
them as future work; `tune_pid` does it by descending the smooth fluctuation index through the
simulation (diffrax, reverse-mode) with optax.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._callables import by_value
from .._checks import check_penalised_limits, check_positive
from ..models.motor import PID, check_pid_nonnegative
from ..objectives.fluctuation import closed_loop_metrics


@dataclasses.dataclass(frozen=True)
class PIDTuneResult:
    """Result of `tune_pid`.

    - `pid`: the tuned regulator (with the caller's limiter kind restored);
    - `chi`: exact χ over the window with `pid` (hard limiter if the input had one);
    - `chi_initial`: exact χ of the starting gains, same conditions;
    - `v_peak`, `i_peak`: peak |voltage| [V] and |current| [A] over [0, t1] with `pid`;
    - `history`: dict of arrays per iteration: `loss`, `chi_smooth`, `v_peak`, `i_peak`,
      `kp`, `ki`, `kd`;
    - `best_step`: iteration whose gains were returned (lowest loss seen).
    """

    pid: PID
    chi: float
    chi_initial: float
    v_peak: float
    i_peak: float
    history: dict
    best_step: int


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

    - `pid`: starting gains, set point and limiter. If `pid.v_limit` is set, the tuner simulates
      with the smooth limiter (gradients through saturation) and reports with `pid`'s own limiter.
    - `v_max` [V], `i_max` [A]: bounds on peak |voltage| and |current| over [0, t1], imposed by
      the quadratic penalty of weight `penalty` (default `v_max`: none; with a limiter the voltage
      bound holds by construction).
    - `optimizer`: any optax transformation (default `optax.adam(learning_rate)`), updated inside
      one jitted step.
    - `temperature`: of the smooth χ (relative to the average speed).
    - `method`, `rtol`, `atol`, `dt`: the simulation (see `simulate`).
    - `progress`: tqdm progress bar.

    Returns a `PIDTuneResult` (the gains with the lowest loss seen).
    """
    check_pid_nonnegative(pid)
    o = "tune_pid"
    check_penalised_limits(o, penalty, (("v_max", v_max, "V"), ("i_max", i_max, "A")))
    check_positive("learning_rate", learning_rate, owner=o)
    check_positive("temperature", temperature, owner=o)
    for name in ("kp", "ki", "kd"):
        if not float(getattr(pid, name)) > 0:
            raise ValueError(f"tune_pid: starting gain `{name}` must be > 0 (the tuner works on log-gains)")
    if not 0 <= t0 < t1:
        raise ValueError(f"tune_pid: need 0 <= t0 < t1; got t0={t0}, t1={t1}")
    if steps < 1:
        raise ValueError(f"tune_pid: `steps` must be >= 1; got {steps}")
    train_pid = pid.with_limiter("smooth") if pid.v_limit is not None else pid
    g0 = pid.gains
    if optimizer is None:
        # one transformation object for every call; the learning rate lives in its state, so a
        # new rate reuses the compiled step
        opt = _default_adam()
        state: Any = opt.init(jnp.zeros(3))  # inject_hyperparams' state (optax types the union of its states)
        state.hyperparams["learning_rate"] = jnp.asarray(learning_rate, dtype=float)
    else:
        # keyed by its functions' code and values: `optax.adam(0.07)` made anew reuses the compiled step
        opt = jax.tree_util.tree_map(by_value, optimizer)
        state = opt.init(jnp.zeros(3))
    # Values travel as arrays (traced: a new value reuses the compiled step); only what fixes the
    # shapes or the program is static: t1 (the output grid), the method, and the RK4 step.
    f = functools.partial(jnp.asarray, dtype=float)
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
    )
    p = jnp.zeros(3)
    hist = {k: [] for k in ("loss", "chi_smooth", "v_peak", "i_peak", "kp", "ki", "kd")}
    best = (np.inf, p, 0)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(range(steps), desc="tune_pid", leave=False)
    for k in range(steps) if bar is None else bar:
        p_new, state, loss, m, gains = _tune_step(opt, drive, train_pid, g0, cfg, p, state)
        loss, m, gains = jax.device_get((loss, m, gains))
        loss = float(loss)
        if not np.isfinite(loss):
            raise FloatingPointError(f"tune_pid: non-finite loss at step {k} with gains {gains.tolist()}")
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
        if loss < best[0]:
            best = (loss, p, k)
        if bar is not None:
            bar.set_postfix(chi_smooth=f"{float(m['chi_smooth']):.4f}")
        p = p_new
    _, p_best, k_best = best
    m0, mb = jax.device_get(
        (_tune_report(drive, pid, g0, cfg, jnp.zeros(3)), _tune_report(drive, pid, g0, cfg, p_best))
    )
    return PIDTuneResult(
        pid=pid.with_gains(g0 * jnp.exp(p_best)),
        chi=float(mb["chi"]),
        chi_initial=float(m0["chi"]),
        v_peak=float(mb["v_peak"]),
        i_peak=float(mb["i_peak"]),
        history={k: np.asarray(v) for k, v in hist.items()},
        best_step=int(k_best),
    )


class _Config(eqx.Module):
    t0: jnp.ndarray
    v_max: jnp.ndarray
    i_max: jnp.ndarray
    penalty: jnp.ndarray
    temperature: jnp.ndarray
    rtol: jnp.ndarray
    atol: jnp.ndarray
    t1: float = eqx.field(static=True)
    method: str = eqx.field(static=True)
    dt: float = eqx.field(static=True)


@functools.cache
def _default_adam():
    return optax.inject_hyperparams(optax.adam)(learning_rate=0.1)


def _metrics(drive, which, g0, cfg: _Config, p):
    # Three parameters: forward-mode derivatives (one JVP per gain, diffrax.ForwardMode) cost about
    # 5 forward solves, a third of reverse mode through the checkpointed solve, and compile faster.
    return closed_loop_metrics(
        drive,
        which.with_gains(g0 * jnp.exp(p)),
        cfg.t0,
        cfg.t1,
        temperature=cfg.temperature,
        method=cfg.method,
        rtol=cfg.rtol,
        atol=cfg.atol,
        dt=cfg.dt,
        adjoint="forward",
    )


#: Number of times the tuning step has been traced (tests check that repeated calls reuse it).
TRACE_COUNT = {"step": 0, "report": 0}


@eqx.filter_jit
def _tune_step(opt, drive, train_pid, g0, cfg: _Config, p, state):
    TRACE_COUNT["step"] += 1

    def loss_aux(q):
        m = _metrics(drive, train_pid, g0, cfg, q)
        # v_max, i_max = inf when unbounded: the penalty terms are then exactly zero
        loss = (
            m["chi_smooth"]
            + cfg.penalty * jnp.maximum(0.0, m["v_peak"] / cfg.v_max - 1.0) ** 2
            + cfg.penalty * jnp.maximum(0.0, m["i_peak"] / cfg.i_max - 1.0) ** 2
        )
        return loss, (loss, m)

    grad, (loss, m) = jax.jacfwd(loss_aux, has_aux=True)(p)
    updates, state = opt.update(grad, state, p)
    p_new = cast(jax.Array, optax.apply_updates(p, updates))  # optax types a pytree; here one array
    return p_new, state, loss, m, g0 * jnp.exp(p)


@eqx.filter_jit
def _tune_report(drive, pid, g0, cfg: _Config, p):
    TRACE_COUNT["report"] += 1
    return _metrics(drive, pid, g0, cfg, p)
