"""Physics replay of a real retargeted G1 run: it stays up, an infeasible edit falls or saturates,
the result is deterministic and independent of the joint order, bad input is refused up front."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from qpretarget.physics.metrics import summarize
from qpretarget.physics.replay import PhysicsInputError, check_run, replay_run
from qpretarget.trajectory import RobotTrajectory

pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def run(drink_run):
    return RobotTrajectory.load(drink_run)


@pytest.fixture(scope="module")
def checked(run, g1_physics):
    _, pm = g1_physics
    return check_run(run, pm=pm)


def test_static_balance_run_survives_unassisted(checked):
    m, free, helped = checked
    u = m["unassisted"]
    assert u["survived_fraction"] == 1.0 and m["verdict"] in ("ok", "saturates")
    # The base stays on the reference (measured 20-40 mm p95: the servoed body sways).
    assert u["root_position_error_mm"]["p95"] < 100.0
    # Stiff servo: joints follow to a fraction of a degree (measured 0.3 deg RMS).
    assert u["joint_tracking_rms_deg"]["overall"] < 1.0
    # Both feet planted: they carry the weight (mean 98-100 %; 90 % leaves room for the
    # oscillation of a contact transient) and agree with the run's contact labels.
    assert u["feet"]["weight_share_mean"] > 0.9
    assert u["feet"]["contact_match"] > 0.95
    # The soft weld of the assisted replay takes little on a feasible clip (measured ~10 % BW p95).
    assert m["assisted"]["assist"]["force_bw_pct"]["p95"] < 20.0
    assert helped is not None and helped.fallen_at is None
    # Dynamically balanced as retargeted: the reference ZMP never leaves the soles.
    assert m["reference_zmp"]["frames_outside"] == 0


def test_deterministic(run, g1_physics, checked):
    _, pm = g1_physics
    again = replay_run(run, pm)
    first = checked[1]
    for f in ("pelvis_height", "joint_err", "foot_force", "root_pos_err", "tilt_deg"):
        np.testing.assert_array_equal(getattr(first, f), getattr(again, f))
    a = summarize(first, None, pm)["unassisted"]
    b = summarize(again, None, pm)["unassisted"]
    for k in ("wall_time_s", "real_time_factor"):
        a.pop(k), b.pop(k)
    assert json.dumps(a) == json.dumps(b)


def test_joint_order_does_not_matter(run, g1_physics, checked):
    """Joints are matched by name: permuting the run's joint columns gives the same replay."""
    _, pm = g1_physics
    perm = np.random.default_rng(1).permutation(len(run.joint_names))
    shuffled = dataclasses.replace(
        run,
        q=np.hstack([run.q[:, :7], run.q[:, 7:][:, perm]]),
        v=np.hstack([run.v[:, :6], run.v[:, 6:][:, perm]]),
        joint_names=[run.joint_names[i] for i in perm],
    )
    s = replay_run(shuffled, pm)
    np.testing.assert_array_equal(s.pelvis_height, checked[1].pelvis_height)


def test_com_pushed_past_the_toes_falls(run, g1_physics):
    """Bend the trunk forward (hip pitch -1.2 rad over 0.5 s): the CoM leaves the soles."""
    _, pm = g1_physics
    q = run.q.copy()
    ramp = np.clip((run.t - 1.0) / 0.5, 0.0, 1.0)
    for j in ("left_hip_pitch_joint", "right_hip_pitch_joint"):
        q[:, 7 + run.joint_names.index(j)] -= 1.2 * ramp
    bent = dataclasses.replace(run, q=q, v=np.vstack([run.v[:1], np.zeros_like(run.v[1:])]))
    m = check_run(bent, pm=pm, assisted=False)[0]
    assert m["verdict"] == "falls"
    assert m["unassisted"]["survived_fraction"] < 1.0
    # The run itself says why: its ZMP leaves the soles before the robot falls.
    assert m["reference_zmp"]["outside_before_fall"] is True


def test_step_discontinuity_saturates_or_falls(run, g1_physics):
    """Both knees jump by 1 rad in one frame: the PD torques hit the URDF limits."""
    _, pm = g1_physics
    q = run.q.copy()
    k0 = len(run.t) // 2
    for j in ("left_knee_joint", "right_knee_joint"):
        q[k0:, 7 + run.joint_names.index(j)] += 1.0
    stepped = dataclasses.replace(run, q=q)
    m = summarize(replay_run(stepped, pm), None, pm)
    assert m["verdict"] in ("falls", "saturates")
    assert m["unassisted"]["saturation"]["frames"] > 0
    assert "left_knee_joint" in m["unassisted"]["saturation"]["per_joint_frames"]


def test_tilted_base_reference_needs_assistance(run, g1_physics, checked):
    """Tilt the base reference 20 deg forward from 1 s on: only the virtual wrench holds it."""
    import pinocchio as pin

    _, pm = g1_physics
    q = run.q.copy()
    for k in np.nonzero(run.t >= 1.0)[0]:
        R = pin.Quaternion(q[k, 6], q[k, 3], q[k, 4], q[k, 5]).toRotationMatrix()
        q[k, 3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0, 0.35, 0) @ R).coeffs()
    tilted = dataclasses.replace(run, q=q)
    m = summarize(replay_run(tilted, pm), replay_run(tilted, pm, assisted=True), pm)
    feasible = checked[0]["assisted"]["assist"]["torque_Nm"]["p95"]
    assert m["assisted"]["assist"]["torque_Nm"]["p95"] > 5 * feasible


def test_joint_count_mismatch_refused_before_simulation(run, g1_physics, monkeypatch):
    import mujoco

    _, pm = g1_physics
    short = dataclasses.replace(
        run, q=run.q[:, :-1], v=run.v[:, :-1], joint_names=run.joint_names[:-1]
    )

    def no_step(*a, **k):
        raise AssertionError("simulated")

    monkeypatch.setattr(mujoco, "mj_step", no_step)
    with pytest.raises(PhysicsInputError, match=r"28 joints .* 29 actuated joints"):
        check_run(short, pm=pm)


def test_gravity_feedforward_balances_the_base_and_cuts_the_sag(run, g1_physics, checked):
    """The stance knees' feed-forward carries the body (not just the shank's own weight);
    without the feed-forward the stiff servo sags by tau/kp and the base drifts further."""
    import pinocchio as pin

    from qpretarget.physics.replay import gravity_feedforward

    robot, pm = g1_physics
    cols = [run.joint_names.index(j) for j in pm.joint_names]
    k = len(run.t) - 1
    tau = gravity_feedforward(
        pm, run.q[k : k + 1, :7], run.q[k : k + 1, 7:][:, cols], np.ones((1, 2), bool)
    )
    q = run.q[k]
    g = pin.computeGeneralizedGravity(robot.model, robot.data, q)
    # Knees and ankles hold the body: their torques are far from the limbs-only gravity torques.
    knee = pm.joint_names.index("left_knee_joint")
    assert abs(tau[0, knee] - g[robot.joint_v_index[knee]]) > 5.0
    without = summarize(replay_run(run, pm, feedforward="none"), None, pm)["unassisted"]
    with_ff = checked[0]["unassisted"]
    assert with_ff["root_position_error_mm"]["p95"] < without["root_position_error_mm"]["p95"]
