# SPDX-License-Identifier: Apache-2.0
"""Solver interface: a registry of backends that solve :class:`~qpretarget.problem.QPProblem`."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..errors import ConfigError, SolverError, close_matches_hint
from ..problem import QPProblem
from ..registry import Registry
from ..validation import check_keys


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


#: Solver name (YAML ``solver: {name: ...}``) -> backend class. A backend registers itself with
#: ``@SOLVERS.register("name")`` in its own module, imported by ``solvers/__init__.py``.
SOLVERS = Registry("solver")


class QPSolver(abc.ABC):
    """A QP backend. ``solve`` may keep state (workspace, warm start) between calls.

    A backend registers itself in :data:`SOLVERS`; :func:`make_solver` builds it with
    :meth:`from_options`.
    """

    name: ClassVar[str] = "solver"
    #: How error messages call the backend.
    label: ClassVar[str] = "solver"
    #: Option keys the backend accepts (checked by the default :meth:`from_options`).
    OPTIONS: ClassVar[tuple[str, ...]] = ()
    #: The backend hands its options to another library unchecked (the qpsolvers adapter): its
    #: names are not listed by :func:`qpretarget.schema.options`.
    passes_options: ClassVar[bool] = False

    @classmethod
    def from_options(cls, name: str, options: dict[str, Any], *, path: str) -> QPSolver:
        """Build the backend registered as ``name`` from its YAML options.

        Raises:
            ConfigError: an option not in :attr:`OPTIONS` (with close names).
        """
        check_keys(options, cls.OPTIONS, path, what=f"{cls.label} option", listed="Options")
        return cls(**options)

    @classmethod
    def option_keys(cls) -> list[str]:
        """The YAML option keys this backend checks (empty: passed through to the backend)."""
        return list(cls.OPTIONS)

    @abc.abstractmethod
    def solve(self, problem: QPProblem) -> QPSolution:
        """Solve ``problem``; never raise on an infeasible or failed solve (report it)."""

    def reset(self) -> None:
        """Drop warm-start information."""

    def settings_summary(self) -> dict[str, Any]:
        """Tolerances and options in force, printed with benchmark results."""
        return {}


#: The backend of a config without ``solver:``: DAQP, hot-started. On the shared G1 workload it is
#: 10-20% faster per tick than ProxSuite at the same accuracy, and bit-reproducible across
#: processes (ProxSuite's result depends on memory alignment in the last bit; docs/solvers.md).
DEFAULT_SOLVER = "daqp"


def split_solver_spec(spec: Any, *, path: str = "solver") -> tuple[str, dict[str, Any]]:
    """Split a ``solver:`` entry (a name, or ``{name, <options>}``) into ``(name, options)``.

    ``None`` or no ``name`` gives :data:`DEFAULT_SOLVER`; ``type:`` is accepted for ``name:``.

    Raises:
        ConfigError: the entry is neither a name nor a mapping.
    """
    if spec is None:
        spec = {"name": DEFAULT_SOLVER}
    if isinstance(spec, str):
        spec = {"name": spec}
    if not isinstance(spec, Mapping):
        raise ConfigError(f"solver must be a name or a mapping, got {spec!r}.", path=path)
    options = dict(spec)
    name = options.pop("name", None) or options.pop("type", None) or DEFAULT_SOLVER
    return str(name), options


def make_solver(spec: str | Mapping[str, Any] | None, *, path: str = "solver") -> QPSolver:
    """Build a solver from a name or ``{name: ..., <options>}`` by looking it up in :data:`SOLVERS`.

    ``daqp`` (the default) and ``proxsuite`` are native warm-started backends; every name
    qpsolvers knows (``osqp``, ``quadprog``, ``clarabel``, ...) is registered by the qpsolvers
    adapter, also as ``qpsolvers/<name>``.

    Raises:
        ConfigError: unknown solver name (with close names) or option keys.
        SolverNotInstalledError: the solver is known but not installed (says how to install it).
    """
    name, options = split_solver_spec(spec, path=path)
    cls: type[QPSolver] | None = SOLVERS.get(name)
    if cls is None:
        known = sorted(SOLVERS)
        raise ConfigError(
            f"solver {name!r} is not known.{close_matches_hint(name, known)} "
            f"Known: {', '.join(known)}.",
            path=f"{path}.name",
        )
    return cls.from_options(name, options, path=path)


__all__ = ["SOLVERS", "QPSolution", "QPSolver", "SolverError", "make_solver", "split_solver_spec"]
