# SPDX-License-Identifier: Apache-2.0
r"""Kinematic stepping: each robot foot's contact switched from the person's support phases.

The *kinematic* balance mode (``retarget.support.mode: kinematic``, the default) makes the robot
do what the person does with its feet: every foot is a small state machine,

==========  ==================================================================================
stance      6-D contact on, the sole pinned where it landed; it *pivots* in place (the anchor's
            yaw ramped towards the person's foot yaw) when the person's foot turns by more than
            ``pivot_yaw`` while staying within ``pivot_radius`` of where it landed and the other
            foot swings (then to the end of the stance, wherever the foot goes), or by more
            than ``pivot_yaw_double`` with the other foot standing; the way that keeps the sole
            within half a turn of the body's heading
toe_off     the person's heel rises while the other robot foot stands flat: contact off, the
            sole turned about the front edge of its rectangle (:meth:`KinematicStepper.toe_pose`),
            and about the vertical through the middle of that edge as the person's foot turns
            on its ball (:meth:`KinematicStepper._toe_pivot`)
tiptoe      the person's heels both rise (the rise before a jump, reaching up on the toes), or
            one while the other foot is up (a hop's push-off): the 6-D contact is kept, its
            anchor turned about the sole's front edge every tick (a moving anchor: the front
            edge stays pinned, the ankle rises as the person's)
swing       contact off; the sole follows the scaled human ankle (position) and the person's foot
            yaw, kept flat and at least ``clearance`` above the ground
landing     the person's foot is down again: the sole goes down flat, at most ``land_speed``,
            to the ground under where it was; the contact is engaged when the sole is within
            ``land_height`` of the ground (``land_timeout`` after, within 5 ``land_height``)
==========  ==================================================================================

A stance foot is released when the person lifts that foot, provided the other robot foot stands
(else it waits for it to land: the robot never drops both feet because of a detection lag) or the
person is in flight (both feet up: jumps, running), which releases both. Touch-down keeps q and v
continuous: the sole arrives with the speed of the capped descent and the contact is anchored
where it is (flattened onto the ground by the contact's drift correction, by at most
``land_height``).

The static balance mode (Poubel 2014 Table I, :class:`~qpretarget.motion.phases.SupportSequencer`)
moves the CoM over the support foot before a foot lifts instead; see ``docs/retargeting.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..motion.calibration import wrap_angle
from ..motion.phases import _OTHER, SIDES, _positive, min_jerk

#: Foot states.
FOOT_STATES = ("stance", "toe_off", "tiptoe", "swing", "landing")

#: Foot states whose 6-D contact is on (a tiptoe contact's anchor rolls about the front edge).
CONTACT_STATES = frozenset({"stance", "tiptoe"})


#: A stance foot pivots only while the other foot's target is lower than this [m]: not under a
#: kick (with pivot_radius 0.12 m on the front kicks: swing-height ratio 0.69 and no contact
#: giving with this guard; without it the next landing made the contacts give).
PIVOT_SWING_MAX = 0.25

#: How long the person holds a foot just over the floor before it is put down for a re-step of
#: the other (``handover``) [s].
HOVER_TIME = 0.2

#: Longest wait of a foot put down for a re-step (``handover``) for that re-step [s].
HANDOVER_TIMEOUT = 0.6

#: A heel rising while the stance anchor pivots stops the pivot, to roll the sole onto its
#: toes, when the pivot can stop within this time at ``pivot_accel`` [s]: a slow turn before a
#: hop, not a dancer spinning on the ball of the foot (stopping every pivot to roll: the dance
#: spin's heading error 47 -> 51 deg, a 5 mm vertical settle).
TIPTOE_STOP = 0.05

#: The switches of :class:`StepSettings` (every other setting is a positive number).
BOOL_SETTINGS = frozenset(
    {
        "pivot", "pivot_double", "initial_stance", "toe_off", "tiptoe", "absolute", "takeoff",
        "settle_step", "handover", "inline_feet",
    }
)  # fmt: skip


@dataclass(frozen=True)
class StepSettings:
    """Parameters of :class:`KinematicStepper` (YAML ``retarget.support.stepping``).

    Attributes:
        clearance: Lowest height of a swinging sole [m] (a sole scraping the ground is held
            back by the ``ground`` constraint).
        land_height: A landing sole is in contact this close to the ground [m].
        land_speed: Largest descent speed of a landing sole [m/s].
        land_reach: A landing sole goes down once this close (horizontally) to its spot [m].
        land_timeout: After this long landing, a sole within 5 ``land_height`` is put down [s].
        land_wait: A landing sole that has not reached its spot goes down where it is, as
            after ``land_timeout``, once it has been landing this long while the person has
            already lifted the other foot [s]: the robot's other foot cannot follow the
            person's step before this one stands. On the front kicks the person steps the
            standing foot 0.1-0.3 s after putting the kicking one down 80-90 cm in front of it,
            a spot the robot's leg reaches only slowly (ankle rolls at their limits), and that
            step came 0.3 s late (ankle error 0.106 -> 0.095 leg lengths).
        min_stance: Shortest stance before a foot may lift again [s] (no flicker).
        lift_time: The swing target blends from the lift-off pose over this time [s].
        pivot_yaw: Turn of the person's stance foot that starts a pivot [rad] (15 deg).
        pivot_radius: Largest motion of the person's foot (scaled) before a pivot starts [m]
            (once started, the pivot follows the foot's yaw to the end of the stance).
        pivot_rate: Largest yaw rate of a pivoting anchor [rad/s].
        pivot_accel: Largest change rate of a pivoting anchor's yaw rate [rad/s^2]: the anchor
            speeds up and slows down smoothly (a pivot started at full rate in one tick asked
            for a joint-speed jump beyond the acceleration limits; the contact then gave
            1-2 mm).
        pivot: Whether stance feet pivot at all (on in the shipped G1 config, off in Talos's:
            on the front kicks Talos's pivots twisted its legs, docs/retargeting.md section 4b).
        pivot_double: Whether a stance foot also pivots while the other foot stands, once the
            person's foot has turned by ``pivot_yaw_double`` (measured since the other foot
            stood; not while the other foot pivots). A person turning on the ball of one foot
            with both feet down left the robot's sole behind by up to 177 deg, and the next
            lift-off turned it within 0.1 s, dragging the pelvis 5-12 cm down (the jumps at
            17.1 s).
        pivot_yaw_double: Turn of the person's stance foot that starts a pivot while the other
            foot stands [rad] (30 deg: at 15 deg, that of single support, the karate kata's
            stance feet turned against each other and its run broke).
        toe_off: Whether a stance foot rolls onto its toes when the person's heel rises
            (walk push-off, a rise before a jump): contact off, the sole turned about its front
            edge, which stays where it stood.
        toe_rise: Rise of the person's ankle above its stance height (scaled) that starts a
            toe-off [m]; under half of it the heel is down again.
        toe_pitch: Largest pitch of a sole in toe-off [rad].
        toe_time: Longest toe-off [s]: a heel held up longer (on the ball of the foot) is put
            down flat again, until the person's heel has been down.
        tiptoe: Whether stance soles roll onto their toes when both of the person's heels rise
            (the rise before a jump, a reach up on tiptoe), or one while the other foot is up
            and not about to land (a hop's push-off): unlike a toe-off the 6-D contacts stay
            on, each anchored to its sole rolled about the front edge
            (:meth:`KinematicStepper.toe_pose`, the pitch that raises the ankle as much as the
            person's, within ``toe_pitch``), a moving anchor whose step is fed forward
            (:meth:`~qpretarget.constraints.contacts.Contacts.set_anchor`): the front edges stay
            pinned, held as long as the person stands on the toes (no ``toe_time``). It ends in
            swing when the person lifts the foot (flight releases both) or flat in stance once
            the person's heel is down and the sole has rolled back.
        tiptoe_rate: Largest pitch rate of a tiptoe anchor [rad/s].
        tiptoe_accel: Largest change rate of a tiptoe anchor's pitch rate [rad/s^2]: the roll
            starts and stops smoothly (a step to full rate in one tick would ask the ankles for
            more than the joint acceleration limits, and the contact would give).
        restep: A stance foot whose person's foot moved this far since touch-down without a
            detected lift (both its ankle and toe, scaled: a shuffle under the detector's lift
            height, a slide) steps there [m]: lifted at least ``lift_time``, put down where
            the person's foot is.
        settle_step: Whether a stance foot put down away from the person's foot steps there
            once the person stands still: while the person has stood on both feet for
            ``settle_time`` (and the robot on both soles as long), the robot foot whose ankle is
            furthest from the scaled person's (more than ``restep``, horizontally, with the
            absolute placement in full: the robot's heading within 30 deg of the person's) is
            lifted at least ``lift_time`` and put down there, once per stance of the person's
            foot. Its swing stays at ``clearance``, under the 3 cm of a counted step. Why: a
            landing the legs could not reach in time (a long stride back out of a kick) kept
            its offset until the foot's next step, for seconds when the person stands still
            after it (the front kicks' last 3 s, 5-9 cm).
        settle_time: How long the person stands still on both feet before a settle step [s].
        handover: Whether a swing foot the person holds just over the floor is put down so that
            the standing foot can re-step: when the person's standing foot moved more than
            ``restep`` (a slide, on the ball of the foot) while the other foot hovers (the
            person's foot under the detector's ``height_off``, slower than ``speed_on``, for
            :data:`HOVER_TIME`, the robot's sole within ``clearance`` + 1 cm of the floor),
            the hovering foot lands, the standing foot steps to the person's, and the first
            one lifts again (after at most :data:`HANDOVER_TIMEOUT` if no re-step comes). A
            robot cannot slide a standing foot; without a second foot down it cannot step
            either: on the dance spin the person slid a foot 13-16 cm with the other 3 cm up,
            and the robot's stayed there for 1.9 s, to the end.
        initial_stance: Start the run in the person's first-sample stance (the soles where the
            scaled person's feet are, solved to convergence before the first tick,
            :func:`~qpretarget.retarget.feet.initial_soles`; on one foot, the other raised,
            when the person stands on one) instead of the robot's reference posture with the
            feet side by side.
        initial_width_min: Narrowest start stance, a share of the robot's reference stance
            width: the run starts at the scaled person's stance width (across the robot's
            reference heading) within ``initial_width_min`` .. ``initial_width_max`` of the
            robot's. The human-referenced ankle error compares each ankle's displacement since
            the first sample, so a robot starting wider than the person stays off by the
            difference once the body turns (the dance spin: 0.237 m against the scaled
            person's 0.112 m, ankle error 0.117 -> 0.103 leg lengths with the person's width).
        initial_width_max: Widest start stance, a share of the robot's reference stance width
            (1.0: never wider; starting the front kicks and the karate kata at the person's
            1.17-1.33 times the robot's width gave no better kata, 0.117-0.125 leg lengths, and
            worse kicks, 0.095 -> 0.098-0.112, docs/retargeting.md *The start width*).
        flight_drift: Largest horizontal correction of the waist at a take-off [m]: the
            person's stance-foot travel (a swivel on the ball of the foot, a slide) that the
            robot's pinned foot did not follow, scaled by the leg-length ratio
            (:meth:`~qpretarget.retarget.rooting.Rooting.takeoff_drift`; on the dance spin
            the flights kept the pelvis 12-13 cm ahead of the scaled person's, ankle error
            0.103 -> 0.095 leg lengths; the same at 0.08 and 0.25 m).
        absolute: Swing soles aim at the scaled person's foot positions in the world (each
            ankle's displacement since the first sample, scaled and turned by the calibration
            heading, added to the robot ankle's first position: the frame of the human-referenced
            metrics) instead of the person's stride from the robot's standing foot. A landing
            that falls short (a kick pulls the pelvis back) is then not carried into every later
            step (:meth:`~qpretarget.retarget.feet.FootTargets.place`).
        inline_feet: Whether swing feet far apart fore-aft may stand in line: the no-crossing
            floor (70 % of the reference stance width across the hip line) falls from one sole
            length fore-aft to 0 at two
            (:meth:`~qpretarget.retarget.feet.FootTargets.crossing_floor`; the karate kata's
            front stance, its feet crossed 4 cm with the front foot 70 cm ahead, was put 15 cm
            beside the person's: ankle error 0.122 -> 0.106). ``false``:
            the floor at any distance (Talos's config: in line, its thick legs held each other
            apart, kata 0.271 -> 0.344, kicks 0.169 -> 0.178).
        flight_foot_weight: In the person's flight, a swing sole's task weight times this once
            the sole's target is 10 cm over the ground (full weight up to 5 cm, linear
            between; changed at most ``1 / lift_time`` per second). With nothing on the ground
            the floating base is the cheapest way to move a foot: at full weight the soles,
            weighted 10-100 times the pelvis, moved the whole body (a split leap's pelvis
            17 cm over the person's, a tuck jump's 6-10 cm under it).
        swing_orientation_weight: A swing sole's orientation rows weighted times this once the
            sole's target is 10 cm over the ground (full weight up to 5 cm, linear between,
            changed at most ``1 / lift_time`` per second): a sole high in the air need not be
            flat or turned exactly, and where its ankle is at a limit (a leg raised high with
            the body leaning back) a fully weighted sole orientation turned the pelvis instead.
        swing_yaw_rate: Largest yaw rate of a swing sole's target 10 cm or more over the floor
            [rad/s] (690 deg/s): a foot lifted 100-180 deg from the person's foot yaw turned
            within the 0.1 s ``lift_time`` blend, at up to 1,800 deg/s, and the turning leg
            dragged the pelvis 5-7 cm down.
        swing_yaw_rate_floor: The same up to 5 cm over the floor [rad/s] (460 deg/s; linear in
            between, the ramp of the swing weights): a sole turning fast just off the floor (a
            re-step turning 80 deg, a lift-off turning 140 deg) still pulled the pelvis 4-5 cm
            under its target at 690 deg/s; high up (the kata's kicks) the faster limit keeps
            the foot with the person's.
        swing_reach: A swing sole's target is kept within this share of the leg length from
            the scaled hip (:meth:`~qpretarget.retarget.feet.FootTargets.reachable`), in (0, 1].
            The standing legs keep ``scaling.leg_extension`` (0.92 by default: a straight
            stance knee stalls the pelvis), but a person puts a foot down with the knee nearly
            straight: with 0.92 the long strides' landings (kicks, kata) were pulled 3-5 cm
            towards the hip, and each stance kept the offset (docs/retargeting.md).
        takeoff: Whether the robot's feet may leave the ground before the person's at a
            take-off (:meth:`~qpretarget.retarget.Retargeter._anticipate_takeoff`): while the
            scaled person's waist rises faster than ``takeoff_speed`` and is more than
            ``takeoff_gap`` over the robot's (the person's height since calibration times the
            leg-length ratio, the height rule of single support and flight), with a robot foot
            standing, both soles are released into flight (rising with the person's ankles),
            until the person's flight is detected, for at most ``takeoff_hold``, or until the
            person's waist stops rising (the soles are then put down again). A person pushes
            off on the toes, the ankles rising with the heels: on the playground jumps the
            waist rose 14 cm (scaled 10) in 0.12 s with the toes still down, and a robot
            standing on its soles (its roll onto the toes held by the ankle's pitch range and
            rate) stayed 8-10 cm under it until the person's feet left the floor.
        takeoff_speed: Rising speed of the scaled person's waist above which a take-off is
            anticipated [m/s] (a walk's waist rises at 0.2-0.3 m/s, a push-off into a jump
            at 1-1.5).
        takeoff_gap: Height of the scaled person's waist over the robot's above which a
            take-off is anticipated [m].
        takeoff_hold: Longest anticipated take-off before the person's flight [s].
    """

    clearance: float = 0.02
    land_height: float = 0.002
    land_speed: float = 0.5
    land_reach: float = 0.02
    land_timeout: float = 0.3
    land_wait: float = 0.1
    min_stance: float = 0.05
    lift_time: float = 0.1
    pivot_yaw: float = math.radians(15.0)
    pivot_radius: float = 0.03
    pivot_rate: float = math.radians(360.0)
    pivot_accel: float = 100.0
    pivot: bool = True
    pivot_double: bool = True
    pivot_yaw_double: float = math.radians(30.0)
    initial_stance: bool = True
    initial_width_min: float = 0.7
    initial_width_max: float = 1.0
    flight_drift: float = 0.15
    toe_off: bool = True
    toe_rise: float = 0.02
    toe_pitch: float = 0.6
    toe_time: float = 0.4
    tiptoe: bool = True
    tiptoe_rate: float = 10.0
    tiptoe_accel: float = 200.0
    restep: float = 0.05
    settle_step: bool = True
    settle_time: float = 0.5
    handover: bool = True
    absolute: bool = True
    inline_feet: bool = True
    flight_foot_weight: float = 0.1
    swing_orientation_weight: float = 0.1
    swing_reach: float = 0.97
    swing_yaw_rate: float = 12.0
    swing_yaw_rate_floor: float = 8.0
    takeoff: bool = True
    takeoff_speed: float = 0.8
    takeoff_gap: float = 0.03
    takeoff_hold: float = 0.15

    def __post_init__(self) -> None:
        """Validate.

        Raises:
            ValueError: A value is not positive, or a switch is not a bool.
        """
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if name in BOOL_SETTINGS:
                if not isinstance(value, bool):
                    raise ValueError(f"{name} must be true or false, got {value!r}")
            else:
                _positive(value, name)
        for name in ("flight_foot_weight", "swing_orientation_weight"):
            if getattr(self, name) > 1.0:
                raise ValueError(
                    f"{name} is a factor on the sole's weight in (0, 1], got "
                    f"{getattr(self, name)!r}"
                )
        if self.initial_width_min > self.initial_width_max:
            raise ValueError(
                "initial_width_min must not exceed initial_width_max, got "
                f"{self.initial_width_min!r} > {self.initial_width_max!r}"
            )
        if self.swing_reach > 1.0:
            raise ValueError(
                f"swing_reach is a share of the leg length in (0, 1], got {self.swing_reach!r}"
            )


@dataclass
class StepCommand:
    """What the stepper asks of the controller for one tick.

    Attributes:
        contacts: Sides in contact from this tick on.
        switched: ``True`` when ``contacts`` changed at this tick.
        feet: side -> sole target (``pinocchio.SE3``): the anchor of a standing foot.
        anchors: side -> new contact anchor (landing flattened, pivots) to set this tick.
        states: side -> foot state (:data:`FOOT_STATES`).
        pivoting: sides whose anchor moves this tick, pivoting or rolling on its toes (a
            moving anchor: its step is fed forward,
            :meth:`~qpretarget.constraints.contacts.Contacts.set_anchor`).
    """

    contacts: tuple[str, ...]
    switched: bool
    feet: dict[str, pin.SE3] = field(default_factory=dict)
    anchors: dict[str, pin.SE3] = field(default_factory=dict)
    states: dict[str, str] = field(default_factory=dict)
    pivoting: frozenset[str] = frozenset()

    @property
    def label(self) -> str:
        """``left-state/right-state``, as recorded in the run's ``support_state``."""
        return "/".join(self.states[s] for s in SIDES)


def _yaw_of(R: np.ndarray) -> float:
    return math.atan2(R[1, 0], R[0, 0])


def _flat(yaw: float, p: np.ndarray) -> pin.SE3:
    c, s = math.cos(yaw), math.sin(yaw)
    return pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.asarray(p, float))


