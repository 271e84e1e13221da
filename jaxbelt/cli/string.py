"""`jaxbelt string`: the belt-span figures (belt-vibration report figs. 40, 41, 43; Moon & Wickert Fig. 5)."""

from __future__ import annotations


def register(subparsers):
    p = subparsers.add_parser(
        "string",
        help="belt spans: contact pressure, span frequencies, exciting speeds, crossing diagram, run-out response",
        description="Belt spans as axially moving strings (the belt-vibration report and Moon & Wickert): writes one figure.",
    )
    p.add_argument("--out", default="string.png", help="output image (default: string.png)")
    p.add_argument("--contact-radius", type=float, default=0.025,
                   help="motor pulley radius [m] for the pressure plot (not in the belt-vibration report; default 0.025)")
    p.set_defaults(func=run)


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import jaxbelt as jb

    from ..plots.string import string_figure

    span = jb.MovingString(tension=140.0, density=0.05, length=0.2621)
    vc = jb.crossing_speeds(length=0.86, pulley_radii=(0.063, 0.063), wave_speed=41.0, n_modes=2)
    fig = string_figure(contact_radius=args.contact_radius)
    fig.savefig(args.out, dpi=110)
    print(f"critical speed (belt-vibration report span): {float(span.critical_speed):.3f} m/s")
    print(f"Moon & Wickert crossings: mode 1 {float(vc[0, 0, 0]):.3f} m/s, mode 2 {float(vc[1, 0, 0]):.3f} m/s")
    print(f"wrote {args.out}")
    return 0
