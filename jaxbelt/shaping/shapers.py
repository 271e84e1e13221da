"""Classic input shapers: impulse sequences that cancel (or bound) a mode's residual vibration.

Each shaper comes in two forms (`form=`):

- **"firmware"** (the default): the shapers as 3D-printer firmware runs them, from Klipper's shaper definitions
  (`klippy/extras/shaper_defs.py`). ZV, ZVD and MZV are exact closed forms for any damping; EI, 2-hump EI and
  3-hump EI are fits in the damping ratio ζ (and, for EI, in the tolerance V) of numerically designed damped
  EI shapers, so that their residual humps stay at V for a damped mode. The fits hold for ζ up to Klipper's
  limits (0.4, 0.3 and 0.2) and for Klipper's vibration tolerance V = 5 % (its `SHAPER_VIBRATION_REDUCTION`
  of 20), and are refused outside them.
- **"textbook"**: Singhose's closed forms, exact for an undamped mode and any V; a damped mode is handled by
  scaling impulse k by $K^k$ (the undamped design carried over, as jaxbelt did before it had the firmware
  forms). With damping its humps fall below V while its zeros stay near their undamped places, so it covers
  a narrower band than the firmware fits, whose humps rise to V again (at ζ = 0.1 and V = 5 %: EI's zeros at
  0.86f and 1.14f against 0.83f and 1.17f).

For a mode of frequency f [Hz] and damping ratio ζ: $K = e^{-\\zeta\\pi/\\sqrt{1-\\zeta^2}}$, the damped period
$T_d = 1/(f\\sqrt{1-\\zeta^2})$ [s] and the undamped period $T = 1/f$ [s]; $p(c_0, c_1, c_2, c_3)$ denotes the
cubic $c_0 + c_1\\zeta + c_2\\zeta^2 + c_3\\zeta^3$. Amplitudes are listed as the sources give them; jaxbelt
normalises them to sum to 1 (so does the firmware: Klipper's fits sum to 1 only to about 5e-4).

| shaper | form | amplitudes | times | source |
|---|---|---|---|---|
| ZV | both | $1, K$ | $0, T_d/2$ | Singer and Seering (1990); Klipper's shaper definitions |
| ZVD | both | $1, 2K, K^2$ | $0, T_d/2, T_d$ | Singer and Seering (1990); Klipper's shaper definitions |
| MZV | both | $1 - 1/\\sqrt2,\\ (\\sqrt2 - 1)K',\\ (1 - 1/\\sqrt2)K'^2$, $K' = K^{3/4}$ | $0, 3T_d/8, 3T_d/4$ | Klipper's shaper definitions (zeros at f and 5f/3) |
| EI | firmware | $a_1,\\ 1 - a_1 - a_3,\\ a_3$ (below), ζ ≤ 0.4 | $0,\\ t_2 T_d,\\ T_d$ | Klipper's shaper definitions |
| 2-hump EI | firmware | $A_i = p(\\cdot)$ (below), ζ ≤ 0.3 | $t_i = p(\\cdot)\\,T$ ($≈ 0, T/2, T, 3T/2$) | Klipper's shaper definitions |
| 3-hump EI | firmware | $A_i = p(\\cdot)$ (below), ζ ≤ 0.2 | $t_i = p(\\cdot)\\,T$ ($≈ 0, T/2, …, 2T$) | Klipper's shaper definitions |
| EI | textbook | $(1+V)/4,\\ (1-V)K/2,\\ (1+V)K^2/4$ | $0, T_d/2, T_d$ | Singhose, Seering and Singer (1994) |
| 2-hump EI | textbook | $b_1,\\ (1/2 - b_1)K,\\ (1/2 - b_1)K^2,\\ b_1K^3$ | $0, T_d/2, T_d, 3T_d/2$ | Singhose, Derezinski and Singer (1996) |
| 3-hump EI | textbook | $c_1,\\ c_2K,\\ (1 - 2c_1 - 2c_2)K^2,\\ c_2K^3,\\ c_1K^4$ | $0, T_d/2, T_d, 3T_d/2, 2T_d$ | Singhose, Derezinski and Singer (1996) |

The firmware EI (V: the tolerance, 0.05):
$a_1 = 0.24968 + 0.24961V + (0.80008 + 1.23328V)\\zeta + (0.49599 + 3.17316V)\\zeta^2$,
$a_3 = 0.25149 + 0.21474V + (-0.83249 + 1.41498V)\\zeta + (0.85181 - 4.90094V)\\zeta^2$,
$t_2 = 0.4999 + (0.46159V + 8.57843V^2)\\zeta + (4.26169V - 108.644V^2)\\zeta^2 + (1.75601V + 336.989V^2)\\zeta^3$.
The firmware multi-hump EI fits (V = 5 %), coefficients $(c_0, c_1, c_2, c_3)$ of $p$ per impulse (the first
impulse at t = 0):

| shaper | i | amplitude $A_i$ | time $t_i / T$ |
|---|---|---|---|
| 2-hump EI | 1 | 0.16054, 0.76699, 2.26560, −1.22750 | 0 |
| | 2 | 0.33911, 0.45081, −2.58080, 1.73650 | 0.49890, 0.16270, −0.54262, 6.16180 |
| | 3 | 0.34089, −0.61533, −0.68765, 0.42261 | 0.99748, 0.18382, −1.58270, 8.17120 |
| | 4 | 0.15997, −0.60246, 1.00280, −0.93145 | 1.49920, −0.09297, −0.28338, 1.85710 |
| 3-hump EI | 1 | 0.11275, 0.76632, 3.29160, −1.44380 | 0 |
| | 2 | 0.23698, 0.61164, −2.57850, 4.85220 | 0.49974, 0.23834, 0.44559, 12.4720 |
| | 3 | 0.30008, −0.19062, −2.14560, 0.13744 | 0.99849, 0.29808, −2.36460, 23.3990 |
| | 4 | 0.23775, −0.73297, 0.46885, −2.08650 | 1.49870, 0.10306, −2.01390, 17.0320 |
| | 5 | 0.11244, −0.45439, 0.96382, −1.46000 | 1.99960, −0.28231, 0.61536, 5.40450 |

Note the two time bases: the EI's times scale with the damped period $T_d$, the multi-hump fits' with the
undamped period $T = 1/f$ (as Klipper's shaper definitions have them).

The textbook EI shapers: $X = (V^2(\\sqrt{1-V^2} + 1))^{1/3}$, $b_1 = (3X^2 + 2X + 3V^2)/(16X)$;
$c_1 = (1 + 3V + 2\\sqrt{2V(V + 1)})/16$, $c_2 = (1 - V)/4$.

What they do, undamped: EI leaves V at f and zero at two frequencies around it (one hump); the 2-hump EI
leaves zero at f and two humps of V beside it; the 3-hump EI leaves V at f and two more humps of V further out,
over the widest band (≈ 0.52f to 1.48f within 5 %) and the longest sequence (2 periods). The firmware fits
reproduce these to within their fitting error: the highest hump within 2 % (EI), 8 % (2-hump EI) and 13 %
(3-hump EI) of V over their damping ranges.

Several modes: the shapers of the modes are convolved (`convolve`); the sequence is as long as the sum of
their durations.
"""

