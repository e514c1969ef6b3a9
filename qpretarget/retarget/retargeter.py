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

import copy
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..control.controller import Controller, StepResult
from ..errors import ConfigError, QPRetargetError, close_matches_hint
from ..motion.calibration import Calibration, calibrate, nearest_rotation, triad, yaw_of
from ..motion.filters import Butterworth, CardinalSpline
from ..motion.human_motion import HumanMotion, MotionError
from ..motion.keypoints import (
    KEYPOINT_NAMES,
    KeypointMap,
    KeypointMapError,
    load_keypoint_map,
    resolve_keypoint_map,
)
from ..motion.phases import (
    SIDES,
    PhaseThresholds,
    SequencerSettings,
    SupportPhaseDetector,
    SupportSequencer,
)
from ..motion.scaling import SCALING_METHODS, Scaler, limit_leg_extension
from ..trajectory import RobotTrajectory

#: Keys of the ``retarget:`` section.
RETARGET_KEYS = (
    "keypoint_map", "robot_keypoints", "tasks", "scaling", "filter", "upsample", "calibration",
    "rate", "support",
)  # fmt: skip

#: Orientation sources a task may follow: the key-point map's ``orientations`` entries of the
#: motion when it has joint orientations, else a frame built from key-points (:func:`triad`).
ORIENTATIONS: dict[str, tuple[str, str, str, str] | None] = {
    "waist": ("left_hip", "right_hip", "waist", "neck"),
    "torso": ("left_shoulder", "right_shoulder", "waist", "neck"),
    "head": None,
}


#: Share of the body's mass carried by each key-point in the estimate of the CoM the scaled person
#: would give the robot (trunk-heavy, roughly Winter's segment masses lumped on the nearest
#: key-point); only its horizontal displacement is used.
COM_WEIGHTS = {
    "waist": 0.45, "neck": 0.2, "head": 0.07, "left_shoulder": 0.04, "right_shoulder": 0.04,
    "left_elbow": 0.02, "right_elbow": 0.02, "left_hip": 0.05, "right_hip": 0.05,
    "left_knee": 0.03, "right_knee": 0.03,
}  # fmt: skip

#: Key-points a balance shift never moves (the feet stay where the sequences put them).
FOOT_POINTS = frozenset(
    f"{side}_{p}" for side in ("left", "right") for p in ("ankle", "toe", "heel")
)


class RetargetError(QPRetargetError, ValueError):
    """The motion cannot be retargeted with this controller (too short, nothing to track...)."""


# ------------------------------------------------------------------------------------ spec
def _mapping(value: Any, path: str, what: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"expected a mapping ({what}), got {value!r}.", path=path)
    return dict(value)


def _check_keys(spec: Mapping[str, Any], allowed: Sequence[str], path: str) -> None:
    for key in spec:
        if key not in allowed:
            raise ConfigError(
                f"unknown key {key!r}.{close_matches_hint(str(key), allowed)} "
                f"Allowed: {', '.join(allowed)}.",
                path=f"{path}.{key}",
            )


def _number(value: Any, path: str, *, positive: bool = True, integer: bool = False) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok:
        ok = math.isfinite(value) and (value > 0 if positive else value >= 0)
    if ok and integer:
        ok = float(value).is_integer()
    if not ok:
        kind = "a positive integer" if integer else ("a positive number" if positive else ">= 0")
        raise ConfigError(f"expected {kind}, got {value!r}.", path=path)
    return float(value)


@dataclass(frozen=True)
class TaskBinding:
    """What drives one controller task.

    Attributes:
        task: Controller task name.
        keypoint: Key-point whose scaled position is the task's position target (or ``None``).
        orientation: Orientation source (``waist``, ``torso``, ``head``) or ``None``.
        offset: Explicit world offset [m] added to the scaled key-point (``None``: measured on
            the robot's reference posture between the key-point's frame and the task's point).
    """

    task: str
    keypoint: str | None = None
    orientation: str | None = None
    offset: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class FootBinding:
    """One foot for the support sequences: the contact name and the task that moves the sole."""

    contact: str
    task: str


@dataclass(frozen=True)
class SupportSpec:
    """The ``retarget.support`` section."""

    feet: dict[str, FootBinding]
    com_task: str
    detection: PhaseThresholds
    sequence: SequencerSettings


