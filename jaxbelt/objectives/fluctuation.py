"""Speed-fluctuation index χ of a motor-driven mechanism (Incerti, 2012, eq. 22).

$\\chi = \\dfrac{\\dot\\varphi_{max} - \\dot\\varphi_{min}}{\\dot\\varphi_{av}}$ over a time window
$[t_0, t_1]$, with $\\dot\\varphi$ the motor speed. The paper calls $\\dot\\varphi_{av}$ "its average
value" without saying which: `average="mean"` (default) is the time mean
$\\frac{1}{t_1 - t_0}\\int_{t_0}^{t_1}\\dot\\varphi\\,dt$ (trapezoid rule on the samples),
`average="midrange"` is $(\\dot\\varphi_{max} + \\dot\\varphi_{min})/2$, for which
$\\chi = 2(\\max - \\min)/(\\max + \\min)$. They differ at second order in the fluctuation (for the
open-loop run of the paper by a few points of χ). The paper's closed-loop window 0.375-0.5 s is
its own choice: at 30 rad/s it covers 0.6 of a crank turn, not a whole one.

Max and min make the exact index
non-smooth (its gradient only sees the two extreme samples and jumps when they move); the
smooth index replaces them by time-weighted log-mean-exp at temperature
$\\tau = \\text{temperature}\\cdot\\dot\\varphi_{av}$:

$\\mathrm{smax}(\\dot\\varphi) = \\tau\\log\\dfrac{\\int_{t_0}^{t_1} e^{\\dot\\varphi/\\tau}dt}{t_1 - t_0}
 \\le \\dot\\varphi_{max}$, and $\\mathrm{smin} = -\\mathrm{smax}(-\\dot\\varphi)$,

so that the smooth χ is slightly below the exact one, independent of the sampling once the
samples resolve the peaks, and tends to it as the temperature goes to zero. Optimisers
(`tune_pid`) descend the smooth index and report the exact one.

All functions are pure and work under `jax.jit`, `jax.grad` and `jax.vmap`.
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from .._checks import check_positive, check_range, check_scalar, collecting, is_concrete, record
from .._guard import guard, reraising
from .._threads import blas_limited
from ..scene import Scene
from ..solution import Solution
from ..solve import forward_sensitivities, simulate

_O = "fluctuation index"
_WINDOW_MSG = f"{_O}: the window [t0, t1] must contain at least two output times (parameters `t0` < `t1` [s])"


#: a sample belongs to the window [t0, t1] within this fraction of max(|last time|, 1 s)
_WINDOW_RTOL = 1e-9


def _node_weights(ts, t0, t1):
    """Trapezoid weights of the samples inside [t0, t1] (zero outside)."""
    if is_concrete((ts, t0, t1)):  # host values: numpy, the same operations (no small programs to compile)
        return _node_weights_host(ts, t0, t1)
    ts = jnp.asarray(ts, dtype=float)
    tol = _WINDOW_RTOL * jnp.maximum(jnp.abs(ts[-1]), 1.0)
    lo = ts[0] if t0 is None else t0
    hi = ts[-1] if t1 is None else t1
    inside = (ts >= lo - tol) & (ts <= hi + tol)
    seg = 0.5 * jnp.diff(ts) * (inside[:-1] & inside[1:])
    w = jnp.zeros_like(ts).at[:-1].add(seg).at[1:].add(seg)
    return inside, w


def _node_weights_host(ts, t0, t1):
    ts = np.asarray(ts, dtype=float)
    tol = _WINDOW_RTOL * max(abs(float(ts[-1])), 1.0)
    lo = ts[0] if t0 is None else float(np.asarray(t0, dtype=float))
    hi = ts[-1] if t1 is None else float(np.asarray(t1, dtype=float))
    inside = (ts >= lo - tol) & (ts <= hi + tol)
    seg = 0.5 * np.diff(ts) * (inside[:-1] & inside[1:])
    w = np.zeros_like(ts)
    w[:-1] += seg
    w[1:] += seg
    return inside, w


def _check_window(inside, w):
    """Raise (concrete) or record (traced) the check that the window holds at least two samples."""
    if is_concrete((inside, w)):
        if int(np.sum(np.asarray(inside))) < 2 or not float(np.sum(np.asarray(w))) > 0:
            raise ValueError(_WINDOW_MSG)
    else:
        record((jnp.sum(inside) >= 2) & (jnp.sum(w) > 0), _WINDOW_MSG)


def _check_bound(name, value):
    """A window bound must be a finite scalar (an infinite one would silently mean 'from the first sample')."""
    msg = f"{_O}: parameter `{name}` (a bound of the window [t0, t1]) must be finite"
    check_scalar(name, value, "s", _O)
    if is_concrete(value):
        v = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{msg}; got {v.tolist()}")
    else:
        record(jnp.all(jnp.isfinite(jnp.asarray(value, dtype=float))), msg)


def _check_inside(name, value, ts):
    """A window bound must lie within the sampled times (beyond them the window would be cut silently)."""
    msg = f"{_O}: parameter `{name}` (a bound of the window [t0, t1]) must lie within the sampled times"
    if is_concrete((value, ts)):
        t = np.asarray(ts, dtype=float)
        tol = _WINDOW_RTOL * max(abs(float(t[-1])), 1.0)
        v = float(np.asarray(value, dtype=float))
        if not (t[0] - tol <= v <= t[-1] + tol):
            raise ValueError(f"{msg} [{t[0]:g}, {t[-1]:g}] s; got {v:g}")
    else:
        t = jnp.asarray(ts, dtype=float)
        tol = _WINDOW_RTOL * jnp.maximum(jnp.abs(t[-1]), 1.0)
        record((value >= t[0] - tol) & (value <= t[-1] + tol), msg)


_AVERAGES = ("mean", "midrange")


def _check_average(average) -> None:
    if not isinstance(average, str) or average not in _AVERAGES:
        raise ValueError(f"{_O}: parameter `average` must be one of {_AVERAGES}; got {average!r}")


def _check_smooth(smooth) -> None:
    """`smooth` chooses the program: a Python (or numpy) bool, not any truthy value."""
    if not isinstance(smooth, bool | np.bool_):
        raise TypeError(f"{_O}: parameter `smooth` must be True or False; got {smooth!r}")


#: the smooth index's temperature (relative to the mean speed) may not exceed this: beyond it the smooth
#: max and min both tend to the mean, and the smooth χ to 0, whatever the fluctuation
MAX_TEMPERATURE = 1.0


def _check_temperature(temperature) -> None:
    check_scalar("temperature", temperature, owner=_O)
    check_range("temperature", temperature, lo=0.0, hi=MAX_TEMPERATURE, lo_open=True, owner=_O)


#: χ divides by the average speed: refused where |average| <= STILL_RTOL x the largest |speed| in the window
#: (the drive stands, or swings about rest) or where that largest |speed| is <= STILL_SPEED [rad/s] (it never
#: moves: its samples are rounding noise about 0)
STILL_RTOL = 1e-3
STILL_SPEED = 1e-9

_STILL_MSG = (
    f"{_O}: the average motor speed over the window [t0, t1] is ~0 (|average| <= {STILL_RTOL:g} x the largest "
    f"|speed| in the window, or the speed never exceeds {STILL_SPEED:g} rad/s): the drive stands in the window, "
    "and χ = (max - min)/|average| would divide by ~0. Choose a window where the drive runs (a set point "
    "omega_ref != 0, a larger voltage, a later window)"
)


def _check_running(speed, inside, w, average) -> None:
    """The average speed χ divides by must not be ~0 (see `STILL_RTOL`, `STILL_SPEED`): concrete values raise
    `ValueError` naming the first bad element; traced ones are recorded (a run-time error, or NaN with
    `throw=False`)."""
    if is_concrete((speed, inside, w)):
        v, m, wt = np.asarray(speed, dtype=float), np.asarray(inside, dtype=bool), np.asarray(w, dtype=float)
        if v.size == 0 or not m.any() or not np.all(np.isfinite(v[..., m])):
            return  # no window (reported by the window's check) or NaN speeds (a failed run: NaN χ)
        sel = v[..., m]
        peak = np.max(np.abs(sel), axis=-1)
        avg = (
            np.sum(np.where(wt > 0, wt * v, 0.0), axis=-1) / np.sum(wt)
            if average == "mean"
            else 0.5 * (sel.max(-1) + sel.min(-1))
        )
        still = (np.abs(avg) <= STILL_RTOL * peak) | (peak <= STILL_SPEED)
        if np.any(still):
            k = int(np.argmax(np.ravel(still)))
            where = (
                ""
                if np.ndim(still) == 0
                else f" (element {tuple(int(i) for i in np.unravel_index(k, still.shape))} of the batch)"
            )
            raise ValueError(
                f"{_O}: the {average} motor speed over the window [t0, t1] is {float(np.ravel(avg)[k]):.4g} rad/s"
                f"{where}, ~0 beside the largest |speed| {float(np.ravel(peak)[k]):.4g} rad/s in it (it must exceed "
                f"{STILL_RTOL:g} x that, and the speed {STILL_SPEED:g} rad/s): the drive stands in the window, and "
                "χ = (max - min)/|average| would divide by ~0. Choose a window where the drive runs (a set point "
                "omega_ref != 0, a larger voltage, a later window)"
            )
        return
    sel = jnp.where(inside, speed, 0.0)
    peak = jnp.max(jnp.abs(sel), axis=-1)
    if average == "mean":
        avg = jnp.sum(jnp.where(w > 0, w * speed, 0.0), axis=-1) / jnp.sum(w)
    else:
        avg = 0.5 * (
            jnp.max(jnp.where(inside, speed, -jnp.inf), axis=-1) + jnp.min(jnp.where(inside, speed, jnp.inf), axis=-1)
        )
    # NaN speeds (a failed run, flagged by the solve) are not "standing": NaN χ follows from them
    record(~((jnp.abs(avg) <= STILL_RTOL * peak) | (peak <= STILL_SPEED)), _STILL_MSG)


def _check_set_point(pid) -> None:
    """A controller's set point `omega_ref` [rad/s] must be != 0 for χ: at 0 the drive is held at rest, its speed
    creeps about 0 and χ divides by it (concrete: `ValueError` now, before the simulation; traced: recorded)."""
    w0 = getattr(pid, "omega_ref", None)
    if w0 is None:
        return
    msg = (
        f"{_O}: parameter `omega_ref` (the controller's set point) must be != 0 rad/s for χ, which divides by "
        "the mean speed: at 0 the drive is held at rest"
    )
    if is_concrete(w0):
        v = np.asarray(w0, dtype=float)
        if np.any(v == 0):
            raise ValueError(f"{msg}; got {v.tolist()}")
    else:
        record(w0 != 0, msg)


def _warn_if_not_running(speed, inside) -> None:
    """Warn when the motor speed changes sign inside the window, or its mean is 0 (concrete values only): χ
    compares the fluctuation with the mean speed of a drive that runs one way, and a speed through zero makes
    that mean ~0 or meaningless, so the index is a large, arbitrary number. (A run from rest, whose speed is 0
    at the first sample, runs one way.)"""
    if not is_concrete((speed, inside)):
        return
    w, m = np.asarray(speed, dtype=float), np.asarray(inside, dtype=bool)
    if w.size == 0 or not m.any():
        return
    sel = w[..., m]
    lo, hi = np.min(sel, axis=-1), np.max(sel, axis=-1)
    mean_zero = np.mean(sel, axis=-1) == 0
    stops = np.isfinite(lo) & np.isfinite(hi) & (((lo < 0) & (hi > 0)) | mean_zero)
    if np.any(stops):
        k = int(np.argmax(np.ravel(stops)))
        lo_k, hi_k, mean_k = np.ravel(lo)[k], np.ravel(hi)[k], float(np.mean(np.reshape(sel, (-1, sel.shape[-1]))[k]))
        where = "" if stops.ndim == 0 else f" (element {np.unravel_index(k, stops.shape)} of the batch)"
        warnings.warn(
            f"{_O}: the motor speed changes sign inside the window{where} (from {lo_k:.4g} to {hi_k:.4g} "
            f"rad/s, mean {mean_k:.4g} rad/s): the drive reverses or stands, so χ = (max - min)/|mean| divides by a "
            "mean that is not a running speed and is no measure of the drive's fluctuation. Choose a window where "
            "the drive runs (a larger voltage or set point, a later window).",
            RuntimeWarning,
            stacklevel=3,
        )


@reraising(_O)
def chi_from_samples(
    ts,
    speed,
    t0=None,
    t1=None,
    *,
    smooth: bool = False,
    temperature: ArrayLike = 3e-4,
    average="mean",
    throw: bool = True,
):
    """χ of the sampled signal `speed` (..., N) at times `ts` (N,) over [t0, t1].

    `average`: `"mean"` (time mean, default) or `"midrange"` ((max + min)/2) for $\\dot\\varphi_{av}$.

    `smooth=False`: exact $(\\max - \\min)/|\\text{average}|$ over the samples in the window (time
    average by the trapezoid rule; its magnitude, so that a drive running backwards has the χ of the
    same motion forwards). `t0`, `t1` must lie within the sampled times. `smooth=True`: log-mean-exp max and min at temperature
    `temperature` × average speed (dimensionless, default 3e-4). `throw=False`: a traced check that fails
    makes the value NaN instead of raising (see `simulate`). An average speed ~0 over the window is refused
    (see `fluctuation_index`).
    """
    _check_average(average)
    _check_smooth(smooth)
    speed = jnp.asarray(speed, dtype=float)
    # concrete: each check raises at once; traced: recorded and attached to the result (a run-time error)
    with collecting() as checks:
        for name, bound in (("t0", t0), ("t1", t1)):
            if bound is not None:
                _check_bound(name, bound)
                _check_inside(name, bound, ts)
        if smooth:
            _check_temperature(temperature)
        inside, w = _node_weights(ts, t0, t1)
        _check_window(inside, w)
        _check_running(speed, inside, w, average)
    _warn_if_not_running(speed, inside)
    if not checks and is_concrete((speed, temperature)):  # eager: one compiled program, not one per operation
        return _chi_program(speed, inside, w, jnp.asarray(temperature, dtype=float), bool(smooth), average)
    return guard(_chi(speed, inside, w, smooth, temperature, average), checks, throw=throw)[0]


@functools.partial(jax.jit, static_argnums=(4, 5))
def _chi_program(speed, inside, w, temperature, smooth, average):
    return _chi(speed, inside, w, smooth, temperature, average)


def _chi(speed, inside, w, smooth, temperature, average):
    wsum = jnp.sum(w)
    avg = jnp.sum(jnp.where(w > 0, w * speed, 0.0), axis=-1) / wsum  # samples outside the window: not read
    if not smooth:
        vmax = jnp.max(jnp.where(inside, speed, -jnp.inf), axis=-1)
        vmin = jnp.min(jnp.where(inside, speed, jnp.inf), axis=-1)
        if average == "midrange":
            avg = 0.5 * (vmax + vmin)
        return (vmax - vmin) / jnp.abs(avg)
    tau = temperature * jnp.abs(avg)
    x = speed / tau[..., None] if jnp.ndim(tau) else speed / tau
    logw = jnp.log(jnp.where(w > 0, w / wsum, 1.0))
    x_in = jnp.where(w > 0, x, -jnp.inf)
    xn_in = jnp.where(w > 0, -x, -jnp.inf)
    smax = jax.nn.logsumexp(x_in + logw, axis=-1)
    smin = -jax.nn.logsumexp(xn_in + logw, axis=-1)
    if average == "midrange":
        avg = 0.5 * tau * (smax + smin)
    return tau * (smax - smin) / jnp.abs(avg)


def _speed(sol):
    if "motor_speed" in sol.outputs:
        return sol.outputs["motor_speed"]
    if sol.ys is not None and "alpha_dot" in sol.state_names:
        # χ is a ratio: the constant gear ratio z between crank and motor speed cancels.
        return sol["alpha_dot"]
    raise ValueError(
        "fluctuation_index needs the motor speed: simulate with observe=('motor_speed',) or keep the state"
    )


@reraising(_O)
@blas_limited
def fluctuation_index(sol, t0=None, t1=None, *, smooth: bool = False, temperature=3e-4, average="mean"):
    """Fluctuation index χ (eq. 22) of the motor speed in a `Solution`, over [t0, t1] [s].

    Uses the observed `motor_speed` output, else the crank speed state (the gear ratio cancels
    in the ratio). `smooth=True` gives the log-sum-exp version (see module docstring).
    `average` is `"mean"` (time mean, default) or `"midrange"` (see module docstring).
    Returns a dimensionless scalar (0.543 means 54.3 %). Called eagerly, it warns (`RuntimeWarning`) when the
    motor speed passes through zero inside the window: the drive stops or reverses there, and χ is no
    measure of its fluctuation. Where the average speed over the window is ~0 (|average| <= `STILL_RTOL` =
    1e-3 x the largest |speed| there, or no speed above `STILL_SPEED` = 1e-9 rad/s: the drive stands) it
    raises `ValueError` with the reason; traced (jit/vmap/grad), a run-time error with the same message (NaN
    with `chi_from_samples(..., throw=False)`). A NaN or infinite speed in the window of a solution whose `success`
    flag is True raises `ValueError` naming `sol` (a failed run, `success` False, gives NaN: the flag says why).
    """
    if not isinstance(sol, Solution):
        raise TypeError(f"{_O}: parameter `sol` must be a jaxbelt Solution (from `simulate`); got {type(sol).__name__}")
    speed = _speed(sol)
    chi = chi_from_samples(sol.ts, speed, t0, t1, smooth=smooth, temperature=temperature, average=average)
    if is_concrete((chi, sol.success)) and bool(np.all(np.asarray(sol.success))):
        if not np.all(np.isfinite(np.asarray(chi))):
            _refuse_nonfinite_speed(np.asarray(sol.ts, dtype=float), np.asarray(speed, dtype=float), t0, t1)
    return chi


def _refuse_nonfinite_speed(ts, v, t0, t1) -> None:
    """`ValueError` naming `sol` and the first non-finite speed sample in the window [t0, t1] (host values)."""
    lo = ts[0] if t0 is None else float(t0)
    hi = ts[-1] if t1 is None else float(t1)
    bad = ~np.all(np.isfinite(v.reshape(-1, v.shape[-1])), axis=0) & (ts >= lo - 1e-9) & (ts <= hi + 1e-9)
    k = int(np.argmax(bad))
    raise ValueError(
        f"{_O}: parameter `sol` holds a non-finite motor speed in the window [t0, t1] (first at t = {ts[k]:.6g} s, "
        f"sample {k}) although its `success` flag is True: χ would be NaN. Check how the solution was made (its "
        "outputs should be finite where `success` is True)"
    )


def _grid(t1, step, step_name):
    """The output grid 0..t1 [s] with spacing `step` [s] (its size fixes the program: concrete values)."""
    for name, value in (("t1", t1), (step_name, step)):
        if not is_concrete(value):
            raise ValueError(
                f"{_O}: `{name}` fixes the number of output times, so it must be a concrete number (not traced)"
            )
        check_scalar(name, value, "s", _O)
        check_positive(name, value, "s", owner=_O)
    t1, step = float(t1), float(step)
    if t1 / step > 1e7:
        raise ValueError(f"{_O}: `t1` / `{step_name}` = {t1 / step:.3g} output times; at most 1e7")
    n = int(round(t1 / step)) + 1
    return np.linspace(0.0, t1, n)


def _check_window_on_grid(ts, t0, t1, owner: str = _O, hint: str = "`dt_save`, or `dt` with method='rk4'") -> None:
    """The window's checks on the output grid `ts` (host values), before anything is simulated: bounds
    finite and within the grid, at least two output times inside (`chi_from_samples` checks the same,
    after the simulation). Traced bounds: left to `chi_from_samples`."""
    for name, bound in (("t0", t0), ("t1", t1)):
        if bound is not None:
            _check_bound(name, bound)
    if not is_concrete((t0, t1)):
        return
    for name, bound in (("t0", t0), ("t1", t1)):
        if bound is not None:
            _check_inside(name, bound, ts)
    tol = _WINDOW_RTOL * max(abs(float(ts[-1])), 1.0)
    lo = ts[0] if t0 is None else float(t0)
    hi = ts[-1] if t1 is None else float(t1)
    if not lo < hi:
        raise ValueError(
            f"{owner}: parameters `t0` and `t1` must satisfy t0 < t1 [s]; got the window [{lo:g}, {hi:g}] s"
        )
    inside = (ts >= lo - tol) & (ts <= hi + tol)
    if int(np.sum(inside)) < 2:
        step = ts[1] - ts[0] if ts.size > 1 else 0.0
        raise ValueError(
            f"{owner}: the window [t0, t1] must contain at least two output times; [{lo:g}, {hi:g}] s holds "
            f"{int(np.sum(inside))} of the output times, spaced {step:g} s (widen the window or refine the grid: "
            f"{hint})"
        )


def _check_options(peak_temperature, temperature, smooth=True) -> None:
    """Concrete checks of the options of `closed_loop_metrics` and `fluctuation_objective` (traced: recorded)."""
    _check_smooth(smooth)
    check_scalar("peak_temperature", peak_temperature, "V or A", _O)
    check_positive("peak_temperature", peak_temperature, owner=_O)
    if smooth:
        _check_temperature(temperature)


def _run_from_rest(drive, pid, ts, observe, state, method, rtol, atol, dt, max_steps, adjoint, throw=True):
    """`simulate` of `drive` under `pid` from rest at t = 0, with outputs at the times `ts`."""
    scene = Scene(drive, pid, ts=ts, t0=0.0, observe=observe, state=state)
    return simulate(
        scene, method=method, rtol=rtol, atol=atol, dt=dt, max_steps=max_steps, adjoint=adjoint, throw=throw
    )


def closed_loop_metrics(
    drive,
    pid,
    t0: ArrayLike = 0.375,
    t1: ArrayLike = 0.5,
    *,
    temperature: ArrayLike = 3e-4,
    peak_temperature: ArrayLike = 0.5,
    dt_save: ArrayLike = 5e-4,
    method="ode",
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-8,
    dt: ArrayLike = 1e-3,
    max_steps=100_000,
    adjoint=None,
    average="mean",
    throw: bool = True,
):
    """χ (exact and smooth) over [t0, t1] and peak |voltage| and |current| over [0, t1].

    Simulates `drive` with the controller (or command) `pid` from rest at t = 0. Peaks are given
    exact (`v_peak`, `i_peak`) and smooth (`v_peak_smooth`, `i_peak_smooth`: log-sum-exp with
    temperature `peak_temperature` in V or A, >= the exact peak); `mean_speed` is the time mean of the
    motor speed over [t0, t1] [rad/s] (what χ divides by). `average` as in `chi_from_samples`.
    `throw`: as in `simulate` (False: a failed solve or check gives NaN values, nothing raises; the program
    then holds no host callback). Returns a dict of scalars.
    """
    ts, option_checks = _metrics_grid(t0, t1, temperature, peak_temperature, dt_save, method, dt, average)
    with collecting() as set_point:  # concrete: raise now, before the simulation
        _check_set_point(pid)
    option_checks = option_checks + set_point
    sol = _run_from_rest(
        drive, pid, ts, ("motor_speed", "voltage"), True, method, rtol, atol, dt, max_steps, adjoint, throw
    )
    speed, v, ys = sol.outputs["motor_speed"], sol.outputs["voltage"], sol.ys
    assert ys is not None  # `_run_from_rest(..., state=True)`
    out = _metrics_from(ts, speed, v, ys[:, 2], t0, t1, temperature, peak_temperature, average, throw)
    return guard(out, option_checks, throw=throw)[0]


def _metrics_grid(t0, t1, temperature, peak_temperature, dt_save, method, dt, average):
    """The metrics' output grid 0..t1 and their option checks, `(ts, checks)`: concrete options are checked (and
    raise) now, before anything is simulated; traced ones come back as checks to attach to the values."""
    _check_average(average)
    ts = _grid(t1, *((dt, "dt") if method == "rk4" else (dt_save, "dt_save")))
    with collecting() as option_checks:
        _check_options(peak_temperature, temperature)
        _check_window_on_grid(ts, t0, t1)
    return ts, option_checks


def _metrics_from(ts, speed, v, i, t0, t1, temperature, peak_temperature, average, throw):
    """`closed_loop_metrics`' values from the sampled speed [rad/s], voltage [V] and current [A]."""

    def speak(x):
        return peak_temperature * jax.nn.logsumexp(jnp.abs(x) / peak_temperature)

    def peak(x):
        # the largest |x| taken where it is: its derivative is that sample's. (`jnp.max`'s derivative finds the
        # maximum again by equality with the samples, which fails, 0/0, where XLA computes the samples twice and
        # rounds them differently, as it may for samples recomputed from a linearised trajectory.)
        a = jnp.abs(x)
        return jnp.take(a, jnp.argmax(a))

    return {
        "chi": chi_from_samples(ts, speed, t0, t1, average=average, throw=throw),
        "chi_smooth": chi_from_samples(
            ts, speed, t0, t1, smooth=True, temperature=temperature, average=average, throw=throw
        ),
        "v_peak": peak(v),
        "i_peak": peak(i),
        "v_peak_smooth": speak(v),
        "i_peak_smooth": speak(i),
        "mean_speed": _window_mean(ts, speed, t0, t1),
    }


