"""`jaxbelt startup`: Fig. 3 of Incerti (2014) (belt-drive start-up for several voltage time constants)."""

from __future__ import annotations

import time

from ._args import float_in, image_path, int_in, positive_float, signed_peak

#: most output points (the eight curves of every time constant are held in memory and drawn)
MAX_POINTS = 1_000_000
#: RK4's fixed step [s] and step budget (`simulate`'s defaults): the longest start-up it can run
RK4_STEP, RK4_MAX_STEPS = 1e-4, 100_000
#: longest simulated time [s]: the closed form's accuracy bounds the span (`jaxbelt.modal.closed_form_error`: about
#: 8e4 s for the paper's drive), and the start-up has settled within a second
MAX_T_END = 1e4


def register(sub):
    p = sub.add_parser(
        "startup",
        help="belt drive start-up driven by a DC motor (Incerti, 2014, Fig. 3)",
        description="Simulate the start-up of the belt drive of Incerti (2014) (Table I) for each time constant "
        "of the voltage command V(t) = Vmax (1 - exp(-t/gamma)) and write the 8-panel figure.",
    )
    p.add_argument(
        "--gamma",
        type=float_in(1e-6, 1e6),
        nargs="+",
        default=[0.02, 0.04, 0.06],
        help="time constants [s], in [1e-6, 1e6] (default 0.02 0.04 0.06; a shorter one is a step)",
    )
    p.add_argument(
        "--v-max", type=float_in(-1e4, 1e4), default=24.0, help="final voltage Vmax [V], |Vmax| <= 1e4 (default 24)"
    )
    p.add_argument(
        "--t-end",
        type=_t_end,
        default=0.5,
        help=f"simulated time [s], in (0, {MAX_T_END:g}] (default 0.5)",
    )
    p.add_argument(
        "--points",
        type=int_in(2, MAX_POINTS, "the curves are held in memory"),
        default=501,
        help="output points (default 501)",
    )
    p.add_argument(
        "--method",
        default="auto",
        choices=["auto", "expm", "modal", "ode", "rk4"],
        help="solution method (default: closed form)",
    )
    p.add_argument("--out", type=image_path, default="startup.png", help="output image (default startup.png)")
    p.set_defaults(func=run, early_check=check)


def _t_end(text: str) -> float:
    """A finite number > 0 and at most `MAX_T_END` [s]."""
    import argparse

    v = positive_float(text)
    if v > MAX_T_END:
        raise argparse.ArgumentTypeError(
            f"must be <= {MAX_T_END:g} s (the start-up settles within a second; the closed form's accuracy bounds "
            f"the span), got {text}"
        )
    return v


def check(args) -> str | None:
    """RK4 takes fixed steps of 0.1 ms within `simulate`'s step budget: a longer start-up cannot be run."""
    longest = RK4_STEP * RK4_MAX_STEPS
    if args.method == "rk4" and args.t_end > longest:
        return (
            f"argument --t-end: with --method rk4 (fixed steps of {RK4_STEP * 1e3:g} ms, at most {RK4_MAX_STEPS} of "
            f"them) at most {longest:g} s, got {args.t_end:g} (use --method auto, the closed form, for longer runs)"
        )
    return None


def summary(gammas, curves) -> list[str]:
    """One line per time constant: the peaks of the current and the electric power (values of largest
    magnitude, with their sign) and the final pulley speeds, read from the arrays `curves` (as
    `startup_curves` returns them)."""
    lines = []
    for i, g in enumerate(gammas):
        lines.append(
            f"  gamma = {1e3 * g:5.4g} ms: peak current {signed_peak(curves['current'][i]):7.2f} A, "
            f"peak electric power {signed_peak(curves['electric_power'][i]):7.1f} W, "
            f"final speeds {curves['omega1'][i][-1]:.3f} / {curves['omega2'][i][-1]:.3f} rad/s"
        )
    return lines


def run(args) -> int:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .._io import save_figure
    from ..models.startup import BeltStartup
    from ..plots.startup import draw_startup
    from ..runs import startup_curves

    model = BeltStartup()
    t = time.perf_counter()
    ts, c = startup_curves(model, args.gamma, args.v_max, args.t_end, args.points, args.method)
    print(
        f"simulated {len(args.gamma)} start-ups ({args.method}) in {time.perf_counter() - t:.2f} s (incl. compilation)"
    )
    print("\n".join(summary(args.gamma, c)))
    # a figure of its own on the Agg canvas (pyplot and its GUI backend are not loaded) with fixed
    # margins (constrained layout would add ~0.35 s to the save of these 8 panels)
    fig = Figure(figsize=(11, 12))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.045, top=0.945, hspace=0.32, wspace=0.2)
    draw_startup(ts, c, args.gamma, args.v_max, fig=fig)
    save_figure(fig, args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
