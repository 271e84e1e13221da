"""Matplotlib figures: the papers' figures and more. One module per scene.

The functions are loaded on first use (module `__getattr__`), so that `import jaxbelt.plots`
costs nothing until a figure is drawn.
"""

import importlib as _importlib

_WHERE = {
    "plot_startup": "startup", "startup_curves": "startup", "draw_startup": "startup",
    "plot_contact_pressure": "string", "plot_crossing_diagram": "string", "plot_exciting_speeds": "string",
    "plot_frequency_harmonics": "string", "plot_runout_response": "string", "string_figure": "string",
    "nonlinear_figure": "nonlinear",
    "plot_fig3": "shaping", "plot_sensitivity": "shaping", "shaping_figure": "shaping",
    "fourbar_figure": "fourbar", "linkage_strip": "fourbar", "simulate_fig4": "fourbar",
}

__all__ = sorted(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        value = getattr(_importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
