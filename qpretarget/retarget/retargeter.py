# SPDX-License-Identifier: Apache-2.0
r"""The retargeting pipeline: human motion in, controller targets every tick, robot trajectory out.

:class:`Retargeter` runs the stages of DESIGN.md "Human motion in" and Dariush 2009 Sec. 2-3,
each usable offline and one frame at a time:

1. key-points from the motion's joints or markers (a key-point map, ``docs/motion.md``);
2. 2nd-order Butterworth low-pass at the capture rate (zero phase offline, causal online);
3. cardinal-spline up-sampling to the control rate (100 Hz);
4. calibration on the first samples (heading, position, segment lengths), then scaling to the
   robot (Poubel 2014 eq. 1 from the support foot, or Dariush 2009 per-link scaling);
5. support-phase detection on the person and the transition sequences of Poubel 2014 Table I
   (contact switches, CoM target, swing-foot targets);
6. one :meth:`Controller.step <qpretarget.control.Controller.step>` per control tick with the
   targets of the tasks named in the controller YAML's ``retarget:`` section.

Offline, :meth:`Retargeter.retarget` returns a :class:`~qpretarget.trajectory.RobotTrajectory`
(saved as the ``.npz`` of ``docs/formats.md``). Online, :meth:`Retargeter.push` takes one captured
frame and returns the commands of the control ticks that became computable; with causal filtering
the online commands equal the offline ones (same code after the filters; the streaming filters
equal their offline versions).

The ``retarget:`` section (validated here, documented in ``docs/retargeting.md``)::

    retarget:
      keypoint_map: cmu                 # optional: guessed from the motion's joint names
      robot_keypoints: {neck: torso_link}   # optional: key-point -> robot frame overrides
      tasks:                            # controller task -> key-point (and orientation)
        pelvis: {keypoint: waist, orientation: waist}
        torso: {orientation: torso}
        left_hand: left_hand
      scaling: poubel                   # poubel | dariush, or {type: poubel, blend_time: 0.3}
      filter: {cutoff_hz: 7.0, order: 2, zero_phase: true}
      upsample: {tension: 0.5}
      calibration: {frames: 1, ramp_time: 0.5}
      rate: 100                         # control rate [Hz], default 1 / dt
      support:                          # optional: support phases and Poubel Table I sequences
        feet: {left: {contact: left_foot, task: left_foot},
               right: {contact: right_foot, task: right_foot}}
        com_task: com
        detection: {height_on: 0.03, height_off: 0.05, speed_on: 0.5, speed_off: 1.0}
        sequence: {com_speed: 0.4, foot_speed: 0.4, lift_height: 0.03}
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..constraints.contacts import Contacts
from ..control.controller import Controller
from ..errors import ConfigError
from ..motion.calibration import (
    UPRIGHT_TILT,
    Calibration,
    body_tilt,
    calibrate,
    nearest_rotation,
)
from ..motion.human_motion import HumanMotion, MotionError
from ..motion.keypoints import (
    KEYPOINT_NAMES,
    KeypointMapError,
    resolve_keypoint_map,
)
from ..motion.phases import (
    AIR_START,
    SIDES,
    PhaseThresholds,
    SupportCommand,
    SupportPhaseDetector,
    foot_points,
    min_jerk,
)
from ..motion.scaling import Scaler
from ..tasks.com import ComTask
from ..tasks.frame import FrameTask
from ..trajectory import RobotTrajectory
from .binding import RobotBinding, waist_yaw
from .feet import FootTargets, initial_soles
from .record import RunRecorder, run_meta
from .rooting import Rooting, anchors_points  # noqa: F401 (anchors_points re-exported)
from .spec import (
    RetargetError,
    RetargetSpec,
    SupportSpec,
    TaskBinding,
    _number,
    default_robot_keypoints,
)
from .stepping import KinematicStepper, StepCommand, blend_pose, swing_height_ramp
from .stream import WAIST_ABOVE_HIPS, Command, KeypointStream, iter_frames
from .support import FOOT_POINTS, ComEstimate, FootSupport
from .whole_body import whole_body_config

#: The initial stance is solved until the base and the soles move slower than this [m/s] ...
INITIAL_SETTLED = 1e-3
#: ... or for at most this many control ticks after the ramp (not recorded).
INITIAL_TICKS = 300
#: The targets of the initial stance are ramped in from the reference posture over this [s].
INITIAL_RAMP = 0.5


class Retargeter:
    """Retarget human motion to the controller's robot (see the module docstring).

    Args:
        controller: The controller; its YAML's ``retarget:`` section says which task tracks which
            key-point (see :class:`RetargetSpec`).
        spec: A ``retarget:`` mapping overriding the controller's, or a :class:`RetargetSpec`.
        keypoint_map: Key-point map of the motions (bundled name, path, dict or
            :class:`KeypointMap`), overriding ``retarget.keypoint_map``; ``None`` guesses it.
        rate: Control rate [Hz], overriding ``retarget.rate`` (default: ``1 / dt``).

    Raises:
        ConfigError: Invalid ``retarget:`` section (with the YAML path).
    """

    def __init__(
        self,
        controller: Controller,
        spec: Mapping[str, Any] | RetargetSpec | None = None,
        *,
        keypoint_map: Any = None,
        rate: float | None = None,
    ) -> None:
        self.controller = controller
        if isinstance(spec, RetargetSpec):
            self.spec = spec
        else:
            raw = spec if spec is not None else controller.config.get("retarget")
            self.spec = RetargetSpec.parse(raw, controller)
        if rate is not None:
            self.spec = replace(self.spec, rate=_number(rate, "rate"))
        self.keypoint_map = keypoint_map if keypoint_map is not None else self.spec.keypoint_map
        self.rate = self.spec.rate or 1.0 / controller.dt
        self.dt = 1.0 / self.rate
        if not 0 < self.dt < 1:
            raise ConfigError(f"rate must be above 1 Hz, got {self.rate!r}.", path="retarget.rate")
        self._setup_robot()
        self._stream: KeypointStream | None = None
        self._record = True
        #: The run's notes on its input (``support phases: ...``; also in the run's messages).
        self.notes: list[str] = []

    def __repr__(self) -> str:
        """Tasks, scaling, filter, rate."""
        s = self.spec
        return (
            f"Retargeter(tasks={list(s.tasks)}, scaling={s.scaling!r}, cutoff_hz={s.cutoff_hz}, "
            f"rate={self.rate:g}, support={'yes' if s.support else 'no'})"
        )

    # -------------------------------------------------------------------- robot side
    def _setup_robot(self) -> None:
        ctrl = self.controller
        b = self.binding = RobotBinding(ctrl, self.spec)
        self.robot_map, self.robot_points = b.robot_map, b.robot_points
        self.robot_waist_rotation = b.robot_waist_rotation
        self.task_reference, self.task_offsets = b.task_reference, b.task_offsets
        self.com_reference, self.leg_lengths = b.com_reference, b.leg_lengths
        self._unheading = b.unheading
        self.com_estimate = ComEstimate(b.robot_map, b.robot_points, b.point_ids, b.com_reference)
        #: The controller's ``contacts`` constraint (its active feet are recorded in the run).
        self.contacts = next((c for c in ctrl.constraints if isinstance(c, Contacts)), None)
        # Support: soles, ankle -> sole transforms, foot task frames.
        self.support = self.spec.support
        self.feet: FootSupport | None = None
        if self.support is not None:
            self.feet = FootSupport(
                self.support, self.contacts, b.data, b.robot_points, b.task_reference,
                b.unheading, b.leg_lengths,
            )  # fmt: skip

    # -------------------------------------------------------------------- offline
    def retarget(
        self,
        motion: HumanMotion,
        *,
        start: float | None = None,
        end: float | None = None,
        causal: bool | None = None,
        progress: bool | Callable[[int, int], None] = False,
    ) -> RobotTrajectory:
        """Retarget a whole motion offline.

        Args:
            motion: The human motion.
            start: Keep ``t >= start`` [s] of the motion (``None``: from its first frame).
            end: Keep ``t < end`` [s] (``None``: to its last frame).
            causal: Causal filtering (as online) instead of the zero-phase filter; default from
                ``retarget.filter.zero_phase``.
            progress: ``True`` for a tqdm progress bar, or ``progress(done, total)`` called
                every tick.

        Returns:
            The :class:`~qpretarget.trajectory.RobotTrajectory` (one sample per control tick).

        Raises:
            RetargetError: The excerpt is too short, or the motion lacks the key-points of every
                task.
            KeypointMapError: No key-point map fits the motion.
        """
        if start is not None or end is not None:
            motion = motion.slice(0.0 if start is None else start, end)
        if len(motion) < 4:
            raise RetargetError(
                f"{motion.source or 'the motion'}: {len(motion)} frames; retargeting needs at "
                "least 4 (filter and spline start-up)"
            )
        causal = (not self.spec.zero_phase) if causal is None else bool(causal)
        stream = self._make_stream(motion, causal=causal)
        if stream.filter is not None and not causal:
            pad = 3 * (stream.filter.order + 1)
            if len(motion) <= pad:
                raise RetargetError(
                    f"{motion.source}: {len(motion)} frames is too short for zero-phase "
                    f"filtering (needs more than {pad}); use causal=True or a longer excerpt"
                )
        t_out, y, raw = stream.offline(motion)
        self._record = True
        self._begin(stream, float(motion.t[0]))
        self._human_raw_t: Any = motion.t.copy()
        self._human_raw: dict[str, Any] = dict(raw)
        total = len(t_out)
        bar = None
        if progress is True:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="tick", desc="retarget", leave=False)
        for k in range(total):
            self._tick(float(t_out[k]), y[k])
            if bar is not None:
                bar.update(1)
            elif callable(progress):
                progress(k + 1, total)
        if bar is not None:
            bar.close()
        if self.calibration is None:
            raise RetargetError(
                f"{motion.source or 'the motion'}: the waist key-point is missing in every frame "
                f"of the excerpt (or in fewer than calibration.frames = "
                f"{self.spec.calibration_frames}); nothing to calibrate the scaling on"
            )
        traj = self.trajectory()
        # What the loader dropped or noticed (a T-pose frame 0: HumanMotion.without_leading_cut).
        traj.meta["motion_notes"] = list(motion.meta.get("notes", []))
        return traj

    # -------------------------------------------------------------------- online
    def start(
        self,
        skeleton: HumanMotion | Sequence[str],
        *,
        rate: float | None = None,
        keypoint_map: Any = None,
        record: bool = True,
    ) -> None:
        """Start an online stream (resets the controller).

        Args:
            skeleton: A motion with the stream's joint names (any frames: only its names, rate and
                orientation availability are used), or the list of joint names.
            rate: Capture rate [Hz] (default: the motion's).
            keypoint_map: Overrides the retargeter's key-point map.
            record: Keep every tick and pushed frame for :meth:`trajectory` (about 8 kB per
                capture frame on G1). ``False`` keeps only the state the next tick needs, so
                memory stays flat over hours of teleoperation; the commands are the same, but
                :meth:`trajectory` then raises.

        Raises:
            ValueError: No rate for a list of names.
        """
        if not isinstance(skeleton, HumanMotion):
            if rate is None:
                raise ValueError("give the capture rate: start(names, rate=120.0)")
            names = list(skeleton)
            skeleton = HumanMotion(
                t=np.array([0.0]), names=tuple(names), positions=np.zeros((1, len(names), 3)),
                parents=tuple([-1] * len(names)), rate=float(rate), source="stream",
            )  # fmt: skip
        elif rate is not None:
            skeleton = HumanMotion(
                t=skeleton.t[:1], names=skeleton.names, positions=skeleton.positions[:1],
                parents=skeleton.parents,
                orientations=None if skeleton.orientations is None else skeleton.orientations[:1],
                rate=float(rate), source=skeleton.source, meta=skeleton.meta,
            )  # fmt: skip
        if keypoint_map is not None:
            self.keypoint_map = keypoint_map
        stream = self._make_stream(skeleton, causal=True)
        self._record = bool(record)
        self._begin(stream, None)
        self._human_raw_t = []
        self._human_raw = {k: [] for k in stream.kmap.keypoints}

    def push(
        self,
        frame: npt.ArrayLike | Mapping[str, npt.ArrayLike],
        t: float,
        *,
        orientations: npt.ArrayLike | Mapping[str, npt.ArrayLike] | None = None,
    ) -> list[Command]:
        """Feed one captured frame; return the control ticks it made computable.

        The spline needs one frame of look-ahead, so the commands lag the input by one to two
        capture periods (docs/motion.md, "Latency").

        Args:
            frame: ``(J, 3)`` joint positions [m] in the skeleton's order, or a mapping joint name
                -> position.
            t: Capture time [s], increasing.
            orientations: ``(J, 3, 3)`` joint orientations (or a mapping), needed when the tasks
                follow motion orientations.

        Returns:
            The :class:`Command` of each new control tick (possibly none).

        Raises:
            RetargetError: :meth:`start` was not called.
            ValueError: Wrong frame shape.
        """
        stream = self._require_stream()
        frame_arr = self._frame_array(frame, stream, what="frame")
        rot_arr = None
        if orientations is not None:
            rot_arr = self._frame_array(orientations, stream, what="orientations", shape=(3, 3))
        outputs, pts = stream.push(float(t), frame_arr, rot_arr)
        if self._record:
            self._human_raw_t.append(float(t))
            for k, v in pts.items():
                self._human_raw[k].append(np.asarray(v, float).copy())
        return [c for to, y in outputs for c in self._tick(float(to), y)]

    def finish(self) -> list[Command]:
        """End the stream: emit the ticks up to the last frame (spline end rule)."""
        stream = self._require_stream()
        return [c for to, y in stream.flush() for c in self._tick(float(to), y)]

    # -------------------------------------------------------------------- narrowed state
    @property
    def _cal(self) -> Calibration:
        if self.calibration is None:
            raise RetargetError("not calibrated yet")
        return self.calibration

    @property
    def _scl(self) -> Scaler:
        if self.scaler is None:
            raise RetargetError("not calibrated yet")
        return self.scaler

    @property
    def _fs(self) -> FootSupport:
        if self.feet is None:
            raise RetargetError("no retarget.support section")
        return self.feet

    @property
    def _sup(self) -> SupportSpec:
        if self.support is None:
            raise RetargetError("no retarget.support section")
        return self.support

    @property
    def _stp(self) -> KinematicStepper:
        if self.stepper is None:
            raise RetargetError("not in the kinematic balance mode")
        return self.stepper

    @property
    def _con(self) -> Contacts:
        if self.contacts is None:
            raise RetargetError("the controller has no contacts constraint")
        return self.contacts

    # -------------------------------------------------------------------- internals
    def _require_stream(self) -> KeypointStream:
        if self._stream is None:
            raise RetargetError("call start(skeleton) before push(frame, t)")
        return self._stream

    @staticmethod
    def _frame_array(
        frame: Any, stream: KeypointStream, *, what: str, shape: tuple[int, ...] = (3,)
    ) -> np.ndarray:
        names = stream.skeleton.names
        if isinstance(frame, Mapping):
            arr = np.full((len(names), *shape), np.nan)
            for name, value in frame.items():
                arr[stream.skeleton.index(name)] = np.asarray(value, float).reshape(shape)
            return arr
        arr = np.asarray(frame, float)
        if arr.shape != (len(names), *shape):
            raise ValueError(
                f"{what} must have shape {(len(names), *shape)} (the skeleton's "
                f"{len(names)} joints), got {arr.shape}"
            )
        return arr

    def _make_stream(self, motion: HumanMotion, *, causal: bool) -> KeypointStream:
        kmap = resolve_keypoint_map(self.keypoint_map, motion)
        missing = kmap.missing_in(list(motion.names))
        if missing:
            raise KeypointMapError(
                f"key-point map {kmap.name!r} names {missing[:6]} which "
                f"{motion.source or 'the motion'} does not have; pass the right map "
                "(retarget.keypoint_map or --keypoint-map)"
            )
        human_kps = list(kmap.keypoints)
        needed = {b.keypoint for b in self.spec.tasks.values() if b.keypoint is not None}
        usable = [
            b for b in self.spec.tasks.values() if b.keypoint in human_kps or b.keypoint is None
        ]
        if not usable:
            raise RetargetError(
                f"the motion's key-points {human_kps} include none of the tasks' key-points "
                f"{sorted(needed)}"
            )
        keypoints = [k for k in human_kps if k in KEYPOINT_NAMES or k in self.robot_points]
        orientations: list[str] = []
        if motion.orientations is not None:
            wanted = {b.orientation for b in self.spec.tasks.values() if b.orientation}
            orientations = [o for o in kmap.orientations if o in wanted]
        return KeypointStream(
            kmap, motion, keypoints, orientations, self.spec, self.rate, causal=causal
        )

    def _begin(self, stream: KeypointStream, t0: float | None) -> None:
        """Reset the controller and every stateful stage for a new motion."""
        self._stream = stream
        ctrl = self.controller
        ctrl.reset()  # resets the fallback's solver too: runs from here reproduce bit for bit
        self.calibration: Calibration | None = None
        self.scaler: Scaler | None = None
        self._pending: list[tuple[float, np.ndarray]] = []
        self._calibration_samples: list[tuple[float, np.ndarray]] = []
        self._rec = RunRecorder(ctrl, self.contacts)
        self._skipped = [
            n for n, b in self.spec.tasks.items()
            if b.keypoint is not None and b.keypoint not in stream.keypoints
        ]  # fmt: skip
        # Phases of the person are detected (and recorded) with or without support sequences.
        self.detector = SupportPhaseDetector(
            self.support.detection if self.support is not None else PhaseThresholds()
        )
        static = self.support is not None and self.support.mode == "static"
        self.sequencer = self.feet.sequencer(self.dt) if self.feet and static else None
        self.stepper = (
            KinematicStepper(self.support.stepping, dt=self.dt, toes=self.feet.toe_geometry())
            if self.feet is not None and self.support is not None and not static
            else None
        )
        self._foot_targets: FootTargets | None = None
        #: Last time the person was in flight [s].
        self._flight_t = -math.inf
        #: Start of an anticipated take-off (``stepping.takeoff``) [s], ``None`` when none.
        self._takeoff_t: float | None = None
        #: The person's waist height at the previous tick [m] (its rising speed).
        self._waist_z: float | None = None
        if self.stepper is not None and self.support is not None:
            for fb in self.support.feet.values():  # a run may follow one that ended in flight
                ctrl.set_weight_scale(fb.task, 1.0)
        self._feet_warned = False
        self.notes = []
        #: Why the start posture is held (the person not upright at calibration), or "".
        self._held = ""
        #: The task targets of that hold (:meth:`_hold_targets`).
        self._held_targets: dict[str, Any] = {}
        #: The person's lowest foot point at calibration [m] (``None``: no foot key-points).
        self._foot_low0: float | None = None
        self._air_warned = False
        #: Feet standing at the run's first tick (the initial stance may start on one foot).
        self._initial_standing: tuple[str, ...] = SIDES
        self._first_targets: dict[str, tuple[np.ndarray | None, np.ndarray | None]] = {}
        self._rooting: Rooting | None = None
        if self.support is not None:
            ctrl.set_contacts([fb.contact for fb in self.support.feet.values()])
        self._t_first: float | None = t0
        #: Task poses the start ramp begins from: the reference posture's, or the person's
        #: first-sample stance (:meth:`_initial_stance`); the targets stay relative to the
        #: reference posture's (:meth:`RobotBinding.task_targets`).
        self._ramp_start = {n: (p.copy(), R.copy()) for n, (p, R) in self.task_reference.items()}

    def _calibrate(self, samples: list[tuple[float, np.ndarray]]) -> None:
        stream = self._require_stream()
        unpacked = [stream.unpack(y) for _, y in samples]
        human = {k: np.array([u[0][k] for u in unpacked]) for k in stream.keypoints}
        waist_R = None
        if "waist" in stream.orientations:
            waist_R = np.array([nearest_rotation(u[1]["waist"]) for u in unpacked])
        foot_R = {s: self._fs.sole_ref[s].rotation for s in SIDES} if self.feet else None
        self.calibration = calibrate(
            human,
            {k: v for k, v in self.robot_points.items()},
            human_waist_rotation=waist_R,
            robot_waist_rotation=self.robot_waist_rotation,
            robot_foot_rotations=foot_R,
        )
        self.scaler = Scaler(self.calibration, self.spec.scaling)
        if stream.lift:
            self._note(
                f"key-points: the skeleton's waist is rooted at (or near) its hip joints; its "
                f"key-point is raised by {100 * stream.lift:.1f} cm to the pelvis centre the "
                f"scaling expects ({WAIST_ABOVE_HIPS:g} leg lengths above the hips, as CMU's "
                "root; docs/motion.md, *The waist key-point*)"
            )
        if stream.rest_fixes:
            self._note(
                "key-points: the skeleton's rest pose is not upright facing +x (BVH: y up, "
                f"facing +z): its {', '.join(sorted(stream.rest_fixes))} orientations are taken "
                "from the person's body frame at the first frame, turned as the joints turn "
                "since (docs/motion.md, *Rest poses*)"
            )
        cal = self._cal
        legs = [f"{side}_{p}" for side in SIDES for p in ("knee", "ankle")]
        robot_l = sum(cal.robot_lengths.get(k, math.nan) for k in legs)
        human_l = sum(cal.human_lengths.get(k, math.nan) for k in legs)
        #: Leg-length ratio robot / person (the scale of heights in the kinematic mode).
        self._leg_scale = robot_l / human_l if human_l > 0 else cal.root_scale
        if not math.isfinite(self._leg_scale):
            self._leg_scale = cal.root_scale
        self._rooting = Rooting(
            self.scaler, cal, self._leg_scale, self.leg_lengths,
            blend_time=self.spec.blend_time, leg_extension=self.spec.leg_extension,
            kinematic=self.stepper is not None,
        )  # fmt: skip
        if self.stepper is not None and self.support is not None:
            self._rooting.flight_drift = self.support.stepping.flight_drift
        # Waist yaw at calibration (feet yaw fallback when the motion has no toes).
        first = unpacked[0]
        self._waist_yaw_cal = waist_yaw(first[0], first[1])
        self._check_upright(human)
        feet = [first[0][k] for s in SIDES for k in foot_points(first[0], s)]
        lows = [float(p[2]) for p in feet if np.all(np.isfinite(p))]
        self._foot_low0 = min(lows) if lows else None

    def _tick(self, t: float, y: np.ndarray) -> list[Command]:
        """Process one control-rate sample (after the first ``calibration.frames``, all held)."""
        if self.calibration is None:
            # Calibrate on the first `calibration.frames` samples where the waist is seen (marker
            # data may start with gaps); the samples before are then run with missing targets.
            self._pending.append((t, y))
            kp, _, missing = self._require_stream().unpack(y)
            if not missing.get("waist", True) and np.all(np.isfinite(kp["waist"])):
                self._calibration_samples.append((t, y))
            if len(self._calibration_samples) < self.spec.calibration_frames:
                return []
            self._calibrate(self._calibration_samples)
            if self.stepper is not None and self._sup.stepping.initial_stance and not self._held:
                self._initial_stance(self._calibration_samples[0][1])
            pending, self._pending = self._pending, []
            return [self._process(tp, yp) for tp, yp in pending]
        return [self._process(t, y)]

    def _check_upright(self, human: Mapping[str, np.ndarray]) -> None:
        """Hold the start posture when the person is not upright at calibration.

        Bad input of issue 15: a skeleton lying down (or upside down, or read with the wrong
        up axis) has no feet to stand on, and scaling it rooted at the robot's feet put the
        robot's pelvis 34 cm lower, a silent crouch (the walk turned 90 deg: pelvis 0.41 m
        against 0.75). When the standing ankle -> waist axis is more than
        :data:`~qpretarget.motion.calibration.UPRIGHT_TILT` from the vertical at calibration
        (:func:`~qpretarget.motion.calibration.body_tilt`), every task keeps its start pose and
        both feet stay planted for the whole run, and a message says so and how to fix it (a
        config without feet, no support section, follows the motion as read: the message
        only).
        """
        tilt = body_tilt(human)
        if tilt is None or tilt <= UPRIGHT_TILT:
            return
        what = "upside down?" if tilt > 135.0 else "lying down?"
        read = self._require_stream().skeleton.meta.get("up_axis")
        other = {"y": "z", "z": "y"}.get(str(read))
        axis = (
            f"it was read with the wrong up axis ({read}): `--up-axis {other}` on the command "
            f'line, load_motion(path, up_axis="{other}") in Python'
            if other
            else "its up axis is not z: turn it z-up (BVH and AMC: `--up-axis`)"
        )
        legs = self.stepper is not None or self.sequencer is not None
        done = (
            "The robot holds its starting posture, both feet planted, for the whole run."
            if legs
            else "It is followed as read (no feet to keep planted in this config)."
        )
        message = (
            "support phases: the person is not upright at the start: the body axis (standing "
            f"ankle to waist) is {tilt:.0f} deg from the vertical ({what}). {done} If the person "
            f"stands in the file, {axis} (docs/motion.md)."
        )
        self._note(message)
        if legs:
            self._held = message
            self._held_targets = self._hold_targets()  # the start poses, fixed from now on

    def _check_air_start(self, t: float) -> None:
        """Measure heights from the floor when the motion started in the air.

        Bad input of issue 15: calibrated on a person in the air (a clip cut mid-jump), the
        kinematic pelvis height (:meth:`~qpretarget.retarget.rooting.Rooting.waist_goal`)
        counted every later stance as a crouch (the playground jumps cut at a flight's apex:
        the robot's pelvis 17-26 cm under its standing height at the landings; pelvis height
        error against the floor over 2.05-5.0 s, RMS, 7.5 cm, now 4.5). Once the lowest foot
        point seen (:attr:`~qpretarget.motion.phases.SupportPhaseDetector.ground`, causal)
        lies more than :data:`~qpretarget.motion.phases.AIR_START` under the person's lowest
        foot point at calibration, that depth is the rooting's ``ground_drop`` (kept up to date
        while it grows) and a message says so (once). Until then the detector reads the falling feet
        as standing: the robot stood on both feet. The shared clips' floors lie at most 3.2 cm
        under their first samples' lowest foot points.
        """
        if self._rooting is None or self._foot_low0 is None or self.stepper is None:
            return
        if self._held:  # the start posture held: no heights to measure
            return
        drop = self._foot_low0 - self.detector.ground
        if not drop > max(AIR_START, self._rooting.ground_drop):
            return
        self._rooting.ground_drop = drop
        if not self._air_warned:
            self._air_warned = True
            t0 = t if self._t_first is None else self._t_first
            self._note(
                f"support phases: the motion starts in the air: at {t - t0:.2f} s the person's "
                f"feet are {100 * drop:.0f} cm under their lowest point at the first sample, "
                "where the run was calibrated. Pelvis heights are measured from that floor "
                "from then on; until then the robot stood on both feet. Start the clip where "
                "the person stands to follow the first part too."
            )

    def _note(self, message: str) -> None:
        """A note on the input: in :attr:`notes` and the run's messages."""
        self.notes.append(message)
        self._rec.rows["messages"].append(message)

    def _hold_targets(self) -> dict[str, Any]:
        """Every bound frame task's start pose (:meth:`_check_upright`)."""
        out: dict[str, Any] = {}
        for name, (p, R) in self._ramp_start.items():
            task = self.controller.tasks.get(name)
            if not isinstance(task, FrameTask):
                continue
            if task.has_position and task.has_orientation:
                out[name] = pin.SE3(R, p).homogeneous
            elif task.has_position:
                out[name] = p.copy()
            elif task.has_orientation:
                out[name] = R.copy()
        return out

    def _initial_stance(self, y: np.ndarray) -> None:
        """Start in the person's first-sample stance (``stepping.initial_stance``).

        The soles are put where the scaled person's feet are
        (:func:`~qpretarget.retarget.feet.initial_soles`) and every task gets its target of
        that sample, rooted at those soles; the controller, contacts off, runs on these fixed
        targets until the floating base and the soles are still (every coordinate slower than
        :data:`INITIAL_SETTLED` m/s; at most :data:`INITIAL_TICKS` ticks, none recorded) and is
        reset there at rest, the standing soles' contacts anchored where they came to rest. The
        run's first tick starts from that posture, the person's stance, instead of the
        reference posture with the feet side by side (a clip starting mid-stride then kept the
        offset of the foot behind through the whole run). A person on one foot at that sample
        gets a robot on the same foot, the other sole raised where the person's is and in
        swing from the first tick (rooted at the standing foot, Poubel eq. 1). Online and
        offline do the same at the same sample.
        """
        ctrl, feet, cal = self.controller, self._fs, self._cal
        stream = self._require_stream()
        kp, rots, missing = stream.unpack(y)
        st = self._sup.stepping
        stance = initial_soles(
            feet, cal, self._leg_scale, self.leg_lengths, kp, self._sup.detection.height_off,
            (st.initial_width_min, st.initial_width_max),
        )  # fmt: skip
        if stance is None or self._rooting is None:
            return
        soles = stance.soles
        human = {k: kp[k] for k in cal.tree}
        anchors = {s: feet.ankle_of(s, soles[s]) for s in SIDES}
        # Rooted at the standing foot (Poubel eq. 1) when the person stands on one.
        root = "double" if len(stance.standing) == 2 else stance.standing[0]
        scaled = self._rooting.scale_from(human, root, anchors)
        ctrl.set_contacts([])

        def targets(w: float) -> dict[str, Any]:
            out: dict[str, Any] = {}
            self.binding.task_targets(
                out, cal, self.task_reference, w, self._skipped, scaled, kp, rots, missing,
                None, self._ramp_start,
            )  # fmt: skip
            for side, sole in soles.items():
                M = blend_pose(feet.sole_ref[side], sole, w) * feet.sole_to_task[side]
                out[self._sup.feet[side].task] = M.homogeneous
            return out

        def points() -> np.ndarray:
            state = ctrl.state
            return np.array(
                [state.q[:3]] + [state.frame_placement(feet.sole_ids[s]).translation for s in SIDES]
            )

        ramp = max(1, round(INITIAL_RAMP / self.dt))
        for k in range(ramp):
            ctrl.step(targets(min_jerk((k + 1) / ramp)), dt=self.dt)
        final = targets(1.0)
        before = points()
        for _ in range(INITIAL_TICKS):
            ctrl.step(final, dt=self.dt)
            now = points()
            if float(np.max(np.abs(now - before))) < INITIAL_SETTLED * self.dt:
                break
            before = now
        ctrl.reset(ctrl.q.copy())
        ctrl.set_contacts([self._sup.feet[s].contact for s in stance.standing])
        self._initial_standing = stance.standing
        if "waist" in self.robot_map.keypoints:
            waist = self.com_estimate.robot_point("waist", ctrl.state.data)
            self._rooting.waist_height = float(waist[2])
        self._ramp_start = {
            n: (p.copy(), R.copy())
            for n, (p, R) in (
                (n, cast(FrameTask, t).current_pose(ctrl.state))
                for n, t in ctrl.tasks.items()
                if n in self._ramp_start
            )
        }

    # The per-tick work: scaling, phases, targets, controller step, record.
    def _process(self, t: float, y: np.ndarray) -> Command:
        ctrl, cal, stream = self.controller, self._cal, self._require_stream()
        if self._t_first is None:
            self._t_first = t
        kp, rots, missing = stream.unpack(y)
        human = {k: kp[k] for k in cal.tree}
        state = ctrl.state
        targets: dict[str, Any] = {}

        # 1. Support phase of the person (foot heights and speeds, with hysteresis).
        phase = ""
        if self.detector is not None:
            pts = {s: [kp[f"{s}_{p}"] for p in ("ankle", "toe", "heel") if f"{s}_{p}" in kp]
                   for s in SIDES}  # fmt: skip
            if pts["left"] and pts["right"]:
                phase = self.detector.update(t, np.array(pts["left"]), np.array(pts["right"]))
                self._check_air_start(t)
                if self.stepper is not None and self.detector.flight:
                    phase = "flight"
                if self.stepper is not None:
                    self._anticipate_takeoff(t, kp)
            elif self.stepper is not None and not self._feet_warned:
                # No foot key-points: no phase to switch contacts from; the feet stay planted.
                self._feet_warned = True
                self._note(
                    f"support phases: the motion has no foot key-points (ankle, toe or heel of "
                    f"both feet; key-point map {stream.kmap.name!r}): both feet stay planted. Map "
                    "the feet in the key-point map (docs/motion.md) to make the robot step."
                )

        # 2. Scaling rooted at the robot's supporting feet (Poubel 2014 III.A), blended at
        #    root switches, legs kept off the straight-knee singularity.
        scaled, anchors = self._scale(t, human)

        # 3. Support sequences (Poubel 2014 Table I); the upper body is shifted horizontally so
        #    that its estimated CoM is where the sequence puts the robot's CoM.
        support_state = ""
        cmd: SupportCommand | StepCommand | None = None
        seq: SupportCommand | None = None
        if self.sequencer is not None and not self._held:
            feet = self._fs
            soles = {s: state.frame_placement(feet.sole_ids[s]).copy() for s in SIDES}
            com = state.com()
            if not self.sequencer.log:
                self.sequencer.reset(t, soles, com[:2])

            def waist_dyaw() -> float:
                return waist_yaw(kp, rots) - self._waist_yaw_cal

            swing = {s: feet.swing_sole(s, scaled, kp, cal, soles[s], waist_dyaw) for s in SIDES}
            predicted = self.com_estimate.predicted(scaled, com, state.data)
            seq = cmd = self.sequencer.update(t, phase, soles, com[:2], swing, predicted)
            support_state = seq.state
            if seq.switched:
                ctrl.set_contacts([self._sup.feet[s].contact for s in seq.contacts])
            natural = self.com_estimate.natural(scaled)
            if natural is not None and predicted is not None:
                w = seq.free_weight
                reference = w * predicted + (1.0 - w) * natural
                shift = np.array([seq.com[0] - reference[0], seq.com[1] - reference[1], 0.0])
                scaled = {k: (v if k in FOOT_POINTS else v + shift) for k, v in scaled.items()}

        # 3'. Kinematic stepping: each foot's contact follows the person's foot.
        if self.stepper is not None and not self._held:
            step = self._step(t, scaled, kp, rots)
            support_state = step.label
            cmd = step

        # 4. Task targets (ramped in from the reference posture over ramp_time); the start
        #    posture held while the person is not upright (:meth:`_check_upright`).
        first = self._first_targets if self.stepper is not None else None
        ramp = self._ramp(t)
        if self._held:
            targets.update(self._held_targets)
            support_state = "stance/stance" if self.stepper is not None else ""
        else:
            self.binding.task_targets(
                targets, cal, self.task_reference, ramp, self._skipped, scaled, kp, rots,
                missing, first, self._ramp_start,
            )  # fmt: skip
        if seq is not None and self._sup.com_task is not None:
            com_task = cast(ComTask, ctrl.tasks[self._sup.com_task])
            full = np.array(com_task.target, dtype=float)
            ramp = self._ramp(t)
            full[:2] = self.com_reference[:2] + ramp * (seq.com - self.com_reference[:2])
            targets[self._sup.com_task] = full
        if cmd is not None:
            for side, sole in cmd.feet.items():
                task_name = self._sup.feet[side].task
                M = sole * self._fs.sole_to_task[side]
                if cast(FrameTask, ctrl.tasks[task_name]).has_orientation:
                    targets[task_name] = M.homogeneous
                else:
                    targets[task_name] = M.translation.copy()

        # 5. One control tick.
        res = ctrl.step(targets, dt=self.dt)
        if self._record:
            rolled = [] if self.stepper is None else self.stepper.rolled
            self._rec.add(
                t, res, phase, support_state, scaled, [self._sup.feet[s].contact for s in rolled]
            )
        else:
            # Not recording: the support log keeps only its last entry (the state in force).
            log = self.sequencer or self.stepper
            if log is not None and len(log.log) > 1:
                del log.log[:-1]
        return Command(t, res.q, res.v, res.status, res, phase, support_state)

    def _scale(
        self, t: float, human: Mapping[str, np.ndarray]
    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Scaled key-points and the supporting ankles they are rooted at."""
        cal, state = self._cal, self.controller.state
        standing: dict[str, np.ndarray] = {}
        planted: dict[str, np.ndarray] | None = None
        if self.stepper is not None:
            # Rooted at the robot's standing feet the person stands on too (Poubel 2014 eq. 1
            # from the support foot; never the mid-ankle point while a leg is in the air), else
            # at the robot's standing feet, else (flight) at the waist moving like the person's.
            # A foot the person stands on that the robot is still putting down counts at its
            # landing spot (rooting at the robot's other foot would place the body from the
            # person's foot in the air).
            on = self._stp.contacts
            support = self._support_now
            soles = {s: state.frame_placement(self._fs.sole_ids[s]) for s in on}
            for s in SIDES:
                spot = self.stepper.landing_spot(s)
                if spot is not None and support.get(s, True):
                    soles[s] = spot
            use = [s for s in soles if support.get(s, True)] or list(on)
            root = "flight" if not use else "double" if len(use) == 2 else use[0]
            ankles = {s: self._fs.ankle_of(s, sole) for s, sole in soles.items()}
            anchors = {s: ankles[s] for s in use}
            # A robot foot still standing on a foot the person lifted bounds the pelvis too
            # (its leg must reach it): on the front kicks the pelvis target moved on over the
            # person's landing foot, 56 cm from the robot's standing one.
            standing = {s: ankles[s] for s in on if s not in anchors}
            # The standing feet where they are (a landing foot is not among them): the
            # take-off drift (Rooting.takeoff_drift).
            planted = {s: ankles[s] for s in on}
        elif self.sequencer is not None:
            on = self.sequencer.contacts
            root = "double" if len(on) == 2 else on[0]
            anchors = {
                s: self._fs.ankle_of(s, state.frame_placement(self._fs.sole_ids[s])) for s in on
            }
        else:
            root = "double"
            anchors = {s: cal.robot_points[f"{s}_ankle"] for s in SIDES
                       if f"{s}_ankle" in cal.robot_points}  # fmt: skip
        if self._rooting is None:
            raise RetargetError("not calibrated yet")
        scaled = self._rooting.scale(t, human, root, anchors, standing)
        if planted is not None:
            self._rooting.plant(planted, human)
        return scaled, anchors

    def _step(
        self,
        t: float,
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        rots: Mapping[str, np.ndarray],
    ) -> StepCommand:
        """One tick of the kinematic stepper: contacts switched, anchors moved, sole targets."""
        ctrl, feet, stepper = self.controller, self._fs, self._stp
        soles = {s: ctrl.state.frame_placement(feet.sole_ids[s]).copy() for s in SIDES}
        if self._foot_targets is None:
            self._foot_targets = FootTargets(
                feet, self._cal, self._leg_scale, self.leg_lengths,
                self._sup.stepping.swing_reach, absolute=self._sup.stepping.absolute,
                inline=self._sup.stepping.inline_feet, dt=self.dt,
            )  # fmt: skip
        ft = self._foot_targets

        def waist_dyaw() -> float:
            return waist_yaw(kp, rots) - self._waist_yaw_cal

        desired, human_foot = ft.orient(scaled, kp, soles, waist_dyaw, flight=self._in_flight)
        base = ctrl.state.q
        yaw = math.atan2(
            2.0 * (base[6] * base[5] + base[3] * base[4]),
            1.0 - 2.0 * (base[4] * base[4] + base[5] * base[5]),
        )  # the floating base's heading (quaternion x, y, z, w at q[3:7])
        heading = (yaw, waist_dyaw())
        if not stepper.started:
            stepper.reset(t, soles, human_foot, standing=self._initial_standing)
            ft.start(kp, soles, heading)
            if self._rooting is not None:
                self._rooting.align = ft.align
        heights = dict(self.detector.height)
        # Swing targets the legs cannot reach are raised in flight and for lift_time after it
        # (the landing spot is taken as the person's foot touches down): feet.REACH_RAISE.
        lift = self._sup.stepping.lift_time
        if self._in_flight:
            self._flight_t = t
            # In flight the soles rise with the person's ankles, not with the lowest foot point:
            # a jumping person points the feet (toes 10-15 cm under the ankles), a flat robot
            # sole at the toes' height held its pelvis 15-17 cm under the person's at every
            # apex of the playground jumps (the legs at full reach).
            for side in SIDES:
                h = self.detector.point_height.get(side) or []
                if f"{side}_ankle" in kp and h and math.isfinite(h[0]):
                    heights[side] = max(heights[side], h[0])
        desired = ft.place(
            desired, scaled, kp, soles, stepper.contacts, heights, stepper.ground, heading,
            rolled=stepper.rolled, flight=self._in_flight or t - self._flight_t <= lift,
        )  # fmt: skip
        before = dict(stepper.states)
        # Heel off: the person's ankle rises over its ground more than the toe does (a foot
        # flat on a raised surface is not a toe-off), scaled.
        rise: dict[str, float] = {}
        for side in SIDES:
            h = self.detector.point_height.get(side) or []
            if f"{side}_ankle" in kp and f"{side}_toe" in kp and len(h) >= 2:
                if math.isfinite(h[0] - h[1]):
                    rise[side] = self._leg_scale * (h[0] - h[1])
        cmd = stepper.update(
            t, self._support_now, soles, desired, human_foot, flight=self._in_flight,
            toe_rise=rise, moved={s: ft.moved(s, kp) for s in SIDES},
            low={s: self.detector.height[s] < self.detector.thresholds.height_on for s in SIDES},
            offset=self._settle_offsets(t, ft, kp, scaled, soles, heading),
            hover={s: self._hovers(s) for s in SIDES}, base_yaw=yaw,
        )  # fmt: skip
        for side in SIDES:
            if before[side] == "swing" and cmd.states[side] != "swing":
                ft.touched_down(side, kp)
            elif before[side] != "swing" and cmd.states[side] == "swing" and self._in_flight:
                # Lifted into the person's flight: nothing holds the body, and a sole target
                # turning fast turns the whole robot (FootTargets.lifted).
                ft.lifted(side, soles[side])
        if cmd.switched:
            ctrl.set_contacts([self._sup.feet[s].contact for s in cmd.contacts])
        self._swing_weights(cmd, stepper.ground)
        self._con.clear_anchor_steps()
        for side, anchor in cmd.anchors.items():
            self._con.set_anchor(self._sup.feet[side].contact, anchor, moving=side in cmd.pivoting)
        return cmd

    def _hovers(self, side: str) -> bool:
        """The person holds the foot just over the floor (``stepping.handover``).

        Under the detector's ``height_off``, slower than its ``speed_on``.
        """
        det = self.detector
        th = det.thresholds
        return bool(det.height[side] < th.height_off and det.speed[side] < th.speed_on)

    def _settle_offsets(
        self,
        t: float,
        ft: FootTargets,
        kp: Mapping[str, np.ndarray],
        scaled: Mapping[str, np.ndarray],
        soles: Mapping[str, pin.SE3],
        heading: tuple[float, float],
    ) -> dict[str, float] | None:
        """Side -> robot ankle's distance from the scaled person's [m], for settle steps.

        Computed only when a settle step may come
        (:meth:`~qpretarget.retarget.stepping.KinematicStepper.settle_possible`):
        :meth:`FootTargets.offset`.
        """
        if not self._stp.settle_possible(t):
            return None
        w = ft.absolute_weight(heading)
        return {s: ft.offset(s, kp, soles, scaled, w) for s in SIDES}

    @property
    def _in_flight(self) -> bool:
        """The robot is released into flight: the person's, or an anticipated take-off."""
        return bool(self.detector.flight) or self._takeoff_t is not None

    @property
    def _support_now(self) -> dict[str, bool]:
        """Whether the person stands on each foot (neither during an anticipated take-off)."""
        if self._takeoff_t is not None:
            return {s: False for s in SIDES}
        return self.detector.feet

    def _anticipate_takeoff(self, t: float, kp: Mapping[str, np.ndarray]) -> None:
        r"""Release the robot into flight before the person's feet leave (``stepping.takeoff``).

        With :math:`z_h` the person's waist height, :math:`s` the leg-length ratio and
        :math:`z_0` the robot's waist height matching the person's at calibration, the scaled
        waist is :math:`z^* = z_0 + s\,(z_h - z_h^{cal})` (the kinematic height rule of single
        support and flight, :class:`~qpretarget.retarget.rooting.Rooting`). A take-off is
        anticipated when :math:`s\,\dot z_h` exceeds ``takeoff_speed`` and :math:`z^*` is more
        than ``takeoff_gap`` over the robot's waist while a robot foot stands (the others in
        swing) and the person is not in flight yet; it holds until the person's flight is
        detected, for at most ``takeoff_hold``, or until the person's waist stops rising (the
        soles are then put down again, as after any swing).
        """
        st = self._sup.stepping
        z = float(kp["waist"][2]) if "waist" in kp else math.nan
        prev, self._waist_z = self._waist_z, z
        if (
            not st.takeoff
            or self.detector.flight
            or self._rooting is None
            or prev is None
            or not math.isfinite(z - prev)
            or "waist" not in self.robot_map.keypoints
        ):
            self._takeoff_t = None
            return
        speed = self._leg_scale * (z - prev) / self.dt
        if self._takeoff_t is not None:
            if speed <= 0.0 or t - self._takeoff_t > st.takeoff_hold:
                self._takeoff_t = None
            return
        if speed <= st.takeoff_speed:
            return
        states = self._stp.states
        standing = [s for s in SIDES if states[s] in ("stance", "tiptoe")]
        if not standing or any(states[s] not in ("stance", "tiptoe", "swing") for s in SIDES):
            return
        goal = self._rooting.waist_goal(z)
        robot = float(self.com_estimate.robot_point("waist", self.controller.state.data)[2])
        if goal - robot > st.takeoff_gap:
            self._takeoff_t = t

    def _swing_weights(self, cmd: StepCommand, ground: float) -> None:
        r"""Swing soles' task weights from their height (``flight_foot_weight`` and so on).

        The ``stepping`` settings ``flight_foot_weight`` and ``swing_orientation_weight``.
        With :math:`h` the sole target's height over the ``ground`` and
        :math:`r = \mathrm{clip}((h - 0.05) / 0.05, 0, 1)` (0 up to 5 cm, 1 from 10 cm), a swing
        sole's orientation rows are weighted :math:`1 - (1 - f_o) r` and, in the person's
        flight, all its rows :math:`1 - (1 - f_f) r` more; stance soles and soles near the
        floor (lift-off, landing) keep their full weights. Each factor changes by at most
        ``dt / lift_time`` a tick (no step in the QP's solution).
        """
        st = self._sup.stepping
        f_f, f_o = st.flight_foot_weight, st.swing_orientation_weight
        if f_f >= 1.0 and f_o >= 1.0:
            return
        rate = self.dt / st.lift_time
        for side, fb in self._sup.feet.items():
            task = cast(FrameTask, self.controller.tasks[fb.task])
            pos = np.ones(3 if task.has_position else 0)
            ori = np.ones(3 if task.has_orientation else 0)
            sole = cmd.feet.get(side)
            if cmd.states.get(side) == "swing" and sole is not None:
                r = swing_height_ramp(float(sole.translation[2]) - ground)
                ori[:] = 1.0 - (1.0 - f_o) * r
                if self._in_flight:
                    flight = 1.0 - (1.0 - f_f) * r
                    pos *= flight
                    ori *= flight
            goal = np.concatenate([pos, ori])
            now = np.broadcast_to(task.weight_scale, goal.shape)
            if not np.array_equal(goal, now):
                step = np.clip(goal - now, -rate, rate)
                self.controller.set_weight_scale(fb.task, now + step)

    def _ramp(self, t: float) -> float:
        """Start ramp weight: minimum-jerk from 0 to 1 over ``calibration.ramp_time``."""
        if self.spec.ramp_time <= 0:
            return 1.0
        s = (t - (t if self._t_first is None else self._t_first)) / self.spec.ramp_time
        return 1.0 if s >= 1 else s * s * s * (10.0 + s * (-15.0 + 6.0 * s))

    # -------------------------------------------------------------------- output
    def trajectory(self) -> RobotTrajectory:
        """The run so far as a :class:`~qpretarget.trajectory.RobotTrajectory`.

        Raises:
            RetargetError: Nothing was retargeted yet, or the stream was started with
                ``record=False``.
        """
        if self._stream is not None and not self._record:
            raise RetargetError(
                "the stream was started without recording (start(..., record=False)): there is "
                "no run to return. Start it with record=True (the default) to get trajectory(); "
                "on the command line, pass --run RUN.npz to `qpretarget live` to write the run file"
            )
        rec = self._rec if self._stream is not None else None
        if rec is None or not len(rec):
            raise RetargetError("no control tick yet: retarget a motion or push frames first")
        human = {k: np.asarray(v, float) for k, v in self._human_raw.items()}
        human["t"] = np.asarray(self._human_raw_t, float)
        log = self.sequencer or self.stepper
        meta = run_meta(
            self.controller, self.spec, self._stream, self.calibration, self.rate,
            skipped=list(self._skipped), messages=rec.rows["messages"][:50],
            support_log=[] if log is None else log.log,
        )  # fmt: skip
        return rec.trajectory(human, meta)


def retarget_motion(
    controller: Controller,
    motion: HumanMotion,
    **kwargs: Any,
) -> RobotTrajectory:
    """Shortcut: ``Retargeter(controller).retarget(motion, **kwargs)``."""
    return Retargeter(controller).retarget(motion, **kwargs)


def timed_retarget(
    retargeter: Retargeter, motion: HumanMotion, **kwargs: Any
) -> tuple[RobotTrajectory, float]:
    """Retarget and return ``(trajectory, wall time [s])``."""
    t0 = time.perf_counter()
    traj = retargeter.retarget(motion, **kwargs)
    return traj, time.perf_counter() - t0


__all__ = [
    "Command",
    "MotionError",
    "RetargetError",
    "RetargetSpec",
    "Retargeter",
    "TaskBinding",
    "default_robot_keypoints",
    "iter_frames",
    "retarget_motion",
    "timed_retarget",
    "whole_body_config",
]
