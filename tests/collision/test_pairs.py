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
