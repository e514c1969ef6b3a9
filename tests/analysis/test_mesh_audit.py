# SPDX-License-Identifier: Apache-2.0
"""The self-collision audit over every pair, confirmed on meshes (one definition)."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.analysis.mesh_audit import audit_self_collision, audited_pairs
from qpretarget.robot import load_robot


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def test_reference_posture_is_clear_on_every_pair(g1):
    audit = audit_self_collision(g1, g1.q_reference[None, :])
    assert len(audit.pairs) == len(audited_pairs(g1)) == 399
    assert audit.penetrating_frames == 0
    assert audit.min_distance_mm > 0.0


def test_an_arm_driven_into_the_torso_is_caught(g1):
    """Elbow folded and shoulder rolled inwards: forearm/hand in the torso (never a listed pair)."""
    q = g1.q_reference.copy()
    names = g1.joint_names
    q[7 + names.index("left_shoulder_roll_joint")] = -1.0  # towards the body (limit -1.59)
    q[7 + names.index("left_shoulder_pitch_joint")] = -0.6
    q[7 + names.index("left_elbow_joint")] = 0.2
    audit = audit_self_collision(g1, np.stack([g1.q_reference, q]))
    assert audit.penetrating[0].sum() == 0
    assert audit.penetrating[1].sum() >= 1, audit.to_dict(5)
    worst = audit.worst(1)[0]
    assert "left" in worst.pair[0] + worst.pair[1]
    d = audit.to_dict()
    assert d["penetrating_frames"] == 1 and d["penetrating_pairs"]
