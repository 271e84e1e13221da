"""Live exploration in a notebook: `explore(scene_or_model, **options)`, sliders on a scene's figure.

A controls engineer who opens a notebook drags a stiffness, a PID gain, an exponent or a mode frequency and
sees the curves move. `explore` builds that view for each of jaxbelt's scenes (the extra `jaxbelt[notebook]`,
which brings ipywidgets):

| scene | start from | sliders | curves | key numbers |
|---|---|---|---|---|
| `"startup"` (Incerti, 2014) | `BeltStartup`, a `Scene` | $k$, $c$, $J_2$, $\\gamma$, $V_{max}$ | current, pulley speeds, acceleration | peak current, final speed, belt mode |
| `"fourbar"` (Incerti, 2012) | `FourBarDrive`, `PID`, a `Scene` | $K_p$, $K_i$, $K_d$, $\\omega_0$ | motor speed, voltage, current | χ (eq. 22), peak voltage and current |
| `"shaping"` (Incerti, pseudo-polynomial) | `BeltPlatform`, `PseudoPolynomial` | $\\gamma_i$, $k$, $c$ | command and platform accelerations | $\\mathcal H$, $E(T)$, one L-BFGS step |
| `"spans"` (belt-vibration report) | `MovingString` | $T$, $\\rho$, $L$, $R_U$, $V/V_{cr}$ | $f_n(V)$ with pulley harmonics, mode 1 | $V_{cr}$, $f_n$ at $V$, exciting speeds |
| `"nonlinear"` (Moon & Wickert, 1997) | `NonlinearBelt` | $v_t$, $v_l$, $\\xi_1$ | response curve (stable, unstable) | fold speeds |
| `"axis"` (`design_move`) | `ModalAxis` | $f_i$, $\\zeta_i$, $T$ | residual % over frequency, accelerations | worst residual, recommendation |

The numbers are the library's own: each view calls the public functions (`simulate`, `fluctuation_index`,
`residual_energy`, `optimise_command`, `MovingString.natural_frequencies`, `exciting_speeds`, `response_curve`,
`design_move`, `tune_pid`). Slider ranges and units come from the parameters' declarations (`jaxbelt._params`):
the unit and the valid range of each model field, around the value the view starts from.

**Fast scenes** (start-up, four-bar χ, $\\mathcal H$ with one optimisation step, span frequencies) call the
library's compiled programs with the slider values as data (arrays): a new value compiles nothing (what the views
derive besides, the start-up's system matrix, the commands' accelerations, the span's arrays, are `jax.jit` programs
of this module with the values as traced arguments). The figure is redrawn in
place, by changing its lines' data (`Line2D.set_data`), never rebuilt; its canvas (`CachedAggCanvas`) keeps the
rendering of the axes, ticks and labels and renders only the curves over it while the axes' limits hold (the limits
follow the data stickily, `_fit`), since text is most of a full rendering's time. With ipympl (`%matplotlib widget`)
the figure is ipympl's canvas and `draw_idle()` redraws it. **Long scenes** (a `design_move`, a `response_curve`
continuation, a `tune_pid` run) compute in one background thread (kept for the process: a program's first call in a
new thread costs more) behind a progress indicator; a slider that moves on makes the computation in flight stale (its
result is dropped when it ends) and replaces the request queued behind it. (A `design_move` compiles again when a
frequency or the move time crosses one of its problem sizes: its frequency grid grows with $f\\,u\\,T$; a damping
ratio never does.)

`Explorer.update(**values)` sets sliders from code (what the tests and the benchmark do) and waits for the figure.

**In a browser** (ipywidgets 8 on noUiSlider) a slider snaps its value to its grid `min + k step` when shown and
sends the snapped value back. Each slider's grid holds the value it starts from (`_grid`), a value set from code
moves the grid to hold it and reaches the front-end as one message (`_set_slider`: range, step and value together),
and a value the front-end sends within half a step of the slider's is a rounding, ignored (`_slider_class`): opening a
view changes no number, and the tuned gains reach the browser as they are. Numbers show 4 significant digits (`SPEC`)
with their units; a failed computation leaves `values` NaN (no number from earlier values).
"""

from __future__ import annotations

import base64
import dataclasses
import importlib
import io
import math
import threading
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ._display import Display, Table, fmt, fmt_list, with_unit

__all__ = ["Explorer", "Knob", "explore"]

#: what `explore` says when ipywidgets is missing
MISSING_WIDGETS = "jb.explore needs ipywidgets: pip install 'jaxbelt[notebook]'"


def _widgets():
    """The ipywidgets module, or the `ImportError` that names the extra installing it."""
    try:  # an optional package (the notebook extra), imported as pandas and xarray are (`jaxbelt._display`)
        return importlib.import_module("ipywidgets")
    except ImportError as e:
        raise ImportError(MISSING_WIDGETS) from e


# --------------------------------------------------------------------------------------------------------------
# Sliders from the parameter declarations
# --------------------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Knob:
    """One slider: `name` (the key of `Explorer.controls` and `Explorer.update`), its `label`, `unit`, range
    `[lo, hi]` in that unit, start `value`, `log` (a logarithmic slider), `doc` (the parameter's meaning) and
    `valid`, the values the parameter's declaration allows (what the option `ranges` is checked against)."""

    name: str
    label: str
    unit: str
    lo: float
    hi: float
    value: float
    log: bool = False
    doc: str = ""
    valid: tuple[float, float, bool] = (-math.inf, math.inf, False)  # (lowest, highest, lowest excluded) allowed

    def check(self, value, owner: str) -> float:
        """`value` as a float, or a `ValueError` naming the slider and its range."""
        unit = f" {self.unit}" if self.unit and self.unit not in ("-", "–") else ""
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise TypeError(
                f"{owner}: parameter `{self.name}` must be a real number{f' [{self.unit}]' if unit else ''}; got {value!r}"
            ) from None
        if not (self.lo <= v <= self.hi):  # NaN fails too
            raise ValueError(
                f"{owner}: parameter `{self.name}` must lie in [{self.lo:.6g}, {self.hi:.6g}]{unit} (the slider's "
                f"range; pass `ranges={{'{self.name}': (lo, hi)}}` to `explore` for another); got {v!r}"
            )
        return v


def _interval(valid: tuple[float, float, bool]) -> str:
    """`(lo, hi]`-style text of a `(lowest, highest, lowest excluded)` triple (an infinite end is open)."""
    lo, hi, open_lo = valid
    return f"{'(' if open_lo or math.isinf(lo) else '['}{lo:g}, {hi:g}{')' if math.isinf(hi) else ']'}"


def _bounds_of(p) -> tuple[float, float, bool]:
    """`(lowest, highest, lowest excluded)` that a declared parameter `p` (a `jaxbelt._params.Param`) allows."""
    if p.check == "positive":
        return 0.0, math.inf, True
    if p.check == "nonnegative":
        return 0.0, math.inf, False
    if p.check == "range":
        lo = -math.inf if p.lo is None else float(p.lo)
        hi = math.inf if p.hi is None else float(p.hi)
        if p.hi_open and math.isfinite(hi):
            hi = hi - 1e-6 * max(abs(hi), 1.0)
        return lo, hi, bool(p.lo_open)
    return -math.inf, math.inf, False


