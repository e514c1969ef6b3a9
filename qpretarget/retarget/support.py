# SPDX-License-Identifier: Apache-2.0
r"""Robot side of the support phases: soles, swing-foot poses and the CoM estimate.

:class:`FootSupport` holds what the support sequences of Poubel 2014 Table I
(:class:`~qpretarget.motion.phases.SupportSequencer`) need from the robot: each sole's frame and
reference pose, the ankle-to-sole offset, the sole-to-task transform of the foot tasks, the sole
rectangles and the landing area derived from the stance width and leg length.
:class:`ComEstimate` gives the horizontal CoM the scaled person would give the robot, from
key-point displacements weighted by :data:`COM_WEIGHTS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..motion.calibration import Calibration, yaw_of
from ..motion.keypoints import KeypointMap
from ..motion.phases import SupportSequencer
from .spec import SupportSpec

#: Share of the body's mass carried by each key-point in the estimate of the CoM the scaled person
#: would give the robot (trunk-heavy, roughly Winter's segment masses lumped on the nearest
#: key-point); only its horizontal displacement is used.
COM_WEIGHTS = {
    "waist": 0.45, "neck": 0.2, "head": 0.07, "left_shoulder": 0.04, "right_shoulder": 0.04,
    "left_elbow": 0.02, "right_elbow": 0.02, "left_hip": 0.05, "right_hip": 0.05,
    "left_knee": 0.03, "right_knee": 0.03,
}  # fmt: skip

#: Key-points a balance shift never moves (the feet stay where the sequences put them).
FOOT_POINTS = frozenset(
    f"{side}_{p}" for side in ("left", "right") for p in ("ankle", "toe", "heel")
)


def rot_z(angle: float) -> np.ndarray:
    """Rotation about the vertical axis by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class FootSupport:
    """The robot's soles for the support sequences of one controller.

    Args:
        spec: The ``retarget.support`` section.
        contacts: The controller's ``contacts`` constraint.
        data: Pinocchio data with the frames placed at the reference posture.
        robot_points: Robot key-points at the reference posture.
        task_reference: task -> ``(p, R)`` at the reference posture.
        unheading: Rotation undoing the robot waist's reference yaw.
        leg_lengths: side -> hip-to-ankle length at full extension [m].

    Raises:
        ConfigError: A foot without an ankle key-point on the robot.
    """

    def __init__(
        self,
        spec: SupportSpec,
        contacts: Any,
        data: pin.Data,
        robot_points: Mapping[str, np.ndarray],
        task_reference: Mapping[str, tuple[np.ndarray, np.ndarray]],
        unheading: np.ndarray,
        leg_lengths: Mapping[str, float],
    ) -> None:
        self.spec = spec
        self.sole_ids: dict[str, int] = {}
        self.sole_ref: dict[str, pin.SE3] = {}
        self.ankle_to_sole: dict[str, np.ndarray] = {}
        self.sole_to_task: dict[str, pin.SE3] = {}
        rects: dict[str, tuple[float, float, float, float]] = {}
        for side, fb in spec.feet.items():
            i = contacts.names.index(fb.contact)
            fid = contacts.frame_ids[i]
            self.sole_ids[side] = fid
            M = data.oMf[fid].copy()
            self.sole_ref[side] = M
            ankle = robot_points.get(f"{side}_ankle")
            if ankle is None:
                raise ConfigError(
                    f"support phases need the {side}_ankle key-point on the robot; add it "
                    "under retarget.robot_keypoints.",
                    path="retarget.support",
                )
            self.ankle_to_sole[side] = M.rotation.T @ (M.translation - ankle)
            p, R = task_reference[fb.task]
            self.sole_to_task[side] = M.inverse() * pin.SE3(R, p)
            rect = contacts.rectangles[i]
            rects[side] = (-0.02, 0.02, -0.02, 0.02) if rect is None else tuple(rect)
        self.sole_rectangles = rects
        # Landing area defaults from the stance width and the leg length.
        seq = spec.sequence
        d = self.sole_ref["left"].translation - self.sole_ref["right"].translation
        width = float(abs(unheading[1] @ d))
        leg = min(leg_lengths.values()) if leg_lengths else 1.0
        self.sequence_settings = replace(
            seq,
            min_width=seq.min_width if seq.min_width is not None else 0.8 * width,
            max_width=seq.max_width if seq.max_width is not None else 1.1 * width,
            max_stride=seq.max_stride if seq.max_stride is not None else 0.25 * leg,
        )

    def toe_geometry(self) -> dict[str, tuple[float, np.ndarray]]:
        """Per side, the front edge x of the sole rectangle and the ankle, in the sole frame."""
        return {
            side: (float(rect[1]), -self.ankle_to_sole[side])
            for side, rect in self.sole_rectangles.items()
        }

    def sequencer(self, dt: float) -> SupportSequencer:
        """A fresh :class:`SupportSequencer` for a run at period ``dt`` [s]."""
        return SupportSequencer(self.sole_rectangles, self.sequence_settings, dt=dt)

    def ankle_of(self, side: str, sole: pin.SE3) -> np.ndarray:
        """Robot ankle position of a sole pose."""
        return sole.act(-self.ankle_to_sole[side])

    def swing_sole(
        self,
        side: str,
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        calibration: Calibration,
        current: pin.SE3,
        waist_dyaw: Callable[[], float],
    ) -> pin.SE3:
        """Desired sole pose of a foot from the scaled ankle, flat, yaw from the human foot.

        The yaw is the human foot's (ankle -> toe) change since calibration, or the waist's
        (``waist_dyaw()``) when the motion has no toes.
        """
        ankle = scaled.get(f"{side}_ankle")
        if ankle is None or not np.all(np.isfinite(ankle)):
            return current.copy()
        toe = kp.get(f"{side}_toe")
        a = kp.get(f"{side}_ankle")
        if toe is not None and a is not None and side in calibration.human_foot_yaw:
            dpsi = yaw_of(toe - a) - calibration.human_foot_yaw[side]
        else:
            dpsi = waist_dyaw()
        R = rot_z(dpsi) @ self.sole_ref[side].rotation
        return pin.SE3(R, ankle + R @ self.ankle_to_sole[side])


