"""A shaper for the firmware: the impulse sequence of a given length with the least worst residual over the band.

Most motion firmware applies one *input shaper* to every move of an axis: a short sequence of impulses
$(A_k, t_k)$, $A_k \\ge 0$, $\\sum_k A_k = 1$, convolved with the commanded motion (Singer and Seering, 1990). The
classic shapers (ZV, ZVD, EI, ...) fix the impulses' number and times in closed form for one mode. Here the times
are a uniform grid over the shaper's length $\\tau$ and the amplitudes are chosen by a linear programme: minimise
the worst residual ratio over every mode of the axis and every frequency of its band,

$\\min_{A,\\,t}\\ t$ subject to $\\mathrm{Re}\\big(e^{-i\\theta_p}\\sum_k A_k e^{s_g(\\tau - t_k)}\\big) \\le t$,
$A_k \\ge 0$, $\\sum_k A_k = 1$,

for the modes' $s_g = -\\zeta\\omega + i\\omega_d$ on a grid of the band $f_i(1 \\pm u)$ and P cut angles
$\\theta_p$ (the modulus as an inscribed polygon: the true residual exceeds t by at most $1/\\cos(\\pi/P) - 1$,
0.5 % for P = 32). $|\\sum_k A_k e^{s(\\tau - t_k)}|$ is the shaper's residual ratio $V$ (the ringing after the
sequence relative to one unit impulse; `shaper_response`). A classic shaper whose impulse times lie on the grid
(ZVD or EI, length $T_d$, on a grid of $T_d/16$) is a feasible point, so the optimum leaves at most what it leaves
on the band's grid (to the polygon's 0.5 %), for one mode or several at once.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._checks import check_real, is_concrete
from .._io import atomic_open, check_output_path
from .._threads import blas_limited
from ..models.axis import ModalAxis
from .shapers import shaper_response


@dataclasses.dataclass(frozen=True)
class FirmwareShaper:
    """`design_shaper`'s result: `amplitudes` (sum 1, each >= 0) and `times` [s] (from 0; the last is the shaper's
    length) of the impulses; `worst`: the worst residual ratio V over every mode's band, measured on a grid 4x
    finer than the design's; `lp_value`, `lower_bound`: the LP's optimum and its certified lower bound (on the
    design's frequency grid); `axis`, `uncertainty`."""

    amplitudes: np.ndarray
    times: np.ndarray
    worst: float
    lp_value: float
    lower_bound: float
    axis: ModalAxis
    uncertainty: float

    @property
    def duration(self) -> float:
        """The shaper's length [s]: the delay it adds to every move."""
        return float(self.times[-1])

    def response(self, freq, mode: int = 0):
        """Residual ratio V at frequencies `freq` [Hz] for the damping ratio of mode `mode`."""
        zeta = float(np.asarray(self.axis.damping_ratios)[mode])
        return shaper_response(self.amplitudes, self.times, freq, zeta)

    def as_lists(self) -> tuple[list[float], list[float]]:
        """`(A, T)`: the amplitudes and times [s] as plain lists, the form firmware shaper definitions use
        (Klipper's shaper definitions return such a pair); impulses of zero amplitude are left out."""
        keep = self.amplitudes > 0
        return [float(a) for a in self.amplitudes[keep]], [float(t) for t in self.times[keep]]

    def to_csv(self, path) -> None:
        """Write the impulses as CSV columns `t,amplitude` (s, -) with that header line (atomically)."""
        path = check_output_path(path, "path", "FirmwareShaper.to_csv", formats=(".csv", ".txt"))
        A, T = self.as_lists()
        with atomic_open(path, "w", newline="") as f:
            f.write("t,amplitude\n")
            for t, a in zip(T, A):
                f.write(f"{t:.17g},{a:.17g}\n")

    def __str__(self) -> str:
        A, T = self.as_lists()
        rows = "\n".join(f"  {t:10.6f} s  {a:.6f}" for t, a in zip(T, A))
        return (
            f"FirmwareShaper: {len(A)} impulses over {1e3 * self.duration:.3f} ms, worst residual "
            f"{100 * self.worst:.3g} % over +-{100 * self.uncertainty:.3g} % of every mode\n{rows}"
        )


def _check(axis, duration, uncertainty, n_impulses, n_freq):
    o = "design_shaper"
    if not isinstance(axis, ModalAxis):
        raise ValueError(f"{o}: parameter `axis` must be a ModalAxis (jb.ModalAxis([f...], [zeta...])); got {axis!r}")
    if not is_concrete(axis.frequencies):
        raise ValueError(f"{o}: parameter `axis` must hold concrete values (the design is solved on the host)")
    check_real("duration", duration, "s", o)  # a string, a bool or None is refused, not converted
    try:
        tau = float(duration)
    except (TypeError, ValueError):
        raise ValueError(f"{o}: parameter `duration` must be a number of seconds > 0; got {duration!r}") from None
    if not (math.isfinite(tau) and tau > 0):
        raise ValueError(f"{o}: parameter `duration` must be finite and > 0 s; got {duration!r}")
    check_real("uncertainty", uncertainty, "", o)
    try:
        u = float(uncertainty)
    except (TypeError, ValueError):
        raise ValueError(f"{o}: parameter `uncertainty` must be a number in [0, 0.9); got {uncertainty!r}") from None
    if not (math.isfinite(u) and 0.0 <= u < 0.9):
        raise ValueError(f"{o}: parameter `uncertainty` must lie in [0, 0.9); got {uncertainty!r}")
    for name, v, lo, hi in (("n_impulses", n_impulses, 2, 257), ("n_freq", n_freq, 1, 401)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi):
            raise ValueError(f"{o}: parameter `{name}` must be an integer in [{lo}, {hi}]; got {v!r}")
    return tau, u


@blas_limited
def design_shaper(axis: ModalAxis, duration, *, uncertainty=0.2, n_impulses: int | None = None, n_freq: int = 61):
    """The input shaper of length `duration` [s] with the least worst residual ratio over every mode of `axis`
    and the band $f_i(1 \\pm u)$ (`uncertainty` u in [0, 0.9)): one shaper for the whole axis, as firmware applies
    it (see the module docstring).

    - `n_impulses`: impulses on a uniform grid of [0, duration] (default: 17, or more, so that the grid step is
      at most a sixteenth of the shortest damped period; at most 257);
    - `n_freq`: frequencies per mode on the band (61; 1 without a band).

    Returns a `FirmwareShaper` (`.as_lists()` for the firmware, `.to_csv(path)`, `.response(freq)`).
    The shaper delays every move by `duration`; on a grid of $T_d/16$ a length of $T_d$ (a ZVD's or an EI's)
    leaves at most what those leave over the band (tested)."""
    tau, u = _check(axis, duration, uncertainty, n_impulses, n_freq)
    from .lp import solve_lp

    f = np.asarray(axis.frequencies, dtype=float)
    z = np.asarray(axis.damping_ratios, dtype=float)
    td_min = float(np.min(1.0 / (f * np.sqrt(1.0 - z**2))))
    if n_impulses is None:
        n_impulses = int(min(257, max(17, 1 + math.ceil(16.0 * tau / td_min))))
    times = np.linspace(0.0, tau, n_impulses)
    nf = 1 if u == 0.0 else n_freq
    factors = 1.0 + u * (np.linspace(-1.0, 1.0, nf) if nf > 1 else np.zeros(1))
    w = 2.0 * np.pi * f[:, None] * factors[None, :]
    wd = w * np.sqrt(1.0 - z[:, None] ** 2)
    s = (-z[:, None] * w + 1j * wd).reshape(-1)
    kern = np.exp(np.multiply.outer(s, tau - times))  # (G, K)
    P = 32
    theta = 2.0 * np.pi * np.arange(P) / P
    cuts = np.real(np.exp(-1j * theta)[:, None, None] * kern[None]).reshape(-1, n_impulses)
    K = n_impulses
    G = np.vstack(
        [
            np.hstack([cuts, -np.ones((cuts.shape[0], 1))]),
            np.hstack([-np.eye(K), np.zeros((K, 1))]),  # A_k >= 0
            np.hstack([np.eye(K), np.zeros((K, 1))]),  # A_k <= 1 (implied; bounds the variables)
            np.r_[np.zeros(K), -1.0][None],  # t >= 0
        ]
    )
    h = np.r_[np.zeros(cuts.shape[0]), np.zeros(K), np.ones(K), 0.0]
    A_eq = np.r_[np.ones(K), 0.0][None]
    c = np.r_[np.zeros(K), 1.0]
    res = solve_lp(c, G, h, A_eq, np.ones(1), x_bound=np.r_[np.ones(K), 1.0], tol=1e-10, max_iter=100)
    x = np.asarray(res.x)
    amps = np.clip(x[:K], 0.0, None)
    amps = amps / amps.sum()
    amps[amps < 1e-12] = 0.0
    amps = amps / amps.sum()
    fine = 1.0 + u * np.linspace(-1.0, 1.0, 4 * nf - 3 if nf > 1 else 1)
    worst = max(float(np.max(shaper_response(amps, times, fi * fine, zi))) for fi, zi in zip(f, z))
    return FirmwareShaper(
        amplitudes=amps,
        times=times,
        worst=worst,
        lp_value=float(res.value),
        lower_bound=float(res.lower_bound),
        axis=axis,
        uncertainty=u,
    )
