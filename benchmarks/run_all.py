"""Run every scene benchmark, then regenerate the README's benchmark table.

Discovers `benchmarks/<scene>.py` (every module here not starting with `_` and not one of the
helpers), runs each as a subprocess (`python benchmarks/<scene>.py [--quick]`, so that one
scene's compile caches and memory do not affect the next), and finally calls
`readme_table.update_readme()`.

Run: `python benchmarks/run_all.py [--quick] [--only startup fourbar]` (also `jaxbelt bench`).
`--quick` is the CI size: the whole run stays under 2 minutes on 2 cores. Its figures go to the
git-ignored scratch folder `benchmarks/results/quick/` and leave the committed results and the
README table alone; `--update` writes them over the committed ones (and regenerates the table).
A quick run checks that every benchmark works, and most of its time is XLA compiling: it compiles
with XLA's quicker CPU settings (`jaxbelt._xla.FAST_COMPILE_FLAGS`; recorded in each JSON as
`machine.xla_flags`), so its run times are slower than the library's. `--xla-defaults` keeps XLA's
defaults; a full run always does.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

# No thread variable is set: the figures are those of a user's environment (jaxbelt limits BLAS threads around
# its own calls, `jaxbelt._threads`).

HERE = Path(__file__).resolve().parent
HELPERS = {
    "run_all",
    "readme_table",
    "shortcuts",
    "coldstart",
    "hostile_probe",
    "browser_view",
}  # coldstart: minutes of cold CLI runs, run alone; hostile_probe: not a scene; browser_view: needs a browser


def discover() -> list[str]:
    return sorted(p.stem for p in HERE.glob("*.py") if not p.stem.startswith("_") and p.stem not in HELPERS)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="CI-sized runs (< 2 minutes in all on 2 cores)")
    p.add_argument("--only", nargs="+", metavar="SCENE", help="run only these scenes")
    p.add_argument(
        "--timeout", type=float, default=None, help="per-scene time limit [s] (default: none; 300 with --quick)"
    )
    p.add_argument(
        "--xla-defaults",
        action="store_true",
        help="with --quick: compile with XLA's default settings (default: its quicker CPU compilation)",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="with --quick: overwrite the committed results and README table (default: scratch folder)",
    )
    args = p.parse_args(argv)
    if args.quick and args.timeout is None:
        args.timeout = 300.0  # a quick script that hangs fails the run instead of holding it
    scenes = discover()
    if args.only:
        unknown = sorted(set(args.only) - set(scenes))
        if unknown:
            print(f"run_all: unknown scene(s) {unknown}; available: {scenes}", file=sys.stderr)
            return 2
        scenes = [s for s in scenes if s in args.only]
    failed = []
    t0 = time.perf_counter()
    scratch = args.quick and not args.update
    env = dict(os.environ)
    if scratch:
        env["JAXBELT_BENCH_OUT"] = str(HERE / "results" / "quick")
    else:
        env.pop("JAXBELT_BENCH_OUT", None)
    if args.quick and not args.xla_defaults:
        sys.path.insert(0, str(HERE.parent))
        from jaxbelt._xla import fast_compile_xla_flags

        flags = fast_compile_xla_flags(env.get("XLA_FLAGS", ""))
        if flags is not None:
            env["XLA_FLAGS"] = flags
            print(f"run_all: quick run compiled with XLA_FLAGS={flags} (run times slower than the library's)")
    for scene in scenes:
        cmd = [sys.executable, str(HERE / f"{scene}.py")] + (["--quick"] if args.quick else [])
        print(f"=== {scene}: {' '.join(cmd[1:])}", flush=True)
        t = time.perf_counter()
        try:
            rc = subprocess.run(cmd, cwd=HERE.parent, timeout=args.timeout, env=env).returncode
        except subprocess.TimeoutExpired:
            rc = "timeout"
        print(f"=== {scene}: {'ok' if rc == 0 else f'FAILED ({rc})'} in {time.perf_counter() - t:.1f} s", flush=True)
        if rc != 0:
            failed.append(scene)
    if scratch:
        print(
            f"run_all: quick results in {env['JAXBELT_BENCH_OUT']} (committed results untouched; --update to overwrite)"
        )
    else:
        sys.path.insert(0, str(HERE))
        import readme_table

        readme_table.update_readme()
    summary = f"run_all: {len(scenes) - len(failed)}/{len(scenes)} benchmarks ran in {time.perf_counter() - t0:.1f} s"
    if failed:
        print(f"{summary}; FAILED: {' '.join(failed)} (their output is above)", file=sys.stderr)
        return 1
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
