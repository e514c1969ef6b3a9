# SPDX-License-Identifier: Apache-2.0
"""Metrics on hand-made trajectories with known answers (issue 6 acceptance), and on a real run."""

from __future__ import annotations

import json
import math

import coal
import numpy as np
import pinocchio as pin
import pytest

from qpretarget.analysis.metrics import (
    GeometryPairDistances,
    MetricsError,
    average_absolute_power,
    carry_base_wrench,
    compute_metrics,
    compute_series,
    convex_hull_2d,
    derivative_peaks,
    joint_limit_violations,
    rmse,
    rnea_torques,
    signed_distance_to_polygon,
    solve_time_stats,
    summarize,
)
from qpretarget.analysis.solver_comparison import record_run, scripted_targets
from qpretarget.control.controller import Controller
from qpretarget.trajectory import RobotTrajectory, TrajectoryFormatError

DT = 0.01


@pytest.fixture(scope="module")
def ctrl(configs_dir) -> Controller:
    return Controller.from_yaml(configs_dir / "g1_augmentation.yaml")


def make_traj(ctrl: Controller, q: np.ndarray, **kw) -> RobotTrajectory:
    """A run of ``len(q)`` samples at DT holding the given configurations."""
    T = len(q)
    return RobotTrajectory(
        t=np.arange(T) * DT,
        q=q,
        v=np.zeros((T, ctrl.robot.nv)),
        joint_names=list(ctrl.robot.joint_names),
        robot=ctrl.robot.name,
        config_yaml=ctrl.config_yaml,
        **kw,
    )


def still(ctrl: Controller, T: int) -> np.ndarray:
    return np.tile(ctrl.robot.q_reference, (T, 1))


# ---------------------------------------------------------------------------------- joint limits
def test_joint_pushed_past_its_limit_for_five_frames_counts_five(ctrl):
    robot = ctrl.robot
    j = robot.joint_names.index("left_elbow_joint")
    qi = robot.joint_q_index[j]
    q = still(ctrl, 20)
    q[5:10, qi] = robot.q_max[qi] + 0.1
    s = compute_series(make_traj(ctrl, q), controller=ctrl, pairs=[])
    expected = np.zeros(20, int)
    expected[5:10] = 1
    np.testing.assert_array_equal(s.joint_violations_per_frame, expected)
    m = summarize(s)
    assert m["joint_limits"]["total_violations"] == 5
    assert m["joint_limits"]["frames_with_violation"] == 5
    assert m["joint_limits"]["per_joint"] == {"left_elbow_joint": 5}
    # 0.1 rad was added to a double: exact up to rounding of q_max + 0.1.
    assert m["joint_limits"]["max_violation_rad"] == pytest.approx(0.1, abs=1e-12)
    assert m["per_frame"]["joint_limit_violations"] == expected.tolist()


def test_joint_limit_violations_pure_function():
    q = np.array([[0.0, 1.0], [-2.0, 0.5], [0.0, 1.0 + 1e-9]])
    mask, amount = joint_limit_violations(q, [-1.0, -1.0], [1.0, 1.0])
    # 1e-9 rad over the limit is below the 1e-6 rad tolerance: not a violation.
    np.testing.assert_array_equal(mask, [[False, False], [True, False], [False, False]])
    assert amount[1, 0] == pytest.approx(1.0, abs=1e-15)


# ---------------------------------------------------------------------------------- collisions
def two_spheres(ctrl: Controller) -> GeometryPairDistances:
    """Sphere r=0.1 fixed at the world origin, sphere r=0.2 on the floating base's origin."""
    robot = ctrl.robot
    gm = pin.GeometryModel()
    world = pin.GeometryObject("ball_world", 0, 0, pin.SE3.Identity(), coal.Sphere(0.1))
    fid = robot.model.getFrameId("root_joint")
    base = pin.GeometryObject("ball_base", 1, fid, pin.SE3.Identity(), coal.Sphere(0.2))
    gm.addGeometryObject(world)
    gm.addGeometryObject(base)
    return GeometryPairDistances(robot, gm, [("ball_world", "ball_base")])


