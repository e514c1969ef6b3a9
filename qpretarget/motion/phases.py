# SPDX-License-Identifier: Apache-2.0
r"""Support phases: detection on the human, transition sequences on the robot (Poubel 2014 III).

**Detection** (:class:`SupportPhaseDetector`, streaming; :func:`detect_support_phases`, offline).
A foot is described by its key-points (ankle and, when available, toe and heel). Each tick, for each
point type the ground height is the lowest height seen so far on either foot (a running minimum,
causal); a foot's height :math:`h` is the lowest of its points' heights above their ground, its
speed :math:`v` the lowest of its points' speeds (the point the foot pivots on: the heel at
heel-strike, the toe at toe-off). With hysteresis, a foot

* enters support when :math:`h < h_{on}` **and** :math:`v < v_{on}`,
* leaves support when :math:`h > h_{off}` **or** :math:`v > v_{off}`,

and a change must persist for ``min_duration`` before it is taken. Both feet in support is double
support; one foot, single support on it; none (a jump, a flight phase of running) keeps the last
phase. Poubel 2014 Sec. III.A uses the height alone (200 mm for Kinect noise); the speed test
separates a foot resting on the floor from a foot brushing over it.

**Transitions** (:class:`SupportSequencer`, Poubel 2014 Table I and Sec. III.B). The robot does
not switch support when the person does; it runs the paper's sequences, each step a smooth
(minimum-jerk) target trajectory:

=================  ========================================================================
DS to single (X)   1. *CoM to X*: the CoM target moves over the support foot X (to the centre
                   of its sole, Poubel's offset towards the foot centre), both feet in contact;
                   2. *lift Y*: contact of Y released, Y lifted flat by ``lift_height``.
single support X   the swing foot Y follows the scaled human ankle, kept flat, above
                   ``lift_height`` and clear of the support foot; the CoM stays over X.
single to DS       1. *lower Y*: Y moves flat to the ground where the scaled human foot landed
                   (horizontal position proportional to the human's, clamped to a reachable
                   area); contact of Y engaged when it touches; 2. *CoM to middle*: the CoM
                   target returns between the feet.
=================  ========================================================================

A transition the person abandons is reversed smoothly (a CoM shift followed by double support goes
back to the middle; a lifted foot is lowered). The sequencer only produces targets and contact
switches; the controller's ``contacts`` and ``support_polygon`` constraints keep the robot on its
feet while it follows them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..geometry2d import convex_hull_2d as convex_hull  # noqa: F401

#: A person whose feet come this much lower than their lowest point at the first sample was in
#: the air there [m] (a clip cut mid-jump): the retargeter then measures heights from the floor
#: the person lands on, and so do the human-referenced metrics. The shared clips' floors lie at
#: most 3.2 cm under their first samples' lowest foot points, a jump's apex 20-40 cm over them.
AIR_START = 0.10

#: Support phases, as stored in runs.
PHASES = ("double", "left", "right")
SIDES = ("left", "right")
_OTHER = {"left": "right", "right": "left"}


def _positive(value: Any, name: str) -> float:
    x = float(value)
    if not (math.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return x


# --------------------------------------------------------------------------------- detection
#: A foot held slow under ``height_off`` this long while the other is up is stood on [s].
TIPTOE_TIME = 0.2


@dataclass(frozen=True)
class PhaseThresholds:
    """Thresholds of :class:`SupportPhaseDetector`.

    Attributes:
        height_on: A foot may enter support below this height above the ground [m].
        height_off: A foot leaves support above this height [m] (> ``height_on``).
        speed_on: A foot may enter support below this speed [m/s].
        speed_off: A foot leaves support above this speed [m/s] (> ``speed_on``).
        min_duration: A change of a foot's state must last this long to be taken [s].
    """

    height_on: float = 0.03
    height_off: float = 0.05
    speed_on: float = 0.5
    speed_off: float = 1.0
    min_duration: float = 0.03

    def __post_init__(self) -> None:
        """Check the hysteresis.

        Raises:
            ValueError: A threshold is not positive, or an ``off`` threshold is below its ``on``.
        """
        for name in ("height_on", "height_off", "speed_on", "speed_off"):
            _positive(getattr(self, name), name)
        if not (math.isfinite(self.min_duration) and self.min_duration >= 0):
            raise ValueError(f"min_duration must be >= 0 [s], got {self.min_duration!r}")
        if self.height_off < self.height_on or self.speed_off < self.speed_on:
            raise ValueError(
                "hysteresis needs height_off >= height_on and speed_off >= speed_on, got heights "
                f"{self.height_on}/{self.height_off}, speeds {self.speed_on}/{self.speed_off}"
            )


class SupportPhaseDetector:
    """Streaming support-phase detection from foot heights and speeds with hysteresis.

    Args:
        thresholds: :class:`PhaseThresholds` (or its fields as keywords).
        **kwargs: Fields of :class:`PhaseThresholds` when ``thresholds`` is ``None``.

    Attributes:
        phase: Current phase (``"double"``, ``"left"``, ``"right"``); in flight (no foot in
            support) the last one is kept and :attr:`flight` is ``True``.
        flight: Neither foot is in support (a jump, the flight phase of running).
        height: side -> last foot height above the ground [m].
        speed: side -> last foot speed [m/s].
    """

    def __init__(self, thresholds: PhaseThresholds | None = None, **kwargs: float) -> None:
        self.thresholds = thresholds if thresholds is not None else PhaseThresholds(**kwargs)
        self.reset()

    def __repr__(self) -> str:
        """Thresholds."""
        return f"SupportPhaseDetector({self.thresholds})"

    def reset(self) -> None:
        """Forget the history (ground, previous samples, states)."""
        self.phase = "double"
        self._ground: list[float] | None = None
        self._prev: dict[str, list[list[float]]] = {}
        self._t_prev: float | None = None
        self._support = {"left": True, "right": True}
        self.flight = False
        self._pending: dict[str, float | None] = {"left": None, "right": None}
        self._low_since: dict[str, float | None] = {"left": None, "right": None}
        self.height = {"left": 0.0, "right": 0.0}
        #: side -> height of each of the foot's points over its type's ground [m] (NaN unseen).
        self.point_height: dict[str, list[float]] = {"left": [], "right": []}
        self.speed = {"left": 0.0, "right": 0.0}

    @property
    def feet(self) -> dict[str, bool]:
        """Side -> the foot is in support (after hysteresis and ``min_duration``)."""
        return dict(self._support)

    @property
    def ground(self) -> float:
        """The lowest ground height of the foot points seen so far [m] (``inf`` before any)."""
        finite = [g for g in (self._ground or []) if math.isfinite(g)]
        return min(finite) if finite else math.inf

    def update(self, t: float, left: npt.ArrayLike, right: npt.ArrayLike) -> str:
        """Add one sample of both feet; return the phase.

        Args:
            t: Time [s], increasing.
            left: ``(K, 3)`` positions [m] of the left foot's points (e.g. ankle, toe), z up;
                NaN rows are ignored.
            right: ``(K, 3)`` positions of the same point types on the right foot.

        Returns:
            ``"double"``, ``"left"`` or ``"right"``.
        """
        feet = {
            "left": np.asarray(left, float).reshape(-1, 3).tolist(),
            "right": np.asarray(right, float).reshape(-1, 3).tolist(),
        }
        inf = math.inf
        if self._ground is None:
            self._ground = [inf] * len(feet["left"])
        ground = self._ground
        for pts in feet.values():  # running minimum of each point type over both feet
            for i, p in enumerate(pts):
                if p[2] < ground[i]:  # False for NaN
                    ground[i] = p[2]
        dt = None if self._t_prev is None else t - self._t_prev
        th = self.thresholds
        first = self._t_prev is None
        for side, pts in feet.items():
            self.point_height[side] = [p[2] - ground[i] for i, p in enumerate(pts)]
            heights = [
                p[2] - ground[i] for i, p in enumerate(pts) if math.isfinite(p[2] - ground[i])
            ]
            if not heights:
                continue
            h = min(heights)
            prev = self._prev.get(side)
            v = 0.0
            if dt is not None and prev is not None and dt > 0:
                speeds = [math.dist(p, q) / dt for p, q in zip(pts, prev, strict=True)]
                speeds = [x for x in speeds if math.isfinite(x)]
                v = min(speeds) if speeds else 0.0
            self._prev[side] = pts
            self.height[side], self.speed[side] = h, v
            if first:
                self._support[side] = h < th.height_on
                continue
            if self._support[side]:
                raw = not (h > th.height_off or v > th.speed_off)
            else:
                raw = h < th.height_on and v < th.speed_on
                other = "right" if side == "left" else "left"
                low = h < th.height_off and v < th.speed_on and h <= self.height[other]
                if not low:
                    self._low_since[side] = None
                elif self._low_since[side] is None:
                    self._low_since[side] = t
                if not raw and not self._support[other] and low:
                    # Nobody hovers: with the other foot up, the lower foot held slow under
                    # height_off for TIPTOE_TIME is stood on (a dancer on the ball of the foot,
                    # its points 3-6 cm over the clip's lowest: it never came under height_on,
                    # and the spin clip read 4.6 s of flight). The hold keeps a jump's apex and
                    # landing approach in flight.
                    raw = t - float(self._low_since[side] or t) >= TIPTOE_TIME - 1e-12
            if raw == self._support[side]:
                self._pending[side] = None
            elif self._pending[side] is None:
                self._pending[side] = t
                if th.min_duration <= 0:
                    self._support[side] = raw
                    self._pending[side] = None
            elif t - float(self._pending[side] or 0.0) >= th.min_duration - 1e-12:
                self._support[side] = raw
                self._pending[side] = None
        self._t_prev = t
        left_on, right_on = self._support["left"], self._support["right"]
        # Flight needs both feet up, not only moving fast: feet sliding on the floor (a dance)
        # leave support by speed while still at the floor.
        self.flight = not (left_on or right_on) and min(self.height.values()) > th.height_on
        if left_on and right_on:
            self.phase = "double"
        elif left_on:
            self.phase = "left"
        elif right_on:
            self.phase = "right"
        return self.phase


def detect_support_phases(
    t: npt.ArrayLike,
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    thresholds: PhaseThresholds | None = None,
    **kwargs: float,
) -> np.ndarray:
    """Support phase of every sample of a clip (the streaming detector run over it).

    Args:
        t: ``(T,)`` times [s].
        left: ``(T, K, 3)`` (or ``(T, 3)``) left-foot key-points [m] (ankle, toe...).
        right: The same point types on the right foot.
        thresholds: :class:`PhaseThresholds`.
        **kwargs: Fields of :class:`PhaseThresholds` when ``thresholds`` is ``None``.

    Returns:
        ``(T,)`` array of ``"double"``, ``"left"``, ``"right"``.
    """
    t = np.asarray(t, float)
    left = np.asarray(left, float).reshape(len(t), -1, 3)
    right = np.asarray(right, float).reshape(len(t), -1, 3)
    det = SupportPhaseDetector(thresholds, **kwargs)
    return np.array([det.update(float(t[k]), left[k], right[k]) for k in range(len(t))])


def foot_points(keypoints: Mapping[str, np.ndarray], side: str) -> list[str]:
    """Names of the foot key-points of one side that exist in ``keypoints`` (ankle, toe, heel)."""
    return [f"{side}_{p}" for p in ("ankle", "toe", "heel") if f"{side}_{p}" in keypoints]


# --------------------------------------------------------------------------------- sequences
def min_jerk(s: float) -> float:
    r"""Minimum-jerk profile :math:`10 s^3 - 15 s^4 + 6 s^5` on :math:`s \in [0, 1]` (clamped)."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


