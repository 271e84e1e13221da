"""`jaxbelt bench [--quick]`: run every scene benchmark of the repository checkout.

Runs `benchmarks/run_all.py` (work-precision JSON + PNG per scene in `benchmarks/results/`, then
the README table). The benchmarks are not part of the installed package: this command needs the
source checkout (`pip install -e .` from a clone), found next to the `jaxbelt` package.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def benchmarks_dir() -> Path | None:
    here = Path(__file__).resolve().parents[2] / "benchmarks"
    if (here / "run_all.py").is_file():
        return here
    cwd = Path.cwd() / "benchmarks"
    if (cwd / "run_all.py").is_file():
        return cwd
    return None


def register(subparsers):
    p = subparsers.add_parser(
        "bench", help="run the work-precision benchmarks (needs the repository checkout)", description=__doc__
    )
    p.add_argument("--quick", action="store_true", help="CI-sized runs (< 2 minutes on 2 cores)")
    p.add_argument("--only", nargs="+", metavar="SCENE", help="run only these scenes (e.g. startup)")
    p.set_defaults(func=run, check=_check_scenes)


def _check_scenes(args):
    """`--only` names scenes of the checkout's benchmarks (the list is the checkout's own: `run_all.discover`)."""
    where = benchmarks_dir()
    if not args.only or where is None:  # no checkout: `run` says so
        return None
    import importlib.util

    spec = importlib.util.spec_from_file_location("_jaxbelt_bench_run_all", where / "run_all.py")
    assert spec is not None and spec.loader is not None  # a .py file: Python's source loader
    run_all = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_all)
    scenes = run_all.discover()
    unknown = sorted(set(args.only) - set(scenes))
    if unknown:
        return f"argument --only: unknown scene(s) {', '.join(unknown)} (choose from {', '.join(scenes)})"
    return None


def run(args) -> int:
    where = benchmarks_dir()
    if where is None:
        print(
            "jaxbelt bench: error: the benchmarks/ folder was not found. The benchmarks live in the jaxbelt "
            "repository, not in the installed package: clone it, `pip install -e .` there, and run "
            "`jaxbelt bench` (or `python benchmarks/run_all.py`) from the checkout.",
            file=sys.stderr,
        )
        return 2
    cmd = [sys.executable, str(where / "run_all.py")] + (["--quick"] if args.quick else [])
    if getattr(args, "only", None):
        cmd += ["--only", *args.only]
    return subprocess.run(cmd, cwd=where.parent).returncode
