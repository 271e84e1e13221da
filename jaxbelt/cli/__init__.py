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
import gc
import importlib
import os
import sys

SUBCOMMANDS = ("startup", "shaping", "fourbar", "string", "nonlinear", "bench")

#: set by `entry`: the command runs in a process of its own (no user code), see `_prepare_figures`
_OWN_PROCESS = False


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
        "--no-cache",
        action="store_true",
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
    """Run the command line `argv` (default: `sys.argv[1:]`); returns the exit status. JAX's 64-bit mode
    must be on, as for every jaxbelt call (`entry`, the command's own process, turns it on)."""
    args = build_parser().parse_args(argv)
    check = getattr(args, "check", None)  # what argparse cannot see: relations between arguments
    problem = check(args) if check is not None else None
    if problem:
        print(f"jaxbelt {args.command}: error: {problem} (see --help)", file=sys.stderr)
        return 2
    if args.command != "bench":  # the figure commands (bench runs the benchmarks in processes of their own)
        if _OWN_PROCESS:
            _prepare_figures()
        if not args.no_cache:
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


def _bind_lapack_tables() -> None:
    """Load scipy's BLAS and LAPACK pointer tables without the rest of `scipy.linalg`.

    jaxlib binds its CPU linear-algebra kernels (eig, LU, ...) to the LAPACK that scipy ships, by
    importing `scipy.linalg.cython_blas` and `scipy.linalg.cython_lapack`. Importing them the usual
    way first runs `scipy.linalg`'s package initialisation (~0.2 s: its array-API layer imports
    numpy.f2py and a hundred other modules), which jaxbelt's commands never use. The two extension
    modules are loaded here on their own, under their own names, so that jaxlib finds them in
    `sys.modules`. Only for the command's own process (where no user code runs); on any failure
    nothing is left behind and jaxlib imports them the usual way.
    """
    if "scipy.linalg" in sys.modules:
        return
    added = []
    try:
        import importlib.machinery
        import importlib.util

        spec = importlib.util.find_spec("scipy")
        folder = os.path.join(os.path.dirname(spec.origin), "linalg")
        for name in ("cython_blas", "cython_lapack"):
            full = f"scipy.linalg.{name}"
            paths = [os.path.join(folder, name + s) for s in importlib.machinery.EXTENSION_SUFFIXES]
            path = next(p for p in paths if os.path.isfile(p))
            mod_spec = importlib.util.spec_from_file_location(full, path)
            module = importlib.util.module_from_spec(mod_spec)
            mod_spec.loader.exec_module(module)
            sys.modules[full] = module
            added.append(full)
    except Exception:  # noqa: BLE001 - another scipy layout: the usual import, 0.2 s slower
        for full in added:
            sys.modules.pop(full, None)


def _no_property_list(artist) -> str:
    return "Properties: see matplotlib's documentation (this list is not built in the jaxbelt command's process)."


def _prepare_figures() -> None:
    """Import matplotlib without building the property lists of its artists' docstrings.

    As each `Artist` subclass is defined, matplotlib writes the docstring of its `set` method: the
    list of every settable property with its accepted values, parsed from the setters' docstrings
    (`matplotlib.artist.kwdoc`). For the ~100 classes a figure imports that is 0.1-0.15 s of the
    0.3-0.4 s matplotlib import, in every command that draws a figure, and nothing in the command's
    process reads a docstring. Here `kwdoc` is replaced by a one-line note before the artists are
    defined; signatures, setters and drawing are matplotlib's own. Only for the command's own process
    (`entry`), and only while no figure module is loaded (afterwards it would change nothing); on any
    failure matplotlib is imported the usual way.
    """
    if "matplotlib.figure" in sys.modules:
        return
    try:
        import matplotlib.artist as artist
    except Exception:  # noqa: BLE001 - the command reports a missing matplotlib itself
        return
    if callable(getattr(artist, "kwdoc", None)):
        artist.kwdoc = _no_property_list


def entry() -> None:
    """The `jaxbelt` command (and `python -m jaxbelt`): `main()`, then the end of the process.

    The command runs as a short-lived process, which turns JAX's 64-bit mode on first (jaxbelt computes in
    float64; a library import changes no configuration, the command is its own program):

    - Python's cyclic garbage collector is off. Its collections cost ~0.2 s of a 1.8 s warm
      `jaxbelt startup` (each one walks JAX's and matplotlib's module objects); with it off the peak
      memory of the longest commands grows by 2-6 % (measured: `nonlinear` 877 -> 897 MB).
    - scipy's LAPACK tables are loaded without `scipy.linalg` (`_bind_lapack_tables`).
    - matplotlib's artists are defined without their docstrings' property lists (`_prepare_figures`).
    - Once the command has written its outputs and the exit handlers have run, the process ends
      without the interpreter's teardown (freeing every module and XLA's client: ~0.3 s). JAX's
      compilation cache and jaxbelt's stored programs are written when they are made, not at exit.
    """
    global _OWN_PROCESS
    _OWN_PROCESS = True
    import jax

    # jaxbelt computes in float64 and leaves JAX's configuration to whoever runs it (the `jaxbelt` docstring):
    # here that is the command itself, so 64-bit mode goes on before anything (argument checks too) makes an array
    jax.config.update("jax_enable_x64", True)
    gc.disable()
    _bind_lapack_tables()
    code = main()
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
