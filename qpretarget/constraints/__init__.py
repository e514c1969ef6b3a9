# SPDX-License-Identifier: Apache-2.0
"""Hard-constraint modules. Each registers itself under its YAML ``type:`` in :data:`CONSTRAINTS`."""

from . import acceleration_limits, contacts, support_polygon  # noqa: F401
from .base import CONSTRAINTS, Constraint, ConstraintBlock
from .joint_limits import JointLimits, VelocityLimits

__all__ = ["CONSTRAINTS", "Constraint", "ConstraintBlock", "JointLimits", "VelocityLimits"]
