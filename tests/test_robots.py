# SPDX-License-Identifier: Apache-2.0
"""Bundled robots: each loads from example-robot-data with a sane standing posture."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget import ROBOTS, load_robot
from qpretarget.errors import ConfigError, UnknownFrameError


def test_registry_is_sorted_and_complete() -> None:
    assert list(ROBOTS) == sorted(ROBOTS)
    assert {"g1", "talos", "romeo", "icub", "simple_humanoid"} <= set(ROBOTS)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_bundled_robot_stands_on_the_ground(name: str) -> None:
    r = load_robot(name)
    assert r.free_flyer and r.nv == r.nq - 1
    q = r.q_reference
    assert not q.flags.writeable
    qi = r.joint_q_index
    assert np.all(q[qi] >= r.q_min[qi]) and np.all(q[qi] <= r.q_max[qi])
    assert np.all(r.v_max[r.joint_v_index] > 0)
    data = r.model.createData()
    pin.framesForwardKinematics(r.model, data, q)
    for foot in r.feet.values():
        sole = data.oMf[r.frame_id(foot.frame)]
        assert abs(sole.translation[2]) < 1e-3, (name, foot.frame)  # soles on z = 0
        assert sole.rotation[2, 2] > 0.99  # flat
    for key, frame in r.keyframes.items():
        assert r.model.existFrame(frame), (name, key, frame)
    com = pin.centerOfMass(r.model, data, q)
    assert com[2] > 0.3


def test_unknown_frame_lists_close_names() -> None:
    r = load_robot("talos")
    with pytest.raises(
        UnknownFrameError,
        match=r"frame 'arm_left_7_lnk' is not known\. Did you mean 'arm_left_7_link'",
    ):
        r.frame_id("arm_left_7_lnk")


def test_overrides_apply() -> None:
    r = load_robot(
        {
            "name": "g1",
            "velocity_limits": {"left_knee_joint": 3.0},
            "position_limits": {"left_elbow_joint": [-0.5, 1.0]},
        }
    )
    j = r.joint_index("left_knee_joint")
    assert r.v_max[r.joint_v_index[j]] == 3.0
    j = r.joint_index("left_elbow_joint")
    assert r.q_min[r.joint_q_index[j]] == -0.5


def test_bad_override_message() -> None:
    with pytest.raises(
        ConfigError, match=r"velocity limit of 'left_knee_joint' must be a positive number"
    ):
        load_robot({"name": "g1", "velocity_limits": {"left_knee_joint": -1}})


def test_urdf_robot_from_example_robot_data_path() -> None:
    r = load_robot(
        {"urdf": "example-robot-data:panda_description/urdf/panda.urdf", "free_flyer": False}
    )
    assert r.nq == r.nv and not r.free_flyer


def test_missing_urdf_message(tmp_path) -> None:
    with pytest.raises(ConfigError, match=r"robot\.urdf: URDF file .*nope\.urdf' does not exist"):
        load_robot({"urdf": str(tmp_path / "nope.urdf")})