def linearised_closed_loop_metrics(
    drive,
    pid_of,
    p,
    t0: ArrayLike = 0.375,
    t1: ArrayLike = 0.5,
    *,
    temperature: ArrayLike = 3e-4,
    peak_temperature: ArrayLike = 0.5,
    dt_save: ArrayLike = 5e-4,
    method="ode",
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-8,
    dt: ArrayLike = 1e-3,
    max_steps=100_000,
    average="mean",
):
    """`q -> closed_loop_metrics(drive, pid_of(q), ...)` to first order about the parameters `p` (a vector).

    One simulation with forward sensitivities (`jaxbelt.solve.forward_sensitivities`) gives the trajectory at
    `p` and its derivative; the function returned evaluates the metrics on the trajectory extrapolated
    linearly to `q`, with `pid_of(q)`'s own outputs (the voltage). Its value at `q = p` is
    `closed_loop_metrics`' (to the solver's tolerance) and its derivative there (`jax.jacfwd`) the derivative
    of the exact metrics, without differentiating through the solver. A failed run or check makes every
    value NaN (as `throw=False`). Options as in `closed_loop_metrics`.
    """
    ys, sens = linearisation_run(
        drive, pid_of, p, t1, dt_save=dt_save, method=method, rtol=rtol, atol=atol, dt=dt, max_steps=max_steps
    )
    return linearised_metrics(
        drive,
        pid_of,
        p,
        ys,
        sens,
        t0,
        t1,
        temperature=temperature,
        peak_temperature=peak_temperature,
        dt_save=dt_save,
        method=method,
        dt=dt,
        average=average,
    )


