"""Figures of the non-linear belt scene (Moon & Wickert, 1997). Every function draws results
computed by the caller (`jaxbelt.models.nonlinear`); nothing here simulates.

- `plot_speed_response`: up/down peak-to-peak against running speed (Fig. 2 analogue);
- `plot_phase_plane`: $\\zeta^R_1$-$\\zeta^I_1$ trajectories ending on two limit cycles (Fig. 6);
- `plot_backbone`: modal amplitudes of the sweeps, KBM amplitudes (eq. 31) and backbone (eq. 33) (Fig. 7);
- `plot_response_curve`: a `ResponseCurve` with its unstable branch, folds and the measured jumps (Fig. 8 analogue);
- `plot_ramp`: a `RampRecord` (Fig. 3); `response_figure`: the page of `jaxbelt nonlinear`.
"""

from __future__ import annotations

import numpy as np


def plot_speed_response(ax, speeds, up, down):
    """Up and down peak-to-peak amplitudes [m] (arrays over `speeds` ascending) in mm."""
    s = np.asarray(speeds)
    ax.plot(s, 1e3 * np.asarray(up), "o-", ms=2.5, lw=1, label="increasing speed")
    ax.plot(s, 1e3 * np.asarray(down), "s--", ms=2.5, lw=1, mfc="none", label="decreasing speed")
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("peak-to-peak at 1 cm [mm]")
    ax.set_title("speed sweeps (Fig. 2 analogue)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def plot_phase_plane(ax, trajectories, speed, n_modes: int = 1, labels=None):
    """Trajectories (each (T, 2N) modal states, e.g. from `nonlinear_trajectory`) in the
    $\\zeta^R_1$-$\\zeta^I_1$ plane at `speed` [m/s]; the last 200 samples drawn bold."""
    for i, zs in enumerate(trajectories):
        zs = np.asarray(zs)
        lab = None if labels is None else labels[i]
        ax.plot(zs[:, 0], zs[:, n_modes], lw=0.4, alpha=0.6, color=f"C{i}")
        ax.plot(zs[-200:, 0], zs[-200:, n_modes], lw=1.8, color=f"C{i}", label=lab)
        ax.plot([zs[0, 0]], [zs[0, n_modes]], "k.", ms=4)
    ax.set_xlabel(r"$\zeta^R_1$")
    ax.set_ylabel(r"$\zeta^I_1$")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"phase plane at V = {float(speed):.2f} m/s (Fig. 6)")
    if labels is not None:
        ax.legend(fontsize=7, loc="upper right")


def plot_backbone(ax, speeds, amp_up, amp_down, kbm=None, backbone=None, title="Fig. 7"):
    """Fig. 7: modal amplitudes of the sweeps (filled: up, open: down); `kbm` = (speeds, amplitudes)
    of the KBM roots of eq. (31) (dots); `backbone` = (speeds, amplitudes) of eq. (33) (line)."""
    s = np.asarray(speeds)
    ax.plot(s, np.asarray(amp_up), "o", ms=3.5, color="k", label="simulation, up")
    ax.plot(s, np.asarray(amp_down), "o", ms=5, mfc="none", color="C3", label="simulation, down")
    if kbm is not None:
        ax.plot(np.asarray(kbm[0]), np.asarray(kbm[1]), ".", ms=1.5, color="C0", label="KBM eq. (31)")
    if backbone is not None:
        ax.plot(np.asarray(backbone[0]), np.asarray(backbone[1]), "-", color="C2", lw=1.2, label="backbone eq. (33)")
    ax.set_xlim(s.min(), s.max())
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("modal amplitude a [-]")
    ax.set_title(title)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


