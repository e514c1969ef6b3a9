# SPDX-License-Identifier: Apache-2.0
r"""Where the scaled body is rooted each tick, and the blends between roots.

The :class:`~qpretarget.retarget.Retargeter` chooses the root of the scaling each tick (the
supporting feet, ``double``/``left``/``right``, or ``flight``) and the robot ankles it is anchored
at; :class:`Rooting` scales the person from it (Poubel 2014 eq. 1,
:class:`~qpretarget.motion.scaling.Scaler`) and keeps the body continuous:

* when the root changes, the waist offset between the old and the new root's scaling decays
  over ``scaling.blend_time`` (minimum jerk);
* in flight (kinematic mode) the waist moves horizontally from where it left the ground like the
  person's, times the leg-length ratio (the scaled person of the human-referenced metrics; the
  calibration's root scale outside the kinematic mode), and its height is the person's change
  of height since calibration times the leg-length ratio (as in single support); where it left
  the ground is corrected by the person's stance-foot travel the robot's pinned foot did not
  follow (:meth:`Rooting.takeoff_drift`, ``stepping.flight_drift``);
* in kinematic single support the pelvis height is the person's change of height since
  calibration times the leg-length ratio, from the robot's waist height at the start of the run
  (:attr:`Rooting.waist_height`; the chain from the support foot places it horizontally);
* no supporting leg, nor a robot leg still standing on a foot the person lifted, is stretched
  beyond ``scaling.leg_extension`` of its length
  (:func:`~qpretarget.motion.scaling.limit_leg_extension`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..motion.calibration import Calibration
from ..motion.phases import SIDES
from ..motion.scaling import Scaler, limit_leg_extension


def anchors_points(anchors: Mapping[str, np.ndarray]) -> frozenset[str]:
    """Foot key-points of the supporting sides (not moved by blending)."""
    return frozenset(f"{s}_{p}" for s in anchors for p in ("ankle", "toe", "heel"))


class Rooting:
    """Scaling from a root that changes over the run (see the module docstring).

    Args:
        scaler: The run's scaler.
        calibration: The run's calibration.
        leg_scale: Leg-length ratio robot / person.
        leg_lengths: side -> robot leg length [m].
        blend_time: ``scaling.blend_time`` [s].
        leg_extension: ``scaling.leg_extension``.
        kinematic: The kinematic balance mode (pelvis height from the person in single
            support).
    """

    def __init__(
        self,
        scaler: Scaler,
        calibration: Calibration,
        leg_scale: float,
        leg_lengths: Mapping[str, float],
        *,
        blend_time: float,
        leg_extension: float,
        kinematic: bool,
    ) -> None:
        self.scaler = scaler
        self.calibration = calibration
        self.leg_scale = leg_scale
        self.leg_lengths = dict(leg_lengths)
        self.blend_time = blend_time
        self.leg_extension = leg_extension
        self.kinematic = kinematic
        self.root: str | None = None
        self.last_anchors: dict[str, np.ndarray] = {}
        self.blend: tuple[float, np.ndarray] | None = None
        self.flight_root: tuple[np.ndarray, np.ndarray] | None = None
        self.last_waist: tuple[np.ndarray, np.ndarray] | None = None
        #: Robot waist height [m] matching the person's at calibration: the reference
        #: posture's, or the initial stance's (``stepping.initial_stance``, set by the
        #: retargeter: a staggered stance holds the pelvis lower).
        self.waist_height = float(calibration.robot_waist[2])
        #: Largest horizontal correction of the waist at a take-off [m]
        #: (``stepping.flight_drift``, set by the retargeter; 0: none).
        self.flight_drift = 0.0
        #: Heading alignment of the person's displacements (the human-referenced metrics',
        #: set by the retargeter; the calibration's heading until then).
        self.align: np.ndarray | None = None
        #: side -> (robot ankle, person's ankle) where each standing robot foot's stance began.
        self.planted: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        #: side -> ankle of each standing robot foot at the last tick.
        self.standing_now: dict[str, np.ndarray] = {}
        #: How far the floor the person stands on lies under the person's lowest foot point at
        #: calibration [m] (set by the retargeter: a motion that starts in the air, 0 else).
        self.ground_drop = 0.0

    def waist_goal(self, z_h: float) -> float:
        r"""The kinematic pelvis height of a person's waist height ``z_h`` [m].

        :math:`z^* = z_0 + s\,(z_h - (z_h^{cal} - \delta))` with :math:`z_0` the robot's waist
        height matching the person's at calibration (:attr:`waist_height`), :math:`s` the
        leg-length ratio and :math:`\delta` = :attr:`ground_drop` (0 unless the person was in
        the air at calibration: then the height is measured from the floor they land on, not
        from where they were, which put every later stance 0.2 m lower: a crouch the person
        did not do).
        """
        return self.waist_height + self.leg_scale * (
            z_h - (float(self.calibration.human_waist[2]) - self.ground_drop)
        )

    def scale(
        self,
        t: float,
        human: Mapping[str, np.ndarray],
        root: str,
        anchors: dict[str, np.ndarray],
        standing: Mapping[str, np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        """Scaled key-points of one sample rooted at ``root`` / ``anchors``, blended.

        ``standing``: side -> ankle of a robot foot on the ground that is not among the
        ``anchors`` (the person lifted it, the robot's is still down): its leg is kept within
        ``leg_extension`` too (:func:`~qpretarget.motion.scaling.limit_leg_extension`).
        """
        if root == "flight" and self.root != "flight" and self.last_waist is not None:
            w_r, w_h = self.last_waist
            self.flight_root = (w_r + self.takeoff_drift(human), w_h)
        scaled = self.scale_from(human, root, anchors)
        if self.root is not None and root != self.root and self.blend_time > 0:
            old = self.scale_from(human, self.root, self.last_anchors)
            delta = old["waist"] - scaled["waist"]
            previous = self.blend_offset(t)
            if previous is not None:
                delta = delta + previous
            self.blend = (t, delta)
        self.root = root
        self.last_anchors = anchors
        offset = self.blend_offset(t)
        if offset is None:
            self.blend = None
        else:
            scaled = {k: (v if k in anchors_points(anchors) else v + offset)
                      for k, v in scaled.items()}  # fmt: skip
        if self.leg_lengths and anchors and self.scaler.method == "poubel":
            scaled, _ = limit_leg_extension(
                scaled, anchors, self.leg_lengths, self.leg_extension, standing
            )
        self.last_waist = (scaled["waist"].copy(), np.asarray(human["waist"], float).copy())
        return scaled

    def plant(
        self, robot_ankles: Mapping[str, np.ndarray], human: Mapping[str, np.ndarray]
    ) -> None:
        """Record this tick's standing robot feet (their ankles), after :meth:`scale`.

        A foot standing since an earlier tick keeps the pair (robot ankle, person's ankle) of
        its stance's first tick; a foot no longer standing is forgotten.
        """
        planted: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for side, r in robot_ankles.items():
            old = self.planted.get(side)
            h = human.get(f"{side}_ankle")
            if old is not None:
                planted[side] = old
            elif h is not None and np.all(np.isfinite(h)) and np.all(np.isfinite(r)):
                planted[side] = (np.array(r, float), np.array(h, float))
        self.planted = planted
        self.standing_now = {s: np.array(r, float) for s, r in robot_ankles.items()}

    def takeoff_drift(self, human: Mapping[str, np.ndarray]) -> np.ndarray:
        r"""Horizontal correction of the waist where the robot leaves the ground [m].

        Poubel eq. 1 roots the body at the robot's stance ankle :math:`r` with the person's
        ankle now, :math:`a(t)`. A person's stance foot that swivels on its ball or slides
        moves :math:`a(t)` away from where it touched down, :math:`a_0`, while the robot's
        foot stays pinned where it landed, :math:`r_0`: the waist target then carries that
        travel relative to the robot's foot, and the flight, which moves the waist like the
        person's from where it left the ground, kept it to the landing (on the dance spin the
        pelvis flew 12-13 cm ahead of the scaled person's). With :math:`s` the leg-length
        ratio and :math:`R_a` the heading alignment (:attr:`align`), the correction is the
        mean over the feet standing at the last tick of

        .. math:: c = s R_a (a(t) - a_0) - (r - r_0),

        horizontal, at most :attr:`flight_drift` long; the root change's blend
        (``scaling.blend_time``) takes the waist there smoothly. Zero without standing feet,
        without their person's ankles, or with ``flight_drift`` 0.
        """
        if self.flight_drift <= 0.0:
            return np.zeros(3)
        R = self.calibration.rotation if self.align is None else self.align
        drifts = []
        for side, (r0, h0) in self.planted.items():
            h, r = human.get(f"{side}_ankle"), self.standing_now.get(side)
            if h is None or r is None or not np.all(np.isfinite(h)):
                continue
            c = self.leg_scale * (R @ (np.asarray(h, float) - h0)) - (r - r0)
            c[2] = 0.0
            drifts.append(c)
        if not drifts:
            return np.zeros(3)
        c = np.mean(drifts, axis=0)
        n = float(np.linalg.norm(c))
        if n > self.flight_drift:
            c *= self.flight_drift / n
        return c if np.all(np.isfinite(c)) else np.zeros(3)

    def scale_from(
        self, human: Mapping[str, np.ndarray], root: str, anchors: Mapping[str, np.ndarray]
    ) -> dict[str, np.ndarray]:
        """Scale one sample from ``root`` (``double``/``left``/``right`` or ``flight``)."""
        cal = self.calibration
        if root == "flight" and self.flight_root is not None:
            w_r, w_h = self.flight_root
            # Horizontally the person's travel times the leg-length ratio in the kinematic mode
            # (the scaled person of the metrics and of the absolute foot placement), else the
            # calibration's root scale.
            k = self.leg_scale if self.kinematic else cal.root_scale
            waist = w_r + k * (cal.rotation @ (human["waist"] - w_h))
            if self.kinematic:
                # Height: the person's since calibration times the leg-length ratio, as in
                # single support, not from where the robot left the ground: a hop starts on the
                # ball of the foot, the robot's flat sole with its leg at full reach leaves
                # 12-15 cm lower, and the whole flight kept that offset (root height 18-22 cm
                # off on the playground jumps, landings with a knee 3 cm over the floor).
                waist[2] = self.waist_goal(float(human["waist"][2]))
            if np.all(np.isfinite(waist)):
                return self.scaler.scale_rooted(human, "waist", waist)
        scaled = self.scaler.scale(human, support=root, anchors=anchors)
        if self.kinematic and root in SIDES and self.scaler.method == "poubel":
            z = self.waist_goal(float(human["waist"][2]))
            dz = z - scaled["waist"][2]
            if math.isfinite(dz):
                fixed = anchors_points(anchors)
                up = np.array([0.0, 0.0, dz])
                scaled = {k: (v if k in fixed else v + up) for k, v in scaled.items()}
        return scaled

    def blend_offset(self, t: float) -> np.ndarray | None:
        """The waist offset still to blend out at ``t`` (``None`` when none)."""
        if self.blend is None:
            return None
        t0, delta = self.blend
        s = (t - t0) / self.blend_time
        if s >= 1.0:
            return None
        w = 1.0 - s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
        return w * delta


__all__ = ["Rooting", "anchors_points"]
