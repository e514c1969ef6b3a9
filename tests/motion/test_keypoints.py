# SPDX-License-Identifier: Apache-2.0
"""Tests of the key-point maps: bundled maps fit their clips and the URDF, YAML errors."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import numpy as np
import pytest

from qpretarget.motion import (
    DARIUSH_KEYPOINTS,
    KEYPOINT_NAMES,
    KeypointMapError,
    guess_keypoint_map,
    list_keypoint_maps,
    load_keypoint_map,
)
from qpretarget.motion.keypoints import keypoint_orientations, keypoint_positions

CMU_CLIPS = [
    "cmu_14_37_drink_soda.bvh",
    "cmu_02_06_bend_scoop_lift_arm.bvh",
    "cmu_14_07_reach_up_tiptoe.bvh",
    "cmu_17_10_boxing.bvh",
    "cmu_131_04_dance_spin.bvh",
    "cmu_14_14_exercise_squats_twists.bvh",
    "cmu_16_15_walk.bvh",
    "cmu_16_33_walk_stop.bvh",
    "cmu_135_04_front_kicks.bvh",
    "cmu_49_18_one_leg_balance.bvh",
    "cmu_29_03_teapot_arm_gestures.bvh",
    "cmu_29_22_chicken_flapping.bvh",
    "cmu_135_06_karate_kata.bvh",
    "cmu_01_01.amc",
    "cmu_14_37.amc",
    "cmu_16_15.amc",
]
CLIP_MAPS = [(name, "cmu") for name in CMU_CLIPS] + [
    ("cgspeed_cmu_01_01_playground_jumps.bvh", "cgspeed"),
    ("opensim_walking2.c3d", "opensim_walking"),
    ("pyomeca_upper_limb_box_lift.c3d", "pyomeca_upper_limb"),
]


def test_bundled_maps_are_listed():
    assert list_keypoint_maps() == [
        "biovision",
        "cgspeed",
        "cmu",
        "human_description",
        "lafan1",
        "mixamo",
        "mvn_bvh",
        "opensim_walking",
        "pyomeca_upper_limb",
        "smpl",
    ]


@pytest.mark.parametrize(("clip", "map_name"), CLIP_MAPS, ids=[c for c, _ in CLIP_MAPS])
def test_map_sources_exist_in_clip_and_are_guessed(load_clip, clip, map_name):
    motion = load_clip(clip)
    kmap = load_keypoint_map(map_name)
    assert kmap.missing_in(motion.names) == []
    assert guess_keypoint_map(motion).name == map_name
    keypoints = keypoint_positions(motion, kmap)
    assert list(keypoints) == list(kmap.keypoints)
    for name, points in keypoints.items():
        assert points.shape == (len(motion), 3)
        assert np.isfinite(points).any(axis=1).sum() > 0.3 * len(motion), name


@pytest.mark.parametrize("map_name", ["cmu", "cgspeed", "human_description"])
def test_skeleton_maps_cover_dariush_and_legs(map_name):
    kmap = load_keypoint_map(map_name)
    assert set(DARIUSH_KEYPOINTS) <= set(kmap.keypoints)
    assert set(kmap.keypoints) <= set(KEYPOINT_NAMES)
    assert {"left_ankle", "right_toe", "neck", "left_hand"} <= set(kmap.keypoints)


def test_cmu_map_on_bvh_and_amc_agree(load_clip):
    bvh = keypoint_positions(load_clip("cmu_16_15_walk.bvh"), "cmu")
    # The BVH starts at AMC frame 3; load_motion drops the AMC's dropout frames 1-2 itself.
    amc = keypoint_positions(load_clip("cmu_16_15.amc"), "cmu")
    for name in bvh:
        np.testing.assert_allclose(bvh[name], amc[name], atol=1e-5)


def test_head_is_between_skull_base_and_top(load_clip):
    motion = load_clip("cmu_14_37_drink_soda.bvh")
    head = keypoint_positions(motion, "cmu")["head"]
    np.testing.assert_allclose(head, (motion.joint("head") + motion.joint("head_end")) / 2)


def test_orientations_come_from_the_named_joints(load_clip):
    motion = load_clip("cmu_16_15_walk.bvh")
    orientations = keypoint_orientations(motion, "cmu")
    assert list(orientations) == ["waist", "torso", "head"]
    np.testing.assert_array_equal(orientations["torso"], motion.joint_orientation("thorax"))
    # Walking along +X with the CMU rest pose facing +X: pelvis heading stays near 0.
    forward = orientations["waist"][:, :, 0]
    assert np.median(forward[:, 0]) > 0.9


def test_marker_motion_has_no_orientations(load_clip):
    with pytest.raises(ValueError, match="has no orientations"):
        keypoint_orientations(
            load_clip("opensim_walking2.c3d"),
            {"keypoints": {"neck": "C7"}, "orientations": {"waist": "LASI"}},
        )


def _human_urdf() -> Path:
    share = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share"
    path = share / "example-robot-data/robots/human_description/robots/human.urdf"
    if not path.is_file():
        pytest.skip(f"example-robot-data human.urdf not found at {path}")
    return path


def test_human_description_frames_exist_and_offsets_are_anatomical():
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromUrdf(str(_human_urdf()))
    kmap = load_keypoint_map("human_description")
    missing = [f for f in kmap.source_names() if not model.existFrame(f)]
    assert missing == []
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))

    def placement(name):
        return data.oMf[model.getFrameId(name)]

    points = kmap.evaluate(
        lambda f: placement(f).translation.copy(), lambda f: placement(f).rotation.copy()
    )
    # Neutral pose of human.urdf: y up, x forward, arms hanging, left side at -z.
    assert points["head"][1] - points["neck"][1] == pytest.approx(0.13)
    assert points["left_toe"][0] - points["left_ankle"][0] == pytest.approx(0.135)
    assert points["left_hand"][1] < points["left_wrist"][1] < points["left_elbow"][1]
    assert points["left_shoulder"][2] < 0 < points["right_shoulder"][2]
    assert points["head"][1] > points["neck"][1] > points["waist"][1] > points["left_knee"][1]


def _write_map(tmp_path, text: str) -> Path:
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    return path


def test_unknown_top_key_names_file_line_and_fix(tmp_path):
    path = _write_map(tmp_path, "name: mine\nkeypoint:\n  waist: root\n")
    with pytest.raises(
        KeypointMapError,
        match=r"mine\.yaml, line 2: keypoint: unknown key\. Did you mean 'keypoints'",
    ):
        load_keypoint_map(path)


def test_misspelt_keypoint_is_rejected(tmp_path):
    path = _write_map(tmp_path, "keypoints:\n  waist: root\n  left_wirst: lwrist\n")
    with pytest.raises(
        KeypointMapError,
        match=r"line 3: keypoints\.left_wirst: 'left_wirst' looks like a misspelling of "
        r".*'left_wrist'",
    ):
        load_keypoint_map(path)


def test_custom_keypoint_names_are_allowed(tmp_path):
    kmap = load_keypoint_map(_write_map(tmp_path, "keypoints:\n  chest: thorax\n"))
    assert kmap.name == "mine" and kmap.source_names() == ["thorax"]


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ("{from: head, offset: [0, 1]}", r"line 2: keypoints\.head\.offset: expected 3 finite"),
        ("{from: [head, neck], offset: [0, 1, 0]}", r"offset needs exactly one source point"),
        ("[]", r"expected a name or a non-empty list of names"),
        ("[head, head]", r"a name is repeated"),
        ("{form: head}", r"expected \{from: <name or list>, offset: \[x, y, z\]\}"),
    ],
)
def test_bad_entries_are_named(tmp_path, entry, message):
    with pytest.raises(KeypointMapError, match=message):
        load_keypoint_map(_write_map(tmp_path, f"keypoints:\n  head: {entry}\n"))


def test_unknown_bundled_map_lists_close_names():
    with pytest.raises(
        KeypointMapError, match=r"no bundled key-point map 'cmuu'\. Did you mean 'cmu'"
    ):
        load_keypoint_map("cmuu")


def test_guess_fails_with_the_closest_map_and_a_fix(load_clip):
    motion = load_clip("cmu_16_15_walk.bvh")
    renamed = motion.with_positions([n.upper() for n in motion.names], motion.positions)
    with pytest.raises(KeypointMapError, match=r"closest is .* Write a YAML map"):
        guess_keypoint_map(renamed)
