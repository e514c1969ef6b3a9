# SPDX-License-Identifier: Apache-2.0
r"""Closed-form null-space baselines (no QP): Dariush 2009 Algorithm 1 and Poubel 2014 eq. 4-8.

**Dariush 2009 Algorithm 1** (variant ``dariush``), tasks grouped by ``level`` (tasks of one level
are augmented, rows scaled by :math:`\sqrt{w}`):

.. math::
    N_0 = I,\quad
    \hat J_i = J_i N_{i-1},\quad
    \hat v_i = v^*_i - J_i \textstyle\sum_{j<i} \hat J_j^{*} \hat v_j,\quad
    N_i = N_{i-1}(I - \hat J_i^+ \hat J_i),\quad
    \dot q = \textstyle\sum_{i=1}^k \hat J_i^{*} \hat v_i + N_k z

with the damped least-squares inverse :math:`\hat J^{*} = \hat J^\top(\hat J \hat J^\top +
\lambda_i^2 I)^{-1}` (Dariush 2009 eq. 10 and the remark after Algorithm 1) wherever
:math:`\hat J^+` multiplies a velocity, and the exact pseudo-inverse in the projectors, so each
:math:`N_i` stays an orthogonal projector and the damped terms of a level never disturb the levels
above (:math:`N_{i-1}\hat J_i^* = \hat J_i^*`). Here :math:`z = 0`. The projector update is
computed as :math:`N_i = N_{i-1} - V_r V_r^\top` from the SVD :math:`\hat J_i = U S V^\top`
(:math:`V_r`: right singular vectors with :math:`s > \text{rank\_tolerance}\, s_{max}`), the same
matrix since the row space of :math:`\hat J_i` lies in the range of :math:`N_{i-1}`.

**Poubel 2014** (variant ``poubel``): the strict tasks of eq. 4 (the same recursion, with the
augmented projector :math:`P^a_j` of eq. 5, equal to :math:`N_j`), then the optimization tasks of
eq. 6 projected into the last null space,

.. math::
    \dot q_M = \dot q_N + P^a_N \textstyle\sum_k \alpha_k \nabla_q f_k(q),

with joint centering (eq. 7), :math:`f_c = \sum_i \big((q_i - \bar q_i)/(q_{max,i} -
q_{min,i})\big)^2`, as :math:`-k_c \nabla f_c` (``centering_gain`` :math:`k_c`), and joint
tracking (eq. 8), :math:`f_h = \sum_i (q_i - q_{h,i})^2`, provided by any task listed in
``optimization_tasks`` as the descent direction :math:`J^\top \operatorname{diag}(w)\, v^*`
(for a ``posture`` task :math:`v^* = K (q_h - q) = -\tfrac{K}{2} \nabla f_h`).

**Metric.** With a regularization metric :math:`W = L L^\top` (``wln``, ``crac``) the recursion
runs on :math:`\tilde J = J L^{-\top}` and maps back :math:`\dot q = L^{-\top} \tilde{\dot q}`:
the weighted DLS inverse :math:`W^{-1}J^\top(JW^{-1}J^\top + \lambda^2 I)^{-1}` (Dariush 2009
eq. 10) and :math:`W`-orthogonal projectors. With ``identity`` it is the unweighted algorithm.

**Box bounds: Poubel's clamping loop** (both variants, ``clamping: true``). After solving, every
joint whose velocity leaves :math:`[v_{min}, v_{max}]` (the merged joint-position and velocity
limits of the constraint modules) is fixed at the bound, its column is removed from every Jacobian
(its fixed contribution is moved to the right-hand side, :math:`v^*_i \leftarrow v^*_i - J_{i,j}
v_j`) and the problem is solved again with fewer DoF, until every joint fits (at most ``nv``
rounds). Poubel clamps joint positions; here the velocity bounds already encode the position
limits over the tick (``joint_limits``), so clamping the velocity clamps the position at its limit.

**Row constraints** (contacts, support polygon, self-collision rows) cannot be honoured by a
closed-form baseline: binding raises :class:`~qpretarget.errors.ConfigError` when the config has
any, unless ``ignore_rows: true`` (then they are ignored and the README/doc says so). Put the feet
as level-1 frame tasks instead, as both papers do.

YAML::

    strategy: {type: nullspace, variant: dariush, damping: 1.0e-3}
    strategy: {type: nullspace, variant: poubel, optimization_tasks: [posture], centering_gain: 0.5}
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from ..errors import ConfigError, close_matches_hint
from ..robot import RobotModel
from ..validation import positive_float
from .base import STRATEGIES, Strategy, StrategyResult, TaskDims, TickProblem, stack_weighted
from .hierarchy import level_dampings

VARIANTS = ("dariush", "poubel")


def prioritized_dls(
    J_levels: Sequence[np.ndarray],
    v_levels: Sequence[np.ndarray],
    dampings: Sequence[float],
    *,
    rank_tolerance: float = 1e-9,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Dariush 2009 Algorithm 1 with damped least-squares inverses (unweighted).

    Args:
        J_levels: Jacobian :math:`J_i` (m_i, n) of each priority level, highest first.
        v_levels: task velocity :math:`\dot x_i` (m_i,) of each level.
        dampings: :math:`\lambda_i` of each level (0: pseudo-inverse, singular values below
            ``rank_tolerance * s_max`` dropped).
        rank_tolerance: relative singular-value threshold of the projectors' rank.

    Returns:
        ``(qdot, N_k)``: the joint velocity (n,) with :math:`z = 0`, and the last null-space
        projector (n, n).
    """
    n = J_levels[0].shape[1] if J_levels else 0
    N = np.eye(n)
    q = np.zeros(n)
    for J, v, lam in zip(J_levels, v_levels, dampings, strict=True):
        if J.shape[0] == 0:
            continue
        Jh = J @ N
        vh = v - J @ q
        U, s, Vt = np.linalg.svd(Jh, full_matrices=False)
        smax = s[0] if s.size else 0.0
        keep = s > rank_tolerance * smax if smax > 0 else np.zeros(s.shape, dtype=bool)
        if lam > 0:
            gain = s / (s * s + lam * lam)
        else:
            gain = np.zeros_like(s)
            gain[keep] = 1.0 / s[keep]
        q += Vt.T @ (gain * (U.T @ vh))
        Vr = Vt[keep]
        N -= Vr.T @ Vr
    return q, N


