"""`jaxbelt shaping`: command shaping on the user's axis, or the paper's platform (Incerti, pseudo-polynomial commands).

With `--mode F:Z` (one per mode) or `--measured FILE` (a free decay t,y, `jaxbelt.identify_axis`, or a power
spectral density such as a firmware's resonance test writes, `jaxbelt.identify_axis_from_psd`; `--column` picks
the file's column), every design for that axis under the same limits and move time (`jaxbelt.design_move`): the
ranked table is printed, the recommended command written as CSV (`--out move.csv`, columns t,x,v,a) and the
figure beside it (or to an image `--out`). Without an axis, the paper's figure: the optimised pseudo-polynomial
command of the belt-driven platform, its Fig. 3, and the comparison with shapers.
"""

from __future__ import annotations

import math

from ._args import csv_or_image_path, fill_defaults, finite_float, float_in, positive_float, refuse_unused

#: the options of the paper's figure (without an axis) and their defaults (None on the parser: an option given
#: where it is not used is refused)
PAPER_DEFAULTS = {
    "figure": "overview",
    "gammas": [3.0, 4.0, 5.0],
    "duration": 1.0,
    "revolutions": 15.0,
    "robust_order": [4],
    "robust_mode": "mean",
    "band": [0.8, 1.2],
    "spread": 0.3,
}
#: the options of the overview figure only (the profiles figure is the paper's Fig. 2, fixed)
#: the most revolutions `--revolutions` takes: PseudoPolynomial's `displacement` is at most 1e9 rad
MAX_REVOLUTIONS = 1e9 / (2 * math.pi)
OVERVIEW_ONLY = ("gammas", "duration", "revolutions", "robust_order", "robust_mode", "band", "spread")
#: the options of a design on the user's axis and their defaults
AXIS_DEFAULTS = {"uncertainty": 0.2, "rate": 1000.0, "smooth": "auto"}
AXIS_ONLY = (
    "distance", "move_time", "v_max", "a_max", "j_max", "n_modes", "uncertainty", "damping", "smooth", "certify",
    "rate", "resolution",
)  # fmt: skip


