# SPDX-License-Identifier: Apache-2.0
"""Hard-constraint modules, registered under their YAML ``type:`` in :data:`CONSTRAINTS`."""

from . import acceleration_limits, contacts, support_polygon  # noqa: F401
from .base import CONSTRAINTS, Constraint, ConstraintBlock
from .ground import Ground  # noqa: F401
from .joint_limits import JointLimits, VelocityLimits
from .self_collision import SelfCollision  # noqa: F401

__all__ = ["CONSTRAINTS", "Constraint", "ConstraintBlock", "JointLimits", "VelocityLimits"]
