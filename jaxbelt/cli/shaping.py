"""`jaxbelt shaping`: command shaping of the belt-driven platform (Incerti, pseudo-polynomial commands).

Optimises the pseudo-polynomial exponents from (3, 4, 5), optionally a robust higher-order
command over a frequency band, compares with ZV/ZVD shapers, prints H and the 5 % tolerance
band widths, and writes the figure (paper's Fig. 3 + sensitivity plot).
"""

from __future__ import annotations

from ._args import float_in, image_path, positive_float


def register(subparsers):
    p = subparsers.add_parser(
        "shaping",
        help="pseudo-polynomial command shaping of a belt-driven platform (Incerti, pseudo-polynomial commands)",
        description="Optimise the exponents of a pseudo-polynomial motion command of the belt-driven platform "
        "(Incerti, Table III) to cancel the residual vibration energy H, optionally a robust command over a "
        "frequency band; compare with ZV/ZVD shapers and write the figure (the paper's Fig. 3 and a "
        "sensitivity plot), or the paper's Fig. 2 with --figure profiles.",
    )
    p.add_argument("--out", type=image_path, default="shaping.png", help="figure file (default shaping.png)")
    p.add_argument(
        "--figure",
        choices=["overview", "profiles"],
        default="overview",
        help="overview: optimisation, Fig. 3 and sensitivity (default); profiles: the paper's Fig. 2, "
        "3-4-5 polynomial vs 4.5-6.2-8.4 pseudo-polynomial (T = 1 s, Phi = 1 rad), with C_i printed",
    )
    p.add_argument(
        "--gammas",
        type=float_in(2.0, 100.0, lo_open=True),
        nargs="+",
        default=[3.0, 4.0, 5.0],
        help="start exponents (default 3 4 5)",
    )
    p.add_argument("--duration", type=positive_float, default=1.0, help="motion time T [s] (default 1)")
    p.add_argument("--revolutions", type=positive_float, default=15.0, help="motor displacement [rev] (default 15)")
    p.add_argument(
        "--robust-order",
        type=int,
        nargs="*",
        default=[4],
        choices=[2, 3, 4, 5],
        help="orders n of band-robust commands to add (none: --robust-order with no value; default 4)",
    )
    p.add_argument(
        "--robust-mode",
        default="mean",
        choices=["mean", "max"],
        help="robust objective over the band: mean or smooth worst case (default mean)",
    )
    p.add_argument(
        "--band",
        type=float_in(0.0, 10.0, lo_open=True),
        nargs=2,
        default=[0.8, 1.2],
        help="robust band as fractions of omega_n (default 0.8 1.2)",
    )
    p.add_argument(
        "--spread",
        type=float_in(0.0, 1.0, lo_open=True, hi_open=True),
        default=0.3,
        help="sensitivity sweep +-spread around omega_n (default 0.3)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.set_defaults(func=run, check=check)


def check(args) -> str | None:
    """The relations between arguments that argparse does not check (run before anything is computed)."""
    from ..commands import MIN_EXPONENT_GAP, exponents_apart

    low, high = args.band
    if not low < high:
        return f"argument --band: LOW must be < HIGH, got {low:g} {high:g}"
    if len(args.gammas) < 2:
        return f"argument --gammas: give at least 2 exponents, got {len(args.gammas)}"
    if not exponents_apart(args.gammas):
        return (
            f"argument --gammas: the exponents must differ pairwise by at least {MIN_EXPONENT_GAP:g}, "
            f"got {' '.join(f'{x:g}' for x in args.gammas)}"
        )
    return None


def run(args) -> int:
    if getattr(args, "mode", None) or getattr(args, "measured", None):
        return _axis_run(args)
    return _paper_run(args)


def _axis_run(args) -> int:
    """`jaxbelt shaping --mode F:Z ... | --measured FILE`: every design for the user's axis (jaxbelt.design_move)."""
    raise NotImplementedError


def _paper_run(args) -> int:
    """Without an axis: the paper's figure (Incerti, pseudo-polynomial commands) and its comparison."""
    import jax.numpy as jnp
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..commands import PseudoPolynomial
    from ..models.platform import BeltPlatform
    from ..objectives.residual import residual_energy
    from ..optimise.command import optimise_command, optimise_robust, sensitivity_curve, shaped_commands, tolerance_band
    from ..plots.shaping import shaping_figure
    from ..runs import platform_response

    if args.figure == "profiles":
        return _profiles(args)
    progress = not args.no_progress
    plat = BeltPlatform()
    phi = args.revolutions * 2 * jnp.pi
    cmd0 = PseudoPolynomial(jnp.asarray(args.gammas, dtype=float), phi, args.duration)
    res = optimise_command(plat, cmd0, progress=progress)
    h0 = float(residual_energy(plat, cmd0))
    print(f"H(start {list(args.gammas)}) = {h0:.6g} rad^2/s^4, E(T) = {h0 * float(plat.energy_factor):.4g} J")
    g = ", ".join(f"{x:.4f}" for x in res.gammas.tolist())
    print(
        f"optimised exponents ({g}): H = {float(res.value):.3g} (H/H0 = {float(res.value) / h0:.2e}, "
        f"{res.n_steps} L-BFGS steps)"
    )
    label0 = "-".join(f"{x:g}" for x in args.gammas)
    cmds = {label0: cmd0, "optimised": res.command}
    for name, c in shaped_commands(plat, cmd0).items():
        cmds[f"{label0} + {name}"] = c
    for n in args.robust_order:
        # start from the classical rest-to-rest polynomial of order n: exponents n+1 .. 2n+1
        start = PseudoPolynomial(jnp.arange(n + 1, 2 * n + 2, dtype=float), phi, args.duration)
        rob = optimise_robust(plat, start, band=tuple(args.band), mode=args.robust_mode, progress=progress)
        g = ", ".join(f"{x:.3f}" for x in rob.gammas.tolist())
        print(
            f"robust n={n} ({args.robust_mode} over {args.band[0]:g}-{args.band[1]:g} omega_n): exponents ({g}), "
            f"band measure {float(rob.value):.3g} (start {float(rob.initial_value):.3g})"
        )
        cmds[f"robust n={n} ({args.robust_mode}, band {args.band[0]:g}-{args.band[1]:g})"] = rob.command
    omegas, curves = sensitivity_curve(plat, cmds, rel=args.spread)
    print(
        f"width of the band where E(T) < 5 % of the {label0} command's (fraction of omega_n = "
        f"{float(plat.omega_n):.3f} rad/s; sweep +-{args.spread:.0%}):"
    )
    for name, e in curves.items():
        c = cmds[name]
        w = tolerance_band(omegas, e, curves[label0], plat.omega_n)
        edge = ">=" if w >= 2 * args.spread * (1 - 1e-9) else "  "  # the band fills the whole sweep
        print(f"  {name:34s} {edge}{w:6.3f}   move time {float(c.end_time):.3f} s")
    before, after = platform_response(plat, cmd0), platform_response(plat, res.command)
    fig = shaping_figure(
        before,
        after,
        omegas,
        curves,
        plat.omega_n,
        reference=label0,
        move_times=(float(cmd0.end_time), float(res.command.end_time)),
    )
    fig.savefig(args.out, dpi=120)
    plt.close(fig)
    print(f"wrote {args.out}")
    return 0


def _profiles(args) -> int:
    import jax.numpy as jnp
    import matplotlib.pyplot as plt
    import numpy as np

    from ..commands import PseudoPolynomial
    from ..plots.shaping import plot_profiles

    t = jnp.linspace(0.0, 1.0, 401)
    profiles = {}
    for g in ((3.0, 4.0, 5.0), (4.5, 6.2, 8.4)):
        cmd = PseudoPolynomial(jnp.asarray(g), 1.0, 1.0)  # Fig. 2: Phi = 1 rad, T = 1 s
        label = "-".join(f"{x:g}" for x in g)
        profiles[label] = (cmd(t), cmd.velocity(t), cmd.acceleration(t))
        print(f"gammas {label}: C = {np.round(np.asarray(cmd.coefficients), 3).tolist()}")
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.4), constrained_layout=True)
    plot_profiles(t, profiles, axes=axes)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
