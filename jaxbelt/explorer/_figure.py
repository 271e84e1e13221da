"""The views' figures: axes' style, sticky limits, and the Agg canvas that renders only the curves anew."""

from __future__ import annotations

import math

import numpy as np


def _style(ax, xlabel: str, ylabel: str) -> None:
    """Labels, a light grid and at most 5 ticks per axis: text is most of a redraw's time (Agg renders each label's
    glyphs anew), so a view keeps its text short."""
    from matplotlib.ticker import MaxNLocator

    ax.set_xlabel(xlabel, fontsize=9)
    ax.set_ylabel(ylabel, fontsize=9)
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=9)
    ax.xaxis.set_major_locator(MaxNLocator(5))
    if ax.get_yscale() == "linear":
        ax.yaxis.set_major_locator(MaxNLocator(5))


def _fit(ax, *arrays, axis: str = "y") -> None:
    """Fit an axis to the data of `arrays`, sticky: the limits stay while the data lie inside them and fill at least
    40 % of them, so that most slider moves redraw only the curves (the axes' text is rendered again only when the
    limits change; see `CachedAggCanvas`)."""
    vals = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in arrays]) if arrays else np.zeros(0)
    log = (ax.get_yscale() if axis == "y" else ax.get_xscale()) == "log"
    vals = vals[np.isfinite(vals) & (vals > 0)] if log else vals[np.isfinite(vals)]
    if not vals.size:
        return
    if log:
        vals = np.log10(vals)
    lo, hi = float(vals.min()), float(vals.max())
    a, b = ax.get_ylim() if axis == "y" else ax.get_xlim()
    if log:
        a, b = math.log10(a), math.log10(b)
    if a <= lo and hi <= b and hi - lo >= 0.4 * (b - a):
        return
    pad = 0.08 * (hi - lo) if hi > lo else 0.05 * max(abs(hi), 1e-12)
    lo, hi = lo - pad, hi + pad
    if log:
        lo, hi = 10.0**lo, 10.0**hi
    (ax.set_ylim if axis == "y" else ax.set_xlim)(lo, hi)


_CANVAS: list = []


def _cached_canvas_class():
    """The Agg canvas of the explorers (made on first use: matplotlib is imported by the first explorer)."""
    if _CANVAS:
        return _CANVAS[0]
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    class CachedAggCanvas(FigureCanvasAgg):
        """An Agg canvas that keeps the rendering of its figure's static part (axes, ticks, labels, grid) and renders
        only the `dynamic` artists (the curves a slider moves, the legends) over it at each `draw()`, until the
        layout changes (the figure's size or resolution, an axis' limits or scale: then it renders everything again).
        Text is most of a full rendering's time. `savefig` always renders the whole figure; `invalidate()` forces
        the next `draw()` to (after a change to a static part it cannot see, e.g. a new title)."""

        def __init__(self, figure=None):
            super().__init__(figure)
            self.dynamic: list = []
            self.full_draws = 0
            self._background = None
            self._key = None

        def invalidate(self) -> None:
            self._background = None

        def _layout_key(self):
            fig = self.figure
            axes = tuple(
                (tuple(ax.get_position().bounds), ax.get_xlim(), ax.get_ylim(), ax.get_xscale(), ax.get_yscale())
                for ax in fig.axes
            )
            return (fig.dpi, tuple(fig.get_size_inches()), axes)

        def draw(self):
            key = self._layout_key()
            if self._background is None or key != self._key or not self.dynamic:
                shown = [a for a in self.dynamic if a.get_visible()]
                for a in shown:
                    a.set_visible(False)
                try:
                    super().draw()
                finally:
                    for a in shown:
                        a.set_visible(True)
                self._background = self.copy_from_bbox(self.figure.bbox)
                self._key = key
                self.full_draws += 1
            else:
                self.renderer = self.get_renderer()
                self.restore_region(self._background)
            for a in self.dynamic:
                if a.get_visible():
                    a.draw(self.renderer)
            self.figure.stale = False

    _CANVAS.append(CachedAggCanvas)
    return CachedAggCanvas


def _figure(figsize):
    """`(figure, mode)`: a figure of its own (not pyplot's), on ipympl's canvas widget when that backend is active
    (`%matplotlib widget`: `mode == "canvas"`), else on a `CachedAggCanvas` shown as a PNG image (`mode == "image"`)."""
    import matplotlib

    backend = matplotlib.get_backend().lower()
    if "ipympl" in backend or backend.endswith("widget"):
        import matplotlib.pyplot as plt

        with plt.ioff():
            fig = plt.figure(figsize=figsize)
        fig.set_layout_engine("tight")
        return fig, "canvas"
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=72)
    _cached_canvas_class()(fig)
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.16, top=0.96, wspace=0.3)
    return fig, "image"
