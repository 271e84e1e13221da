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
import contextlib
import errno
import gc
import importlib
import os
import sys
import warnings

from .._lapack import bind_tables

SUBCOMMANDS = ("startup", "shaping", "shaper", "fourbar", "string", "nonlinear", "bench")

#: set by `entry`: the command runs in a process of its own (no user code), see `_prepare_figures`
_OWN_PROCESS = False


class _Parser(argparse.ArgumentParser):
    """Bad arguments: one line on stderr (`jaxbelt startup: error: argument --gamma: must be > 0`), exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


class _ArgumentError(Exception):
    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog, self.message = prog, message


class _EarlyParser(_Parser):
    """The parser of the early pass (`_refuse_early`): a bad argument is raised, to be reported by the caller."""

    def error(self, message):
        raise _ArgumentError(self.prog, message)


def build_parser(parser_class=_Parser) -> argparse.ArgumentParser:
    parser = parser_class(
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
    return _run(build_parser().parse_args(argv))


def _refused(args, stage: str) -> bool:
    """Run the sub-command's checks of `stage` ("early_check": relations between arguments, output paths and
    unused options, with the standard library only; "check": those that build a model); print the problem in one
    line and return True when they refuse the command."""
    check = getattr(args, stage, None)  # what argparse cannot see: relations between arguments
    problem = check(args) if check is not None else None
    if problem:
        print(f"jaxbelt {args.command}: error: {problem} (see --help)", file=sys.stderr)
        return True
    return False


def _run(args) -> int:
    """Check and run the parsed command line `args`."""
    if _refused(args, "early_check") or _refused(args, "check"):
        return 2
    if args.command != "bench":  # the figure commands (bench runs the benchmarks in processes of their own)
        if _OWN_PROCESS:
            _prepare_figures()
        if not args.no_cache:
            from ..cache import enable_compilation_cache

            try:
                enable_compilation_cache()
            except (OSError, ValueError) as e:  # an unwritable cache folder costs time, not the result
                print(f"jaxbelt: compilation cache disabled ({e})", file=sys.stderr)
    try:
        with _OneLineWarnings(f"jaxbelt {args.command}"):
            return int(args.func(args) or 0)
    except Exception as e:
        found = _failure(e)
        if found is None:
            raise
        message, code = found
        print(f"jaxbelt {args.command}: error: {message}", file=sys.stderr)
        return code


def _refuse_early() -> None:
    """In the command's own process, before JAX is imported (about 1 s): parse the command line and run the
    sub-command's early checks (values, output paths, rates, unused options: the standard library only); a bad
    one ends the process at once with its one line and status 2, before anything is loaded or compiled. A command
    line without a command is left to `main`, which reports it the same way."""
    try:
        args = build_parser(_EarlyParser).parse_args(sys.argv[1:])
    except _ArgumentError as e:
        if e.prog == "jaxbelt" and "required" in e.message:  # no command: `main` says so (or runs what replaced it)
            return
        print(f"{e.prog}: error: {e.message} (see --help)", file=sys.stderr)
        sys.stderr.flush()
        os._exit(2)
    if _refused(args, "early_check"):
        sys.stderr.flush()
        os._exit(2)


def _failure(error: BaseException) -> tuple[str, int] | None:
    """`(one-line message, exit status)` of an error a command reports without a traceback: bad parameters
    (`ValueError`, status 2), a computation that failed for a reason jaxbelt states (`SolveError`,
    `SteadyStateError`, `FloatingPointError`, or a check that failed inside a compiled program: status 1).
    None for anything else (a bug: the traceback is wanted)."""
    from .._guard import runtime_message

    inner = runtime_message(error)  # a check inside a compiled program: its message, not JAX's stack
    if inner is not None:
        return inner, 1
    if isinstance(error, ValueError):
        return str(error), 2
    system = _system_failure(error)
    if system is not None:
        return system, 1
    if isinstance(error, RuntimeError | FloatingPointError) and type(error).__module__.startswith("jaxbelt"):
        return str(error), 1
    return None


#: errors of the system, not of jaxbelt, that a command reports in one line (status 1): a full disk or quota, a
#: file-size limit, a read-only file system, no permission, an I/O error
_SYSTEM_ERRNOS = {
    errno.ENOSPC: "free some space (or write to another disk) and run again",
    errno.EDQUOT: "free some space (or write to another disk) and run again",
    errno.EFBIG: "the file system or `ulimit -f` limits the file's size",
    errno.EROFS: "write to another folder",
    errno.EACCES: "check the permissions, or write to another folder",
    errno.EPERM: "check the permissions, or write to another folder",
    errno.EIO: "the disk reported an error",
}


def _system_failure(error: BaseException) -> str | None:
    """One line for an `OSError` of the system (`_SYSTEM_ERRNOS`: a full disk, ...): what failed on which file and
    what to do, instead of a traceback; None for any other error. Outputs are written atomically
    (`jaxbelt._io`), so a failed write leaves the previous file whole."""
    if not isinstance(error, OSError) or error.errno not in _SYSTEM_ERRNOS:
        return None
    where = f" writing {error.filename!r}" if error.filename else ""
    return (
        f"{error.strerror or os.strerror(error.errno)}{where}: {_SYSTEM_ERRNOS[error.errno]} (any previous output "
        "file is left as it was)"
    )


class _OneLineWarnings(contextlib.ContextDecorator):
    """jaxbelt's warnings as one line each on stderr (`jaxbelt CMD: warning: ...`), without the file and line
    of the code that raised them; other libraries' warnings as usual."""

    def __init__(self, prefix: str):
        self.prefix = prefix
        self._saved = None

    def __enter__(self):
        self._saved = warnings.showwarning
        prefix, usual = self.prefix, warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if f"{os.sep}jaxbelt{os.sep}" in str(filename):
                print(f"{prefix}: warning: {message}", file=sys.stderr if file is None else file)
            else:
                usual(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc):
        warnings.showwarning = self._saved
        return False


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

    Measured saving (as for the LAPACK tables, `entry`): without it a warm `jaxbelt startup` takes 1.051x
    the time (median of 20 pairs; spread 0.86-1.51x) and 1.061x the CPU time, about 0.07 s. Safe: only
    the text of the `set` docstrings changes, in a process that never shows one (tested).
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
    float64; a library import changes no configuration, the command is its own program). Four start-up
    savings, each kept for what it was measured to save: the whole process of a warm
    `jaxbelt startup --out s.png` (compilation cache filled), run 20 times with and 20 times without the
    saving in turn, on 2 CPU cores shared with other work; the ratio without/with is the median of the
    pairs (spread: smallest and largest pair). Without all four the command takes 1.56x the time
    (1.09-1.79x), 1.49x the CPU time.

    - Python's cyclic garbage collector is off: without that, 1.106x the time (0.99-1.39x), 1.112x the
      CPU time, about 0.17 s (each collection walks JAX's and matplotlib's module objects). Safe in a
      process that ends when the command does: reference counting still frees almost everything; the
      peak memory of the longest command grows by 2-6 % (`nonlinear` 877 -> 897 MB), the start-up's not
      at all (270 MiB either way).
    - scipy's LAPACK tables are loaded without `scipy.linalg` (`jaxbelt._lapack.bind_tables`, which the library
      also does at its first use): 1.087x, 0.1 s.
    - matplotlib's artists are defined without their docstrings' property lists (`_prepare_figures`):
      1.051x, 0.07 s.
    - Once the command has written its outputs and the exit handlers have run, the process ends
      without the interpreter's teardown (freeing every module and XLA's client): without that,
      1.195x the time (0.97-1.52x), 1.182x the CPU time, about 0.3 s. Safe: the exit handlers run and
      the output streams are flushed first (tested); the figure file is closed when it is written,
      and JAX's compilation cache and jaxbelt's stored programs are written when they are made, not
      at exit.
    """
    global _OWN_PROCESS
    _OWN_PROCESS = True
    _refuse_early()
    # (BLAS threads: the library limits them around its own calls, `jaxbelt._threads`; nothing to set here)
    import jax

    # jaxbelt computes in float64 and leaves JAX's configuration to whoever runs it (the `jaxbelt` docstring):
    # here that is the command itself, so 64-bit mode goes on before anything (argument checks too) makes an array
    jax.config.update("jax_enable_x64", True)
    gc.disable()
    bind_tables()
    code = main()
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
