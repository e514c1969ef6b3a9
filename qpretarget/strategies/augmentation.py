# SPDX-License-Identifier: Apache-2.0
r"""Task augmentation (Dariush 2009 4.3.1): every task in one weighted least-squares QP.

.. math::
    \min_v \tfrac12 \sum_i w_i |J_i v - v^*_i|^2 + \tfrac12 \lambda^2 v^\top W v
    \quad \text{s.t. hard constraints}

assembled with one matrix product, :math:`H = \bar J^\top \bar J + \lambda^2 W`,
:math:`g = -\bar J^\top \bar r`, where :math:`\bar J` stacks :math:`\sqrt{w_i} J_i` and
:math:`\bar r` stacks :math:`\sqrt{w_i} v^*_i`.
"""

from __future__ import annotations

import numpy as np

from ..problem import QPProblem
from ..robot import RobotModel
from .base import STRATEGIES, Strategy, StrategyResult, TickProblem, solution_to_result


@STRATEGIES.register("augmentation")
class Augmentation(Strategy):
    """One weighted QP for all tasks; ``level`` is ignored."""

    def __init__(self) -> None:
        self._problem: QPProblem | None = None

    def bind(self, robot: RobotModel, task_dims, n_rows, solver_factory) -> None:  # noqa: ANN001
        super().bind(robot, task_dims, n_rows, solver_factory)
        m = sum(d for _, d, _ in task_dims)
        self._Jw = np.zeros((m, robot.nv))
        self._rw = np.zeros(m)
        self._problem = QPProblem(robot.nv, n_rows)
        self._solver = solver_factory()
        self._sqrt_cache = [(None, None)] * len(task_dims)
        self._w_seen: list = []
        self._W_seen = None
        self._W_is_eye = False
        self._sw_all = np.zeros(m)

    def reset(self) -> None:
        self._solver.reset()

    def solvers(self):  # noqa: ANN201
        return [self._solver]

    def assemble(self, tp: TickProblem) -> QPProblem:
        """Fill the QP of this tick (exposed for tests and solver comparisons)."""
        Jw, rw, p = self._Jw, self._rw, self._problem
        blocks = tp.blocks
        J_all, v_all = tp.J_all, tp.v_all
        if (
            J_all is not None
            and J_all.shape == Jw.shape
            and all(b.J.base is J_all and b.v_star.base is v_all for b in blocks)
        ):
            # Fast path: all rows already stacked; weight them with two products.
            weights = [b.weight for b in blocks]
            if len(weights) != len(self._w_seen) or any(
                w is not s for w, s in zip(weights, self._w_seen, strict=True)
            ):
                self._sw_all = np.sqrt(np.concatenate(weights))
                self._w_seen = weights
            sw = self._sw_all
            np.multiply(tp.J_all, sw[:, None], out=Jw)
            np.multiply(tp.v_all, sw, out=rw)
        else:
            i = 0
            cache = self._sqrt_cache
            for j, b in enumerate(blocks):
                k = b.J.shape[0]
                w, sw = cache[j]
                if b.weight is not w:  # weights rarely change: reuse their square root
                    sw = np.sqrt(b.weight)
                    cache[j] = (b.weight, sw)
                np.multiply(b.J, sw[:, None], out=Jw[i : i + k])
                np.multiply(b.v_star, sw, out=rw[i : i + k])
                i += k
        np.matmul(Jw.T, Jw, out=p.H)
        lam2 = tp.damping * tp.damping
        if lam2 > 0:
            W = tp.W
            if W is not self._W_seen:
                # A read-only W cannot change in place: test once whether it is the identity.
                self._W_seen = W
                self._W_is_eye = not W.flags.writeable and np.array_equal(W, np.eye(len(W)))
            if self._W_is_eye:
                p.H.flat[:: p.n + 1] += lam2
            else:
                p.H += lam2 * W
        np.matmul(Jw.T, rw, out=p.g)
        np.negative(p.g, out=p.g)
        if p.n_in:
            p.C[...] = tp.C
            p.l[...] = tp.l
            p.u[...] = tp.u
        p.lb[...] = tp.lb
        p.ub[...] = tp.ub
        return p

    def solve(self, tp: TickProblem) -> StrategyResult:
        return solution_to_result(self._solver.solve(self.assemble(tp)))
