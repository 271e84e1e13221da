"""The spans view: speed-dependent natural frequencies of axially moving belt spans (belt-vibration report)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._display import Table, with_unit
from ._figure import _fit, _style
from ._knobs import _declared_knob, _knob, _with_ranges
from ._scene import _host, _program, _Scene


def _spans_impl(span, radius, ratio, grid, modes, harmonics):
    import jax.numpy as jnp

    from ..models.string import exciting_speeds

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
        from ..models.string import MovingString

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
