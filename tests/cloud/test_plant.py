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


def _retargeter(g1, plant: str, **stability) -> CloudRetargeter:
    cfg = {
        "robot": "g1",
        "calibration": {"enabled": False},
        "stability": {"plant": plant, **stability},
    }
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
        rt = _retargeter(g1, plant, replant_distance=None, replant_angle=3.0)  # held, not re-put
        rt.placement.placed = {"left_foot": target}
        rt.placement.fit_placed = {"left_foot": fitted}  # the person's foot stood still
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
    # Put down flat on the floor where the fit has it (its leg's joints), as the primary is.
    held = _flat(_sole(g1, q_fit, "right_foot"))
    assert np.abs(pin.log6(_sole(g1, q0, "right_foot").inverse() * held).vector).max() < 1e-8
    assert rt.placement.stance == ("left_foot", "right_foot") and rt.placement.moved == ()
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
    assert "right_foot" not in rt.placement.placed and rt.placement.stance == ("left_foot",)


def test_a_sole_the_fit_moves_away_is_put_down_again(g1):
    """A supporting foot the fit puts farther than ``stability.replant_distance`` (8 cm) from
    where it stands (a shuffle, a step carried low) is put down where the fit has it; that
    frame it is not in the stance (not in contact, not in the balance), the next it is.
    Exact placements: 1e-8 (Newton's tolerance)."""
    rt = _retargeter(g1, "leg")
    both = Support(feet=["left_foot", "right_foot"], primary="left_foot")
    q_fit = _fitted(g1)
    rt.robot_configuration(q_fit, both)
    first = rt.placement.placed["right_foot"]
    q_step = q_fit.copy()
    q_step[_iq(g1, "right_hip_pitch_joint")] -= 0.25  # the right sole 10-15 cm forward
    moved = _flat(_sole(g1, q_step, "right_foot"))
    assert np.linalg.norm(moved.translation - first.translation) > 0.08
    q = rt.robot_configuration(q_step, both)
    assert rt.placement.moved == ("right_foot",) and rt.placement.stance == ("left_foot",)
    assert np.abs(pin.log6(_sole(g1, q, "right_foot").inverse() * moved).vector).max() < 1e-8
    rt.robot_configuration(q_step, both)
    assert rt.placement.moved == () and rt.placement.stance == ("left_foot", "right_foot")
    # 5 cm is the fit's own scatter on a standing foot: held where it stands.
    q_small = q_step.copy()
    q_small[_iq(g1, "right_hip_pitch_joint")] += 0.08
    assert np.linalg.norm(_flat(_sole(g1, q_small, "right_foot")).translation
                          - moved.translation) < 0.08  # fmt: skip
    q = rt.robot_configuration(q_small, both)
    assert rt.placement.moved == ()
    assert np.abs(pin.log6(_sole(g1, q, "right_foot").inverse() * moved).vector).max() < 1e-8


def test_a_new_primary_foot_stands_where_it_was_put_down(g1):
    """The primary foot changes (the fit lifts the old one): the robot stays where it stands,
    on the new primary's placement, not under its fitted sole (before stop 49 the command
    jumped by the fit's drift there, 0.47 m on a reach-up run)."""
    rt = _retargeter(g1, "leg")
    q_fit = _fitted(g1)
    rt.robot_configuration(q_fit, Support(feet=["left_foot", "right_foot"], primary="left_foot"))
    held = rt.placement.placed["right_foot"]
    drifted = q_fit.copy()
    drifted[0] += 0.05  # the fit's whole body 5 cm off: within the replant distance
    q = rt.robot_configuration(drifted, Support(feet=["right_foot"], primary="right_foot"))
    assert rt.placement.stance == ("right_foot",)
    assert np.abs(pin.log6(_sole(g1, q, "right_foot").inverse() * held).vector).max() < 1e-8


def test_a_raised_heel_does_not_carry_the_trunk_back(g1):
    """A fitted sole pitched 8 deg (a heel raised): laid flat on the floor, the trunk moves
    with the sole's position only (the leg takes the pitch), where turning the body about
    the sole (``rigid``) carries a pelvis 0.7 m above it about 10 cm. Exact: 1e-9."""
    q_fit = _fitted(g1)
    q_fit[_iq(g1, "left_ankle_pitch_joint")] += np.radians(8.0)
    support = Support(feet=["left_foot"], primary="left_foot")
    rt = _retargeter(g1, "leg")
    q = rt.robot_configuration(q_fit, support)
    sole = _sole(g1, q_fit, "left_foot")
    shift = _flat(sole).translation - sole.translation
    assert np.abs(q[:3] - (q_fit[:3] + shift)).max() < 1e-9
    rigid = _retargeter(g1, "rigid").robot_configuration(q_fit, support)
    assert np.linalg.norm(rigid[:2] - q_fit[:2] - shift[:2]) > 0.05
