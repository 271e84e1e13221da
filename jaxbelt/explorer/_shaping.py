"""The shaping view: pseudo-polynomial commands of a belt-driven platform (Incerti)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from ._figure import _fit, _style
from ._knobs import _declared_knob, _knob, _time_grid, _with_ranges, check_t_end
from ._scene import _host, _program, _Scene


def _accelerations(cmd, gammas_step, ts):
    """The motor accelerations [rad/s²] of `cmd` and of the same move with the exponents `gammas_step`."""
    from ..commands import PseudoPolynomial

    stepped = PseudoPolynomial(gammas_step, cmd.displacement, cmd.duration)
    return cmd.acceleration(ts), stepped.acceleration(ts)


class _Shaping(_Scene):
    key = "shaping"
    title = "Pseudo-polynomial command of a belt-driven platform (Incerti)"
    OPTIONS = ("command", "t_end", "n_points", "ranges")

    def __init__(self, start=None, command=None, t_end=None, n_points: int = 601, ranges=None):
        from ..commands import PseudoPolynomial
        from ..models.platform import BeltPlatform

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
        t_end = check_t_end(o, 1.5 * T if t_end is None else t_end)
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
        from ..commands import PseudoPolynomial

        plat = dataclasses.replace(self.plat, k=v["k"], c=v["c"])
        g = np.array([v[f"gamma{i}"] for i in range(self.n_exp)])
        return plat, PseudoPolynomial(g, self.cmd.displacement, self.cmd.duration)

    def compute(self, v):
        from ..objectives.residual import residual_energy
        from ..optimise.command import optimise_command
        from ..scene import Scene
        from ..solve import simulate

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
