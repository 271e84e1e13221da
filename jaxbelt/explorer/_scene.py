"""What a scene's view is (`_Scene`) and the helpers the scenes share (compiled programs, host transfers)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ._knobs import Knob


def _host(tree):
    """A pytree of device arrays as numpy arrays (one transfer)."""
    import jax

    return jax.tree_util.tree_map(np.asarray, jax.device_get(tree))


class _Scene:
    """One scene's view: its sliders (`knobs`), what a set of values computes (`compute`, returning host arrays and
    numbers), the figure's artists (`build`) and how a result redraws them (`draw`), and its key numbers."""

    key = ""
    title = ""
    long = False  # computed in the background thread
    busy_text = "computing"
    figsize = (10.5, 3.1)
    knobs: list[Knob]

    def build(self, fig) -> None:
        raise NotImplementedError

    def compute(self, v: dict) -> dict:
        raise NotImplementedError

    def job(self, v: dict) -> Callable[[], dict]:
        """The computation at the values `v` as a callable for the background thread (a long scene builds and
        checks its inputs here, in the caller's thread, and computes in the callable)."""
        return lambda: self.compute(v)

    def draw(self, r: dict) -> None:
        raise NotImplementedError

    def numbers(self, r: dict) -> list[tuple]:
        """`[(key, label, value, unit, shown)]`: `value` goes to `Explorer.values[key]`; `shown` (or the value)
        to the display."""
        raise NotImplementedError

    def tables(self, r: dict) -> tuple:
        return ()

    def extra_controls(self, explorer: Any, w) -> list:
        """The scene's own controls beside the sliders (the four-bar's *tune PID* button), acting on `explorer` (the
        `Explorer` that shows the scene)."""
        return []


_PROGRAMS: dict = {}


def _program(name: str, impl: Callable):
    """The module's one jitted program for `name` (made on first use: JAX is imported by the first explorer)."""
    prog = _PROGRAMS.get(name)
    if prog is None:
        import jax

        prog = _PROGRAMS[name] = jax.jit(impl)
    return prog
