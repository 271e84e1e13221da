"""Steady-state response and quasi-static speed sweeps of the non-linear belt (Moon & Wickert, 1997).

- `nonlinear_steady_state(belt, speed)`: integrate whole forcing periods until the transient has decayed,
  then report the peak-to-peak displacement at a point (default 1 cm from the driven pulley, as
  in the experiment) and the modal amplitudes.
- `speed_sweep(belt, speeds)`: the contract call; peak-to-peak amplitudes [m] of a quasi-static
  sweep (a `lax.scan` over speeds, each speed started from the previous final state, so the
  jump and the hysteresis band appear). `nonlinear_sweep(...)` returns everything (states, flags).
- `nonlinear_basins(belt, speed, z0s)`: steady states reached from several initial conditions (Fig. 6).
- `nonlinear_trajectory(belt, speed, z0, periods)`: modal state history for phase-plane plots.

## Integration and convergence criterion

Time is dimensionless ($\\tau = t v_t / L$). One forcing period $T = 2\\pi/\\Omega_0$ of the
pulley at x = 0 is integrated with `diffrax` (adaptive Tsit5, rtol 1e-9, atol 1e-9 of the
run-out), sampling $w(x_m)$ at `steps_per_period` equal steps; the peak and trough are refined
by a parabola through the three samples around them. Periods are
integrated inside `lax.while_loop` until the change of the per-period peak-to-peak
$p_k$ satisfies

$\\max(|p_k - p_{k-1}|, |p_{k-1} - p_{k-2}|) \\le (\\mathrm{rtol}\\,p_k + \\mathrm{atol})(1-\\rho)$,
$\\rho = e^{-\\xi\\omega_1 T}$,

i.e. the geometric tail of a transient decaying at the first mode's modal rate is below the
tolerance, or `max_periods` is reached (then the speed is reported as not converged).
With unequal pulley radii the response is quasi-periodic; raise `periods_per_chunk` so that one
measurement window holds several beats.

When the speed changes, the modal state is carried over by projecting the displacement and
velocity fields onto the new speed's modes (A-orthogonality of the state eigenvectors), and the
pulley angles continue, as in a slow physical speed ramp.
"""

from __future__ import annotations

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._checks import check_fits, check_int, check_nonnegative, check_real, check_scalar, is_concrete
from ..._guard import guard, reraising, traced_checks
from ..._threads import blas_limited
from .model import ModalSystem, NonlinearBelt, _gauss, mode_shapes


class SteadyStateError(RuntimeError):
    """A sweep step did not reach a steady state within `max_periods` forcing periods."""


class SteadyState(eqx.Module):
    """Steady response at one speed (arrays gain leading axes under `vmap`/in sweeps).

    - `pp`: peak-to-peak displacement [m] at the measurement point over the last period;
    - `amplitude`: (N,) modal amplitudes $a_n = \\max_t\\sqrt{(\\zeta^R_n)^2 + (\\zeta^I_n)^2}$ over the
      last period (dimensionless, $w \\approx a_n\\,\\mathrm{Re}(\\psi_n e^{i\\theta})$);
    - `z`: final modal state; `theta`: final drive-pulley angle [rad];
    - `periods`: forcing periods integrated; `converged`: criterion met.
    """

    pp: jnp.ndarray
    amplitude: jnp.ndarray
    z: jnp.ndarray
    theta: jnp.ndarray
    periods: jnp.ndarray
    converged: jnp.ndarray


class SweepResult(eqx.Module):
    """A quasi-static sweep: `speeds` [m/s] in sweep order and one `SteadyState` per speed."""

    speeds: jnp.ndarray
    steady: SteadyState

    @property
    def pp(self):
        return self.steady.pp

    @property
    def converged(self):
        return self.steady.converged


# ----------------------------------------------------------------------------------------------
_SOLVER = diffrax.Tsit5()