def weighted_prioritized_dls(
    J_levels: Sequence[np.ndarray],
    v_levels: Sequence[np.ndarray],
    dampings: Sequence[float],
    W: np.ndarray | None = None,
    *,
    z: np.ndarray | None = None,
    rank_tolerance: float = 1e-9,
) -> np.ndarray:
    r"""Algorithm 1 in the metric :math:`W = L L^\top`, plus a null-space term.

    Runs :func:`prioritized_dls` on :math:`\tilde J_i = J_i L^{-\top}` and returns
    :math:`\dot q = L^{-\top} (\tilde{\dot q} + \tilde N_k L^\top z)`: the weighted DLS inverse of
    Dariush 2009 eq. 10 level by level, and ``z`` projected by the :math:`W`-orthogonal projector
    onto the null space of all levels (Poubel 2014 eq. 6).

    Args:
        J_levels: Jacobians, highest level first.
        v_levels: task velocities.
        dampings: one lambda per level.
        W: symmetric positive definite metric (n, n), ``None`` for the identity.
        z: joint-space vector (n,) projected into the last null space (``None``: 0).
        rank_tolerance: see :func:`prioritized_dls`.
    """
    if W is None:
        q, N = prioritized_dls(J_levels, v_levels, dampings, rank_tolerance=rank_tolerance)
        if z is not None:
            q = q + N @ z
        return q
    L = np.linalg.cholesky(W)
    Jt = [solve_triangular(L, J.T, lower=True).T for J in J_levels]
    u, N = prioritized_dls(Jt, v_levels, dampings, rank_tolerance=rank_tolerance)
    if z is not None:
        u = u + N @ (L.T @ z)
    return solve_triangular(L.T, u, lower=False)


