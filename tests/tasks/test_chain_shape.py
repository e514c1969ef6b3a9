# SPDX-License-Identifier: Apache-2.0
"""The chain_shape task (Tosun 2014): metrics, normalization, Jacobian, QP step, validation."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget import Controller
from qpretarget.errors import ConfigError, TargetError
from qpretarget.retarget.shape import retarget_pose, robot_chain
from qpretarget.tasks.chain_shape import (
    ChainShapeTask,
    normalized_pose,
    sample_parameters,
    shape_errors,
)

G1_ARM = ["left_shoulder_roll_link", "left_elbow_link", "left_wrist_pitch_link", "left_rubber_hand"]


def g1_config(**task) -> dict:
    """Floating-base G1 (free flyer): the chain's base and reference frame both move."""
    spec = {"type": "chain_shape", "name": "arm", "frames": G1_ARM, "reference_frame": "torso_link"}
    spec.update(task)
    return {
        "robot": "g1",
        "dt": 0.01,
        "regularization": {"type": "identity", "damping": 1e-2},
        "solver": {"name": "proxsuite", "eps_abs": 1e-10},
        "tasks": [spec],
    }


@pytest.fixture(scope="module")
def g1() -> Controller:
    return Controller(g1_config())


@pytest.fixture(scope="module")
def planar3(configs_dir) -> Controller:
    return Controller.from_yaml(configs_dir / "arm_planar_3dof.yaml")


@pytest.fixture(scope="module")
def panda(configs_dir) -> Controller:
    return Controller.from_yaml(configs_dir / "arm_panda.yaml")


def random_q(ctrl: Controller, rng: np.random.Generator, spread: float = 0.6) -> np.ndarray:
    r = ctrl.robot
    q = r.q_reference.copy()
    qi = r.joint_q_index
    lo = np.where(np.isfinite(r.q_min[qi]), r.q_min[qi] + 0.1, -np.pi)
    hi = np.where(np.isfinite(r.q_max[qi]), r.q_max[qi] - 0.1, np.pi)
    q[qi] = np.clip(q[qi] + rng.uniform(-spread, spread, len(qi)), lo, hi)
    if r.free_flyer:
        q[:3] += rng.uniform(-0.1, 0.1, 3)
        q[3:7] = pin.Quaternion(pin.exp3(rng.uniform(-0.3, 0.3, 3))).coeffs()
    return q


# ---------------------------------------------------------------------------- pure metrics
def test_normalized_pose_is_invariant_to_translation_and_scale() -> None:
    rng = np.random.default_rng(0)
    P = rng.normal(size=(5, 3))
    s = sample_parameters(37)
    ref = normalized_pose(P, s)
    # Tosun 3.1: base at the origin, unit length -> same curve for any offset and scale
    # (1e-12: a few roundings of O(1) numbers).
    np.testing.assert_allclose(normalized_pose(3.7 * P + [1.0, -2.0, 5.0], s), ref, atol=1e-12)
    np.testing.assert_allclose(normalized_pose(P, [0.0])[0], np.zeros(3), atol=1e-15)
    # P(1) is the end effector at distance <= 1 and the arc length of the samples is exact
    lengths = np.linalg.norm(np.diff(P, axis=0), axis=1)
    np.testing.assert_allclose(
        normalized_pose(P, [1.0])[0], (P[-1] - P[0]) / lengths.sum(), atol=1e-12
    )
    # s is arc length: consecutive samples 1/m apart in s are 1/m apart in space on a segment,
    # closer when they straddle a joint (4 of the m steps); 1e-12 is rounding.
    m = 20000
    steps = np.linalg.norm(np.diff(normalized_pose(P, np.linspace(0, 1, m + 1)), axis=0), axis=1)
    assert np.all(steps <= 1.0 / m + 1e-12)
    assert np.sum(np.abs(steps - 1.0 / m) > 1e-12) <= 4


