"""Physical models, one module per system (see each module for its source paper)."""

from .base import AbstractModel as AbstractModel
from .startup import BeltChain as BeltChain
from .startup import BeltStartup as BeltStartup
from .startup import chain_matrices as chain_matrices
from .fourbar import FourBarDrive as FourBarDrive
from .motor import PID as PID
