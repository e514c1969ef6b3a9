# SPDX-License-Identifier: Apache-2.0
r"""Swing-sole targets of the kinematic balance mode, from the scaled person's feet.

:class:`FootTargets` turns one sample of the person into the sole pose each robot foot should
have if it swings (docs/retargeting.md, section 4b):

* horizontally, near the floor, the scaled person's foot in the world (``absolute``,
  :meth:`FootTargets.absolute_ankle`: each ankle's displacement since the first sample), kept
  on its side of the standing foot; high up (a kick) or while the robot lags the person's turn
  by more than 30 deg, blended towards the stride below (:meth:`FootTargets.place`);
* the stride: beside a standing foot, the person's foot-to-foot vector since the standing
  foot touched down times the leg-length ratio :math:`s` (:meth:`FootTargets.stride`): the
  scaled person's stride, not the robot's leg proportions' (the person's ankle rolls forward
  over the toes during stance, a flat robot sole does not); laterally the robot's stance width
  plus :math:`s` times the person's change of width, at least 70 % of it while the soles are
  side by side, down to in line (not crossed) two sole lengths apart fore-aft
  (:meth:`FootTargets.crossing_floor`);
* vertically :math:`s` times the person's foot height (the detector's: the lowest foot
  key-point above its ground);
* the yaw of the person's foot (ankle -> toe), kept while the foot points down, within
  :data:`FOOT_YAW_RANGE` of the waist's turn, turning at most :data:`FOOT_YAW_RATE`;
* pulled within the leg's reach of the scaled hip (:meth:`FootTargets.reachable`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..motion.calibration import Calibration, hip_heading, rotation_z, wrap_angle, yaw_of
from ..motion.phases import SIDES
from .support import FootSupport, rot_z

#: Largest yaw of a swinging sole from the person's waist turn [rad] (a foot held up behind,
#: sole up, points backwards: followed, it would twist the hip to its limit).
FOOT_YAW_RANGE = 0.8

#: Largest turn rate of a swing sole's yaw target [rad/s] (690 deg/s, the stance pivots' rate
#: in the G1 config). The person's foot yaw is kept while the foot points down and taken again
#: when it is level: on the dance spin it came back 97 deg away in one sample, and in flight the
#: robot turned its whole body 40 deg in one tick to follow the sole (the base has no
#: acceleration limit, the hip yaw has).
FOOT_YAW_RATE = 12.0

#: In the person's flight, largest turn rate of a swing sole's yaw target *relative to the
#: waist's turn* [rad/s]: the target turns with the person's waist plus at most this much. In
#: flight nothing holds the body and the floating base has no acceleration limit, so a sole
#: target catching up at :data:`FOOT_YAW_RATE` from where it lifted turned the whole robot
#: (the dance spin at 4.3 s and 7.2 s: the base at 600 deg/s for 50 ms, 21-24 deg past the
#: person's heading, which it had followed within 1 deg before the flight).
FLIGHT_FOOT_YAW_RATE = 4.0

_OTHER = {"left": "right", "right": "left"}

#: Absolute placement (``stepping.absolute``) is used in full while the robot's heading is
#: within the first angle of the person's, and not at all beyond the second (linear blend with
#: the stride placement in between) [rad]: a foot put at the person's spot behind a body that
#: lags the person's turn twists the legs (the karate kata's 140 deg turns on one foot: stance
#: slip 0.8 -> 5.4 mm without the gate).
ABSOLUTE_HEADING = (math.radians(30.0), math.radians(60.0))

#: A swing foot higher than this (scaled) may cross the standing foot's line [m].
CROSS_HEIGHT = 0.15

#: The width of a step is measured across the feet's mean heading while their yaws differ by
#: at most this [rad], else across the standing sole's.
STRIDE_MEAN_YAW = 0.5

#: A swing sole the leg cannot reach beside a standing sole rolled onto its toes (tiptoe), or
#: while the person is in flight (and ``lift_time`` after it, when the landing spot is taken),
#: is first raised by at most this much [m], then pulled towards the hip
#: (:meth:`FootTargets.reachable`): the rolled sole, or the flight's waist, lifts the hips with
#: the person's, whose legs are straight, and near the floor the swing leg then had no
#: horizontal reach left (on the tiptoe clip the foot was pulled right under the hip, 18 cm
#: sideways; ankle error 0.118 -> 0.126 leg lengths with the roll, 0.108 with the raise beside
#: it, 0.081 in flight too; a jump's landing 10 cm beside the person's foot: jumps 0.105 ->
#: 0.096). Not always: raising every unreachable swing target (tiptoe clip 0.074, jumps 0.090)
#: moved the kicks', kata's and spin's chaotic runs past their bounds (smallest kick lift 0.71
#: -> 0.69 of the person's, smallest kata lift 0.49 -> 0.21, spin heading error 47 -> 52 deg),
#: and so did raising whenever no robot foot stands (the kata's: 0.49 -> 0.39).
REACH_RAISE = 0.03


class FootTargets:
    """The person's feet -> robot swing-sole targets, for one run.

    Args:
        feet: The robot's soles (:class:`~qpretarget.retarget.support.FootSupport`).
        calibration: The run's calibration.
        leg_scale: Leg-length ratio robot / person :math:`s`.
        leg_lengths: side -> robot leg length (hip-knee-ankle) [m].
        leg_extension: Largest share of the leg length a swing target may ask for
            (``stepping.swing_reach``).
    """

    def __init__(
        self,
        feet: FootSupport,
        calibration: Calibration,
        leg_scale: float,
        leg_lengths: Mapping[str, float],
        leg_extension: float,
        *,
        absolute: bool = False,
        inline: bool = True,
        dt: float = 0.01,
    ) -> None:
        self.feet = feet
        #: Feet far apart fore-aft may stand in line (``stepping.inline_feet``).
        self.inline = inline
        self.dt = float(dt)
        #: side -> last yaw change of the swing-sole target since calibration [rad], unwrapped.
        self._yaw_target: dict[str, float] = {}
        self._waist_last: float | None = None  # the waist's turn at the last orient [rad]
        self.absolute = absolute
        #: side -> (robot ankle, person's ankle) at the first sample (``absolute`` placement).
        self.origin: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        #: Heading alignment of the absolute placement, person -> robot world (``start``;
        #: ``None``: the calibration's heading).
        self.align: np.ndarray | None = None
        #: (robot heading, person's waist turn) at the first sample [rad].
        self.heading0: tuple[float, float] | None = None
        self.calibration = calibration
        self.leg_scale = leg_scale
        self.leg_lengths = dict(leg_lengths)
        self.leg_extension = leg_extension
        #: side -> the person's ankle where that foot last touched down.
        self.human_anchor: dict[str, np.ndarray] = {}
        #: side -> the person's toe where that foot last touched down.
        self.human_toe: dict[str, np.ndarray] = {}
        self.width_r = 0.0
        self.width_h = 0.0
        #: The robot's sole length, heel to toe (its longest contact rectangle's) [m].
        rects = getattr(feet, "sole_rectangles", {})
        self.sole_length = max((float(r[1] - r[0]) for r in rects.values()), default=0.0)
        self._last_yaw: dict[str, float] = {}
        #: side -> the person's ankle-toe length [m]: the calibration's (the robot has a toe
        #: key-point) or the first sample's (it has none, as G1: the foot yaw and the pivots
        #: were never measured then).
        self.toe_length: dict[str, float] = {}
        #: side -> the person's foot pitch at the first sample (standing) [rad].
        self.pitch0: dict[str, float] = {}

    def start(
        self,
        kp: Mapping[str, np.ndarray],
        soles: Mapping[str, pin.SE3],
        heading: tuple[float, float] | None = None,
    ) -> None:
        """Anchor the person's feet where they are and measure both stance widths.

        ``heading``: the robot's heading and the person's waist turn now [rad] (the reference
        of :meth:`absolute_weight`).
        """
        self.heading0 = heading
        self.human_anchor = {
            side: np.array(kp[f"{side}_ankle"], float)
            for side in SIDES
            if f"{side}_ankle" in kp and np.all(np.isfinite(kp[f"{side}_ankle"]))
        }
        self.human_toe = {
            side: np.array(kp[f"{side}_toe"], float)
            for side in SIDES
            if f"{side}_toe" in kp and np.all(np.isfinite(kp[f"{side}_toe"]))
        }
        for side in SIDES:
            length = self.calibration.human_lengths.get(f"{side}_toe")
            toe, ankle = kp.get(f"{side}_toe"), kp.get(f"{side}_ankle")
            if not length and toe is not None and ankle is not None:
                length = float(np.linalg.norm(np.asarray(toe) - np.asarray(ankle)))
            if length and math.isfinite(length) and length > 0:
                self.toe_length[side] = float(length)
            pitch = self.foot_pitch(side, kp)
            if pitch is not None:
                self.pitch0[side] = pitch
        self.origin = {
            side: (self.feet.ankle_of(side, soles[side]), a.copy())
            for side, a in self.human_anchor.items()
        }
        # The metrics' alignment: the robot's heading at the first sample minus the person's
        # (hip line); the calibration's heading (from the waist frame) differed by 0.8 deg on
        # the front kicks, 4 cm sideways 2.8 m away.
        hips = kp.get("left_hip"), kp.get("right_hip")
        self.align = None
        if heading is not None and hips[0] is not None and hips[1] is not None:
            psi_h = float(hip_heading(hips[0], hips[1]))
            if math.isfinite(psi_h) and math.isfinite(heading[0]):
                self.align = rotation_z(heading[0] - psi_h)
        psi = yaw_of(soles["left"].rotation[:, 0])
        lateral = np.array([-math.sin(psi), math.cos(psi), 0.0])
        self.width_r = float(lateral @ (soles["left"].translation - soles["right"].translation))
        self.width_h = 0.0
        if len(self.human_anchor) == 2:
            d = self.calibration.rotation @ (self.human_anchor["left"] - self.human_anchor["right"])
            self.width_h = self.leg_scale * float(lateral @ d)

    def touched_down(self, side: str, kp: Mapping[str, np.ndarray]) -> None:
        """The person's foot ``side`` is down: the reference of the next stride."""
        ankle = kp.get(f"{side}_ankle")
        if ankle is not None and np.all(np.isfinite(ankle)):
            self.human_anchor[side] = np.array(ankle, float)
        toe = kp.get(f"{side}_toe")
        if toe is not None and np.all(np.isfinite(toe)):
            self.human_toe[side] = np.array(toe, float)

    def lifted(self, side: str, sole: pin.SE3) -> None:
        r"""A sole lifts into flight: its yaw target turns from where the sole is.

        The swing-sole yaw target :math:`\Delta\psi` (the change since calibration, turning at
        most :data:`FOOT_YAW_RATE`) keeps following the person's foot while the sole stands;
        a stance sole the person turned the body over (a dancer's swivel the pivot did not
        follow: the dance spin's left sole 100 deg from the person's foot when it lifted at
        6.58 s) is far from it, and the lift-off blend turned it there within ``lift_time``.
        In flight nothing holds the body, and the whole robot turned with the sole (the base at
        34 rad/s, the pelvis from 33 deg behind the person's to 20 deg past it within 0.06 s,
        tilted 15 deg). From the lift-off on, :math:`\Delta\psi`
        starts at the sole's own yaw change :math:`\psi_{sole} - \psi_{ref}` (unwrapped near
        the last target) and turns towards the person's foot at most :data:`FOOT_YAW_RATE`.
        """
        ref = self.feet.sole_ref[side].rotation
        dpsi = yaw_of(sole.rotation[:, 0]) - yaw_of(ref[:, 0])
        last = self._yaw_target.get(side)
        if last is not None:
            dpsi = last + math.atan2(math.sin(dpsi - last), math.cos(dpsi - last))
        self._yaw_target[side] = dpsi

    def moved(self, side: str, kp: Mapping[str, np.ndarray]) -> float:
        """How far the person's foot moved since it touched down, scaled [m].

        The smaller horizontal displacement of its ankle and its toe (``0`` when unknown): a
        foot rolling over its toe (push-off) or turning on it keeps one of them in place; a
        foot slid or put down elsewhere without a detected lift (a shuffle under the lift
        height) moves both.
        """
        out = math.inf
        for point, anchors in (("ankle", self.human_anchor), ("toe", self.human_toe)):
            p, p0 = kp.get(f"{side}_{point}"), anchors.get(side)
            if p is not None and p0 is not None:
                d = self.leg_scale * math.hypot(p[0] - p0[0], p[1] - p0[1])
                if math.isfinite(d):
                    out = min(out, d)
        return out if math.isfinite(out) else 0.0

    def foot_yaw(self, side: str, kp: Mapping[str, np.ndarray]) -> tuple[float | None, bool]:
        """The person's foot yaw (ankle -> toe) and whether it is measured now.

        A foot pointing down (its ankle-toe vector's horizontal part under 80 % of the
        calibration length: a kick, a toe stand) has no reliable yaw: the last reliable one is
        kept and the flag is ``False`` (pivots are detected on measured yaws only: flat feet
        and feet on their ball, heel up to about 35 deg; with flat feet only, 90 %, a dancer
        turning on the ball of the foot never pivoted).
        """
        toe, ankle = kp.get(f"{side}_toe"), kp.get(f"{side}_ankle")
        length = self.toe_length.get(side)
        if toe is None or ankle is None or not length:
            return None, False
        d = toe - ankle
        ratio = math.hypot(d[0], d[1]) / length
        if not math.isfinite(ratio):
            return self._last_yaw.get(side), False
        if ratio >= 0.8:
            self._last_yaw[side] = yaw_of(d)
        return self._last_yaw.get(side), ratio >= 0.8

    def stride(
        self,
        side: str,
        stance: pin.SE3,
        human: np.ndarray,
        heading: float | None = None,
        cross: bool = False,
    ) -> np.ndarray:
        r"""Robot ankle-to-ankle vector of a step from the person's, ``human`` (swing - stance).

        Scaled by :math:`s` and turned by the calibration heading; in the frame of ``heading``
        (default: the stance sole's yaw) the forward part is kept, the lateral part is the
        robot's reference stance width plus :math:`s` times the person's change of lateral
        distance since calibration, at least :meth:`crossing_floor` of the forward part (feet
        never cross).
        """
        d = self.leg_scale * (self.calibration.rotation @ human)
        psi = yaw_of(stance.rotation[:, 0]) if heading is None else heading
        c, s_ = math.cos(psi), math.sin(psi)
        fwd, lat = c * d[0] + s_ * d[1], -s_ * d[0] + c * d[1]
        sign = 1.0 if side == "left" else -1.0
        lat = self.width_r + sign * lat - self.width_h
        lat = sign * (lat if cross else max(self.crossing_floor(fwd), lat))
        return np.array([c * fwd - s_ * lat, s_ * fwd + c * lat, d[2]])

    def absolute_weight(self, heading: tuple[float, float] | None) -> float:
        r"""Share of the absolute placement in a swing target, from the heading error.

        With :math:`e` the robot's turn since the first sample minus the person's waist turn
        (``heading``: both now, [rad]), 1 for :math:`|e|` up to the first angle of
        :data:`ABSOLUTE_HEADING`, 0 from the second, linear in between.
        """
        if not self.absolute:
            return 0.0
        if heading is None or self.heading0 is None:
            return 1.0
        e = (heading[0] - self.heading0[0]) - (heading[1] - self.heading0[1])
        e = abs(math.atan2(math.sin(e), math.cos(e)))
        lo, hi = ABSOLUTE_HEADING
        return float(min(1.0, max(0.0, (hi - e) / (hi - lo))))

    def absolute_ankle(self, side: str, ankle: np.ndarray) -> np.ndarray:
        r"""The scaled person's ankle in the robot's world: :math:`a_r(0) + s R_a (a(t) - a(0))`.

        :math:`a_r(0)` is the robot ankle and :math:`a(0)` the person's at the first sample,
        :math:`s` the leg-length ratio and :math:`R_a = R_z(\psi_r(0) - \psi_h(0))` the heading
        alignment at the first sample (robot heading minus the person's hip-line heading,
        :func:`~qpretarget.motion.calibration.hip_heading`; the calibration heading when the
        hips are unknown): the scaled person of the human-referenced metrics (docs/metrics.md),
        so a foot put down there has no ankle displacement error, whatever the earlier steps
        did.
        """
        a_r0, a_h0 = self.origin[side]
        R_a = self.calibration.rotation if self.align is None else self.align
        d = self.leg_scale * (R_a @ (np.asarray(ankle, float) - a_h0))
        return a_r0 + d

    def offset(
        self,
        side: str,
        kp: Mapping[str, np.ndarray],
        soles: Mapping[str, pin.SE3],
        scaled: Mapping[str, np.ndarray],
        weight: float,
    ) -> float:
        """Horizontal distance of the robot's ankle from the scaled person's in the world [m].

        The robot's ankle under its sole against :meth:`absolute_ankle`: the ankle
        displacement error of the human-referenced metrics, in metres. ``0`` where a step
        could not put the foot there: unless the absolute placement is used in full
        (``weight``, :meth:`absolute_weight`, at 1), where :meth:`uncrossed` or
        :meth:`reachable` move the person's spot by more than 1 cm (feet too close across the
        hip line: on the playground jumps a settle step aimed there was pushed 12 cm further
        off), or when the person's ankle or hips are unknown.
        """
        a = kp.get(f"{side}_ankle")
        left, right = scaled.get("left_hip"), scaled.get("right_hip")
        if weight < 1.0 or a is None or side not in self.origin or left is None or right is None:
            return 0.0
        spot = self.absolute_ankle(side, a)
        sole = soles[side]
        if not np.all(np.isfinite(spot)):
            return 0.0
        target = self.uncrossed(side, spot, soles[_OTHER[side]], (left, right))
        p = target + sole.rotation @ self.feet.ankle_to_sole[side]
        p[2] = float(sole.translation[2])
        p = self.reachable(side, p, sole.rotation, scaled.get(f"{side}_hip"))
        moved = p - sole.rotation @ self.feet.ankle_to_sole[side] - spot
        if math.hypot(float(moved[0]), float(moved[1])) > 0.01:
            return 0.0
        d = (self.feet.ankle_of(side, sole) - spot)[:2]
        out = math.hypot(float(d[0]), float(d[1]))
        return out if math.isfinite(out) else 0.0

    def uncrossed(
        self, side: str, ankle: np.ndarray, stance: pin.SE3, hips: tuple[np.ndarray, np.ndarray]
    ) -> np.ndarray:
        """A swing ankle kept on its side of the standing foot.

        Along the scaled hip line (right hip -> left hip, horizontal), the swing ankle is at
        least :meth:`crossing_floor` of its fore-aft distance (70 % of the robot's reference
        stance width side by side, 0 two sole lengths apart) to its side of the standing ankle:
        the feet never cross (a person's crossed feet would put one robot leg through the other).
        The body's axis, not the standing sole's: a sole turned out in a fighting stance (60 deg
        on the front kicks) made a kick landing in front of the body count as crossed, and the
        push put it 0.58 m beside the person's.
        """
        axis = np.asarray(hips[0], float) - np.asarray(hips[1], float)
        axis[2] = 0.0
        n = float(np.linalg.norm(axis))
        if not (math.isfinite(n) and n > 1e-6):
            return ankle
        lateral = axis / n
        base = self.feet.ankle_of(_OTHER[side], stance)
        sign = 1.0 if side == "left" else -1.0
        lat = float(lateral @ (ankle - base))
        forward = np.array([lateral[1], -lateral[0], 0.0])
        low = self.crossing_floor(float(forward @ (ankle - base)))
        if sign * lat >= low:
            return ankle
        return ankle + (sign * low - lat) * lateral

    def crossing_floor(self, forward: float) -> float:
        r"""Least distance [m] of a swing ankle to its own side of the standing one, across.

        With :math:`f` the fore-aft distance of the two ankles and :math:`\ell` the robot's sole
        length (its rectangle's, heel to toe): :math:`0.7\,w_r` (the reference stance width
        :math:`w_r`) while :math:`|f| \le \ell` (the soles side by side would overlap),
        falling linearly to 0 at :math:`|f| = 2\ell` (a sole length of floor between them):
        feet far apart fore-aft may stand in line, never crossed. A person's front stance puts
        the feet in line or crossed by a few centimetres with the front foot 70 cm ahead; a
        floor at any distance put the karate kata's front foot 15 cm beside the person's
        (ankle error 0.122 -> 0.106 leg lengths with this one). Without ``inline``
        (``stepping.inline_feet: false``) :math:`0.7\,w_r` at any distance.
        """
        ell = self.sole_length
        if not (self.inline and math.isfinite(forward) and ell > 0.0):
            return 0.7 * self.width_r
        k = min(1.0, max(0.0, (abs(forward) - ell) / ell))
        return (1.0 - k) * 0.7 * self.width_r

    def reachable(
        self,
        side: str,
        sole: np.ndarray,
        R: np.ndarray,
        hip: np.ndarray | None,
        lift: float = 0.0,
    ) -> np.ndarray:
        r"""A swing sole position moved towards the scaled hip until the leg reaches it.

        Beyond the leg length the ankle is pulled along the hip-ankle line to ``leg_extension``
        of it; else, with :math:`h` the hip, :math:`a` the ankle and :math:`\rho L` the
        ``leg_extension`` share of the leg length, :math:`\lVert a_{xy} - h_{xy} \rVert \le
        \sqrt{(\rho L)^2 - (h_z - a_z)^2}` (an unreachable target stretches the leg and drags
        the foot along the ground instead of lifting it). With ``lift`` [m] a sole the leg
        cannot reach is first raised by at most ``lift``, to the height
        :math:`a_z = h_z - \sqrt{(\rho L)^2 - \lVert a_{xy} - h_{xy} \rVert^2}` at which it
        reaches, then moved horizontally (:data:`REACH_RAISE`, beside a standing sole rolled
        onto its toes and in flight).
        """
        L = self.leg_lengths.get(side)
        if L is None or hip is None or not np.all(np.isfinite(hip)):
            return sole
        offset = R @ self.feet.ankle_to_sole[side]
        ankle = sole - offset
        if np.linalg.norm(ankle - hip) > L:
            d3 = ankle - hip
            ankle = hip + d3 * (self.leg_extension * L / float(np.linalg.norm(d3)))
            return ankle + offset
        rho_l = self.leg_extension * L
        d = ankle[:2] - hip[:2]
        n = float(np.hypot(d[0], d[1]))
        r = math.sqrt(max(rho_l**2 - (hip[2] - ankle[2]) ** 2, 0.0))
        if n <= r:
            return sole
        out = sole.copy()
        # First raised, by at most `lift`, to the height at which the leg reaches the foot's
        # horizontal offset n: a_z = h_z - sqrt((rho L)^2 - n^2).
        if lift > 0.0 and n < rho_l:
            raise_ = min(lift, hip[2] - math.sqrt(rho_l**2 - n**2) - ankle[2])
            if raise_ > 0.0:
                out[2] += raise_
                r = math.sqrt(max(rho_l**2 - (hip[2] - ankle[2] - raise_) ** 2, 0.0))
                if n <= r:
                    return out
        out[:2] = sole[:2] - d * (1.0 - r / n)
        return out

    def foot_pitch(self, side: str, kp: Mapping[str, np.ndarray]) -> float | None:
        """Elevation of the person's ankle -> toe vector [rad] (toe up positive)."""
        toe, ankle = kp.get(f"{side}_toe"), kp.get(f"{side}_ankle")
        if toe is None or ankle is None:
            return None
        d = np.asarray(toe, float) - np.asarray(ankle, float)
        pitch = math.atan2(float(d[2]), math.hypot(float(d[0]), float(d[1])))
        return pitch if math.isfinite(pitch) else None

    def pitched(
        self, side: str, sole: pin.SE3, kp: Mapping[str, np.ndarray], ground: float
    ) -> pin.SE3:
        r"""A swing sole turned about its y axis like the person's foot, high enough.

        The person's foot pitch change since the first sample, :math:`\Delta\theta`, weighted
        by :math:`w = \mathrm{clip}((z - z_g - 0.05) / 0.15, 0, 1)` of the sole's height over
        the ground: flat within 5 cm of the floor (lift-off, landing), the person's pitch from
        20 cm up (a kick points the foot up: a flat sole there folds the knee to its limit and
        the ankle pitch to its -0.87 rad limit, the foot stopping at 0.66 of the kick height).
        """
        pitch, pitch0 = self.foot_pitch(side, kp), self.pitch0.get(side)
        if pitch is None or pitch0 is None:
            return sole
        w = min(1.0, max(0.0, (float(sole.translation[2]) - ground - 0.05) / 0.15))
        theta = -w * max(0.0, pitch - pitch0)
        if abs(theta) < 1e-12:
            return sole
        c, s_ = math.cos(theta), math.sin(theta)
        Ry = np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])
        return pin.SE3(sole.rotation @ Ry, sole.translation.copy())

    def orient(
        self,
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        soles: Mapping[str, pin.SE3],
        waist_dyaw: Callable[[], float],
        flight: bool = False,
    ) -> tuple[dict[str, pin.SE3], dict[str, tuple[float, np.ndarray] | None]]:
        """Swing-sole poses at the scaled ankles, with the feet's yaw.

        In the person's ``flight`` a yaw target turns with the waist plus at most
        :data:`FLIGHT_FOOT_YAW_RATE` relative to it, else at most :data:`FOOT_YAW_RATE`.

        Also ``(yaw, points)`` of each person's foot whose yaw is measured now (for pivots;
        else ``None``): its ankle and toe times the leg-length ratio (their displacements are
        the scaled person's; a ball-of-the-foot pivot keeps the toe in place, a heel pivot the
        ankle).
        """
        feet, cal = self.feet, self.calibration
        desired = {s: feet.swing_sole(s, scaled, kp, cal, soles[s], waist_dyaw) for s in SIDES}
        human_foot: dict[str, tuple[float, np.ndarray] | None] = {}
        for s in SIDES:
            yaw, measured = self.foot_yaw(s, kp)
            pts = [kp.get(f"{s}_{p}") for p in ("ankle", "toe")]
            found = [np.asarray(p, float) for p in pts if p is not None]
            xy = self.leg_scale * np.array(found) if found else None
            ok = yaw is not None and measured and xy is not None and bool(np.all(np.isfinite(xy)))
            human_foot[s] = (yaw, xy) if ok and yaw is not None and xy is not None else None
            if s in cal.human_foot_yaw and (yaw is not None or s in self.toe_length):
                base = waist_dyaw()
                if yaw is None:
                    # Never measured (the foot has pointed down since the first sample: a
                    # fighting stance on the balls of the feet): its ankle -> toe yaw is
                    # noise (DeepMimic's punch: 113 deg from the waist's turn, turning the
                    # other way), so the sole turns with the waist.
                    off = 0.0
                else:
                    dpsi = yaw - cal.human_foot_yaw[s]
                    off = math.atan2(math.sin(dpsi - base), math.cos(dpsi - base))
                    off = max(-FOOT_YAW_RANGE, min(FOOT_YAW_RANGE, off))
                dpsi = base + off
                last = self._yaw_target.get(s)
                if last is not None and flight and self._waist_last is not None:
                    lim = FLIGHT_FOOT_YAW_RATE * self.dt
                    rel = wrap_angle(last - self._waist_last)
                    rel += max(-lim, min(lim, wrap_angle(off - rel)))
                    dpsi = last + wrap_angle(base + rel - last)
                elif last is not None:
                    lim = FOOT_YAW_RATE * self.dt
                    step = wrap_angle(dpsi - last)
                    dpsi = last + max(-lim, min(lim, step))
                self._yaw_target[s] = dpsi
                R = rot_z(dpsi) @ feet.sole_ref[s].rotation
                desired[s] = pin.SE3(R, desired[s].translation)
        self._waist_last = waist_dyaw()
        return desired, human_foot

    def place(
        self,
        desired: dict[str, pin.SE3],
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        soles: Mapping[str, pin.SE3],
        standing: tuple[str, ...],
        heights: Mapping[str, float],
        ground: float,
        heading: tuple[float, float] | None = None,
        rolled: tuple[str, ...] = (),
        flight: bool = False,
    ) -> dict[str, pin.SE3]:
        """Place the swing soles (see the module docstring).

        ``rolled``: standing sides whose sole is rolled onto its toes (tiptoe): the other
        sole's target may be raised by :data:`REACH_RAISE` to stay within the leg's reach
        (:meth:`reachable`); so may both with ``flight`` (the person in flight, or just landed).

        With ``absolute`` the horizontal target is the scaled person's foot in the world
        (:meth:`absolute_ankle`, kept uncrossed), blended with the stride placement by
        :meth:`absolute_weight` of ``heading`` (robot heading, person's waist turn [rad]).

        Stride beside a standing foot, the person's foot height, within the leg's reach. The
        stride's width is measured across the mean heading of the two soles when they point
        within :data:`STRIDE_MEAN_YAW` of each other (a toed-out standing sole alone turned
        every step's width towards its side: the walk-stop's feet drifted 5 cm sideways), else
        across the standing sole's (feet turned apart, a karate stance: the mean heading
        twisted the legs).
        """
        feet = self.feet
        w_abs = self.absolute_weight(heading)
        for side, d in desired.items():
            p = d.translation.copy()
            other = _OTHER[side]
            h = heights.get(side)
            # A foot higher than CROSS_HEIGHT (scaled) may cross the standing foot's line: a
            # leg raised in front of the body (the one-leg balance holds the foot 25 cm across
            # the midline); near the floor the feet never cross. The self-collision constraint
            # keeps the legs apart either way.
            cross = h is not None and math.isfinite(h) and self.leg_scale * h > CROSS_HEIGHT
            a, b = kp.get(f"{side}_ankle"), self.human_anchor.get(other)
            if standing == (other,) and a is not None and b is not None:
                # Width across the feet's mean heading when they point within
                # STRIDE_MEAN_YAW of each other (a toed-out standing sole alone turned every
                # step's width towards its side: the walk-stop's feet drifted 5 cm), else
                # across the standing sole's (feet turned apart: a karate stance).
                y1, y2 = yaw_of(soles[other].rotation[:, 0]), yaw_of(d.rotation[:, 0])
                gap = math.atan2(math.sin(y2 - y1), math.cos(y2 - y1))
                heading_s = y1 + 0.5 * gap if abs(gap) <= STRIDE_MEAN_YAW else y1
                step = self.stride(side, soles[other], a - b, heading_s, cross)
                ankle = feet.ankle_of(other, soles[other]) + step
                if np.all(np.isfinite(ankle)):
                    p[:2] = (ankle + d.rotation @ feet.ankle_to_sole[side])[:2]
            w = w_abs
            if h is not None and math.isfinite(h):
                # High up (a kick) the stride from the standing foot, near the floor (where the
                # foot lands) the absolute spot: weight 1 up to 5 cm of scaled foot height, 0
                # from 20 cm (the toes-up band of `pitched`). A kick aimed at the person's
                # absolute foot stretched the leg forward from a pelvis that leans back, and
                # reached 0.64-0.70 of the height instead of 0.75.
                w *= min(1.0, max(0.0, (0.20 - self.leg_scale * h) / 0.15))
            if w > 0.0 and a is not None and side in self.origin:
                ankle = self.absolute_ankle(side, a)
                hips = scaled.get("left_hip"), scaled.get("right_hip")
                if (
                    standing == (other,)
                    and not cross
                    and hips[0] is not None
                    and hips[1] is not None
                ):
                    ankle = self.uncrossed(side, ankle, soles[other], (hips[0], hips[1]))
                if np.all(np.isfinite(ankle)):
                    q = (ankle + d.rotation @ feet.ankle_to_sole[side])[:2]
                    p[:2] = w * q + (1.0 - w) * p[:2]
            if h is not None and math.isfinite(h):
                p[2] = ground + self.leg_scale * h
            lift = REACH_RAISE if other in rolled or flight else 0.0
            p = self.reachable(side, p, d.rotation, scaled.get(f"{side}_hip"), lift)
            desired[side] = self.pitched(side, pin.SE3(d.rotation, p), kp, ground)
        return desired


