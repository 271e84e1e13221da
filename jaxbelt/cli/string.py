"""`jaxbelt string`: the belt-span figures (belt-vibration report figs. 37-43, eq. 51-53; Moon & Wickert Fig. 5)."""

from __future__ import annotations

from ._args import fill_defaults, float_in, image_path, refuse_unused

#: the options of each figure and their defaults (None on the parser: an option of the other figure is refused)
OVERVIEW_DEFAULTS = {"contact_radius": 0.025}
MODES_DEFAULTS = {"belt_speed": 20.0, "pulley_radius": 0.1166}


def register(subparsers):
    p = subparsers.add_parser(
        "string",
        help="belt spans: contact pressure, span frequencies, exciting speeds, crossing diagram, run-out response",
        description="Belt spans as axially moving strings (the belt-vibration report and Moon & Wickert): writes one figure.",
    )
    p.add_argument("--out", type=image_path, default="string.png", help="output image (default: string.png)")
    p.add_argument(
        "--figure",
        choices=["overview", "modes"],
        default="overview",
        help="overview: pressure, exciting speeds, crossings, run-out (default); modes: the first three "
        "mode shapes of the moving span (report figs. 37-39) and omega_n(omega_U) with omega_CR (eq. 51, 53)",
    )
    p.add_argument(
        "--contact-radius",
        type=float_in(1e-3, 10.0),
        default=None,
        help="motor pulley radius [m] for the pressure plot of the overview, in [0.001, 10] (not in the "
        "belt-vibration report; default 0.025)",
    )
    p.add_argument(
        "--belt-speed",
        type=float_in(0.0, 52.9),
        default=None,
        help="belt speed V [m/s] of the mode-shape snapshots (--figure modes), below sqrt(T/rho) = 52.9 m/s "
        "(default 20)",
    )
    p.add_argument(
        "--pulley-radius",
        type=float_in(1e-3, 10.0),
        default=None,
        help="driven pulley radius R_U [m] for omega_CR (--figure modes), in [0.001, 10] (fitted to Table 2; "
        "default 0.1166)",
    )
    p.set_defaults(func=run, early_check=check)


def check(args) -> str | None:
    """Each figure's own options: one of the other figure is refused (never ignored); the defaults filled in."""
    if args.figure == "modes":
        unused = refuse_unused(args, OVERVIEW_DEFAULTS, "with --figure modes (it sets the overview's pressure plot)")
    else:
        unused = refuse_unused(args, MODES_DEFAULTS, "with --figure overview (it sets the modes figure)")
    if unused:
        return unused
    fill_defaults(args, OVERVIEW_DEFAULTS if args.figure != "modes" else MODES_DEFAULTS)
    return None


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import jax.numpy as jnp
    import numpy as np

    import jaxbelt as jb

    from .._io import save_figure
    from ..plots.string import string_figure

    span = jb.MovingString(tension=140.0, density=0.05, length=0.2621)
    if args.figure == "modes":
        return _modes(args, span)
    # Moon & Wickert (1997) test stand: crossing diagram (Fig. 5a) and linear run-out response (Fig. 5b)
    rig = jb.RunoutRig(damping_ratio=0.01)
    vmax = 0.55 * float(rig.wave_speed)
    V = jnp.linspace(0.0, vmax, 400)
    natural, load = jb.crossing_diagram(rig, V, n_modes=3)
    crossings = jb.crossing_speeds(rig, n_modes=3)
    Vr = jnp.linspace(0.05, vmax, 1500)
    responses = {
        f"ζ = {float(rig.damping_ratio):g}, x = {1e3 * float(rig.position):.0f} mm": jb.linear_runout_response(rig, Vr),
        f"ζ = {float(rig.damping_ratio):g}, x = L/4": jb.linear_runout_response(
            jb.RunoutRig(damping_ratio=rig.damping_ratio, position=rig.length / 4), Vr
        ),
    }
    # Galerkin frequencies (belt-vibration report, eq. 24) against eq. (39) at 20 m/s
    n_basis = np.array([4, 8, 16, 32, 64])
    exact = np.asarray(jb.MovingString().natural_frequencies(20.0, 3))
    errors = np.array(
        [np.abs(np.asarray(jb.MovingString().galerkin_frequencies(20.0, n, 3)) - exact) / exact for n in n_basis]
    )
    fig = string_figure(
        diagram=dict(speeds=V, natural=natural, load=load, crossings=crossings, pulley_radii=rig.pulley_radii),
        response=dict(speeds=Vr, responses=responses, crossings=crossings),
        galerkin=dict(n_basis=n_basis, errors=errors, speed=20.0),
        contact=jb.BeltPulleyContact(radius=args.contact_radius),
    )
    save_figure(fig, args.out, dpi=110)
    print("\n".join(summary(span, crossings)))
    print(f"wrote {args.out}")
    return 0


def summary(span, crossings) -> list[str]:
    """The overview's printed figures: the span's critical speed and the first two crossing speeds of
    Moon & Wickert's stand (pulley 0, first harmonic), read from `span` and the array `crossings`."""
    return [
        f"critical speed (belt-vibration report span): {float(span.critical_speed):.3f} m/s",
        f"Moon & Wickert crossings: mode 1 {float(crossings[0, 0, 0]):.3f} m/s, mode 2 {float(crossings[1, 0, 0]):.3f} m/s",
    ]


def modes_summary(w_cr: float, pulley_radius: float) -> str:
    """The modes figure's printed line: the critical rotor speed omega_CR [rad/s] and in rpm."""
    from ..plots.string import RPM

    return (
        f"critical rotor speed omega_CR = {w_cr:.5g} rad/s = {w_cr * RPM:.5g} rpm (eq. 53, R_U = {pulley_radius:g} m)"
    )


def _modes(args, span) -> int:
    import jax.numpy as jnp
    import numpy as np

    from .._io import save_figure
    from ..plots.string import RPM, modes_figure

    x = np.linspace(0.0, float(span.length), 201)
    shapes, times = [], []
    for n in (1, 2, 3):
        w = float(span.natural_frequencies(args.belt_speed, n)[n - 1])
        t = np.linspace(0.0, np.pi / w, 7)  # half a period of the mode, 7 snapshots
        shapes.append(np.asarray(span.mode_shape(x[None, :], t[:, None], args.belt_speed, n)))
        times.append(t)
    w_cr = float(span.critical_rotor_speed(args.pulley_radius))
    rotor = np.linspace(0.0, w_cr, 300)
    freqs = np.asarray(span.natural_frequencies(jnp.asarray(rotor[:-1] * args.pulley_radius), 3))
    freqs = np.vstack([freqs, np.zeros((1, 3))])  # eq. (51) is exactly zero at omega_CR
    fig = modes_figure(
        x, times[0], np.stack(shapes), rotor * RPM, freqs, w_cr * RPM, title=f"moving span, V = {args.belt_speed:g} m/s"
    )
    save_figure(fig, args.out, dpi=110)
    print(modes_summary(w_cr, args.pulley_radius))
    print(f"wrote {args.out}")
    return 0
