# SPDX-License-Identifier: Apache-2.0
"""The retargeting pipeline end to end on G1: spec validation, offline/online, occlusions, runs."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget.control.controller import Controller
from qpretarget.errors import ConfigError
from qpretarget.motion import HumanMotion, load_motion
from qpretarget.motion.calibration import rotation_z
from qpretarget.retarget.retargeter import (
    Retargeter,
    RetargetError,
    RetargetSpec,
    whole_body_config,
)
from qpretarget.retarget.summary import summarize_run
from qpretarget.trajectory import RobotTrajectory

REPO = Path(__file__).resolve().parents[1]
MOCAP = REPO.parent / "shared" / "data" / "mocap"

UPPER_BODY = {
    "tasks": {
        "pelvis": {"keypoint": "waist", "orientation": "waist"},
        "torso": {"orientation": "torso"},
        "left_hand": "left_hand",
        "right_hand": "right_hand",
        "left_elbow": "left_elbow",
        "right_elbow": "right_elbow",
        "head": "head",
    }
}


def _clip(name: str, start: float, end: float) -> HumanMotion:
    return load_motion(MOCAP / name).slice(start, end)


@pytest.fixture(scope="module")
def whole_body() -> Controller:
    """configs/g1_whole_body_static.yaml: the static balance mode (Poubel 2014 Table I)."""
    return Controller.from_yaml(REPO / "configs" / "g1_whole_body_static.yaml")


@pytest.fixture(scope="module")
def g1_whole_body() -> Controller:
    """configs/g1_whole_body.yaml as it is (kinematic stepping), or the generated whole-body one."""
    path = REPO / "configs" / "g1_whole_body.yaml"
    if path.is_file() and yaml.safe_load(path.read_text()).get("retarget"):
        return Controller.from_yaml(path)
    return Controller(whole_body_config("g1"))


@pytest.fixture(scope="module")
def upper_body() -> Controller:
    cfg = yaml.safe_load((REPO / "configs" / "g1_augmentation.yaml").read_text())
    cfg.setdefault("retarget", copy.deepcopy(UPPER_BODY))
    return Controller(cfg)


@pytest.fixture(scope="module")
def retargeter(whole_body) -> Retargeter:
    return Retargeter(whole_body)


def _report(label: str, traj: RobotTrajectory, controller: Controller) -> dict:
    s = summarize_run(traj, controller)
    rmse = ", ".join(f"{k} {v:.1f}" for k, v in s["rmse_mm"].items())
    print(f"\n{label}: RMSE [mm] {rmse}; violations {s['joint_limit_violations']}; "
          f"feet drift {s['feet_drift_mm']}")  # fmt: skip
    return s


# ----------------------------------------------------------------------------------- spec
@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"taks": {}}, r"retarget\.taks: unknown key 'taks'\. Did you mean 'tasks'"),
        ({"tasks": {"left_hnd": "left_hand"}}, r"tasks\.left_hnd: no controller task .*'left_hand'"),
        ({"tasks": {"left_hand": "left_wirst"}}, r"left_hand\.keypoint: unknown key-point 'left_wirst'\. Did you mean 'left_wrist'"),
        ({"tasks": {"torso": "waist"}}, r"task 'torso' has no position to track"),
        ({"tasks": {"left_hand": {"orientation": "torso"}}}, r"has no orientation to track"),
        ({"tasks": {"head": {"keypoint": "head", "offest": [0, 0, 0]}}}, r"unknown key 'offest'\. Did you mean 'offset'"),
        ({"scaling": "poubl"}, r"unknown scaling 'poubl'; one of poubel, dariush"),
        ({"filter": {"cutoff_hz": -3}}, r"filter\.cutoff_hz: expected a positive number"),
        ({"support": {}}, r"no `contacts` constraint"),
        ({"scaling": {"type": "poubel", "leg_extension": 1.5}}, r"fraction of the leg length"),
    ],
)  # fmt: skip
def test_retarget_section_errors_name_the_path_and_the_fix(upper_body, patch, message):
    spec = copy.deepcopy(UPPER_BODY)
    for key, value in patch.items():
        if key == "tasks":
            spec["tasks"].update(value)
        else:
            spec[key] = value
    with pytest.raises(ConfigError, match=message):
        RetargetSpec.parse(spec, upper_body)


def test_missing_retarget_section_says_what_to_add(upper_body):
    with pytest.raises(ConfigError, match=r"no `retarget:` section .*\(docs/retargeting\.md\)"):
        RetargetSpec.parse(None, upper_body)


def test_a_too_short_excerpt_is_an_error(retargeter):
    with pytest.raises(RetargetError, match="at least 4"):
        retargeter.retarget(_clip("cmu_14_37_drink_soda.bvh", 0.0, 0.02))


# ----------------------------------------------------------------------------------- runs
def test_upper_body_config_tracks_the_arms(upper_body):
    traj = Retargeter(upper_body).retarget(_clip("cmu_14_37_drink_soda.bvh", 1.0, 3.5))
    s = _report("drink soda, g1_augmentation", traj, upper_body)
    assert s["joint_limit_violations"] == 0
    assert traj.contacts is None and traj.foot_names == []  # no contacts in this config
    # Hands tracked to a few centimetres (G1 arms are 0.37 m, the person's 0.5 m).
    assert s["rmse_mm"]["left_hand"] < 60 and s["rmse_mm"]["right_hand"] < 60
    assert np.all(traj.status == "ok")


@pytest.mark.parametrize("config", ["g1_whole_body", "whole_body"])
def test_reaching_clip_end_to_end(request, config):
    """Bend, scoop, rise and lift the arm (02_06): both feet down all along."""
    controller = request.getfixturevalue(config)
    traj = Retargeter(controller).retarget(_clip("cmu_02_06_bend_scoop_lift_arm.bvh", 2.0, 6.0))
    s = _report(f"reach (02_06, 2-6 s), {config}", traj, controller)
    assert s["joint_limit_violations"] == 0
    # Contacts hold the soles: the controller corrects the integration drift every tick, so a
    # sole moves by well under 1 mm (the acceptance bound) while in contact.
    assert max(s["feet_drift_mm"].values()) < 1.0
    assert traj.contacts.all()  # double support only: no step is taken
    assert set(traj.extra["human_phase"].tolist()) == {"double"}
    # Pelvis: 13-16 mm with the former 20 self-collision pairs; with `pairs: auto` in both G1
    # whole-body configs (issue 16) it lags about 90 mm on this bend-and-scoop clip (hands
    # 62-74 mm): the person's hands pass where the robot's thighs and pelvis are, and the robot
    # keeps them apart (docs/collisions.md, tracking cost). Since the run starts in the person's
    # first stance (stepping.initial_stance, issue 15) the hands follow better (46 mm) and the
    # pelvis a little worse (106 mm; the generated `whole_body` config: 91 mm, hands 67-75).
    assert s["rmse_mm"]["pelvis"] < 115 and s["rmse_mm"]["left_hand"] < 80


def test_stepping_clip_end_to_end(whole_body):
    """The last steps of a walk that stops (16_33): single supports with real contact switches."""
    import dataclasses

    # The config's 2 s start ramp (for the physics replay, docs/physics.md) would cover this
    # 1.8 s excerpt: the former 0.5 s here, so the steps happen inside it.
    retargeter = Retargeter(whole_body)
    retargeter.spec = dataclasses.replace(retargeter.spec, ramp_time=0.5)
    traj = retargeter.retarget(_clip("cmu_16_33_walk_stop.bvh", 0.6, 2.38))
    s = _report("walk stop (16_33, 0.6-2.38 s)", traj, whole_body)
    assert s["joint_limit_violations"] == 0
    assert max(s["feet_drift_mm"].values()) < 1.0  # feet fixed within 1 mm while supporting
    contacts = traj.contacts
    assert not contacts.all(axis=1).all()  # a foot was lifted ...
    assert contacts.any(axis=1).all()  # ... but never both
    states = [s for _, s in traj.meta["support_log"]]
    assert "lift_right" in states and "lower_right" in states
    # The step goes forward, like the person's.
    robot = whole_body.robot
    data = robot.model.createData()
    sole = robot.frame_id(robot.feet["right_foot"].frame)
    x = []
    for q in (traj.q[0], traj.q[-1]):
        pin.framesForwardKinematics(robot.model, data, q)
        x.append(data.oMf[sole].translation[0])
    assert x[1] - x[0] > 0.05


def test_online_push_matches_offline_causal(whole_body, push_all):
    """Frames pushed one by one at the capture rate give the offline causal run's commands."""
    motion = _clip("cmu_16_33_walk_stop.bvh", 0.6, 1.6)
    rt = Retargeter(whole_body)
    offline = rt.retarget(motion, causal=True)
    commands = push_all(rt, motion)
    q = np.array([c.q for c in commands])
    t = np.array([c.t for c in commands])
    assert np.allclose(np.diff(t), 0.01, atol=1e-9)  # 100 Hz commands
    assert q.shape == offline.q.shape
    # The streaming filter and spline equal their offline versions to ~1e-12; the ticks then
    # run the same code, so the result agrees far below 1e-6.
    assert np.abs(q - offline.q).max() < 1e-6
    online = rt.trajectory()
    for name in offline.targets:
        assert np.abs(online.targets[name] - offline.targets[name]).max() < 1e-6


