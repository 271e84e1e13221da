"""Matplotlib figures: the papers' figures and more. One module per scene."""
from .fourbar import fourbar_figure as fourbar_figure
from .fourbar import linkage_strip as linkage_strip
from .fourbar import simulate_fig4 as simulate_fig4
