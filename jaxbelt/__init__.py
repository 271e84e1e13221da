"""jaxbelt: differentiable simulation and optimisation of belt drives and DC-motor mechanisms.

**Precision.** `import jaxbelt` switches JAX to float64 (`jax_enable_x64`), which the papers'
checks need (closed forms to 1e-12, energy balances); `jaxbelt.X64_SWITCHED_ON` says whether this
import changed the setting. To keep JAX's float32 default, set the environment variable
`JAXBELT_X64=0` before the import (or build models and inputs inside `jax.enable_x64(False)`):
every scene then runs in float32, with the accuracy the stress tests measure.
"""

import os as _os

import jax as _jax

#: True when `import jaxbelt` switched JAX to float64 (it was off and `JAXBELT_X64` is not "0").
X64_SWITCHED_ON = False
if _os.environ.get("JAXBELT_X64", "1") != "0" and not _jax.config.jax_enable_x64:
    _jax.config.update("jax_enable_x64", True)
    X64_SWITCHED_ON = True

# --- core: scenes, simulation, commands --------------------------------------------------------
from .commands import AbstractInput as AbstractInput  # noqa: E402
from .commands import AbstractVoltageSource as AbstractVoltageSource  # noqa: E402
from .commands import AbstractVoltageCommand as AbstractVoltageCommand  # noqa: E402
from .commands import AbstractExponentialVoltage as AbstractExponentialVoltage  # noqa: E402
from .commands import AbstractController as AbstractController  # noqa: E402
from .commands import AbstractRunningSpeed as AbstractRunningSpeed  # noqa: E402
from .commands import MotorState as MotorState  # noqa: E402
from .commands import AbstractMotionCommand as AbstractMotionCommand  # noqa: E402
from .commands import ConstantVoltage as ConstantVoltage  # noqa: E402
from .commands import ExponentialVoltage as ExponentialVoltage  # noqa: E402
from .commands import PseudoPolynomial as PseudoPolynomial  # noqa: E402
from .commands import ShapedCommand as ShapedCommand  # noqa: E402
from .models import AbstractModel as AbstractModel  # noqa: E402
from .models import AbstractLinearModel as AbstractLinearModel  # noqa: E402
from .models import integrand as integrand  # noqa: E402
from .models import observable as observable  # noqa: E402
from .scene import Scene as Scene  # noqa: E402
from .scene import TracedGridWarning as TracedGridWarning  # noqa: E402
from .solution import Solution as Solution  # noqa: E402
from .solution import SolveError as SolveError  # noqa: E402
from .solve import simulate as simulate  # noqa: E402
from .batch import cpu_devices as cpu_devices  # noqa: E402
from .batch import sweep as sweep  # noqa: E402

# --- start-up of a belt drive (Incerti, 2014) ---------------------------------------------------------
from .models import BeltChain as BeltChain  # noqa: E402
from .models import BeltStartup as BeltStartup  # noqa: E402
from .models.startup import startup_curves as startup_curves  # noqa: E402

# --- four-bar linkage + PID-controlled DC motor (Incerti, 2012) -------------------------------------
from .models.fourbar import FourBarDrive as FourBarDrive  # noqa: E402
from .models.fourbar import simulate_fig4 as simulate_fig4  # noqa: E402
from .models.motor import PID as PID  # noqa: E402
from .objectives.fluctuation import fluctuation_index as fluctuation_index  # noqa: E402
from .objectives.fluctuation import fluctuation_objective as fluctuation_objective  # noqa: E402
from .optimise.pid import PIDTuneResult as PIDTuneResult  # noqa: E402
from .optimise.pid import tune_pid as tune_pid  # noqa: E402

