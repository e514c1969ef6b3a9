# SPDX-License-Identifier: Apache-2.0
r"""Task augmentation (Dariush 2009 4.3.1): every task in one weighted least-squares QP.

.. math::
    \min_v \tfrac12 \sum_i w_i |J_i v - v^*_i|^2 + \tfrac12 \lambda^2 v^\top W v
    \quad \text{s.t. hard constraints}

assembled with one matrix product, :math:`H = \bar J^\top \bar J + \lambda^2 W`,
:math:`g = -\bar J^\top \bar r`, where :math:`\bar J` stacks :math:`\sqrt{w_i} J_i` and
:math:`\bar r` stacks :math:`\sqrt{w_i} v^*_i`.

Soft rows (``constraints/base.py``): the variable becomes :math:`x = (v, s)`, one slack per row
of each soft constraint, with the exact penalty :math:`w\,s + \tfrac{\epsilon}{2} s^2`
(:math:`\epsilon` = :attr:`Augmentation.SLACK_CURVATURE`, which keeps :math:`H` positive
definite for the dual active-set solver) and the row :math:`C_i v - s_i \le u_i` (or
:math:`C_i v + s_i \ge l_i` for a row bounded from below only); the slack of a row with no
finite side this tick needs none: slacks live in a few *slots* given each tick to the soft rows
in play (a collision pair within its influence distance, the polygon's edges), so 381
self-collision pairs do not make the QP 381 variables larger. The hard set left (contacts, the
viable box) always has a solution from a state the controller produced, so the QP does too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..problem import QPProblem
from ..robot import RobotModel
from ..solvers import QPSolver
from ..solvers.daqp_ import DaqpSolver
from .base import (
    STRATEGIES,
    SoftRows,
    Strategy,
    StrategyResult,
    TaskDims,
    TickProblem,
    solution_to_result,
)


@STRATEGIES.register("augmentation")
class Augmentation(Strategy):
    """One weighted QP for all tasks; ``level`` is ignored."""

    #: :math:`\epsilon` of the slacks' quadratic term [cost per (row unit)^2]: small against
    #: the penalty weights (>= 1e5), so a slack is zero whenever its row can hold.
    SLACK_CURVATURE = 1.0
    #: Slacks below this are not reported (row units; the solver's primal tolerance is 1e-9).
    REPORT_TOLERANCE = 1e-7
    #: Slack slots allocated first (the QP grows, once, when more soft rows are in play).
    INITIAL_SLOTS = 16

    def __init__(self) -> None:
        self._problem = QPProblem(0, 0)
        self._soft: list[SoftRows] = []
        self._soft_idx = np.zeros(0, dtype=int)

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        super().bind(robot, task_dims, n_rows, solver_factory)
        m = sum(d for _, d, _ in task_dims)
        self._Jw = np.zeros((m, robot.nv))
        self._rw = np.zeros(m)
        self._problem = QPProblem(robot.nv, n_rows)
        self._solver: QPSolver = solver_factory()
        self._sqrt_cache: list[tuple[Any, Any]] = [(None, None)] * len(task_dims)
        self._w_seen: list[Any] = []
        self._W_seen: np.ndarray | None = None
        self._W_is_eye = False
        self._sw_all = np.zeros(m)
        self._fused_key: tuple[Any, ...] | None = None  # the buffers the kernel's fused call holds
        self._fused_settings: tuple[Any, ...] = ()  # and the solver settings it was given
        #: Why the fused kernel call was turned off ('' while it is used when possible).
        self.fused_error = ""
        self._no_slots = np.zeros(1, dtype=np.int64)
        self._slot_buf = self._no_slots

    def set_soft_rows(self, soft: list[SoftRows]) -> bool:
        """Slack slots for the rows of the soft constraints (module docstring)."""
        self._soft = list(soft)
        idx = [np.arange(g.rows.start, g.rows.stop) for g in soft]
        self._soft_idx = np.concatenate(idx) if idx else np.zeros(0, dtype=int)
        w = [np.full(g.rows.stop - g.rows.start, g.weight) for g in soft]
        self._soft_w = np.concatenate(w) if w else np.zeros(0)
        group = [np.full(g.rows.stop - g.rows.start, k) for k, g in enumerate(soft)]
        self._soft_group = np.concatenate(group) if group else np.zeros(0, dtype=int)
        self._slot_rows = np.zeros(0, dtype=int)  # stacked row of each used slot, last tick
        self._slot_group = np.zeros(0, dtype=int)
        self._soft_idx64 = self._soft_idx.astype(np.int64)
        self._row_group = np.full(self.n_rows, -1, dtype=int)  # soft constraint of each row
        self._row_group[self._soft_idx] = self._soft_group
        self._Hv = np.zeros((self.nv, self.nv))
        self._gv = np.zeros(self.nv)
        self._allocate_slots(min(self._soft_idx.size, self.INITIAL_SLOTS))
        return True

    def _allocate_slots(self, k: int) -> None:
        """A QP with ``k`` slack slots (only when more soft rows are in play than slots)."""
        nv = self.nv
        self._n_slots = k
        p = self._problem = QPProblem(nv + k, self.n_rows)
        p.H[nv:, nv:] = self.SLACK_CURVATURE * np.eye(k)
        p.lb[nv:] = 0.0
        p.ub[nv:] = 0.0
        self._slot_rows = self._slot_rows[:0]
        self._slot_buf = np.zeros(max(k, 1), dtype=np.int64)  # the compiled path's slot rows

    def reset(self) -> None:
        """Drop the warm start and the slack slots grown since.

        A run from ``reset`` must repeat to the last bit, and a larger QP gives the same
        solution only to round-off.
        """
        self._solver.reset()
        if self._soft_idx.size:
            self._allocate_slots(min(self._soft_idx.size, self.INITIAL_SLOTS))

    def solvers(self) -> list[QPSolver]:
        return [self._solver]

    def assemble(self, tp: TickProblem) -> QPProblem:
        r"""Fill the QP of this tick (exposed for tests and solver comparisons).

        Cost :math:`\tfrac12 |W_t^{1/2}(J v - v^*)|^2 + \tfrac12 \lambda^2 v^\top W v`
        (Dariush 2009 4.3.1, CRAC eq. 10), and the soft rows' exact-penalty slacks when any
        soft row is in play.
        """
        H = self._Hv if self._soft_idx.size else self._problem.H
        if self._compiled_cost(tp, H):  # H and g in the kernel (control/compiled.py)
            if not self._soft_idx.size:
                p = self._problem
                tp.compiled.copy_constraints(p.C, p.l, p.u, p.lb, p.ub)
                return p
            return self._with_slacks_compiled(tp, H, self._gv)
        self._weighted_rows(tp)
        self._hessian(tp, H)
        if not self._soft_idx.size:
            p = self._problem
            np.matmul(self._Jw.T, self._rw, out=p.g)
            np.negative(p.g, out=p.g)
            p.set_constraints(tp.C, tp.l, tp.u, tp.lb, tp.ub)
            return p
        np.matmul(self._Jw.T, self._rw, out=self._gv)
        np.negative(self._gv, out=self._gv)
        return self._with_slacks(tp, H, self._gv)

    def _sqrt_weights(self, tp: TickProblem) -> np.ndarray:
        """Square roots of the tick's stacked weights (recomputed when a weight array changes)."""
        weights = [b.weight for b in tp.blocks]
        if len(weights) != len(self._w_seen) or any(
            w is not s for w, s in zip(weights, self._w_seen, strict=True)
        ):
            self._sw_all = np.sqrt(np.concatenate(weights))
            self._w_seen = weights
        return self._sw_all

    def solve_fused(self, tp: TickProblem) -> tuple[StrategyResult, np.ndarray] | None:
        """The QP of :meth:`assemble`, DAQP's solve and the integration in one kernel call.

        A kernel error turns the fused call off for good (:attr:`fused_error` says why); the
        tick and the next ones are solved by :meth:`solve`.
        """
        if self.fused_error or not self.use_fused:
            return None
        try:
            return self._solve_fused(tp)
        except Exception as exc:  # never stop the loop: the Python path solves from here on
            self.fused_error = repr(exc)
            self._fused_key = None
            return None

    def _solve_fused(self, tp: TickProblem) -> tuple[StrategyResult, np.ndarray] | None:
        """:meth:`solve_fused` itself.

        Used when the tick was compiled, ``W = I`` and the solver calls DAQP from C
        (:meth:`DaqpSolver.fused_settings`); the same QP and the same hot start, so the same
        solution as :meth:`solve`. ``None`` hands the tick to :meth:`solve` (more soft rows in
        play than slack slots, a failed solve).
        """
        ct = tp.compiled
        sv = self._solver
        if ct is None or not isinstance(sv, DaqpSolver) or tp.J_all is None:
            return None
        settings = sv.fused_settings()
        if settings is None or not self._is_eye(tp.W):
            return None
        p = self._problem
        soft = bool(self._soft_idx.size)
        sv.prepare(p)
        buf = self._slot_buf if soft else self._no_slots
        x, lam = sv.buffers()
        # Registered again when one of the arrays is a new one or a solver setting changed.
        key = (p.H, x, lam, buf)
        skey = tuple(settings.values())
        if (
            self._fused_key is None
            or any(a is not b for a, b in zip(key, self._fused_key, strict=True))
            or skey != self._fused_settings
        ):
            ct.tick.set_qp(
                p.H, p.g, p.C, p.l, p.u, p.lb, p.ub, x, lam, soft, buf,
                self._soft_idx64 if soft else self._no_slots, self._soft_w if soft else p.g[:0],
                settings["warm"], settings["primal_tol"], settings["dual_tol"],
                settings["iter_limit"], settings["eps_prox"],
            )  # fmt: skip
            self._fused_key, self._fused_settings = key, skey
        n_last = self._slot_rows.size if soft else 0
        if n_last and self._slot_rows.base is not buf:  # last tick's rows from the Python path
            buf[:n_last] = self._slot_rows
        q_next = np.empty(tp.state.q.size)
        sw = self._sqrt_weights(tp)
        k, flag, iters, ok, smax, t_solve, _ = ct.tick.fused(
            sw, tp.damping * tp.damping, n_last, tp.dt, q_next
        )
        if k < 0:
            return None  # more soft rows in play than slots: solve() grows the QP
        if soft:
            self._slot_rows = buf[:k]
            self._slot_group = self._row_group[self._slot_rows]
        if not ok:
            return None
        x_full = sv.buffers()[0]
        res = StrategyResult(x_full[: self.nv].copy(), True, sv.status_text(flag), iters, t_solve)
        if soft and smax > self.REPORT_TOLERANCE:
            res.slack = self._slacks(x_full)
        return res, q_next

    def _compiled_cost(self, tp: TickProblem, H: np.ndarray) -> bool:
        """:math:`H` and :math:`g` from the kernel when the tick was compiled (same cost).

        Needs the stacked rows (``tp.J_all``) and the identity metric :math:`W = I`.
        """
        ct = tp.compiled
        if ct is None or tp.J_all is None or not self._is_eye(tp.W):
            return False
        g = self._gv if self._soft_idx.size else self._problem.g
        ct.hessian(self._sqrt_weights(tp), tp.damping * tp.damping, H, g)
        return True

    def _is_eye(self, W: np.ndarray) -> bool:
        """``W`` is the identity (tested once per read-only matrix)."""
        if W is not self._W_seen:
            # A read-only W cannot change in place: test once whether it is the identity.
            self._W_seen = W
            self._W_is_eye = not W.flags.writeable and np.array_equal(W, np.eye(len(W)))
        return self._W_is_eye

    def _weighted_rows(self, tp: TickProblem) -> None:
        """Every task's rows times the square root of its weights, stacked in ``_Jw``, ``_rw``."""
        Jw, rw = self._Jw, self._rw
        blocks = tp.blocks
        J_all, v_all = tp.J_all, tp.v_all
        if (
            J_all is not None
            and J_all.shape == Jw.shape
            and v_all is not None
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
            np.multiply(J_all, sw[:, None], out=Jw)
            np.multiply(v_all, sw, out=rw)
            return
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

    def _hessian(self, tp: TickProblem, H: np.ndarray) -> None:
        r""":math:`H = J_w^\top J_w + \lambda^2 W` into ``H`` (nv, nv)."""
        nv = self.nv
        np.matmul(self._Jw.T, self._Jw, out=H)
        lam2 = tp.damping * tp.damping
        if lam2 > 0:
            W = tp.W
            if self._is_eye(W):
                H.flat[:: nv + 1] += lam2
            else:
                H += lam2 * W

    def _with_slacks(self, tp: TickProblem, H: np.ndarray, g: np.ndarray) -> QPProblem:
        """The QP with one slack slot per soft row in play (a finite side), in row order.

        A slack keeps its slot (and the solver its hot start) while the set does not change.
        """
        nv = self.nv
        p = self._problem
        idx = self._soft_idx
        up = np.isfinite(tp.u[idx])
        lo = np.isfinite(tp.l[idx]) & ~up
        play = up | lo
        k = int(play.sum())
        if k > self._n_slots:
            self._allocate_slots(min(idx.size, max(2 * self._n_slots, k)))
            p = self._problem
        rows = idx[play]
        slots = nv + np.arange(k)
        p.C[self._slot_rows, nv + np.arange(self._slot_rows.size)] = 0.0
        p.C[:, :nv] = tp.C
        p.C[rows, slots] = np.where(up[play], -1.0, 1.0)  # relax the finite side (upper first)
        p.H[:nv, :nv] = H
        p.g[:nv] = g
        p.g[nv:] = 0.0
        p.g[slots] = self._soft_w[play]
        p.ub[nv:] = 0.0  # unused slots are fixed at zero
        p.ub[slots] = np.inf
        p.l[...] = tp.l
        p.u[...] = tp.u
        p.lb[:nv] = tp.lb
        p.ub[:nv] = tp.ub
        self._slot_rows = rows
        self._slot_group = self._soft_group[play]
        return p

    def _with_slacks_compiled(self, tp: TickProblem, H: np.ndarray, g: np.ndarray) -> QPProblem:
        """:meth:`_with_slacks` in the kernel: the same QP, slots in row order."""
        k_mod = tp.compiled.module
        buf = self._slot_buf
        n_last = self._slot_rows.size
        if n_last and self._slot_rows.base is not buf:  # last tick's rows from the Python path
            buf[:n_last] = self._slot_rows
        args = (H, g, tp.C, tp.l, tp.u, tp.lb, tp.ub, self._soft_idx64, self._soft_w)
        p = self._problem
        k = k_mod.slack_qp(*args, p.H, p.g, p.C, p.l, p.u, p.lb, p.ub, buf, n_last)
        if k < 0:  # more soft rows in play than slots: grow the QP once (as the Python path)
            self._allocate_slots(min(self._soft_idx.size, max(2 * self._n_slots, -k)))
            p, buf = self._problem, self._slot_buf
            k = k_mod.slack_qp(*args, p.H, p.g, p.C, p.l, p.u, p.lb, p.ub, buf, 0)
        self._slot_rows = buf[:k]
        self._slot_group = self._row_group[self._slot_rows]
        return p

    def _slacks(self, x: np.ndarray) -> dict[str, float]:
        """Soft constraint name -> its largest slack, for the ones that gave (row units)."""
        k = self._slot_rows.size
        s = x[self.nv : self.nv + k]
        out: dict[str, float] = {}
        for j in np.flatnonzero(s > self.REPORT_TOLERANCE):
            name = self._soft[self._slot_group[j]].name
            out[name] = max(out.get(name, 0.0), float(s[j]))
        return out

    def solve(self, tp: TickProblem) -> StrategyResult:
        res = solution_to_result(self._solver.solve(self.assemble(tp)))
        if self._soft_idx.size and res.x is not None:
            res.slack = self._slacks(res.x)
            res.x = res.x[: self.nv].copy()
        return res