import math

import numpy as np

from .._checks import is_concrete
from ..models.axis import FREQUENCY_RANGE_HZ

#: The classic shapers jaxbelt compares with, in order of length.
SHAPERS = ("ZV", "MZV", "ZVD", "EI", "2-hump EI", "3-hump EI")

#: The forms of `shaper_impulses`: Klipper's (the default) and Singhose's closed forms.
FORMS = ("firmware", "textbook")

#: Klipper's vibration tolerance V (1 / its `SHAPER_VIBRATION_REDUCTION` of 20): the one its EI fits are used at.
FIRMWARE_TOLERANCE = 0.05

#: The largest damping ratio each firmware EI fit holds for (Klipper's `max_damping_ratio`).
FIRMWARE_MAX_DAMPING = {"EI": 0.4, "2-hump EI": 0.3, "3-hump EI": 0.2}

# Klipper's multi-hump EI fits, one row per impulse: the coefficients (c0, c1, c2, c3) of c0 + c1 ζ + c2 ζ² + c3 ζ³;
# the amplitudes as they are (they sum to 1 within ~5e-4), the times in units of the undamped period 1/f.
_EI2_AMPLITUDES = np.array(
    [
        [0.16054, 0.76699, 2.26560, -1.22750],
        [0.33911, 0.45081, -2.58080, 1.73650],
        [0.34089, -0.61533, -0.68765, 0.42261],
        [0.15997, -0.60246, 1.00280, -0.93145],
    ]
)
_EI2_TIMES = np.array(
    [
        [0.0, 0.0, 0.0, 0.0],
        [0.49890, 0.16270, -0.54262, 6.16180],
        [0.99748, 0.18382, -1.58270, 8.17120],
        [1.49920, -0.09297, -0.28338, 1.85710],
    ]
)
_EI3_AMPLITUDES = np.array(
    [
        [0.11275, 0.76632, 3.29160, -1.44380],
        [0.23698, 0.61164, -2.57850, 4.85220],
        [0.30008, -0.19062, -2.14560, 0.13744],
        [0.23775, -0.73297, 0.46885, -2.08650],
        [0.11244, -0.45439, 0.96382, -1.46000],
    ]
)
_EI3_TIMES = np.array(
    [
        [0.0, 0.0, 0.0, 0.0],
        [0.49974, 0.23834, 0.44559, 12.4720],
        [0.99849, 0.29808, -2.36460, 23.3990],
        [1.49870, 0.10306, -2.01390, 17.0320],
        [1.99960, -0.28231, 0.61536, 5.40450],
    ]
)


