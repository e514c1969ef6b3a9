# SPDX-License-Identifier: Apache-2.0
r"""Posture task: actuated joints towards a reference posture, :math:`e = (q_r \ominus q)_{act}`.

Its Jacobian selects the actuated velocity coordinates, :math:`J = [0\ I]`. With a small weight it
is the usual posture regularization that resolves the redundancy of the key-point tasks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ..robot import RobotModel, RobotState
from .base import TASKS, Task


@TASKS.register("posture")
class PostureTask(Task):
    """Pull the joints towards a posture (the robot's reference standing posture by default).

    Args:
        name: task name.
        weight: scalar, or a mapping joint name -> weight (others get ``default_weight``).
        default_weight: weight of joints not named when ``weight`` is a mapping.
        **kwargs: ``gain``, ``level``, ``recovery_time`` of :class:`Task`.

    Targets accepted by ``step``: a full configuration (nq,), the actuated joint values
    (n_joints,), or a mapping joint name -> value [rad] (other joints keep their target).
    """

    drift_kind: ClassVar[str] = "zero"

    def __init__(
        self,
        name: str = "posture",
        *,
        weight: Any = 1.0,
        default_weight: float = 1.0,
        gain: float | None = None,
        level: int = 1,
        recovery_time: float = 0.2,
    ) -> None:
        self._joint_weights = dict(weight) if isinstance(weight, Mapping) else None
        super().__init__(
            name, weight=1.0 if self._joint_weights is not None else weight, gain=gain,
            level=level, recovery_time=recovery_time,
        )  # fmt: skip
        self.default_weight = float(default_weight)
        self.q_target: np.ndarray | None = None  # set by bind
        self._root_nv = 0  # velocity coordinates of the free-flyer, set by bind

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        self.dim = robot.nv - robot.root_nv
        super().bind(robot, path=path)
        self._root_nv = robot.root_nv
        if self._joint_weights is not None:
            w = np.full(self.dim, self.default_weight)
            for jname, wj in self._joint_weights.items():
                j = robot.joint_index(jname, path=f"{path}.weight.{jname}")
                w[robot.joint_v_index[j] - robot.root_nv] = float(wj)
            self.weight = w
        self.q_target = robot.q_reference.copy()
        self._J = np.zeros((self.dim, robot.nv))
        self._J[:, robot.root_nv :] = np.eye(self.dim)

    def reset(self, state: RobotState) -> None:
        super().reset(state)

    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        robot = self.robot
        assert robot is not None and self.q_target is not None, "bind() before set_target()"
        q = self.q_target.copy()
        if isinstance(target, Mapping):
            for jname, value in target.items():
                try:
                    j = robot.joint_index(jname)
                except Exception as exc:
                    raise self.target_error(str(exc), tick) from None
                q[robot.joint_q_index[j]] = float(value)
        else:
            arr = self.target_array(
                target, tick, "posture target must be numbers or {joint: value}"
            )
            if arr.shape == (robot.nq,):
                q = arr
            elif arr.shape == (len(robot.joint_names),):
                q[robot.joint_q_index] = arr
            else:
                raise self.target_error(
                    f"posture target must have shape ({robot.nq},) (full q) or "
                    f"({len(robot.joint_names)},) (joints), got {arr.shape}.",
                    tick,
                )
        if not np.all(np.isfinite(q)):
            return False
        self.q_target = q
        return True

    def compile_into(self, tick: Any, row: int) -> bool:
        """Compiled posture error ``q_target ⊖ q`` (joint rows) and its constant Jacobian."""
        tick.add_posture_task(self, row, self.dim, self._root_nv, self._kernel_gain())
        return True

    def compute_error(self, state: RobotState) -> np.ndarray:
        return pin.difference(state.model, state.q, self.q_target)[self._root_nv :]

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        return self._J


@TASKS.register("damping")
class DampingTask(Task):
    r"""Velocity damping: :math:`J = I`, :math:`v^* = 0` (Tikhonov term :math:`w |v|^2`)."""

    drift_kind: ClassVar[str] = "zero"

    def __init__(self, name: str = "damping", *, weight: Any = 1e-3, level: int = 1) -> None:
        super().__init__(name, weight=weight, level=level)

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        self.dim = robot.nv
        super().bind(robot, path=path)
        self._J = np.eye(robot.nv)
        self._zero = np.zeros(robot.nv)

    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        raise self.target_error("a damping task takes no target.", tick)

    def compute_error(self, state: RobotState) -> np.ndarray:
        return self._zero

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        return self._J