def test_two_spheres_at_known_distance(ctrl):
    q = still(ctrl, 3)
    q[:, 3:7] = [0, 0, 0, 1]
    q[:, :3] = [[1.0, 0, 0], [0.5, 0, 0], [0.25, 0, 0]]  # centres 1.0, 0.5, 0.25 m apart
    s = compute_series(
        make_traj(ctrl, q), controller=ctrl, collision=two_spheres(ctrl), safety_distance=0.25
    )
    # Sphere-sphere distance is analytic in coal: |c_a - c_b| - r_a - r_b, to rounding.
    np.testing.assert_allclose(s.pair_distance[:, 0], [0.7, 0.2, -0.05], atol=1e-9)
    np.testing.assert_array_equal(s.collision_violations_per_frame, [0, 0, 1])
    np.testing.assert_array_equal(s.below_safety_per_frame, [0, 1, 1])
    m = summarize(s)
    assert m["self_collision"]["total_violations"] == 1
    assert m["self_collision"]["min_distance_per_pair"]["ball_world/ball_base"][
        "min_m"
    ] == pytest.approx(-0.05, abs=1e-9)
    assert m["self_collision"]["min_distance_per_pair"]["ball_world/ball_base"][
        "at_s"
    ] == pytest.approx(2 * DT)


def test_unknown_collision_body_is_named(ctrl):
    with pytest.raises(
        MetricsError, match="left_wrist_yaw_lnk.*Did you mean 'left_wrist_yaw_link'"
    ):
        compute_series(
            make_traj(ctrl, still(ctrl, 2)),
            controller=ctrl,
            pairs=[("left_wrist_yaw_lnk", "torso_link")],
        )


# ---------------------------------------------------------------------------------- derivatives
def test_constant_velocity_joint_has_zero_jerk():
    t = np.arange(50) * DT
    q = np.column_stack([0.3 + 0.5 * t, 0.2 * t**2])  # constant velocity; constant acceleration
    p = derivative_peaks(t, q)
    # Divided differences are exact for polynomials; the only error is rounding amplified by
    # 1/dt^3 = 1e6 for the jerk (about 1e-9 here).
    assert p["velocity"][0] == pytest.approx(0.5, abs=1e-9)
    assert p["acceleration"][0] == pytest.approx(0.0, abs=1e-6)
    assert p["jerk"][0] == pytest.approx(0.0, abs=1e-3)
    assert p["acceleration"][1] == pytest.approx(0.4, abs=1e-6)
    assert p["jerk"][1] == pytest.approx(0.0, abs=1e-3)


def test_peaks_of_a_run(ctrl):
    robot = ctrl.robot
    j = robot.joint_names.index("right_elbow_joint")
    q = still(ctrl, 30)
    q[:, robot.joint_q_index[j]] += 0.8 * np.arange(30) * DT
    m = summarize(compute_series(make_traj(ctrl, q), controller=ctrl, pairs=[]))
    assert m["joint_motion"]["velocity_peak_rad_s"]["joint"] == "right_elbow_joint"
    assert m["joint_motion"]["velocity_peak_rad_s"]["value"] == pytest.approx(0.8, abs=1e-9)
    assert m["joint_motion"]["jerk_peak_rad_s3"]["value"] == pytest.approx(0.0, abs=1e-3)


# ---------------------------------------------------------------------------------- power
def test_power_of_a_known_torque_velocity_pair():
    tau = np.array([[2.0, -1.0], [1.0, 0.0], [-1.0, 0.0]])
    qdot = np.array([[3.0, 4.0], [2.0, 0.0], [2.0, 0.0]])
    # |2*3 - 4| = 2, |2| = 2, |-2| = 2: CRAC eq. 43 averages absolute values (mean of tau'qdot is 2/3).
    assert average_absolute_power(tau, qdot) == pytest.approx(2.0, abs=1e-15)


def test_power_from_stored_torques(ctrl):
    robot = ctrl.robot
    j = robot.joint_names.index("left_shoulder_pitch_joint")
    q = still(ctrl, 20)
    q[:, robot.joint_q_index[j]] += 0.5 * np.arange(20) * DT  # 0.5 rad/s
    tau = np.zeros((20, robot.nv))
    tau[:, robot.joint_v_index[j]] = 3.0  # 3 N m
    s = compute_series(make_traj(ctrl, q, tau=tau), controller=ctrl, pairs=[])
    assert s.power_source == "tau"
    # 3 N m * 0.5 rad/s = 1.5 W on every interior sample (central differences of a line).
    np.testing.assert_allclose(s.power, 1.5, atol=1e-9)
    assert summarize(s)["power"]["mean_abs_power_W"] == pytest.approx(1.5, abs=1e-9)


