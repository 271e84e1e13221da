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

import re

import numpy as np

#: The most impulses RepRapFirmware's custom shaper holds (`MaxImpulses` in `AxisShaper.h`).
RRF_MAX_IMPULSES = 5
#: RepRapFirmware's step clock on Duet 3 boards [Hz]: delays are whole clocks of this rate.
STEP_CLOCK_RATE = 750_000.0
#: The longest delay jaxbelt writes [s]: RepRapFirmware parses floats (single precision) and converts them to
#: 32-bit step clocks; 10 s is far beyond any shaper (a 1 Hz mode's 3-hump EI lasts 2 s).
RRF_MAX_DELAY = 10.0


def _fmt(x: float) -> str:
    return f"{x:.9g}"


def m593_line(amplitudes, times) -> str:
    """The `M593 P"custom" H… T…` line of the shaper with `amplitudes` (>= 0, adding to 1) and `times` [s]
    (ascending, the first 0): at most `RRF_MAX_IMPULSES` impulses. Delays are written as whole step clocks (in
    seconds, 9 significant digits), so the firmware's `lrintf` gives them back exactly."""
    A = np.asarray(amplitudes, dtype=float)
    T = np.asarray(times, dtype=float)
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
    h32 = np.asarray(H, dtype=np.float32)
    last = np.float32(1.0) - np.sum(h32, dtype=np.float32)
    A = np.r_[h32, last].astype(float)
    # lrintf: to the nearest whole clock (ties to even), of the single-precision product
    clocks = np.rint(np.asarray(D, dtype=np.float32) * np.float32(step_clock_rate)).astype(float)
    T = np.r_[0.0, clocks / step_clock_rate]
    if np.any(A < 0):
        raise ValueError("parse_m593: the amplitudes must be >= 0 (the last, 1 - sum(H), included)")
    if np.any(np.diff(T) < 0):
        raise ValueError("parse_m593: the delays T must ascend")
    return A, T