def linearisation_run(
    drive,
    pid_of,
    p,
    t1: ArrayLike = 0.5,
    *,
    dt_save: ArrayLike = 5e-4,
    method="ode",
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-8,
    dt: ArrayLike = 1e-3,
    max_steps=100_000,
):
    """The simulation `linearised_closed_loop_metrics` linearises about: `(ys, sens)`, the trajectory of `drive` under
    `pid_of(p)` on the metrics' output grid over [0, t1] [s] (N, n) and its sensitivities to `p` (N, n, P), NaN where
    the run failed. Split from the metrics (`linearised_metrics`) so that a caller can compile the two apart."""
    ts = _grid(t1, *((dt, "dt") if method == "rk4" else (dt_save, "dt_save")))
    p = jnp.asarray(p, dtype=float)
    model = Scene(drive, pid_of(p), ts=ts, t0=0.0).model
    ys, sens, _ = forward_sensitivities(
        model, pid_of, p, ts, method=method, rtol=rtol, atol=atol, dt=dt, max_steps=max_steps
    )
    return ys, sens


def linearised_metrics(
    drive,
    pid_of,
    p,
    ys,
    sens,
    t0: ArrayLike = 0.375,
    t1: ArrayLike = 0.5,
    *,
    temperature: ArrayLike = 3e-4,
    peak_temperature: ArrayLike = 0.5,
    dt_save: ArrayLike = 5e-4,
    method="ode",
    dt: ArrayLike = 1e-3,
    average="mean",
):
    """`linearised_closed_loop_metrics` from its simulation `(ys, sens)` (`linearisation_run` with the same `p`, `t1`,
    `dt_save`, `method` and `dt`)."""
    ts, option_checks = _metrics_grid(t0, t1, temperature, peak_temperature, dt_save, method, dt, average)
    p = jnp.asarray(p, dtype=float)
    model = Scene(drive, pid_of(p), ts=ts, t0=0.0).model

    def metrics(q):
        inp = pid_of(q)
        y = ys + jnp.einsum("tnk,k->tn", sens, q - p)
        speed = jax.vmap(lambda t, x: model.output("motor_speed", t, x, inp))(ts, y)
        v = jax.vmap(lambda t, x: model.output("voltage", t, x, inp))(ts, y)
        out = _metrics_from(ts, speed, v, y[:, 2], t0, t1, temperature, peak_temperature, average, False)
        return guard(out, option_checks, throw=False)[0]

    return metrics


