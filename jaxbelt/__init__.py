"""jaxbelt: differentiable simulation and optimisation of belt drives and DC-motor mechanisms.

**Precision.** jaxbelt computes in float64, which the papers' checks need (closed forms to 1e-12,
energy balances, the folds of the non-linear belt), and it does not change JAX's configuration on
import: a program that imports it keeps its own settings (a float32 network next to it stays float32).
Turn JAX's 64-bit mode on yourself, once, right after importing JAX and before any array is made:

```python
import jax
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
```

With the mode off, the first jaxbelt call that builds a model, a command or an array raises
`RuntimeError` naming that line (a config read, no cost). The `jaxbelt` command switches the mode on
itself. Why an error and not the caller's precision: in float32 the scenes lose most of the digits
their checks rely on (the start-up closed form kept a relative error of 1e-3 against 2e-13 in float64
when jaxbelt still ran in float32 on request), and nothing would say so; an error at the first call
costs one line and no digit (docs: Errors and guarantees, Precision).

**Imports.** `import jaxbelt` imports nothing heavy (not even JAX); each public name imports its module on first use
(`jaxbelt.simulate`, `jaxbelt.tune_pid`, ...), so a session that only solves the start-up in closed
form never loads diffrax, optax or matplotlib. At its first use jaxbelt loads scipy's BLAS and LAPACK tables, which
JAX's CPU kernels run on, without the `scipy.linalg` package (0.1-0.2 s saved); a later `import scipy.linalg` is the
usual package (`jaxbelt._lapack`; import `scipy.linalg` first to keep the usual order).
"""

import typing as _typing