def _edge_turn(x_front: float, theta: float) -> pin.SE3:
    r"""Pitch ``theta`` about the sole's front edge, in the sole frame.

    :math:`(R_y(\theta),\ e - R_y(\theta) e)` with :math:`e = (x_{front}, 0, 0)`: the edge's
    points stay in place.
    """
    c, s_ = math.cos(theta), math.sin(theta)
    Ry = np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])
    edge = np.array([x_front, 0.0, 0.0])
    return pin.SE3(Ry, edge - Ry @ edge)


def _ramp(w: float, r: float, dt: float, rate_max: float, accel: float) -> float:
    r"""Rate ``w`` one tick on towards the angle ``r`` still to turn, stopping there in time.

    It moves by at most :math:`a\,dt` towards :math:`\operatorname{sign}(r) \min(|r| / dt,
    \omega_{max}, \sqrt{2 a |r|})` (``r = 0``: it brakes to a stop).
    """
    mag = min(abs(r) / dt, rate_max, math.sqrt(2.0 * accel * abs(r)))
    dw = accel * dt
    return max(w - dw, min(w + dw, math.copysign(mag, r)))


def swing_height_ramp(height: float) -> float:
    r"""Share of a swing sole's high-in-the-air settings at ``height`` over the floor [m].

    :math:`r = \mathrm{clip}((h - 0.05) / 0.05, 0, 1)`: 0 up to 5 cm (lift-offs and landings keep
    the near-floor values), 1 from 10 cm. The ramp of the swing weights
    (:meth:`~qpretarget.retarget.Retargeter._swing_weights`) and of the swing yaw rate.
    """
    return min(1.0, max(0.0, (height - 0.05) / 0.05))


