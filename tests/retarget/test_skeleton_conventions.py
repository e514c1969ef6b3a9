# SPDX-License-Identifier: Apache-2.0
"""Skeleton conventions the key-point stream corrects at the first frame.

A waist key-point at the hip joints is raised to the pelvis centre, and a rest pose that does
not stand upright facing forward is re-referenced (docs/motion.md, *Rest poses*).

Poubel 2014 eq. 1 roots the scaled body at the feet, so the robot's pelvis target is as high
above its ankles as the person's waist key-point is above theirs (times the leg-length ratio).
CMU's root is the pelvis centre, 0.110-0.128 leg lengths above the hip joints' midpoint on the
shared clips; Biovision's and DeepMimic's roots sit at the hip joints, and the robot crouched
(G1's knees at 1.5 rad on a real Biovision clip of a person standing still). See
``KeypointStream.waist_lift`` and docs/motion.md (*The waist key-point*).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.motion import load_motion
from qpretarget.motion.keypoints import guess_keypoint_map
from qpretarget.retarget import Retargeter
from qpretarget.retarget.stream import WAIST_ABOVE_HIPS

MOCAP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "mocap"
WALK = MOCAP / "cmu_16_15_walk.bvh"


def _person(waist_above_hips: float, lean_deg: float = 0.0) -> dict[str, np.ndarray]:
    """A standing person: hips 0.9 m up, thighs 0.42 m, shanks 0.40 m (leg 0.82 m)."""
    pts = {
        "left_hip": [0.0, 0.09, 0.9], "right_hip": [0.0, -0.09, 0.9],
        "left_knee": [0.0, 0.09, 0.48], "right_knee": [0.0, -0.09, 0.48],
        "left_ankle": [0.0, 0.09, 0.08], "right_ankle": [0.0, -0.09, 0.08],
        "waist": [0.0, 0.0, 0.9 + waist_above_hips],
    }  # fmt: skip
    a = np.radians(lean_deg)
    pts["neck"] = [0.5 * np.sin(a), 0.0, 0.9 + waist_above_hips + 0.5 * np.cos(a)]
    return {k: np.array(v, float) for k, v in pts.items()}


@pytest.fixture(scope="module")
def controller(repo_dir) -> Controller:
    return Controller.from_yaml(repo_dir / "configs" / "g1_whole_body.yaml")


def _stream(controller: Controller, kmap="cmu"):
    r = Retargeter(controller, keypoint_map=kmap)
    return r._make_stream(load_motion(WALK).slice(0.0, 0.1), causal=False)


def test_the_lift_is_what_takes_the_waist_to_the_pelvis_centre(controller) -> None:
    stream = _stream(controller)
    leg = 0.82
    # Rooted at the hip joints (Biovision, DeepMimic): raised to 0.12 leg lengths, to 1e-12 m
    # (sums of a few distances).
    assert stream.waist_lift(_person(0.0), None) == pytest.approx(WAIST_ABOVE_HIPS * leg, abs=1e-12)
    assert stream.waist_lift(_person(-0.01), None) == pytest.approx(
        WAIST_ABOVE_HIPS * leg + 0.01, abs=1e-12
    )
    # CMU's root (0.110-0.128 leg lengths up) and Mixamo-like roots above 0.09: left as they are.
    assert stream.waist_lift(_person(0.10), None) == 0.0
    assert stream.waist_lift(_person(0.075), None) == 0.0
    # Not measured on a person lying down, nor with a point missing.
    assert stream.waist_lift(_person(0.0, lean_deg=80.0), None) == 0.0
    p = _person(0.0)
    p["left_knee"] = np.full(3, np.nan)
    assert stream.waist_lift(p, None) == 0.0


def test_the_shared_cmu_clips_are_not_lifted(controller) -> None:
    """Every shared CMU clip's root is above the threshold: their runs are unchanged."""
    for clip in sorted(MOCAP.glob("*.bvh")):
        motion = load_motion(clip).slice(0.0, 0.1)
        r = Retargeter(controller)
        stream = r._make_stream(motion, causal=False)
        stream.offline(motion)
        assert stream.lift == 0.0, clip.name


