# SPDX-License-Identifier: Apache-2.0
r"""Direct DAQP backend: a dual active-set solver, hot-started from the last tick's active set.

DAQP (Arnström, Bemporad, Axehill 2022) solves the tick's dense QP

.. math::
    \min_x \tfrac12 x^\top H x + g^\top x \quad \text{s.t.} \quad
    x_{min} \le x \le x_{max}, \quad l \le C x \le u

with the box as simple bounds and the rows of :math:`C` as general constraints; a row with
:math:`l = u` is an equality (DAQP ``sense`` 5). Each tick starts from the active set of the
previous solution (constraints whose multiplier was non-zero are marked active, ``sense`` 1), so a
slowly changing problem converges in a few iterations. Unlike ProxSuite, DAQP's result does not
depend on memory alignment: the same QP gives the same solution to the last bit, in any process
(docs/reliability.md), which makes runs repeatable.

Infinite bounds become :math:`\pm 10^{30}`; rows with no finite side this tick (an inactive
collision pair) are not passed at all (DAQP tests every row at every iteration: with 381 pairs that
was most of the solve), their multipliers kept at zero for the next hot start. An infeasible QP,
the iteration limit or a cycling active set is reported as a failed solve (``success=False``),
never an exception.
"""

from __future__ import annotations

import time
from typing import Any, ClassVar

import numpy as np

from ..errors import SolverNotInstalledError
from ..kernel import daqp_kernel
from ..problem import QPProblem
from .base import SOLVERS, QPSolution, QPSolver

#: Stand-in for an infinite bound.
BIG = 1e30

#: DAQP exit flags (its documentation, "parameters") -> status text.
EXITFLAGS = {
    1: "DAQP_OPTIMAL",
    2: "DAQP_SOFT_OPTIMAL",
    -1: "DAQP_INFEASIBLE",
    -2: "DAQP_CYCLING",
    -3: "DAQP_UNBOUNDED",
    -4: "DAQP_ITERLIMIT",
    -5: "DAQP_NONCONVEX",
    -6: "DAQP_OVERDETERMINED_INITIAL",
}


