# SPDX-License-Identifier: Apache-2.0
r"""Centre-of-mass task: :math:`e = c_r - c`, :math:`J = J_{com}` (rows of the chosen axes)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from .base import TASKS, Task

_AXES = {"x": 0, "y": 1, "z": 2}


@TASKS.register("com")
class ComTask(Task):
    """Track the centre of mass (all axes or a subset, e.g. ``axes: xy`` for the ground projection).

    Args:
        name: task name.
        axes: which world axes are tracked, a string of ``x``, ``y``, ``z``.
        weight: weight [cost]/[m]^2 (scalar or one per axis).
        **kwargs: ``gain``, ``level``, ``feedforward``, ``recovery_time`` of :class:`Task`.
    """

    drift_kind: ClassVar[str] = "com"
    target_attributes: ClassVar[tuple[str, ...]] = ("target",)

    def __init__(
        self,
        name: str = "com",
        *,
        axes: str = "xyz",
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
        if (
            not isinstance(axes, str)
            or not axes
            or any(a not in _AXES for a in axes)
            or len(set(axes)) != len(axes)
        ):
            raise ConfigError(
                f"axes must be a string of distinct letters among x, y, z, got {axes!r}."
            )
        self.axes = axes
        self.rows = np.array([_AXES[a] for a in axes], dtype=int)
        self._rows_list = self.rows.tolist()
        self.dim = len(self.rows)
        self.target = np.zeros(3)

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)

    def reset(self, state: RobotState) -> None:
        super().reset(state)
        self.target = state.com().copy()

    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        """Set the CoM target: a 3-vector, or ``len(axes)`` values for the tracked axes."""
        if type(target) is np.ndarray and target.shape == (3,) and target.dtype == np.float64:
            tl = target.tolist()  # fast path: a position array
            if not all(math.isfinite(tl[r]) for r in self._rows_list):
                return False
            self.target = target.copy()
            return True
        arr = self.target_array(target, tick, "CoM target must be numbers")
        if arr.shape == (3,):
            full = arr
        elif arr.shape == (self.dim,):
            full = self.target.copy()
            full[self.rows] = arr
        else:
            raise self.target_error(
                f"CoM target must have shape (3,) or ({self.dim},) for axes {self.axes!r}, "
                f"got {arr.shape}.",
                tick,
            )
        if not np.all(np.isfinite(full[self.rows])):
            return False
        self.target = full
        return True

    def compile_into(self, tick: Any, row: int) -> bool:
        """Compiled CoM error and Jacobian rows (no feed-forward in the kernel)."""
        if self.feedforward:
            return False
        tick.add_com_task(self, row, [int(r) for r in self.rows], self._kernel_gain())
        return True

    def compute_error(self, state: RobotState) -> np.ndarray:
        return (self.target - state.com())[self.rows]

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        return state.com_jacobian()[self.rows]

    def compute_jdot_v(self, state: RobotState) -> np.ndarray:
        r"""CoM drift acceleration :math:`\dot J_{com} v` (needs ``forwardKinematics(q, v, 0)``)."""
        pin.centerOfMass(state.model, state.data, pin.KinematicLevel.ACCELERATION, False)
        return state.data.acom[0][self.rows].copy()

    def __repr__(self) -> str:
        return (
            f"ComTask(axes={self.axes!r}, name={self.name!r}, weight={self._weight_spec!r}, "
            f"gain={self.gain!r}, level={self.level})"
        )
