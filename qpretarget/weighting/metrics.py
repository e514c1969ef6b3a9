# SPDX-License-Identifier: Apache-2.0
r"""Adaptive regularization metrics: ``wln`` (Dariush 2009 eq. 13-14) and ``crac`` (CRAC eq. 17-29).

Both plug into the cost term :math:`\tfrac12 \lambda^2 v^\top W v` of every strategy, so without
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

``crac`` (CRAC eq. 17-29):

.. math::
    W = W_K + W_D, \quad W_K = a W_{JL} + (1 - a) W_{COL}, \quad a = \frac{1}{N_c + 1},

with :math:`W_{JL} = \operatorname{diag}(|\nabla h_i|)` on joints moving toward their limit, else 0
(eq. 21); collision weights from :math:`g(d) = \rho e^{-\alpha d} d^{-\beta}` (eq. 25),
:math:`\partial g / \partial d = -\rho e^{-\alpha d} d^{-\beta}(\beta/d + \alpha)` (eq. 26) and the
distance gradient :math:`\partial d / \partial q` (eq. 23), :math:`\nabla f_j = \tfrac{\partial
g}{\partial d}(d_j)\, \tfrac{\partial d_j}{\partial q}` (eq. 22),
:math:`w_{COL_j,i} = |\nabla f_{j,i}|` while joint :math:`i` moves pair :math:`j` toward collision
(:math:`\tfrac{\partial d_j}{\partial q_i} \dot q_i \le 0`, eq. 24), else 0, averaged over the
:math:`N_c` pairs (eq. 27); :math:`W_D = H` (joint-space inertia from pinocchio's CRBA, eq. 29) or
the identity. Distances and gradients come from the ``self_collision`` constraint module
(``distances_and_gradients(state) -> (d (P,), dd/dq (P, nv))``); without one, :math:`N_c = 0` and
:math:`W_K = W_{JL}`. Weights are capped at ``max_weight`` so the QP stays well conditioned.

Paper defaults (CRAC section 5): :math:`\rho = 1`, :math:`\beta = 2`, :math:`\alpha = 50`,
:math:`\lambda = 0.1`.

Registration: this module registers ``wln`` and ``crac`` in
:data:`~qpretarget.weighting.base.REGULARIZATIONS`; it is imported by
``qpretarget/strategies/__init__.py`` (which the controller imports): ``weighting.py`` cannot
import it without a cycle, since this module imports ``weighting.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import REGULARIZATIONS, Regularization

#: CRAC section 5 defaults.
PAPER_RHO, PAPER_ALPHA, PAPER_BETA, PAPER_DAMPING = 1.0, 50.0, 2.0, 0.1


class _JointLimitGradient:
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


@REGULARIZATIONS.register("wln")
class WeightedLeastNorm(Regularization):
    r"""Chan-Dubey weighted least norm (Dariush 2009 eq. 13-14): :math:`w_i = 1 + |\nabla h_i|`.

    Args:
        damping: :math:`\lambda`.
        max_weight: cap on each :math:`w_i` (keeps the QP well conditioned at a limit).
        min_distance: distance to a limit below which :math:`\nabla h` stops growing [rad].
    """

    def __init__(
        self, damping: float = PAPER_DAMPING, *, max_weight: float = 1e6, min_distance: float = 1e-6
    ) -> None:  # noqa: E501
        super().__init__(damping)
        self.max_weight = positive_float(max_weight, "max_weight")
        self.min_distance = positive_float(min_distance, "min_distance [rad]")

    def bind(self, robot: RobotModel, controller: Any = None) -> None:
        super().bind(robot, controller)
        self._jl = _JointLimitGradient(robot, self.min_distance)
        self._W = np.eye(robot.nv)
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


@REGULARIZATIONS.register("crac")
class CracRegularization(Regularization):
    r"""CRAC adaptive weight :math:`W = W_K + W_D` (CRAC eq. 17-29).

    Args:
        damping: :math:`\lambda` (CRAC section 5: 0.1).
        rho: amplitude :math:`\rho` of the collision function (eq. 25).
        alpha: decay rate :math:`\alpha` [1/m] (eq. 25).
        beta: exponent :math:`\beta` (eq. 25).
        inertia: ``True`` for :math:`W_D = H` (CRBA, eq. 29), ``False`` for the identity.
        collisions: use the ``self_collision`` constraint module's pairs when there is one.
        max_weight: cap on each diagonal entry of :math:`W_K`.
        min_distance: joint-limit distance floor [rad] of :math:`\nabla h`.
        min_pair_distance: pair distance floor [m] in :math:`g'(d)` (penetration gives 0 or less).
    """

    def __init__(
        self,
        damping: float = PAPER_DAMPING,
        *,
        rho: float = PAPER_RHO,
        alpha: float = PAPER_ALPHA,
        beta: float = PAPER_BETA,
        inertia: bool = True,
        collisions: bool = True,
        max_weight: float = 1e6,
        min_distance: float = 1e-6,
        min_pair_distance: float = 1e-3,
    ) -> None:
        super().__init__(damping)
        self.rho = positive_float(rho, "rho")
        self.alpha = positive_float(alpha, "alpha [1/m]", allow_zero=True)
        self.beta = positive_float(beta, "beta", allow_zero=True)
        if not isinstance(inertia, bool):
            raise ConfigError(
                f"inertia must be true (W_D = H) or false (W_D = I), got {inertia!r}."
            )
        self.inertia = inertia
        self.collisions = bool(collisions)
        self.max_weight = positive_float(max_weight, "max_weight")
        self.min_distance = positive_float(min_distance, "min_distance [rad]")
        self.min_pair_distance = positive_float(min_pair_distance, "min_pair_distance [m]")

    def bind(self, robot: RobotModel, controller: Any = None) -> None:
        super().bind(robot, controller)
        self._jl = _JointLimitGradient(robot, self.min_distance)
        self._W = np.eye(robot.nv)
        self._wk = np.zeros(robot.nv)
        self._data = robot.model.createData()  # CRBA runs on its own data: state.data stays intact
        self._pairs: list[Any] = []
        if self.collisions and controller is not None:
            self._pairs = [
                c
                for c in getattr(controller, "constraints", [])
                if getattr(c, "type_name", "") == "self_collision"
                and hasattr(c, "distances_and_gradients")
            ]
        #: Last :math:`W_{JL}` (nv,), :math:`W_{COL}` (nv,) diagonals and :math:`N_c` (inspection).
        self.w_jl = np.zeros(robot.nv)
        self.w_col = np.zeros(robot.nv)
        self.n_pairs = 0

    def collision_function_derivative(self, d: np.ndarray) -> np.ndarray:
        r"""CRAC eq. 26: :math:`g'(d) = -\rho e^{-\alpha d} d^{-\beta} (\beta/d + \alpha)`."""
        d = np.maximum(d, self.min_pair_distance)
        return (
            -self.rho * np.exp(-self.alpha * d) * d ** (-self.beta) * (self.beta / d + self.alpha)
        )

    def _distances(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        ds, gs = [], []
        for c in self._pairs:
            d, g = c.distances_and_gradients(state)
            ds.append(np.asarray(d, dtype=float).reshape(-1))
            gs.append(np.asarray(g, dtype=float).reshape(-1, self.robot.nv))
        if not ds:
            return np.zeros(0), np.zeros((0, self.robot.nv))
        return np.concatenate(ds), np.vstack(gs)

    def kinematic_weights(self, state: RobotState) -> np.ndarray:
        r"""Diagonal of :math:`W_K = a W_{JL} + (1 - a) W_{COL}` (nv,) (CRAC eq. 18-27)."""
        jl = self._jl
        g = jl.gradient(state.q)
        w_jl = self.w_jl
        w_jl.fill(0.0)
        w_jl[jl.vi] = np.where(jl.toward(g, state.v), np.abs(g), 0.0)  # eq. 21
        d, dd_dq = self._distances(state)
        n_c = d.shape[0]
        self.n_pairs = n_c
        w_col = self.w_col
        if n_c:
            grad_f = self.collision_function_derivative(d)[:, None] * dd_dq  # eq. 22, (P, nv)
            toward = dd_dq * state.v[None, :] <= 0.0  # eq. 24: joint i brings pair j closer
            np.mean(np.where(toward, np.abs(grad_f), 0.0), axis=0, out=w_col)  # eq. 27
        else:
            w_col.fill(0.0)
        a = 1.0 / (n_c + 1.0)  # eq. 19
        np.minimum(a * w_jl + (1.0 - a) * w_col, self.max_weight, out=self._wk)  # eq. 18
        return self._wk

    def matrix(self, state: RobotState, dt: float) -> np.ndarray:
        wk = self.kinematic_weights(state)
        W = self._W
        if self.inertia:
            M = pin.crba(self.robot.model, self._data, state.q)  # eq. 29: W_D = H
            np.add(M, M.T, out=W)
            W *= 0.5
        else:
            W[...] = self._eye
        W[np.diag_indices_from(W)] += wk  # eq. 17
        return W

    def __repr__(self) -> str:
        return (
            f"CracRegularization(damping={self.damping}, rho={self.rho}, alpha={self.alpha}, "
            f"beta={self.beta}, inertia={self.inertia}, pairs={self.n_pairs})"
        )