def test_a_clip_turned_backwards_gives_the_same_robot_motion():
    # The generated whole-body config: without self-collision rows its closed loop is well
    # conditioned, so a 1e-13 difference in the inputs stays 1e-13 (with self-collision rows G1
    # amplifies such differences ~1.6x per tick in deep bends; that is the controller's, not the
    # heading alignment's, and is reported apart).
    controller = Controller(whole_body_config("g1"))
    motion = _clip("cmu_16_33_walk_stop.bvh", 0.6, 1.4)
    R = rotation_z(math.pi)
    turned = HumanMotion(
        t=motion.t, names=motion.names, positions=motion.positions @ R.T + [4.0, -1.0, 0.0],
        parents=motion.parents, orientations=R @ motion.orientations, rate=motion.rate,
    )  # fmt: skip
    rt = Retargeter(controller)
    a, b = rt.retarget(motion), rt.retarget(turned)
    assert "lift_right" in [s for _, s in a.meta["support_log"]]  # the step is in the excerpt
    # Alignment removes the turn up to rounding (1e-12 m), which the closed loop keeps tiny.
    assert np.abs(a.q - b.q).max() < 1e-9


def test_missing_keypoints_drop_the_task_for_the_gap_and_recover(upper_body):
    motion = _clip("cmu_14_37_drink_soda.bvh", 1.0, 3.0)
    positions = motion.positions.copy()
    gap = (motion.t >= 1.8) & (motion.t < 2.0)
    positions[gap, motion.index("lhand")] = np.nan  # the left hand marker is occluded
    occluded = HumanMotion(
        t=motion.t, names=motion.names, positions=positions, parents=motion.parents,
        orientations=motion.orientations, rate=motion.rate, source="occluded",
    )  # fmt: skip
    traj = Retargeter(upper_body).retarget(occluded, causal=True)
    assert np.all(np.isfinite(traj.q)) and np.all(traj.status == "ok")
    messages = [m for m in traj.meta["messages"] if "'left_hand'" in m]
    assert messages and "NaN" in messages[0]
    target = traj.targets["left_hand"]
    during = (traj.t > 1.83) & (traj.t < 1.97)
    # The task kept its last target (weight 0) during the gap ...
    assert np.ptp(target[during], axis=0).max() == 0.0
    # ... and follows the hand again afterwards; the other hand never stopped.
    after = traj.t > 2.2
    assert np.ptp(target[after], axis=0).max() > 0.01
    assert np.ptp(traj.targets["right_hand"][during], axis=0).max() > 0.0


