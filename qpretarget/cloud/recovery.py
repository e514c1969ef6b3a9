# SPDX-License-Identifier: Apache-2.0
r"""A frame's fit lost or stuck: the re-initialisation and the shoulder branches.

Mixed into the EM fit, :class:`.em.CloudRetargeter` (:class:`RecoveryMixin`). Not in Wang 2017
(HUMROB), where each frame starts from the prediction of the previous poses (V.B) alone.

**A lost frame** (issue 23 item 2): a frame whose :math:`\sigma` is above ``em.reinit_ratio``
times the median of the recent frames' that were not lost (:meth:`RecoveryMixin._lost`), or
whose fit ends a joint of ``em.reinit_at_limits`` within :data:`LIMIT_MARGIN` of its fit limit
(:meth:`RecoveryMixin.at_limits`), is fitted again (:meth:`RecoveryMixin._reinitialise`) from
the last good pose (moved to where the frame's fit stands, ``em.reinit_recentre``), from the
constant-velocity prediction, and by a coarse search over the trunk's yaw
(``em.reinit_yaw_starts``: the floating base turned about the vertical,
:math:`R_0 \leftarrow R_z(\psi_k + \Delta) R_0` with :math:`\psi_k = k\,\delta`,
:meth:`RecoveryMixin.yaw_starts`). The fits are ranked by
:math:`E + \rho N [q \text{ at a limit}]` (:meth:`RecoveryMixin.reinit_cost`): the NLL of eq. 3
on the frame's :math:`N` cloud points, each fit with its own :math:`\sigma^2`, plus
``em.reinit_limit_penalty`` :math:`\rho` nats per point for a fit ending at such a limit.

**Shoulder branches** (:meth:`RecoveryMixin._switch_branches`): three orthogonal one-DoF joints
a -> b -> c (``em.branch_joints``) give their last joint the same rotation with the angles
:math:`(\theta_a + \pi, \pi - \theta_b, \theta_c + \pi)`, refined by Gauss-Newton on
:math:`\log(R(\theta)^\top R(\theta_{fit}))` where the axes are not quite orthogonal
(:meth:`RecoveryMixin._other_branch`). A triple with a joint within :data:`BRANCH_MARGIN` of a
limit is fitted again from its other angles; the lower NLL (eq. 3) wins, and the pose history
is mapped to the winning angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robot import RobotModel
from .config import CloudConfig
from .iterations import IterationLog

#: A fit within this distance of a joint limit [rad] tries the other angles of its
#: ``em.branch_joints`` triple.
BRANCH_MARGIN = 0.01
#: A joint of ``em.reinit_at_limits`` within this of its fit limit flags the frame lost [rad].
LIMIT_MARGIN = 0.01


def _other_angles(th: np.ndarray) -> np.ndarray:
    r"""The other angles of three orthogonal joints giving the same rotation.

    :math:`(\theta_a + \pi, \pi - \theta_b, \theta_c + \pi)`, each wrapped into
    :math:`[-\pi, \pi]`.
    """
    return _wrap_near(np.array([th[0] + math.pi, math.pi - th[1], th[2] + math.pi]), np.zeros(3))


def _wrap_near(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Angles ``x`` moved by whole turns to the values nearest ``ref`` (same rotations)."""
    return x - 2.0 * math.pi * np.round((x - ref) / (2.0 * math.pi))