@dataclass
class _Move:
    """A minimum-jerk move of a vector from ``start`` to ``end`` over ``[t0, t0 + duration]``.

    ``end`` is ``None`` for a moving goal given to :meth:`at` (the free double-support CoM).
    """

    t0: float
    duration: float
    start: np.ndarray
    end: np.ndarray | None

    def at(self, t: float, goal: np.ndarray | None = None) -> np.ndarray:
        end = self.end if self.end is not None else goal
        s = 1.0 if self.duration <= 0 else min_jerk((t - self.t0) / self.duration)
        return self.start + s * (end - self.start)

    def done(self, t: float) -> bool:
        return t >= self.t0 + self.duration - 1e-9


@dataclass
class _PoseMove:
    """A minimum-jerk move of a pose: straight line for the position, geodesic for the rotation."""

    t0: float
    duration: float
    start: pin.SE3
    end: pin.SE3

    def __post_init__(self) -> None:
        self._w = pin.log3(self.start.rotation.T @ self.end.rotation)

    def at(self, t: float) -> pin.SE3:
        s = 1.0 if self.duration <= 0 else min_jerk((t - self.t0) / self.duration)
        p = self.start.translation + s * (self.end.translation - self.start.translation)
        return pin.SE3(self.start.rotation @ pin.exp3(s * self._w), p)

    def done(self, t: float) -> bool:
        return t >= self.t0 + self.duration - 1e-9


