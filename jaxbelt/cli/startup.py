"""`jaxbelt startup`: Fig. 3 of Incerti (2014) (belt-drive start-up for several voltage time constants)."""

from __future__ import annotations

import time

from ._args import finite_float, image_path, int_at_least, positive_float


def register(sub):
    p = sub.add_parser(
        "startup",
        help="belt drive start-up driven by a DC motor (Incerti, 2014, Fig. 3)",
        description="Simulate the start-up of the belt drive of Incerti (2014) (Table I) for each time constant "
        "of the voltage command V(t) = Vmax (1 - exp(-t/gamma)) and write the 8-panel figure.",
    )
    p.add_argument(
        "--gamma",
        type=positive_float,
        nargs="+",
        default=[0.02, 0.04, 0.06],
        help="time constants [s] (default 0.02 0.04 0.06)",
    )
    p.add_argument("--v-max", type=finite_float, default=24.0, help="final voltage Vmax [V] (default 24)")
    p.add_argument("--t-end", type=positive_float, default=0.5, help="simulated time [s] (default 0.5)")
    p.add_argument("--points", type=int_at_least(2), default=501, help="output points (default 501)")
    p.add_argument(
        "--method",
        default="auto",
        choices=["auto", "expm", "modal", "ode", "rk4"],
        help="solution method (default: closed form)",
    )
    p.add_argument("--out", type=image_path, default="startup.png", help="output image (default startup.png)")
    p.set_defaults(func=run)


def run(args) -> int:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..models.startup import BeltStartup
    from ..plots.startup import draw_startup
    from ..runs import startup_curves

    model = BeltStartup()
    t = time.perf_counter()
    ts, c = startup_curves(model, args.gamma, args.v_max, args.t_end, args.points, args.method)
    print(
        f"simulated {len(args.gamma)} start-ups ({args.method}) in {time.perf_counter() - t:.2f} s (incl. compilation)"
    )
    for i, g in enumerate(args.gamma):
        print(
            f"  gamma = {1e3 * g:5.1f} ms: peak current {c['current'][i].max():7.2f} A, "
            f"peak electric power {c['electric_power'][i].max():7.1f} W, "
            f"final speeds {c['omega1'][i][-1]:.3f} / {c['omega2'][i][-1]:.3f} rad/s"
        )
    # a figure of its own on the Agg canvas (pyplot and its GUI backend are not loaded) with fixed
    # margins (constrained layout would add ~0.35 s to the save of these 8 panels)
    fig = Figure(figsize=(11, 12))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.045, top=0.945, hspace=0.32, wspace=0.2)
    draw_startup(ts, c, args.gamma, args.v_max, fig=fig)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
