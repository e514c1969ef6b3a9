# SPDX-License-Identifier: Apache-2.0
r"""Frame task: position, orientation or full pose of a robot frame (a key-point).

Position error :math:`e_p = p_r - p`, with :math:`p = p_f + R_f o` the point at offset :math:`o`
in the frame; orientation error of Dariush 2009 eq. 11 (CRAC eq. 12),

.. math:: e_o = \tfrac12 (n \times n_r + s \times s_r + a \times a_r),

where :math:`R = [n\ s\ a]` is the frame's world rotation and :math:`R_r = [n_r\ s_r\ a_r]` the
target's. Jacobians are the LOCAL_WORLD_ALIGNED frame Jacobian's rows: linear rows
:math:`J_v - [R o]_\times J_\omega` for the position, angular rows :math:`J_\omega` for the
orientation.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from ..validation import weight_vector
from .base import TASKS, Task

_MODES = ("position", "orientation", "pose")


def orientation_error(R: np.ndarray, R_ref: np.ndarray) -> np.ndarray:
    r"""Dariush 2009 eq. 11: :math:`\tfrac12 \sum_k R_{:,k} \times R_{r,:,k}` (3,).

    Computed as :math:`\tfrac12 \operatorname{vee}(R_r R^\top - R R_r^\top)`, the same sum.
    """
    M = R_ref @ R.T
    return 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])


def _is_rotation(R: np.ndarray) -> bool:
    r"""``R'R = I`` and ``det R = 1`` to 1e-3 (cheap enough for every tick).

    The entries of :math:`R^\top R - I` are the columns' dot products minus the identity,
    computed on Python floats (faster than numpy for a 3x3).
    """
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    tol = 1e-3
    if not (
        abs(a * a + d * d + g * g - 1.0) < tol
        and abs(b * b + e * e + h * h - 1.0) < tol
        and abs(c * c + f * f + i * i - 1.0) < tol
        and abs(a * b + d * e + g * h) < tol
        and abs(a * c + d * f + g * i) < tol
        and abs(b * c + e * f + h * i) < tol
    ):
        return False
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return abs(det - 1.0) < tol


def skew(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix with ``skew(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@TASKS.register("frame")
class FrameTask(Task):
    """Track the position and/or orientation of a robot frame.

    Args:
        name: task name (key of its target in ``step``).
        frame: robot frame name, or a key-point name of the robot (``left_hand``).
        mode: ``position``, ``orientation`` or ``pose``.
        position_weight: weight of the position rows [cost]/[m]^2 (scalar or 3 values).
        orientation_weight: weight of the orientation rows [cost]/[rad]^2 (scalar or 3 values).
        offset: point in the frame that is tracked [m] (default: the frame origin).
        weight: overall weight multiplying both.
        **kwargs: ``gain``, ``level``, ``feedforward``, ``recovery_time`` of :class:`Task`.
    """

    drift_kind: ClassVar[str] = "analytic"
    target_attributes: ClassVar[tuple[str, ...]] = ("position_target", "rotation_target")

    def __init__(
        self,
        name: str,
        frame: str,
        *,
        mode: str = "pose",
        position_weight: Any = 1.0,
        orientation_weight: Any = 1.0,
        offset: Any = None,
        weight: Any = 1.0,
        gain: float | None = None,
        level: int = 1,
        feedforward: bool = False,
        recovery_time: float = 0.2,
    ) -> None:
        super().__init__(
            name, weight=weight, gain=gain, level=level, feedforward=feedforward,
            recovery_time=recovery_time,
        )  # fmt: skip
        if mode not in _MODES:
            raise ConfigError(f"mode must be one of {', '.join(_MODES)}, got {mode!r}.")
        self.frame = frame
        self.mode = mode
        self.has_position = mode in ("position", "pose")
        self.has_orientation = mode in ("orientation", "pose")
        self.dim = 3 * (int(self.has_position) + int(self.has_orientation))
        self.position_weight = weight_vector(position_weight, 3, "position_weight")
        self.orientation_weight = weight_vector(orientation_weight, 3, "orientation_weight")
        self.offset = None if offset is None else np.asarray(offset, dtype=float)
        if self.offset is not None and (
            self.offset.shape != (3,) or not np.all(np.isfinite(self.offset))
        ):
            raise ConfigError(f"offset must be 3 finite numbers [m], got {offset!r}.")
        self.frame_id = -1
        self.position_target = np.zeros(3)
        self.rotation_target = np.eye(3)

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        self.frame_id = robot.frame_id(self.frame, path=f"{path}.frame" if path else "frame")
        super().bind(robot, path=path)
        parts = []
        if self.has_position:
            parts.append(self.position_weight)
        if self.has_orientation:
            parts.append(self.orientation_weight)
        self.weight = self.weight * np.concatenate(parts)

    def compile_into(self, tick: Any, row: int) -> bool:
        """Compiled error and Jacobian (the same eq. 11 error; no feed-forward in the kernel)."""
        if self.feedforward:
            return False
        off = np.zeros(3) if self.offset is None else np.ascontiguousarray(self.offset)
        mode = {"position": 0, "orientation": 1, "pose": 2}[self.mode]
        tick.add_frame_task(
            self, row, self.frame_id, mode, off, self.offset is not None, self._kernel_gain()
        )
        return True

    # ------------------------------------------------------------------ state
    def current_pose(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """World position of the tracked point and world rotation of the frame."""
        M = state.data.oMf[self.frame_id]
        R = M.rotation
        p = M.translation if self.offset is None else M.translation + R @ self.offset
        return p, R

    def reset(self, state: RobotState) -> None:
        super().reset(state)
        p, R = self.current_pose(state)
        self.position_target = p.copy()
        self.rotation_target = R.copy()

    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        """Set the target from a 3-vector, 3x3 rotation, 4x4 transform or ``pinocchio.SE3``.

        A 3-vector given to a pose task moves its position target only; a rotation, its
        orientation target only.

        Returns:
            ``False`` when the target holds NaN/inf (missing data): the last target is kept.

        Raises:
            TargetError: on a wrong shape or type, on a rotation given to a position-only task
                (or a position to an orientation-only task), on a matrix that is not a rotation.
        """
        if type(target) is np.ndarray and target.shape == (3,) and self.has_position:
            # Fast path: a position array (the common case in a 100 Hz loop); a NaN or inf
            # anywhere makes the sum non-finite.
            if not math.isfinite(sum(target.tolist())):
                return False
            self.position_target = target.astype(float, copy=True)
            return True
        position = rotation = None
        if type(target) is np.ndarray and target.dtype == np.float64 and target.ndim == 2:
            # Fast path: a 4x4 transform or 3x3 rotation array (a 100 Hz loop's other case).
            if target.shape == (4, 4):
                position, rotation = target[:3, 3].copy(), target[:3, :3].copy()
            elif target.shape == (3, 3):
                rotation = target.copy()
        if position is not None or rotation is not None:
            pass
        elif isinstance(target, pin.SE3):
            position, rotation = target.translation.copy(), target.rotation.copy()
        else:
            arr = self.target_array(
                target,
                tick,
                "target must be a 3-vector, 3x3 rotation, 4x4 transform or pinocchio.SE3",
            )
            if arr.shape == (3,):
                position = arr
            elif arr.shape == (3, 3):
                rotation = arr
            elif arr.shape == (4, 4):
                position, rotation = arr[:3, 3].copy(), arr[:3, :3].copy()
            else:
                raise self.target_error(
                    f"target must be a 3-vector (position), a 3x3 rotation, a 4x4 transform or a "
                    f"pinocchio.SE3, got shape {arr.shape}.",
                    tick,
                )
        if position is not None and rotation is None and not self.has_position:
            raise self.target_error(
                "a position was given to an orientation-only task (mode: orientation).", tick
            )
        if rotation is not None and position is None and not self.has_orientation:
            raise self.target_error(
                "a rotation was given to a position-only task (mode: position).", tick
            )
        for x in (position, rotation):
            if x is not None and not math.isfinite(sum(x.ravel().tolist())):
                return False  # a NaN or inf anywhere makes the sum non-finite
        if rotation is not None and not _is_rotation(rotation):
            raise self.target_error(
                "rotation target is not a rotation matrix (R'R != I or det(R) != 1).", tick
            )
        if position is not None and self.has_position:
            self.position_target = position
        if rotation is not None and self.has_orientation:
            self.rotation_target = rotation
        return True

    # ------------------------------------------------------------------ maths
    def compute_error(self, state: RobotState) -> np.ndarray:
        M = state.data.oMf[self.frame_id]
        if self.offset is None and self.mode == "position":
            return self.position_target - M.translation
        R = M.rotation
        if self.mode == "orientation":
            return orientation_error(R, self.rotation_target)
        p = M.translation if self.offset is None else M.translation + R @ self.offset
        if self.mode == "position":
            return self.position_target - p
        e = np.empty(6)
        np.subtract(self.position_target, p, out=e[:3])
        e[3:] = orientation_error(R, self.rotation_target)
        return e

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        J6 = state.frame_jacobian(self.frame_id)
        if self.offset is None:
            if self.mode == "position":
                return J6[:3]
            if self.mode == "orientation":
                return J6[3:]
            return J6  # rows [linear; angular], the order of compute_error
        R = state.data.oMf[self.frame_id].rotation
        Jp = J6[:3] - skew(R @ self.offset) @ J6[3:]
        if self.mode == "position":
            return Jp
        if self.mode == "orientation":
            return J6[3:]
        return np.vstack([Jp, J6[3:]])

    def compute_jdot_v(self, state: RobotState) -> np.ndarray:
        r"""Classical acceleration :math:`\dot J v` of the frame.

        Needs ``forwardKinematics(model, data, q, v, 0)`` first.
        """
        a = pin.getFrameClassicalAcceleration(
            state.model, state.data, self.frame_id, pin.LOCAL_WORLD_ALIGNED
        )
        parts = []
        if self.has_position:
            lin = a.linear
            if self.offset is not None:
                w = pin.getFrameVelocity(
                    state.model, state.data, self.frame_id, pin.LOCAL_WORLD_ALIGNED
                ).angular
                r = state.frame_placement(self.frame_id).rotation @ self.offset
                lin = lin + np.cross(a.angular, r) + np.cross(w, np.cross(w, r))
            parts.append(lin)
        if self.has_orientation:
            parts.append(a.angular)
        return np.concatenate(parts)

    def error_norm(self, error: np.ndarray) -> float:
        """Position error norm [m] for position/pose tasks, orientation error norm [rad] else."""
        e = error[:3]
        return float(np.sqrt(e @ e))

    def __repr__(self) -> str:
        return (
            f"FrameTask(frame={self.frame!r}, mode={self.mode!r}, "
            f"position_weight={self.position_weight.tolist()}, "
            f"orientation_weight={self.orientation_weight.tolist()}, name={self.name!r}, "
            f"gain={self.gain!r}, level={self.level})"
        )
