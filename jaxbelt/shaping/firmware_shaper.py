"""A shaper for the firmware: the impulse sequence of a given length with the least worst residual over the band,
in the form a firmware loads.

Most motion firmware applies one *input shaper* to every move of an axis: a short sequence of impulses
$(A_k, t_k)$, $A_k \\ge 0$, $\\sum_k A_k = 1$, convolved with the commanded motion (Singer and Seering, 1990). Its
residual ratio at a pole $s = -\\zeta\\omega + i\\omega_d$ of a mode is $V = |\\sum_k A_k e^{s(t_K - t_k)}|$ (the
ringing after the sequence relative to one unit impulse; `shaper_response`), and the design minimises its worst
value over every mode of the axis and every frequency of its band $f_i(1 \\pm u)$. Three designs
(`design_shaper(..., firmware=)`):

- **`None`** (any number of impulses): the times a uniform grid over the length $\\tau$, the amplitudes the
  linear programme (solved by jaxbelt's interior point method, `jaxbelt.shaping.lp`)

  $\\min_{A}\\ t$ subject to $\\mathrm{Re}(e^{-i\\theta_p}\\sum_k A_k e^{s_g(\\tau - t_k)}) \\le t$, $A_k \\ge 0$,
  $\\sum_k A_k = 1$,

  for the band's poles $s_g$ and P = 32 cut angles $\\theta_p$ (the modulus as an inscribed polygon: the true
  residual exceeds t by at most $1/\\cos(\\pi/P) - 1$, 0.5 %). A classic shaper whose times lie on the grid (ZVD
  or EI, length $T_d$, on a grid of $T_d/16$) is a feasible point. With `max_impulses=K` the times are free
  instead, as for RepRapFirmware.
- **`"rrf"`** (RepRapFirmware's custom shaper: at most 5 impulses): amplitudes and times optimised together by
  gradient from several starts (`jaxbelt.shaping.free_times`), among them Klipper's six shapers stretched to
  the length $\\tau$ at each mode's damping, each mode's shapers at their own length where they fit, two modes'
  ZV shapers convolved, and K impulses on a uniform grid with the LP's amplitudes; the amplitudes at the best
  times are polished by the LP. Every start is itself a candidate, so the result leaves at most what each
  start leaves on the check grid (up to RepRapFirmware's rounding of the delays to its step clock: 1.7e-5
  relative for a ZV at 40 Hz). Exported as RepRapFirmware's `M593 P"custom"` line (`jaxbelt.shaping.rrf`).
- **`"klipper"`**: one of Klipper's six shaper types (`jaxbelt.shaping.klipper`), its frequency and damping
  ratio chosen by gradient for the band (`jaxbelt.shaping.klipper_tune`), at most $\\tau$ long; exported as the
  `[input_shaper]` section or the `SET_INPUT_SHAPER` command.

**What is stated is what is exported.** A firmware design's `amplitudes` and `times` are those the firmware
runs: the text (`to_firmware()`) is read back by a reader written from the firmware's source (RepRapFirmware's
single-precision amplitudes and whole step clocks; Klipper's impulses from the frequency and damping ratio the
text states in full), and `worst` is measured on those impulses, on a frequency grid 4x finer than the
design's. A grid design drops no impulse either: impulses of zero amplitude are removed before `worst` is
measured, on what is exported (the residual is measured from the last impulse, so removing trailing zeros
would otherwise change it).

**The lower bound** of a free-time or Klipper design (`lp_value`, `lower_bound`): the LP on a uniform grid of
257 times over $[0, \\tau]$ with any number of impulses, on the design's frequency grid (the same solver).
`lp_value` is its optimum: no shaper whose times lie on that grid leaves less. `lower_bound` holds for every
shaper of length at most $\\tau$, any number of impulses, any times (weak duality: the LP's multipliers $z$
of the cut rows, normalised, give a weighting under which each impulse at time t contributes
$\\varphi(t) = \\mathrm{Re}\\sum_g w_g e^{s_g(\\tau-t)}$, and a shaper's worst is at least $\\min_t\\varphi$, taken
on 20001 times less the slope bound); a shorter shaper measured from its own last impulse leaves at least what
it leaves measured from $\\tau$. It bounds the worst on the design's frequency grid, hence on the band. For a
grid design (`firmware=None` without `max_impulses`) both are the LP's at the design's own times.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._checks import check_real, is_concrete
from .._io import atomic_open, check_output_path
from .._threads import blas_limited
from ..models.axis import FREQUENCY_RANGE_HZ, ModalAxis
from .klipper import KLIPPER_MAX_PULSES, KLIPPER_SHAPERS, KlipperConfig, impulses, klipper_impulses
from .rrf import RRF_MAX_IMPULSES, STEP_CLOCK_RATE, m593_line, parse_m593
from .shapers import shaper_response

#: The firmware `design_shaper` writes for.
FIRMWARES = ("rrf", "klipper")
#: The longest shaper `design_shaper` designs, in damped periods of the axis' lowest mode: a shaper lasting many
#: periods delays every move by as much and gains nothing a shorter one cannot reach.
MAX_DURATION_PERIODS = 16.0
#: The shortest, as a fraction of the shortest damped period: a shaper that short leaves its residual within
#: 0.3 % of the unshaped move's.
MIN_DURATION_PERIODS = 1e-3
#: The least `target` (residual ratio) `design_shaper` accepts. Below it the residual a shaper leaves is the rounding
#: of its numbers, not its design: RepRapFirmware holds the amplitudes in single precision (a relative 6e-8 each, so
#: ~1e-7 of the move over 5 impulses) and its delays in whole step clocks, and the LP meets its constraints to 1e-9
#: per row; a target of 1e-300 searched for 84 s before it said "not reached".
TARGET_FLOOR = 1e-6
#: The most impulses of a free-time design (`max_impulses`).
MAX_FREE_IMPULSES = 16


@dataclasses.dataclass(frozen=True)
class FirmwareShaper:
    """`design_shaper`'s result: `amplitudes` (sum 1, each > 0) and `times` [s] (from 0; the last is the shaper's
    length) of the impulses, exactly as they are exported (for a firmware: as the firmware reads its text back);
    `worst`: the worst residual ratio V of these impulses over every mode's band, measured on a grid 4x finer
    than the design's; `lp_value`, `lower_bound`: the LP's optimum and its certified lower bound (the module
    docstring says what each bounds); `axis`, `uncertainty`; `firmware` (None, "rrf" or "klipper");
    `config`: Klipper's `KlipperConfig` (type, frequency, damping ratio) for "klipper"."""

    amplitudes: np.ndarray
    times: np.ndarray
    worst: float
    lp_value: float
    lower_bound: float
    axis: ModalAxis
    uncertainty: float
    firmware: str | None = None
    config: KlipperConfig | None = None

    @property
    def duration(self) -> float:
        """The shaper's length [s]: the delay it adds to every move."""
        return float(self.times[-1])

    def response(self, freq, mode: int = 0):
        """Residual ratio V at frequencies `freq` [Hz] (finite, >= 0, at most `FREQUENCY_RANGE_HZ`'s top) for the
        damping ratio of mode `mode` (0 … n_modes - 1)."""
        o = "FirmwareShaper.response"
        check_real("freq", freq, "Hz", o)
        try:
            f = np.asarray(freq, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(
                f"{o}: parameter `freq` must be a number or an array of numbers [Hz]; got {freq!r}"
            ) from None
        hi = FREQUENCY_RANGE_HZ[1]
        bad = ~(np.isfinite(f) & (f >= 0) & (f <= hi))
        if np.any(bad):
            raise ValueError(
                f"{o}: parameter `freq` must be finite and within [0, {hi:g}] Hz; got {f[bad].ravel()[0]!r}"
            )
        z = np.asarray(self.axis.damping_ratios)
        n = z.size
        if isinstance(mode, bool) or not isinstance(mode, int | np.integer) or not 0 <= mode < n:
            raise ValueError(
                f"FirmwareShaper.response: parameter `mode` must be an integer in [0, {n - 1}] (the axis has {n} "
                f"mode{'s' if n > 1 else ''}); got {mode!r}"
            )
        return shaper_response(self.amplitudes, self.times, f, float(z[mode]))

    def as_lists(self) -> tuple[list[float], list[float]]:
        """`(A, T)`: the amplitudes and times [s] as plain lists, every exported impulse (the form firmware shaper
        definitions use: Klipper's shaper definitions return such a pair)."""
        return [float(a) for a in self.amplitudes], [float(t) for t in self.times]

    def to_firmware(self, form: str = "config", axis: str = "x") -> str:
        """The text the firmware parses. "rrf": the `M593 P"custom" H… T…` line (RepRapFirmware 3.6; `form`
        ignored). "klipper": `form="config"` the `[input_shaper]` section for `axis`, `form="command"` the
        `SET_INPUT_SHAPER` command. A design without a firmware has no text: `as_lists()` or `to_csv()`."""
        if self.firmware == "rrf":
            return m593_line(self.amplitudes, self.times)
        if self.firmware == "klipper":
            assert self.config is not None
            if form not in ("config", "command"):
                raise ValueError(f"to_firmware: parameter `form` must be 'config' or 'command'; got {form!r}")
            if axis not in ("x", "y"):
                raise ValueError(f"to_firmware: parameter `axis` must be 'x' or 'y'; got {axis!r}")
            return self.config.section(axis) if form == "config" else self.config.command(axis)
        raise ValueError(
            "to_firmware: this shaper was designed without a firmware (firmware=None); design it with "
            "firmware='rrf' or 'klipper', or export its impulses with as_lists() / to_csv()"
        )

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
        head = f"FirmwareShaper ({self.firmware})" if self.firmware else "FirmwareShaper"
        extra = (
            f" ({self.config.kind} at {self.config.freq:.3f} Hz, damping {self.config.damping:.4f})"
            if self.config
            else ""
        )
        return (
            f"{head}{extra}: {len(A)} impulses over {1e3 * self.duration:.3f} ms, worst residual "
            f"{100 * self.worst:.3g} % over +-{100 * self.uncertainty:.3g} % of every mode (lower bound "
            f"{100 * self.lower_bound:.3g} %)\n{rows}"
        )


def _periods(axis):
    f = np.asarray(axis.frequencies, dtype=float)
    z = np.asarray(axis.damping_ratios, dtype=float)
    td = 1.0 / (f * np.sqrt(1.0 - z**2))
    return float(td.min()), float(td.max())


def _check(axis, duration, uncertainty, n_impulses, n_freq, firmware, max_impulses, target):
    o = "design_shaper"
    if not isinstance(axis, ModalAxis):
        raise ValueError(f"{o}: parameter `axis` must be a ModalAxis (jb.ModalAxis([f...], [zeta...])); got {axis!r}")
    if not is_concrete(axis.frequencies):
        raise ValueError(f"{o}: parameter `axis` must hold concrete values (the design is solved on the host)")
    if firmware is not None and firmware not in FIRMWARES:
        raise ValueError(f"{o}: parameter `firmware` must be None, 'rrf' or 'klipper'; got {firmware!r}")
    td_min, td_max = _periods(axis)
    lo, hi = MIN_DURATION_PERIODS * td_min, MAX_DURATION_PERIODS * td_max
    tau = None
    if duration is not None:
        check_real("duration", duration, "s", o)  # a string, a bool is refused, not converted
        try:
            tau = float(duration)
        except (TypeError, ValueError):
            raise ValueError(f"{o}: parameter `duration` must be a number of seconds > 0; got {duration!r}") from None
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"{o}: parameter `duration` must be finite and > 0 s; got {duration!r}")
        if not lo <= tau <= hi:
            raise ValueError(
                f"{o}: parameter `duration` must lie in [{lo:.4g}, {hi:.4g}] s for this axis ({MIN_DURATION_PERIODS:g} "
                f"of its shortest damped period to {MAX_DURATION_PERIODS:g} of its longest); got {duration!r}"
            )
        if firmware == "rrf" and tau < (RRF_MAX_IMPULSES - 1) / STEP_CLOCK_RATE:
            raise ValueError(f"{o}: parameter `duration` is shorter than RepRapFirmware's step clocks can time")
    check_real("uncertainty", uncertainty, "", o)
    try:
        u = float(uncertainty)
    except (TypeError, ValueError):
        raise ValueError(f"{o}: parameter `uncertainty` must be a number in [0, 0.9); got {uncertainty!r}") from None
    if not (math.isfinite(u) and 0.0 <= u < 0.9):
        raise ValueError(f"{o}: parameter `uncertainty` must lie in [0, 0.9); got {uncertainty!r}")
    for name, v, a, b in (("n_impulses", n_impulses, 2, 257), ("n_freq", n_freq, 1, 401)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | np.integer) or not a <= v <= b):
            raise ValueError(f"{o}: parameter `{name}` must be an integer in [{a}, {b}]; got {v!r}")
    if n_impulses is not None and firmware is not None:
        raise ValueError(f"{o}: parameter `n_impulses` (a uniform grid) is for firmware=None; use `max_impulses`")
    cap = {"rrf": RRF_MAX_IMPULSES, "klipper": KLIPPER_MAX_PULSES, None: MAX_FREE_IMPULSES}[firmware]
    least = 2 if firmware != "klipper" else 2
    if max_impulses is not None:
        if isinstance(max_impulses, bool) or not isinstance(max_impulses, int | np.integer):
            raise ValueError(
                f"{o}: parameter `max_impulses` must be an integer in [{least}, {cap}]; got {max_impulses!r}"
            )
        if not least <= max_impulses <= cap:
            who = {"rrf": "RepRapFirmware's custom shaper", "klipper": "Klipper's kernel", None: "a free-time design"}
            raise ValueError(
                f"{o}: parameter `max_impulses` must lie in [{least}, {cap}] ({who[firmware]} takes at most {cap}); "
                f"got {max_impulses!r}"
            )
        if n_impulses is not None:
            raise ValueError(f"{o}: give `n_impulses` (a uniform grid) or `max_impulses` (free times), not both")
    if target is not None:
        check_real("target", target, "", o)
        if not (isinstance(target, int | float | np.floating) and TARGET_FLOOR <= float(target) < 1.0):
            raise ValueError(
                f"{o}: parameter `target` must be a residual ratio in [{TARGET_FLOOR:g}, 1) (`TARGET_FLOOR`: below, a "
                f"shaper's residual is the rounding of its exported numbers); got {target!r}"
            )
        if duration is not None:
            raise ValueError(f"{o}: give `duration` or `target` (the shortest shaper that reaches it), not both")
    return tau, u, (lo, hi)