# Every public name below is imported on first use (`jaxbelt._lazy`): `import jaxbelt` costs next to nothing
# (JAX is imported by the first name that needs it), and a scene loads only what it needs (the start-up closed form never loads diffrax,
# optax or matplotlib). This block is the list of public names: type checkers and the documentation
# read it as imports, `jaxbelt._lazy.attach` as the table of where each name lives.
if _typing.TYPE_CHECKING:
    # --- core: scenes, simulation, commands --------------------------------------------------------
    # --- sub-modules -------------------------------------------------------------------------------
    from . import modal as modal
    from . import plots as plots
    from ._model import AbstractLinearModel as AbstractLinearModel
    from ._model import AbstractModel as AbstractModel
    from ._model import integrand as integrand
    from ._model import observable as observable
    from ._model import observable_family as observable_family
    from .batch import cpu_devices as cpu_devices
    from .batch import sweep as sweep

    # --- persistent compilation cache (opt-in; the CLI switches it on) --------------------------------
    from .cache import enable_compilation_cache as enable_compilation_cache
    from .commands import AbstractController as AbstractController
    from .commands import AbstractExponentialVoltage as AbstractExponentialVoltage
    from .commands import AbstractInput as AbstractInput
    from .commands import AbstractMotionCommand as AbstractMotionCommand
    from .commands import AbstractRunningSpeed as AbstractRunningSpeed
    from .commands import AbstractVoltageCommand as AbstractVoltageCommand
    from .commands import AbstractVoltageSource as AbstractVoltageSource
    from .commands import ConstantVoltage as ConstantVoltage
    from .commands import ExponentialVoltage as ExponentialVoltage
    from .commands import MotorState as MotorState
    from .commands import PseudoPolynomial as PseudoPolynomial
    from .commands import ShapedCommand as ShapedCommand

    # --- live exploration in a notebook (the extra jaxbelt[notebook]: ipywidgets) ---------------------------
    from .explorer import Explorer as Explorer
    from .explorer import explore as explore

    # --- parameter identification (weighted least squares, optimistix) -------------------------------
    from .identification import IdentifyResult as IdentifyResult
    from .identification import identify as identify

    # --- start-up of a belt drive (Incerti, 2014) ---------------------------------------------------------
    from .models import BeltChain as BeltChain

    # --- command shaping of a belt-driven platform (Incerti, pseudo-polynomial commands) --------------------------------------
    from .models import BeltPlatform as BeltPlatform

    # --- belt spans: contact, moving string, crossing diagrams (belt-vibration report; Moon & Wickert, 1997) --------------------
    from .models import BeltPulleyContact as BeltPulleyContact
    from .models import BeltStartup as BeltStartup
    from .models import ModalAxis as ModalAxis
    from .models import MovingString as MovingString
    from .models import RunoutRig as RunoutRig
    from .models import SlipError as SlipError
    from .models import SlipReport as SlipReport
    from .models import crossing_diagram as crossing_diagram
    from .models import crossing_speeds as crossing_speeds
    from .models import exciting_speeds as exciting_speeds
    from .models import linear_runout_response as linear_runout_response
    from .models import runout_phasors as runout_phasors
    from .models import simulate_runout_response as simulate_runout_response

    # --- four-bar linkage + PID-controlled DC motor (Incerti, 2012) -------------------------------------
    from .models.fourbar import FourBarDrive as FourBarDrive
    from .models.motor import PID as PID
    from .models.nonlinear import MEASUREMENTS as MEASUREMENTS

    # --- non-linear belt vibration (Moon & Wickert, 1997) ------------------------------------------------------
    from .models.nonlinear import NonlinearBelt as NonlinearBelt
    from .models.nonlinear import ResponseCurve as ResponseCurve
    from .models.nonlinear import RunningSpeed as RunningSpeed
    from .models.nonlinear import SpeedRamp as SpeedRamp
    from .models.nonlinear import SteadyStateError as SteadyStateError
    from .models.nonlinear import backbone_amplitude as backbone_amplitude
    from .models.nonlinear import backbone_frequency as backbone_frequency
    from .models.nonlinear import backbone_speed as backbone_speed
    from .models.nonlinear import calibrate as calibrate
    from .models.nonlinear import fold_speeds as fold_speeds
    from .models.nonlinear import harmonic_balance as harmonic_balance
    from .models.nonlinear import jumps as jumps
    from .models.nonlinear import kbm_amplitudes as kbm_amplitudes
    from .models.nonlinear import kbm_coefficients as kbm_coefficients
    from .models.nonlinear import nonlinear_basins as nonlinear_basins
    from .models.nonlinear import nonlinear_steady_state as nonlinear_steady_state
    from .models.nonlinear import nonlinear_sweep as nonlinear_sweep
    from .models.nonlinear import nonlinear_trajectory as nonlinear_trajectory
    from .models.nonlinear import response_curve as response_curve
    from .models.nonlinear import speed_ramp as speed_ramp
    from .models.nonlinear import speed_sweep as speed_sweep
    from .objectives.fluctuation import fluctuation_index as fluctuation_index
    from .objectives.fluctuation import fluctuation_objective as fluctuation_objective
    from .objectives.residual import residual_energy as residual_energy
    from .objectives.residual import residual_energy_joules as residual_energy_joules
    from .optimise.command import CommandOptimResult as CommandOptimResult
    from .optimise.command import optimise_command as optimise_command
    from .optimise.command import optimise_robust as optimise_robust
    from .optimise.command import sensitivity_curve as sensitivity_curve
    from .optimise.command import shaped_commands as shaped_commands
    from .optimise.command import tolerance_band as tolerance_band
    from .optimise.pid import PIDTuneResult as PIDTuneResult
    from .optimise.pid import tune_pid as tune_pid
    from .runs import platform_response as platform_response
    from .runs import simulate_fig4 as simulate_fig4
    from .runs import startup_curves as startup_curves
    from .scene import Scene as Scene
    from .scene import TracedGridWarning as TracedGridWarning
    from .shaping.codesign import best_residual as best_residual
    from .shaping.codesign import shortest_move_time as shortest_move_time
    from .shaping.firmware_shaper import FirmwareShaper as FirmwareShaper
    from .shaping.firmware_shaper import design_shaper as design_shaper

    # --- command shaping on the user's axis ---------------------------------------------------------
    from .shaping.identify import identify_axis as identify_axis
    from .shaping.klipper import KlipperConfig as KlipperConfig
    from .shaping.klipper import klipper_calibration as klipper_calibration
    from .shaping.klipper import klipper_impulses as klipper_impulses
    from .shaping.klipper import parse_klipper as parse_klipper
    from .shaping.measurement import identify_measurement as identify_measurement
    from .shaping.moves import PiecewiseMove as PiecewiseMove
    from .shaping.moves import SplineMove as SplineMove
    from .shaping.moves import fastest_move as fastest_move
    from .shaping.moves import shape_move as shape_move
    from .shaping.moves import trapezoid_move as trapezoid_move
    from .shaping.plan import Candidate as Candidate
    from .shaping.plan import MovePlan as MovePlan
    from .shaping.plan import design_move as design_move
    from .shaping.psd import identify_axis_from_psd as identify_axis_from_psd
    from .shaping.psd import welch as welch
    from .shaping.readers import load_record as load_record
    from .shaping.readers import load_spectrum as load_spectrum
    from .shaping.residual import residual_amplitudes as residual_amplitudes
    from .shaping.residual import residual_curve as residual_curve
    from .shaping.resonance_test import identify_axis_from_sweep as identify_axis_from_sweep
    from .shaping.resonance_test import klipper_sweep as klipper_sweep
    from .shaping.rrf import m593_line as m593_line
    from .shaping.rrf import parse_m593 as parse_m593
    from .shaping.shapers import shaper_impulses as shaper_impulses
    from .solution import Solution as Solution
    from .solution import SolveError as SolveError
    from .solve import simulate as simulate

from ._lazy import attach as _attach  # noqa: E402

__getattr__, __dir__, _names = _attach(__name__, __file__)
#: the one place the version is written (pyproject.toml reads it; CHANGELOG.md has a section per version)
__version__ = "0.3.0"
# type checkers read the public names from the TYPE_CHECKING block above; at run time they come from the same block
__all__ = [*_names]  # pyright: ignore[reportUnsupportedDunderAll]
