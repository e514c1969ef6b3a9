# SPDX-License-Identifier: Apache-2.0
"""Strategy ``redirection``: Dariush 2009 eq. 17-23 self-collision redirection with blending."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget import Controller, load_robot
from qpretarget.collision import CollisionModel
from qpretarget.errors import UnknownNameError
from qpretarget.strategies.nullspace import weighted_prioritized_dls
from qpretarget.strategies.redirection import blending, blending_reach

PAIRS = [
    ["right_wrist_yaw_link", "torso_link"],
    ["right_wrist_yaw_link", "pelvis_contour_link"],
    ["right_elbow_link", "torso_link"],
    ["right_wrist_roll_link", "torso_link"],
]


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def test_blending_function_eq_23() -> None:
    dc = 0.05
    # b(delta * d_c) = 1/2; b -> 1 at contact, -> 0 far away; decreasing (Dariush 2009 Fig. 9).
    assert blending(0.5 * dc, dc, 15.0, 0.5) == pytest.approx(0.5, abs=1e-15)
    assert blending(dc, dc, 15.0, 1.0) == pytest.approx(0.5, abs=1e-15)
    assert blending(0.0, dc, 15.0, 1.0) == pytest.approx(1.0 / (1.0 + np.exp(-15.0)), rel=1e-12)
    assert blending(2 * dc, dc, 15.0, 0.5) < 1e-9
    d = np.linspace(0, 3 * dc, 50)
    assert np.all(np.diff(blending(d, dc, 15.0, 1.0)) < 0)
    # The reach (pairs computed at all) inverts eq. 23: b = level there, to round-off.
    reach = blending_reach(dc, 15.0, 1.0, 1e-4)
    assert blending(reach, dc, 15.0, 1.0) == pytest.approx(1e-4, rel=1e-9)


def reach_config(g1, strategy):
    return Controller(
        {
            "robot": g1,
            "strategy": strategy,
            "regularization": {"type": "identity", "damping": 1e-3},
            "tasks": [
                {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "pose",
                 "position_weight": 100.0, "orientation_weight": 100.0},
                {"type": "frame", "name": "torso", "frame": "torso_link", "mode": "orientation",
                 "orientation_weight": 100.0},
                {"type": "frame", "name": "right_hand", "frame": "right_rubber_hand",
                 "mode": "position", "position_weight": 100.0},
                {"type": "posture", "weight": 0.01},
            ],
            "constraints": [{"type": "joint_limits", "gain": 0.95}, {"type": "velocity_limits"}],
        }
    )  # fmt: skip


@pytest.fixture(scope="module")
def runs(g1):
    """Right hand driven into the torso, with redirection and with plain DLS (same lambda)."""
    dist = CollisionModel(g1, [tuple(p) for p in PAIRS], broad_phase=False)
    out = {}
    for name, strategy in [
        ("redirection", {"type": "redirection", "pairs": PAIRS}),
        ("plain", {"type": "nullspace", "clamping": True}),
    ]:
        ctrl = reach_config(g1, strategy)
        ctrl.reset()
        st = ctrl.state
        p0 = st.frame_placement(g1.frame_id("right_rubber_hand")).translation.copy()
        goal = st.frame_placement(g1.frame_id("torso_link")).translation + [0.05, 0.0, 0.0]
        ds, statuses = [], []
        for k in range(70):
            a = min(1.0, k / 100)
            res = ctrl.step({"right_hand": (1 - a) * p0 + a * goal})
            statuses.append(res.solver_status)
            ds.append(dist.compute_all(ctrl.state)[0].min())
        out[name] = (np.array(ds), statuses, ctrl)
    return out


def test_without_active_pairs_it_is_the_dls_closed_form(runs) -> None:
    ds, statuses, _ = runs["redirection"]
    ds_plain, _, _ = runs["plain"]
    # Far from the torso (b < 1e-4 everywhere) both closed forms give the same motion.
    far = np.flatnonzero(ds > 0.075)
    assert far.size > 10
    assert "0 pair(s) active" in statuses[far[0]]
    assert np.allclose(ds[far[:10]], ds_plain[far[:10]], atol=1e-9)


def test_redirection_slows_the_approach(runs) -> None:
    ds, statuses, ctrl = runs["redirection"]
    ds_plain, _, _ = runs["plain"]
    assert ctrl.strategy.last_blend > 0.5  # redirection is engaged by the end
    # Once blending engages the pairs close in more slowly than with plain DLS tracking
    # (measured with the shared link hulls: 0.035 m vs 0.018 m at tick 60; asserted with 4 mm
    # of margin).
    assert ds[60] > ds_plain[60] + 0.004
    assert np.all(ds[40:70] >= ds_plain[40:70] - 1e-6)


def test_same_tick_matches_weighted_dls_when_inactive(g1) -> None:
    ctrl = reach_config(g1, {"type": "redirection", "pairs": PAIRS, "clamping": False})
    ctrl.reset()
    p = ctrl.state.frame_placement(g1.frame_id("right_rubber_hand")).translation
    ctrl.set_targets({"right_hand": p + [0.05, -0.05, 0.02]}, [])  # moving away from the torso
    tp = ctrl.build_tick(ctrl.dt)
    x = ctrl.strategy.solve(tp).x
    J = np.vstack([np.sqrt(b.weight)[:, None] * b.J for b in tp.blocks])
    v = np.concatenate([np.sqrt(b.weight) * b.v_star for b in tp.blocks])
    assert ctrl.strategy.last_blend < 1e-4
    assert np.linalg.norm(x - weighted_prioritized_dls([J], [v], [tp.damping])) < 1e-9


def test_unknown_link_lists_close_names(g1) -> None:
    with pytest.raises(UnknownNameError, match="right_wrist_yaw_link"):
        reach_config(g1, {"type": "redirection", "pairs": [["right_wrist_yaw", "torso_link"]]})


def test_collision_points_are_the_shared_models(g1) -> None:
    """Witness points from the shared CollisionModel; point Jacobians match its gradients."""
    ctrl = reach_config(g1, {"type": "redirection", "pairs": PAIRS, "critical_distance": 0.5})
    ctrl.reset()
    ctrl.step({})
    strat = ctrl.strategy
    pairs, d, pa, pb, n, Jc = strat.collision_points(ctrl.state)
    assert pairs.size == len(PAIRS)  # d_c = 0.5 m: every pair is within the blending's reach
    ref = CollisionModel(g1, [tuple(p) for p in PAIRS], broad_phase=False)
    d_ref, pa_ref, pb_ref, _ = ref.compute_all(ctrl.state)
    # Same geometry and GJK: identical numbers (1e-12 m: round-off only).
    assert np.allclose(d, d_ref, atol=1e-12) and np.allclose(pa, pa_ref, atol=1e-12)
    assert np.allclose(pb - pa, d[:, None] * n, atol=1e-9)  # p_b = p_a + d n
    # n^T (J_b(p_b) - J_a(p_a)) is the distance gradient the QP's self_collision rows use
    # (collision.py); equal to round-off (1e-9 on entries of order 1).
    grad = np.einsum("ki,kij->kj", n, Jc[1::2] - Jc[0::2])
    assert np.allclose(grad, strat.collision.gradients(ctrl.state), atol=1e-9)


def test_key_point_names_resolve_to_links(g1) -> None:
    ctrl = reach_config(g1, {"type": "redirection", "pairs": [["right_hand", "torso_link"]]})
    assert ctrl.strategy.collision.pairs[0][1] == "torso_link"
    assert ctrl.strategy.collision.pairs[0][0] in {p[0] for p in PAIRS}