class _Band:
    """The band's poles: the design grid (`s`, per mode `nf` factors) and the 4x finer check grid."""

    def __init__(self, axis, u, nf):
        self.f = np.asarray(axis.frequencies, dtype=float)
        self.z = np.asarray(axis.damping_ratios, dtype=float)
        nf = 1 if u == 0.0 else nf
        self.s = self._poles(1.0 + u * (np.linspace(-1.0, 1.0, nf) if nf > 1 else np.zeros(1)))
        self.fine = 1.0 + u * np.linspace(-1.0, 1.0, 4 * nf - 3 if nf > 1 else 1)

    def _poles(self, factors):
        w = 2.0 * np.pi * self.f[:, None] * factors[None, :]
        wd = w * np.sqrt(1.0 - self.z[:, None] ** 2)
        return (-self.z[:, None] * w + 1j * wd).reshape(-1)

    def worst(self, A, T) -> float:
        return max(float(np.max(shaper_response(A, T, fi * self.fine, zi))) for fi, zi in zip(self.f, self.z))


#: the LP's impulse counts, padded up to one of these (compile once per size, not per call)
_LP_SIZES = (8, 17, 33, 65, 129, 257)


def _lp_or_none(times, s, tau):
    """The LP of the module docstring at fixed `times` (K,) over [0, tau], solved by jaxbelt's interior point
    method (`jaxbelt.shaping.lp.solve_lp`): `(amplitudes, value, lower_bound, w)`. The times are padded with
    copies of the last one up to a size of `_LP_SIZES` (a copy is the same column: the LP's value is unchanged,
    and the copies' amplitudes are added back), so that one program serves every call of that size. The bound
    is weak duality with the solver's multipliers $z$ of the cut rows (normalised to add to 1): every row is at
    most t, so $t \\ge z^TCA \\ge \\min_k (z^TC)_k$ for amplitudes A that add to 1; it holds whatever the
    solver's tolerances. `w`: the multipliers as weights of the poles (for `_bound`). Where the solver stops short
    of its tolerance (times that nearly coincide make the LP degenerate) the value is NaN: the amplitudes are still
    a shaper, whose residual is measured on what is exported, and the bound still holds."""
    from .lp import simplex_minimax

    times = np.asarray(times, dtype=float)
    kern = np.exp(np.multiply.outer(s, tau - times))  # (G, K)
    P = 32
    theta = 2.0 * np.pi * np.arange(P) / P
    cuts = np.real(np.exp(-1j * theta)[:, None, None] * kern[None]).reshape(-1, len(times))
    amps, value, z, converged = simplex_minimax(cuts, _LP_SIZES)
    if not converged:  # the amplitudes are still a shaper (measured as exported) and z still bounds: no LP value
        value = math.nan
    # the multipliers as weights of the poles: z^T C's column at time t is Re(sum_g w_g e^{s_g (tau - t)})
    w = (z.reshape(P, -1) * np.exp(-1j * theta)[:, None]).sum(axis=0)
    amps[amps < 1e-12 * amps.max()] = 0.0
    return amps / amps.sum(), value, float(np.min(z @ cuts)), w


