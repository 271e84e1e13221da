"""Figure of a `MovePlan` (`jaxbelt.design_move`): residual % against frequency for every candidate, and the commands.

Drawing only: the curves come from `MovePlan.curves()` and the commands' own `sample`.
"""

import numpy as np

_STYLE = {
    "minimax": dict(color="C3", lw=2.2, zorder=5),
    "ZV": dict(color="C0", lw=1.0),
    "MZV": dict(color="C1", lw=1.0),
    "ZVD": dict(color="C2", lw=1.0),
    "EI": dict(color="C4", lw=1.0),
    "2-hump EI": dict(color="C5", lw=1.0),
    "3-hump EI": dict(color="C8", lw=1.0),
}


def _style(name):
    if name in _STYLE:
        return _STYLE[name]
    if name.startswith("pseudo"):
        return dict(color="C6" if "robust" in name else "C8", lw=1.0, ls="--")
    return dict(color="0.5", lw=1.0, ls=":")


def plan_figure(plan):
    """One panel per mode: residual amplitude in % of the unshaped move (log scale) against frequency [Hz], the
    band $f_i(1 \\pm u)$ shaded and the 5 % level dashed; below, velocity and acceleration of every candidate."""
    import matplotlib.pyplot as plt

    n = plan.axis.n_modes
    factors, curves = plan.curves()
    fig, axes = plt.subplots(2, max(n, 2), figsize=(5.2 * max(n, 2), 7.4), constrained_layout=True, squeeze=False)
    freqs = np.asarray(plan.axis.frequencies)
    u = plan.uncertainty
    for i in range(n):
        ax = axes[0, i]
        f = factors * freqs[i]
        for name, cur in curves.items():
            ax.semilogy(f, np.maximum(cur[i], 1e-6), label=name, **_style(name))
        if u > 0:
            ax.axvspan(freqs[i] * (1 - u), freqs[i] * (1 + u), color="0.9", zorder=0)
        ax.axhline(5.0, color="k", ls="--", lw=0.7)
        ax.axvline(freqs[i], color="0.4", lw=0.6)
        ax.set_xlabel("mode frequency [Hz]")
        ax.set_ylabel("residual [% of unshaped]")
        zeta = (
            f"ζ = {float(plan.axis.damping_ratios[i]):.3g}"
            if plan.damping is None
            else f"ζ in [{plan.damping[0]:.3g}, {plan.damping[1]:.3g}] (worst)"
        )
        ax.set_title(f"mode {i + 1}: {freqs[i]:.3g} Hz, {zeta}")
        ax.set_ylim(1e-4, 300)
        ax.grid(alpha=0.3, which="both")
    for i in range(n, axes.shape[1]):
        axes[0, i].axis("off")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    axv, axa = axes[1, 0], axes[1, 1]
    for c in plan.table:
        if c.command is None:
            continue
        t, _, v, a = c.command.sample(2000.0 / max(c.move_time, 1e-9))
        axv.plot(t, v, label=c.name, **_style(c.name))
        axa.plot(t, a, label=c.name, **_style(c.name))
    for ax, lim, lab in ((axv, plan.v_max, "velocity [m/s]"), (axa, plan.a_max, "acceleration [m/s²]")):
        ax.axhline(lim, color="k", ls=":", lw=0.7)
        ax.axhline(-lim, color="k", ls=":", lw=0.7)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    for i in range(2, axes.shape[1]):
        axes[1, i].axis("off")
    best = plan.best
    rec = (
        f"recommended: {best.name} ({best.move_time:.3f} s, worst {best.worst_percent:.3g} %)"
        if best is not None
        else "no candidate recommended"
    )
    fig.suptitle(
        f"{plan.distance:g} m move, limits v ≤ {plan.v_max:g}, a ≤ {plan.a_max:g}"
        + (f", j ≤ {plan.j_max:g}" if plan.j_max is not None else "")
        + f"; band ±{100 * u:.0f} %; {rec}"
    )
    return fig
