# SPDX-License-Identifier: Apache-2.0
r"""The level interface: what a control level (velocity, acceleration) supplies to one tick.

:meth:`Controller.step <qpretarget.control.controller.Controller.step>` is the one tick
template: validate ``dt`` -> hand out the targets -> build every block -> :meth:`Level.solve`
-> apply the outcome (constraints' ``after_step``, kinematics update) -> :class:`StepResult`
and observers. A level only turns the tick's :class:`~qpretarget.strategies.TickProblem` into a
:class:`LevelOutcome`; it never touches the controller's state.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field

import numpy as np

from ..strategies import TickProblem


@dataclass(slots=True)
class LevelOutcome:
    """What a level's solve gives back to the tick template.

    Attributes:
        v_next: velocity applied during the tick (nv,).
        q_next: configuration at the end of the tick (nq,).
        status: ``"ok"``, ``"relaxed"`` or ``"held"``.
        solver_status: status text of the (last) solver.
        solve_time: time spent in the QP solver(s) [s].
        iterations: solver iterations.
        relaxed: constraint name -> amount it gave.
        messages: what a person should know about this tick.
        build_time: time spent building the level's own QP (added to the tick's build time) [s].
        tau: joint torques (nv,) at acceleration level, else ``None``.
    """

    v_next: np.ndarray
    q_next: np.ndarray
    status: str
    solver_status: str
    solve_time: float
    iterations: int
    relaxed: dict[str, float] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    build_time: float = 0.0
    tau: np.ndarray | None = None


class Level(abc.ABC):
    """One control level: solves a tick's problem for the motion of the tick.

    Attributes:
        name: the YAML ``level:`` value.
        timings: the controller's per-stage seconds (``Controller.last_timings``), written by
            :meth:`solve` for the stages it runs.
    """

    name: str = "level"

    def __init__(self, timings: dict[str, float]) -> None:
        self.timings = timings

    @abc.abstractmethod
    def solve(self, tp: TickProblem) -> LevelOutcome:
        """Solve the tick built in ``tp`` (never raise on a failed solve: hold and say why)."""

    def reset(self) -> None:
        """Drop warm starts and history (called by ``Controller.reset``)."""


__all__ = ["Level", "LevelOutcome"]