# --- response curve by continuation, ramps, measurements (computed by the caller) -------------------------
def plot_response_curve(ax, curve, measurements=None, *, title="response curve (HB + continuation)", mode: int = 1):
    """A `ResponseCurve`: stable points solid, unstable (saddle) dashed, folds as vertical lines;
    with `measurements` (the `MEASUREMENTS` table) the measured jumps as arrows (Fig. 8 analogue),
    or for `mode=2` the measured second-mode hysteresis band as a shaded span."""
    s, p, st = np.asarray(curve.speed), 1e3 * np.asarray(curve.pp), np.asarray(curve.stable)
    ps = np.where(st, p, np.nan)
    pu = np.where(~st | np.r_[~st[1:], False] | np.r_[False, ~st[:-1]], p, np.nan)
    ax.plot(s, ps, "-", color="C0", lw=1.6, label="stable (Floquet)")
    ax.plot(s, pu, "--", color="C3", lw=1.2, label="unstable")
    for k, f in enumerate(np.asarray(curve.folds)):
        ax.axvline(f, color="0.5", lw=0.8, ls=":", label="folds" if k == 0 else None)
    if measurements is not None and mode == 2:
        m = {x.quantity: x.value for x in measurements}
        ax.axvspan(
            m["mode2_band_low"], m["mode2_band_high"], color="C2", alpha=0.15, label="measured hysteresis band (Sec. 2)"
        )
    elif measurements is not None:
        m = {x.quantity: x.value for x in measurements}
        ax.annotate(
            "",
            xy=(m["up_jump_speed"], 1e3 * m["up_jump_pp_after"]),
            xytext=(m["up_jump_speed"], 1e3 * m["up_jump_pp_before"]),
            arrowprops=dict(arrowstyle="->", color="k"),
        )
        ax.annotate(
            "",
            xy=(m["down_jump_speed"], 1e3 * m["down_jump_pp_after"]),
            xytext=(m["down_jump_speed"], 1e3 * m["down_jump_pp_before"]),
            arrowprops=dict(arrowstyle="->", color="C2"),
        )
        ax.plot(
            [m["up_jump_speed"]] * 2,
            [1e3 * m["up_jump_pp_before"], 1e3 * m["up_jump_pp_after"]],
            "ko",
            ms=5,
            label="measured, increasing (Sec. 2)",
        )
        ax.plot(
            [m["down_jump_speed"]] * 2,
            [1e3 * m["down_jump_pp_before"], 1e3 * m["down_jump_pp_after"]],
            "o",
            color="C2",
            mfc="none",
            ms=6,
            label="measured, decreasing (Sec. 2)",
        )
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("peak-to-peak at 1 cm [mm]")
    ax.set_title(title)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def plot_ramp(ax, record, *, title=None):
    """A `RampRecord`: displacement [mm] 1 cm from the sensor pulley against the belt speed (Fig. 3)."""
    ax.plot(np.asarray(record.speed), 1e3 * np.asarray(record.w), lw=0.3)
    v0, v1 = float(record.speed[0]), float(record.speed[-1])
    ax.set_xlabel("running speed V [m/s] (ramped in time)")
    ax.set_ylabel("w at 1 cm [mm]")
    ax.set_title(title or f"speed ramp {v0:.2f} -> {v1:.2f} m/s in {float(record.t[-1]):.3g} s (Fig. 3)")
    ax.grid(alpha=0.3)
    if v0 > v1:
        ax.invert_xaxis()


def response_figure(curve, ramp_up, ramp_down, measurements, summary: str = "", jumps=None, curve2=None):
    """One page: the response curve with its unstable branch, folds and the measured jumps
    (with `jumps`, a `Jumps`, the predicted jumps as arrows too), the up/down ramp records and,
    with `curve2` (the two-mode curve over the second resonance), the second-mode curve against
    the measured band (all computed by the caller). Returns the figure."""
    import matplotlib.pyplot as plt  # on first use: `import jaxbelt` loads no plotting library

    if curve2 is None:
        fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    else:
        fig, grid = plt.subplots(2, 2, figsize=(14, 9))
        axes = [grid[0, 0], grid[1, 0], grid[1, 1]]
        plot_response_curve(
            grid[0, 1], curve2, measurements, mode=2, title="second mode (2-mode model) vs the measured band"
        )
    plot_response_curve(axes[0], curve, measurements, title="predicted vs measured (Fig. 8 analogue)")
    if jumps is not None:
        for V, b, a in zip(*(np.asarray(x) for x in (jumps.speed, jumps.pp_before, jumps.pp_after))):
            axes[0].annotate(
                "", xy=(V, 1e3 * a), xytext=(V, 1e3 * b), arrowprops=dict(arrowstyle="->", color="C1", lw=1.5)
            )
        axes[0].plot([], [], color="C1", lw=1.5, label="predicted jumps")
        axes[0].legend(fontsize=7)
    plot_ramp(axes[1], ramp_up)
    plot_ramp(axes[2], ramp_down)
    if summary:
        axes[0].text(0.02, 0.98, summary, transform=axes[0].transAxes, fontsize=7, va="top", family="monospace")
    fig.tight_layout()
    return fig
