"""The live view of one scene (`Explorer`) and its entry point `explore`."""

from __future__ import annotations

import base64
import dataclasses
import io
import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from .._display import Display, fmt, fmt_list
from ._figure import _figure
from ._fourbar import _FourBar
from ._knobs import _options
from ._registry import _ALIASES, _SCENES, _scene_key
from ._scene import _Scene
from ._sliders import _set_slider, _slider, _widgets
from ._worker import _worker


class Explorer:
    """A live view of one scene (what `explore` returns).

    - `controls`: `{name: ipywidgets slider}` (units in each description); dragging one recomputes and redraws;
    - `figure`: the scene's matplotlib `Figure`, redrawn in place (its lines' data change, the figure stays);
    - `values`: `{name: number}` of the key numbers of the last result (χ, H, the worst residual, the fold
      speeds, ...), `units`: their units; NaN after a computation that failed (`error` says why), and NaN while a
      background computation runs (`update(wait=False)`, a slider moved in a long scene: `wait()` for its numbers);
    - `update(**values)`: set sliders from code and wait for the redrawn figure (`wait=False`: do not wait);
    - `widget`: the composed ipywidgets box (figure on top; sliders, numbers and status below); a notebook shows it
      when the explorer is the cell's value (a static renderer shows the figure as a PNG);
    - `wait(timeout)`: wait until no background computation is in flight (long scenes); `close()`.

    Long scenes compute in one background thread: a slider change that arrives while a computation runs makes
    that computation stale (its result is dropped when it ends: `stats["dropped"]`) and replaces any request
    queued behind it (`stats["skipped"]`); only the latest values are drawn.
    """

    def __init__(self, scene: _Scene):
        w = _widgets()
        self._w = w
        self.scene = scene
        self._lock = threading.RLock()
        self._generation = 0
        self._quiet = False
        self._pending: tuple | None = None
        self._idle = threading.Event()
        self._idle.set()
        self._errors: dict[int, BaseException] = {}
        self.stats = {"computed": 0, "dropped": 0, "skipped": 0}
        self.error: str = ""
        self.values: dict[str, Any] = {}
        self.units: dict[str, str] = {}
        self._display = Display(scene.title)
        self.controls = {k.name: _slider(w, k) for k in scene.knobs}
        self._knobs = {k.name: k for k in scene.knobs}
        self.figure, self._mode = _figure(scene.figsize)
        scene.build(self.figure)
        if self._mode == "image":
            canvas: Any = self.figure.canvas  # a CachedAggCanvas
            canvas.dynamic = list(getattr(scene, "dynamic", []))
        self._numbers = w.HTML()
        self._status = w.HTML()
        self._progress = w.FloatProgress(
            value=0.0, min=0.0, max=1.0, description="", bar_style="info", layout=w.Layout(width="160px")
        )
        self._progress.layout.visibility = "hidden"
        self._extra = scene.extra_controls(self, w)
        self._image = None
        self._box = None
        for slider in self.controls.values():
            slider.observe(self._on_change, names="value")
        self._refresh(wait=True, raise_errors=True)

    # --- the public surface -----------------------------------------------------------------------------------
    def update(self, wait: bool = True, **values) -> Explorer:
        """Set the sliders named in `values` ({name: value in the slider's unit}) and recompute once; with `wait`,
        return when the figure is redrawn (a long scene's error is raised here). Unknown names raise `TypeError`,
        values outside a slider's range `ValueError` naming the slider and its range."""
        owner = f"explore('{self.scene.key}').update"
        unknown = sorted(set(values) - set(self.controls))
        if unknown:
            raise TypeError(f"{owner}: no slider named {unknown}; sliders: {list(self.controls)}")
        checked = {name: self._knobs[name].check(v, owner) for name, v in values.items()}
        self._quiet = True
        try:
            for name, v in checked.items():
                _set_slider(self.controls[name], self._knobs[name], v)
        finally:
            self._quiet = False
        self._refresh(wait=wait, raise_errors=True)
        return self

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until no background computation is in flight; False if `timeout` [s] passed first."""
        return self._idle.wait(timeout)

    @property
    def slider_values(self) -> dict[str, float]:
        """`{name: value}` of the sliders now."""
        return {name: float(s.value) for name, s in self.controls.items()}

    @property
    def widget(self):
        """The composed ipywidgets box, at most `WIDTH` px wide: the figure on top (it stays in place while the
        numbers below change height), then the sliders (and the scene's buttons) beside the key numbers and the
        status; the numbers' column wraps its text and moves below the sliders where the view is narrower."""
        if self._box is None:
            w = self._w
            if self._mode == "canvas":
                view = self.figure.canvas
            else:
                self._image = view = w.Image(
                    value=self._png(), format="png", layout=w.Layout(max_width="100%", height="auto")
                )
            left = w.VBox([*self.controls.values(), *self._extra], layout=w.Layout(flex="0 0 auto", width="410px"))
            right = w.VBox(
                [self._numbers, w.HBox([self._progress, self._status], layout=w.Layout(flex_flow="row wrap"))],
                layout=w.Layout(flex="1 1 300px", min_width="0"),
            )
            controls = w.HBox([left, right], layout=w.Layout(flex_flow="row wrap", width="100%"))
            self._box = w.VBox([view, controls], layout=w.Layout(max_width=f"{WIDTH}px", overflow="hidden"))
        return self._box

    def tune(self, wait: bool = True) -> Explorer:
        """Four-bar scene: run `jb.tune_pid` from the sliders' gains in the background and move the sliders to the
        tuned gains (dropped if a slider moves on first)."""
        if not isinstance(self.scene, _FourBar):
            raise TypeError(f"explore('{self.scene.key}'): `tune` is the four-bar scene's (PID gains)")
        scene = self.scene
        with self._lock:
            gen = self._generation
        job = scene.tune_job(self.slider_values)
        self._pending_numbers(gen)
        self._submit(gen, job, self._apply_tune, scene.busy_text)
        if wait:
            self.wait()
            err = self._errors.pop(gen, None)
            if err is not None:
                raise err
        return self

    def close(self) -> None:
        """Close the widgets and the figure's canvas."""
        for s in self.controls.values():
            s.close()
        for x in (self._box, self._image, self._numbers, self._status, self._progress, *self._extra):
            if x is not None:
                x.close()
        if self._mode == "canvas":
            import matplotlib.pyplot as plt

            plt.close(self.figure)

    def _repr_mimebundle_(self, include=None, exclude=None):
        bundle: dict[str, Any] = {}
        bundle.update(self.widget._repr_mimebundle_() or {})
        bundle["text/plain"] = self._display.text()
        bundle["image/png"] = base64.b64encode(self._png()).decode("ascii")
        return bundle

    def __repr__(self) -> str:
        return f"<jaxbelt Explorer {self.scene.key!r}: {', '.join(self.controls)}>"

    # --- computing and drawing --------------------------------------------------------------------------------
    def _on_change(self, change) -> None:
        if self._quiet:
            return
        self._refresh(wait=False, raise_errors=False)

    def _refresh(self, wait: bool, raise_errors: bool) -> None:
        with self._lock:
            self._generation += 1
            gen = self._generation
        values = self.slider_values
        if not self.scene.long:
            try:
                result = self.scene.compute(values)
            except Exception as e:
                self._show_error(e)
                if raise_errors:
                    raise
                return
            with self._lock:
                if gen == self._generation:
                    self._apply(result)
            return
        try:
            job = self.scene.job(values)  # inputs built and checked here: a bad value raises in the caller
        except Exception as e:
            self._show_error(e)
            if raise_errors:
                raise
            return
        self._pending_numbers(gen)
        self._submit(gen, job, self._apply, self.scene.busy_text)
        if wait:
            self.wait()
            err = self._errors.pop(gen, None)
            if err is not None and raise_errors:
                raise err

    def _submit(self, gen: int, job: Callable[[], Any], apply: Callable[[Any], None], text: str) -> None:
        with self._lock:
            if self._pending is not None:
                self.stats["skipped"] += 1
            self._pending = (gen, job, apply, text)
            self._idle.clear()
        _worker().submit(self)

    def _run_pending(self) -> None:
        """Run this explorer's pending computations (in the worker thread) until none is left, then mark it idle."""
        while True:
            with self._lock:
                item = self._pending
                self._pending = None
                if item is None:
                    self._busy(None)
                    self._idle.set()
                    return
                gen, job, apply, text = item
                self._busy(text)
            try:
                result, err = job(), None
            except Exception as e:
                result, err = None, e
            with self._lock:
                if gen != self._generation:
                    self.stats["dropped"] += 1
                    continue
                if err is not None:
                    self._errors = {gen: err}
                    self._show_error(err)
                    continue
                try:
                    apply(result)
                except Exception as e:
                    self._errors = {gen: e}
                    self._show_error(e)

    def _busy(self, text: str | None) -> None:
        if text is None:
            self._progress.layout.visibility = "hidden"
            self._progress.value = 1.0
            if self._status.value.startswith("<i>"):  # the busy text of a computation whose result was dropped
                self._status.value = ""
        else:
            self._progress.layout.visibility = "visible"
            self._progress.value = 0.5
            self._status.value = f"<i>{text}…</i>"

    def _apply(self, result: dict) -> None:
        scene = self.scene
        scene.draw(result)
        nums = scene.numbers(result)
        self.values = {k: v for k, _, v, _, _ in nums}
        self.units = {k: u for k, _, _, u, _ in nums}
        fields = tuple((label, _shown(v, u) if shown is None else shown, "") for _, label, v, u, shown in nums)
        self._display = Display(scene.title, fields, scene.tables(result), spec=SPEC)
        self._numbers.value = _wrapped(self._display.html())
        note = result.get("note") if isinstance(result, dict) else None
        self.error = ""
        self._status.value = "" if not note else _wrapped(f"<small>{_escape(note)}</small>")
        self.stats["computed"] += 1
        self._redraw()

    def _apply_tune(self, out) -> None:
        res, caught = out
        pid = res.pid
        gains = {"kp": float(pid.kp), "ki": float(pid.ki), "kd": float(pid.kd)}
        self._quiet = True
        try:
            for name, v in gains.items():
                k = self._knobs[name]
                if not k.lo <= v <= k.hi:  # widen the slider to hold the tuned gain
                    k = self._knobs[name] = dataclasses.replace(k, lo=min(k.lo, v), hi=max(k.hi, v))
                _set_slider(self.controls[name], k, v)  # range, grid and value in one message to the front-end
        finally:
            self._quiet = False
        self._generation += 1
        self._apply(self.scene.compute(self.slider_values))
        msg = (
            f"tune_pid: χ {100 * res.chi_initial:.4g} % → {100 * res.chi:.4g} % in {getattr(self.scene, 'tune_steps', '?')} Adam "
            f"steps ({res.status})"
        )
        if caught:
            msg += "; " + "; ".join(caught)
        self.values["tuned_chi"] = float(res.chi)
        self._status.value = _wrapped(f"<small>{_escape(msg)}</small>")

    def _pending_numbers(self, gen: int) -> None:
        """While the computation of generation `gen` runs in the background, no key number of earlier sliders is
        shown or returned: `values` become NaN and the numbers' panel is cleared until the result is drawn (the
        curves stay, under the busy indicator). A result of a later generation already drawn is left alone."""
        with self._lock:
            if gen != self._generation:
                return
            self.values = {k: math.nan for k in self.values}
            self._display = Display(self.scene.title)
            self._numbers.value = _wrapped(self._display.html())

    def _show_error(self, e: BaseException) -> None:
        """Show the error of a computation at the sliders' values, and no number from earlier values: the key numbers
        (`values`) become NaN, their display is cleared and the curves are emptied (the axes stay)."""
        from matplotlib.lines import Line2D

        self.error = f"{type(e).__name__}: {e}"
        self.values = {k: math.nan for k in self.values}
        self._display = Display(self.scene.title)
        self._numbers.value = _wrapped(self._display.html())
        self._status.value = _wrapped(f'<span style="color:#b00">{_escape(self.error)}</span>')
        for a in getattr(self.scene, "dynamic", ()):
            if isinstance(a, Line2D):
                a.set_data([], [])
        self._redraw()

    def _redraw(self) -> None:
        """Redraw the figure in place: on ipympl's canvas `draw_idle()` (it renders and sends the image); on the Agg
        canvas of an image view, render and send the PNG. A figure no view shows yet (headless: tests, scripts) is
        left stale with its new data, and renders when drawn or saved (`figure.canvas.draw()`, `savefig`)."""
        if self._mode == "canvas":
            self.figure.canvas.draw_idle()
        elif self._image is not None:
            self.figure.canvas.draw()
            self._image.value = self._png(drawn=True)
        else:
            self.figure.stale = True

    def _png(self, drawn: bool = False) -> bytes:
        """The figure as PNG bytes (from the Agg buffer when it was just drawn: no second rendering)."""
        canvas: Any = self.figure.canvas
        if self._mode == "image" and drawn:
            from matplotlib.image import imsave

            buf = io.BytesIO()  # matplotlib's own PNG writer (through Pillow, which matplotlib requires)
            imsave(buf, np.asarray(canvas.buffer_rgba()), format="png", pil_kwargs={"compress_level": 1})
            return buf.getvalue()
        buf = io.BytesIO()
        self.figure.savefig(buf, format="png")
        return buf.getvalue()


#: the widest a view is laid out [px] (a notebook's output area of a 1000 px window holds it: no horizontal scrollbar)
WIDTH = 960

#: the format of the numbers a view shows (3-4 significant digits: what a slider's readout resolves)
SPEC = ".4g"


def _shown(value, unit: str) -> str:
    """A key number as the view shows it: `SPEC` digits (each element of a sequence) and its unit."""
    if isinstance(value, str):
        text = value
    elif isinstance(value, tuple | list | np.ndarray) and np.ndim(value) > 0:
        text = fmt_list(value, SPEC) if np.size(value) else "none"
    else:
        text = fmt(value, SPEC)
    return text + (f" {unit}" if unit and unit not in ("-", "–") and text not in ("–", "none") else "")


def _wrapped(html: str) -> str:
    """`html` in a block whose text wraps (an ipywidgets `HTML` keeps a line unbroken by default)."""
    return f'<div style="white-space:normal;overflow-wrap:anywhere">{html}</div>'


def _escape(text: str) -> str:
    import html

    return html.escape(text)


def explore(scene_or_model="startup", **options) -> Explorer:
    """A live view of a scene: sliders for its parameters, its figure redrawn in place, its key numbers beside it.

    `scene_or_model`: a scene name, `"startup"`, `"fourbar"`, `"shaping"`, `"spans"`, `"nonlinear"` or `"axis"`;
    or the object to start from, whose values centre the sliders: a `BeltStartup` or `ExponentialVoltage`
    (start-up, Incerti, 2014), a `FourBarDrive` or `PID` (four-bar + PID, Incerti, 2012), a `BeltPlatform` or
    `PseudoPolynomial` (pseudo-polynomial commands, Incerti), a `MovingString` (belt spans, belt-vibration report),
    a `NonlinearBelt` (Moon & Wickert, 1997), a `ModalAxis` (`design_move`), or a `Scene` of the first two.

    Options (each scene takes its own; `ranges={slider: (lo, hi)}` in every scene, checked against the parameter's
    declared valid values):

    - startup: `t_end` [s] (0.5), `n_points` (501);
    - fourbar: `window` (t0, t1) [s] of χ (0.375, 0.5), `t_end` [s], `n_points`, `tune_steps` (20) of the
      "tune PID" button (`Explorer.tune`, `jb.tune_pid`);
    - shaping: `command` (a `PseudoPolynomial`, default exponents 3, 4, 5), `t_end` [s] (1.5 T), `n_points`;
    - spans: `pulley_radius` $R_U$ [m] (0.1166), `n_modes` (3), `harmonics` (3), `speed_ratio` $V/V_{cr}$ (0.3);
    - nonlinear: `speed_range` (v0, v1) [m/s] (0.9-1.26 x the first linear crossing), `n_harmonics` (3),
      `max_points` (200);
    - axis: `distance` [m] (0.1), `move_time` [s] (0.8), `v_max` [m/s] (0.3), `a_max` [m/s²] (1.2), `uncertainty`
      (0.2), `include` (minimax, ZV, ZVD, EI, unshaped).

    Returns an `Explorer` (`.controls`, `.figure`, `.values`, `.update(**values)`); in a notebook, make it the
    cell's value to show it. Needs ipywidgets (`pip install 'jaxbelt[notebook]'`).
    """
    _widgets()  # the clear ImportError first
    if isinstance(scene_or_model, str):
        key = _ALIASES.get(scene_or_model, scene_or_model)
        if key not in _SCENES:
            raise ValueError(f"explore: unknown scene {scene_or_model!r}; scenes: {sorted(_SCENES)}")
        start = None
    else:
        key, start = _scene_key(scene_or_model), scene_or_model
    cls: Any = _SCENES[key]
    _options(f"explore('{key}')", options, cls.OPTIONS)
    scene = cls(start, **options)
    return Explorer(scene)
