"""The physical ranges of the models' parameters: wide enough for any real belt drive or DC motor, narrow
enough that a degenerate magnitude (1e300, 1e-300) is refused at construction by name instead of ending in a
solver failure, an overflow or a plausible-looking finite number far downstream.

Each range is `(lo, hi)` in SI units; `ranged(...)` declares a parameter with it (`check="range"`). A parameter
that may be zero (a damping, a mass left out, a load) takes `zero=True`: `[0, hi]`; a signed one (a load
torque, a gain, an angle) takes `signed=True`: `[-hi, hi]`.

Why these bounds (the smallest and largest of any real drive, with margin):

- mass 1e-6 to 1e6 kg: a milligram slider to a 1000 t hoist load;
- inertia 1e-12 to 1e6 kg m²: a 1 mm, 1 mg rotor (1e-12) to a mine hoist drum (1e5);
- stiffness 1e-3 to 1e12 N/m: a slack elastic cord to a steel strap far stiffer than any belt branch;
- damping 0 to 1e9 N s/m (translational), torque 0 to 1e7 N m, viscous 0 to 1e7 N m s/rad;
- radius 1e-4 to 10 m: a 0.1 mm watch pinion to a 20 m sheave; span 1e-4 to 1e3 m (a conveyor's km span);
- resistance 1e-6 to 1e6 ohm; inductance 1e-12 to 10 H (below the nanohenry of a short lead, the limit of a
  stiff but still solvable electrical time constant, to a large field coil);
- motor constant 1e-6 to 1e3 N m/A (V s/rad): a micromotor to a megawatt torque motor;
- gear ratio 1e-4 to 1e4: multi-stage reducers and step-ups of four decades either way;
- tension 1e-3 to 1e7 N (a 10 MN steel-cord conveyor belt); mass per length 1e-6 to 1e4 kg/m;
- transverse wave speed 1e-3 to 1e5 m/s: above the speed of sound in any solid (about 1.8e4 m/s);
- motor speed set point within ±1e5 rad/s (about a million rpm); voltages 1e-6 to 1e6 V;
- controller gains within ±1e9 in their units; angles within ±1e6 rad (float64 keeps 1e-10 rad of them);
- gravity 0 to 1e3 m/s² (a centrifuge test stand); run-out 0 to 10 m (a pulley's radius at most).

Beyond these the products of the equations overflow, underflow or round the others away (a stiffness of 1e300
N/m makes the belt's period 1e-150 s; a tension of 1e300 N a 1e151 Hz mode), and no physical drive is there.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .._params import param

MASS_KG = (1e-6, 1e6)
INERTIA_KG_M2 = (1e-12, 1e6)
STIFFNESS_N_PER_M = (1e-3, 1e12)
DAMPING_N_S_PER_M = (0.0, 1e9)
TORQUE_N_M = (0.0, 1e7)
VISCOUS_N_M_S = (0.0, 1e7)
RADIUS_M = (1e-4, 10.0)
SPAN_M = (1e-4, 1e3)
DISTANCE_M = (0.0, 1e3)
RESISTANCE_OHM = (1e-6, 1e6)
INDUCTANCE_H = (1e-12, 10.0)
MOTOR_CONSTANT = (1e-6, 1e3)
GEAR_RATIO = (1e-4, 1e4)
TENSION_N = (1e-3, 1e7)
LINEAR_DENSITY_KG_PER_M = (1e-6, 1e4)
WAVE_SPEED_M_S = (1e-3, 1e5)
MOTOR_SPEED_RAD_S = (0.0, 1e5)
VOLTAGE_V = (1e-6, 1e6)
GAIN = (0.0, 1e9)
ANGLE_RAD = (0.0, 1e6)
GRAVITY_M_S2 = (0.0, 1e3)
RUNOUT_M = (0.0, 10.0)
SPEED_RATIO = (0.0, 1e4)


def ranged(
    default: Any = dataclasses.MISSING,
    rng: tuple[float, float] = (0.0, 0.0),
    *,
    zero: bool = False,
    signed: bool = False,
    **kw,
) -> Any:
    """A `param` field valid in `rng` = `(lo, hi)`; `zero=True`: in `[0, hi]`; `signed=True`: in `[-hi, hi]`."""
    lo, hi = rng
    if signed:
        lo = -hi
    elif zero:
        lo = 0.0
    return param(default, check="range", lo=lo, hi=hi, **kw)
