"""`jaxbelt nonlinear --out nonlinear.png`: the non-linear belt scene (Moon & Wickert, 1997) on one page."""

from __future__ import annotations

from typing import Any

from ._args import float_in, image_path, int_in

#: most harmonics of the balance (its Newton system grows as the square of them; 3 resolve the paper's folds)
MAX_HARMONICS = 10


def register(subparsers):
    p = subparsers.add_parser(
        "nonlinear",
        help="non-linear belt with eccentric pulleys: response curve, folds, speed ramps vs measurements (Moon & Wickert)",
        description="Response curve by harmonic balance and continuation with its unstable branch and folds, "
        "the measured jumps (Fig. 8 analogue) and speed ramps through resonance (Fig. 3).",
    )
    p.add_argument("--out", type=image_path, default="nonlinear.png", help="output image (default: nonlinear.png)")
    p.add_argument(
        "--damping",
        type=float_in(0.0, 1.0, hi_open=True),
        nargs="+",
        default=None,
        metavar="XI",
        help="modal damping ratio, one for all modes or one per mode (default: identified, 0.01219 0.02713)",
    )
    p.add_argument(
        "--v-l",
        type=float_in(0.0, 1000.0),
        default=None,
        help="longitudinal/transverse wave speed ratio, in [0, 1000] (0: a linear belt; default 50)",
    )
    p.add_argument(
        "--wave-speed",
        type=float_in(0.0, 1e4, lo_open=True),
        default=None,
        help="transverse wave speed [m/s] (default 37.94, identified); the speed ranges around the crossings "
        "must stay below it",
    )
    p.add_argument(
        "--harmonics",
        type=int_in(1, MAX_HARMONICS, "the balance's system grows as their square"),
        default=3,
        help="harmonics of the harmonic balance (default 3)",
    )
    p.add_argument("--quick", action="store_true", help="shorter, coarser ramp records (faster)")
    p.add_argument("--no-mode2", action="store_true", help="skip the second-mode panel (two-mode model, 14-19 m/s)")
    p.set_defaults(func=run, check=check)


def check(args) -> str | None:
    """The models of this command have at most two modes: a third damping ratio would go unused."""
    if args.damping is not None and len(args.damping) > 2:
        return (
            f"argument --damping: give 1 ratio (all modes) or 2 (modes 1 and 2; the command's models have at "
            f"most 2 modes), got {len(args.damping)}"
        )
    if args.wave_speed is not None or args.v_l is not None or args.damping is not None:
        belt = _belt(args)
        vt = float(belt.wave_speed)
        for what, (lo, hi) in (("mode 1", _ranges(belt, True)[0]), ("mode 2", _ranges(belt, True)[1])):
            if what == "mode 2" and args.no_mode2:
                continue
            if not (0.0 < lo and hi < vt):
                return (
                    f"argument --wave-speed: the {what} response is traced over {lo:.3g}-{hi:.3g} m/s around its "
                    f"crossing speed, which must lie in (0, wave speed) = (0, {vt:g}) m/s (a faster belt is "
                    f"super-critical); give a larger --wave-speed{'' if args.no_mode2 else ' or --no-mode2'}"
                )
    return None


def _belt(args):
    from ..models.nonlinear import NonlinearBelt

    damping = None if args.damping is None else (args.damping[0] if len(args.damping) == 1 else tuple(args.damping))
    kw: dict[str, Any] = {
        k: v for k, v in (("damping", damping), ("v_l", args.v_l), ("wave_speed", args.wave_speed)) if v is not None
    }
    return NonlinearBelt(**kw)


def _ranges(belt, custom: bool):
    """The speed ranges [m/s] of the mode-1 and mode-2 response curves: the paper's, or for a belt of the
    user's, around its first and second crossing speeds."""
    from ..models.nonlinear.calibration import MODE2_RANGE

    if not custom:
        return (7.5, 10.5), MODE2_RANGE
    c1, c2 = (float(c) for c in belt.crossing_speeds(2))
    return (c1 - 1.0, c1 + 2.0), (c2 - 0.6, c2 + 4.4)


