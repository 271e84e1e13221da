"""Matplotlib figures: the papers' figures and more. One module per scene."""
from .shaping import plot_fig3 as plot_fig3
from .shaping import plot_sensitivity as plot_sensitivity
from .shaping import shaping_figure as shaping_figure
