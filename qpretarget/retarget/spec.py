# SPDX-License-Identifier: Apache-2.0
r"""The ``retarget:`` section of a controller YAML, validated (:class:`RetargetSpec`).

The keys and their defaults are documented in ``docs/retargeting.md`` (section 1); every error
names its YAML path and the closest valid names.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..constraints.contacts import Contacts
from ..control.controller import Controller
from ..errors import ConfigError, QPRetargetError, close_matches_hint
from ..motion.keypoints import KEYPOINT_NAMES, KeypointMapError, load_keypoint_map
from ..motion.phases import SIDES, PhaseThresholds, SequencerSettings
from ..motion.scaling import SCALING_METHODS
from ..tasks.com import ComTask
from ..tasks.frame import FrameTask
from ..validation import check_keys
from .stepping import BOOL_SETTINGS, StepSettings

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


class RetargetError(QPRetargetError, ValueError):
    """The motion cannot be retargeted with this controller (too short, nothing to track...)."""


# ------------------------------------------------------------------------------------ spec
def _mapping(value: Any, path: str, what: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"expected a mapping ({what}), got {value!r}.", path=path)
    return dict(value)


def _check_known(
    name: Any, known: Sequence[str], what: str, listing: str | None, path: str
) -> None:
    """Raise ``"<what> <name>." + close names (+ "<listing>: <known>.")`` if ``name`` is unknown."""
    if name not in known:
        names = f" {listing}: {', '.join(known)}." if listing else ""
        raise ConfigError(
            f"{what} {name!r}.{close_matches_hint(str(name), list(known))}{names}", path=path
        )


def _the_one(candidates: list[str], message: str, path: str) -> str:
    """The only candidate; a ConfigError ``message`` when there are none or several."""
    if len(candidates) != 1:
        raise ConfigError(message, path=path)
    return candidates[0]


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


#: Balance modes of ``retarget.support.mode`` (docs/retargeting.md, "Balance modes").
SUPPORT_MODES = ("kinematic", "static")


@dataclass(frozen=True)
class SupportSpec:
    """The ``retarget.support`` section.

    Attributes:
        feet: side -> contact and foot task.
        com_task: The CoM task (``static`` mode; ``None`` in ``kinematic`` mode without one).
        detection: Support-phase thresholds on the person.
        sequence: Poubel 2014 Table I sequence settings (``static`` mode).
        mode: ``kinematic`` (contacts follow the person's feet, the base follows the person's
            root) or ``static`` (Poubel 2014 Table I: CoM over the support foot first).
        stepping: Kinematic stepping settings.
    """

    feet: dict[str, FootBinding]
    com_task: str | None
    detection: PhaseThresholds
    sequence: SequencerSettings
    mode: str = "kinematic"
    stepping: StepSettings = field(default_factory=StepSettings)


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
        check_keys(spec, RETARGET_KEYS, path)
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
            _check_known(name, list(controller.tasks), "no controller task named", "Tasks", tpath)
            if isinstance(entry, str):
                entry = {"keypoint": entry}
            entry = _mapping(entry, tpath, "{keypoint, orientation, offset}")
            check_keys(entry, ("keypoint", "orientation", "offset"), tpath)
            task = controller.tasks[name]
            keypoint = entry.get("keypoint")
            orientation = entry.get("orientation")
            if keypoint is not None:
                if not isinstance(keypoint, str) or not keypoint:
                    raise ConfigError(
                        f"keypoint must be a key-point name, got {keypoint!r}.",
                        path=f"{tpath}.keypoint",
                    )
                _check_known(
                    keypoint, KEYPOINT_NAMES, "unknown key-point", "Key-points", f"{tpath}.keypoint"
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
        check_keys(scaling, ("type", "blend_time", "leg_extension"), f"{path}.scaling")
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
            check_keys(filt, ("cutoff_hz", "order", "zero_phase"), f"{path}.filter")
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
        check_keys(up, ("tension",), f"{path}.upsample")
        if "tension" in up:
            kwargs["tension"] = _number(up["tension"], f"{path}.upsample.tension", positive=False)
        cal = _mapping(spec.get("calibration"), f"{path}.calibration", "{frames, ramp_time}")
        check_keys(cal, ("frames", "ramp_time"), f"{path}.calibration")
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
    raw = {} if raw is True else _mapping(raw, path, "{mode, feet, com_task, detection, ...}")
    check_keys(raw, ("mode", "feet", "com_task", "detection", "sequence", "stepping"), path)
    mode = raw.get("mode", "kinematic")
    if mode not in SUPPORT_MODES:
        raise ConfigError(
            f"unknown balance mode {mode!r}; one of {', '.join(SUPPORT_MODES)} "
            "(docs/retargeting.md, 'Balance modes').",
            path=f"{path}.mode",
        )
    contacts = next((c for c in controller.constraints if isinstance(c, Contacts)), None)
    if contacts is None:
        raise ConfigError(
            "support phases switch foot contacts, but the controller has no `contacts` "
            "constraint; add `- {type: contacts}` under `constraints:` or remove `support:`.",
            path=path,
        )
    robot = controller.robot
    feet_raw = _mapping(raw.get("feet"), f"{path}.feet", "side -> {contact, task}")
    check_keys(feet_raw, SIDES, f"{path}.feet")
    feet: dict[str, FootBinding] = {}
    for side in SIDES:
        fpath = f"{path}.feet.{side}"
        entry = feet_raw.get(side)
        if isinstance(entry, str):
            entry = {"contact": entry}
        entry = _mapping(entry, fpath, "{contact, task}")
        check_keys(entry, ("contact", "task"), fpath)
        contact = entry.get("contact")
        if contact is None:
            contact = _the_one(
                [n for n in contacts.names if side in n.lower()],
                f"cannot tell which contact is the {side} foot among {contacts.names}; "
                f"give `contact:`.",
                fpath,
            )
        _check_known(contact, contacts.names, "no contact", "Contacts", f"{fpath}.contact")
        frame_id = contacts.frame_ids[contacts.names.index(contact)]
        task = entry.get("task")
        if task is None:
            same = [
                n
                for n, t in controller.tasks.items()
                if isinstance(t, FrameTask)
                and _same_body(robot, t.frame_id, frame_id)
                and t.has_position
            ]
            task = _the_one(
                same,
                f"no single frame task on the {side} foot ({contact!r}) to move it while it "
                f"swings (found {same}); add one, e.g. `- {{type: frame, name: {side}_foot, "
                f"frame: {robot.model.frames[frame_id].name}, mode: pose}}`, or give `task:`.",
                fpath,
            )
        _check_known(
            task, list(controller.tasks), "no controller task named", None, f"{fpath}.task"
        )
        t = controller.tasks[task]
        if (
            not isinstance(t, FrameTask)
            or not t.has_position
            or not _same_body(robot, t.frame_id, frame_id)
        ):
            raise ConfigError(
                f"task {task!r} must track the position (ideally the pose) of a frame on the "
                f"{side} foot's body ({robot.model.frames[frame_id].name}).",
                path=f"{fpath}.task",
            )
        feet[side] = FootBinding(contact, task)
    com_task = raw.get("com_task")
    if com_task is None:
        coms: list[str | None] = [n for n, t in controller.tasks.items() if isinstance(t, ComTask)]
        if len(coms) != 1 and mode == "kinematic":
            coms = [None]
        elif len(coms) != 1:
            raise ConfigError(
                f"support sequences move the CoM: add one `- {{type: com, axes: xy}}` task "
                f"(found {coms}) or name it with `com_task:`.",
                path=path,
            )
        com_task = coms[0]
    if com_task is not None and not isinstance(controller.tasks.get(com_task), ComTask):
        raise ConfigError(
            f"{com_task!r} is not a CoM task of the controller.", path=f"{path}.com_task"
        )
    det = _mapping(raw.get("detection"), f"{path}.detection", "thresholds")
    check_keys(det, [f.name for f in fields(PhaseThresholds)], f"{path}.detection")
    seq = _mapping(raw.get("sequence"), f"{path}.sequence", "sequence settings")
    check_keys(seq, [f.name for f in fields(SequencerSettings)], f"{path}.sequence")
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
    step = _mapping(raw.get("stepping"), f"{path}.stepping", "stepping settings")
    check_keys(step, [f.name for f in fields(StepSettings)], f"{path}.stepping")
    try:
        step_args: dict[str, Any] = {
            k: v if k in BOOL_SETTINGS else _number(v, f"{path}.stepping.{k}")
            for k, v in step.items()
        }
        stepping = StepSettings(**step_args)
    except ValueError as exc:
        raise ConfigError(str(exc), path=f"{path}.stepping") from None
    return SupportSpec(
        feet=feet, com_task=com_task, detection=detection, sequence=sequence, mode=mode,
        stepping=stepping,
    )  # fmt: skip


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
