"""The papers' runs: the simulations behind their figures, as arrays and solutions.

These sit above `simulate` (they build scenes and solve them); the models below them only describe
the physics.

- `startup_curves`: the eight time histories of Incerti (2014), Fig. 3;
- `simulate_fig4`: the open- and closed-loop runs of Incerti (2012), Fig. 4;
- `platform_response`: the platform's motion under a command, Incerti (pseudo-polynomial commands), Fig. 3.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_fits, check_int, check_positive, check_range, check_scalar
from ._threads import blas_limited
from .commands import ConstantVoltage, ExponentialVoltage
from .models.fourbar import FourBarDrive
from .models.motor import PID
from .models.startup import BeltStartup
from .scene import Scene
from .solve import simulate

#: The eight time histories of Incerti (2014), Fig. 3, in the paper's panel order (a-h).
STARTUP_OUTPUTS = (
    "voltage",
    "current",
    "electric_power",
    "mechanical_power",
    "omega1",
    "omega2",
    "alpha1",
    "alpha2",
)


#: the span [s] of a start-up or four-bar run: the start-up's electrical time constant is ~1 ms and its transient
#: ~0.1 s, the four-bar's window ~0.5 s; 1 us to 1000 s reaches three decades beyond each (t1 = 1e300 s ran the ODE
#: to its step budget, a `SolveError` after 6 s naming `max_steps`, not the span)
RUN_SPAN_RANGE_S = (1e-6, 1e3)

#: bytes a run holds per saved time, an upper estimate: the state and the observed outputs (about 16 columns of
#: float64) in the solver's output, its host copy and the result's arrays
BYTES_PER_SAVED_POINT = 512


@blas_limited
def startup_curves(model=None, gammas=(0.02, 0.04, 0.06), v_max=24.0, t_end=0.5, n_points=501, method="auto"):
    """The eight time histories of Incerti (2014), Fig. 3, for each voltage time constant, as numpy arrays.

    The motor voltage is $V(t) = V_{max}(1 - e^{-t/\\gamma})$ (Incerti, 2014, eq. 30) with
    `v_max` $V_{max}$ [V] and each $\\gamma$ of `gammas` [s]; the drive starts at rest and is
    simulated over $[0, t_{end}]$ [s] on `n_points` equally spaced times (one compiled program, run for
    each $\\gamma$; closed form by default, `method` as in `simulate`).

    Returns `(ts, curves)`: `ts` [s] of shape `(n_points,)` and `curves[name]` of shape
    `(len(gammas), n_points)` for each name of `STARTUP_OUTPUTS`: voltage [V], current [A],
    electric and mechanical power [W], pulley speeds [rad/s] and accelerations [rad/s²].
    Default model: `BeltStartup()` (Incerti, 2014, Table I).
    """

    n_points = check_int("startup_curves", "n_points", n_points, 2)
    check_fits("startup_curves", "n_points", BYTES_PER_SAVED_POINT * n_points, f"{n_points:.3g} saved times")
    check_scalar("t_end", t_end, "s", "startup_curves")
    check_range("t_end", t_end, *RUN_SPAN_RANGE_S, unit="s", owner="startup_curves")
    model = BeltStartup() if model is None else model
    ts = np.linspace(0.0, float(t_end), n_points)
    observe = tuple(n for n in STARTUP_OUTPUTS if n not in model.state_names)
    rows = []
    for g in np.atleast_1d(np.asarray(gammas, dtype=float)).tolist():
        sol = simulate(Scene(model, ExponentialVoltage(v_max, g), ts=ts, observe=observe), method=method)
        sol = jax.device_get(sol)  # the columns are read on the host (no program per column)
        rows.append([sol[n] for n in STARTUP_OUTPUTS])
    return ts, {n: np.stack([r[i] for r in rows]) for i, n in enumerate(STARTUP_OUTPUTS)}


#: The outputs of Incerti (2012), Fig. 4 (besides the state): motor speed, voltage, mechanical and electric power.
FIG4_OUTPUTS = ("motor_speed", "voltage", "mechanical_power", "electric_power")


@blas_limited
def simulate_fig4(drive=None, pid=None, *, voltage: float = 25.0, t1: float = 1.0, n: int = 2001, **kw):
    """The two runs of Incerti (2012), Fig. 4: open loop at constant `voltage` [V] and closed loop with `pid`.

    Both start at rest and are saved on `n` equally spaced times over $[0, t_1]$ [s] with the
    outputs `FIG4_OUTPUTS` observed; `kw` go to `simulate`. Defaults: `FourBarDrive()` (crank
    length and resistance identified, the other lost Table I values assumed) and the paper's PID
    with ramped proportional gain (eq. 16: $K_p$ = 80, $K_i$ = 32, $K_d$ = 0.015, $\\omega_0$ = 30 rad/s).
    Returns `(open_loop, closed_loop)` `Solution`s.
    """

    check_scalar("t1", t1, "s", "simulate_fig4")
    check_range("t1", t1, *RUN_SPAN_RANGE_S, unit="s", owner="simulate_fig4")
    n = check_int("simulate_fig4", "n", n, 2)
    check_fits("simulate_fig4", "n", 2 * BYTES_PER_SAVED_POINT * n, f"{n:.3g} saved times of two runs")
    drive = FourBarDrive() if drive is None else drive
    pid = PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0) if pid is None else pid
    ts = jnp.linspace(0.0, float(t1), n)
    open_loop = simulate(Scene(drive, ConstantVoltage(voltage), ts=ts, observe=FIG4_OUTPUTS), **kw)
    closed_loop = simulate(Scene(drive, pid, ts=ts, observe=FIG4_OUTPUTS), **kw)
    return open_loop, closed_loop


#: The time histories returned by `platform_response` besides `t` and `velocity`.
PLATFORM_OUTPUTS = ("acceleration", "kinetic_energy", "elastic_energy", "command_velocity", "command_acceleration")


@blas_limited
def platform_response(platform, command, t_end: float | None = None, n: int = 901, *, rtol=1e-10, atol=1e-12):
    """The platform's motion under `command` over $[0, t_{end}]$ (Incerti, pseudo-polynomial commands, Fig. 3).

    `t_end` [s] defaults to 1.5 × the move time (so the residual vibration shows); `n` equally
    spaced output times; solved as an ODE at `rtol`, `atol`. Returns a dict of numpy arrays of
    shape `(n,)`: `t` [s], platform `velocity` [rad/s] and `acceleration` [rad/s²], the rigid-body
    commands $\\lambda\\dot\\varphi_m$ (`command_velocity` [rad/s]) and $\\lambda\\ddot\\varphi_m$
    (`command_acceleration` [rad/s²]), `kinetic_energy` and `elastic_energy` [J].
    """

    if t_end is None:
        t_end = 1.5 * float(command.end_time)
    check_scalar("t_end", t_end, "s", "platform_response")
    check_positive("t_end", t_end, "s", "platform_response")
    n = check_int("platform_response", "n", n, 2)
    check_fits("platform_response", "n", BYTES_PER_SAVED_POINT * n, f"{n:.3g} saved times")
    ts = jnp.linspace(0.0, float(t_end), n)
    sol = simulate(Scene(platform, command, ts=ts, observe=PLATFORM_OUTPUTS), method="ode", rtol=rtol, atol=atol)
    out = {"t": np.asarray(ts), "velocity": np.asarray(sol.omega)}
    out.update({k: np.asarray(sol[k]) for k in PLATFORM_OUTPUTS})
    return out