def clamping_loop(
    J_levels: Sequence[np.ndarray],
    v_levels: Sequence[np.ndarray],
    dampings: Sequence[float],
    lb: np.ndarray,
    ub: np.ndarray,
    W: np.ndarray | None = None,
    *,
    z: np.ndarray | None = None,
    rank_tolerance: float = 1e-9,
    tol: float = 1e-12,
) -> tuple[np.ndarray, int, int]:
    r"""Poubel 2014's clamping loop around :func:`weighted_prioritized_dls`.

    Solve; fix every joint whose velocity leaves ``[lb, ub]`` at the violated bound, move its
    contribution to the right-hand sides (:math:`v_i \leftarrow v_i - J_{i,j} v_j`), drop its column
    (and its row/column of ``W``), solve again with the other joints; repeat until all fit.

    Returns:
        ``(v, rounds, n_clamped)``.
    """
    nv = lb.shape[0]
    free = np.ones(nv, dtype=bool)
    v = np.zeros(nv)
    rounds = 0
    for rounds in range(1, nv + 2):  # noqa: B007 - each round fixes at least one joint
        F = np.flatnonzero(free)
        if F.size == 0:
            break
        if F.size == nv:
            Js, vs = list(J_levels), list(v_levels)
            WF, zF = W, z
        else:
            fixed = ~free
            Js = [J[:, F] for J in J_levels]
            vs = [vl - J[:, fixed] @ v[fixed] for J, vl in zip(J_levels, v_levels, strict=True)]
            WF = W[np.ix_(F, F)] if W is not None else None
            zF = z[F] if z is not None else None
        v[F] = weighted_prioritized_dls(Js, vs, dampings, WF, z=zF, rank_tolerance=rank_tolerance)
        bad = free & ((v < lb - tol) | (v > ub + tol))
        if not bad.any():
            break
        v[bad] = np.clip(v[bad], lb[bad], ub[bad])
        free[bad] = False
    return v, rounds, int(nv - np.count_nonzero(free))


def row_constraints_error(strategy: str, n_rows: int) -> ConfigError:
    """The error raised when a closed-form strategy is bound with constraint rows."""
    return ConfigError(
        f"strategy {strategy!r} is a closed-form baseline: it honours box bounds (joint_limits, "
        f"velocity_limits) by clamping but cannot honour the {n_rows} constraint row(s) of this "
        f"config (contacts, support polygon or self-collision rows). Remove those constraints "
        f"(put the feet as level-1 frame tasks), use strategy hierarchy or augmentation, or set "
        f"`ignore_rows: true` to run the baseline without them.",
        path="strategy",
    )


class ClosedFormStrategy(Strategy):
    """A closed-form baseline: no QP, so constraint rows cannot hold (``ignore_rows`` to run)."""

    ignore_rows: bool = False

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        super().bind(robot, task_dims, n_rows, solver_factory)
        if n_rows and not self.ignore_rows:
            raise row_constraints_error(self.type_name, n_rows)


