# SPDX-License-Identifier: Apache-2.0
"""Solver interface: a registry of backends that solve :class:`~qpretarget.problem.QPProblem`."""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..errors import ConfigError, SolverError, close_matches_hint
from ..problem import QPProblem


@dataclass(slots=True)
class QPSolution:
    """Result of one QP solve.

    Attributes:
        x: primal solution (n,), or ``None`` when the solver returned nothing usable.
        success: the solver reports an optimal solution within its tolerances.
        status: solver status text.
        iterations: iterations (``-1`` when the backend does not say).
        solve_time: wall time of the solver call [s].
        extras: backend-specific details.
    """

    x: np.ndarray | None
    success: bool
    status: str
    iterations: int = -1
    solve_time: float = 0.0
    extras: dict[str, Any] = field(default_factory=dict)


class QPSolver(abc.ABC):
    """A QP backend. ``solve`` may keep state (workspace, warm start) between calls."""

    name: ClassVar[str] = "solver"

    @abc.abstractmethod
    def solve(self, problem: QPProblem) -> QPSolution:
        """Solve ``problem``; never raise on an infeasible or failed solve (report it)."""

    def reset(self) -> None:
        """Drop warm-start information."""

    def settings_summary(self) -> dict[str, Any]:
        """Tolerances and options in force, printed with benchmark results."""
        return {}


def make_solver(spec: str | dict[str, Any] | None, *, path: str = "solver") -> QPSolver:
    """Build a solver from a name or ``{name: ..., <options>}``.

    ``proxsuite`` is the native warm-started backend; any other name is handed to qpsolvers
    (``osqp``, ``quadprog``, ``daqp``, ``clarabel``, ...).

    Raises:
        ConfigError: unknown option keys. SolverNotInstalledError: solver not installed.
    """
    from .proxsuite_ import ProxSuiteSolver
    from .qpsolvers_ import QpsolversSolver, known_qpsolvers

    if spec is None:
        spec = {"name": "proxsuite"}
    if isinstance(spec, str):
        spec = {"name": spec}
    if not isinstance(spec, dict):
        raise ConfigError(f"solver must be a name or a mapping, got {spec!r}.", path=path)
    spec = dict(spec)
    name = spec.pop("name", None) or spec.pop("type", None) or "proxsuite"
    if name == "proxsuite":
        allowed = ProxSuiteSolver.OPTIONS
        for key in spec:
            if key not in allowed:
                raise ConfigError(
                    f"unknown ProxSuite option {key!r}.{close_matches_hint(key, allowed)} "
                    f"Options: {', '.join(allowed)}.",
                    path=f"{path}.{key}",
                )
        return ProxSuiteSolver(**spec)
    known = known_qpsolvers()
    if name not in known:
        raise ConfigError(
            f"solver {name!r} is not known.{close_matches_hint(name, ['proxsuite', *known])} "
            f"Known: proxsuite, {', '.join(known)}.",
            path=f"{path}.name",
        )
    return QpsolversSolver(name, **spec)


__all__ = ["QPSolution", "QPSolver", "SolverError", "make_solver"]
