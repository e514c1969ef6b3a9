# SPDX-License-Identifier: Apache-2.0
"""Each export format written and re-read by an independent reader (numpy, pickle, json)."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.dataset import export_run, resample_run
from qpretarget.dataset.exports import parse_formats
from qpretarget.errors import UnknownNameError
from qpretarget.motion import load_motion
from qpretarget.retarget import Retargeter
from qpretarget.trajectory import RobotTrajectory

from .conftest import MOCAP

#: The G1 joint order of mjlab's / BeyondMimic's scripts/csv_to_npz.py (the joint-name list it
#: passes for its G1 scene; read in its public source, docs/formats.md): columns 7.. of the CSV.
MJLAB_G1_JOINTS = [
    f"{s}_{j}_joint" for s in ("left", "right")
    for j in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")
] + ["waist_yaw_joint", "waist_roll_joint", "waist_pitch_joint"] + [
    f"{s}_{j}_joint" for s in ("left", "right")
    for j in ("shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow", "wrist_roll",
              "wrist_pitch", "wrist_yaw")
]  # fmt: skip


@pytest.fixture(scope="module")
def run_and_robot(repo_dir):
    ctrl = Controller.from_yaml(repo_dir / "configs" / "g1_whole_body.yaml")
    motion = load_motion(MOCAP / "cmu_16_33_walk_stop.bvh").slice(0.0, 1.5)
    return Retargeter(ctrl).retarget(motion), ctrl.robot


def test_csv_is_the_lafan1_layout_with_a_sidecar(tmp_path, run_and_robot):
    run, robot = run_and_robot
    out = resample_run(run, 30.0, robot=robot)
    files = export_run(out, tmp_path / "clip", ["csv"], robot=robot, source="walk_stop.bvh")
    table = np.loadtxt(tmp_path / "clip.csv", delimiter=",")  # BeyondMimic's reader
    side = json.loads((tmp_path / "clip.json").read_text())
    assert {f.name for f in files} == {"clip.csv", "clip.json"}
    assert table.shape == (len(out.t), 7 + 29)
    assert side["joint_names"] == robot.joint_names  # URDF actuated-joint order
    assert side["joint_names"] == MJLAB_G1_JOINTS  # what the trainers' reader assumes
    assert side["columns"][7:] == robot.joint_names and side["quaternion"] == "xyzw"
    assert side["fps"] == 30.0 and side["frames"] == len(table)
    np.testing.assert_allclose(np.linalg.norm(table[:, 3:7], axis=1), 1.0, atol=1e-8)
    # Columns are pinocchio's q (x y z, qx qy qz qw, joints) to the printed 10 digits.
    np.testing.assert_allclose(table, out.q, rtol=1e-9, atol=1e-9)
    assert len(side["contacts"]) == len(table) and len(side["contacts"][0]) == 2


def test_pkl_is_gmr_robot_motion(tmp_path, run_and_robot):
    run, robot = run_and_robot
    export_run(run, tmp_path / "clip", ["pkl"], robot=robot)
    with open(tmp_path / "clip.pkl", "rb") as f:
        data = pickle.load(f)
    assert set(data) == {"fps", "root_pos", "root_rot", "dof_pos", "local_body_pos",
                         "link_body_list"}  # fmt: skip
    T = len(run.t)
    assert data["fps"] == pytest.approx(100.0)
    assert data["root_pos"].shape == (T, 3) and data["root_rot"].shape == (T, 4)
    assert data["dof_pos"].shape == (T, 29)
    assert data["local_body_pos"].shape == (T, len(data["link_body_list"]), 3)
    assert "pelvis" in data["link_body_list"]
    pelvis = data["link_body_list"].index("pelvis")
    np.testing.assert_allclose(data["local_body_pos"][:, pelvis], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(data["root_rot"], axis=1), 1.0, atol=1e-9)


def test_npz_round_trips(tmp_path, run_and_robot):
    run, robot = run_and_robot
    export_run(run, tmp_path / "clip", ["npz"], robot=robot)
    back = RobotTrajectory.load(tmp_path / "clip.npz")
    np.testing.assert_array_equal(back.q, run.q)
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


def test_unknown_format_names_the_close_one():
    with pytest.raises(UnknownNameError, match="csv"):
        parse_formats("cvs,npz")
