# SPDX-License-Identifier: Apache-2.0
"""The point-cloud fit's self-collision (qpretarget.cloud.command, config ``self_collision``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget.analysis.mesh_audit import audit_self_collision
from qpretarget.cloud.command import (
    CLEAR_TOLERANCE,
    FOLLOW_STEPS,
    SEGMENTS,
    CommandProjection,
)
from qpretarget.cloud.config import CloudConfig
from qpretarget.errors import ConfigError
from qpretarget.solvers import make_solver

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "cloud_g1.yaml"


@pytest.fixture(scope="module")
def shipped_spec() -> dict:
    return yaml.safe_load(CONFIG.read_text())["self_collision"]


def _arm_in_the_hip(g1) -> np.ndarray:
    """G1's left arm rolled 0.3 rad into its hip: 44.5 mm deep on the meshes."""
    q = g1.q_reference.copy()
    m = g1.model
    q[m.joints[m.getJointId("left_shoulder_roll_joint")].idx_q] = -0.3
    return q


def _segment_angles(g1, q: np.ndarray, q_ref: np.ndarray) -> dict[tuple[str, str], float]:
    """Angle [deg] of each key-point segment of ``q`` to the same segment of ``q_ref``."""
    out = {}
    d, r = g1.model.createData(), g1.model.createData()
    pin.framesForwardKinematics(g1.model, d, q)
    pin.framesForwardKinematics(g1.model, r, q_ref)
    kf = g1.keyframes
    for a, b in SEGMENTS:
        u = d.oMf[g1.frame_id(kf[b])].translation - d.oMf[g1.frame_id(kf[a])].translation
        v = r.oMf[g1.frame_id(kf[b])].translation - r.oMf[g1.frame_id(kf[a])].translation
        c = u @ v / np.linalg.norm(u) / np.linalg.norm(v)
        out[(a, b)] = float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    return out


def _sole_errors(g1, q0: np.ndarray, q1: np.ndarray, soles: list[int]) -> list[np.ndarray]:
    d0, d1 = g1.model.createData(), g1.model.createData()
    pin.framesForwardKinematics(g1.model, d0, q0)
    pin.framesForwardKinematics(g1.model, d1, q1)
    return [pin.log6(d0.oMf[f].actInv(d1.oMf[f])).vector for f in soles]


def _placed(g1, q: np.ndarray, soles: list[int]) -> list[tuple[int, pin.SE3]]:
    """The soles ``soles`` (frame ids) with their placements where ``q`` has them."""
    data = g1.model.createData()
    pin.framesForwardKinematics(g1.model, data, q)
    return [(f, data.oMf[f].copy()) for f in soles]


def test_a_penetrating_command_is_cleared_turning_the_segments_the_least(g1, shipped_spec):
    cc = CommandProjection(g1, shipped_spec)
    target = _arm_in_the_hip(g1)
    assert audit_self_collision(g1, target[None]).penetrating_frames == 1
    soles = [g1.frame_id(f.frame) for f in g1.feet.values()]
    q, gap = cc.follow(target, None, _placed(g1, target, soles), g1.q_min, g1.q_max,
                       make_solver({"name": "daqp"}))  # fmt: skip
    # Every pair at its safety distance on the hulls (conservative: the meshes lie inside)
    # up to the tolerance: d_s = 5 mm, or a quarter of the pair's distance at rest for pairs
    # that sit close by construction.
    assert gap >= -CLEAR_TOLERANCE and 0 < cc.steps <= FOLLOW_STEPS
    audit = audit_self_collision(g1, q[None])
    assert audit.penetrating_frames == 0
    assert audit.min_distance_mm >= 1.0
    # The soles held (weight 1e4 against the segments): within 1 mm and 0.2 deg.
    for err in _sole_errors(g1, target, q, soles):
        assert np.linalg.norm(err[:3]) < 1e-3 and np.linalg.norm(err[3:]) < np.radians(0.2)
    qi = g1.joint_q_index
    assert np.all(q[qi] >= g1.q_min[qi] - 1e-12) and np.all(q[qi] <= g1.q_max[qi] + 1e-12)
    # The segments turn the least (in angle: each weighed by 1/length^2): the left upper arm
    # swings out of the hip (it went 0.3 rad in) and the trunk yields a little (the shoulder
    # girdle 4.95 deg, the head 4.1), the legs and the right arm within 0.3 deg.
    turned = _segment_angles(g1, q, target)
    assert turned[("left_shoulder", "left_elbow")] > 5.0, turned
    trunk = {k: v for k, v in turned.items() if k[0] in ("pelvis", "torso")}
    assert max(trunk.values()) < 6.0, trunk
    rest = {k: v for k, v in turned.items() if k[0].startswith(("right_", "left_hip", "left_knee"))}
    assert max(rest.values()) < 1.0, rest


def test_a_clear_start_never_enters_and_stops_at_the_contact(g1, shipped_spec):
    """From the last frame's clear command, the steps follow the fit's penetrating pose up to
    the safety distance (the controller's damper: the hulls are never entered)."""
    cc = CommandProjection(g1, shipped_spec)
    start, target = g1.q_reference.copy(), _arm_in_the_hip(g1)
    assert cc.linearize(start) >= 0.0
    q, gap = cc.follow(target, start, [], g1.q_min, g1.q_max, make_solver({"name": "daqp"}))
    assert gap >= -CLEAR_TOLERANCE
    assert audit_self_collision(g1, q[None]).penetrating_frames == 0
    # It went towards the target: the left upper arm nearer the target's than at the start,
    # and up to the contact: the closest pair within 2 mm of its safety distance.
    key = ("left_shoulder", "left_elbow")
    assert _segment_angles(g1, q, target)[key] < _segment_angles(g1, start, target)[key] - 1.0
    assert gap < 2e-3


