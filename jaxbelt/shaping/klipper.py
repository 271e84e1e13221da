"""Klipper's input shapers as Klipper computes them, the text its configuration parser reads, and its
calibration's choice rule.

**The shapers** (Klipper's shaper definitions, `klippy/extras/shaper_defs.py`; facts re-implemented here): six
types, each a function of a frequency $f$ [Hz] and a damping ratio $\\zeta$, with $d = \\sqrt{1-\\zeta^2}$,
$K = e^{-\\zeta\\pi/d}$, $t_d = 1/(fd)$:

| type | amplitudes (not normalised; Klipper's kernel divides by their sum) | times | largest ζ |
|---|---|---|---|
| `zv` | $1, K$ | $0, t_d/2$ | 0.99 |
| `mzv` | $a_i K'^i$, $a$ from the zero placement below, $K' = e^{-2t\\zeta\\pi/((n-1)d)}$ | $i\\,t\\,t_d/(n-1)$ | 0.99 |
| `zvd` | $1, 2K, K^2$ | $0, t_d/2, t_d$ | 0.99 |
| `ei` | $a_1, 1 - a_1 - a_3, a_3$ (Klipper's fit, V = 5 %) | $0, t_2 t_d, t_d$ | 0.4 |
| `2hump_ei` | cubics in ζ | cubics in ζ times $1/f$ | 0.3 |
| `3hump_ei` | cubics in ζ | cubics in ζ times $1/f$ | 0.2 |

The `mzv` amplitudes $a$ (n = 3 impulses at $t = 0.75$ damped periods, Klipper's default) are the least-squares
solution of $\\sum a = 1$ and $\\sum_j a_j e^{2\\pi i (1 + k/\\tau) T_j} = 0$ for $k = 0 \\dots n-2$,
$\\tau = t(n-2)/(n-2t-1)$: for n = 3 exactly $1 - 1/\\sqrt2,\\ \\sqrt2 - 1,\\ 1 - 1/\\sqrt2$ (zeros at $f$ and
$5f/3$). The EI fits' coefficients are those of `jaxbelt.shaping.shapers` (the same published table).
Klipper's motion kernel takes at most 10 pulses (`klippy/chelper/kin_shaper.c`); every type here has at most 5.

**The text**: the `[input_shaper]` section (`shaper_type_x`, `shaper_freq_x`, `damping_ratio_x`) and the
`SET_INPUT_SHAPER` command; `parse_klipper` reads either back as Klipper's `input_shaper.py` does (types in lower
case, a damping ratio in [0, the type's largest], a frequency >= 0, 0 meaning no shaping).

**The calibration** (`klipper_calibration`): Klipper's `shaper_calibrate.py` choice from a resonance test's PSD.
For each type and each test frequency (from the type's `min_freq` to 150 Hz in 0.2 Hz steps, highest first) at
damping 0.1, the remaining vibration is
$\\max_{\\zeta_t \\in \\{0.075, 0.1, 0.15\\}} \\sum_f \\max(V(f)P(f) - P_{max}/20, 0) / \\sum_f \\max(P(f) - P_{max}/20, 0)$
(the PSD normalised by $f + 0.1$ and below 10 Hz damped first, as Klipper does before it fits), the smoothing
is Klipper's offset estimate at 5000 mm/s² and square-corner velocity 5 mm/s, and the score
$s(v^{1.5} + 0.2v + 0.01)$; per type the frequency of least vibration is kept, or a lower-smoothing one of
score less and vibrations within $1.1v + 0.0005$; across types, a type replaces the best when its score is 20 %
less, or 5 % less with 10 % less smoothing; finally `zv` gives way to the first type that leaves 10 % less
vibration. The types tried are Klipper's `AUTOTUNE_SHAPERS` (all but `zvd`).
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

import numpy as np

from .._checks import check_real, is_concrete
from ..models.axis import FREQUENCY_RANGE_HZ

#: Klipper's shaper types in its order, with the calibration's lowest test frequency [Hz] and the largest
#: damping ratio each type accepts (`INPUT_SHAPERS` in Klipper's shaper definitions).
KLIPPER_SHAPERS = {
    "zv": (21.0, 0.99),
    "mzv": (23.0, 0.99),
    "zvd": (29.0, 0.99),
    "ei": (29.0, 0.4),
    "2hump_ei": (39.0, 0.3),
    "3hump_ei": (48.0, 0.2),
}
#: The most pulses Klipper's motion kernel accepts (`kin_shaper.c`).
KLIPPER_MAX_PULSES = 10
#: jaxbelt's name of each Klipper type (`jaxbelt.shaping.shapers.SHAPERS`).
JAXBELT_NAME = {"zv": "ZV", "mzv": "MZV", "zvd": "ZVD", "ei": "EI", "2hump_ei": "2-hump EI", "3hump_ei": "3-hump EI"}
#: Klipper's vibration tolerance (1 / SHAPER_VIBRATION_REDUCTION) at which its EI shapers are fitted.
_V_TOL = 1.0 / 20.0
_AUTOTUNE = ("zv", "mzv", "ei", "2hump_ei", "3hump_ei")
_TEST_DAMPING = (0.075, 0.1, 0.15)

_EI2_T = ((0.0, 0.0, 0.0, 0.0), (0.49890, 0.16270, -0.54262, 6.16180), (0.99748, 0.18382, -1.58270, 8.17120))
_EI2_T += ((1.49920, -0.09297, -0.28338, 1.85710),)
_EI2_A = ((0.16054, 0.76699, 2.26560, -1.22750), (0.33911, 0.45081, -2.58080, 1.73650))
_EI2_A += ((0.34089, -0.61533, -0.68765, 0.42261), (0.15997, -0.60246, 1.00280, -0.93145))
_EI3_T = ((0.0, 0.0, 0.0, 0.0), (0.49974, 0.23834, 0.44559, 12.4720), (0.99849, 0.29808, -2.36460, 23.3990))
_EI3_T += ((1.49870, 0.10306, -2.01390, 17.0320), (1.99960, -0.28231, 0.61536, 5.40450))
_EI3_A = ((0.11275, 0.76632, 3.29160, -1.44380), (0.23698, 0.61164, -2.57850, 4.85220))
_EI3_A += ((0.30008, -0.19062, -2.14560, 0.13744), (0.23775, -0.73297, 0.46885, -2.08650))
_EI3_A += ((0.11244, -0.45439, 0.96382, -1.46000),)


def mzv_coefficients(n: int = 3, t: float = 0.75):
    """The undamped `mzv` amplitudes and times (in damped periods) for `n` impulses over `t` periods: the
    least-squares solution of Klipper's zero-placement equations (module docstring)."""
    tau = t * (n - 2.0) / (n - 2.0 * t - 1.0)
    T = np.array([i * t / (n - 1.0) for i in range(n)])
    rows = [np.ones(n)]
    for i in range(n - 1):
        w = 2.0 * math.pi * (1.0 + i / tau) * T
        rows += [np.cos(w), np.sin(w)]
    F = np.r_[1.0, np.zeros(2 * (n - 1))]
    return np.linalg.pinv(np.array(rows)) @ F, T


