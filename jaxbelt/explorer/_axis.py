"""The axis view: shaped moves on the user's modal axis (`design_move`)."""

from __future__ import annotations

import math

import numpy as np

from .._display import Table, with_unit
from ._figure import _fit, _style
from ._knobs import _declared_knob, _knob, _with_ranges
from ._scene import _Scene


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
        from ..models.axis import ModalAxis
        from ..shaping.moves import fastest_time

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
        if (
            isinstance(include, str)
            or not isinstance(include, (tuple, list))
            or not all(isinstance(name, str) for name in include)
        ):
            raise TypeError(
                f"{o}: option `include` must be a tuple of candidate names (of {', '.join(self.INCLUDE)}); got {include!r}"
            )
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
        from ..models.axis import ModalAxis

        f = [v[f"f{i + 1}"] for i in range(self.n_modes)]
        z = [v[f"zeta{i + 1}"] for i in range(self.n_modes)]
        return ModalAxis(f, z, self.axis.gains)

    def job(self, v: dict):
        from ..shaping.moves import derivatives_at
        from ..shaping.plan import design_move

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
                    # one compiled program per command structure (`derivatives_at`), not 20 eager operations
                    # compiled at a view's first result: 41 compilations, 27 s of CPU time on 2 busy cores
                    (acc[c.name],) = derivatives_at(c.command, t, (2,))
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