def _window_mean(ts, speed, t0, t1):
    """Time mean (trapezoid rule) of `speed` over the samples in [t0, t1]."""
    _, w = _node_weights(ts, t0, t1)
    return jnp.sum(w * speed, axis=-1) / jnp.sum(w)


@reraising(_O)
@blas_limited
def fluctuation_objective(
    drive,
    pid,
    t0=0.375,
    t1=0.5,
    *,
    smooth=True,
    temperature=3e-4,
    peak_temperature=0.5,
    dt_save=5e-4,
    method="ode",
    rtol=1e-8,
    atol=1e-8,
    dt=1e-3,
    max_steps=100_000,
    adjoint=None,
    average="mean",
):
    """Pure scalar objective $\\chi(\\text{drive}, \\text{pid})$ over [t0, t1] for optimisers.

    Simulates from rest (diffrax by default; `method="rk4", dt=1e-3` reproduces the paper's
    integration) and returns the smooth χ (default) or the exact one. Differentiable with
    respect to every array field of `drive` and `pid` (use `eqx.filter_grad`), and `vmap`-able.
    The keywords are those of `closed_loop_metrics` (`peak_temperature` has no effect on χ), and the
    value is its `chi_smooth` (or `chi`) exactly: the same samples, but only the motor speed at the
    samples inside the window is stored (a quarter of them for the paper's window), which makes a
    batched sweep about 25 % faster.
    """
    _check_smooth(smooth)
    if not (is_concrete(t0) and is_concrete(t1)):  # a traced window: the whole grid, as closed_loop_metrics
        m = closed_loop_metrics(
            drive,
            pid,
            t0,
            t1,
            temperature=temperature,
            peak_temperature=peak_temperature,
            dt_save=dt_save,
            method=method,
            rtol=rtol,
            atol=atol,
            dt=dt,
            max_steps=max_steps,
            adjoint=adjoint,
            average=average,
        )
        return m["chi_smooth"] if smooth else m["chi"]
    _check_average(average)
    ts = _grid(t1, *((dt, "dt") if method == "rk4" else (dt_save, "dt_save")))
    with collecting() as option_checks:  # concrete: raise now, before the simulation; traced: attached below
        _check_options(peak_temperature, temperature, smooth)
        _check_set_point(pid)
    _check_window_on_grid(ts, t0, t1)
    keep = ts >= float(t0) - _WINDOW_RTOL * max(abs(float(ts[-1])), 1.0)  # as `_node_weights` decides
    window = ts[keep] if keep.sum() >= 2 else ts  # fewer than two: chi_from_samples names the error
    sol = _run_from_rest(drive, pid, window, ("motor_speed",), False, method, rtol, atol, dt, max_steps, adjoint)
    chi = chi_from_samples(
        window, sol.outputs["motor_speed"], t0, t1, smooth=smooth, temperature=temperature, average=average
    )
    return guard(chi, option_checks, throw=True)[0]