class ShaperRangeError(ValueError):
    """A firmware shaper asked for outside the damping range its fit holds for. `note`: the reason in a few
    words (what `design_move`'s table says for the shaper it cannot build)."""

    def __init__(self, message: str, note: str):
        super().__init__(message)
        self.note = note


def _k_td(freq: float, zeta: float):
    df = math.sqrt(1.0 - zeta * zeta)
    return math.exp(-zeta * math.pi / df), 1.0 / (freq * df)


def _cubic(table, zeta: float):
    """Each row `(c0, c1, c2, c3)` of `table` evaluated at ζ: $c_0 + c_1\\zeta + c_2\\zeta^2 + c_3\\zeta^3$."""
    return table @ np.array([1.0, zeta, zeta * zeta, zeta**3])


def _firmware_ei(zeta: float, V: float, td: float):
    """Klipper's damped EI: amplitudes and times [s] (see the module docstring)."""
    a1 = 0.24968 + 0.24961 * V + (0.80008 + 1.23328 * V) * zeta + (0.49599 + 3.17316 * V) * zeta**2
    a3 = 0.25149 + 0.21474 * V + (-0.83249 + 1.41498 * V) * zeta + (0.85181 - 4.90094 * V) * zeta**2
    t2 = (
        0.4999
        + (0.46159 * V + 8.57843 * V**2) * zeta
        + (4.26169 * V - 108.644 * V**2) * zeta**2
        + (1.75601 * V + 336.989 * V**2) * zeta**3
    )
    return [a1, 1.0 - a1 - a3, a3], [0.0, t2 * td, td]


def _textbook_ei(name: str, V: float, K: float, td: float):
    """Singhose's undamped EI shapers, impulse k scaled by $K^k$, at multiples of $T_d/2$ (module docstring)."""
    if name == "EI":
        a = [0.25 * (1 + V), 0.5 * (1 - V), 0.25 * (1 + V)]
    elif name == "2-hump EI":
        X = (V * V * (math.sqrt(1.0 - V * V) + 1.0)) ** (1.0 / 3.0)
        b1 = (3 * X * X + 2 * X + 3 * V * V) / (16 * X)
        a = [b1, 0.5 - b1, 0.5 - b1, b1]
    else:
        c1 = (1 + 3 * V + 2 * math.sqrt(2 * V * (V + 1))) / 16
        c2 = 0.25 * (1 - V)
        a = [c1, c2, 1 - 2 * c1 - 2 * c2, c2, c1]
    return [ak * K**k for k, ak in enumerate(a)], [0.5 * td * k for k in range(len(a))]