def test_a_clear_command_is_left_as_the_fit_has_it(g1, shipped_spec):
    cc = CommandProjection(g1, shipped_spec)
    q0 = g1.q_reference.copy()
    q, gap = cc.follow(q0, None, [], g1.q_min, g1.q_max, make_solver({"name": "daqp"}))
    assert q is q0 and cc.steps == 0 and gap >= 0.0


def test_bad_self_collision_sections_name_the_key():
    with pytest.raises(ConfigError, match=r"self_collision\.typo.*unknown key"):
        CloudConfig.from_dict({"self_collision": {"pairs": "auto", "typo": 1}})
    with pytest.raises(ConfigError, match="remove `type`"):
        CloudConfig.from_dict({"self_collision": {"type": "self_collision"}})
    with pytest.raises(ConfigError, match="mapping"):
        CloudConfig.from_dict({"self_collision": "auto"})
    with pytest.raises(ConfigError, match="d_i"):
        CloudConfig.from_dict({"self_collision": {"d_s": 0.1, "d_i": 0.05}})
    # One gain form: a given gain replaces the fit's default gain_per_tick.
    cfg = CloudConfig.from_dict({"self_collision": {"gain": 2.0}})
    assert cfg.self_collision == {"gain": 2.0}
    assert CloudConfig.from_dict({}).self_collision is None


def test_moving_the_links_apart_does_not_tip_the_robot(g1, shipped_spec):
    """With balance rows the projection moves the CoM no further out of the support polygon.

    G1 on its right sole alone with its left arm in its hip: the CoM already lies outside that
    sole (between the feet), and swinging the left arm out moves it further left, away from
    the sole (measured without the rows: 9.6 mm further out). With the rows (each bound at
    least 0) it ends no further out than it started, 0.1 mm allowed for the linearization.
    """
    from qpretarget.cloud.stability import StabilityRows, Support

    target = _arm_in_the_hip(g1)
    right = g1.frame_id(g1.feet["right_foot"].frame)
    soles = _placed(g1, target, [right])
    support = Support(feet=["right_foot"], primary="right_foot")
    margins = {}
    for with_rows in (False, True):
        rows = StabilityRows(g1, margin=0.01, region="polygon")
        rows.set_support(support, target)
        before = rows.margin_of(target, full=True)
        cc = CommandProjection(g1, shipped_spec)
        q, gap = cc.follow(target, None, soles, g1.q_min, g1.q_max,
                           make_solver({"name": "daqp"}),
                           (lambda q, r=rows: (r, False)) if with_rows else None)  # fmt: skip
        assert gap >= -CLEAR_TOLERANCE
        margins[with_rows] = rows.margin_of(q, full=True) - before
    assert margins[False] < -5e-3, margins  # the arm swung out tips the robot further ...
    assert margins[True] >= -1e-4, margins  # ... which the rows do not let it do


def test_a_sole_off_its_placement_is_put_back_and_the_robot_balanced_where_the_person_is(g1):
    """Without self-collision rows: the right sole's placement 3 cm beside where the target
    has it (a leg that cannot reach it alone) and the robot on that sole alone with its CoM
    outside it, the person's balanced there (``(rows, True)``): the steps put the sole on its
    placement (1 mm, the steps' tolerance) and the CoM inside the sole's polygon (0.1 mm
    allowed for the linearization), the left foot free."""
    from qpretarget.cloud.stability import StabilityRows, Support

    cc = CommandProjection(g1, None)
    target = g1.q_reference.copy()
    right = g1.frame_id(g1.feet["right_foot"].frame)
    ((fid, M),) = _placed(g1, target, [right])
    M.translation[1] -= 0.03
    rows = StabilityRows(g1, margin=0.01, region="polygon")
    support = Support(feet=["right_foot"], primary="right_foot")
    rows.set_support(support, target)
    assert rows.margin_of(target, full=True) < -0.02  # between the feet, outside the sole
    q, gap = cc.follow(target, None, [(fid, M)], g1.q_min, g1.q_max,
                       make_solver({"name": "daqp"}), lambda q: (rows, True))  # fmt: skip
    assert gap == np.inf and 0 < cc.steps <= FOLLOW_STEPS
    ((_, got),) = _placed(g1, q, [right])
    assert np.linalg.norm(got.translation - M.translation) < 1e-3
    rows.set_support(support, q)
    assert rows.margin_of(q, full=True) >= -1e-4
    # The same with the person not balanced there ((rows, False)): the sole put back, the CoM
    # no further out than the target has it, not pulled in.
    cc = CommandProjection(g1, None)
    rows.set_support(support, target)
    before = rows.margin_of(target, full=True)
    q, _ = cc.follow(target, None, [(fid, M)], g1.q_min, g1.q_max,
                     make_solver({"name": "daqp"}), lambda q: (rows, False))  # fmt: skip
    rows.set_support(support, q)
    assert before - 1e-4 <= rows.margin_of(q, full=True) < -0.01
