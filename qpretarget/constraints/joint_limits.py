# SPDX-License-Identifier: Apache-2.0
r"""Joint position limits folded into velocity bounds (DESIGN.md "One tick").

.. math:: \gamma \frac{q_{min} - q}{dt} \le v \le \gamma \frac{q_{max} - q}{dt}

on the actuated one-DoF joints, with gain :math:`0 < \gamma \le 1` (the fraction of the remaining
range that may be used in one tick). A joint already outside its range gets a bound that pushes it
back in.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import CONSTRAINTS, Constraint


@CONSTRAINTS.register("joint_limits")
class JointLimits(Constraint):
    r"""Keep every limited joint inside ``[q_min, q_max]`` of the URDF (or the YAML override).

    Args:
        gain: :math:`\gamma`, fraction of the distance to the limit allowed per tick (0, 1].
        margin: keep this far inside the limits [rad].
        name: constraint name.
    """

    importance = 90

    has_bounds: ClassVar[bool] = True

    def __init__(self, *, gain: float = 0.9, margin: float = 0.0, name: str | None = None) -> None:
        super().__init__(name)
        self.gain = positive_float(gain, "gain")
        if self.gain > 1:
            from ..errors import ConfigError

            raise ConfigError(f"gain must be in (0, 1], got {gain!r}.")
        self.margin = positive_float(margin, "margin [rad]", allow_zero=True)

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        qi, vi = robot.joint_q_index, robot.joint_v_index
        lo, hi = robot.q_min[qi] + self.margin, robot.q_max[qi] - self.margin
        finite = np.isfinite(lo) & np.isfinite(hi)
        self._qi, self._vi = qi[finite], vi[finite]
        self._lo, self._hi = lo[finite], hi[finite]
        self._lb = np.full(robot.nv, -np.inf)
        self._ub = np.full(robot.nv, np.inf)

    def compile_bounds_into(self, tick: Any) -> bool:
        """The same bounds, computed in the kernel."""
        tick.add_joint_limits(
            self.name, [int(i) for i in self._qi], [int(i) for i in self._vi],
            np.ascontiguousarray(self._lo), np.ascontiguousarray(self._hi), self.gain,
        )  # fmt: skip
        return True

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray]:
        q = state.q[self._qi]
        k = self.gain / dt
        self._lb[self._vi] = k * (self._lo - q)
        self._ub[self._vi] = k * (self._hi - q)
        return self._lb, self._ub

    def __repr__(self) -> str:
        return f"JointLimits(gain={self.gain}, margin={self.margin}, name={self.name!r})"


@CONSTRAINTS.register("velocity_limits")
class VelocityLimits(Constraint):
    """``|v_j| <= scale * v_max_j`` for every joint with a finite URDF (or YAML) velocity limit.

    Args:
        scale: fraction of the URDF velocity limit allowed (0, 1].
        name: constraint name.
    """

    importance = 95

    has_bounds: ClassVar[bool] = True

    def __init__(self, *, scale: float = 1.0, name: str | None = None) -> None:
        super().__init__(name)
        self.scale = positive_float(scale, "scale")

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        self._ub = self.scale * robot.v_max.copy()
        self._lb = -self._ub

    def compile_bounds_into(self, tick: Any) -> bool:
        """Constant bounds, copied by the kernel."""
        tick.add_const_bounds(self.name, self._lb, self._ub)
        return True

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray]:
        return self._lb, self._ub

    def __repr__(self) -> str:
        return f"VelocityLimits(scale={self.scale}, name={self.name!r})"