def _solve_period(sys: ModalSystem, z, tau0, T, theta00, n_save: int, rtol, atol):
    """diffrax solve of the modal system over [tau0, tau0 + T], saved at `n_save` equal steps."""
    ts = tau0 + T * jnp.arange(1, n_save + 1) / n_save
    ts = jnp.minimum(ts, tau0 + T).at[-1].set(tau0 + T)  # rounding must not put a save time past t1
    term = diffrax.ODETerm(lambda tau, zz, args: sys.rhs(tau, zz, theta00))
    sol = diffrax.diffeqsolve(
        term,
        _SOLVER,
        t0=tau0,
        t1=tau0 + T,
        dt0=T / n_save,
        y0=z,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=16 * n_save,
        throw=False,
    )
    ok = sol.result == diffrax.RESULTS.successful
    assert sol.ys is not None  # saved at `ts`
    return ts, jnp.where(ok, sol.ys, jnp.nan)


def _refined(p2, p1, p0, sign):
    """Extremum (sign=+1 max, -1 min) of the parabola through three equally spaced samples."""
    a, b, c = sign * p2, sign * p1, sign * p0
    den = a - 2 * b + c
    is_peak = (b >= a) & (b >= c) & (den < 0)
    vert = b - (c - a) ** 2 / (8 * jnp.where(is_peak, den, -1.0))
    return sign * jnp.where(is_peak, vert, b)


def _steps_per_period(sys: ModalSystem, min_steps: int, periods_per_chunk: int):
    return periods_per_chunk * 2 * jnp.pi / sys.Omega[0], min_steps * periods_per_chunk


def _point_shape(sys: ModalSystem, xm, n_modes):
    psi, _ = mode_shapes(jnp.atleast_1d(xm), sys.v, n_modes)
    return jnp.concatenate([psi.real[:, 0], psi.imag[:, 0]])


# integration tolerances of the diffrax solve (relative; absolute relative to the run-out)
_ODE_RTOL, _ODE_ATOL = 1e-9, 1e-9


def _chunk(sys: ModalSystem, xm, phi_m, z, tau0, theta00, window, T, n_steps):
    """Integrate one measurement chunk (diffrax, adaptive Tsit5); returns new state, time,
    window and (peak-to-peak, modal amplitudes) from `n_steps` samples refined by parabolas."""
    n = sys.n_modes
    atol = _ODE_ATOL * (sys.e[0] + sys.e[1] + 1e-300)
    ts, zs = _solve_period(sys, z, tau0, T, theta00, n_steps, _ODE_RTOL, atol)
    ws = zs @ phi_m + jax.vmap(lambda tau: sys.boundary(xm, tau, theta00))(ts)
    p2, p1 = window
    seq = jnp.concatenate([jnp.stack([p2, p1]), ws])
    mx = jnp.max(_refined(seq[:-2], seq[1:-1], seq[2:], 1.0))
    mn = jnp.min(_refined(seq[:-2], seq[1:-1], seq[2:], -1.0))
    amp = jnp.max(jnp.sqrt(zs[:, :n] ** 2 + zs[:, n:] ** 2), axis=0)
    return zs[-1], tau0 + T, (ws[-2], ws[-1]), mx - mn, amp


