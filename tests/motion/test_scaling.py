# SPDX-License-Identifier: Apache-2.0
"""Calibration and scaling to the robot (Poubel 2014 eq. 1, Dariush 2009 per-link scaling)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.motion import HumanMotion, KeypointMap
from qpretarget.motion.calibration import (
    KEYPOINT_TREE,
    build_tree,
    calibrate,
    nearest_rotation,
    rotation_z,
    triad,
)
from qpretarget.motion.keypoints import keypoint_orientations, keypoint_positions
from qpretarget.motion.scaling import LOWEST_HIP, Scaler, limit_leg_extension
from qpretarget.retarget.retargeter import default_robot_keypoints
from qpretarget.robot import load_robot

# Scaled lengths and directions are computed with a handful of floating-point operations from
# values of order 1 m: 1e-9 leaves six orders of magnitude of margin over double rounding while
# catching any real mistake (a wrong length or direction is off by millimetres or degrees).
EXACT = 1e-9


#: Key-point segments that are a single rigid bone of the CMU skeleton (the others, such as waist
#: -> neck or waist -> shoulder, bend with the spine and the clavicles).
RIGID = {
    f"{side}_{name}" for side in ("left", "right")
    for name in ("hip", "knee", "ankle", "elbow", "wrist", "hand")
}  # fmt: skip


@pytest.fixture(scope="module")
def g1_points() -> dict[str, np.ndarray]:
    """G1 key-points in its reference posture (the robot side of the calibration)."""
    robot = load_robot("g1")
    kmap = KeypointMap.from_dict({"name": "g1", "keypoints": default_robot_keypoints(robot)})
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_reference)

    def placement(name: str) -> pin.SE3:
        return data.oMf[robot.frame_id(name)]

    return kmap.evaluate(
        lambda f: placement(f).translation.copy(), lambda f: placement(f).rotation.copy()
    )


@pytest.fixture(scope="module")
def walk(load_clip) -> tuple[HumanMotion, dict[str, np.ndarray]]:
    motion = load_clip("cmu_16_15_walk.bvh")
    return motion, keypoint_positions(motion, "cmu")


def _frame(points: dict[str, np.ndarray], k: int) -> dict[str, np.ndarray]:
    return {name: p[k] for name, p in points.items()}


def _segments(tree: dict[str, str | None]) -> list[tuple[str, str]]:
    return [(child, parent) for child, parent in tree.items() if parent is not None]


def test_build_tree_hangs_orphans_on_the_nearest_ancestor():
    tree = build_tree(["waist", "left_shoulder", "left_wrist", "left_hand", "head"])
    # No elbow: the wrist hangs from the shoulder; no neck: the head hangs from the waist.
    assert tree == {
        "waist": None,
        "head": "waist",
        "left_shoulder": "waist",
        "left_wrist": "left_shoulder",
        "left_hand": "left_wrist",
    }
    assert list(build_tree(KEYPOINT_TREE)) == list(KEYPOINT_TREE)  # parents come first


@pytest.mark.parametrize("support", ["left", "right", "waist"])
def test_poubel_segments_have_robot_length_and_human_direction(walk, g1_points, support):
    motion, points = walk
    cal = calibrate(_frame(points, 0), g1_points)
    scaler = Scaler(cal, "poubel")
    for k in range(0, len(motion), 47):  # 10 frames spread over the walk
        human = _frame(points, k)
        if support == "waist":
            out = scaler.scale(human)  # no anchors: rooted at the waist
        else:
            anchor = g1_points[f"{support}_ankle"] + [0.1 * k / len(motion), 0.0, 0.0]
            out = scaler.scale(human, support=support, anchors={support: anchor})
            assert np.allclose(out[f"{support}_ankle"], anchor, atol=0.0)
        for child, parent in _segments(cal.tree):
            d_r = out[child] - out[parent]
            d_h = cal.rotation @ (human[child] - human[parent])
            assert abs(np.linalg.norm(d_r) - cal.robot_lengths[child]) < EXACT
            assert np.linalg.norm(np.cross(d_r, d_h)) / np.linalg.norm(d_h) < EXACT
            assert d_r @ d_h > 0  # same direction, not opposite


def test_poubel_double_support_fixes_both_ankles_and_scales_every_other_segment(walk, g1_points):
    motion, points = walk
    cal = calibrate(_frame(points, 0), g1_points)
    scaler = Scaler(cal, "poubel")
    left, right = g1_points["left_ankle"], g1_points["right_ankle"] + [0.2, -0.05, 0.0]
    for k in range(0, len(motion), 47):
        human = _frame(points, k)
        out = scaler.scale(human, support="double", anchors={"left": left, "right": right})
        assert np.array_equal(out["left_ankle"], left)
        assert np.array_equal(out["right_ankle"], right)
        # Poubel 2014 III.A: the legs' loop closes at the fixed ankles, so the shanks (knee ->
        # ankle) take whatever length closes it; every other segment is eq. 1.
        for child, parent in _segments(cal.tree):
            if child.endswith("_ankle"):
                continue
            d_r = out[child] - out[parent]
            d_h = cal.rotation @ (human[child] - human[parent])
            assert abs(np.linalg.norm(d_r) - cal.robot_lengths[child]) < EXACT
            assert np.linalg.norm(np.cross(d_r, d_h)) / np.linalg.norm(d_h) < EXACT
        # The mid-ankle -> mid-hip segment follows the person's direction.
        mid_a = 0.5 * (left + right)
        mid_h = 0.5 * (out["left_hip"] + out["right_hip"])
        human_dir = cal.rotation @ (
            0.5 * (human["left_hip"] + human["right_hip"])
            - 0.5 * (human["left_ankle"] + human["right_ankle"])
        )
        cos = (
            (mid_h - mid_a) @ human_dir / np.linalg.norm(mid_h - mid_a) / np.linalg.norm(human_dir)
        )
        assert cos > 0.99  # the waist -> hips offset tilts it by at most a few degrees


def test_dariush_per_link_scaling(walk, g1_points):
    motion, points = walk
    cal = calibrate({k: v[:5] for k, v in points.items()}, g1_points)
    scaler = Scaler(cal, "dariush")
    for k in range(0, len(motion), 47):
        human = _frame(points, k)
        out = scaler.scale(human)
        for child, parent in _segments(cal.tree):
            d_r = out[child] - out[parent]
            d_h = cal.rotation @ (human[child] - human[parent])
            # Dariush 2009 Sec. 3: each link vector is the human's times its scale.
            assert np.allclose(d_r, cal.scales[child] * d_h, atol=EXACT)
            if child in RIGID:
                # One BVH bone: rigid, so s * l_h(t) = l_r to the precision of the file's
                # forward kinematics (~1e-12 m over the clip).
                assert abs(np.linalg.norm(d_r) - cal.robot_lengths[child]) < EXACT
        # The waist moves by the human's displacement times the height ratio.
        expected = cal.robot_waist + cal.root_scale * (
            cal.rotation @ (human["waist"] - cal.human_waist)
        )
        assert np.allclose(out["waist"], expected, atol=EXACT)


def test_scales_are_robot_over_human_lengths(walk, g1_points):
    _, points = walk
    cal = calibrate(_frame(points, 0), g1_points)
    for child, parent in _segments(cal.tree):
        human = np.linalg.norm(points[child][0] - points[parent][0])
        robot = np.linalg.norm(g1_points[child] - g1_points[parent])
        assert cal.scales[child] == pytest.approx(robot / human, rel=1e-12)
    # Human thigh 0.40 m (README: 0.39-0.43 m), G1 thigh 0.31 m.
    assert 0.35 < cal.human_lengths["left_knee"] < 0.45
    assert 0.28 < cal.robot_lengths["left_knee"] < 0.34


@pytest.mark.parametrize("angle_deg", [180.0, 90.0, -135.0])
def test_initial_heading_is_aligned_to_the_robot(walk, g1_points, angle_deg):
    """A clip turned about z (GMR users report collapses at 180 deg) scales to the same targets."""
    motion, points = walk
    R = rotation_z(math.radians(angle_deg))
    shift = np.array([2.0, -3.0, 0.0])
    turned = {k: v @ R.T + shift for k, v in points.items()}
    rots = keypoint_orientations(motion, "cmu")["waist"]
    cal_a = calibrate(_frame(points, 0), g1_points, human_waist_rotation=rots[0])
    cal_b = calibrate(_frame(turned, 0), g1_points, human_waist_rotation=R @ rots[0])
    expected_yaw = math.remainder(cal_a.yaw - math.radians(angle_deg), 2 * math.pi)
    assert math.remainder(cal_b.yaw - expected_yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    for method in ("poubel", "dariush"):
        a, b = Scaler(cal_a, method), Scaler(cal_b, method)
        for k in (0, 150, 300):
            anchors = {"left": g1_points["left_ankle"]}
            out_a = a.scale(_frame(points, k), support="left", anchors=anchors)
            out_b = b.scale(_frame(turned, k), support="left", anchors=anchors)
            for name in out_a:
                # Rotating by R and back changes the last bits only: 1e-9 m.
                assert np.allclose(out_a[name], out_b[name], atol=EXACT), (method, name)
    # After alignment the walk goes along the robot's +x (it faces +x at its reference).
    sa = Scaler(cal_a, "dariush")
    start, end = sa.scale(_frame(points, 0))["waist"], sa.scale(_frame(points, 460))["waist"]
    assert end[0] - start[0] > 2.5 and abs(end[1] - start[1]) < 0.5


def test_heading_without_orientations_comes_from_the_hips(g1_points):
    human = {k: v.copy() for k, v in g1_points.items()}  # a "person" shaped like G1, facing +x
    R = rotation_z(math.pi)
    cal = calibrate({k: R @ v for k, v in human.items()}, g1_points)
    assert abs(abs(cal.yaw) - math.pi) < 1e-9
    scaled = Scaler(cal).scale({k: R @ v for k, v in human.items()})
    # Same shape and same lengths: the robot's own reference key-points come back.
    for name, p in scaled.items():
        assert np.allclose(p - scaled["waist"], g1_points[name] - g1_points["waist"], atol=EXACT)


def test_triad_is_a_rotation_and_nearest_rotation_projects():
    rng = np.random.default_rng(0)
    left, right = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    low, up = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    R = triad(left, right, low, up)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    noisy = R + 1e-3 * rng.normal(size=R.shape)
    P = nearest_rotation(noisy)
    assert np.allclose(np.linalg.det(P), 1.0, atol=1e-12)
    assert np.abs(P - R).max() < 3e-3


def test_leg_extension_limit_lowers_the_body_only_as_needed(g1_points):
    scaled = {k: v.copy() for k, v in g1_points.items()}
    legs = {"left": 0.6229, "right": 0.6229}
    anchors = {s: g1_points[f"{s}_ankle"] for s in ("left", "right")}
    out, dz = limit_leg_extension(scaled, anchors, legs, 0.92)
    assert dz > 0
    for side in ("left", "right"):
        reach = np.linalg.norm(out[f"{side}_hip"] - anchors[side])
        assert reach <= 0.92 * legs[side] + 1e-12
        assert np.array_equal(out[f"{side}_ankle"], anchors[side])
    assert np.allclose(out["head"], scaled["head"] - [0, 0, dz])
    # Already bent enough: nothing moves.
    again, dz2 = limit_leg_extension(out, anchors, legs, 0.92)
    assert dz2 == pytest.approx(0.0, abs=1e-12)
    assert all(np.array_equal(again[k], out[k]) for k in out)


def test_a_robot_leg_still_standing_bounds_the_body_but_its_foot_points_move_with_it(g1_points):
    scaled = {k: v.copy() for k, v in g1_points.items()}
    legs = {"left": 0.6229, "right": 0.6229}
    # The person stands on the right foot only; the robot's left still stands 20 cm behind.
    anchors = {"right": g1_points["right_ankle"]}
    left = g1_points["left_ankle"] - np.array([0.2, 0.0, 0.0])
    alone, dz0 = limit_leg_extension(scaled, anchors, legs, 0.92)
    out, dz = limit_leg_extension(scaled, anchors, legs, 0.92, standing={"left": left})
    assert dz > dz0  # the left leg, further from its hip, needs the body lower
    assert np.linalg.norm(out["left_hip"] - left) <= 0.92 * legs["left"] + 1e-12
    assert np.array_equal(out["right_ankle"], anchors["right"])  # the support stays
    # The standing robot foot is not a support of the scaling: the person's (lifted) left foot
    # points move down with the body.
    assert np.allclose(out["left_ankle"], scaled["left_ankle"] - [0, 0, dz])


def test_a_hip_beyond_the_reach_sideways_is_lowered_to_a_squat_not_to_the_floor(g1_points):
    scaled = {k: v.copy() for k, v in g1_points.items()}
    legs = {"left": 0.6229, "right": 0.6229}
    # A support 0.8 m from its hip horizontally: no height brings it within 0.92 of the leg.
    far = g1_points["left_ankle"] - np.array([0.8, 0.0, 0.0])
    out, dz = limit_leg_extension(scaled, {"left": far}, legs, 0.92)
    hip_height = out["left_hip"][2] - far[2]
    assert hip_height == pytest.approx(LOWEST_HIP * 0.92 * legs["left"], abs=1e-12)
    assert hip_height > 0.25
