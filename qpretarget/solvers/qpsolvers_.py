# SPDX-License-Identifier: Apache-2.0
"""Adapter to every solver qpsolvers knows (osqp, quadprog, daqp, clarabel, ...), for comparisons.

qpsolvers calls are stateless (no warm start): this backend is for comparing solvers, the native
:class:`~qpretarget.solvers.proxsuite_.ProxSuiteSolver` is the one to run in a loop.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import qpsolvers

from ..errors import SolverNotInstalledError
from ..problem import QPProblem
from .base import SOLVERS, QPSolution, QPSolver

#: Tolerances set explicitly so results are comparable (qpsolvers' own defaults differ widely).
DEFAULT_OPTIONS: dict[str, dict[str, Any]] = {
    # Polishing with a small regularization delta recovers the exact active set; without it OSQP
    # stops 1e-4 away on ticks with many active velocity bounds.
    "osqp": {
        "eps_abs": 1e-8,
        "eps_rel": 1e-8,
        "polishing": True,
        "delta": 1e-9,
        "polish_refine_iter": 50,
        "max_iter": 100000,
        "verbose": False,
    },
    "proxqp": {"eps_abs": 1e-9, "eps_rel": 0.0},
    "clarabel": {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9},
    "piqp": {
        "eps_abs": 1e-9,
        "eps_rel": 1e-9,
        "eps_duality_gap_abs": 1e-10,
        "eps_duality_gap_rel": 1e-10,
    },  # fmt: skip
    "qpalm": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 100000},
    "daqp": {},
    "quadprog": {},
}


def known_qpsolvers() -> list[str]:
    """Names of every solver qpsolvers supports (installed or not)."""
    names = set(getattr(qpsolvers, "solvers", {}).__dict__.get("available_solvers", []))
    names |= set(qpsolvers.available_solvers)
    try:
        from qpsolvers.solvers import dense_solvers, sparse_solvers  # noqa: F401

        names |= set(dense_solvers) | set(sparse_solvers)
    except Exception:  # pragma: no cover - older qpsolvers
        pass
    names |= {"clarabel", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp",
              "kvxopt", "mosek", "osqp", "piqp", "proxqp", "qpalm", "qpoases", "qpswift",
              "quadprog", "scs", "sip"}  # fmt: skip
    return sorted(names)


def installed_qpsolvers() -> list[str]:
    """Names of the qpsolvers backends installed here."""
    return sorted(qpsolvers.available_solvers)


#: Backends that want sparse (CSC) matrices: the dense problem is converted once per call here.
SPARSE_SOLVERS = frozenset({"osqp", "scs", "qpalm"})


class _NullWriter:
    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Drop what a backend prints to ``sys.stdout`` and its pending-deprecation chatter.

    OSQP 1.x prints "Polishing not needed ..." through Python's stdout even with
    ``verbose=False``, and warns on every solve that qpsolvers does not pass ``raise_error``:
    hundreds of lines in a solver comparison that nobody can act on. (Another thread printing
    during the call is silenced too; this is a comparison backend, never the control loop's.)
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
        with contextlib.redirect_stdout(_NullWriter()):
            yield


class QpsolversSolver(QPSolver):
    """Solve with ``qpsolvers.solve_problem(problem, solver=name)``.

    Args:
        solver: qpsolvers solver name.
        **options: solver options, on top of :data:`DEFAULT_OPTIONS`.

    Raises:
        SolverNotInstalledError: when the solver's package is not installed.
    """

    def __init__(self, solver: str, **options: Any) -> None:
        if solver not in qpsolvers.available_solvers:
            raise SolverNotInstalledError(
                f"QP solver {solver!r} is known to qpsolvers but not installed here "
                f"(installed: {', '.join(installed_qpsolvers())}). Install it with "
                f"`pip install qpsolvers[{solver}]` or `pip install {solver}`."
            )
        self.name = solver  # type: ignore[misc]
        self.options = {**DEFAULT_OPTIONS.get(solver, {}), **options}
        # Backends that print when told not to (see _quiet).
        self._silence = solver == "osqp" and not self.options.get("verbose", False)

    passes_options = True

    @classmethod
    def from_options(cls, name: str, options: dict[str, Any], *, path: str) -> QPSolver:
        """``QpsolversSolver(name, **options)``: options go to the backend unchecked."""
        return cls(name.removeprefix("qpsolvers/"), **options)

    def settings_summary(self) -> dict[str, Any]:
        return dict(self.options)

    def solve(self, problem: QPProblem) -> QPSolution:
        t0 = time.perf_counter()
        # Copies: some backends (piqp, qpalm) write into their inputs, which may be read-only.
        parts = {k: None if a is None else np.array(a) for k, a in problem.split().items()}
        if self.name in SPARSE_SOLVERS:  # they take CSC matrices (and warn on dense ones)
            from scipy import sparse

            for key in ("P", "G", "A"):
                if parts[key] is not None:
                    parts[key] = sparse.csc_matrix(parts[key])
        qp = qpsolvers.Problem(**parts)  # type: ignore[arg-type]  # None = no such block
        try:
            if self._silence:
                with _quiet():
                    sol = qpsolvers.solve_problem(qp, solver=self.name, **self.options)
            else:
                sol = qpsolvers.solve_problem(qp, solver=self.name, **self.options)
        except Exception as exc:  # a backend error is a failed tick, not a crash of the loop
            return QPSolution(None, False, f"error: {exc}", solve_time=time.perf_counter() - t0)
        # A copy: piqp and qpalm return read-only views of their own memory.
        x = np.array(sol.x, dtype=float) if sol.x is not None else None
        x = x if x is not None and np.all(np.isfinite(x)) else None
        iters = -1
        extras = getattr(sol, "extras", {}) or {}
        info = extras.get("info")
        info_iter = getattr(info, "iter", None)  # a backend's own info record, if it has one
        if info_iter is not None:
            iters = int(info_iter)
        elif "iter" in extras:
            iters = int(extras["iter"])
        ok = bool(sol.found) if sol.found is not None else x is not None
        return QPSolution(
            x=x,
            success=ok and x is not None,
            status="solved" if ok else "failed",
            iterations=iters,
            solve_time=time.perf_counter() - t0,
        )


# Every solver qpsolvers knows is a registered name (an uninstalled one says how to install it),
# also as ``qpsolvers/<name>`` so that a solver with a native backend here (daqp) can still be
# run through qpsolvers, e.g. to compare the two.
for _name in known_qpsolvers():
    SOLVERS.add(f"qpsolvers/{_name}", QpsolversSolver)
    if _name not in SOLVERS:  # a native backend keeps its own name
        SOLVERS.add(_name, QpsolversSolver)
