# SPDX-License-Identifier: Apache-2.0
"""qpretarget: online human-to-humanoid motion retargeting as a QP whole-body controller."""

from .control.controller import Controller, StepResult
from .errors import ConfigError, QPRetargetError, SolverError, TargetError, UnknownFrameError
from .robot import RobotModel, load_robot
from .robots import ROBOTS

__version__ = "0.1.0"

__all__ = [
    "Controller",
    "StepResult",
    "RobotModel",
    "load_robot",
    "ROBOTS",
    "QPRetargetError",
    "ConfigError",
    "TargetError",
    "SolverError",
    "UnknownFrameError",
    "__version__",
]