def _lp(times, s, tau):
    """`_lp_or_none` (it always answers; see there)."""
    return _lp_or_none(times, s, tau)


def _exported(A, T):
    """The impulses of nonzero amplitude, the first at time 0."""
    A, T = np.asarray(A, dtype=float), np.asarray(T, dtype=float)
    keep = A > 0
    A, T = A[keep], T[keep] - T[keep][0]
    T_u, idx = np.unique(T, return_inverse=True)  # impulses at one time are one impulse
    A_u = np.bincount(idx, weights=A)
    return A_u / A_u.sum(), T_u


def _grid_design(axis, band, tau, u, n_impulses):
    td_min, _ = _periods(axis)
    if n_impulses is None:
        n_impulses = int(min(257, max(17, 1 + math.ceil(16.0 * tau / td_min))))
    times = np.linspace(0.0, tau, n_impulses)
    amps, value, bound, _ = _lp(times, band.s, tau)
    A, T = _exported(amps, times)
    return FirmwareShaper(A, T, band.worst(A, T), value, bound, axis, u)


def _classic_starts(band, tau, K):
    """Klipper's six shapers (at most K impulses) stretched to `tau` at each mode's damping, and at each mode's
    frequency and damping where they last at most `tau`; two modes' ZV shapers convolved (K >= 4)."""
    from .klipper_tune import length_factor

    out = []
    for kind, (_, zmax) in KLIPPER_SHAPERS.items():
        for f, z in zip(band.f, band.z):
            zz = min(float(z), zmax)
            n = len(impulses(kind, 1.0, zz)[0])
            if n > K:
                continue
            fs = float(length_factor(kind, zz)) / tau
            out.append(klipper_impulses(kind, fs, zz))
            if fs <= f:
                out.append(klipper_impulses(kind, float(f), zz))
    if K >= 4:
        for i in range(len(band.f)):
            for j in range(i + 1, len(band.f)):
                a = klipper_impulses("zv", float(band.f[i]), float(band.z[i]))
                b = klipper_impulses("zv", float(band.f[j]), float(band.z[j]))
                A = np.outer(a[0], b[0]).ravel()
                T = np.add.outer(a[1], b[1]).ravel()
                o = np.argsort(T, kind="stable")
                if T[o][-1] <= tau:
                    out.append((A[o], T[o]))
    return out