class ComEstimate:
    """The horizontal CoM the scaled person would give the robot (:data:`COM_WEIGHTS`).

    Args:
        robot_map: The robot's key-point map.
        robot_points: Robot key-points at the reference posture.
        point_ids: key-point -> robot frame ids.
        com_reference: Robot CoM at the reference posture ``(3,)``.
    """

    def __init__(
        self,
        robot_map: KeypointMap,
        robot_points: Mapping[str, np.ndarray],
        point_ids: Mapping[str, list[int]],
        com_reference: np.ndarray,
    ) -> None:
        self.robot_map = robot_map
        self.point_ids = dict(point_ids)
        self.com_reference = com_reference
        weights = {k: w for k, w in COM_WEIGHTS.items() if k in robot_points}
        total = sum(weights.values())
        self.weights = {k: w / total for k, w in weights.items()} if total > 0 else {}
        self._w = np.array(list(self.weights.values()))
        self._ref_xy = sum((w * robot_points[k][:2] for k, w in self.weights.items()), np.zeros(2))

    def predicted(
        self, scaled: Mapping[str, np.ndarray], com: np.ndarray, data: pin.Data
    ) -> np.ndarray | None:
        r"""Horizontal CoM of the robot once its key-points reach the scaled ones, to first order.

        :math:`c + \sum_k w_k (s_k - x_k(q))` with :math:`x_k(q)` the robot's key-points now
        (:data:`COM_WEIGHTS`); equal to the current CoM when the targets are reached, so in double
        support the CoM target never pulls against the other tasks.
        """
        S = self.weighted_xy(scaled)
        if S is None:
            return None
        X = sum(w * self.robot_point(k, data)[:2] for k, w in self.weights.items())
        return np.asarray(com, float)[:2] + S - X

    def natural(self, scaled: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """Horizontal CoM the scaled person would give the robot.

        The robot's reference CoM moved by the weighted key-point displacements from the
        reference posture (:data:`COM_WEIGHTS`).
        """
        S = self.weighted_xy(scaled)
        if S is None:
            return None
        return self.com_reference[:2] + S - self._ref_xy

    def weighted_xy(self, points: Mapping[str, np.ndarray]) -> np.ndarray | None:
        r""":math:`\sum_k w_k p_{k,xy}` over :data:`COM_WEIGHTS` (``None`` if one is missing)."""
        if not self.weights:
            return None
        try:
            P = np.array([points[k][:2] for k in self.weights])
        except KeyError:
            return None
        if not np.all(np.isfinite(P)):
            return None
        return self._w @ P

    def robot_point(self, name: str, data: pin.Data) -> np.ndarray:
        """A robot key-point from placed frames (mean of its frames, plus its offset)."""
        src = self.robot_map.keypoints[name]
        ids = self.point_ids[name]
        p = data.oMf[ids[0]].translation.copy()
        for i in ids[1:]:
            p += data.oMf[i].translation
        p /= len(ids)
        if src.offset is not None:
            p = p + data.oMf[ids[0]].rotation @ np.asarray(src.offset)
        return p


__all__ = ["COM_WEIGHTS", "FOOT_POINTS", "ComEstimate", "FootSupport", "rot_z"]
