# SPDX-License-Identifier: Apache-2.0
r"""Adaptive regularization metric ``wln``: Chan-Dubey weighted least norm (Dariush 2009 eq. 13-14).

It plugs into the cost term :math:`\tfrac12 \lambda^2 v^\top W v` of every strategy, so without
active constraints a single level gives the weighted damped least squares of CRAC eq. 10 /
Dariush 2009 eq. 10,

.. math:: v = W^{-1} J^\top (J W^{-1} J^\top + \lambda^2 I)^{-1} v^*.

**Joint-limit gradient** (Dariush 2009 eq. 13, CRAC eq. 20), on every one-DoF joint with finite
limits:

.. math::
    \nabla h_i = \frac{(q_{i,max} - q_{i,min})^2 (2 q_i - q_{i,max} - q_{i,min})}
                      {4 (q_{i,max} - q_i)^2 (q_i - q_{i,min})^2},

zero at mid-range and infinite at either limit.

**Direction test.** Both papers weight a joint only while :math:`|\nabla h_i|` grows
(:math:`\Delta|\nabla h_i| \ge 0`, Dariush 2009 eq. 14; :math:`\tfrac{d}{dt}|\nabla h_i| \ge 0`,
CRAC eq. 21). Since :math:`|\nabla h_i|` grows monotonically with :math:`|q_i - \bar q_i|`, this
is :math:`\nabla h_i\, \dot q_i \ge 0` with :math:`\dot q` the velocity applied during the
previous tick (``state.v``); a joint at rest counts as moving toward its limit. The test needs no
history, so building a tick twice gives the same :math:`W`.

``wln`` (Chan-Dubey weighted least norm, Dariush 2009 eq. 14):
:math:`W = \operatorname{diag}(w)`, :math:`w_i = 1 + |\nabla h_i|` if moving toward the limit,
else 1.

The joint-limit gradient and the direction test are shared with ``crac`` (``weighting/crac.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..constraints.base import Constraint
from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import REGULARIZATIONS, Regularization

#: CRAC section 5 defaults.
PAPER_RHO, PAPER_ALPHA, PAPER_BETA, PAPER_DAMPING = 1.0, 50.0, 2.0, 0.1


class JointLimitGradient:
    r"""Joint-limit gradient :math:`\nabla h` (Dariush 2009 eq. 13, CRAC eq. 20) of a robot."""

    def __init__(self, robot: RobotModel, min_distance: float) -> None:
        qi, vi = robot.joint_q_index, robot.joint_v_index
        lo, hi = robot.q_min[qi], robot.q_max[qi]
        finite = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
        self.qi, self.vi = qi[finite], vi[finite]
        self.lo, self.hi = lo[finite], hi[finite]
        self.range2 = (self.hi - self.lo) ** 2
        self.min_distance = min_distance

    def gradient(self, q: np.ndarray) -> np.ndarray:
        r""":math:`\nabla h_i` on the limited joints (distances to the limits floored)."""
        qj = q[self.qi]
        up = np.maximum(self.hi - qj, self.min_distance)
        down = np.maximum(qj - self.lo, self.min_distance)
        return self.range2 * (2.0 * qj - self.hi - self.lo) / (4.0 * up * up * down * down)

    def toward(self, grad: np.ndarray, v: np.ndarray) -> np.ndarray:
        r"""``True`` where :math:`|\nabla h_i|` grows (or the joint is at rest)."""
        return grad * v[self.vi] >= 0.0


class JointLimitWeighting(Regularization):
    r"""A metric weighted by the joint-limit gradient :math:`\nabla h` (``wln`` and ``crac``).

    Args:
        damping: :math:`\lambda`.
        max_weight: cap on each diagonal weight (keeps the QP well conditioned at a limit).
        min_distance: distance to a limit below which :math:`\nabla h` stops growing [rad].
    """

    def __init__(
        self, damping: float = PAPER_DAMPING, *, max_weight: float = 1e6, min_distance: float = 1e-6
    ) -> None:  # noqa: E501
        super().__init__(damping)
        self.max_weight = positive_float(max_weight, "max_weight")
        self.min_distance = positive_float(min_distance, "min_distance [rad]")

    def bind(self, robot: RobotModel, constraints: Sequence[Constraint] = ()) -> None:
        r"""Build :math:`\nabla h` of ``robot`` and the (nv, nv) buffer of :math:`W`."""
        super().bind(robot, constraints)
        self._jl = JointLimitGradient(robot, self.min_distance)
        self._W = np.eye(robot.nv)


@REGULARIZATIONS.register("wln")
class WeightedLeastNorm(JointLimitWeighting):
    r"""Chan-Dubey weighted least norm (Dariush 2009 eq. 13-14): :math:`w_i = 1 + |\nabla h_i|`.

    Args:
        damping: :math:`\lambda`.
        max_weight: cap on each :math:`w_i` (keeps the QP well conditioned at a limit).
        min_distance: distance to a limit below which :math:`\nabla h` stops growing [rad].
    """

    def bind(self, robot: RobotModel, constraints: Sequence[Constraint] = ()) -> None:
        super().bind(robot, constraints)
        self._diag = np.ones(robot.nv)

    def weights(self, state: RobotState) -> np.ndarray:
        """Diagonal :math:`w` (nv,) of this state (Dariush 2009 eq. 14)."""
        jl = self._jl
        g = jl.gradient(state.q)
        w = np.where(jl.toward(g, state.v), 1.0 + np.abs(g), 1.0)
        d = self._diag
        d.fill(1.0)
        d[jl.vi] = np.minimum(w, self.max_weight)
        return d

    def matrix(self, state: RobotState, dt: float) -> np.ndarray:
        d = self.weights(state)
        np.fill_diagonal(self._W, d)
        return self._W

    def __repr__(self) -> str:
        return f"WeightedLeastNorm(damping={self.damping}, max_weight={self.max_weight})"
