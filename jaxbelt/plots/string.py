"""Figures of the belt-span scene: belt-vibration report figs. 37-43 and Moon & Wickert's Fig. 5.

Drawing only: crossing diagrams, run-out responses and Galerkin errors are computed beforehand
(`jaxbelt.crossing_diagram`, `jaxbelt.crossing_speeds`, `jaxbelt.linear_runout_response`,
`MovingString.galerkin_frequencies`); the closed-form contact pressure (eq. 10), span frequencies
(eq. 51) and exciting speeds (eq. 55) are evaluated here.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..models.contact import BeltPulleyContact
from ..models.string import TABLE2_COMPUTED_RPM, TABLE2_MEASURED_RPM, MovingString, exciting_speeds

__all__ = [
    "plot_contact_pressure",
    "plot_frequency_harmonics",
    "plot_exciting_speeds",
    "plot_crossing_diagram",
    "plot_runout_response",
    "plot_galerkin_convergence",
    "string_figure",
    "plot_mode_shapes",
    "plot_span_frequencies",
    "modes_figure",
]

RPM = 30.0 / np.pi  # rad/s -> rpm


def _ax(ax):
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 4))
    return ax


def plot_contact_pressure(contact: BeltPulleyContact | None = None, rpm: float = 15000.0, ax=None):
    """Belt-vibration report, Fig. 40: contact pressure $p(\\alpha)$ over the wrap at `rpm` (eq. 10).

    Default contact: the belt-vibration report's values with an ASSUMED motor-pulley radius of 25 mm (not in the text).
    """
    contact = BeltPulleyContact(radius=0.025) if contact is None else contact
    ax = _ax(ax)
    omega = rpm / RPM
    a = np.linspace(0.0, float(contact.wrap_angle), 200)
    p = np.asarray(contact.pressure(a, omega))
    ax.plot(np.degrees(a), p, label=f"{rpm:.0f} rpm")
    ax.plot(np.degrees(a), np.asarray(contact.pressure(a, 0.0)), ":", color="gray", label="at rest")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("wrap position α [deg]")
    ax.set_ylabel("contact pressure p [N/m]")
    ax.set_title(f"Belt pressure on the pulley (R = {1e3 * float(contact.radius):.1f} mm)")
    ax.legend(fontsize=8)
    return ax


def plot_frequency_harmonics(
    span: MovingString | None = None,
    pulley_radius: float = 0.1166,
    n_modes: int = 3,
    harmonics=range(3, 10),
    max_rpm: float = 2000.0,
    ax=None,
):
    """Belt-vibration report, Fig. 41: sub-multiples $\\omega_n/m$ of the span frequencies against rotor speed (eq. 51).

    The rotor harmonic m meets mode n where the line $\\omega_U$ crosses $\\omega_n(\\omega_U R_U)/m$;
    the crossings are the exciting speeds of eq. (55) (dots).
    """
    span = MovingString() if span is None else span
    import matplotlib.pyplot as plt

    ax = _ax(ax)
    rpm = np.linspace(0.0, max_rpm, 400)
    wn = np.asarray(span.natural_frequencies(jnp.asarray(rpm / RPM * pulley_radius), n_modes))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i in range(n_modes):
        for m in harmonics:
            ax.plot(
                rpm,
                wn[:, i] / m * RPM,
                "--",
                lw=0.7,
                color=colors[i % len(colors)],
                label=f"n = {i + 1}" if m == list(harmonics)[0] else None,
            )
            w = float(exciting_speeds(span, pulley_radius, i + 1, m)) * RPM
            if w <= max_rpm:
                ax.plot(w, w, "o", ms=3, color=colors[i % len(colors)])
    ax.plot(rpm, rpm, "k", lw=1, label="rotor speed")
    ax.set_xlim(0, max_rpm)
    ax.set_ylim(0, max_rpm)
    ax.set_xlabel("rotor speed [rpm]")
    ax.set_ylabel("ω_n / m [rpm]")
    ax.set_title(f"Span frequencies / harmonic order m = {min(harmonics)}..{max(harmonics)}")
    ax.legend(fontsize=8)
    return ax


def plot_exciting_speeds(span: MovingString | None = None, pulley_radius: float = 0.1166, ax=None):
    """Belt-vibration report, Fig. 43 / Table 2: exciting speeds of eq. (55) against the measured speeds."""
    span = MovingString() if span is None else span
    ax = _ax(ax)
    markers = {1: "o", 2: "s", 3: "^"}
    for (n, m), paper in TABLE2_COMPUTED_RPM.items():
        w = float(exciting_speeds(span, pulley_radius, n, m)) * RPM
        ax.plot(w, n, markers[n], color="C0", mfc="none")
        ax.annotate(f"m={m}", (w, n), textcoords="offset points", xytext=(0, 6), fontsize=6, ha="center")
        ax.plot(paper, n, "x", color="C1", ms=5)
    for meas, _ in TABLE2_MEASURED_RPM:
        ax.axvline(meas, color="C2", lw=0.8, alpha=0.6)
    ax.plot([], [], "o", color="C0", mfc="none", label="eq. (55), this code")
    ax.plot([], [], "x", color="C1", label="Table 2, computed")
    ax.plot([], [], "-", color="C2", label="measured")
    ax.set_yticks([1, 2, 3])
    ax.set_ylim(0.5, 3.6)
    ax.set_xlabel("rotor speed [rpm]")
    ax.set_ylabel("mode n")
    ax.set_title("Exciting speeds vs measurements")
    ax.legend(fontsize=7, loc="lower right")
    return ax


def plot_crossing_diagram(speeds, natural, load, crossings, pulley_radii, *, harmonics=None, ax=None):
    """Moon & Wickert (1997), Fig. 5(a): natural frequencies and pulley load lines against running speed.

    `speeds` (N,) [m/s]; `natural` (N, n_modes) and `load` (N, n_pulleys, n_harmonics) [rad/s] from
    `jaxbelt.crossing_diagram`; `crossings` (n_modes, n_pulleys, n_harmonics) [m/s] from
    `jaxbelt.crossing_speeds` (dots); `pulley_radii` [m]; `harmonics`: the harmonic orders (default 1, 2, ...).
    """
    ax = _ax(ax)
    V = np.asarray(speeds)
    vmax = float(V[-1])
    nat, load = np.asarray(natural) / (2 * np.pi), np.asarray(load) / (2 * np.pi)
    radii = np.atleast_1d(np.asarray(pulley_radii, dtype=float))
    vc = np.asarray(crossings)
    ks = np.arange(1, load.shape[2] + 1) if harmonics is None else np.atleast_1d(np.asarray(harmonics))
    for i in range(nat.shape[1]):
        ax.plot(V, nat[:, i], "k", lw=1.2, label="ω_n / 2π" if i == 0 else None)
    ls = ["-", "--", ":", "-."]
    for j in range(load.shape[1]):
        for k in range(load.shape[2]):
            ax.plot(
                V,
                load[:, j, k],
                ls[j % 4],
                color=f"C{k}",
                lw=0.9,
                label=f"pulley {j} (r = {1e3 * radii[j]:.0f} mm), harmonic {ks[k]:g}" if k < 3 else None,
            )
    for i in range(vc.shape[0]):
        for j in range(vc.shape[1]):
            for k in range(vc.shape[2]):
                if vc[i, j, k] <= vmax:
                    f = ks[k] * vc[i, j, k] / radii[j] / (2 * np.pi)
                    ax.plot(vc[i, j, k], f, "o", color="C3", ms=4)
                    if j == 0 and k == 0:
                        ax.annotate(
                            f"{vc[i, j, k]:.2f} m/s",
                            (vc[i, j, k], f),
                            textcoords="offset points",
                            xytext=(4, -10),
                            fontsize=7,
                        )
    ax.set_xlim(0, vmax)
    ax.set_ylim(0, 1.05 * nat[0, -1])
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title("Frequency crossing diagram")
    ax.legend(fontsize=7)
    return ax


def plot_runout_response(speeds, responses: dict, crossings=None, *, ax=None):
    """Moon & Wickert (1997), Fig. 5(b): linear steady peak-to-peak response [mm] against running speed.

    `speeds` (N,) [m/s]; `responses`: `{label: peak-to-peak [m] of shape (N,)}` (from
    `jaxbelt.linear_runout_response`); `crossings` [m/s] (any shape; e.g. `jaxbelt.crossing_speeds`)
    are marked by dotted lines.
    """
    ax = _ax(ax)
    V = np.asarray(speeds)
    vmax = float(V[-1])
    for label, pp in responses.items():
        ax.semilogy(V, 1e3 * np.asarray(pp), lw=1.2 if not ax.lines else 0.9, label=label)
    if crossings is not None:
        for v in np.unique(np.round(np.asarray(crossings).ravel(), 9)):
            if v <= vmax:
                ax.axvline(v, color="C3", lw=0.6, ls=":")
    ax.set_xlim(0, vmax)
    ax.set_xlabel("running speed V [m/s]")
    ax.set_ylabel("peak-to-peak displacement [mm]")
    ax.set_title("Linear response to pulley run-out")
    ax.legend(fontsize=8)
    return ax


def plot_galerkin_convergence(n_basis, errors, speed, *, ax=None):
    """Relative error of the Galerkin frequencies against eq. (39) versus the number of sine modes.

    `n_basis` (K,) numbers of sine modes, `errors` (K, n_modes) relative frequency errors (computed
    from `MovingString.galerkin_frequencies` and `MovingString.natural_frequencies`), `speed` [m/s].
    """
    ax = _ax(ax)
    Ns = np.asarray(n_basis)
    err = np.asarray(errors)
    for i in range(err.shape[1]):
        ax.loglog(Ns, err[:, i], "o-", label=f"mode {i + 1}")
    ax.loglog(Ns, 0.5 * err[0, 0] * (Ns / Ns[0]) ** -3.0, "k:", label="N^-3")
    ax.set_xticks(Ns, [str(n) for n in Ns])
    ax.minorticks_off()
    ax.set_xlabel("number of sine modes N")
    ax.set_ylabel("relative frequency error")
    ax.set_title(f"Galerkin vs eq. (39), V = {float(speed):g} m/s")
    ax.legend(fontsize=8)
    return ax


def string_figure(
    diagram: dict,
    response: dict,
    galerkin: dict,
    *,
    contact: BeltPulleyContact | None = None,
    span: MovingString | None = None,
    pulley_radius: float = 0.1166,
):
    """All figures of the scene on one page (the `jaxbelt string` CLI figure), from computed results.

    `diagram`: keyword arguments of `plot_crossing_diagram`; `response`: of `plot_runout_response`;
    `galerkin`: of `plot_galerkin_convergence`. `contact`, `span`, `pulley_radius` [m] for the
    closed-form panels (pressure, Fig. 41, Fig. 43).
    """
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, 3, figsize=(16, 9.5))
    plot_contact_pressure(contact, ax=axs[0, 0])
    plot_frequency_harmonics(span, pulley_radius, ax=axs[0, 1])
    plot_exciting_speeds(span, pulley_radius, ax=axs[0, 2])
    plot_crossing_diagram(**diagram, ax=axs[1, 0])
    plot_runout_response(**response, ax=axs[1, 1])
    plot_galerkin_convergence(**galerkin, ax=axs[1, 2])
    fig.tight_layout()
    return fig


def plot_mode_shapes(x, t, shapes, *, axes=None, labels=None):
    """Belt-vibration report, Figs. 37-39: snapshots of the travelling mode shapes of eq. (49).

    `x` (Nx,) [m] along the span, `t` (Nt,) [s] snapshot times, `shapes` (n_modes, Nt, Nx): the
    deflection $y(x, t)$ of each mode (computed, e.g., by `MovingString.mode_shape`). Draws one
    panel per mode; the points of the belt do not cross zero at the same time.
    """
    import matplotlib.pyplot as plt

    x, t, shapes = np.asarray(x), np.asarray(t), np.asarray(shapes)
    n = shapes.shape[0]
    if axes is None:
        axes = plt.subplots(1, n, figsize=(4.5 * n, 3.2), squeeze=False)[1][0]
    axes = np.ravel(np.asarray(axes, dtype=object))  # one Axes or a sequence of them
    cmap = plt.get_cmap("viridis")
    for i in range(n):
        ax = axes[i]
        for k in range(t.size):
            ax.plot(1e3 * x, shapes[i, k], color=cmap(k / max(t.size - 1, 1)), lw=1.0)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("x along the span [mm]")
        ax.set_ylabel("y [units of B1]")
        ax.set_title(labels[i] if labels is not None else f"mode {i + 1} (Fig. {37 + i})")
    return axes


def plot_span_frequencies(rotor_rpm, frequencies, critical_rpm, *, ax=None):
    """Belt-vibration report, eq. (51) and (53): span frequencies $\\omega_n$ against rotor speed
    $\\omega_U$, falling to zero at the critical rotor speed $\\omega_{CR}$.

    `rotor_rpm` (N,), `frequencies` (N, n_modes) [rad/s], `critical_rpm` [rpm] (computed values).
    """
    ax = _ax(ax)
    rotor_rpm, frequencies = np.asarray(rotor_rpm), np.asarray(frequencies)
    for i in range(frequencies.shape[1]):
        ax.plot(rotor_rpm, frequencies[:, i] * RPM, label=f"n = {i + 1}")
    ax.axvline(float(critical_rpm), color="k", ls="--", lw=0.8)
    ax.annotate(
        f"ω_CR = {float(critical_rpm):.0f} rpm",
        (float(critical_rpm), 0.0),
        textcoords="offset points",
        xytext=(-4, 8),
        ha="right",
        fontsize=8,
    )
    ax.set_xlabel("rotor speed ω_U [rpm]")
    ax.set_ylabel("span frequency ω_n [rpm]")
    ax.set_title("Eq. (51): ω_n(ω_U R_U); eq. (53): ω_CR")
    ax.legend(fontsize=8)
    return ax


def modes_figure(x, t, shapes, rotor_rpm, frequencies, critical_rpm, *, title=None):
    """Figs. 37-39 and the eq. (51)/(53) panel on one page (the `jaxbelt string --figure modes` figure)."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, 2, figsize=(11, 7.5))
    plot_mode_shapes(x, t, shapes, axes=axs.ravel()[:3])
    plot_span_frequencies(rotor_rpm, frequencies, critical_rpm, ax=axs[1, 1])
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
