# SPDX-License-Identifier: Apache-2.0
"""Strategy ``hierarchy``: strict priorities as lexicographic QPs (issue #4 acceptance)."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget import Controller, load_robot
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotState
from qpretarget.solvers import make_solver
from qpretarget.strategies import STRATEGIES, TickProblem
from qpretarget.tasks import CostBlock


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def hand_config(g1, strategy, *, level2_weight=1e4, constraints=()):
    """Level 1: left hand position; level 2: the same hand elsewhere (conflict) + right hand."""
    return Controller(
        {
            "robot": g1,
            "dt": 0.01,
            "strategy": strategy,
            "regularization": {"type": "identity", "damping": 1e-3},
            "tasks": [
                {"type": "frame", "name": "hand", "frame": "left_rubber_hand", "mode": "position",
                 "level": 1},
                {"type": "frame", "name": "hand_elsewhere", "frame": "left_rubber_hand",
                 "mode": "position", "position_weight": level2_weight, "level": 2},
                {"type": "frame", "name": "right_hand", "frame": "right_rubber_hand",
                 "mode": "position", "level": 2},
                {"type": "posture", "weight": 1.0, "level": 3},
            ],
            "constraints": list(constraints),
        }
    )  # fmt: skip


def test_feasible_level1_is_exact_whatever_lower_levels_ask(g1) -> None:
    strat = {"type": "hierarchy", "damping": [0.0, 1e-3, 1e-3]}
    ctrl = hand_config(g1, strat)
    ctrl.reset()
    fid = g1.frame_id("left_rubber_hand")
    p0 = ctrl.state.frame_placement(fid).translation.copy()
    target = p0 + np.array([0.03, 0.04, 0.05])  # reachable
    conflict = p0 + np.array([-0.2, 0.2, -0.2])  # level 2 pulls hard elsewhere (weight 1e4)
    for _ in range(15):
        ctrl.set_targets({"hand": target, "hand_elsewhere": conflict}, [])
        tp = ctrl.build_tick(ctrl.dt)
        res = ctrl.strategy.solve(tp)
        assert res.success, res.status
        b = tp.blocks[0]
        # Level 1 feasible and undamped: its task velocity is met to the solver tolerance
        # (eps_abs 1e-9 on each of 3 levels), whatever level 2 asks.
        assert np.linalg.norm(b.J @ res.x - b.v_star) < 1e-6
        ctrl.step({"hand": target, "hand_elsewhere": conflict})
    err = np.linalg.norm(ctrl.state.frame_placement(fid).translation - target)
    # K = 1/dt: full correction each tick, Newton-like convergence; 1e-6 m is the acceptance bound.
    assert err < 1e-6
    # The same tasks augmented in one QP do not track level 1 (the test can fail).
    aug = hand_config(g1, {"type": "augmentation"})
    aug.reset()
    for _ in range(15):
        aug.step({"hand": target, "hand_elsewhere": conflict})
    assert np.linalg.norm(aug.state.frame_placement(fid).translation - target) > 1e-2


def weighted(blocks):
    J = np.vstack([np.sqrt(b.weight)[:, None] * b.J for b in blocks])
    v = np.concatenate([np.sqrt(b.weight) * b.v_star for b in blocks])
    return J, v


def test_level2_equals_closed_form_null_space_solution(g1) -> None:
    lam2 = 0.05
    ctrl = Controller(
        {
            "robot": g1,
            "strategy": {"type": "hierarchy", "damping": [0.0, lam2]},
            "regularization": {"type": "identity"},
            "tasks": [
                {"type": "frame", "name": "left", "frame": "left_rubber_hand", "mode": "position",
                 "level": 1},
                {"type": "frame", "name": "torso", "frame": "torso_link", "mode": "orientation",
                 "level": 1},
                {"type": "frame", "name": "right", "frame": "right_rubber_hand", "mode": "pose",
                 "position_weight": 4.0, "level": 2},
                {"type": "com", "name": "com", "axes": "xy", "level": 2},
            ],
        }
    )  # fmt: skip
    ctrl.reset()
    st = ctrl.state
    ctrl.set_targets(
        {
            "left": st.frame_placement(g1.frame_id("left_rubber_hand")).translation
            + [0.02, 0, 0.03],
            "right": st.frame_placement(g1.frame_id("right_rubber_hand")).homogeneous
            @ np.array([[1, 0, 0, 0.03], [0, 0, -1, -0.02], [0, 1, 0, 0.01], [0, 0, 0, 1.0]]),
            "com": st.com() + [0.01, -0.01, 0.0],
        },
        [],
    )
    tp = ctrl.build_tick(0.01)
    res = ctrl.strategy.solve(tp)
    assert res.success and len(res.levels) == 2
    J1, v1 = weighted(tp.blocks[:2])
    J2, v2 = weighted(tp.blocks[2:])
    # Dariush 2009 Algorithm 1, level 1 exact (lambda 0), level 2 damped least squares.
    x1 = np.linalg.pinv(J1) @ v1
    N1 = np.eye(g1.nv) - np.linalg.pinv(J1) @ J1
    Jh = J2 @ N1
    x = x1 + Jh.T @ np.linalg.solve(Jh @ Jh.T + lam2**2 * np.eye(len(v2)), v2 - J2 @ x1)
    # No inequality is active: the QP solution is the closed form to the solver's tolerance.
    assert np.linalg.norm(res.x - x) < 1e-6 * max(1.0, np.linalg.norm(x))


def random_tick(g1, rng, *, dims=((3, 1), (6, 1), (3, 2), (5, 2), (10, 3)), n_rows=8):
    nv = g1.nv
    blocks = []
    for i, (m, lvl) in enumerate(dims):
        J = rng.standard_normal((m, nv))
        blocks.append(
            CostBlock(f"t{i}", J, rng.standard_normal(m) * 3.0, np.full(m, 1.0), lvl, np.zeros(m))
        )
    # Level 1 infeasible alone: the same Jacobian twice with different targets (t0, t1).
    blocks[1] = CostBlock("t1", np.vstack([blocks[0].J, blocks[0].J]), rng.standard_normal(6),
                          np.ones(6), 1, np.zeros(6))  # fmt: skip
    C = rng.standard_normal((n_rows, nv))
    l = -rng.uniform(0.05, 0.5, n_rows)
    u = rng.uniform(0.05, 0.5, n_rows)
    lb = -rng.uniform(0.1, 1.0, nv)
    ub = rng.uniform(0.1, 1.0, nv)
    tp = TickProblem(RobotState(g1), 0.01, blocks, C, l, u, lb, ub, np.eye(nv), 1e-3, 1)
    return tp, [(b.task, b.J.shape[0], b.level) for b in blocks]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hard_constraints_hold_at_every_level_and_levels_above_keep_their_values(g1, seed) -> None:
    rng = np.random.default_rng(seed)
    tp, task_dims = random_tick(g1, rng)
    strat = STRATEGIES["hierarchy"](damping=[0.0, 1e-3, 1e-2])
    strat.bind(g1, task_dims, tp.C.shape[0], lambda: make_solver("proxsuite"))
    res = strat.solve(tp)
    assert res.success and res.status == "solved", res.status
    xs = [d["x"] for d in res.levels]
    assert len(xs) == 3
    tol = 1e-7  # solver eps_abs 1e-9, box handled as rows of the null-space basis
    for x in xs:
        assert np.all(x >= tp.lb - tol) and np.all(x <= tp.ub + tol)
        Cx = tp.C @ x
        assert np.all(Cx >= tp.l - tol) and np.all(Cx <= tp.u + tol)
    # Some bound is active (the test exercises the constraints): the unconstrained level-3
    # optimum would leave the box.
    assert np.any(np.isclose(xs[-1], tp.lb, atol=1e-6) | np.isclose(xs[-1], tp.ub, atol=1e-6))
    # Lower levels never change what the levels above achieved, including the infeasible
    # (least-squares) level 1; the null-space basis is exact to round-off.
    J1, _ = weighted(tp.blocks[:2])
    J2, _ = weighted(tp.blocks[2:4])
    assert np.linalg.norm(J1 @ xs[2] - J1 @ xs[0]) < 1e-8
    assert np.linalg.norm(J2 @ xs[2] - J2 @ xs[1]) < 1e-8
    # Level 1 is its own least-squares optimum: residual orthogonal to J1's feasible directions
    # is all that remains (the two copies of J0 ask for different values).
    assert res.levels[0]["residual"] > 0.1


def test_damping_list_must_match_levels(g1) -> None:
    with pytest.raises(ConfigError, match="one lambda per priority level"):
        hand_config(g1, {"type": "hierarchy", "damping": [0.0, 1e-3]})
    with pytest.raises(ConfigError, match="damping"):
        hand_config(g1, {"type": "hierarchy", "damping": -1.0})


def test_constraints_hold_through_the_controller(g1) -> None:
    """Targets out of reach drive joints into their limits: every level stays inside."""
    ctrl = hand_config(
        g1,
        {"type": "hierarchy"},
        constraints=[{"type": "joint_limits", "gain": 0.9}, {"type": "velocity_limits"}],
    )
    ctrl.reset()
    p0 = ctrl.state.frame_placement(g1.frame_id("left_rubber_hand")).translation.copy()
    active = 0
    for k in range(60):
        far = p0 + np.array([0.6, 0.5, 0.4]) * min(1.0, k / 20)
        ctrl.set_targets({"hand": far, "hand_elsewhere": far - 0.3}, [])
        tp = ctrl.build_tick(ctrl.dt)
        res = ctrl.strategy.solve(tp)
        assert res.x is not None
        for d in res.levels:
            if d["x"] is not None:
                assert np.all(d["x"] >= tp.lb - 1e-7) and np.all(d["x"] <= tp.ub + 1e-7)
        active += int(
            np.any(np.isclose(res.x, tp.lb, atol=1e-6) | np.isclose(res.x, tp.ub, atol=1e-6))
        )
        ctrl.step({"hand": far, "hand_elsewhere": far - 0.3})
        q = ctrl.q[g1.joint_q_index]
        assert np.all(q >= g1.q_min[g1.joint_q_index] - 1e-9)
        assert np.all(q <= g1.q_max[g1.joint_q_index] + 1e-9)
    assert active > 10  # the limits were really active