def _steady_core(
    belt: NonlinearBelt,
    sys: ModalSystem,
    z0,
    theta00,
    xm,
    rtol,
    atol_rel,
    min_periods,
    max_periods,
    min_steps,
    periods_per_chunk,
):
    n = belt.n_modes
    phi_m = _point_shape(sys, xm, n)
    T, n_steps = _steps_per_period(sys, min_steps, periods_per_chunk)
    rho = jnp.exp(-jnp.min(sys.damping * sys.omega) * T)  # the slowest-decaying mode
    scale = 2.0 * (sys.e[0] + sys.e[1]) + 1e-300
    atol = atol_rel * scale
    w0 = phi_m @ z0 + sys.boundary(xm, 0.0, theta00)

    def cond(c):
        z, tau, window, k, pp, d1, d2, amp, done = c
        return (k < max_periods) & ~done

    def body(c):
        z, tau, window, k, pp_prev, d1, d2, amp, done = c
        z, tau, window, pp, amp = _chunk(sys, xm, phi_m, z, tau, theta00, window, T, n_steps)
        d = jnp.abs(pp - pp_prev)
        ok = (k + 1 >= min_periods) & (jnp.maximum(d, d1) <= (rtol * pp + atol) * (1.0 - rho))
        bad = ~jnp.all(jnp.isfinite(z))
        return z, tau, window, k + 1, pp, d, d1, amp, ok | bad

    init = (
        z0,
        jnp.asarray(0.0),
        (w0, w0),
        jnp.asarray(0),
        jnp.asarray(jnp.inf),
        jnp.asarray(jnp.inf),
        jnp.asarray(jnp.inf),
        jnp.zeros((n,)),
        jnp.asarray(False),
    )
    z, tau, window, k, pp, d1, d2, amp, done = jax.lax.while_loop(cond, body, init)
    finite = jnp.all(jnp.isfinite(z)) & jnp.isfinite(pp)
    converged = done & finite & (jnp.maximum(d1, d2) <= (rtol * pp + atol) * (1.0 - rho))
    theta = theta00 + sys.Omega[0] * tau
    return SteadyState(
        pp=pp * belt.span, amplitude=amp, z=z, theta=theta, periods=k * periods_per_chunk, converged=converged
    )


def _project(belt: NonlinearBelt, v_old, v_new, z):
    """Modal state at speed v_old -> modal coordinates at v_new (same displacement and velocity)."""
    n = belt.n_modes
    x, wq = _gauss(n)

    def basis(v):
        psi, dpsi = mode_shapes(x, v, n)
        om = jnp.pi * jnp.arange(1, n + 1, dtype=float)[:, None] * (1 - v**2)
        # state vectors (velocity field, displacement field, displacement slope) of zeta^R, zeta^I
        vel = jnp.concatenate([-om * psi.imag, om * psi.real])
        dis = jnp.concatenate([psi.real, psi.imag])
        slope = jnp.concatenate([dpsi.real, dpsi.imag])
        return vel, dis, slope

    vo, do, so = basis(v_old)
    vn, dn, sn = basis(v_new)
    gram = (vn * wq) @ vn.T + (1 - v_new**2) * (sn * wq) @ sn.T
    cross = (vn * wq) @ vo.T + (1 - v_new**2) * (sn * wq) @ so.T
    return jnp.linalg.solve(gram, cross @ z)


def _check_common(owner, belt, speeds, at, name="speed"):
    """The belt, the running speed(s) `name` (real; in (0, wave_speed) when concrete, recorded when traced)
    and the measurement point `at` (inside the span)."""
    if not isinstance(belt, NonlinearBelt):
        raise TypeError(f"{owner}: parameter `belt` must be a NonlinearBelt; got {type(belt).__name__}")
    check_real(name, speeds, "m/s", owner)
    if is_concrete(speeds) and is_concrete(belt.wave_speed):
        s = np.atleast_1d(np.asarray(speeds, dtype=float))
        vt = float(np.min(np.asarray(belt.wave_speed)))
        bad = s[~np.isfinite(s) | (s < 0) | (s >= vt)]
        if bad.size:
            raise ValueError(
                f"{owner}: parameter `{name}` (running speed) must lie in [0, wave_speed) = [0, {vt:g}) m/s "
                f"(sub-critical travelling string); got {bad.tolist()} m/s"
            )
        if np.any(s <= 0):
            raise ValueError(
                f"{owner}: parameter `{name}` must be > 0 m/s (a steady state needs the pulleys to turn); "
                f"got {s[s <= 0].tolist()} m/s"
            )
    else:
        belt.check_speed(speeds)  # traced: recorded
    if at is not None:
        check_scalar("at", at, "m", owner)
        if is_concrete(at) and is_concrete(belt.span):
            a, span = float(np.asarray(at)), float(np.max(np.asarray(belt.span)))
            if not (0 < a < span):
                raise ValueError(
                    f"{owner}: parameter `at` (measurement point) must lie inside the span (0, {span:g}) m; got {a}"
                )


