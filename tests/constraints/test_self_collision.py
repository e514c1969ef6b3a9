# SPDX-License-Identifier: Apache-2.0
"""self_collision: damper rows, auto pair selection, acceptance (hands through the body), recovery."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.collision import CollisionModel
from qpretarget.constraints.self_collision import SelfCollision
from qpretarget.control.controller import Controller
from qpretarget.errors import ConfigError, UnknownNameError
from qpretarget.robot import RobotModel, RobotState

#: The workload's 20 G1 pairs: hands/forearms/elbows vs torso, pelvis, thighs, head; hand vs hand.
PAIRS = [
    ["left_wrist_yaw_link", "torso_link"], ["right_wrist_yaw_link", "torso_link"],
    ["left_wrist_yaw_link", "pelvis_contour_link"], ["right_wrist_yaw_link", "pelvis_contour_link"],
    ["left_wrist_yaw_link", "left_hip_yaw_link"], ["right_wrist_yaw_link", "right_hip_yaw_link"],
    ["left_wrist_yaw_link", "right_hip_yaw_link"], ["right_wrist_yaw_link", "left_hip_yaw_link"],
    ["left_wrist_roll_link", "torso_link"], ["right_wrist_roll_link", "torso_link"],
    ["left_elbow_link", "torso_link"], ["right_elbow_link", "torso_link"],
    ["left_wrist_roll_link", "pelvis_contour_link"], ["right_wrist_roll_link", "pelvis_contour_link"],
    ["left_wrist_yaw_link", "right_wrist_yaw_link"], ["left_wrist_roll_link", "right_wrist_roll_link"],
    ["left_wrist_yaw_link", "right_wrist_roll_link"], ["right_wrist_yaw_link", "left_wrist_roll_link"],
    ["left_wrist_yaw_link", "head_link"], ["right_wrist_yaw_link", "head_link"],
]  # fmt: skip
D_S, D_I = 0.03, 0.10


@pytest.fixture(scope="module")
def g1() -> RobotModel:
    return RobotModel.from_name("g1")


def config(with_collision: bool) -> dict:
    """Feet held by contacts, pelvis and torso held, hands tracked (gain 20/s), posture."""
    cons = [
        {"type": "contacts"},
        {"type": "joint_limits", "gain": 0.95},
        {"type": "velocity_limits"},
    ]
    if with_collision:
        cons.append({"type": "self_collision", "pairs": PAIRS, "d_s": D_S, "d_i": D_I})
    return {
        "robot": "g1",
        "dt": 0.01,
        "regularization": {"type": "identity", "damping": 0.05},
        "tasks": [
            {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "pose",
             "position_weight": 100.0, "orientation_weight": 100.0},
            {"type": "frame", "name": "torso", "frame": "torso_link", "mode": "orientation",
             "orientation_weight": 100.0},
            {"type": "frame", "name": "left_hand", "frame": "left_rubber_hand", "mode": "position",
             "position_weight": 100.0, "gain": 20.0},
            {"type": "frame", "name": "right_hand", "frame": "right_rubber_hand",
             "mode": "position", "position_weight": 100.0, "gain": 20.0},
            {"type": "posture", "name": "posture", "weight": 0.1},
        ],
        "constraints": cons,
    }  # fmt: skip


def hands_through_body(ctrl: Controller, n: int = 150):
    """Targets: left hand straight through the torso, then the two hands through each other."""
    st = ctrl.state
    robot = ctrl.robot
    torso = st.frame_placement(robot.frame_id("torso_link")).translation.copy()
    lh = st.frame_placement(robot.frame_id("left_rubber_hand")).translation.copy()
    rh = st.frame_placement(robot.frame_id("right_rubber_hand")).translation.copy()
    through = torso + np.array([0.0, -0.2, 0.05])  # right of the torso: the path crosses it
    front_l = torso + np.array([0.25, 0.05, 0.05])
    front_r = torso + np.array([0.25, -0.05, 0.05])
    for k in range(n):  # phase 1: left hand through the torso, right hand stays
        s = 0.5 - 0.5 * np.cos(np.pi * k / (n - 1))
        yield {"left_hand": (1 - s) * lh + s * through, "right_hand": rh}
    for k in range(n):  # phase 2: both hands in front of the chest, then swapped
        s = 0.5 - 0.5 * np.cos(np.pi * k / (n - 1))
        yield {
            "left_hand": (1 - s) * through + s * front_r,
            "right_hand": (1 - s) * rh + s * front_l,
        }
    for k in range(n):
        s = 0.5 - 0.5 * np.cos(np.pi * k / (n - 1))
        yield {
            "left_hand": (1 - s) * front_r + s * front_l,
            "right_hand": (1 - s) * front_l + s * front_r,
        }


def run(ctrl: Controller, targets, meter: CollisionModel):
    dmin, statuses = [], []
    for t in targets:
        res = ctrl.step(t)
        assert np.all(np.isfinite(res.q))
        statuses.append(res.status)
        dmin.append(meter.compute_all(ctrl.state)[0].min())
    return np.array(dmin), statuses


@pytest.fixture(scope="module")
def meter(g1) -> CollisionModel:
    """Exact distances of the 20 pairs (no broad phase), independent of the constraint."""
    return CollisionModel(g1, [tuple(p) for p in PAIRS], broad_phase=False)


def test_constraint_keeps_the_hands_out_of_the_body(g1, meter):
    # Acceptance: the minimum pair distance never goes below d_s - 1 mm with the constraint;
    # the same targets without it penetrate (pair distance < 0), so the constraint is what holds.
    free, _ = run(Controller(config(False)), hands_through_body(Controller(config(False))), meter)
    assert free.min() < 0.0
    ctrl = Controller(config(True))
    held, statuses = run(ctrl, hands_through_body(ctrl), meter)
    assert held.min() >= D_S - 1e-3, f"min pair distance {held.min():.4f} m"
    assert statuses.count("held") == 0


def test_rows_are_minus_the_distance_rate(g1):
    # Each active row C_i satisfies C_i v = -d'(q) v: checked against finite differences of
    # the exact distance along q ⊕ h v (GJK tolerance tightened to 1e-12, h = 1e-6; tolerance
    # 2e-5 per unit |v| covers the O(h) curvature term).
    con = SelfCollision(pairs=PAIRS, d_s=D_S, d_i=0.5, broad_phase=False, trust_region=None)
    con.bind(g1)
    for req in con.model.gdata.distanceRequests:
        req.gjk_tolerance = 1e-12
    state = RobotState(g1)
    q0 = g1.q_reference.copy()
    q0[g1.joint_q_index[g1.joint_index("left_elbow_joint")]] = 1.4
    state.update(q0)
    blk = con.compute_rows(state, 0.01)
    active = np.isfinite(blk.u)
    assert active.sum() >= 5
    d0 = con.model.distances.copy()
    C = blk.C.copy()
    rng = np.random.default_rng(3)
    for _ in range(3):
        v = rng.standard_normal(g1.nv)
        state.update(pin.integrate(g1.model, q0, 1e-6 * v))
        d1 = con.model.compute_all(state)[0]
        rate = (d1 - d0) / 1e-6
        np.testing.assert_allclose(C[active] @ v, -rate[active], atol=2e-5 * np.linalg.norm(v))


def test_damper_bound_and_fixed_shape(g1):
    # u = gain_per_tick (d - d_s) / dt on active rows (exact formula: 1e-12), inactive rows are
    # zero with infinite bounds, and the block keeps one row per pair at every tick.
    con = SelfCollision(pairs=PAIRS, d_s=D_S, d_i=D_I, gain_per_tick=0.5)
    con.bind(g1)
    state = RobotState(g1)
    q = g1.q_reference.copy()
    for angle in (0.9, 1.3, 1.7, 2.0):
        q[g1.joint_q_index[g1.joint_index("left_elbow_joint")]] = angle
        q[g1.joint_q_index[g1.joint_index("left_shoulder_roll_joint")]] = -0.2
        state.update(q)
        blk = con.compute_rows(state, 0.01)
        assert blk.C.shape == (len(PAIRS), g1.nv) and con.n_rows == len(PAIRS)
        d = con.model.distances
        act = np.isfinite(blk.u)
        np.testing.assert_allclose(
            blk.u[act], np.maximum(0.5 * (d[act] - D_S) / 0.01, -con.recovery_speed), atol=1e-12
        )
        assert np.all(d[act] < D_I)
        assert np.all(blk.C[~act] == 0.0) and np.all(np.isneginf(blk.l))


@pytest.mark.parametrize("robot_name", ["g1", "talos"])
def test_auto_pairs_are_reproducible_and_not_touching(robot_name, g1):
    robot = g1 if robot_name == "g1" else RobotModel.from_name("talos")
    a = SelfCollision(pairs="auto", d_s=0.02)
    a.bind(robot)
    b = SelfCollision(pairs="auto", d_s=0.02)
    b.bind(robot)
    assert a.pairs == b.pairs and len(a.pairs) > 50  # same list, same order
    # No kept pair touches at the reference posture (exact distances, 1e-6: GJK).
    d = CollisionModel(robot, a.pairs, broad_phase=False).compute_all(RobotState(robot))[0]
    assert d.min() >= a.touch_distance - 1e-6
    # No kept pair is pushed apart at rest: safety distances never exceed rest distances
    # (pairs close at rest get min(d_s, rest_fraction x rest)).
    assert np.all(a.safety <= d + 1e-6) and a.safety.min() > 0
    np.testing.assert_allclose(a.safety, np.minimum(0.02, 0.25 * d), atol=1e-6)
    reasons = " ".join(a.left_out)
    assert "adjacent" in reasons
    lines = a.describe()
    assert any(line.startswith("left out:") for line in lines)
    assert lines[0].startswith(f"{len(a.pairs)} pairs (auto")
    full = a.describe(full=True)  # `qpretarget info CONFIG --pairs`: every pair, every reason
    assert sum(line.startswith("  keep ") for line in full) == len(a.pairs)
    n_out = sum(len(v) for v in a.left_out.values())
    assert sum(line.startswith("  ") and " / " in line for line in full) == len(a.pairs) + n_out
    shapes = a.model.shapes
    joints = {n: s.joint for n, s in zip(a.model.bodies, shapes, strict=True)}
    parents = robot.model.parents
    for x, y in a.pairs:  # no adjacent pair kept
        assert joints[x] != joints[y] and parents[joints[x]] != joints[y]
        assert parents[joints[y]] != joints[x]
    if robot_name == "talos":  # Talos has an SRDF with disabled pairs
        assert any("SRDF" in r for r in a.left_out)
    assert a.n_rows == min(len(a.pairs), 24)


def test_recovery_from_inside_a_pair(g1, meter):
    # Start 2 cm inside a pair: every tick returns a finite step, the violation is reported by
    # the constraint, and the pair is back beyond d_s within 50 ticks (1e-4 m: GJK + QP).
    free = Controller(config(False))
    pen = None
    for t in hands_through_body(free):
        free.step(t)
        d = meter.compute_all(free.state)[0]
        if d.min() <= -0.02:
            pen = free.state.q.copy()
            break
    assert pen is not None
    ctrl = Controller(config(True))
    ctrl.reset(pen)
    con = ctrl.constraint("self_collision")
    back = None
    for k in range(60):
        res = ctrl.step()
        assert np.all(np.isfinite(res.v)) and res.status != "held"
        if k == 0:
            assert con.violations and max(con.violations.values()) >= D_S + 0.02 - 1e-3
        if back is None and meter.compute_all(ctrl.state)[0].min() >= D_S - 1e-4:
            back = k + 1
    assert back is not None and back <= 50, back


def test_bad_configurations_are_reported(g1):
    with pytest.raises(ConfigError, match="d_i .* must be larger"):
        SelfCollision(pairs=PAIRS, d_s=0.1, d_i=0.05)
    with pytest.raises(ConfigError, match="give one of xi"):
        SelfCollision(pairs=PAIRS, xi=0.1, gain_per_tick=0.5)
    with pytest.raises(ConfigError, match="gain_per_tick must be in"):
        SelfCollision(pairs=PAIRS, gain_per_tick=2.0)
    with pytest.raises(ConfigError, match="'auto' or a list"):
        SelfCollision(pairs="all")
    con = SelfCollision(pairs=[["left_wrist_yaw_link", "torso_lnk"]])
    with pytest.raises(UnknownNameError, match="torso_link"):
        con.bind(g1, path="constraints[3]")


def test_robot_without_collision_geometry_needs_optional(repo_dir):
    """A clear refusal, or (``optional: true``) a run without the constraint and a warning."""
    base = {
        "robot": {"urdf": str(repo_dir / "configs" / "robots" / "planar_3dof.urdf"),
                  "free_flyer": False},
        "dt": 0.01,
        "tasks": [{"type": "posture", "name": "posture", "weight": 1.0}],
    }  # fmt: skip
    with pytest.raises(ConfigError, match="no collision geometry.*optional: true"):
        Controller({**base, "constraints": [{"type": "self_collision"}]})
    with pytest.warns(UserWarning, match="self_collision is off"):
        ctrl = Controller({**base, "constraints": [{"type": "self_collision", "optional": True}]})
    con = ctrl.constraint("self_collision")
    assert con.disabled and con.n_rows == 0 and con.pairs == []
    assert ctrl.step().status == "ok"
    assert any("disabled (optional: true)" in line for line in con.describe())


def test_include_and_exclude_name_unknown_bodies_with_close_names(g1):
    con = SelfCollision(pairs="auto", include=[["left_hip_rol_link", "pelvis_contour_link"]])
    with pytest.raises(UnknownNameError, match="left_hip_roll_link"):
        con.bind(g1, path="constraints[2]")
    with pytest.raises(ConfigError, match="include"):
        SelfCollision(pairs=PAIRS, include=[["left_hip_roll_link", "pelvis_contour_link"]])


def test_auto_rows_keep_their_slot(g1):
    """Capped rows: a pair keeps its QP row while it stays among the closest (warm start)."""
    con = SelfCollision(pairs="auto", max_rows=4)
    con.bind(g1)
    first = con._slots(np.array([3, 7, 9]))
    again = con._slots(np.array([3, 9, 11]))  # 7 leaves, 11 arrives and takes 7's row
    assert first.tolist() == [0, 1, 2] and again.tolist() == [0, 2, 1]
    assert con._slots(np.array([11, 20, 30, 40])).tolist() == [1, 0, 2, 3]


def test_auto_slots_repeat_and_reset(g1):
    """The same row pairs as last tick keep their rows; a reset forgets them (fresh slots)."""
    from qpretarget.robot import RobotState

    con = SelfCollision(pairs="auto", max_rows=4)
    con.bind(g1)
    assert con._slots(np.array([3, 7, 9])).tolist() == [0, 1, 2]
    assert con._slots(np.array([7, 9, 12])).tolist() == [1, 2, 0]  # 3 left, 12 took row 0
    assert con._slots(np.array([7, 9, 12])).tolist() == [1, 2, 0]  # unchanged set: same rows
    con.reset(RobotState(g1))
    assert con._slots(np.array([7, 9, 12])).tolist() == [0, 1, 2]  # as in a fresh run


HIP_PAIRS = [
    ["left_hip_roll_link", "pelvis_contour_link"],
    ["right_hip_roll_link", "pelvis_contour_link"],
]


def test_pair_safety_frees_a_hip_that_nests_into_the_pelvis(g1):
    """``safety:`` sets a pair's safety distance in place of the rest rule (min(d_s, 0.25 rest)).

    G1's hip-roll motor folds into the pelvis shell as the hip flexes: 24 mm apart at the
    reference, 0.4 mm at 2 rad. The rest rule keeps it 6 mm away, which holds the hip at about
    1.15 rad; with 2 mm it may flex on. The bounds are compared exactly (1e-12: the same
    arithmetic) and the pair's distance is the constraint's own.
    """
    rest = SelfCollision(pairs="auto", include=HIP_PAIRS)
    rest.bind(g1)
    over = SelfCollision(pairs="auto", include=HIP_PAIRS, safety=[[*HIP_PAIRS[0], 0.002]])
    over.bind(g1)
    assert over.pairs == rest.pairs
    k = {frozenset(p): i for i, p in enumerate(over.pairs)}
    left, right = (k[frozenset(p)] for p in HIP_PAIRS)
    assert over.safety[left] == 0.002 and rest.safety[left] > 0.005  # 0.25 x 24 mm
    assert over.safety[right] == rest.safety[right]  # the other hip keeps the rest rule
    others = np.ones(len(over.pairs), bool)
    others[left] = False
    np.testing.assert_array_equal(over.safety[others], rest.safety[others])
    assert any(f"safety {2.0:.1f} mm" in line for line in over.describe(full=True))
    # The left hip flexed to 1.4 rad: the pair is between the two safety distances.
    q = g1.q_reference.copy()
    q[g1.joint_q_index[g1.joint_index("left_hip_pitch_joint")]] = -1.4
    q[g1.joint_q_index[g1.joint_index("left_hip_roll_joint")]] = 0.0
    state = RobotState(g1)
    state.update(q)
    name = f"{HIP_PAIRS[0][0]}/{HIP_PAIRS[0][1]}"
    for con in (rest, over):
        con.compute_rows(state, 0.01)
    d = over.model.distances[left]
    assert 0.002 < d < rest.safety[left]
    # With the rest rule the pair is inside its safety distance (pushed apart, reported); with
    # 2 mm it may still approach by half its gap per tick.
    assert rest.violations[name] == pytest.approx(rest.safety[left] - d, abs=1e-12)
    assert name not in over.violations


def test_pair_safety_is_validated(g1):
    with pytest.raises(ConfigError, match=r"list of \[link_a, link_b, distance"):
        SelfCollision(pairs="auto", safety=[["left_hip_roll_link", "pelvis_contour_link"]])
    with pytest.raises(ConfigError, match=r"in \(0, d_i = 0.08\)"):
        SelfCollision(pairs="auto", safety=[[*HIP_PAIRS[0], 0.0]])
    with pytest.raises(ConfigError, match=r"in \(0, d_i = 0.08\)"):
        SelfCollision(pairs="auto", safety=[[*HIP_PAIRS[0], 0.1]])
    with pytest.raises(ConfigError, match="list of"):
        SelfCollision(pairs="auto", safety="left_hip_roll_link")
    con = SelfCollision(pairs="auto", safety=[["left_hip_rol_link", "pelvis_contour_link", 0.002]])
    with pytest.raises(UnknownNameError, match="left_hip_roll_link"):
        con.bind(g1)
    # Without `include` the hip pair is left out (chain neighbours close at rest).
    con = SelfCollision(pairs="auto", safety=[[*HIP_PAIRS[0], 0.002]])
    with pytest.raises(ConfigError, match="does not keep.*add it to `include`"):
        con.bind(g1)
