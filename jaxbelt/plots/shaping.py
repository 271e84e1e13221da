"""Figures of the command-shaping scene (Incerti, pseudo-polynomial commands): the paper's Fig. 2 and Fig. 3, and the
sensitivity plot.

Drawing only: the responses come from `jaxbelt.platform_response`, the sensitivity curves from
`jaxbelt.sensitivity_curve` (residual amplitudes by default, drawn in % of a reference: the measure of
input-shaping practice; the paper's residual energy when asked, labelled as such).
"""

from __future__ import annotations

import numpy as np


def plot_fig3(before: dict, after: dict, *, move_times=None, axes=None, titles=("3-4-5 polynomial", "optimised")):
    """Paper's Fig. 3 (Incerti, pseudo-polynomial commands): platform velocity and acceleration (solid) with
    the rigid-body commands $\\lambda\\dot\\varphi_m$, $\\lambda\\ddot\\varphi_m$ (dashed), kinetic and
    elastic energy, for the command before (left column) and after (right column) the optimisation.

    `before`, `after`: the dicts of `jaxbelt.platform_response` (computed beforehand);
    `move_times`: the two move times [s], marked by a vertical line; `axes`: a 4 × 2 array.
    """
    import matplotlib.pyplot as plt

    if axes is None:
        _, axes = plt.subplots(4, 2, figsize=(10, 9), sharex=True)
    axes = np.asarray(axes)
    rows = [
        ("velocity", "command_velocity", "platform speed [rad/s]"),
        ("acceleration", "command_acceleration", "platform accel. [rad/s²]"),
        ("kinetic_energy", None, "kinetic energy [J]"),
        ("elastic_energy", None, "elastic energy [J]"),
    ]
    move_times = (None, None) if move_times is None else move_times
    for col, (r, title, t_move) in enumerate(zip((before, after), titles, move_times)):
        for row, (key, dashed, label) in enumerate(rows):
            ax = axes[row, col]
            ax.plot(r["t"], r[key], "C0-", lw=1.2)
            if dashed is not None:
                ax.plot(r["t"], r[dashed], "k--", lw=0.9)
            if t_move is not None:
                ax.axvline(float(t_move), color="0.6", lw=0.6)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(label)
        axes[0, col].set_title(title)
        axes[-1, col].set_xlabel("time [s]")
    # same scales left and right, as in the paper, so the residual vibration is comparable
    for row in range(axes.shape[0]):
        lo = min(a.get_ylim()[0] for a in axes[row])
        hi = max(a.get_ylim()[1] for a in axes[row])
        for a in axes[row]:
            a.set_ylim(lo, hi)
    return axes


def reference_level(omegas, curves: dict, omega0, reference, band=None) -> float:
    """The number a sensitivity plot divides by: `reference` itself when it is a number, else the worst value of
    the curve it names over `band` ((low, high) fractions of `omega0`; None: the whole sweep)."""
    if not isinstance(reference, str):
        return float(reference)
    x = np.asarray(omegas) / float(omega0)
    y = np.asarray(curves[reference])
    inside = np.ones_like(x, dtype=bool) if band is None else (x >= band[0] - 1e-12) & (x <= band[1] + 1e-12)
    return float(np.max(y[inside]))


