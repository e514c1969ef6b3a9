# SPDX-License-Identifier: Apache-2.0
"""Tests of qpretarget/relaxation.py: infeasible ticks relax in order of importance and recover."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from qpretarget import Controller, load_robot
from qpretarget.errors import ConfigError

# The whole-body G1 config builder lives with the constraint tests' fixtures.
_spec = importlib.util.spec_from_file_location(
    "constraints_conftest", Path(__file__).resolve().parent / "constraints" / "conftest.py"
)
_wb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_wb)
whole_body_config = _wb.whole_body_config
shrunk_polygon_margin = _wb.shrunk_polygon_margin


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def test_fallback_section_is_validated(g1) -> None:
    cfg = whole_body_config(g1)
    for fallback, match in [
        ({"ratoi": 10}, r"fallback\.ratoi.*Did you mean 'ratio'"),
        ({"ratio": 1.0}, "ratio must be > 1"),
        ({"enabled": "no"}, "enabled must be true or false"),
        ({"hard": ["velocity_limit"]}, r"fallback\.hard\[0\].*Did you mean 'velocity_limits'"),
        ({"hard": "velocity_limits"}, "list of constraint names"),
        ([1, 2], "must be a mapping"),
    ]:
        with pytest.raises(ConfigError, match=match):
            Controller({**cfg, "fallback": fallback})
    assert Controller({**cfg, "fallback": {"enabled": False}}).fallback is None
    fb = Controller({**cfg, "fallback": {"solver": {"name": "quadprog"}, "ratio": 100}}).fallback
    assert fb is not None and fb.solver.name == "quadprog" and fb.ratio == 100


def test_weights_grow_with_importance(g1) -> None:
    ctrl = Controller(whole_body_config(g1))
    fb = ctrl.fallback
    order = sorted(ctrl.constraints, key=lambda c: c.importance)
    weights = [fb.weight_of[c.name] for c in order]
    assert weights == sorted(weights) and len(set(weights)) == len(weights)
    assert order[0].name == "support_polygon" and order[-1].name == "contacts"
    assert fb.hard == ("velocity_limits",)
    assert fb.weight_of["acceleration_limits"] == 10 * fb.weight_of["support_polygon"]


@pytest.mark.parametrize(
    ("joint", "side"), [("left_knee_joint", "min"), ("left_elbow_joint", "max")]
)
def test_recovery_from_outside_a_joint_limit(g1, joint, side) -> None:
    """Acceptance "Recovery" (joint limit): reset 0.1 rad beyond a limit (a knee, with both feet
    in contact, and an elbow). Every tick returns a finite step (never held), the first reports
    what gave (the acceleration bound that cannot follow the joint limit's pull back), and the
    controller is feasible again within 50 ticks: the joint inside its range and nothing relaxed
    (measured: from tick 2)."""
    ctrl = Controller(whole_body_config(g1))
    j = g1.joint_index(joint)
    iq = g1.joint_q_index[j]
    q0 = g1.q_reference.copy()
    q0[iq] = g1.q_min[iq] - 0.1 if side == "min" else g1.q_max[iq] + 0.1
    ctrl.reset(q0)
    first_feasible = None
    for tick in range(1, 61):
        res = ctrl.step()
        assert res.status != "held" and np.all(np.isfinite(res.v)) and np.all(np.isfinite(res.q))
        if tick == 1:
            assert res.status == "relaxed" and "acceleration_limits" in res.relaxed, res.relaxed
            assert all(np.isfinite(a) and a > 0 for a in res.relaxed.values())
        inside = g1.q_min[iq] <= res.q[iq] <= g1.q_max[iq]
        if first_feasible is None and inside and not res.relaxed:
            first_feasible = tick
        if first_feasible is not None:  # and it stays feasible
            assert inside and not res.relaxed, (tick, res.relaxed)
    assert first_feasible is not None and first_feasible <= 50


def test_recovery_with_the_com_outside_the_polygon(g1) -> None:
    """Acceptance "Recovery" (CoM): switching to single support with the CoM between the feet
    puts it ~10 cm outside the left sole's shrunk polygon. Every tick is finite, the first reports
    that only the support polygon gave (the lowest importance), and within 50 ticks the CoM is
    back inside (1e-4 m: one tick's linearization error) with nothing relaxed, and stays there."""
    ctrl = Controller(whole_body_config(g1))
    con = ctrl.constraint("contacts")
    ctrl.set_contacts(["left_foot"])
    corners = con.sole_corners_in_world()
    assert shrunk_polygon_margin(corners, ctrl.state.com()[:2], 0.01) < -0.05
    first_feasible = None
    for tick in range(1, 71):
        res = ctrl.step()
        assert res.status != "held" and np.all(np.isfinite(res.v))
        if tick == 1:
            assert set(res.relaxed) == {"support_polygon"}, res.relaxed
        margin = shrunk_polygon_margin(corners, ctrl.state.com()[:2], 0.01)
        if first_feasible is None and margin >= -1e-4 and not res.relaxed:
            first_feasible = tick
        if first_feasible is not None:
            assert margin >= -1e-4 and not res.relaxed, (tick, margin, res.relaxed)
    assert first_feasible is not None and first_feasible <= 50


def test_a_contact_that_cannot_be_kept_gives(g1) -> None:
    """A right-foot anchor moved 0.8 m sideways is out of the leg's reach (pulled at a correction
    speed capped at 4 m/s, so the leg is stretched within 15 ticks). By importance (joint_limits 90 < contacts 100) the joint limits
    give first and both soles are kept (the left one within a few mm); with joint limits declared
    hard, they hold and the contacts give instead. Never a held tick, always finite."""
    for hard, gives in [(None, "joint_limits"), (["velocity_limits", "joint_limits"], "contacts")]:
        cfg = whole_body_config(g1)
        cfg["constraints"][2]["max_correction"] = [4.0, 4.0]
        if hard is not None:
            cfg["fallback"] = {"hard": hard}
        ctrl = Controller(cfg)
        con = ctrl.constraint("contacts")
        far = con.anchor_pose("right_foot")
        far.translation[1] -= 0.8
        con.set_anchor("right_foot", far)
        seen: set[str] = set()
        left = con.anchor_pose("left_foot").translation
        for _ in range(25):
            res = ctrl.step()
            assert res.status != "held" and np.all(np.isfinite(res.v))
            seen |= set(res.relaxed)
            if hard is None:  # contacts held: the left sole stays on its anchor, to the
                # second-order drift of this violent motion (measured 1.7 mm; bound 5 mm)
                slip = ctrl.state.frame_placement(con.frame_ids[0]).translation - left
                assert np.linalg.norm(slip) < 5e-3
        assert gives in seen, seen
        if hard is not None:
            assert "joint_limits" not in seen and "velocity_limits" not in seen, seen


def test_relaxed_step_keeps_what_did_not_give(g1, monkeypatch) -> None:
    """On a relaxed tick, rows and bounds of the constraints that are not reported hold to the
    solver tolerance (1e-6), and the applied velocity stays within the velocity limits (hard).
    The support polygon is soft: its rows gave inside the tick's QP (exact-penalty slacks), the
    relaxation fallback was not needed."""
    ctrl = Controller(whole_body_config(g1))
    assert ctrl.soft_in_qp
    captured = {}
    solve = ctrl.strategy.solve

    def spy(tp):
        captured["C"], captured["l"], captured["u"] = tp.C.copy(), tp.l.copy(), tp.u.copy()
        return solve(tp)

    monkeypatch.setattr(ctrl.strategy, "solve", spy)
    monkeypatch.setattr(ctrl.fallback, "solve", lambda *a: pytest.fail("fallback called"))
    ctrl.set_contacts(["left_foot"])
    res = ctrl.step()
    assert set(res.relaxed) == {"support_polygon"}
    Cv = captured["C"] @ res.v
    viol = np.maximum(captured["l"] - Cv, Cv - captured["u"])
    for name, rows in ctrl.fallback.groups:
        if name not in res.relaxed:
            assert np.max(viol[rows], initial=0.0) < 1e-6, name
    assert np.all(np.abs(res.v) <= g1.v_max + 1e-9)


def test_soft_key_and_merge_order(g1) -> None:
    """``soft:`` on any constraint overrides its class default; a soft constraint's box bounds
    are merged after every hard one's (they give to the acceleration limits, never the reverse)."""
    cfg = whole_body_config(g1)
    cfg["constraints"].append(
        {"type": "self_collision", "pairs": [["left_wrist_yaw_link", "torso_link"]], "soft": True}
    )
    ctrl = Controller(cfg)
    sc = ctrl.constraint("self_collision")
    assert sc.is_soft() and not ctrl.constraint("contacts").is_soft()
    assert [g.name for g in ctrl.soft_rows()] == ["support_polygon", "self_collision"]
    order = [c.name for c in ctrl.bound_constraints]
    assert order.index("self_collision") > order.index("acceleration_limits")
    cfg["constraints"][-1]["soft"] = False
    assert not Controller(cfg).constraint("self_collision").is_soft()
    cfg["constraints"][-1]["soft"] = "yes"
    with pytest.raises(ConfigError, match=r"constraints\[\d\]\.soft"):
        Controller(cfg)


def test_soft_rows_change_nothing_while_they_can_hold(g1) -> None:
    """Exact penalty: on ticks where the polygon rows can hold, the soft QP's velocity is the hard
    QP's, to DAQP's accuracy (1e-7 rad/s; the two QPs differ in size, so not to the bit)."""
    runs = []
    for soft in (True, False):
        cfg = whole_body_config(g1)
        cfg["solver"] = {"name": "daqp"}
        cfg["constraints"][3]["soft"] = soft
        ctrl = Controller(cfg)
        hand = ctrl.tasks["left_hand"].position_target.copy()
        vs = []
        for k in range(30):
            res = ctrl.step({"left_hand": hand + [0.1 * np.sin(k / 5), 0.05, 0.0]})
            assert res.status == "ok", res.messages
            vs.append(res.v)
        runs.append(np.array(vs))
    assert np.abs(runs[0] - runs[1]).max() < 1e-7


def test_a_tick_without_solution_brakes(g1) -> None:
    """Out of iterations (a budget of 1 on a moving robot): the tick is flagged held and brakes
    at the acceleration limit towards zero (never v = 0 from full speed), the feet kept to first
    order (a few mm at most for the one tick)."""
    cfg = whole_body_config(g1)
    cfg["solver"] = {"name": "daqp"}
    ctrl = Controller(cfg)
    hand = ctrl.tasks["left_hand"].position_target.copy()
    for _ in range(15):  # get the arm moving
        res = ctrl.step({"left_hand": hand + [0.3, 0.2, 0.2]})
    v_prev = np.array(res.v)
    assert np.abs(v_prev).max() > 1.0
    ctrl.strategy._solver.settings["iter_limit"] = 1
    con = ctrl.constraint("contacts")
    feet = [ctrl.state.frame_placement(f).translation.copy() for f in con.frame_ids]
    res = ctrl.step({"left_hand": hand - [0.3, 0.2, 0.2]})
    assert res.status == "held" and "braking" in res.messages[-1], res.messages
    a_dt = 100.0 * 0.01  # a_max dt of whole_body_config
    vi = g1.joint_v_index
    dv = np.abs(res.v[vi] - v_prev[vi])
    assert dv.max() <= a_dt + 1e-9  # within the acceleration limits
    assert np.all(np.abs(res.v[vi]) <= np.abs(v_prev[vi]) + 1e-12)  # slower, never faster
    assert np.abs(res.v[vi]).max() > 0  # not frozen from full speed
    for f, p0 in zip(con.frame_ids, feet, strict=True):
        assert np.linalg.norm(ctrl.state.frame_placement(f).translation - p0) < 5e-3


def test_braking_bound_is_viable() -> None:
    """Del Prete 2018's viability, for the closed form of acceleration_limits: from any admissible
    (distance, speed), braking one tick at a_max lands on an admissible one again, so joint
    position limits stay reachable under the acceleration limits (units a_max dt, a_max dt^2;
    1e-9 for round-off). 20000 seeded states, gains 0.5-1."""
    from qpretarget.constraints.acceleration_limits import AccelerationLimits

    rng = np.random.default_rng(0)
    for gamma in (0.5, 0.9, 0.95, 1.0):
        con = AccelerationLimits(a_max=1.0)
        con._set_gamma(gamma)
        delta = rng.uniform(0, 200, 5000)
        nu_max = con._nu_max(delta.copy())
        nu = rng.uniform(0, 1, 5000) * nu_max
        nxt = con._nu_max(delta - nu)  # distance left after the tick
        assert np.all(nu - 1 <= nxt + 1e-9), gamma
        assert np.all(nu <= gamma * delta + 1e-9)  # and the joint_limits bound holds


def test_a_box_side_no_constraint_reaches_is_owned_by_the_tightest(g1) -> None:
    """A merged box side that no bound constraint's recomputed bound reaches (an ``ok`` tick
    of the kata went 1.87 rad/s past the acceleration limit: its widening had no owner and was
    not reported) belongs to the constraint with the tightest bound there, at its weight.
    Synthetic bounds; exact comparisons (booleans and copied weights)."""
    ctrl = Controller(whole_body_config(g1))  # joint, velocity and acceleration limits
    fb = ctrl.fallback
    names = [c.name for c in fb._bound_cons]
    k_acc, k_vel = names.index("acceleration_limits"), names.index("velocity_limits")
    nv = fb.nv
    lb, ub = np.full(nv, -1.0), np.full(nv, 1.0)
    bounds: list = [None] * len(names)
    bounds[k_vel] = (np.full(nv, -30.0), np.full(nv, 30.0))
    bounds[k_acc] = (np.full(nv, -2.0), np.full(nv, 1.5))
    bounds[k_acc][0][3] = -np.inf  # no acceleration bound on entry 3's lower side
    free_lo, free_hi = np.ones(nv, bool), np.zeros(nv, bool)
    free_hi[5] = True
    w_lo, w_hi = np.ones(nv), np.ones(nv)
    own_lo = [np.zeros(nv, bool) for _ in names]
    own_hi = [np.zeros(nv, bool) for _ in names]
    fb._own_unowned(lb, ub, free_lo, free_hi, bounds, w_lo, w_hi, own_lo, own_hi)
    expect_acc = np.ones(nv, bool)
    expect_acc[3] = False
    np.testing.assert_array_equal(own_lo[k_acc], expect_acc)
    np.testing.assert_array_equal(own_lo[k_vel], ~expect_acc)  # the next tightest
    assert own_hi[k_acc][5] and own_hi[k_acc].sum() == 1 and not own_hi[k_vel].any()
    assert w_lo[0] == fb.weight_of["acceleration_limits"] != 1.0
    assert w_lo[3] == fb.weight_of["velocity_limits"] and w_hi[5] == w_lo[0]