def _z0(owner, belt, z0, name="z0", batch=False):
    """The initial modal state(s) `z0`: shape (2N,) ((K, 2N) for `batch`), real; rest when None."""
    n2 = 2 * belt.n_modes
    if z0 is None:
        return jnp.zeros((n2,))
    check_real(name, z0, owner=owner)
    z0 = jnp.asarray(z0, dtype=float)
    if batch:
        z0 = jnp.atleast_2d(z0)
    if z0.shape != ((max(z0.shape[0], 1), n2) if batch and z0.ndim == 2 else (n2,)):
        shape = f"(K, {n2})" if batch else f"({n2},)"
        raise ValueError(
            f"{owner}: parameter `{name}` (initial modal state{'s' if batch else ''}: zeta_r, zeta_i of the belt's "
            f"{belt.n_modes} mode{'s' if belt.n_modes != 1 else ''}) must have shape {shape}; got shape {z0.shape}"
        )
    if is_concrete(z0) and not bool(np.all(np.isfinite(np.asarray(z0)))):
        raise ValueError(f"{owner}: parameter `{name}` must be finite; got {np.asarray(z0).tolist()}")
    return z0


def _check_saved_steps(owner, belt: NonlinearBelt, counts: dict, n_runs: int = 1) -> None:
    """Refuse, before anything is allocated, a buffer of prod(`counts`) saved steps per run (`n_runs` runs at
    once) that would not fit in half the memory available, naming the parameter of the largest count: each saved
    step holds the 2N modal states and the time (float64) in the solver's buffer and its temporaries, about four
    copies (steps_per_period=1e9 was XLA's out-of-memory error after 6 s)."""
    total = float(n_runs) * float(np.prod([float(c) for c in counts.values()]))
    name = max(counts, key=lambda k: counts[k])
    check_fits(owner, name, 4 * 8.0 * (2 * belt.n_modes + 1) * total, f"{total:.3g} saved steps")


def _options(owner, min_periods, max_periods, steps_per_period, periods_per_chunk=1, belt=None, n_runs: int = 1):
    """The integer options of the steady-state solves, checked (a float or bool is refused, not truncated;
    `min_periods` <= `max_periods`, else no solve could end converged); with `belt`, the buffer of one chunk
    (`periods_per_chunk` x `steps_per_period` saved steps, `n_runs` runs at once) must fit in memory."""
    out = (
        check_int(owner, "min_periods", min_periods),
        check_int(owner, "max_periods", max_periods),
        check_int(owner, "steps_per_period", steps_per_period),
        check_int(owner, "periods_per_chunk", periods_per_chunk),
    )
    if belt is not None:
        _check_saved_steps(owner, belt, {"steps_per_period": out[2], "periods_per_chunk": out[3]}, n_runs)
    if out[0] > out[1]:
        raise ValueError(
            f"{owner}: parameter `min_periods` must be <= `max_periods` (a steady state is accepted after at least "
            f"min_periods forcing periods, within max_periods); got min_periods={out[0]}, max_periods={out[1]}"
        )
    return out


def _tolerances(owner, rtol, atol) -> None:
    """`rtol`, `atol` of the convergence test: finite, >= 0 and not both 0 (concrete values; a negative or NaN
    tolerance never lets the test pass, and the solve would run to `max_periods` for nothing)."""
    check_nonnegative("rtol", rtol, owner=owner)
    check_nonnegative("atol", atol, owner=owner)
    if is_concrete((rtol, atol)) and float(np.max(np.asarray(rtol))) == 0.0 and float(np.max(np.asarray(atol))) == 0:
        raise ValueError(f"{owner}: parameters `rtol` and `atol` must not both be 0 (no test of convergence passes)")


