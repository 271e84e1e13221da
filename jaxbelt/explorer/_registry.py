"""The scenes by name, their aliases, and the scene a start object belongs to."""

from __future__ import annotations

from ._axis import _Axis
from ._fourbar import _FourBar
from ._nonlinear import _Nonlinear
from ._scene import _Scene
from ._shaping import _Shaping
from ._spans import _Spans
from ._startup import _Startup

_SCENES: dict[str, type[_Scene]] = {
    "startup": _Startup,
    "fourbar": _FourBar,
    "shaping": _Shaping,
    "spans": _Spans,
    "nonlinear": _Nonlinear,
    "axis": _Axis,
}
_ALIASES = {
    "start-up": "startup",
    "four-bar": "fourbar",
    "platform": "shaping",
    "pseudo-polynomial": "shaping",
    "string": "spans",
    "belt_spans": "spans",
    "design_move": "axis",
    "shaping_axis": "axis",
}


def _scene_key(start) -> str:
    """The scene a start object belongs to."""
    from ..commands import ExponentialVoltage, PseudoPolynomial
    from ..models.axis import ModalAxis
    from ..models.fourbar import FourBarDrive
    from ..models.motor import PID
    from ..models.nonlinear import NonlinearBelt
    from ..models.platform import BeltPlatform
    from ..models.startup import BeltStartup
    from ..models.string import MovingString
    from ..scene import Scene

    kinds = (
        (BeltStartup, "startup"),
        (ExponentialVoltage, "startup"),
        (FourBarDrive, "fourbar"),
        (PID, "fourbar"),
        (BeltPlatform, "shaping"),
        (PseudoPolynomial, "shaping"),
        (MovingString, "spans"),
        (NonlinearBelt, "nonlinear"),
        (ModalAxis, "axis"),
    )
    probe = start.model if isinstance(start, Scene) else start
    for cls, key in kinds:
        if isinstance(probe, cls):
            return key
    names = ", ".join(sorted({c.__name__ for c, _ in kinds}))
    raise TypeError(
        f"explore: `scene_or_model` must be a scene name {sorted(_SCENES)}, a Scene, or one of {names}; "
        f"got {type(start).__name__}"
    )