_MZV_A, _MZV_T = mzv_coefficients()


def _horner(c, z, xp):
    return c[0] + z * (c[1] + z * (c[2] + z * c[3]))


def impulses(kind: str, freq, damping, xp=np):
    """`(A, T)`: Klipper's amplitudes (not normalised) and times [s] of the shaper `kind` (a key of
    `KLIPPER_SHAPERS`) at `freq` [Hz] and damping ratio `damping`, in Klipper's arithmetic. `xp`: `numpy` (floats)
    or `jax.numpy` (differentiable in `freq` and `damping`)."""
    z = damping
    df = xp.sqrt(1.0 - z * z)
    K = xp.exp(-z * math.pi / df)
    td = 1.0 / (freq * df)
    if kind == "zv":
        return [1.0 + 0.0 * K, K], [0.0 * td, 0.5 * td]
    if kind == "zvd":
        return [1.0 + 0.0 * K, 2.0 * K, K * K], [0.0 * td, 0.5 * td, td]
    if kind == "mzv":
        Km = xp.exp(-2.0 * 0.75 * z * math.pi / (2.0 * df))
        return [float(_MZV_A[i]) * Km**i for i in range(3)], [float(_MZV_T[i]) * td for i in range(3)]
    if kind == "ei":
        v = _V_TOL
        a1 = (0.24968 + 0.24961 * v) + ((0.80008 + 1.23328 * v) + (0.49599 + 3.17316 * v) * z) * z
        a3 = (0.25149 + 0.21474 * v) + ((-0.83249 + 1.41498 * v) + (0.85181 - 4.90094 * v) * z) * z
        t2 = (
            0.4999
            + (((0.46159 + 8.57843 * v) * v) + (((4.26169 - 108.644 * v) * v) + ((1.75601 + 336.989 * v) * v) * z) * z)
            * z
        )
        return [a1, 1.0 - a1 - a3, a3], [0.0 * td, t2 * td, td]
    if kind in ("2hump_ei", "3hump_ei"):
        ta, aa = (_EI2_T, _EI2_A) if kind == "2hump_ei" else (_EI3_T, _EI3_A)
        return [_horner(a, z, xp) for a in aa], [_horner(t, z, xp) / freq for t in ta]
    raise ValueError(f"klipper shaper: parameter `kind` must be one of {tuple(KLIPPER_SHAPERS)}; got {kind!r}")


