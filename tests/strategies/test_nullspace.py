# SPDX-License-Identifier: Apache-2.0
"""Strategy ``nullspace``: Dariush 2009 Algorithm 1 and Poubel 2014 eq. 4-8 with clamping."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget import Controller, load_robot
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotState
from qpretarget.strategies import STRATEGIES, TickProblem
from qpretarget.strategies.nullspace import prioritized_dls, weighted_prioritized_dls
from qpretarget.tasks import CostBlock


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def algorithm1_literal(Js, vs, lams):
    """Dariush 2009 Algorithm 1, line by line, DLS inverse where J^+ multiplies a velocity."""
    n = Js[0].shape[1]
    N = np.eye(n)
    terms = []  # \hat J_j^* \hat v_j
    for J, v, lam in zip(Js, vs, lams, strict=True):
        Jh = J @ N
        vh = v - J @ sum(terms, np.zeros(n))
        if lam > 0:
            Jstar = Jh.T @ np.linalg.inv(Jh @ Jh.T + lam**2 * np.eye(J.shape[0]))
        else:
            Jstar = np.linalg.pinv(Jh)
        terms.append(Jstar @ vh)
        N = N @ (np.eye(n) - np.linalg.pinv(Jh) @ Jh)
    return sum(terms, np.zeros(n)), N


def hand_built(rng, n=10):
    Js = [rng.standard_normal((3, n)), rng.standard_normal((2, n)), rng.standard_normal((4, n))]
    vs = [rng.standard_normal(3), rng.standard_normal(2), rng.standard_normal(4)]
    return Js, vs


@pytest.mark.parametrize("lams", [(0.0, 0.0, 0.0), (0.05, 0.1, 0.2)])
def test_reproduces_algorithm1_on_three_tasks(lams) -> None:
    rng = np.random.default_rng(7)
    Js, vs = hand_built(rng)
    q, N = prioritized_dls(Js, vs, lams)
    q_ref, N_ref = algorithm1_literal(Js, vs, lams)
    # Same algebra, different factorizations (SVD projector update vs pinv products): 1e-9.
    assert np.linalg.norm(q - q_ref) < 1e-9
    assert np.linalg.norm(N - N_ref) < 1e-9
    if lams[0] == 0.0:
        # 9 rows, 10 joints, full rank: every task is met exactly, in priority order.
        for J, v in zip(Js, vs, strict=True):
            assert np.linalg.norm(J @ q - v) < 1e-9


def test_conflicting_lower_task_never_disturbs_higher_ones() -> None:
    rng = np.random.default_rng(3)
    Js, vs = hand_built(rng, n=6)  # 9 rows on 6 joints: task 3 cannot be met
    q, _ = prioritized_dls(Js, vs, (0.0, 0.0, 0.0))
    assert np.linalg.norm(Js[0] @ q - vs[0]) < 1e-9
    assert np.linalg.norm(Js[1] @ q - vs[1]) < 1e-9
    assert np.linalg.norm(Js[2] @ q - vs[2]) > 1e-3


def test_weighted_metric_is_the_weighted_dls_inverse() -> None:
    rng = np.random.default_rng(11)
    J = rng.standard_normal((4, 9))
    v = rng.standard_normal(4)
    A = rng.standard_normal((9, 9))
    W = A @ A.T + 9 * np.eye(9)
    lam = 0.3
    q = weighted_prioritized_dls([J], [v], [lam], W)
    Wi = np.linalg.inv(W)
    q_ref = Wi @ J.T @ np.linalg.solve(J @ Wi @ J.T + lam**2 * np.eye(4), v)  # Dariush eq. 10
    assert np.linalg.norm(q - q_ref) < 1e-9


def tick(g1, rng, levels=(1, 2, 3)):
    nv = g1.nv
    blocks = [
        CostBlock(f"t{i}", rng.standard_normal((m, nv)), rng.standard_normal(m),
                  rng.uniform(0.5, 4.0, m), lvl, np.zeros(m))
        for i, (m, lvl) in enumerate(zip((6, 3, 5), levels, strict=True))
    ]  # fmt: skip
    inf = np.full(nv, np.inf)
    C = np.zeros((0, nv))
    return TickProblem(RobotState(g1), 0.01, blocks, C, C[:, 0], C[:, 0], -inf, inf,
                       np.eye(nv), 0.0, 1)  # fmt: skip


def test_strategy_is_algorithm1_on_weighted_blocks(g1) -> None:
    rng = np.random.default_rng(5)
    tp = tick(g1, rng)
    strat = STRATEGIES["nullspace"](damping=[0.0, 0.01, 0.1])
    strat.bind(g1, [(b.task, b.J.shape[0], b.level) for b in tp.blocks], 0, None)
    res = strat.solve(tp)
    Js = [np.sqrt(b.weight)[:, None] * b.J for b in tp.blocks]
    vs = [np.sqrt(b.weight) * b.v_star for b in tp.blocks]
    q_ref, _ = algorithm1_literal(Js, vs, (0.0, 0.01, 0.1))
    assert res.success
    assert np.linalg.norm(res.x - q_ref) < 1e-9


def test_rows_are_refused_and_dariush_takes_no_optimization_tasks(g1) -> None:
    strat = STRATEGIES["nullspace"]()
    with pytest.raises(ConfigError, match="cannot honour the 4 constraint row"):
        strat.bind(g1, [("a", 3, 1)], 4, None)
    STRATEGIES["nullspace"](ignore_rows=True).bind(g1, [("a", 3, 1)], 4, None)
    with pytest.raises(ConfigError, match="belong to variant 'poubel'"):
        STRATEGIES["nullspace"](optimization_tasks=["posture"])
    with pytest.raises(ConfigError, match="variant"):
        STRATEGIES["nullspace"](variant="siciliano")


def reach_config(g1, strategy):
    return Controller(
        {
            "robot": g1,
            "strategy": strategy,
            "regularization": {"type": "identity", "damping": 0.05},
            "tasks": [
                {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "pose", "level": 1},
                {"type": "frame", "name": "left", "frame": "left_rubber_hand", "mode": "position",
                 "level": 2},
                {"type": "frame", "name": "right", "frame": "right_rubber_hand",
                 "mode": "position", "level": 2},
                {"type": "posture", "weight": 0.1, "level": 3},
            ],
            "constraints": [{"type": "joint_limits", "gain": 0.9}, {"type": "velocity_limits"}],
        }
    )  # fmt: skip


@pytest.mark.parametrize("variant", ["dariush", "poubel"])
def test_clamping_loop_keeps_every_joint_inside_its_limits(g1, variant) -> None:
    extra = (
        {"optimization_tasks": ["posture"], "centering_gain": 1.0} if variant == "poubel" else {}
    )
    ctrl = reach_config(g1, {"type": "nullspace", "variant": variant, **extra})
    ctrl.reset()
    st = ctrl.state
    pl = st.frame_placement(g1.frame_id("left_rubber_hand")).translation.copy()
    pr = st.frame_placement(g1.frame_id("right_rubber_hand")).translation.copy()
    qi, vi = g1.joint_q_index, g1.joint_v_index
    clamped = 0
    for k in range(80):
        s = min(1.0, k / 30)
        res = ctrl.step({"left": pl + s * np.array([0.5, 0.6, 0.5]),
                         "right": pr + s * np.array([0.4, -0.3, -0.6])})  # fmt: skip
        assert res.status == "ok", res.messages
        clamped += "0 joint(s) clamped" not in res.solver_status
        q = res.q[qi]
        # Position limits: the bound gamma (q_max - q)/dt is a velocity bound; clamping keeps v in
        # it exactly, so q stays inside up to integration round-off.
        assert np.all(q >= g1.q_min[qi] - 1e-9) and np.all(q <= g1.q_max[qi] + 1e-9)
        assert np.all(np.abs(res.v[vi]) <= g1.v_max[vi] * (1 + 1e-12))
    assert clamped > 20  # the loop really clamped joints (targets out of reach)


def test_poubel_optimization_terms_stay_in_the_null_space(g1) -> None:
    """Eq. 6: the optimization tasks never change the strict tasks' velocities."""
    rng = np.random.default_rng(2)
    tp = tick(g1, rng, levels=(1, 1, 2))
    dims = [(b.task, b.J.shape[0], b.level) for b in tp.blocks]
    base = STRATEGIES["nullspace"](variant="poubel", damping=0.0)
    opt = STRATEGIES["nullspace"](variant="poubel", damping=0.0, optimization_tasks=["t2"],
                                  centering_gain=2.0)  # fmt: skip
    base.bind(g1, dims, 0, None)
    opt.bind(g1, dims, 0, None)
    tp.state.update(g1.q_reference.copy())
    x0 = base.solve(tp).x
    x1 = opt.solve(tp).x
    J = np.vstack([b.J for b in tp.blocks[:2]])
    # The strict level (t0, t1: 9 rows) is met identically; the gradients move other joints.
    assert np.linalg.norm(J @ (x1 - x0)) < 1e-9
    assert np.linalg.norm(x1 - x0) > 1e-3
