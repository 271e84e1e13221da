"""The ipywidgets sliders of the knobs, as a browser shows them: grids holding the values set, echoes ignored."""

from __future__ import annotations

import importlib
import math

from .._display import with_unit
from ._knobs import Knob

#: what `explore` says when ipywidgets is missing
MISSING_WIDGETS = "jb.explore needs ipywidgets: pip install 'jaxbelt[notebook]'"


def _widgets():
    """The ipywidgets module, or the `ImportError` that names the extra installing it."""
    try:  # an optional package (the notebook extra), imported as pandas and xarray are (`jaxbelt._display`)
        return importlib.import_module("ipywidgets")
    except ImportError as e:
        raise ImportError(MISSING_WIDGETS) from e


def _grid(lo: float, hi: float, value: float, n: int = 200) -> tuple[float, float]:
    """`(min, step)` of a slider over `[lo, hi]` whose grid `min + k step` holds `value` (in the slider's own
    coordinate: the exponent for a logarithmic slider), about `n` steps over the range.

    A browser's slider (noUiSlider, under ipywidgets) snaps its value to `min + k step` when it is shown and sends the
    snapped value back: a start off that grid would change the view's numbers by opening it (80 on a grid of 1.2 from
    0 becomes 80.4). So the step is the nearest to `(hi - lo) / n` that divides `value - lo` (the low end stays); a
    value within half a step of `lo` moves the low end to the value instead."""
    step = (hi - lo) / n
    k = round((value - lo) / step)
    if k >= 1:
        return lo, (value - lo) / k
    return value, step


def _off_grid(slider, new, log: bool) -> bool:
    """Whether `new`, a value a front-end sends for `slider`, lies within half a step of the slider's value: the echo
    of the value snapped to the front-end's grid (a rounding), not a move (a move is at least one step)."""
    try:
        new, old, step = float(new), float(slider.value), float(slider.step)
    except (TypeError, ValueError):
        return False
    if log:
        if not (new > 0 and old > 0):
            return False
        base = float(slider.base)
        return abs(math.log(new, base) - math.log(old, base)) < 0.5 * step
    return abs(new - old) < 0.5 * step  # NaN: False


_SLIDER_CLASSES: dict = {}


def _slider_class(w, log: bool):
    """ipywidgets' `FloatSlider` (`FloatLogSlider` where `log`) that ignores a front-end's echo of its value snapped
    to the front-end's grid (`_off_grid`): the value set from Python stays exact, and the echo recomputes nothing."""
    cls = _SLIDER_CLASSES.get(log)
    if cls is None:
        base = w.FloatLogSlider if log else w.FloatSlider

        class Slider(base):  # type: ignore[valid-type, misc]
            def set_state(self, sync_data):
                """A state from the front-end, less a `value` that only rounds this slider's value to its grid."""
                if "value" in sync_data and _off_grid(self, sync_data["value"], log):
                    sync_data = {k: v for k, v in sync_data.items() if k != "value"}
                if sync_data:
                    super().set_state(sync_data)

            def send_state(self, key=None):
                """Send the state of `key` with the range (`min`, `max`, `step`) before the `value`: the front-end
                handles the keys in the message's order, and a value ahead of its new range would be clamped to the
                old one (a tuned gain beyond the slider's first range came back as the old maximum)."""
                if key is not None and not isinstance(key, str):
                    key = sorted(key, key=lambda k: (k == "value", str(k)))
                super().send_state(key)

        Slider.__name__ = Slider.__qualname__ = "LogSlider" if log else "Slider"
        cls = _SLIDER_CLASSES[log] = Slider
    return cls


def _slider_range(k: Knob, value: float) -> dict:
    """`{min, max, step}` of the slider of `k` with `value` on its grid (`_grid`; exponents for a log slider)."""
    if k.log:
        lo, hi, x = math.log10(k.lo), math.log10(k.hi), math.log10(value)
    else:
        lo, hi, x = k.lo, k.hi, value
    mn, step = _grid(lo, hi, x)
    if k.log and mn == x:  # base**min may round above the value: keep the low end a hair below it
        mn = x - 1e-9 * step
    return dict(min=mn, max=hi, step=step)


def _set_slider(slider, k: Knob, value: float) -> None:
    """Move `slider` to `value` with its grid re-aligned to hold it, as one message to the front-end (`hold_sync`):
    a front-end that received the range and the value apart would snap the old value to the new range, or the new
    value to the old grid, and send that back."""
    r = _slider_range(k, value)
    with slider.hold_sync():
        slider.min = min(float(slider.min), r["min"])  # widen first: the value is validated against the range
        slider.max = max(float(slider.max), r["max"])
        slider.value = value
        slider.min, slider.max, slider.step = r["min"], r["max"], r["step"]


def _slider(w, k: Knob):
    """The ipywidgets slider of a knob (logarithmic where `k.log`), its grid holding the start value (`_grid`)."""
    common = dict(
        description=with_unit(k.label, k.unit),
        continuous_update=True,
        readout_format=".4g",
        style={"description_width": "100px"},
        layout=w.Layout(width="400px"),
        tooltip=k.doc,
        **_slider_range(k, k.value),
    )
    if k.log:
        return _slider_class(w, True)(value=k.value, base=10.0, **common)
    return _slider_class(w, False)(value=k.value, **common)
