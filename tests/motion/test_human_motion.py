# SPDX-License-Identifier: Apache-2.0
"""Tests of HumanMotion: look-ups, errors, slicing, read-only arrays, axis conventions."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import HumanMotion, MotionError, UnknownMotionJointError, read_bvh
from qpretarget.motion._kinematics import Y_UP_TO_Z_UP


def _toy(num_frames: int = 10) -> HumanMotion:
    t = np.arange(num_frames) / 10.0
    positions = np.zeros((num_frames, 3, 3))
    positions[:, 1, 2] = 1.0
    positions[:, 2, 0] = t
    return HumanMotion(
        t=t,
        names=["Subject:pelvis", "Subject:head", "marker"],
        positions=positions,
        parents=[-1, -1, -1],
        rate=10.0,
        source="toy",
    )


def test_unknown_joint_lists_close_matches(load_clip):
    motion = load_clip("cmu_16_15_walk.bvh")
    with pytest.raises(UnknownMotionJointError, match=r"'lhumerous' .*Did you mean 'lhumerus'"):
        motion.joint("lhumerous")
    # Also a KeyError (lookup) and a MotionError (package base class).
    with pytest.raises(KeyError):
        motion.joint("nope")
    with pytest.raises(MotionError):
        motion.joint("nope")


def test_prefixed_labels_resolve_without_prefix():
    motion = _toy()
    np.testing.assert_array_equal(motion.joint("head")[:, 2], 1.0)
    assert motion.index("Subject:head") == motion.index("head") == 1
    with pytest.raises(UnknownMotionJointError, match="Did you mean 'head'"):
        motion.joint("haed")


def test_ambiguous_unprefixed_label_is_an_error():
    motion = HumanMotion(
        t=[0.0, 0.1],
        names=["A:knee", "B:knee"],
        positions=np.zeros((2, 2, 3)),
        parents=[-1, -1],
        rate=10.0,
    )
    with pytest.raises(UnknownMotionJointError, match="ambiguous, it matches 'A:knee', 'B:knee'"):
        motion.joint("knee")


def test_arrays_are_read_only():
    motion = _toy()
    with pytest.raises(ValueError, match="read-only"):
        motion.positions[0, 0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        motion.joint("marker")[0, 0] = 1.0


def test_constructor_validates_shapes():
    with pytest.raises(ValueError, match=r"positions must have shape \(T, J, 3\) = \(2, 1, 3\)"):
        HumanMotion(t=[0, 1], names=["a"], positions=np.zeros((2, 2, 3)), parents=[-1], rate=1.0)
    with pytest.raises(ValueError, match="repeated: \\['a'\\]"):
        HumanMotion(
            t=[0], names=["a", "a"], positions=np.zeros((1, 2, 3)), parents=[-1, -1], rate=1
        )
    with pytest.raises(ValueError, match="strictly increasing"):
        HumanMotion(t=[0, 0], names=["a"], positions=np.zeros((2, 1, 3)), parents=[-1], rate=1.0)


def test_slice_keeps_timestamps_and_half_open_interval(load_clip):
    motion = load_clip("cmu_16_15_walk.bvh")
    part = motion.slice(1.0, 2.0)
    assert len(part) == 120  # 120 Hz, [1, 2) s
    assert part.t[0] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(part.positions, motion.positions[120:240])
    np.testing.assert_array_equal(part.orientations, motion.orientations[120:240])
    assert len(motion.slice(3.0)) == len(motion) - 360
    with pytest.raises(ValueError, match=r"no frame .* the clip spans \[0.0000, 3.9000\] s"):
        motion.slice(10.0, 11.0)


def test_frame_indexing_and_len(load_clip):
    motion = load_clip("cmu_16_15_walk.bvh")
    assert len(motion) == 469
    half = motion[::2]
    assert len(half) == 235 and half.rate == 60.0
    with pytest.raises(TypeError, match="frame slices only"):
        motion["root"]


def test_segment_length_is_median_and_ignores_missing():
    motion = _toy()
    assert motion.segment_length("head", "pelvis") == pytest.approx(1.0)
    positions = np.array(motion.positions)
    positions[:4, 1] = np.nan
    positions[4:, 1, 2] = [1.0, 1.0, 1.0, 5.0, 5.0, 1.0]  # median over valid frames = 1
    holey = HumanMotion(
        t=motion.t, names=motion.names, positions=positions, parents=motion.parents, rate=10.0
    )
    assert holey.segment_length("head", "pelvis") == pytest.approx(1.0)


def test_up_axis_conversion_is_a_proper_rotation():
    np.testing.assert_allclose(Y_UP_TO_Z_UP @ Y_UP_TO_Z_UP.T, np.eye(3), atol=0)
    assert np.linalg.det(Y_UP_TO_Z_UP) == pytest.approx(1.0)
    np.testing.assert_array_equal(Y_UP_TO_Z_UP @ [0, 1, 0], [0, 0, 1])  # y up -> z up


def test_cmu_rest_pose_faces_x_with_left_arm_along_y(mocap, tmp_path):
    """The documented convention: CMU rest pose (y up, facing +Z) -> facing +X, left +Y, z up."""
    text = (mocap / "cmu_16_15_walk.bvh").read_text()
    header = text[: text.index("MOTION")]
    rest = tmp_path / "rest.bvh"
    rest.write_text(header + "MOTION\nFrames: 1\nFrame Time: 0.0083333\n" + " ".join(["0"] * 96))
    motion = read_bvh(rest)
    arm = motion.joint("lwrist")[0] - motion.joint("lhumerus")[0]
    np.testing.assert_allclose(arm / np.linalg.norm(arm), [0, 1, 0], atol=1e-6)
    foot = motion.joint("ltoes_end")[0] - motion.joint("lfoot")[0]
    assert foot[0] > 0.1 and foot[2] < 0  # toes point forward (+X) and down
    assert motion.joint("head_end")[0, 2] - motion.joint("ltoes_end")[0, 2] > 1.4
    # Orientations are relative to the rest pose: identity there.
    np.testing.assert_allclose(motion.orientations[0], np.broadcast_to(np.eye(3), (38, 3, 3)))


def test_orientations_are_rotations(load_clip):
    motion = load_clip("cmu_131_04_dance_spin.bvh")
    R = motion.orientations[::50]
    identity = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), identity, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def test_repr_names_source_and_size(load_clip):
    text = repr(load_clip("cmu_16_15_walk.bvh"))
    assert "cmu_16_15_walk.bvh" in text and "frames=469" in text and "rate=120 Hz" in text


def _walker(frames: int = 240, rate: float = 120.0) -> np.ndarray:
    """Three points moving smoothly (a 1 m/s walk with a 2 Hz arm swing): (T, 3, 3) [m]."""
    t = np.arange(frames) / rate
    base = np.stack([t, np.zeros_like(t), np.full_like(t, 1.0)], axis=1)
    arm = base + np.stack([0.3 * np.sin(4 * np.pi * t), 0.2 + 0 * t, 0 * t], axis=1)
    foot = base + np.stack([0 * t, -0.1 + 0 * t, -0.9 + 0.05 * np.sin(2 * np.pi * t)], axis=1)
    return np.stack([base, arm, foot], axis=1)


def test_leading_cut_finds_a_reference_pose_and_a_dropout():
    from qpretarget.motion.human_motion import leading_cut

    p = _walker()
    assert leading_cut(p)[0] == 0  # continuous motion: nothing dropped
    tpose = p.copy()
    tpose[0, 1] += [0.0, 0.6, 0.5]  # frame 0: the arm held out (a T-pose)
    n, jump, largest = leading_cut(tpose)
    assert n == 1
    assert jump == pytest.approx(np.hypot(0.6, 0.5), abs=0.02)  # plus one frame of motion
    assert largest < 0.05  # a 1 m/s walk with a swinging arm: about 1-2 cm per frame
    dropout = p.copy()
    dropout[:2, 1] = dropout[:2, 0]  # frames 0-1: the arm snapped onto the base (CMU 16_15)
    assert leading_cut(dropout)[0] == 2
    # A fast motion from the first frame is not a cut: 3x its own largest later jump is the bar.
    fast = p.copy()
    fast[:, 1, 0] += 0.5 * np.sin(np.arange(len(p)) * 0.8)  # a 0.5 m, 15 Hz flail throughout
    assert leading_cut(fast)[0] == 0
    # Missing points (NaN) are ignored; a clip shorter than twice the search is left alone.
    gappy = tpose.copy()
    gappy[5:50, 2] = np.nan
    assert leading_cut(gappy)[0] == 1
    assert leading_cut(tpose[:15])[0] == 0


def test_without_leading_cut_keeps_timestamps_and_says_what_it_dropped():
    p = _walker()
    p[0, 1] += [0.0, 0.6, 0.5]
    t = np.arange(len(p)) / 120.0
    m = HumanMotion(t=t, names=("base", "arm", "foot"), positions=p, parents=(-1, 0, 0),
                    rate=120.0, source="/x/clip.bvh")  # fmt: skip
    cut = m.without_leading_cut()
    assert len(cut) == len(m) - 1 and cut.t[0] == t[1]
    assert cut.meta["dropped_leading_frames"] == 1
    (note,) = cut.meta["notes"]
    assert "frame 0 of clip.bvh dropped" in note and "keep_leading_cut=True" in note
    assert cut.without_leading_cut() is cut  # nothing left to drop