def _real_scalar(owner: str, name: str, value, unit: str) -> float:
    """`value` as a Python float: a real number, a numpy scalar or a concrete 0-d array; anything else (a string, a
    bool, None, a complex number, an array of several values, a traced value) is refused by name."""
    try:
        check_real(name, value, unit, owner)
        if not is_concrete(value) or np.ndim(value) != 0:
            raise TypeError
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(
            f"{owner}: parameter `{name}` must be one real number{f' [{unit}]' if unit else ''} (a concrete scalar); "
            f"got {value!r}"
        ) from None


def klipper_impulses(kind: str, freq: float, damping: float):
    """Klipper's shaper `kind` at `freq` [Hz] > 0 and `damping` in [0, the type's largest]: `(amplitudes, times)`
    as numpy arrays, amplitudes normalised to sum 1 (as Klipper's kernel uses them), times [s] from 0."""
    if kind not in KLIPPER_SHAPERS:
        raise ValueError(f"klipper_impulses: parameter `kind` must be one of {tuple(KLIPPER_SHAPERS)}; got {kind!r}")
    zmax = KLIPPER_SHAPERS[kind][1]
    lo, hi = FREQUENCY_RANGE_HZ
    freq = _real_scalar("klipper_impulses", "freq", freq, "Hz")
    if not (math.isfinite(freq) and lo <= freq <= hi):
        raise ValueError(
            f"klipper_impulses: parameter `freq` must be finite and within [{lo:g}, {hi:g}] Hz (a mode's frequency, "
            f"`FREQUENCY_RANGE_HZ`); got {freq!r}"
        )
    damping = _real_scalar("klipper_impulses", "damping", damping, "")
    if not 0.0 <= damping <= zmax:
        raise ValueError(f"klipper_impulses: parameter `damping` must lie in [0, {zmax}] for {kind}; got {damping!r}")
    A, T = impulses(kind, freq, damping)
    A = np.array([float(a) for a in A])
    return A / A.sum(), np.array([float(t) for t in T])


class KlipperConfig(NamedTuple):
    """One axis' Klipper input shaper: `kind` (Klipper's type name), `freq` [Hz], `damping`. The text writes the
    numbers in full (the shortest decimal that reads back to the same float: Klipper reads its configuration's
    numbers as Python floats), so Klipper runs exactly the shaper whose residual jaxbelt states."""

    kind: str
    freq: float
    damping: float

    def section(self, axis: str = "x") -> str:
        """The `[input_shaper]` section of Klipper's configuration for `axis`."""
        return (
            f"[input_shaper]\nshaper_type_{axis}: {self.kind}\nshaper_freq_{axis}: {float(self.freq)!r}\n"
            f"damping_ratio_{axis}: {float(self.damping)!r}\n"
        )

    def command(self, axis: str = "x") -> str:
        """The `SET_INPUT_SHAPER` command that sets this shaper on `axis` at run time."""
        a = axis.upper()
        return (
            f"SET_INPUT_SHAPER SHAPER_TYPE_{a}={self.kind} SHAPER_FREQ_{a}={float(self.freq)!r} "
            f"DAMPING_RATIO_{a}={float(self.damping)!r}"
        )


