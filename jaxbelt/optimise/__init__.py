"""Optimisers: optax loops (one jitted step), constraints, progress bars and result objects."""
from .pid import PIDTuneResult as PIDTuneResult
from .pid import tune_pid as tune_pid