def shaper_impulses(name: str, freq: float, zeta: float, tolerance: float = 0.05, *, form: str = "firmware"):
    """`(amplitudes, times)` (numpy, amplitudes summing to 1, times [s] from 0) of the shaper `name` (one of
    `SHAPERS`) for a mode of frequency `freq` [Hz] and damping ratio `zeta` in [0, 1).

    - `tolerance`: the vibration tolerance V of the EI shapers, a fraction in (0, 1) (ignored by ZV, MZV, ZVD);
    - `form`: `"firmware"` (default): the shapers as Klipper defines them (Klipper's shaper definitions), whose EI
      fits hold for V = 0.05 only and for `zeta` up to 0.4 (EI), 0.3 (2-hump EI), 0.2 (3-hump EI); outside that
      range a `ShaperRangeError` (a `ValueError`) names the limit. `"textbook"`: Singhose's closed forms (any V,
      any `zeta`). The formulas and their sources: the docstring of the module `jaxbelt.shaping.shapers`.
    """
    if name not in SHAPERS:
        raise ValueError(f"shaper_impulses: parameter `name` must be one of {SHAPERS}; got {name!r}")
    if form not in FORMS:
        raise ValueError(f"shaper_impulses: parameter `form` must be one of {FORMS}; got {form!r}")
    for name_, value in (("freq", freq), ("zeta", zeta), ("tolerance", tolerance)):
        if not is_concrete(value):  # the impulse times are host numbers (a shaper is a table, not a traced function)
            raise ValueError(
                f"shaper_impulses: parameter `{name_}` is traced (jax.jit, jax.vmap, jax.grad): the shaper's impulses "
                "are computed on the host from concrete numbers; call it outside the transformation, or use "
                "`jaxbelt.shaping.klipper.impulses(kind, freq, damping, xp=jax.numpy)` for a differentiable Klipper shaper"
            )
    lo, hi = FREQUENCY_RANGE_HZ
    if not (math.isfinite(freq) and lo <= freq <= hi):
        raise ValueError(
            f"shaper_impulses: parameter `freq` must be finite and within [{lo:g}, {hi:g}] Hz (a mode's frequency, "
            f"`FREQUENCY_RANGE_HZ`); got {freq}"
        )
    if not (0.0 <= zeta < 1.0):
        raise ValueError(f"shaper_impulses: parameter `zeta` must lie in [0, 1); got {zeta}")
    if not (0.0 < tolerance < 1.0):
        raise ValueError(f"shaper_impulses: parameter `tolerance` must lie in (0, 1); got {tolerance}")
    firmware_fit = form == "firmware" and name in FIRMWARE_MAX_DAMPING
    if firmware_fit:
        if abs(tolerance - FIRMWARE_TOLERANCE) > 1e-12:
            raise ValueError(
                f"shaper_impulses: parameter `tolerance` must be {FIRMWARE_TOLERANCE} for the firmware {name} (Klipper's "
                f"fit is made for its 5 % vibration tolerance); got {tolerance} (form='textbook' takes any tolerance "
                f"in (0, 1))"
            )
        z_max = FIRMWARE_MAX_DAMPING[name]
        if zeta > z_max:
            raise ShaperRangeError(
                f"shaper_impulses: parameter `zeta` must lie in [0, {z_max}] for the firmware {name} (the range "
                f"Klipper's fit holds for); got {zeta} (form='textbook' takes any zeta in [0, 1))",
                note=f"not built: Klipper's {name} holds for damping ratios <= {z_max} (got {zeta:.3g})",
            )
    K, td = _k_td(freq, zeta)
    V = tolerance
    if name == "ZV":
        A, t = [1.0, K], [0.0, 0.5 * td]
    elif name == "ZVD":
        A, t = [1.0, 2 * K, K * K], [0.0, 0.5 * td, td]
    elif name == "MZV":
        k = K**0.75
        a1 = 1.0 - 1.0 / math.sqrt(2.0)
        A, t = [a1, (math.sqrt(2.0) - 1.0) * k, a1 * k * k], [0.0, 0.375 * td, 0.75 * td]
    elif not firmware_fit:
        A, t = _textbook_ei(name, V, K, td)
    elif name == "EI":
        A, t = _firmware_ei(zeta, V, td)
    else:
        amplitudes, times = (_EI2_AMPLITUDES, _EI2_TIMES) if name == "2-hump EI" else (_EI3_AMPLITUDES, _EI3_TIMES)
        A, t = _cubic(amplitudes, zeta), _cubic(times, zeta) / freq
    A = np.asarray(A, dtype=float)
    return A / A.sum(), np.asarray(t, dtype=float)


