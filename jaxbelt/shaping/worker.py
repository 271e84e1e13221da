"""The minimax worker: the one thread beside the caller's in which `design_move`, at a given move time, prepares
and solves the minimax design and makes its rows (`minimax_solve.solving`) while the caller builds and measures the
other candidates. The LP is the longest stage of a design and needs nothing they compute; XLA releases the GIL while
it runs and compiles, so on two cores the two overlap (a warm 3-mode design 2.5 s -> 1.7 s, a first call 18 s ->
12 s). Work given to it runs in the order given (`request.validate` queues the LP's preparation first).
"""

import concurrent.futures
import os

import jax

#: created at import, its thread starts at the first submit; a forked child makes its own (a parent's executor never
#: runs the child's work: `design_move` would wait for it forever)
_WORKER: concurrent.futures.ThreadPoolExecutor


def _new_worker() -> None:
    global _WORKER
    _WORKER = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxbelt-minimax")


_new_worker()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_worker)


def _in_callers_context(fun, *args):
    """`fun(*args)` as a thread of its own would run it under the caller's JAX settings: the 64-bit mode and the
    default device, which a `with jax.enable_x64(True):` or `with jax.default_device(d):` block sets for the
    caller's thread only (read here, in the caller's thread; re-entered in the worker's)."""
    x64, device = bool(jax.enable_x64.value), jax.default_device.value

    def run():
        with jax.enable_x64(x64), jax.default_device(device):
            return fun(*args)

    return run


def submit(fun, *args) -> concurrent.futures.Future:
    """Queue `fun(*args)` on the worker, under the caller's 64-bit mode and default device; its future."""
    return _WORKER.submit(_in_callers_context(fun, *args))
