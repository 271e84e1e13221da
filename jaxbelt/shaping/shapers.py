"""Classic input shapers: impulse sequences that cancel (or bound) a mode's residual vibration.

For a mode of frequency f [Hz] and damping ratio ζ, with $K = e^{-\\zeta\\pi/\\sqrt{1-\\zeta^2}}$ and the
damped period $T_d = 1/(f\\sqrt{1-\\zeta^2})$; amplitudes are normalised to sum to 1:

| shaper | amplitudes | times | source |
|---|---|---|---|
| ZV | $1, K$ | $0, T_d/2$ | Singer and Seering (1990) |
| ZVD | $1, 2K, K^2$ | $0, T_d/2, T_d$ | Singer and Seering (1990) |
| MZV | $1 - 1/\\sqrt2,\\ (\\sqrt2 - 1)K',\\ (1 - 1/\\sqrt2)K'^2$, $K' = K^{3/4}$ | $0, 3T_d/8, 3T_d/4$ | as used in 3D-printer firmware |
| EI | $(1+V)/4,\\ (1-V)K/2,\\ (1+V)K^2/4$ | $0, T_d/2, T_d$ | Singhose, Seering and Singer (1994) |
| 2-hump EI | $a_1,\\ (1/2 - a_1)K,\\ (1/2 - a_1)K^2,\\ a_1K^3$ | $0, T_d/2, T_d, 3T_d/2$ | Singhose, Derezinski and Singer (1996) |

EI shapers hold the residual at or below the tolerance V (5 % by default) over a band around the
design frequency instead of cancelling it at one point; for the 2-hump EI,
$X = (V^2(\\sqrt{1-V^2} + 1))^{1/3}$ and $a_1 = (3X^2 + 2X + 3V^2)/(16X)$. The EI formulas are the
undamped closed forms with the damping carried by powers of K, as firmware uses them.

Several modes: the shapers of the modes are convolved (`convolve`); the sequence is as long as the sum of
their durations.
"""

import math

import numpy as np

#: The classic shapers jaxbelt compares with, in order of length.
SHAPERS = ("ZV", "MZV", "ZVD", "EI", "2-hump EI")


def _k_td(freq: float, zeta: float):
    df = math.sqrt(1.0 - zeta * zeta)
    return math.exp(-zeta * math.pi / df), 1.0 / (freq * df)


def shaper_impulses(name: str, freq: float, zeta: float, tolerance: float = 0.05):
    """`(amplitudes, times)` (numpy, amplitudes summing to 1, times [s] from 0) of the shaper `name` for a mode of
    frequency `freq` [Hz] and damping ratio `zeta` in [0, 1); `tolerance` V of the EI shapers (0 < V < 1)."""
    if name not in SHAPERS:
        raise ValueError(f"shaper_impulses: parameter `name` must be one of {SHAPERS}; got {name!r}")
    if not (math.isfinite(freq) and freq > 0):
        raise ValueError(f"shaper_impulses: parameter `freq` must be finite and > 0 Hz; got {freq}")
    if not (0.0 <= zeta < 1.0):
        raise ValueError(f"shaper_impulses: parameter `zeta` must lie in [0, 1); got {zeta}")
    if not (0.0 < tolerance < 1.0):
        raise ValueError(f"shaper_impulses: parameter `tolerance` must lie in (0, 1); got {tolerance}")
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
    elif name == "EI":
        A, t = [0.25 * (1 + V), 0.5 * (1 - V) * K, 0.25 * (1 + V) * K * K], [0.0, 0.5 * td, td]
    else:
        V2 = V * V
        X = (V2 * (math.sqrt(1.0 - V2) + 1.0)) ** (1.0 / 3.0)
        a1 = (3 * X * X + 2 * X + 3 * V2) / (16 * X)
        a2 = 0.5 - a1
        A, t = [a1, a2 * K, a2 * K * K, a1 * K**3], [0.0, 0.5 * td, td, 1.5 * td]
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


def shaper_for_axis(name: str, frequencies, damping_ratios, tolerance: float = 0.05):
    """The shaper `name` for every mode of an axis, convolved: `(amplitudes, times)`."""
    return convolve(
        [
            shaper_impulses(name, float(f), float(z), tolerance)
            for f, z in zip(np.asarray(frequencies), np.asarray(damping_ratios))
        ]
    )


def shaper_response(amplitudes, times, freq, zeta):
    """The shaper's own residual ratio $V(\\omega)$ (Singer and Seering, 1990): the ringing after the impulse
    sequence relative to one unit impulse, at frequencies `freq` [Hz] (any shape) for damping ratio `zeta`."""
    w = 2 * np.pi * np.asarray(freq, dtype=float)[..., None]
    wd = w * np.sqrt(1.0 - zeta * zeta)
    tl = np.asarray(times)[-1]
    terms = np.asarray(amplitudes) * np.exp(-zeta * w * (tl - np.asarray(times))) * np.exp(1j * wd * np.asarray(times))
    return np.abs(np.sum(terms, axis=-1))
