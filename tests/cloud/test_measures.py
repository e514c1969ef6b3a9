# SPDX-License-Identifier: Apache-2.0
"""The reachability bound of the arm-direction error (qpretarget.cloud.measures)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.cloud.measures import (
    ARM_SEGMENTS,
    arm_direction_bound,
    arm_direction_errors,
    arm_direction_summary,
)


class _RobotAsPerson:
    """A 'poser' whose person is the robot itself at given configurations (key points)."""

    def __init__(self, robot, qs: np.ndarray) -> None:
        self.robot, self.qs = robot, qs
        self.data = robot.model.createData()

    def model_keypoints(self, k) -> dict[str, np.ndarray]:
        model = self.robot.model
        pin.framesForwardKinematics(model, self.data, self.qs[int(k)])
        return {
            name: self.data.oMf[model.getFrameId(frame)].translation.copy()
            for name, frame in self.robot.keyframes.items()
        }


def _with(g1, **angles: float) -> np.ndarray:
    q = g1.q_reference.copy()
    for name, value in angles.items():
        q[g1.joint_q_index[g1.joint_index(name)]] = value
    return q


def test_a_reachable_pose_has_no_bound(g1):
    """The person is G1 in a pose within its limits (arms raised and bent, waist turned): the
    nearest reachable arms from a run at the reference posture are that pose's, to 0.05 deg
    (least squares to xtol 1e-10 from four starts; the error of the run itself is tens of
    degrees, so the search moved). With the trunk free as well."""
    person = _with(
        g1,
        left_shoulder_pitch_joint=-1.2,
        left_shoulder_roll_joint=0.6,
        left_elbow_joint=0.4,
        right_shoulder_pitch_joint=-2.4,
        right_shoulder_roll_joint=-0.3,
        right_shoulder_yaw_joint=0.7,
        right_elbow_joint=1.0,
        waist_yaw_joint=0.3,
    )
    poser = _RobotAsPerson(g1, person[None])
    run = g1.q_reference[None]
    assert arm_direction_errors(g1, run, poser, np.zeros(1)).max() > 20.0
    fit = arm_direction_bound(g1, run, poser, np.zeros(1))
    assert fit.max() < 0.05
    free = arm_direction_bound(g1, run, poser, np.zeros(1), trunk="free")
    assert free.max() < 0.05


def test_a_fold_beyond_the_arm_is_bounded(g1):
    """The person's forearm folded back 175 deg onto the upper arm, beyond G1's elbow and
    wrist: the bound is the minimum over the arm's joints within their limits (the sum of the
    two segments' squared chords, 2 sin(e/2)): no one of 20,000 uniform draws of the seven
    left-arm joints does better (to 1e-9; the best draw's cost is about 6 times the bound's),
    and it is not zero (6.6 deg per segment, asserted above 5: with the wrist's pitch G1 folds
    its segments to about 162 deg); the other arm, hanging, is reachable (< 0.05 deg)."""
    model, data = g1.model, g1.model.createData()
    poser = _RobotAsPerson(g1, g1.q_reference[None])
    points = poser.model_keypoints(0)
    s, e = points["left_shoulder"], points["left_elbow"]
    up = (e - s) / np.linalg.norm(e - s)
    side = np.cross(up, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    a = np.radians(175.0)  # the forearm's direction, 175 deg from the upper arm's
    points["left_wrist"] = e + 0.2 * (np.cos(a) * up + np.sin(a) * side)
    poser.model_keypoints = lambda k: points  # type: ignore[method-assign]
    b = arm_direction_bound(g1, g1.q_reference[None], poser, np.zeros(1))[0]
    assert b[:2].max() > 5.0
    assert b[2:].max() < 0.05
    bound_cost = float(np.sum((2 * np.sin(np.radians(b[:2]) / 2)) ** 2))
    keys = [model.getFrameId(g1.keyframes[f"left_{n}"]) for n in ("shoulder", "elbow", "wrist")]
    target = [up, np.cos(a) * up + np.sin(a) * side]
    names = [n for n in g1.joint_names if n.startswith("left_") and ("shoulder" in n or
             "elbow" in n or "wrist" in n)]  # fmt: skip
    assert len(names) == 7
    idx = [g1.joint_q_index[g1.joint_index(n)] for n in names]
    rng = np.random.default_rng(0)
    q = g1.q_reference.copy()
    best = np.inf
    for x in rng.uniform(model.lowerPositionLimit[idx], model.upperPositionLimit[idx], (20000, 7)):
        q[idx] = x
        pin.framesForwardKinematics(model, data, q)
        p = [data.oMf[f].translation for f in keys]
        cost = 0.0
        for (i, j), t in zip(((0, 1), (1, 2)), target, strict=True):
            u = (p[j] - p[i]) / np.linalg.norm(p[j] - p[i])
            cost += float((u - t) @ (u - t))
        best = min(best, cost)
    assert best >= bound_cost - 1e-9


def test_arm_direction_summary():
    """The figures of the docs, the benchmark and ``evaluate`` from (T, 4) errors, by hand."""
    t = np.arange(10) / 10.0
    e = np.full((10, 4), 5.0)
    e[3, 2] = 13.0  # one frame above 12 deg: the right upper arm at 0.3 s, the worst
    e[5:8, 1] = 46.0  # the left forearm lost for frames 5-7: 0.2 s + one period = 0.3 s
    e[6, 1] = 50.0
    s = arm_direction_summary(e, t + 2.0)  # times from the clip's start: relative
    assert s["worst_deg"] == 50.0 and s["worst_segment"] == ARM_SEGMENTS[1]
    assert s["worst_time_s"] == pytest.approx(0.6, abs=1e-12)
    assert s["per_segment_worst_deg"] == dict(
        zip(ARM_SEGMENTS, [5.0, 50.0, 13.0, 5.0], strict=True)
    )
    assert s["median_deg"] == 5.0 and s["frames"] == 10
    assert s["frames_above_tolerance"] == 4  # frames 3, 5, 6, 7
    assert s["longest_lost_s"] == pytest.approx(0.3, abs=1e-12)
    with pytest.raises(ValueError, match=r"errors \(T, 4\)"):
        arm_direction_summary(e[:, :3], t)
    with pytest.raises(ValueError, match="T > 0"):
        arm_direction_summary(e, t[:5])
