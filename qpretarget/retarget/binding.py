# SPDX-License-Identifier: Apache-2.0
r"""Key-point binding: the robot's key-points and the task targets built from scaled ones.

:class:`RobotBinding` measures, once per controller, the robot's key-points at its reference
posture (``retarget.robot_keypoints`` over the registry key-frames), each task's reference pose
and its offset from its key-point, the reference CoM and the leg lengths.
:meth:`RobotBinding.task_targets` turns one sample of scaled key-points and human orientations
into the targets of the tasks named in ``retarget.tasks``:

.. math::

    p_t = s_k + R_t R_{ref}^\top o, \qquad R_t = R_a R_h R_z(-\psi_r) R_{ref},

with :math:`s_k` the scaled key-point, :math:`o` the reference offset, :math:`R_a` the
calibration's heading rotation, :math:`R_h` the person's orientation and :math:`\psi_r` the
robot waist's reference yaw; both blend in from the reference pose over ``calibration.ramp_time``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from ..control.controller import Controller
from ..errors import ConfigError
from ..motion.calibration import Calibration, nearest_rotation, triad, yaw_of
from ..motion.keypoints import KeypointMap, KeypointMapError
from ..motion.phases import SIDES
from ..tasks.frame import FrameTask
from .spec import ORIENTATIONS, RetargetSpec, default_robot_keypoints
from .support import rot_z


def pose_matrix(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Homogeneous 4x4 matrix of a rotation and a position."""
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = p
    return M


class RobotBinding:
    """The robot side of the key-point binding (measured at the reference posture).

    Args:
        controller: The controller (reset once to its reference posture).
        spec: The validated ``retarget:`` section.

    Raises:
        ConfigError: A robot key-point with an unknown frame, or a task key-point the robot has
            no frame for.
    """

    def __init__(self, controller: Controller, spec: RetargetSpec) -> None:
        self.spec = spec
        ctrl = controller
        robot = ctrl.robot
        entries = default_robot_keypoints(robot)
        entries.update(spec.robot_keypoints)
        try:
            self.robot_map = KeypointMap.from_dict(
                {"name": f"{robot.name}_keypoints", "kind": "robot", "keypoints": entries},
                path="retarget.robot_keypoints",
            )
        except KeypointMapError as exc:
            raise ConfigError(str(exc)) from None
        for kp, src in self.robot_map.keypoints.items():
            for frame in src.points:
                robot.frame_id(frame, path=f"retarget.robot_keypoints.{kp}")
        model = robot.model
        data = model.createData()
        q_ref = robot.q_reference
        pin.framesForwardKinematics(model, data, q_ref)
        #: Frames placed at the reference posture.
        self.data = data

        def placement(name: str) -> pin.SE3:
            return data.oMf[robot.frame_id(name)]

        self.robot_points: dict[str, np.ndarray] = self.robot_map.evaluate(
            lambda f: placement(f).translation.copy(), lambda f: placement(f).rotation.copy()
        )
        waist_src = self.robot_map.keypoints.get("waist")
        self.robot_waist_rotation = (
            placement(waist_src.points[0]).rotation.copy() if waist_src is not None else None
        )
        for name, b in spec.tasks.items():
            if b.keypoint is not None and b.keypoint not in self.robot_points:
                raise ConfigError(
                    f"key-point {b.keypoint!r} has no robot frame; add it under "
                    f"retarget.robot_keypoints (robot key-points: {sorted(self.robot_points)}).",
                    path=f"retarget.tasks.{name}.keypoint",
                )
        # Task reference poses (reset the controller to its reference posture once).
        ctrl.reset()
        self.task_reference: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, task in ctrl.tasks.items():
            if isinstance(task, FrameTask):
                p, R = task.current_pose(ctrl.state)
                self.task_reference[name] = (p.copy(), R.copy())
        self.task_offsets: dict[str, np.ndarray] = {}
        for name, b in spec.tasks.items():
            if b.keypoint is None:
                continue
            if b.offset is not None:
                self.task_offsets[name] = np.asarray(b.offset, float)
            else:
                self.task_offsets[name] = (
                    self.task_reference[name][0] - self.robot_points[b.keypoint]
                )
        self.com_reference = np.array(pin.centerOfMass(model, data, q_ref))
        self.point_ids = {
            k: [robot.frame_id(f) for f in src.points]
            for k, src in self.robot_map.keypoints.items()
        }
        psi_r = (
            yaw_of(self.robot_waist_rotation[:, 0])
            if self.robot_waist_rotation is not None
            else 0.0
        )
        self.unheading = rot_z(-psi_r)
        pts = self.robot_points
        #: side -> hip-to-ankle length at full extension (thigh + shank) [m].
        self.leg_lengths: dict[str, float] = {
            side: float(
                np.linalg.norm(pts[f"{side}_knee"] - pts[f"{side}_hip"])
                + np.linalg.norm(pts[f"{side}_ankle"] - pts[f"{side}_knee"])
            )
            for side in SIDES
            if all(f"{side}_{p}" in pts for p in ("hip", "knee", "ankle"))
        }

    def task_targets(
        self,
        targets: dict[str, Any],
        calibration: Calibration,
        reference: Mapping[str, tuple[np.ndarray, np.ndarray]],
        ramp: float,
        skipped: list[str],
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        rots: Mapping[str, np.ndarray],
        missing: Mapping[str, bool],
        first: dict[str, tuple[np.ndarray | None, np.ndarray | None]] | None = None,
        start: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    ) -> None:
        """Write the targets of the bound tasks into ``targets`` (see the module docstring).

        ``reference``: each task's pose at the robot's reference posture, :math:`R_{ref}` of
        the module docstring. ``start``: the pose the start ramp begins from (default:
        ``reference``; the person's first-sample stance when the run starts there). They are
        not the same: a person whose pelvis is pitched 21 deg at the first sample (CMU 49_18)
        gets a robot pelvis pitched 21 deg at the start, and taking that pose as
        :math:`R_{ref}` too applied the person's pitch twice (the robot's pelvis 20 deg forward
        of the person's through the whole clip).

        A pose task whose orientation (or position) is missing keeps tracking the other half;
        a missing half keeps its last target. With ``first`` (a dict filled on the first call),
        the start ramp blends out the offset between the start pose and the first target
        instead of the target itself: the person's motion is followed from the first sample
        (a clip that starts walking keeps its first steps' travel).
        """
        start = reference if start is None else start
        cal = calibration
        orient: dict[str, np.ndarray] = {}
        for name in {b.orientation for b in self.spec.tasks.values() if b.orientation}:
            R = human_orientation(name, kp, rots)
            if R is not None:
                orient[name] = R
        parents = cal.tree
        for name, b in self.spec.tasks.items():
            if name in skipped:
                continue
            R_ref = reference[name][1]
            p_s, R_s = start[name]
            R_t = None
            if b.orientation is not None:
                Rh = orient.get(b.orientation)
                if Rh is None:
                    R_t = np.full((3, 3), np.nan)
                else:
                    R_t = cal.rotation @ Rh @ self.unheading @ R_ref
                    if first is not None:
                        R0 = first.setdefault(name, (None, R_t.copy()))[1]
                        if ramp < 1.0 and R0 is not None:
                            R_t = pin.exp3((1.0 - ramp) * pin.log3(R_s @ R0.T)) @ R_t
                    elif ramp < 1.0:
                        R_t = R_s @ pin.exp3(ramp * pin.log3(R_s.T @ R_t))
            p_t = None
            if b.keypoint is not None:
                k = b.keypoint
                parent = parents.get(k)
                gone = missing.get(k, True) or (parent is not None and missing.get(parent, False))
                if gone or k not in scaled:
                    p_t = np.full(3, np.nan)
                else:
                    off = self.task_offsets[name]
                    if R_t is not None and np.all(np.isfinite(R_t)):
                        off = R_t @ R_ref.T @ off
                    p_t = scaled[k] + off
                    if first is not None:
                        p0: np.ndarray | None = None
                        entry = first.get(f"{name}/p")
                        if entry is None:
                            first[f"{name}/p"] = (p_t.copy(), None)
                            p0 = p_t
                        else:
                            p0 = entry[0]
                        if ramp < 1.0 and p0 is not None:
                            p_t = p_t + (1.0 - ramp) * (p_s - p0)
                    elif ramp < 1.0:
                        p_t = p_s + ramp * (p_t - p_s)
            p_ok = p_t is not None and bool(np.all(np.isfinite(p_t)))
            R_ok = R_t is not None and bool(np.all(np.isfinite(R_t)))
            if p_ok and R_ok and R_t is not None and p_t is not None:
                targets[name] = pose_matrix(R_t, p_t)
            elif p_ok or (p_t is not None and not R_ok):
                targets[name] = p_t
            else:
                targets[name] = R_t