#: the memory a view may take per output time [bytes]: its curves and the solver's saved states, with room for the
#: intermediate arrays (measured: 136 bytes per point for the start-up's closed form, more for the ODE scenes)
BYTES_PER_POINT = 2048


def max_points() -> int:
    """The most output times a view takes: those whose arrays (`BYTES_PER_POINT` each) fit in a quarter of this
    machine's memory (1e7 where the memory cannot be read)."""
    import os

    try:
        memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return 10**7
    return max(int(memory // 4 // BYTES_PER_POINT), 1000)


def _time_grid(owner: str, t_end: float, n_points, least: int = 2):
    """The view's output times `(ts on the device, t on the host)`: `n_points` (an integer in [`least`,
    `max_points()`]: refused before anything is allocated) equally spaced from 0 to `t_end` [s] (checked by the
    caller)."""
    if isinstance(n_points, bool) or not isinstance(n_points, int | np.integer) or n_points < least:
        raise ValueError(f"{owner}: option `n_points` must be an integer >= {least}; got {n_points!r}")
    most = max_points()
    if n_points > most:
        raise ValueError(
            f"{owner}: option `n_points` must lie in [{least}, {most}] (the output times whose arrays fit in a quarter "
            f"of this machine's memory, {BYTES_PER_POINT} bytes each; a figure shows a few thousand); got {n_points!r}"
        )
    import jax

    ts = jax.device_put(np.linspace(0.0, t_end, int(n_points)))
    return ts, np.asarray(ts)


def _declared_knob(
    cls,
    field: str,
    value: float,
    label: str,
    *,
    factors: tuple[float, float] = (0.25, 4.0),
    lo: float | None = None,
    hi: float | None = None,
    log: bool = False,
    name: str | None = None,
) -> Knob:
    """A slider for the declared parameter `field` of `cls`: its unit and meaning from the declaration, its range
    `value` x `factors` (or `lo`, `hi`) within the values the declaration allows."""
    from ._params import declared

    p, _ = declared(cls)[field]
    return _knob(name or field, label, p.unit, value, p, factors=factors, lo=lo, hi=hi, log=log, doc=p.doc)


def _knob(
    name, label, unit, value, p=None, *, factors=(0.25, 4.0), lo=None, hi=None, log=False, doc="", valid=None
) -> Knob:
    """A slider over `value` x `factors` (or `[lo, hi]`), within the values the declaration `p` (or `valid`, a
    `(lowest, highest, lowest excluded)` triple) allows."""
    value = float(value)
    lo = value * factors[0] if lo is None else float(lo)
    hi = value * factors[1] if hi is None else float(hi)
    if lo > hi:
        lo, hi = hi, lo
    valid = _bounds_of(p) if p is not None else (valid or (-math.inf, math.inf, False))
    dlo, dhi, open_lo = valid
    if not ((value > dlo if open_lo else value >= dlo) and value <= dhi):
        units = f" {unit}" if unit and unit not in ("-", "–") else ""
        raise ValueError(f"explore: parameter `{name}` must lie in {_interval(valid)}{units}; got {value}")
    if open_lo and lo <= dlo:
        lo = dlo + 1e-3 * (hi - dlo if math.isfinite(hi) else 1.0)
    lo, hi = max(lo, dlo), min(hi, dhi)
    lo, hi = min(lo, value), max(hi, value)
    if log and not lo > 0:
        raise ValueError(f"explore: the logarithmic slider `{name}` needs a positive range; got [{lo}, {hi}]")
    if not hi > lo:
        hi = lo + (abs(lo) or 1.0)
    return Knob(name, label, unit, lo, hi, value, log, doc, valid)


def _with_ranges(knobs: list[Knob], ranges, owner: str) -> list[Knob]:
    """`knobs` with the ranges of the option `ranges` ({name: (lo, hi)}), checked against the declarations."""
    if not ranges:
        return knobs
    if not isinstance(ranges, dict):
        raise TypeError(f"{owner}: option `ranges` must be a dict {{slider name: (lo, hi)}}; got {ranges!r}")
    names = [k.name for k in knobs]
    out = []
    for k in knobs:
        if k.name not in ranges:
            out.append(k)
            continue
        r = ranges[k.name]
        try:
            lo, hi = (float(x) for x in r)
        except (TypeError, ValueError):
            raise ValueError(f"{owner}: `ranges[{k.name!r}]` must be a pair (lo, hi) of numbers; got {r!r}") from None
        dlo, dhi, open_lo = k.valid
        unit = f" {k.unit}" if k.unit and k.unit not in ("-", "–") else ""
        valid = _interval(k.valid)
        if not (lo < hi and (lo > dlo if open_lo else lo >= dlo) and hi <= dhi and math.isfinite(lo + hi)):
            raise ValueError(
                f"{owner}: `ranges[{k.name!r}]` must be (lo, hi) with lo < hi inside the valid values {valid}{unit} "
                f"of parameter `{k.name}`; got {(lo, hi)}"
            )
        if k.log and not lo > 0:
            raise ValueError(f"{owner}: `ranges[{k.name!r}]` is a logarithmic slider: lo must be > 0; got {lo}")
        out.append(dataclasses.replace(k, lo=lo, hi=hi, value=min(max(k.value, lo), hi)))
    unknown = sorted(set(ranges) - set(names))
    if unknown:
        raise ValueError(f"{owner}: `ranges` names no slider {unknown}; sliders: {names}")
    return out


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


def _options(owner: str, given: dict, allowed: Sequence[str]) -> None:
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise TypeError(f"{owner}: unknown option(s) {unknown}; options: {sorted(allowed)}")


def _host(tree):
    """A pytree of device arrays as numpy arrays (one transfer)."""
    import jax

    return jax.tree_util.tree_map(np.asarray, jax.device_get(tree))


# --------------------------------------------------------------------------------------------------------------
# The scenes: what each computes and draws
# --------------------------------------------------------------------------------------------------------------
class _Scene:
    """One scene's view: its sliders (`knobs`), what a set of values computes (`compute`, returning host arrays and
    numbers), the figure's artists (`build`) and how a result redraws them (`draw`), and its key numbers."""

    key = ""
    title = ""
    long = False  # computed in the background thread
    busy_text = "computing"
    figsize = (10.5, 3.1)
    knobs: list[Knob]

    def build(self, fig) -> None:
        raise NotImplementedError

    def compute(self, v: dict) -> dict:
        raise NotImplementedError

    def job(self, v: dict) -> Callable[[], dict]:
        """The computation at the values `v` as a callable for the background thread (a long scene builds and
        checks its inputs here, in the caller's thread, and computes in the callable)."""
        return lambda: self.compute(v)

    def draw(self, r: dict) -> None:
        raise NotImplementedError

    def numbers(self, r: dict) -> list[tuple]:
        """`[(key, label, value, unit, shown)]`: `value` goes to `Explorer.values[key]`; `shown` (or the value)
        to the display."""
        raise NotImplementedError

    def tables(self, r: dict) -> tuple:
        return ()

    def extra_controls(self, explorer: Explorer, w) -> list:
        return []


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


# --- start-up of a belt drive (Incerti, 2014) -----------------------------------------------------------------
_PROGRAMS: dict = {}


def _program(name: str, impl: Callable):
    """The module's one jitted program for `name` (made on first use: JAX is imported by the first explorer)."""
    prog = _PROGRAMS.get(name)
    if prog is None:
        import jax

        prog = _PROGRAMS[name] = jax.jit(impl)
    return prog


def _system_matrix(model):
    return model.matrices()[0]


class _Startup(_Scene):
    key = "startup"
    title = "Start-up of a belt drive driven by a DC motor (Incerti, 2014)"
    OPTIONS = ("t_end", "n_points", "ranges")

    def __init__(self, start=None, t_end: float = 0.5, n_points: int = 501, ranges=None):
        from .commands import ExponentialVoltage
        from .models.startup import BeltStartup
        from .scene import Scene

        o = "explore('startup')"
        model, cmd = BeltStartup(), ExponentialVoltage(24.0, 0.02)
        if isinstance(start, Scene):
            model, cmd = start.model, start.input
            if start.ts is not None:
                ts = np.asarray(start.ts, dtype=float)
                t_end, n_points = float(ts[-1]), int(ts.size)
        elif isinstance(start, BeltStartup):
            model = start
        elif isinstance(start, ExponentialVoltage):
            cmd = start
        elif start is not None:
            raise TypeError(f"{o}: start from a BeltStartup, an ExponentialVoltage or a Scene of them; got {start!r}")
        if not isinstance(model, BeltStartup) or not isinstance(cmd, ExponentialVoltage) or np.ndim(cmd.gamma) != 0:
            raise TypeError(
                f"{o}: the scene must be a BeltStartup driven by an ExponentialVoltage of one time constant"
            )
        t_end = float(t_end)
        if not (math.isfinite(t_end) and t_end > 0):
            raise ValueError(f"{o}: option `t_end` (s) must be > 0; got {t_end}")
        self.ts, self.t = _time_grid(o, t_end, n_points)
        self.model, self.cmd = model, cmd
        import jax

        m = jax.device_get(model)
        knobs = [
            _declared_knob(BeltStartup, "k", m.k, "k", factors=(0.1, 10.0), log=True),
            _declared_knob(BeltStartup, "c", m.c, "c", lo=0.0, hi=5.0 * float(m.c) or 100.0),
            _declared_knob(BeltStartup, "j2", m.j2, "J₂", factors=(0.2, 5.0), log=True),
            _declared_knob(ExponentialVoltage, "gamma", float(cmd.gamma), "γ", lo=1e-3, hi=max(0.2, float(cmd.gamma))),
            _declared_knob(ExponentialVoltage, "v_max", float(cmd.v_max), "V_max", factors=(0.1, 2.5)),
        ]
        self.knobs = _with_ranges(knobs, ranges, o)

    def model_and_input(self, v: dict):
        """The `BeltStartup` and `ExponentialVoltage` of the slider values `v` (checked at construction)."""
        from .commands import ExponentialVoltage

        model = dataclasses.replace(self.model, k=v["k"], c=v["c"], j2=v["j2"])
        return model, ExponentialVoltage(v["v_max"], v["gamma"])

    def compute(self, v):
        from .scene import Scene
        from .solve import simulate

        model, cmd = self.model_and_input(v)
        sol = simulate(Scene(model, cmd, ts=self.ts, observe=("alpha2",)))  # closed form (matrix exponential)
        r = _host({k: sol[k] for k in ("current", "omega1", "omega2", "alpha2")})
        A = np.asarray(_program("startup_A", _system_matrix)(model))
        r["f"] = float(np.max(np.abs(np.linalg.eigvals(A).imag))) / (2 * np.pi)  # the belt's torsional mode
        return r

    def build(self, fig):
        axes = fig.subplots(1, 3)
        self.axes = axes
        (self.l_current,) = axes[0].plot([], [], color="C0")
        (self.l_w1,) = axes[1].plot([], [], color="C0", label="pulley 1")
        (self.l_w2,) = axes[1].plot([], [], color="C1", label="pulley 2")
        legend = axes[1].legend(loc="lower right", fontsize=9)
        (self.l_a2,) = axes[2].plot([], [], color="C1")
        self.dynamic = [self.l_current, self.l_w1, self.l_w2, legend, self.l_a2]
        for ax, label in zip(axes, ("current I [A]", "speeds θ̇1, θ̇2 [rad/s]", "pulley 2 acceleration θ̈2 [rad/s²]")):
            _style(ax, "time t [s]", label)
            ax.set_xlim(self.t[0], self.t[-1])

    def draw(self, r):
        t = self.t
        self.l_current.set_data(t, r["current"])
        self.l_w1.set_data(t, r["omega1"])
        self.l_w2.set_data(t, r["omega2"])
        self.l_a2.set_data(t, r["alpha2"])
        _fit(self.axes[0], r["current"])
        _fit(self.axes[1], r["omega1"], r["omega2"])
        _fit(self.axes[2], r["alpha2"])

    def numbers(self, r):
        return [
            ("peak_current", "peak current", float(np.max(np.abs(r["current"]))), "A", None),
            ("final_omega2", f"pulley 2 speed at {self.t[-1]:g} s", float(r["omega2"][-1]), "rad/s", None),
            ("peak_alpha2", "peak |θ̈2|", float(np.max(np.abs(r["alpha2"]))), "rad/s²", None),
            ("belt_mode", "belt mode (eigenvalues of A)", float(r["f"]), "Hz", None),
        ]


# --- four-bar linkage under PID speed control (Incerti, 2012) ---------------------------------------------------
class _FourBar(_Scene):
    key = "fourbar"
    title = "Four-bar linkage driven by a PID-controlled DC motor (Incerti, 2012)"
    busy_text = "tuning the PID (tune_pid)"
    OPTIONS = ("window", "t_end", "n_points", "tune_steps", "ranges")

    def __init__(self, start=None, window=(0.375, 0.5), t_end=None, n_points=None, tune_steps: int = 20, ranges=None):
        from .models.fourbar import FourBarDrive
        from .models.motor import PID
        from .scene import Scene

        o = "explore('fourbar')"
        drive, pid = FourBarDrive(), PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0)
        if isinstance(start, Scene):
            drive, pid = start.model, start.input
        elif isinstance(start, FourBarDrive):
            drive = start
        elif isinstance(start, PID):
            pid = start
        elif start is not None:
            raise TypeError(f"{o}: start from a FourBarDrive, a PID or a Scene of them; got {start!r}")
        if not isinstance(drive, FourBarDrive) or not isinstance(pid, PID):
            raise TypeError(f"{o}: the scene must be a FourBarDrive under a PID speed regulator")
        try:
            t0, t1 = (float(x) for x in window)
        except (TypeError, ValueError):
            raise ValueError(f"{o}: option `window` must be (t0, t1) in s; got {window!r}") from None
        if not (0 <= t0 < t1):
            raise ValueError(f"{o}: option `window` must be (t0, t1) with 0 <= t0 < t1 [s]; got {(t0, t1)}")
        t_end = t1 if t_end is None else float(t_end)
        if not t_end >= t1:
            raise ValueError(f"{o}: option `t_end` must be >= the window's end {t1:g} s; got {t_end}")
        self.ts, self.t = _time_grid(o, t_end, int(round(t_end / 5e-4)) + 1 if n_points is None else n_points, 3)
        if isinstance(tune_steps, bool) or not isinstance(tune_steps, int | np.integer) or tune_steps < 1:
            raise ValueError(f"{o}: option `tune_steps` must be an integer >= 1; got {tune_steps!r}")
        import jax

        self.drive, self.pid, self.window, self.tune_steps = drive, pid, (t0, t1), int(tune_steps)
        p = jax.device_get(pid)
        knobs = [
            _declared_knob(PID, "kp", p.kp, "Kp", lo=0.0, hi=3.0 * abs(float(p.kp)) or 240.0),
            _declared_knob(PID, "ki", p.ki, "Ki", lo=0.0, hi=3.0 * abs(float(p.ki)) or 96.0),
            _declared_knob(PID, "kd", p.kd, "Kd", lo=0.0, hi=4.0 * abs(float(p.kd)) or 0.06),
            _declared_knob(PID, "omega_ref", p.omega_ref, "ω0", factors=(0.3, 2.0)),
        ]
        self.knobs = _with_ranges(knobs, ranges, o)

    def pid_of(self, v: dict):
        """The `PID` of the slider values `v`."""
        return dataclasses.replace(self.pid, kp=v["kp"], ki=v["ki"], kd=v["kd"], omega_ref=v["omega_ref"])

    def compute(self, v):
        from .objectives.fluctuation import fluctuation_index
        from .scene import Scene
        from .solve import simulate

        sol = simulate(Scene(self.drive, self.pid_of(v), ts=self.ts, observe=("motor_speed", "voltage")))
        r = _host({"speed": sol.motor_speed, "voltage": sol.voltage, "current": sol.current})
        r["chi"] = float(fluctuation_index(sol, *self.window))  # eq. 22, exact
        r["omega_ref"] = float(v["omega_ref"])
        return r

    def build(self, fig):
        axes = fig.subplots(1, 3)
        self.axes = axes
        (self.l_speed,) = axes[0].plot([], [], color="C0")
        self.l_ref = axes[0].axhline(np.nan, color="k", ls="--", lw=0.8)
        (self.l_v,) = axes[1].plot([], [], color="C2")
        (self.l_i,) = axes[2].plot([], [], color="C3")
        self.dynamic = [self.l_speed, self.l_ref, self.l_v, self.l_i]
        for ax, label in zip(axes, ("motor speed φ̇ [rad/s]", "voltage V [V]", "current I [A]")):
            ax.axvspan(*self.window, color="0.9", zorder=0)
            _style(ax, "time t [s]", label)
            ax.set_xlim(self.t[0], self.t[-1])

    def draw(self, r):
        t = self.t
        self.l_speed.set_data(t, r["speed"])
        self.l_ref.set_ydata([r["omega_ref"]] * 2)
        self.l_v.set_data(t, r["voltage"])
        self.l_i.set_data(t, r["current"])
        _fit(self.axes[0], r["speed"], [r["omega_ref"]])
        _fit(self.axes[1], r["voltage"])
        _fit(self.axes[2], r["current"])

    def numbers(self, r):
        chi = float(r["chi"])
        t0, t1 = self.window
        return [
            ("chi", f"χ over {t0:g}–{t1:g} s (eq. 22)", chi, "–", f"{chi:.4g} ({100 * chi:.4g} %)"),
            ("peak_voltage", "peak |V|", float(np.max(np.abs(r["voltage"]))), "V", None),
            ("peak_current", "peak |I|", float(np.max(np.abs(r["current"]))), "A", None),
        ]

    def extra_controls(self, explorer, w):
        button = w.Button(
            description=f"tune PID ({self.tune_steps} steps)",
            tooltip="jb.tune_pid from the sliders' gains (in the background); the sliders move to the tuned gains",
            layout=w.Layout(width="220px"),
        )
        button.on_click(lambda _: explorer.tune(wait=False))
        return [button]

    def tune_job(self, v: dict) -> Callable[[], Any]:
        from .optimise.pid import tune_pid

        pid = self.pid_of(v)
        t0, t1 = self.window

        def job():
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                res = tune_pid(self.drive, pid, t0, t1, steps=self.tune_steps, progress=False)
            return res, [str(c.message) for c in caught]

        return job


# --- pseudo-polynomial commands of a belt-driven platform (Incerti) -----------------------------------------------
def _accelerations(cmd, gammas_step, ts):
    """The motor accelerations [rad/s²] of `cmd` and of the same move with the exponents `gammas_step`."""
    from .commands import PseudoPolynomial

    stepped = PseudoPolynomial(gammas_step, cmd.displacement, cmd.duration)
    return cmd.acceleration(ts), stepped.acceleration(ts)


class _Shaping(_Scene):
    key = "shaping"
    title = "Pseudo-polynomial command of a belt-driven platform (Incerti)"
    OPTIONS = ("command", "t_end", "n_points", "ranges")

    def __init__(self, start=None, command=None, t_end=None, n_points: int = 601, ranges=None):
        from .commands import PseudoPolynomial
        from .models.platform import BeltPlatform

        o = "explore('shaping')"
        plat = BeltPlatform()
        cmd = PseudoPolynomial(np.array([3.0, 4.0, 5.0])) if command is None else command
        if isinstance(start, BeltPlatform):
            plat = start
        elif isinstance(start, PseudoPolynomial):
            cmd = start
        elif start is not None:
            raise TypeError(f"{o}: start from a BeltPlatform or a PseudoPolynomial; got {start!r}")
        if not isinstance(cmd, PseudoPolynomial):
            raise TypeError(f"{o}: option `command` must be a PseudoPolynomial; got {type(cmd).__name__}")
        import jax

        c = jax.device_get(cmd)
        T = float(c.duration)
        t_end = 1.5 * T if t_end is None else float(t_end)
        if not (math.isfinite(t_end) and t_end > 0):
            raise ValueError(f"{o}: option `t_end` (s) must be > 0; got {t_end}")
        self.ts, self.t = _time_grid(o, t_end, n_points)
        self.plat, self.cmd = plat, cmd
        self.T = T
        g = np.asarray(c.gammas, dtype=float)
        self.n_exp = g.size
        low = float(max(g.size - 1, 2))
        knobs = [
            _knob(
                f"gamma{i}",
                f"γ{i}",
                "–",
                g[i],
                lo=low + 0.02,
                hi=max(10.0, g[i]),
                doc=f"exponent {i} of the pseudo-polynomial (each > {low:g}, distinct)",
                valid=(low, math.inf, True),
            )
            for i in range(g.size)
        ]
        p = jax.device_get(plat)
        knobs += [
            _declared_knob(BeltPlatform, "k", p.k, "k", factors=(0.25, 4.0), log=True),
            _declared_knob(BeltPlatform, "c", p.c, "c", lo=0.0, hi=4.0 * float(p.c) or 600.0),
        ]
        self.knobs = _with_ranges(knobs, ranges, o)

    def platform_and_command(self, v: dict):
        """The `BeltPlatform` and `PseudoPolynomial` of the slider values `v` (checked at construction)."""
        from .commands import PseudoPolynomial

        plat = dataclasses.replace(self.plat, k=v["k"], c=v["c"])
        g = np.array([v[f"gamma{i}"] for i in range(self.n_exp)])
        return plat, PseudoPolynomial(g, self.cmd.displacement, self.cmd.duration)

    def compute(self, v):
        from .objectives.residual import residual_energy
        from .optimise.command import optimise_command
        from .scene import Scene
        from .solve import simulate

        plat, cmd = self.platform_and_command(v)
        note = ""
        try:
            with warnings.catch_warnings(record=True) as caught:  # a start near the exponents' bounds warns
                warnings.simplefilter("always")
                step = optimise_command(plat, cmd, max_steps=1, progress=False)
            g1, H1 = np.asarray(step.gammas_history)[1], float(np.asarray(step.history)[1])
            note = "; ".join(str(c.message) for c in caught)
        except (ValueError, FloatingPointError) as e:  # no step from here: the curves without it
            g1, H1, note = np.sort(np.asarray(cmd.gammas)), math.nan, f"no optimisation step: {e}"
        H = residual_energy(plat, cmd)  # eq. 32, the quadrature
        sol = simulate(
            Scene(plat, cmd, ts=self.ts, observe=("acceleration", "command_acceleration")),
            method="ode",
            rtol=1e-10,
            atol=1e-12,
        )
        acc, acc_step = _program("shaping_acc", _accelerations)(cmd, np.asarray(g1, dtype=float), self.ts)
        r = _host(dict(H=H, acc=acc, acc_step=acc_step, platform=sol.acceleration, rigid=sol.command_acceleration))
        r.update(
            E=float(r["H"]) * float(plat.energy_factor),
            f_n=float(plat.omega_n) / (2 * np.pi),
            gammas_step=g1,
            H_step=H1,
            note=note,
        )
        return r

    def build(self, fig):
        axes = fig.subplots(1, 2)
        self.axes = axes
        (self.l_acc,) = axes[0].plot([], [], color="C0", label="command")
        (self.l_step,) = axes[0].plot([], [], color="C1", ls="--", label="after one L-BFGS step")
        _style(axes[0], "time t [s]", "motor acceleration φ̈m [rad/s²]")
        axes[0].set_xlim(0.0, self.T)
        (self.l_plat,) = axes[1].plot([], [], color="C0", label="platform θ̈")
        (self.l_rigid,) = axes[1].plot([], [], color="k", ls="--", lw=0.8, label="rigid belt λφ̈m")
        axes[1].axvline(self.T, color="0.5", lw=0.8, ls=":")
        _style(axes[1], "time t [s]", "platform acceleration [rad/s²]")
        axes[1].set_xlim(self.t[0], self.t[-1])
        legends = [ax.legend(fontsize=9, loc="upper right") for ax in axes]
        self.dynamic = [self.l_acc, self.l_step, self.l_plat, self.l_rigid, *legends]

    def draw(self, r):
        t = self.t
        inside = t <= self.T
        self.l_acc.set_data(t[inside], r["acc"][inside])
        self.l_step.set_data(t[inside], r["acc_step"][inside])
        self.l_plat.set_data(t, r["platform"])
        self.l_rigid.set_data(t, r["rigid"])
        _fit(self.axes[0], r["acc"][inside], r["acc_step"][inside])
        _fit(self.axes[1], r["platform"], r["rigid"])

    def numbers(self, r):
        return [
            ("H", "residual energy H (eq. 32)", float(r["H"]), "rad²/s⁴", None),
            ("E", "energy left E(T) = hH (eq. 31)", float(r["E"]), "J", None),
            ("H_step", "H after one L-BFGS step", float(r["H_step"]), "rad²/s⁴", None),
            ("gammas_step", "exponents after the step", tuple(float(x) for x in r["gammas_step"]), "–", None),
            ("f_n", "platform natural frequency", float(r["f_n"]), "Hz", None),
        ]


# --- axially moving belt spans (belt-vibration report, eq. 39, 54-55) ---------------------------------------------
def _spans_impl(span, radius, ratio, grid, modes, harmonics):
    import jax.numpy as jnp

    from .models.string import exciting_speeds

    n_modes = modes.shape[0]
    vc = span.critical_speed
    speeds = grid * vc
    V = ratio * vc
    w = span.natural_frequencies(speeds, n_modes)
    w_at = span.natural_frequencies(V, n_modes)
    rotor = exciting_speeds(span, radius, n=modes[:, None], m=harmonics[None, :])  # (n_modes, harmonics) rad/s
    x = jnp.linspace(0.0, 1.0, 101) * span.length
    period = 2.0 * jnp.pi / w_at[0]
    tt = jnp.arange(5.0) / 10.0 * period  # five instants over half a period
    shape = span.mode_shape(x[None, :], tt[:, None], V, n=1)
    return dict(vc=vc, speeds=speeds, w=w, V=V, w_at=w_at, rotor=rotor, x=x, shape=shape)


class _Spans(_Scene):
    key = "spans"
    title = "Axially moving belt span: speed-dependent natural frequencies (belt-vibration report)"
    OPTIONS = ("pulley_radius", "n_modes", "harmonics", "speed_ratio", "ranges")

    def __init__(
        self, start=None, pulley_radius=0.1166, n_modes: int = 3, harmonics: int = 3, speed_ratio=0.3, ranges=None
    ):
        from .models.string import MovingString

        o = "explore('spans')"
        span = MovingString(tension=140.0, density=0.05, length=0.2621)
        if isinstance(start, MovingString):
            span = start
        elif start is not None:
            raise TypeError(f"{o}: start from a MovingString; got {start!r}")
        for name, n in (("n_modes", n_modes), ("harmonics", harmonics)):
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 8:
                raise ValueError(f"{o}: option `{name}` must be an integer in [1, 8]; got {n!r}")
        R = float(pulley_radius)
        if not (math.isfinite(R) and R > 0):
            raise ValueError(f"{o}: option `pulley_radius` (m) must be > 0; got {pulley_radius!r}")
        import jax

        self.span = span
        self.grid = jax.device_put(np.linspace(0.0, 0.995, 200))
        self.modes = jax.device_put(np.arange(1.0, n_modes + 1))
        self.harmonics = jax.device_put(np.arange(1.0, harmonics + 1))
        s = jax.device_get(span)
        knobs = [
            _declared_knob(MovingString, "tension", s.tension, "T", factors=(0.25, 4.0), log=True),
            _declared_knob(MovingString, "density", s.density, "ρ", factors=(0.25, 4.0), log=True),
            _declared_knob(MovingString, "length", s.length, "L", factors=(0.25, 4.0), log=True),
            _knob(
                "pulley_radius",
                "R_U",
                "m",
                R,
                factors=(0.25, 3.0),
                log=True,
                doc="radius of the pulley whose rotation excites the span (eq. 50, 55)",
                valid=(0.0, math.inf, True),
            ),
            _knob(
                "speed_ratio",
                "V / V_cr",
                "–",
                speed_ratio,
                lo=0.0,
                hi=0.95,
                doc="belt speed over the critical speed",
                valid=(0.0, 0.995, False),
            ),
        ]
        self.knobs = _with_ranges(knobs, ranges, o)
        self.n_modes, self.n_harm = int(n_modes), int(harmonics)

    def span_of(self, v: dict):
        """The `MovingString` of the slider values `v` (checked at construction)."""
        return dataclasses.replace(self.span, tension=v["tension"], density=v["density"], length=v["length"])

    def compute(self, v):
        import jax

        span = self.span_of(v)
        R, ratio = (jax.device_put(np.asarray(v[k], dtype=float)) for k in ("pulley_radius", "speed_ratio"))
        r = _host(_program("spans", _spans_impl)(span, R, ratio, self.grid, self.modes, self.harmonics))
        r["radius"] = float(v["pulley_radius"])
        return r

    def build(self, fig):
        axes = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.5, 1.0)})
        self.axes = axes
        ax = axes[0]
        self.l_modes = [ax.plot([], [], color=f"C{i}", label=f"f{i + 1}(V)")[0] for i in range(self.n_modes)]
        self.l_loads = [
            ax.plot([], [], color="0.55", lw=0.8, ls="--", label="pulley harmonics m V/(2π R_U)" if m == 0 else None)[0]
            for m in range(self.n_harm)
        ]
        (self.l_cross,) = ax.plot([], [], "ko", ms=4, label="exciting speeds (eq. 55)")
        self.l_speed = ax.axvline(np.nan, color="C3", lw=1.0)
        _style(ax, "belt speed V [m/s]", "natural frequency f [Hz]")
        legend = ax.legend(fontsize=9, loc="upper right")
        self.l_shape = [axes[1].plot([], [], color="C0", alpha=0.35 + 0.13 * k)[0] for k in range(5)]
        _style(axes[1], "x along the span [mm]", "mode 1 (eq. 49), 5 instants")
        self.dynamic = [*self.l_modes, *self.l_loads, self.l_cross, self.l_speed, legend, *self.l_shape]

    def draw(self, r):
        V, f = r["speeds"], r["w"] / (2 * np.pi)
        for i, line in enumerate(self.l_modes):
            line.set_data(V, f[:, i])
        for m, line in enumerate(self.l_loads):
            line.set_data(V, (m + 1) * V / (2 * np.pi * r["radius"]))
        rotor = r["rotor"]  # rad/s of the pulley; belt speed = rotor R_U, frequency = m rotor / 2 pi
        m = np.arange(1, rotor.shape[1] + 1)[None, :]
        self.l_cross.set_data((rotor * r["radius"]).ravel(), (m * rotor / (2 * np.pi)).ravel())
        self.l_speed.set_xdata([r["V"]] * 2)
        ax = self.axes[0]
        _fit(ax, [0.0], r["speeds"], axis="x")
        _fit(ax, [0.0], f)
        for k, line in enumerate(self.l_shape):
            line.set_data(1e3 * r["x"], r["shape"][k])
        _fit(self.axes[1], 1e3 * r["x"], axis="x")
        _fit(self.axes[1], r["shape"])

    def numbers(self, r):
        f = r["w_at"] / (2 * np.pi)
        out = [
            ("critical_speed", "critical speed V_cr (eq. 52)", float(r["vc"]), "m/s", None),
            ("speed", "belt speed V", float(r["V"]), "m/s", None),
            ("frequencies", "f_n at V (eq. 39)", tuple(float(x) for x in f), "Hz", None),
        ]
        rpm = r["rotor"] * 30.0 / np.pi
        out.append(("exciting_rpm", "exciting rotor speeds (eq. 55)", rpm, "rpm", "table below"))
        return out

    def tables(self, r):
        rpm = r["rotor"] * 30.0 / np.pi
        headers = ("mode",) + tuple(with_unit(f"harmonic {m + 1}", "rpm") for m in range(rpm.shape[1]))
        rows = tuple((i + 1, *(float(x) for x in row)) for i, row in enumerate(rpm))
        return (Table(headers, rows, caption="pulley speeds at which harmonic m excites mode n (eq. 55)"),)


