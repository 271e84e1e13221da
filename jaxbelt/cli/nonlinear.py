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
    p.add_argument("--quick", action="store_true", help="shorter ramps (faster)")
    p.set_defaults(func=run)


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np

    from ..models.nonlinear import MEASUREMENTS, NonlinearBelt, response_curve, speed_ramp
    from ..plots.nonlinear import response_figure

    kw = {k: v for k, v in (("damping", args.damping), ("v_l", args.v_l), ("wave_speed", args.wave_speed)) if v is not None}
    belt = NonlinearBelt(**kw)
    c1 = float(belt.crossing_speeds(1)[0])
    curve = response_curve(belt, (c1 - 1.5, c1 + 1.5), args.harmonics)
    f = np.asarray(curve.folds)
    lo, hi = (f.min() - 0.4, f.max() + 0.4) if f.size else (c1 - 0.4, c1 + 0.4)
    dur = 3.0 if args.quick else 8.0
    up = speed_ramp(belt, lo, hi, dur)
    down = speed_ramp(belt, hi, lo, dur)
    summary = (f"v_t {float(belt.wave_speed):.2f} m/s, v_l {float(belt.v_l):.1f}, xi {float(belt.damping):.4f}\n"
               f"sensor: {belt.sensor_pulley} pulley, travel {belt.travel}\nfolds {np.round(f, 3).tolist()} m/s")
    fig = response_figure(curve, up, down, MEASUREMENTS, summary)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0
