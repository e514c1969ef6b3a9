# SPDX-License-Identifier: Apache-2.0
"""Every clip of shared/data/mocap loads with the size, rate and body the README states."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion.keypoints import keypoint_positions

# (file, frames, rate [Hz], key-point map) as stated in shared/data/mocap/README.md, section 1.
CLIPS = [
    ("cmu_14_37_drink_soda.bvh", 513, 120.0, "cmu"),
    ("cmu_02_06_bend_scoop_lift_arm.bvh", 1200, 120.0, "cmu"),
    ("cmu_14_07_reach_up_tiptoe.bvh", 1200, 120.0, "cmu"),
    ("cmu_17_10_boxing.bvh", 1200, 120.0, "cmu"),
    ("cmu_131_04_dance_spin.bvh", 1086, 120.0, "cmu"),
    ("cmu_14_14_exercise_squats_twists.bvh", 1260, 120.0, "cmu"),
    ("cmu_16_15_walk.bvh", 469, 120.0, "cmu"),
    ("cmu_16_33_walk_stop.bvh", 285, 120.0, "cmu"),
    ("cmu_135_04_front_kicks.bvh", 1316, 120.0, "cmu"),
    ("cmu_49_18_one_leg_balance.bvh", 1102, 120.0, "cmu"),
    ("cmu_29_03_teapot_arm_gestures.bvh", 1560, 120.0, "cmu"),
    ("cmu_29_22_chicken_flapping.bvh", 1200, 120.0, "cmu"),
    ("cmu_135_06_karate_kata.bvh", 1440, 120.0, "cmu"),
    ("cgspeed_cmu_01_01_playground_jumps.bvh", 2752, 120.0, "cgspeed"),  # incl. T-pose frame 0
    ("cmu_01_01.amc", 2751, 120.0, "cmu"),
    ("cmu_14_37.amc", 513, 120.0, "cmu"),
    ("cmu_16_15.amc", 471, 120.0, "cmu"),
    ("opensim_walking2.c3d", 1249, 250.0, "opensim_walking"),
    ("pyomeca_upper_limb_box_lift.c3d", 580, 100.0, "pyomeca_upper_limb"),
]
NAMES = [c[0] for c in CLIPS]


def _median_distance(a: np.ndarray, b: np.ndarray) -> float:
    d = np.linalg.norm(a - b, axis=-1)
    return float(np.median(d[np.isfinite(d)]))


#: Frames before a cut at the start, which load_motion drops (README: cgspeed's T-pose frame
#: 0, caveat 2; the 16_15 AMC's dropout in frames 1-2, caveat 4). No other clip has one.
LEADING_CUT = {"cgspeed_cmu_01_01_playground_jumps.bvh": 1, "cmu_16_15.amc": 2}


@pytest.mark.parametrize(("name", "frames", "rate", "kmap"), CLIPS, ids=NAMES)
def test_frame_count_and_rate(mocap, load_clip, name, frames, rate, kmap):
    from qpretarget.motion import load_motion

    whole = load_motion(mocap / name, keep_leading_cut=True)
    assert len(whole) == frames
    assert whole.rate == rate  # BVH 'Frame Time: 0.0083333' snaps to exactly 120 Hz
    assert whole.t[0] == 0.0
    assert whole.t[-1] == pytest.approx((frames - 1) / rate, rel=1e-12)
    # By default the frames before a cut at the start are dropped (timestamps kept) and a note
    # says so; on every other clip nothing is.
    cut = LEADING_CUT.get(name, 0)
    motion = load_clip(name)
    assert len(motion) == frames - cut
    assert motion.t[0] == pytest.approx(cut / rate, rel=1e-12)
    np.testing.assert_array_equal(motion.positions, whole.positions[cut:])
    assert motion.meta.get("dropped_leading_frames", 0) == cut
    assert bool(motion.meta.get("notes")) == bool(cut)


@pytest.mark.parametrize(("name", "frames", "rate", "kmap"), CLIPS, ids=NAMES)
def test_segments_are_human_sized_in_metres(load_clip, name, frames, rate, kmap):
    keypoints = keypoint_positions(load_clip(name), kmap)
    checked = 0
    for side in ("left", "right"):
        if f"{side}_shoulder" in keypoints and f"{side}_elbow" in keypoints:
            upper_arm = _median_distance(keypoints[f"{side}_shoulder"], keypoints[f"{side}_elbow"])
            assert 0.2 <= upper_arm <= 0.45, f"{side} upper arm {upper_arm:.3f} m"
            checked += 1
        if f"{side}_hip" in keypoints and f"{side}_knee" in keypoints:
            thigh = _median_distance(keypoints[f"{side}_hip"], keypoints[f"{side}_knee"])
            assert 0.3 <= thigh <= 0.6, f"{side} thigh {thigh:.3f} m"
            checked += 1
    assert checked >= 1


@pytest.mark.parametrize(("name", "frames", "rate", "kmap"), CLIPS, ids=NAMES)
def test_z_is_up(load_clip, name, frames, rate, kmap):
    """Head above the feet (arm-only clip: shoulder above pelvis) in the first complete frame."""
    keypoints = keypoint_positions(load_clip(name), kmap)
    if "left_ankle" in keypoints:
        top, bottom = (
            keypoints["head"],
            np.stack([keypoints["left_ankle"], keypoints["right_ankle"]]),
        )
        bottom_z = bottom[..., 2].max(axis=0)
        margin = 0.8  # squats and kicks start mid-motion; standing would give ~1.4 m
    else:
        top, bottom_z = keypoints["right_shoulder"], keypoints["waist"][:, 2]
        margin = 0.3
    complete = np.nonzero(np.isfinite(top[:, 2]) & np.isfinite(bottom_z))[0]
    first = complete[0]
    assert top[first, 2] - bottom_z[first] > margin


def test_opensim_gaps_are_nan_not_dropped(load_clip):
    motion = load_clip("opensim_walking2.c3d")
    assert len(motion.names) == 44
    missing = np.isnan(motion.positions[..., 0])
    # README caveat 7: ~50 % of samples missing; all 44 points together only in frames 424-837.
    assert 0.45 < missing.mean() < 0.55
    complete = np.nonzero(~missing.any(axis=1))[0] + 1
    assert (complete[0], complete[-1], complete.size) == (424, 837, 414)
    assert motion.meta["analog_channels"] == 12


def test_c3d_walks_along_x_in_metres(load_clip):
    motion = load_clip("opensim_walking2.c3d")
    head = np.stack([motion.joint(n) for n in ("LFHD", "RFHD", "LBHD", "RBHD")])
    # README: walking along +X, head markers span ~6.5 m (in mm in the file).
    assert 6.3 < np.nanmax(head[..., 0]) - np.nanmin(head[..., 0]) < 6.7
    assert 1.5 < np.nanmedian(head[..., 2]) < 1.85


def test_pyomeca_labels_keep_their_prefix(load_clip):
    motion = load_clip("pyomeca_upper_limb_box_lift.c3d")
    assert len(motion.names) == 51
    assert "Daphnee:ASISr" in motion.names and "boite:gauche_ext" in motion.names
    np.testing.assert_array_equal(motion.joint("ASISr"), motion.joint("Daphnee:ASISr"))
    assert np.isnan(motion.positions).mean() < 0.02  # README: 99 % complete