# --- non-linear belt vibration (Moon & Wickert, 1997) -----------------------------------------------------------
class _Nonlinear(_Scene):
    key = "nonlinear"
    title = "Non-linear belt vibration: response curve (Moon & Wickert, 1997)"
    long = True
    busy_text = "continuation (response_curve)"
    OPTIONS = ("speed_range", "n_harmonics", "max_points", "ranges")

    def __init__(self, start=None, speed_range=None, n_harmonics: int = 3, max_points: int = 200, ranges=None):
        from .models.nonlinear import NonlinearBelt

        o = "explore('nonlinear')"
        belt = NonlinearBelt()
        if isinstance(start, NonlinearBelt):
            belt = start
        elif start is not None:
            raise TypeError(f"{o}: start from a NonlinearBelt; got {start!r}")
        for name, n, lo in (("n_harmonics", n_harmonics, 1), ("max_points", max_points, 2)):
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < lo:
                raise ValueError(f"{o}: option `{name}` must be an integer >= {lo}; got {n!r}")
        if speed_range is not None:
            try:
                a, b = (float(x) for x in speed_range)
            except (TypeError, ValueError):
                raise ValueError(f"{o}: option `speed_range` must be (v0, v1) in m/s; got {speed_range!r}") from None
            if not 0 < a < b:
                raise ValueError(f"{o}: option `speed_range` must be (v0, v1) with 0 < v0 < v1 [m/s]; got {(a, b)}")
            speed_range = (a, b)
        import jax

        self.belt, self.speed_range, self.H, self.max_points = belt, speed_range, int(n_harmonics), int(max_points)
        b = jax.device_get(belt)
        damping = np.atleast_1d(np.asarray(b.damping, dtype=float))
        knobs = [
            _declared_knob(NonlinearBelt, "wave_speed", b.wave_speed, "v_t", factors=(0.8, 1.25)),
            _declared_knob(NonlinearBelt, "v_l", b.v_l, "v_l = c/v_t", factors=(0.2, 3.0)),
            _declared_knob(NonlinearBelt, "damping", damping[0], "ξ1", factors=(0.25, 4.0), log=True, name="damping1"),
        ]
        self.knobs = _with_ranges(knobs, ranges, o)

    def belt_of(self, v: dict):
        """The `NonlinearBelt` of the slider values `v` (checked at construction)."""
        d = np.array(np.asarray(self.belt.damping, dtype=float))
        if d.ndim == 0:
            d = np.asarray(v["damping1"], dtype=float)
        else:
            d[0] = v["damping1"]
        return dataclasses.replace(self.belt, wave_speed=v["wave_speed"], v_l=v["v_l"], damping=d)

    def range_of(self, v: dict) -> tuple[float, float]:
        """The speed range [m/s]: the option, else 0.9-1.26 x the first linear crossing (Moon & Wickert, Fig. 5),
        which holds the first resonance's folds for the stand's values."""
        if self.speed_range is not None:
            return self.speed_range
        b = self.belt
        c = float(b.span) / float(np.asarray(b.pulley_radii)[0])
        crossing = (-c + math.sqrt(c * c + 4 * math.pi**2)) / (2 * math.pi) * float(v["wave_speed"])
        return 0.9 * crossing, 1.26 * crossing

    def job(self, v: dict):
        from .models.nonlinear import response_curve

        belt, rng = self.belt_of(v), self.range_of(v)

        def run():
            c = response_curve(belt, rng, self.H, max_points=self.max_points)
            return dict(
                speed=np.asarray(c.speed),
                pp=np.asarray(c.pp),
                stable=np.asarray(c.stable, dtype=bool),
                folds=np.asarray(c.folds),
                range=rng,
            )

        return run

    def compute(self, v):
        return self.job(v)()

    def build(self, fig):
        ax = fig.subplots(1, 1)
        self.axes = [ax]
        (self.l_stable,) = ax.plot([], [], "-", color="C0", lw=1.6, label="stable (Floquet)")
        (self.l_unstable,) = ax.plot([], [], "--", color="C3", lw=1.2, label="unstable")
        self.l_folds = [
            ax.axvline(np.nan, color="0.5", lw=0.8, ls=":", label="folds" if k == 0 else None) for k in range(6)
        ]
        _style(ax, "belt speed V [m/s]", "peak-to-peak 1 cm from the pulley [mm]")
        legend = ax.legend(fontsize=9, loc="upper left")
        self.dynamic = [self.l_stable, self.l_unstable, *self.l_folds, legend]

    def draw(self, r):
        s, p, st = r["speed"], 1e3 * r["pp"], r["stable"]
        self.l_stable.set_data(s, np.where(st, p, np.nan))
        near = ~st | np.r_[~st[1:], False] | np.r_[False, ~st[:-1]]  # the unstable runs joined to their ends
        self.l_unstable.set_data(s, np.where(near, p, np.nan))
        for k, line in enumerate(self.l_folds):
            line.set_xdata([r["folds"][k]] * 2 if k < r["folds"].size else [np.nan] * 2)
        ax = self.axes[0]
        if tuple(ax.get_xlim()) != tuple(r["range"]):
            ax.set_xlim(*r["range"])
        _fit(ax, p)

    def numbers(self, r):
        folds = r["folds"]
        return [
            ("folds", "fold (jump) speeds", tuple(float(x) for x in folds), "m/s", None),
            ("max_pp", "largest peak-to-peak", 1e3 * float(np.nanmax(r["pp"])), "mm", None),
            ("speed_range", "speed range", tuple(float(x) for x in r["range"]), "m/s", None),
        ]


