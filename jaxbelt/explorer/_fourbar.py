"""The four-bar view: a linkage under PID speed control (Incerti, 2012), with the *tune PID* button."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ._figure import _fit, _style
from ._knobs import MAX_TUNE_STEPS, _declared_knob, _time_grid, _with_ranges, check_t_end
from ._scene import _host, _Scene


class _FourBar(_Scene):
    key = "fourbar"
    title = "Four-bar linkage driven by a PID-controlled DC motor (Incerti, 2012)"
    busy_text = "tuning the PID (tune_pid)"
    OPTIONS = ("window", "t_end", "n_points", "tune_steps", "ranges")

    def __init__(self, start=None, window=(0.375, 0.5), t_end=None, n_points=None, tune_steps: int = 20, ranges=None):
        from ..models.fourbar import FourBarDrive
        from ..models.motor import PID
        from ..scene import Scene

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
        t_end = t1 if t_end is None else check_t_end(o, t_end)
        if not t_end >= t1:
            raise ValueError(f"{o}: option `t_end` must be >= the window's end {t1:g} s; got {t_end}")
        self.ts, self.t = _time_grid(o, t_end, int(round(t_end / 5e-4)) + 1 if n_points is None else n_points, 3)
        if (
            isinstance(tune_steps, bool)
            or not isinstance(tune_steps, int | np.integer)
            or not 1 <= tune_steps <= MAX_TUNE_STEPS
        ):
            raise ValueError(
                f"{o}: option `tune_steps` must be an integer in [1, {MAX_TUNE_STEPS}] (each step a simulation and a "
                f"gradient); got {tune_steps!r}"
            )
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
        from ..objectives.fluctuation import fluctuation_index
        from ..scene import Scene
        from ..solve import simulate

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
        from ..optimise.pid import tune_pid

        pid = self.pid_of(v)
        t0, t1 = self.window

        def job():
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                res = tune_pid(self.drive, pid, t0, t1, steps=self.tune_steps, progress=False)
            return res, [str(c.message) for c in caught]

        return job
