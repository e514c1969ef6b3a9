# SPDX-License-Identifier: Apache-2.0
r"""Velocity level (``level: velocity``, the default): the QP's variable is :math:`v`.

One solve: the strategy solves the tick's problem for :math:`v`. The soft rows (collision and
ground margins, the CoM polygon: ``constraints/base.py``) carry exact-penalty slacks inside that
QP, so from a state the controller produced it always has a solution; a slack that is used is
reported in ``StepResult.relaxed`` (status ``relaxed``). When the QP still fails as infeasible
(a start outside the hard set, a strategy without slacks), the relaxation fallback
(``control/relaxation.py``) relaxes the least important hard constraints. When the solver runs out
of its iteration budget (:data:`BUDGET_STATUSES`) the fallback is skipped (it would cost two more
solves) and so is a fallback that fails: the tick *brakes* (:func:`braking_velocity`: every joint
slows down at its acceleration limit within the tick's box, the floating base keeps the contacts
to first order), is flagged ``held`` and says why — never :math:`v = 0` from full speed. The
configuration is integrated explicitly, :math:`q^+ = q \oplus v\,dt`.

Corrector steps: a row constraint with ``refine_rows`` (the contacts) compares what its rows
asked for with what the solved step reaches at :math:`q^+`; when they differ it shifts its rows
and the tick is solved again, the same way (``VelocityLevel._refine``).
"""

from __future__ import annotations

import time

import numpy as np

from ..constraints.base import Constraint
from ..robot import RobotModel
from ..strategies import Strategy, StrategyResult, TickProblem
from .levels import Level, LevelOutcome
from .relaxation import Fallback

#: Solver statuses meaning "ran out of its per-tick budget", not "infeasible": no fallback. (An
#: active-set solver says so reliably; ProxSuite's iteration limit is also how it often ends on
#: an infeasible QP, so it still goes to the fallback.)
BUDGET_STATUSES = frozenset({"DAQP_ITERLIMIT", "DAQP_CYCLING"})


