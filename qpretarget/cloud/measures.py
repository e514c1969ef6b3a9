# SPDX-License-Identifier: Apache-2.0
r"""Measures of a point-cloud run against the rendered truth (one definition: tests, bench, docs).

The *arm-direction error* compares the robot's command with the person it was fitted to: for each
upper arm (shoulder to elbow) and forearm (elbow to wrist), the angle between the segment of the
robot, the G1 itself at the run's configurations (fitted joints, primary sole flat on the floor:
what the robot is sent), and the same segment of the human model that was rendered,

.. math:: e = \arccos \frac{u_{robot}^\top u_{human}}{\|u_{robot}\| \|u_{human}\|}.

A fit whose feet are tilted or twisted shows here as a leaning or turned robot.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

if TYPE_CHECKING:
    from ..robot import RobotModel
    from .render import HumanPoser

#: Column order of :func:`arm_direction_errors`.
ARM_SEGMENTS: tuple[str, ...] = (
    "left_upper_arm",
    "left_forearm",
    "right_upper_arm",
    "right_forearm",
)


def arm_direction_errors(
    robot: RobotModel, q_robot: np.ndarray, poser: HumanPoser, q_human: np.ndarray
) -> np.ndarray:
    """(T, 4) angles [deg] between the robot's and the human model's arm segments.

    Args:
        robot: the robot (its ``keyframes`` name the shoulder, elbow and wrist frames).
        q_robot: (T, nq) robot configurations (the run file's ``q``).
        poser: the :class:`~qpretarget.cloud.render.HumanPoser` that posed the rendered model.
        q_human: (T, nq_h) configurations of the rendered human model (``SyntheticSequence.q``).

    Returns:
        Columns :data:`ARM_SEGMENTS`: left upper arm, left forearm, right upper arm, right
        forearm.
    """
    model = robot.model
    data = model.createData()
    keys = ("shoulder", "elbow", "wrist")
    out = np.empty((len(q_robot), 4))
    for k, q in enumerate(np.asarray(q_robot, float)):
        human = poser.model_keypoints(q_human[k])
        pin.framesForwardKinematics(model, data, q)
        col = 0
        for side in ("left", "right"):
            rob = {
                n: data.oMf[model.getFrameId(robot.keyframes[f"{side}_{n}"])].translation
                for n in keys
            }
            for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
                u, v = rob[b] - rob[a], human[f"{side}_{b}"] - human[f"{side}_{a}"]
                c = u @ v / (np.linalg.norm(u) * np.linalg.norm(v))
                out[k, col] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
                col += 1
    return out


def longest_run_above(errors: np.ndarray, t: np.ndarray, threshold: float) -> float:
    """Longest time [s] the worst segment of consecutive frames stays above ``threshold`` [deg].

    A run of frames k..l above it lasts ``t[l] - t[k]`` plus one frame period (a single frame
    counts one period). ``errors``: (T, 4) from :func:`arm_direction_errors`; ``t``: (T,) [s].
    """
    above = np.asarray(errors).max(axis=1) > threshold
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    best, start = 0.0, None
    for k, a in enumerate(above):
        if a and start is None:
            start = k
        if start is not None and (not a or k == len(above) - 1):
            end = k if a else k - 1
            best = max(best, float(t[end] - t[start]) + dt)
            start = None
    return best


__all__ = ["ARM_SEGMENTS", "arm_direction_errors", "longest_run_above"]
