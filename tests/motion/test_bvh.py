# SPDX-License-Identifier: Apache-2.0
"""Tests of the BVH reader: malformed files, channel orders, End Sites, units."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from qpretarget.motion import MotionFormatError, read_bvh
from qpretarget.motion.bvh import guess_length_scale, rate_from_frame_time

WALK = "cmu_16_15_walk.bvh"  # HIERARCHY lines 1-184, MOTION line 185, Frames line 186, data 188-656


def _walk_lines(mocap) -> list[str]:
    return (mocap / WALK).read_text().splitlines()


def _write(tmp_path, lines: list[str], name: str = "broken.bvh"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_walk_layout_assumed_by_these_tests(mocap):
    lines = _walk_lines(mocap)
    assert lines[184] == "MOTION" and lines[185] == "Frames: 469" and len(lines) == 656


def test_truncated_motion_names_line_and_counts(mocap, tmp_path):
    path = _write(tmp_path, _walk_lines(mocap)[:-10])  # 459 of 469 rows
    with pytest.raises(
        MotionFormatError,
        match=r"broken\.bvh, line 646: motion section is truncated: 'Frames: 469' \(line 186\) "
        r"but only 459 data rows",
    ):
        read_bvh(path)


def test_wrong_channel_count_names_line_and_frame(mocap, tmp_path):
    lines = _walk_lines(mocap)
    lines[286] = " ".join(lines[286].split()[:-1])  # line 287 = frame 100 loses a value
    with pytest.raises(
        MotionFormatError,
        match=r"line 287 \(frame 100\): expected 96 channel values .*found 95",
    ):
        read_bvh(_write(tmp_path, lines))


def test_extra_rows_are_an_error(mocap, tmp_path):
    lines = _walk_lines(mocap)
    path = _write(tmp_path, lines + [lines[-1]])
    with pytest.raises(MotionFormatError, match=r"line 657: more data rows than 'Frames: 469'"):
        read_bvh(path)


def test_non_numeric_value_names_line(mocap, tmp_path):
    lines = _walk_lines(mocap)
    words = lines[199].split()
    words[5] = "1.2.3"
    lines[199] = " ".join(words)
    with pytest.raises(MotionFormatError, match=r"line 200 \(frame 13\): expected finite numbers"):
        read_bvh(_write(tmp_path, lines))


def test_channel_declaration_mismatch_names_line(mocap, tmp_path):
    lines = _walk_lines(mocap)
    assert lines[8].strip() == "CHANNELS 3 Zrotation Yrotation Xrotation"
    lines[8] = "\t\tCHANNELS 3 Zrotation Yrotation"
    with pytest.raises(
        MotionFormatError, match=r"line 9: CHANNELS of 'lhipjoint' says 3 channels but lists 2"
    ):
        read_bvh(_write(tmp_path, lines))


def test_missing_brace_names_line(mocap, tmp_path):
    lines = _walk_lines(mocap)
    assert lines[6].strip() == "{"
    del lines[6]
    with pytest.raises(MotionFormatError, match=r"line 7: expected '\{', found 'OFFSET'"):
        read_bvh(_write(tmp_path, lines))


TWO_JOINTS = """HIERARCHY
ROOT hips
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {order}
  JOINT chest
  {{
    OFFSET 0 {length} 0
    CHANNELS 3 {order}
    End Site
    {{
      OFFSET {end}
    }}
  }}
}}
MOTION
Frames: {frames}
Frame Time: 0.01
{rows}
"""


@pytest.mark.parametrize("order", ["ZYX", "XYZ", "YXZ", "ZXY"])
def test_any_channel_order_matches_intrinsic_rotations(tmp_path, order):
    """BVH 'Xrotation Yrotation Zrotation' is R = Rx Ry Rz (scipy intrinsic 'XYZ')."""
    rng = np.random.default_rng(0)
    angles = rng.uniform(-170, 170, size=(5, 2, 3))
    root = rng.uniform(-1, 1, size=(5, 3))
    rows = "\n".join(
        " ".join(f"{v:.10f}" for v in np.concatenate([root[k], angles[k, 0], angles[k, 1]]))
        for k in range(5)
    )
    channels = " ".join(f"{axis}rotation" for axis in order)
    path = tmp_path / "two.bvh"
    path.write_text(TWO_JOINTS.format(order=channels, length=1.0, end="1 0 0", frames=5, rows=rows))
    motion = read_bvh(path, length_scale=1.0, up_axis="z")
    assert motion.names == ("hips", "chest", "chest_end")
    assert motion.parents == (-1, 0, 1)
    r_hips = Rotation.from_euler(order, angles[:, 0], degrees=True).as_matrix()
    r_chest = Rotation.from_euler(order, angles[:, 1], degrees=True).as_matrix()
    expected_chest = root + r_hips @ [0.0, 1.0, 0.0]
    expected_end = expected_chest + (r_hips @ r_chest) @ [1.0, 0.0, 0.0]
    # 1e-9: angles written with 10 decimals of a degree (2e-13 rad) on 1-2 m lever arms.
    np.testing.assert_allclose(motion.joint("chest"), expected_chest, atol=1e-9)
    np.testing.assert_allclose(motion.joint("chest_end"), expected_end, atol=1e-9)
    np.testing.assert_allclose(motion.joint_orientation("chest"), r_hips @ r_chest, atol=1e-9)
    np.testing.assert_allclose(motion.joint_orientation("chest_end"), r_hips @ r_chest, atol=1e-9)


def test_end_site_names_avoid_collisions(tmp_path):
    text = TWO_JOINTS.format(
        order="Zrotation Yrotation Xrotation", length=1, end="1 0 0", frames=1, rows="0 " * 9
    )
    text = text.replace("JOINT chest", "JOINT hips_end")
    path = tmp_path / "collide.bvh"
    path.write_text(text)
    assert read_bvh(path, length_scale=1.0).names == ("hips", "hips_end", "hips_end_end")


@pytest.mark.parametrize(
    ("length", "unit", "scale"),
    [(85.0, "cm", 0.01), (0.85, "m", 1.0), (850.0, "mm", 0.001), (33.0, "inch", 0.0254)],
)
def test_auto_length_scale_picks_a_human_unit(tmp_path, length, unit, scale):
    rows = "0 " * 9
    path = tmp_path / "unit.bvh"
    end = f"0 {length} 0"
    order = "Zrotation Yrotation Xrotation"
    path.write_text(TWO_JOINTS.format(order=order, length=length, end=end, frames=1, rows=rows))
    motion = read_bvh(path)  # rest extent = 2 * length: 1.70 m (1.68 m for the inch case)
    assert motion.meta["length_scale"] == scale
    assert motion.meta["length_unit"].startswith(unit + " (auto")
    # y-up (0, 2 L, 0) -> z-up (0, 0, 2 L)
    assert motion.joint("chest_end")[0] == pytest.approx([0.0, 0.0, 2 * length * scale])


def test_cmu_files_are_detected_as_cmu_units(load_clip):
    motion = load_clip("cmu_14_37_drink_soda.bvh")
    assert motion.meta["length_scale"] == pytest.approx(0.0254 / 0.45)
    assert motion.meta["length_unit"].startswith("CMU unit")


def test_explicit_length_scale_wins(mocap, load_clip):
    auto = load_clip(WALK)
    explicit = read_bvh(mocap / WALK, length_scale=0.0254 / 0.45)
    np.testing.assert_array_equal(auto.positions, explicit.positions)
    assert explicit.meta["length_unit"] == "explicit"
    with pytest.raises(ValueError, match="length_scale must be a positive number"):
        read_bvh(mocap / WALK, length_scale=-1.0)


def test_auto_length_scale_refuses_non_human_sizes():
    with pytest.raises(ValueError, match="pass length_scale=<metres per file unit>"):
        guess_length_scale(4.5)  # 4.5 m, 11 cm, 4.5 mm, 11 cm, 25 cm: nothing is 1-3 m


def test_y_up_and_z_up_readings_differ_by_the_documented_rotation(mocap, load_clip):
    y_up = load_clip(WALK)
    raw = read_bvh(mocap / WALK, up_axis="z")
    np.testing.assert_allclose(y_up.positions[..., [1, 2, 0]], raw.positions, atol=0)
    with pytest.raises(ValueError, match="up_axis must be 'y' or 'z'"):
        read_bvh(mocap / WALK, up_axis="x")


def test_rate_snapping():
    assert rate_from_frame_time(0.0083333) == 120.0
    assert rate_from_frame_time(0.00833333) == 120.0
    assert rate_from_frame_time(1 / 29.97) == pytest.approx(29.97)
    assert not math.isclose(rate_from_frame_time(0.0084), 120.0)
