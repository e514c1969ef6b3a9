# SPDX-License-Identifier: Apache-2.0
r"""Adaptive regularization metric ``crac`` (CRAC, Bin Hammam et al. 2015, eq. 17-29).

It plugs into the cost term :math:`\tfrac12 \lambda^2 v^\top W v` of every strategy, like
``wln`` (``weighting/wln.py``, where the joint-limit gradient :math:`\nabla h` of CRAC eq. 20
and the direction test of CRAC eq. 21 are described).

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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ..constraints.base import Constraint
from ..constraints.self_collision import SelfCollision
from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import REGULARIZATIONS
from .wln import PAPER_ALPHA, PAPER_BETA, PAPER_DAMPING, PAPER_RHO, JointLimitWeighting


@REGULARIZATIONS.register("crac")
class CracRegularization(JointLimitWeighting):
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
        super().__init__(damping, max_weight=max_weight, min_distance=min_distance)
        self.rho = positive_float(rho, "rho")
        self.alpha = positive_float(alpha, "alpha [1/m]", allow_zero=True)
        self.beta = positive_float(beta, "beta", allow_zero=True)
        if not isinstance(inertia, bool):
            raise ConfigError(
                f"inertia must be true (W_D = H) or false (W_D = I), got {inertia!r}."
            )
        self.inertia = inertia
        self.collisions = bool(collisions)
        self.min_pair_distance = positive_float(min_pair_distance, "min_pair_distance [m]")

    def bind(self, robot: RobotModel, constraints: Sequence[Constraint] = ()) -> None:
        super().bind(robot, constraints)
        self._wk = np.zeros(robot.nv)
        self._data = robot.model.createData()  # CRBA runs on its own data: state.data stays intact
        self._pairs: list[SelfCollision] = []
        if self.collisions:
            self._pairs = [c for c in constraints if isinstance(c, SelfCollision)]
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
