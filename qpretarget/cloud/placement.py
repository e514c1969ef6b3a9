# SPDX-License-Identifier: Apache-2.0
r"""The robot's stance from the fitted pose: its supporting soles flat on the floor.

The EM fit (:mod:`.em`) gives the person's pose with the robot's joints, its soles wherever the
cloud put them; the command is that pose with its supporting soles flat on the floor (z = 0),
each kept where it was put down while it supports and the fit keeps it near there
(:class:`SolePlacement`, ``stability.plant``, ``stability.replant_*``).
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
#: A planted foot is also put down again when G1's own sole at the fitted configuration is
#: this many replant distances from it (the person's pelvis carried over a foot they keep
#: planted farther than G1's shorter legs reach: a walk's hips lagged 10 cm at the median
#: without it; at 2.0, 7-8 cm, and boxing's 10 s lost an arm for 0.70 and 0.87 s on 2 of 15
#: runs, at 1.0 none over 0.40 s; docs/point_clouds.md, eighteenth round).
ROBOT_REACH = 1.0


class SolePlacement:
    """The robot's configuration from a fitted one, its supporting soles on the floor.

    Args:
        robot: the robot (its soles are the ones put down).
        template: the fitted template (its model and data give the fitted soles).
        plant: ``stability.plant``: ``leg`` or ``rigid`` (:meth:`configuration`).

        replant_distance, replant_angle: ``stability.replant_*`` (:meth:`configuration`).

    Keeps the supporting soles' placements (:attr:`placed`) from frame to frame; :meth:`reset`
    forgets them.
    """

    def __init__(
        self,
        robot: RobotModel,
        template: Template,
        plant: str,
        *,
        replant_distance: float | None = None,
        replant_angle: float = math.inf,
    ) -> None:
        self.robot = robot
        self.template = template
        self.model = template.model
        self.plant = plant
        self.replant_distance = replant_distance
        self.replant_angle = float(replant_angle)
        #: foot -> its sole frame in the template's model (the fitted soles).
        self.sole_ids = {f: self.model.getFrameId(d.frame) for f, d in robot.feet.items()}
        self._robot_data = robot.model.createData()  # the robot's kinematics
        self.reset()

    def reset(self) -> None:
        """Forget the placements of the soles (a new run)."""
        #: Supporting foot -> its sole's placement on the floor (z = 0, flat: the x, y and
        #: heading of G1's sole at the fitted configuration when it was put down), kept
        #: while it supports.
        self.placed: dict[str, pin.SE3] = {}
        #: ... and the fitted (person-sized) sole's, laid flat, at the same moment: the fit's
        #: contact anchors (``CloudRetargeter._update_anchors``).
        self.fit_placed: dict[str, pin.SE3] = {}
        #: The feet the last :meth:`configuration` stood on their placements (its stance:
        #: the support less the feet put down again that frame), the first the primary.
        self.stance: tuple[str, ...] = ()
        #: The supporting feet the last :meth:`configuration` put down again (moved).
        self.moved: tuple[str, ...] = ()
        self._primary: str | None = None
        #: foot -> (sole frame, leg's configuration and velocity indices): :meth:`_leg`.
        self._legs: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}

    @staticmethod
    def heading(M: pin.SE3) -> float:
        """Heading [rad] of ``M``'s x axis in the horizontal plane."""
        R = M.rotation
        return math.atan2(R[1, 0], R[0, 0])

    @classmethod
    def flat(cls, M: pin.SE3) -> pin.SE3:
        """``M`` laid flat on the floor: its x, y and heading, z = 0, no tilt."""
        return pin.SE3(
            pin.rpy.rpyToMatrix(0.0, 0.0, cls.heading(M)), np.array([*M.translation[:2], 0.0])
        )

    def _far(self, placed: pin.SE3, fitted: pin.SE3, factor: float = 1.0) -> bool:
        """Whether a sole at ``fitted`` left ``placed`` (``stability.replant_*`` x ``factor``)."""
        if self.replant_distance is None:
            return False
        d = float(np.linalg.norm(fitted.translation[:2] - placed.translation[:2]))
        turn = abs(pin.log3(fitted.rotation @ placed.rotation.T)[2])
        return d > factor * self.replant_distance or turn > factor * self.replant_angle

    def configuration(self, q_fit: np.ndarray, support: Support) -> np.ndarray:
        r"""Robot configuration: the fitted joints, the supporting soles flat on the floor.

        **The stance.** A supporting foot is put down where the robot's sole is at the fitted
        configuration (G1's own leg at the fitted angles, its pelvis where the person's is),
        laid flat on the floor (x, y, heading; z = 0, :meth:`flat`), and kept there while it
        supports (no slip), unless the person's fitted sole moves farther than
        ``stability.replant_distance`` from where it was put down or turns by more than
        ``stability.replant_angle`` (or G1's sole at the fitted configuration
        :data:`ROBOT_REACH` times as far from its placement): then it is put down again and,
        that frame, is not part of the stance (a foot shuffled, pivoted or swung low,
        :attr:`moved`). G1's soles, not the person's: a robot with shorter legs stands
        narrower under the same hips (a boxer's wide stance put G1's feet under the
        person's and its hips 20 cm from theirs), and the fit's balance rows hold the
        robot's CoM over these soles. The fit's contact term anchors the person-sized soles
        put down at the same moments (:attr:`fit_placed`, ``CloudRetargeter._update_anchors``),
        so fit and command agree on when a foot stands and moves.

        The **primary** foot is the support's (the fit's) when it stands, else the stance's
        other foot; it keeps its placement from frame to frame, so a change of primary does
        not move the robot (before stop 49 a new primary was put under the fitted sole, and
        the command jumped by the fit's drift, up to 0.47 m).

        With ``stability.plant: rigid`` the whole fitted body is turned and moved with the
        primary sole onto its placement, :math:`M_{base}' = M_{target} M_{sole}^{-1}
        M_{base}`; with ``leg`` (default) the trunk keeps its fitted orientation and the
        supporting leg's joints put the sole there (:meth:`_plant_leg`), and the stance's
        other soles are put on theirs by their own legs (the nearest pose within their
        limits; where the leg cannot reach, ``CloudRetargeter._command`` moves the body).

        Why ``leg``: the cloud barely determines a sole's orientation (a small, partly hidden
        foot), so a rigid placement turned the whole robot, arms included, by the fit's error
        at the foot: 4-5 deg at the median on the standing clips, up to 45 deg of yaw on the
        boxing clip (the person pivots on the planted foot), the arm-direction error there
        51.5 deg where the fit's own arms were within 26.6.
        """
        if not self.robot.free_flyer or not self.robot.feet:
            self.stance, self.moved = (), ()
            return q_fit.copy()
        tdata, rdata = self.template.data, self._robot_data
        pin.framesForwardKinematics(self.model, tdata, q_fit)
        pin.framesForwardKinematics(self.robot.model, rdata, q_fit)
        # Where G1's own soles are with its pelvis where the person's is, at the fitted angles
        # (a smaller robot stands narrower under the same hips; the fit's balance rows hold
        # its CoM over these soles).
        fitted = {
            f: self.flat(rdata.oMf[self.robot.frame_id(self.robot.feet[f].frame)])
            for f in support.feet
        }
        for f in list(self.placed):
            if f not in fitted:
                del self.placed[f]
                del self.fit_placed[f]
        moved = []
        for f, M in fitted.items():
            # The person's foot decides (their sole against where it was put down): a pelvis
            # moving over planted feet moves G1's sole at the fitted angles too, by what its
            # shorter legs take differently, and is the legs' to take up; unless that takes
            # G1's sole as far (ROBOT_REACH: a stride longer than its legs reach).
            person = self.flat(tdata.oMf[self.sole_ids[f]])
            P = self.fit_placed.get(f)
            if P is None or self._far(P, person) or self._far(self.placed[f], M, ROBOT_REACH):
                if P is not None:
                    moved.append(f)
                self.placed[f] = M
                self.fit_placed[f] = person
        stance = [f for f in support.feet if f not in moved]
        if support.primary in stance:
            foot = support.primary
        elif self._primary in stance:
            foot = self._primary
        elif stance:
            foot = stance[0]
        elif support.primary is not None:
            foot = support.primary  # the only support moved: it stands where it went
        else:  # flight: the fitted sole's place, not kept
            foot = self._primary if self._primary is not None else next(iter(self.robot.feet))
        MF = rdata.oMf[self.robot.frame_id(self.robot.feet[foot].frame)]
        target = self.placed[foot] if foot in self.placed else self.flat(MF)
        self._primary = foot if support.feet else self._primary
        self.stance = tuple([foot, *(f for f in stance if f != foot)] if foot in stance else [])
        self.moved = tuple(moved)
        base = pin.XYZQUATToSE3(q_fit[:7])
        if self.plant == "leg":
            # The trunk moved with the sole's position, not turned with its tilt: a fitted
            # sole pitched by a raised heel, laid flat by a rigid turn about it, carried the
            # pelvis 0.9 m above it back by 0.9 sin(pitch) (12 cm at 8 deg, CMU 14_07).
            position = base.translation + target.translation - MF.translation
            q = self._plant_leg(q_fit, position, foot, target)
            for f in (*self.stance[1:], *self.moved):
                if f != foot:
                    q = self._plant_leg(q, None, f, self.placed[f])
            return q
        new_base = target * MF.inverse() * base
        q = q_fit.copy()
        q[:7] = pin.SE3ToXYZQUAT(new_base)
        return q

    def on_placements(
        self, q: np.ndarray, feet: tuple[str, ...], tolerance: tuple[float, float]
    ) -> tuple[str, ...]:
        """The feet of ``feet`` whose robot soles at ``q`` are on their placements.

        Within ``tolerance`` (distance [m], angle [rad]); one forward-kinematics pass.
        """
        feet = tuple(f for f in feet if f in self.placed)
        if not feet:
            return ()
        rdata = self._robot_data
        pin.framesForwardKinematics(self.robot.model, rdata, q)
        out = []
        for f in feet:
            M, P = rdata.oMf[self.sole_frame(f)], self.placed[f]
            d = float(np.linalg.norm(M.translation - P.translation))
            a = float(np.linalg.norm(pin.log3(P.rotation @ M.rotation.T)))
            if d <= tolerance[0] and a <= tolerance[1]:
                out.append(f)
        return tuple(out)

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
