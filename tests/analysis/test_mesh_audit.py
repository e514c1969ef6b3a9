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


def _independent_pairs(robot):
    """Every pair of bodies with collision geometry that is neither on one joint nor adjacent.

    Written here without the library's pair selection, so a pair the audit drops (by a bug or a
    new rule) fails the test: adjacency is "one body's joint is the nearest ancestor joint of the
    other's that carries geometry" (MoveIt's rule; links without geometry are skipped).
    """
    import itertools

    from qpretarget.collision import link_shapes

    shapes = link_shapes(robot, "convex_hull")
    carriers = {s.joint for s in shapes.values()}
    parents = robot.model.parents

    def geometric_parent(j: int) -> int:
        j = parents[j]
        while j != 0 and j not in carriers:
            j = parents[j]
        return j

    out = set()
    for a, b in itertools.combinations(shapes, 2):
        ja, jb = shapes[a].joint, shapes[b].joint
        if ja == jb or geometric_parent(ja) == jb or geometric_parent(jb) == ja:
            continue
        out.add(frozenset((a, b)))
    return out


def test_the_audit_leaves_no_pair_out(g1):
    # G1 touches nowhere at rest: every non-adjacent pair is audited (30 bodies, 435 pairs, 36
    # on one joint or adjacent).
    assert {frozenset(p) for p in audited_pairs(g1)} == _independent_pairs(g1)


#: Excerpts of the five clips where the arms swing and the legs kick: the seconds in which the
#: shipped G1 config with its former 20 listed pairs penetrated most (measured over all pairs:
#: walk 361/391 frames, kicks 46 frames in 3-6 s, boxing 88 frames in 1.5-4.5 s, dance 287 in
#: 6-9 s, reach-up 18 frames in 5-6 s). Excerpts, not whole clips, to keep the test near 20 s.
CLIP_WINDOWS = {
    "cmu_16_15_walk.bvh": (0.0, 2.5),
    "cmu_135_04_front_kicks.bvh": (3.0, 6.0),
    "cmu_17_10_boxing.bvh": (1.5, 4.5),
    "cmu_131_04_dance_spin.bvh": (6.0, 9.0),
    "cmu_14_07_reach_up_tiptoe.bvh": (4.5, 6.5),
}


@pytest.mark.parametrize("clip", sorted(CLIP_WINDOWS))
def test_shipped_g1_config_never_penetrates_on_the_meshes(clip, g1, mocap_dir, configs_dir):
    """Acceptance of pairs: auto: zero penetrating frames over every pair, min distance > 0.

    Exact on the meshes where the hulls overlap (module docstring of mesh_audit): no tolerance,
    a touching pair counts as penetrating.
    """
    from qpretarget.control.controller import Controller
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter
    from qpretarget.retarget.summary import summarize_run

    ctrl = Controller.from_yaml(configs_dir / "g1_whole_body.yaml")
    start, end = CLIP_WINDOWS[clip]
    motion = load_motion(mocap_dir / clip).slice(start, end)
    traj = Retargeter(ctrl).retarget(motion, progress=False)
    s = summarize_run(traj, ctrl)["mesh_self_collision"]  # the summary's audit: same definition
    assert s["pairs_audited"] == len(_independent_pairs(g1))
    assert s["frames_audited"] == len(traj.q)
    assert s["penetrating_frames"] == 0, s["penetrating_pairs"]
    assert s["min_distance_mm"] > 0.0, s["closest_pairs"][:3]


def test_shipped_talos_config_never_penetrates_on_the_meshes(mocap_dir, configs_dir):
    """The same acceptance on Talos (885 controller pairs, 1159 audited), on the kata excerpt
    where its shoulders met the torso and its forearms the wrist force sensors before those pairs
    were included (376 penetrating frames in its first 6 s; the test takes the first 4 s)."""
    from qpretarget.control.controller import Controller
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter
    from qpretarget.retarget.summary import summarize_run

    ctrl = Controller.from_yaml(configs_dir / "talos_whole_body.yaml")
    assert len(ctrl.constraint("self_collision").pairs) == 885
    motion = load_motion(mocap_dir / "cmu_135_06_karate_kata.bvh").slice(0.0, 4.0)
    traj = Retargeter(ctrl).retarget(motion, progress=False)
    s = summarize_run(traj, ctrl)["mesh_self_collision"]
    from qpretarget.collision import pair_distances

    robot = ctrl.robot
    every = sorted(tuple(sorted(p)) for p in _independent_pairs(robot))  # 1166
    rest = pair_distances(robot, robot.q_reference, every)[0]
    touching = {frozenset(p) for p, d in zip(every, rest, strict=True) if d <= 0.0}
    assert len(touching) == 7  # hulls overlapping at rest: in contact by design, not audited
    audited = {frozenset(p) for p in audited_pairs(robot)}
    assert audited == {frozenset(p) for p in every} - touching
    assert s["pairs_audited"] == len(audited) == 1159
    assert s["penetrating_frames"] == 0, s["penetrating_pairs"]
    assert s["min_distance_mm"] > 0.0, s["closest_pairs"][:3]
