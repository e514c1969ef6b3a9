# SPDX-License-Identifier: Apache-2.0
"""Tests of qpretarget/constraints/contacts.py: anchored 6-D foot equalities."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget import Controller
from qpretarget.errors import ConfigError, UnknownFrameError, UnknownNameError


def _ctrl(g1, make_config, **kw) -> Controller:
    return Controller(make_config(g1, **kw))


def test_rows_keep_their_shape_and_inactive_feet_have_infinite_bounds(g1, make_config) -> None:
    ctrl = _ctrl(g1, make_config)
    con = ctrl.constraint("contacts")
    assert con.n_rows == 12 and con.active_feet == ["left_foot", "right_foot"]
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    # Active feet: equalities l == u (exactly: the same numbers are written to both).
    assert blk.C.shape == (12, g1.nv) and np.array_equal(blk.l, blk.u)
    ctrl.set_contacts(["left_foot"])
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    assert blk.C.shape == (12, g1.nv)
    assert (
        np.all(blk.C[6:] == 0.0)
        and np.all(np.isneginf(blk.l[6:]))
        and np.all(np.isposinf(blk.u[6:]))
    )
    assert np.array_equal(blk.l[:6], blk.u[:6])
    assert con.active_feet == ["left_foot"]


def test_error_rate_is_minus_the_jacobian_rows(g1, make_config) -> None:
    """At zero error, e(q + v h) / h = -J v: the rows [linear; angular] and the error agree.

    Finite difference with h = 1e-6: the remainder is O(h |v|^2) ~ 1e-6, tolerance 1e-5.
    """
    ctrl = _ctrl(g1, make_config)
    con = ctrl.constraint("contacts")
    state = ctrl.state
    J = con.compute_rows(state, ctrl.dt).C.copy()
    v = np.random.default_rng(0).normal(size=g1.nv)
    h = 1e-6
    from qpretarget.robot import RobotState

    moved = RobotState(g1)
    moved.update(g1.integrate(state.q, v, h), np.zeros(g1.nv))
    e = con.errors(moved).reshape(-1) / h
    np.testing.assert_allclose(e, -J @ v, atol=1e-5)


def test_drift_correction_pulls_the_sole_onto_a_moved_anchor(g1, make_config) -> None:
    ctrl = _ctrl(g1, make_config, a_max=None, polygon=False)
    con = ctrl.constraint("contacts")
    fid = con.frame_ids[0]
    M = ctrl.state.frame_placement(fid)
    target = pin.SE3(
        M.rotation @ pin.exp3(np.array([0.0, 0.0, 0.02])), M.translation + [0.002, -0.001, 0.0]
    )
    con.set_anchor("left_foot", target)
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    # Rows: K e with K = 1/dt (default gain), e = [p_a - p; R log3(R' R_a)] (v = 0: no drift term).
    expected = np.concatenate(
        [target.translation - M.translation, M.rotation @ pin.log3(M.rotation.T @ target.rotation)]
    )
    np.testing.assert_allclose(blk.l[:6], expected / ctrl.dt, atol=1e-12)
    for _ in range(3):
        ctrl.step()
    # After the correction the sole sits on its new anchor; 2 mm / 0.02 rad corrected with a
    # first-order step leaves a second-order residual, ~1e-6, so 1e-5 m and 1e-5 rad.
    M = ctrl.state.frame_placement(fid)
    assert np.linalg.norm(M.translation - target.translation) < 1e-5
    assert np.linalg.norm(pin.log3(target.rotation.T @ M.rotation)) < 1e-5


def test_a_moving_anchor_is_fed_forward_outside_the_correction_caps(g1, make_config) -> None:
    """A pivot: the anchor turned by 0.06 rad about z, ``moving=True``. The rows ask for the
    whole step over one tick (6 rad/s) though the angular cap is 0.5 rad/s, plus the capped
    correction of the error left at the previous anchor (none here); without ``moving`` the
    same anchor is approached at the cap. Then the step is cleared: the rows are the plain
    correction again. Exact arithmetic on the same numbers: 1e-12."""
    ctrl = _ctrl(g1, make_config, a_max=None, polygon=False)
    con = ctrl.constraint("contacts")
    con.max_correction = (0.1, 0.5)
    fid = con.frame_ids[0]
    M = ctrl.state.frame_placement(fid)
    turned = pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.06])) @ M.rotation, M.translation.copy())
    con.set_anchor("left_foot", turned, moving=True)
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    np.testing.assert_allclose(blk.l[:3], 0.0, atol=1e-12)
    np.testing.assert_allclose(blk.l[3:6], [0.0, 0.0, 0.06 / ctrl.dt], atol=1e-9)
    con.set_anchor("left_foot", turned)  # not moving: capped at 0.5 rad/s
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    np.testing.assert_allclose(np.linalg.norm(blk.l[3:6]), 0.5, atol=1e-12)
    con.set_anchor("left_foot", turned, moving=True)
    con.clear_anchor_steps()
    blk2 = con.compute_rows(ctrl.state, ctrl.dt)
    np.testing.assert_array_equal(blk.l, blk2.l)


def test_switching_anchors_the_new_foot_where_it_is(g1, make_config) -> None:
    ctrl = _ctrl(g1, make_config, polygon=False)
    con = ctrl.constraint("contacts")
    ctrl.set_contacts(["left_foot"])
    assert con.active_feet == ["left_foot"]
    rf = con.frame_ids[1]
    for _ in range(5):  # move the free right foot a bit (the posture task pulls it around)
        ctrl.step(
            {
                "pelvis": ctrl.state.frame_placement(g1.frame_id("pelvis")).translation
                + [0.0, 0.02, 0.0]
            }
        )
    here = ctrl.state.frame_placement(rf).copy()
    version = con.version
    ctrl.set_contacts(["left_foot", "right_foot"])
    assert con.version > version
    np.testing.assert_array_equal(con.anchor_pose("right_foot").translation, here.translation)
    np.testing.assert_array_equal(con.anchor_pose("right_foot").rotation, here.rotation)


def test_sole_corners_are_the_rectangles_at_the_anchors(g1, make_config) -> None:
    ctrl = _ctrl(g1, make_config)
    con = ctrl.constraint("contacts")
    corners = con.sole_corners_in_world()
    assert corners.shape == (8, 3)
    for k, foot in enumerate(("left_foot", "right_foot")):
        x0, x1, y0, y1 = g1.feet[foot].rectangle
        M = con.anchor_pose(foot)
        local = (corners[4 * k : 4 * k + 4] - M.translation) @ M.rotation
        np.testing.assert_allclose(
            local[:, :2], [[x0, y0], [x1, y0], [x1, y1], [x0, y1]], atol=1e-12
        )
    ctrl.set_contacts(["right_foot"])
    assert con.sole_corners_in_world().shape == (4, 3)


def test_unknown_names_fail_with_close_matches(g1, make_config) -> None:
    cfg = make_config(g1)
    cfg["constraints"][2] = {"type": "contacts", "feet": ["left_fot"]}
    with pytest.raises(
        UnknownNameError, match=r"constraints\[2\].*'left_fot'.*Did you mean 'left_foot'"
    ):
        Controller(cfg)
    ctrl = _ctrl(g1, make_config)
    with pytest.raises(UnknownNameError, match="right_foot"):
        ctrl.set_contacts(["rigth_foot"])
    cfg = make_config(g1)
    cfg["constraints"][2] = {"type": "contacts", "frames": {"lf": "left_sole", "hand": "left_hnd"}}
    with pytest.raises(UnknownFrameError, match="left_hnd"):
        Controller(cfg)


def test_explicit_frames_and_robots_without_feet(g1, make_config) -> None:
    cfg = make_config(g1, polygon=False)
    cfg["constraints"][2] = {
        "type": "contacts",
        "frames": {
            "lf": {"frame": "left_sole", "rectangle": [-0.05, 0.12, -0.03, 0.03]},
            "hand": "left_rubber_hand",
        },
        "active": ["lf"],
    }
    ctrl = Controller(cfg)
    con = ctrl.constraint("contacts")
    assert con.names == ["lf", "hand"] and con.active_feet == ["lf"] and con.n_rows == 12
    ctrl.set_contacts(["lf", "hand"])
    with pytest.raises(ConfigError, match="no sole rectangle"):
        con.sole_corners_in_world()
    cfg = {
        "robot": {"name": "g1", "feet": {}},
        "tasks": [{"type": "posture", "name": "posture"}],
        "constraints": [{"type": "contacts"}],
    }
    robot_without_feet = Controller({**cfg, "constraints": []}).robot
    if robot_without_feet.feet:  # the registry merges feet overrides: build a robot without any
        from qpretarget.robot import RobotModel

        robot_without_feet = RobotModel(g1.urdf_path, name="nofeet")
    cfg["robot"] = robot_without_feet
    with pytest.raises(ConfigError, match="has no feet"):
        Controller(cfg)


def test_bad_values_are_config_errors(g1, make_config) -> None:
    for bad, match in [
        ({"gain": -1.0}, "gain"),
        ({"second_order": "yes"}, "second_order"),
        ({"refine": "yes"}, "refine"),
        ({"refine_tolerance": 0.0}, "refine_tolerance"),
        ({"refine_iterations": 0}, "refine_iterations"),
        ({"refine_iterations": 1.5}, "refine_iterations"),
        ({"feet": "left_foot"}, "feet"),
    ]:
        cfg = make_config(g1)
        cfg["constraints"][2] = {"type": "contacts", **bad}
        with pytest.raises(ConfigError, match=match):
            Controller(cfg)
    ctrl = _ctrl(g1, make_config)
    with pytest.raises(ConfigError, match="4x4"):
        ctrl.constraint("contacts").set_anchor("left_foot", np.eye(3))


def test_feet_stay_planted_under_wild_targets(g1, make_config, make_wild_targets) -> None:
    """Acceptance "Feet": 2000 ticks of hand and pelvis targets jumping 4 times a second (hands
    +-0.4 m, pelvis +-0.15 m and +-0.4 rad) in double support; every tick each sole stays within
    1 mm and 0.5 degree of its anchor (measured on the integrated configuration).

    Whole-body config: tasks with gain 15/s, damping 0.3, joint/velocity/acceleration
    (100 rad/s^2) limits, support polygon. The contact rows are linear with the second-order drift
    anticipated, so what remains is the tick's higher-order integration error (measured worst
    0.50-0.57 mm over three seeds, 0.1 degree; a tick where the acceleration bound must give to
    keep the feet makes a velocity jump, and with gain 20/s and damping 1e-3 such ticks reached
    1.3 mm).
    """
    ctrl = _ctrl(g1, make_config)
    con = ctrl.constraint("contacts")
    anchors = [con.anchor_pose(f) for f in con.names]
    worst_p = worst_a = 0.0
    held = 0
    for targets in make_wild_targets(ctrl, 2000, seed=1):
        res = ctrl.step(targets)
        held += res.status == "held"
        for a, fid in zip(anchors, con.frame_ids, strict=True):
            M = ctrl.state.frame_placement(fid)
            worst_p = max(worst_p, float(np.linalg.norm(M.translation - a.translation)))
            worst_a = max(worst_a, float(np.linalg.norm(pin.log3(a.rotation.T @ M.rotation))))
    assert held == 0
    assert worst_p < 1e-3, f"a sole moved {worst_p * 1e3:.3f} mm"
    assert np.degrees(worst_a) < 0.5, f"a sole turned {np.degrees(worst_a):.3f} deg"


def test_second_order_term_is_what_keeps_fast_motions_planted(
    g1, make_config, make_wild_targets
) -> None:
    """The same wild targets for 300 ticks with ``second_order: false`` drift about three times
    more (measured 1.13 mm vs 0.34 mm): the drift anticipation is what holds the 1 mm. (The
    corrector step is off in both runs: it would take the rest, see the next test.)"""
    worst = {}
    for second_order in (False, True):
        cfg = make_config(g1)
        cfg["constraints"][2]["second_order"] = second_order
        cfg["constraints"][2]["refine"] = False
        ctrl = Controller(cfg)
        con = ctrl.constraint("contacts")
        anchors = [con.anchor_pose(f).translation for f in con.names]
        w = 0.0
        for targets in make_wild_targets(ctrl, 300, seed=1):
            ctrl.step(targets)
            for a, fid in zip(anchors, con.frame_ids, strict=True):
                w = max(w, float(np.linalg.norm(ctrl.state.frame_placement(fid).translation - a)))
        worst[second_order] = w
    assert worst[True] < 0.5 * worst[False], worst


def test_corrector_step_takes_the_drift_the_anticipation_leaves(
    g1, make_config, make_wild_targets
) -> None:
    """The corrector step (``refine``, default on): the same 300 wild ticks, three seeds.

    The anticipation uses the last tick's velocity; the corrector solves again with the rows
    shifted by what the solved step itself did. Measured (G1, daqp): worst sole drift
    0.34 / 0.47 / 0.46 mm without, 0.074 / 0.067 / 0.066 mm with, a corrector solve on about
    60 % of these (violent) ticks, no held tick. Asserted: at most 0.15 mm with it (twice the
    measured, for solver round-off over 300 chaotic ticks) and at most half of the drift
    without it, seed by seed.
    """
    for seed in (1, 2, 3):
        worst, solves = {}, 0
        for refine in (False, True):
            cfg = make_config(g1)
            cfg["constraints"][2]["refine"] = refine
            ctrl = Controller(cfg)
            con = ctrl.constraint("contacts")
            anchors = [con.anchor_pose(f).translation for f in con.names]
            w = 0.0
            for targets in make_wild_targets(ctrl, 300, seed=seed):
                res = ctrl.step(targets)
                assert res.status != "held"
                solves += ctrl.level_impl.refined
                for a, fid in zip(anchors, con.frame_ids, strict=True):
                    p = ctrl.state.frame_placement(fid).translation
                    w = max(w, float(np.linalg.norm(p - a)))
            worst[refine] = w
        assert solves > 0
        assert worst[True] < 1.5e-4, f"seed {seed}: {worst}"
        assert worst[True] < 0.5 * worst[False], f"seed {seed}: {worst}"


def test_corrector_step_leaves_a_resting_tick_alone(g1, make_config) -> None:
    """At rest the solved step is the rows' request to well under the tolerance: no extra
    solve, and ``refine_rows`` reports nothing to correct."""
    ctrl = _ctrl(g1, make_config)
    for _ in range(5):
        ctrl.step({})
        assert ctrl.level_impl.refined == 0
    con = ctrl.constraint("contacts")
    blk = con.compute_rows(ctrl.state, ctrl.dt)
    l, u = blk.l.copy(), blk.u.copy()
    assert not con.refine_rows(ctrl.state, ctrl.state.q.copy(), ctrl.dt, l, u)
    assert np.array_equal(l, blk.l)
