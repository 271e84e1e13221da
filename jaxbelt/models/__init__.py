"""Physical models, one module per system (see each module for its source paper)."""

import typing as _typing

if _typing.TYPE_CHECKING:  # the public names, imported on first use (`jaxbelt._lazy`)
    from .axis import ModalAxis as ModalAxis
    from .contact import BeltPulleyContact as BeltPulleyContact
    from .contact import SlipError as SlipError
    from .contact import SlipReport as SlipReport
    from .fourbar import FourBarDrive as FourBarDrive
    from .motor import PID as PID
    from .nonlinear import NonlinearBelt as NonlinearBelt
    from .nonlinear import RunningSpeed as RunningSpeed
    from .platform import BeltPlatform as BeltPlatform
    from .startup import BeltChain as BeltChain
    from .startup import BeltStartup as BeltStartup
    from .startup import chain_matrices as chain_matrices
    from .string import MovingString as MovingString
    from .string import RunoutRig as RunoutRig
    from .string import crossing_diagram as crossing_diagram
    from .string import crossing_speeds as crossing_speeds
    from .string import exciting_speeds as exciting_speeds
    from .string import galerkin_runout_system as galerkin_runout_system
    from .string import linear_runout_response as linear_runout_response
    from .string import runout_phasors as runout_phasors
    from .string import simulate_runout_response as simulate_runout_response

from .._lazy import attach as _attach  # noqa: E402

__getattr__, __dir__, __all__ = _attach(__name__, __file__)
