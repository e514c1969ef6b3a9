# SPDX-License-Identifier: Apache-2.0
"""Tests of the C3D reader: units, missing samples, prefixes, marker maps, truncated files."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import MotionFormatError, UnknownMotionJointError, read_c3d
from qpretarget.motion.keypoints import keypoint_positions

PYOMECA = "pyomeca_upper_limb_box_lift.c3d"


def test_millimetres_become_metres(mocap, load_clip):
    metres = load_clip(PYOMECA)
    assert metres.meta["length_scale"] == 0.001 and metres.meta["length_unit"] == "mm"
    millimetres = read_c3d(mocap / PYOMECA, length_scale=1.0)
    np.testing.assert_allclose(millimetres.positions * 0.001, metres.positions, atol=1e-12)
    # README: ASIS at z ~ 0.18 m, acromion ~ 0.68 m in this lab frame.
    assert np.nanmedian(metres.joint("ASISr")[:, 2]) == pytest.approx(0.18, abs=0.03)
    assert np.nanmedian(metres.joint("ACRO_tip")[:, 2]) == pytest.approx(0.68, abs=0.03)


def test_missing_samples_are_nan_and_kept(mocap, load_clip):
    import c3d

    motion = load_clip("opensim_walking2.c3d")
    with (mocap / "opensim_walking2.c3d").open("rb") as handle:
        residuals = np.array([p[:, 3] for _, p, _ in c3d.Reader(handle).read_frames()])
    np.testing.assert_array_equal(np.isnan(motion.positions[..., 0]), residuals < 0)
    assert np.isnan(motion.positions).any(axis=2).sum() == (residuals < 0).sum()


def test_marker_map_gives_keypoints(mocap):
    motion = read_c3d(mocap / PYOMECA, marker_map="pyomeca_upper_limb")
    assert motion.names == (
        "waist",
        "neck",
        "right_shoulder",
        "right_elbow",
        "right_wrist",
        "right_hand",
    )
    assert motion.meta["keypoint_map"] == "pyomeca_upper_limb"
    raw = read_c3d(mocap / PYOMECA)
    elbow = (raw.joint("Daphnee:EPICl") + raw.joint("Daphnee:EPICm")) / 2
    np.testing.assert_allclose(motion.joint("right_elbow"), elbow, atol=1e-12)
    # A motion made of key-points maps to itself.
    np.testing.assert_array_equal(
        keypoint_positions(motion)["right_wrist"], motion.joint("right_wrist")
    )


def test_marker_map_as_dict_and_average_propagates_nan(mocap):
    motion = read_c3d(
        mocap / "opensim_walking2.c3d",
        marker_map={"name": "mine", "keypoints": {"left_knee": ["LLFC", "LMFC"], "neck": "C7"}},
    )
    knee = motion.joint("left_knee")
    valid = np.nonzero(np.isfinite(knee[:, 0]))[0] + 1
    assert (valid[0], valid[-1]) == (424, 837)  # the condyles exist only in frames 424-837
    assert np.isfinite(motion.joint("neck")[330]).all()  # C7 is present from frame 326


def test_marker_map_with_unknown_marker_fails_with_close_match(mocap):
    with pytest.raises(UnknownMotionJointError, match="'LASIS'.*Did you mean 'LASI'"):
        read_c3d(mocap / "opensim_walking2.c3d", marker_map={"keypoints": {"waist": "LASIS"}})


def test_truncated_file_is_an_error(mocap, tmp_path):
    data = (mocap / PYOMECA).read_bytes()
    path = tmp_path / "cut.c3d"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(
        MotionFormatError, match=r"cut\.c3d \(frame \d+\): header says frames 1\.\.580"
    ):
        read_c3d(path)


def test_not_a_c3d_file(tmp_path):
    path = tmp_path / "text.c3d"
    path.write_text("hello")
    with pytest.raises(MotionFormatError, match=r"text\.c3d: not a readable C3D file"):
        read_c3d(path)