def summary(belt, folds, jumps, folds2, measured: dict, rng) -> list[str]:
    """The printed figures, read from the belt, the fold speeds `folds` of the mode-1 response curve over
    `rng`, its `jumps` (or None) and the mode-2 folds `folds2` (or None)."""
    import numpy as np

    xi = " ".join(f"{x:.5f}" for x in np.atleast_1d(np.asarray(belt.damping)))
    m = measured
    if len(folds):
        fold_line = (
            f"folds {', '.join(f'{x:.4f}' for x in folds)} m/s (measured {m['down_jump_speed']:g}, "
            f"{m['up_jump_speed']:g})"
        )
    else:
        fold_line = (
            f"folds: none between {rng[0]:.4g} and {rng[1]:.4g} m/s (the response has no jump there: too much "
            f"damping or too weak a non-linearity; measured {m['down_jump_speed']:g}, {m['up_jump_speed']:g})"
        )
    lines = [
        f"v_t {float(belt.wave_speed):.2f} m/s, v_l {float(belt.v_l):.1f}, xi {xi}",
        f"sensor: {belt.sensor_pulley} pulley, travel {belt.travel}",
        fold_line,
    ]
    if jumps is not None:
        lines.append(
            "jumps [mm]: up {:.2f} -> {:.2f} (meas. {:.2f} -> {:.2f}), down {:.2f} -> {:.2f} "
            "(meas. {:.2f} -> {:.2f})".format(
                1e3 * float(jumps.pp_before[1]),
                1e3 * float(jumps.pp_after[1]),
                1e3 * m["up_jump_pp_before"],
                1e3 * m["up_jump_pp_after"],
                1e3 * float(jumps.pp_before[0]),
                1e3 * float(jumps.pp_after[0]),
                1e3 * m["down_jump_pp_before"],
                1e3 * m["down_jump_pp_after"],
            )
        )
    if folds2 is not None:
        shown = ", ".join(f"{x:.3f}" for x in folds2) if len(folds2) else "none"
        lines.append(f"mode 2 folds {shown} m/s (measured band {m['mode2_band_low']:g}-{m['mode2_band_high']:g})")
    return lines


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np

    from .._io import save_figure
    from ..models.nonlinear import MEASUREMENTS, jumps, response_curve, speed_ramp
    from ..models.nonlinear.calibration import two_mode
    from ..plots.nonlinear import response_figure

    custom = args.damping is not None or args.v_l is not None or args.wave_speed is not None
    belt = _belt(args)
    rng, rng2 = _ranges(belt, custom)
    c1 = float(belt.crossing_speeds(1)[0])
    curve = response_curve(belt, rng, args.harmonics)
    f = np.asarray(curve.folds)
    j = jumps(belt, rng, args.harmonics, throw=False) if f.size == 2 else None
    lo, hi = (f.min() - 0.3, f.max() + 0.3) if f.size else (c1 - 0.3, c1 + 0.5)
    lo = max(lo, 0.05)
    dur, hold = (2.0, 0.5) if args.quick else (6.0, 2.0)
    up = speed_ramp(belt, lo, hi, dur, hold=hold, samples_per_period=12 if args.quick else 24)
    down = speed_ramp(belt, hi, lo, dur, hold=hold, samples_per_period=12 if args.quick else 24)
    curve2 = f2 = None
    if not args.no_mode2:
        curve2 = response_curve(two_mode(belt), rng2, args.harmonics, max_points=400)
        f2 = np.asarray(curve2.folds)
    m = {x.quantity: x.value for x in MEASUREMENTS}
    text = "\n".join(summary(belt, f, j, f2, m, rng))
    fig = response_figure(curve, up, down, MEASUREMENTS, text, jumps=j, curve2=curve2)
    save_figure(fig, args.out, dpi=110)
    print(text)
    print(f"wrote {args.out}")
    return 0
