"""Fig. 3 of Incerti (2014): start-up of the belt drive for several voltage time constants.

Drawing only: the curves come from `jaxbelt.startup_curves`.
"""

from __future__ import annotations

import numpy as np

#: Panel titles of Fig. 3, keyed by the names of `jaxbelt.runs.STARTUP_OUTPUTS` (paper order a-h).
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


def draw_startup(ts, curves, gammas, v_max=24.0, fig=None):
    """Draw the 8 panels of Incerti (2014), Fig. 3, from computed curves.

    `ts` [s] of shape (N,), `curves[name]` of shape (len(gammas), N) for each panel name (the
    output of `jaxbelt.startup_curves`), `gammas` the voltage time constants [s], `v_max` [V]
    (for the title). Returns the matplotlib figure.
    """
    ts = np.asarray(ts)
    if fig is None:
        import matplotlib.pyplot as plt  # only to make the figure: the CLI passes its own Agg figure

        fig = plt.figure(figsize=(11, 12), constrained_layout=True)
    axes = fig.subplots(4, 2)
    for ax, (name, title) in zip(axes.ravel(), STARTUP_PANELS):
        for i, g in enumerate(gammas):
            ax.plot(ts, np.asarray(curves[name][i]), label=f"γ = {1e3 * float(g):g} ms")
        ax.set_title(title, fontsize=10, loc="left")
        ax.grid(alpha=0.3)
        ax.set_xlim(ts[0], ts[-1])
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    axes[0, 0].legend(fontsize=9)
    fig.suptitle(f"Belt drive start-up, V(t) = {v_max:g}(1 − e^(−t/γ)) V  (Incerti, 2014, Fig. 3)")
    return fig