def convolve(sequences):
    """The convolution of impulse sequences `[(amplitudes, times), ...]`: `(amplitudes, times)` sorted by time."""
    A, t = np.array([1.0]), np.array([0.0])
    for a, tt in sequences:
        A = (A[:, None] * np.asarray(a)[None, :]).ravel()
        t = (t[:, None] + np.asarray(tt)[None, :]).ravel()
    order = np.argsort(t, kind="stable")
    return A[order], t[order]


#: the most impulses a shaper convolved over an axis' modes may have (ZV over 8 modes, ZVD or EI over 5, 3-hump EI
#: over 3): the convolution of a k-impulse shaper over n modes has k**n impulses (3-hump EI over 10 modes: 9.8
#: million), and a move shaped by it as many terms to evaluate; such a shaper also lasts the sum of its modes' shapers
MAX_IMPULSES = 256


def shaper_for_axis(name: str, frequencies, damping_ratios, tolerance: float = 0.05, *, form: str = "firmware"):
    """The shaper `name` for every mode of an axis (`frequencies` [Hz], `damping_ratios`), convolved:
    `(amplitudes, times [s])`; `tolerance` and `form` as in `shaper_impulses`.

    Raises `ShaperRangeError` (a `ValueError`) when the convolution would have more than `MAX_IMPULSES` = 256
    impulses (a k-impulse shaper over n modes has k**n); `design_move` then lists the shaper as not built."""
    each = [
        shaper_impulses(name, float(f), float(z), tolerance, form=form)
        for f, z in zip(np.asarray(frequencies), np.asarray(damping_ratios))
    ]
    size = math.prod(len(a) for a, _ in each)
    if size > MAX_IMPULSES:
        k = len(each[0][0])
        raise ShaperRangeError(
            f"shaper_for_axis: {name} convolved over {len(each)} modes has {k}**{len(each)} = {size} impulses, more "
            f"than MAX_IMPULSES = {MAX_IMPULSES}; shape fewer modes with it (the ones that ring), or use the minimax "
            "design (`design_move`) or `design_shaper`, whose size does not grow with the number of modes",
            note=f"not built: {size} impulses over {len(each)} modes (more than {MAX_IMPULSES})",
        )
    return convolve(each)


def shaper_response(amplitudes, times, freq, zeta):
    """The shaper's own residual ratio $V(\\omega)$ (Singer and Seering, 1990): the ringing after the impulse
    sequence relative to one unit impulse, at frequencies `freq` [Hz] (any shape) for damping ratio `zeta`."""
    w = 2 * np.pi * np.asarray(freq, dtype=float)[..., None]
    wd = w * np.sqrt(1.0 - zeta * zeta)
    tl = np.asarray(times)[-1]
    terms = np.asarray(amplitudes) * np.exp(-zeta * w * (tl - np.asarray(times))) * np.exp(1j * wd * np.asarray(times))
    return np.abs(np.sum(terms, axis=-1))
