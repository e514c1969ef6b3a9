# SPDX-License-Identifier: Apache-2.0
r"""Constrained resolved acceleration control, CRAC (Bin Hammam et al. 2015, eq. 9-11, 30-42).

``level: acceleration`` in a controller's YAML makes :class:`AccelerationLevel` the
:class:`~qpretarget.control.levels.Level` that :meth:`Controller.step` solves each tick with.
It reuses the controller's task and constraint modules, its regularization metric :math:`W`
and its strategy (augmentation, hierarchy, ...): one tick is

1. **Velocity-level reference** :math:`\dot q_c` (CRAC eq. 16 / 41): the controller's own
   velocity-level problem for the same targets, solved by a second instance of its strategy, with
   every hard constraint (foot contacts as equality rows, hence first priority as in eq. 41).
2. **Resolved acceleration** :math:`\alpha` (CRAC eq. 9-11, 13-14, 32) as a QP. Every task block
   keeps its Jacobian and weight; its reference becomes

   .. math::
       J_i \alpha \approx a^*_i - \dot J_i \dot q, \qquad
       a^*_i = a_{d,i} + K_v (v_{d,i} - J_i \dot q) + K_p e_i \quad \text{(CRAC eq. 11)},

   and the same strategy solves it, so augmentation, hierarchy and any regularization work at
   acceleration level. Hard constraints are transcribed from the velocity level: a velocity-level
   row :math:`l \le C v \le u` (or box bound) must hold for the velocity reached at the end of the
   tick, :math:`v^+ = \dot q + \alpha_c\,dt`, i.e.

   .. math::
       \frac{l - C \dot q}{dt} - C s \le C \alpha \le \frac{u - C \dot q}{dt} - C s,
       \qquad s = G_v (\dot q_c - \dot q).

   With the semi-implicit integration below, :math:`q^+ = q \oplus v^+ dt`, the joint-limit bound
   :math:`\gamma (q_{min} - q)/dt \le v^+ \le \gamma (q_{max} - q)/dt` keeps :math:`q^+` inside
   its limits and the velocity bound keeps :math:`|v^+| \le v_{max}`: the limits hold over the
   tick, for the acceleration actually applied. Equality rows (foot contacts,
   :math:`J_f v = -k\,e_f` with drift correction) stay equalities on :math:`\alpha`, hence the
   first priority of CRAC eq. 34-42.
3. **Constrained resolved acceleration** (CRAC eq. 31)
   :math:`\alpha_c = \alpha + G_v (\dot q_c - \dot q)`, torques by RNEA (CRAC eq. 30)
   :math:`\tau = H \alpha_c + C(q, \dot q)\dot q + \tau_g`, and the state is integrated
   semi-implicitly (symplectic Euler): :math:`\dot q^+ = \dot q + \alpha_c dt`,
   :math:`q^+ = q \oplus \dot q^+ dt` (pinocchio ``integrate``).

Without active constraints, for a task with :math:`J J^\dagger = I`, the task error obeys CRAC
eq. 33, :math:`\ddot e + K_v \dot e + K_p e = -J G_v (\dot q_c - \dot q)`; with
:math:`J \dot q_c = v_d + K e` (the velocity-level gain :math:`K`) the right side is
:math:`-G_v (K e + \dot e)` and the closed loop is
:math:`\ddot e + (K_v + G_v)\dot e + (K_p + G_v K) e = 0`; with :math:`G_v = 0` it is the
critically damped :math:`\ddot e + K_v \dot e + K_p e = 0` of the paper's gains.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..registry import build_from_spec
from ..robot import RobotModel, RobotState
from ..strategies import Strategy, StrategyResult, TickProblem
from ..tasks import CostBlock, Task
from ..validation import positive_float
from .levels import Level, LevelOutcome
from .relaxation import Fallback
from .velocity import braking_velocity, solve_with_fallback

#: ``Task.drift_kind`` of a task whose drift is a finite difference of its Jacobian.
FD = "finite_difference"

#: Damping :math:`\lambda` of CRAC section 5, used when the YAML's ``regularization`` gives none.
PAPER_DAMPING = 0.1


@dataclass(frozen=True, slots=True)
class AccelerationGains:
    r"""The YAML ``acceleration:`` section (CRAC section 5 defaults).

    Args:
        kp: position gain :math:`K_p` [1/s^2] of CRAC eq. 11.
        kv: velocity gain :math:`K_v` [1/s]; ``None`` gives the critically damped
            :math:`2\sqrt{K_p}`.
        gv: joint velocity gain :math:`G_v` [1/s] of CRAC eq. 31 pulling :math:`\dot q` towards
            the velocity-level solution :math:`\dot q_c`; 0 turns the pull off.
        velocity_gain: task gain :math:`K` [1/s] of the velocity-level reference
            :math:`v^* = v_d + K e` (CRAC eq. 15) used for :math:`\dot q_c`; ``None`` uses each
            task's own ``gain`` (the velocity-level controller's reference, capped at ``1/dt``).
    """

    kp: float = 300.0
    kv: float | None = None
    gv: float = 30.0
    velocity_gain: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kp", positive_float(self.kp, "kp [1/s^2]"))
        kv = 2.0 * math.sqrt(self.kp) if self.kv is None else positive_float(self.kv, "kv [1/s]")
        object.__setattr__(self, "kv", kv)
        object.__setattr__(self, "gv", positive_float(self.gv, "gv [1/s]", allow_zero=True))
        if self.velocity_gain is not None:
            vg = positive_float(self.velocity_gain, "velocity_gain [1/s]")
            object.__setattr__(self, "velocity_gain", vg)


class AccelerationLevel(Level):
    r"""CRAC at acceleration level: the :class:`~qpretarget.control.levels.Level` of that name.

    The controller's strategy solves the acceleration QP, a second instance of the same strategy
    (``make_strategy()``) solves the velocity-level reference :math:`\dot q_c`.

    Args:
        robot: the controller's robot.
        tasks: the controller's tasks, in YAML order.
        n_rows: number of constraint rows of the controller's QP.
        strategy: the controller's strategy (solves the acceleration QP).
        make_strategy: builds a second, independent instance of the strategy (own solvers, own
            warm start) for :math:`\dot q_c`.
        fallback: the relaxation fallback of the velocity-level reference, or ``None``.
        damping: :math:`\lambda` of both QPs (the YAML's ``regularization.damping``, else
            :data:`PAPER_DAMPING`).
        timings: the controller's per-stage seconds.
        spec: the YAML ``acceleration:`` mapping (keys of :class:`AccelerationGains`) or ``None``.

    Attributes:
        gains: the :class:`AccelerationGains` in force.
        damping: :math:`\lambda` of both QPs.
        alpha: resolved acceleration :math:`\alpha` of the last tick (nv,).
        alpha_c: constrained resolved acceleration :math:`\alpha_c` of the last tick (nv,).
        qdot_c: velocity-level reference :math:`\dot q_c` of the last tick (nv,).

    Raises:
        ConfigError: on an invalid ``acceleration:`` section.
    """

    name = "acceleration"

    def __init__(
        self,
        robot: RobotModel,
        tasks: list[Task],
        n_rows: int,
        strategy: Strategy,
        make_strategy: Callable[[], Strategy],
        fallback: Fallback | None,
        damping: float,
        timings: dict[str, float],
        spec: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__(timings)
        if spec is None:
            spec = {}
        if not isinstance(spec, Mapping):
            raise ConfigError(
                f"expected a mapping such as {{kp: 300, kv: null, gv: 30}}, got {spec!r}.",
                path="acceleration",
            )
        self.gains: AccelerationGains = build_from_spec(
            AccelerationGains, dict(spec), path="acceleration"
        )
        self.robot = robot
        self.model = robot.model
        self.strategy, self.fallback, self.damping = strategy, fallback, damping
        self.velocity_strategy = make_strategy()
        self._dyn_data = self.model.createData()  # RNEA works on its own data
        self._tasks: list[Task] = list(tasks)
        nv = robot.nv
        # Drift terms (each task's ``drift_kind``): exact for frame tasks (classical
        # acceleration) and the CoM (pinocchio), zero for constant Jacobians, finite differences
        # for any other task.
        self._drift_kind: list[str] = [t.drift_kind for t in self._tasks]
        self._n_rows = n_rows
        self._fd_state = RobotState(robot) if FD in self._drift_kind else None
        self._zero_v = np.zeros(nv)
        self._lb, self._ub = np.empty(nv), np.empty(nv)  # bounds on alpha
        self._lbv, self._ubv = np.empty(nv), np.empty(nv)  # velocity-level box containing qdot_c
        self._l = np.empty(n_rows)
        self._u = np.empty(n_rows)
        self._prev_vd: dict[str, np.ndarray] = {}
        m = sum(t.dim for t in self._tasks)
        #: Stacked acceleration references of every task, in task order (m,).
        self.a_all = np.zeros(m)
        self._vg_all = np.zeros(m)  # velocity references with ``velocity_gain``
        self.alpha = np.zeros(nv)
        self.alpha_c = np.zeros(nv)
        self.qdot_c = np.zeros(nv)

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Drop warm starts and feed-forward history (called by ``Controller.reset``)."""
        self.velocity_strategy.reset()
        self._prev_vd.clear()
        self.alpha = np.zeros(self.robot.nv)
        self.alpha_c = np.zeros(self.robot.nv)
        self.qdot_c = np.zeros(self.robot.nv)

    # ------------------------------------------------------------------ maths
    def compute_drifts(self, state: RobotState) -> list[np.ndarray]:
        r"""Drift :math:`\dot J_i \dot q` of every task (CRAC eq. 9), in task order.

        Runs one ``forwardKinematics(q, v, 0)`` on the state's data (joint velocities and
        bias accelerations; the cached Jacobians are untouched).
        """
        model, data, q, v = self.model, state.data, state.q, state.v
        pin.forwardKinematics(model, data, q, v, self._zero_v)
        out: list[np.ndarray] = []
        com_acc = None
        fd_J: dict[int, np.ndarray] = {}
        if self._fd_state is not None:
            # Finite difference of J along v for tasks without an analytic drift: J(q + h v) v.
            h = 1e-7
            self._fd_state.update(pin.integrate(model, q, v * h), v)
            for i, (t, kind) in enumerate(zip(self._tasks, self._drift_kind, strict=True)):
                if kind == FD:
                    # Copy first: a task may return one internal buffer; evaluate at ``state``
                    # last so such a buffer ends up holding this tick's Jacobian.
                    J_h = t.compute_jacobian(self._fd_state).copy()
                    fd_J[i] = (J_h - t.compute_jacobian(state)) @ v / h
        for i, (t, kind) in enumerate(zip(self._tasks, self._drift_kind, strict=True)):
            if kind == "zero":
                out.append(np.zeros(t.dim))
            elif kind == "analytic":
                out.append(np.asarray(t.compute_jdot_v(state), dtype=float))
            elif kind == "com":
                if com_acc is None:
                    pin.centerOfMass(model, data, pin.KinematicLevel.ACCELERATION, False)
                    com_acc = data.acom[0].copy()
                out.append(com_acc[t.rows])  # type: ignore[attr-defined]
            else:  # kind == FD
                out.append(fd_J[i])
        return out

    def acceleration_blocks(self, tp: TickProblem, drifts: list[np.ndarray]) -> list[CostBlock]:
        r"""Acceleration-QP blocks, reference :math:`a^*_i - \dot J_i \dot q` (CRAC eq. 11).

        :math:`v_{d,i}` is the task's feed-forward velocity (its ``v_star`` minus :math:`K e`,
        non-zero only with ``feedforward: true``); :math:`a_{d,i}` its finite difference over
        the ticks. The references are rows of one stacked buffer (:attr:`a_all`), like the
        velocity level's, so strategies can weight them in one product.
        """
        g, v, dt = self.gains, tp.state.v, tp.dt
        kv = g.kv
        assert kv is not None  # AccelerationGains fills it in
        a_all = self.a_all
        blocks = []
        i = 0
        for t, b, jdv in zip(self._tasks, tp.blocks, drifts, strict=True):
            seg = a_all[i : i + t.dim]
            np.multiply(b.error, g.kp, out=seg)  # K_p e
            seg -= jdv
            if t.feedforward:
                vd = b.v_star - t.effective_gain(dt) * b.error
                prev = self._prev_vd.get(t.name)
                seg += kv * vd
                if prev is not None:
                    seg += (vd - prev) / dt  # a_d
                self._prev_vd[t.name] = vd
            if tp.J_all is None:
                seg -= kv * (b.J @ v)
            blocks.append(CostBlock(b.task, b.J, seg, b.weight, b.level, b.error))
            i += t.dim
        if tp.J_all is not None:
            a_all -= kv * (tp.J_all @ v)  # - K_v J v for every task in one product
        return blocks

    def _velocity_blocks(self, tp: TickProblem) -> list[CostBlock]:
        """The velocity-level blocks, with ``velocity_gain`` replacing the tasks' gain if set."""
        K = self.gains.velocity_gain
        if K is None:
            return tp.blocks
        Kc = min(K, 1.0 / tp.dt)
        out, i = [], 0
        for t, b in zip(self._tasks, tp.blocks, strict=True):
            seg = self._vg_all[i : i + t.dim]
            np.multiply(b.error, Kc - t.effective_gain(tp.dt), out=seg)
            seg += b.v_star
            out.append(CostBlock(b.task, b.J, seg, b.weight, b.level, b.error))
            i += t.dim
        return out

    # ------------------------------------------------------------------ the tick
    def solve(self, tp: TickProblem) -> LevelOutcome:
        """One CRAC tick (see the module docstring); the outcome carries ``tau``."""
        state, dt, timings = tp.state, tp.dt, self.timings
        tp.damping = self.damping
        td = time.perf_counter()
        drifts = self.compute_drifts(state)
        timings["drift"] = time.perf_counter() - td
        build_time = timings["drift"]

        # 1. Velocity-level reference qdot_c (CRAC eq. 16 / 41). Conflicting hard constraints are
        #    relaxed here, once per tick, by the relaxation fallback (when installed).
        blocks_v = self._velocity_blocks(tp)
        tp_v = TickProblem(
            state, dt, blocks_v, tp.C, tp.l, tp.u, tp.lb, tp.ub, tp.W, tp.damping, tp.tick,
            tp.J_all, tp.v_all if blocks_v is tp.blocks else self._vg_all, tp.bound_gave,
        )  # fmt: skip
        tv = time.perf_counter()
        qdot_c, res_v, rel_v = solve_with_fallback(self.velocity_strategy, self.fallback, tp_v)
        timings["velocity_qp"] = time.perf_counter() - tv
        out = LevelOutcome(
            state.v, state.q, "ok", res_v.status, res_v.solve_time, res_v.iterations,
            dict(tp.bound_gave),
        )  # fmt: skip
        out.relaxed.update(rel_v or {})
        if rel_v is not None:
            out.messages.append(
                f"tick {tp.tick}: hard constraints conflicted ({res_v.status}); relaxed {rel_v}."
            )
        if out.relaxed:
            out.status = "relaxed"
        if qdot_c is None:
            out.v_next = self._hold(tp, res_v, out)
        else:
            out.v_next = self._accelerate(tp, drifts, qdot_c, rel_v is not None, out)
        out.build_time += build_time
        self._finish(tp, out)
        return out

    def _hold(self, tp: TickProblem, res_v: StrategyResult, out: LevelOutcome) -> np.ndarray:
        """No velocity-level solution: brake as the velocity level does.

        Never ``v+ = 0`` from full speed: :func:`~qpretarget.control.velocity.braking_velocity`,
        every limited joint slowing by ``a_max dt`` within the tick's box, the contacts kept to
        first order.
        """
        v_b = braking_velocity(tp)
        self.qdot_c = v_b.copy()
        self.alpha = (v_b - tp.state.v) * (1.0 / tp.dt)
        out.status = "held"
        out.messages.append(
            f"tick {tp.tick}: no usable velocity-level solution (solver status "
            f"{res_v.status}); braking at the acceleration limits with the feet kept."
        )
        return v_b

    def _transcribe_constraints(
        self, tp: TickProblem, qdot_c: np.ndarray, s: np.ndarray, widen: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Bounds and rows on :math:`\alpha` from the velocity-level ones (CRAC eq. 34-42).

        For :math:`v^+ = \dot q + (\alpha + s)\,dt`, written into this level's buffers.

        The map alpha -> v+ is a bijection, so this QP is feasible exactly when the
        velocity-level one is. When the fallback had to relax the velocity level (``widen``),
        its set is widened to contain qdot_c: the QP keeps exactly that relaxation and stays
        feasible (alpha = (qdot_c - v)/dt - s is a solution).

        Returns:
            The velocity-level box ``(lbv, ubv)`` in force (widened or not).
        """
        v, inv_dt = tp.state.v, 1.0 / tp.dt
        lbv = np.minimum(tp.lb, qdot_c, out=self._lbv) if widen else tp.lb
        ubv = np.maximum(tp.ub, qdot_c, out=self._ubv) if widen else tp.ub
        np.subtract(lbv, v, out=self._lb)
        self._lb *= inv_dt
        self._lb -= s
        np.subtract(ubv, v, out=self._ub)
        self._ub *= inv_dt
        self._ub -= s
        if self._n_rows:
            Cq = tp.C @ qdot_c if widen else tp.l
            Cv_s = tp.C @ (v * inv_dt + s)
            np.minimum(tp.l, Cq, out=self._l)
            self._l *= inv_dt
            self._l -= Cv_s
            np.maximum(tp.u, Cq if widen else tp.u, out=self._u)
            self._u *= inv_dt
            self._u -= Cv_s
        return lbv, ubv

    def _accelerate(
        self,
        tp: TickProblem,
        drifts: list[np.ndarray],
        qdot_c: np.ndarray,
        widen: bool,
        out: LevelOutcome,
    ) -> np.ndarray:
        """2. The resolved acceleration QP (CRAC eq. 9-14) and CRAC eq. 31; returns ``v+``."""
        v, dt = tp.state.v, tp.dt
        tb = time.perf_counter()
        s = self.gains.gv * (qdot_c - v)  # (nv,) CRAC eq. 31 shift
        lbv, ubv = self._transcribe_constraints(tp, qdot_c, s, widen)
        blocks_a = self.acceleration_blocks(tp, drifts)
        tp_a = TickProblem(
            tp.state, dt, blocks_a, tp.C, self._l, self._u, self._lb, self._ub, tp.W,
            tp.damping, tp.tick, tp.J_all, self.a_all,
        )  # fmt: skip
        out.build_time += time.perf_counter() - tb
        tq = time.perf_counter()
        res_a = self.strategy.solve(tp_a)
        self.timings["acceleration_qp"] = time.perf_counter() - tq
        out.solver_status = res_a.status
        out.solve_time += res_a.solve_time
        out.iterations += res_a.iterations
        if res_a.success and res_a.x is not None and np.all(np.isfinite(res_a.x)):
            alpha = res_a.x
        else:
            alpha = (qdot_c - v) * (1.0 / dt) - s
            out.messages.append(
                f"tick {tp.tick}: the acceleration QP failed (solver status "
                f"{res_a.status}); applying the velocity-level solution qdot_c this tick."
            )
        self.alpha, self.qdot_c = alpha, qdot_c
        v_next = v + (alpha + s) * dt  # CRAC eq. 31, integrated
        # Solvers meet bounds to their tolerance; the box is cheap to meet exactly.
        np.clip(v_next, lbv, ubv, out=v_next)
        return v_next

    def _finish(self, tp: TickProblem, out: LevelOutcome) -> None:
        r"""3. Torques (CRAC eq. 30) and semi-implicit integration :math:`q^+ = q \oplus v^+ dt`."""
        q, v, dt = tp.state.q, tp.state.v, tp.dt
        # alpha_c of the motion actually applied (alpha + s up to the clip).
        self.alpha_c = (out.v_next - v) * (1.0 / dt)
        tr = time.perf_counter()
        tau = pin.rnea(self.model, self._dyn_data, q, v, self.alpha_c).copy()
        self.timings["dynamics"] = time.perf_counter() - tr
        tau.setflags(write=False)
        out.tau = tau
        out.q_next = pin.integrate(self.model, q, out.v_next * dt)

    def __repr__(self) -> str:
        g = self.gains
        return (
            f"AccelerationLevel(kp={g.kp}, kv={g.kv}, gv={g.gv}, velocity_gain={g.velocity_gain}, "
            f"damping={self.damping}, strategy={self.strategy!r})"
        )
