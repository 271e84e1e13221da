"""Objectives: pure scalar functions of (model, command/controller), composable with grad/vmap/jit.

One module per objective family: residual vibration energy H (command shaping, Incerti (pseudo-polynomial commands)) and
the speed-fluctuation index χ (four-bar drive, Incerti (2012)).
"""

from .fluctuation import chi_from_samples as chi_from_samples
from .fluctuation import closed_loop_metrics as closed_loop_metrics
from .fluctuation import fluctuation_index as fluctuation_index
from .fluctuation import fluctuation_objective as fluctuation_objective
from .residual import convolution_integrals as convolution_integrals
from .residual import residual_energy as residual_energy
from .residual import residual_energy_joules as residual_energy_joules