@dataclass(frozen=True)
class RetargetSpec:
    """The validated ``retarget:`` section (see the module docstring and docs/retargeting.md)."""

    tasks: dict[str, TaskBinding]
    keypoint_map: Any = None
    robot_keypoints: dict[str, Any] = field(default_factory=dict)
    scaling: str = "poubel"
    blend_time: float = 0.3
    leg_extension: float = 0.92
    cutoff_hz: float | None = 7.0
    filter_order: int = 2
    zero_phase: bool = True
    tension: float = 0.5
    calibration_frames: int = 1
    ramp_time: float = 0.5
    rate: float | None = None
    support: SupportSpec | None = None

    @classmethod
    def parse(
        cls, spec: Mapping[str, Any] | None, controller: Controller, *, path: str = "retarget"
    ) -> RetargetSpec:
        """Validate a ``retarget:`` mapping against a controller.

        Raises:
            ConfigError: Unknown key, unknown task, key-point or orientation, a key-point given to
                a task without position (or an orientation to one without orientation), bad
                numbers; the message has the YAML path and the closest names.
        """
        if spec is None:
            raise ConfigError(
                "the controller config has no `retarget:` section saying which task tracks which "
                "human key-point; add one (docs/retargeting.md), e.g. "
                "`retarget: {tasks: {left_hand: left_hand, pelvis: {keypoint: waist}}}`.",
                path=path,
            )
        spec = _mapping(spec, path, "the retarget section")
        _check_keys(spec, RETARGET_KEYS, path)
        kwargs: dict[str, Any] = {}

        # Tasks.
        raw_tasks = _mapping(spec.get("tasks"), f"{path}.tasks", "task -> key-point")
        if not raw_tasks:
            raise ConfigError(
                "no task to drive: map controller tasks to key-points, e.g. "
                "`tasks: {left_hand: left_hand}`.",
                path=f"{path}.tasks",
            )
        tasks: dict[str, TaskBinding] = {}
        for name, entry in raw_tasks.items():
            tpath = f"{path}.tasks.{name}"
            if name not in controller.tasks:
                raise ConfigError(
                    f"no controller task named {name!r}."
                    f"{close_matches_hint(str(name), list(controller.tasks))} "
                    f"Tasks: {', '.join(controller.tasks)}.",
                    path=tpath,
                )
            if isinstance(entry, str):
                entry = {"keypoint": entry}
            entry = _mapping(entry, tpath, "{keypoint, orientation, offset}")
            _check_keys(entry, ("keypoint", "orientation", "offset"), tpath)
            task = controller.tasks[name]
            keypoint = entry.get("keypoint")
            orientation = entry.get("orientation")
            if keypoint is not None:
                if not isinstance(keypoint, str) or not keypoint:
                    raise ConfigError(
                        f"keypoint must be a key-point name, got {keypoint!r}.",
                        path=f"{tpath}.keypoint",
                    )
                if keypoint not in KEYPOINT_NAMES:
                    raise ConfigError(
                        f"unknown key-point {keypoint!r}."
                        f"{close_matches_hint(keypoint, KEYPOINT_NAMES)} "
                        f"Key-points: {', '.join(KEYPOINT_NAMES)}.",
                        path=f"{tpath}.keypoint",
                    )
                if not getattr(task, "has_position", False):
                    raise ConfigError(
                        f"task {name!r} has no position to track ({task!r}); give it "
                        "`orientation:` only, or use a position/pose frame task.",
                        path=f"{tpath}.keypoint",
                    )
            if orientation is not None:
                if orientation not in ORIENTATIONS:
                    raise ConfigError(
                        f"unknown orientation {orientation!r}; one of {', '.join(ORIENTATIONS)}.",
                        path=f"{tpath}.orientation",
                    )
                if not getattr(task, "has_orientation", False):
                    raise ConfigError(
                        f"task {name!r} has no orientation to track ({task!r}); use "
                        "`mode: pose` or `mode: orientation`.",
                        path=f"{tpath}.orientation",
                    )
            if keypoint is None and orientation is None:
                raise ConfigError("give a `keypoint:` and/or an `orientation:`.", path=tpath)
            offset = entry.get("offset")
            if offset is not None:
                arr = np.asarray(offset, dtype=float) if _is_numbers(offset) else None
                if arr is None or arr.shape != (3,) or not np.all(np.isfinite(arr)):
                    raise ConfigError(
                        f"offset must be 3 numbers [m], got {offset!r}.", path=f"{tpath}.offset"
                    )
                offset = tuple(float(x) for x in arr)
            tasks[name] = TaskBinding(name, keypoint, orientation, offset)
        kwargs["tasks"] = tasks

        # Key-point maps.
        if spec.get("keypoint_map") is not None:
            try:
                load_keypoint_map(spec["keypoint_map"])
            except KeypointMapError as exc:
                raise ConfigError(str(exc), path=f"{path}.keypoint_map") from None
            kwargs["keypoint_map"] = spec["keypoint_map"]
        kwargs["robot_keypoints"] = _mapping(
            spec.get("robot_keypoints"), f"{path}.robot_keypoints", "key-point -> robot frame"
        )

        # Scaling.
        scaling = spec.get("scaling", "poubel")
        if isinstance(scaling, str):
            scaling = {"type": scaling}
        scaling = _mapping(scaling, f"{path}.scaling", "{type, blend_time, leg_extension}")
        _check_keys(scaling, ("type", "blend_time", "leg_extension"), f"{path}.scaling")
        method = scaling.get("type", "poubel")
        if method not in SCALING_METHODS:
            raise ConfigError(
                f"unknown scaling {method!r}; one of {', '.join(SCALING_METHODS)}.",
                path=f"{path}.scaling.type",
            )
        kwargs["scaling"] = method
        if "blend_time" in scaling:
            kwargs["blend_time"] = _number(
                scaling["blend_time"], f"{path}.scaling.blend_time", positive=False
            )
        if "leg_extension" in scaling:
            ext = _number(scaling["leg_extension"], f"{path}.scaling.leg_extension")
            if ext > 1:
                raise ConfigError(
                    f"leg_extension is a fraction of the leg length in (0, 1], got {ext!r}.",
                    path=f"{path}.scaling.leg_extension",
                )
            kwargs["leg_extension"] = ext

        # Filter and up-sampling.
        filt = spec.get("filter", {})
        if filt is False or filt == "none":
            kwargs["cutoff_hz"] = None
        else:
            filt = _mapping(filt, f"{path}.filter", "{cutoff_hz, order, zero_phase}")
            _check_keys(filt, ("cutoff_hz", "order", "zero_phase"), f"{path}.filter")
            if "cutoff_hz" in filt:
                kwargs["cutoff_hz"] = _number(filt["cutoff_hz"], f"{path}.filter.cutoff_hz")
            if "order" in filt:
                kwargs["filter_order"] = int(
                    _number(filt["order"], f"{path}.filter.order", integer=True)
                )
            if "zero_phase" in filt:
                if not isinstance(filt["zero_phase"], bool):
                    raise ConfigError(
                        f"expected true or false, got {filt['zero_phase']!r}.",
                        path=f"{path}.filter.zero_phase",
                    )
                kwargs["zero_phase"] = filt["zero_phase"]
        up = _mapping(spec.get("upsample"), f"{path}.upsample", "{tension}")
        _check_keys(up, ("tension",), f"{path}.upsample")
        if "tension" in up:
            kwargs["tension"] = _number(up["tension"], f"{path}.upsample.tension", positive=False)
        cal = _mapping(spec.get("calibration"), f"{path}.calibration", "{frames, ramp_time}")
        _check_keys(cal, ("frames", "ramp_time"), f"{path}.calibration")
        if "frames" in cal:
            kwargs["calibration_frames"] = int(
                _number(cal["frames"], f"{path}.calibration.frames", integer=True)
            )
        if "ramp_time" in cal:
            kwargs["ramp_time"] = _number(
                cal["ramp_time"], f"{path}.calibration.ramp_time", positive=False
            )
        if spec.get("rate") is not None:
            kwargs["rate"] = _number(spec["rate"], f"{path}.rate")

        # Support.
        if spec.get("support") not in (None, False):
            kwargs["support"] = _parse_support(spec["support"], controller, f"{path}.support")
        return cls(**kwargs)


def _is_numbers(x: Any) -> bool:
    return isinstance(x, (list, tuple)) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in x
    )