@functools.partial(jax.jit, static_argnames=("min_periods", "max_periods", "min_steps", "periods_per_chunk"))
def _steady_jit(belt, speed, z0, theta0, xm, rtol, atol, *, min_periods, max_periods, min_steps, periods_per_chunk):
    sys = belt.modal(speed)
    return _steady_core(belt, sys, z0, theta0, xm, rtol, atol, min_periods, max_periods, min_steps, periods_per_chunk)


@blas_limited
def nonlinear_steady_state(
    belt: NonlinearBelt,
    speed,
    z0=None,
    theta0=0.0,
    *,
    at=0.01,
    rtol=1e-4,
    atol=1e-7,
    min_periods: int = 4,
    max_periods: int = 3000,
    steps_per_period: int = 64,
    periods_per_chunk: int = 1,
) -> SteadyState:
    """Steady state at running speed `speed` [m/s] from modal state `z0` (default: rest).

    `at`: measurement point [m] from the driven pulley (x = 0). `rtol`/`atol`: convergence
    tolerances on the per-period peak-to-peak (atol relative to the pulleys' total run-out).
    Does not raise when not converged: check `.converged` (see `speed_sweep` for raising).
    """
    o = "nonlinear_steady_state"
    check_scalar("speed", speed, "m/s", o)
    _check_common(o, belt, speed, at)
    min_periods, max_periods, steps_per_period, periods_per_chunk = _options(
        o, min_periods, max_periods, steps_per_period, periods_per_chunk, belt
    )
    _tolerances(o, rtol, atol)
    check_scalar("theta0", theta0, "rad", o)
    return _steady_jit(
        belt,
        jnp.asarray(speed, dtype=float),
        _z0(o, belt, z0),
        jnp.asarray(theta0, dtype=float),
        belt.sensor_x(at),
        jnp.asarray(rtol, dtype=float),
        jnp.asarray(atol, dtype=float),
        min_periods=min_periods,
        max_periods=max_periods,
        min_steps=steps_per_period,
        periods_per_chunk=periods_per_chunk,
    )


def _sweep_core(belt, speeds, z0, theta0, xm, rtol, atol, min_periods, max_periods, min_steps, periods_per_chunk):
    v_first = speeds[0] / belt.wave_speed

    def step(carry, speed):
        z, theta, v_prev = carry
        sys = belt.modal(speed)
        z = _project(belt, v_prev, sys.v, z)
        ss = _steady_core(belt, sys, z, theta, xm, rtol, atol, min_periods, max_periods, min_steps, periods_per_chunk)
        return (ss.z, ss.theta, sys.v), ss

    _, steady = jax.lax.scan(step, (z0, theta0, v_first), speeds)
    return SweepResult(speeds=speeds, steady=steady)


@functools.partial(jax.jit, static_argnames=("min_periods", "max_periods", "min_steps", "periods_per_chunk"))
def _sweep_jit(belt, speeds, z0, theta0, xm, rtol, atol, *, min_periods, max_periods, min_steps, periods_per_chunk):
    return _sweep_core(belt, speeds, z0, theta0, xm, rtol, atol, min_periods, max_periods, min_steps, periods_per_chunk)


@blas_limited
def nonlinear_sweep(
    belt: NonlinearBelt,
    speeds,
    z0=None,
    theta0=0.0,
    *,
    at=0.01,
    rtol=1e-4,
    atol=1e-7,
    min_periods: int = 4,
    max_periods: int = 3000,
    steps_per_period: int = 64,
    periods_per_chunk: int = 1,
) -> SweepResult:
    """Quasi-static sweep over `speeds` [m/s] (in the given order), each speed started from the
    previous speed's final state (the first from `z0`, default rest). Jit-compiled; `vmap` it
    over belts (damping, v_l, ...) or initial states for many sweeps at once. Does not raise on
    non-convergence: see `.converged` (or use `speed_sweep`)."""
    return _nonlinear_sweep(
        "nonlinear_sweep",
        belt,
        speeds,
        z0,
        theta0,
        at,
        rtol,
        atol,
        min_periods,
        max_periods,
        steps_per_period,
        periods_per_chunk,
    )


