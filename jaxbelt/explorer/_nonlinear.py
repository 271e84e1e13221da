"""The non-linear view: the response curve of a belt with eccentric pulleys (Moon & Wickert, 1997)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._figure import _fit, _style
from ._knobs import _declared_knob, _with_ranges
from ._scene import _Scene


class _Nonlinear(_Scene):
    key = "nonlinear"
    title = "Non-linear belt vibration: response curve (Moon & Wickert, 1997)"
    long = True
    busy_text = "continuation (response_curve)"
    OPTIONS = ("speed_range", "n_harmonics", "max_points", "ranges")

    def __init__(self, start=None, speed_range=None, n_harmonics: int = 3, max_points: int = 200, ranges=None):
        from ..models.nonlinear import NonlinearBelt

        o = "explore('nonlinear')"
        belt = NonlinearBelt()
        if isinstance(start, NonlinearBelt):
            belt = start
        elif start is not None:
            raise TypeError(f"{o}: start from a NonlinearBelt; got {start!r}")
        from ..models.nonlinear.harmonic import MAX_CURVE_POINTS

        for name, n, lo, hi in (("n_harmonics", n_harmonics, 1, None), ("max_points", max_points, 2, MAX_CURVE_POINTS)):
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < lo or (hi is not None and n > hi):
                within = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
                raise ValueError(f"{o}: option `{name}` must be an integer {within}; got {n!r}")
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
        from ..models.nonlinear import response_curve

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
