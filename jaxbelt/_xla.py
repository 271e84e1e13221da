"""XLA's quicker CPU compilation, for runs where compiling dominates (the test suite, quick benchmarks, first calls).

XLA's classic CPU emitters at LLVM optimisation level 0, without splitting a program for parallel
code generation, compile jaxbelt's programs 2-3x faster than XLA's defaults. The programs (HLO) are
the same and their results agree with XLA's defaults to rounding (tests/test_xla_flags.py); they
run slower, so timings taken with them are not the library's speed.

XLA's options change between releases (XLA 0.11's CPU compiler has no `xla_cpu_use_fusion_emitters`) and between
backends (a GPU compiler knows none of the CPU's): `supported_options` keeps those the running backend accepts,
found by compiling a one-operation program with them once per process, and `quick_compile()` gives the quick CPU
options to a CPU backend only. An option the running XLA does not know is left out, with no error: the program
compiles with XLA's defaults for it.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys

import jax
import numpy as np

FAST_COMPILE_FLAGS = (
    "--xla_cpu_use_fusion_emitters=false",
    "--xla_backend_optimization_level=0",
    "--xla_cpu_parallel_codegen_split_count=1",  # one LLVM module per program: the callers run one process per core
)


def fast_compile_xla_flags(caller: str = "") -> str | None:
    """`caller`'s XLA_FLAGS with the fast-compilation flags it does not set itself (the caller's win),
    or None where this JAX's XLA refuses one of them (XLA aborts on an unknown flag: checked in a
    0.7 s subprocess)."""
    given = caller.split()
    names = {f.split("=", 1)[0] for f in given}
    wanted = [f for f in FAST_COMPILE_FLAGS if f.split("=", 1)[0] not in names]

    def accepted(extra) -> bool:
        probe = subprocess.run(
            [sys.executable, "-c", "import jax; jax.devices('cpu')"],
            capture_output=True,
            env=dict(os.environ, XLA_FLAGS=" ".join(given + list(extra))),
            timeout=300,
        )
        return probe.returncode == 0

    if not accepted([]):
        return None  # the caller's own flags are refused: leave them to fail where the caller runs
    if not accepted(wanted):  # an XLA that no longer knows one of them: the ones it knows
        wanted = [f for f in wanted if accepted([f])]
    return " ".join(given + wanted) if wanted else None


#: XLA's options for a program compiled on a user's first call whose run time is small beside its compile time
#: (an optimiser's step, an evaluation on a grid): the classic CPU emitters at LLVM optimisation level 0 compile it
#: 2-3x faster; the same HLO, results equal to rounding. CPU only (`quick_compile`).
QUICK_COMPILE = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}

_ACCEPTED: dict = {}


def _probe(x):
    return x + 1


def _accepts(options: dict) -> bool:
    try:
        jax.jit(_probe, compiler_options=options).lower(jax.ShapeDtypeStruct((), np.float32)).compile()
    except Exception as e:  # noqa: BLE001 - XLA's INVALID_ARGUMENT "No such compile option" (or a bad value)
        if "option" in str(e).lower() or "INVALID_ARGUMENT" in str(e):
            return False
        raise
    return True


#: the CPU options `QUICK_COMPILE` names, known to the CPU compiler of these jaxlib releases (major, minor) (the
#: suite runs on them): no probe there. Any other release is probed.
_KNOWN = {"cpu": ((0, 10), frozenset(QUICK_COMPILE))}


def _known(backend: str, names) -> bool:
    import importlib.metadata as md

    entry = _KNOWN.get(backend)
    if entry is None or not set(names) <= entry[1]:
        return False
    try:
        major, minor = (int(p) for p in md.version("jaxlib").split(".")[:2])
    except (md.PackageNotFoundError, ValueError):
        return False
    return (major, minor) == entry[0]


def supported_options(wanted: dict | None) -> dict | None:
    """The options of `wanted` that the XLA of JAX's default backend accepts, or None where it accepts none of
    them. Known for the CPU options of `QUICK_COMPILE` on the jaxlib release the suite runs on (`_KNOWN`); found
    otherwise once per process and option set, by compiling a one-operation program with all of them (one probe,
    ~20 ms) and, where that is refused, with each alone."""
    if not wanted:
        return None
    backend = jax.default_backend()
    key = (backend, tuple(sorted(wanted.items())))
    if key not in _ACCEPTED:
        if _known(backend, wanted) or _accepts(dict(wanted)):
            kept = dict(wanted)
        else:
            kept = {k: v for k, v in wanted.items() if _accepts({k: v})}
        _ACCEPTED[key] = kept or None
    return _ACCEPTED[key]


def quick_compile(wanted: dict | None = None) -> dict | None:
    """`QUICK_COMPILE` (or `wanted`, a set of CPU options) as far as the default backend knows them; None on a GPU
    or TPU, whose programs compile with XLA's defaults."""
    if jax.default_backend() != "cpu":
        return None
    return supported_options(QUICK_COMPILE if wanted is None else wanted)


class LazyJit:
    """`jit(fun, compiler_options=quick_compile(wanted), **kwargs)`, built at its first call (the backend, and so
    which options it knows, is known only then; a module-level program must not start the backend at import)."""

    def __init__(self, jit, fun, wanted: dict | None, **kwargs):
        self._make = functools.partial(jit, fun, **kwargs)
        self._wanted = wanted
        self._built = None
        self._options: tuple | None = None  # (options,) once found: the backend does not change after its start
        self._ahead: list = []  # the futures of its compilations started ahead (`compiling`)
        functools.update_wrapper(self, fun)

    def options(self) -> dict | None:
        if self._options is None:
            self._options = (quick_compile(self._wanted) if self._wanted else None,)
        return self._options[0]

    def _get(self):
        if self._built is None:
            options = self.options()
            self._built = self._make(compiler_options=options) if options else self._make()
        return self._built

    def compiling(self, future) -> None:
        """Note a compilation of this program started ahead of its call, in another thread (`future`): the next call
        waits for it. (JAX keeps one compilation per program and input types, but a call made while another
        thread compiles the same program ahead of time compiles it a second time.)"""
        # the finished ones dropped: a program prepared at every call but called only now and then holds no more
        self._ahead = [(pid, f) for pid, f in self._ahead if not f.done()] + [(os.getpid(), future)]

    def __call__(self, *args, **kwargs):
        while self._ahead:
            try:
                pid, future = self._ahead.pop()
            except IndexError:  # another thread took it
                break
            if pid == os.getpid():  # a forked child never sees its parent's compile threads finish
                future.exception()  # waits; its error, if any, is the call's to raise
        return self._get()(*args, **kwargs)

    def __getattr__(self, name):  # lower, trace, ... of the jitted function
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._get(), name)
