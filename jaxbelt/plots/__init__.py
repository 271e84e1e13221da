"""Matplotlib figures: the papers' figures and more. One module per scene.

Plot functions draw results computed beforehand by the library (`startup_curves`, `simulate_fig4`,
`platform_response`, `crossing_speeds`, ...); they never run a simulation. Matplotlib is imported
only when a figure is drawn.
"""

import typing as _typing

if _typing.TYPE_CHECKING:  # the public names, imported on first use (`jaxbelt._lazy`)
    from .fourbar import fourbar_figure as fourbar_figure
    from .fourbar import linkage_strip as linkage_strip
    from .fourbar import plot_regulators as plot_regulators
    from .measurement import decay_fit as decay_fit
    from .measurement import plot_decay_fit as plot_decay_fit
    from .measurement import plot_spectrum_fit as plot_spectrum_fit
    from .measurement import spectrum_fit as spectrum_fit
    from .nonlinear import response_figure as response_figure
    from .plan import plan_figure as plan_figure
    from .shaping import plot_fig3 as plot_fig3
    from .shaping import plot_sensitivity as plot_sensitivity
    from .shaping import shaping_figure as shaping_figure
    from .startup import draw_startup as draw_startup
    from .string import plot_contact_pressure as plot_contact_pressure
    from .string import plot_crossing_diagram as plot_crossing_diagram
    from .string import plot_exciting_speeds as plot_exciting_speeds
    from .string import plot_frequency_harmonics as plot_frequency_harmonics
    from .string import plot_galerkin_convergence as plot_galerkin_convergence
    from .string import plot_runout_response as plot_runout_response
    from .string import string_figure as string_figure

from .._lazy import attach as _attach  # noqa: E402

__getattr__, __dir__, __all__ = _attach(__name__, __file__)
