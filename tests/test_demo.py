# SPDX-License-Identifier: Apache-2.0
"""The built-in human motion and the ``demo`` / ``retarget`` commands."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from qpretarget.cli import main
from qpretarget.motion.builtin import builtin_motion, human_model, scripted_joints
from qpretarget.motion.phases import detect_support_phases
from qpretarget.retarget.retargeter import whole_body_config
from qpretarget.trajectory import RobotTrajectory

REPO = Path(__file__).resolve().parents[1]
MOCAP = REPO.parent / "shared" / "data" / "mocap"


@pytest.fixture(scope="module")
def motion():
    return builtin_motion()


def test_builtin_motion_is_a_human_with_the_scripted_moves(motion):
    assert motion.rate == 60.0 and motion.duration == pytest.approx(10.2)
    names = set(motion.names)
    assert {"waist", "head", "left_hand", "right_hand", "left_ankle", "right_toe"} <= names
    p = {n: motion.joint(n) for n in motion.names}
    # Human proportions from the model: thigh 0.44 m, upper arm 0.28 m, head top ~1.66 m.
    thigh = np.linalg.norm(p["left_knee"] - p["left_hip"], axis=1)
    assert np.allclose(thigh, 0.439, atol=1e-3)
    assert 1.55 < p["head"][0, 2] < 1.75
    # Feet on the ground: the left ankle never moves (IK to 1e-5 m); soles at z = 0.
    assert np.abs(p["left_ankle"] - p["left_ankle"][0]).max() < 1e-5
    assert p["left_ankle"][0, 2] == pytest.approx(0.077, abs=1e-6)
    t = motion.t
    # Wave: right hand above the head; reach: left hand on the right side; squat: waist down
    # 0.2 m; side step: right foot 15 cm further right and lifted 8 cm on the way.
    assert p["right_hand"][np.searchsorted(t, 2.0), 2] > p["head"][0, 2] - 0.05
    assert p["left_hand"][np.searchsorted(t, 4.2), 1] < -0.2
    assert p["waist"][0, 2] - p["waist"][np.searchsorted(t, 6.2), 2] == pytest.approx(0.2, abs=1e-6)
    assert p["right_ankle"][-1, 1] - p["right_ankle"][0, 1] == pytest.approx(-0.15, abs=1e-5)
    assert p["right_ankle"][:, 2].max() - p["right_ankle"][0, 2] == pytest.approx(0.08, abs=1e-3)


def test_builtin_motion_has_one_step_of_the_right_foot(motion):
    feet = {
        s: np.stack([motion.joint(f"{s}_ankle"), motion.joint(f"{s}_toe")], axis=1)
        for s in ("left", "right")
    }
    phases = detect_support_phases(motion.t, feet["left"], feet["right"])
    changes = [str(phases[0])] + [
        str(phases[k]) for k in range(1, len(phases)) if phases[k] != phases[k - 1]
    ]
    assert changes == ["double", "left", "double"]


def test_scripted_joints_are_within_the_model_limits():
    model = human_model()
    for t in np.arange(0.0, 10.2, 0.05):
        for joint, value in scripted_joints(float(t)).items():
            q = model.joints[model.getJointId(joint)].idx_q
            assert model.lowerPositionLimit[q] - 1e-9 <= value <= model.upperPositionLimit[q]


def test_demo_command_prints_a_summary_and_writes_the_run(tmp_path, capsys):
    out = tmp_path / "demo.npz"
    assert main(["demo", "--seconds", "3", "-o", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    for line in ("qpretarget demo", "ticks/s", "tracking RMSE per task", "left_hand",
                 "joint limits 0 violation(s)", "feet drift", f"wrote {out}"):  # fmt: skip
        assert line in text
    run = RobotTrajectory.load(out)
    assert len(run.t) == 301 and run.robot == "g1"  # 3 s at 100 Hz, both ends included


def _config_file(tmp_path: Path) -> Path:
    path = REPO / "configs" / "g1_whole_body.yaml"
    if path.is_file() and (yaml.safe_load(path.read_text()) or {}).get("retarget"):
        return path
    path = tmp_path / "g1_whole_body.yaml"
    path.write_text(yaml.safe_dump(whole_body_config("g1"), sort_keys=False))
    return path


def test_retarget_command_on_a_walk_excerpt(tmp_path, capsys):
    out = tmp_path / "walk.npz"
    clip = MOCAP / "cmu_16_33_walk_stop.bvh"
    args = ["retarget", str(_config_file(tmp_path)), str(clip), "-o", str(out),
            "--start", "1.0", "--end", "1.6", "--quiet"]  # fmt: skip
    assert main(args) == 0
    text = capsys.readouterr().out
    assert (
        "cmu_16_33_walk_stop.bvh -> g1 (cmu key-points, poubel scaling, 120 Hz -> 100 Hz)" in text
    )
    run = RobotTrajectory.load(out)
    assert run.t[0] == pytest.approx(1.0) and run.t[-1] == pytest.approx(1.59, abs=1e-9)
    # --rate changes the control rate.
    assert main(args[:-1] + ["--rate", "50", "--quiet"]) == 0
    assert np.allclose(np.diff(RobotTrajectory.load(out).t), 0.02)


def test_retarget_command_drops_a_t_pose_first_frame_and_says_so(tmp_path, capsys):
    # cgspeed's CMU conversions start with a T-pose frame (README caveat 2): calibrating on it
    # and counting the jump from it as motion made the human 34 steps instead of 25.
    out = tmp_path / "jumps.npz"
    clip = MOCAP / "cgspeed_cmu_01_01_playground_jumps.bvh"
    args = ["retarget", str(_config_file(tmp_path)), str(clip), "-o", str(out),
            "--end", "0.5", "--quiet"]  # fmt: skip
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "note: frame 0 of cgspeed_cmu_01_01_playground_jumps.bvh dropped" in text
    run = RobotTrajectory.load(out)
    assert run.t[0] == pytest.approx(1 / 120)  # the motion's own clock, from frame 1
    assert run.meta["motion_notes"] and "0.69 m" in run.meta["motion_notes"][0]
    assert main(args + ["--keep-leading-cut"]) == 0
    assert "dropped" not in capsys.readouterr().out
    assert RobotTrajectory.load(out).t[0] == pytest.approx(0.0)


def test_retarget_command_errors_are_one_line(tmp_path, capsys):
    config = str(_config_file(tmp_path))
    assert main(["retarget", config, str(tmp_path / "nope.bvh"), "-o", "x.npz"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("qpretarget retarget: error:") and "does not exist" in err
    assert main(["retarget", config, str(MOCAP / "cmu_16.asf"), "-o", "x.npz"]) == 1
    assert "load the AMC motion instead" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["retarget", "demo"])
def test_help_has_examples(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text and f"qpretarget {command}" in text
