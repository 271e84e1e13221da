"""Objectives: pure scalar functions of (model, command/controller), composable with grad/vmap/jit.

One module per objective family: residual vibration energy H (command shaping, seed 003) and
the speed-fluctuation index χ (four-bar drive, seed 001).
"""
from .residual import convolution_integrals as convolution_integrals
from .residual import residual_energy as residual_energy
from .residual import residual_energy_joules as residual_energy_joules
