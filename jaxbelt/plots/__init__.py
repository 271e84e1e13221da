"""Matplotlib figures: the papers' figures and more. One module per scene."""
from .nonlinear import nonlinear_figure as nonlinear_figure  # noqa: E402