def braking_velocity(tp: TickProblem) -> np.ndarray:
    r"""The velocity of a tick with no usable QP solution: brake, keep the feet.

    :math:`v_b = \operatorname{clip}(0, lb, ub)`: the box merges the acceleration limits around
    the previous velocity, so every limited joint slows down by at most :math:`a_{max} dt`
    towards zero (and stays viable for its position limits). Then the smallest correction
    :math:`\Delta = E^+ (b - E v_b)` meets the tick's equality rows :math:`E v = b` (the
    contacts), and the result is clipped to the box again. No solver, bounded time.
    """
    v = np.clip(0.0, tp.lb, tp.ub)
    eq = np.isfinite(tp.u) & (tp.l == tp.u)
    if eq.any():
        E = tp.C[eq]
        r = tp.u[eq] - E @ v
        if np.all(np.isfinite(r)) and np.all(np.isfinite(E)):
            dv, *_ = np.linalg.lstsq(E, r, rcond=1e-10)
            if np.all(np.isfinite(dv)):
                v = np.clip(v + dv, tp.lb, tp.ub)
    v[~np.isfinite(v)] = 0.0
    return v


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
    if x is not None and res.slack:
        relaxed = dict(res.slack)
    if x is None and fallback is not None and res.status not in BUDGET_STATUSES:
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
        refiners: list[tuple[Constraint, slice]] | None = None,
    ) -> None:
        super().__init__(timings)
        self.robot, self.strategy, self.fallback = robot, strategy, fallback
        #: Row constraints with a corrector step (``Constraint.refine_rows``) and their rows.
        self.refiners = refiners or []
        #: Extra solves of the last tick's corrector steps.
        self.refined = 0

    def _solve_once(
        self, tp: TickProblem
    ) -> tuple[np.ndarray | None, StrategyResult, dict[str, float] | None, np.ndarray | None]:
        """One solve of ``tp``: ``(x, result, relaxed, q_next)``.

        A compiled tick may solve and integrate in one kernel call (docs/benchmarks.md;
        ``q_next`` is then its integration, else ``None``); any tick it does not finish
        cleanly is solved by :func:`solve_with_fallback`.
        """
        fused = self.strategy.solve_fused(tp) if tp.compiled is not None else None
        if fused is not None:
            res, q_next = fused
            return res.x, res, (dict(res.slack) if res.slack else None), q_next
        x, res, relaxed = solve_with_fallback(self.strategy, self.fallback, tp)
        return x, res, relaxed, None

    def solve(self, tp: TickProblem) -> LevelOutcome:
        """One velocity-level solve with fallback and hold (see the module docstring)."""
        ts = time.perf_counter()
        x, res, fb_relaxed, q_next = self._solve_once(tp)
        # Wall time of strategy + fallback, minus the strategy's own solver time.
        self.timings["assembly"] = time.perf_counter() - ts - res.solve_time
        self.timings["solve"] = res.solve_time
        out = LevelOutcome(
            tp.state.v, tp.state.q, "ok", res.status, res.solve_time, res.iterations,
            dict(tp.bound_gave),
        )  # fmt: skip
        if tp.bound_gave:
            out.messages.append(
                f"tick {tp.tick}: box bounds gave to more important ones (rad/s): "
                f"{_fmt(tp.bound_gave)}."
            )
        if fb_relaxed is not None and res.success:
            out.relaxed.update(fb_relaxed)
            out.messages.append(
                f"tick {tp.tick}: soft constraints gave (exact-penalty slack, row units): "
                f"{_fmt(fb_relaxed)}."
            )
        elif fb_relaxed is not None:
            out.relaxed.update(fb_relaxed)
            out.messages.append(
                f"tick {tp.tick}: hard constraints conflicted ({res.status}); relaxed "
                f"{_fmt(fb_relaxed)}."
                if fb_relaxed
                else f"tick {tp.tick}: the QP solver reported {res.status}; the fallback "
                "solved it without relaxing anything."
            )
        if out.relaxed:
            out.status = "relaxed"
        if x is None:
            why = (
                "the solver ran out of its per-tick budget"
                if res.status in BUDGET_STATUSES
                else "no usable QP solution"
            )
            out.messages.append(
                f"tick {tp.tick}: {why} (solver status {res.status}); braking at the "
                "acceleration limits with the feet kept (a bug to report if it repeats)."
            )
            x = braking_velocity(tp)
            out.status = "held"
        elif q_next is None:
            # Solvers meet bounds to their tolerance; the box is cheap to meet exactly.
            np.clip(x, tp.lb, tp.ub, out=x)
        out.v_next = x
        out.q_next = self.robot.integrate(tp.state.q, x, tp.dt) if q_next is None else q_next
        self.refined = 0
        if self.refiners and out.status != "held":
            self._refine(tp, out)
        return out

    def _refine(self, tp: TickProblem, out: LevelOutcome) -> None:
        """Corrector steps: rows shifted by what the solved step did not predict, solved again.

        Each refining constraint (``Constraint.refine_rows``) compares its rows' request with
        the configuration the solved velocity reaches and shifts its bounds; while any does,
        the tick is solved again (the same QP with those bounds, hot-started), at most the
        constraints' ``refine_iterations`` times. A solve that fails keeps the last motion.
        """
        n_max = max(c.refine_iterations for c, _ in self.refiners)
        kernel = tp.compiled.tick if tp.compiled is not None else None
        # What the first solve relaxed stays relaxed: the fallback widened this tick's box in
        # place (RelaxationFallback.solve), so a corrector solve inside that box succeeds
        # without reporting it (an acceleration limit 0.09 rad/s over on an "ok" tick).
        first: dict[str, float] | None = None
        for _ in range(n_max):
            changed = False
            for con, rows in self.refiners:
                if con.refines() and con.refine_rows(
                    tp.state, out.q_next, tp.dt, tp.l[rows], tp.u[rows], kernel
                ):
                    changed = True
            if not changed:
                return
            if first is None:  # copied on a corrector solve only, not every tick
                first = dict(out.relaxed)
            ts = time.perf_counter()
            x, res, relaxed, q_next = self._solve_once(tp)
            self.timings["solve"] += res.solve_time
            self.timings["assembly"] += time.perf_counter() - ts - res.solve_time
            out.solve_time += res.solve_time
            out.iterations += res.iterations
            self.refined += 1
            if x is None or not np.all(np.isfinite(x)):
                out.messages.append(
                    f"tick {tp.tick}: a corrector solve failed ({res.status}); the last "
                    "solved motion is kept."
                )
                return
            if q_next is None:
                np.clip(x, tp.lb, tp.ub, out=x)
            gave = {**first, **tp.bound_gave}
            for name, amount in (relaxed or {}).items():
                gave[name] = max(gave.get(name, 0.0), amount)
            out.relaxed = gave
            out.status = "relaxed" if gave else "ok"
            out.v_next = x
            out.q_next = self.robot.integrate(tp.state.q, x, tp.dt) if q_next is None else q_next


def _fmt(amounts: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.3g}" for k, v in amounts.items()) or "nothing"


__all__ = ["BUDGET_STATUSES", "VelocityLevel", "braking_velocity", "solve_with_fallback"]
