"""`jaxbelt nonlinear --out nonlinear.png`: the non-linear belt scene (Moon & Wickert, 1997) on one page."""

from __future__ import annotations

from ._args import float_in, image_path, int_at_least, positive_float


def register(subparsers):
    p = subparsers.add_parser(
        "nonlinear",
        help="non-linear belt with eccentric pulleys: response curve, folds, speed ramps vs measurements (Moon & Wickert)",
        description="Response curve by harmonic balance and continuation with its unstable branch and folds, "
        "the measured jumps (Fig. 8 analogue) and speed ramps through resonance (Fig. 3).",
    )
    p.add_argument("--out", type=image_path, default="nonlinear.png", help="output image (default: nonlinear.png)")
    p.add_argument("--damping", type=float_in(0.0, 1.0), default=None, help="modal damping ratio (default: identified)")
    p.add_argument("--v-l", type=positive_float, default=None, help="longitudinal/transverse wave speed ratio")
    p.add_argument("--wave-speed", type=positive_float, default=None, help="transverse wave speed [m/s]")
    p.add_argument("--harmonics", type=int_at_least(1), default=3, help="harmonics of the harmonic balance (default 3)")
    p.add_argument("--quick", action="store_true", help="shorter, coarser ramp records (faster)")
    p.set_defaults(func=run)


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np

    from ..models.nonlinear import MEASUREMENTS, NonlinearBelt, jumps, response_curve, speed_ramp
    from ..plots.nonlinear import response_figure

    kw = {k: v for k, v in (("damping", args.damping), ("v_l", args.v_l), ("wave_speed", args.wave_speed)) if v is not None}
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
    m = {x.quantity: x.value for x in MEASUREMENTS}
    lines = [f"v_t {float(belt.wave_speed):.2f} m/s, v_l {float(belt.v_l):.1f}, xi {float(belt.damping):.4f}",
             f"sensor: {belt.sensor_pulley} pulley, travel {belt.travel}",
             f"folds {', '.join(f'{x:.4f}' for x in f)} m/s (measured {m['down_jump_speed']:g}, {m['up_jump_speed']:g})"]
    if j is not None:
        lines.append("jumps [mm]: up {:.2f} -> {:.2f} (meas. {:.2f} -> {:.2f}), down {:.2f} -> {:.2f} "
                     "(meas. {:.2f} -> {:.2f})".format(1e3 * float(j.pp_before[1]), 1e3 * float(j.pp_after[1]),
                                                        1e3 * m["up_jump_pp_before"], 1e3 * m["up_jump_pp_after"],
                                                        1e3 * float(j.pp_before[0]), 1e3 * float(j.pp_after[0]),
                                                        1e3 * m["down_jump_pp_before"], 1e3 * m["down_jump_pp_after"]))
    summary = "\n".join(lines)
    fig = response_figure(curve, up, down, MEASUREMENTS, summary, jumps=j)
    fig.savefig(args.out, dpi=110)
    print(summary)
    print(f"wrote {args.out}")
    return 0
