"""RepRapFirmware's custom input shaper: the `M593 P"custom"` line and how the firmware reads it.

Facts from RepRapFirmware 3.6 (`src/Movement/AxisShaper.cpp`, `AxisShaper::Configure`, and `AxisShaper.h`),
re-implemented here:

- at most `MaxImpulses` = 5 impulses; the first is at delay 0;
- `H`: the amplitudes of every impulse but the last (at most 4, colon-separated); the firmware sets the last impulse's amplitude to $1 - \\sum H$ (so the
  amplitudes add to 1; it does not check that this is >= 0: jaxbelt writes only shapers where it is);
- `T`: the delays [s] of impulses 2 … n+1 from the first, as many as `H` (else the firmware refuses the line),
  each converted to whole step clocks, `lrintf(T * StepClockRate)`; without `T` the delays are $k\\,T_d/2$ from
  `F` and `S`;
- `StepClockRate`: 750 kHz on Duet 3 boards (48 MHz / 64), `STEP_CLOCK_RATE` here.

So a shaper $(A_k, t_k)_{k=0..n}$ is written `M593 P"custom" H{A_0}:…:{A_{n-1}} T{t_1}:…:{t_n}`. RepRapFirmware
3.5 and earlier read a different form (`H` the cumulative amplitudes of the acceleration segments, `T` the
segments' durations, at most 4 each); jaxbelt writes the 3.6 form.
"""

from __future__ import annotations

import math
import re

import numpy as np

from .._checks import check_real

#: The most impulses RepRapFirmware's custom shaper holds (`MaxImpulses` in `AxisShaper.h`).
RRF_MAX_IMPULSES = 5
#: RepRapFirmware's step clock on Duet 3 boards [Hz]: delays are whole clocks of this rate.
STEP_CLOCK_RATE = 750_000.0
#: The longest delay jaxbelt writes [s]: RepRapFirmware parses floats (single precision) and converts them to
#: 32-bit step clocks; 10 s is far beyond any shaper (a 1 Hz mode's 3-hump EI lasts 2 s).
RRF_MAX_DELAY = 10.0
#: the step clock rates `parse_m593` accepts [Hz]: a microcontroller's timer, from 1 kHz to 1 GHz
STEP_CLOCK_RANGE_HZ = (1e3, 1e9)
_INT32_MAX = 2**31 - 1


def _floats(owner: str, name: str, value) -> np.ndarray:
    """`value` as a float array, or a `TypeError` naming `name` (a string, bytes, None, a bool ...)."""
    check_real(name, value, "", owner)
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{owner}: parameter `{name}` must be an array of numbers; got {value!r}") from None


def _fmt(x: float) -> str:
    return f"{x:.9g}"


