# SPDX-License-Identifier: Apache-2.0
r"""Strict task priorities as a sequence of QPs (lexicographic / hierarchical QP).

Tasks carry ``level: 1..K`` (1 = highest). Level :math:`k` solves

.. math::
    \min_v \tfrac12 \sum_{i \in k} w_i |J_i v - v^*_i|^2 + \tfrac12 \lambda_k^2 v^\top W v
    \quad \text{s.t.} \quad
    \begin{cases}
      l \le C v \le u, \quad v_{min} \le v \le v_{max} & \text{(every hard constraint)}\\
      J_i v = J_i v^\star_{k-1} \ \forall i \text{ above } k & \text{(achieved above)}
    \end{cases}

where :math:`v^\star_{k-1}` is the solution of level :math:`k-1`. The equalities are imposed by
construction rather than as rows: with :math:`Z_{<k}` an orthonormal basis of the null space of
the stacked weighted Jacobians :math:`\sqrt{w_i} J_i` of every level above, level :math:`k`
optimizes :math:`z` in

.. math:: v = v^\star_{k-1} + Z_{<k}\, z,

(:math:`Z_{<k+1} = Z_{<k}\, \mathrm{null}(J_k Z_{<k})`, one SVD per level; singular values below
``rank_tolerance`` times the largest count as zero), so :math:`J_i v = J_i v^\star_{k-1}` holds
exactly for every task above, whether that level was
feasible or only solved in the least-squares sense (Dariush 2009 Algorithm 1 and Poubel 2014 eq. 4
in the exact case), rank-deficient stacks (CRAC's over-constrained Task Set 1) need no special
care, and :math:`z = 0` is always feasible. (Equality rows :math:`B v = B v^\star` were tried
first: ProxSuite then reported feasible levels as primal infeasible on about a quarter of the
ticks with active joint limits.) The box bounds become the rows
:math:`v_{min} - v^\star \le Z z \le v_{max} - v^\star`; the QP of every level keeps a fixed
shape (``nv`` variables, ``n_rows + nv`` rows; the columns of :math:`Z` beyond the nullity are
zero and their variables get a unit Hessian, so they stay 0). Each level has its own
warm-started solver.

Without active inequality constraints and with :math:`W = I`, level 2's solution is the
closed-form null-space solution (Dariush 2009 Algorithm 1 with damped least-squares inverses):

.. math::
    v = v_1 + \hat J_2^{*} (v^*_2 - J_2 v_1), \quad
    \hat J_2 = J_2 (I - J_1^+ J_1), \quad
    \hat J^{*} = \hat J^\top (\hat J \hat J^\top + \lambda_2^2 I)^{-1}.

If a lower level's QP fails (numerically: its feasible set always contains :math:`z = 0`), it is
retried once without warm start; if it fails again, the level takes the feasible part
:math:`t \in [0, 1]` of its unconstrained step :math:`v^\star + t Z z_u` and the levels below
it are skipped for this tick (reported in the status): lower levels never degrade higher ones.

YAML::

    strategy: {type: hierarchy, damping: [1.0e-6, 1.0e-3, 1.0e-2]}   # one lambda per level
    tasks:
      - {type: frame, name: left_foot, frame: left_sole, level: 1}
      - {type: frame, name: right_hand, frame: right_rubber_hand, mode: position, level: 2}
      - {type: posture, weight: 0.01, level: 3}
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..problem import QPProblem
from ..robot import RobotModel
from ..solvers.base import QPSolver
from ..validation import positive_float
from .base import STRATEGIES, Strategy, StrategyResult, TaskDims, TickProblem, stack_weighted


def level_dampings(
    damping: Any, n_levels: int, levels: Sequence[int], *, path: str
) -> list[float] | None:
    """Validate ``damping``: ``None`` (use the regularization's lambda), a scalar, or one per level.

    Raises:
        ConfigError: on a negative value or a list whose length is not the number of levels.
    """
    if damping is None:
        return None
    if isinstance(damping, (list, tuple)):
        if len(damping) != n_levels:
            raise ConfigError(
                f"damping lists one lambda per priority level; the tasks use {n_levels} "
                f"level(s) {list(levels)} but {len(damping)} value(s) were given.",
                path=path,
            )
        return [positive_float(d, "damping (lambda)", allow_zero=True) for d in damping]
    return [positive_float(damping, "damping (lambda)", allow_zero=True)] * n_levels


#: Rows of the null-space basis shorter than this are dropped (joint fixed by the levels above).
_LOCKED_ROW = 1e-9


def null_space_basis(J: np.ndarray, rank_tolerance: float) -> np.ndarray:
    """Orthonormal basis (n, n - r) of the null space of ``J`` (m, n) from its SVD.

    Singular values below ``rank_tolerance * s_max`` are treated as zero.
    """
    n = J.shape[1]
    if J.shape[0] == 0:
        return np.eye(n)
    _, s, Vt = np.linalg.svd(J, full_matrices=True)
    if s.size == 0 or s[0] <= 0.0:
        return np.eye(n)
    r = int(np.count_nonzero(s > rank_tolerance * s[0]))
    return Vt[r:].T


class _Level:
    """Preallocated data of one priority level."""

    def __init__(
        self, level: int, block_ids: list[int], names: list[str], dim: int, first: bool,
        nv: int, n_rows: int, solver: Any,
    ) -> None:  # fmt: skip
        self.level = level
        self.block_ids = block_ids
        self.names = names
        self.dim = dim
        self.first = first
        self.Jw = np.zeros((dim, nv))
        self.rw = np.zeros(dim)
        self.Hv = np.zeros((nv, nv))
        self.Z = np.zeros((nv, nv))  # null-space basis of the levels above, zero-padded
        # Level 1 optimizes v with box bounds; lower levels optimize z with the box as rows.
        self.problem = QPProblem(nv, n_rows if first else n_rows + nv)
        self.solver = solver


@STRATEGIES.register("hierarchy")
class Hierarchy(Strategy):
    r"""One QP per priority level, each keeping the hard constraints and the levels above.

    Args:
        damping: :math:`\lambda_k` of each level: ``None`` uses the regularization's ``damping``
            for every level, a number is used for every level, a list gives one value per level
            (in increasing ``level`` order). The metric is the regularization's :math:`W`.
        rank_tolerance: relative singular-value threshold below which a direction of the stacked
            higher-level Jacobians is left free for the lower levels (numerical rank).
    """

    def __init__(
        self,
        damping: float | Sequence[float] | None = None,
        *,
        rank_tolerance: float = 1e-9,
    ) -> None:
        if damping is not None and not isinstance(damping, (list, tuple)):
            positive_float(damping, "damping (lambda)", allow_zero=True)
        self._damping_spec = damping
        self.rank_tolerance = positive_float(rank_tolerance, "rank_tolerance")
        self._levels: list[_Level] = []

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        super().bind(robot, task_dims, n_rows, solver_factory)
        nv = robot.nv
        levels = sorted({lvl for _, _, lvl in task_dims})
        self.level_numbers = levels
        self.dampings = level_dampings(
            self._damping_spec, len(levels), levels, path="strategy.damping"
        )
        self._levels = []
        for k, lvl in enumerate(levels):
            ids = [i for i, (_, _, li) in enumerate(task_dims) if li == lvl]
            names = [task_dims[i][0] for i in ids]
            dim = sum(task_dims[i][1] for i in ids)
            self._levels.append(_Level(lvl, ids, names, dim, k == 0, nv, n_rows, solver_factory()))
        self._N_above = np.eye(nv)

    def reset(self) -> None:
        for lv in self._levels:
            lv.solver.reset()

    def solvers(self) -> list[QPSolver]:
        return [lv.solver for lv in self._levels]

    def assemble(self, tp: TickProblem, k: int, x_above: np.ndarray | None) -> QPProblem:
        """Fill level ``k``'s QP (index into the sorted levels) for this tick.

        Level 0's variable is ``v``; level ``k > 0``'s is ``z`` with ``v = x_above + Z z``
        (``lv.Z`` is filled here).

        Args:
            tp: the tick's problem.
            k: level index (0 = highest).
            x_above: solution of level ``k - 1`` (``None`` for ``k = 0``).
        """
        lv = self._levels[k]
        Jw, rw, p, Hv = lv.Jw, lv.rw, lv.problem, lv.Hv
        stack_weighted(tp.blocks, lv.block_ids, Jw, rw)
        np.matmul(Jw.T, Jw, out=Hv)
        lam = tp.damping if self.dampings is None else self.dampings[k]
        if lam > 0:
            Hv += (lam * lam) * tp.W
        nr = self.n_rows
        if lv.first:
            p.H[...] = Hv
            np.matmul(Jw.T, rw, out=p.g)
            np.negative(p.g, out=p.g)
            p.set_constraints(tp.C, tp.l, tp.u, tp.lb, tp.ub)
            return p
        assert x_above is not None, "a level below the first needs the solution above it"
        # v = x + Z z: cost 1/2 z'Z'Hv Z z + z'Z'(Hv x + g_v), with g_v = -Jw' rw.
        N = self._N_above
        f = N.shape[1]
        Z = lv.Z
        Z[:, :f] = N
        Z[:, f:] = 0.0
        HZ = Hv @ Z
        np.matmul(Z.T, HZ, out=p.H)
        if f < self.nv:
            p.H[f:, f:] = np.eye(self.nv - f)  # padding variables: z = 0
        gv = Hv @ x_above - Jw.T @ rw
        np.matmul(Z.T, gv, out=p.g)
        if nr:
            np.matmul(tp.C, Z, out=p.C[:nr])
            Cx = tp.C @ x_above
            np.subtract(tp.l, Cx, out=p.l[:nr])
            np.subtract(tp.u, Cx, out=p.u[:nr])
        p.C[nr:] = Z
        np.subtract(tp.lb, x_above, out=p.l[nr:])
        np.subtract(tp.ub, x_above, out=p.u[nr:])
        # Joints the levels above fully determine give (numerically) zero rows: drop them, as
        # ProxSuite's scaling turns such rows into spurious infeasibility reports.
        locked = np.einsum("ij,ij->i", Z, Z) < _LOCKED_ROW**2
        p.C[nr:][locked] = 0.0
        p.l[nr:][locked] = -np.inf
        p.u[nr:][locked] = np.inf
        return p

    def _safeguarded_step(self, tp: TickProblem, k: int, x: np.ndarray) -> tuple[np.ndarray, float]:
        r"""Fallback of a failed level: the feasible part ``t`` of its unconstrained step.

        The unconstrained minimizer :math:`z_u` of level ``k`` is scaled by the largest
        :math:`t \in [0, 1]` keeping ``x + t Z z_u`` inside the rows and the box (``x`` is
        feasible), so the higher levels keep their values and the hard constraints hold.
        """
        p, Z = self._levels[k].problem, self._levels[k].Z
        try:
            zu = np.linalg.solve(p.H, -p.g)
        except np.linalg.LinAlgError:
            return x, 0.0
        d = Z @ zu
        t = 1.0
        nr = self.n_rows
        pairs = [(d, tp.lb - x, tp.ub - x)]
        if nr:
            pairs.append((tp.C @ d, tp.l - tp.C @ x, tp.u - tp.C @ x))
        for a, lo, hi in pairs:
            with np.errstate(divide="ignore", invalid="ignore"):
                up = np.where(a > 1e-15, np.maximum(hi, 0.0) / a, np.inf)
                down = np.where(a < -1e-15, np.minimum(lo, 0.0) / a, np.inf)
            t = min(t, float(np.min(up, initial=np.inf)), float(np.min(down, initial=np.inf)))
        t = max(t, 0.0)
        return x + t * d, t

    def solve(self, tp: TickProblem) -> StrategyResult:
        x: np.ndarray | None = None
        iterations = 0
        solve_time = 0.0
        details: list[dict[str, Any]] = []
        status = "solved"
        for k, lv in enumerate(self._levels):
            p = self.assemble(tp, k, x)
            sol = lv.solver.solve(p)
            ok = sol.success and sol.x is not None and bool(np.all(np.isfinite(sol.x)))
            if not ok:
                # A warm start from the previous tick can mislead the solver's infeasibility
                # test: retry once from scratch before giving up.
                iterations += max(sol.iterations, 0)
                solve_time += sol.solve_time
                lv.solver.reset()
                sol = lv.solver.solve(p)
                ok = sol.success and sol.x is not None and bool(np.all(np.isfinite(sol.x)))
            iterations += max(sol.iterations, 0)
            solve_time += sol.solve_time
            v = None
            if ok and sol.x is not None:
                v = sol.x.copy() if x is None else x + lv.Z @ sol.x
            details.append(
                {
                    "level": lv.level,
                    "tasks": lv.names,
                    "status": sol.status,
                    "success": ok,
                    "iterations": sol.iterations,
                    "solve_time": sol.solve_time,
                    "x": v,
                    "residual": (
                        float(np.linalg.norm(lv.Jw @ v - lv.rw)) if v is not None else float("nan")
                    ),
                }
            )
            if v is None:
                if x is None:
                    msg = f"level {lv.level}: {sol.status}"
                    return StrategyResult(None, False, msg, iterations, solve_time, details)
                x, t = self._safeguarded_step(tp, k, x)
                details[-1]["x"] = x
                status = (
                    f"level {lv.level}: solver failed ({sol.status}); applied {t:.3g} of its "
                    f"unconstrained step"
                )
                break
            # Clip round-off outside the box so the next level starts from a feasible point.
            x = np.clip(v, tp.lb, tp.ub)
            if k + 1 < len(self._levels):
                # null([J_1; ...; J_k]) = Z_{<k} null(J_k Z_{<k}): one small SVD per level.
                if lv.first:
                    self._N_above = null_space_basis(lv.Jw, self.rank_tolerance)
                elif self._N_above.shape[1]:
                    Nk = null_space_basis(lv.Jw @ self._N_above, self.rank_tolerance)
                    self._N_above = self._N_above @ Nk
        return StrategyResult(x, True, status, iterations, solve_time, details)

    def __repr__(self) -> str:
        return f"Hierarchy(damping={self._damping_spec!r}, rank_tolerance={self.rank_tolerance})"
