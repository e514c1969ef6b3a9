# SPDX-License-Identifier: Apache-2.0
"""Retargeting human motion to a robot, offline and online, around :class:`Retargeter`.

Modules: ``spec`` (the validated ``retarget:`` section), ``binding`` (robot key-points, task
targets), ``stream`` (key-points, filter, spline; the per-tick :class:`Command`), ``support``
(soles, swing feet, CoM estimate for the support phases), ``record`` (per-tick records and the
run's trajectory), ``retargeter`` (the :class:`Retargeter` pipeline), ``whole_body``
(:func:`whole_body_config`), ``summary`` (the run summary), ``timing`` and ``shape``.
"""

from .retargeter import Retargeter, RetargetError, RetargetSpec, retarget_motion, whole_body_config

__all__ = ["Retargeter", "RetargetError", "RetargetSpec", "retarget_motion", "whole_body_config"]
