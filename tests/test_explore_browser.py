"""`jb.explore` as a browser drives it: the sliders' comm messages of ipywidgets 8, both ways.

A stand-in front-end (`FrontEnd`) receives what the kernel sends each slider (its comm's `update` messages) and does
what the browser's slider view does with it (ipywidgets 8's `FloatSliderView` / `FloatLogSliderView` on noUiSlider
15): it snaps the value to the grid `min + k step` (in percent of the range, JavaScript's `Math.round`, as
noUiSlider computes) and, when that changes the value, sends the snapped value back as a front-end `update`
(through the widget's `_handle_msg`, as the kernel's comm handler does). It reproduces the numbers measured in
JupyterLab in headless Chromium before the fix (Kp 80.40, Ki 32.16, ω 29.91 on the four-bar's old grids).

What is checked: opening a view changes no slider and no number; a drag (one step on the browser's grid) reaches
the view with the browser's exact value; the tune button pressed from the browser (a `custom` click message) moves
every gain to the tuned one (`jb.tune_pid` run headless at the same start) and its message stays; a slider set to
NaN leaves no number of the previous values.
"""

import itertools
import math

import numpy as np
import pytest

import jaxbelt as jb

pytest.importorskip("ipywidgets")


def _js_round(x: float) -> float:
    """JavaScript's `Math.round` (halves up)."""
    return math.floor(x + 0.5)


def nouislider_snap(value: float, lo: float, hi: float, step: float) -> float:
    """The value noUiSlider 15 holds after `set(value)` on the range `[lo, hi]` with `step` (`toStepping`, `getStep`,
    `limit`, `fromStepping` of its `Spectrum`, one sub-range)."""
    if value >= hi:
        pct = 100.0
    else:
        offset = value + abs(lo) if lo < 0 else value - lo
        pct = (offset * 100 / (hi - lo)) / (100 / (100 - 0))
        xs = (step * 100 / (hi - lo)) / (100 / (100 - 0))
        pct = 0 + _js_round((pct - 0) / xs) * xs
    pct = max(min(pct, 100.0), 0.0)
    if pct >= 100:
        return hi
    return (pct * (hi - lo)) / 100 + lo


def browser_value(state: dict) -> float:
    """The value a browser's slider view holds and sends for a model `state` (a `FloatLogSlider`: the exponent is
    snapped, `Math.log(v) / Math.log(base)` clamped to the range, and `base ** x` sent)."""
    if state["_model_name"] == "FloatLogSliderModel":
        base = state["base"]
        x = min(max(math.log(state["value"]) / math.log(base), state["min"]), state["max"])
        return base ** nouislider_snap(x, state["min"], state["max"], state["step"])
    return nouislider_snap(state["value"], state["min"], state["max"], state["step"])


class _Comm:
    """A slider's comm to the stand-in front-end."""

    kernel = True
    _ids = itertools.count()

    def __init__(self, front, widget):
        self.front, self.widget, self.comm_id = front, widget, f"fake-{next(self._ids)}"

    def on_msg(self, callback):
        pass

    def send(self, data=None, buffers=None, **kw):
        self.front.receive(self.widget, data)

    def close(self, *a, **kw):
        pass