# --- shaped moves on the user's modal axis (design_move) -------------------------------------------------------
class _Axis(_Scene):
    key = "axis"
    title = "Shaped move on a modal axis (design_move)"
    long = True
    busy_text = "designing the move (design_move)"
    OPTIONS = ("distance", "move_time", "v_max", "a_max", "uncertainty", "include", "ranges")
    INCLUDE = ("minimax", "ZV", "ZVD", "EI", "unshaped")

    def __init__(
        self,
        start=None,
        distance=0.1,
        move_time=0.8,
        v_max=0.3,
        a_max=1.2,
        uncertainty=0.2,
        include=INCLUDE,
        ranges=None,
    ):
        from .models.axis import ModalAxis
        from .shaping.moves import fastest_time

        o = "explore('axis')"
        axis = ModalAxis([7.3], [0.015])
        if isinstance(start, ModalAxis):
            axis = start
        elif start is not None:
            raise TypeError(f"{o}: start from a ModalAxis; got {start!r}")
        t_min = fastest_time(distance, v_max, a_max)  # checks the move's limits by name
        T = float(move_time)
        if not T > t_min:
            raise ValueError(
                f"{o}: option `move_time` must exceed the time-optimal move's {t_min:.4g} s for distance {distance} "
                f"with v_max {v_max}, a_max {a_max}; got {move_time}"
            )
        u = float(uncertainty)
        if not 0 <= u < 0.9:
            raise ValueError(f"{o}: option `uncertainty` must lie in [0, 0.9); got {uncertainty}")
        include = tuple(include)
        if "unshaped" not in include:
            include = include + ("unshaped",)
        self.axis, self.include = axis, include
        self.move = dict(distance=float(distance), v_max=float(v_max), a_max=float(a_max), uncertainty=u)
        self.factors = np.linspace(0.5, 1.5, 201)
        import jax

        a = jax.device_get(axis)
        f, z = np.asarray(a.frequencies, dtype=float), np.asarray(a.damping_ratios, dtype=float)
        self.n_modes = f.size
        knobs = []
        for i in range(f.size):
            knobs.append(
                _declared_knob(ModalAxis, "frequencies", f[i], f"f{i + 1}", factors=(0.5, 2.0), name=f"f{i + 1}")
            )
            knobs.append(
                _declared_knob(
                    ModalAxis,
                    "damping_ratios",
                    z[i],
                    f"ζ{i + 1}",
                    lo=1e-3,
                    hi=max(0.2, z[i]),
                    log=True,
                    name=f"zeta{i + 1}",
                )
            )
        knobs.append(
            _knob(
                "move_time",
                "T",
                "s",
                T,
                lo=1.03 * t_min,
                hi=max(2.5 * t_min, 1.5 * T),
                doc="move time (at least the time-optimal move's)",
                valid=(t_min, math.inf, True),
            )
        )
        self.knobs = _with_ranges(knobs, ranges, o)
        self.T_max = max(k.hi for k in self.knobs if k.name == "move_time")

    def axis_of(self, v: dict):
        """The `ModalAxis` of the slider values `v` (gains kept; checked at construction)."""
        from .models.axis import ModalAxis

        f = [v[f"f{i + 1}"] for i in range(self.n_modes)]
        z = [v[f"zeta{i + 1}"] for i in range(self.n_modes)]
        return ModalAxis(f, z, self.axis.gains)

    def job(self, v: dict):
        from .shaping.plan import design_move

        axis, T, m = self.axis_of(v), float(v["move_time"]), self.move
        f0 = np.array([v[f"f{i + 1}"] for i in range(self.n_modes)])

        def run():
            plan = design_move(
                axis,
                m["distance"],
                T,
                v_max=m["v_max"],
                a_max=m["a_max"],
                uncertainty=m["uncertainty"],
                include=self.include,
            )
            factors, curves = plan.curves(self.factors)
            t = np.linspace(0.0, T, 401)
            acc = {}
            for c in plan.table:
                if c.command is not None and (c is plan.best or c.name == "unshaped"):
                    acc[c.name] = np.asarray(c.command.acceleration(t))
            return dict(plan=plan, factors=factors, curves=curves, t=t, acc=acc, f0=f0, T=T)

        return run

    def compute(self, v):
        return self.job(v)()

    def build(self, fig):
        axes = fig.subplots(1, 2)
        self.axes = axes
        u = self.move["uncertainty"]
        ax = axes[0]
        self.l_curves = {
            name: ax.plot([], [], label=name, lw=2.0 if name == "minimax" else 1.0, color=f"C{k}")[0]
            for k, name in enumerate(self.include)
        }
        ax.axvspan(1 - u, 1 + u, color="0.9", zorder=0)
        ax.set_yscale("log")
        ax.set_xlim(self.factors[0], self.factors[-1])
        _style(ax, "actual / nominal frequency", "residual [% of unshaped, worst mode]")
        self.legend0 = ax.legend(fontsize=9, loc="lower left", ncol=2)
        (self.l_best,) = axes[1].plot([], [], color="C0", label="recommended")
        (self.l_unshaped,) = axes[1].plot([], [], color="0.5", ls="--", lw=0.8, label="unshaped")
        _style(axes[1], "time t [s]", "acceleration [m/s²]")
        axes[1].set_xlim(0.0, self.T_max)
        self.legend1 = axes[1].legend(fontsize=9, loc="upper right")
        self.dynamic = [*self.l_curves.values(), self.l_best, self.l_unshaped, self.legend0, self.legend1]

    def draw(self, r):
        plan = r["plan"]
        for name, line in self.l_curves.items():
            cur = r["curves"].get(name)
            line.set_data(r["factors"], np.max(cur, axis=0) if cur is not None else np.full(r["factors"].shape, np.nan))
        best = plan.best
        self.l_best.set_label(f"recommended: {best.name}" if best is not None else "no recommendation")
        a_best = r["acc"].get(best.name) if best is not None else None
        self.l_best.set_data(r["t"], a_best if a_best is not None else np.full(r["t"].shape, np.nan))
        a_un = r["acc"].get("unshaped")
        self.l_unshaped.set_data(r["t"], a_un if a_un is not None else np.full(r["t"].shape, np.nan))
        self.legend1.get_texts()[0].set_text(self.l_best.get_label())
        # residuals below 1e-6 % (a shaper's exact notch) leave the panel: they would stretch it over decades
        _fit(self.axes[0], *(np.maximum(np.max(c, axis=0), 1e-6) for c in r["curves"].values()))
        _fit(self.axes[1], [0.0, r["T"]], axis="x")
        _fit(self.axes[1], *r["acc"].values())

    def numbers(self, r):
        plan = r["plan"]
        best = plan.best
        mm = next((c for c in plan.table if c.name == "minimax"), None)
        out = [
            ("recommended", "recommended", best.name if best is not None else None, "", None),
            ("worst_percent", "worst residual (recommended)", best.worst_percent if best else math.nan, "%", None),
            ("worst_m", "worst residual amplitude", best.worst_m if best else math.nan, "m", None),
        ]
        if mm is not None:
            out.append(("minimax_worst_percent", "worst residual, minimax", mm.worst_percent, "%", None))
        out.append(("move_time", "move time", float(r["T"]), "s", None))
        return out

    def tables(self, r):
        plan = r["plan"]
        rows = tuple((c.name, c.worst_percent, c.ok, c.note) for c in plan.table)
        marked = next((i for i, c in enumerate(plan.table) if c is plan.best), None)
        headers = ("candidate", with_unit("worst", "%"), "ok", "note")
        return (Table(headers, rows, caption="candidates, best first (MovePlan.table)", marked=marked),)