def _nonlinear_sweep(
    o, belt, speeds, z0, theta0, at, rtol, atol, min_periods, max_periods, steps_per_period, periods_per_chunk
) -> SweepResult:
    """`nonlinear_sweep`, its arguments checked in the name of `o` (the function the user called)."""
    check_real("speeds", speeds, "m/s", o)
    speeds = jnp.asarray(speeds, dtype=float)
    if speeds.ndim != 1 or speeds.shape[0] < 1:
        raise ValueError(
            f"{o}: parameter `speeds` must be a 1-D array of running speeds [m/s]; got shape {speeds.shape}"
        )
    _check_common(o, belt, speeds, at, "speeds")
    min_periods, max_periods, steps_per_period, periods_per_chunk = _options(
        o, min_periods, max_periods, steps_per_period, periods_per_chunk, belt
    )
    _tolerances(o, rtol, atol)
    check_scalar("theta0", theta0, "rad", o)
    return _sweep_jit(
        belt,
        speeds,
        _z0(o, belt, z0),
        jnp.asarray(theta0, dtype=float),
        belt.sensor_x(at),
        jnp.asarray(rtol, dtype=float),
        jnp.asarray(atol, dtype=float),
        min_periods=min_periods,
        max_periods=max_periods,
        min_steps=steps_per_period,
        periods_per_chunk=periods_per_chunk,
    )


def check_converged(result: SweepResult | SteadyState, speeds=None, max_periods=None):
    """Raise `SteadyStateError` naming the speeds [m/s] where no steady state was reached."""
    conv = result.converged
    if not is_concrete(conv):
        return result
    conv = np.asarray(conv)
    if np.all(conv):
        return result
    if speeds is None:  # a sweep knows its speeds; a single steady state is named by its caller's
        speeds = result.speeds if isinstance(result, SweepResult) else np.nan
    sp = np.atleast_1d(np.asarray(speeds, dtype=float))
    bad = np.broadcast_to(sp, conv.shape)[~conv] if sp.shape == conv.shape or sp.size == 1 else sp
    lim = f" within max_periods={max_periods} forcing periods" if max_periods else ""
    raise SteadyStateError(
        f"no steady state reached{lim} at running speed(s) {np.round(np.unique(bad), 6).tolist()} m/s "
        "(too little damping, a too tight rtol, or an unbounded response); raise max_periods or damping"
    )


@reraising("speed_sweep")
@blas_limited
def speed_sweep(
    belt: NonlinearBelt,
    speeds,
    z0=None,
    *,
    at=0.01,
    rtol=1e-4,
    atol=1e-7,
    min_periods: int = 4,
    max_periods: int = 3000,
    steps_per_period: int = 64,
    periods_per_chunk: int = 1,
    throw: bool = True,
):
    """Peak-to-peak displacement [m] at `at` (default 1 cm from the driven pulley) per speed of a
    quasi-static sweep over `speeds` [m/s] in the given order (`speeds[::-1]` sweeps down).

    Raises `SteadyStateError` naming the speeds where the steady state was not reached
    (`throw=False` returns the amplitudes anyway; under `jit`/`vmap` an `eqx.error_if` fires).

    A belt whose traced parameters (a `vmap` over damping ratios, ...) break their ranges raises `ValueError`
    whose first line names the parameter and its range, before the sweep runs (under the caller's `jit`:
    JAX's run-time error, the same message after its stack); `throw=False` gives NaN for that element.
    """
    if throw:
        checks = traced_checks(belt)  # empty for a concrete belt (checked when it was built)
        if checks:
            # attached to a sweep input, so they run before the sweep and lead: a bad parameter is reported
            # as such, not as the missing steady state it causes
            rtol = guard(jnp.asarray(rtol, dtype=float), checks, throw=True)[0]
    res = _nonlinear_sweep(
        "speed_sweep",
        belt,
        speeds,
        z0,
        0.0,
        at,
        rtol,
        atol,
        min_periods,
        max_periods,
        steps_per_period,
        periods_per_chunk,
    )
    pp = res.pp
    if throw:
        if is_concrete(res.converged):
            check_converged(res, max_periods=max_periods)
        else:
            pp = eqx.error_if(
                pp,
                ~jnp.all(res.converged),
                "speed_sweep: no steady state reached at some speed; call jaxbelt.nonlinear_sweep to see which",
            )
    return pp