_OPTIONAL = ("min_width", "max_width", "max_stride")


@dataclass(frozen=True)
class SequencerSettings:
    """Parameters of :class:`SupportSequencer` (YAML ``retarget.support``).

    Attributes:
        com_speed: Average speed of a CoM transfer [m/s].
        foot_speed: Average speed of a foot lift / placement [m/s].
        swing_speed: Top speed of the swing-foot target in single support [m/s].
        lift_height: Height a foot is lifted flat before it swings (Poubel's epsilon) [m].
        com_tolerance: CoM distance to its target at which a foot may be lifted [m].
        land_tolerance: A lowered foot is in contact when its sole is this close to the ground
            and five times this close horizontally to the landing spot [m].
        min_width: Smallest lateral distance between the soles, in the support sole's heading
            frame [m]; ``None``: 0.16 m, or (in a :class:`~qpretarget.retarget.Retargeter`)
            80 % of the robot's reference stance width.
        max_width: Largest lateral distance between the soles [m]; ``None``: 0.3 m, or (in a
            retargeter) 110 % of the robot's reference stance width.
        max_stride: Largest forward or backward distance between the soles [m]; ``None``:
            0.15 m, or (in a retargeter) 25 % of the robot's leg length. With ``min_width`` and
            ``max_width`` it is the landing area of Poubel 2014 Sec. III.A, "an area on the
            floor where the robot is able to place the foot flat".
        max_yaw: Largest yaw between the feet [rad].
        min_time: Shortest duration of any transition step [s].
        timeout: Longest wait for the CoM or a landing before going on anyway [s].
        com_margin: In double support the CoM target follows the person's (scaled) CoM,
            kept this far inside the support polygon [m].
    """

    com_speed: float = 0.4
    foot_speed: float = 0.4
    swing_speed: float = 1.5
    lift_height: float = 0.03
    com_tolerance: float = 0.01
    land_tolerance: float = 0.002
    min_width: float | None = None
    max_width: float | None = None
    max_stride: float | None = None
    max_yaw: float = 0.6
    min_time: float = 0.15
    timeout: float = 0.5
    com_margin: float = 0.02

    def __post_init__(self) -> None:
        """Validate.

        Raises:
            ValueError: A value is not positive.
        """
        for name in self.__dataclass_fields__:
            if getattr(self, name) is not None or name not in _OPTIONAL:
                _positive(getattr(self, name), name)


