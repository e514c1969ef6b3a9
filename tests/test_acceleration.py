# SPDX-License-Identifier: Apache-2.0
"""Acceleration level (CRAC eq. 9-11, 30-42): error dynamics, torques, limits, contacts, configs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml
from scipy.linalg import expm

from qpretarget.constraints import CONSTRAINTS
from qpretarget.control.acceleration import PAPER_DAMPING, AccelerationLevel
from qpretarget.control.controller import Controller
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotState

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
ACC_CONFIGS = sorted(CONFIGS.glob("*acceleration*.yaml"))
KP = 300.0
KV = 2.0 * np.sqrt(KP)


def hand_config(
    dt: float, gv: float, *, velocity_gain: float | None = None, **extra: Any
) -> dict[str, Any]:
    """One position task on the right wrist (G1, free-floating base), limits as hard constraints."""
    return {
        "robot": "g1",
        "dt": dt,
        "level": "acceleration",
        "regularization": {"type": "identity", "damping": 0.1},  # paper lambda
        "solver": {"name": "proxsuite", "eps_abs": 1e-10},
        "tasks": [
            {
                "type": "frame",
                "name": "hand",
                "frame": "right_wrist_yaw_link",
                "mode": "position",
                "position_weight": 100.0,
            },
        ],
        "constraints": [{"type": "joint_limits"}, {"type": "velocity_limits"}],
        "acceleration": {"gv": gv, "velocity_gain": velocity_gain, **extra},
    }


def track_step_target(ctrl: Controller, displacement: np.ndarray, duration: float) -> np.ndarray:
    """Step the hand target by ``displacement`` at t = 0 and return the error e(t) (T+1, 3)."""
    task = ctrl.task("hand")
    target = task.position_target + displacement
    errors = [displacement.copy()]
    for _ in range(int(round(duration / ctrl.dt))):
        ctrl.step({"hand": target})
        errors.append(target - task.current_pose(ctrl.state)[0])
    return np.array(errors)


def second_order_response(t: np.ndarray, damping: float, stiffness: float) -> np.ndarray:
    """e(t)/e0 of e'' + damping e' + stiffness e = 0 with e(0) = e0, e'(0) = 0 (uniform t)."""
    A = np.array([[0.0, 1.0], [-stiffness, -damping]])
    step = expm(A * (t[1] - t[0]))  # exact transition over one sample
    x, out = np.array([1.0, 0.0]), np.empty(len(t))
    for k in range(len(t)):
        out[k] = x[0]
        x = step @ x
    return out


# ---------------------------------------------------------------- CRAC eq. 33: error dynamics
def test_error_dynamics_follow_kp_kv() -> None:
    """No constraint active, G_v = 0: the error is the critically damped e0 (1 + w t) exp(-w t)."""
    dt = 1e-3
    ctrl = Controller(hand_config(dt, gv=0.0))
    e0 = np.array([0.01, -0.01, 0.01])  # 1.7 cm: small displacement, Jacobian nearly constant
    e = track_step_target(ctrl, e0, duration=0.6)
    t = np.arange(len(e)) * dt
    w = np.sqrt(KP)
    analytic = (1.0 + w * t) * np.exp(-w * t)
    assert np.allclose(second_order_response(t, KV, KP), analytic, atol=1e-9)  # K_v = 2 sqrt(K_p)
    # Tolerance 5% of |e0| (the acceptance criterion). Error sources: semi-implicit Euler with
    # w dt = 0.017 (global error O(w dt), about 0.3% measured), damping lambda^2/w_task = 1e-4
    # relative, and the nonlinearity left after the exact drift term Jdot v (none to first order).
    deviation = np.abs(e - analytic[:, None] * e0).max() / np.linalg.norm(e0)
    assert deviation < 0.05, deviation
    assert np.linalg.norm(e[-1]) < 0.01 * np.linalg.norm(e0)  # converged (analytic: 5e-4 e0)


def test_error_dynamics_with_velocity_reference() -> None:
    """G_v = 30 (paper): eq. 33's right side -G_v (K e + e') adds to the gains as predicted."""
    dt, K, gv = 1e-3, 10.0, 30.0
    ctrl = Controller(hand_config(dt, gv=gv, velocity_gain=K))
    e0 = np.array([-0.01, 0.01, 0.005])
    e = track_step_target(ctrl, e0, duration=0.6)
    t = np.arange(len(e)) * dt
    # J qdot_c = K e (velocity-level reference, eq. 15-16) and e' = -J qdot, so eq. 33 reads
    # e'' + (K_v + G_v) e' + (K_p + G_v K) e = 0.
    predicted = second_order_response(t, KV + gv, KP + gv * K)
    deviation = np.abs(e - predicted[:, None] * e0).max() / np.linalg.norm(e0)
    assert deviation < 0.05, deviation  # same error budget as above
    # ... while the G_v = 0 response is rejected by the same measure: the test can fail.
    w = np.sqrt(KP)
    unpulled = (1 + w * t) * np.exp(-w * t)
    assert np.abs(e - unpulled[:, None] * e0).max() / np.linalg.norm(e0) > 0.05


# ---------------------------------------------------------------- CRAC eq. 30: torques
@pytest.fixture(scope="module")
def g1_acc() -> Controller:
    cfg = yaml.safe_load((CONFIGS / "g1_augmentation.yaml").read_text())
    cfg["level"] = "acceleration"
    return Controller(cfg)


def test_tau_is_inverse_dynamics(g1_acc: Controller) -> None:
    ctrl = g1_acc
    ctrl.reset()
    model, data = ctrl.robot.model, ctrl.robot.model.createData()
    p_left = ctrl.task("left_hand").position_target.copy()
    p_right = ctrl.task("right_hand").position_target.copy()
    q, v, dt = ctrl.q.copy(), np.zeros(ctrl.robot.nv), ctrl.dt
    for k in range(30):
        s = np.sin(2 * np.pi * k * dt)
        res = ctrl.step(
            {
                "left_hand": p_left + [0.05 * s, 0, 0.05 * s],
                "right_hand": p_right + [0, -0.05 * s, 0],
            }
        )
        assert res.status == "ok", res.messages
        assert res.tau is not None and res.tau.shape == (ctrl.robot.nv,)
        alpha_c = (res.v - v) / dt  # acceleration applied during the tick
        assert np.allclose(alpha_c, ctrl.level_impl.alpha_c, atol=1e-9)
        H = pin.crba(model, data, q)
        H = np.triu(H) + np.triu(H, 1).T
        h = pin.nonLinearEffects(model, data, q, v)
        # 1e-8 [N m] (acceptance); both sides are float64 evaluations of the same dynamics,
        # rounding ~1e-12 at these magnitudes (|tau| <= ~1e3).
        assert np.abs(res.tau - (H @ alpha_c + h)).max() < 1e-8
        q, v = res.q.copy(), res.v.copy()
    assert np.abs(v).max() > 1e-3  # the robot did move: velocity terms were exercised


def test_fulfilled_targets_give_gravity_torque(g1_acc: Controller) -> None:
    ctrl = g1_acc
    q = ctrl.reset()
    res = ctrl.step({})
    # Zero error, zero velocity: alpha_c = 0 (solver tolerance 1e-9) and tau = tau_g(q).
    g = pin.computeGeneralizedGravity(ctrl.robot.model, ctrl.robot.model.createData(), q)
    assert np.abs(res.tau - g).max() < 1e-6
    assert np.abs(res.v).max() < 1e-10


# ---------------------------------------------------------------- limits over the tick
def test_limits_hold_at_acceleration_level() -> None:
    joint = "right_elbow_joint"
    cfg = {
        "robot": {"name": "g1", "velocity_limits": {joint: 1.0}},
        "dt": 0.01,
        "level": "acceleration",
        "tasks": [
            {
                "type": "frame",
                "name": "pelvis",
                "frame": "pelvis",
                "position_weight": 100.0,
                "orientation_weight": 100.0,
            },
            {"type": "posture", "name": "posture", "weight": 1.0},
        ],
        "constraints": [{"type": "joint_limits", "gain": 0.9}, {"type": "velocity_limits"}],
    }
    ctrl = Controller(cfg)
    robot = ctrl.robot
    j = robot.joint_index(joint)
    iq, iv = robot.joint_q_index[j], robot.joint_v_index[j]
    hi = robot.q_max[iq]
    ctrl.step({"posture": {joint: hi + 1.0}})  # target 1 rad beyond the upper limit
    qs, vs = [], []
    for _ in range(150):
        res = ctrl.step({})
        qs.append(res.q.copy())
        vs.append(res.v.copy())
    qs, vs = np.array(qs), np.array(vs)
    lim = np.isfinite(robot.q_min)
    # Tolerance 1e-9: the bounds hold exactly after the clip of v+ (solver eps 1e-9 before).
    assert np.all(qs[:, lim] >= robot.q_min[lim] - 1e-9)
    assert np.all(qs[:, lim] <= robot.q_max[lim] + 1e-9)
    assert np.all(np.abs(vs) <= robot.v_max + 1e-9)
    # Both limits were active (else this test could not fail): the joint ran at its velocity
    # limit, then stopped just inside its position limit.
    assert np.abs(vs[:, iv]).max() > 1.0 - 1e-6
    assert hi - qs[-1, iq] < 1e-3


@pytest.mark.skipif(
    "contacts" not in CONSTRAINTS, reason="the contacts constraint module is not installed"
)
def test_contacts_hold_as_first_priority() -> None:
    cfg = {
        "robot": "g1",
        "dt": 0.01,
        "level": "acceleration",
        "tasks": [
            {
                "type": "frame",
                "name": "hand",
                "frame": "right_wrist_yaw_link",
                "mode": "position",
                "position_weight": 100.0,
            },
            {
                "type": "frame",
                "name": "pelvis",
                "frame": "pelvis",
                "mode": "position",
                "position_weight": 100.0,
            },
            {"type": "posture", "name": "posture", "weight": 1.0e-3},
        ],
        "constraints": [
            {"type": "contacts"},
            {"type": "joint_limits"},
            {"type": "velocity_limits"},
        ],
    }
    ctrl = Controller(cfg)
    sole_ids = [ctrl.robot.frame_id(f.frame) for f in ctrl.robot.feet.values()]
    soles0 = [ctrl.state.frame_placement(i).copy() for i in sole_ids]
    p_hand = ctrl.task("hand").position_target.copy()
    p_pelvis = ctrl.task("pelvis").position_target.copy()
    for k in range(100):
        s = np.sin(2 * np.pi * k * ctrl.dt)
        res = ctrl.step(
            {
                "hand": p_hand + [0.1 * s, -0.1 * s, 0.1 * s],
                "pelvis": p_pelvis + [0.0, 0.03 * s, -0.03 * s],
            }
        )
        assert res.status == "ok", res.messages
    for i, M0 in zip(sole_ids, soles0, strict=True):
        M = ctrl.state.frame_placement(i)
        # Contacts are equalities on v+ with drift correction: the soles stay put to second
        # order in (v dt); 1e-4 m / rad leaves room for that while a free foot would move cm.
        assert np.linalg.norm(M.translation - M0.translation) < 1e-4
        assert np.linalg.norm(pin.log3(M0.rotation.T @ M.rotation)) < 1e-4
    # and the hand did move (the tasks were not frozen by the contacts)
    assert np.linalg.norm(ctrl.task("hand").current_pose(ctrl.state)[0] - p_hand) > 0.02


# ---------------------------------------------------------------- drift terms
def test_drift_terms_match_finite_differences() -> None:
    cfg = {
        "robot": "g1",
        "level": "acceleration",
        "tasks": [
            {
                "type": "frame",
                "name": "hand",
                "frame": "right_wrist_yaw_link",
                "offset": [0.05, 0.0, 0.02],
            },
            {"type": "com", "name": "com"},
            {"type": "posture", "name": "posture"},
        ],
    }
    ctrl = Controller(cfg)
    lvl: AccelerationLevel = ctrl.level_impl
    robot = ctrl.robot
    rng = np.random.default_rng(3)
    q = robot.q_reference.copy()
    q[7:] += 0.2 * rng.standard_normal(robot.nv - 6)
    v = rng.standard_normal(robot.nv)
    ctrl.state.update(q, v)
    tasks = list(ctrl.tasks.values())
    J0 = [t.compute_jacobian(ctrl.state).copy() for t in tasks]
    drifts = lvl.compute_drifts(ctrl.state)
    h = 1e-6
    shifted = RobotState(robot)
    shifted.update(pin.integrate(robot.model, q, v * h), v)
    for t, J, d in zip(tasks, J0, drifts, strict=True):
        fd = (t.compute_jacobian(shifted) - J) @ v / h
        # Forward difference with h = 1e-6: truncation ~h |d2J/dq2| |v|^3 ~ 1e-5 here.
        assert np.allclose(d, fd, atol=1e-4), t.name
    # The finite-difference fallback (tasks without an analytic drift) agrees with the CoM's.
    lvl._drift_kind[1] = "finite_difference"
    lvl._fd_state = RobotState(robot)
    assert np.allclose(lvl.compute_drifts(ctrl.state)[1], drifts[1], atol=1e-5)


# ---------------------------------------------------------------- configuration
def test_paper_defaults() -> None:
    cfg = hand_config(0.01, gv=30.0)
    del cfg["acceleration"], cfg["regularization"]
    lvl: AccelerationLevel = Controller(cfg).level_impl
    assert (lvl.gains.kp, lvl.gains.kv, lvl.gains.gv) == (300.0, pytest.approx(KV), 30.0)
    assert lvl.damping == PAPER_DAMPING == 0.1


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"kpp": 10}, r"acceleration\.kpp: unknown key 'kpp'.*Did you mean 'kp'"),
        ({"kp": -1.0}, r"acceleration: kp \[1/s\^2\] must be a finite number > 0"),
        ({"gv": "fast"}, r"acceleration: gv \[1/s\] must be a number"),
        ([300, 30], r"acceleration: expected a mapping"),
    ],
)
def test_bad_acceleration_section(section: Any, match: str) -> None:
    cfg = hand_config(0.01, gv=30.0)
    cfg["acceleration"] = section
    with pytest.raises(ConfigError, match=match):
        Controller(cfg)


@pytest.mark.parametrize("path", ACC_CONFIGS, ids=[p.stem for p in ACC_CONFIGS])
def test_acceleration_configs_track(path: Path) -> None:
    ctrl = Controller.from_yaml(path)
    assert ctrl.level == "acceleration"
    hand = next(n for n in ctrl.tasks if "right" in n and ("wrist" in n or "hand" in n))
    feet = [n for n in ctrl.tasks if n.endswith("_foot")]
    p0 = ctrl.task(hand).position_target.copy()
    target = p0 + np.array([0.02, -0.02, 0.02])
    foot_error = 0.0
    for _ in range(40):
        res = ctrl.step({hand: target})
        assert res.status == "ok", res.messages
        assert res.tau is not None and np.all(np.isfinite(res.tau))
        foot_error = max([foot_error, *(res.task_errors[f] for f in feet)])
    # 0.4 s at K_p = 300: the critically damped response alone leaves 0.3% of the error;
    # 20% leaves room for the compromise with the other tasks of over-constrained Task Set 1.
    assert res.task_errors[hand] < 0.2 * np.linalg.norm(target - p0)
    # Feet (first priority or 100x weight) stay put: their error is the O(dt^2) integration
    # residue that K_p, K_v correct (measured < 1e-4 m); 1e-3 m would be a visible slide.
    assert foot_error < 1e-3


def test_conflicting_bounds_give_and_are_reported() -> None:
    """A joint reset 0.2 rad beyond its limit: returning within a tick needs more than v_max."""
    joint = "right_elbow_joint"
    cfg = {
        "robot": {"name": "g1", "velocity_limits": {joint: 0.5}},
        "dt": 0.01,
        "level": "acceleration",
        "tasks": [{"type": "posture", "name": "posture", "weight": 1.0}],
        "constraints": [{"type": "joint_limits", "gain": 0.9}, {"type": "velocity_limits"}],
    }
    ctrl = Controller(cfg)
    robot = ctrl.robot
    j = robot.joint_index(joint)
    iq, iv = robot.joint_q_index[j], robot.joint_v_index[j]
    q0 = robot.q_reference.copy()
    q0[iq] = robot.q_max[iq] + 0.2
    ctrl.reset(q0)
    res = ctrl.step({})
    # joint_limits (importance 90) gives to velocity_limits (95): the joint heads back at v_max.
    assert res.status == "relaxed" and "joint_limits" in res.relaxed, (res.status, res.relaxed)
    assert res.v[iv] == pytest.approx(-0.5, abs=1e-9)
    assert np.all(np.abs(res.v) <= robot.v_max + 1e-12)
    assert np.all(np.isfinite(res.tau))


@pytest.mark.skipif(
    "contacts" not in CONSTRAINTS, reason="the contacts constraint module is not installed"
)
def test_conflicting_rows_relax_through_the_fallback() -> None:
    """Feet fixed, legs nearly frozen, a knee outside its range: contacts and limits conflict."""
    from qpretarget import load_robot

    slow = {
        n: 0.01 for n in load_robot("g1").joint_names if n.split("_")[1] in ("hip", "knee", "ankle")
    }
    del slow["left_knee_joint"]
    cfg = {
        "robot": {"name": "g1", "velocity_limits": slow},
        "dt": 0.01,
        "level": "acceleration",
        "tasks": [{"type": "posture", "name": "posture", "weight": 1.0}],
        "constraints": [
            {"type": "contacts"},
            {"type": "joint_limits", "gain": 0.9},
            {"type": "velocity_limits"},
        ],
    }
    ctrl = Controller(cfg)
    if ctrl.fallback is None:
        pytest.skip("the relaxation module is not installed")
    robot = ctrl.robot
    iq = robot.joint_q_index[robot.joint_index("left_knee_joint")]
    q0 = robot.q_reference.copy()
    q0[iq] = robot.q_min[iq] - 0.1
    ctrl.reset(q0)
    res = ctrl.step({})
    # The least important constraint gives (joint_limits, 90 < contacts 100, velocity_limits 95);
    # the tick is not held and the torques are usable.
    assert res.status == "relaxed" and set(res.relaxed) == {"joint_limits"}, res.relaxed
    assert any("conflicted" in m for m in res.messages)
    assert np.all(np.abs(res.v) <= robot.v_max + 1e-9)
    assert np.all(np.isfinite(res.tau))
    # the knee still moves back towards its range, as fast as the frozen legs allow
    assert res.v[robot.joint_v_index[robot.joint_index("left_knee_joint")]] > 0.0


def test_doc_yaml_runs() -> None:
    """The YAML of docs/schemes/acceleration.md builds and runs (doc snippets must not rot)."""
    doc = (CONFIGS.parent / "docs" / "schemes" / "acceleration.md").read_text()
    snippet = doc.split("```yaml\n", 1)[1].split("```", 1)[0]
    ctrl = Controller(yaml.safe_load(snippet))
    assert isinstance(ctrl.level_impl, AccelerationLevel)
    assert ctrl.level_impl.gains.kv == pytest.approx(KV)
    p = ctrl.task("right_wrist").position_target + [0.01, 0.0, 0.0]
    for _ in range(3):
        res = ctrl.step({"right_wrist": p})
    assert res.status == "ok" and res.tau.shape == (ctrl.robot.nv,)


def test_observers_and_stage_timings(g1_acc: Controller) -> None:
    seen = []
    g1_acc.add_observer(seen.append)
    try:
        g1_acc.reset()
        res = g1_acc.step({})
    finally:
        g1_acc.remove_observer(seen.append)
    assert seen == [res] and seen[0].tau is not None
    for stage in ("drift", "velocity_qp", "acceleration_qp", "dynamics", "kinematics"):
        assert g1_acc.last_timings[stage] >= 0.0