def test_run_file_holds_the_documented_keys(tmp_path, whole_body, retargeter):
    traj = retargeter.retarget(_clip("cmu_16_33_walk_stop.bvh", 1.0, 1.5))
    path = traj.save(tmp_path / "run.npz")
    with np.load(path) as data:
        keys = set(data.files)
    T = len(traj.t)
    required = {"t", "q", "v", "joint_names", "robot", "config_yaml", "task_names", "contacts",
                "foot_names", "status", "solve_time", "meta", "human/t"}  # fmt: skip
    assert required <= keys
    run = RobotTrajectory.load(path)
    assert run.q.shape == (T, whole_body.robot.nq) and run.contacts.shape == (T, 2)
    assert run.robot == "g1" and yaml.safe_load(run.config_yaml)["retarget"]
    assert np.allclose(np.diff(run.t), 0.01)
    for name in run.task_names:
        assert run.targets[name].shape == (T, 3) and run.actual[name].shape == (T, 3)
    assert (
        run.human["left_wrist"].ndim == 2
        and len(run.human["t"]) == run.human["left_wrist"].shape[0]
    )
    # actual/<task> is the forward kinematics of q after each tick.
    task = whole_body.tasks["left_hand"]
    data = whole_body.robot.model.createData()
    for k in (0, T // 2, T - 1):
        pin.framesForwardKinematics(whole_body.robot.model, data, run.q[k])
        assert np.allclose(
            run.actual["left_hand"][k], data.oMf[task.frame_id].translation, atol=1e-12
        )
    assert run.meta["keypoint_map"] == "cmu" and run.meta["control_rate"] == 100.0