def test_power_from_rnea_matches_pinocchio(ctrl):
    robot = ctrl.robot
    j = robot.joint_names.index("left_shoulder_roll_joint")
    q = still(ctrl, 10)
    q[:, robot.joint_q_index[j]] += 1.0 * np.arange(10) * DT
    s = compute_series(make_traj(ctrl, q), controller=ctrl, pairs=[])
    assert s.power_source == "rnea"
    v = np.zeros(robot.nv)
    v[robot.joint_v_index[j]] = 1.0
    data = robot.model.createData()
    vi = robot.joint_v_index
    expected = [
        abs(pin.rnea(robot.model, data, q[k], v, np.zeros(robot.nv))[vi] @ v[vi])
        for k in s.power_index
    ]
    # Constant joint velocity: finite differences give v exactly and a = 0 up to rounding / dt^2.
    np.testing.assert_allclose(s.power, expected, rtol=1e-6, atol=1e-8)
    assert s.power.mean() > 0.01  # the arm is lifted against gravity
    # The feet carry the base wrench through the legs only: the arm's torques are unchanged.
    np.testing.assert_allclose(s.power_base_held, s.power, rtol=1e-9, atol=1e-12)


def test_feet_carry_the_weight_of_a_standing_robot(ctrl):
    robot = ctrl.robot
    q = still(ctrl, 3)
    feet = [robot.frame_id(robot.feet[f].frame) for f in ("left_foot", "right_foot")]
    zero = np.zeros((3, robot.nv))
    tau = rnea_torques(robot, q, zero, zero)
    tau_j = carry_base_wrench(robot, q, tau, np.ones((3, 2), bool), feet)
    # What the joints do not provide, the two contact wrenches do: tau - [0; tau_j] = Jc' f.
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q[0])
    pin.updateFramePlacements(robot.model, data)
    Jc = np.vstack(
        [pin.getFrameJacobian(robot.model, data, f, pin.LOCAL_WORLD_ALIGNED) for f in feet]
    )
    r = tau[0] - np.concatenate([np.zeros(6), tau_j[0]])
    f, *_ = np.linalg.lstsq(Jc.T, r, rcond=None)
    np.testing.assert_allclose(Jc.T @ f, r, atol=1e-8)  # exactly carried (rounding of 1e2 N m)
    # Static standing: the vertical contact forces add up to the robot's weight m g.
    weight = pin.computeTotalMass(robot.model) * 9.81
    assert f[2] + f[8] == pytest.approx(weight, rel=1e-9)
    # ... and the knees hold it: without the contact forces they would carry nothing.
    knee = robot.joint_names.index("left_knee_joint")
    assert abs(tau[0, 6 + knee]) < 1.0 < abs(tau_j[0, knee])