def _bound(band, tau, n_grid=257, n_check=20001):
    """`(lp_value, lower_bound)` for shapers of length at most `tau` (module docstring): the LP on `n_grid`
    uniform times, and weak duality with its multipliers over every time of $[0, \\tau]$: any shaper's
    amplitudes are a probability over times, so its worst is at least $\\min_t \\varphi(t)$,
    $\\varphi(t) = \\mathrm{Re}\\sum_g w_g e^{s_g(\\tau - t)}$, bounded below by its minimum on `n_check` times
    less its largest slope $\\sum_g |w_g||s_g|$ times half their step."""
    _, value, _, w = _lp(np.linspace(0.0, tau, n_grid), band.s, tau)
    t = np.linspace(0.0, tau, n_check)
    phi = np.real(np.exp(np.multiply.outer(tau - t, band.s)) @ w)
    slope = float(np.sum(np.abs(w) * np.abs(band.s)))
    return value, max(0.0, float(phi.min()) - slope * tau / (n_check - 1) / 2)


def _rrf_export(A, T):
    """The impulses RepRapFirmware runs for the shaper `(A, T)`: its M593 line read back."""
    return parse_m593(m593_line(A, T))


def _free_design(axis, band, tau, u, K, firmware):
    from .free_times import optimise

    starts = _classic_starts(band, tau, K)
    grid_t = np.linspace(0.0, tau, K)
    A_grid, _, _, _ = _lp(grid_t, band.s, tau)
    starts.append((np.where(A_grid > 0, A_grid, 1e-9) / np.sum(np.where(A_grid > 0, A_grid, 1e-9)), grid_t))
    rng = np.random.default_rng(0)
    for _ in range(6):
        T = np.r_[0.0, np.sort(rng.uniform(0.0, tau, K - 1))]
        T[-1] = tau
        starts.append((rng.dirichlet(np.ones(K)), T))
    runs = optimise(starts, tau, band.s, K)
    cands = [(np.asarray(A), np.asarray(T)) for A, T in starts] + runs
    cands.sort(key=lambda c: band.worst(*_exported(*c)))
    for _, T in cands[:4]:  # the LP's amplitudes at the best runs' times
        cands.append((_lp(T, band.s, tau)[0], T))

    def exported(c):
        A, T = c
        if firmware == "rrf":  # whole step clocks first: impulses that fall on one clock are one impulse
            T = (
                np.minimum(np.rint(np.asarray(T) * STEP_CLOCK_RATE), math.floor(tau * STEP_CLOCK_RATE))
                / STEP_CLOCK_RATE
            )
        A, T = _exported(A, T)
        return _rrf_export(A, T) if firmware == "rrf" else (A, T)

    best = min((exported(c) for c in cands), key=lambda c: band.worst(*c))
    value, lb = _bound(band, tau)
    A, T = best
    return FirmwareShaper(A, T, band.worst(A, T), value, lb, axis, u, firmware=firmware)