class FrontEnd:
    """The browser's side of an explorer's sliders: their models' state, the messages each way."""

    def __init__(self, explorer):
        self.sliders = list(explorer.controls.values())
        self.state: dict = {}
        self.outbox: list = []  # (widget, state) from the front-end, delivered by `deliver`
        self.received: list = []  # (widget, state) of the kernel's `update` messages
        self.ranges: dict = {}  # the range each slider view holds now
        for s in self.sliders:
            s.comm = _Comm(self, s)

    def open(self):
        """Show the view: each slider's model is made from the kernel's state and its view rendered."""
        for s in self.sliders:
            self.state[s] = dict(s.get_state())
            self._render(s)

    def _render(self, s):
        st = self.state[s]
        self.ranges[s] = {k: st[k] for k in ("min", "max", "step")}
        value = browser_value(st)
        if value != st["value"]:  # the view's `model.set('value', snapped)` + `touch()`: a change is sent
            st["value"] = value
            self.outbox.append((s, {"value": value}))

    def receive(self, widget, data):
        """A kernel's `update`: the model takes every key at once, then its change handlers run in the keys' order
        (Backbone): a range key re-creates the slider's range at the model's value; `value` moves the slider within
        the range it has then (a value ahead of its new range is clamped to the old one)."""
        if data.get("method") != "update" or widget not in self.state:
            return  # an `echo_update` repeats what this front-end sent
        self.received.append((widget, dict(data["state"])))
        st = self.state[widget]
        shown = self.ranges.get(widget, {k: st[k] for k in ("min", "max", "step")})
        st.update(data["state"])
        for key in data["state"]:
            if key in ("min", "max", "step"):
                shown = self.ranges[widget] = {k: st[k] for k in ("min", "max", "step")}
            if key in ("min", "max", "step", "value"):
                value = browser_value({**st, **shown})
                if value != st["value"]:
                    st["value"] = value
                    self.outbox.append((widget, {"value": value}))

    def drag(self, s, steps: int):
        """Move a slider by `steps` steps of the browser's grid (as the arrow keys do) and send the value."""
        st = self.state[s]
        if st["_model_name"] == "FloatLogSliderModel":
            x = math.log(st["value"]) / math.log(st["base"]) + steps * st["step"]
            value = st["base"] ** nouislider_snap(x, st["min"], st["max"], st["step"])
        else:
            value = nouislider_snap(st["value"] + steps * st["step"], st["min"], st["max"], st["step"])
        st["value"] = value
        self.outbox.append((s, {"value": value}))
        return value

    def deliver(self):
        """Hand the front-end's messages to the kernel (the comm handler calls the widget's `_handle_msg`)."""
        while self.outbox:
            s, state = self.outbox.pop(0)
            s._handle_msg(
                {"content": {"data": {"method": "update", "state": state, "buffer_paths": []}}, "buffers": []}
            )


def _click(button):
    button._handle_msg({"content": {"data": {"method": "custom", "content": {"event": "click"}}}, "buffers": []})


def test_the_stand_in_front_end_snaps_as_the_browser_did():
    """Before the fix the four-bar's sliders had the grid (hi - lo) / 200 from lo: JupyterLab in headless Chromium
    showed Kp 80.40, Ki 32.16 and ω 29.91 for 80, 32 and 30; the stand-in gives the same."""
    assert nouislider_snap(80.0, 0.0, 240.0, 240.0 / 200) == pytest.approx(80.40, abs=1e-12)
    assert nouislider_snap(32.0, 0.0, 96.0, 96.0 / 200) == pytest.approx(32.16, abs=1e-12)
    assert nouislider_snap(30.0, 9.0, 60.0, 51.0 / 200) == pytest.approx(29.91, abs=1e-12)


@pytest.mark.parametrize("scene", ["startup", "fourbar", pytest.param("shaping", marks=pytest.mark.slow), "spans"])
def test_opening_a_view_changes_no_slider_and_no_number(scene):
    ex = jb.explore(scene)
    sliders, values, computed = dict(ex.slider_values), dict(ex.values), ex.stats["computed"]
    front = FrontEnd(ex)
    front.open()
    for s in front.sliders:  # the browser shows the start: it lies on the grid (to rounding)
        assert front.state[s]["value"] == pytest.approx(s.value, rel=1e-12, abs=1e-300)
    front.deliver()
    assert ex.slider_values == sliders  # exactly: a rounding echo is no move
    assert ex.stats["computed"] == computed and not ex.error
    for k, v in values.items():
        np.testing.assert_array_equal(ex.values[k], v)
    # a drag of one step in the browser reaches the view with the browser's value, and its echo changes nothing more
    s = front.sliders[0]
    name = next(n for n, c in ex.controls.items() if c is s)
    moved = front.drag(s, 1)
    front.deliver()
    assert ex.slider_values[name] == moved and ex.stats["computed"] == computed + 1
    assert abs(moved - sliders[name]) > 0.5 * abs(s.step if scene != "startup" else moved - sliders[name])
    ref = jb.explore(scene).update(**{name: moved})
    for k, v in ref.values.items():
        np.testing.assert_array_equal(ex.values[k], v)


