# SPDX-License-Identifier: Apache-2.0
r"""A built-in human motion for ``qpretarget demo``: nothing to download.

The human model of example-robot-data (``human_description/robots/human.urdf``, 36 joints) is
driven by scripted joint trajectories and its key-points are read with pinocchio forward
kinematics through the bundled ``human_description`` key-point map. The 10.2 s script:

========  ==================================================================================
0-1 s     standing, arms hanging
1-3.2 s   wave: right arm raised sideways, forearm swinging at 1.5 Hz
3.2-5.2   reach across the body: left hand to the right shoulder's side, trunk turned right
5.2-7.2   squat: pelvis 0.2 m down with the feet fixed, trunk leaning, arms forward
7.2-10.2  a step to the side: weight onto the left foot, right foot lifted 8 cm and put down
          15 cm further right, weight back between the feet
========  ==================================================================================

The URDF has a fixed base at the pelvis; the pelvis is moved in the world by hand and the legs
follow by inverse kinematics (Gauss-Newton on each leg's six joints) so that a foot on the ground
stays exactly where it is. The model's world (y up, x forward, z right) becomes the z-up world of
:class:`~qpretarget.motion.HumanMotion` by :data:`HUMAN_TO_Z_UP`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pinocchio as pin

from ..robot import resolve_robot_path
from .calibration import KEYPOINT_TREE
from .human_motion import HumanMotion
from .keypoints import load_keypoint_map
from .phases import min_jerk

#: The human model inside example-robot-data.
HUMAN_URDF = "example-robot-data:human_description/robots/human.urdf"

#: Model axes (x forward, y up, z right) to the z-up world (x forward, y left, z up).
HUMAN_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

#: Height of the ankle frame above the sole in the model [m] (foot mesh sole at y = -0.077).
ANKLE_HEIGHT = 0.077

#: Duration of the script [s].
DURATION = 10.2

_LEGS = {
    side: [f"{side}_hip_Z", f"{side}_hip_X", f"{side}_hip_Y", f"{side}_knee_Z",
           f"{side}_ankle_Z", f"{side}_ankle_X"]
    for side in ("left", "right")
}  # fmt: skip


@functools.cache
def human_model() -> pin.Model:
    """The pinocchio model of example-robot-data's ``human_description`` (fixed base, cached)."""
    return pin.buildModelFromUrdf(str(resolve_robot_path(HUMAN_URDF)))


def _ramp(t: float, t0: float, t1: float) -> float:
    """Minimum-jerk 0 -> 1 between ``t0`` and ``t1``."""
    return min_jerk((t - t0) / (t1 - t0))


def _bump(t: float, t0: float, t1: float) -> float:
    """0 -> 1 -> 0 between ``t0`` and ``t1`` (raised, held, lowered by minimum-jerk ramps)."""
    if t <= t0 or t >= t1:
        return 0.0
    edge = min(0.45, 0.3 * (t1 - t0))
    return _ramp(t, t0, t0 + edge) * (1.0 - _ramp(t, t1 - edge, t1))


def scripted_joints(t: float) -> dict[str, float]:
    """Upper-body joint angles [rad] of the script at time ``t`` [s] (legs come from IK)."""
    q: dict[str, float] = {
        "left_shoulder_X": 0.12, "right_shoulder_X": 0.12,
        "left_elbow_Z": 0.15, "right_elbow_Z": 0.15,
    }  # fmt: skip
    # Wave (1.0 - 3.2 s): right arm out to the side and up, forearm swinging.
    w = _bump(t, 1.0, 3.2)
    q["right_shoulder_X"] += w * 1.25
    q["right_shoulder_Z"] = w * 0.35
    q["right_shoulder_Y"] = -w * 1.2
    q["right_elbow_Z"] += w * (1.2 + 0.45 * math.sin(2.0 * math.pi * 1.5 * (t - 1.0)))
    # Reach across the body (3.2 - 5.2 s): left arm forward and to the right, trunk turned right.
    r = _bump(t, 3.2, 5.2)
    q["left_shoulder_Z"] = r * 1.35
    q["left_shoulder_X"] += -r * 0.75
    q["left_elbow_Z"] += r * 0.25
    q["middle_thoracic_Y"] = -r * 0.35
    # Squat (5.2 - 7.2 s): trunk leaning forward, both arms forward.
    s = _bump(t, 5.2, 7.2)
    q["middle_lumbar_Z"] = s * 0.35
    q["left_shoulder_Z"] += s * 1.2
    q["right_shoulder_Z"] += s * 1.2
    # Step (7.2 - 10.2 s): arms slightly out for balance.
    b = _bump(t, 7.2, 10.2)
    q["left_shoulder_X"] += b * 0.25
    q["right_shoulder_X"] += b * 0.25
    return q


