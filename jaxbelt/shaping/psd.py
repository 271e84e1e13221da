"""The modes of the user's axis from a power spectral density (PSD): `identify_axis_from_psd`, with the model the
spectrum holds (`kind`: what was measured and how the axis was excited; `window`: the estimate's smearing), and
`welch`, the estimate itself (as a firmware's resonance test computes it).

**The models.** A mode $i$ of frequency $f_i$ and damping ratio $\\zeta_i$ has, at $r_i = f/f_i$, the displacement
frequency response $H_i = 1/(1 - r_i^2 + 2j\\zeta_i r_i)$ (in units of its static response), with
$|H_i|^2 = 1/D_i$, $D_i = (1 - r_i^2)^2 + (2\\zeta_i r_i)^2$ (e.g. Ewins, 2000, Modal Testing, ch. 2).

- *Force-excited* (a tap test: an impact hammer or broadband force on the payload, a sensor on it), the kinds
  `"displacement"`, `"velocity"`, `"acceleration"`: the measured quantity is the $m$-th derivative of the
  displacement ($m$ = 0, 1, 2), so each mode contributes $A_i r_i^{2m}/D_i$ (the factor $(2\\pi f)^{2m}$ of each
  derivative, absorbed in $A_i$ up to $f_i^{2m}$); the modes add in power (independent excitation, or modes
  far apart in frequency):
  $P(f) = P_0 + \\sum_i A_i\\,r_i^{2m}/D_i$.
- *Base-excited* (the carriage driven by its motor, a sensor on the payload, as in a firmware's resonance test),
  the kinds `"base-acceleration"`, `"klipper"`, `"klipper-normalised"`: the payload's modal coordinates obey
  $\\ddot q_i + 2\\zeta_i\\omega_i\\dot q_i + \\omega_i^2 q_i = -g_i a$ for the carriage's acceleration $a$ (the model of
  `ModalAxis`), and the payload's acceleration $a + \\sum_i \\ddot q_i$ is $a$ times the transmissibility
  $T(f) = 1 + \\sum_i g_i r_i^2/(1 - r_i^2 + 2j\\zeta_i r_i)$ (one mode of unit gain: $|T|^2 = (1 + (2\\zeta r)^2)/D$),
  the modes adding in amplitude, with signed participations $g_i$:
  $P(f) = P_0 + E\\,(f/f_\\mathrm{ref})^{2q}\\,|T(f)|^2$,
  with $E (f/f_\\mathrm{ref})^{2q}$ the spectrum of the carriage's acceleration: flat ($q = 0$,
  `"base-acceleration"`), or rising as $f^2$ ($q = 1$) in Klipper's resonance test, whose sweep commands an
  acceleration of amplitude `accel_per_hz` $\\times f$ at a constant sweep rate (`hz_per_sec`), so that the
  energy it puts at each frequency grows as $f^2$ (its square wave's harmonics at $3f, 5f, \\ldots$ have the same
  $f^2$ shape). `"klipper"` is the PSD that `TEST_RESONANCES` writes (`resonances_*.csv`); `"klipper-normalised"`
  the one `SHAPER_CALIBRATE` writes (`calibration_data_*.csv`), which Klipper divided by $f + 0.1$ and tapered
  below 10 Hz by $e^{1 - (10/(f + 0.1))^2}$ (its `normalize_to_frequencies`): that factor is known, and is undone
  before the fit. `jaxbelt.shaping.readers.spectrum_kind` tells the two files apart.

**The estimate's statistics.** A Welch estimate of $K$ averaged segments scatters about its expectation as a
chi-square variable of about $2K$ degrees of freedom over $2K$ (Welch, 1967): multiplicatively, the same at
every frequency. The fit therefore minimises $\\sum_k (\\ln \\hat P(f_k) - \\ln P(f_k))^2$ (log-periodogram
regression): its residuals are identically distributed, whatever the peak's height over the floor; their mean
($\\psi(K) - \\ln K \\approx -1/(2K)$) scales $P$ as a whole and moves no $f_i$ or $\\zeta_i$. The expectation of the
estimate is the PSD smeared by the window's spectral window $|W(\\delta)|^2$ (Bendat and Piersol, 2010, Random Data,
sec. 11.5): with `window` (`"hann"`, or `"kaiser"`, Klipper's Kaiser window of $\\beta = 6$), the model is smeared
the same way on the estimate's frequency resolution (its bin width), so that a peak a few bins wide keeps its
damping. Neighbouring bins of a windowed, overlapping estimate are correlated: the standard errors
$C = s^2(J^TJ)^{-1}$, $s^2 = \\mathrm{SSR}/(N - p)$, are multiplied by the long-run variance factor
$1 + 2\\sum_{l=1}^{L}(1 - l/(L + 1))\\rho_l$ of the residuals' autocorrelation $\\rho_l$ ($L$ = 4; Newey and West,
1987, Econometrica 55(3)), so that they count independent points.
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

__all__ = ["KINDS", "WINDOWS", "identify_axis_from_psd", "welch"]

_OWNER = "identify_axis_from_psd"
#: a mode's amplitude ($A_i$, or $g_i$ base-excited) must exceed this many of its standard errors
PSD_MIN_SIGNIFICANCE = 8.0
#: a mode's half-power bandwidth $2\zeta_i f_i$ must span at least this many steps of the frequency grid (one
#: step where the estimate's window is modelled)
MIN_BANDWIDTH_STEPS = 2.0
#: what a spectrum may hold: kind -> (excitation, power): the force-excited m-th derivative of the displacement,
#: or the base-excited payload acceleration under a carriage acceleration whose PSD rises as f^(2 power)
KINDS = {
    "displacement": ("force", 0),
    "velocity": ("force", 1),
    "acceleration": ("force", 2),
    "base-acceleration": ("base", 0),
    "klipper": ("base", 1),
    "klipper-normalised": ("base", 1),
}
#: the estimate's windows whose smearing is modelled
WINDOWS = ("none", "hann", "kaiser")
#: Klipper's resonance test sweeps 5-135 Hz by default (`min_freq`, `max_freq`): its spectrum follows the model
#: there (above the sweep's end only its harmonics excite the axis)
KLIPPER_BAND = (5.0, 135.0)
#: the Kaiser window's beta in Klipper's estimate
_KAISER_BETA = 6.0
#: the fit's arrays are padded (with points of zero weight) to a multiple of this length
_PSD_PAD = 64
#: points of the moving average of ln PSD that the start's peak search runs on
_PSD_SMOOTH = 3
#: smallest and largest damping ratio of the start point
_PSD_ZETA0 = (1e-3, 0.5)
#: lags of the residuals' autocorrelation in the standard errors' correction
_HAC_LAGS = 4
#: the smeared model: offsets of +-`_KERNEL_HALF` bins, `_KERNEL_STEPS` per bin
_KERNEL_HALF, _KERNEL_STEPS = 6, 8


def _window(name: str, m: int) -> np.ndarray:
    k = np.arange(m)
    if name == "hann":
        return 0.5 - 0.5 * np.cos(2.0 * np.pi * k / m)  # periodic, as scipy's welch
    return np.kaiser(m, _KAISER_BETA)


@functools.cache
def _kernel(name: str) -> tuple[np.ndarray, np.ndarray]:
    """`(offsets [bins], weights)` of the spectral window $|W(\\delta)|^2$ of `name`, normalised to sum 1: a Welch
    estimate's expectation at $f$ is $\\sum_j w_j P(f + \\delta_j\\Delta f)$ ($\\Delta f$ the bin width)."""
    if name == "none":
        return np.zeros(1), np.ones(1)
    m = 512
    w = _window(name, m)
    delta = np.arange(-_KERNEL_HALF * _KERNEL_STEPS, _KERNEL_HALF * _KERNEL_STEPS + 1) / _KERNEL_STEPS
    W = np.exp(-2j * np.pi * np.outer(delta, np.arange(m)) / m) @ w
    weights = np.abs(W) ** 2
    return delta, weights / weights.sum()