@dataclass
class SupportCommand:
    """What the sequencer asks of the controller for one tick.

    Attributes:
        state: Sequencer state (``double``, ``com_to_left``, ``lift_right``, ``left``,
            ``lower_right``, ``com_to_middle``, ...).
        contacts: Sides in contact during this tick (``left``/``right``).
        switched: ``True`` when ``contacts`` changed at this tick.
        com: CoM target ``(2,)`` (x, y) [m].
        feet: side -> sole target pose (``pinocchio.SE3``); the feet in contact get their anchor.
        free_weight: 1 when the CoM target follows the person (double support), 0 when it is
            held over a support foot, in between during a CoM transfer.
    """

    state: str
    contacts: tuple[str, ...]
    switched: bool
    com: np.ndarray
    feet: dict[str, pin.SE3] = field(default_factory=dict)
    free_weight: float = 1.0


class SupportSequencer:
    """The transition sequences of Poubel 2014 Table I, on the robot side (see module docstring).

    Args:
        soles: side -> sole rectangle ``(x_min, x_max, y_min, y_max)`` in the sole frame [m];
            in single support the CoM goes over its centre, in double support it stays inside
            the hull of both.
        settings: :class:`SequencerSettings`.
        dt: Tick length [s] (for the swing-target rate limit).
    """

    def __init__(
        self,
        soles: Mapping[str, tuple[float, float, float, float]],
        settings: SequencerSettings | None = None,
        *,
        dt: float = 0.01,
    ) -> None:
        self.settings = settings or SequencerSettings()
        self.dt = _positive(dt, "dt")
        self.sole_corners: dict[str, list[np.ndarray]] = {}
        self.sole_centers: dict[str, np.ndarray] = {}
        for side in SIDES:
            x0, x1, y0, y1 = (float(v) for v in soles[side])
            self.sole_corners[side] = [
                np.array([x, y, 0.0]) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
            ]
            self.sole_centers[side] = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
        self._polygon = np.zeros((0, 2))
        self._free = np.zeros(2)
        self._w_start = self._w_end = 1.0
        self.state = "double"
        self.contacts: tuple[str, ...] = SIDES
        self.anchors: dict[str, pin.SE3] = {}
        self.ground = 0.0
        self._com: _Move | None = None
        self._foot: _PoseMove | None = None
        self._swing_target: pin.SE3 | None = None
        self._lift_anchor = pin.SE3.Identity()
        self._replanned = False
        self._t_state = 0.0
        self.log: list[tuple[float, str]] = []

    def __repr__(self) -> str:
        """State and contacts."""
        return f"SupportSequencer(state={self.state!r}, contacts={self.contacts})"

    # ------------------------------------------------------------------------------ helpers
    def reset(self, t: float, soles: Mapping[str, pin.SE3], com_xy: npt.ArrayLike) -> None:
        """Start in double support with both soles anchored where they are.

        Args:
            t: Time [s].
            soles: side -> current sole pose.
            com_xy: Current CoM ``(2,)`` [m].
        """
        self.anchors = {s: soles[s].copy() for s in SIDES}
        self.ground = float(np.mean([soles[s].translation[2] for s in SIDES]))
        self.state = "double"
        self.contacts = SIDES
        self._update_polygon()
        com_xy = np.asarray(com_xy, float)[:2]
        self._free = com_xy.copy()
        self._w_start = self._w_end = 1.0
        self._com = _Move(t, 0.0, com_xy.copy(), None)
        self._foot = None
        self._swing_target = None
        self._t_state = t
        self.log = [(t, "double")]

    def support_point(self, side: str) -> np.ndarray:
        """CoM target over the sole centre of ``side`` (its anchor), ``(2,)``."""
        return (self.anchors[side].act(self.sole_centers[side]))[:2]

    def middle_point(self) -> np.ndarray:
        """CoM target between the sole centres of the two anchors, ``(2,)``."""
        return 0.5 * (self.support_point("left") + self.support_point("right"))

    def free_point(self, natural: np.ndarray | None) -> np.ndarray:
        """Double-support CoM goal: the person's scaled CoM kept inside the two soles' polygon.

        Without a natural CoM (``None``) it is the middle point (Poubel 2014 Table I).
        """
        if natural is None or not np.all(np.isfinite(natural)):
            return self.middle_point()
        return clamp_to_polygon(np.asarray(natural, float)[:2], self._polygon)

    def _update_polygon(self) -> None:
        corners = [
            (self.anchors[s].rotation @ c + self.anchors[s].translation)[:2]
            for s in SIDES
            for c in self.sole_corners[s]
        ]
        self._polygon = shrink_polygon(convex_hull(np.array(corners)), self.settings.com_margin)

    def _enter(self, t: float, state: str) -> None:
        self.state = state
        self._t_state = t
        self.log.append((t, state))

    def _move_com(self, t: float, end: np.ndarray | None) -> None:
        """Plan the CoM target to ``end`` (``None``: the moving double-support goal)."""
        goal = self._free if end is None else np.asarray(end, float)
        start = self._com.at(t, self._free) if self._com is not None else goal
        self._w_start = self.free_weight(t)
        self._w_end = 1.0 if end is None else 0.0
        dist = float(np.linalg.norm(goal - start))
        duration = max(self.settings.min_time, dist / self.settings.com_speed)
        self._com = _Move(t, duration, start, None if end is None else goal)

    def free_weight(self, t: float) -> float:
        """Weight of the free double-support goal in the CoM target (1) against a planned point (0).

        Interpolated like the CoM target itself.
        """
        if self._com is None:
            return 1.0
        s = 1.0 if self._com.duration <= 0 else min_jerk((t - self._com.t0) / self._com.duration)
        return self._w_start + s * (self._w_end - self._w_start)

    def _move_foot(self, t: float, start: pin.SE3, end: pin.SE3) -> None:
        """Plan a straight minimum-jerk move of the swing sole, ending with ``end``'s rotation."""
        dist = float(np.linalg.norm(end.translation - start.translation))
        duration = max(self.settings.min_time, dist / self.settings.foot_speed)
        self._foot = _PoseMove(t, duration, start.copy(), end.copy())

    def clamp_swing(self, support: str, desired: pin.SE3, *, clearance: float) -> pin.SE3:
        """Keep a swing-sole pose reachable: flat, beside the support sole, above the ground.

        In the support sole's heading frame the swing sole stays between ``min_width`` and
        ``max_width`` to its side and within ``max_stride`` forward or backward, its yaw within
        ``max_yaw`` of the support's, and its height at least ``clearance`` above the ground.
        """
        st = self.settings
        min_width = 0.16 if st.min_width is None else st.min_width
        max_width = max(min_width, 0.3 if st.max_width is None else st.max_width)
        max_stride = 0.15 if st.max_stride is None else st.max_stride
        swing = _OTHER[support]
        base = self.anchors[support]
        psi_s = math.atan2(base.rotation[1, 0], base.rotation[0, 0])
        c, s = math.cos(psi_s), math.sin(psi_s)
        d = desired.translation - base.translation
        sign = 1.0 if swing == "left" else -1.0
        x = float(np.clip(c * d[0] + s * d[1], -max_stride, max_stride))
        y = sign * float(np.clip(sign * (-s * d[0] + c * d[1]), min_width, max_width))
        xy = base.translation[:2] + np.array([c * x - s * y, s * x + c * y])
        psi = math.atan2(desired.rotation[1, 0], desired.rotation[0, 0])
        dpsi = math.atan2(math.sin(psi - psi_s), math.cos(psi - psi_s))
        dpsi = float(np.clip(dpsi, -st.max_yaw, st.max_yaw))
        R = _yaw(psi_s + dpsi)
        z = max(float(desired.translation[2]), self.ground + clearance)
        return pin.SE3(R, np.array([xy[0], xy[1], z]))

    @property
    def _com_move(self) -> _Move:
        """The CoM move in progress (set in every state that reads it)."""
        if self._com is None:
            raise RuntimeError("SupportSequencer: no CoM move; call reset() first")
        return self._com

    @property
    def _foot_move(self) -> _PoseMove:
        """The foot move in progress (set in the lift and lower states)."""
        if self._foot is None:
            raise RuntimeError("SupportSequencer: no foot move in this state")
        return self._foot

    # ------------------------------------------------------------------------------ the tick
    def update(
        self,
        t: float,
        human_phase: str,
        soles: Mapping[str, pin.SE3],
        com_xy: npt.ArrayLike,
        swing: Mapping[str, pin.SE3],
        natural_com: npt.ArrayLike | None = None,
    ) -> SupportCommand:
        """Advance the sequences by one tick.

        Args:
            t: Time [s].
            human_phase: Detected phase of the person (``double``, ``left``, ``right``).
            soles: side -> current sole pose of the robot.
            com_xy: Current CoM of the robot ``(2,)`` [m].
            swing: side -> desired sole pose from the scaled human (used for the swing foot).
            natural_com: The CoM ``(2,)`` the scaled person would have [m]; in double support
                the CoM target follows it inside the support polygon (``None``: the middle).

        Returns:
            The :class:`SupportCommand` of this tick.
        """
        st = self.settings
        com_xy = np.asarray(com_xy, float)[:2]
        self._free = self.free_point(None if natural_com is None else np.asarray(natural_com))
        before = self.contacts
        state = self.state
        if state == "double":
            if human_phase in SIDES:
                self._enter(t, f"com_to_{human_phase}")
                self._move_com(t, self.support_point(human_phase))
        elif state.startswith("com_to_") and state != "com_to_middle":
            side = state[len("com_to_") :]
            if human_phase == "double":
                self._enter(t, "com_to_middle")
                self._move_com(t, None)
            elif human_phase != side:
                self._enter(t, f"com_to_{human_phase}")
                self._move_com(t, self.support_point(human_phase))
            elif self._com_move.done(t):
                close = np.linalg.norm(com_xy - self._com_move.at(t)) <= st.com_tolerance
                if close or t - (self._com_move.t0 + self._com_move.duration) >= st.timeout:
                    swing_side = _OTHER[side]
                    self.contacts = (side,)
                    start = soles[swing_side]
                    self._lift_anchor = self.anchors[swing_side].copy()
                    anchor = self.anchors[swing_side]
                    up = pin.SE3(
                        anchor.rotation.copy(), anchor.translation + [0.0, 0.0, st.lift_height]
                    )
                    self._enter(t, f"lift_{swing_side}")
                    self._move_foot(t, start, up)
        elif state.startswith("lift_"):
            swing_side = state[len("lift_") :]
            support = _OTHER[swing_side]
            if human_phase in ("double", swing_side):
                self._start_lowering(t, support, swing)
            elif self._foot_move.done(t):
                self._enter(t, support)
                self._swing_target = self._foot_move.end.copy()
        elif state in SIDES:
            support = state
            swing_side = _OTHER[support]
            if human_phase in ("double", swing_side):
                self._start_lowering(t, support, swing)
        elif state.startswith("lower_"):
            swing_side = state[len("lower_") :]
            support = _OTHER[swing_side]
            if self._foot_move.done(t):
                sole = soles[swing_side]
                height = float(sole.translation[2]) - self.ground
                miss = float(
                    np.linalg.norm(sole.translation[:2] - self._foot_move.end.translation[:2])
                )
                down = abs(height) <= st.land_tolerance and miss <= 5.0 * st.land_tolerance
                late = t - (self._foot_move.t0 + self._foot_move.duration) >= st.timeout
                touching = abs(height) <= 3.0 * st.land_tolerance
                if late and not touching and not self._replanned:
                    # The robot cannot reach the landing spot: put the foot back where it rose.
                    self._replanned = True
                    self.log.append((t, f"replan_{swing_side}"))
                    self._move_foot(t, self._foot_move.at(t), self._lift_anchor.copy())
                elif down or (late and touching) or (late and self._replanned):
                    self.contacts = SIDES
                    self.anchors[swing_side] = soles[swing_side].copy()
                    self._update_polygon()
                    self._free = self.free_point(
                        None if natural_com is None else np.asarray(natural_com)
                    )
                    if human_phase == swing_side:
                        self._enter(t, f"com_to_{swing_side}")
                        self._move_com(t, self.support_point(swing_side))
                    else:
                        self._enter(t, "com_to_middle")
                        self._move_com(t, None)
        elif state == "com_to_middle":
            if human_phase in SIDES:
                self._enter(t, f"com_to_{human_phase}")
                self._move_com(t, self.support_point(human_phase))
            elif self._com_move.done(t):
                self._enter(t, "double")

        # Targets of this tick.
        feet: dict[str, pin.SE3] = {}
        for side in SIDES:
            if side in self.contacts:
                feet[side] = self.anchors[side].copy()
        state = self.state
        if state.startswith(("lift_", "lower_")):
            swing_side = state.split("_", 1)[1]
            feet[swing_side] = self._foot_move.at(t)
        elif state in SIDES:
            support = state
            swing_side = _OTHER[support]
            desired = self.clamp_swing(support, swing[swing_side], clearance=st.lift_height)
            feet[swing_side] = self._rate_limit(desired)
        com = self._com.at(t, self._free) if self._com is not None else com_xy.copy()
        return SupportCommand(
            state=state,
            contacts=self.contacts,
            switched=self.contacts != before,
            com=com,
            feet=feet,
            free_weight=self.free_weight(t),
        )

    def _rate_limit(self, desired: pin.SE3) -> pin.SE3:
        """Move the swing target towards ``desired``, rate-limited.

        At most ``swing_speed`` [m/s] and ``swing_speed / 0.1`` [rad/s] (a 10 cm lever).
        """
        prev = self._swing_target
        if prev is None:
            self._swing_target = desired.copy()
            return desired.copy()
        step = self.settings.swing_speed * self.dt
        d = desired.translation - prev.translation
        n = float(np.linalg.norm(d))
        p = desired.translation if n <= step else prev.translation + d * (step / n)
        w = pin.log3(prev.rotation.T @ desired.rotation)
        a = float(np.linalg.norm(w))
        max_a = step / 0.1
        R = desired.rotation if a <= max_a else prev.rotation @ pin.exp3(w * (max_a / a))
        out = pin.SE3(R.copy(), p.copy())
        self._swing_target = out
        return out.copy()

    def _start_lowering(self, t: float, support: str, swing: Mapping[str, pin.SE3]) -> None:
        swing_side = _OTHER[support]
        if self.state in SIDES and self._swing_target is not None:
            start = self._swing_target.copy()
        elif self._foot is not None:
            start = self._foot.at(t)
        else:
            start = self.anchors[swing_side].copy()
        landing = self.clamp_swing(support, swing[swing_side], clearance=0.0)
        landing = pin.SE3(landing.rotation, np.array([*landing.translation[:2], self.ground]))
        self._enter(t, f"lower_{swing_side}")
        self._replanned = False
        self._move_foot(t, start, landing)
        self._swing_target = None


