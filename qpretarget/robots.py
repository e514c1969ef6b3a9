# SPDX-License-Identifier: Apache-2.0
"""Registry of the bundled humanoids, resolved from the ``example-robot-data`` package.

Each entry is a frozen :class:`RobotDescription`: where its URDF/SRDF live inside the package's
share directory, its reference standing posture, its feet (sole frames and sole rectangles) and the
robot frames that play the role of the human key-points. Nothing here holds a machine path: the
share directory is found from the installed package (``<site-packages>/cmeel.prefix/share``).
"""

from __future__ import annotations

import sysconfig
from dataclasses import dataclass, field
from pathlib import Path

from .errors import UnknownNameError


@dataclass(frozen=True, slots=True)
class FootDescription:
    """A foot of a robot: its sole frame and sole rectangle.

    Attributes:
        frame: sole frame name. If ``parent`` is set, the frame is added to the model as an
            operational frame of ``parent`` at ``offset``.
        parent: existing frame the sole frame is attached to (``None``: ``frame`` exists).
        offset: position of the sole frame in ``parent`` [m].
        rectangle: ``(x_min, x_max, y_min, y_max)`` of the sole in the sole frame [m].
    """

    frame: str
    parent: str | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rectangle: tuple[float, float, float, float] = (-0.05, 0.1, -0.03, 0.03)


@dataclass(frozen=True, slots=True)
class RobotDescription:
    """A bundled humanoid.

    Attributes:
        name: registry name (``g1``, ``talos``...).
        urdf: URDF path relative to ``example-robot-data/robots``.
        srdf: SRDF path relative to the same directory, or ``None``.
        reference: name of the SRDF reference configuration used as standing posture, or
            ``None`` to use ``reference_joints``.
        reference_joints: joint values [rad] of the standing posture (joints not named are 0);
            applied on top of the SRDF reference when both are given.
        feet: ``{"left_foot": FootDescription, "right_foot": ...}``.
        keyframes: robot frames for the human key-points (``left_hand`` -> frame name).
        velocity_limit_override: per-joint velocity limits [rad/s] replacing URDF values.
        description: one line for ``qpretarget info`` and the README table.
    """

    name: str
    urdf: str
    srdf: str | None
    reference: str | None
    feet: dict[str, FootDescription]
    keyframes: dict[str, str]
    reference_joints: dict[str, float] = field(default_factory=dict)
    velocity_limit_override: dict[str, float] = field(default_factory=dict)
    description: str = ""


def share_directory() -> Path:
    """Return the ``example-robot-data`` share directory of the installed package.

    Raises:
        FileNotFoundError: if the ``example-robot-data`` package is not installed.
    """
    candidates = []
    for key in ("purelib", "platlib"):
        candidates.append(Path(sysconfig.get_paths()[key]) / "cmeel.prefix" / "share")
    try:  # site-packages of the interpreter that imported us (virtualenvs, user installs)
        import site

        for p in [*site.getsitepackages(), site.getusersitepackages()]:
            candidates.append(Path(p) / "cmeel.prefix" / "share")
    except Exception:  # pragma: no cover - site may be stripped in embedded interpreters
        pass
    for c in candidates:
        if (c / "example-robot-data" / "robots").is_dir():
            return c
    raise FileNotFoundError(
        "the example-robot-data package is not installed (looked for cmeel.prefix/share/"
        "example-robot-data in site-packages). Install it with `pip install example-robot-data`."
    )


def robots_directory() -> Path:
    """Return ``<share>/example-robot-data/robots``."""
    return share_directory() / "example-robot-data" / "robots"


_G1_STAND = {
    "left_hip_pitch_joint": -0.25,
    "left_knee_joint": 0.5,
    "left_ankle_pitch_joint": -0.25,
    "right_hip_pitch_joint": -0.25,
    "right_knee_joint": 0.5,
    "right_ankle_pitch_joint": -0.25,
    "left_shoulder_pitch_joint": 0.2,
    "left_shoulder_roll_joint": 0.25,
    "left_elbow_joint": 0.9,
    "right_shoulder_pitch_joint": 0.2,
    "right_shoulder_roll_joint": -0.25,
    "right_elbow_joint": 0.9,
}


def _feet(
    left: str, right: str, rectangle: tuple[float, float, float, float]
) -> dict[str, FootDescription]:
    """Both feet of a robot whose sole frames exist in its URDF, with one sole rectangle."""
    return {
        "left_foot": FootDescription(left, rectangle=rectangle),
        "right_foot": FootDescription(right, rectangle=rectangle),
    }


def _keyframes(pelvis: str, torso: str, head: str, **sides: tuple[str, str]) -> dict[str, str]:
    """Key-point frames: the trunk, then ``left_<part>`` and ``right_<part>`` of each ``part``."""
    frames = {"pelvis": pelvis, "torso": torso, "head": head}
    for part, (left, right) in sides.items():
        frames[f"left_{part}"] = left
        frames[f"right_{part}"] = right
    return frames


