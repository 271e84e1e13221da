"""jaxbelt: differentiable simulation and optimisation of belt drives and DC-motor mechanisms.

float64 is switched on at import (the papers' checks need it); see README for the scenes.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from .commands import AbstractCommand as AbstractCommand  # noqa: E402
from .commands import ConstantVoltage as ConstantVoltage  # noqa: E402
from .commands import ExponentialVoltage as ExponentialVoltage  # noqa: E402
from .models import AbstractModel as AbstractModel  # noqa: E402
from .models import BeltChain as BeltChain  # noqa: E402
from .models import BeltStartup as BeltStartup  # noqa: E402
from .scene import Scene as Scene  # noqa: E402
from .solve import Solution as Solution  # noqa: E402
from .solve import SolveError as SolveError  # noqa: E402
from .solve import simulate as simulate  # noqa: E402

__version__ = "0.1.0"
from .commands import PseudoPolynomial as PseudoPolynomial  # noqa: E402
from .commands import ShapedCommand as ShapedCommand  # noqa: E402
from .models import BeltPlatform as BeltPlatform  # noqa: E402
from .objectives.residual import residual_energy as residual_energy  # noqa: E402
from .objectives.residual import residual_energy_joules as residual_energy_joules  # noqa: E402
from .optimise.command import CommandOptimResult as CommandOptimResult  # noqa: E402
from .optimise.command import optimise_command as optimise_command  # noqa: E402
from .optimise.command import optimise_robust as optimise_robust  # noqa: E402
from .optimise.command import sensitivity_curve as sensitivity_curve  # noqa: E402
from .optimise.command import tolerance_band as tolerance_band  # noqa: E402
from .optimise.command import shaped_commands as shaped_commands  # noqa: E402