#: Largest forward distance between the feet of the initial stance, in leg lengths.
INITIAL_STRIDE = 0.8
#: Highest start of a raised foot in a one-foot initial stance, in leg lengths (above the
#: standing sole).
INITIAL_RAISE = 0.5


class InitialStance(NamedTuple):
    """The run's initial posture: where the soles start and which of them stand."""

    #: side -> sole pose.
    soles: dict[str, pin.SE3]
    #: Sides standing on the floor (both, or the one the person stands on).
    standing: tuple[str, ...]


def initial_soles(
    feet: FootSupport,
    calibration: Calibration,
    leg_scale: float,
    leg_lengths: Mapping[str, float],
    kp: Mapping[str, np.ndarray],
    height_off: float,
    width_range: tuple[float, float] = (1.0, 1.0),
) -> InitialStance | None:
    r"""The soles of the person's first-sample stance (the run's initial posture).

    With :math:`d = s\,R_a (a_l - a_r)` the person's ankle-to-ankle vector scaled by the
    leg-length ratio :math:`s` and turned by the calibration heading :math:`R_a`, and
    :math:`d_f` its part along the robot's reference heading: the soles keep their reference
    height, flatness, yaw, stance width and mid-point, and are placed :math:`\pm d_f / 2`
    forward (within :data:`INITIAL_STRIDE` of the leg length). Across, standing on both feet,
    the stance width :math:`w_r` of the robot's reference becomes the person's,
    :math:`\mathrm{clip}(d_l, \rho_{lo} w_r, \rho_{hi} w_r)` with :math:`d_l` the part of
    :math:`d` across the reference heading and :math:`(\rho_{lo}, \rho_{hi})` =
    ``width_range`` (``stepping.initial_width_min`` / ``_max``; ``(1, 1)`` keeps the robot's
    width): each ankle's later target is its displacement since the first sample, so a start
    width other than the person's stays in every spot once the body turns. The yaws stay the
    robot's (the feet's yaws are followed as changes from calibration).

    A person standing on one foot (the lowest foot key-points, ankle, toe or heel, of the two
    feet differ by more than ``height_off``, the detector's lift height) starts on that foot,
    placed as above; the other sole, flat, is put where the scaled person's foot is from it:
    :math:`d_f` forward, the person's lateral offset across (not narrower than the robot's
    stance width unless higher than :data:`CROSS_HEIGHT`, as a swing foot), raised by
    :math:`s\,\Delta z` (the difference of the two lowest points, within
    :data:`INITIAL_RAISE` leg lengths); ``standing`` then names the lower foot only. Before,
    the robot started on both feet and its raised foot kept the person's first-sample offset
    through the whole run: each foot's later spots are the person's displacements from the
    first sample added to the robot's (``absolute`` placement), and the robot's raised foot
    started on the floor beside the other (CMU 49_18, one-leg balance: ankle error 0.19 leg
    lengths; with the raised sole at the robot's stance width instead of the person's 0.33 m,
    Talos's leg ended inside the person's and crouched under its target, 26 cm).

    Returns ``None`` (the robot starts from its reference posture) when an ankle or a foot's
    lowest point of the person is missing in the sample.
    """
    ankles = [kp.get(f"{side}_ankle") for side in SIDES]
    if any(a is None or not np.all(np.isfinite(a)) for a in ankles):
        return None
    lows = []
    for side in SIDES:
        z = [float(kp[f"{side}_{p}"][2]) for p in ("ankle", "toe", "heel") if f"{side}_{p}" in kp]
        lows.append(min((v for v in z if math.isfinite(v)), default=math.nan))
    if not all(math.isfinite(v) for v in lows):
        return None
    psi = yaw_of(feet.sole_ref["left"].rotation[:, 0])
    fwd_axis = np.array([math.cos(psi), math.sin(psi), 0.0])
    d = leg_scale * (calibration.rotation @ (np.asarray(ankles[0]) - np.asarray(ankles[1])))
    leg = min(leg_lengths.values()) if leg_lengths else 1.0
    reach = INITIAL_STRIDE * leg
    fwd = max(-reach, min(reach, float(fwd_axis @ d)))
    lat_axis = np.array([-math.sin(psi), math.cos(psi), 0.0])
    ref = feet.sole_ref
    width = float(lat_axis @ (ref["left"].translation - ref["right"].translation))
    both = abs(lows[0] - lows[1]) <= height_off
    widen = 0.0  # how much wider than the robot's reference the stance starts [m]
    if both and width > 0.0:
        lo, hi = width_range
        widen = min(max(float(lat_axis @ d), lo * width), hi * width) - width
    out = {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        shift = 0.5 * sign * (fwd * fwd_axis + widen * lat_axis)
        out[side] = pin.SE3(ref[side].rotation.copy(), ref[side].translation + shift)
    if both:
        return InitialStance(out, SIDES)
    # On one foot: the raised sole where the scaled person's is from the standing one (its
    # forward part within INITIAL_STRIDE; across, the person's offset, not narrower than the
    # robot's stance width unless the foot is higher than CROSS_HEIGHT, as a swing foot).
    up = 0 if lows[0] > lows[1] else 1
    raised, standing = SIDES[up], SIDES[1 - up]
    sign = 1.0 if raised == "left" else -1.0  # d is left minus right: sign d = raised - standing
    raise_z = min(leg_scale * abs(lows[0] - lows[1]), INITIAL_RAISE * leg)
    lat = float(lat_axis @ d)  # the raised foot's offset towards its own side
    if raise_z <= CROSS_HEIGHT:
        lat = max(lat, width)
    stand = out[standing].translation
    p = stand + sign * (fwd * fwd_axis + lat * lat_axis)
    p[2] = stand[2] + raise_z
    out[raised] = pin.SE3(out[raised].rotation, p)
    return InitialStance(out, (standing,))


__all__ = [
    "FOOT_YAW_RANGE",
    "FLIGHT_FOOT_YAW_RATE",
    "FOOT_YAW_RATE",
    "INITIAL_RAISE",
    "INITIAL_STRIDE",
    "FootTargets",
    "InitialStance",
    "initial_soles",
]