def shrink_polygon(hull: np.ndarray, margin: float) -> np.ndarray:
    """Half-planes ``(normals (m, 2), offsets (m,))`` of a CCW hull moved inwards by ``margin``."""
    hull = np.asarray(hull, float)
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, hull) - margin
    return np.concatenate([normals, offsets[:, None]], axis=1)


def clamp_to_polygon(point: np.ndarray, halfplanes: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Project a 2-D point onto ``{x : n_k' x <= o_k}`` (Dykstra's alternating projections).

    An empty region (margin larger than the polygon) returns the projection onto its
    least-violated constraints, never NaN.
    """
    x = np.asarray(point, float).copy()
    if halfplanes.size == 0:
        return x
    N, o = halfplanes[:, :2], halfplanes[:, 2]
    if np.all(N @ x <= o + 1e-12):
        return x
    corrections = np.zeros_like(N)
    for _ in range(iterations):
        for k in range(len(o)):
            y = x + corrections[k]
            viol = N[k] @ y - o[k]
            x_new = y - max(viol, 0.0) * N[k]
            corrections[k] = y - x_new
            x = x_new
    return x


def _yaw(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


__all__ = [
    "AIR_START",
    "PHASES",
    "clamp_to_polygon",
    "convex_hull",
    "shrink_polygon",
    "PhaseThresholds",
    "SequencerSettings",
    "SupportCommand",
    "SupportPhaseDetector",
    "SupportSequencer",
    "detect_support_phases",
    "foot_points",
    "min_jerk",
]