def parse_klipper(text: str, axis: str = "x") -> KlipperConfig:
    """Read an `[input_shaper]` section or a `SET_INPUT_SHAPER` line for `axis` as Klipper does: the type's name in
    any case (lower-cased; `shaper_type` applies to both axes unless `shaper_type_x` is given; default `mzv`), the
    damping ratio (default 0.1) within [0, the type's largest], the frequency >= 0 (default 0: no shaping).
    Returns a `KlipperConfig`; anything Klipper would refuse raises a `ValueError` naming the field."""
    o = "parse_klipper"
    if not isinstance(text, str):
        raise TypeError(
            f"{o}: parameter `text` must be a str (a configuration section or a command); got {type(text).__name__}"
        )
    if not isinstance(axis, str) or axis.lower() not in ("x", "y"):
        raise ValueError(f"{o}: parameter `axis` must be 'x' or 'y' (Klipper's shaped axes); got {axis!r}")
    a = axis.lower()
    values: dict[str, str] = {}
    if text.lstrip().upper().startswith("SET_INPUT_SHAPER"):
        for key, val in re.findall(r"(\w+)=(\S+)", text):
            values[key.lower()] = val
    else:
        in_section = False
        for raw in text.splitlines():
            line = raw.split("#")[0].split(";")[0].strip()
            if line.startswith("["):
                in_section = line == "[input_shaper]"
                continue
            if in_section and line:
                key, _, val = line.partition(":") if ":" in line else line.partition("=")
                values[key.strip().lower()] = val.strip()
    kind = values.get(f"shaper_type_{a}", values.get("shaper_type", "mzv")).lower()
    if kind not in KLIPPER_SHAPERS:
        raise ValueError(f"parse_klipper: shaper_type_{a} {kind!r} is not one of {tuple(KLIPPER_SHAPERS)}")

    def number(key: str, default: float) -> float:
        raw = values.get(key)
        if raw is None:
            return default
        try:
            return float(raw)
        except ValueError:
            raise ValueError(f"{o}: {key} must be a number; got {raw!r}") from None

    damping = number(f"damping_ratio_{a}", 0.1)
    zmax = KLIPPER_SHAPERS[kind][1]
    if not 0.0 <= damping <= zmax:
        raise ValueError(f"parse_klipper: damping_ratio_{a} must lie in [0, {zmax}] for {kind}; got {damping}")
    freq = number(f"shaper_freq_{a}", 0.0)
    lo, hi = FREQUENCY_RANGE_HZ
    if not (freq == 0.0 or (math.isfinite(freq) and lo <= freq <= hi)):
        raise ValueError(
            f"parse_klipper: shaper_freq_{a} must be 0 (no shaping) or within [{lo:g}, {hi:g}] Hz (a mode's "
            f"frequency, `FREQUENCY_RANGE_HZ`); got {freq}"
        )
    return KlipperConfig(kind, freq, damping)


def smoothing(A, T, accel: float = 5000.0, scv: float = 5.0) -> float:
    """Klipper's smoothing estimate [mm] of a shaper (`A`, `T` [s]) at acceleration `accel` [mm/s²] and square
    corner velocity `scv` [mm/s]: the larger of its 90° and 180° corner offsets (`shaper_calibrate.py`)."""
    A, T = np.asarray(A, dtype=float), np.asarray(T, dtype=float)
    inv_d = 1.0 / A.sum()
    ts = float(np.sum(A * T)) * inv_d
    after = T >= ts
    o90 = float(np.sum(A[after] * (scv + 0.5 * accel * (T[after] - ts)) * (T[after] - ts))) * inv_d * math.sqrt(2.0)
    o180 = float(np.sum(A * 0.5 * accel * (T - ts) ** 2)) * inv_d
    return max(o90, o180)


def _estimate(A, T, zeta, f):
    A, T = np.asarray(A, dtype=float), np.asarray(T, dtype=float)
    w = 2.0 * math.pi * f
    wd = w * math.sqrt(1.0 - zeta * zeta)
    W = A * np.exp(np.outer(-zeta * w, T[-1] - T))
    return np.hypot((W * np.sin(np.outer(wd, T))).sum(axis=1), (W * np.cos(np.outer(wd, T))).sum(axis=1)) / A.sum()


class CalibrationChoice(NamedTuple):
    """Klipper's calibration result: the chosen `config` (at Klipper's damping 0.1), its remaining `vibrations`
    (fraction), `smoothing` [mm] and `score`; `per_type`: the same for the best of each type tried."""

    config: KlipperConfig
    vibrations: float
    smoothing: float
    score: float
    per_type: tuple


def normalise_psd(freq_bins, psd):
    """Klipper's normalisation of a resonance test's PSD before it fits: divided by $f + 0.1$, and below 10 Hz
    multiplied by $e^{1 - (10/(f + 0.1))^2}$."""
    f = np.asarray(freq_bins, dtype=float)
    p = np.asarray(psd, dtype=float) / (f + 0.1)
    low = f < 10.0
    p[low] *= np.exp(-((10.0 / (f[low] + 0.1)) ** 2) + 1.0)
    return p


