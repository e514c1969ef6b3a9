# SPDX-License-Identifier: Apache-2.0
r"""Regularization metrics of the weighted damped least squares (CRAC eq. 10, Dariush 2009 eq. 10).

Every strategy adds :math:`\tfrac12 \lambda^2 v^\top W v` to its cost; without active constraints
the single-level minimizer is then

.. math:: v = W^{-1} J^\top (J W^{-1} J^\top + \lambda^2 I)^{-1} v^*.

``identity`` (:math:`W = I`, damped least squares) is defined here; ``wln`` and ``crac`` register
themselves in :data:`REGULARIZATIONS` from their own modules.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from ..constraints.base import Constraint
from ..registry import Registry
from ..robot import RobotModel, RobotState
from ..validation import positive_float

REGULARIZATIONS = Registry("regularization")


class Regularization(abc.ABC):
    r"""A regularization metric :math:`W` with damping :math:`\lambda`.

    Args:
        damping: :math:`\lambda` (>= 0); the cost gets :math:`\tfrac12\lambda^2 v^\top W v`.
    """

    type_name: ClassVar[str] = "regularization"

    def __init__(self, damping: float = 1e-3) -> None:
        self.damping = positive_float(damping, "damping (lambda)", allow_zero=True)

    def bind(self, robot: RobotModel, constraints: Sequence[Constraint] = ()) -> None:
        """Prepare buffers; ``constraints`` are the controller's (e.g. the collision pairs)."""
        self.robot = robot
        self._eye = np.eye(robot.nv)
        self._eye.setflags(write=False)

    def reset(self, state: RobotState) -> None:
        """Forget history."""

    @abc.abstractmethod
    def matrix(self, state: RobotState, dt: float) -> np.ndarray:
        """The (nv, nv) symmetric positive definite :math:`W` of this tick."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(damping={self.damping})"


@REGULARIZATIONS.register("identity")
class IdentityRegularization(Regularization):
    r"""Damped least squares: :math:`W = I` (Dariush 2009 eq. 10 with :math:`W = I`)."""

    def matrix(self, state: RobotState, dt: float) -> np.ndarray:
        return self._eye