# ---------------------------------------------------------------------------------- tracking
def test_rmse_known_offset_and_missing_rows():
    ref = np.array([[0.03, 0.04, 0.0], [0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    act = np.zeros((3, 3))
    # rows: 0.05 m, 0 m, missing -> sqrt((0.05^2 + 0) / 2)
    assert rmse(ref, act) == pytest.approx(0.05 / math.sqrt(2), abs=1e-15)


def test_tracking_rmse_is_recomputed_with_forward_kinematics(ctrl):
    q = still(ctrl, 5)
    fid = ctrl.tasks["left_hand"].frame_id
    data = ctrl.robot.model.createData()
    pin.framesForwardKinematics(ctrl.robot.model, data, q[0])
    p = data.oMf[fid].translation.copy()
    target = np.tile(p + [0.0, 0.03, 0.04], (5, 1))
    traj = make_traj(
        ctrl,
        q,
        task_names=["left_hand"],
        targets={"left_hand": target},
        actual={"left_hand": np.tile(p, (5, 1))},
    )
    m = compute_metrics(traj, controller=ctrl, pairs=[])
    assert m["tracking"]["left_hand"]["rmse_m"] == pytest.approx(0.05, abs=1e-12)
    assert m["tracking"]["left_hand"]["rmse_xyz_m"] == pytest.approx([0.0, 0.03, 0.04], abs=1e-12)
    assert m["tracking"]["left_hand"]["recorded_vs_fk_max_m"] == pytest.approx(0.0, abs=1e-12)


# ---------------------------------------------------------------------------------- support
def test_signed_distance_to_polygon_and_hull():
    square = convex_hull_2d([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.2, 0.9]])
    assert len(square) == 4  # interior points dropped
    assert signed_distance_to_polygon([0.25, 0.5], square) == pytest.approx(0.25)
    assert signed_distance_to_polygon([2.0, 0.5], square) == pytest.approx(-1.0)
    assert signed_distance_to_polygon([2.0, 2.0], square) == pytest.approx(-math.sqrt(2))


def test_com_margin_double_and_single_support(ctrl):
    robot = ctrl.robot
    q = still(ctrl, 2)
    contacts = np.array([[True, True], [True, False]])
    s = compute_series(
        make_traj(ctrl, q, contacts=contacts, foot_names=["left_foot", "right_foot"]),
        controller=ctrl,
        pairs=[],
    )
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q[0])
    c = pin.centerOfMass(robot.model, data, q[0])
    # In the reference posture the soles are flat and aligned with the world axes.
    L = data.oMf[robot.frame_id("left_sole")].translation
    R = data.oMf[robot.frame_id("right_sole")].translation
    x0, x1, y0, y1 = robot.feet["left_foot"].rectangle
    double = min(c[0] - (L[0] + x0), (L[0] + x1) - c[0], c[1] - (R[1] + y0), (L[1] + y1) - c[1])
    assert s.com_margin[0] == pytest.approx(double, abs=1e-6)  # 1e-6 m: soles flat to ~1e-7 rad
    assert s.com_margin[1] == pytest.approx(
        -((L[1] + y0) - c[1]), abs=1e-6
    )  # CoM outside the left sole
    assert not s.contacts_assumed


def test_foot_slip_during_support(ctrl):
    q = still(ctrl, 12)
    q[5:, 0] += 0.02  # the whole robot slides 2 cm forward at frame 5
    contacts = np.ones((12, 2), bool)
    contacts[4:8, 1] = False  # the right foot is lifted over the slide and put down again
    s = compute_series(
        make_traj(ctrl, q, contacts=contacts, foot_names=["left_foot", "right_foot"]),
        controller=ctrl,
        pairs=[],
    )
    m = summarize(s)
    assert m["foot_slip"]["left_foot"]["max_slip_m"] == pytest.approx(0.02, abs=1e-12)
    assert m["foot_slip"]["right_foot"]["max_slip_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["foot_slip"]["right_foot"]["frames_in_contact"] == 8
    assert np.isnan(s.foot_slip["right_foot"][5])


# ---------------------------------------------------------------------------------- misc
def test_solve_time_stats():
    st = solve_time_stats(np.arange(1, 101) * 1e-3)
    assert st["median_ms"] == pytest.approx(50.5)
    assert st["p95_ms"] == pytest.approx(95.05)
    assert st["max_ms"] == pytest.approx(100.0)


def test_wrong_robot_width_is_reported(ctrl):
    traj = make_traj(ctrl, still(ctrl, 3)[:, :-1])
    with pytest.raises(TrajectoryFormatError, match=r"q has shape \(3, 35\), expected \(3, 36\)"):
        compute_series(traj, controller=ctrl)


def test_metrics_of_a_real_run_are_strict_json(ctrl):
    traj = record_run(ctrl, scripted_targets(ctrl, 0.5))
    m = compute_metrics(traj)  # controller rebuilt from the run's YAML, default collision pairs
    json.dumps(m, allow_nan=False)
    assert m["self_collision"]["pairs"] and m["self_collision"]["min_distance_m"] > 0
    assert m["joint_limits"]["total_violations"] == 0  # the config has joint_limits
    for name in ("left_hand", "right_hand"):
        # The recorder stores FK of the same q: equal to rounding.
        assert m["tracking"][name]["recorded_vs_fk_max_m"] < 1e-12
        assert m["tracking"][name]["rmse_m"] < 0.02