def plot_sensitivity(
    omegas, curves: dict, omega0, *, ax=None, reference=None, level: float = 0.05, measure: str = "amplitude",
    band=None,
):  # fmt: skip
    """Residual vibration of each command against the actual natural frequency (relative to the design value
    `omega0`), log scale, one line per command.

    `measure="amplitude"` (default): `curves` are residual amplitudes (`sensitivity_curve`'s default). With
    `reference` (the name of a curve, standing for its worst over `band`, fractions of `omega0`, default the whole
    sweep; or a number in the curves' units) they are drawn in % of it, with the `level` line dotted (the 5 % band
    of input-shaping practice); without, in the curves' units [rad].
    `measure="energy"`: `curves` are the paper's residual energies E(T) [J]; with `reference` named, `level` × that
    curve is drawn dotted (an energy level: 5 % of the energy is 22 % of the amplitude).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 4))
    x = np.asarray(omegas) / float(omega0)
    if measure == "energy":
        floor = 1e-12 * max(float(np.max(np.asarray(c))) for c in curves.values())
        for name, e in curves.items():
            ax.semilogy(x, np.maximum(np.asarray(e), floor), label=name, lw=1.3)
        if reference is not None:
            ax.semilogy(x, level * np.asarray(curves[reference]), "k:", lw=0.9, label=f"{level:.0%} of {reference}")
        ax.set_ylabel("residual energy E(T) [J] (Incerti eq. 31)")
    else:
        scale, unit = 1.0, "residual amplitude [rad]"
        if reference is not None:
            scale = 100.0 / reference_level(omegas, curves, omega0, reference, band)
            what = reference if isinstance(reference, str) else "the reference"
            where = "" if band is None else f" over {band[0]:g}-{band[1]:g}"
            unit = f"residual amplitude [% of {what}'s worst{where}]"
        ys = {name: scale * np.asarray(c) for name, c in curves.items()}
        floor = 1e-6 * max(float(np.max(y)) for y in ys.values())
        for name, y in ys.items():
            ax.semilogy(x, np.maximum(y, floor), label=name, lw=1.3)
        if reference is not None:
            ax.axhline(100.0 * level, color="k", ls=":", lw=0.9, label=f"{level:.0%} level")
        ax.set_ylabel(unit)
    ax.axvline(1.0, color="0.6", lw=0.6)
    if band is not None:
        for b in band:
            ax.axvline(float(b), color="0.8", lw=0.6, ls="--")
    ax.set_xlabel("actual / design natural frequency")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, ncol=2)
    return ax


def shaping_figure(
    before: dict, after: dict, omegas, curves: dict, omega_n, *, move_times=None, reference=None, band=None,
    measure: str = "amplitude",
):  # fmt: skip
    """One figure: Fig. 3 (rows 1-4, from the `jaxbelt.platform_response` dicts `before`, `after`) and the
    sensitivity plot (row 5: `omegas` [rad/s], `curves` {label: residual amplitude [rad]} (or, with
    `measure="energy"`, E(T) [J]), design `omega_n` [rad/s]; `reference`, `band` as in `plot_sensitivity`).
    Returns the Figure."""
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(10, 12), constrained_layout=True)
    gs = fig.add_gridspec(5, 2, height_ratios=[1, 1, 1, 1, 1.6])
    axes = np.empty((4, 2), dtype=object)
    for i in range(4):
        for j in range(2):
            axes[i, j] = fig.add_subplot(gs[i, j], sharex=axes[0, 0] if (i, j) != (0, 0) else None)
    plot_fig3(before, after, move_times=move_times, axes=axes)
    plot_sensitivity(
        omegas, curves, omega_n, ax=fig.add_subplot(gs[4, :]), reference=reference, band=band, measure=measure
    )
    return fig


def plot_profiles(t, profiles: dict, *, axes=None, styles=("-", "--", ":", "-.")):
    """Incerti (pseudo-polynomial commands), Fig. 2: displacement, velocity and acceleration of motion commands.

    `t` (N,) [s]; `profiles`: `{label: (position [rad], velocity [rad/s], acceleration [rad/s²])}`,
    each (N,) (computed, e.g., from `PseudoPolynomial(...)(t)`, `.velocity(t)`, `.acceleration(t)`).
    The paper's figure: 3-4-5 polynomial (solid) and 4.5-6.2-8.4 pseudo-polynomial (dashed), T = 1 s,
    Φ = 1 rad.
    """
    import matplotlib.pyplot as plt

    if axes is None:
        _, axes = plt.subplots(1, 3, figsize=(13, 3.4))
    t = np.asarray(t)
    names = ("a) displacement [rad]", "b) velocity [rad/s]", "c) acceleration [rad/s²]")
    for j, (label, curves) in enumerate(profiles.items()):
        for k in range(3):
            axes[k].plot(
                t, np.asarray(curves[k]), styles[j % len(styles)], color="k" if j == 0 else f"C{j}", label=label
            )
    for k in range(3):
        axes[k].set_xlabel("t [s]")
        axes[k].set_ylabel(names[k])
        axes[k].grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return axes
