"""Figures of the non-linear belt scene (Moon & Wickert, 1997): Fig. 2, 6 and 7 analogues.

- `plot_speed_response`: peak-to-peak response 1 cm from the driven pulley against running
  speed, increasing and decreasing quasi-static sweeps (Fig. 2 analogue);
- `plot_phase_plane`: $\\zeta^R_1$-$\\zeta^I_1$ trajectories from several initial conditions at
  one speed inside the hysteresis band, ending on two different limit cycles (Fig. 6);
- `plot_backbone`: simulated up/down modal amplitudes, the KBM steady amplitudes (eq. 31) and
  the backbone (eq. 33) for one $v_l$ (Fig. 7);
- `nonlinear_figure`: all of them on one page (used by `jaxbelt nonlinear`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..models.nonlinear import NonlinearBelt
from ..models.nonlinear.kbm import backbone_speed, kbm_amplitudes
from ..models.nonlinear.steady import nonlinear_basins, nonlinear_sweep, nonlinear_trajectory


def plot_speed_response(ax, speeds, up, down, *, label_jumps=True):
    """Up and down peak-to-peak amplitudes [m] (arrays over `speeds` ascending) in mm."""
    s = np.asarray(speeds)
    ax.plot(s, 1e3 * np.asarray(up), "o-", ms=2.5, lw=1, label="increasing speed")
    ax.plot(s, 1e3 * np.asarray(down), "s--", ms=2.5, lw=1, mfc="none", label="decreasing speed")
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("peak-to-peak at 1 cm [mm]")
    ax.set_title("speed sweeps (Fig. 2 analogue)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def response_sweeps(belt: NonlinearBelt, speeds, **kw):
    """(up, down) `SweepResult`s for ascending `speeds`, as in the experiment: the decreasing
    sweep starts from the final state of the increasing one; down is returned in ascending order."""
    speeds = jnp.asarray(speeds, dtype=float)
    up = nonlinear_sweep(belt, speeds, **kw)
    dn = nonlinear_sweep(belt, speeds[::-1], up.steady.z[-1], up.steady.theta[-1], **kw)
    return up, _reverse(dn)


def _reverse(res):
    return jax.tree_util.tree_map(lambda a: a[::-1], res)


def plot_phase_plane(ax, belt: NonlinearBelt, speed, z0s, periods=150):
    """Trajectories in the $\\zeta^R_1$-$\\zeta^I_1$ plane from each row of `z0s` at `speed`."""
    ss = nonlinear_basins(belt, speed, z0s)
    for i, z0 in enumerate(np.asarray(z0s)):
        _, zs = nonlinear_trajectory(belt, speed, z0, periods=periods)
        zs = np.asarray(zs)
        ax.plot(zs[:, 0], zs[:, belt.n_modes], lw=0.4, alpha=0.6, color=f"C{i}")
        ax.plot(zs[-200:, 0], zs[-200:, belt.n_modes], lw=1.8, color=f"C{i}",
                label=f"start a={np.hypot(z0[0], z0[belt.n_modes]):.1e}: pp {1e3 * float(ss.pp[i]):.2f} mm")
        ax.plot([z0[0]], [z0[belt.n_modes]], "k.", ms=4)
    ax.set_xlabel(r"$\zeta^R_1$")
    ax.set_ylabel(r"$\zeta^I_1$")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"phase plane at V = {float(speed):.2f} m/s (Fig. 6)")
    ax.legend(fontsize=7, loc="upper right")


def plot_backbone(ax, belt: NonlinearBelt, speeds, up=None, down=None):
    """Fig. 7 for one belt: simulated modal amplitudes (filled: up, open: down), KBM roots of
    eq. (31) (dots) and the backbone of eq. (33) (line)."""
    s = np.asarray(speeds)
    if up is None or down is None:
        up, down = response_sweeps(belt, speeds)
    ax.plot(s, np.asarray(up.steady.amplitude[:, 0]), "o", ms=3.5, color="k", label="simulation, up")
    ax.plot(s, np.asarray(down.steady.amplitude[:, 0]), "o", ms=5, mfc="none", color="C3", label="simulation, down")
    fine = np.linspace(s.min(), s.max(), 200)
    pts = [(sp, a) for sp in fine for a in kbm_amplitudes(belt, sp)]
    if pts:
        p = np.array(pts)
        ax.plot(p[:, 0], p[:, 1], ".", ms=1.5, color="C0", label="KBM eq. (31)")
    amax = 1.15 * float(np.max(np.asarray(up.steady.amplitude[:, 0])))
    a = np.linspace(0, amax, 100)
    ax.plot(np.asarray(backbone_speed(belt, a)), a, "-", color="C2", lw=1.2, label="backbone eq. (33)")
    ax.set_xlim(s.min(), s.max())
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("modal amplitude a [-]")
    ax.set_title(f"v_l = {float(belt.v_l):g}, damping {float(belt.damping):g} (Fig. 7)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def nonlinear_figure(belt: NonlinearBelt | None = None, *, quick: bool = False, n_modes: int = 2):
    """The scene on one page: Fig. 2 sweep (N = `n_modes`), Fig. 6 phase plane, Fig. 7 for
    v_l = 25, 50, 75 (N = 1). `quick` uses coarser speed grids. Returns the figure."""
    belt = NonlinearBelt() if belt is None else belt
    b2 = NonlinearBelt(span=belt.span, wave_speed=belt.wave_speed, v_l=belt.v_l, pulley_radii=belt.pulley_radii,
                       runout=belt.runout, phase=belt.phase, damping=belt.damping, n_modes=n_modes)
    b1 = NonlinearBelt(span=belt.span, wave_speed=belt.wave_speed, v_l=belt.v_l, pulley_radii=belt.pulley_radii,
                       runout=belt.runout, phase=belt.phase, damping=belt.damping, n_modes=1)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    step = 0.25 if quick else 0.1
    fine = 0.05 if quick else 0.02  # the hysteresis band near the first crossing is narrow
    c1 = float(belt.crossing_speeds(1)[0])
    speeds = jnp.concatenate([jnp.arange(0.5, c1 - 0.5, step), jnp.arange(c1 - 0.5, c1 + 1.0, fine),
                              jnp.arange(c1 + 1.0, 17.0 + 1e-9, step)])
    up, dn = response_sweeps(b2, speeds)
    plot_speed_response(axes[0, 0], speeds, up.pp, dn.pp)
    band = jnp.linspace(8.8, 9.8, 11 if quick else 26)
    up1, dn1 = response_sweeps(b1, band)
    diff = np.abs(np.asarray(up1.steady.amplitude[:, 0] - dn1.steady.amplitude[:, 0]))
    i = int(np.argmax(diff))
    sp = float(band[i])
    zs = np.array([np.asarray(up1.steady.z[i]), np.asarray(dn1.steady.z[i])])
    z0s = np.concatenate([0.2 * zs[1:2], 1.1 * zs[0:1], np.array([[0.0, 0.0]])])
    plot_phase_plane(axes[0, 1], b1, sp, z0s, periods=60 if quick else 150)
    axes[0, 2].axis("off")
    axes[0, 2].text(0.0, 0.9, _summary(b2, speeds, up, dn), fontsize=9, va="top", family="monospace")
    for ax, vl in zip(axes[1], (25.0, 50.0, 75.0)):
        b = NonlinearBelt(span=belt.span, wave_speed=belt.wave_speed, v_l=vl, pulley_radii=belt.pulley_radii,
                          runout=belt.runout, phase=belt.phase, damping=belt.damping, n_modes=1)
        sp_ = jnp.linspace(8.8, 10.2, 15 if quick else 36)
        u, d = response_sweeps(b, sp_)
        plot_backbone(ax, b, sp_, u, d)
    fig.tight_layout()
    return fig


def _summary(belt, speeds, up, dn):
    s = np.asarray(speeds)
    u, d = np.asarray(up.pp), np.asarray(dn.pp)
    au, ad = np.asarray(up.steady.amplitude[:, 0]), np.asarray(dn.steady.amplitude[:, 0])
    band = s[np.abs(au - ad) > 0.05 * np.maximum(au, ad)]
    lines = [
        "NonlinearBelt (Moon & Wickert 1997)",
        f"span {float(belt.span):g} m, v_t {float(belt.wave_speed):g} m/s, v_l {float(belt.v_l):g}",
        f"run-out {np.asarray(belt.runout) * 2e3} mm p-p",
        f"damping ratio {float(belt.damping):g}, N = {belt.n_modes}",
        f"linear crossings {np.round(np.asarray(belt.crossing_speeds(2)), 2)} m/s",
        f"max pp up {1e3 * u.max():.2f} mm, down {1e3 * d.max():.2f} mm",
    ]
    if band.size:
        lines.append(f"hysteresis band {band.min():.2f}-{band.max():.2f} m/s")
    lines.append(f"all converged: {bool(np.all(up.converged) and np.all(dn.converged))}")
    return "\n".join(lines)


# --- response curve by continuation, ramps, measurements (computed by the caller) -------------------------
def plot_response_curve(ax, curve, measurements=None, *, title="response curve (HB + continuation)"):
    """A `ResponseCurve`: stable points solid, unstable (saddle) dashed, folds as vertical lines;
    with `measurements` (the `MEASUREMENTS` table) the measured jumps as arrows (Fig. 8 analogue)."""
    s, p, st = np.asarray(curve.speed), 1e3 * np.asarray(curve.pp), np.asarray(curve.stable)
    ps = np.where(st, p, np.nan)
    pu = np.where(~st | np.r_[~st[1:], False] | np.r_[False, ~st[:-1]], p, np.nan)
    ax.plot(s, ps, "-", color="C0", lw=1.6, label="stable (Floquet)")
    ax.plot(s, pu, "--", color="C3", lw=1.2, label="unstable")
    for k, f in enumerate(np.asarray(curve.folds)):
        ax.axvline(f, color="0.5", lw=0.8, ls=":", label="folds" if k == 0 else None)
    if measurements is not None:
        m = {x.quantity: x.value for x in measurements}
        ax.annotate("", xy=(m["up_jump_speed"], 1e3 * m["up_jump_pp_after"]),
                    xytext=(m["up_jump_speed"], 1e3 * m["up_jump_pp_before"]), arrowprops=dict(arrowstyle="->", color="k"))
        ax.annotate("", xy=(m["down_jump_speed"], 1e3 * m["down_jump_pp_after"]),
                    xytext=(m["down_jump_speed"], 1e3 * m["down_jump_pp_before"]),
                    arrowprops=dict(arrowstyle="->", color="C2"))
        ax.plot([m["up_jump_speed"]] * 2, [1e3 * m["up_jump_pp_before"], 1e3 * m["up_jump_pp_after"]], "ko", ms=5,
                label="measured, increasing (Sec. 2)")
        ax.plot([m["down_jump_speed"]] * 2, [1e3 * m["down_jump_pp_before"], 1e3 * m["down_jump_pp_after"]], "o",
                color="C2", mfc="none", ms=6, label="measured, decreasing (Sec. 2)")
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
    ax.set_title(title or f"speed ramp {v0:g} -> {v1:g} m/s in {float(record.t[-1]):g} s (Fig. 3)")
    ax.grid(alpha=0.3)
    if v0 > v1:
        ax.invert_xaxis()


def response_figure(curve, ramp_up, ramp_down, measurements, summary: str = ""):
    """One page: the response curve with its unstable branch, folds and the measured jumps,
    and the up/down ramp records (all computed by the caller). Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    plot_response_curve(axes[0], curve, measurements, title="predicted vs measured (Fig. 8 analogue)")
    plot_ramp(axes[1], ramp_up)
    plot_ramp(axes[2], ramp_down)
    if summary:
        axes[0].text(0.02, 0.98, summary, transform=axes[0].transAxes, fontsize=7, va="top", family="monospace")
    fig.tight_layout()
    return fig