class RecoveryMixin:
    """The re-initialisation of a lost frame and the shoulder-branch switch (module docstring)."""

    # Set up here (_init_recovery, which the fitter's __init__ calls: em.branch_joints,
    # em.reinit_*)...
    _branches: list[np.ndarray]
    _branch_joints: list[tuple[int, np.ndarray]]
    _branch_data: Any  # pinocchio.Data
    _yaw_data: Any  # pinocchio.Data
    _yaw_reset: np.ndarray
    _yaw_joint: int
    _limit_watch: np.ndarray
    # Of the fitter (.em.CloudRetargeter), used here: its state...
    config: CloudConfig
    robot: RobotModel
    model: Any  # pinocchio.Model
    history: list[np.ndarray]
    q_min: np.ndarray
    q_max: np.ndarray
    stability_mode: str
    _good: np.ndarray | None
    _sigmas: list[float]
    _anchors: dict[str, tuple[np.ndarray, float]]
    # ... and its methods.
    _clip: Callable[[np.ndarray], np.ndarray]
    _restore_balance: Callable[[np.ndarray], tuple[np.ndarray, bool]]
    model_difference: Callable[[np.ndarray, np.ndarray], np.ndarray]
    _trial: Callable[..., tuple[np.ndarray, float, float]]  # CloudRetargeter._trial

    def _init_recovery(self) -> None:
        """Check the joints of ``em.branch_joints`` and ``em.reinit_*``; set up their indices.

        The triples' indices (:meth:`_branch_triples`); the coordinates in q of
        ``em.reinit_yaw_reset`` and the deepest of them (whose heading the yaw starts keep),
        and of ``em.reinit_at_limits``.

        Raises:
            ConfigError: a joint the robot does not have, a triple that is not three orthogonal
                one-DoF joints in a chain, or ``em.reinit_yaw_starts`` on a template whose root
                is not a free-flyer.
        """
        em = self.config.em
        self._branch_joints = []
        self._branch_data = self.robot.model.createData()
        self._branches = self._branch_triples(em.branch_joints)
        self._yaw_data = self.model.createData()
        names = em.reinit_yaw_reset
        for n in names:
            self.robot.joint_index(n, path="em.reinit_yaw_reset")  # a clear error if unknown
        ids = [self.model.getJointId(n) for n in names]
        self._yaw_reset = np.array([self.model.joints[j].idx_q for j in ids], dtype=int)
        self._yaw_joint = max(ids, default=0)  # the deepest: its heading is kept
        watch = []
        for n in em.reinit_at_limits:
            self.robot.joint_index(n, path="em.reinit_at_limits")  # a clear error if unknown
            watch.append(self.model.joints[self.model.getJointId(n)].idx_q)
        self._limit_watch = np.array(watch, dtype=int)  # their coordinates in q
        if em.reinit_yaw_starts and self.model.joints[1].nq != 7:
            raise ConfigError(
                "the yaw search turns the floating base: the template's root must be a free-flyer.",
                path="em.reinit_yaw_starts",
            )

    def _lost(self, sigma2: float) -> bool:
        """Whether the frame's fit looks lost: sigma above ``em.reinit_ratio`` times the median."""
        em = self.config.em
        if not em.reinit_ratio > 0 or len(self._sigmas) < 5 or self._good is None:
            return False
        return math.sqrt(sigma2) > em.reinit_ratio * float(np.median(self._sigmas))

    def at_limits(self, q: np.ndarray) -> bool:
        """Whether a joint of ``em.reinit_at_limits`` ends within ``LIMIT_MARGIN`` of its limit.

        The limits are the fit's (``em.joint_limits`` within the robot's). With the waist
        bounded to a person's twist, a fit at that bound is a pelvis and a torso that disagree
        on the heading: a lost trunk, whatever its sigma.
        """
        idx = self._limit_watch
        if not idx.size:
            return False
        th = q[idx]
        return bool(
            np.any((th - self.q_min[idx] < LIMIT_MARGIN) | (self.q_max[idx] - th < LIMIT_MARGIN))
        )

    def _at_limits(self, q: np.ndarray) -> bool:
        """:meth:`at_limits`, once there is a good pose to re-initialise from."""
        return self._good is not None and self.at_limits(q)

    def _reinitialise(
        self,
        S: np.ndarray,
        Sn: np.ndarray | None,
        fit: tuple[np.ndarray, float, float],
        log: list[IterationLog],
    ) -> tuple[np.ndarray, float, float]:
        """Fit the frame again from other starts; keep the lowest NLL (issue 23 item 2).

        Called on a frame flagged lost: its sigma well above the recent frames'
        (``em.reinit_ratio``) or a joint of ``em.reinit_at_limits`` at its fit limit.

        Starts: the pose of the last frame that was not lost (the fit may have drifted since)
        and the constant-velocity prediction (a fast limb the auto-regression lags behind).
        With ``em.reinit_recentre``, the last good pose is moved to where the frame's fit
        stands (:meth:`recentred`): the person may have walked on since. Each runs the linear
        and refinement stages (no centre stage: the joint-centre estimate learns from tracked
        frames only), its temporal term towards its own start. With
        ``em.reinit_yaw_starts``, the coarse search over the trunk's yaw (:meth:`_yaw_search`)
        competes too; when it wins, the pose history restarts from its fit.

        The fits are compared by :meth:`reinit_cost`: the NLL of eq. 3 on the same cloud, each
        with its own sigma^2, plus ``em.reinit_limit_penalty`` nats per cloud point for a fit
        ending at a limit of ``em.reinit_at_limits`` (this frame's first fit included): such
        a fit is what flags a frame lost, so a fit that is not wins unless it explains the
        cloud clearly worse.
        """
        here = fit[0]
        starts = []
        if self._good is not None:
            starts.append(("reinit-last-", self.recentred(self._good, here)))
        if len(self.history) >= 2:
            h = self.history
            starts.append(
                (
                    "reinit-velocity-",
                    pin.integrate(self.model, h[-1], self.model_difference(h[-2], h[-1])),
                )
            )
        n = len(S)
        best, best_cost = fit, self.reinit_cost(fit[0], fit[2], n)
        for tag, start in starts:
            q0, q_prev = self._reinit_start(start)
            cand = self._trial(S, Sn, q0, q_prev, log, tag)
            cost = self.reinit_cost(cand[0], cand[2], n)
            if cost < best_cost:
                best, best_cost = cand, cost
        # A whip turn pivots on the feet: the soles' anchors (where the lost fit put them)
        # would hold every turned start back. Released for the search, anchored again where
        # a winning start puts the soles (fit() anchors soles that have none).
        release = self.config.em.reinit_release_contacts
        anchors = self._anchors
        if release:
            self._anchors = {}
        yaw = self._yaw_search(S, Sn, log, here)
        self._anchors = anchors
        if yaw is not None and self.reinit_cost(yaw[0], yaw[2], n) < best_cost:
            best = yaw
            if release:
                self._anchors = {}
            # The prediction must not extrapolate the jump to the turned pose: it goes on
            # from the new pose alone (fit() appends it).
            self.history.clear()
        return best

    def reinit_cost(self, q: np.ndarray, nll: float, n_points: int) -> float:
        r"""The re-initialisation's ranking of a fit: :math:`E + \rho N [q \text{ at a limit}]`.

        :math:`E`: the fit's NLL (eq. 3, Wang 2017) on the frame's :math:`N` cloud points;
        :math:`\rho`: ``em.reinit_limit_penalty`` [nats per point], added when a joint of
        ``em.reinit_at_limits`` ends at its fit limit (:meth:`at_limits`). Not in Wang
        2017: at a person's twist limit the fit's pelvis and torso disagree on the heading
        (the rule that flags the frame lost), and on CMU 17_10 boxing's whip turns such a
        fit, its arms laid on the cloud in whatever way, kept winning by 13-560 nats over
        2,500 points against a start 10-20 deg from the person's shoulder line
        (docs/point_clouds.md, twelfth round).
        """
        rho = self.config.em.reinit_limit_penalty
        return float(nll) + (rho * n_points if rho > 0 and self.at_limits(q) else 0.0)

    def recentred(self, start: np.ndarray, here: np.ndarray) -> np.ndarray:
        """``start`` with its floating base moved horizontally to ``here``'s (x, y).

        With ``em.reinit_recentre`` (else ``start`` unchanged): the last good pose is the
        last frame that was not flagged lost, up to a second old, and the person may have
        walked on since (on CMU 17_10 boxing's whip turn, 33 cm). Started there, 16 sigma
        of the first E-step away, a start cannot reach the person; the frame's own fit,
        lost in its heading or twist, still stands where the person does.
        """
        if not self.config.em.reinit_recentre or self.model.joints[1].nq != 7:
            return start
        out = start.copy()
        out[:2] = here[:2]
        return out

    def _reinit_start(self, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A re-initialisation start within the limits and balanced, and its temporal reference."""
        q0 = self._clip(start)
        if self.stability_mode == "qp":
            q0, _ = self._restore_balance(q0)
        ref = self.history[-1] if self.history else q0
        q_prev = q0.copy() if self.config.em.temporal_reference == "prediction" else ref
        return q0, q_prev

    def _heading(self, q: np.ndarray, joint: int) -> float:
        """Heading [rad] of pinocchio joint ``joint``'s frame: the angle of its x axis about z."""
        pin.forwardKinematics(self.model, self._yaw_data, q)
        R = self._yaw_data.oMi[joint].rotation
        return math.atan2(R[1, 0], R[0, 0])

    def yaw_starts(self, q: np.ndarray) -> list[tuple[float, np.ndarray]]:
        r"""Starts of the coarse search over the trunk's yaw around pose ``q``: (offset, pose).

        With :math:`\psi_k = k\,\delta` for :math:`k = \pm 1, \dots, \pm n`
        (``em.reinit_yaw_starts`` n, ``em.reinit_yaw_step`` :math:`\delta`), the start k is
        ``q`` with the joints ``em.reinit_yaw_reset`` set to 0 (clipped to their limits) and
        the floating base turned about the vertical through its origin,
        :math:`R_0 \leftarrow R_z(\psi_k + \Delta) R_0`, where :math:`\Delta` turns the base
        so that the deepest reset joint's frame keeps its heading (the torso stays where it
        was; the pelvis comes under it); with reset joints, :math:`\psi_0 = 0` (the untwisted
        pose) is a start too. The other joints (arms, legs) keep ``q``'s angles.
        """
        em = self.config.em
        base = q.copy()
        turn = 0.0
        offsets = [k * em.reinit_yaw_step for k in range(1, em.reinit_yaw_starts + 1)]
        offsets = [x for k in offsets for x in ((k, -k) if k < math.pi - 1e-9 else (k,))]
        if self._yaw_reset.size:
            h0 = self._heading(base, self._yaw_joint)
            idx = self._yaw_reset
            base[idx] = np.clip(0.0, self.q_min[idx], self.q_max[idx])
            turn = h0 - self._heading(base, self._yaw_joint)
            offsets.insert(0, 0.0)
        out = []
        M0 = pin.XYZQUATToSE3(base[:7])
        for psi in offsets:
            a = turn + psi
            Rz = np.array(
                [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0, 0, 1]]
            )
            qk = base.copy()
            qk[:7] = pin.SE3ToXYZQUAT(pin.SE3(Rz @ M0.rotation, M0.translation))
            out.append((psi, qk))
        return out

    def _yaw_search(
        self, S: np.ndarray, Sn: np.ndarray | None, log: list[IterationLog], here: np.ndarray
    ) -> tuple[np.ndarray, float, float] | None:
        r"""Coarse global search over the trunk's yaw (issue 23 item 2; None when off).

        Every start of :meth:`yaw_starts` around the last good pose (moved to ``here``, the
        frame's own fit, with ``em.reinit_recentre``: :meth:`recentred`) gets
        ``em.reinit_yaw_iterations`` iterations of the linear stage (temporal term towards its
        own start), and the one ranked first by :meth:`reinit_cost` (the NLL of eq. 3,
        :math:`E = -\sum_n \log(\frac{1-\mu}{M}\sum_m \mathcal N(s_n; v_m, \sigma^2 I)
        + \frac{\mu}{N})`, each with its own :math:`\sigma^2`, plus the limit penalty) is
        fitted on by the full linear and refinement stages. A short fit suffices to rank the
        starts: the trunk and the arms are most of the cloud, and a start half a turn from
        the person cannot lay them on it.
        """
        em = self.config.em
        if em.reinit_yaw_starts < 1 or self._good is None:
            return None
        best: tuple[np.ndarray, float, float, np.ndarray, str] | None = None
        best_cost = math.inf
        for psi, start in self.yaw_starts(self.recentred(self._good, here)):
            q0, q_prev = self._reinit_start(start)
            tag = f"reinit-yaw{math.degrees(psi):+.0f}-"
            q, sigma2, nll = self._trial(
                S, Sn, q0, q_prev, log, tag, iterations=em.reinit_yaw_iterations, refine=False
            )
            cost = self.reinit_cost(q, nll, len(S))
            if best is None or cost < best_cost:
                best, best_cost = (q, sigma2, nll, q_prev, tag), cost
        if best is None:
            return None
        q, sigma2, _, q_prev, tag = best
        return self._trial(S, Sn, q, q_prev, log, f"{tag}full-", sigma2=sigma2)

    def _branch_triples(self, spec: list[list[str]]) -> list[np.ndarray]:
        r"""Configuration indices (3,) of each ``em.branch_joints`` triple, checked.

        Each must be a chain a -> b -> c of one-DoF joints with b orthogonal to a and c
        (within 0.05 in their cosines): then a second set of angles gives the same rotation
        (:meth:`_other_branch`). Returns the configuration indices; the triple's joint ids
        and velocity indices are kept in ``self._branch_joints``.
        """
        robot, model = self.robot, self.robot.model
        out: list[np.ndarray] = []
        if not spec:
            return out
        data = model.createData()
        pin.computeJointJacobians(model, data, robot.q_reference)
        for k, names in enumerate(spec):
            path = f"em.branch_joints[{k}]"
            for n in names:
                robot.joint_index(n, path=path)  # a clear error for an unknown name
            js = [model.getJointId(n) for n in names]
            if any(model.joints[j].nv != 1 for j in js) or not (
                model.parents[js[1]] == js[0] and model.parents[js[2]] == js[1]
            ):
                raise ConfigError(
                    f"{names} must be three one-DoF joints, each the child of the one before.",
                    path=path,
                )
            axes = [
                pin.getJointJacobian(model, data, j, pin.ReferenceFrame.WORLD)[
                    3:, model.joints[j].idx_v
                ]
                for j in js
            ]
            cos = [abs(float(axes[a] @ axes[b])) for a, b in ((0, 1), (1, 2))]
            if max(cos) > 0.05:
                raise ConfigError(
                    f"the middle joint's axis of {names} is not orthogonal to the others "
                    f"(cosines {np.round(cos, 3).tolist()}): no second set of angles gives the "
                    "same rotation.",
                    path=path,
                )
            out.append(np.array([model.joints[j].idx_q for j in js]))
            self._branch_joints.append((js[2], np.array([model.joints[j].idx_v for j in js])))
        return out

    def _other_branch(self, q: np.ndarray, k: int, *, limits: bool = True) -> np.ndarray | None:
        r"""The other angles of triple k giving its last joint the same rotation, or None.

        Start: :math:`(\theta_a + \pi, \pi - \theta_b, \theta_c + \pi)`, exact when the
        three axes are mutually orthogonal; then Gauss-Newton on
        :math:`\log(R(\theta)^\top R(\theta_{fit}))` (G1's shoulder pitch axis is tilted by
        16 deg from the plane normal to its yaw axis, which moves the start's elbow by 11 cm).
        None when it does not converge (1e-8 rad) or (``limits``) leaves the joint limits.
        """
        idx = self._branches[k]
        jc, iv = self._branch_joints[k]
        model, data = self.robot.model, self._branch_data
        pin.forwardKinematics(model, data, q)
        target = data.oMi[jc].rotation.copy()
        x = _other_angles(q[idx])
        qq = q.copy()
        for _ in range(20):
            qq[idx] = x
            pin.computeJointJacobians(model, data, qq)
            r = pin.log3(data.oMi[jc].rotation.T @ target)
            if float(np.linalg.norm(r)) < 1e-8:
                break
            J = pin.getJointJacobian(model, data, jc, pin.ReferenceFrame.LOCAL)[3:, iv]
            x = x + np.linalg.lstsq(J, r, rcond=None)[0]
        else:
            return None
        lo, hi = self.q_min[idx], self.q_max[idx]
        if not limits:
            return x
        x = _wrap_near(x, 0.5 * (lo + hi))  # into the limits' window where it can be
        if np.all(x >= lo) and np.all(x <= hi) and np.max(np.abs(x - q[idx])) > 1e-3:
            return x
        return None

    def _switch_branches(
        self,
        S: np.ndarray,
        Sn: np.ndarray | None,
        fit: tuple[np.ndarray, float, float],
        log: list[IterationLog],
    ) -> tuple[np.ndarray, float, float]:
        """Fit again from the other angles of a triple stuck at a limit; keep the lower NLL.

        A shoulder of three orthogonal joints reaches most arm directions with two sets of
        angles. Tracking follows one of them continuously; when the arm moves where that set
        runs into a joint limit (the arm raised beside the head, CMU 14_07: G1's shoulder roll
        at -2.25 rad, the upper arm 30 deg off the person's) while the other set is free, the
        EM cannot get there through the limit. Each triple with a joint within
        ``BRANCH_MARGIN`` of a limit gets a start with its other angles (the rest of the
        fitted pose kept), fitted by the linear and refinement stages with the temporal term
        towards that start (no centre stage), compared by the NLL of eq. 3. When a start
        wins, the pose history is mapped to the same angles so that the prediction goes on
        from them.
        """
        em = self.config.em
        best = fit
        for k, idx in enumerate(self._branches):
            q = best[0]
            th = q[idx]
            lo, hi = self.q_min[idx], self.q_max[idx]
            if not np.any((th - lo < BRANCH_MARGIN) | (hi - th < BRANCH_MARGIN)):
                continue
            alt = self._other_branch(q, k)
            if alt is None:
                continue
            q0 = q.copy()
            q0[idx] = alt
            if self.stability_mode == "qp":
                q0, _ = self._restore_balance(q0)
            q_prev = q0.copy() if em.temporal_reference == "prediction" else self.history[-1]
            cand = self._trial(S, Sn, q0, q_prev, log, f"branch{k}-")
            if cand[2] < best[2]:
                best = cand
                # Newest first, each wrapped next to the newer one: a continuous history.
                ref = cand[0][idx]
                for i in range(len(self.history) - 1, -1, -1):
                    alt_h = self._other_branch(self.history[i], k, limits=False)
                    if alt_h is None:
                        del self.history[: i + 1]  # older poses: not mapped, not used
                        break
                    ref = _wrap_near(alt_h, ref)
                    self.history[i] = self.history[i].copy()
                    self.history[i][idx] = ref
        return best


__all__ = ["BRANCH_MARGIN", "LIMIT_MARGIN", "RecoveryMixin"]