def _parse_support(raw: Any, controller: Controller, path: str) -> SupportSpec:
    raw = {} if raw is True else _mapping(raw, path, "{feet, com_task, detection, sequence}")
    _check_keys(raw, ("feet", "com_task", "detection", "sequence"), path)
    contacts = next((c for c in controller.constraints if hasattr(c, "set_contacts")), None)
    if contacts is None:
        raise ConfigError(
            "support phases switch foot contacts, but the controller has no `contacts` "
            "constraint; add `- {type: contacts}` under `constraints:` or remove `support:`.",
            path=path,
        )
    robot = controller.robot
    feet_raw = _mapping(raw.get("feet"), f"{path}.feet", "side -> {contact, task}")
    _check_keys(feet_raw, SIDES, f"{path}.feet")
    feet: dict[str, FootBinding] = {}
    for side in SIDES:
        fpath = f"{path}.feet.{side}"
        entry = feet_raw.get(side)
        if isinstance(entry, str):
            entry = {"contact": entry}
        entry = _mapping(entry, fpath, "{contact, task}")
        _check_keys(entry, ("contact", "task"), fpath)
        contact = entry.get("contact")
        if contact is None:
            guesses = [n for n in contacts.names if side in n.lower()]
            if len(guesses) != 1:
                raise ConfigError(
                    f"cannot tell which contact is the {side} foot among {contacts.names}; "
                    f"give `contact:`.",
                    path=fpath,
                )
            contact = guesses[0]
        if contact not in contacts.names:
            raise ConfigError(
                f"no contact {contact!r}.{close_matches_hint(str(contact), contacts.names)} "
                f"Contacts: {', '.join(contacts.names)}.",
                path=f"{fpath}.contact",
            )
        frame_id = contacts.frame_ids[contacts.names.index(contact)]
        task = entry.get("task")
        if task is None:
            same = [
                n
                for n, t in controller.tasks.items()
                if getattr(t, "frame_id", None) is not None
                and _same_body(robot, t.frame_id, frame_id)
                and getattr(t, "has_position", False)
            ]
            if len(same) != 1:
                raise ConfigError(
                    f"no single frame task on the {side} foot ({contact!r}) to move it while it "
                    f"swings (found {same}); add one, e.g. `- {{type: frame, name: {side}_foot, "
                    f"frame: {robot.model.frames[frame_id].name}, mode: pose}}`, or give `task:`.",
                    path=fpath,
                )
            task = same[0]
        if task not in controller.tasks:
            raise ConfigError(
                f"no controller task named {task!r}."
                f"{close_matches_hint(str(task), list(controller.tasks))}",
                path=f"{fpath}.task",
            )
        t = controller.tasks[task]
        if not getattr(t, "has_position", False) or not _same_body(robot, t.frame_id, frame_id):
            raise ConfigError(
                f"task {task!r} must track the position (ideally the pose) of a frame on the "
                f"{side} foot's body ({robot.model.frames[frame_id].name}).",
                path=f"{fpath}.task",
            )
        feet[side] = FootBinding(contact, task)
    com_task = raw.get("com_task")
    if com_task is None:
        coms = [n for n, t in controller.tasks.items() if type(t).__name__ == "ComTask"]
        if len(coms) != 1:
            raise ConfigError(
                f"support sequences move the CoM: add one `- {{type: com, axes: xy}}` task "
                f"(found {coms}) or name it with `com_task:`.",
                path=path,
            )
        com_task = coms[0]
    if com_task not in controller.tasks or not hasattr(controller.tasks[com_task], "axes"):
        raise ConfigError(
            f"{com_task!r} is not a CoM task of the controller.", path=f"{path}.com_task"
        )
    det = _mapping(raw.get("detection"), f"{path}.detection", "thresholds")
    _check_keys(det, [f.name for f in fields(PhaseThresholds)], f"{path}.detection")
    seq = _mapping(raw.get("sequence"), f"{path}.sequence", "sequence settings")
    _check_keys(seq, [f.name for f in fields(SequencerSettings)], f"{path}.sequence")
    try:
        detection = PhaseThresholds(
            **{k: _number(v, f"{path}.detection.{k}", positive=False) for k, v in det.items()}
        )
    except ValueError as exc:
        raise ConfigError(str(exc), path=f"{path}.detection") from None
    try:
        sequence = SequencerSettings(
            **{k: _number(v, f"{path}.sequence.{k}") for k, v in seq.items()}
        )
    except ValueError as exc:
        raise ConfigError(str(exc), path=f"{path}.sequence") from None
    return SupportSpec(feet=feet, com_task=com_task, detection=detection, sequence=sequence)


def _same_body(robot: Any, frame_a: int, frame_b: int) -> bool:
    """Whether two frames move with the same joint (same rigid body)."""
    frames = robot.model.frames
    return frames[frame_a].parentJoint == frames[frame_b].parentJoint


def default_robot_keypoints(robot: Any) -> dict[str, Any]:
    """Key-point -> robot frame(s) from the robot's registry key-frames.

    ``waist`` comes from the ``pelvis`` key-frame when the robot has no ``waist``; ``neck``,
    when missing, is the mean of the two shoulder frames.
    """
    keyframes = dict(robot.keyframes)
    out: dict[str, Any] = {k: v for k, v in keyframes.items() if k in KEYPOINT_NAMES}
    if "waist" not in out and "pelvis" in keyframes:
        out["waist"] = keyframes["pelvis"]
    if "neck" not in out and "left_shoulder" in out and "right_shoulder" in out:
        out["neck"] = [out["left_shoulder"], out["right_shoulder"]]
    return out