def welch(y, rate: float, *, nperseg: int | None = None, window: str = "kaiser"):
    """The one-sided power spectral density of the samples `y` (any unit; PSD in unit²/Hz) taken at `rate` [Hz], by
    Welch's method (Welch, 1967) as Klipper's resonance test computes it: segments of `nperseg` samples overlapping
    by half, each segment's mean removed, times the window (`"kaiser"`, $\\beta = 6$, or `"hann"`), averaged
    periodograms scaled to a density ($\\sum w^2$ and the rate), doubled except at 0 Hz and Nyquist.

    `nperseg` default: Klipper's, the power of two at or above half a second of samples. Returns
    `(f [Hz], psd, segments)`, `segments` the number $K$ averaged."""
    y = np.asarray(y, dtype=float)
    rate = float(rate)
    if y.ndim != 1:
        raise ValueError(f"welch: parameter `y` must be 1-D; got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        bad = np.flatnonzero(~np.isfinite(y))
        raise ValueError(
            f"welch: parameter `y` must be finite (no NaN or inf); got {y[bad[0]]} at index {int(bad[0])} "
            f"({bad.size} non-finite value(s) in all)"
        )
    if y.size and not np.max(np.abs(y)) < 1e150:  # the periodograms square the samples: beyond, they overflow
        raise ValueError(
            f"welch: parameter `y` must have |y| < 1e150 (its squares stay finite); got {np.max(np.abs(y))}"
        )
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"welch: parameter `rate` must be finite and > 0 Hz; got {rate}")
    if window not in ("kaiser", "hann"):
        raise ValueError(f"welch: parameter `window` must be 'kaiser' or 'hann'; got {window!r}")
    if nperseg is None:
        if rate * 0.5 > y.size:  # also keeps a degenerate rate (1e300 Hz) from making a 300-digit segment length
            raise ValueError(
                f"welch: the record (`y`, {y.size} samples) is shorter than half a second at parameter `rate` = "
                f"{rate:.6g} Hz (the default `nperseg`, Klipper's): give a shorter `nperseg` or check `rate`"
            )
        nperseg = 1 << int(rate * 0.5 - 1).bit_length()
    nperseg = check_int("welch", "nperseg", nperseg, lo=8)
    if y.size < nperseg:
        raise ValueError(
            f"welch: the record (`y`, {y.size} samples) is shorter than one segment (`nperseg` = {nperseg})"
        )
    w = _window(window, nperseg)
    starts = np.arange(0, y.size - nperseg + 1, nperseg // 2)
    seg = y[starts[:, None] + np.arange(nperseg)[None, :]]
    seg = (seg - seg.mean(axis=1, keepdims=True)) * w
    psd = np.mean(np.abs(np.fft.rfft(seg, axis=1)) ** 2, axis=0) / (rate * np.sum(w**2))
    psd[1 : -1 if nperseg % 2 == 0 else None] *= 2.0
    return np.fft.rfftfreq(nperseg, 1.0 / rate), psd, int(starts.size)


def _klipper_normalisation(f: np.ndarray) -> np.ndarray:
    """The factor Klipper's `normalize_to_frequencies` multiplies its PSD by: $1/(f + 0.1)$, times
    $e^{1 - (10/(f + 0.1))^2}$ below 10 Hz."""
    factor = 1.0 / (f + 0.1)
    low = f < 10.0
    factor[low] *= np.exp(1.0 - (10.0 / (f[low] + 0.1)) ** 2)
    return factor


def _check_spectrum(f, psd, n_modes, band, p_of_n):
    """Validated host arrays `(f, psd)` inside the band (the 0 Hz point left out), the band's ends [Hz], the
    number of modes `n` and of parameters `p`."""
    owner = _OWNER
    n = check_int(owner, "n_modes", n_modes, lo=1)
    arrays = []
    for name, x, what in (("f", f, "frequencies [Hz]"), ("psd", psd, "power spectral densities")):
        try:
            a = np.asarray(x, dtype=float)
        except (TypeError, ValueError) as e:
            raise ValueError(
                f"{owner}: parameter `{name}` must be a 1-D array of {what}; got {type(x).__name__} ({e})"
            ) from None
        if a.ndim != 1:
            raise ValueError(f"{owner}: parameter `{name}` must be a 1-D array of {what}; got shape {a.shape}")
        arrays.append(a)
    f, psd = arrays
    if psd.shape != f.shape:
        raise ValueError(f"{owner}: parameter `psd` must have the shape of `f`, {f.shape}; got shape {psd.shape}")
    _core._first_bad("f", f, owner)
    _core._first_bad("psd", psd, owner)
    steps = np.diff(f)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(
            f"{owner}: parameter `f` must be strictly increasing; got f[{k}] = {float(f[k])!r} >= "
            f"f[{k + 1}] = {float(f[k + 1])!r}"
        )
    if f.size and f[0] < 0:
        raise ValueError(f"{owner}: parameter `f` must be >= 0 Hz; got f[0] = {float(f[0])!r}")
    if np.any(psd < 0):
        k = int(np.flatnonzero(psd < 0)[0])
        raise ValueError(
            f"{owner}: parameter `psd` must be >= 0 (a power spectral density); got {float(psd[k])!r} at index {k} "
            f"(f = {f[k]:.6g} Hz)"
        )
    if band is None:
        lo, hi = 0.0, math.inf
    else:
        try:
            lo, hi = (float(v) for v in band)
        except (TypeError, ValueError):
            raise ValueError(
                f"{owner}: parameter `band` must be a pair (low, high) of frequencies [Hz]; got {band!r}"
            ) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
            raise ValueError(f"{owner}: parameter `band` must be finite with 0 <= low < high [Hz]; got {band!r}")
    keep = (f > 0) & (f >= lo) & (f <= hi)  # 0 Hz: the mean, which Welch's method removes from every segment
    fs, ps = f[keep], psd[keep]
    where = "" if band is None else f" within `band` = ({lo:g}, {hi:g}) Hz"
    p = p_of_n(n)
    n_min = _core.SAMPLES_PER_PARAMETER * p
    if fs.size < n_min:
        raise ValueError(
            f"{owner}: the spectrum (parameters `f`, `psd`) is too short: {n} mode(s) and the level(s) are {p} "
            f"parameters, which need at least {n_min} points above 0 Hz{where} ({_core.SAMPLES_PER_PARAMETER} per "
            f"parameter); got {fs.size}"
        )
    if np.any(ps == 0):
        k = int(np.flatnonzero(ps == 0)[0])
        raise ValueError(
            f"{owner}: parameter `psd` must be > 0 where it is fitted (the fit compares logarithms); got 0 at "
            f"f = {fs[k]:.6g} Hz: leave that point out with `band`"
        )
    if np.ptp(ps) == 0.0:
        raise ValueError(
            f"{owner}: parameter `psd` is constant ({float(ps[0])!r}){where}: the spectrum holds no peak to identify"
        )
    return fs, ps, float(fs[0]), float(fs[-1]), n, p


def _psd_peaks(f: np.ndarray, psd: np.ndarray, n: int):
    """The start point of the fit: the `n` largest distinct peaks of the spectrum, `(f_peak [Hz], zeta, height)`
    sorted by frequency, by the half-power bandwidth method: $\\zeta \\approx (f_2 - f_1)/(2 f_{peak})$ with $f_1$,
    $f_2$ where the PSD has fallen to half its peak (e.g. Ewins, 2000, Modal Testing, sec. 4.3).

    On a moving average of ln PSD (`_PSD_SMOOTH` points), its local maxima from the highest down: a peak is
    distinct when the spectrum falls to half of it on both sides before rising above it; one that rises above it
    first sits on a larger peak's flank (or is noise) and is passed over, as is a maximum at an end point (a
    trend, not a peak). Raises `ValueError` for a peak whose half-power point lies beyond an end of the frequency
    range on one side (a mode at or beyond the edge), met before `n` distinct peaks, and when the spectrum holds
    fewer than `n` distinct peaks."""
    owner = _OWNER
    N = f.size
    logp = np.log(psd)
    s = np.convolve(logp, np.ones(_PSD_SMOOTH), mode="same") / np.convolve(
        np.ones(N), np.ones(_PSD_SMOOTH), mode="same"
    )
    up = np.concatenate([[True], s[1:] >= s[:-1]])
    down = np.concatenate([s[:-1] >= s[1:], [True]])
    candidates = np.flatnonzero(up & down)
    candidates = candidates[np.argsort(-s[candidates], kind="stable")]
    drop = math.log(2.0)
    found = []
    at_end = None  # a maximum at an end point: a mode beyond the range, or a trend; an error only if peaks lack
    for k in candidates:
        sides = []
        for step in (-1, 1):
            j = int(k)
            while True:
                j += step
                if j < 0 or j >= N:
                    sides.append(("edge", None))
                    break
                if s[j] > s[k]:
                    sides.append(("higher", None))
                    break
                if s[j] < s[k] - drop:
                    i = j - step
                    w = (s[i] - (s[k] - drop)) / (s[i] - s[j])
                    sides.append(("crossed", f[i] + w * (f[j] - f[i])))
                    break
        kinds = {kind for kind, _ in sides}
        if "higher" in kinds or kinds == {"edge"}:
            continue
        if "edge" in kinds:
            side = "low" if sides[0][0] == "edge" else "high"
            end = f[0] if side == "low" else f[-1]
            message = (
                f"{owner}: the peak at {f[k]:.6g} Hz is at the edge of the frequency range (parameter `f`, "
                f"{f[0]:.6g}-{f[-1]:.6g} Hz above 0 Hz, or `band`): the spectrum does not fall to half of it on the "
                f"{side} side before {end:.6g} Hz, so a mode may lie beyond the range: widen the range, or leave the "
                f"edge out with `band`"
            )
            if k in (0, N - 1):
                at_end = at_end or message
                continue
            raise ValueError(message)
        f1, f2 = sides[0][1], sides[1][1]
        zeta = (f2 - f1) / (2.0 * f[k])
        found.append((float(f[k]), float(np.clip(zeta, *_PSD_ZETA0)), float(np.exp(s[k]))))
        if len(found) == n:
            break
    if len(found) < n and at_end is not None:
        raise ValueError(at_end)
    if len(found) < n:
        at = ", ".join(f"{fk:.6g} Hz" for fk, _, _ in sorted(found))
        held = f"{len(found)} distinct peak(s) ({at})" if found else "no distinct peak (it may be noise)"
        raise ValueError(
            f"{owner}: the spectrum (`psd`) holds {held}, fewer than `n_modes` = {n} (a peak is distinct where the "
            f"PSD falls to half of it on both sides before rising above it)"
            + (": fit a smaller `n_modes`" if found else "")
        )
    found.sort()
    fk, zk, hk = (np.array(v) for v in zip(*found))
    return fk, zk, hk


def _psd_log_model(theta, fo, kw, floor_ref, n: int, excitation: str, power: int):
    """ln of the modelled estimate at the frequencies `fo` [Hz] (shape (points, kernel offsets), in units of the
    reference frequency), smeared with the kernel weights `kw`, for the coordinates `theta`:
    force-excited (ln f_i, logit zeta_i, ln A_i, v), base-excited (ln f_i, logit zeta_i, g_i, ln E, v); the floor
    is $P_0 = v^2 P_{ref}$ (`floor_ref`): where the data do not fix it, the Gauss-Newton step halves $v$, which
    converges to 0 (with $\\ln P_0$ it would drift down for ever)."""
    fi = jnp.exp(theta[:n])
    zeta = jax.nn.sigmoid(theta[n : 2 * n])
    r = fo[:, :, None] / fi
    one = (1.0 - r) * (1.0 + r)
    d = one**2 + (2.0 * zeta * r) ** 2
    if excitation == "force":
        terms = jnp.exp(theta[2 * n : 3 * n]) * r ** (2 * power) / d
        p = jnp.sum(terms, axis=2)
    else:
        g = theta[2 * n : 3 * n]
        c = g * r**2 / d
        re = 1.0 + jnp.sum(c * one, axis=2)
        im = -jnp.sum(c * 2.0 * zeta * r, axis=2)
        p = jnp.exp(theta[3 * n]) * fo ** (2 * power) * (re**2 + im**2)
    return jnp.log(floor_ref * theta[-1] ** 2 + p @ kw)


@functools.partial(jax.jit, static_argnames=("n", "excitation", "power", "rtol", "atol", "max_steps"))
def _fit_psd(fo, kw, logp, weight, floor_ref, theta0, scale, *, n, excitation, power, rtol, atol, max_steps):
    """LM on `u` with `theta = theta0 + scale * u`, residuals `weight * (ln model - ln psd)` (weight 0 on the
    padding). Returns as `identify._fit`."""

    def resid(u, _):
        return weight * (_psd_log_model(theta0 + scale * u, fo, kw, floor_ref, n, excitation, power) - logp)

    return _core._levenberg_marquardt(resid, jnp.zeros_like(theta0), rtol=rtol, atol=atol, max_steps=max_steps)


def _resolve_kind(kind, window, band):
    owner = _OWNER
    if kind is None:
        kind = "displacement"
    if kind not in KINDS:
        raise ValueError(f"{owner}: parameter `kind` must be one of {', '.join(map(repr, KINDS))}; got {kind!r}")
    klipper = kind.startswith("klipper")
    if window is None:
        window = "kaiser" if klipper else "none"
    if window not in WINDOWS:
        raise ValueError(
            f"{owner}: parameter `window` must be one of {', '.join(map(repr, WINDOWS))} or None; got {window!r}"
        )
    if band is None and klipper:
        band = KLIPPER_BAND
    return kind, window, band


@blas_limited
def identify_axis_from_psd(
    f,
    psd,
    n_modes: int,
    *,
    kind: str | None = None,
    window: str | None = None,
    resolution: float | None = None,
    band: tuple[float, float] | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 256,
):
    """The modes of a belt-driven axis from a power spectral density (PSD): a `ModalAxis` with the frequencies [Hz],
    damping ratios and their standard errors.

    ```python
    f, psd = jb.load_spectrum("calibration_data_x.csv")                  # Klipper's SHAPER_CALIBRATE output
    axis = jb.identify_axis_from_psd(f, psd, 2, kind="klipper-normalised")
    f, psd, _ = jb.welch(accel, 3200.0, window="hann", nperseg=4096)    # a tap test's accelerometer
    axis = jb.identify_axis_from_psd(f, psd, 1, kind="acceleration", window="hann")
    ```

    - `f`: frequencies [Hz], 1-D, strictly increasing, >= 0 (a point at 0 Hz is left out); any spacing.
    - `psd`: the PSD at `f`, same shape, >= 0 and > 0 where fitted, any unit: only its shape matters.
    - `n_modes`: number of modes $n \\ge 1$; the fit needs `SAMPLES_PER_PARAMETER` = 10 points per parameter
      ($3n + 1$ force-excited, $3n + 2$ base-excited).
    - `kind`: what the spectrum holds (see the module's documentation for each model): `"displacement"`,
      `"velocity"`, `"acceleration"` of a force-excited axis (a tap test); `"base-acceleration"` (the payload's
      acceleration, the carriage driven with a flat spectrum); `"klipper"` (Klipper's `TEST_RESONANCES`
      spectrum, `resonances_*.csv`) or `"klipper-normalised"` (its `SHAPER_CALIBRATE` spectrum,
      `calibration_data_*.csv`). None: `"displacement"`. `jaxbelt.identify_measurement` takes the kind from the
      file.
    - `window`: the estimate's window, whose smearing the model then carries: `"hann"`, `"kaiser"` (Klipper's,
      $\\beta$ = 6), `"none"` (an exact PSD, or one whose bins are far narrower than its peaks). None: `"kaiser"`
      for Klipper's kinds, else `"none"`. `resolution`: the estimate's bin width [Hz] (rate / segment length),
      > 0 and at most the band's width over `SAMPLES_PER_PARAMETER` bins per parameter; None: the mean step of `f`
      in the band.
    - `band`: `(low, high)` [Hz]: fit only the points with low <= f <= high. None: all above 0 Hz, and for
      Klipper's kinds its default sweep, `KLIPPER_BAND` = 5-135 Hz (pass the sweep's `FREQ_START`, `FREQ_END`
      where they differ).
    - `rtol`, `atol`, `max_steps`: the Levenberg-Marquardt solver's step tolerances and budget, as in
      `identify_axis`.

    The fit is a log-periodogram regression (the module's documentation says why), by Levenberg-Marquardt
    (`optimistix.least_squares`) in coordinates that keep every mode physical ($\\ln f_i$,
    $\\operatorname{logit}\\zeta_i$), from the half-power estimate of the $n$ largest distinct peaks (of the PSD,
    divided by the excitation's $f^{2q}$ base-excited). The arrays are padded to a multiple of 64 points: one
    compiled program per `n_modes`, kind, window and padded length.

    Returns `ModalAxis(frequencies, damping_ratios, gains=None, frequency_std=..., damping_std=...)`, the modes
    sorted by frequency, with the standard errors corrected for correlated bins (module documentation). The gains
    are unit gains, as `identify_axis` returns.

    Raises `ValueError`, naming the argument, before anything is compiled for: arrays that are not 1-D of the
    same shape, NaN or inf, `f` not strictly increasing or negative, `psd` negative (or zero where fitted), a
    bad `kind`, `window`, `resolution` or `band`, too few points, `n_modes` not an integer >= 1, a peak at the
    edge of the range, fewer distinct peaks than `n_modes`; and after the fit for: a frequency at or beyond the
    ends of the fitted range, a damping ratio outside (0, 1), a half-power bandwidth under `MIN_BANDWIDTH_STEPS`
    frequency steps (1 where the window is modelled), a mode whose amplitude is below `PSD_MIN_SIGNIFICANCE` = 8
    standard errors (a fit to noise, or more `n_modes` than the spectrum holds). Raises `RuntimeError` when the
    fit does not converge although every mode stands out, and when JAX's 64-bit mode is off.
    """
    owner = _OWNER
    _core._require_x64(owner)
    kind, window, band = _resolve_kind(kind, window, band)
    excitation, power = KINDS[kind]
    n_levels = 1 if excitation == "force" else 2
    fs, ps, lo, hi, n, p = _check_spectrum(f, psd, n_modes, band, lambda n: 3 * n + n_levels)
    if kind == "klipper-normalised":
        ps = ps / _klipper_normalisation(fs)
    rtol, atol = float(rtol), float(atol)
    if not (math.isfinite(rtol) and rtol > 0):
        raise ValueError(f"{owner}: parameter `rtol` must be finite and > 0; got {rtol}")
    if not (math.isfinite(atol) and atol >= 0):
        raise ValueError(f"{owner}: parameter `atol` must be finite and >= 0; got {atol}")
    max_steps = check_int(owner, "max_steps", max_steps, lo=1)
    N = fs.size
    step = (fs[-1] - fs[0]) / (N - 1)
    if resolution is not None:
        resolution = float(resolution)
        # each bin of the estimate is one independent value: the band must hold SAMPLES_PER_PARAMETER of them per
        # fitted parameter, as it must hold that many points
        widest = (hi - lo) / (_core.SAMPLES_PER_PARAMETER * p)
        if not (math.isfinite(resolution) and 0 < resolution <= widest):
            raise ValueError(
                f"{owner}: parameter `resolution` (the estimate's bin width) must be finite, > 0 and at most "
                f"{widest:.4g} Hz (the fitted band {lo:.6g}-{hi:.6g} Hz over {_core.SAMPLES_PER_PARAMETER} independent bins "
                f"for each of the {p} parameters); got {resolution}"
            )
    df = step if resolution is None else resolution
    # in units of the spectrum's median, and of the band's middle frequency
    fref = math.sqrt(fs[0] * fs[-1])
    unit = float(np.exp(np.median(np.log(ps))))
    logp = np.log(ps / unit)
    trend = (fs / fref) ** (2 * power) if excitation == "base" else np.ones(N)
    f0, z0, height = _psd_peaks(fs, ps / (unit * trend), n)
    floor0 = float(np.exp(np.percentile(logp, 10.0)))
    logit0 = np.log(z0) - np.log1p(-z0)
    if excitation == "force":
        amp0 = np.maximum(height - floor0, 0.1 * height) * (2.0 * z0) ** 2  # |H|^2 = 1/(2 zeta)^2 at r = 1
        theta0 = np.concatenate([np.log(f0), logit0, np.log(amp0), [1.0]])
        scale = np.concatenate([z0, np.ones(2 * n + 1)])
    else:
        x = ps / (unit * trend)
        below = fs < 0.6 * f0[0]
        level0 = float(np.median(x[below])) if below.sum() >= 5 else float(np.exp(np.percentile(np.log(x), 25.0)))
        g0 = 2.0 * z0 * np.sqrt(np.maximum(height / level0 - 1.0, 0.25))
        theta0 = np.concatenate([np.log(f0), logit0, g0, [math.log(level0)], [0.3]])
        scale = np.concatenate([z0, np.ones(n), g0, [1.0, 1.0]])
    offsets, kw = _kernel(window)
    size = _PSD_PAD * math.ceil(N / _PSD_PAD)
    pad = size - N
    fp = np.concatenate([fs, np.full(pad, fs[-1])])
    fo = np.maximum(fp[:, None] + offsets[None, :] * df, 1e-3 * fs[0]) / fref
    lp = np.concatenate([logp, np.full(pad, logp[-1])])
    weight = np.concatenate([np.ones(N), np.zeros(pad)])
    theta0 = theta0.copy()
    theta0[:n] -= math.log(fref)  # the frequencies in units of fref
    out = _fit_psd(
        device_array(fo),
        device_array(kw),
        device_array(lp),
        device_array(weight),
        floor0,
        device_array(theta0),
        device_array(scale),
        n=n,
        excitation=excitation,
        power=power,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
    )
    r, sv, vt, code, steps, finite, theta, fi, zeta = _core._fit_outcome(out, theta0, scale, n)
    fi = fi * fref
    start = f"started from the half-power estimate f = {_core._fmt(f0)} Hz, zeta = {_core._fmt(z0)}"
    if finite:
        factor = _core._long_run_factor(np.asarray(r)[:N], _HAC_LAGS)
        var = np.diag(_core._covariance(r, sv, vt, scale, p, N)) * factor  # the padding's residuals are 0
        f_std = fi * np.sqrt(var[:n])
        z_std = zeta * (1.0 - zeta) * np.sqrt(var[n : 2 * n])
        with np.errstate(divide="ignore", invalid="ignore"):
            if excitation == "force":
                significance = 1.0 / np.sqrt(var[2 * n : 3 * n])  # A / std(A) = 1 / std(ln A)
            else:
                significance = np.abs(theta[2 * n : 3 * n]) / np.sqrt(var[2 * n : 3 * n])
        significance = np.nan_to_num(significance, nan=0.0)
    else:
        f_std = z_std = significance = np.zeros(n)
    if code != 0:
        reason = _core._RESULT_NAMES[code] if code >= 0 else "unknown solver failure"
        failed = f"the Levenberg-Marquardt fit of {n} mode(s) did not converge ({reason}) after {steps} steps"
        if finite and np.any(~(significance >= PSD_MIN_SIGNIFICANCE)):
            i = int(np.argmin(significance))
            raise ValueError(
                f"{owner}: {failed}, and its last iterate has a mode ({fi[i]:.6g} Hz) whose amplitude is only "
                f"{significance[i]:.3g} standard errors (at least {PSD_MIN_SIGNIFICANCE:g} are needed): the spectrum "
                f"(`psd`) may hold fewer than `n_modes` = {n} modes, or another `kind` than {kind!r}: try a smaller "
                f"`n_modes` ({start})"
            )
        hint = (
            f"give a larger `max_steps` (now {max_steps})"
            if reason in ("max_steps_reached", "nonlinear_max_steps_reached")
            else f"check that the spectrum is a PSD of the axis of the `kind` {kind!r}"
        )
        raise RuntimeError(
            f"{owner}: {failed}, {start}. {hint[0].upper() + hint[1:]}, try another `n_modes`, or fit a narrower `band`"
        )
    if not finite:
        raise RuntimeError(
            f"{owner}: the fit of {n} mode(s) ended at non-finite values ({start}); try another `n_modes`"
        )
    fi, zeta, f_std, z_std, found = sorted_fitted_modes(
        owner,
        n,
        fi,
        zeta,
        f_std,
        z_std,
        significance,
        (lo, hi),
        found_suffix=f" as a {kind!r} spectrum",
        edge=f"the fitted frequency range {lo:.6g}-{hi:.6g} Hz (parameter `f`, or `band`): widen the range, fit "
        "fewer `n_modes`, or check `kind`",
        zeta_hint="`psd` is not a resonant spectrum",
        weak="amplitude",
        holder="spectrum (`psd`)",
    )
    min_steps = MIN_BANDWIDTH_STEPS if window == "none" else 1.0
    for i in range(n):
        width = 2.0 * zeta[i] * fi[i]
        if width < min_steps * df:
            raise ValueError(
                f"{owner}: mode {i + 1} ({fi[i]:.6g} Hz, zeta = {zeta[i]:.3g}) has a half-power bandwidth of "
                f"{width:.3g} Hz, under {min_steps:g} step(s) of the frequency grid (`f`: {df:.3g} Hz): the spectrum "
                f"does not resolve its damping; use a finer frequency grid (longer segments), give the estimate's "
                f"`window` (its smearing is then modelled), or identify the axis from a time record with "
                f"identify_axis ({found})"
            )
    from ..models.axis import ModalAxis

    return ModalAxis(fi, zeta, None, frequency_std=f_std, damping_std=z_std)


def sorted_fitted_modes(
    owner, n, fi, zeta, f_std, z_std, significance, band, *, found_suffix, edge, zeta_hint, weak, holder
):
    """The fitted modes in ascending frequency, `(fi, zeta, f_std, z_std, found)`, after the checks every fit of
    modes ends with (`identify_axis_from_psd`, `identify_axis_from_sweep`): a mode at or beyond an edge of `band`
    (`edge`: what the band is and what to do), a damping ratio outside (0, 1) (`zeta_hint`), a mode whose `weak`
    ("amplitude", "gain") is below `PSD_MIN_SIGNIFICANCE` standard errors (`holder`: what holds the modes). `found`:
    the sentence naming the fitted values, for the caller's own messages."""
    lo, hi = band
    order = np.argsort(fi)
    fi, zeta, f_std, z_std, significance = (v[order] for v in (fi, zeta, f_std, z_std, significance))
    found = f"identified f = {_core._fmt(fi)} Hz, zeta = {_core._fmt(zeta)}{found_suffix}"
    outside = np.flatnonzero((fi <= lo) | (fi >= hi))
    if outside.size:
        i = int(outside[0])
        raise ValueError(
            f"{owner}: mode {i + 1} comes out at {fi[i]:.6g} Hz, at or beyond the edge of {edge} ({found})"
        )
    if not np.all((zeta > 0.0) & (zeta < 1.0)):
        raise ValueError(f"{owner}: a damping ratio comes out outside (0, 1) ({found}): {zeta_hint}")
    below = np.flatnonzero(~(significance >= PSD_MIN_SIGNIFICANCE))
    if below.size:
        i = int(below[0])
        raise ValueError(
            f"{owner}: mode {i + 1} ({fi[i]:.6g} Hz, zeta = {zeta[i]:.3g}) is not resolved above the noise: its "
            f"{weak} is {significance[i]:.3g} standard errors (at least {PSD_MIN_SIGNIFICANCE:g} are needed): the "
            f"{holder} may hold fewer than `n_modes` = {n} modes: try a smaller `n_modes` ({found})"
        )
    return fi, zeta, f_std, z_std, found
