"""`jaxbelt fourbar`: the paper's Fig. 4 (open loop vs PID) and a linkage snapshot strip (Incerti, 2012)."""

from __future__ import annotations

import warnings
from pathlib import Path

from ._args import fill_defaults, float_in, image_path, nonnegative_float, refuse_unused

#: the longest run [s]: the ramped gain Kp t grows with time and the closed loop stiffens with it (about 2300
#: solver steps per simulated second at 10 s); 20 s stays well inside `simulate`'s budget of 100000 steps
MAX_T1 = 20.0
#: the closed loop holds its set point when its mean speed over the window is within this of it (relative)
SET_POINT_RTOL = 0.05


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "fourbar",
        help="four-bar linkage + DC motor + PID: Fig. 4 and speed-fluctuation indices",
        description="Simulate the four-bar drive open loop (constant voltage) and with the PID of the paper, "
        "print the fluctuation indices and write Fig. 4. The paper's Table I was lost: crank length and R are "
        "identified from its two published indices, the other lost values assumed.",
    )
    p.add_argument("--out", type=image_path, default="fourbar.png", help="Fig. 4 image (default fourbar.png)")
    p.add_argument("--strip", type=image_path, default=None, help="also write a linkage snapshot strip to this image")
    p.add_argument(
        "--regulators",
        type=image_path,
        default=None,
        help="also write the comparison of the ramped-gain PID (eq. 16) with a constant-gain PID (eq. 14)",
    )
    p.add_argument(
        "--kp-constant",
        type=nonnegative_float,
        default=None,
        help="Kp [V s/rad] of the constant-gain PID in --regulators, only with it (default 35: Kp t at t = 0.44 s)",
    )
    p.add_argument(
        "--voltage", type=float_in(-1e4, 1e4), default=25.0, help="open-loop voltage [V], |V| <= 1e4 (paper: 25)"
    )
    p.add_argument("--kp", type=nonnegative_float, default=80.0, help="Kp [V/rad], multiplies t (paper: 80)")
    p.add_argument("--ki", type=nonnegative_float, default=32.0, help="Ki [V/rad] (paper: 32)")
    p.add_argument("--kd", type=nonnegative_float, default=0.015, help="Kd [V/(rad/s^2)] (paper: 0.015)")
    p.add_argument(
        "--omega-ref",
        type=float_in(0.0, 1e4, lo_open=True),
        default=30.0,
        help="motor speed set point [rad/s], in (0, 1e4] (paper: 30)",
    )
    p.add_argument(
        "--v-limit",
        type=float_in(0.0, 1e4, lo_open=True),
        default=None,
        help="voltage limiter [V], in (0, 1e4] (default: none)",
    )
    p.add_argument(
        "--t1",
        type=float_in(0.5, MAX_T1, lo_open=True),
        default=1.0,
        help=f"simulated time [s], in (0.5, {MAX_T1:g}] (the closed-loop index is taken over 0.375-0.5 s; default 1)",
    )
    p.set_defaults(func=run, early_check=check)


def check(args) -> str | None:
    """--kp-constant sets the comparison of --regulators: refused without it (never ignored)."""
    if args.regulators is None:
        unused = refuse_unused(args, ("kp_constant",), "without --regulators (it sets that comparison)")
        if unused:
            return unused
    fill_defaults(args, {"kp_constant": 35.0})
    return None


def summary(open_, closed, voltage: float, t1: float, omega_ref: float) -> tuple[list[str], list[str]]:
    """`(lines, warnings)`: the printed figures, read from the two runs (χ of each over its window and the
    mean motor speed it divides by, so that a drive that does not run, or runs backwards, shows as such),
    and a warning when the closed loop misses its set point."""
    import numpy as np

    import jaxbelt as jb
    from jaxbelt.objectives.fluctuation import _window_mean

    def mean(sol, a, b):
        return float(_window_mean(np.asarray(sol.ts), np.asarray(sol.outputs["motor_speed"]), a, b))

    chi_open = float(jb.fluctuation_index(open_, 0.5 * t1, t1))
    chi_closed = float(jb.fluctuation_index(closed, 0.375, 0.5))
    w_open, w_closed = mean(open_, 0.5 * t1, t1), mean(closed, 0.375, 0.5)
    lines = [
        f"open loop {voltage:g} V: chi = {100 * chi_open:.1f} % over {0.5 * t1:g}-{t1:g} s, mean motor speed "
        f"{w_open:.4g} rad/s (paper: 54.3 %)",
        f"closed loop PID: chi = {100 * chi_closed:.2f} % over 0.375-0.5 s, mean motor speed {w_closed:.4g} rad/s "
        "(paper: 2.6 %)",
    ]
    warns = []
    if abs(w_closed - omega_ref) > SET_POINT_RTOL * omega_ref:
        warns.append(
            f"the closed loop does not hold its set point: mean motor speed {w_closed:.4g} rad/s over 0.375-0.5 s "
            f"against omega_ref = {omega_ref:g} rad/s, so its chi measures another motion"
        )
    return lines, warns


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import jaxbelt as jb
    from jaxbelt._io import save_figure
    from jaxbelt.plots.fourbar import fourbar_figure, linkage_strip
    from jaxbelt.runs import FIG4_OUTPUTS, simulate_fig4

    drive = jb.FourBarDrive()
    pid = jb.PID(kp=args.kp, ki=args.ki, kd=args.kd, omega_ref=args.omega_ref, v_limit=args.v_limit)
    back_emf = float(drive.km) * args.omega_ref
    if args.v_limit is not None and args.v_limit < back_emf:
        warnings.warn(
            f"--v-limit {args.v_limit:g} V is below the back-emf at the set point, k_m * omega_ref = "
            f"{back_emf:.4g} V: the PID cannot hold {args.omega_ref:g} rad/s",
            RuntimeWarning,
            stacklevel=1,
        )
    open_, closed = simulate_fig4(drive, pid, voltage=args.voltage, t1=args.t1, n=int(round(2000 * args.t1)) + 1)
    lines, warns = summary(open_, closed, args.voltage, args.t1, args.omega_ref)
    print("\n".join(lines))
    for w in warns:
        warnings.warn(w, RuntimeWarning, stacklevel=1)
    fig = fourbar_figure(open_, closed, omega_ref=args.omega_ref, voltage=args.voltage)
    save_figure(fig, Path(args.out), dpi=120)
    print(f"wrote {args.out}")
    if args.regulators:
        import matplotlib.pyplot as plt

        from jaxbelt.plots.fourbar import plot_regulators

        const = jb.PID(
            kp=args.kp_constant, ki=args.ki, kd=args.kd, omega_ref=args.omega_ref, v_limit=args.v_limit, gain="constant"
        )
        sol_c = jb.simulate(jb.Scene(drive, const, ts=closed.ts, observe=FIG4_OUTPUTS))
        chi_c = float(jb.fluctuation_index(sol_c, 0.375, 0.5))
        print(
            f"closed loop PID, constant Kp = {args.kp_constant:g} V s/rad: chi = {100 * chi_c:.2f} % over 0.375-0.5 s"
        )
        fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
        plot_regulators(
            {f"ramped, Kp t = {args.kp:g} t": closed, f"constant, Kp = {args.kp_constant:g}": sol_c},
            omega_ref=args.omega_ref,
            ax=ax,
        )
        save_figure(fig, Path(args.regulators), dpi=120)
        print(f"wrote {args.regulators}")
    if args.strip:
        save_figure(linkage_strip(drive), Path(args.strip), dpi=120)
        print(f"wrote {args.strip}")
    return 0
