"""BLAS threads: one while a jaxbelt entry point runs, the caller's own setting restored when it returns.

jaxlib's CPU linear-algebra kernels (LU, Cholesky, QR, eigen-decompositions: the minimax design's linear
programme, the matrix exponential, the fits) and `numpy.linalg` call OpenBLAS. Its worker threads spin while
they wait for work: on jaxbelt's small matrices they gain nothing, and when the cores are busy (a browser, a
second kernel, the other worker of a test run) they take the cores from the threads doing the work. With both
cores of a 2-core machine busy, a warm `design_move` took 17x as long with OpenBLAS's default threads as with
one (24 s against 1.4 s); users do not set `OPENBLAS_NUM_THREADS`, so jaxbelt sets the limit itself, around its
own calls only (threadpoolctl), and leaves the user's numpy with its threads outside them.

`JAXBELT_BLAS_THREADS=n` sets another limit (`0`: leave BLAS alone). Without threadpoolctl the decorator does
nothing.
"""

from __future__ import annotations

import functools
import os
import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar

_F = TypeVar("_F", bound=Callable[..., Any])

_lock = threading.Lock()
_state: dict = {"depth": 0, "limiter": None, "controller": None, "modules": -1}


def blas_thread_limit() -> int | None:
    """The BLAS thread limit inside jaxbelt's entry points (`JAXBELT_BLAS_THREADS`, default 1); None: no limit."""
    raw = os.environ.get("JAXBELT_BLAS_THREADS", "1").strip()
    try:
        n = int(raw)
    except ValueError:
        raise ValueError(f"JAXBELT_BLAS_THREADS must be a whole number >= 0 (0: no limit), got {raw!r}") from None
    if n < 0:
        raise ValueError(f"JAXBELT_BLAS_THREADS must be a whole number >= 0 (0: no limit), got {n}")
    return n or None


def _controller():
    """threadpoolctl's view of the loaded BLAS libraries, made again when modules were imported since (a module
    may have loaded another BLAS: scipy's, at the first linear-algebra kernel); None without threadpoolctl."""
    count = len(sys.modules)
    if _state["modules"] != count:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:
            return None
        _state["controller"] = ThreadpoolController()
        _state["modules"] = len(sys.modules)
    return _state["controller"]


def _release_openblas() -> None:
    """Let the next thread's OpenBLAS limit take effect.

    threadpoolctl (3.6 and later) lets one thread only set OpenBLAS's process-wide thread count: the first that
    sets it, until a `with` block of its own ends; the calls of every other thread do nothing. jaxbelt's limit is
    set by the first thread to enter and lifted by the last to leave, which may be another thread (an explorer's
    background thread, a user's thread pool), and it is not a `with` block: without this release the thread that
    set the limit first (the main thread) kept that right for good, and the limit of every later computation in
    another thread was silently not set (the explorer's background `design_move` ran 2-4x slower than in the main
    thread, its OpenBLAS workers spinning on the busy cores). Called under `_lock`, around each set."""
    try:
        from threadpoolctl import OpenBLASController
    except ImportError:  # threadpoolctl without OpenBLAS support, or before 3.6: nothing holds the right
        return
    clear = getattr(OpenBLASController, "clear_controlling_thread", None)
    if clear is not None:
        clear(force=True)


def _enter() -> None:
    limit = blas_thread_limit()
    with _lock:
        _state["depth"] += 1
        if _state["depth"] > 1:
            return
        controller = _controller() if limit else None
        if controller is None:
            _state["limiter"] = None
            return
        _release_openblas()
        _state["limiter"] = controller.limit(limits=limit, user_api="blas")
        _release_openblas()


def _exit() -> None:
    with _lock:
        _state["depth"] -= 1
        if _state["depth"] == 0 and _state["limiter"] is not None:
            _release_openblas()
            _state["limiter"].restore_original_limits()
            _state["limiter"] = None
            _release_openblas()


class limited_blas:
    """Context: BLAS limited to `blas_thread_limit()` threads inside it (nested and concurrent uses share one
    limit, set by the first to enter and lifted by the last to leave: OpenBLAS's thread count is process-wide)."""

    def __enter__(self):
        _enter()
        return self

    def __exit__(self, *exc):
        _exit()
        return False


def blas_limited(fun: _F) -> _F:
    """Decorator of a public entry point: it runs inside `limited_blas()`."""

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        _enter()
        try:
            return fun(*args, **kwargs)
        finally:
            _exit()

    return wrapper  # type: ignore[return-value]
