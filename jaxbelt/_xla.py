"""XLA's quicker CPU compilation, for runs where compiling dominates (the test suite, quick benchmarks).

XLA's classic CPU emitters at LLVM optimisation level 0, without splitting a program for parallel
code generation, compile jaxbelt's programs 2-3x faster than XLA's defaults. The programs (HLO) are
the same and their results agree with XLA's defaults to rounding (tests/test_xla_flags.py); they
run slower, so timings taken with them are not the library's speed.
"""

from __future__ import annotations

import os
import subprocess
import sys

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
    flags = " ".join(given + [f for f in FAST_COMPILE_FLAGS if f.split("=", 1)[0] not in names])
    probe = subprocess.run(
        [sys.executable, "-c", "import jax; jax.devices('cpu')"],
        capture_output=True,
        env=dict(os.environ, XLA_FLAGS=flags),
        timeout=300,
    )
    return flags if probe.returncode == 0 else None


#: XLA's options for a program compiled on a user's first call whose run time is small beside its compile time
#: (an optimiser's step, an evaluation on a grid): the classic CPU emitters at LLVM optimisation level 0 compile it
#: 2-3x faster; the same HLO, results equal to rounding.
QUICK_COMPILE = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
