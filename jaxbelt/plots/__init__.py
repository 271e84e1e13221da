"""Matplotlib figures: the papers' figures and more. One module per scene."""
from .startup import plot_startup as plot_startup  # noqa: E402
from .startup import startup_curves as startup_curves  # noqa: E402
