# SPDX-License-Identifier: Apache-2.0
"""Joint PD gains and passive joint parameters of the physics replay, per robot (docs/physics.md).

A :class:`GainProfile` gives, for each one-DoF joint, the PD gains ``kp`` [N m/rad] and ``kd``
[N m s/rad] of the tracking law

    tau = clip(kp (q_ref - q) + kd (qdot_ref - qdot), -tau_max, tau_max)

(``tau_max`` is the URDF ``<limit effort>``), and the joint's passive ``armature`` [kg m^2],
viscous ``damping`` [N m s/rad] and dry ``frictionloss`` [N m] in the MuJoCo model.

Profiles (:data:`GAIN_PROFILES`):

* ``unitree`` (G1): the gains of Unitree's own low-level G1 examples (unitree_sdk2,
  ``example/g1/low_level/g1_ankle_swing_example.cpp``: Kp 60/60/60/100/40/40 per leg, 60/40/40
  waist, 40 every arm joint; Kd 1, knees 2) and the passive joint parameters of Unitree's MuJoCo
  model of the G1 (unitree_mujoco ``unitree_robots/g1/g1_29dof.xml``: damping 0.05, armature 0.01,
  frictionloss 0.2, wrists 0.1).
* ``beyondmimic`` (G1): BeyondMimic's motion-tracking gains (HybridRobotics whole_body_tracking,
  ``robots/g1.py``): each joint's armature is its motor's reflected rotor inertia (Unitree motors
  5020, 7520-14, 7520-22, 4010; the ankles and waist roll/pitch drive two 5020s), and
  ``kp = armature * w^2``, ``kd = 2 zeta armature w`` with ``w = 2 pi 10 Hz``, ``zeta = 2``.
* ``stiff`` (any robot, the default): a stiff servo within the robot's torque limits,
  ``kp = tau_max / 0.05 rad`` (the full URDF effort at 2.9 deg of error) and ``kd = 0.02 s * kp``;
  armature 0.01, damping 0.05, frictionloss 0. Not a vendor's tuning: the vendor gains above are
  the inner loop of a balance policy, and on their own (PD and feed-forward, no policy) they let
  the G1 fall even on the standing gesture clips (docs/physics.md measures it); the stiff servo
  asks instead whether the motion itself — its momentum, contacts and torques — is one the robot
  can carry out.
* ``generic`` (any robot): ``kp = I w^2``, ``kd = 2 zeta I w`` from ``I``, the joint's apparent
  inertia in the standing posture (MuJoCo ``dof_M0``, the joint-space inertia's diagonal), with
  ``w = 2 pi 5 Hz`` and ``zeta = 1``; armature 0.01, damping 0.05, frictionloss 0 — a documented
  rule, not a vendor's tuning.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

#: Unitree motor rotor inertias reflected at the joint [kg m^2] (BeyondMimic robots/g1.py).
ARMATURE_5020 = 0.003609725
ARMATURE_7520_14 = 0.010177520
ARMATURE_7520_22 = 0.025101925
ARMATURE_4010 = 0.00425
_BM_W = 10.0 * 2.0 * math.pi  # BeyondMimic natural frequency [rad/s]
_BM_ZETA = 2.0

#: Stiff rule: full effort at this joint error [rad], and the damping time constant [s].
STIFF_ERROR_AT_LIMIT = 0.05
STIFF_DAMPING_TIME = 0.02

#: Generic rule: natural frequency [rad/s] and damping ratio of ``kp = I w^2, kd = 2 zeta I w``.
GENERIC_OMEGA = 5.0 * 2.0 * math.pi
GENERIC_ZETA = 1.0


@dataclass(frozen=True)
class JointGains:
    """PD gains and passive parameters of one joint."""

    kp: float
    kd: float
    armature: float
    damping: float
    frictionloss: float


@dataclass(frozen=True)
class GainProfile:
    """Per-joint gains by regular expression on the joint name (first match wins).

    Attributes:
        name: profile name (``unitree``, ``beyondmimic``, ``generic``).
        source: where the numbers come from (printed in the report).
        rules: ``(pattern, JointGains)``; ``None`` gains mean "the generic rule" for that joint.
        robots: registry names the profile is written for (empty: any robot).
        rule: ``table`` (``rules``), ``effort`` (stiff rule on the URDF effort) or ``inertia``
            (generic rule on the apparent inertia).
    """

    name: str
    source: str
    rules: tuple[tuple[str, JointGains], ...]
    robots: tuple[str, ...] = ()
    rule: str = "table"

    def gains(self, joint: str) -> JointGains | None:
        """The gains of ``joint``, or ``None`` when no rule matches."""
        for pattern, g in self.rules:
            if re.fullmatch(pattern, joint):
                return g
        return None


def _u(kp: float, kd: float, friction: float = 0.2) -> JointGains:
    return JointGains(kp, kd, 0.01, 0.05, friction)


_UNITREE = GainProfile(
    "unitree",
    "Unitree unitree_sdk2 G1 low-level example gains; joint armature/damping/friction of "
    "Unitree's MuJoCo model (unitree_mujoco g1_29dof.xml)",
    (
        (r".*_hip_(pitch|roll|yaw)_joint", _u(60.0, 1.0)),
        (r".*_knee_joint", _u(100.0, 2.0)),
        (r".*_ankle_(pitch|roll)_joint", _u(40.0, 1.0)),
        (r"waist_yaw_joint", _u(60.0, 1.0)),
        (r"waist_(roll|pitch)_joint", _u(40.0, 1.0)),
        (r".*_(shoulder_(pitch|roll|yaw)|elbow)_joint", _u(40.0, 1.0)),
        (r".*_wrist_(roll|pitch|yaw)_joint", _u(40.0, 1.0, 0.1)),
    ),
    ("g1",),
)


def _bm(armature: float) -> JointGains:
    return JointGains(armature * _BM_W**2, 2.0 * _BM_ZETA * armature * _BM_W, armature, 0.05, 0.0)


_BEYONDMIMIC = GainProfile(
    "beyondmimic",
    "BeyondMimic (whole_body_tracking robots/g1.py): armature = motor rotor inertia, "
    "kp = armature (2 pi 10 Hz)^2, kd = 2 * 2 * armature (2 pi 10 Hz)",
    (
        (r".*_hip_(pitch|yaw)_joint", _bm(ARMATURE_7520_14)),
        (r".*_(hip_roll|knee)_joint", _bm(ARMATURE_7520_22)),
        (r".*_ankle_(pitch|roll)_joint", _bm(2.0 * ARMATURE_5020)),
        (r"waist_yaw_joint", _bm(ARMATURE_7520_14)),
        (r"waist_(roll|pitch)_joint", _bm(2.0 * ARMATURE_5020)),
        (r".*_(shoulder_(pitch|roll|yaw)|elbow|wrist_roll)_joint", _bm(ARMATURE_5020)),
        (r".*_wrist_(pitch|yaw)_joint", _bm(ARMATURE_4010)),
    ),
    ("g1",),
)

_GENERIC = GainProfile(
    "generic",
    "generic rule: kp = I (2 pi 5 Hz)^2, kd = 2 I (2 pi 5 Hz), I = the joint's apparent inertia "
    "in the standing posture (MuJoCo dof_M0); armature 0.01, damping 0.05",
    (),
    rule="inertia",
)

_STIFF = GainProfile(
    "stiff",
    "stiff servo within the torque limits: kp = effort / 0.05 rad, kd = 0.02 s * kp; "
    "armature 0.01, damping 0.05",
    (),
    rule="effort",
)

#: Gain profiles by name (``--physics-gains``).
GAIN_PROFILES: dict[str, GainProfile] = {
    p.name: p for p in (_STIFF, _UNITREE, _BEYONDMIMIC, _GENERIC)
}

#: Passive parameters of joints the generic rule covers.
GENERIC_PASSIVE = JointGains(0.0, 0.0, 0.01, 0.05, 0.0)


#: The profile used when none is asked for.
DEFAULT_PROFILE = "stiff"
