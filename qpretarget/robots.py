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

ROBOTS: dict[str, RobotDescription] = {
    "g1": RobotDescription(
        name="g1",
        urdf="g1_description/urdf/g1_29dof_rev_1_0.urdf",
        srdf=None,
        reference=None,
        reference_joints=_G1_STAND,
        feet={
            # The URDF's contact spheres sit 3 cm below the ankle roll link with radius 5 mm.
            "left_foot": FootDescription(
                "left_sole", "left_ankle_roll_link", (0.0, 0.0, -0.035), (-0.05, 0.12, -0.03, 0.03)
            ),
            "right_foot": FootDescription(
                "right_sole",
                "right_ankle_roll_link",
                (0.0, 0.0, -0.035),
                (-0.05, 0.12, -0.03, 0.03),
            ),
        },
        keyframes={
            "pelvis": "pelvis",
            "torso": "torso_link",
            "head": "mid360_link",
            "left_shoulder": "left_shoulder_roll_link",
            "right_shoulder": "right_shoulder_roll_link",
            "left_elbow": "left_elbow_link",
            "right_elbow": "right_elbow_link",
            "left_wrist": "left_wrist_yaw_link",
            "right_wrist": "right_wrist_yaw_link",
            "left_hand": "left_rubber_hand",
            "right_hand": "right_rubber_hand",
            "left_hip": "left_hip_roll_link",
            "right_hip": "right_hip_roll_link",
            "left_knee": "left_knee_link",
            "right_knee": "right_knee_link",
            "left_ankle": "left_ankle_roll_link",
            "right_ankle": "right_ankle_roll_link",
        },
        description="Unitree G1, 29 actuated DoF (g1_29dof_rev_1_0.urdf)",
    ),
    "icub": RobotDescription(
        name="icub",
        urdf="icub_description/robots/icub_reduced.urdf",
        srdf="icub_description/srdf/icub.srdf",
        reference="half_sitting",
        feet={
            "left_foot": FootDescription("l_sole", rectangle=(-0.04, 0.10, -0.035, 0.035)),
            "right_foot": FootDescription("r_sole", rectangle=(-0.04, 0.10, -0.035, 0.035)),
        },
        keyframes={
            "pelvis": "root_link",
            "torso": "chest",
            "head": "head",
            "left_shoulder": "l_shoulder_2",
            "right_shoulder": "r_shoulder_2",
            "left_elbow": "l_elbow_1",
            "right_elbow": "r_elbow_1",
            "left_wrist": "l_hand",
            "right_wrist": "r_hand",
            "left_hand": "l_gripper",
            "right_hand": "r_gripper",
            "left_knee": "l_lower_leg",
            "right_knee": "r_lower_leg",
            "left_ankle": "l_foot",
            "right_ankle": "r_foot",
        },
        description="iCub, reduced model (icub_reduced.urdf), SRDF half_sitting",
    ),
    "romeo": RobotDescription(
        name="romeo",
        urdf="romeo_description/urdf/romeo_small.urdf",
        srdf="romeo_description/srdf/romeo_small.srdf",
        reference="half_sitting",
        feet={
            "left_foot": FootDescription("l_sole", rectangle=(-0.077, 0.14, -0.069, 0.069)),
            "right_foot": FootDescription("r_sole", rectangle=(-0.077, 0.14, -0.069, 0.069)),
        },
        keyframes={
            "pelvis": "body",
            "torso": "torso",
            "head": "HeadRollLink",
            "left_shoulder": "LShoulderYawLink",
            "right_shoulder": "RShoulderYawLink",
            "left_elbow": "LElbowRollLink",
            "right_elbow": "RElbowRollLink",
            "left_wrist": "l_wrist",
            "right_wrist": "r_wrist",
            "left_hand": "l_gripper",
            "right_hand": "r_gripper",
            "left_knee": "LKneePitchLink",
            "right_knee": "RKneePitchLink",
            "left_ankle": "l_ankle",
            "right_ankle": "r_ankle",
        },
        description="Aldebaran Romeo (romeo_small.urdf), SRDF half_sitting",
    ),
    "simple_humanoid": RobotDescription(
        name="simple_humanoid",
        urdf="simple_humanoid_description/urdf/simple_humanoid.urdf",
        srdf="simple_humanoid_description/srdf/simple_humanoid.srdf",
        # The SRDF's half_sitting puts four leg joints outside this URDF's limits: stand straight.
        reference=None,
        feet={
            "left_foot": FootDescription("l_ankle", rectangle=(-0.08, 0.12, -0.05, 0.05)),
            "right_foot": FootDescription("r_ankle", rectangle=(-0.08, 0.12, -0.05, 0.05)),
        },
        keyframes={
            "pelvis": "BODY",
            "torso": "torso",
            "head": "torso",
            "left_shoulder": "LARM_LINK2",
            "right_shoulder": "RARM_LINK2",
            "left_elbow": "LARM_LINK4",
            "right_elbow": "RARM_LINK4",
            "left_wrist": "l_wrist",
            "right_wrist": "r_wrist",
            "left_hand": "l_wrist",
            "right_hand": "r_wrist",
            "left_knee": "LLEG_LINK4",
            "right_knee": "RLEG_LINK4",
            "left_ankle": "l_ankle",
            "right_ankle": "r_ankle",
        },
        description="simple_humanoid (HRP-2-like test model), straight standing posture",
    ),
    "talos": RobotDescription(
        name="talos",
        urdf="talos_data/robots/talos_reduced.urdf",
        srdf="talos_data/srdf/talos.srdf",
        reference="half_sitting",
        feet={
            "left_foot": FootDescription("left_sole_link", rectangle=(-0.11, 0.10, -0.069, 0.069)),
            "right_foot": FootDescription(
                "right_sole_link", rectangle=(-0.11, 0.10, -0.069, 0.069)
            ),
        },
        keyframes={
            "pelvis": "base_link",
            "torso": "torso_2_link",
            "head": "head_2_link",
            "left_shoulder": "arm_left_2_link",
            "right_shoulder": "arm_right_2_link",
            "left_elbow": "arm_left_4_link",
            "right_elbow": "arm_right_4_link",
            "left_wrist": "arm_left_7_link",
            "right_wrist": "arm_right_7_link",
            "left_hand": "gripper_left_base_link",
            "right_hand": "gripper_right_base_link",
            "left_knee": "leg_left_4_link",
            "right_knee": "leg_right_4_link",
            "left_ankle": "leg_left_6_link",
            "right_ankle": "leg_right_6_link",
        },
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
