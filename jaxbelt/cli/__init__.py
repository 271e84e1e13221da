"""The `jaxbelt` command: one sub-command per scene (`jaxbelt startup --out startup.png`, ...).

Each sub-command lives in `jaxbelt/cli/<name>.py` and defines `register(subparsers)`, which adds
its parser and sets `func` to the function that runs it.

Compiled programs are kept in JAX's persistent compilation cache (`jaxbelt.cache`), so that a
second run of a command skips most of its XLA compilation; `jaxbelt --no-cache COMMAND` runs
without it.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import sys

SUBCOMMANDS = ("startup", "shaping", "fourbar", "string", "nonlinear", "bench")


class _Parser(argparse.ArgumentParser):
    """Bad arguments: one line on stderr (`jaxbelt startup: error: argument --gamma: must be > 0`), exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxbelt",
        description="Differentiable simulation of belt drives and DC-motor mechanisms (figures from the papers).",
    )
    parser.add_argument(
        "--no-cache", action="store_true",
        help="do not use the persistent compilation cache (default: compiled programs are kept in "
        "~/.cache/jaxbelt/xla, or $XDG_CACHE_HOME/jaxbelt/xla, and reused by later runs)",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:  # a scene that is not part of this installation
            if e.name == f"{__name__}.{name}":
                continue
            raise
        mod.register(sub)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    check = getattr(args, "check", None)  # what argparse cannot see: relations between arguments
    problem = check(args) if check is not None else None
    if problem:
        print(f"jaxbelt {args.command}: error: {problem} (see --help)", file=sys.stderr)
        return 2
    if not args.no_cache and args.command != "bench":
        from ..cache import enable_compilation_cache

        try:
            enable_compilation_cache()
        except OSError as e:  # an unwritable cache folder costs time, not the result
            print(f"jaxbelt: compilation cache disabled ({e})", file=sys.stderr)
    try:
        return int(args.func(args) or 0)
    except ValueError as e:  # bad parameters: say which, no traceback
        print(f"jaxbelt {args.command}: error: {e}", file=sys.stderr)
        return 2


def entry() -> None:
    """The `jaxbelt` command (and `python -m jaxbelt`): `main()`, then the end of the process.

    Once the command has written its outputs and the exit handlers have run, the process ends
    without the interpreter's teardown (freeing every module and XLA's client: ~0.3 s, a sixth of
    a warm `jaxbelt startup`). JAX's compilation cache and jaxbelt's stored programs are written
    when they are made, not at exit.
    """
    code = main()
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
