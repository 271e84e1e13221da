"""Optimisers: optax loops (one jitted step), constraints, progress bars and result objects."""

from .command import CommandOptimResult as CommandOptimResult
from .command import optimise_command as optimise_command
from .command import optimise_robust as optimise_robust
from .command import sensitivity_curve as sensitivity_curve
from .command import shaped_commands as shaped_commands
from .command import tolerance_band as tolerance_band
from .pid import PIDTuneResult as PIDTuneResult
from .pid import tune_pid as tune_pid