def human_orientation(
    name: str, kp: Mapping[str, np.ndarray], rots: Mapping[str, np.ndarray]
) -> np.ndarray | None:
    """The person's orientation ``name`` (``waist``/``torso``/``head``) in one sample.

    From the motion's joint orientations when it has them, else a frame built from key-points
    (:func:`~qpretarget.motion.calibration.triad`); ``head`` falls back to ``torso``.
    """
    if name in rots:
        R = rots[name]
        return nearest_rotation(R) if np.all(np.isfinite(R)) else None
    pts = ORIENTATIONS.get(name)
    if pts is None and name == "head":
        return human_orientation("torso", kp, rots)
    if pts is None or not all(p in kp for p in pts):
        return None
    R = triad(kp[pts[0]], kp[pts[1]], kp[pts[2]], kp[pts[3]])
    return R if np.all(np.isfinite(R)) else None


def waist_yaw(kp: Mapping[str, np.ndarray], rots: Mapping[str, np.ndarray]) -> float:
    """Yaw of the person's waist [rad]: its orientation's x axis, else normal to the hip line."""
    if "waist" in rots:
        return yaw_of(rots["waist"][:, 0])
    if "left_hip" in kp and "right_hip" in kp:
        y = kp["left_hip"] - kp["right_hip"]
        return yaw_of(np.cross(y, [0.0, 0.0, 1.0]))
    return 0.0


__all__ = ["RobotBinding", "human_orientation", "pose_matrix", "waist_yaw"]