def m593_line(amplitudes, times) -> str:
    """The `M593 P"custom" H… T…` line of the shaper with `amplitudes` (>= 0, adding to 1) and `times` [s]
    (ascending, the first 0): at most `RRF_MAX_IMPULSES` impulses. Delays are written as whole step clocks (in
    seconds, 9 significant digits), so the firmware's `lrintf` gives them back exactly."""
    o = "m593_line"
    A, T = (_floats(o, n, v) for n, v in (("amplitudes", amplitudes), ("times", times)))
    for name, v in (("amplitudes", A), ("times", T)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{o}: parameter `{name}` must be finite; got {v.tolist()}")
    if A.ndim != 1 or A.shape != T.shape or not 2 <= A.size <= RRF_MAX_IMPULSES:
        raise ValueError(
            f"m593_line: parameter `amplitudes` must hold 2 to {RRF_MAX_IMPULSES} impulses (RepRapFirmware's "
            f"MaxImpulses), as many as `times`; got {A.size} and {T.size}"
        )
    if np.any(A < 0) or abs(A.sum() - 1.0) > 1e-6:
        raise ValueError("m593_line: parameter `amplitudes` must be >= 0 and add to 1")
    if T[0] != 0.0 or np.any(np.diff(T) < 0) or T[-1] > RRF_MAX_DELAY:
        raise ValueError(f"m593_line: parameter `times` must start at 0, ascend, and end by {RRF_MAX_DELAY} s")
    clocks = np.rint(T[1:] * STEP_CLOCK_RATE)
    if clocks[-1] < 1:
        raise ValueError(
            f"{o}: parameter `times` must end at least half a step clock after 0 ({0.5 / STEP_CLOCK_RATE:.3g} s at "
            f"{STEP_CLOCK_RATE:g} Hz): the firmware would run every impulse at once (no shaping); got {T.tolist()}"
        )
    H = ":".join(_fmt(a) for a in A[:-1])
    D = ":".join(_fmt(c / STEP_CLOCK_RATE) for c in clocks)
    return f'M593 P"custom" H{H} T{D}'


def parse_m593(line: str, step_clock_rate: float = STEP_CLOCK_RATE):
    """Read an `M593 P"custom"` line as RepRapFirmware 3.6 does: `(amplitudes, times)` of the impulses it runs
    (numpy; the amplitudes single precision as the firmware holds them, the last $1 - \\sum H$; the delays whole
    step clocks of `step_clock_rate`, in seconds). Raises `ValueError` where the firmware refuses the line (no
    `H`, more than 4 values, `T` not as many as `H`) or would run a shaper that is not one (a negative last
    amplitude, delays that do not ascend). A line without `T` is refused here (its delays would come from `F`
    and `S`, which jaxbelt does not write)."""
    o = "parse_m593"
    if not isinstance(line, str):
        raise TypeError(f"{o}: parameter `line` must be a str (one M593 line); got {type(line).__name__}")
    check_real("step_clock_rate", step_clock_rate, "Hz", o)
    rate = float(np.asarray(step_clock_rate, dtype=float)) if np.ndim(step_clock_rate) == 0 else math.nan
    lo, hi = STEP_CLOCK_RANGE_HZ
    if not (math.isfinite(rate) and lo <= rate <= hi):
        raise ValueError(
            f"{o}: parameter `step_clock_rate` must be one number within [{lo:g}, {hi:g}] Hz (a firmware's step "
            f"clock: RepRapFirmware's is {STEP_CLOCK_RATE:g} Hz on Duet 3); got {step_clock_rate!r}"
        )
    text = line.split(";")[0].strip()
    if not re.match(r"^M593\b", text, re.IGNORECASE):
        raise ValueError(f"parse_m593: not an M593 line: {line!r}")
    m = re.search(r'\bP"([^"]*)"', text)
    if m is None or m.group(1).lower() != "custom":
        raise ValueError('parse_m593: the line must select P"custom"')

    def values(letter):
        found = re.search(rf"\s{letter}([-+0-9.eE:]+)", text)
        if found is None:
            return None
        try:
            v = [float(x) for x in found.group(1).split(":")]
        except ValueError:
            raise ValueError(f"parse_m593: parameter {letter} is not a colon-separated list of numbers") from None
        if len(v) > RRF_MAX_IMPULSES - 1:
            raise ValueError(f"parse_m593: parameter {letter} holds {len(v)} values; RepRapFirmware takes at most 4")
        return v

    H = values("H")
    if H is None:
        raise ValueError("parse_m593: parameter H (the amplitudes) is missing")
    D = values("T")
    if D is None:
        raise ValueError("parse_m593: parameter T (the delays [s]) is missing")
    if len(D) != len(H):
        raise ValueError("parse_m593: Number of delays must be same as number of amplitudes (T and H)")
    if not np.all(np.isfinite(np.asarray(H, dtype=np.float32))):
        raise ValueError(
            f"parse_m593: parameter H holds an amplitude that is not a finite single-precision number; got {H}"
        )
    h32 = np.asarray(H, dtype=np.float32)
    last = np.float32(1.0) - np.sum(h32, dtype=np.float32)
    A = np.r_[h32, last].astype(float)
    # lrintf: to the nearest whole clock (ties to even), of the single-precision product
    with np.errstate(over="ignore"):
        clocks = np.rint(np.asarray(D, dtype=np.float32) * np.float32(rate)).astype(float)
    if not np.all(np.abs(clocks) <= _INT32_MAX):
        raise ValueError(
            f"parse_m593: parameter T holds a delay beyond the firmware's 32-bit step clock count ({_INT32_MAX} clocks "
            f"= {_INT32_MAX / rate:.4g} s at {rate:g} Hz); got {D}"
        )
    T = np.r_[0.0, clocks / rate]
    if np.any(A < 0):
        raise ValueError("parse_m593: the amplitudes must be >= 0 (the last, 1 - sum(H), included)")
    if np.any(np.diff(T) < 0):
        raise ValueError("parse_m593: the delays T must ascend")
    return A, T