def register(subparsers):
    p = subparsers.add_parser(
        "shaping",
        help="pseudo-polynomial command shaping of a belt-driven platform (Incerti, pseudo-polynomial commands)",
        description="Optimise the exponents of a pseudo-polynomial motion command of the belt-driven platform "
        "(Incerti, Table III) to cancel the residual vibration energy H, optionally a robust command over a "
        "frequency band; compare with ZV/ZVD shapers and write the figure (the paper's Fig. 3 and a "
        "sensitivity plot), or the paper's Fig. 2 with --figure profiles.",
    )
    p.add_argument(
        "--out",
        type=csv_or_image_path,
        nargs="+",
        default=None,
        help="with an axis: the command as CSV (.csv; the figure goes beside it as .png) and/or the figure (an image "
        "format); without: the figure (default shaping.png)",
    )
    axis = p.add_argument_group("your axis (jaxbelt.design_move)")
    axis.add_argument(
        "--mode",
        type=_mode,
        action="append",
        metavar="F:Z[:G]",
        help="a mode of the axis: frequency F [Hz], damping ratio Z (and gain G, default 1); repeat for each mode",
    )
    axis.add_argument(
        "--measured",
        type=_record_path,
        metavar="FILE",
        help="identify the modes from a measured record (CSV t,y: a free decay) or a power spectral density (CSV whose "
        "first column is the frequency, e.g. Klipper's freq,psd_x,psd_y,psd_z,psd_xyz)",
    )
    axis.add_argument(
        "--n-modes", type=_positive_int, default=None, help="modes to identify from --measured (default 1)"
    )
    axis.add_argument(
        "--column",
        type=_column,
        default=None,
        metavar="NAME|INDEX",
        help="the column of --measured to read, by header name (any case) or index (1 = the first after the time or "
        "frequency); default: the only one, or psd_xyz in a spectrum",
    )
    axis.add_argument(
        "--kind",
        default=None,
        metavar="K",
        help="what --measured holds: for a time record decay or sweep (default: a sweep where the record looks like "
        "one); for a spectrum displacement, velocity, acceleration (a tap test), base-acceleration, klipper or "
        "klipper-normalised (default: the file's own, Klipper's calibration CSVs; else displacement)",
    )
    axis.add_argument("--distance", type=finite_float, help="move distance [m] (or rad), non-zero")
    axis.add_argument(
        "--move-time", type=positive_float, help="move time [s] (default: the shortest that beats the shapers)"
    )
    axis.add_argument("--v-max", type=positive_float, help="velocity limit [m/s]")
    axis.add_argument("--a-max", type=positive_float, help="acceleration limit [m/s^2]")
    axis.add_argument("--j-max", type=positive_float, help="jerk limit [m/s^3] (optional)")
    axis.add_argument(
        "--uncertainty",
        type=float_in(0.0, 0.9, hi_open=True),
        default=None,
        help="frequency error every residual is judged over, +- (default 0.2)",
    )
    axis.add_argument(
        "--damping",
        nargs="+",
        default=None,
        metavar="LO HI | unknown",
        help="damping ratios every residual is judged over, as well as the band: a range LO HI (0 <= LO <= HI < 1), "
        "or 'unknown' for 0.01-0.1 with the classic shapers designed at 0.1 (Klipper's default); default: each "
        "mode's own damping ratio",
    )
    axis.add_argument(
        "--smooth",
        choices=["auto", "true", "false"],
        default=None,
        help="the minimax design's command space: true, a continuous acceleration; false, one that may jump as a "
        "shaped trapezoid's does; auto (default), the smooth design and, where a classic shaper leaves no more or it "
        "is infeasible, the one with jumps too",
    )
    axis.add_argument(
        "--certify",
        type=float_in(0.0, 1.0, lo_open=True, hi_open=True),
        default=None,
        metavar="RTOL",
        help="refine the minimax design with jumps until a rigorous lower bound on what any command can leave is "
        "within RTOL of it (e.g. 0.05; with --smooth auto or false, without --j-max; a minute or more on a hard "
        "axis); default: no refinement, the bound reported where a design with jumps is made",
    )
    axis.add_argument(
        "--rate",
        type=positive_float,
        default=None,
        help="the drive's setpoint rate [Hz]: the CSV's sample rate, at which the table's residuals are those of the "
        "CSV executed linear between samples; above twice the band's highest frequency (default 1000)",
    )
    axis.add_argument(
        "--resolution",
        type=positive_float,
        default=None,
        metavar="STEP",
        help="the drive's position step [m] (a motor step or encoder count, e.g. 1.25e-5): rows whose residual lies "
        "below what rounding the setpoints to it leaves rank by their peaks; default: none",
    )
    p.add_argument(
        "--figure",
        choices=["overview", "profiles"],
        default=None,
        help="overview: optimisation, Fig. 3 and sensitivity (default); profiles: the paper's Fig. 2, "
        "3-4-5 polynomial vs 4.5-6.2-8.4 pseudo-polynomial (T = 1 s, Phi = 1 rad), with C_i printed",
    )
    p.add_argument(
        "--gammas",
        type=float_in(2.0, 100.0, lo_open=True),
        nargs="+",
        default=None,
        help="start exponents (default 3 4 5)",
    )
    # the ranges of PseudoPolynomial's `duration` [1e-6, 1e6] s and `displacement` |phi| <= 1e9 rad, said as the
    # options the user typed (1e300 named the command's `displacement`, not --revolutions)
    p.add_argument(
        "--duration", type=float_in(1e-6, 1e6), default=None, help="motion time T [s], in [1e-6, 1e6] (default 1)"
    )
    p.add_argument(
        "--revolutions",
        type=float_in(0.0, MAX_REVOLUTIONS, lo_open=True),
        default=None,
        help=f"motor displacement [rev], in (0, {MAX_REVOLUTIONS:.4g}] (default 15)",
    )
    p.add_argument(
        "--robust-order",
        type=int,
        nargs="*",
        default=None,
        choices=[2, 3, 4, 5],
        help="orders n of band-robust commands to add (none: --robust-order with no value; default 4)",
    )
    p.add_argument(
        "--robust-mode",
        default=None,
        choices=["mean", "max"],
        help="robust objective over the band: mean or smooth worst case (default mean)",
    )
    p.add_argument(
        "--band",
        type=float_in(0.0, 10.0, lo_open=True),
        nargs=2,
        default=None,
        help="robust band as fractions of omega_n (default 0.8 1.2)",
    )
    p.add_argument(
        "--spread",
        type=float_in(0.0, 1.0, lo_open=True, hi_open=True),
        default=None,
        help="sensitivity sweep +-spread around omega_n (default 0.3)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.set_defaults(func=run, early_check=check, check=check_exponents)


def _mode(text: str):
    """F:Z or F:Z:G -> (frequency [Hz] > 0, damping ratio in [0, 1), gain != 0)."""
    import argparse
    import math

    parts = text.split(":")
    try:
        vals = [float(x) for x in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected F:Z or F:Z:G (numbers), got {text!r}") from None
    if len(vals) not in (2, 3) or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected F:Z or F:Z:G (finite numbers), got {text!r}")
    f, z = vals[0], vals[1]
    g = vals[2] if len(vals) == 3 else 1.0
    from .shaper import FREQUENCY_RANGE_HZ  # ModalAxis's range, without importing JAX

    lo, hi = FREQUENCY_RANGE_HZ
    if not lo <= f <= hi:
        raise argparse.ArgumentTypeError(f"frequency F must lie in [{lo:g}, {hi:g}] Hz, got {f:g}")
    if not 0 <= z < 1:
        raise argparse.ArgumentTypeError(f"damping ratio Z must lie in [0, 1), got {z:g}")
    if g == 0:
        raise argparse.ArgumentTypeError("gain G must be non-zero")
    return f, z, g


def _record_path(text: str):
    import argparse
    from pathlib import Path

    p = Path(text).expanduser()
    if not p.is_file():
        raise argparse.ArgumentTypeError(f"no such file: {text!r}")
    return p


def _cli_names(message: str) -> str:
    """An identification's refusal with the command line's options in place of the API's parameter names."""
    for api, option in (("channel", "--column"), ("column", "--column"), ("kind", "--kind"), ("n_modes", "--n-modes")):
        message = message.replace(f"parameter `{api}`", option).replace(f"`{api}`", option)
    return message


def _column(text: str) -> int | str:
    """A column by its header name, or by its index >= 1 (digits)."""
    import argparse

    text = text.strip()
    if not text:
        raise argparse.ArgumentTypeError("expected a column name or an index >= 1, got ''")
    if text.isdigit():
        if int(text) < 1:
            raise argparse.ArgumentTypeError(
                f"an index must be >= 1 (column 0 holds the time or frequency), got {text}"
            )
        return int(text)
    return text


def _positive_int(text: str) -> int:
    import argparse

    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def _damping(values: list[str]):
    """`--damping`'s words as `design_move`'s `damping` ("unknown" or (lo, hi)), or the error message."""
    import math

    if values == ["unknown"]:
        return "unknown"
    why = (
        f"argument --damping: give LO HI with 0 <= LO <= HI < 1 (damping ratios), or 'unknown'; got {' '.join(values)}"
    )
    if len(values) != 2:
        return why
    try:
        lo, hi = (float(v) for v in values)
    except ValueError:
        return why
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi < 1.0):
        return why
    return lo, hi


def check(args) -> str | None:
    """The relations between arguments that argparse does not check (run before anything is computed): what each
    mode needs, the options it does not use (refused, never ignored), the CSV rate against the band's Nyquist
    rate, and the default output paths. Fills in the defaults of the options the mode uses."""
    from pathlib import Path

    from .._io import output_path_problem

    if args.column is not None and not args.measured:
        return "argument --column: only with --measured (the column of the measured file)"
    if args.kind is not None and not args.measured:
        return "argument --kind: only with --measured (what the measured file holds)"
    if args.mode or args.measured:
        if args.mode and args.measured:
            return "argument --measured: give the axis either by --mode or by --measured, not both"
        unused = refuse_unused(args, PAPER_DEFAULTS, "with an axis (--mode or --measured): it sets the paper's figure")
        if unused:
            return unused
        for name in ("distance", "v_max", "a_max"):
            if getattr(args, name) is None:
                return f"argument --{name.replace('_', '-')}: required with an axis (--mode or --measured)"
        if args.distance == 0:
            return "argument --distance: must be non-zero"
        if args.n_modes is not None and not args.measured:
            return "argument --n-modes: only with --measured"
        if args.certify is not None and (args.smooth == "true" or args.j_max is not None):
            return "argument --certify: the continuous certificate bounds the design with jumps: not with " + (
                "--smooth true (give auto or false)" if args.smooth == "true" else "--j-max"
            )
        if args.damping is not None:
            damping = _damping(args.damping)
            if isinstance(damping, str) and damping != "unknown":
                return damping
            args.damping = damping
        outs = list(args.out or [Path("move.csv")])
        if args.resolution is not None and not args.resolution <= abs(args.distance):
            return f"argument --resolution: must lie in (0, {abs(args.distance):g}] m (at most --distance)"
        fill_defaults(args, AXIS_DEFAULTS)
        if args.mode:
            nyquist = 2.0 * max(f for f, _, _ in args.mode) * (1.0 + args.uncertainty)
            if not args.rate > nyquist:
                return (
                    f"argument --rate: must exceed twice the highest frequency of the band (Nyquist: > {nyquist:g} Hz "
                    f"with --uncertainty {args.uncertainty:g}), got {args.rate:g}"
                )
        if args.out is None:
            problem = output_path_problem("move.csv")
            if problem:
                return f"argument --out: the default move.csv cannot be written: {problem}"
        return None
    for name in AXIS_ONLY:
        if getattr(args, name) is not None:
            return f"argument --{name.replace('_', '-')}: only with an axis (--mode or --measured)"
    outs = args.out or []
    if any(str(o).lower().endswith(".csv") for o in outs):
        return "argument --out: a .csv command is written only with an axis (--mode or --measured)"
    if len(outs) > 1:
        return "argument --out: one figure file without an axis"
    if args.figure == "profiles":
        unused = refuse_unused(args, OVERVIEW_ONLY, "with --figure profiles (the paper's Fig. 2 is fixed)")
        if unused:
            return unused
    fill_defaults(args, PAPER_DEFAULTS)
    if args.out is None:
        problem = output_path_problem("shaping.png")
        if problem:
            return f"argument --out: the default shaping.png cannot be written: {problem}"
    low, high = args.band
    if not low < high:
        return f"argument --band: LOW must be < HIGH, got {low:g} {high:g}"
    if len(args.gammas) < 2:
        return f"argument --gammas: give at least 2 exponents, got {len(args.gammas)}"
    return None


def check_exponents(args) -> str | None:
    """The paper's start exponents must be pairwise apart (checked with the command's own rule, after `check`)."""
    if args.mode or args.measured or args.figure == "profiles":
        return None
    from ..commands import MIN_EXPONENT_GAP, exponents_apart

    if not exponents_apart(args.gammas):
        return (
            f"argument --gammas: the exponents must differ pairwise by at least {MIN_EXPONENT_GAP:g}, "
            f"got {' '.join(f'{x:g}' for x in args.gammas)}"
        )
    return None


def run(args) -> int:
    if getattr(args, "mode", None) or getattr(args, "measured", None):
        return _axis_run(args)
    from pathlib import Path

    args.out = args.out[0] if args.out else Path("shaping.png")  # the paper's figure: one image
    return _paper_run(args)


def _axis_run(args) -> int:
    """`jaxbelt shaping --mode F:Z ... | --measured FILE`: every design for the user's axis (jaxbelt.design_move)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure
    from ..models.axis import ModalAxis
    from ..shaping.moves import PiecewiseMove
    from ..shaping.plan import design_move
    from ..solution import SolveError

    if args.measured:
        from ..shaping.measurement import identify_measurement

        try:
            axis, what = identify_measurement(args.measured, args.n_modes or 1, column=args.column, kind=args.kind)
        except ValueError as e:  # the API names its parameters; the command line names its own options
            raise ValueError(_cli_names(str(e))) from None
        column = f", column {args.column}" if args.column is not None else ""
        print(f"identified from {args.measured} ({what}{column}):")
        for i in range(axis.n_modes):
            f, z = float(axis.frequencies[i]), float(axis.damping_ratios[i])
            sf = float(axis.frequency_std[i]) if axis.frequency_std is not None else float("nan")
            sz = float(axis.damping_std[i]) if axis.damping_std is not None else float("nan")
            print(f"  mode {i + 1}: {f:.4f} +- {sf:.2g} Hz, damping ratio {z:.4f} +- {sz:.2g}")
        nyquist = 2.0 * float(np.max(np.asarray(axis.frequencies))) * (1.0 + args.uncertainty)
        writes_csv = any(str(o).lower().endswith(".csv") for o in (args.out or ["move.csv"]))
        if writes_csv and not args.rate > nyquist:  # known once the modes are: before the design
            raise ValueError(
                f"argument --rate: must exceed twice the highest frequency of the identified band (Nyquist: > "
                f"{nyquist:g} Hz with --uncertainty {args.uncertainty:g}), got {args.rate:g}"
            )
    else:
        f, z, g = zip(*args.mode)
        axis = ModalAxis(list(f), list(z), list(g))
    plan = design_move(
        axis,
        args.distance,
        args.move_time,
        v_max=args.v_max,
        a_max=args.a_max,
        j_max=args.j_max,
        uncertainty=args.uncertainty,
        progress=not args.no_progress,
        damping=args.damping,
        smooth={"auto": "auto", "true": True, "false": False}[args.smooth],
        certify_rtol=args.certify,
        rate_hz=args.rate,
        resolution=args.resolution,
    )
    print(plan.format_table())
    best = plan.best
    if best is None:
        raise SolveError(
            "no candidate is feasible, converged and within the limits (the table's notes say why); nothing written"
        )
    print(
        f"recommended: {best.name}, move time {best.move_time:.4f} s, worst residual {best.worst_percent:.4g} % of the "
        f"unshaped move ({best.worst_m:.3e} m) over +-{100 * args.uncertainty:.0f} %"
    )
    from pathlib import Path

    outs = list(args.out or [Path("move.csv")])
    figures = [o for o in outs if not str(o).lower().endswith(".csv")]
    for o in outs:
        if str(o).lower().endswith(".csv"):
            pv, pa, pj = plan.to_csv(o, args.rate)
            limits = f"v_max {args.v_max:g}, a_max {args.a_max:g}" + (
                f", j_max {args.j_max:g}" if args.j_max is not None else ""
            )
            print(
                f"wrote {o} ({args.rate:g} Hz, columns t,x,v,a; sampled peaks |v| {pv:.6g} m/s, |a| {pa:.6g} m/s^2, "
                f"|j| {pj:.6g} m/s^3; limits {limits})"
            )
            if isinstance(best.command, PiecewiseMove):
                print(
                    f"note: the recommended command's {'jerk' if args.j_max is not None else 'acceleration'} jumps; "
                    f"the table states its residual as a drive that follows the x column linearly at {args.rate:g} Hz "
                    "executes it; a drive that interpolates the a column instead runs another command (v and a are "
                    "for feed-forward)"
                )
            if not figures:
                figures.append(o.with_suffix(".png"))
    fig = plan.plot()
    for o in figures:
        save_figure(fig, o, dpi=120)
        print(f"wrote {o}")
    plt.close(fig)
    return 0


def _paper_run(args) -> int:
    """Without an axis: the paper's figure (Incerti, pseudo-polynomial commands) and an honest comparison: residual
    *amplitudes* (the paper's energy H only where the paper uses it, labelled), every command ending at the same
    move time, and each command's peaks."""
    import jax.numpy as jnp
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure
    from ..commands import PseudoPolynomial
    from ..models.platform import BeltPlatform
    from ..objectives.residual import residual_energy
    from ..optimise.command import optimise_command, optimise_robust, sensitivity_curve, shaped_commands, tolerance_band
    from ..plots.shaping import reference_level, shaping_figure
    from ..runs import platform_response
    from ..shaping.moves import peaks

    if args.figure == "profiles":
        return _profiles(args)
    progress = not args.no_progress
    plat = BeltPlatform()
    phi = args.revolutions * 2 * jnp.pi
    T = float(args.duration)
    band = (float(args.band[0]), float(args.band[1]))
    cmd0 = PseudoPolynomial(jnp.asarray(args.gammas, dtype=float), phi, T)
    res = optimise_command(plat, cmd0, progress=progress)
    h0 = float(residual_energy(plat, cmd0))
    print(
        f"residual energy (Incerti eq. 32, the paper's target): H(start {list(args.gammas)}) = {h0:.6g} rad^2/s^4, "
        f"E(T) = {h0 * float(plat.energy_factor):.4g} J"
    )
    g = ", ".join(f"{x:.4f}" for x in res.gammas.tolist())
    print(
        f"optimised exponents ({g}): H = {float(res.value):.3g} (H/H0 = {float(res.value) / h0:.2e}, "
        f"{res.n_steps} L-BFGS steps)"
    )
    label0 = "-".join(f"{x:g}" for x in args.gammas)
    cmds = {label0: cmd0, "optimised": res.command}
    for name, c in shaped_commands(plat, cmd0).items():  # the base shortened: every command ends at T
        cmds[f"{label0} + {name} (base {float(c.base.duration):.3g} s)"] = c
    measure = "worst" if args.robust_mode == "max" else "mean"
    for n in args.robust_order:
        # start from the classical rest-to-rest polynomial of order n: exponents n+1 .. 2n+1
        start = PseudoPolynomial(jnp.arange(n + 1, 2 * n + 2, dtype=float), phi, T)
        rob = optimise_robust(plat, start, band=band, mode=args.robust_mode, progress=progress)
        g = ", ".join(f"{x:.3f}" for x in rob.gammas.tolist())
        state = "converged" if rob.converged else "NOT converged"
        print(
            f"robust n={n} ({measure} residual amplitude over {band[0]:g}-{band[1]:g} omega_n, relative to the "
            f"{label0} command's): exponents ({g}), {float(rob.value):.3g} (start {float(rob.initial_value):.3g}); "
            f"{state}: {rob.message}"
        )
        cmds[f"robust n={n} ({args.robust_mode}, band {band[0]:g}-{band[1]:g})"] = rob.command
    omegas, curves = sensitivity_curve(plat, cmds, rel=args.spread)
    ref = reference_level(omegas, curves, plat.omega_n, label0, band)
    x = np.asarray(omegas) / float(plat.omega_n)
    inside = (x >= band[0] - 1e-12) & (x <= band[1] + 1e-12)
    centre = int(np.argmin(np.abs(x - 1.0)))
    print(
        f"residual vibration amplitude of the platform after the move, in % of the {label0} command's worst over "
        f"{band[0]:g}-{band[1]:g} omega_n ({1e3 * ref:.4g} mrad); 5 % band: the width, as a fraction of omega_n = "
        f"{float(plat.omega_n):.3f} rad/s, where the amplitude stays below 5 % of that (sweep +-{args.spread:.0%}); "
        f"every command ends at {T:g} s:"
    )
    print(
        f"  {'command':44s} {'worst %':>8s} {'at w_n %':>9s} {'5 % band':>9s} {'move time':>10s} "
        f"{'peak speed':>11s} {'peak accel':>11s}"
    )
    for name, a in curves.items():
        c = cmds[name]
        a = np.asarray(a)
        w = tolerance_band(omegas, a, ref, plat.omega_n)
        edge = ">=" if w >= 2 * args.spread * (1 - 1e-9) else "  "  # the band fills the whole sweep
        pv, pa, _ = peaks(c, n=4001)
        print(
            f"  {name:44s} {100 * np.max(a[inside]) / ref:8.2f} {100 * a[centre] / ref:9.3g} {edge}{w:7.3f} "
            f"{float(c.end_time):8.3f} s {pv:7.1f} rad/s {pa:6.0f} rad/s^2"
        )
    before, after = platform_response(plat, cmd0), platform_response(plat, res.command)
    fig = shaping_figure(
        before,
        after,
        omegas,
        curves,
        plat.omega_n,
        reference=label0,
        band=band,
        move_times=(float(cmd0.end_time), float(res.command.end_time)),
    )
    save_figure(fig, args.out, dpi=120)
    plt.close(fig)
    print(f"wrote {args.out}")
    return 0


def _profiles(args) -> int:
    import jax.numpy as jnp
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure
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
    save_figure(fig, args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