@STRATEGIES.register("nullspace")
class NullSpace(ClosedFormStrategy):
    r"""Closed-form prioritized inverse kinematics (no QP), the reference baseline.

    Args:
        variant: ``dariush`` (Dariush 2009 Algorithm 1) or ``poubel`` (Poubel 2014 eq. 4-8).
        damping: :math:`\lambda` per level (``None``: the regularization's damping, a number,
            or a list with one value per level); 0 gives the exact pseudo-inverse.
        optimization_tasks: (``poubel``) names of tasks used as optimization tasks (eq. 6, 8)
            projected into the null space of the strict tasks instead of being strict tasks.
        centering_gain: (``poubel``) :math:`k_c` [1/s] of the joint-centering term (eq. 7);
            Poubel used weights -0.10 (limits) and -0.02 (joint tracking).
        clamping: run Poubel's clamping loop to keep every joint inside the box bounds.
        ignore_rows: run even though the config has constraint rows (they are ignored).
        rank_tolerance: relative singular-value threshold of the projectors.
    """

    def __init__(
        self,
        variant: str = "dariush",
        *,
        damping: float | Sequence[float] | None = None,
        optimization_tasks: Sequence[str] = (),
        centering_gain: float = 0.0,
        clamping: bool = True,
        ignore_rows: bool = False,
        rank_tolerance: float = 1e-9,
    ) -> None:
        if variant not in VARIANTS:
            raise ConfigError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}.")
        self.variant = variant
        if damping is not None and not isinstance(damping, (list, tuple)):
            positive_float(damping, "damping (lambda)", allow_zero=True)
        self._damping_spec = damping
        if isinstance(optimization_tasks, str) or not all(
            isinstance(t, str) for t in optimization_tasks
        ):
            raise ConfigError(
                f"optimization_tasks must be a list of task names, got {optimization_tasks!r}."
            )
        self.optimization_tasks = list(optimization_tasks)
        self.centering_gain = positive_float(
            centering_gain, "centering_gain [1/s]", allow_zero=True
        )
        if variant == "dariush" and (self.optimization_tasks or self.centering_gain):
            raise ConfigError(
                "optimization_tasks and centering_gain belong to variant 'poubel' (Poubel 2014 "
                "eq. 6-8); variant 'dariush' is Algorithm 1 with z = 0."
            )
        self.clamping = bool(clamping)
        self.ignore_rows = bool(ignore_rows)
        self.rank_tolerance = positive_float(rank_tolerance, "rank_tolerance")

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        super().bind(robot, task_dims, n_rows, solver_factory)
        names = [n for n, _, _ in task_dims]
        for t in self.optimization_tasks:
            if t not in names:
                raise ConfigError(
                    f"optimization task {t!r} is not a task of this config."
                    f"{close_matches_hint(t, names)} Tasks: {', '.join(names)}.",
                    path="strategy.optimization_tasks",
                )
        opt = set(self.optimization_tasks)
        strict = [(i, d, lvl) for i, (n, d, lvl) in enumerate(task_dims) if n not in opt]
        if not strict:
            raise ConfigError(
                "every task is an optimization task: keep at least one strict task.",
                path="strategy",
            )
        levels = sorted({lvl for _, _, lvl in strict})
        self.level_numbers = levels
        self.dampings = level_dampings(
            self._damping_spec, len(levels), levels, path="strategy.damping"
        )
        self._groups = [[i for i, _, lvl in strict if lvl == L] for L in levels]
        self._opt_ids = [i for i, (n, _, _) in enumerate(task_dims) if n in opt]
        self._J = [np.zeros((sum(task_dims[i][1] for i in g), robot.nv)) for g in self._groups]
        self._v = [np.zeros(J.shape[0]) for J in self._J]
        # Joint centering (Poubel eq. 7) on the one-DoF joints with finite limits.
        qi, vi = robot.joint_q_index, robot.joint_v_index
        lo, hi = robot.q_min[qi], robot.q_max[qi]
        finite = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
        self._cq, self._cv = qi[finite], vi[finite]
        self._cmid = 0.5 * (lo[finite] + hi[finite])
        self._crange2 = (hi[finite] - lo[finite]) ** 2

    def gather(
        self, tp: TickProblem
    ) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray | None]:
        """Stack the tick's weighted Jacobians and velocities per level, and the null-space term."""
        for g, J, v in zip(self._groups, self._J, self._v, strict=True):
            stack_weighted(tp.blocks, g, J, v)
        z = None
        if self._opt_ids or self.centering_gain:
            z = np.zeros(self.nv)
            for bi in self._opt_ids:
                b = tp.blocks[bi]
                z += b.J.T @ (b.weight * b.v_star)
            if self.centering_gain:
                q = tp.state.q[self._cq]
                z[self._cv] -= self.centering_gain * 2.0 * (q - self._cmid) / self._crange2
        return self._J, self._v, z

    def solve(self, tp: TickProblem) -> StrategyResult:
        t0 = time.perf_counter()
        Js, vs, z = self.gather(tp)
        dampings = self.dampings if self.dampings is not None else [tp.damping] * len(Js)
        W: np.ndarray | None = tp.W
        if W is not None and np.array_equal(W, np.eye(self.nv)):
            W = None
        try:
            if self.clamping:
                x, rounds, n_clamped = clamping_loop(
                    Js, vs, dampings, tp.lb, tp.ub, W, z=z, rank_tolerance=self.rank_tolerance
                )
            else:
                x = weighted_prioritized_dls(
                    Js, vs, dampings, W, z=z, rank_tolerance=self.rank_tolerance
                )
                rounds, n_clamped = 1, 0
        except np.linalg.LinAlgError as exc:
            return StrategyResult(
                None, False, f"closed form failed: {exc}", 0, time.perf_counter() - t0
            )
        ok = bool(np.all(np.isfinite(x)))
        status = f"closed form ({n_clamped} joint(s) clamped)" if ok else "closed form: non-finite"
        return StrategyResult(x if ok else None, ok, status, rounds, time.perf_counter() - t0)

    def __repr__(self) -> str:
        return (
            f"NullSpace(variant={self.variant!r}, damping={self._damping_spec!r}, "
            f"optimization_tasks={self.optimization_tasks!r}, "
            f"centering_gain={self.centering_gain}, "
            f"clamping={self.clamping})"
        )


__all__ = ["NullSpace", "prioritized_dls", "weighted_prioritized_dls", "clamping_loop", "VARIANTS"]
