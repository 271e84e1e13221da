"""What jaxbelt's first-call machinery saves today, against JAX's own persistent compilation cache.

Each variant runs an entry point's first call in a fresh process, **cold** (empty cache folder) and with a
**warm cache** (the folder a previous process of the same variant filled), in a user's environment (no thread
variable). The variants switch off one piece each:

- `all on`: jaxbelt as shipped;
- `store off`: `enable_compilation_cache(programs=False)`: JAX's persistent cache alone, no stored programs
  (`jaxbelt._store`: a later process runs the lowered program without tracing it);
- `quick compile off`: XLA's default options for the programs jaxbelt compiles with its quick CPU options
  (`jaxbelt._xla.QUICK_COMPILE`);
- `private off`: `JAXBELT_PRIVATE_APIS=0`: none of the private internals (`jaxbelt._compat`: checkify's pass
  over loops, equinox's internal checks as values, the check counter), the public fallback.

Run: `python benchmarks/machinery.py [--repeats N] [--quick] [NAME ...]`; writes `benchmarks/results/machinery.json`.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import coldstart  # noqa: E402
from _common import machine_info, results_dir  # noqa: E402

VARIANTS = {
    "all on": ({}, {}),
    "store off": ({"programs": False}, {}),
    "quick compile off": (
        {
            "before_cache": "from jaxbelt import _xla; _xla.QUICK_COMPILE.clear()\n"
            "import jaxbelt.shaping.pseudo as _p; _p.COMPILER_OPTIONS.clear()"
        },
        {},
    ),
    "private off": ({}, {"JAXBELT_PRIVATE_APIS": "0"}),
}
DEFAULT = ("tune_pid", "optimise_command", "design_move", "simulate_fourbar", "response_curve")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(DEFAULT))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="check that the benchmark runs: residual_energy only, jaxbelt as shipped, one repeat (a cold and a "
        "warm process); writes into the scratch folder",
    )
    args = parser.parse_args()
    variants = VARIANTS
    if args.quick:
        args.names, args.repeats = ["residual_energy"], 1
        variants = {k: VARIANTS[k] for k in ("all on",)}
    rows = []
    with tempfile.TemporaryDirectory() as data_dir:
        for name in args.names:
            for variant, (spec, env_extra) in variants.items():
                cold, warm = [], []
                for _ in range(args.repeats):
                    with tempfile.TemporaryDirectory() as cache:
                        env = dict(coldstart._entry_env(cache), **env_extra)
                        cold.append(coldstart._child(name, env, data_dir, **spec)["first"]["s"])
                        warm.append(coldstart._child(name, env, data_dir, **spec)["first"]["s"])
                row = dict(
                    name=name,
                    variant=variant,
                    cold_s=float(np.median(cold)),
                    warm_s=float(np.median(warm)),
                    cold_range=[float(min(cold)), float(max(cold))],
                    warm_range=[float(min(warm)), float(max(warm))],
                )
                rows.append(row)
                print(f"{name:18s} {variant:18s} cold {row['cold_s']:.2f} s  warm {row['warm_s']:.2f} s", flush=True)
    out_dir = results_dir(args.quick)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = dict(
        scene="machinery",
        machine=machine_info(),
        quick=args.quick,
        repeats=args.repeats,
        rows=rows,
        when=time.strftime("%Y-%m-%d"),
    )
    (out_dir / "machinery.json").write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