def _klipper_design(axis, band, tau, u, K):
    """Every type on a coarse grid of frequency and damping; the two best types tuned by gradient from their
    three best grid points; the best configuration as its text rounds it."""
    from .klipper_tune import grid, tune

    modes = list(zip(band.f.tolist(), band.z.tolist()))
    kinds = [k for k in KLIPPER_SHAPERS if len(impulses(k, 1.0, 0.0)[0]) <= K]
    scored = {k: grid(k, tau, band.s, modes) for k in kinds}
    ranked = sorted(kinds, key=lambda k: scored[k][0][0])
    cands = [(k, f, z) for k in kinds for _, f, z in scored[k][:3]]
    for k in ranked[:2]:
        cands += [(k, f, z) for f, z in tune(k, tau, band.s, [(f, z) for _, f, z in scored[k][:3]])]
    best = None
    for kind, f, z in cands:
        cfg = _klipper_round(KlipperConfig(kind, f, z), tau)
        A, T = klipper_impulses(cfg.kind, cfg.freq, cfg.damping)
        w = band.worst(A, T)
        if best is None or w < best[0]:
            best = (w, cfg, A, T)
    assert best is not None
    w, cfg, A, T = best
    value, lb = _bound(band, tau)
    return FirmwareShaper(A, T, w, value, lb, axis, u, firmware="klipper", config=cfg)