@pytest.mark.slow
def test_the_tune_button_pressed_in_the_browser_moves_every_gain():
    steps = 3
    ex = jb.explore("fourbar", tune_steps=steps, ranges={"kd": (0.0, 0.016)})
    front = FrontEnd(ex)
    front.open()
    front.deliver()
    start = ex.scene.pid_of(ex.slider_values)
    _click(ex._extra[0])  # the button's click, as the browser sends it
    assert ex.wait(300)
    front.deliver()  # what the browser sends back on receiving the tuned gains
    ref = jb.tune_pid(jb.FourBarDrive(), start, 0.375, 0.5, steps=steps, progress=False)
    tuned = {"kp": float(ref.pid.kp), "ki": float(ref.pid.ki), "kd": float(ref.pid.kd)}
    assert tuned["kd"] > ex.scene.knobs[2].hi  # the tuned Kd lies beyond the slider's first range: it widens
    for name, v in tuned.items():
        assert ex.slider_values[name] == v  # the kernel's value: exactly the tuned gain
        st = front.state[ex.controls[name]]
        assert st["value"] == pytest.approx(v, rel=1e-12) and st["max"] >= v  # the browser's: the same, in range
    # each gain reached the browser as one message (range, grid and value together)
    kd_msgs = [m for w, m in front.received if w is ex.controls["kd"]]
    assert kd_msgs and {"value", "max", "step"} <= set(kd_msgs[-1]) and list(kd_msgs[-1])[-1] == "value"
    ts = np.linspace(0.0, 0.5, 1001)  # the view's grid: chi (eq. 22) at the tuned gains, by the library
    sol = jb.simulate(jb.Scene(jb.FourBarDrive(), ref.pid, ts=ts, observe=("motor_speed", "voltage")))
    assert ex.values["chi"] == pytest.approx(float(jb.fluctuation_index(sol, 0.375, 0.5)), rel=1e-10)
    assert ex.values["tuned_chi"] == float(ref.chi)
    assert "tune_pid: χ" in ex._status.value and f"in {steps} Adam steps" in ex._status.value


def test_a_nan_slider_leaves_no_old_number():
    ex = jb.explore("fourbar")
    chi = ex.values["chi"]
    ex.controls["kp"].value = float("nan")  # set from code: the observer recomputes and fails
    assert "kp" in ex.error
    assert ex.values.keys() == {"chi", "peak_voltage", "peak_current"}
    assert all(math.isnan(v) for v in ex.values.values())
    assert len(ex.scene.l_speed.get_xdata()) == 0  # the curves are emptied too
    ex.controls["kp"].value = 80.0
    assert not ex.error and ex.values["chi"] == chi


def test_numbers_show_four_digits_with_their_units():
    """The non-linear view's fold speeds, speed range (m/s) and peak-to-peak (mm, as its plot) with their units, at
    4 significant digits; a long note in a table wraps (its cell's style) instead of widening the view."""
    from jaxbelt._display import Display, Table
    from jaxbelt.explorer._nonlinear import _Nonlinear
    from jaxbelt.explorer._view import _shown

    scene = _Nonlinear()
    r = dict(
        folds=np.array([7.512345678, 8.0987654321]),
        pp=np.array([0.001234567, 0.0045678912]),
        range=(7.1234567, 9.87654),
    )
    shown = {k: _shown(v, u) if s is None else s for k, _, v, u, s in scene.numbers(r)}
    assert shown == {"folds": "7.512, 8.099 m/s", "max_pp": "4.568 mm", "speed_range": "7.123, 9.877 m/s"}
    assert _shown((), "m/s") == "none" and _shown(math.nan, "m/s") == "–"
    assert scene.knobs[1].label == "v_l = c/v_t"
    html = Display("t", tables=(Table(("note",), (("a note " * 30,),)),), spec=".4g").html()
    assert "white-space:normal" in html and "max-width:32em" in html
