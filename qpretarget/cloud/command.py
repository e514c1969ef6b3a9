# SPDX-License-Identifier: Apache-2.0
r"""The point-cloud command with the robot's links apart (config section ``self_collision``).

The fit (:mod:`.em`) places a template with the person's proportions; the command is G1 at the
fitted joint angles, its primary sole planted (:mod:`.placement`). Wang 2017 (HUMROB) keeps the
joint limits (eq. 17) and the balance (eq. 18-19), not link distances: where a person's hand
passes beside their hip, G1's (other proportions) goes through its own. Before stop 48
``evaluate``'s mesh audit found bend-and-scoop's command penetrating on 77 of 95 frames, a
wrist 42.7 mm into a hip, and 7 of 12 shared clips penetrating somewhere. So the command, not
the fit, is kept apart.

**The pairs** are the controller's :class:`~qpretarget.constraints.SelfCollision` (the same
pair rules, convex hulls, safety distances; docs/collisions.md) at the robot's joint angles
(the base does not change a distance between links). For the closest pairs, distance
:math:`d`, safety distance :math:`d_s`, gradient :math:`\nabla d`, a step :math:`\Delta` keeps
the linearized distance at :math:`d_s`:

.. math::
    d + \nabla d^\top \Delta \;\ge\; d_s
    \quad\Longleftrightarrow\quad
    -\nabla d^\top \Delta \;\le\; \max(d - d_s,\ -r),

the controller's velocity damper with one "tick" per step and a gain of one
(``gain_per_tick: 1``: the whole gap may close), :math:`r` (``recovery_speed``, metres per
step) the most a pair already too close is asked to part in one step.

**The projection** (:meth:`CommandProjection.follow`, every frame). The fit's configuration
is the command when its links are apart. Otherwise Gauss-Newton steps move it the least, in
the sense of the body's segments (pelvis-torso, torso-head, the shoulders, upper arms,
forearms, hands, hips, thighs, shanks, from the robot's ``keyframes``): their vectors follow
the fit's, each weighed by 1/length² so that the objective is in squared angle (the
arm-direction measure's terms), the supporting soles held (weight :data:`SOLE_WEIGHT`),
under the rows above, the balance rows of :mod:`.stability` (the CoM kept over the soles'
polygon; ``CloudRetargeter`` asks it on every frame, ``follow`` can also be asked only for no
further out), the joint limits and :data:`STEP_BOUND` a step. The steps start from
the last frame's command, which is clear, so that, like the controller's damper, they never
enter a pair: a hand slides along the hip instead of going through it.

**Not in the fit.** The same rows in every M-step (the template itself kept apart) were
measured (docs/point_clouds.md, *Seventeenth round*): the template cannot follow a person
whose hands pass where G1's hips are, and bend-and-scoop's arms were lost (worst frame
23-110 deg on 9 runs, was 6.7-11.2).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from ..constraints.self_collision import SelfCollision
from ..problem import QPProblem
from ..registry import build_from_spec
from ..robot import RobotModel, RobotState

#: Defaults of the ``self_collision`` section where they differ from the controller's
#: constraint: one step of :meth:`CommandProjection.follow` is one "tick" whose rows keep the
#: linearized distance at d_s (gain 1), a pair already too close parts by at most 2 cm a step,
#: and the step bound :data:`STEP_BOUND` replaces the trust region.
FIT_DEFAULTS: dict[str, Any] = {
    "d_s": 0.005,
    "d_i": 0.06,
    "gain_per_tick": 1.0,
    "recovery_speed": 0.02,
    "trust_region": None,
}


def fit_spec(spec: Mapping[str, Any]) -> dict[str, Any]:
    """``spec`` with :data:`FIT_DEFAULTS` where not given (no default gain if one is given)."""
    gains = ("xi", "gain", "gain_per_tick")
    defaults = {
        k: v for k, v in FIT_DEFAULTS.items() if not (k in gains and any(g in spec for g in gains))
    }
    return {**defaults, **dict(spec)}


#: Body segments (parent, child key point) whose vectors the command keeps as the fit has
#: them: the trunk, head, shoulders, arms, hands and legs (a segment's vector is its
#: direction times its fixed length, so this keeps the directions the measures compare).
SEGMENTS: tuple[tuple[str, str], ...] = (
    ("pelvis", "torso"),
    ("torso", "head"),
    *(
        (f"{s}_{a}", f"{s}_{b}") if a != "torso" and a != "pelvis" else (a, f"{s}_{b}")
        for s in ("left", "right")
        for a, b in (
            ("torso", "shoulder"),
            ("shoulder", "elbow"),
            ("elbow", "wrist"),
            ("wrist", "hand"),
            ("pelvis", "hip"),
            ("hip", "knee"),
            ("knee", "ankle"),
        )
    ),
)
#: Weight of the joints' own distance to the fit's (times the number of joints each moves)
#: against the segments' turns [1/rad^2 per rad^2]: it settles what the segments leave free
#: (a wrist's roll).
JOINT_REGULARIZATION = 1e-2
#: Weight of a supporting sole's pose error against the segments' (its placement is held).
SOLE_WEIGHT = 1e4
#: Largest change of a coordinate in one step [rad, m]: the rows are first order.
STEP_BOUND = 0.1
#: Farthest a joint of the fit's configuration may have jumped since the last frame's [rad]
#: for the steps to start from the last command: a fit that jumped further (a walk's knee
#: flipping between two fits, 1 rad) is not followed from where the command was (the steps
#: move a joint by at most STEP_BOUND, FOLLOW_STEPS times) but pushed out from where it is.
FOLLOW_REACH = 0.4
#: Most Gauss-Newton steps of :meth:`CommandProjection.follow` per frame.
FOLLOW_STEPS = 8
#: Halvings of what a step asks of the pairs inside their safety distance when it cannot
#: be met within the step bound (then: no deeper).
PART_HALVINGS = 3
#: A sole farther than this from its placement [m, rad] is moved back onto it (a leg that
#: cannot reach it alone: the body moves too).
SOLE_TOLERANCE = (1e-3, 1e-2)
#: A step smaller than this on every coordinate ends them [rad, m].
FOLLOW_TOLERANCE = 1e-3
#: A pair this far inside its safety distance [m] counts as clear (the rows' linearization
#: error of a few tenths of a millimetre).
CLEAR_TOLERANCE = 2e-4


class CommandProjection:
    r"""The robot command with its links apart (module docstring).

    Args:
        robot: the robot (its collision geometry and key points).
        spec: the config's ``self_collision`` mapping: the keys of the controller's
            ``self_collision`` constraint (``pairs``, ``d_s``, ``d_i``, ``include``,
            ``safety``, ...), with :data:`FIT_DEFAULTS` where not given; ``None``: the
            links are not checked (:meth:`follow` returns the fit's configuration).

    Raises:
        ConfigError: an unknown key, a bad value or a link without collision geometry (with
            the YAML path ``self_collision.<key>``).
    """

    def __init__(self, robot: RobotModel, spec: Mapping[str, Any] | None) -> None:
        self.robot = robot
        self.constraint: SelfCollision | None = None
        self.n_rows = 0
        if spec is not None:
            self.constraint = build_from_spec(SelfCollision, fit_spec(spec), path="self_collision")
            self.constraint.bind(robot, path="self_collision")
            # optional and the robot has no collision geometry: nothing to keep apart
            self.n_rows = 0 if self.constraint.disabled else self.constraint.n_rows
        self.state = RobotState(robot)
        #: The robot's body segments between its key points (:data:`SEGMENTS` of its
        #: ``keyframes``), whose vectors follow the fit's: (parent frame, child frame).
        kf = robot.keyframes
        self._segments = [
            (robot.frame_id(kf[a]), robot.frame_id(kf[b]))
            for a, b in SEGMENTS
            if a in kf and b in kf
        ]
        # 1 / length^2 [1/m^2]: a segment's vector error over its length is its turn [rad].
        ref = robot.model.createData()
        pin.framesForwardKinematics(robot.model, ref, robot.q_reference)
        self._segment_weights = [
            1.0
            / max(float(np.linalg.norm(ref.oMf[b].translation - ref.oMf[a].translation)), 0.05) ** 2
            for a, b in self._segments
        ]
        #: Weight of each velocity coordinate: the number of joints it moves (its subtree; a
        #: limb's end 1, G1's waist 17), the base 1000.
        m = robot.model
        self._weights = np.ones(robot.nv)
        for j in range(1, m.njoints):
            jm = m.joints[j]
            w = 1e3 if jm.shortname() == "JointModelFreeFlyer" else float(len(m.subtrees[j]))
            self._weights[jm.idx_v : jm.idx_v + jm.nv] = w
        self._C = np.zeros((self.n_rows, robot.nv))
        self._lo = np.full(self.n_rows, -np.inf)
        self._up = np.full(self.n_rows, np.inf)
        #: Steps taken by the last :meth:`follow` (0: the fit's configuration was clear).
        self.steps = 0
        self._previous_target: np.ndarray | None = None

    def reset(self) -> None:
        """A new run: the pair model's state as built (a run repeats to the bit)."""
        if self.constraint is not None:
            self.constraint.reset(self.state)
        self._previous_target = None

    def linearize(self, q: np.ndarray) -> float:
        r"""Linearize the closest pairs at ``q``; return their smallest :math:`d - d_s` [m].

        Sets the rows ``lo <= C Delta <= up`` of a step from ``q`` (module docstring; unused
        rows zero with infinite bounds) and the state's kinematics to ``q``'s; inf: no pair
        within :math:`d_i`.
        """
        self.state.update(q)
        if not self.n_rows or self.constraint is None:
            return np.inf
        block = self.constraint.compute_rows(self.state, 1.0)
        np.copyto(self._C, block.C)
        np.copyto(self._lo, block.l)
        np.copyto(self._up, block.u)
        gap = self.constraint._gap
        return float(gap.min()) if gap.size else np.inf

    def _sole_error(self, fid: int, target: pin.SE3) -> np.ndarray:
        """[translation; rotation] error (6,) of sole frame ``fid`` to ``target``.

        At the state's configuration, in the world's axes (the LOCAL_WORLD_ALIGNED Jacobian's).
        """
        cur = self.state.data.oMf[fid]
        return np.concatenate(
            [target.translation - cur.translation, pin.log3(target.rotation @ cur.rotation.T)]
        )

    def follow(
        self,
        q_target: np.ndarray,
        q_start: np.ndarray | None,
        soles: Sequence[tuple[int, pin.SE3]],
        q_min: np.ndarray,
        q_max: np.ndarray,
        solver: Any,
        balance: Callable[[np.ndarray], tuple[BalanceRows, bool] | None] | None = None,
    ) -> tuple[np.ndarray, float]:
        r"""The command nearest the fit's configuration ``q_target`` that the robot can hold.

        ``q_target`` itself when its links are apart, its soles (``soles``: sole frame id and
        placement) on their placements (within :data:`SOLE_TOLERANCE`) and, where
        ``balance(q_target)`` says the robot must balance (``(rows, True)``), its CoM over
        their polygon. Otherwise Gauss-Newton steps from ``q_target`` when its links are
        apart, else from ``q_start`` (the last frame's command, clear: the steps never enter
        a pair; first from ``q_target`` and then, if that cannot clear every pair, from
        ``q_start`` when a joint of the fit jumped more than :data:`FOLLOW_REACH` since the
        last call; the clearest result kept) solve

        .. math::
            \min_\Delta \sum_s w_s \|(J_{b_s} - J_{a_s}) \Delta - e_s\|^2
            + w_f \sum_f \|J_f \Delta - e_f\|^2
            + \epsilon\, (\Delta - \delta)^\top W (\Delta - \delta)

        under the rows of :meth:`linearize`, the balance rows (the CoM over the soles'
        polygon, :meth:`.stability.StabilityRows.rows`, Wang 2017 eq. 18-19; with
        ``(rows, False)`` each bound at least 0: a CoM outside goes no further out rather
        than being pulled in; ``CloudRetargeter`` asks ``(rows, True)`` since stop 50), the
        joint limits and
        :math:`|\Delta_j| \le` :data:`STEP_BOUND`: :math:`e_s` the segments' vector errors
        to the target's (weights :math:`w_s` = 1/length², module docstring), :math:`e_f` the
        pose errors of the soles to their placements (:math:`w_f` = :data:`SOLE_WEIGHT`),
        :math:`\delta = q_{target} \ominus q`, :math:`\epsilon` =
        :data:`JOINT_REGULARIZATION`. A step whose rows cannot all be met within the bound
        (a start deep inside several pairs) asks half as much of the rows it violates, up to
        :data:`PART_HALVINGS` times, then only that they get no worse.

        Returns:
            ``(q, gap)``: the command and its smallest :math:`d - d_s` [m] (negative: a pair
            the steps could not clear; inf: no pair checked or none within :math:`d_i`).
        """
        self.steps = 0
        previous, self._previous_target = self._previous_target, q_target
        gap = self.linearize(q_target)
        clear = gap >= -CLEAR_TOLERANCE
        oMf = self.state.data.oMf  # at q_target
        off = any(self._sole_off(oMf[f], M) for f, M in soles)
        held = None if balance is None else balance(q_target)
        tipped = held is not None and held[1] and held[0].margin_of(q_target, full=True) < 0.0
        if clear and not off and not tipped:
            return q_target, gap
        robot, model = self.robot, self.robot.model
        seg_targets = [oMf[b].translation - oMf[a].translation for a, b in self._segments]
        nv, k = robot.nv, self.n_rows
        nb = 0 if held is None else held[0].n_rows
        if clear:
            starts = [q_target]
        else:
            starts = [q_target] if q_start is None else [q_start]
            if q_start is not None and previous is not None:
                jump = np.abs(pin.difference(model, previous, q_target)[robot.joint_v_index])
                if float(jump.max(initial=0.0)) > FOLLOW_REACH:
                    starts.insert(0, q_target)  # then, if that cannot clear, from the command
        qp = QPProblem(nv, k + nb)
        best: tuple[np.ndarray, float] | None = None
        for q in starts:
            q, gap = self._steps(q, q_target, seg_targets, soles, q_min, q_max, solver, held, qp)
            if best is None or gap > best[1]:
                best = (q, gap)
            if gap >= -CLEAR_TOLERANCE:
                break
        assert best is not None
        return best

    @staticmethod
    def _sole_off(M: pin.SE3, target: pin.SE3) -> bool:
        """Whether a sole at ``M`` is off its placement ``target`` (:data:`SOLE_TOLERANCE`)."""
        d = float(np.linalg.norm(M.translation - target.translation))
        a = float(np.linalg.norm(pin.log3(target.rotation @ M.rotation.T)))
        return d > SOLE_TOLERANCE[0] or a > SOLE_TOLERANCE[1]

    def _steps(
        self,
        q: np.ndarray,
        q_target: np.ndarray,
        seg_targets: list[np.ndarray],
        soles: Sequence[tuple[int, pin.SE3]],
        q_min: np.ndarray,
        q_max: np.ndarray,
        solver: Any,
        balance: tuple[BalanceRows, bool] | None,
        qp: QPProblem,
    ) -> tuple[np.ndarray, float]:
        """The Gauss-Newton steps of :meth:`follow` from ``q``; return ``(q, gap)``."""
        robot, model = self.robot, self.robot.model
        k = self.n_rows
        qi, vi = robot.joint_q_index, robot.joint_v_index
        reg = JOINT_REGULARIZATION * self._weights
        gap = self.linearize(q)
        for _ in range(FOLLOW_STEPS):
            delta = pin.difference(model, q, q_target)
            H, g = np.diag(reg), -reg * delta
            oMf = self.state.data.oMf
            for (a, b), u, w in zip(
                self._segments, seg_targets, self._segment_weights, strict=True
            ):
                J = self.state.frame_jacobian(b)[:3] - self.state.frame_jacobian(a)[:3]
                H += w * J.T @ J
                g -= w * J.T @ (u - (oMf[b].translation - oMf[a].translation))
            for fid, M in soles:
                J = self.state.frame_jacobian(fid)
                H += SOLE_WEIGHT * J.T @ J
                g -= SOLE_WEIGHT * J.T @ self._sole_error(fid, M)
            qp.H[...], qp.g[...] = H, g
            qp.C[:k], qp.l[:k], qp.u[:k] = self._C, self._lo, self._up
            if balance is not None:
                qp.C[k:], qp.l[k:], qp.u[k:] = balance[0].rows(q)
                if not balance[1]:
                    # No further out than the fit's command has it (a walk's CoM leaves the
                    # support: moving the links apart must not tip it, nor pull it in).
                    np.maximum(qp.u[k:], 0.0, out=qp.u[k:])
            qp.lb[...], qp.ub[...] = -STEP_BOUND, STEP_BOUND
            qp.lb[vi] = np.maximum(np.minimum(q_min[qi] - q[qi], 0.0), -STEP_BOUND)
            qp.ub[vi] = np.minimum(np.maximum(q_max[qi] - q[qi], 0.0), STEP_BOUND)
            sol = solver.solve(qp)
            for halving in range(PART_HALVINGS + 1):
                if sol.x is not None and np.all(np.isfinite(sol.x)):
                    break
                # Pairs too deep to part by recovery_speed at once within the step bound (a
                # link pressed into two others from both sides): ask half as much of them,
                # at last only that they go no deeper.
                inside = qp.u < 0.0
                qp.u[inside] = 0.5 * qp.u[inside] if halving < PART_HALVINGS - 1 else 0.0
                sol = solver.solve(qp)
            if sol.x is None or not np.all(np.isfinite(sol.x)):
                break
            x = sol.x
            q = pin.integrate(model, q, x)
            q[qi] = np.clip(q[qi], q_min[qi], q_max[qi])
            gap = self.linearize(q)
            self.steps += 1
            if np.max(np.abs(x)) < FOLLOW_TOLERANCE:
                break
        return q, gap


class BalanceRows(Protocol):
    """The balance :meth:`CommandProjection.follow` keeps.

    :class:`.stability.StabilityRows`, its support set at the fit's command.
    """

    n_rows: int

    def rows(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def margin_of(self, q: np.ndarray, *, full: bool = False) -> float: ...


__all__ = ["FIT_DEFAULTS", "BalanceRows", "CommandProjection", "fit_spec"]
