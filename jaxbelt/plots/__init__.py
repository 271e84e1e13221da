"""Matplotlib figures: the papers' figures and more. One module per scene."""
from .startup import plot_startup as plot_startup  # noqa: E402
from .startup import startup_curves as startup_curves  # noqa: E402
from .string import plot_contact_pressure as plot_contact_pressure
from .string import plot_crossing_diagram as plot_crossing_diagram
from .string import plot_exciting_speeds as plot_exciting_speeds
from .string import plot_frequency_harmonics as plot_frequency_harmonics
from .string import plot_runout_response as plot_runout_response
from .string import string_figure as string_figure
from .nonlinear import nonlinear_figure as nonlinear_figure  # noqa: E402
from .shaping import plot_fig3 as plot_fig3
from .shaping import plot_sensitivity as plot_sensitivity
from .shaping import shaping_figure as shaping_figure
from .fourbar import fourbar_figure as fourbar_figure
from .fourbar import linkage_strip as linkage_strip
from .fourbar import simulate_fig4 as simulate_fig4
from .startup import draw_startup as draw_startup  # noqa: E402