def test_a_waist_at_the_hip_joints_gives_the_cmu_root_s_pelvis(
    controller, waist_at_hips_map
) -> None:
    """The walk with its waist key-point put at the hip joints' midpoint, against CMU's root.

    The same real clip with ``waist: [lfemur, rfemur]`` (the mean of the hip joints, where a
    Biovision or DeepMimic skeleton has its root): raised by 0.12 leg lengths, the run's first
    pelvis height is the CMU map's within 1 cm (CMU's root on this clip is 0.119 leg lengths
    up and 1-2 cm off the mid-hip horizontally; measured 0.7 cm), and over the first second
    (steps on both feet) within 2.5 cm (measured 1.6 cm). Without the lift the first pelvis
    height was 7 cm lower, with the knees bent further.
    """
    data = waist_at_hips_map
    motion = load_motion(WALK).slice(0.0, 1.0)
    base = Retargeter(controller).retarget(motion)
    hips = Retargeter(controller, keypoint_map=data).retarget(motion)
    assert any("raised by" in n for n in hips.meta["messages"])
    assert hips.meta["waist_lift_m"] > 0.09
    assert base.meta["waist_lift_m"] == 0.0
    assert abs(hips.q[0, 2] - base.q[0, 2]) < 0.01
    assert np.max(np.abs(hips.q[:, 2] - base.q[:, 2])) < 0.025


