# SPDX-License-Identifier: Apache-2.0
"""ground: links above the ground plane and away from static obstacles (velocity damper)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.collision import CollisionModel, obstacle_shape
from qpretarget.constraints.ground import Ground
from qpretarget.control.controller import Controller
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotModel, RobotState


@pytest.fixture(scope="module")
def g1() -> RobotModel:
    return RobotModel.from_name("g1")


def config(ground: dict | None) -> dict:
    cons = [
        {"type": "contacts"},
        {"type": "joint_limits", "gain": 0.95},
        {"type": "velocity_limits"},
    ]
    if ground is not None:
        cons.append({"type": "ground", **ground})
    return {
        "robot": "g1",
        "dt": 0.01,
        "regularization": {"type": "identity", "damping": 0.05},
        "tasks": [
            {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "position",
             "position_weight": 10.0},
            {"type": "frame", "name": "left_hand", "frame": "left_rubber_hand", "mode": "position",
             "position_weight": 100.0, "gain": 20.0},
            {"type": "posture", "name": "posture", "weight": 0.1},
        ],
        "constraints": cons,
    }  # fmt: skip


def drive_left_hand(ctrl: Controller, goal: np.ndarray, n: int = 200):
    p0 = ctrl.state.frame_placement(ctrl.robot.frame_id("left_rubber_hand")).translation.copy()
    for k in range(n):
        s = min(1.0, k / (0.75 * n))
        yield {"left_hand": (1 - s) * p0 + s * goal}


def test_hand_stays_above_a_raised_ground(g1):
    # A ground plane at z = 0.55 m (above the hands' reach when standing), hand pulled to 0.3 m:
    # the hand link's lowest point stays above 0.55 + margin - 1 mm with the constraint and goes
    # below the plane without it.
    spec = {"links": ["left_hand"], "height": 0.55, "margin": 0.01}
    meter = CollisionModel(
        g1, [("left_wrist_yaw_link", "plane")],
        obstacles=[obstacle_shape({"name": "plane", "shape": "halfspace", "normal": [0, 0, 1],
                                   "offset": 0.55}, g1.model)],
        broad_phase=False,
    )  # fmt: skip
    goal = np.array([0.3, 0.25, 0.3])
    lows = {}
    for name, ground in (("free", None), ("held", spec)):
        ctrl = Controller(config(ground))
        low = np.inf
        for t in drive_left_hand(ctrl, goal):
            res = ctrl.step(t)
            assert np.all(np.isfinite(res.q))
            low = min(low, meter.compute_all(ctrl.state)[0][0])
        lows[name] = low
    assert lows["free"] < 0.0
    assert lows["held"] >= 0.01 - 1e-3, lows


def test_hand_goes_around_a_sphere_obstacle(g1):
    # A ball in front of the chest; the hand is pulled through its centre. Distance to the ball
    # stays above margin - 1 mm with the constraint; without it the hand enters the ball.
    ball = {"name": "ball", "shape": "sphere", "radius": 0.08, "position": [0.3, 0.15, 0.85]}
    spec = {"links": [], "obstacles": [ball], "obstacle_links": ["left_wrist_yaw_link",
            "left_wrist_roll_link", "left_elbow_link"], "obstacle_margin": 0.02}  # fmt: skip
    meter = CollisionModel(
        g1, [("left_wrist_yaw_link", "ball")], obstacles=[obstacle_shape(ball, g1.model)],
        broad_phase=False,
    )  # fmt: skip
    goal = np.array([0.45, 0.15, 0.85])  # beyond the ball: the straight path crosses it
    dmin = {}
    for name, ground in (("free", None), ("held", spec)):
        ctrl = Controller(config(ground))
        d = np.inf
        for t in drive_left_hand(ctrl, goal):
            ctrl.step(t)
            d = min(d, meter.compute_all(ctrl.state)[0][0])
        dmin[name] = d
    assert dmin["free"] < 0.0
    assert dmin["held"] >= 0.02 - 1e-3, dmin


def test_default_links_and_standing_feet(g1):
    # Defaults: feet, hands and knees of the key-points, resolved to links with geometry. The
    # feet stand on the ground at reset: their rows are disarmed (the contacts hold them).
    ctrl = Controller(config({}))
    con = ctrl.constraint("ground")
    assert set(con.links) == {
        "left_ankle_roll_link", "right_ankle_roll_link", "left_wrist_yaw_link",
        "right_wrist_yaw_link", "left_knee_link", "right_knee_link",
    }  # fmt: skip
    armed = dict(zip(con.links, con.armed[: con.n_ground], strict=True))
    assert not armed["left_ankle_roll_link"] and not armed["right_ankle_roll_link"]
    assert armed["left_wrist_yaw_link"] and armed["left_knee_link"]
    for _ in range(5):
        res = ctrl.step()
        assert res.status == "ok"
    ctrl.set_contacts(["right_foot"])  # the released left foot stays disarmed until lifted
    assert not con.armed[con.links.index("left_ankle_roll_link")]


def test_ground_row_is_minus_the_height_rate(g1):
    # Row . v = -d(lowest point height)/dt, checked by finite differences (h = 1e-6; hull
    # vertices are exact for a half-space, so 1e-6 per unit |v| covers the O(h) term).
    con = Ground(links=["left_hand", "left_knee"], d_i=1.0, trust_region=None)
    con.bind(g1)
    state = RobotState(g1)
    q0 = g1.q_reference.copy()
    state.update(q0)
    con.reset(state)
    blk = con.compute_rows(state, 0.01)
    assert np.all(np.isfinite(blk.u))
    d0 = con.model.distances.copy()
    rng = np.random.default_rng(4)
    v = rng.standard_normal(g1.nv)
    state.update(pin.integrate(g1.model, q0, 1e-6 * v))
    d1 = con.model.compute_all(state)[0]
    np.testing.assert_allclose(blk.C @ v, -(d1 - d0) / 1e-6, atol=1e-6 * np.linalg.norm(v))


def test_bad_ground_configurations(g1):
    with pytest.raises(ConfigError, match="needs `radius`"):
        Ground(obstacles=[{"name": "b", "shape": "sphere"}]).bind(g1, path="constraints[2]")
    with pytest.raises(ConfigError, match="unique"):
        Ground(obstacles=[{"name": "b", "shape": "sphere", "radius": 0.1}] * 2).bind(g1)
    with pytest.raises(ConfigError, match="links must be a list"):
        Ground(links="left_hand")


def _trust_box(g1, plane_trust: bool, rpy: tuple[float, float, float]) -> np.ndarray:
    con = Ground(links=["left_knee"], d_i=1.0, plane_trust=plane_trust)
    con.bind(g1)
    state = RobotState(g1)
    q = g1.q_reference.copy()
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(*rpy)).coeffs()
    state.update(q)
    con.reset(state)
    box = con.compute_bounds(state, 0.01)
    assert box is not None
    return box[1] * 0.01  # |v_j| dt bound [rad]


def test_plane_trust_bounds_a_rotation_by_its_tilt_from_the_normal(g1):
    # Knee above the ground: a rotation theta about a unit axis a changes a height to second
    # order by -theta^2/2 n.r_perp, |n.r_perp| <= |n x a| r, so the bound sqrt(2 eps / r) becomes
    # sqrt(2 eps / (r |n x a|)). Upright base: its local z is the normal (sine floored at 1e-6:
    # 1000x the lever bound, no cap at a tracking speed), local x and y are horizontal (the lever
    # bound, unchanged). Base rolled 30 deg: local z is 30 deg off the normal, bound x sqrt(2).
    off, on = _trust_box(g1, False, (0, 0, 0)), _trust_box(g1, True, (0, 0, 0))
    assert np.all(np.isfinite(on[3:6])) and off[5] < 0.03  # a cap of <= 3 rad/s at dt = 10 ms
    np.testing.assert_allclose(on[5], 1000.0 * off[5], rtol=1e-6)
    np.testing.assert_allclose(on[3:5], off[3:5], rtol=1e-12)
    assert np.all(on[:3] == np.inf) and np.all(off[:3] == np.inf)  # translations are exact
    off, on = _trust_box(g1, False, (np.pi / 6, 0, 0)), _trust_box(g1, True, (np.pi / 6, 0, 0))
    np.testing.assert_allclose(on[5], off[5] * np.sqrt(2.0), rtol=1e-9)
    np.testing.assert_allclose(on[3], off[3], rtol=1e-12)  # local x: still horizontal
    # Local y, rolled 30 deg: (0, cos 30, sin 30), so |n x a| = cos 30 deg.
    np.testing.assert_allclose(on[4], off[4] / np.sqrt(np.cos(np.pi / 6)), rtol=1e-9)
    # The left leg's joints: each bounded by its own axis's tilt, never below the lever bound.
    leg = slice(6, 12)
    assert np.all(on[leg] >= off[leg] * (1 - 1e-12))


def test_plane_trust_is_a_checked_bool(g1):
    with pytest.raises(ConfigError, match="plane_trust"):
        Ground(plane_trust="yes")


def test_the_trust_region_grows_with_the_gap_to_the_ground(g1):
    """``trust_gap_fraction`` f: a pair's tolerated linearization error is max(eps, f d), so its
    rotation bounds sqrt(2 eps / r) grow by sqrt(f d / eps) once f d > eps; 0 keeps eps."""
    con0 = Ground(links=["left_knee"], d_i=1.0, trust_region=4e-4)
    con1 = Ground(links=["left_knee"], d_i=1.0, trust_region=4e-4, trust_gap_fraction=0.1)
    boxes = []
    for con in (con0, con1):
        con.bind(g1)
        state = RobotState(g1)
        state.update(g1.q_reference.copy())
        con.reset(state)
        box = con.compute_bounds(state, 0.01)
        assert box is not None
        boxes.append((box[1].copy(), float(con.model.distances[0])))
    (ub0, d), (ub1, _) = boxes
    assert 0.1 * d > 4e-4  # the knee's hull is more than 4 mm up at the reference posture
    bounded = np.isfinite(ub0)
    assert bounded[3:6].all()  # the base's rotations are bounded by the knee
    np.testing.assert_allclose(ub1[bounded], ub0[bounded] * np.sqrt(0.1 * d / 4e-4), rtol=1e-9)


def test_trust_gap_fraction_is_checked(g1):
    with pytest.raises(ConfigError, match="trust_gap_fraction"):
        Ground(trust_gap_fraction=2.0)
