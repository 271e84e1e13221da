"""Steady-state response and quasi-static speed sweeps of the non-linear belt (Moon & Wickert, 1997).

- `steady_state(belt, speed)`: integrate whole forcing periods until the transient has decayed,
  then report the peak-to-peak displacement at a point (default 1 cm from the driven pulley, as
  in the experiment) and the modal amplitudes.
- `speed_sweep(belt, speeds)`: the contract call; peak-to-peak amplitudes [m] of a quasi-static
  sweep (a `lax.scan` over speeds, each speed started from the previous final state, so the
  jump and the hysteresis band appear). `sweep(...)` returns everything (states, flags).
- `basins(belt, speed, z0s)`: steady states reached from several initial conditions (Fig. 6).
- `trajectory(belt, speed, z0, periods)`: modal state history for phase-plane plots.

## Integration and convergence criterion

Time is dimensionless ($\\tau = t v_t / L$). One forcing period $T = 2\\pi/\\Omega_0$ of the
driven pulley is integrated with classical fixed-step RK4, $n = \\max(n_{min}, \\lceil T\\,\\omega_N/0.25\\rceil)$
steps (so $\\omega_N h \\le 0.25$ for the highest mode), sampling $w(x_m)$ at every step; the peak
and trough are refined by a parabola through the three samples around them. Periods are
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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_concrete
from .models.nonlinear import ModalSystem, NonlinearBelt, _gauss, mode_shapes


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
def _rk4_step(sys: ModalSystem, z, tau, h, theta00):
    f = sys.rhs
    k1 = f(tau, z, theta00)
    k2 = f(tau + h / 2, z + h / 2 * k1, theta00)
    k3 = f(tau + h / 2, z + h / 2 * k2, theta00)
    k4 = f(tau + h, z + h * k3, theta00)
    return z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _refined(p2, p1, p0, sign):
    """Extremum (sign=+1 max, -1 min) of the parabola through three equally spaced samples."""
    a, b, c = sign * p2, sign * p1, sign * p0
    den = a - 2 * b + c
    is_peak = (b >= a) & (b >= c) & (den < 0)
    vert = b - (c - a) ** 2 / (8 * jnp.where(is_peak, den, -1.0))
    return sign * jnp.where(is_peak, vert, b)


def _steps_per_period(sys: ModalSystem, min_steps: int, periods_per_chunk: int):
    T = periods_per_chunk * 2 * jnp.pi / sys.Omega[0]
    n = jnp.maximum(min_steps * periods_per_chunk, jnp.ceil(T * sys.omega[-1] / 0.25))
    return T, n.astype(jnp.int32)


def _point_shape(sys: ModalSystem, xm, n_modes):
    psi, _ = mode_shapes(jnp.atleast_1d(xm), sys.v, n_modes)
    return jnp.concatenate([psi.real[:, 0], psi.imag[:, 0]])


def _chunk(sys: ModalSystem, xm, phi_m, z, tau0, theta00, window, T, n_steps):
    """Integrate one measurement chunk; returns new state, time, window and (max, min, amp)."""
    n = sys.n_modes
    h = T / n_steps

    def w_at(zz, tau):
        return phi_m @ zz + sys.boundary(xm, tau, theta00)

    def body(k, c):
        zz, p2, p1, mx, mn, amp = c
        tau = tau0 + k * h
        zz = _rk4_step(sys, zz, tau, h, theta00)
        p0 = w_at(zz, tau + h)
        mx = jnp.maximum(mx, _refined(p2, p1, p0, 1.0))
        mn = jnp.minimum(mn, _refined(p2, p1, p0, -1.0))
        amp = jnp.maximum(amp, jnp.sqrt(zz[:n] ** 2 + zz[n:] ** 2))
        return zz, p1, p0, mx, mn, amp

    p2, p1 = window
    init = (z, p2, p1, -jnp.inf, jnp.inf, jnp.zeros((n,)))
    z, p2, p1, mx, mn, amp = jax.lax.fori_loop(0, n_steps, body, init)
    return z, tau0 + T, (p2, p1), mx - mn, amp


def _steady_core(belt: NonlinearBelt, sys: ModalSystem, z0, theta00, xm, rtol, atol_rel,
                 min_periods, max_periods, min_steps, periods_per_chunk):
    n = belt.n_modes
    phi_m = _point_shape(sys, xm, n)
    T, n_steps = _steps_per_period(sys, min_steps, periods_per_chunk)
    rho = jnp.exp(-sys.damping * sys.omega[0] * T)
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

    init = (z0, jnp.asarray(0.0), (w0, w0), jnp.asarray(0), jnp.asarray(jnp.inf), jnp.asarray(jnp.inf),
            jnp.asarray(jnp.inf), jnp.zeros((n,)), jnp.asarray(False))
    z, tau, window, k, pp, d1, d2, amp, done = jax.lax.while_loop(cond, body, init)
    finite = jnp.all(jnp.isfinite(z)) & jnp.isfinite(pp)
    converged = done & finite & (jnp.maximum(d1, d2) <= (rtol * pp + atol) * (1.0 - rho))
    theta = theta00 + sys.Omega[0] * tau
    return SteadyState(pp=pp * belt.span, amplitude=amp, z=z, theta=theta, periods=k * periods_per_chunk,
                       converged=converged)


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


def _check_common(belt, speeds, at):
    if not isinstance(belt, NonlinearBelt):
        raise TypeError(f"expected a NonlinearBelt, got {type(belt).__name__}")
    belt.check_speed(speeds)
    if is_concrete(speeds):
        s = np.atleast_1d(np.asarray(speeds, dtype=float))
        if np.any(s <= 0):
            raise ValueError(
                f"steady state needs a running speed > 0 m/s (the pulleys must turn); got {s[s <= 0].tolist()} m/s"
            )
    if at is not None and is_concrete(at) and is_concrete(belt.span):
        a = float(np.asarray(at))
        if not (0 < a < float(np.max(np.asarray(belt.span)))):
            raise ValueError(f"measurement point `at` must lie inside the span (0, {float(belt.span):g}) m; got {a}")


def _z0(belt, z0):
    if z0 is None:
        return jnp.zeros((2 * belt.n_modes,))
    z0 = jnp.asarray(z0, dtype=float)
    if z0.shape[-1] != 2 * belt.n_modes:
        raise ValueError(f"initial modal state must have {2 * belt.n_modes} entries (zeta_r, zeta_i); got shape {z0.shape}")
    return z0


@functools.partial(jax.jit, static_argnames=("min_periods", "max_periods", "min_steps", "periods_per_chunk"))
def _steady_jit(belt, speed, z0, theta0, xm, rtol, atol, *, min_periods, max_periods, min_steps, periods_per_chunk):
    sys = belt.modal(speed)
    return _steady_core(belt, sys, z0, theta0, xm, rtol, atol, min_periods, max_periods, min_steps, periods_per_chunk)


def steady_state(belt: NonlinearBelt, speed, z0=None, theta0=0.0, *, at=0.01, rtol=1e-4, atol=1e-7,
                 min_periods: int = 4, max_periods: int = 3000, steps_per_period: int = 64,
                 periods_per_chunk: int = 1) -> SteadyState:
    """Steady state at running speed `speed` [m/s] from modal state `z0` (default: rest).

    `at`: measurement point [m] from the driven pulley (x = 0). `rtol`/`atol`: convergence
    tolerances on the per-period peak-to-peak (atol relative to the pulleys' total run-out).
    Does not raise when not converged: check `.converged` (see `speed_sweep` for raising).
    """
    _check_common(belt, speed, at)
    return _steady_jit(belt, jnp.asarray(speed, dtype=float), _z0(belt, z0), jnp.asarray(theta0, dtype=float),
                       jnp.asarray(at, dtype=float) / belt.span, jnp.asarray(rtol, dtype=float),
                       jnp.asarray(atol, dtype=float), min_periods=min_periods, max_periods=max_periods,
                       min_steps=steps_per_period, periods_per_chunk=periods_per_chunk)


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


def sweep(belt: NonlinearBelt, speeds, z0=None, theta0=0.0, *, at=0.01, rtol=1e-4, atol=1e-7,
          min_periods: int = 4, max_periods: int = 3000, steps_per_period: int = 64,
          periods_per_chunk: int = 1) -> SweepResult:
    """Quasi-static sweep over `speeds` [m/s] (in the given order), each speed started from the
    previous speed's final state (the first from `z0`, default rest). Jit-compiled; `vmap` it
    over belts (damping, v_l, ...) or initial states for many sweeps at once. Does not raise on
    non-convergence: see `.converged` (or use `speed_sweep`)."""
    speeds = jnp.asarray(speeds, dtype=float)
    if speeds.ndim != 1 or speeds.shape[0] < 1:
        raise ValueError(f"`speeds` must be a 1-D array of running speeds [m/s]; got shape {speeds.shape}")
    _check_common(belt, speeds, at)
    return _sweep_jit(belt, speeds, _z0(belt, z0), jnp.asarray(theta0, dtype=float),
                      jnp.asarray(at, dtype=float) / belt.span, jnp.asarray(rtol, dtype=float),
                      jnp.asarray(atol, dtype=float), min_periods=min_periods, max_periods=max_periods,
                      min_steps=steps_per_period, periods_per_chunk=periods_per_chunk)


def check_converged(result: SweepResult | SteadyState, speeds=None, max_periods=None):
    """Raise `SteadyStateError` naming the speeds [m/s] where no steady state was reached."""
    conv = result.converged
    if not is_concrete(conv):
        return result
    conv = np.asarray(conv)
    if np.all(conv):
        return result
    sp = np.atleast_1d(np.asarray(result.speeds if speeds is None else speeds, dtype=float))
    bad = np.broadcast_to(sp, conv.shape)[~conv] if sp.shape == conv.shape or sp.size == 1 else sp
    lim = f" within max_periods={max_periods} forcing periods" if max_periods else ""
    raise SteadyStateError(
        f"no steady state reached{lim} at running speed(s) {np.round(np.unique(bad), 6).tolist()} m/s "
        "(too little damping, a too tight rtol, or an unbounded response); raise max_periods or damping"
    )


def speed_sweep(belt: NonlinearBelt, speeds, z0=None, *, at=0.01, rtol=1e-4, atol=1e-7,
                min_periods: int = 4, max_periods: int = 3000, steps_per_period: int = 64,
                periods_per_chunk: int = 1, throw: bool = True):
    """Peak-to-peak displacement [m] at `at` (default 1 cm from the driven pulley) per speed of a
    quasi-static sweep over `speeds` [m/s] in the given order (`speeds[::-1]` sweeps down).

    Raises `SteadyStateError` naming the speeds where the steady state was not reached
    (`throw=False` returns the amplitudes anyway; under `jit`/`vmap` an `eqx.error_if` fires).
    """
    res = sweep(belt, speeds, z0, at=at, rtol=rtol, atol=atol, min_periods=min_periods,
                max_periods=max_periods, steps_per_period=steps_per_period, periods_per_chunk=periods_per_chunk)
    pp = res.pp
    if throw:
        if is_concrete(res.converged):
            check_converged(res, max_periods=max_periods)
        else:
            pp = eqx.error_if(pp, ~jnp.all(res.converged),
                              "speed_sweep: no steady state reached at some speed; call jaxbelt.sweep to see which")
    return pp


def basins(belt: NonlinearBelt, speed, z0s, *, at=0.01, rtol=1e-4, atol=1e-7, min_periods: int = 4,
           max_periods: int = 3000, steps_per_period: int = 64) -> SteadyState:
    """Steady states at one speed reached from each initial modal state in `z0s` (shape (K, 2N)),
    computed with `vmap` (Fig. 6: in the hysteresis band, two stable branches)."""
    z0s = jnp.atleast_2d(jnp.asarray(z0s, dtype=float))
    _z0(belt, z0s)
    _check_common(belt, speed, at)
    f = lambda z: _steady_jit(belt, jnp.asarray(speed, dtype=float), z, jnp.asarray(0.0),  # noqa: E731
                              jnp.asarray(at, dtype=float) / belt.span, jnp.asarray(rtol, dtype=float),
                              jnp.asarray(atol, dtype=float), min_periods=min_periods, max_periods=max_periods,
                              min_steps=steps_per_period, periods_per_chunk=1)
    return jax.vmap(f)(z0s)


@functools.partial(jax.jit, static_argnames=("periods", "steps_per_period"))
def _trajectory_jit(belt, speed, z0, *, periods, steps_per_period):
    sys = belt.modal(speed)
    T = 2 * jnp.pi / sys.Omega[0]
    h = T / steps_per_period

    def step(z, k):
        z = _rk4_step(sys, z, k * h, h, 0.0)
        return z, z

    _, zs = jax.lax.scan(step, z0, jnp.arange(periods * steps_per_period))
    taus = h * jnp.arange(1, periods * steps_per_period + 1)
    return taus * belt.span / belt.wave_speed, jnp.concatenate([z0[None], zs]), sys


def trajectory(belt: NonlinearBelt, speed, z0=None, periods: int = 200, steps_per_period: int = 64):
    """Modal state history from `z0` at a fixed speed: `(t [s], zs (periods*steps+1, 2N))`,
    for phase-plane plots ($\\zeta^R_1$ against $\\zeta^I_1$, Fig. 6)."""
    _check_common(belt, speed, None)
    sys = belt.modal(speed)
    if is_concrete(sys.omega):
        need = int(np.ceil(2 * np.pi / float(sys.Omega[0]) * float(sys.omega[-1]) / 0.25))
        steps_per_period = max(steps_per_period, need)
    ts, zs, _ = _trajectory_jit(belt, jnp.asarray(speed, dtype=float), _z0(belt, z0), periods=periods,
                                steps_per_period=steps_per_period)
    return jnp.concatenate([jnp.zeros((1,)), ts]), zs
