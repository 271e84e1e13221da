"""Objectives: pure scalar functions of (model, command/controller), composable with grad/vmap/jit.

One module per objective family: residual vibration energy H (command shaping, seed 003) and
the speed-fluctuation index χ (four-bar drive, seed 001).
"""
