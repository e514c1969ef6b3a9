# SPDX-License-Identifier: Apache-2.0
"""Physics check of a retargeted run: replay it in MuJoCo, report whether the robot could do it.

``qpretarget evaluate RUN.npz --physics`` and ``qpretarget batch ... --physics`` (docs/physics.md).
:func:`~qpretarget.physics.model.build_physics_model` builds the MuJoCo model of the robot from
its URDF; :func:`~qpretarget.physics.replay.check_run` replays the run with joint PD tracking
(unassisted, then with a virtual root wrench) and :func:`~qpretarget.physics.metrics.summarize`
turns the per-frame series into the metrics. mujoco is the optional ``physics`` extra.
"""

from __future__ import annotations

from .gains import GAIN_PROFILES
from .metrics import FALL_HEIGHT_M, FALL_TILT_DEG, summarize
from .model import PhysicsModel, PhysicsModelError, build_physics_model
from .replay import PhysicsInputError, ReplaySeries, check_run, replay_run

__all__ = [
    "FALL_HEIGHT_M",
    "FALL_TILT_DEG",
    "GAIN_PROFILES",
    "PhysicsInputError",
    "PhysicsModel",
    "PhysicsModelError",
    "ReplaySeries",
    "build_physics_model",
    "check_run",
    "replay_run",
    "summarize",
]