_SCENES: dict[str, type[_Scene]] = {
    "startup": _Startup,
    "fourbar": _FourBar,
    "shaping": _Shaping,
    "spans": _Spans,
    "nonlinear": _Nonlinear,
    "axis": _Axis,
}
_ALIASES = {
    "start-up": "startup",
    "four-bar": "fourbar",
    "platform": "shaping",
    "pseudo-polynomial": "shaping",
    "string": "spans",
    "belt_spans": "spans",
    "design_move": "axis",
    "shaping_axis": "axis",
}


def _scene_key(start) -> str:
    """The scene a start object belongs to."""
    from .commands import ExponentialVoltage, PseudoPolynomial
    from .models.axis import ModalAxis
    from .models.fourbar import FourBarDrive
    from .models.motor import PID
    from .models.nonlinear import NonlinearBelt
    from .models.platform import BeltPlatform
    from .models.startup import BeltStartup
    from .models.string import MovingString
    from .scene import Scene

    kinds = (
        (BeltStartup, "startup"),
        (ExponentialVoltage, "startup"),
        (FourBarDrive, "fourbar"),
        (PID, "fourbar"),
        (BeltPlatform, "shaping"),
        (PseudoPolynomial, "shaping"),
        (MovingString, "spans"),
        (NonlinearBelt, "nonlinear"),
        (ModalAxis, "axis"),
    )
    probe = start.model if isinstance(start, Scene) else start
    for cls, key in kinds:
        if isinstance(probe, cls):
            return key
    names = ", ".join(sorted({c.__name__ for c, _ in kinds}))
    raise TypeError(
        f"explore: `scene_or_model` must be a scene name {sorted(_SCENES)}, a Scene, or one of {names}; "
        f"got {type(start).__name__}"
    )