@blas_limited
def nonlinear_basins(
    belt: NonlinearBelt,
    speed,
    z0s,
    *,
    at=0.01,
    rtol=1e-4,
    atol=1e-7,
    min_periods: int = 4,
    max_periods: int = 3000,
    steps_per_period: int = 64,
) -> SteadyState:
    """Steady states at one speed reached from each initial modal state in `z0s` (shape (K, 2N)),
    computed with `vmap` (Fig. 6: in the hysteresis band, two stable branches)."""
    o = "nonlinear_basins"
    check_scalar("speed", speed, "m/s", o)
    _check_common(o, belt, speed, at)
    if z0s is None:
        raise TypeError(f"{o}: parameter `z0s` (initial modal states, shape (K, {2 * belt.n_modes})) is required")
    min_periods, max_periods, steps_per_period, _ = _options(o, min_periods, max_periods, steps_per_period)
    if np.ndim(z0s) == 2:  # the runs' buffers (vmap: all at once), bounded before the initial states are converted
        _check_saved_steps(o, belt, {"z0s": int(np.shape(z0s)[0]), "steps_per_period": steps_per_period})
    z0s = _z0(o, belt, z0s, "z0s", batch=True)
    _tolerances(o, rtol, atol)

    def f(z):
        return _steady_jit(
            belt,
            jnp.asarray(speed, dtype=float),
            z,
            jnp.asarray(0.0),
            belt.sensor_x(at),
            jnp.asarray(rtol, dtype=float),
            jnp.asarray(atol, dtype=float),
            min_periods=min_periods,
            max_periods=max_periods,
            min_steps=steps_per_period,
            periods_per_chunk=1,
        )

    return jax.vmap(f)(z0s)


@functools.partial(jax.jit, static_argnames=("periods", "steps_per_period"))
def _trajectory_jit(belt, speed, z0, *, periods, steps_per_period):
    sys = belt.modal(speed)
    T = 2 * jnp.pi / sys.Omega[0]
    n = periods * steps_per_period
    atol = 1e-3 * _ODE_ATOL * (sys.e[0] + sys.e[1] + 1e-300)
    taus, zs = _solve_period(sys, z0, 0.0, periods * T, 0.0, n, 1e-3 * _ODE_RTOL, atol)
    return taus * belt.span / belt.wave_speed, jnp.concatenate([z0[None], zs]), sys


@blas_limited
def nonlinear_trajectory(belt: NonlinearBelt, speed, z0=None, periods: int = 200, steps_per_period: int = 64):
    """Modal state history from `z0` at a fixed speed: `(t [s], zs (periods*steps+1, 2N))`,
    for phase-plane plots ($\\zeta^R_1$ against $\\zeta^I_1$, Fig. 6). diffrax (Tsit5, tight
    tolerances), saved `steps_per_period` times per forcing period."""
    o = "nonlinear_trajectory"
    check_scalar("speed", speed, "m/s", o)
    _check_common(o, belt, speed, None)
    periods = check_int(o, "periods", periods)
    steps_per_period = check_int(o, "steps_per_period", steps_per_period)
    _check_saved_steps(o, belt, {"periods": periods, "steps_per_period": steps_per_period})
    ts, zs, _ = _trajectory_jit(
        belt, jnp.asarray(speed, dtype=float), _z0(o, belt, z0), periods=periods, steps_per_period=steps_per_period
    )
    return jnp.concatenate([jnp.zeros((1,)), ts]), zs
