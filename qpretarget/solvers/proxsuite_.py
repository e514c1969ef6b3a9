# SPDX-License-Identifier: Apache-2.0
"""ProxSuite dense backend: one workspace built once, updated and warm-started every tick.

The workspace is (re)initialised only when the problem's shape changes; afterwards each tick calls
``update`` and ``solve`` starting from the previous primal-dual solution.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from proxsuite import proxqp

from ..problem import INF, QPProblem
from .base import SOLVERS, QPSolution, QPSolver

_SOLVED = proxqp.QPSolverOutput.PROXQP_SOLVED
_STATUS: dict = {}


@SOLVERS.register("proxsuite")
class ProxSuiteSolver(QPSolver):
    """Warm-started dense ProxQP with native box constraints.

    Args:
        eps_abs: absolute tolerance (primal and dual residuals).
        eps_rel: relative tolerance.
        max_iter: iteration cap.
        warm_start: start each tick from the previous solution.
        verbose: print ProxQP's log.
    """

    name = "proxsuite"
    label = "ProxSuite"
    OPTIONS = ("eps_abs", "eps_rel", "max_iter", "warm_start", "verbose")

    def __init__(
        self,
        eps_abs: float = 1e-9,
        eps_rel: float = 0.0,
        max_iter: int = 1000,
        warm_start: bool = True,
        verbose: bool = False,
    ) -> None:
        self.eps_abs, self.eps_rel, self.max_iter = float(eps_abs), float(eps_rel), int(max_iter)
        self.warm_start, self.verbose = bool(warm_start), bool(verbose)
        self._qp: Any = None
        self._shape: tuple[int, int] | None = None
        self._l: np.ndarray | None = None
        self._u: np.ndarray | None = None
        self._keep: np.ndarray | None = None
        self._fresh = True

    def reset(self) -> None:
        self._qp = None
        self._shape = None

    def settings_summary(self) -> dict[str, Any]:
        return {
            "eps_abs": self.eps_abs,
            "eps_rel": self.eps_rel,
            "max_iter": self.max_iter,
            "warm_start": self.warm_start,
        }

    def _fill(self, problem: QPProblem) -> None:
        # Row bounds: +-inf become +-1e20 (ProxSuite's box accepts inf as is, rows are safer so).
        if problem.n_in:
            np.maximum(problem.l, -INF, out=self._l)
            np.minimum(problem.u, INF, out=self._u)

    def _result(self) -> tuple[np.ndarray | None, bool, Any]:
        """``(x, solved, info)`` of the last ProxQP solve (``x`` ``None`` when not finite)."""
        res = self._qp.results
        info = res.info
        ok = info.status == _SOLVED
        x = np.array(res.x, dtype=float)
        if not np.isfinite(x).all():
            return None, False, info
        return x, ok, info

    def solve(self, problem: QPProblem) -> QPSolution:
        t0 = time.perf_counter()
        shape = (problem.n, problem.n_in)
        n, m = shape
        if self._qp is None or shape != self._shape:
            self._l, self._u = np.empty(m), np.empty(m)
            self._fill(problem)
            qp = proxqp.dense.QP(n, 0, m, True)
            s = qp.settings
            s.eps_abs, s.eps_rel = self.eps_abs, self.eps_rel
            s.max_iter, s.verbose = self.max_iter, self.verbose
            qp.init(
                problem.H,
                problem.g,
                None,
                None,
                problem.C,
                self._l,
                self._u,
                problem.lb,
                problem.ub,
            )
            self._fresh = True
            self._keep = self._qp  # keep the old workspace alive until the new one exists
            self._qp, self._shape = qp, shape
        else:
            self._fill(problem)
            C = problem.C if m else None
            self._qp.update(problem.H, problem.g, None, None, C, self._l if m else None,
                            self._u if m else None, problem.lb, problem.ub)  # fmt: skip
        self._qp.solve()
        if self._fresh and self.warm_start:
            # Only once a result exists: ProxSuite 0.8 crashes when asked to warm-start from
            # a previous result before the first solve.
            self._qp.settings.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            self._fresh = False
        x, ok, info = self._result()
        if not ok and not self._fresh and self.warm_start:
            # A warm start far from the new solution can stall ProxQP: retry once cold.
            st = self._qp.settings
            st.initial_guess = proxqp.InitialGuess.NO_INITIAL_GUESS
            self._qp.solve()
            st.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            x, ok, info = self._result()
        if not ok:
            # A failed solve leaves a poor warm start: rebuild the workspace next tick.
            self._shape = None
        status = info.status
        name = _STATUS.get(status)
        if name is None:
            name = _STATUS[status] = str(status).split(".")[-1]
        return QPSolution(x, ok, name, info.iter, time.perf_counter() - t0)