# --------------------------------------------------------------------------------------------------------------
# The explorer: sliders, figure, numbers, and the background worker of the long scenes
# --------------------------------------------------------------------------------------------------------------
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


class _Worker:
    """The one background thread of the explorers' long computations (a daemon, started on first use).

    One thread for the process, kept: the first JAX call of a program in a new thread costs a few hundred
    milliseconds more than later ones (measured: 0.6 s against 0.2 s for a 1-mode `design_move`), so a thread per
    computation would pay that at every slider move."""

    def __init__(self):
        self._cond = threading.Condition()
        self._queue: list[Explorer] = []
        self._thread: threading.Thread | None = None

    def submit(self, explorer: Explorer) -> None:
        with self._cond:
            if explorer not in self._queue:
                self._queue.append(explorer)
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="jaxbelt-explore", daemon=True)
                self._thread.start()
            self._cond.notify()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._queue:
                    self._cond.wait()
                explorer = self._queue.pop(0)
            explorer._run_pending()


_WORKERS: list[_Worker] = []
_WORKERS_LOCK = threading.Lock()


def _worker() -> _Worker:
    with _WORKERS_LOCK:
        if not _WORKERS:
            _WORKERS.append(_Worker())
        return _WORKERS[0]


class Explorer:
    """A live view of one scene (what `explore` returns).

    - `controls`: `{name: ipywidgets slider}` (units in each description); dragging one recomputes and redraws;
    - `figure`: the scene's matplotlib `Figure`, redrawn in place (its lines' data change, the figure stays);
    - `values`: `{name: number}` of the key numbers of the last result (χ, H, the worst residual, the fold
      speeds, ...), `units`: their units; NaN after a computation that failed (`error` says why);
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