def blend_pose(a: pin.SE3, b: pin.SE3, w: float) -> pin.SE3:
    """Pose ``w`` of the way from ``a`` to ``b`` (straight line, geodesic rotation)."""
    R = a.rotation @ pin.exp3(w * pin.log3(a.rotation.T @ b.rotation))
    return pin.SE3(R, a.translation + w * (b.translation - a.translation))


def _xy(points: np.ndarray) -> np.ndarray:
    """Horizontal parts ``(k, 2)`` of one point ``(3,)`` or of points ``(k, 3)``."""
    return np.atleast_2d(np.asarray(points, float))[:, :2].copy()


#: Points of the ankle-toe segment tried for the one a foot pivots on (:func:`_least_motion`).
_SEGMENT = np.linspace(0.0, 1.0, 11)


def _least_motion(xy: np.ndarray, xy0: np.ndarray) -> float:
    r"""Smallest horizontal motion of a point of the foot since ``xy0`` [m].

    One point (the ankle): its motion. Two (ankle, toe): the least over the points of the
    segment between them, :math:`\min_{\alpha} \lVert (1-\alpha)(a - a_0) + \alpha (t - t_0)
    \rVert` for :math:`\alpha \in [0, 1]`: a foot turning on its ball moves both the ankle and
    the toe key-point by several centimetres (10 and 4 cm over a 100 deg turn on the karate
    kata), the ball between them stays.
    """
    d = np.asarray(xy, float) - np.asarray(xy0, float)
    if len(d) == 1:
        return float(np.linalg.norm(d[0]))
    path = (1.0 - _SEGMENT)[:, None] * d[0] + _SEGMENT[:, None] * d[1]
    return float(np.min(np.linalg.norm(path, axis=1)))


