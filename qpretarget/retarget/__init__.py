# SPDX-License-Identifier: Apache-2.0
"""Retargeting human motion to a robot, offline and online, around :class:`Retargeter`."""

from .retargeter import Retargeter, RetargetError, RetargetSpec, retarget_motion, whole_body_config

__all__ = ["Retargeter", "RetargetError", "RetargetSpec", "retarget_motion", "whole_body_config"]