# --- belt spans: contact, moving string, crossing diagrams (belt-vibration report; Moon & Wickert, 1997) --------------------
from .models import BeltPulleyContact as BeltPulleyContact  # noqa: E402
from .models import MovingString as MovingString  # noqa: E402
from .models import RunoutRig as RunoutRig  # noqa: E402
from .models import SlipError as SlipError  # noqa: E402
from .models import SlipReport as SlipReport  # noqa: E402
from .models import crossing_diagram as crossing_diagram  # noqa: E402
from .models import crossing_speeds as crossing_speeds  # noqa: E402
from .models import exciting_speeds as exciting_speeds  # noqa: E402
from .models import linear_runout_response as linear_runout_response  # noqa: E402
from .models import runout_phasors as runout_phasors  # noqa: E402
from .models import simulate_runout_response as simulate_runout_response  # noqa: E402

# --- command shaping of a belt-driven platform (Incerti, pseudo-polynomial commands) --------------------------------------
from .models import BeltPlatform as BeltPlatform  # noqa: E402
from .models.platform import platform_response as platform_response  # noqa: E402
from .objectives.residual import residual_energy as residual_energy  # noqa: E402
from .objectives.residual import residual_energy_joules as residual_energy_joules  # noqa: E402
from .optimise.command import CommandOptimResult as CommandOptimResult  # noqa: E402
from .optimise.command import optimise_command as optimise_command  # noqa: E402
from .optimise.command import optimise_robust as optimise_robust  # noqa: E402
from .optimise.command import sensitivity_curve as sensitivity_curve  # noqa: E402
from .optimise.command import shaped_commands as shaped_commands  # noqa: E402
from .optimise.command import tolerance_band as tolerance_band  # noqa: E402

# --- non-linear belt vibration (Moon & Wickert, 1997) ------------------------------------------------------
from .models.nonlinear import NonlinearBelt as NonlinearBelt  # noqa: E402
from .models.nonlinear import RunningSpeed as RunningSpeed  # noqa: E402
from .models.nonlinear import SpeedRamp as SpeedRamp  # noqa: E402
from .models.nonlinear import kbm_coefficients as kbm_coefficients  # noqa: E402
from .models.nonlinear import backbone_amplitude as backbone_amplitude  # noqa: E402
from .models.nonlinear import backbone_frequency as backbone_frequency  # noqa: E402
from .models.nonlinear import backbone_speed as backbone_speed  # noqa: E402
from .models.nonlinear import kbm_amplitudes as kbm_amplitudes  # noqa: E402
from .models.nonlinear import SteadyStateError as SteadyStateError  # noqa: E402
from .models.nonlinear import nonlinear_basins as nonlinear_basins  # noqa: E402
from .models.nonlinear import speed_sweep as speed_sweep  # noqa: E402
from .models.nonlinear import nonlinear_steady_state as nonlinear_steady_state  # noqa: E402
from .models.nonlinear import nonlinear_sweep as nonlinear_sweep  # noqa: E402
from .models.nonlinear import nonlinear_trajectory as nonlinear_trajectory  # noqa: E402
from .models.nonlinear import ResponseCurve as ResponseCurve  # noqa: E402
from .models.nonlinear import response_curve as response_curve  # noqa: E402
from .models.nonlinear import fold_speeds as fold_speeds  # noqa: E402
from .models.nonlinear import harmonic_balance as harmonic_balance  # noqa: E402
from .models.nonlinear import speed_ramp as speed_ramp  # noqa: E402
from .models.nonlinear import MEASUREMENTS as MEASUREMENTS  # noqa: E402
from .models.nonlinear import calibrate as calibrate  # noqa: E402
from .models.nonlinear import jumps as jumps  # noqa: E402

# --- parameter identification (weighted least squares, optimistix) -------------------------------
from .identify import IdentifyResult as IdentifyResult  # noqa: E402
from .identify import identify as identify  # noqa: E402

# --- persistent compilation cache (opt-in; the CLI switches it on) --------------------------------
from .cache import enable_compilation_cache as enable_compilation_cache  # noqa: E402

# --- sub-modules -------------------------------------------------------------------------------
from . import modal as modal  # noqa: E402
def __getattr__(name):
    # `jb.plots` is imported on first use: `import jaxbelt` loads no plotting library
    if name == "plots":
        import importlib

        return importlib.import_module(".plots", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__version__ = "0.1.0"

__all__ = [name for name in dir() if not name.startswith("_")] + ["plots"]