ROBOTS: dict[str, RobotDescription] = {
    "g1": RobotDescription(
        name="g1",
        urdf="g1_description/urdf/g1_29dof_rev_1_0.urdf",
        srdf=None,
        reference=None,
        reference_joints=_G1_STAND,
        feet={
            # The URDF's contact spheres sit 3 cm below the ankle roll link with radius 5 mm.
            f"{side}_foot": FootDescription(
                f"{side}_sole",
                f"{side}_ankle_roll_link",
                (0.0, 0.0, -0.035),
                (-0.05, 0.12, -0.03, 0.03),
            )
            for side in ("left", "right")
        },
        keyframes=_keyframes(
            "pelvis",
            "torso_link",
            "mid360_link",
            shoulder=("left_shoulder_roll_link", "right_shoulder_roll_link"),
            elbow=("left_elbow_link", "right_elbow_link"),
            wrist=("left_wrist_yaw_link", "right_wrist_yaw_link"),
            hand=("left_rubber_hand", "right_rubber_hand"),
            hip=("left_hip_roll_link", "right_hip_roll_link"),
            knee=("left_knee_link", "right_knee_link"),
            ankle=("left_ankle_roll_link", "right_ankle_roll_link"),
        ),
        description="Unitree G1, 29 actuated DoF (g1_29dof_rev_1_0.urdf)",
    ),
    "icub": RobotDescription(
        name="icub",
        urdf="icub_description/robots/icub_reduced.urdf",
        srdf="icub_description/srdf/icub.srdf",
        reference="half_sitting",
        feet=_feet("l_sole", "r_sole", (-0.04, 0.10, -0.035, 0.035)),
        keyframes=_keyframes(
            "root_link",
            "chest",
            "head",
            shoulder=("l_shoulder_2", "r_shoulder_2"),
            elbow=("l_elbow_1", "r_elbow_1"),
            wrist=("l_hand", "r_hand"),
            hand=("l_gripper", "r_gripper"),
            knee=("l_lower_leg", "r_lower_leg"),
            ankle=("l_foot", "r_foot"),
        ),
        description="iCub, reduced model (icub_reduced.urdf), SRDF half_sitting",
    ),
    "romeo": RobotDescription(
        name="romeo",
        urdf="romeo_description/urdf/romeo_small.urdf",
        srdf="romeo_description/srdf/romeo_small.srdf",
        reference="half_sitting",
        feet=_feet("l_sole", "r_sole", (-0.077, 0.14, -0.069, 0.069)),
        keyframes=_keyframes(
            "body",
            "torso",
            "HeadRollLink",
            shoulder=("LShoulderYawLink", "RShoulderYawLink"),
            elbow=("LElbowRollLink", "RElbowRollLink"),
            wrist=("l_wrist", "r_wrist"),
            hand=("l_gripper", "r_gripper"),
            knee=("LKneePitchLink", "RKneePitchLink"),
            ankle=("l_ankle", "r_ankle"),
        ),
        description="Aldebaran Romeo (romeo_small.urdf), SRDF half_sitting",
    ),
    "simple_humanoid": RobotDescription(
        name="simple_humanoid",
        urdf="simple_humanoid_description/urdf/simple_humanoid.urdf",
        srdf="simple_humanoid_description/srdf/simple_humanoid.srdf",
        # The SRDF's half_sitting puts four leg joints outside this URDF's limits: stand straight.
        reference=None,
        feet=_feet("l_ankle", "r_ankle", (-0.08, 0.12, -0.05, 0.05)),
        keyframes=_keyframes(
            "BODY",
            "torso",
            "torso",
            shoulder=("LARM_LINK2", "RARM_LINK2"),
            elbow=("LARM_LINK4", "RARM_LINK4"),
            wrist=("l_wrist", "r_wrist"),
            hand=("l_wrist", "r_wrist"),
            knee=("LLEG_LINK4", "RLEG_LINK4"),
            ankle=("l_ankle", "r_ankle"),
        ),
        description="simple_humanoid (HRP-2-like test model), straight standing posture",
    ),
    "talos": RobotDescription(
        name="talos",
        urdf="talos_data/robots/talos_reduced.urdf",
        srdf="talos_data/srdf/talos.srdf",
        reference="half_sitting",
        feet=_feet("left_sole_link", "right_sole_link", (-0.11, 0.10, -0.069, 0.069)),
        keyframes=_keyframes(
            "base_link",
            "torso_2_link",
            "head_2_link",
            shoulder=("arm_left_2_link", "arm_right_2_link"),
            elbow=("arm_left_4_link", "arm_right_4_link"),
            wrist=("arm_left_7_link", "arm_right_7_link"),
            hand=("gripper_left_base_link", "gripper_right_base_link"),
            knee=("leg_left_4_link", "leg_right_4_link"),
            ankle=("leg_left_6_link", "leg_right_6_link"),
        ),
        description="PAL Talos (talos_reduced.urdf), SRDF half_sitting",
    ),
}


def get_description(name: str, *, path: str = "robot") -> RobotDescription:
    """Return the registry entry ``name``.

    Raises:
        UnknownNameError: with the close names and the list of bundled robots.
    """
    try:
        return ROBOTS[name]
    except KeyError:
        raise UnknownNameError(
            "robot",
            name,
            sorted(ROBOTS),
            path=path,
            fix=f"Bundled robots: {', '.join(sorted(ROBOTS))}; or give `robot: {{urdf: PATH}}`.",
        ) from None