BIOVISION_HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET -0.17 10.29 0.13
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Chest2
    {
      OFFSET 0.32 15.82 -2.64
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT LeftCollar
      {
        OFFSET -0.07 16.88 0.30
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT LeftShoulder
        {
          OFFSET 16.01 -3.08 2.05
          CHANNELS 3 Zrotation Xrotation Yrotation
          JOINT LeftElbow
          {
            OFFSET 2.62 -25.42 1.72
            CHANNELS 3 Zrotation Xrotation Yrotation
            JOINT LeftWrist
            {
              OFFSET 2.36 -22.47 1.05
              CHANNELS 3 Zrotation Xrotation Yrotation
              End Site
              {
                OFFSET 1.49 -13.99 1.15
              }
            }
          }
        }
      }
      JOINT RightCollar
      {
        OFFSET -0.07 16.88 0.30
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT RightShoulder
        {
          OFFSET -16.37 -2.44 2.08
          CHANNELS 3 Zrotation Xrotation Yrotation
          JOINT RightElbow
          {
            OFFSET -2.69 -25.09 1.30
            CHANNELS 3 Zrotation Xrotation Yrotation
            JOINT RightWrist
            {
              OFFSET -2.38 -22.83 1.03
              CHANNELS 3 Zrotation Xrotation Yrotation
              End Site
              {
                OFFSET -1.47 -14.72 1.07
              }
            }
          }
        }
      }
      JOINT Neck
      {
        OFFSET -0.07 16.88 0.30
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT Head
        {
          OFFSET 0.13 11.41 4.71
          CHANNELS 3 Zrotation Xrotation Yrotation
          End Site
          {
            OFFSET 0.05 18.04 0.34
          }
        }
      }
    }
  }
  JOINT LeftHip
  {
    OFFSET 9.32 -0.04 3.54
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftKnee
    {
      OFFSET -0.54 -48.84 0.31
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT LeftAnkle
      {
        OFFSET 0.20 -38.49 -4.29
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
          OFFSET 1.19 -7.45 17.81
        }
      }
    }
  }
  JOINT RightHip
  {
    OFFSET -10.07 -0.07 3.15
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT RightKnee
    {
      OFFSET 0.32 -48.52 0.11
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT RightAnkle
      {
        OFFSET -1.12 -38.44 -3.43
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
          OFFSET -1.33 -7.37 17.38
        }
      }
    }
  }
}
"""


def test_a_biovision_skeleton_is_recognised_and_lifted(tmp_path, controller) -> None:
    """The classic Biovision naming (the hierarchy of a MocapBank file), standing in its rest
    pose for 1 s (synthetic frames): the ``biovision`` map fits, the toes are the ankles' End
    Sites, and the waist (``Hips``, at the hip joints) is raised by 0.12 leg lengths."""
    n = 30
    row = " ".join(["0"] * (6 + 3 * 18))
    rows = "\n".join(row.replace("0 0 0", "0 93.6 0", 1) for _ in range(n))
    path = tmp_path / "biovision.bvh"
    path.write_text(BIOVISION_HEADER + f"MOTION\nFrames: {n}\nFrame Time: 0.033333\n{rows}\n")
    motion = load_motion(path)
    assert guess_keypoint_map(motion).name == "biovision"
    run = Retargeter(controller).retarget(motion)
    leg = 0.01 * (48.84 + 38.49 + 48.52 + 38.44) / 2  # the rest pose's legs, nearly straight
    # The Hips sit 0.04-0.07 cm under the hip joints: lift 0.12 leg + 0.06 cm, to 2 mm.
    assert run.meta["waist_lift_m"] == pytest.approx(WAIST_ABOVE_HIPS * leg + 0.0006, abs=2e-3)
    assert set(np.asarray(run.status)) <= {"ok", "relaxed"}
    # A person standing still: the robot stands (no crouch), knees under 1 rad (1.5 without
    # the lift on the real clip this header comes from).
    knees = [controller.robot.model.getJointId(f"{s}_knee_joint") for s in ("left", "right")]
    idx = [controller.robot.model.joints[j].idx_q for j in knees]
    assert np.max(run.q[:, idx]) < 1.0


def _rest_turned(motion, Q: np.ndarray):
    """The same motion with its skeleton's rest pose turned by ``Q``.

    Offsets ``Q o`` and local rotations ``Q R Q^T`` (the root's ``R Q^T``) give the same joint
    positions, and world orientations relative to the new rest pose ``R_w Q^T``: what a BVH
    whose rest pose faces another axis, or a Maya-style skeleton with its bones along one
    axis, reads as.
    """
    from dataclasses import replace

    return replace(motion, orientations=motion.orientations @ Q.T)


@pytest.mark.parametrize(
    ("axis", "deg"), [((0, 0, 1), 90.0), ((0, 0, 1), 180.0), ((0, 1, 0), -90.0)]
)
def test_a_rest_pose_facing_another_axis_gives_the_same_run(controller, axis, deg) -> None:
    """The walk's first 2 s with the rest pose facing sideways, backwards, or lying along the
    body's forward axis (bones along one axis, as LAFAN1's): the pelvis, torso and head
    orientations are re-referenced to the person's body frame at the first frame
    (``KeypointStream.rest_fix``) and the run is the CMU rest pose's within the body frame's
    1.8-3.2 deg disagreement with CMU's joint frames on this clip. Before, the tasks read the
    rotations as the body's: a DeepMimic walk whose rest pose faces +x (not +z) in its BVH was
    walked sideways, legs crossed (ankle error 2.7 leg lengths, 0.076 with its rest pose
    facing +z; docs/motion.md, *Rest poses*).
    """
    import pinocchio as pin

    motion = load_motion(WALK).slice(0.0, 2.0)
    Q = pin.exp3(np.radians(deg) * np.asarray(axis, float))
    base = Retargeter(controller).retarget(motion)
    turned = Retargeter(controller).retarget(_rest_turned(motion, Q))
    assert base.meta["rest_fixes"] == []
    assert turned.meta["rest_fixes"] == ["torso", "waist"]  # the config has no head orientation
    assert any("rest pose" in n for n in turned.meta["messages"])
    # The pelvis (bound 3 cm, measured 0.4-0.6 cm) and both feet (bound 3 cm) follow the same
    # path; the heading within 5 deg of the CMU rest pose's run at every tick.
    assert np.max(np.abs(turned.q[:, :3] - base.q[:, :3])) < 0.03
    for task in ("left_foot", "right_foot"):
        assert np.max(np.linalg.norm(turned.targets[task] - base.targets[task], axis=1)) < 0.03
    yaw = [np.unwrap([np.arctan2(*pin.Quaternion(*r.q[:, 3:7].T[[3, 0, 1, 2], k]).matrix()[[1, 0], 0])
                      for k in range(len(r.q))]) for r in (base, turned)]  # fmt: skip
    assert np.max(np.abs(np.degrees(yaw[1] - yaw[0]))) < 5.0


def test_online_push_lifts_and_re_references_as_offline(
    controller, waist_at_hips_map, push_all
) -> None:
    """Frames pushed one by one (a live suit) get the lift and the rest-pose re-referencing
    decided on the first pushed frame, as the offline causal run does: the walk's first 1.5 s
    with its waist at the hip joints and its rest pose turned 90 deg about the vertical, online
    against offline causal within 1e-6 (the same code after the streaming filter, which equals
    the batch one to ~1e-12)."""
    import pinocchio as pin

    data = waist_at_hips_map
    Q = pin.exp3(np.radians(90.0) * np.array([0.0, 0.0, 1.0]))
    motion = _rest_turned(load_motion(WALK).slice(0.0, 1.5), Q)
    rt = Retargeter(controller, keypoint_map=data)
    offline = rt.retarget(motion, causal=True)
    assert offline.meta["waist_lift_m"] > 0.09 and offline.meta["rest_fixes"]
    q = np.array([c.q for c in push_all(rt, motion)])
    assert q.shape == offline.q.shape
    assert np.abs(q - offline.q).max() < 1e-6
    assert any("raised by" in n for n in rt.notes) and any("rest pose" in n for n in rt.notes)