def scripted_pelvis_and_feet(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pelvis, left-ankle and right-ankle positions [m] in the z-up world at time ``t`` [s]."""
    stand = 0.979 + ANKLE_HEIGHT
    left = np.array([0.023, 0.082, ANKLE_HEIGHT])
    right = np.array([0.023, -0.082, ANKLE_HEIGHT])
    pelvis = np.array([0.0, 0.0, stand])
    # Squat: pelvis 0.2 m down, slightly back.
    s = _bump(t, 5.2, 7.2)
    pelvis += s * np.array([-0.05, 0.0, -0.2])
    # Step to the side: weight left (7.2-7.8), right foot lifted and moved (7.8-8.7),
    # weight to the new middle (8.8-9.4).
    side_step = 0.15
    shift_left = _ramp(t, 7.2, 7.8)
    shift_back = _ramp(t, 8.8, 9.4)
    y_left, y_mid = 0.06, -0.5 * side_step
    pelvis[1] += shift_left * y_left + shift_back * (y_mid - y_left)
    pelvis[2] -= 0.02 * shift_left + 0.015 * shift_back  # the wider stance is lower
    move = _ramp(t, 7.8, 8.7)
    right[1] -= side_step * move
    right[2] += 0.08 * math.sin(math.pi * move)
    return pelvis, left, right


class _LegIK:
    """Gauss-Newton inverse kinematics of one leg (6 joints) for an ankle pose in the model."""

    def __init__(self, model: pin.Model, side: str) -> None:
        self.model = model
        self.data = model.createData()
        self.frame = model.getFrameId(f"{side}_foot")
        joints = [model.joints[model.getJointId(n)] for n in _LEGS[side]]
        self.q_idx = np.array([j.idx_q for j in joints])
        self.v_idx = np.array([j.idx_v for j in joints])
        self.lo = model.lowerPositionLimit[self.q_idx]
        self.hi = model.upperPositionLimit[self.q_idx]

    def solve(self, q: np.ndarray, target: pin.SE3, iterations: int = 30) -> None:
        """Move the leg joints of ``q`` (in place) so that the ankle frame reaches ``target``."""
        model, data = self.model, self.data
        for _ in range(iterations):
            pin.forwardKinematics(model, data, q)
            pin.updateFramePlacement(model, data, self.frame)
            M = data.oMf[self.frame]
            err = pin.log6(M.actInv(target)).vector  # local frame
            if err @ err < 1e-18:
                break
            J = pin.computeFrameJacobian(model, data, q, self.frame, pin.LOCAL)[:, self.v_idx]
            dq = np.linalg.solve(J.T @ J + 1e-8 * np.eye(6), J.T @ err)
            q[self.q_idx] = np.clip(q[self.q_idx] + dq, self.lo, self.hi)


def builtin_motion(rate: float = 60.0, *, duration: float = DURATION) -> HumanMotion:
    """The scripted demo motion as key-points of the ``human_description`` model.

    Args:
        rate: Capture rate [Hz] of the generated motion (60 Hz, a Kinect-like rate, so that the
            pipeline up-samples to the 100 Hz control rate).
        duration: Length [s] (at most the script's 10.2 s).

    Returns:
        A :class:`~qpretarget.motion.HumanMotion` whose points are the key-points (``waist``,
        ``neck``, ``head``, shoulders, elbows, wrists, hands, hips, knees, ankles, toes) in
        metres, z up, soles on ``z = 0``.

    Raises:
        ValueError: A non-positive rate or duration.
    """
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number of Hz, got {rate!r}")
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be positive [s], got {duration!r}")
    model = human_model()
    data = model.createData()
    kmap = load_keypoint_map("human_description")
    names = list(kmap.keypoints)
    legs = {side: _LegIK(model, side) for side in ("left", "right")}
    joint_q = {model.names[j]: model.joints[j].idx_q for j in range(1, model.njoints)}
    A = HUMAN_TO_Z_UP
    times = np.arange(int(math.floor(min(duration, DURATION) * rate + 1e-9)) + 1) / rate
    T = len(times)
    frames = kmap.source_names()
    ids = [model.getFrameId(f) for f in frames]
    translations = np.empty((len(frames), T, 3))  # model frame, pelvis at the origin
    rotations = np.empty((len(frames), T, 3, 3))
    pelvis_path = np.empty((T, 3))
    q = pin.neutral(model)
    for k, t in enumerate(times):
        for joint, value in scripted_joints(float(t)).items():
            q[joint_q[joint]] = value
        pelvis, left, right = scripted_pelvis_and_feet(float(t))
        pelvis_path[k] = pelvis
        for side, ankle in (("left", left), ("right", right)):
            legs[side].solve(q, pin.SE3(np.eye(3), A.T @ (ankle - pelvis)))
        pin.framesForwardKinematics(model, data, q)
        for i, fid in enumerate(ids):
            M = data.oMf[fid]
            translations[i, k] = M.translation
            rotations[i, k] = M.rotation
    index_of = {f: i for i, f in enumerate(frames)}
    points = kmap.evaluate(
        lambda f: translations[index_of[f]], lambda f: rotations[index_of[f]]
    )  # model axes, (T, 3) each
    positions = np.stack([points[n] @ A.T + pelvis_path for n in names], axis=1)
    index = {n: i for i, n in enumerate(names)}
    parents = []
    for n in names:
        p = KEYPOINT_TREE.get(n)
        while p is not None and p not in index:
            p = KEYPOINT_TREE.get(p)
        parents.append(-1 if p is None else index[p])
    return HumanMotion(
        t=times,
        names=tuple(names),
        positions=positions,
        parents=tuple(parents),
        rate=float(rate),
        source="builtin:human_description (wave, reach across, squat, side step)",
        meta={"format": "builtin", "keypoint_map": "identity", "model": HUMAN_URDF},
    )


__all__ = [
    "DURATION",
    "HUMAN_TO_Z_UP",
    "HUMAN_URDF",
    "builtin_motion",
    "human_model",
    "scripted_joints",
    "scripted_pelvis_and_feet",
]