@SOLVERS.register("daqp")
class DaqpSolver(QPSolver):
    """The dense QP of a tick with DAQP, hot-started (module docstring).

    Args:
        primal_tol: primal feasibility tolerance (constraint violation accepted).
        dual_tol: dual feasibility tolerance.
        iter_limit: iterations per solve before it is reported as failed.
        warm_start: start from the previous tick's active set.
        eps_prox: DAQP's proximal term (0: off, for a positive definite H as the damping makes
            it; a solve that finds H singular is retried with 1e-6).

    Raises:
        SolverNotInstalledError: the ``daqp`` package is missing.
    """

    name: ClassVar[str] = "daqp"
    label: ClassVar[str] = "DAQP"
    OPTIONS: ClassVar[tuple[str, ...]] = (
        "primal_tol", "dual_tol", "iter_limit", "warm_start", "eps_prox",
    )  # fmt: skip

    def __init__(
        self,
        primal_tol: float = 1e-9,
        dual_tol: float = 1e-12,
        iter_limit: int = 1000,
        warm_start: bool = True,
        eps_prox: float = 0.0,
    ) -> None:
        try:
            import daqp
        except ImportError:
            raise SolverNotInstalledError(
                "QP solver 'daqp' is not installed: pip install daqp (or the `solvers` extra)."
            ) from None
        self._daqp: Any = daqp
        self.settings = {
            "primal_tol": float(primal_tol),
            "dual_tol": float(dual_tol),
            "iter_limit": int(iter_limit),
            "eps_prox": float(eps_prox),
        }
        self.warm_start = bool(warm_start)
        #: Call DAQP from the compiled kernel when it is installed (same result, less overhead).
        self.compiled = True
        self._shape: tuple[int, int] | None = None
        self._lam: np.ndarray | None = None

    def reset(self) -> None:
        self._lam = None
        if self._shape is not None:
            self._lam_c[...] = 0.0

    def settings_summary(self) -> dict[str, Any]:
        return {**self.settings, "warm_start": self.warm_start}

    def _allocate(self, n: int, m: int) -> None:
        self._shape, self._lam = (n, m), None
        self._x = np.zeros(n)
        self._lam_c = np.zeros(n + m)  # the compiled call's multipliers (zeros: no hot start)

    def fused_settings(self) -> dict[str, Any] | None:
        """Settings for a solve inside a fused kernel call, or ``None`` without DAQP from C."""
        if not self.compiled or daqp_kernel() is None:
            return None
        return {
            "warm": self.warm_start, "primal_tol": self.settings["primal_tol"],
            "dual_tol": self.settings["dual_tol"], "iter_limit": int(self.settings["iter_limit"]),
            "eps_prox": self.settings["eps_prox"],
        }  # fmt: skip

    def prepare(self, problem: QPProblem) -> None:
        """Size the solution and hot-start buffers for ``problem`` (kept while its shape holds)."""
        if self._shape != (problem.n, problem.n_in):
            self._allocate(problem.n, problem.n_in)

    def buffers(self) -> tuple[np.ndarray, np.ndarray]:
        """The solution and multiplier buffers (the hot start) a fused call writes."""
        return self._x, self._lam_c

    def status_text(self, flag: int) -> str:
        """DAQP's exit flag as status text."""
        return EXITFLAGS.get(int(flag), f"DAQP_{int(flag)}")

    def _solve_compiled(self, k: Any, problem: QPProblem, t0: float) -> QPSolution:
        """The same solve through DAQP's C entry point (qpretarget/kernel.py).

        Same inputs, same rows left out, same hot start: the same result to the last bit,
        without the Python work around it.
        """
        p = problem
        flag, iters, ok = k.daqp_solve(
            p.H, p.g, p.C, p.l, p.u, p.lb, p.ub, self._x, self._lam_c, self.warm_start,
            self.settings["primal_tol"], self.settings["dual_tol"],
            int(self.settings["iter_limit"]), self.settings["eps_prox"],
        )  # fmt: skip
        status = EXITFLAGS.get(int(flag), f"DAQP_{int(flag)}")
        x = self._x.copy() if ok else None
        return QPSolution(x, bool(ok), status, int(iters), time.perf_counter() - t0)

    def _fill(
        self, p: QPProblem
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """DAQP's ``A, bu, bl, sense`` and the indices of the rows passed.

        Rows with no finite side are left out (DAQP would test them at every iteration).
        """
        n = p.n
        rows = np.flatnonzero(np.isfinite(p.l) | np.isfinite(p.u))
        if rows.size == p.n_in:
            A = p.C
            lo, hi = p.l, p.u
        else:
            A = p.C[rows]
            lo, hi = p.l[rows], p.u[rows]
        m = rows.size
        bu, bl = np.empty(n + m), np.empty(n + m)
        np.minimum(p.ub, BIG, out=bu[:n])
        np.maximum(p.lb, -BIG, out=bl[:n])
        np.minimum(hi, BIG, out=bu[n:])
        np.maximum(lo, -BIG, out=bl[n:])
        sense = np.zeros(n + m, dtype=np.int32)
        lam = self._lam
        if self.warm_start and lam is not None:  # hot start: last tick's active set
            # (marked active as DAQP's upper side whatever the multiplier's sign: handing the
            # lower side over for negative multipliers cut B+poly's iterations 9 -> 1 but moved
            # the kicks clip's stance slip from 0.85 to 7.7 mm; kept as recorded)
            sense[:n][lam[:n] != 0.0] = 1
            sense[n:][lam[n:][rows] != 0.0] = 1
        sense[bl == bu] = 5
        return np.ascontiguousarray(A, dtype=float), bu, bl, sense, rows

    def solve(self, problem: QPProblem) -> QPSolution:
        t0 = time.perf_counter()
        if self._shape != (problem.n, problem.n_in):
            self._allocate(problem.n, problem.n_in)
        k = daqp_kernel() if self.compiled else None
        if k is not None and problem.H.flags.c_contiguous and problem.C.flags.c_contiguous:
            return self._solve_compiled(k, problem, t0)
        A, bu, bl, sense, rows = self._fill(problem)
        H = np.ascontiguousarray(problem.H, dtype=float)
        g = np.ascontiguousarray(problem.g, dtype=float)
        x, _, flag, info = self._daqp.solve(H, g, A, bu, bl, sense, **self.settings)
        if flag == -5 and self.settings["eps_prox"] == 0.0:
            # A singular H (a strategy's level without damping): DAQP's proximal-point
            # iterations solve it exactly; only this solve pays for them.
            settings = {**self.settings, "eps_prox": 1e-6}
            x, _, flag, info = self._daqp.solve(H, g, A, bu, bl, sense, **settings)
        ok = flag in (1, 2)
        xs = np.array(x, dtype=float) if ok else None
        if xs is not None and not np.all(np.isfinite(xs)):
            xs, ok = None, False
        if ok:  # multipliers of every bound and row (zero for the rows left out)
            lam = np.asarray(info["lam"], dtype=float)
            full = np.zeros(problem.n + problem.n_in)
            full[: problem.n] = lam[: problem.n]
            full[problem.n + rows] = lam[problem.n :]
            self._lam = full
        else:
            self._lam = None
        status = EXITFLAGS.get(int(flag), f"DAQP_{int(flag)}")
        return QPSolution(xs, ok, status, int(info["iterations"]), time.perf_counter() - t0)