def whole_body_config(
    robot: str = "g1", *, base: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """A whole-body retargeting controller with support sequences for a bundled robot.

    Without ``base`` it is built from the robot's registry entry (an installed package ships no
    configs): pelvis pose, torso orientation, hands, elbows and head (gain 30 /s); joint,
    velocity and acceleration limits, contacts and support polygon. With ``base`` (e.g.
    ``configs/g1_whole_body.yaml``) that config is kept and only what the support sequences of
    Poubel 2014 Table I need is added when missing: a CoM task (x, y), a pose task on each sole,
    and the ``retarget:`` section (its ``support:`` included). In both cases the knees are kept
    0.2 rad from straight (the straight-knee singularity stalls a velocity-level controller
    holding a foot on the ground), and the damping is at least 0.3: with 1e-3 and full-error
    gains the closed loop is ill-conditioned near G1's wrist and knee singularities (without
    acceleration limits the wrists chatter at their velocity limits; with them, a 1e-16 change
    of the inputs grows to 1e-5..0.2 rad within a second, so runs are not reproducible).

    Args:
        robot: Bundled robot with two feet and key-point frames (g1, talos, romeo, icub).
        base: A configuration mapping to extend (its ``robot`` must be ``robot``).

    Returns:
        The configuration mapping (``Controller(config)`` builds it).

    Raises:
        ConfigError: Unknown robot, or a robot without two feet.
    """
    from ..robot import load_robot

    model = load_robot(robot)
    kf = model.keyframes
    sides = {s: [f for f in model.feet if s in f.lower()] for s in SIDES}
    if any(len(v) != 1 for v in sides.values()):
        raise ConfigError(
            f"robot {robot!r} needs one left and one right foot for a whole-body config, has "
            f"{list(model.feet)}."
        )
    limits: dict[str, list[float]] = {}
    for side in SIDES:
        frame = kf.get(f"{side}_knee")
        if frame is None:
            continue
        joint_id = model.model.frames[model.frame_id(frame)].parentJoint
        name = model.model.names[joint_id]
        if name not in model.joint_names:
            continue
        qi = model.model.joints[joint_id].idx_q
        lo, hi, ref = model.q_min[qi], model.q_max[qi], model.q_reference[qi]
        if ref > 0.2 and lo < 0.2 < hi:
            limits[name] = [0.2, float(hi)]
        elif ref < -0.2 and lo < -0.2 < hi:
            limits[name] = [float(lo), -0.2]
    tasks: list[dict[str, Any]] = []
    bindings: dict[str, Any] = {}

    def frame_task(name: str, robot_kp: str, mode: str, weight: float, **extra: Any) -> None:
        if robot_kp not in kf:
            return
        spec = {"type": "frame", "name": name, "frame": kf[robot_kp], "mode": mode, "gain": 30.0}
        if mode in ("position", "pose"):
            spec["position_weight"] = weight
        if mode in ("orientation", "pose"):
            spec["orientation_weight"] = weight
        tasks.append(spec)
        bindings[name] = extra

    frame_task("pelvis", "pelvis", "pose", 100.0, keypoint="waist", orientation="waist")
    frame_task("torso", "torso", "orientation", 100.0, orientation="torso")
    for side in SIDES:
        frame_task(f"{side}_hand", f"{side}_hand", "position", 100.0, keypoint=f"{side}_hand")
    for side in SIDES:
        frame_task(f"{side}_elbow", f"{side}_elbow", "position", 25.0, keypoint=f"{side}_elbow")
    frame_task("head", "head", "position", 25.0, keypoint="head")
    support_tasks: list[dict[str, Any]] = [
        {"type": "com", "name": "com", "axes": "xy", "weight": 1.0e4, "gain": 30.0}
    ]
    feet: dict[str, Any] = {}
    for side in SIDES:
        foot = sides[side][0]
        support_tasks.append(
            {"type": "frame", "name": foot, "frame": model.feet[foot].frame, "mode": "pose",
             "position_weight": 1000.0, "orientation_weight": 1000.0}
        )  # fmt: skip
        feet[side] = {"contact": foot, "task": foot}
    posture = {"type": "posture", "name": "posture", "weight": 1.0e-3}
    if base is None:
        robot_spec: Any = robot if not limits else {"name": robot, "position_limits": limits}
        return {
            "name": f"{robot}_whole_body_demo",
            "description": "whole-body retargeting, generated by retarget.whole_body_config",
            "robot": robot_spec,
            "dt": 0.01,
            "strategy": {"type": "augmentation"},
            "regularization": {"type": "identity", "damping": 0.3},
            "solver": {"name": "daqp"},
            "tasks": tasks + support_tasks + [posture],
            "constraints": [
                {"type": "joint_limits", "gain": 0.95},
                {"type": "velocity_limits"},
                {"type": "acceleration_limits", "a_max": 300.0},
                {"type": "contacts"},
                {"type": "support_polygon", "margin": 0.01},
            ],
            "retarget": {"tasks": dict(bindings), "support": {"feet": feet, "com_task": "com"}},
        }
    # Extend a given config.
    cfg = copy.deepcopy(dict(base))
    spec = cfg.get("robot")
    name = spec if isinstance(spec, str) else (spec or {}).get("name")
    if name != robot:
        raise ConfigError(f"the base config is for robot {spec!r}, not {robot!r}.", path="robot")
    if limits:
        spec = {"name": robot} if isinstance(spec, str) else dict(spec)
        merged = dict(spec.get("position_limits") or {})
        for joint, bounds in limits.items():
            merged.setdefault(joint, bounds)
        spec["position_limits"] = merged
        cfg["robot"] = spec
    reg = dict(cfg.get("regularization") or {"type": "identity"})
    reg["damping"] = max(float(reg.get("damping", 0.0)), 0.3)
    cfg["regularization"] = reg
    cfg_tasks = list(cfg.get("tasks") or [])
    names = {t.get("name") for t in cfg_tasks}
    frames = {t.get("frame") for t in cfg_tasks if t.get("type") == "frame"}
    added = []
    if not any(t.get("type") == "com" for t in cfg_tasks):
        added.append(support_tasks[0])
    com_task = next((t.get("name", "com") for t in cfg_tasks if t.get("type") == "com"), "com")
    for side, spec_t in zip(SIDES, support_tasks[1:], strict=True):
        foot_frame = spec_t["frame"]
        if foot_frame in frames:
            existing = next(t for t in cfg_tasks if t.get("frame") == foot_frame)
            feet[side]["task"] = existing["name"]
        elif spec_t["name"] not in names:
            added.append(spec_t)
    posture_at = next((i for i, t in enumerate(cfg_tasks) if t.get("type") == "posture"), None)
    if posture_at is None:
        cfg_tasks += added + [posture]
    else:
        cfg_tasks[posture_at:posture_at] = added
    cfg["tasks"] = cfg_tasks
    retarget = dict(cfg.get("retarget") or {})
    retarget.setdefault("tasks", {k: v for k, v in bindings.items() if k in names})
    support = dict(retarget.get("support") or {})
    support.setdefault("feet", feet)
    support.setdefault("com_task", com_task)
    retarget["support"] = support
    cfg["retarget"] = retarget
    cfg["name"] = f"{cfg.get('name', robot)}+support"
    return cfg


# ------------------------------------------------------------------------------------ commands
@dataclass(frozen=True)
class Command:
    """One control tick of the retargeter.

    Attributes:
        t: Time of the tick on the motion's clock [s].
        q: Configuration after the tick (nq,).
        v: Velocity applied during the tick (nv,).
        status: ``ok`` / ``relaxed`` / ``held``.
        result: The controller's :class:`~qpretarget.control.controller.StepResult`.
        phase: Support phase detected on the person (``double``/``left``/``right``, or ``""``).
        support: State of the support sequencer (``""`` without support handling).
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    status: str
    result: StepResult
    phase: str = ""
    support: str = ""


# ------------------------------------------------------------------------------------ pipeline
class _Stream:
    """Key-point extraction, Butterworth and cardinal spline for one motion (offline or online)."""

    def __init__(
        self,
        kmap: KeypointMap,
        skeleton: HumanMotion,
        keypoints: list[str],
        orientations: list[str],
        spec: RetargetSpec,
        rate_out: float,
        *,
        causal: bool,
    ) -> None:
        self.kmap = kmap
        self.skeleton = skeleton
        self.keypoints = keypoints
        self.orientations = orientations
        self.rate_in = skeleton.rate
        self.K, self.M = len(keypoints), len(orientations)
        self.causal = causal
        self.filter = (
            None
            if spec.cutoff_hz is None
            else Butterworth(
                _cutoff(spec.cutoff_hz, skeleton.rate), skeleton.rate, spec.filter_order
            )
        )
        self.spline = CardinalSpline(skeleton.rate, rate_out, spec.tension)
        self._index = {name: skeleton.index(name) for name in kmap.source_names()}

    # A sample is [positions (3K), rotations (9M)]; the spline also carries K missing flags.
    def values_of(self, positions: Mapping[str, np.ndarray], rotations: Mapping[str, np.ndarray]):
        parts = [np.asarray(positions[k], float).reshape(-1, 3) for k in self.keypoints]
        parts += [np.asarray(rotations[o], float).reshape(-1, 9) for o in self.orientations]
        return np.concatenate(parts, axis=-1) if parts else np.zeros((1, 0))

    def missing_of(self, values: np.ndarray) -> np.ndarray:
        pos = values[..., : 3 * self.K].reshape(values.shape[:-1] + (self.K, 3))
        return np.any(np.isnan(pos), axis=-1).astype(float)

    def frame_keypoints(self, frame: np.ndarray, rotations: np.ndarray | None):
        def position_of(name: str) -> np.ndarray:
            return frame[self._index[name]]

        def rotation_of(name: str) -> np.ndarray:
            return rotations[self._index[name]]

        pts = self.kmap.evaluate(position_of, rotation_of if rotations is not None else None)
        rots = {o: rotation_of(self.kmap.orientations[o]) for o in self.orientations}
        return pts, rots

    # -------------------------------------------------------------------- offline
    def offline(self, motion: HumanMotion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Control-rate samples of a whole motion: ``(t_out, y, raw key-points)``.

        Zero phase: batch ``filtfilt`` and ``upsample``. Causal: the streaming code of
        :meth:`push`, sample by sample, so that an online run reproduces it bit for bit (the
        batch ``lfilter`` agrees with it only to ~1e-12, which a sensitive controller amplifies).
        """
        if self.causal:
            self.spline.reset()
            if self.filter is not None:
                self.filter = Butterworth(self.filter.cutoff_hz, self.rate_in, self.filter.order)
            outputs: list[tuple[float, np.ndarray]] = []
            raw: dict[str, list[np.ndarray]] = {k: [] for k in self.kmap.keypoints}
            rotations = motion.orientations
            for k in range(len(motion)):
                out, pts = self.push(
                    float(motion.t[k]),
                    motion.positions[k],
                    None if rotations is None else rotations[k],
                )
                outputs += out
                for name, value in pts.items():
                    raw[name].append(np.asarray(value, float))
            outputs += self.flush()
            t_out = np.array([o[0] for o in outputs])
            y = np.array([o[1] for o in outputs])
            return t_out, y, {k: np.array(v) for k, v in raw.items()}
        pts = self.kmap.positions(motion)
        rots = (
            {o: motion.joint_orientation(self.kmap.orientations[o]) for o in self.orientations}
            if self.orientations
            else {}
        )
        x = self.values_of(pts, rots)
        missing = self.missing_of(x)
        if self.filter is not None:
            x = self.filter.filtfilt(x)
        t_out, y = self.spline.upsample(motion.t, np.concatenate([x, missing], axis=-1))
        return t_out, y, _raw(pts)

    # -------------------------------------------------------------------- online
    def push(self, t: float, frame: np.ndarray, rotations: np.ndarray | None):
        pts, rots = self.frame_keypoints(frame, rotations)
        x = self.values_of(pts, rots)[0]
        missing = self.missing_of(x)
        if self.filter is not None:
            x = self.filter.push(x)
        return self.spline.push(t, np.concatenate([x, missing])), pts

    def flush(self):
        return self.spline.flush()

    def unpack(self, y: np.ndarray):
        K, M = self.K, self.M
        pos = y[: 3 * K].reshape(K, 3)
        rot = y[3 * K : 3 * K + 9 * M].reshape(M, 3, 3)
        miss = np.abs(y[3 * K + 9 * M :]) > 1e-9
        return (
            {k: pos[i] for i, k in enumerate(self.keypoints)},
            {o: rot[i] for i, o in enumerate(self.orientations)},
            {k: bool(miss[i]) for i, k in enumerate(self.keypoints)},
        )


def _cutoff(cutoff: float, rate: float) -> float:
    """The cut-off, kept below 45 % of the capture rate (a 7 Hz filter on 10 Hz data would fail)."""
    return min(cutoff, 0.45 * rate)


def _raw(points: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.asarray(v, float) for k, v in points.items()}


# ------------------------------------------------------------------------------------ retargeter
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
        self._stream: _Stream | None = None

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
        robot = ctrl.robot
        entries = default_robot_keypoints(robot)
        entries.update(self.spec.robot_keypoints)
        try:
            self.robot_map = KeypointMap.from_dict(
                {"name": f"{robot.name}_keypoints", "kind": "robot", "keypoints": entries},
                path="retarget.robot_keypoints",
            )
        except KeypointMapError as exc:
            raise ConfigError(str(exc)) from None
        for kp, src in self.robot_map.keypoints.items():
            for frame in src.points:
                robot.frame_id(frame, path=f"retarget.robot_keypoints.{kp}")
        model = robot.model
        data = model.createData()
        q_ref = robot.q_reference
        pin.framesForwardKinematics(model, data, q_ref)

        def placement(name: str) -> pin.SE3:
            return data.oMf[robot.frame_id(name)]

        self.robot_points = self.robot_map.evaluate(
            lambda f: placement(f).translation.copy(), lambda f: placement(f).rotation.copy()
        )
        waist_src = self.robot_map.keypoints.get("waist")
        self.robot_waist_rotation = (
            placement(waist_src.points[0]).rotation.copy() if waist_src is not None else None
        )
        for name, b in self.spec.tasks.items():
            if b.keypoint is not None and b.keypoint not in self.robot_points:
                raise ConfigError(
                    f"key-point {b.keypoint!r} has no robot frame; add it under "
                    f"retarget.robot_keypoints (robot key-points: {sorted(self.robot_points)}).",
                    path=f"retarget.tasks.{name}.keypoint",
                )
        # Task reference poses (reset the controller to its reference posture once).
        ctrl.reset()
        self.task_reference: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, task in ctrl.tasks.items():
            if hasattr(task, "current_pose"):
                p, R = task.current_pose(ctrl.state)
                self.task_reference[name] = (p.copy(), R.copy())
        self.task_offsets: dict[str, np.ndarray] = {}
        for name, b in self.spec.tasks.items():
            if b.keypoint is None:
                continue
            if b.offset is not None:
                self.task_offsets[name] = np.asarray(b.offset, float)
            else:
                self.task_offsets[name] = (
                    self.task_reference[name][0] - self.robot_points[b.keypoint]
                )
        self.com_reference = np.array(pin.centerOfMass(model, data, q_ref))
        self._robot_point_ids = {
            k: [robot.frame_id(f) for f in src.points]
            for k, src in self.robot_map.keypoints.items()
        }
        weights = {k: w for k, w in COM_WEIGHTS.items() if k in self.robot_points}
        total = sum(weights.values())
        self.com_weights = {k: w / total for k, w in weights.items()} if total > 0 else {}
        self._com_w = np.array(list(self.com_weights.values()))
        self._com_ref_xy = sum(
            (w * self.robot_points[k][:2] for k, w in self.com_weights.items()), np.zeros(2)
        )
        psi_r = (
            yaw_of(self.robot_waist_rotation[:, 0])
            if self.robot_waist_rotation is not None
            else 0.0
        )
        self._unheading = _rot_z(-psi_r)
        # Support: soles, ankle -> sole transforms, foot task frames.
        self.support = self.spec.support
        #: The controller's ``contacts`` constraint (its active feet are recorded in the run).
        self.contacts = next((c for c in ctrl.constraints if hasattr(c, "set_contacts")), None)
        self.leg_lengths: dict[str, float] = {
            side: float(
                np.linalg.norm(self.robot_points[f"{side}_knee"] - self.robot_points[f"{side}_hip"])
                + np.linalg.norm(
                    self.robot_points[f"{side}_ankle"] - self.robot_points[f"{side}_knee"]
                )
            )
            for side in SIDES
            if all(f"{side}_{p}" in self.robot_points for p in ("hip", "knee", "ankle"))
        }
        if self.support is not None:
            self.sole_ids: dict[str, int] = {}
            self.sole_ref: dict[str, pin.SE3] = {}
            self.ankle_to_sole: dict[str, np.ndarray] = {}
            self.sole_to_task: dict[str, pin.SE3] = {}
            rects: dict[str, tuple[float, float, float, float]] = {}
            for side, fb in self.support.feet.items():
                i = self.contacts.names.index(fb.contact)
                fid = self.contacts.frame_ids[i]
                self.sole_ids[side] = fid
                M = data.oMf[fid].copy()
                self.sole_ref[side] = M
                ankle = self.robot_points.get(f"{side}_ankle")
                if ankle is None:
                    raise ConfigError(
                        f"support phases need the {side}_ankle key-point on the robot; add it "
                        "under retarget.robot_keypoints.",
                        path="retarget.support",
                    )
                self.ankle_to_sole[side] = M.rotation.T @ (M.translation - ankle)
                p, R = self.task_reference[fb.task]
                self.sole_to_task[side] = M.inverse() * pin.SE3(R, p)
                rect = self.contacts.rectangles[i]
                rects[side] = (-0.02, 0.02, -0.02, 0.02) if rect is None else tuple(rect)
            self.sole_rectangles = rects
            # Landing area defaults from the stance width and the leg length.
            seq = self.support.sequence
            d = self.sole_ref["left"].translation - self.sole_ref["right"].translation
            width = float(abs(self._unheading[1] @ d))
            leg = min(self.leg_lengths.values()) if self.leg_lengths else 1.0
            self.sequence_settings = replace(
                seq,
                min_width=seq.min_width if seq.min_width is not None else 0.8 * width,
                max_width=seq.max_width if seq.max_width is not None else 1.1 * width,
                max_stride=seq.max_stride if seq.max_stride is not None else 0.25 * leg,
            )

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
        self._begin(stream, float(motion.t[0]))
        self._human_raw_t = motion.t.copy()
        self._human_raw = raw
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
        return self.trajectory()

    # -------------------------------------------------------------------- online
    def start(
        self,
        skeleton: HumanMotion | Sequence[str],
        *,
        rate: float | None = None,
        keypoint_map: Any = None,
    ) -> None:
        """Start an online stream (resets the controller).

        Args:
            skeleton: A motion with the stream's joint names (any frames: only its names, rate and
                orientation availability are used), or the list of joint names.
            rate: Capture rate [Hz] (default: the motion's).
            keypoint_map: Overrides the retargeter's key-point map.

        Raises:
            ValueError: No rate for a list of names.
        """
        if not isinstance(skeleton, HumanMotion):
            if rate is None:
                raise ValueError("give the capture rate: start(names, rate=120.0)")
            names = list(skeleton)
            skeleton = HumanMotion(
                t=[0.0], names=names, positions=np.zeros((1, len(names), 3)),
                parents=[-1] * len(names), rate=float(rate), source="stream",
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
        self._human_raw_t.append(float(t))
        for k, v in pts.items():
            self._human_raw[k].append(np.asarray(v, float).copy())
        return [c for to, y in outputs for c in self._tick(float(to), y)]

    def finish(self) -> list[Command]:
        """End the stream: emit the ticks up to the last frame (spline end rule)."""
        stream = self._require_stream()
        return [c for to, y in stream.flush() for c in self._tick(float(to), y)]

    # -------------------------------------------------------------------- internals
    def _require_stream(self) -> _Stream:
        if self._stream is None:
            raise RetargetError("call start(skeleton) before push(frame, t)")
        return self._stream

    @staticmethod
    def _frame_array(
        frame: Any, stream: _Stream, *, what: str, shape: tuple[int, ...] = (3,)
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

    def _make_stream(self, motion: HumanMotion, *, causal: bool) -> _Stream:
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
        return _Stream(kmap, motion, keypoints, orientations, self.spec, self.rate, causal=causal)

    def _begin(self, stream: _Stream, t0: float | None) -> None:
        """Reset the controller and every stateful stage for a new motion."""
        self._stream = stream
        ctrl = self.controller
        ctrl.reset()
        # Technical debt: Controller.reset() does not drop the warm start of the relaxation
        # fallback's solver, so a run after a relaxed tick differed in the last bits from a fresh
        # one (and a sensitive closed loop amplifies that). Reset it here until reset() does.
        fallback_solver = getattr(getattr(ctrl, "fallback", None), "solver", None)
        if hasattr(fallback_solver, "reset"):
            fallback_solver.reset()
        self.calibration: Calibration | None = None
        self.scaler: Scaler | None = None
        self._pending: list[tuple[float, np.ndarray]] = []
        self._calibration_samples: list[tuple[float, np.ndarray]] = []
        self._records: dict[str, list[Any]] = {
            k: []
            for k in ("t", "q", "v", "status", "solve_time", "tau", "contacts", "phase",
                      "support", "messages")
        }  # fmt: skip
        self._pos_tasks = [n for n, t in ctrl.tasks.items() if getattr(t, "has_position", False)]
        self._targets_rec: dict[str, list[np.ndarray]] = {n: [] for n in self._pos_tasks}
        self._actual_rec: dict[str, list[np.ndarray]] = {n: [] for n in self._pos_tasks}
        self._scaled_rec: dict[str, list[np.ndarray]] = {}
        self._skipped = [
            n for n, b in self.spec.tasks.items()
            if b.keypoint is not None and b.keypoint not in stream.keypoints
        ]  # fmt: skip
        # Phases of the person are detected (and recorded) with or without support sequences.
        self.detector = SupportPhaseDetector(
            self.support.detection if self.support is not None else PhaseThresholds()
        )
        self.sequencer = (
            SupportSequencer(self.sole_rectangles, self.sequence_settings, dt=self.dt)
            if self.support is not None
            else None
        )
        if self.support is not None:
            ctrl.set_contacts([fb.contact for fb in self.support.feet.values()])
        self._t_first: float | None = t0
        self._root: str | None = None
        self._blend: tuple[float, np.ndarray] | None = None
        self._targets_ref = {n: (p.copy(), R.copy()) for n, (p, R) in self.task_reference.items()}

    def _calibrate(self, samples: list[tuple[float, np.ndarray]]) -> None:
        stream = self._stream
        unpacked = [stream.unpack(y) for _, y in samples]
        human = {k: np.array([u[0][k] for u in unpacked]) for k in stream.keypoints}
        waist_R = None
        if "waist" in stream.orientations:
            waist_R = np.array([nearest_rotation(u[1]["waist"]) for u in unpacked])
        foot_R = {s: self.sole_ref[s].rotation for s in SIDES} if self.support else None
        self.calibration = calibrate(
            human,
            {k: v for k, v in self.robot_points.items()},
            human_waist_rotation=waist_R,
            robot_waist_rotation=self.robot_waist_rotation,
            robot_foot_rotations=foot_R,
        )
        self.scaler = Scaler(self.calibration, self.spec.scaling)
        # Waist yaw at calibration (feet yaw fallback when the motion has no toes).
        first = unpacked[0]
        self._waist_yaw_cal = self._waist_yaw(first[0], first[1])

    def _waist_yaw(self, kp: Mapping[str, np.ndarray], rots: Mapping[str, np.ndarray]) -> float:
        if "waist" in rots:
            return yaw_of(rots["waist"][:, 0])
        if "left_hip" in kp and "right_hip" in kp:
            y = kp["left_hip"] - kp["right_hip"]
            return yaw_of(np.cross(y, [0.0, 0.0, 1.0]))
        return 0.0

    def _tick(self, t: float, y: np.ndarray) -> list[Command]:
        """Process one control-rate sample (after the first ``calibration.frames``, all held)."""
        if self.calibration is None:
            # Calibrate on the first `calibration.frames` samples where the waist is seen (marker
            # data may start with gaps); the samples before are then run with missing targets.
            self._pending.append((t, y))
            kp, _, missing = self._stream.unpack(y)
            if not missing.get("waist", True) and np.all(np.isfinite(kp["waist"])):
                self._calibration_samples.append((t, y))
            if len(self._calibration_samples) < self.spec.calibration_frames:
                return []
            self._calibrate(self._calibration_samples)
            pending, self._pending = self._pending, []
            return [self._process(tp, yp) for tp, yp in pending]
        return [self._process(t, y)]

    # The per-tick work: scaling, phases, targets, controller step, record.
    def _process(self, t: float, y: np.ndarray) -> Command:
        ctrl, cal, stream = self.controller, self.calibration, self._stream
        assert cal is not None and self.scaler is not None
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

        # 2. Scaling rooted at the robot's supporting feet (Poubel 2014 III.A), blended at
        #    root switches, legs kept off the straight-knee singularity.
        scaled, anchors = self._scale(t, human)

        # 3. Support sequences (Poubel 2014 Table I); the upper body is shifted horizontally so
        #    that its estimated CoM is where the sequence puts the robot's CoM.
        support_state = ""
        cmd = None
        if self.sequencer is not None:
            soles = {s: state.frame_placement(self.sole_ids[s]).copy() for s in SIDES}
            com = state.com()
            if not self.sequencer.log:
                self.sequencer.reset(t, soles, com[:2])
            swing = {s: self._swing_sole(s, scaled, kp, rots, soles[s]) for s in SIDES}
            predicted = self._predicted_com(scaled, com)
            cmd = self.sequencer.update(t, phase, soles, com[:2], swing, predicted)
            support_state = cmd.state
            if cmd.switched:
                ctrl.set_contacts([self.support.feet[s].contact for s in cmd.contacts])
            natural = self._natural_com(scaled)
            if natural is not None and predicted is not None:
                w = cmd.free_weight
                reference = w * predicted + (1.0 - w) * natural
                shift = np.array([cmd.com[0] - reference[0], cmd.com[1] - reference[1], 0.0])
                scaled = {k: (v if k in FOOT_POINTS else v + shift) for k, v in scaled.items()}

        # 4. Task targets (ramped in from the reference posture over ramp_time).
        self._task_targets(t, targets, scaled, kp, rots, missing)
        if cmd is not None:
            com_task = ctrl.tasks[self.support.com_task]
            full = np.array(com_task.target, float)
            ramp = self._ramp(t)
            full[:2] = self.com_reference[:2] + ramp * (cmd.com - self.com_reference[:2])
            targets[self.support.com_task] = full
            for side, sole in cmd.feet.items():
                task_name = self.support.feet[side].task
                M = sole * self.sole_to_task[side]
                if ctrl.tasks[task_name].has_orientation:
                    targets[task_name] = M.homogeneous
                else:
                    targets[task_name] = M.translation.copy()

        # 5. One control tick.
        res = ctrl.step(targets, dt=self.dt)
        self._record(t, res, phase, support_state, scaled)
        return Command(t, res.q, res.v, res.status, res, phase, support_state)

    def _scale(
        self, t: float, human: Mapping[str, np.ndarray]
    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Scaled key-points and the supporting ankles they are rooted at."""
        cal, state = self.calibration, self.controller.state
        if self.sequencer is not None:
            on = self.sequencer.contacts
            root = "double" if len(on) == 2 else on[0]
            anchors = {
                s: state.frame_placement(self.sole_ids[s]).act(-self.ankle_to_sole[s]) for s in on
            }
        else:
            root = "double"
            anchors = {s: cal.robot_points[f"{s}_ankle"] for s in SIDES
                       if f"{s}_ankle" in cal.robot_points}  # fmt: skip
        scaled = self.scaler.scale(human, support=root, anchors=anchors)
        if self._root is not None and root != self._root and self.spec.blend_time > 0:
            old = self.scaler.scale(human, support=self._root, anchors=self._last_anchors)
            delta = old["waist"] - scaled["waist"]
            previous = self._blend_offset(t)
            if previous is not None:
                delta = delta + previous
            self._blend = (t, delta)
        self._root = root
        self._last_anchors = anchors
        offset = self._blend_offset(t)
        if offset is None:
            self._blend = None
        else:
            scaled = {k: (v if k in anchors_points(anchors) else v + offset)
                      for k, v in scaled.items()}  # fmt: skip
        if self.leg_lengths and anchors and self.scaler.method == "poubel":
            scaled, _ = limit_leg_extension(
                scaled, anchors, self.leg_lengths, self.spec.leg_extension
            )
        return scaled, anchors

    def _ramp(self, t: float) -> float:
        """Start ramp weight: minimum-jerk from 0 to 1 over ``calibration.ramp_time``."""
        if self.spec.ramp_time <= 0:
            return 1.0
        s = (t - self._t_first) / self.spec.ramp_time
        return 1.0 if s >= 1 else s * s * s * (10.0 + s * (-15.0 + 6.0 * s))

    def _predicted_com(
        self, scaled: Mapping[str, np.ndarray], com: np.ndarray
    ) -> np.ndarray | None:
        r"""Horizontal CoM of the robot once its key-points reach the scaled ones, to first order.

        :math:`c + \sum_k w_k (s_k - x_k(q))` with :math:`x_k(q)` the robot's key-points now
        (:data:`COM_WEIGHTS`); equal to the current CoM when the targets are reached, so in double
        support the CoM target never pulls against the other tasks.
        """
        S = self._weighted_xy(scaled)
        if S is None:
            return None
        data = self.controller.state.data
        X = sum(w * self._robot_point(k, data)[:2] for k, w in self.com_weights.items())
        return np.asarray(com, float)[:2] + S - X

    def _weighted_xy(self, points: Mapping[str, np.ndarray]) -> np.ndarray | None:
        r""":math:`\sum_k w_k p_{k,xy}` over :data:`COM_WEIGHTS` (``None`` if one is missing)."""
        if not self.com_weights:
            return None
        try:
            P = np.array([points[k][:2] for k in self.com_weights])
        except KeyError:
            return None
        if not np.all(np.isfinite(P)):
            return None
        return self._com_w @ P

    def _robot_point(self, name: str, data: pin.Data) -> np.ndarray:
        src = self.robot_map.keypoints[name]
        ids = self._robot_point_ids[name]
        p = data.oMf[ids[0]].translation.copy()
        for i in ids[1:]:
            p += data.oMf[i].translation
        p /= len(ids)
        if src.offset is not None:
            p = p + data.oMf[ids[0]].rotation @ np.asarray(src.offset)
        return p

    def _natural_com(self, scaled: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """Horizontal CoM the scaled person would give the robot.

        The robot's reference CoM moved by the weighted key-point displacements from the
        reference posture (:data:`COM_WEIGHTS`).
        """
        S = self._weighted_xy(scaled)
        if S is None:
            return None
        return self.com_reference[:2] + S - self._com_ref_xy

    def _task_targets(
        self,
        t: float,
        targets: dict[str, Any],
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        rots: Mapping[str, np.ndarray],
        missing: Mapping[str, bool],
    ) -> None:
        cal = self.calibration
        orient: dict[str, np.ndarray] = {}
        for name in {b.orientation for b in self.spec.tasks.values() if b.orientation}:
            R = self._human_orientation(name, kp, rots)
            if R is not None:
                orient[name] = R
        ramp = self._ramp(t)
        parents = cal.tree
        for name, b in self.spec.tasks.items():
            if name in self._skipped:
                continue
            p_ref, R_ref = self._targets_ref[name]
            R_t = None
            if b.orientation is not None:
                Rh = orient.get(b.orientation)
                if Rh is None:
                    R_t = np.full((3, 3), np.nan)
                else:
                    R_t = cal.rotation @ Rh @ self._unheading @ R_ref
                    if ramp < 1.0:
                        R_t = R_ref @ pin.exp3(ramp * pin.log3(R_ref.T @ R_t))
            p_t = None
            if b.keypoint is not None:
                k = b.keypoint
                gone = missing.get(k, True) or (
                    parents.get(k) is not None and missing.get(parents[k], False)
                )
                if gone or k not in scaled:
                    p_t = np.full(3, np.nan)
                else:
                    off = self.task_offsets[name]
                    if R_t is not None and np.all(np.isfinite(R_t)):
                        off = R_t @ R_ref.T @ off
                    p_t = scaled[k] + off
                    if ramp < 1.0:
                        p_t = p_ref + ramp * (p_t - p_ref)
            # A pose task whose orientation (or position) is missing keeps tracking the other
            # half; a missing half keeps its last target.
            p_ok = p_t is not None and bool(np.all(np.isfinite(p_t)))
            R_ok = R_t is not None and bool(np.all(np.isfinite(R_t)))
            if p_ok and R_ok:
                targets[name] = _pose_matrix(R_t, p_t)
            elif p_ok or (p_t is not None and not R_ok):
                targets[name] = p_t
            else:
                targets[name] = R_t

    def _blend_offset(self, t: float) -> np.ndarray | None:
        if self._blend is None:
            return None
        t0, delta = self._blend
        s = (t - t0) / self.spec.blend_time
        if s >= 1.0:
            return None
        w = 1.0 - s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
        return w * delta

    def _human_orientation(
        self, name: str, kp: Mapping[str, np.ndarray], rots: Mapping[str, np.ndarray]
    ) -> np.ndarray | None:
        if name in rots:
            R = rots[name]
            return nearest_rotation(R) if np.all(np.isfinite(R)) else None
        pts = ORIENTATIONS.get(name)
        if pts is None and name == "head":
            return self._human_orientation("torso", kp, rots)
        if pts is None or not all(p in kp for p in pts):
            return None
        R = triad(kp[pts[0]], kp[pts[1]], kp[pts[2]], kp[pts[3]])
        return R if np.all(np.isfinite(R)) else None

    def _swing_sole(
        self,
        side: str,
        scaled: Mapping[str, np.ndarray],
        kp: Mapping[str, np.ndarray],
        rots: Mapping[str, np.ndarray],
        current: pin.SE3,
    ) -> pin.SE3:
        """Desired sole pose of a foot from the scaled ankle, flat, yaw from the human foot."""
        cal = self.calibration
        ankle = scaled.get(f"{side}_ankle")
        if ankle is None or not np.all(np.isfinite(ankle)):
            return current.copy()
        toe = kp.get(f"{side}_toe")
        a = kp.get(f"{side}_ankle")
        if toe is not None and a is not None and side in cal.human_foot_yaw:
            dpsi = yaw_of(toe - a) - cal.human_foot_yaw[side]
        else:
            dpsi = self._waist_yaw(kp, rots) - self._waist_yaw_cal
        R = _rot_z(dpsi) @ self.sole_ref[side].rotation
        return pin.SE3(R, ankle + R @ self.ankle_to_sole[side])

    def _record(
        self, t: float, res: StepResult, phase: str, support: str, scaled: Mapping[str, np.ndarray]
    ) -> None:
        r = self._records
        ctrl = self.controller
        r["t"].append(t)
        r["q"].append(np.array(res.q))
        r["v"].append(np.array(res.v))
        r["status"].append(res.status)
        r["solve_time"].append(res.solve_time)
        r["tau"].append(None if res.tau is None else np.array(res.tau))
        r["phase"].append(phase)
        r["support"].append(support)
        if res.messages:
            r["messages"].extend(res.messages)
        if self.contacts is not None:
            active = set(self.contacts.active_feet)
            r["contacts"].append([n in active for n in self.contacts.names])
        for n in self._pos_tasks:
            task = ctrl.tasks[n]
            self._targets_rec[n].append(np.array(task.position_target, float))
            self._actual_rec[n].append(task.current_pose(ctrl.state)[0].copy())
        for k, v in scaled.items():
            self._scaled_rec.setdefault(k, []).append(np.asarray(v, float).copy())

    # -------------------------------------------------------------------- output
    def trajectory(self) -> RobotTrajectory:
        """The run so far as a :class:`~qpretarget.trajectory.RobotTrajectory`.

        Raises:
            RetargetError: Nothing was retargeted yet.
        """
        r = self._records if self._stream is not None else None
        if not r or not r["t"]:
            raise RetargetError("no control tick yet: retarget a motion or push frames first")
        ctrl = self.controller
        T = len(r["t"])
        taus = r["tau"]
        tau = np.array(taus) if all(x is not None for x in taus) else None
        human = {k: np.asarray(v, float) for k, v in self._human_raw.items()}
        human["t"] = np.asarray(self._human_raw_t, float)
        extra = {
            "human_phase": np.asarray(r["phase"], dtype=str),
            "support_state": np.asarray(r["support"], dtype=str),
        }
        for k, v in self._scaled_rec.items():
            extra[f"scaled/{k}"] = np.asarray(v, float)
        stream = self._stream
        cal = self.calibration
        motion = stream.skeleton
        meta = {
            "source": motion.source,
            "capture_rate": motion.rate,
            "control_rate": self.rate,
            "keypoint_map": stream.kmap.name,
            "scaling": self.spec.scaling,
            "filter": {
                "cutoff_hz": None if stream.filter is None else stream.filter.cutoff_hz,
                "order": self.spec.filter_order,
                "zero_phase": not stream.causal,
            },
            "tension": self.spec.tension,
            "tasks": {n: [b.keypoint, b.orientation] for n, b in self.spec.tasks.items()},
            "skipped_tasks": list(self._skipped),
            "calibration": None if cal is None else cal.to_dict(),
            "human_alignment": None
            if cal is None
            else {
                "rotation": cal.rotation.round(12).tolist(),
                "human_origin": [
                    float(cal.human_waist[0]),
                    float(cal.human_waist[1]),
                    float(cal.human_ankle_height),
                ],
                "robot_origin": [
                    float(cal.robot_waist[0]),
                    float(cal.robot_waist[1]),
                    float(cal.robot_ankle_height),
                ],
            },  # fmt: skip
            "config_name": ctrl.config.get("name", ""),
            "root_nq": ctrl.robot.root_nq,
            "messages": r["messages"][:50],
            "support_log": [] if self.sequencer is None else self.sequencer.log,
        }
        return RobotTrajectory(
            t=np.asarray(r["t"], float),
            q=np.asarray(r["q"], float),
            v=np.asarray(r["v"], float),
            joint_names=list(ctrl.robot.joint_names),
            robot=ctrl.robot.name,
            config_yaml=ctrl.config_yaml,
            task_names=list(self._pos_tasks),
            targets={n: np.asarray(v, float) for n, v in self._targets_rec.items()},
            actual={n: np.asarray(v, float) for n, v in self._actual_rec.items()},
            contacts=np.asarray(r["contacts"], bool).reshape(T, -1)
            if self.contacts is not None
            else None,
            foot_names=list(self.contacts.names) if self.contacts is not None else [],
            status=np.asarray(r["status"], dtype=str),
            solve_time=np.asarray(r["solve_time"], float),
            tau=tau,
            human=human,
            extra=extra,
            meta=meta,
        )


def anchors_points(anchors: Mapping[str, np.ndarray]) -> frozenset[str]:
    """Foot key-points of the supporting sides (not moved by blending)."""
    return frozenset(f"{s}_{p}" for s in anchors for p in ("ankle", "toe", "heel"))


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose_matrix(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = p
    return M


# ------------------------------------------------------------------------------------ summary
def iter_frames(motion: HumanMotion) -> Iterable[tuple[float, np.ndarray, np.ndarray | None]]:
    """``(t, positions (J, 3), orientations (J, 3, 3) or None)`` of every frame (for ``push``)."""
    for k in range(len(motion)):
        yield (
            float(motion.t[k]),
            motion.positions[k],
            None if motion.orientations is None else motion.orientations[k],
        )


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