def test_shape_errors_of_known_chains() -> None:
    """Straight chain vs the same chain folded at mid-length, computed by hand (eq. 1, 2, 3)."""
    straight = np.array([[0, 0, 0], [0, 0, -1.0], [0, 0, -2.0]])
    bent = np.array([[0, 0, 0], [0, 0, -1.0], [0, 1.0, -1.0]])  # 90 degrees at s = 0.5
    n = 10000
    e = shape_errors(straight, bent, n_samples=n, alpha=0.5)
    # For s > 1/2 the points differ by (s - 1/2) * (0, -1, -1): |.|^2 = 2 (s - 1/2)^2,
    # E_p = int_{1/2}^1 2 (s - 1/2)^2 ds = 1/12; E_e = 2 * (1/2)^2 = 1/2.
    # Tolerance 1e-4: the right-endpoint Riemann sum of eq. 5 errs by O(1/N).
    assert e.pose == pytest.approx(1.0 / 12.0, abs=1e-4)
    assert e.end_effector == pytest.approx(0.5, abs=1e-12)
    assert e.total == pytest.approx(e.pose + 0.5 * e.end_effector, abs=1e-15)
    assert shape_errors(straight, 5 * straight).total == 0.0


# ---------------------------------------------------------------------------- task maths
def test_task_error_matches_point_metrics(g1: Controller) -> None:
    """The task's E equals shape_errors() on the frame origins, in the reference frame's axes."""
    rng = np.random.default_rng(1)
    task: ChainShapeTask = g1.tasks["arm"]
    g1.reset(random_q(g1, rng))
    src = rng.normal(size=(4, 3))
    task.set_target(src)
    state = g1.state
    R = state.frame_placement(g1.robot.frame_id("torso_link")).rotation
    pts = np.array([state.frame_placement(f).translation for f in task.frame_ids]) @ R
    ref = shape_errors(src, pts, n_samples=task.n_samples, alpha=task.alpha)
    got = task.errors(state)
    # 1e-12: same formula evaluated twice on O(1) numbers.
    assert got.total == pytest.approx(ref.total, abs=1e-12)
    assert got.pose == pytest.approx(ref.pose, abs=1e-12)
    assert got.end_effector == pytest.approx(ref.end_effector, abs=1e-12)
    assert task.error_norm(task.compute_error(state)) == pytest.approx(ref.total, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_jacobian_matches_finite_differences(g1: Controller, seed: int) -> None:
    """d P_T(q, s_n)/dq by central differences on the configuration manifold (free-flyer G1).

    The G1 shoulder joints are offset, so the segment lengths and L vary with q and the reference
    frame (torso) rotates: every term of the exact Jacobian is exercised.
    """
    rng = np.random.default_rng(seed)
    task: ChainShapeTask = g1.tasks["arm"]
    q = random_q(g1, rng)
    g1.reset(q)
    J = task.compute_jacobian(g1.state)
    h = 1e-6
    model = g1.robot.model
    fd = np.zeros_like(J)
    probe = Controller(g1_config())
    for i in range(model.nv):
        dv = np.zeros(model.nv)
        dv[i] = h
        probe.reset(pin.integrate(model, q, dv))
        plus = probe.tasks["arm"].robot_samples(probe.state).ravel()
        probe.reset(pin.integrate(model, q, -dv))
        minus = probe.tasks["arm"].robot_samples(probe.state).ravel()
        fd[:, i] = (plus - minus) / (2 * h)
    # Central differences with h = 1e-6 on O(1) normalized points: truncation O(h^2) and rounding
    # O(1e-16 / h) = 1e-10; 1e-6 absolute (the acceptance tolerance of the issue).
    np.testing.assert_allclose(J, fd, atol=1e-6)
    assert np.abs(J).max() > 0.1  # the arm joints do move the chain


def test_qp_step_predicted_decrease_matches_finite_differences(g1: Controller) -> None:
    """First-order decrease of E predicted by the QP's linearization vs E along the QP step."""
    rng = np.random.default_rng(7)
    task: ChainShapeTask = g1.tasks["arm"]
    q = random_q(g1, rng)
    g1.reset(q)
    src = robot_chain(g1.robot, G1_ARM, random_q(g1, rng), reference_frame="torso_link")[0]
    task.set_target(src)
    w, e, J = task.metric_weight, task.compute_error(g1.state), task.compute_jacobian(g1.state)
    res = g1.step({"arm": src})
    dq = np.asarray(res.v) * g1.dt  # the QP step (tangent vector)
    # Linearization of E = sum w e^2 along dq: dE/de = -2 sum w e (J dq).
    predicted = -2.0 * float(np.dot(w * e, J @ dq))
    assert predicted < -1e-4  # the QP step is a descent direction

    def E_at(x: np.ndarray) -> float:
        probe = Controller(g1_config())
        probe.reset(x)
        probe.tasks["arm"].set_target(src)
        return probe.tasks["arm"].errors(probe.state).total

    model = g1.robot.model
    h = 1e-6
    fd = (E_at(pin.integrate(model, q, h * dq)) - E_at(pin.integrate(model, q, -h * dq))) / (2 * h)
    # Relative 1e-6 (the tolerance): central difference truncation O(h^2 |dq|^3) and
    # rounding O(1e-16 / h) relative to a derivative of order 0.1.
    assert fd == pytest.approx(predicted, rel=1e-6)
    # The QP's own model: its predicted decrease (Gauss-Newton with K dt = 1) equals
    # E - |e - J dq|_w^2 and is positive; the true decrease of a full step is of the same sign.
    r = e - J @ dq
    model_decrease = float(np.dot(w, e * e) - np.dot(w, r * r))
    assert model_decrease > 0
    assert E_at(pin.integrate(model, q, dq)) < float(np.dot(w, e * e))


# ---------------------------------------------------------------------------- acceptance
@pytest.mark.parametrize("config", ["planar3", "panda"])
def test_identical_chain_reaches_zero_error(config: str, request) -> None:
    """Source = the robot's own chain in another configuration: E < 1e-8 (issue #8 acceptance)."""
    ctrl: Controller = request.getfixturevalue(config)
    task: ChainShapeTask = ctrl.tasks["arm"]
    rng = np.random.default_rng(3)
    q_star = random_q(ctrl, rng, spread=1.0)
    src = robot_chain(ctrl.robot, task.frames, q_star)[0]
    if task.source_rotation is not None:  # express the source in the axes the task expects
        src = src @ task.source_rotation
    ctrl.reset()
    res = retarget_pose(ctrl, src, tol=1e-10, max_iterations=200)
    assert res.converged
    # Zero-residual problem: Gauss-Newton converges quadratically to E = 0 (up to rounding).
    assert res.errors.total < 1e-8


def test_reset_gives_zero_error_and_no_motion(planar3: Controller) -> None:
    planar3.reset()
    res = planar3.step({})
    assert res.task_errors["arm"] == 0.0
    assert np.abs(res.v).max() < 1e-9  # fulfilled task: zero velocity up to solver accuracy


# ---------------------------------------------------------------------------- validation
def test_target_validation(planar3: Controller) -> None:
    task = planar3.tasks["arm"]
    with pytest.raises(TargetError, match=r"\(n, 3\) array"):
        planar3.step({"arm": np.zeros((3, 2))})
    with pytest.raises(TargetError, match="zero total length"):
        planar3.step({"arm": np.ones((3, 3))})
    with pytest.raises(TargetError, match="n >= 2"):
        planar3.step({"arm": np.zeros((1, 3))})
    good = np.array([[0, 0, 0], [0, 0.1, -0.2], [0, 0.2, -0.3]])
    planar3.step({"arm": good})
    before = task.source_samples.copy()
    res = planar3.step({"arm": np.full((3, 3), np.nan)})
    assert any("NaN" in m for m in res.messages)
    np.testing.assert_array_equal(task.source_samples, before)  # last source kept


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"frames": ["left_elbow_link"]}, "at least two"),
        ({"frames": ["left_elbow_link", "left_elbow_link"]}, "distinct"),
        ({"frames": ["left_elbow_link", "left_elbw_link"]}, "Did you mean 'left_elbow_link'"),
        ({"alpha": -1.0}, "alpha must be"),
        ({"n_samples": 0}, "n_samples"),
        ({"source_rotation": [1, 2]}, "source_rotation"),
        ({"reference_frame": "torsoo"}, "reference_frame"),
        ({"frames": ["left_elbow_link", "left_elbow_joint"]}, "same point"),
    ],
)
def test_config_errors(change: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        Controller(g1_config(**change))


def test_yaml_keys_documented(configs_dir) -> None:
    """Every chain_shape key used in the shipped configs is a constructor keyword."""
    import inspect

    params = set(inspect.signature(ChainShapeTask.__init__).parameters) - {"self"}
    for path in sorted(configs_dir.glob("*.yaml")):
        for spec in yaml.safe_load(path.read_text()).get("tasks", []):
            if spec.get("type") == "chain_shape":
                assert set(spec) - {"type"} <= params, path.name
