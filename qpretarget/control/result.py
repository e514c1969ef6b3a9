# SPDX-License-Identifier: Apache-2.0
"""What one controller tick returns: :class:`StepResult` and its lazy :class:`TaskErrors`."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..tasks import Task


class TaskErrors(Mapping[str, float]):
    """Task name -> error norm, computed on first access (keeps ``step`` cheap when unread)."""

    __slots__ = ("_blocks", "_tasks", "_d")

    _d: dict[str, float] | None

    def __init__(self, blocks: list[Any], tasks: Mapping[str, Task]) -> None:
        self._blocks, self._tasks, self._d = blocks, tasks, None

    def _dict(self) -> dict[str, float]:
        if self._d is None:
            self._d = {b.task: self._tasks[b.task].error_norm(b.error) for b in self._blocks}
        return self._d

    def __getitem__(self, key: str) -> float:
        return self._dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._dict())

    def __len__(self) -> int:
        return len(self._blocks)

    def __repr__(self) -> str:
        return repr(self._dict())


@dataclass(slots=True)
class StepResult:
    """Outcome of one tick.

    Attributes:
        q: configuration after the tick (nq,), read-only.
        v: velocity applied during the tick (nv,), read-only.
        tick: tick counter (1 for the first step after ``reset``).
        t: controller time after the tick [s].
        status: ``"ok"``, ``"relaxed"`` (a constraint gave: a soft row's slack, a box bound in
            the merge or the relaxation fallback; see ``relaxed`` and ``messages``) or ``"held"``
            (no usable solution or the solver's budget ran out: the robot brakes within its
            acceleration limits, feet kept; docs/reliability.md).
        solver_status: status text of the solver.
        task_errors: task name -> error norm at the start of the tick against this tick's target
            (position tasks in [m], orientation-only tasks in [rad]; see each task's error_norm).
        solve_time: time spent in the QP solver(s) [s].
        build_time: time spent building the QP (kinematics excluded) [s].
        step_time: whole ``step`` call [s].
        iterations: solver iterations.
        relaxed: constraint name -> amount it gave (in its own units).
        messages: what a person should know about this tick (missing targets, fallbacks).
        tau: joint torques (nv,) at acceleration level, else ``None``.
    """

    q: np.ndarray
    v: np.ndarray
    tick: int
    t: float
    status: str
    solver_status: str
    task_errors: Mapping[str, float]
    solve_time: float
    build_time: float
    step_time: float
    iterations: int = 0
    relaxed: dict[str, float] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    tau: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        """``True`` when the tick solved without relaxing anything."""
        return self.status == "ok"


__all__ = ["StepResult", "TaskErrors"]
