"""A firmware's resonance test, as a record of a known excitation: Klipper's sweep (`klipper_sweep`, the schedule its
`TEST_RESONANCES` and `SHAPER_CALIBRATE` commands run), the payload's response to it (`sweep_response`, exact for
a `ModalAxis`), and the axis from the raw accelerometer record of the test (`identify_axis_from_sweep`).

**Klipper's sweep** (facts from its `resonance_tester.py`): from `freq_start` (default 5 Hz) to `freq_end`
(135 Hz), the carriage is accelerated at $\\pm$`accel_per_hz`$\\cdot f$ (60 mm/s² per Hz) in segments of a quarter
period $1/(4f)$, alternating as a square wave of frequency $f$ (signs $+,-,-,+$ per period), while $f$ grows
by `hz_per_sec` (1 Hz/s) times the time elapsed: a linear sweep. Newer versions add a slow square wave of
$\\pm$`sweeping_accel` (400 mm/s²) with period `sweeping_period` (1.2 s; 0 switches it off) that moves the
carriage along the axis, starting a quarter-period ($\\sqrt2/8$ of a period) in.

The record of the test is a forced response, not a free decay: its spectrum is the base-excited model of
`identify_axis_from_psd` with `kind="klipper"` (the carriage's acceleration puts energy rising as $f^2$ at
each frequency), so `identify_axis_from_sweep` estimates it as Klipper does (Welch, Kaiser window) and fits that.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int
from .._threads import blas_limited
from . import identify as _core
from . import psd as _psd

__all__ = ["identify_axis_from_sweep", "klipper_sweep", "sweep_response"]


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
    if not (sweeping_period and sweeping_accel):
        return np.array(ends), np.array(accel)
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


def sweep_response(axis, rate: float, ends, accel, *, upsample: int = 4, lead: float = 0.1):
    """The payload's acceleration [m/s²] of `axis` (a `ModalAxis`) under the carriage acceleration `accel` held
    until `ends` (`klipper_sweep`), sampled at `rate` [Hz] from `lead` [s] before the sweep to its end, as an
    accelerometer on the payload records it: `(t [s], y [m/s²])`. Exact for the acceleration held over steps of
    `1 / (rate * upsample)` (each segment's ends rounded to that grid): the modes' state is propagated by its
    matrix exponential; the payload's acceleration is the carriage's plus the modes' $\\ddot q_i$ (the model
    of `ModalAxis`)."""
    rate = float(rate)
    upsample = check_int("sweep_response", "upsample", upsample, lo=1)
    h = 1.0 / (rate * upsample)
    ends = np.asarray(ends, dtype=float)
    accel = np.asarray(accel, dtype=float)
    n_fine = int(math.ceil((ends[-1] + lead) / h))
    tf = np.arange(n_fine) * h - lead
    idx = np.searchsorted(ends, tf + 0.5 * h, side="right")
    a = np.where((tf + 0.5 * h >= 0) & (idx < ends.size), accel[np.minimum(idx, ends.size - 1)], 0.0)
    w = 2.0 * np.pi * np.asarray(axis.frequencies, dtype=float)
    y = np.asarray(
        _modal_zoh(
            jnp.asarray(a),
            h,
            jnp.asarray(w),
            jnp.asarray(np.asarray(axis.damping_ratios, dtype=float)),
            jnp.asarray(np.asarray(axis.gains, dtype=float)),
        )
    )
    return tf[::upsample], y[::upsample]


@blas_limited
def identify_axis_from_sweep(
    t,
    y,
    n_modes: int,
    *,
    band: tuple[float, float] | None = None,
    nperseg: int | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 256,
):
    """The modes of an axis from the raw accelerometer record of a resonance sweep (Klipper's `TEST_RESONANCES
    ... OUTPUT=raw_data`: `raw_data_*.csv`, one column): a `ModalAxis` with standard errors.

    ```python
    t, y = jb.load_record("raw_data_x.csv", channel="accel_x")
    axis = jb.identify_axis_from_sweep(t, y, n_modes=2)
    ```

    The record is a forced response to the sweep (the module's documentation), not a free decay: its PSD is
    estimated as Klipper does (`welch`: Kaiser window of $\\beta$ = 6, segments of Klipper's length, half
    overlapping, or `nperseg`) and fitted with the base-excited model of `identify_axis_from_psd`
    (`kind="klipper"`, the window's smearing modelled) over `band` (default `KLIPPER_BAND`, 5-135 Hz, Klipper's
    default sweep: pass its `FREQ_START`, `FREQ_END` where they differ). `t` must be uniformly sampled as
    `identify_axis` requires (Klipper's `%.6f` time stamps are). Raises as `identify_axis_from_psd`, and
    `ValueError` for a record shorter than two segments.
    """
    t, y, dt, n, _ = _core._check_record(t, y, n_modes, True)
    rate = 1.0 / dt
    f, p, segments = _psd.welch(y, rate, nperseg=nperseg, window="kaiser")
    if segments < 2:
        raise ValueError(
            f"identify_axis_from_sweep: the record (`t`, `y`) holds {segments} segment(s) of {f.size * 2 - 2} samples; "
            "a sweep's record holds many (a Klipper test lasts minutes): is it a free decay? (identify_axis)"
        )
    return _psd.identify_axis_from_psd(
        f, p, n, kind="klipper", window="kaiser", band=band, rtol=rtol, atol=atol, max_steps=max_steps
    )
