"""Counting XLA compilations in a block of a test (compile once per shape and static option)."""

import contextlib

import jax
import jax.monitoring

_COMPILE = "/jax/core/compile/backend_compile_duration"
_TRACE = "/jax/core/compile/jaxpr_trace_duration"


@contextlib.contextmanager
def count_compiles():
    """Number of XLA compilations inside the block (every jit, eager op or lowering counts) as `n`, and of
    traces of Python functions to jaxprs as `traces`."""
    box = {"n": 0, "traces": 0}

    def listener(name, duration, **kw):
        if name == _COMPILE:
            box["n"] += 1
        elif name == _TRACE:
            box["traces"] += 1

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield box
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
