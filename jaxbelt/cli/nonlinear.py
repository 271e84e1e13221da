"""`jaxbelt nonlinear --out nonlinear.png`: the non-linear belt scene (Moon & Wickert, 1997) on one page."""

from __future__ import annotations


def register(subparsers):
    p = subparsers.add_parser(
        "nonlinear",
        help="non-linear belt with eccentric pulleys: speed sweeps, phase plane, backbone (Moon & Wickert)",
        description="Up/down speed sweeps over 0.5-17 m/s (Fig. 2), phase plane in the hysteresis band "
        "(Fig. 6) and simulation vs KBM backbone for v_l = 25, 50, 75 (Fig. 7).",
    )
    p.add_argument("--out", default="nonlinear.png", help="output image (default: nonlinear.png)")
    p.add_argument("--damping", type=float, default=0.015, help="modal damping ratio (default 0.015)")
    p.add_argument("--v-l", type=float, default=50.0, help="longitudinal/transverse wave speed ratio (default 50)")
    p.add_argument("--wave-speed", type=float, default=41.0, help="transverse wave speed [m/s] (default 41)")
    p.add_argument("--modes", type=int, default=2, help="Galerkin modes for the 0-17 m/s sweep (default 2)")
    p.add_argument("--quick", action="store_true", help="coarser speed grids (faster)")
    p.set_defaults(func=run)


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    from ..models.nonlinear import NonlinearBelt
    from ..plots.nonlinear import nonlinear_figure

    belt = NonlinearBelt(damping=args.damping, v_l=args.v_l, wave_speed=args.wave_speed, n_modes=args.modes)
    fig = nonlinear_figure(belt, quick=args.quick, n_modes=args.modes)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