def _calibration_inputs(freq_bins, psd, normalised, max_freq):
    """`klipper_calibration`'s arguments checked, by name, before the search: `freq_bins` [Hz] 1-D, finite, >= 0 and
    ascending, at least 2; `psd` as many, finite, >= 0 and not all 0 below `max_freq` (its largest value sets
    Klipper's threshold, and the remaining vibrations are a fraction of what lies above it); `max_freq` [Hz] finite
    and above the first bin. Returns `(f, psd, max_freq)` as float arrays and a float."""
    o = "klipper_calibration"
    arrays = []
    for name, value in (("freq_bins", freq_bins), ("psd", psd)):
        check_real(name, value, "Hz" if name == "freq_bins" else "", o)
        try:
            a = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{o}: parameter `{name}` must be a 1-D array of numbers; got {value!r}") from None
        if a.ndim != 1 or a.size < 2:
            raise ValueError(f"{o}: parameter `{name}` must be a 1-D array of at least 2 values; got shape {a.shape}")
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            i = int(np.flatnonzero(~(np.isfinite(a) & (a >= 0)))[0])
            raise ValueError(f"{o}: parameter `{name}` must be finite and >= 0; got {a[i]!r} at index {i}")
        arrays.append(a)
    f, p = arrays
    if p.shape != f.shape:
        raise ValueError(f"{o}: parameter `psd` must have one value per frequency bin, shape {f.shape}; got {p.shape}")
    if np.any(np.diff(f) <= 0):
        i = int(np.flatnonzero(np.diff(f) <= 0)[0])
        raise ValueError(
            f"{o}: parameter `freq_bins` must ascend strictly (Klipper's calibration bins); bin {i + 1} = {f[i + 1]!r} "
            f"Hz follows {f[i]!r} Hz"
        )
    if isinstance(normalised, bool | np.bool_) is False:
        raise TypeError(f"{o}: parameter `normalised` must be True or False; got {normalised!r}")
    check_real("max_freq", max_freq, "Hz", o)
    mf = float(max_freq)
    if not (math.isfinite(mf) and mf > f[0]):
        raise ValueError(
            f"{o}: parameter `max_freq` must be finite and above the first frequency bin ({f[0]:g} Hz); got {mf!r}"
        )
    if not np.any(p[f <= mf] > 0):
        raise ValueError(f"{o}: parameter `psd` is 0 at every frequency up to `max_freq` = {mf:g} Hz: nothing to fit")
    return f, p, mf


def klipper_calibration(freq_bins, psd, *, normalised: bool = False, max_freq: float = 200.0) -> CalibrationChoice:
    """The shaper Klipper's calibration picks from a resonance test's PSD (`freq_bins` [Hz], `psd` of the summed
    axes, as Klipper's `calibration_data_*.csv` holds them): the rule of the module docstring, at Klipper's
    defaults (damping 0.1, test damping ratios 0.075/0.1/0.15, frequencies to 150 Hz in 0.2 Hz steps, no
    smoothing or vibration limits). `normalised=True`: `psd` is already normalised (`normalise_psd`)."""
    f, raw, max_freq = _calibration_inputs(freq_bins, psd, normalised, max_freq)
    p = raw if normalised else normalise_psd(f, raw)
    keep = f <= max_freq
    f, p = f[keep], p[keep]
    thr = p.max() / 20.0
    all_vibr = np.maximum(p - thr, 0.0).sum()
    best = None
    chosen = []
    for kind in _AUTOTUNE:
        results = []
        best_res = None
        for fs in np.arange(min(KLIPPER_SHAPERS[kind][0], 150.0 - 1e-7), 150.0, 0.2)[::-1]:
            A, T = impulses(kind, float(fs), 0.1)
            sm = smoothing(A, T)
            vib = 0.0
            for zt in _TEST_DAMPING:
                vals = _estimate(A, T, zt, f)
                vib = max(vib, float(np.maximum(vals * p - thr, 0.0).sum() / all_vibr))
            res = (KlipperConfig(kind, float(fs), 0.1), vib, sm, sm * (vib**1.5 + 0.2 * vib + 0.01))
            results.append(res)
            if best_res is None or best_res[1] > vib:
                best_res = res
        assert best_res is not None
        sel = best_res
        for r in results[::-1]:
            if r[1] < best_res[1] * 1.1 + 0.0005 and r[3] < sel[3]:
                sel = r
        shaper = sel
        if best is None or shaper[3] * 1.2 < best[3] or (shaper[3] * 1.05 < best[3] and shaper[2] * 1.1 < best[2]):
            best = shaper
        for r in results[::-1]:
            if r[1] < best[1] and r[2] < best[2]:
                best = shaper = r
        chosen.append(shaper)
    assert best is not None
    if best[0].kind == "zv":
        for s in chosen:
            if s[0].kind != "zv" and s[1] * 1.1 < best[1]:
                best = s
                break
    return CalibrationChoice(best[0], best[1], best[2], best[3], tuple(chosen))
