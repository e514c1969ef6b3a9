# SPDX-License-Identifier: Apache-2.0
r"""The robot's stance from the fitted pose: its supporting soles flat on the floor.

The EM fit (:mod:`.em`) gives the person's pose with the robot's joints, its soles wherever the
cloud put them; the command is that pose with the primary sole flat on the floor (z = 0), kept
where it was put down while it supports, and the other supporting soles held where they were put
down (:class:`SolePlacement`, ``stability.plant``).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..robot import RobotModel
from .stability import Support
from .template import Template

#: Newton iterations of a supporting leg put onto its sole's placement (``stability.plant``).
PLANT_ITERATIONS = 10
#: Sole pose error [m, rad] under which the leg is on its placement.
PLANT_TOLERANCE = 1e-9
#: Weight of the sole's pose error against the trunk's rotation [rad] and translation [m] when
#: the leg cannot reach the placement within its joint limits.
PLANT_SOLE_WEIGHT = 100.0
#: Iterations of that compromise (projected Levenberg-Marquardt).
PLANT_LM_ITERATIONS = 20


class SolePlacement:
    """The robot's configuration from a fitted one, its supporting soles on the floor.

    Args:
        robot: the robot (its soles are the ones put down).
        template: the fitted template (its model and data give the fitted soles).
        plant: ``stability.plant``: ``leg`` or ``rigid`` (:meth:`configuration`).

    Keeps the primary sole's placement (:attr:`planted`) and the other supporting soles'
    (:attr:`held`) from frame to frame; :meth:`reset` forgets them.
    """

    def __init__(self, robot: RobotModel, template: Template, plant: str) -> None:
        self.robot = robot
        self.template = template
        self.model = template.model
        self.plant = plant
        #: foot -> its sole frame in the template's model (the fitted soles).
        self.sole_ids = {f: self.model.getFrameId(d.frame) for f, d in robot.feet.items()}
        self._robot_data = robot.model.createData()  # the robot's kinematics
        self.reset()

    def reset(self) -> None:
        """Forget the placements of the soles (a new run)."""
        #: The primary foot and its sole's placement, kept while it stays the primary support.
        self.planted: tuple[str, pin.SE3] | None = None
        #: Supporting feet other than the primary -> their sole placement, held while they
        #: support (``stability.plant: leg``).
        self.held: dict[str, pin.SE3] = {}
        #: foot -> (sole frame, leg's configuration and velocity indices): :meth:`_leg`.
        self._legs: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}

    def configuration(self, q_fit: np.ndarray, support: Support) -> np.ndarray:
        r"""Robot configuration: the fitted joints, the primary sole flat on the floor (z = 0).

        While the same foot stays the primary support its sole keeps its first placement (no
        slip); a new primary foot is put down under the fitted model's sole (x, y and heading).
        With ``stability.plant: rigid`` the whole fitted body is turned and moved with its
        sole onto that placement, :math:`M_{base}' = M_{target} M_{sole}^{-1} M_{base}`; with
        ``leg`` (default) the trunk keeps its fitted orientation and the supporting leg's
        joints put the sole there (:meth:`_plant_leg`).

        Why ``leg``: the cloud barely determines a sole's orientation (a small, partly hidden
        foot), so a rigid placement turned the whole robot, arms included, by the fit's error
        at the foot: 4-5 deg at the median on the standing clips, up to 45 deg of yaw on the
        boxing clip (the person pivots on the planted foot), the arm-direction error there
        51.5 deg where the fit's own arms were within 26.6.
        """
        if not self.robot.free_flyer or not self.robot.feet:
            return q_fit.copy()
        foot = (
            support.primary
            if support.primary is not None
            else (self.planted[0] if self.planted is not None else next(iter(self.robot.feet)))
        )
        rdata = self._robot_data
        pin.framesForwardKinematics(self.robot.model, rdata, q_fit)
        MF = rdata.oMf[self.robot.frame_id(self.robot.feet[foot].frame)]
        if self.planted is not None and self.planted[0] == foot and support.primary is not None:
            target = self.planted[1]
        else:
            pin.framesForwardKinematics(self.model, self.template.data, q_fit)
            fit_sole = self.template.data.oMf[self.sole_ids[foot]]
            R = fit_sole.rotation
            yaw = math.atan2(R[1, 0], R[0, 0])
            target = pin.SE3(
                pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([*fit_sole.translation[:2], 0.0])
            )
            if support.primary is not None:
                self.planted = (foot, target)
        base = pin.XYZQUATToSE3(q_fit[:7])
        new_base = target * MF.inverse() * base
        if self.plant == "leg":
            q = self._plant_leg(q_fit, new_base.translation, foot, target)
            return self._hold_others(q, support, foot)
        q = q_fit.copy()
        q[:7] = pin.SE3ToXYZQUAT(new_base)
        return q

    def _plant_leg(
        self, q_fit: np.ndarray, position: np.ndarray | None, foot: str, target: pin.SE3
    ) -> np.ndarray:
        r"""``q_fit`` with the sole of ``foot`` at ``target``, moved by its leg's joints.

        The base keeps the fitted orientation at ``position`` (the rigid placement's); Newton
        on the leg's joints :math:`\theta` (G1: six, hip to ankle) solves
        :math:`\log_6(M_{sole}(\theta)^{-1} M_{target}) = 0` from the fitted angles. When it
        does not converge within the joint limits (a sole turned or tilted beyond what the
        ankle and hip can take), a bounded least-squares compromise over the leg's joints
        within their limits and the base's rotation :math:`\delta` and translation
        :math:`\tau`, :math:`\min \|w_s e_{sole}\|^2 + \|\delta\|^2 + \|\tau\|^2`
        (:data:`PLANT_SOLE_WEIGHT`: the sole within about 0.1 mm before the trunk turns by a
        degree or moves by 2 cm), then the remaining sole error taken up by a rigid placement
        so that the sole is exactly on ``target``. With ``position`` None the base stays as in
        ``q_fit`` and only the leg's joints move (the nearest pose within their limits).
        """
        model, rdata = self.robot.model, self._robot_data
        fid, iq, iv = self._leg(foot)
        lo, hi = self.robot.q_min[iq], self.robot.q_max[iq]
        q = q_fit.copy()
        if position is not None:
            q[:3] = position
        for _ in range(PLANT_ITERATIONS):
            pin.forwardKinematics(model, rdata, q)
            e = pin.log6(pin.updateFramePlacement(model, rdata, fid).inverse() * target).vector
            if float(np.abs(e).max()) < PLANT_TOLERANCE:
                if np.all(q[iq] >= lo) and np.all(q[iq] <= hi):
                    return q
                break
            J = pin.computeFrameJacobian(model, rdata, q, fid, pin.ReferenceFrame.LOCAL)[:, iv]
            q[iq] += np.linalg.lstsq(J, e, rcond=None)[0]
        return self._plant_bounded(q_fit, position, fid, iq, iv, target)

    def sole_frame(self, foot: str) -> int:
        """The robot's sole frame of ``foot``."""
        return self.robot.frame_id(self.robot.feet[foot].frame)

    def _leg(self, foot: str) -> tuple[int, np.ndarray, np.ndarray]:
        """The sole frame of ``foot`` and its leg's one-DoF joints, computed once per foot.

        Returns ``(frame id, configuration indices, velocity indices)``, the base excluded.
        """
        leg = self._legs.get(foot)
        if leg is None:
            model = self.robot.model
            fid = self.robot.frame_id(self.robot.feet[foot].frame)
            chain = [
                j
                for j in model.supports[model.frames[fid].parentJoint]
                if j > 1 and model.joints[j].nv == 1
            ]
            iq = np.array([model.joints[j].idx_q for j in chain], dtype=int)
            iv = np.array([model.joints[j].idx_v for j in chain], dtype=int)
            leg = self._legs[foot] = (fid, iq, iv)
        return leg

    def _hold_others(self, q: np.ndarray, support: Support, primary: str) -> np.ndarray:
        """The other supporting soles held where they were put down, by their legs' joints.

        A sole that starts supporting is held at its pose of that frame; while it supports,
        its leg's joints keep it there (Newton from the fitted angles, else the bounded
        least-squares nearest pose within the joint limits, the trunk unmoved): with the trunk
        kept as fitted, it would otherwise slide with the trunk's small motions over the
        planted primary sole (29 mm on CMU 14_37).
        """
        model, rdata = self.robot.model, self._robot_data
        others = [f for f in support.feet if f != primary]
        for f in list(self.held):
            if f not in others:
                del self.held[f]
        for f in others:
            if f not in self.held:
                pin.forwardKinematics(model, rdata, q)
                self.held[f] = pin.updateFramePlacement(model, rdata, self._leg(f)[0]).copy()
                continue
            q = self._plant_leg(q, None, f, self.held[f])
        return q

    def _plant_bounded(
        self,
        q_fit: np.ndarray,
        position: np.ndarray | None,
        fid: int,
        iq: np.ndarray,
        iv: np.ndarray,
        target: pin.SE3,
    ) -> np.ndarray:
        r"""The bounded least-squares compromise of :meth:`_plant_leg` (projected LM).

        Residual :math:`[w_s e;\ d]`, :math:`e = \log_6(M^{-1} M_{target})` the sole's error,
        :math:`d` the base's displacement from ``q_fit`` (rotation [rad], translation [m],
        none with ``position`` None); Jacobian :math:`\partial e / \partial v =
        -J_{log6}(X)\, \mathrm{Ad}_{X^{-1}} J_{sole}` (:math:`X = M^{-1} M_{target}`,
        :math:`J_{sole}` the sole's LOCAL frame Jacobian); Levenberg-Marquardt steps on the
        leg's joints (clipped to their limits) and the base, accepted when they lower the
        cost.
        """
        model, rdata = self.robot.model, self._robot_data
        lo, hi = self.robot.q_min[iq], self.robot.q_max[iq]
        base = position is not None
        cols = np.r_[np.arange(6), iv] if base else iv
        q0 = q_fit.copy()
        if position is not None:
            q0[:3] = position
        q = q0.copy()
        q[iq] = np.clip(q[iq], lo, hi)
        n = len(cols)

        def residual(qq: np.ndarray) -> tuple[np.ndarray, pin.SE3]:
            pin.forwardKinematics(model, rdata, qq)
            X = pin.updateFramePlacement(model, rdata, fid).inverse() * target
            r = PLANT_SOLE_WEIGHT * pin.log6(X).vector
            if base:
                r = np.r_[r, pin.difference(model, q0, qq)[:6]]
            return r, X

        r, X = residual(q)
        cost = float(r @ r)
        mu = 1e-4
        for _ in range(PLANT_LM_ITERATIONS):
            Js = pin.computeFrameJacobian(model, rdata, q, fid, pin.ReferenceFrame.LOCAL)[:, cols]
            J = -PLANT_SOLE_WEIGHT * (pin.Jlog6(X) @ X.inverse().action @ Js)
            if base:
                Jd = np.zeros((6, n))
                Jd[:, :6] = np.eye(6)
                J = np.vstack([J, Jd])
            g = J.T @ r
            H = J.T @ J
            while True:
                dx = -np.linalg.solve(H + mu * np.eye(n), g)
                v = np.zeros(model.nv)
                v[cols] = dx
                qn = pin.integrate(model, q, v)
                qn[iq] = np.clip(qn[iq], lo, hi)
                rn, Xn = residual(qn)
                cn = float(rn @ rn)
                if cn < cost:
                    mu = max(mu / 3.0, 1e-9)
                    break
                mu *= 10.0
                if mu > 1e6:
                    break
            if not cn < cost:
                break
            done = cost - cn < 1e-14 * max(cost, 1.0)
            q, r, X, cost = qn, rn, Xn, cn
            if done:
                break
        if base:  # the remaining sole error as a rigid placement: the sole exactly on target
            pin.framesForwardKinematics(model, rdata, q)
            M = pin.XYZQUATToSE3(q[:7])
            q[:7] = pin.SE3ToXYZQUAT(target * rdata.oMf[fid].inverse() * M)
        return q


__all__ = ["SolePlacement"]
