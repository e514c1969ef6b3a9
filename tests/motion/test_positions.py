# SPDX-License-Identifier: Apache-2.0
"""Key-point files (npz, csv): layout, units and up axis, map choice, retargeting, bad input.

The files are written here from a real clip's key-points (CMU 16_33 walk-and-stop), so the
expected positions are known exactly; the SMPL naming is that clip's key-points renamed (a
synthetic naming of real motion, like a forward pass of SMPL-X would name them).
"""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import MotionFormatError, guess_keypoint_map, keypoint_positions
from qpretarget.motion.load import is_scanned_motion_file, load_motion

SMPL_NAMES = {
    "waist": "pelvis", "left_toe": "left_foot", "right_toe": "right_foot", "neck": "neck",
    "head": "head", "left_hand": None, "right_hand": None,
}  # fmt: skip


@pytest.fixture(scope="module")
def walk(load_clip):
    motion = load_clip("cmu_16_33_walk_stop.bvh")
    kp = keypoint_positions(motion)
    return motion, list(kp), np.stack([kp[n] for n in kp], axis=1)


def test_npz_in_mm_and_y_up_reads_back_in_metres_z_up(tmp_path, walk):
    motion, names, P = walk
    y_up_mm = np.stack([P[..., 0], P[..., 2], -P[..., 1]], axis=-1) * 1000.0
    path = tmp_path / "walk.keypoints.npz"
    np.savez(path, names=np.array(names), positions=y_up_mm, fps=motion.rate, up="y", units="mm")
    m = load_motion(path)
    # Tolerance: one float64 rounding of the mm -> m scale and the axis swap.
    np.testing.assert_allclose(m.positions, P, atol=1e-12, equal_nan=True)
    assert m.rate == pytest.approx(motion.rate) and m.orientations is None
    assert guess_keypoint_map(m).name == "identity"  # names are key-point names already


def test_csv_with_smpl_names_picks_the_smpl_map_and_retargets(tmp_path, walk, repo_dir):
    from qpretarget import Controller
    from qpretarget.motion import HumanMotion
    from qpretarget.retarget import Retargeter

    motion, names, P = walk
    keep = [i for i, n in enumerate(names) if SMPL_NAMES.get(n, n) is not None]
    smpl = [SMPL_NAMES.get(names[i], names[i]) for i in keep]
    header = "frame," + ",".join(f"{n}_{a}" for n in smpl for a in "xyz")
    rows = [f"{k}," + ",".join(f"{v:.9f}" for v in P[k, keep].ravel()) for k in range(len(P))]
    path = tmp_path / "walk.keypoints.csv"
    path.write_text(f"# fps: {motion.rate}\n{header}\n" + "\n".join(rows) + "\n")
    m = load_motion(path)
    assert guess_keypoint_map(m).name == "smpl"
    np.testing.assert_allclose(m.positions, P[:, keep], atol=1e-9)  # 9 printed decimals
    # The same points under key-point names (SMPL has no hand joint: the map extends the
    # forearm past the wrist by half its length).
    kp = {names[i]: m.positions[:, j] for j, i in enumerate(keep)}
    for s in ("left", "right"):
        w, e = kp[f"{s}_wrist"], kp[f"{s}_elbow"]
        kp[f"{s}_hand"] = w + 0.5 * (w - e)
    same = HumanMotion(
        t=m.t, names=tuple(kp), positions=np.stack(list(kp.values()), axis=1),
        parents=(-1,) * len(kp), rate=m.rate, source="key-point names",
    )  # fmt: skip
    runs = []
    for mm in (m, same):
        ctrl = Controller.from_yaml(repo_dir / "configs" / "g1_whole_body.yaml")
        runs.append(Retargeter(ctrl).retarget(mm, progress=False))
    assert "held" not in set(np.asarray(runs[0].status).astype(str))
    # The smpl map picks exactly these points: the same q (1e-9: summation order only).
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-9)


def test_folder_scan_takes_only_keypoint_double_endings():
    assert is_scanned_motion_file("a/walk.keypoints.npz")
    assert is_scanned_motion_file("a/walk.KEYPOINTS.csv")
    assert not is_scanned_motion_file("out/walk.npz")  # a run file of a previous batch
    assert not is_scanned_motion_file("out/walk.csv")  # a CSV export
    assert is_scanned_motion_file("a/walk.bvh")


@pytest.mark.parametrize(
    "content, message",
    [
        ({"names": ["waist"], "positions": np.zeros((3, 1, 3))}, "frame rate"),
        ({"names": ["waist"], "positions": np.zeros((3, 2, 3)), "fps": 30.0}, r"\(T, 1, 3\)"),
        ({"q": np.zeros((3, 7)), "t": np.arange(3.0)}, "robot run"),
        ({"positions": np.zeros((3, 1, 3)), "fps": 30.0}, "missing"),
        ({"names": ["waist"], "positions": np.zeros((3, 1, 3)), "fps": -1.0}, "positive"),
        ({"names": ["waist"], "positions": np.full((3, 1, 3), np.inf), "fps": 30.0}, "inf"),
        ({"names": ["waist"], "positions": np.zeros((3, 1, 3)), "fps": 30.0, "up": "x"}, "up"),
        ({"names": ["waist"], "positions": np.zeros((0, 1, 3)), "fps": 30.0}, "no frame"),
    ],
)
def test_bad_npz_is_a_clear_error(tmp_path, content, message):
    path = tmp_path / "bad.npz"
    np.savez(path, **content)
    with pytest.raises(MotionFormatError, match=message):
        load_motion(path)


@pytest.mark.parametrize(
    "text, message",
    [
        ("time,waist_x,waist_y\n0,1,2\n", r"lacks its \['z'\]"),
        ("stamp,waist_x,waist_y,waist_z\n0,1,2,3\n", "first column"),
        ("t,waist_x,waist_y,waist_z\n0,1,two,3\n", "not a number"),
        ("t,waist_x,waist_y,waist_z\n0,1,2,3\n0,1,2,3\n", "strictly increasing"),
        ("t,waist,waist_y,waist_z\n0,1,2,3\n", "NAME_x"),
        ("", "no header"),
    ],
)
def test_bad_csv_is_a_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MotionFormatError, match=message):
        load_motion(path)
