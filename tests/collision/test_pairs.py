# SPDX-License-Identifier: Apache-2.0
"""``pairs: auto``: every body pair minus same-joint, adjacent, reference-contact and SRDF pairs."""

from __future__ import annotations

import itertools

import pytest

from qpretarget.collision import link_shapes
from qpretarget.collision.pairs import select_pairs, srdf_disabled_pairs
from qpretarget.errors import UnknownNameError
from qpretarget.robot import load_robot


@pytest.fixture(scope="module")
def g1():
    robot = load_robot("g1")
    return robot, link_shapes(robot)


def test_every_pair_is_selected_or_excluded_with_a_reason(g1):
    robot, shapes = g1
    sel = select_pairs(robot, shapes)
    names = list(shapes)
    every = {frozenset(p) for p in itertools.combinations(names, 2)}
    chosen = {frozenset(p) for p in sel.pairs}
    left_out = {frozenset(p) for p in sel.excluded}
    assert chosen | left_out == every and not chosen & left_out
    assert all(isinstance(why, str) and why for why in sel.excluded.values())
    # G1 ships no SRDF: 30 bodies, 435 pairs, 36 structural exclusions (same joint, adjacent).
    assert sel.n_bodies == 30 and len(sel.pairs) == 399


def test_adjacent_links_are_left_out_and_arm_leg_pairs_kept(g1):
    robot, shapes = g1
    sel = select_pairs(robot, shapes)
    pairs = {frozenset(p) for p in sel.pairs}
    assert frozenset(("left_elbow_link", "left_shoulder_yaw_link")) not in pairs  # parent/child
    assert frozenset(("left_wrist_yaw_link", "left_hip_roll_link")) in pairs  # arm-leg
    assert frozenset(("left_knee_link", "right_knee_link")) in pairs  # leg-leg
    assert frozenset(("left_wrist_yaw_link", "torso_link")) in pairs


def test_include_and_exclude_lists_apply_on_top(g1):
    robot, shapes = g1
    sel = select_pairs(
        robot,
        shapes,
        include=[["left_elbow_link", "left_shoulder_yaw_link"]],
        exclude=[["left_knee_link", "right_knee_link"]],
    )
    pairs = {frozenset(p) for p in sel.pairs}
    assert frozenset(("left_elbow_link", "left_shoulder_yaw_link")) in pairs
    assert frozenset(("left_knee_link", "right_knee_link")) not in pairs
    assert "excluded by the config" in sel.excluded.values()


def test_unknown_body_names_the_close_ones(g1):
    robot, shapes = g1
    with pytest.raises(UnknownNameError, match="left_knee_link"):
        select_pairs(robot, shapes, exclude=[["left_kne_link", "torso_link"]])


def test_talos_srdf_disables_its_listed_pairs():
    robot = load_robot("talos")
    disabled = srdf_disabled_pairs(robot.srdf_path)
    assert len(disabled) > 100
    sel = select_pairs(robot, link_shapes(robot))
    assert sel.reasons().get("disabled by the SRDF", 0) > 100
    for a, b in sel.pairs:
        assert (min(a, b), max(a, b)) not in disabled


def test_ranked_update_gives_the_nearest_pairs_exactly(g1):
    """``nearest=K``: the K smallest gaps are those computing every pair gives, fewer GJK calls.

    Configurations: the reference posture then 60 ticks of a smooth arm/waist/leg motion
    (synthetic joint angles on the real robot, a unit test of the broad phase). Tolerance 1e-5 m:
    ten times coal's GJK tolerance (two GJK runs from other starts differ by about 1e-6 m).
    """
    import numpy as np

    from qpretarget.collision import CollisionModel
    from qpretarget.robot import RobotState

    robot, shapes = g1
    pairs = select_pairs(robot, shapes).pairs
    ranked = CollisionModel(robot, pairs)
    plain = CollisionModel(robot, pairs)  # broad phase, every candidate computed
    full = CollisionModel(robot, pairs, broad_phase=False)
    offset = np.full(len(pairs), 0.01)
    rng = np.random.default_rng(3)
    amp, freq = rng.uniform(0.2, 0.8, robot.nv - 6), rng.uniform(0.5, 2.0, robot.nv - 6)
    state = RobotState(robot)
    K, computed, plain_computed = 12, [], []
    for k in range(61):
        q = robot.q_reference.copy()
        q[7:] = np.clip(q[7:] + amp * np.sin(freq * k * 0.05), robot.q_min[7:], robot.q_max[7:])
        state.update(q)
        d_ranked = ranked.update(state, 0.1, nearest=K, offset=offset)
        d_full = full.compute_all(state)[0]
        gaps = np.where(d_full < 0.1, d_full - offset, np.inf)
        want = np.argsort(gaps, kind="stable")[:K]
        want = want[np.isfinite(gaps[want])]
        assert np.all(ranked.exact[want]), k
        np.testing.assert_allclose(d_ranked[want], d_full[want], rtol=0, atol=1e-5)
        assert np.all(d_ranked <= d_full + 1e-5)  # the others: lower bounds
        computed.append(ranked.last_n_computed)
        plain.update(state, 0.1)
        plain_computed.append(plain.last_n_computed)
        assert set(ranked.active.tolist()) >= set(want.tolist())
    assert sum(computed) < sum(plain_computed)  # fewer GJK calls for the same K rows


def test_common_ancestor_coordinates_leave_a_pair_unbounded(g1):
    """The trust region bounds only the coordinates of the two branches (base, waist excluded)."""
    import numpy as np

    from qpretarget.collision import CollisionModel

    robot, _ = g1
    cm = CollisionModel(robot, [("left_elbow_link", "left_wrist_yaw_link")])
    lever = cm.pair_levers(np.array([0]))[0]
    names = robot.joint_names
    v = robot.joint_v_index
    assert np.all(lever[:6] == 0.0)  # free flyer
    assert lever[v[names.index("waist_yaw_joint")]] == 0.0
    assert lever[v[names.index("left_shoulder_pitch_joint")]] == 0.0
    assert lever[v[names.index("left_wrist_pitch_joint")]] > 0.0
