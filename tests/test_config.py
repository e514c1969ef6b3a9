# SPDX-License-Identifier: Apache-2.0
"""YAML validation: every bad input gives one clear message with its YAML path (issue #2 item 6)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from qpretarget import Controller
from qpretarget.errors import ConfigError, TargetError


@pytest.fixture(scope="module")
def base(configs_dir) -> dict:
    return yaml.safe_load((configs_dir / "g1_augmentation.yaml").read_text())


def with_change(base: dict, fn) -> dict:
    cfg = copy.deepcopy(base)
    fn(cfg)
    return cfg


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        (
            lambda c: c["tasks"][2].update(frame="left_rubber_hnd"),
            r"tasks\[2\]\.frame: frame 'left_rubber_hnd' is not known\. Did you mean 'left_rubber_hand'",
        ),
        (
            lambda c: c["tasks"][0].update(frme="pelvis"),
            r"tasks\[0\]\.frme: unknown key 'frme' for 'frame'\. Did you mean 'frame'",
        ),
        (
            lambda c: c["tasks"].append({"type": "fram", "frame": "pelvis"}),
            r"tasks\[8\]\.type: task type 'fram' is not known\. Did you mean 'frame'",
        ),
        (
            lambda c: c["tasks"][2].update(position_weight=[1.0, 2.0]),
            r"tasks\[2\]: position_weight must be a number or a list of 3 numbers",
        ),
        (
            lambda c: c["tasks"][2].update(mode="positon"),
            r"tasks\[2\]: mode must be one of position, orientation, pose, got 'positon'",
        ),
        (lambda c: c.update(robt="g1"), r"robt: unknown key 'robt'\. Did you mean 'robot'"),
        (lambda c: c.update(robot="g2"), r"robot: robot 'g2' is not known\. Did you mean 'g1'"),
        (lambda c: c.update(dt=-0.01), r"dt: dt must be a number of seconds in \(0, 1\)"),
        (
            lambda c: c["constraints"][0].update(gain=1.5),
            r"constraints\[0\]: gain must be in \(0, 1\]",
        ),
        (
            lambda c: c["constraints"].append({"type": "joint_limit"}),
            r"constraints\[2\]\.type: constraint type 'joint_limit' is not known\. Did you mean 'joint_limits'",
        ),
        (
            lambda c: c.update(strategy={"type": "augmentaton"}),
            r"strategy\.type: strategy type 'augmentaton' is not known\. Did you mean 'augmentation'",
        ),
        (
            lambda c: c.update(solver={"name": "osqq"}),
            r"solver\.name: solver 'osqq' is not known\. Did you mean 'osqp'",
        ),
        (
            lambda c: c["tasks"].append({"type": "frame", "name": "pelvis", "frame": "pelvis"}),
            r"tasks\[8\]\.name: two tasks are named 'pelvis'",
        ),
        (
            lambda c: c.update(robot={"name": "g1", "velocity_limits": {"left_knee": 3.0}}),
            r"robot\.velocity_limits\.left_knee: joint 'left_knee' is not known\. Did you mean 'left_knee_joint'",
        ),
        (
            lambda c: c["tasks"][1].pop("frame"),
            r"tasks\[1\]: missing required key 'frame' for 'frame'",
        ),
    ],
)
def test_bad_config_gives_clear_message(base: dict, change, pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        Controller(with_change(base, change))


def test_yaml_syntax_error_has_line(tmp_path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("robot: g1\ntasks:\n  - {type: frame, name: x\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: invalid YAML at line \d+"):
        Controller.from_yaml(p)


def test_yaml_numbers_without_exponent_sign_are_floats(configs_dir, tmp_path) -> None:
    """PyYAML reads ``1e4`` as a string (YAML 1.1); config files read it as 10000.0."""
    from qpretarget.yamlio import load_yaml

    assert load_yaml("a: 1e4\nb: 1.5E3\nc: .5\nd: 3\ne: '1e4'\nf: 1.0e-2") == {
        "a": 1e4, "b": 1500.0, "c": 0.5, "d": 3, "e": "1e4", "f": 0.01,
    }  # fmt: skip
    text = (configs_dir / "g1_augmentation.yaml").read_text()
    p = tmp_path / "g1.yaml"
    p.write_text(text.replace("solver: {name: daqp}", "solver: {name: daqp, primal_tol: 2e-9}", 1))
    assert "primal_tol: 2e-9" in p.read_text()
    ctrl = Controller.from_yaml(p)
    assert ctrl.config["solver"]["primal_tol"] == 2e-9


def test_missing_file() -> None:
    with pytest.raises(ConfigError, match=r"config file 'nope\.yaml' does not exist"):
        Controller.from_yaml("nope.yaml")


@pytest.fixture(scope="module")
def ctrl(base: dict) -> Controller:
    return Controller(base)


@pytest.mark.parametrize(
    ("targets", "pattern"),
    [
        ({"left_hnd": [0, 0, 1]}, r"tick \d+: no task named 'left_hnd'\. Did you mean 'left_hand'"),
        (
            {"left_hand": [0, 0]},
            r"task 'left_hand', tick \d+: target must be a 3-vector .* got shape \(2,\)",
        ),
        (
            {"left_hand": np.eye(3)},
            r"task 'left_hand', tick \d+: a rotation was given to a position-only task",
        ),
        (
            {"torso": [0, 0, 1.0]},
            r"task 'torso', tick \d+: a position was given to an orientation-only task",
        ),
        (
            {"pelvis": 2 * np.eye(3)},
            r"task 'pelvis', tick \d+: rotation target is not a rotation matrix",
        ),
        ({"left_hand": "up"}, r"task 'left_hand', tick \d+: target must be a 3-vector"),
        (
            {"posture": [0.0] * 5},
            r"task 'posture', tick \d+: posture target must have shape \(36,\)",
        ),
    ],
)
def test_bad_target_gives_clear_message(ctrl: Controller, targets: dict, pattern: str) -> None:
    ctrl.reset()
    with pytest.raises(TargetError, match=pattern):
        ctrl.step(targets)


def test_targets_accept_every_documented_form(ctrl: Controller) -> None:
    import pinocchio as pin

    ctrl.reset()
    M = ctrl.state.frame_placement(ctrl.tasks["pelvis"].frame_id)
    for target in (M.copy(), M.homogeneous.copy(), M.translation.copy(), M.rotation.copy(), None):
        res = ctrl.step({"pelvis": target})
        assert res.status == "ok"
    assert isinstance(M, pin.SE3)
    res = ctrl.step({"posture": {"left_elbow_joint": 0.5}})
    assert res.status == "ok"
