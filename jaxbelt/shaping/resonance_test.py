"""A firmware's resonance test, as a record of a known excitation: Klipper's sweep (`klipper_sweep`, the schedule its
`TEST_RESONANCES` and `SHAPER_CALIBRATE` commands run), the payload's response to it (`sweep_response`, exact for
a `ModalAxis`), and the axis from the raw accelerometer record of the test (`identify_axis_from_sweep`).

**Klipper's sweep** (facts from its `resonance_tester.py`): from `freq_start` (default 5 Hz) to `freq_end`
(135 Hz), the carriage is accelerated at $\\pm$`accel_per_hz`$\\cdot f$ (60 mm/s² per Hz) in segments of a quarter
period $1/(4f)$, alternating as a square wave of frequency $f$ (signs $+,-,-,+$ per period), while $f$ grows
by `hz_per_sec` (1 Hz/s) times the time elapsed: a linear sweep. Newer versions add a slow square wave of
$\\pm$`sweeping_accel` (400 mm/s²) with period `sweeping_period` (1.2 s; 0 switches it off) that moves the
carriage along the axis, starting a quarter-period ($\\sqrt2/8$ of a period) in.

The record of the test is a forced response to this known excitation, not a free decay:
`identify_axis_from_sweep` fits its transfer function, in the DFT of the whole record, with the exact model of a
record that starts and ends anywhere (its documentation gives it), the sweep's start in the record found from the
record. Its standard errors hold (the residuals are the sensor's white noise, independent between bins), where a
fit of the record's Welch estimate (the model of `identify_axis_from_psd` with `kind="klipper"`, what Klipper's own
files hold) gave errors 2-4 times too large and damping biased low.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int, device_array
from .._threads import blas_limited
from . import identify as _core
from . import psd as _psd

__all__ = ["identify_axis_from_sweep", "klipper_sweep", "sweep_response"]


#: the most held segments a sweep schedule may hold (16 MB of schedule; Klipper's default test holds about 36 600)
MAX_SWEEP_SEGMENTS = 1e6


def klipper_sweep(
    freq_start: float = 5.0,
    freq_end: float = 135.0,
    *,
    accel_per_hz: float = 0.06,
    hz_per_sec: float = 1.0,
    sweeping_accel: float = 0.4,
    sweeping_period: float = 1.2,
):
    """The carriage's acceleration in Klipper's resonance sweep: `(ends [s], accel [m/s²])`, the acceleration
    `accel[k]` held from `ends[k-1]` (0 for k = 0) to `ends[k]` (the module's documentation gives the schedule).
    SI units: `accel_per_hz` [m/s² per Hz] (Klipper's 60 mm/s²/Hz = 0.06), `hz_per_sec` [Hz/s],
    `sweeping_accel` [m/s²] (Klipper's 400 mm/s² = 0.4), `sweeping_period` [s] (0: no slow sweep)."""
    owner = "klipper_sweep"
    for name, v, lo in (
        ("freq_start", freq_start, 0.0),
        ("freq_end", freq_end, 0.0),
        ("accel_per_hz", accel_per_hz, 0.0),
        ("hz_per_sec", hz_per_sec, 0.0),
    ):
        if not (math.isfinite(float(v)) and float(v) > lo):
            raise ValueError(f"{owner}: parameter `{name}` must be finite and > {lo:g}; got {v!r}")
    if not freq_end >= freq_start:
        raise ValueError(f"{owner}: parameter `freq_end` must be >= `freq_start` ({freq_start:g} Hz); got {freq_end!r}")
    if not (
        math.isfinite(sweeping_accel)
        and sweeping_accel >= 0
        and math.isfinite(sweeping_period)
        and sweeping_period >= 0
    ):
        raise ValueError(
            f"{owner}: parameters `sweeping_accel` and `sweeping_period` must be finite and >= 0; got "
            f"{sweeping_accel!r}, {sweeping_period!r}"
        )
    # the schedule holds about 2 (freq_end^2 - freq_start^2) / hz_per_sec held segments: bounded before it is built
    n_est = 2.0 * (float(freq_end) - float(freq_start)) * (float(freq_end) + float(freq_start)) / float(hz_per_sec)
    if not n_est <= MAX_SWEEP_SEGMENTS:
        raise ValueError(
            f"{owner}: parameters `freq_start`, `freq_end`, `hz_per_sec` ({freq_start!r}, {freq_end!r}, "
            f"{hz_per_sec!r}) make a sweep of about {n_est:.3g} held segments; at most {MAX_SWEEP_SEGMENTS:g} "
            "(Klipper's default test: 36 600): lower `freq_end` or raise `hz_per_sec`"
        )
    ends, accel = [], []
    freq, sign, time = float(freq_start), 1.0, 0.0
    while freq <= freq_end + 1e-6:
        t_seg = 0.25 / freq
        a = accel_per_hz * freq
        time += t_seg
        ends.append(time)
        accel.append(sign * a)
        time += t_seg
        ends.append(time)
        accel.append(-sign * a)
        freq += 2.0 * t_seg * hz_per_sec
        sign = -sign
        if len(ends) > 2 * MAX_SWEEP_SEGMENTS:  # a step lost to rounding (freq_start ~ 1e300): no progress
            raise ValueError(
                f"{owner}: parameters `freq_start`, `freq_end`, `hz_per_sec` ({freq_start!r}, {freq_end!r}, "
                f"{hz_per_sec!r}) make a sweep of more than {MAX_SWEEP_SEGMENTS:g} held segments"
            )
    if not (sweeping_period and sweeping_accel):
        return np.array(ends), np.array(accel)
    n_slow = 2.0 * time / sweeping_period  # the slow sweep's sign flips, each one more segment
    if not n_slow <= MAX_SWEEP_SEGMENTS:
        raise ValueError(
            f"{owner}: parameter `sweeping_period` ({sweeping_period!r} s) splits the {time:.4g} s sweep into about "
            f"{n_slow:.3g} more segments; at most {MAX_SWEEP_SEGMENTS:g}: raise `sweeping_period` (or 0: no slow sweep)"
        )
    # the slow sweep: its sign flips at sqrt(2)/8 of a period, then every half period; segments split there
    out_t, out_a = [], []
    fraction = math.sqrt(2.0) * 0.125
    t_rem, sig, last = sweeping_period * fraction, 1.0, 0.0
    fraction += 0.25
    for end, a in zip(ends, accel):
        seg = end - last
        while t_rem <= seg:
            last += t_rem
            out_t.append(last)
            out_a.append(a + sweeping_accel * sig)
            seg -= t_rem
            t_rem = sweeping_period * fraction
            fraction = 0.5
            sig = -sig
        t_rem -= seg
        out_t.append(end)
        out_a.append(a + sweeping_accel * sig)
        last = end
    return np.array(out_t), np.array(out_a)


@jax.jit
def _modal_zoh(a, h, w, zeta, g):
    """The payload's acceleration $a + \\sum_i \\ddot q_i$ of the modes $\\ddot q + 2\\zeta\\omega\\dot q + \\omega^2 q = -g a$,
    `a` held over each step `h` [s] (exact: the matrix exponential of the modes' state with the input)."""

    def one(wi, zi, gi):
        A = jnp.array([[0.0, 1.0, 0.0], [-(wi**2), -2.0 * zi * wi, -gi], [0.0, 0.0, 0.0]])
        E = jax.scipy.linalg.expm(A * h)
        Phi, Gam = E[:2, :2], E[:2, 2]

        def step(x, ak):
            x = Phi @ x + Gam * ak
            return x, x

        _, xs = jax.lax.scan(step, jnp.zeros(2), a)
        x_prev = jnp.concatenate([jnp.zeros((1, 2)), xs[:-1]])
        # q'' at the start of each step, from the state there and the acceleration held over it
        return -(wi**2) * x_prev[:, 0] - 2.0 * zi * wi * x_prev[:, 1] - gi * a

    return a + jnp.sum(jax.vmap(one)(w, zeta, g), axis=0)


def _schedule_at(ends: np.ndarray, accel: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The carriage acceleration of the schedule `(ends, accel)` at the sweep times `s` [s] (right-continuous: the
    segment that holds `s`; 0 before the sweep and after it)."""
    idx = np.searchsorted(ends, s, side="right")
    return np.where((s >= 0.0) & (idx < ends.size), accel[np.minimum(idx, ends.size - 1)], 0.0)


@jax.jit
def _linear_recurrence(alpha, beta):
    """$z_{j+1} = \\alpha_j z_j + \\beta_j$ from $z_0 = 0$: all $z_{j+1}$ (a parallel scan)."""

    def combine(left, right):
        a1, b1 = left
        a2, b2 = right
        return a1 * a2, a2 * b1 + b2

    return jax.lax.associative_scan(combine, (alpha, beta))[1]


def sweep_response(axis, rate: float, ends, accel, *, lead: float = 0.1):
    """The payload's acceleration [m/s²] of `axis` (a `ModalAxis`) under the carriage acceleration `accel` held
    until `ends` (`klipper_sweep`), sampled at `rate` [Hz] from `lead` [s] before the sweep to its end, as an
    accelerometer on the payload records it: `(t [s], y [m/s²])`, `t` in the sweep's time (0 at its start).

    Exact (to rounding) for the schedule's own switching times: between consecutive events (a sample, or a switch
    of the acceleration) each mode $\\ddot q + 2\\zeta\\omega\\dot q + \\omega^2 q = -g a$ is propagated in closed form
    in its complex modal coordinate $z$ ($\\dot z = \\lambda z + b\\,a$, $\\lambda = -\\zeta\\omega + j\\omega\\sqrt{1-\\zeta^2}$:
    $z \\leftarrow e^{\\lambda\\,\\delta t} z + b\\,a\\,(e^{\\lambda\\,\\delta t} - 1)/\\lambda$), and the samples are the
    payload's acceleration $a + \\sum_i \\ddot q_i$ at the sample times (the model of `ModalAxis`; $a$ the segment
    that starts there)."""
    rate, lead = float(rate), float(lead)
    for name, v in (("rate", rate), ("lead", lead)):
        if not (math.isfinite(v) and v >= (0.0 if name == "lead" else 1e-300)):
            raise ValueError(
                f"sweep_response: parameter `{name}` must be finite and {'>= 0' if name == 'lead' else '> 0'}; got {v!r}"
            )
    ends = np.asarray(ends, dtype=float)
    accel = np.asarray(accel, dtype=float)
    if ends.ndim != 1 or accel.shape != ends.shape or ends.size == 0:
        raise ValueError(
            "sweep_response: parameters `ends` and `accel` must be 1-D arrays of the same, non-zero length"
        )
    h = 1.0 / rate
    n = int(math.floor((ends[-1] + lead) * rate)) + 1
    t = np.arange(n) * h - lead
    # every event: the samples and the switches, in order; `is_sample` marks the samples
    times = np.concatenate([t, [0.0], ends[:-1]])
    is_sample = np.concatenate([np.ones(n, bool), np.zeros(ends.size, bool)])
    order = np.argsort(times, kind="stable")
    times, is_sample = times[order], is_sample[order]
    a_ev = _schedule_at(ends, accel, times)
    dts = np.diff(times, append=times[-1])
    y = a_ev[is_sample].copy()
    w = 2.0 * np.pi * np.asarray(axis.frequencies, dtype=float)
    zetas = np.asarray(axis.damping_ratios, dtype=float)
    gains = np.asarray(axis.gains, dtype=float)
    for wi, zi, gi in zip(w, zetas, gains):
        A = np.array([[0.0, 1.0], [-(wi**2), -2.0 * zi * wi]])
        lam, V = np.linalg.eig(A)
        k = int(np.argmax(np.imag(lam)))
        lam_k, v_k = lam[k], V[:, k]
        b_k = (np.linalg.inv(V) @ np.array([0.0, -gi]))[k]
        e = np.exp(lam_k * dts)
        z = np.asarray(_linear_recurrence(jnp.asarray(e), jnp.asarray(b_k * a_ev * (e - 1.0) / lam_k)))
        z = np.concatenate([[0.0], z[:-1]])  # the state at each event, before its segment
        x = 2.0 * np.real(np.outer(z, v_k))  # (q, q') at each event
        qdd = -(wi**2) * x[:, 0] - 2.0 * zi * wi * x[:, 1] - gi * a_ev
        y += qdd[is_sample]
    return t, y


def _input_spectrum(ends, accel, tau, n, h, m):
    """At the bins `m` of an `n`-point DFT of samples `h` [s] apart, with the sweep starting `tau` [s] after the
    first sample: `(S, A)`, the DFT of the sampled carriage acceleration and $1/h$ times the Fourier transform
    $\\int_0^{nh} a(t - \\tau) e^{-j\\omega t} dt$ of the held (piecewise constant) acceleration over the record.

    $A$ from the switches: $\\int_0^T a e^{-j\\omega t} dt = (a(0) - a(T) + \\sum_k \\Delta a_k e^{-j\\omega t_k})/(j\\omega)$
    ($e^{-j\\omega T} = 1$ on the DFT's bins), each switch time $t_k = (n_k + \\phi_k) h$ ($|\\phi_k| \\le 1/2$) taken
    as the grid point $n_k$ times the Taylor series of $e^{-j\\omega h \\phi_k}$ (one FFT a term; 1e-13)."""
    T = n * h
    levels = np.concatenate([[0.0], accel, [0.0]])
    times = np.concatenate([[0.0], ends]) + tau  # the switch from levels[k] to levels[k + 1]
    jumps = np.diff(levels)
    inside = (times > 0.0) & (times < T) & (jumps != 0.0)
    x = times[inside] / h
    nk = np.floor(x + 0.5).astype(np.int64)
    phi = x - nk
    da = jumps[inside]
    w = 2.0 * np.pi * m / T
    wh = float(np.max(w)) * h * 0.5
    total = np.zeros(m.size, complex)
    term = da.copy()
    p = 0
    while True:
        total += np.fft.rfft(np.bincount(nk % n, term, minlength=n))[m] * (-1j * w * h) ** p / math.factorial(p)
        p += 1
        if wh**p / math.factorial(p) < 1e-14 or p > 40:
            break
        term = term * phi
    ends_at = np.array([0.0, T]) - tau
    a0, aT = _schedule_at(ends, accel, ends_at + np.array([0.0, -1e-12 * T]))
    A = (a0 - aT + total) / (1j * w) / h
    S = np.fft.rfft(_schedule_at(ends, accel, np.arange(n) * h - tau))[m]
    return S, A


def _sweep_model(theta, x, xr, S, A, n: int):
    """The record's DFT at the bins (scaled): $d_0 S + \\sum_i [b_i (1 + 2j\\zeta_i x_i) A + \\alpha_i + j\\beta_i x_i] / D_i
    + \\kappa_{-1}/(j x_r) + \\kappa_0 + j\\kappa_1 x_r$, $x_i = \\omega/\\omega_i$, $D_i = 1 - x_i^2 + 2j\\zeta_i x_i$, with
    $S$, $A$ delayed by $\\delta$ samples; `theta` = (ln f_i / f_ref, logit zeta_i, delta, d0, b_i, alpha_i, beta_i,
    kappa). `x`: the bins' $\\omega h$, `xr`: $\\omega/\\omega_{ref}$."""
    fi = jnp.exp(theta[:n])
    zeta = jax.nn.sigmoid(theta[n : 2 * n])
    delay = jnp.exp(-1j * x * theta[2 * n])
    k = 2 * n + 1
    d0, b = theta[k], theta[k + 1 : k + 1 + n]
    alpha, beta = theta[k + 1 + n : k + 1 + 2 * n], theta[k + 1 + 2 * n : k + 1 + 3 * n]
    kap = theta[k + 1 + 3 * n :]
    xi = xr[:, None] / fi[None, :]
    den = 1.0 - xi**2 + 2j * zeta * xi
    modes = (b * (1.0 + 2j * zeta * xi) * (A * delay)[:, None] + alpha + 1j * beta * xi) / den
    return d0 * S * delay + jnp.sum(modes, axis=1) + kap[0] / (1j * xr) + kap[1] + 1j * kap[2] * xr


@functools.partial(jax.jit, static_argnames=("n", "rtol", "atol", "max_steps"))
def _fit_sweep(x, xr, S, A, Y, weight, theta0, scale, *, n, rtol, atol, max_steps):
    """LM on `u` with `theta = theta0 + scale * u`, residuals (real and imaginary parts) `weight * (model - Y)`.
    Returns as `identify._fit`."""

    def resid(u, _):
        e = weight * (_sweep_model(theta0 + scale * u, x, xr, S, A, n) - Y)
        return jnp.concatenate([e.real, e.imag])

    return _core._levenberg_marquardt(resid, jnp.zeros_like(theta0), rtol=rtol, atol=atol, max_steps=max_steps)


def _sweep_basis(fi, zeta, x, xr, S, A):
    """The model's columns at fixed (f_i, zeta_i) and no delay (the linear coefficients' start)."""
    xi = xr[:, None] / fi[None, :]
    den = 1.0 - xi**2 + 2j * zeta * xi
    cols = [S[:, None], (1.0 + 2j * zeta * xi) * A[:, None] / den, 1.0 / den, 1j * xi / den]
    cols += [(1.0 / (1j * xr))[:, None], np.ones((xr.size, 1)), (1j * xr)[:, None]]
    return np.concatenate(cols, axis=1)


def _smooth_length(n: int, up: bool) -> int:
    """The 5-smooth number ($2^a 3^b 5^c$, a fast FFT length) nearest `n` at or above it (`up`), or at or below it."""
    values = []
    p5 = 1
    while p5 <= 2 * n:
        p3 = p5
        while p3 <= 2 * n:
            v = p3
            while v <= 2 * n:
                values.append(v)
                v *= 2
            p3 *= 3
        p5 *= 5
    return min((v for v in values if v >= n), default=n) if up else max(v for v in values if v <= n)


def _transfer_estimate(y, ends, accel, h, band):
    """The record and the sweep (started at the first sample) zero-padded to one length, in the DFT: the bins in
    `band`, their frequencies [Hz], the ratio $E = Y/A$ (the transfer function times $e^{-j\\omega\\tau}$, $\\tau$ the
    sweep's start in the record), the weights $|A|^2$, and $|Y|^2/|A|^2$ smoothed over 0.25 Hz (whose peaks start
    the modes: it does not depend on $\\tau$)."""
    n_s = int(math.ceil(ends[-1] / h)) + 1
    N2 = _smooth_length(y.size + n_s, up=True)
    Y2 = np.fft.rfft(y - y.mean(), N2)
    A2 = np.fft.rfft(_schedule_at(ends, accel, np.arange(n_s) * h), N2)
    f2 = np.fft.rfftfreq(N2, h)
    k = np.flatnonzero((f2 >= band[0]) & (f2 <= band[1]) & (np.abs(A2) > 0))
    wgt = np.abs(A2[k]) ** 2
    width = max(1, int(round(0.25 * N2 * h)))
    kernel = np.ones(width) / width
    ratio = np.convolve(np.abs(Y2[k]) ** 2, kernel, "same") / np.convolve(wgt, kernel, "same")
    return N2, k, f2[k], Y2[k] / A2[k], wgt, ratio


def _delay_estimate(N2, k, fk, E, wgt, f0, z0, h):
    """The sweep's start [s after the first sample] from $E \\approx c\\,T(f) e^{-j\\omega\\tau}$ (`_transfer_estimate`):
    with the transmissibility $T = 1 + \\sum_i g_i B_i$, $B_i = r_i^2/(1 - r_i^2 + 2j\\zeta_i r_i)$ at the start's
    modes `f0` [Hz], `z0`, the least-squares fit of $E e^{j\\omega\\tau}$ on $(1, B_1, \\ldots)$ (weights $|A|^2$: the
    noise of $E = Y/A$) is best where $u(\\tau)^H G^{-1} u(\\tau)$ is largest, $G = B^H W B$ and
    $u(\\tau) = B^H W E e^{j\\omega\\tau}$: one inverse FFT per column gives $u$ at every delay on the grid of one
    sample, the best refined by a parabola."""
    r = fk[:, None] / np.asarray(f0)[None, :]
    B = np.concatenate([np.ones((fk.size, 1)), r**2 / (1.0 - r**2 + 2j * np.asarray(z0) * r)], axis=1)
    W = wgt / wgt.max()
    G = (B.conj().T * W) @ B
    U = np.empty((B.shape[1], N2), complex)
    F = np.zeros(N2, complex)
    for col in range(B.shape[1]):
        F[k] = B[:, col].conj() * W * E
        U[col] = np.fft.ifft(F) * N2
    q = np.real(np.sum(U.conj() * np.linalg.solve(G, U), axis=0))
    i = int(np.argmax(q))
    left, mid, right = q[i - 1], q[i], q[(i + 1) % N2]
    den = left - 2.0 * mid + right
    lag = i + (0.5 * (left - right) / den if den < 0 else 0.0)
    if lag > N2 / 2:
        lag -= N2
    return lag * h


#: the fit's bins are padded (with points of zero weight) to a multiple of this number
_SWEEP_PAD = 512
#: rounds of the fit, each from the input's spectrum at the last round's delay
_SWEEP_ROUNDS = 4


@blas_limited
def identify_axis_from_sweep(
    t,
    y,
    n_modes: int,
    *,
    sweep=None,
    band: tuple[float, float] | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 256,
):
    """The modes of an axis from the raw accelerometer record of a resonance sweep (Klipper's `TEST_RESONANCES
    ... OUTPUT=raw_data`: `raw_data_*.csv`, one column): a `ModalAxis` with standard errors.

    ```python
    t, y = jb.load_record("raw_data_x.csv", channel="accel_x")
    axis = jb.identify_axis_from_sweep(t, y, n_modes=2)                      # Klipper's default sweep
    axis = jb.identify_axis_from_sweep(t, y, 2, sweep=jb.klipper_sweep(hz_per_sec=2.0))
    ```

    - `t` [s], `y` (any unit: only the shape of the response matters): uniformly sampled as `identify_axis`
      requires (Klipper's `%.6f` time stamps are), holding the sweep; the record may start before it and end
      after it.
    - `sweep`: the carriage's acceleration, `(ends [s], accel [m/s²])` as `klipper_sweep` returns it; None:
      `klipper_sweep()`, Klipper's defaults. Its start in the record is found from the record.
    - `band`: `(low, high)` [Hz], the bins fitted; None: `KLIPPER_BAND`, 5-135 Hz (Klipper's default sweep: pass
      its `FREQ_START`, `FREQ_END` where they differ).

    **The model: the transfer function from the known excitation.** The record is the payload's acceleration
    $y = c\\,(a + \\sum_i \\ddot q_i)$ under the carriage's acceleration $a(t - \\tau)$ (the model of `ModalAxis`;
    $c$ the sensor's unit and sign), plus the sensor's noise. With $p_i = \\ddot q_i + g_i a$ (smooth) it is
    $y = c(1 - \\sum g_i)\\,a + c\\sum_i p_i$, and over the record's $N$ samples (Pintelon and Schoukens, 2012,
    System Identification: A Frequency Domain Approach, ch. 6: a record that does not start and end at rest adds
    a transient term that is a rational function of the same denominator) its DFT at $\\omega_k = 2\\pi k/(Nh)$ is
    exactly

    $Y_k = d_0 S_k + \\sum_i \\frac{b_i (1 + 2j\\zeta_i x_i) A_k + \\alpha_i + j\\beta_i x_i}{1 - x_i^2 + 2j\\zeta_i x_i}
    + \\frac{\\kappa_{-1}}{j x} + \\kappa_0 + j\\kappa_1 x + N_k$, $x_i = \\omega_k/\\omega_i$,

    with $S$ the DFT of the sampled $a$ (its aliases included), $A$ the Fourier transform of the held $a$ over the
    record, $d_0 = c(1 - \\sum g_i)$ and $b_i = c g_i$, $\\alpha_i$, $\\beta_i$ the modes' states at the record's ends,
    $\\kappa$ the rectangle rule's end corrections, and $N_k$ the noise's DFT: for white sensor noise, independent
    between bins, and of the same variance in their real and imaginary parts. The fit is least squares on these
    (an efficient estimator, so the standard errors $s^2(J^TJ)^{-1}$ hold) over the bins in `band`, by
    Levenberg-Marquardt on $\\ln f_i$, $\\operatorname{logit}\\zeta_i$, the delay $\\tau$ and the linear
    coefficients. The delay starts from the best fit of $Y/A$ by the start's transmissibility over every delay (`_delay_estimate`), the modes from the half-power
    peaks of $|Y|^2/|A|^2$; $S$ and $A$ are recomputed at the fitted delay and the fit repeated (at most 4
    rounds) until the delay moves by under 0.01 sample. One compiled program per `n_modes` and number of bins
    (padded to a multiple of 512).

    Why not the record's PSD, as Klipper estimates it (Welch's method, `kind="klipper"` of
    `identify_axis_from_psd`, as this function did before): that model takes the response as stationary, and a
    sweep's is not. It excites each frequency during a few of the estimate's segments only, so the estimate has
    neither the chi-square scatter of $K$ averages (the standard errors came out 2-4 times too large: over 20
    sweeps the standardised errors had a spread of 0.24 in f and 0.43 in zeta) nor the expectation of the smeared
    stationary PSD: each segment's periodogram holds the part of the resonance's build-up and ring-down that
    falls in it, windowed, and their average is not the stationary peak smeared by the window: its width depends
    on how the sweep's rate compares with the mode's decay, which the model does not hold (the damping came out
    biased low, by up to 7 % for the slower sweeps). The transfer function has neither problem: 95 % intervals hold the truth 90-98 % of the time
    (docs/benchmarks.md, "Identification: coverage of the intervals").

    Returns `ModalAxis(frequencies, damping_ratios, gains=None, frequency_std=..., damping_std=...)`, the modes
    sorted by frequency (unit gains, as `identify_axis` returns). Raises `ValueError` as `identify_axis` does
    for the record, for a bad `sweep` or `band`, for a record that does not hold at least half of the sweep, and after the fit for
    a mode at or beyond the band's ends, a damping ratio outside (0, 1) or a mode whose gain is below
    `PSD_MIN_SIGNIFICANCE` = 8 standard errors (also where the fit did not converge: more `n_modes` than the record
    holds); `RuntimeError` when the fit does not converge although every mode stands out.
    """
    owner = "identify_axis_from_sweep"
    _core._require_x64(owner)
    t, y, h, n, _ = _core._check_record(t, y, n_modes, True)
    if not np.max(np.abs(y)) < 1e150:  # the transfer estimate squares the spectra: beyond, they overflow
        raise ValueError(
            f"{owner}: parameter `y` must have |y| < 1e150 (its squared spectra stay finite); got {np.max(np.abs(y))}"
        )
    if sweep is None:
        sweep = klipper_sweep()
    try:
        ends, accel = (np.asarray(v, dtype=float) for v in sweep)
    except (TypeError, ValueError):
        raise ValueError(
            f"{owner}: parameter `sweep` must be a pair (ends [s], accel [m/s²]) as klipper_sweep returns"
        ) from None
    if (
        ends.ndim != 1
        or accel.shape != ends.shape
        or ends.size < 2
        or not (np.all(np.isfinite(ends)) and np.all(np.isfinite(accel)) and np.all(np.diff(ends) > 0) and ends[0] > 0)
    ):
        raise ValueError(
            f"{owner}: parameter `sweep` must be a pair (ends [s], accel [m/s²]) of finite 1-D arrays of the same "
            "length >= 2, `ends` positive and increasing (as klipper_sweep returns)"
        )
    if band is None:
        band = _psd.KLIPPER_BAND
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        raise ValueError(
            f"{owner}: parameter `band` must be a pair (low, high) of frequencies [Hz]; got {band!r}"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi < 0.5 / h):
        raise ValueError(
            f"{owner}: parameter `band` must be finite with 0 < low < high < {0.5 / h:.6g} Hz (the record's Nyquist "
            f"frequency); got {band!r}"
        )
    rtol, atol = float(rtol), float(atol)
    if not (math.isfinite(rtol) and rtol > 0):
        raise ValueError(f"{owner}: parameter `rtol` must be finite and > 0; got {rtol}")
    if not (math.isfinite(atol) and atol >= 0):
        raise ValueError(f"{owner}: parameter `atol` must be finite and >= 0; got {atol}")
    max_steps = check_int(owner, "max_steps", max_steps, lo=1)
    N = _smooth_length(y.size, up=False)  # the FFTs' length: the record cut to a fast one (a few samples)
    t, y = t[:N], y[:N]
    T = N * h
    m = np.arange(max(1, int(math.ceil(lo * T))), int(math.floor(hi * T)) + 1)
    p = 5 * n + 5
    if 2 * m.size < _core.SAMPLES_PER_PARAMETER * p:
        raise ValueError(
            f"{owner}: the record ({T:.3g} s) holds {m.size} frequency bins in `band` = ({lo:g}, {hi:g}) Hz, too "
            f"few for {n} mode(s): a sweep's record lasts minutes"
        )
    N2, k2, f_ratio, E, wgt, ratio = _transfer_estimate(y, ends, accel, h, (lo, hi))
    f0, z0, _ = _psd._psd_peaks(f_ratio, ratio, n)
    tau = _delay_estimate(N2, k2, f_ratio, E, wgt, f0, z0, h)
    overlap = min(T, tau + ends[-1]) - max(0.0, tau)
    if not overlap >= 0.5 * ends[-1]:
        raise ValueError(
            f"{owner}: the record (`t`, `y`, {T:.3g} s) does not hold the sweep (`sweep`, {ends[-1]:.3g} s): its best "
            f"match starts {tau:.3g} s after the record's first sample and holds {max(overlap, 0.0):.3g} s of it (at "
            "least half is needed): give the sweep's schedule as the test ran it (klipper_sweep with its settings)"
        )
    fref = math.sqrt(lo * hi)
    w = 2.0 * np.pi * m / T
    x_h, xr = w * h, w / (2.0 * np.pi * fref)
    Y = np.fft.rfft(y)[m]
    unit = float(np.sqrt(np.mean(np.abs(Y) ** 2)))
    Yn = Y / unit
    size = _SWEEP_PAD * math.ceil(m.size / _SWEEP_PAD)
    pad = size - m.size

    def padded(v, fill):
        return device_array(np.concatenate([v, np.full(pad, fill, dtype=v.dtype)]))

    weight = padded(np.ones(m.size), 0.0)
    theta = None
    for _round in range(_SWEEP_ROUNDS):
        S, A = _input_spectrum(ends, accel, tau, N, h, m)
        s_unit = float(np.sqrt(np.mean(np.abs(S) ** 2)))
        a_unit = float(np.sqrt(np.mean(np.abs(A) ** 2)))
        Sn, An = S / s_unit, A / a_unit
        if theta is None:
            B = _sweep_basis(f0 / fref, z0, None, xr, Sn, An)
            coef = np.linalg.lstsq(
                np.concatenate([np.real(B), np.imag(B)]), np.concatenate([np.real(Yn), np.imag(Yn)]), rcond=None
            )[0]
            theta = np.concatenate([np.log(f0 / fref), np.log(z0) - np.log1p(-z0), [0.0], coef])
        else:
            theta[2 * n] = 0.0
        lin = np.abs(theta[2 * n + 1 :])
        scale = np.concatenate([np.full(n, float(np.min(z0))), np.ones(n), [1.0], np.maximum(lin, 1e-6 * lin.max())])
        out = _fit_sweep(
            padded(x_h, x_h[-1]),
            padded(xr, xr[-1]),
            padded(Sn, 0j),
            padded(An, 0j),
            padded(Yn, 0j),
            weight,
            device_array(theta),
            device_array(scale),
            n=n,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
        )
        r, sv, vt, code, steps, finite, theta, fi, zeta = _core._fit_outcome(out, theta, scale, n)
        if code != 0 or not finite:
            break
        shift = float(theta[2 * n])
        tau += shift * h
        if abs(shift) < 0.01:
            break
    fi = fi * fref
    start = f"started from f = {_core._fmt(f0)} Hz, zeta = {_core._fmt(z0)}, the sweep {tau:.6g} s into the record"
    r, theta, fi, zeta = (np.asarray(v, dtype=float) for v in (r, theta, fi, zeta))
    if finite:
        var = np.diag(_core._covariance(r, sv, vt, scale, p, 2 * m.size))
        ib = slice(2 * n + 2, 3 * n + 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            significance = np.nan_to_num(np.abs(theta[ib]) / np.sqrt(var[ib]), nan=0.0)
    else:
        var, significance = np.zeros(p), np.zeros(n)
    f_std = fi * np.sqrt(var[:n])
    z_std = zeta * (1.0 - zeta) * np.sqrt(var[n : 2 * n])
    if code != 0 and finite and np.any(~(significance >= _psd.PSD_MIN_SIGNIFICANCE)):
        i = int(np.argmin(significance))
        raise ValueError(
            f"{owner}: the Levenberg-Marquardt fit of {n} mode(s) did not converge after {steps} steps, and its last "
            f"iterate has a mode ({fi[i]:.6g} Hz) whose gain is only {significance[i]:.3g} standard errors (at least "
            f"{_psd.PSD_MIN_SIGNIFICANCE:g} are needed): the record may hold fewer than `n_modes` = {n} modes in "
            f"`band`: try a smaller `n_modes` ({start})"
        )
    if code != 0 or not finite:
        reason = (
            (_core._RESULT_NAMES[code] if code >= 0 else "unknown solver failure") if finite else "non-finite values"
        )
        raise RuntimeError(
            f"{owner}: the Levenberg-Marquardt fit of {n} mode(s) did not converge ({reason}) after {steps} steps, "
            f"{start}; give a larger `max_steps` (now {max_steps}), try another `n_modes`, or check `sweep` (the "
            "excitation the record holds)"
        )
    fi, zeta, f_std, z_std, _ = _psd.sorted_fitted_modes(
        owner,
        n,
        fi,
        zeta,
        f_std,
        z_std,
        significance,
        (lo, hi),
        found_suffix="",
        edge=f"`band` = ({lo:g}, {hi:g}) Hz: widen the band, or fit fewer `n_modes`",
        zeta_hint="check `sweep`",
        weak="gain",
        holder="record",
    )
    from ..models.axis import ModalAxis

    return ModalAxis(fi, zeta, None, frequency_std=f_std, damping_std=z_std)
