"""Fig. 3 of Incerti (2014): start-up of the belt drive for several voltage time constants."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..commands import ExponentialVoltage
from ..models.startup import BeltStartup
from ..scene import Scene
from ..solve import simulate

STARTUP_PANELS = (
    ("voltage", "a) motor voltage V [V]"),
    ("current", "b) armature current I [A]"),
    ("electric_power", "c) electric power V·I [W]"),
    ("mechanical_power", "d) mechanical power at motor shaft [W]"),
    ("omega1", "e) pulley 1 speed θ̇1 [rad/s]"),
    ("omega2", "f) pulley 2 speed θ̇2 [rad/s]"),
    ("alpha1", "g) pulley 1 acceleration θ̈1 [rad/s²]"),
    ("alpha2", "h) pulley 2 acceleration θ̈2 [rad/s²]"),
)


def startup_curves(model=None, gammas=(0.02, 0.04, 0.06), v_max=24.0, t_end=0.5, n_points=501, method="auto"):
    """The eight time histories of Fig. 3 for each time constant, as numpy arrays.

    Returns `(ts, curves)` with `curves[name]` of shape (len(gammas), n_points); one `vmap`
    over γ, closed form by default.
    """
    model = BeltStartup() if model is None else model
    ts = jnp.linspace(0.0, float(t_end), int(n_points))
    names = tuple(n for n, _ in STARTUP_PANELS if n not in model.state_names)

    def one(g):
        sol = simulate(Scene(model, ExponentialVoltage(v_max, g), ts=ts, observe=names), method=method)
        return {n: sol[n] for n, _ in STARTUP_PANELS}

    out = jax.vmap(one)(jnp.asarray(gammas, dtype=float))
    return np.asarray(ts), {k: np.asarray(v) for k, v in out.items()}


def plot_startup(model=None, gammas=(0.02, 0.04, 0.06), v_max=24.0, t_end=0.5, n_points=501, method="auto", fig=None):
    """Draw the 8 panels of Incerti (2014)'s Fig. 3 (V, I, electric and mechanical power, pulley speeds
    and accelerations) for each voltage time constant γ [s]. Returns the matplotlib figure."""
    ts, curves = startup_curves(model, gammas, v_max, t_end, n_points, method)
    return draw_startup(ts, curves, gammas, v_max, fig)


def draw_startup(ts, curves, gammas, v_max=24.0, fig=None):
    """Draw Fig. 3 from `startup_curves` output (`ts`, `curves`) for the time constants `gammas`."""
    import matplotlib.pyplot as plt

    if fig is None:
        fig = plt.figure(figsize=(11, 12), constrained_layout=True)
    axes = fig.subplots(4, 2)
    for ax, (name, title) in zip(axes.ravel(), STARTUP_PANELS):
        for i, g in enumerate(gammas):
            ax.plot(ts, curves[name][i], label=f"γ = {1e3 * float(g):g} ms")
        ax.set_title(title, fontsize=10, loc="left")
        ax.grid(alpha=0.3)
        ax.set_xlim(ts[0], ts[-1])
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    axes[0, 0].legend(fontsize=9)
    fig.suptitle(f"Belt drive start-up, V(t) = {v_max:g}(1 − e^(−t/γ)) V  (Incerti, 2014, Fig. 3)")
    return fig
