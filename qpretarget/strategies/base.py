# SPDX-License-Identifier: Apache-2.0
"""Strategy interface: turn this tick's cost blocks and constraint rows into one or several QPs.

Tasks and constraints never call a solver; a strategy decides how their blocks become QPs
(augmentation: one weighted QP; hierarchy: one QP per priority level) and which solver solves them.
"""

from __future__ import annotations

import abc
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..registry import Registry
from ..robot import RobotModel, RobotState
from ..solvers import QPSolution, QPSolver
from ..tasks import CostBlock

STRATEGIES = Registry("strategy")


@dataclass(slots=True)
class TickProblem:
    """Everything a strategy needs for one tick.

    Attributes:
        state: kinematics of the configuration the tick starts from.
        dt: tick length [s].
        blocks: cost blocks of every task, in YAML order.
        C, l, u: stacked constraint rows (fixed shape, inactive rows with infinite bounds).
        lb, ub: merged box bounds on the variable.
        W: regularization metric (nv, nv); damping: its lambda.
        tick: tick counter.
        J_all, v_all: when set, every block's ``J`` / ``v_star`` are consecutive rows of these
            stacked buffers (in block order), so a strategy may use them in one product.
        bound_gave: constraint name -> amount its box bound gave when the bounds were merged
            (a less important bound conflicting with more important ones), in its own units.
    """

    state: RobotState
    dt: float
    blocks: list[CostBlock]
    C: np.ndarray
    l: np.ndarray
    u: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    W: np.ndarray
    damping: float
    tick: int
    J_all: np.ndarray | None = None
    v_all: np.ndarray | None = None
    bound_gave: dict[str, float] = field(default_factory=dict)
    #: The controller's :class:`~qpretarget.control.compiled.CompiledTick` when the kernel
    #: built this tick (a strategy may then assemble its QP there too), else ``None``.
    compiled: Any = None


@dataclass(slots=True)
class StrategyResult:
    """Solution of a tick's QP(s).

    Attributes:
        x: decision variable (v at velocity level), or ``None`` on failure.
        success: every QP solved.
        status: solver status text (of the failing level, if any).
        iterations: total solver iterations.
        solve_time: total solver time [s].
        levels: per-level details (hierarchy).
        slack: soft constraint name -> largest slack of its rows (row units), for the
            constraints that gave this tick (see :meth:`Strategy.set_soft_rows`).
    """

    x: np.ndarray | None
    success: bool
    status: str
    iterations: int = 0
    solve_time: float = 0.0
    levels: list[dict[str, Any]] = field(default_factory=list)
    slack: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class SoftRows:
    """The rows of one soft constraint in the stacked ``C, l, u`` (``constraints/base.py``).

    Attributes:
        name: constraint name.
        rows: its slice of the stacked rows.
        weight: exact-penalty weight per unit of slack.
    """

    name: str
    rows: slice
    weight: float


#: Tasks of a controller as ``(name, dim, level)``, in stacking order.
TaskDims = list[tuple[str, int, int]]


class Strategy(abc.ABC):
    """A task-management scheme."""

    type_name: ClassVar[str] = "strategy"

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        """Preallocate for tasks ``(name, dim, level)``, ``n_rows`` constraint rows.

        ``solver_factory()`` returns a new :class:`QPSolver` (one per QP that needs its own warm
        start).
        """
        self.robot = robot
        self.nv = robot.nv
        self.task_dims = task_dims
        self.n_rows = n_rows
        self.solver_factory = solver_factory

    def set_soft_rows(self, soft: list[SoftRows]) -> bool:
        """Give the rows of the soft constraints exact-penalty slacks (called once after bind).

        Returns:
            ``True`` when the strategy handles them; the default keeps every row hard (``False``)
            and an infeasible tick goes to the relaxation fallback.
        """
        return False

    @abc.abstractmethod
    def solve(self, tp: TickProblem) -> StrategyResult:
        """Solve this tick."""

    #: Let :meth:`solve_fused` run when it can (``False``: every QP goes through the strategy's
    #: ``QPSolver.solve``, e.g. to record each one, as ``compare-solvers`` does).
    use_fused: bool = True

    def solve_fused(self, tp: TickProblem) -> tuple[StrategyResult, np.ndarray] | None:
        """Solve the tick and integrate it in one compiled call (``tp.compiled`` set).

        Returns:
            ``(result, q_next)`` with ``result.x`` already within the box, or ``None`` (the
            default: the level solves through :meth:`solve`, as on any tick the compiled call
            does not finish).
        """
        return None

    def reset(self) -> None:
        """Drop warm starts."""

    def solvers(self) -> list[QPSolver]:
        """The solver instances in use."""
        return []

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


def stack_weighted(
    blocks: Sequence[CostBlock], ids: Iterable[int], J: np.ndarray, r: np.ndarray
) -> None:
    r"""Rows :math:`\sqrt{w_i} J_i` and :math:`\sqrt{w_i} v^*_i` of the blocks ``ids``, stacked.

    Written into ``J`` (m, nv) and ``r`` (m,) in the order of ``ids`` (Dariush 2009 eq. 9 rows of
    the weighted least-squares cost).
    """
    i = 0
    for bi in ids:
        b = blocks[bi]
        m = b.J.shape[0]
        sw = np.sqrt(b.weight)
        np.multiply(b.J, sw[:, None], out=J[i : i + m])
        np.multiply(b.v_star, sw, out=r[i : i + m])
        i += m


def solution_to_result(sol: QPSolution) -> StrategyResult:
    """Wrap a single QP solution."""
    return StrategyResult(sol.x, sol.success, sol.status, max(sol.iterations, 0), sol.solve_time)
