# SPDX-License-Identifier: Apache-2.0
r"""Infeasibility never kills the loop: relax the hard constraints in a fixed order of importance.

When the tick's QP has no solution (a start outside the joint limits, a pair already penetrating,
the CoM already outside the polygon, a contact set that cannot be kept), the controller hands the
:class:`~qpretarget.strategies.TickProblem` to :meth:`Fallback.solve`, which works in two phases.

**Phase 1: the least relaxation.** With non-negative slacks on both sides of every constraint
row (:math:`s^-, s^+`) and of every box bound (:math:`b^-, b^+`),

.. math::
    \min_{v, s, b \ge 0}\ w^\top (s^- + s^+) + w_{lb}^\top b^- + w_{ub}^\top b^+
        + \tfrac{\epsilon}{2} (|s|^2 + |b|^2) + \tfrac{\rho}{2} |v|^2
    \quad \text{s.t.} \quad l \le C v + s^- - s^+ \le u, \quad
    lb \le v + b^- - b^+ \le ub,

an exact (L1) penalty: a slack is non-zero only where the constraints cannot all hold. The weight
of a slack grows with the importance of the constraint owning the row,
:math:`w = r^{\text{rank}}` (rank 0 for the least important constraint, ratio :math:`r = 10` by
default), so the least important constraint gives first and contacts and joint/velocity limits
give last. A box entry is owned by the most important constraint whose own bound is at (or
tighter than) the merged bound, the one that widening it would violate.

**Phase 2: the best motion within it.** The controller's strategy solves the tick again, with the
rows and bounds widened by the phase-1 slacks only, so tracking is as good as the relaxed
constraints allow (and a hierarchy keeps its priorities). If that fails too, the phase-1 velocity
(the smallest one meeting the relaxed constraints) is used.

Each slack is reported in ``StepResult.relaxed`` under its constraint's name, as the largest slack
of its rows, in the rows' units ([m/s] or [rad/s]: multiply by ``dt`` for a displacement); the
amount a box bound already gave in ``Controller.build_tick``'s merge is added.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import ConfigError, close_matches_hint
from ..problem import QPProblem
from ..solvers import make_solver
from ..solvers.daqp_ import DaqpSolver
from ..strategies import TickProblem
from ..validation import check_keys, positive_float

_KEYS = ("enabled", "ratio", "report_tolerance", "solver", "hard")
#: Bound constraints the fallback never widens by default: the actuators' velocity limits.
DEFAULT_HARD = ("velocity_limits",)


@dataclasses.dataclass(slots=True)
class FallbackResult:
    """Result of a relaxed solve.

    Attributes:
        x: velocity (nv,), or ``None`` when even the relaxation failed.
        relaxed: constraint name -> largest slack of its rows/bounds (row units).
        status: ``"relaxed"`` (phase 2 solved), ``"least-relaxation"`` (phase-1 velocity used)
            or the failing solver status.
        solve_time: time of both phases [s].
    """

    x: np.ndarray | None
    relaxed: dict[str, float]
    status: str
    solve_time: float = 0.0


def make_fallback(controller: Any, spec: Mapping[str, Any] | None) -> Fallback | None:
    """Build the relaxation fallback of ``controller`` from the YAML ``fallback:`` section.

    Args:
        controller: the controller being built (constraints bound, strategy bound).
        spec: ``None`` (defaults) or ``{enabled, ratio, report_tolerance, solver}``.

    Returns:
        The :class:`Fallback`, or ``None`` with ``enabled: false`` (a failed tick then holds).

    Raises:
        ConfigError: unknown keys or bad values, with the YAML path.
    """
    if spec is None:
        spec = {}
    if not isinstance(spec, Mapping):
        raise ConfigError(
            "fallback must be a mapping {enabled, ratio, report_tolerance, solver}, "
            f"got {spec!r}.",
            path="fallback",
        )
    check_keys(spec, _KEYS, "fallback", listed="Allowed keys")
    enabled = spec.get("enabled", True)
    if not isinstance(enabled, bool):
        raise ConfigError(
            f"enabled must be true or false, got {enabled!r}.", path="fallback.enabled"
        )
    if not enabled:
        return None
    try:
        ratio = positive_float(spec.get("ratio", 10.0), "ratio")
        tol = positive_float(spec.get("report_tolerance", 1e-7), "report_tolerance")
    except ConfigError as exc:
        raise ConfigError(exc.bare_message, path="fallback") from None
    if ratio <= 1:
        raise ConfigError(f"ratio must be > 1, got {ratio!r}.", path="fallback.ratio")
    solver_spec = spec.get("solver")
    # DAQP by default: deterministic to the last bit (a ProxSuite phase 1 made runs differ across
    # processes) and it solved the wild-target relaxations ProxSuite called primal infeasible.
    solver = (
        DaqpSolver(warm_start=False)
        if solver_spec is None
        else make_solver(solver_spec, path="fallback.solver")
    )
    hard = spec.get("hard")
    if hard is None:
        hard_names = [
            c.name
            for c in controller.constraints
            if c.type_name in DEFAULT_HARD or c.name in DEFAULT_HARD
        ]
    else:
        if isinstance(hard, str) or not isinstance(hard, Sequence):
            raise ConfigError(
                f"hard must be a list of constraint names, got {hard!r}.", path="fallback.hard"
            )
        hard_names = []
        known = [c.name for c in controller.constraints]
        for i, h in enumerate(hard):
            match = [c for c in controller.constraints if h in (c.name, c.type_name)]
            if not match:
                raise ConfigError(
                    f"no constraint {h!r} in this controller.{close_matches_hint(str(h), known)} "
                    f"Constraints: {', '.join(known)}.",
                    path=f"fallback.hard[{i}]",
                )
            hard_names += [c.name for c in match]
    return Fallback(
        controller, ratio=ratio, report_tolerance=tol, solver=solver, hard=tuple(hard_names)
    )


class Fallback:
    r"""Two-phase relaxation of a tick whose hard constraints conflict (module docstring).

    Args:
        controller: the controller (its constraints, strategy and row layout are read).
        ratio: weight ratio between consecutive importance ranks (> 1).
        report_tolerance: slacks below this are not reported (row units).
        solver: solver of the phase-1 QP (own workspace; the shape is fixed).
        hard: names of bound constraints the fallback never widens (default: velocity limits,
            the actuators' physical limits); every other bound and row may give.
    """

    #: Quadratic regularization of the slacks and of the velocity in phase 1 (ProxSuite needs
    #: some curvature: with 1e-6 it reported feasible relaxations as primal infeasible).
    EPS_SLACK = 1e-4
    RHO_V = 1e-4
    #: Extra widening of the relaxed sides in phase 2, so that phase 1's tolerance cannot make
    #: phase 2 infeasible [row units].
    WIDEN = 1e-4

    def __init__(
        self,
        controller: Any,
        *,
        ratio: float,
        report_tolerance: float,
        solver: Any,
        hard: tuple[str, ...] = (),
    ) -> None:
        self.controller = controller
        self.ratio = ratio
        self.report_tolerance = report_tolerance
        self.solver = solver
        self.hard = hard
        nv, m = controller.robot.nv, controller.n_rows
        self.nv, self.m = nv, m
        levels = sorted({c.importance for c in controller.constraints})
        self.weight_of = {
            c.name: ratio ** levels.index(c.importance) for c in controller.constraints
        }
        # Row groups: constraint -> slice of the stacked rows.
        self.groups: list[tuple[str, slice]] = []
        i = 0
        for con in controller.row_constraints:
            self.groups.append((con.name, slice(i, i + con.n_rows)))
            i += con.n_rows
        w_rows = np.ones(m)
        for name, rows in self.groups:
            w_rows[rows] = self.weight_of[name]
        self._w_rows = w_rows
        self._bound_cons = [c for c in controller.bound_constraints if c.has_bounds]
        self._cap_lo, self._cap_hi = np.full(nv, np.inf), np.full(nv, np.inf)

    # ------------------------------------------------------------------ helpers
    def _box_owners(
        self, tp: Any
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """Weights of the box slacks and, per bound constraint, the entries it owns.

        The owner of a merged bound is the most important constraint whose own bound is at or
        tighter than it (widening the merged bound violates that constraint first). Also sets the
        caps of the box slacks: the relaxed box stays inside the bounds of the ``hard``
        constraints.
        """
        nv = self.nv
        w_lo, w_hi = np.ones(nv), np.ones(nv)
        cap_lo, cap_hi = self._cap_lo, self._cap_hi
        cap_lo.fill(np.inf)
        cap_hi.fill(np.inf)
        free_lo, free_hi = np.ones(nv, dtype=bool), np.ones(nv, dtype=bool)
        own_lo, own_hi = [], []
        lb, ub = tp.lb, tp.ub
        tol_lo = 1e-9 * (1.0 + np.abs(np.where(np.isfinite(lb), lb, 0.0)))
        tol_hi = 1e-9 * (1.0 + np.abs(np.where(np.isfinite(ub), ub, 0.0)))
        bounds: list[tuple[np.ndarray, np.ndarray] | None] = []
        for con in self._bound_cons:  # most important first
            b = con.compute_bounds(tp.state, tp.dt)
            if b is None:
                bounds.append(None)
                own_lo.append(np.zeros(nv, dtype=bool))
                own_hi.append(np.zeros(nv, dtype=bool))
                continue
            clo, chi = b  # each constraint's own buffers: valid through this call
            bounds.append((clo, chi))
            if con.name in self.hard:
                with np.errstate(invalid="ignore"):  # inf - inf where both sides are unbounded
                    room_lo = np.maximum(lb - clo, 0.0)
                    room_hi = np.maximum(chi - ub, 0.0)
                room_lo[~(np.isfinite(clo) & np.isfinite(lb))] = np.inf
                room_hi[~(np.isfinite(chi) & np.isfinite(ub))] = np.inf
                np.minimum(cap_lo, room_lo, out=cap_lo)
                np.minimum(cap_hi, room_hi, out=cap_hi)
            mlo = free_lo & np.isfinite(clo) & (clo >= lb - tol_lo)
            mhi = free_hi & np.isfinite(chi) & (chi <= ub + tol_hi)
            w = self.weight_of[con.name]
            w_lo[mlo] = w
            w_hi[mhi] = w
            free_lo &= ~mlo
            free_hi &= ~mhi
            own_lo.append(mlo)
            own_hi.append(mhi)
        self._own_unowned(lb, ub, free_lo, free_hi, bounds, w_lo, w_hi, own_lo, own_hi)
        return w_lo, w_hi, own_lo, own_hi

    def _own_unowned(
        self,
        lb: np.ndarray,
        ub: np.ndarray,
        free_lo: np.ndarray,
        free_hi: np.ndarray,
        bounds: list[tuple[np.ndarray, np.ndarray] | None],
        w_lo: np.ndarray,
        w_hi: np.ndarray,
        own_lo: list[np.ndarray],
        own_hi: list[np.ndarray],
    ) -> None:
        """Give a merged side that no constraint's bound reaches now to the tightest one.

        The merged box can have a side that none of the bound constraints' bounds, recomputed
        here, reaches (seen on the kata: a merged -9.20 rad/s where the tightest recomputed
        bound, the acceleration limit's, was -9.57): that side had no owner, its slack cost
        the least and widening it was not reported, while it passed the acceleration limit
        (1.87 rad/s over on an ``ok`` tick). Widening such a side violates the constraint with
        the tightest bound there first: it owns the side, its weight prices the slack and the
        amount is reported under its name.
        """
        for free, side, sign, own, w in (
            (free_lo, lb, 1.0, own_lo, w_lo),
            (free_hi, ub, -1.0, own_hi, w_hi),
        ):
            cols = np.flatnonzero(free & np.isfinite(side))
            if cols.size == 0:
                continue
            best = np.full(cols.size, -1)
            tight = np.full(cols.size, -np.inf)
            for k, b in enumerate(bounds):
                if b is None:
                    continue
                c = sign * (b[0] if sign > 0 else b[1])[cols]
                better = np.isfinite(c) & (c > tight)
                best[better] = k
                tight[better] = c[better]
            for k in np.unique(best[best >= 0]):
                sel = cols[best == k]
                own[k][sel] = True
                w[sel] = self.weight_of[self._bound_cons[k].name]

    def _phase1(
        self,
        C: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        lb: np.ndarray,
        ub: np.ndarray,
        w_lo: np.ndarray,
        w_hi: np.ndarray,
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The least relaxation (module docstring), with slacks only where a side is bounded.

        Variables ``x = [v; s-; s+; b-; b+]`` where ``s-`` are the rows with a finite lower side,
        ``s+`` those with a finite upper side, ``b-/b+`` the box entries with a finite side that
        may give (``_box_owners``' caps); rows with no finite side are left out. A slack on an
        unbounded side could only cost, so the optimum is the same as with every slack present,
        in a QP a fraction of the size (inactive collision pairs are most rows).

        Returns:
            ``(solution, s-, s+, b-, b+)``, the slacks at full size (m, m, nv, nv).
        """
        nv, m = self.nv, self.m
        rows = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        r = rows.size
        lr, ur = lo[rows], hi[rows]
        i_lo = np.flatnonzero(np.isfinite(lr))
        i_hi = np.flatnonzero(np.isfinite(ur))
        j_lo = np.flatnonzero(np.isfinite(lb) & (self._cap_lo > 0))
        j_hi = np.flatnonzero(np.isfinite(ub) & (self._cap_hi > 0))
        sizes = (i_lo.size, i_hi.size, j_lo.size, j_hi.size)
        offs = np.cumsum((nv,) + sizes)  # start of s-, s+, b-, b+, and n
        n = int(offs[-1])
        p = QPProblem(n, r + nv)
        p.H[np.arange(nv), np.arange(nv)] = self.RHO_V
        p.H[np.arange(nv, n), np.arange(nv, n)] = self.EPS_SLACK
        p.C[:r, :nv] = C[rows]
        p.C[r:, :nv] = np.eye(nv)
        w = self._w_rows[rows]
        for (idx, row0, sign, weight, cap), start in zip(
            (
                (i_lo, 0, 1.0, w[i_lo], None),
                (i_hi, 0, -1.0, w[i_hi], None),
                (j_lo, r, 1.0, w_lo[j_lo], self._cap_lo[j_lo]),
                (j_hi, r, -1.0, w_hi[j_hi], self._cap_hi[j_hi]),
            ),
            offs[:4],
            strict=True,
        ):
            cols = start + np.arange(idx.size)
            p.C[row0 + idx, cols] = sign
            p.g[cols] = weight
            if cap is not None:
                p.ub[cols] = cap
        p.l[:r], p.u[:r] = lr, ur
        p.l[r:], p.u[r:] = lb, ub
        p.lb[nv:] = 0.0
        sol = self.solver.solve(p)
        s_lo, s_hi, b_lo, b_hi = np.zeros(m), np.zeros(m), np.zeros(nv), np.zeros(nv)
        if sol.x is not None:
            x = np.maximum(sol.x, 0.0)
            s_lo[rows[i_lo]] = x[offs[0] : offs[1]]
            s_hi[rows[i_hi]] = x[offs[1] : offs[2]]
            b_lo[j_lo] = x[offs[2] : offs[3]]
            b_hi[j_hi] = x[offs[3] : offs[4]]
        return sol, s_lo, s_hi, b_lo, b_hi

    # ------------------------------------------------------------------ solve
    def reset(self) -> None:
        """Drop the phase-1 solver's warm start (runs from ``Controller.reset`` reproduce)."""
        self.solver.reset()

    def solve(self, tp: TickProblem, failed_result: Any = None) -> FallbackResult | None:
        """Relax this tick's hard constraints in order of importance and solve again.

        Args:
            tp: the tick problem that failed. Its box ``lb, ub`` is widened in place to the
                relaxed box (the controller clips the applied velocity to it).
            failed_result: the strategy's failed result (unused).

        Returns:
            A :class:`FallbackResult` (``x is None`` when even the relaxation failed); never
            raises on numerical trouble.
        """
        t0 = time.perf_counter()
        nv = self.nv
        C, lo, hi, lb, ub = tp.C, tp.l, tp.u, tp.lb, tp.ub
        if not (np.isfinite(C).all() and not np.isnan(lo).any() and not np.isnan(hi).any()):
            return FallbackResult(None, {}, "non-finite constraint rows", time.perf_counter() - t0)
        w_lo, w_hi, own_lo, own_hi = self._box_owners(tp)
        try:
            sol, s_lo, s_hi, b_lo, b_hi = self._phase1(C, lo, hi, lb, ub, w_lo, w_hi)
        except Exception as exc:  # noqa: BLE001 - the loop must go on
            return FallbackResult(None, {}, f"relaxation failed: {exc}", time.perf_counter() - t0)
        if sol.x is None or not sol.success:
            return FallbackResult(
                None, {}, f"relaxation failed: {sol.status}", time.perf_counter() - t0
            )
        x = sol.x
        tol = self.report_tolerance
        relaxed: dict[str, float] = {}
        for name, rows in self.groups:
            amount = float(max(s_lo[rows].max(initial=0.0), s_hi[rows].max(initial=0.0)))
            if amount > tol:
                relaxed[name] = amount
        for con, mlo, mhi in zip(self._bound_cons, own_lo, own_hi, strict=True):
            amount = max(float(b_lo[mlo].max(initial=0.0)), float(b_hi[mhi].max(initial=0.0)))
            if amount > tol:
                relaxed[con.name] = max(relaxed.get(con.name, 0.0), amount)
        gave = tp.bound_gave
        for name in relaxed:
            relaxed[name] += gave.get(name, 0.0)

        # Phase 2: the strategy again, with only the relaxed sides widened.
        widen = self.WIDEN
        l2 = np.where(s_lo > tol, lo - s_lo - widen, lo)
        u2 = np.where(s_hi > tol, hi + s_hi + widen, hi)
        lb2 = np.where(b_lo > tol, lb - b_lo - widen, lb)
        ub2 = np.where(b_hi > tol, ub + b_hi + widen, ub)
        tp2 = dataclasses.replace(tp, l=l2, u=u2, lb=lb2, ub=ub2)
        v = None
        status = "relaxed"
        try:
            res = self.controller.strategy.solve(tp2)
            if res.success and res.x is not None and np.all(np.isfinite(res.x)):
                v = res.x
        except Exception:  # noqa: BLE001 - the loop must go on; phase 1's velocity is safe
            v = None
        if v is None:
            v = x[:nv].copy()
            status = "least-relaxation"
        # The controller clips the applied velocity to this tick's box: make that the relaxed box.
        tp.lb[...] = lb2
        tp.ub[...] = ub2
        return FallbackResult(v, relaxed, status, time.perf_counter() - t0)

    def __repr__(self) -> str:
        return f"Fallback(ratio={self.ratio}, report_tolerance={self.report_tolerance})"
