"""`jaxbelt shaper`: an input shaper for the user's axis, as the text a firmware loads (`jaxbelt.design_shaper`).

`jaxbelt shaper --firmware rrf --mode 40:0.05` prints RepRapFirmware's `M593 P"custom" H… T…` line;
`--firmware klipper` Klipper's `[input_shaper]` section and its `SET_INPUT_SHAPER` command. The axis comes from
`--mode F:Z` (one per mode) or `--measured FILE` (a free decay t,y, or a power spectral density such as Klipper's
resonance test writes; `--n-modes`, `--column`). `--duration` [s] or `--target` (the shortest shaper that leaves
at most that residual ratio); neither: the duration of the best classic shaper. `--out FILE` writes the text.
"""

from __future__ import annotations

from ._args import float_in, int_in, positive_float


def register(subparsers):
    p = subparsers.add_parser(
        "shaper",
        help="an input shaper for your axis as the firmware's text (RepRapFirmware M593, Klipper [input_shaper])",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    p.add_argument("--firmware", choices=("rrf", "klipper"), required=True, help="the firmware that loads it")
    p.add_argument("--mode", type=_mode, action="append", default=[], help="a mode: frequency F [Hz]:damping Z")
    p.add_argument("--measured", default=None, help="identify the modes from a CSV (free decay t,y or a PSD)")
    p.add_argument("--n-modes", type=int_in(1, 8), default=None, help="modes to identify from --measured (1)")
    p.add_argument("--column", default=None, help="the column of --measured to read (name or index)")
    p.add_argument("--duration", type=positive_float, default=None, help="the shaper's longest length [s]")
    p.add_argument(
        "--target", type=float_in(0.0, 1.0, lo_open=True, hi_open=True), default=None, help="residual ratio to reach"
    )
    p.add_argument(
        "--uncertainty", type=float_in(0.0, 0.9, hi_open=True), default=0.2, help="band +-u of every mode (0.2)"
    )
    p.add_argument("--axis-name", choices=("x", "y"), default="x", help="Klipper's axis letter (x)")
    p.add_argument("--out", default=None, help="write the firmware text to this file (.g, .gcode, .cfg or .txt)")
    p.set_defaults(func=run, early_check=early_check)


#: `jaxbelt.models.axis.FREQUENCY_RANGE_HZ`, here without importing JAX (the command line is parsed first; a test
#: keeps the two equal)
FREQUENCY_RANGE_HZ = (1e-3, 1e7)
#: `jaxbelt.shaping.firmware_shaper.TARGET_FLOOR`, likewise
TARGET_FLOOR = 1e-6
#: design_shaper's and identify_measurement's parameters, as the options that give them
_OPTIONS = {"duration": "--duration", "target": "--target", "uncertainty": "--uncertainty", "channel": "--column"}


def _mode(text: str):
    """F:Z -> (frequency [Hz] within `FREQUENCY_RANGE_HZ`, damping ratio in [0, 1))."""
    import argparse
    import math

    try:
        f, z = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected F:Z (two numbers), got {text!r}") from None
    lo, hi = FREQUENCY_RANGE_HZ
    if not (math.isfinite(f) and lo <= f <= hi):
        raise argparse.ArgumentTypeError(
            f"frequency F must be finite and within [{lo:g}, {hi:g}] Hz (a mode's period from 0.1 us to 16 min), "
            f"got {f:g}"
        )
    if not (math.isfinite(z) and 0 <= z < 1):
        raise argparse.ArgumentTypeError(f"damping ratio Z must lie in [0, 1), got {z:g}")
    return f, z


def early_check(args) -> str | None:
    """Relations between the arguments (the standard library only)."""
    if bool(args.mode) == bool(args.measured):
        return "argument --mode/--measured: give the axis by --mode F:Z (one per mode) or by --measured FILE, one of the two"
    if args.measured is None and (args.n_modes is not None or args.column is not None):
        return "argument --n-modes/--column: only with --measured"
    if args.duration is not None and args.target is not None:
        return "argument --target: give --duration or --target, not both"
    if args.out is not None and not str(args.out).lower().endswith((".g", ".gcode", ".cfg", ".txt")):
        return "argument --out: the file must end in .g, .gcode, .cfg or .txt"
    if args.target is not None and args.target < TARGET_FLOOR:
        return (
            f"argument --target: must be >= {TARGET_FLOOR:g} (below, a shaper's residual is the rounding of its "
            f"exported numbers), got {args.target:g}"
        )
    if args.out is not None:
        from .._io import output_path_problem

        problem = output_path_problem(args.out)  # before the design (minutes for a --target): a hard link, ...
        if problem is not None:
            return f"argument --out: {problem}"
    return None


def _named_by_option(error: ValueError) -> ValueError:
    """`error` of a library call whose first line names a parameter that an option gives: the same, naming the
    option ("argument --duration: ...")."""
    import re

    text = str(error)
    found = re.search(r"parameter `(\w+)`", text.splitlines()[0] if text else "")
    if found is None or found.group(1) not in _OPTIONS:
        return error
    return ValueError(f"argument {_OPTIONS[found.group(1)]}: {text}")


def run(args) -> int:
    from ..models.axis import ModalAxis
    from ..shaping.firmware_shaper import design_shaper

    try:
        if args.measured:
            from ..shaping.measurement import identify_measurement

            # the model the file holds (a Klipper calibration CSV is Klipper's kind; a raw sweep is a sweep)
            axis, _ = identify_measurement(args.measured, args.n_modes or 1, column=args.column)
        else:
            fs, zs = zip(*args.mode)
            axis = ModalAxis(list(fs), list(zs))
        s = design_shaper(axis, args.duration, uncertainty=args.uncertainty, firmware=args.firmware, target=args.target)
    except ValueError as e:
        raise _named_by_option(e) from e
    modes = ", ".join(
        f"{float(f):.3f} Hz (damping {float(z):.4f})" for f, z in zip(axis.frequencies, axis.damping_ratios)
    )
    print(f"; axis: {modes}; band +-{100 * s.uncertainty:g} %")
    print(
        f"; {len(s.amplitudes)} impulses over {1e3 * s.duration:.3f} ms: worst residual {100 * s.worst:.3g} % "
        f"(no shaper of this length leaves less than {100 * s.lower_bound:.3g} %)"
    )
    if args.firmware == "rrf":
        text = s.to_firmware() + "\n"
    else:
        text = s.to_firmware("config", args.axis_name) + "\n" + s.to_firmware("command", args.axis_name) + "\n"
    print(text, end="")
    if args.out:
        from .._io import atomic_open

        with atomic_open(args.out, "w") as fh:
            fh.write(text)
        print(f"; written to {args.out}")
    return 0
