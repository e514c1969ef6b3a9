# SPDX-License-Identifier: Apache-2.0
r"""Velocity level (``level: velocity``, the default): the QP's variable is :math:`v`.

One solve: the strategy solves the tick's problem for :math:`v`; when it fails, the relaxation
fallback (``control/relaxation.py``) relaxes the least important hard constraints; when that
fails too, the robot holds (:math:`v = 0`). The configuration is integrated explicitly,
:math:`q^+ = q \oplus v\,dt`.
"""

from __future__ import annotations

import time

import numpy as np

from ..robot import RobotModel
from ..strategies import Strategy, StrategyResult, TickProblem
from .levels import Level, LevelOutcome
from .relaxation import Fallback


def solve_with_fallback(
    strategy: Strategy, fallback: Fallback | None, tp: TickProblem
) -> tuple[np.ndarray | None, StrategyResult, dict[str, float] | None]:
    """Solve ``tp`` with ``strategy``, then with the relaxation ``fallback`` if that failed.

    Returns:
        ``(x, result, relaxed)``: ``x`` is ``None`` when both failed (or gave a non-finite
        solution); ``relaxed`` is ``None`` unless the fallback's solution is used.
    """
    res = strategy.solve(tp)
    x = res.x if res.success and res.x is not None and np.all(np.isfinite(res.x)) else None
    relaxed: dict[str, float] | None = None
    if x is None and fallback is not None:
        fb = fallback.solve(tp, res)
        if fb is not None and fb.x is not None and np.all(np.isfinite(fb.x)):
            x = fb.x
            relaxed = dict(fb.relaxed)
    return x, res, relaxed


class VelocityLevel(Level):
    """The velocity level of a controller.

    Args:
        robot: the controller's robot (integration).
        strategy: the controller's strategy.
        fallback: the relaxation fallback, or ``None`` (a failed tick then holds).
        timings: the controller's per-stage seconds.
    """

    name = "velocity"

    def __init__(
        self,
        robot: RobotModel,
        strategy: Strategy,
        fallback: Fallback | None,
        timings: dict[str, float],
    ) -> None:
        super().__init__(timings)
        self.robot, self.strategy, self.fallback = robot, strategy, fallback

    def solve(self, tp: TickProblem) -> LevelOutcome:
        """One velocity-level solve with fallback and hold (see the module docstring)."""
        ts = time.perf_counter()
        x, res, fb_relaxed = solve_with_fallback(self.strategy, self.fallback, tp)
        # Wall time of strategy + fallback, minus the strategy's own solver time.
        self.timings["assembly"] = time.perf_counter() - ts - res.solve_time
        self.timings["solve"] = res.solve_time
        out = LevelOutcome(
            tp.state.v, tp.state.q, "ok", res.status, res.solve_time, res.iterations,
            dict(tp.bound_gave),
        )  # fmt: skip
        if fb_relaxed is not None:
            out.relaxed.update(fb_relaxed)
            out.messages.append(
                f"tick {tp.tick}: hard constraints conflicted ({res.status}); relaxed {fb_relaxed}."
                if fb_relaxed
                else f"tick {tp.tick}: the QP solver reported {res.status}; the fallback "
                "solved it without relaxing anything."
            )
        if out.relaxed:
            out.status = "relaxed"
        if x is None:
            out.messages.append(
                f"tick {tp.tick}: no usable QP solution (solver status {res.status}); "
                "holding the configuration (v = 0)."
            )
            x = np.zeros(self.robot.nv)
            out.status = "held"
        else:
            # Solvers meet bounds to their tolerance; the box is cheap to meet exactly.
            np.clip(x, tp.lb, tp.ub, out=x)
        out.v_next = x
        out.q_next = self.robot.integrate(tp.state.q, x, tp.dt)
        return out


__all__ = ["VelocityLevel", "solve_with_fallback"]
