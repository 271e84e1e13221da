"""Non-linear travelling belt driven by eccentric pulleys (Moon & Wickert, 1997).

- `model`: the N-mode Galerkin model (`NonlinearBelt`, `ModalSystem`, input kinds);
- `steady`: steady states and quasi-static speed sweeps by time integration (diffrax);
- `harmonic`: harmonic balance, pseudo-arclength continuation in speed, stability, folds;
- `ramp`: the belt speed ramped through resonance (time records);
- `kbm`: first-order KBM averaging (backbone, steady amplitudes);
- `calibration`: the measured values of the paper and the identification of the unknowns.
"""

import typing as _typing

if _typing.TYPE_CHECKING:  # the public names, imported on first use (`jaxbelt._lazy`)
    from .calibration import MEASUREMENTS as MEASUREMENTS
    from .calibration import calibrate as calibrate
    from .harmonic import HarmonicSolution as HarmonicSolution
    from .harmonic import Jumps as Jumps
    from .harmonic import ResponseCurve as ResponseCurve
    from .harmonic import fold_speeds as fold_speeds
    from .harmonic import harmonic_balance as harmonic_balance
    from .harmonic import jumps as jumps
    from .harmonic import response_curve as response_curve
    from .kbm import backbone_amplitude as backbone_amplitude
    from .kbm import backbone_frequency as backbone_frequency
    from .kbm import backbone_speed as backbone_speed
    from .kbm import kbm_amplitudes as kbm_amplitudes
    from .kbm import kbm_coefficients as kbm_coefficients
    from .model import ModalSystem as ModalSystem
    from .model import NonlinearBelt as NonlinearBelt
    from .model import RunningSpeed as RunningSpeed
    from .model import SpeedRamp as SpeedRamp
    from .model import mode_shapes as mode_shapes
    from .ramp import RampRecord as RampRecord
    from .ramp import speed_ramp as speed_ramp
    from .steady import SteadyStateError as SteadyStateError
    from .steady import nonlinear_basins as nonlinear_basins
    from .steady import nonlinear_steady_state as nonlinear_steady_state
    from .steady import nonlinear_sweep as nonlinear_sweep
    from .steady import nonlinear_trajectory as nonlinear_trajectory
    from .steady import speed_sweep as speed_sweep

from ..._lazy import attach as _attach  # noqa: E402

__getattr__, __dir__, __all__ = _attach(__name__, __file__)
