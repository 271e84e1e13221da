"""Figures of the four-bar drive (Incerti, 2012): the paper's Fig. 4 and a linkage snapshot strip.

Drawing only: the runs come from `jaxbelt.simulate_fig4` (or `jaxbelt.simulate`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def fourbar_figure(
    open_sol,
    closed_sol,
    *,
    omega_ref: float = 30.0,
    voltage: float = 25.0,
    chi_window=(0.375, 0.5),
    title: str | None = None,
):
    """Paper Fig. 4: open loop (left) and closed loop (right), rows a-b motor speed with the set
    point, c-d voltage, e-f current, g-h mechanical and electric power.

    `open_sol`, `closed_sol`: the two `Solution`s of `jaxbelt.simulate_fig4` (computed beforehand;
    they observe `FIG4_OUTPUTS`). The χ of each run is written in its speed panel (open loop: over the
    second half of the run; closed loop: over `chi_window`). Returns the matplotlib `Figure`.
    """
    import matplotlib.pyplot as plt

    from ..objectives.fluctuation import fluctuation_index

    fig, axes = plt.subplots(4, 2, figsize=(10, 10), sharex="col", constrained_layout=True)
    letters = iter("abcdefgh")
    for col, (sol, label) in enumerate(((open_sol, f"open loop, {voltage:g} V"), (closed_sol, "closed loop, PID"))):
        t = np.asarray(sol.ts)
        ax = axes[0, col]
        ax.plot(t, np.asarray(sol.motor_speed), color="C0")
        ax.axhline(omega_ref, color="k", ls="--", lw=0.8)
        if col == 0:
            w0, w1 = 0.5 * float(t[-1]), float(t[-1])
        else:
            w0, w1 = chi_window
        chi = float(fluctuation_index(sol, w0, w1))
        ax.set_title(f"{label}: χ = {100 * chi:.1f} % over {w0:g}–{w1:g} s")
        ax.set_ylabel("motor speed [rad/s]")
        axes[1, col].plot(t, np.asarray(sol.voltage), color="C1")
        axes[1, col].set_ylabel("voltage [V]")
        axes[2, col].plot(t, np.asarray(sol.current), color="C2")
        axes[2, col].set_ylabel("current [A]")
        axes[3, col].plot(t, np.asarray(sol.mechanical_power), color="C3", label="mechanical")
        axes[3, col].plot(t, np.asarray(sol.electric_power), color="C4", lw=0.9, label="electric")
        axes[3, col].set_ylabel("power [W]")
        axes[3, col].legend(loc="upper right", fontsize=8)
        axes[3, col].set_xlabel("time [s]")
    for ax in axes.ravel():  # the paper letters row by row: a-b speed, c-d voltage, ...
        ax.grid(alpha=0.3)
        ax.text(0.01, 0.92, f"{next(letters)})", transform=ax.transAxes, fontsize=9)
    fig.suptitle(title or "Four-bar linkage driven by a DC motor (Fig. 4; Table I values partly assumed)")
    return fig


def linkage_strip(drive=None, alphas=None, *, n: int = 8, ax=None):
    """Snapshot strip of the linkage at `n` crank angles over one turn (or at `alphas` [rad]).

    Each snapshot shows the crank A-B, coupler B-C, rocker D-C, the fixed pivots and the centres
    of mass G1-G3. Returns the matplotlib `Figure`.
    """
    import matplotlib.pyplot as plt

    from ..models.fourbar import FourBarDrive

    drive = FourBarDrive() if drive is None else drive
    alphas = np.linspace(0.0, 2 * np.pi, n, endpoint=False) if alphas is None else np.asarray(alphas, dtype=float)
    pts = {k: np.asarray(v) for k, v in drive.points(jnp.asarray(alphas)).items()}
    allx = np.concatenate([pts[k][:, 0] for k in ("A", "B", "C", "D")])
    ally = np.concatenate([pts[k][:, 1] for k in ("A", "B", "C", "D")])
    width = allx.max() - allx.min()
    gap = 0.25 * width
    if ax is None:
        fig, ax = plt.subplots(figsize=(1.6 * len(alphas) + 1, 2.6), constrained_layout=True)
    else:
        fig = ax.figure
    for j, al in enumerate(alphas):
        dx = j * (width + gap)
        P = {k: v[j] + np.array([dx, 0.0]) for k, v in pts.items()}
        for (p, q), col in ((("A", "B"), "C0"), (("B", "C"), "C1"), (("D", "C"), "C2")):
            ax.plot([P[p][0], P[q][0]], [P[p][1], P[q][1]], color=col, lw=2.5, solid_capstyle="round")
        for k in ("A", "D"):
            ax.plot(*P[k], marker="^", color="k", ms=7)
        for k in ("B", "C"):
            ax.plot(*P[k], marker="o", color="k", ms=3)
        for k in ("G1", "G2", "G3"):
            ax.plot(*P[k], marker="x", color="0.3", ms=4)
        ax.text(
            dx + 0.5 * (allx.min() + allx.max()),
            ally.min() - 0.06 * width,
            f"α = {np.degrees(al):.0f}°",
            ha="center",
            va="top",
            fontsize=8,
        )
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title("four-bar linkage over one crank turn (A, D fixed pivots; x: centres of mass)", fontsize=9)
    return fig


def plot_regulators(solutions: dict, *, omega_ref: float = 30.0, chi_window=(0.375, 0.5), ax=None):
    """Motor speed under several regulators, e.g. the ramped gain $K_p t$ (Incerti, 2012, eq. 16)
    against a constant gain (eq. 14). `solutions`: `{label: Solution}` observing `motor_speed`
    (computed beforehand); the legend gives χ over `chi_window` [s] (time-mean average)."""
    import matplotlib.pyplot as plt

    from ..objectives.fluctuation import fluctuation_index

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    for label, sol in solutions.items():
        chi = float(fluctuation_index(sol, *chi_window))
        ax.plot(np.asarray(sol.ts), np.asarray(sol.motor_speed), label=f"{label}: χ = {100 * chi:.2f} %")
    ax.axhline(omega_ref, color="k", ls="--", lw=0.8)
    ax.axvspan(*chi_window, color="0.9")
    ax.set_ylim(0.0, 1.5 * omega_ref)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("motor speed [rad/s]")
    ax.set_title("PID with ramped (eq. 16) and constant (eq. 14) proportional gain")
    ax.legend(fontsize=8)
    return ax