class KinematicStepper:
    """Per-foot contact switching from the person's support phases (see the module docstring).

    Args:
        settings: :class:`StepSettings`.
        dt: Control period [s].
        toes: side -> ``(front edge x [m], ankle (3,))`` in the sole frame, for toe-offs.
    """

    def __init__(
        self,
        settings: StepSettings | None = None,
        *,
        dt: float = 0.01,
        toes: Mapping[str, tuple[float, np.ndarray]] | None = None,
    ) -> None:
        self.settings = settings if settings is not None else StepSettings()
        self.dt = float(dt)
        #: side -> (front edge x of the sole [m], ankle position in the sole frame (3,)): the
        #: toe-off geometry (no toe-off without it).
        self.toes = dict(toes or {})
        self.states: dict[str, str] = {s: "stance" for s in SIDES}
        self.ground = 0.0
        self.log: list[tuple[float, str]] = []
        self._since: dict[str, float] = {s: 0.0 for s in SIDES}
        self._landing: dict[str, pin.SE3] = {}
        self._target: dict[str, pin.SE3] = {}
        #: side -> [person's foot yaw last sample, its turn since the pivot's start (unwrapped),
        #: its points then, the anchor's yaw then, pivot started].
        self._pivot: dict[str, list] = {}
        #: Sides whose pivot is measured while the other foot stands (``pivot_double``).
        self._pivot_double: set[str] = set()
        #: side -> yaw rate of a pivoting anchor [rad/s] (ramped by ``pivot_accel``).
        self._omega: dict[str, float] = {}
        #: side -> the pivoting anchor's yaw, unwrapped [rad].
        self._yaw_u: dict[str, float] = {}
        #: The robot's floating-base heading at this tick (``update``'s ``base_yaw``) [rad].
        self._base_yaw: float | None = None
        #: side -> [person's foot yaw last measured, its turn since the toe-off began
        #: (unwrapped), the anchor's yaw then] (:meth:`_toe_pivot`).
        self._toe_turn: dict[str, list[float]] = {}
        self._anchor: dict[str, pin.SE3] = {}
        self._lift: dict[str, tuple[float, pin.SE3]] = {}
        self._toe_down: set[str] = set()
        self._toe_armed: set[str] = set()
        self._restep: set[str] = set()
        #: Since when the person has stood on both feet (``None``: not now).
        self._both_since: float | None = None
        #: Sides that made their settle step during the person's current stance of that foot.
        self._settled: set[str] = set()
        #: side -> [time it was put down for the other's re-step, that re-step started]
        #: (``handover``).
        self._handover: dict[str, list] = {}
        #: side -> since when the person holds that foot just over the floor.
        self._hover_since: dict[str, float] = {}
        #: side -> pitch of a tiptoe anchor about the sole's front edge [rad].
        self._roll: dict[str, float] = {}
        #: side -> pitch rate of a tiptoe anchor [rad/s] (ramped by ``tiptoe_accel``).
        self._roll_rate: dict[str, float] = {}
        self._started = False

    def __repr__(self) -> str:
        """Foot states."""
        return f"KinematicStepper({self.states})"

    @property
    def started(self) -> bool:
        """Whether :meth:`reset` ran (the first :meth:`update` calls it)."""
        return self._started

    @property
    def contacts(self) -> tuple[str, ...]:
        """Sides whose contact is on (in stance, or on tiptoe)."""
        return tuple(s for s in SIDES if self.states[s] in CONTACT_STATES)

    @property
    def rolled(self) -> tuple[str, ...]:
        """Sides whose contact is on with the sole rolled onto its toes (tiptoe)."""
        return tuple(s for s in SIDES if self.states[s] == "tiptoe")

    def reset(
        self,
        t: float,
        soles: Mapping[str, pin.SE3],
        human_foot: Mapping[str, tuple[float, np.ndarray] | None] | None = None,
        standing: tuple[str, ...] = SIDES,
    ) -> None:
        """Start with the ``standing`` feet in stance where they are, the others in swing.

        The ground is the standing soles' mean height. A foot not standing (a run that starts
        on one foot: :func:`~qpretarget.retarget.feet.initial_soles`) starts in swing from
        where it is, as if it had just lifted there.
        """
        if not standing or any(s not in SIDES for s in standing):
            raise ValueError(f"standing must name at least one of {SIDES}, got {standing!r}")
        self.ground = float(np.mean([soles[s].translation[2] for s in standing]))
        self.states = {s: ("stance" if s in standing else "swing") for s in SIDES}
        self._since = {s: t for s in SIDES}
        self._anchor = {s: soles[s].copy() for s in SIDES}
        self._landing, self._target, self._pivot, self._lift = {}, {}, {}, {}
        self._pivot_double = set()
        self._omega, self._yaw_u = {}, {}
        self._toe_down, self._toe_armed, self._restep = set(), set(), set()
        self._both_since, self._settled = None, set()
        self._handover, self._hover_since = {}, {}
        self._roll, self._roll_rate = {}, {}
        for side in SIDES:
            if side not in standing:
                self._lift[side] = (t, soles[side].copy())
        for side, foot in (human_foot or {}).items():
            if foot is not None and side in standing:
                yaw0 = _yaw_of(soles[side].rotation)
                self._start_pivot(side, foot, yaw0)
        self.log = [(t, "/".join(self.states[s] for s in SIDES))]
        self._started = True

    # ------------------------------------------------------------------------------ the tick
    def update(
        self,
        t: float,
        human_support: Mapping[str, bool],
        soles: Mapping[str, pin.SE3],
        desired: Mapping[str, pin.SE3],
        human_foot: Mapping[str, tuple[float, np.ndarray] | None],
        flight: bool | None = None,
        toe_rise: Mapping[str, float] | None = None,
        moved: Mapping[str, float] | None = None,
        low: Mapping[str, bool] | None = None,
        offset: Mapping[str, float] | None = None,
        hover: Mapping[str, bool] | None = None,
        base_yaw: float | None = None,
    ) -> StepCommand:
        """Advance every foot by one tick.

        Args:
            t: Time [s].
            human_support: side -> the person's foot is in support (detector, with hysteresis).
            soles: side -> current sole pose of the robot.
            desired: side -> sole pose from the scaled person (scaled ankle, foot yaw, flat).
            human_foot: side -> ``(yaw [rad], scaled points)`` of the person's foot (the yaw in
                the capture's frame: only its change counts; its ankle
                ``(3,)``, or ankle and toe ``(2, 3)``: a pivot keeps one of them within
                ``pivot_radius``), or ``None`` when unknown (no pivots then).
            flight: The person is in flight (both feet up; default: neither foot in support).
                Only then may both robot feet leave the ground.
            toe_rise: side -> rise of the person's ankle above its stance height, scaled [m]
                (heel off the ground: toe-off; ``None``: no toe-offs).
            moved: side -> how far the person's foot moved since touch-down, scaled [m]
                (re-steps beyond ``restep``; ``None``: none).
            low: side -> the person's foot is under the detector's touch-down height
                (``height_on``): a foot about to be put down. A heel rising while the other
                foot is up rolls the sole onto its toes (tiptoe) only while that foot is not
                low (a hop's push-off, not a walk's heel-off just before the other foot
                lands, which is a toe-off once the other foot stands). ``None``: never low.
            offset: side -> horizontal distance of the robot's ankle from the scaled person's
                in the world [m] (:meth:`~qpretarget.retarget.feet.FootTargets.offset`; 0 where
                the absolute placement is not in full): settle steps (``settle_step``).
                ``None``: none.
            hover: side -> the person holds that foot just over the floor (under the
                detector's ``height_off``, slower than its ``speed_on``): ``handover``.
                ``None``: never.
            base_yaw: The robot's floating-base heading now [rad]: a pivot turns its sole the
                way that keeps it on the body's side (:meth:`_pivot_anchor`). ``None``: the
                shorter way from where the sole is.

        Returns:
            The :class:`StepCommand` of this tick.
        """
        self._base_yaw = base_yaw
        if not self._started:
            self.reset(t, soles, human_foot)
        st = self.settings
        before = self.contacts
        if flight is None:
            flight = not any(human_support.get(s, True) for s in SIDES)
        anchors: dict[str, pin.SE3] = {}
        pivoting: set[str] = set()
        settle = self._settle_side(t, human_support, flight, offset)
        self._update_handover(t, human_support, soles, flight, moved, hover)
        for side in SIDES:
            state = self.states[side]
            up = not human_support.get(side, True) and side not in self._handover
            other_state = self.states[_OTHER[side]]
            other_stands = other_state == "stance"
            rise = (toe_rise or {}).get(side, 0.0)
            rolls = side in self.toes and rise > st.toe_rise
            heel_up = st.toe_off and rolls
            # Tiptoe: both heels rise (the other at least half way, its robot foot standing, on
            # tiptoe or in toe-off: the rise before a jump), or the heel rises while the other
            # foot is up and not about to be put down (a hop's push-off): the sole rolls onto
            # its toes with its contact kept.
            other = _OTHER[side]
            on_toes = (
                st.tiptoe
                and rolls
                and (
                    (
                        other in self.toes
                        and (toe_rise or {}).get(other, 0.0) > 0.5 * st.toe_rise
                        and other_state in ("stance", "tiptoe", "toe_off")
                    )
                    or (other_state in ("swing", "landing") and not (low or {}).get(other, False))
                )
            )
            if state == "stance":
                settled = t - self._since[side] >= st.min_stance
                restep = not up and (moved or {}).get(side, 0.0) > st.restep
                if side == settle and settled:
                    restep = True
                    self._settled.add(side)
                lift_ok = other_state in ("stance", "toe_off", "tiptoe") or flight
                if (up or restep) and lift_ok and settled:
                    self._enter(t, side, "swing")
                    self._lift[side] = (t, soles[side].copy())
                    self._pivot.pop(side, None)
                    if restep:
                        self._restep.add(side)
                elif not heel_up and rise <= 0.5 * st.toe_rise:
                    self._toe_armed.add(side)
                armed = self.states[side] == "stance" and not up and settled
                armed = armed and side in self._toe_armed
                if armed and on_toes and side not in self._omega:
                    # Both heels rise (before a jump, on tiptoe), or one while the other foot is
                    # up: the sole rolls onto its toes with its contact kept, the anchor turned
                    # about the front edge. Not while the anchor pivots (stopping its yaw rate
                    # in one tick to roll it slid the dance spin's front edge 1.9 mm): the pivot
                    # is stopped first, below.
                    self._enter(t, side, "tiptoe")
                    self._toe_armed.discard(side)
                    self._pivot.pop(side, None)
                    self._roll[side] = 0.0
                    self._roll_rate[side] = 0.0
                    self._tiptoe_tick(side, rise, anchors, pivoting)
                    continue
                if armed and heel_up and other_stands:
                    # The person's heel rises (push-off): the sole rolls onto its toes.
                    self._enter(t, side, "toe_off")
                    self._toe_armed.discard(side)
                    self._pivot.pop(side, None)
                    continue
                if self.states[side] != "stance":
                    continue
                if (
                    self.states[_OTHER[side]] != "swing"
                    or float(desired[_OTHER[side]].translation[2]) - self.ground > PIVOT_SWING_MAX
                ):
                    # Pivots only while the other foot swings: turning one anchored sole while
                    # the other is anchored (or landing) twists the legs against both contacts
                    # (on the front kicks such a pivot made the contacts give, the robot spun).
                    # The person's turn is measured from here on, unless the other foot stands
                    # still: a turn past pivot_yaw_double on the ball of this foot is a pivot.
                    other = _OTHER[side]
                    both = self.states[other] == "stance" and other not in self._omega
                    if st.pivot_double and both:
                        self._pivot_double.add(side)
                        pivot = self._pivot_anchor(
                            side, human_foot.get(side), _yaw_of(desired[side].rotation),
                            threshold=st.pivot_yaw_double,
                        )  # fmt: skip
                    else:
                        self._rebase_pivot(side, human_foot.get(side))
                        pivot = self._turn_anchor(side, None)
                elif (
                    armed
                    and on_toes
                    and abs(self._omega.get(side, 0.0)) <= TIPTOE_STOP * st.pivot_accel
                ):
                    # The heel rises while the anchor turns slowly: the pivot stops (its yaw
                    # rate ramped down by pivot_accel, within TIPTOE_STOP), then the sole rolls
                    # (a hop's push-off on the playground jumps rolled 70 ms late, waiting for
                    # a 1.2 rad/s pivot to end).
                    pivot = self._turn_anchor(side, None)
                else:
                    if side in self._pivot_double:
                        # The other foot lifted: single support's pivot_yaw counts from here,
                        # unless a pivot started with both feet down goes on (a turn measured
                        # since the other foot stood started a pivot at every lift: the karate
                        # kata's run broke, heading 117 deg off).
                        self._pivot_double.discard(side)
                        record, foot = self._pivot.get(side), human_foot.get(side)
                        if record is not None and not record[4] and foot is not None:
                            # From the last sample's yaw: this tick's turn counts.
                            anchor_yaw = _yaw_of(self._anchor[side].rotation)
                            self._start_pivot(side, (record[0], foot[1]), anchor_yaw)
                    pivot = self._pivot_anchor(
                        side, human_foot.get(side), _yaw_of(desired[side].rotation)
                    )
                if pivot is not None:
                    anchors[side] = pivot
                    pivoting.add(side)
            elif state == "toe_off":
                other_up = not human_support.get(_OTHER[side], True)
                if up and (other_state in CONTACT_STATES or flight):
                    self._enter(t, side, "swing")
                    self._lift[side] = (t, soles[side].copy())
                    self._toe_down.discard(side)
                    continue
                if other_state == "tiptoe" and rolls and side not in self._toe_down and not up:
                    # The other heel rose too: this sole's contact is engaged on its toes, at
                    # the pitch it has (about the same front edge), and rolls on from there. (A
                    # toe-off whose other foot lifts goes flat as before: rolled on with its
                    # contact, the karate kata's two such stances changed its chaotic run, 16
                    # -> 13 robot steps for 15, the smallest followed lift 0.49 -> 0.36.)
                    self._enter(t, side, "tiptoe")
                    self._unroll(side, soles[side])
                    self._roll_rate[side] = 0.0
                    self._tiptoe_tick(side, rise, anchors, pivoting)
                    # Not a moving anchor this tick: the contact was just anchored where the
                    # sole is, the drift correction takes it onto the rolled pose.
                    anchors[side] = self._rolled(side, self._roll[side])
                    pivoting.discard(side)
                    continue
                if (
                    rise <= 0.5 * st.toe_rise
                    or t - self._since[side] > st.toe_time
                    or (other_up and not up)
                ):
                    # The person's heel is down again, or the toe-off lasts longer than
                    # toe_time (on the ball of the foot, turning on it), or the other foot
                    # steps: the sole goes flat about its front edge and is back in contact
                    # once flat on the floor (the other foot may lift meanwhile).
                    self._toe_down.add(side)
                if st.pivot and side not in self._toe_down:
                    self._toe_pivot(side, human_foot.get(side))
                if side in self._toe_down:
                    sole = soles[side]
                    h = float(sole.translation[2]) - self.ground
                    tilt = math.acos(max(-1.0, min(1.0, float(sole.rotation[2, 2]))))
                    if h <= st.land_height and tilt <= 0.05:
                        # Anchored flat where the sole is (the toe may have turned a little).
                        self._enter(t, side, "stance")
                        self._toe_down.discard(side)
                        anchor = _flat(
                            _yaw_of(sole.rotation),
                            np.array([sole.translation[0], sole.translation[1], self.ground]),
                        )
                        self._anchor[side] = anchor
                        anchors[side] = anchor
            elif state == "tiptoe":
                if up and (other_state in CONTACT_STATES or other_state == "toe_off" or flight):
                    self._enter(t, side, "swing")
                    self._lift[side] = (t, soles[side].copy())
                    self._roll.pop(side, None)
                    self._roll_rate.pop(side, None)
                    continue
                self._tiptoe_tick(side, rise, anchors, pivoting)
                if self._roll[side] <= 0.0 and rise <= 0.5 * st.toe_rise:
                    # Rolled back flat, the person's heel down: a flat stance again, on the
                    # anchor it stood on (the front edge did not move).
                    self._enter(t, side, "stance")
                    self._roll.pop(side, None)
                    self._roll_rate.pop(side, None)
                    anchors[side] = self._anchor[side].copy()
            elif state == "swing":
                if side in self._restep and not up and t - self._since[side] < st.lift_time:
                    pass  # a re-step is lifted lift_time before it goes down
                elif not up:
                    self._restep.discard(side)
                    self._enter(t, side, "landing")
                    # Put down where the person's foot is; a foot put down for the other's
                    # re-step (handover) straight under itself, and so is one whose target
                    # is unknown (the person's foot markers missing: a NaN landing spot left
                    # the OpenSim C3D walk's foot hovering in `landing` to the end, and the
                    # body rooted at it ran 1.8 m ahead).
                    d = soles[side] if side in self._handover else desired[side]
                    if not (np.all(np.isfinite(d.translation)) and np.all(np.isfinite(d.rotation))):
                        d = soles[side]
                    p = np.array([d.translation[0], d.translation[1], self.ground])
                    self._landing[side] = _flat(_yaw_of(d.rotation), p)
            elif state == "landing":
                if up:
                    self._enter(t, side, "swing")
                else:
                    sole = soles[side]
                    h = float(sole.translation[2]) - self.ground
                    late = self._landing_late(t, side, human_support)
                    if h <= st.land_height or (late and h <= 5.0 * st.land_height):
                        self._enter(t, side, "stance")
                        anchor = _flat(
                            _yaw_of(sole.rotation),
                            np.array([sole.translation[0], sole.translation[1], self.ground]),
                        )
                        self._anchor[side] = anchor
                        anchors[side] = anchor
                        foot = human_foot.get(side)
                        if foot is not None:
                            yaw0 = _yaw_of(anchor.rotation)
                            self._start_pivot(side, foot, yaw0)
        feet: dict[str, pin.SE3] = {}
        for side in SIDES:
            state = self.states[side]
            if state == "swing":
                d = desired[side]
                z = max(float(d.translation[2]), self.ground + st.clearance)
                target = pin.SE3(d.rotation.copy(), np.array([*d.translation[:2], z]))
                start = self._lift.get(side)
                if start is not None:
                    # Blend from where the sole left the ground (no step in the target).
                    w = min_jerk((t - start[0]) / st.lift_time)
                    if w >= 1.0:
                        self._lift.pop(side)
                    else:
                        target = blend_pose(start[1], target, w)
                target = self._yaw_limited(side, target)
                feet[side] = target
                self._target[side] = target
            elif state == "toe_off":
                rise = (toe_rise or {}).get(side, 0.0)
                target = self.toe_pose(side, 0.0 if side in self._toe_down else rise)
                feet[side] = target
                self._target[side] = target
            elif state == "tiptoe":
                self._target.pop(side, None)
                feet[side] = self._rolled(side, self._roll[side])
            elif state == "landing":
                # Down only once above the landing spot (a sole put down short of it would carry
                # the lag of the swing into every later stance), at most `land_speed`.
                land = self._landing[side]
                prev = self._target.get(side, soles[side])
                z_prev = float(prev.translation[2])
                miss = float(np.linalg.norm(soles[side].translation[:2] - land.translation[:2]))
                late = self._landing_late(t, side, human_support)
                step = st.land_speed * self.dt if miss <= st.land_reach or late else 0.0
                z = max(self.ground, z_prev - step)
                target = pin.SE3(land.rotation.copy(), np.array([*land.translation[:2], z]))
                feet[side] = target
                self._target[side] = target
            else:
                self._target.pop(side, None)
                feet[side] = self._anchor[side].copy()
        contacts = self.contacts
        return StepCommand(
            contacts=contacts,
            switched=contacts != before,
            feet=feet,
            anchors=anchors,
            states=dict(self.states),
            pivoting=frozenset(pivoting),
        )

    def toe_pose(self, side: str, rise: float) -> pin.SE3:
        """Sole pose of a toe-off: the stance anchor turned about the sole's front edge.

        The pitch is the one that raises the ankle by ``rise`` (:meth:`toe_angle`).
        """
        return self._rolled(side, self.toe_angle(side, rise))

    def toe_angle(self, side: str, rise: float) -> float:
        r"""Pitch about the sole's front edge that raises the ankle by ``rise`` [rad].

        With :math:`d` the distance from the ankle to the front edge along the sole and
        :math:`h` the ankle's height over the sole, turning by :math:`\theta` raises the ankle
        by :math:`d \sin\theta - h (1 - \cos\theta) = r \sin(\theta + \varphi) - h`
        (:math:`r = \sqrt{d^2 + h^2}`, :math:`\varphi = \operatorname{atan2}(h, d)`): the pitch
        that raises it by ``rise`` is :math:`\theta = \arcsin((\mathrm{rise} + h) / r) -
        \varphi`, within ``[0, toe_pitch]``.
        """
        x_front, ankle = self.toes[side]
        d, h = x_front - float(ankle[0]), float(ankle[2])
        r = math.hypot(d, h)
        if rise <= 0.0 or r <= 0.0:
            return 0.0
        theta = math.asin(min(1.0, (rise + h) / r)) - math.atan2(h, d)
        return max(0.0, min(self.settings.toe_pitch, theta))

    def _rolled(self, side: str, theta: float) -> pin.SE3:
        r"""The stance anchor of ``side`` turned by the pitch ``theta`` about its front edge.

        :math:`M = A\,(R_y(\theta),\ e - R_y(\theta) e)` with :math:`e = (x_{front}, 0, 0)` in
        the sole frame: the points of the front edge stay where they stood.
        """
        anchor = self._anchor[side]
        if theta <= 0.0:
            return anchor.copy()
        return anchor * _edge_turn(self.toes[side][0], theta)

    def _unroll(self, side: str, sole: pin.SE3) -> None:
        r"""Stance anchor and roll of ``side`` from a sole that rolled without its contact.

        A toe-off's sole follows its target through the foot task only, and may have moved
        from its stance anchor (5-10 mm on the karate kata): the pitch :math:`\theta` is the
        sole's (:meth:`_pitch_of`), the anchor the sole turned back by :math:`\theta` about its
        own front edge, flat on the ground, so that the rolled anchor is where the sole is.
        """
        theta = self._pitch_of(side, sole)
        base = sole * _edge_turn(self.toes[side][0], theta).inverse()
        p = np.array([base.translation[0], base.translation[1], self.ground])
        self._anchor[side] = _flat(_yaw_of(base.rotation), p)
        self._roll[side] = theta

    def _pitch_of(self, side: str, sole: pin.SE3) -> float:
        r"""Pitch of ``sole`` relative to the stance anchor of ``side`` [rad].

        Within ``[0, toe_pitch]``: :math:`\operatorname{atan2}(R_{02}, R_{22})` of
        :math:`R = R_a^\top R_{sole}`.
        """
        R = self._anchor[side].rotation.T @ sole.rotation
        return max(0.0, min(self.settings.toe_pitch, math.atan2(R[0, 2], R[2, 2])))

    def _tiptoe_tick(
        self, side: str, rise: float, anchors: dict[str, pin.SE3], pivoting: set[str]
    ) -> None:
        r"""Roll the tiptoe anchor of ``side`` one tick towards the person's heel rise.

        The pitch goes to :meth:`toe_angle` of ``rise`` (0 once the rise is under half
        ``toe_rise``: the heel is down); its rate :math:`\omega` moves by at most
        ``tiptoe_accel`` :math:`dt` per tick towards :math:`\operatorname{sign}(r)
        \min(|r| / dt, \omega_{max}, \sqrt{2 a |r|})` (:math:`r` the pitch still to turn,
        :math:`\omega_{max}` = ``tiptoe_rate``: it slows down in time to stop at the goal), as a
        pivot's yaw (:meth:`_turn_anchor`). The anchor is the stance anchor turned about the
        front edge (:meth:`_rolled`), a moving anchor.
        """
        st = self.settings
        goal = self.toe_angle(side, rise) if rise > 0.5 * st.toe_rise else 0.0
        old = self._roll[side]
        w = _ramp(self._roll_rate.get(side, 0.0), goal - old, self.dt, st.tiptoe_rate,
                  st.tiptoe_accel)  # fmt: skip
        new = max(0.0, min(st.toe_pitch, old + w * self.dt))
        if abs(goal - new) < 1e-9:
            new = goal
        self._roll_rate[side] = (new - old) / self.dt
        self._roll[side] = new
        if new != old:
            anchors[side] = self._rolled(side, new)
            pivoting.add(side)

    def landing_spot(self, side: str) -> pin.SE3 | None:
        """Sole pose a landing foot is going down to (``None`` unless ``side`` is landing)."""
        if self.states[side] != "landing":
            return None
        return self._landing[side].copy()

    def _yaw_limited(self, side: str, target: pin.SE3) -> pin.SE3:
        r"""A swing target turned at most :math:`\omega\, dt` from the last one.

        :math:`\omega` is ``swing_yaw_rate_floor`` for a sole target up to 5 cm over the floor,
        ``swing_yaw_rate`` from 10 cm, linear in between. The yaw change :math:`\delta` beyond
        the limit is taken out by a turn about the vertical, :math:`R \leftarrow
        R_z(\mathrm{clip}(\delta) - \delta)\, R` (pitch and roll kept); the first swing tick
        (no previous target) is the lift-off pose.
        """
        prev = self._target.get(side)
        if prev is None:
            return target
        delta = wrap_angle(_yaw_of(target.rotation) - _yaw_of(prev.rotation))
        st = self.settings
        r = swing_height_ramp(float(target.translation[2]) - self.ground)
        rate = st.swing_yaw_rate_floor + (st.swing_yaw_rate - st.swing_yaw_rate_floor) * r
        limit = rate * self.dt
        if abs(delta) <= limit:
            return target
        turn = pin.exp3(np.array([0.0, 0.0, math.copysign(limit, delta) - delta]))
        return pin.SE3(turn @ target.rotation, target.translation.copy())

    def _landing_late(self, t: float, side: str, human_support: Mapping[str, bool]) -> bool:
        """Whether a landing sole goes down where it is, short of its spot.

        After ``land_timeout``, or after ``land_wait`` once the person has lifted the other foot.
        """
        since = t - self._since[side]
        waited = not human_support.get(_OTHER[side], True) and since >= self.settings.land_wait
        return since >= self.settings.land_timeout or waited

    def _settle_ready(self, t: float, slack: float = 0.0) -> bool:
        """Whether a settle step's wait is over at ``t`` (``settle_step``).

        The person on both feet, and the robot on both soles in stance, for ``settle_time``
        less ``slack``.
        """
        st = self.settings
        if not st.settle_step or self._both_since is None:
            return False
        if t - self._both_since < st.settle_time - slack:
            return False
        return all(
            self.states[s] == "stance" and t - self._since[s] >= st.settle_time - slack
            for s in SIDES
        )

    def settle_possible(self, t: float) -> bool:
        """Whether a settle step may come at ``t`` (``settle_step``).

        :meth:`_settle_ready` up to the last tick, and a side has not made its settle step
        yet: the caller computes the offsets :meth:`update` needs only then.
        """
        return len(self._settled) < len(SIDES) and self._settle_ready(t, self.dt + 1e-12)

    def _settle_side(
        self,
        t: float,
        human_support: Mapping[str, bool],
        flight: bool,
        offset: Mapping[str, float] | None,
    ) -> str | None:
        """The side that makes a settle step this tick (``settle_step``), or ``None``.

        Both robot soles flat in stance, still (not pivoting) and for ``settle_time``; the
        person on both feet as long; the robot ankle furthest from the person's, beyond
        ``restep``, that has not made its settle step in the person's current stance.
        """
        st = self.settings
        for side in SIDES:
            if not human_support.get(side, True):
                self._settled.discard(side)
        if flight or not all(human_support.get(s, True) for s in SIDES):
            self._both_since = None
            return None
        if self._both_since is None:
            self._both_since = t
        if not offset or not self._settle_ready(t) or any(s in self._omega for s in SIDES):
            return None
        side = max(SIDES, key=lambda s: offset.get(s, 0.0))
        if offset.get(side, 0.0) <= st.restep or side in self._settled:
            return None
        return side

    def _update_handover(
        self,
        t: float,
        human_support: Mapping[str, bool],
        soles: Mapping[str, pin.SE3],
        flight: bool,
        moved: Mapping[str, float] | None,
        hover: Mapping[str, bool] | None,
    ) -> None:
        """Start and end the feet put down for the other's re-step (``handover``).

        A foot put down stays down (as if the person stood on it) until the other foot's
        re-step has landed, the person puts it down or flies, or :data:`HANDOVER_TIMEOUT`
        passed without the re-step starting.
        """
        st = self.settings
        for side in list(self._handover):
            record, other = self._handover[side], _OTHER[side]
            if human_support.get(side, True) or flight:
                del self._handover[side]
            elif self.states[other] in ("swing", "landing"):
                record[1] = True
            elif record[1] or t - record[0] > HANDOVER_TIMEOUT:
                del self._handover[side]  # the re-step landed, or none came
        for side in SIDES:
            if (hover or {}).get(side, False):
                self._hover_since.setdefault(side, t)
            else:
                self._hover_since.pop(side, None)
        if not st.handover or flight or not moved:
            return
        for side in SIDES:
            other = _OTHER[side]
            if (
                side in self._handover
                or self.states[side] != "swing"
                or human_support.get(side, True)
                or self.states[other] != "stance"
                or t - self._since[side] < st.lift_time
                or moved.get(other, 0.0) <= st.restep
                or t - self._hover_since.get(side, t) < HOVER_TIME - 1e-12
                or float(soles[side].translation[2]) - self.ground > st.clearance + 0.01
            ):
                continue
            self._handover[side] = [t, False]

    def _enter(self, t: float, side: str, state: str) -> None:
        self.states[side] = state
        self._since[side] = t
        self._toe_turn.pop(side, None)
        if state != "stance":
            self._omega.pop(side, None)  # a lifted foot's anchor no longer turns
        self.log.append((t, "/".join(self.states[s] for s in SIDES)))

    def _toe_pivot(self, side: str, foot: tuple[float, np.ndarray] | None) -> None:
        r"""Turn a toe-off's anchor with the person's foot, about the sole's front edge.

        A person pushing off turns the foot on its ball (heel up): the ankle swings round the
        ball. Once the person's foot has turned ``pivot_yaw`` since the toe-off began (its
        yaw measured while the foot is not pointing down, :meth:`FootTargets.foot_yaw`), the
        anchor turns after it, at most ``pivot_rate`` :math:`dt` a tick, about the vertical
        through the middle of the sole's front edge :math:`b`: :math:`p' = b - R_z(\psi')\,e`,
        :math:`e = (x_{front}, 0, 0)`. A toe-off's contact is off (its sole follows its task),
        so nothing slides; the sole goes down flat where the anchor now is. On the karate kata
        the person's right foot turned 42 deg on its ball in 0.2 s and its ankle moved 11 cm,
        which the robot's foot, turned back flat where it had stood, kept as an error until
        its next step (0.6 s).
        """
        if foot is None or side not in self.toes:
            return
        yaw = float(foot[0])
        anchor = self._anchor[side]
        rec = self._toe_turn.get(side)
        if rec is None:
            self._toe_turn[side] = [yaw, 0.0, _yaw_of(anchor.rotation)]
            return
        rec[1] += wrap_angle(yaw - rec[0])
        rec[0] = yaw
        if abs(rec[1]) < self.settings.pivot_yaw:
            return
        now = _yaw_of(anchor.rotation)
        lim = self.settings.pivot_rate * self.dt
        step = max(-lim, min(lim, wrap_angle(rec[2] + rec[1] - now)))
        if step == 0.0:
            return
        e = np.array([self.toes[side][0], 0.0, 0.0])
        ball = anchor.act(e)
        psi = now + step
        p = ball - _flat(psi, np.zeros(3)).rotation @ e
        self._anchor[side] = _flat(psi, np.array([p[0], p[1], self.ground]))

    def _rebase_pivot(self, side: str, foot: tuple[float, np.ndarray] | None) -> None:
        """Measure the person's pivot of ``side`` from now (its current foot and anchor)."""
        if foot is None:
            self._pivot.pop(side, None)
            return
        anchor_yaw = _yaw_of(self._anchor[side].rotation)
        self._start_pivot(side, foot, anchor_yaw)

    def _start_pivot(self, side: str, foot: tuple[float, np.ndarray], anchor_yaw: float) -> None:
        """Measure the person's turn of ``side`` from this sample on."""
        self._pivot[side] = [foot[0], 0.0, _xy(foot[1]), anchor_yaw, False]
        self._yaw_u[side] = anchor_yaw

    def _pivot_anchor(
        self,
        side: str,
        foot: tuple[float, np.ndarray] | None,
        yaw: float | None = None,
        threshold: float | None = None,
    ) -> pin.SE3 | None:
        """The ramped anchor of a stance foot that pivots, or ``None``.

        A pivot starts once the person's foot turn since the pivot's reference sample (unwrapped:
        a dancer's 300 deg turn on one foot is followed the long way round) exceeds
        ``pivot_yaw`` with a point of the foot within ``pivot_radius`` of where it was
        (:func:`_least_motion`); once started it goes on to the end of the stance wherever the
        person's foot moves (a turn that slides: the robot's sole turns in place). The
        anchor's yaw then goes to ``yaw``, the sole yaw the
        person's foot asks for (the swing target's: the foot's yaw within the waist's range),
        else to its yaw at the start plus the person's turn; its rate is ramped
        (:meth:`_turn_anchor`), the way that keeps the sole within half a turn of the floating
        base's heading (``update``'s ``base_yaw``; the shorter way from where the sole is
        without it). Aiming at the foot's yaw rather than adding the turn also takes
        out the offset a landing left (the dance spin's left sole was put down 69 deg from the
        person's foot, and a pivot adding the turn kept the pelvis 40 deg behind).
        """
        start = self._pivot.get(side)
        if foot is None or not self.settings.pivot:
            return self._turn_anchor(side, None)
        if start is None:
            # The person's foot was not flat at touch-down (landed on the ball of the foot, a
            # spin): the pivot is measured from the first flat sample of the stance (else a
            # spinning dancer's stance foot never pivoted: spin heading error 98 deg).
            self._start_pivot(side, foot, _yaw_of(self._anchor[side].rotation))
            return self._turn_anchor(side, None)
        yaw_last, turn, xy0, anchor_yaw0, active = start
        st = self.settings
        # The person's foot yaw is in the capture's frame: only its change counts (the goal
        # below is ``yaw``, the robot's frame). Until stop 36 it was unpacked into ``yaw``
        # itself, and the pivots aimed at the capture frame's yaw: off by the person's heading
        # at calibration (10 deg on the karate kata; a clip turned 180 deg about the vertical
        # ended 355 deg off).
        foot_yaw, points = foot
        turn += wrap_angle(foot_yaw - yaw_last)
        start[0], start[1] = foot_yaw, turn
        xy = _xy(points)
        if xy.shape != xy0.shape:
            return self._turn_anchor(side, None)
        if not active and _least_motion(xy, xy0) > st.pivot_radius:
            # A pivot starts only with the foot in place; once started it follows the
            # person's foot yaw for the rest of the stance even when the foot then moves (a
            # turn on the ball of the foot that slides): the robot's sole turns in place. A
            # pivot stopped there left the karate kata played 1.25 times faster with its
            # anchor 94 deg behind the person's foot and the pelvis twisted 160 deg over it,
            # the heading 135 deg off to the end of the clip (docs/retargeting.md, *Pivots
            # that go on*).
            return self._turn_anchor(side, None)
        if not active:
            if abs(turn) < (st.pivot_yaw if threshold is None else threshold):
                return self._turn_anchor(side, None)
            start[4] = True
        if yaw is not None:
            yaw_u = self._yaw_u.get(side, anchor_yaw0)
            if self._base_yaw is None:
                return self._turn_anchor(side, yaw_u + wrap_angle(yaw - yaw_u))
            # The turn that keeps the sole within half a turn of the body's heading (the hip's
            # yaw range): the change of the sole's yaw relative to the base. The shorter way
            # from where the sole is went the wrong way round once the sole lagged the turn
            # by more than half a turn, and the hip at its yaw limit turned the body back.
            b = self._base_yaw
            return self._turn_anchor(side, yaw_u + wrap_angle(yaw - b) - wrap_angle(yaw_u - b))
        return self._turn_anchor(side, anchor_yaw0 + turn)

    def _turn_anchor(self, side: str, goal: float | None) -> pin.SE3 | None:
        r"""Turn the anchor of ``side`` one tick towards the yaw ``goal`` (``None``: stop).

        The yaw rate :math:`\omega` moves by at most ``pivot_accel`` :math:`dt` per tick
        towards :math:`\operatorname{sign}(r) \min(|r| / dt, \omega_{max},
        \sqrt{2 a |r|})` (:math:`r` the yaw still to turn, :math:`a` = ``pivot_accel``,
        :math:`\omega_{max}` = ``pivot_rate``: it slows down in time to stop at the goal), or
        towards 0 without a goal. ``None`` once the anchor is still.
        """
        st = self.settings
        anchor = self._anchor[side]
        base = _yaw_of(anchor.rotation)
        yaw_u = self._yaw_u.get(side)
        if yaw_u is None or abs(wrap_angle(yaw_u - base)) > 1e-6:
            yaw_u = base  # the anchor was set elsewhere (a landing): count from it
        r = 0.0 if goal is None else goal - yaw_u
        w = _ramp(self._omega.get(side, 0.0), r, self.dt, st.pivot_rate, st.pivot_accel)
        if abs(w) < 1e-9:
            self._omega.pop(side, None)
            return None
        self._omega[side] = w
        self._yaw_u[side] = yaw_u + w * self.dt
        new = _flat(yaw_u + w * self.dt, anchor.translation.copy())
        self._anchor[side] = new
        return new


__all__ = ["FOOT_STATES", "KinematicStepper", "StepCommand", "StepSettings"]
