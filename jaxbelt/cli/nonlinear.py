"""`jaxbelt nonlinear --out nonlinear.png`: the non-linear belt scene (Moon & Wickert, 1997) on one page."""

from __future__ import annotations

from typing import Any

from ._args import float_in, image_path, int_at_least, positive_float


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
    p.add_argument("--v-l", type=positive_float, default=None, help="longitudinal/transverse wave speed ratio")
    p.add_argument("--wave-speed", type=positive_float, default=None, help="transverse wave speed [m/s]")
    p.add_argument("--harmonics", type=int_at_least(1), default=3, help="harmonics of the harmonic balance (default 3)")
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
    return None


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np

    from ..models.nonlinear import MEASUREMENTS, NonlinearBelt, jumps, response_curve, speed_ramp
    from ..models.nonlinear.calibration import MODE2_RANGE, two_mode
    from ..plots.nonlinear import response_figure

    damping = None if args.damping is None else (args.damping[0] if len(args.damping) == 1 else tuple(args.damping))
    kw: dict[str, Any] = {
        k: v for k, v in (("damping", damping), ("v_l", args.v_l), ("wave_speed", args.wave_speed)) if v is not None
    }
    belt = NonlinearBelt(**kw)
    c1 = float(belt.crossing_speeds(1)[0])
    rng = (7.5, 10.5) if not kw else (c1 - 1.0, c1 + 2.0)
    curve = response_curve(belt, rng, args.harmonics)
    f = np.asarray(curve.folds)
    j = jumps(belt, rng, args.harmonics, throw=False) if f.size == 2 else None
    lo, hi = (f.min() - 0.3, f.max() + 0.3) if f.size else (c1 - 0.3, c1 + 0.5)
    dur, hold = (2.0, 0.5) if args.quick else (6.0, 2.0)
    up = speed_ramp(belt, lo, hi, dur, hold=hold, samples_per_period=12 if args.quick else 24)
    down = speed_ramp(belt, hi, lo, dur, hold=hold, samples_per_period=12 if args.quick else 24)
    curve2 = f2 = None
    if not args.no_mode2:
        c2 = float(belt.crossing_speeds(2)[1])
        curve2 = response_curve(
            two_mode(belt), MODE2_RANGE if not kw else (c2 - 0.6, c2 + 4.4), args.harmonics, max_points=400
        )
        f2 = np.asarray(curve2.folds)
    m = {x.quantity: x.value for x in MEASUREMENTS}
    xi = " ".join(f"{x:.5f}" for x in np.atleast_1d(np.asarray(belt.damping)))
    lines = [
        f"v_t {float(belt.wave_speed):.2f} m/s, v_l {float(belt.v_l):.1f}, xi {xi}",
        f"sensor: {belt.sensor_pulley} pulley, travel {belt.travel}",
        f"folds {', '.join(f'{x:.4f}' for x in f)} m/s (measured {m['down_jump_speed']:g}, {m['up_jump_speed']:g})",
    ]
    if j is not None:
        lines.append(
            "jumps [mm]: up {:.2f} -> {:.2f} (meas. {:.2f} -> {:.2f}), down {:.2f} -> {:.2f} "
            "(meas. {:.2f} -> {:.2f})".format(
                1e3 * float(j.pp_before[1]),
                1e3 * float(j.pp_after[1]),
                1e3 * m["up_jump_pp_before"],
                1e3 * m["up_jump_pp_after"],
                1e3 * float(j.pp_before[0]),
                1e3 * float(j.pp_after[0]),
                1e3 * m["down_jump_pp_before"],
                1e3 * m["down_jump_pp_after"],
            )
        )
    if f2 is not None:
        lines.append(
            f"mode 2 folds {', '.join(f'{x:.3f}' for x in f2)} m/s (measured band "
            f"{m['mode2_band_low']:g}-{m['mode2_band_high']:g})"
        )
    summary = "\n".join(lines)
    fig = response_figure(curve, up, down, MEASUREMENTS, summary, jumps=j, curve2=curve2)
    fig.savefig(args.out, dpi=110)
    print(summary)
    print(f"wrote {args.out}")
    return 0
