# SPDX-License-Identifier: Apache-2.0
"""The command's stance (``stability.plant``): the primary sole flat on the floor at its
placement, put there by the supporting leg (``leg``) or by turning the whole body (``rigid``).

Synthetic fitted configurations of G1 (no cloud): the fitted trunk is turned and tilted, or its
sole is far from its placement; the tolerances are the solvers' (Newton to 1e-9 in the sole's
pose, exact rigid placements: 1e-9).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.cloud.em import CloudRetargeter
from qpretarget.cloud.stability import Support


def _retargeter(g1, plant: str) -> CloudRetargeter:
    cfg = {"robot": "g1", "calibration": {"enabled": False}, "stability": {"plant": plant}}
    return CloudRetargeter(cfg, robot=g1)


def _iq(g1, name: str) -> int:
    """Configuration index of a one-DoF joint."""
    return int(g1.model.joints[g1.model.getJointId(name)].idx_q)


def _fitted(g1) -> np.ndarray:
    """G1 standing, its base turned 10 deg and tilted 3 deg, the legs bent a little."""
    q = g1.q_reference.copy()
    R = pin.rpy.rpyToMatrix(0.05, 0.03, np.radians(10.0))
    q[:7] = pin.SE3ToXYZQUAT(pin.SE3(R, np.array([0.3, -0.2, 0.75])))
    for side in ("left", "right"):
        for name, value in (("hip_pitch", -0.2), ("knee", 0.4), ("ankle_pitch", -0.2)):
            q[_iq(g1, f"{side}_{name}_joint")] = value
    return q


def _sole(g1, q: np.ndarray, foot: str) -> pin.SE3:
    data = g1.model.createData()
    pin.framesForwardKinematics(g1.model, data, q)
    return data.oMf[g1.frame_id(g1.feet[foot].frame)].copy()


def _flat(M: pin.SE3) -> pin.SE3:
    yaw = np.arctan2(M.rotation[1, 0], M.rotation[0, 0])
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([*M.translation[:2], 0.0]))


def test_the_leg_puts_the_sole_down_under_the_fitted_trunk(g1):
    q_fit = _fitted(g1)
    support = Support(feet=["left_foot"], primary="left_foot")
    rt = _retargeter(g1, "leg")
    q = rt.robot_configuration(q_fit, support)
    # The sole on its placement (the fitted sole flattened onto the floor), the trunk's
    # orientation and every joint outside the supporting leg as fitted.
    target = _flat(_sole(g1, q_fit, "left_foot"))
    got = _sole(g1, q, "left_foot")
    assert np.abs(pin.log6(got.inverse() * target).vector).max() < 1e-8
    assert np.allclose(q[3:7], q_fit[3:7], atol=1e-12)
    leg = [_iq(g1, f"left_{n}_joint") for n in
           ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")]  # fmt: skip
    rest = np.setdiff1d(np.arange(7, g1.model.nq), leg)
    assert np.array_equal(q[rest], q_fit[rest])
    assert not np.allclose(q[leg], q_fit[leg])  # the leg took the 3 deg tilt
    qi = g1.joint_q_index
    assert np.all(q[qi] >= g1.q_min[qi]) and np.all(q[qi] <= g1.q_max[qi])
    # rigid: the whole body turned with the sole, every joint as fitted, the trunk tilted.
    rigid = _retargeter(g1, "rigid").robot_configuration(q_fit, support)
    assert np.abs(pin.log6(_sole(g1, rigid, "left_foot").inverse() * target).vector).max() < 1e-9
    assert np.array_equal(rigid[7:], q_fit[7:])
    turn = pin.log3(pin.XYZQUATToSE3(q_fit[:7]).rotation.T @ pin.XYZQUATToSE3(rigid[:7]).rotation)
    assert np.degrees(np.linalg.norm(turn)) > 2.0


def test_a_placement_out_of_the_legs_reach_turns_the_trunk_as_little_as_needed(g1):
    """The planted sole turned 60 deg from the fitted one (a person pivoting on it): beyond the
    ankle's roll and the leg's reach with the trunk as fitted; the compromise puts the sole
    exactly on its placement, the leg within its limits, the trunk turned less than the rigid
    placement turns it (60 deg)."""
    q_fit = _fitted(g1)
    support = Support(feet=["left_foot"], primary="left_foot")
    fitted = _flat(_sole(g1, q_fit, "left_foot"))
    target = fitted * pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.radians(60.0)), np.zeros(3))
    out = {}
    for plant in ("leg", "rigid"):
        rt = _retargeter(g1, plant)
        rt.placement.planted = ("left_foot", target)
        q = rt.robot_configuration(q_fit, support)
        got = _sole(g1, q, "left_foot")
        assert np.abs(pin.log6(got.inverse() * target).vector).max() < 1e-8, plant
        qi = g1.joint_q_index
        assert np.all(q[qi] >= g1.q_min[qi] - 1e-12) and np.all(q[qi] <= g1.q_max[qi] + 1e-12)
        R0, R = pin.XYZQUATToSE3(q_fit[:7]).rotation, pin.XYZQUATToSE3(q[:7]).rotation
        out[plant] = np.degrees(np.linalg.norm(pin.log3(R0.T @ R)))
    assert out["rigid"] == pytest.approx(60.0, abs=0.5)
    assert out["leg"] < 0.5 * out["rigid"], out


def test_a_second_supporting_sole_is_held_where_it_was_put_down(g1):
    rt = _retargeter(g1, "leg")
    both = Support(feet=["left_foot", "right_foot"], primary="left_foot")
    q_fit = _fitted(g1)
    q0 = rt.robot_configuration(q_fit, both)
    held = _sole(g1, q0, "right_foot")
    # The fitted trunk moves 2 cm sideways and turns 2 deg over the planted left sole: the
    # right sole stays where it was put down (its leg's joints), as the left one does.
    q_fit2 = q_fit.copy()
    M = pin.XYZQUATToSE3(q_fit[:7])
    M2 = pin.SE3(M.rotation @ pin.rpy.rpyToMatrix(0, 0, np.radians(2.0)), M.translation)
    M2.translation[1] += 0.02
    q_fit2[:7] = pin.SE3ToXYZQUAT(M2)
    q1 = rt.robot_configuration(q_fit2, both)
    assert np.abs(pin.log6(_sole(g1, q1, "right_foot").inverse() * held).vector).max() < 1e-8
    assert np.allclose(q1[3:7], q_fit2[3:7], atol=1e-12)
    # A foot that stops supporting is released: put down again, it is held at its new pose.
    rt.robot_configuration(q_fit2, Support(feet=["left_foot"], primary="left_foot"))
    assert "right_foot" not in rt.placement.held