def _klipper_round(cfg, tau):
    """The configuration with its damping ratio within the type's range and its duration at most tau (the
    frequency raised by round-off steps where the duration's float exceeds tau by round-off)."""
    c = KlipperConfig(cfg.kind, float(cfg.freq), min(float(cfg.damping), KLIPPER_SHAPERS[cfg.kind][1]))
    for _ in range(100):
        if klipper_impulses(c.kind, c.freq, c.damping)[1][-1] <= tau:
            break
        c = KlipperConfig(c.kind, c.freq * (1 + 1e-13), c.damping)
    return c


def _reference_duration(axis, band):
    """The duration of the best classic shaper: each of Klipper's six at each mode's frequency and damping
    (clipped to the type's range), the one of least worst residual over the band."""
    best = None
    for kind, (_, zmax) in KLIPPER_SHAPERS.items():
        for f, z in zip(band.f, band.z):
            A, T = klipper_impulses(kind, float(f), min(float(z), zmax))
            w = band.worst(A, T)
            if best is None or w < best[0]:
                best = (w, float(T[-1]))
    assert best is not None
    return best[1]


@blas_limited
def design_shaper(
    axis: ModalAxis,
    duration=None,
    *,
    uncertainty=0.2,
    firmware: str | None = None,
    max_impulses: int | None = None,
    target: float | None = None,
    n_impulses: int | None = None,
    n_freq: int = 61,
):
    """The input shaper of length at most `duration` [s] with the least worst residual ratio over every mode of
    `axis` and the band $f_i(1 \\pm u)$ (`uncertainty` u in [0, 0.9)): one shaper for the whole axis, in the form
    `firmware` loads (see the module docstring).

    - `firmware`: None (any number of impulses, on a uniform grid), "rrf" (RepRapFirmware's custom shaper: at
      most 5 impulses, free times), "klipper" (one of Klipper's six types, frequency and damping ratio tuned);
    - `duration` [s]: from 1e-3 of the axis' shortest damped period to 16 of its longest. None: the shortest
      shaper whose `worst` reaches `target` (a ratio in (0, 1), bisection on the duration to 1 %), or without
      a target the duration of the best classic shaper (Klipper's six at each mode's frequency and damping,
      the one of least worst residual over the band);
    - `max_impulses`: at most this many impulses (firmware=None: free times, as for "rrf", up to 16; "rrf": up
      to 5; "klipper": the types with at most this many, up to Klipper's 10);
    - `n_impulses` (firmware=None only): impulses on a uniform grid of [0, duration] (default: 17, or more, so
      that the grid step is at most a sixteenth of the shortest damped period; at most 257);
    - `n_freq`: frequencies per mode on the band (61; 1 without a band).

    Returns a `FirmwareShaper` (`.to_firmware()` the text, `.as_lists()`, `.to_csv(path)`, `.response(freq)`);
    its `worst` is that of the impulses exported (tested by reading the text back). On a grid of $T_d/16$ a
    length of $T_d$ (a ZVD's or an EI's) leaves at most what those leave over the band (tested)."""
    tau, u, (lo, hi) = _check(axis, duration, uncertainty, n_impulses, n_freq, firmware, max_impulses, target)
    band = _Band(axis, u, n_freq)

    def at(t):
        if firmware == "klipper":
            return _klipper_design(axis, band, t, u, KLIPPER_MAX_PULSES if max_impulses is None else max_impulses)
        if firmware == "rrf" or max_impulses is not None:
            K = RRF_MAX_IMPULSES if max_impulses is None else int(max_impulses)
            return _free_design(axis, band, t, u, K, firmware)
        return _grid_design(axis, band, t, u, n_impulses)

    if tau is not None:
        return at(tau)
    if target is None:
        return at(min(max(_reference_duration(axis, band), lo), hi))
    top = at(hi)
    if top.worst > target:
        raise ValueError(
            f"design_shaper: parameter `target` {target!r} is not reached within {hi:.4g} s ({MAX_DURATION_PERIODS:g} "
            f"damped periods of the axis' lowest mode), where the best shaper leaves {top.worst:.4g}"
        )
    a, b, best = max(lo, _periods(axis)[0] / 8), hi, top
    first = at(a)
    if first.worst <= target:
        return first
    while b / a > 1.01:
        m = math.sqrt(a * b)
        s = at(m)
        if s.worst <= target:
            b, best = m, s
        else:
            a = m
    return best
