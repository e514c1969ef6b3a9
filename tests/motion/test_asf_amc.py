# SPDX-License-Identifier: Apache-2.0
"""Tests of the ASF/AMC reader: agreement with the BVH re-encodings, CRLF, malformed files."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import MotionFormatError, read_asf, read_asf_amc

# BVH re-encodings vs their AMC source (README section 5). The README bound is 7e-5 CMU units
# = 4.0e-6 m (BVH angles rounded to 1e-4 deg, offsets to 1e-6 units); we allow 1e-5 m
# (1.8e-4 units) because we compare every frame and every joint, not 200 frames per clip.
FK_TOLERANCE_M = 1e-5


@pytest.mark.parametrize(
    ("asf", "amc", "bvh", "first_amc_frame"),
    [
        ("cmu_16.asf", "cmu_16_15.amc", "cmu_16_15_walk.bvh", 3),  # README: frames 3-471
        ("cmu_14.asf", "cmu_14_37.amc", "cmu_14_37_drink_soda.bvh", 1),  # frames 1-513
    ],
)
def test_amc_matches_its_bvh_reencoding(mocap, load_clip, asf, amc, bvh, first_amc_frame):
    from_amc = read_asf_amc(mocap / asf, mocap / amc)
    from_bvh = load_clip(bvh)
    assert from_amc.names == from_bvh.names and from_amc.parents == from_bvh.parents
    assert from_amc.meta["first_frame"] == 1
    start = first_amc_frame - from_amc.meta["first_frame"]
    window = from_amc[start : start + len(from_bvh)]
    assert len(window) == len(from_bvh)
    np.testing.assert_allclose(window.positions, from_bvh.positions, atol=FK_TOLERANCE_M, rtol=0)
    # Rotations: 1e-4 deg rounding per angle, chains of up to 8 joints -> 1e-5 rad.
    np.testing.assert_allclose(window.orientations, from_bvh.orientations, atol=1e-5, rtol=0)
    # And the BVH does not match the AMC frames next to the right ones (the offset matters).
    shifted = from_amc[start + 1 : start + 1 + len(from_bvh) - 1]
    assert np.abs(shifted.positions - from_bvh.positions[:-1]).max() > 100 * FK_TOLERANCE_M


def test_cgspeed_bvh_matches_amc_except_the_thorax_vector(load_clip):
    """README caveats 2-3: legs and spine agree; neck/arms shift by the 0.117 m thorax bone."""
    amc = load_clip("cmu_01_01.amc")
    cgspeed = load_clip("cgspeed_cmu_01_01_playground_jumps.bvh")  # its T-pose frame 0 dropped
    for ours, theirs in [
        ("lfemur", "LeftUpLeg"),
        ("rtoes_end", "RightToeBase_end"),
        ("thorax", "Spine1"),
        ("root", "Hips"),
    ]:
        np.testing.assert_allclose(amc.joint(ours), cgspeed.joint(theirs), atol=FK_TOLERANCE_M)
    shift = np.linalg.norm(amc.joint("lhumerus") - cgspeed.joint("LeftArm"), axis=1)
    np.testing.assert_allclose(shift, 2.06 * 0.0254 / 0.45, atol=0.002)


def test_crlf_and_lf_files_read_the_same(mocap, tmp_path):
    asf_text = (mocap / "cmu_16.asf").read_bytes()
    amc_text = (mocap / "cmu_16_15.amc").read_bytes()
    assert b"\r\n" not in asf_text
    (tmp_path / "crlf.asf").write_bytes(asf_text.replace(b"\n", b"\r\n"))
    (tmp_path / "crlf.amc").write_bytes(amc_text.replace(b"\n", b"\r\n"))
    lf = read_asf_amc(mocap / "cmu_16.asf", mocap / "cmu_16_15.amc")
    crlf = read_asf_amc(tmp_path / "crlf.asf", tmp_path / "crlf.amc")
    np.testing.assert_array_equal(lf.positions, crlf.positions)
    assert b"\r\n" in (mocap / "cmu_01_01.amc").read_bytes()[:200]  # the real CRLF pair loads
    assert len(read_asf(mocap / "cmu_01.asf").bones) == 30


def test_asf_units_and_skeleton(mocap):
    skeleton = read_asf(mocap / "cmu_16.asf")
    assert skeleton.length_unit == 0.45 and skeleton.angle_unit == "deg"
    assert skeleton.root_order == ["tx", "ty", "tz", "rx", "ry", "rz"]
    femur = skeleton.bones["lfemur"]
    assert femur.dof == ["rx", "ry", "rz"] and femur.axis_order == "XYZ"
    assert femur.limits == [(-160.0, 20.0), (-70.0, 70.0), (-60.0, 70.0)]
    assert skeleton.children["thorax"] == ["lowerneck", "lclavicle", "rclavicle"]


def test_default_length_scale_comes_from_asf_units(mocap):
    motion = read_asf_amc(mocap / "cmu_14.asf", mocap / "cmu_14_37.amc")
    assert motion.meta["length_scale"] == pytest.approx(0.0254 / 0.45)
    assert motion.meta["length_unit"] == "inch/0.45"
    raw = read_asf_amc(mocap / "cmu_14.asf", mocap / "cmu_14_37.amc", length_scale=1.0)
    np.testing.assert_allclose(raw.positions * 0.0254 / 0.45, motion.positions, atol=1e-12)


def _amc_lines(mocap) -> list[str]:
    return (mocap / "cmu_16_15.amc").read_text().splitlines()


def _write(tmp_path, lines):
    path = tmp_path / "broken.amc"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_missing_frame_is_named(mocap, tmp_path):
    lines = _amc_lines(mocap)
    assert lines[123] == "5" and lines[153] == "6"
    del lines[123:153]  # frame 5 and its 29 bone lines
    with pytest.raises(
        MotionFormatError,
        match=r"broken\.amc, line 124 \(frame 6\): expected frame 5 after frame 4, found frame 6",
    ):
        read_asf_amc(mocap / "cmu_16.asf", _write(tmp_path, lines))


def test_bad_value_is_named(mocap, tmp_path):
    lines = _amc_lines(mocap)
    assert lines[183] == "7" and lines[184].startswith("root ")
    lines[185] = "lowerback 4.4 1.2.3 2.9"
    with pytest.raises(
        MotionFormatError,
        match=r"line 186 \(frame 7\): bone 'lowerback' expects numbers, found .*'1\.2\.3'",
    ):
        read_asf_amc(mocap / "cmu_16.asf", _write(tmp_path, lines))


def test_missing_bone_line_is_named(mocap, tmp_path):
    lines = _amc_lines(mocap)
    assert lines[273] == "10"
    removed = lines.pop(280)
    bone = removed.split()[0]
    with pytest.raises(
        MotionFormatError, match=rf"\(frame 10\): frame 10 \(line 274\) lacks \['{bone}'\]"
    ):
        read_asf_amc(mocap / "cmu_16.asf", _write(tmp_path, lines))


def test_wrong_value_count_is_named(mocap, tmp_path):
    lines = _amc_lines(mocap)
    lines[184] = lines[184] + " 0.0"  # root of frame 7 gets a 7th value
    with pytest.raises(
        MotionFormatError, match=r"line 185 \(frame 7\): bone 'root' expects 6 values .* found 7"
    ):
        read_asf_amc(mocap / "cmu_16.asf", _write(tmp_path, lines))


def test_malformed_asf_is_named(mocap, tmp_path):
    lines = (mocap / "cmu_16.asf").read_text().splitlines()
    index = next(i for i, line in enumerate(lines) if line.strip() == "name lfemur")
    lines[index + 1] = "     direction 0.34202 -0.939693"
    path = tmp_path / "broken.asf"
    path.write_text("\n".join(lines))
    with pytest.raises(
        MotionFormatError, match=rf"broken\.asf, line {index + 2}: expected 3 numbers for direction"
    ):
        read_asf(path)
