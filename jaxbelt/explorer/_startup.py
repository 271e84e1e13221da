"""The start-up view: a belt drive driven by a DC motor (Incerti, 2014)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._figure import _fit, _style
from ._knobs import _declared_knob, _time_grid, _with_ranges, check_t_end
from ._scene import _host, _program, _Scene


def _system_matrix(model):
    return model.matrices()[0]


class _Startup(_Scene):
    key = "startup"
    title = "Start-up of a belt drive driven by a DC motor (Incerti, 2014)"
    OPTIONS = ("t_end", "n_points", "ranges")

    def __init__(self, start=None, t_end: float = 0.5, n_points: int = 501, ranges=None):
        from ..commands import ExponentialVoltage
        from ..models.startup import BeltStartup
        from ..scene import Scene

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
        t_end = check_t_end(o, t_end)
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
        from ..commands import ExponentialVoltage

        model = dataclasses.replace(self.model, k=v["k"], c=v["c"], j2=v["j2"])
        return model, ExponentialVoltage(v["v_max"], v["gamma"])

    def compute(self, v):
        from ..scene import Scene
        from ..solve import simulate

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
