# SPDX-License-Identifier: Apache-2.0
"""Key-point maps picked from joint names: LAFAN1, Mixamo and MVN BVH skeletons.

The LAFAN1-, Mixamo- and MVN-named files here are synthetic: a shared CMU clip (real motion) whose
joints are renamed to the other skeleton's names, so that nothing but the names differs.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.motion import load_motion
from qpretarget.motion.keypoints import guess_keypoint_map
from qpretarget.retarget import Retargeter

MOCAP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "mocap"
CLIP = MOCAP / "cmu_29_03_teapot_arm_gestures.bvh"

_SIDES = {"l": "Left", "r": "Right"}
LAFAN1 = {"root": "Hips", "lowerback": "Spine", "upperback": "Spine1", "thorax": "Spine2",
          "lowerneck": "Neck", "upperneck": "Neck1", "head": "Head"}  # fmt: skip
MVN = {"root": "Hips", "lowerback": "Chest", "upperback": "Chest2", "thorax": "Chest4",
       "lowerneck": "Neck", "upperneck": "Chest3", "head": "Head"}  # fmt: skip
for s, side in _SIDES.items():
    LAFAN1.update({f"{s}hipjoint": f"{side}HipJoint", f"{s}femur": f"{side}UpLeg",
                   f"{s}tibia": f"{side}Leg", f"{s}foot": f"{side}Foot", f"{s}toes": f"{side}Toe",
                   f"{s}clavicle": f"{side}Shoulder", f"{s}humerus": f"{side}Arm",
                   f"{s}radius": f"{side}ForeArm", f"{s}wrist": f"{side}Hand",
                   f"{s}hand": f"{side}HandEnd", f"{s}fingers": f"{side}Fingers",
                   f"{s}thumb": f"{side}Thumb"})  # fmt: skip
    MVN.update({f"{s}hipjoint": f"{side}Pelvis", f"{s}femur": f"{side}Hip",
                f"{s}tibia": f"{side}Knee", f"{s}foot": f"{side}Ankle", f"{s}toes": f"{side}Toe",
                f"{s}clavicle": f"{side}Collar", f"{s}humerus": f"{side}Shoulder",
                f"{s}radius": f"{side}Elbow", f"{s}wrist": f"{side}Wrist",
                f"{s}hand": f"{side}Hand", f"{s}fingers": f"{side}Fingers",
                f"{s}thumb": f"{side}Thumb"})  # fmt: skip
MIXAMO = {k: "mixamorig:" + v.replace("Toe", "ToeBase") for k, v in LAFAN1.items()}


def renamed(tmp_path: Path, names: dict[str, str], tag: str) -> Path:
    text = CLIP.read_text()
    out = re.sub(r"^(\s*(?:ROOT|JOINT)\s+)(\S+)", lambda m: m.group(1) + names[m.group(2)], text,
                 flags=re.M)  # fmt: skip
    path = tmp_path / f"teapot_{tag}.bvh"
    path.write_text(out)
    return path


@pytest.fixture(scope="module")
def controller(repo_dir) -> Controller:
    return Controller.from_yaml(repo_dir / "configs" / "g1_whole_body.yaml")


@pytest.fixture(scope="module")
def cmu_run(controller):
    return Retargeter(controller).retarget(load_motion(CLIP).slice(0.0, 2.0))


@pytest.mark.parametrize(("names", "expected"), [(LAFAN1, "lafan1"), (MIXAMO, "mixamo"),
                                                 (MVN, "mvn_bvh")])  # fmt: skip
def test_skeleton_is_recognised_and_retargeted(tmp_path, names, expected, controller, cmu_run):
    motion = load_motion(renamed(tmp_path, names, expected)).slice(0.0, 2.0)
    assert guess_keypoint_map(motion).name == expected
    run = Retargeter(controller).retarget(motion)
    assert np.all(np.isfinite(run.q)) and set(np.asarray(run.status)) <= {"ok", "relaxed"}
    # Same motion, other names: the same targets as with the CMU map. These skeletons have no
    # hand bone: the hand key-point is extended past the wrist by half the forearm, where CMU's
    # hand joint sits (collinear, ratio 0.5 to 3e-7 m on this clip). The targets are built from
    # the robot's stance foot (Poubel eq. 1), so that 3e-7 m reaches the other targets through
    # the closed loop (5e-8 m measured before the run started in the person's first stance).
    # That start settles until the base and soles are still (a speed threshold): the 3e-7 m
    # changes where it stops, and the targets then differ by up to 4e-4 m (measured). 2e-3 m
    # still fails any other mapping of a joint (the next joint is 5 cm or more away).
    for task in ("left_elbow", "right_elbow", "left_hand", "right_hand"):
        np.testing.assert_allclose(run.targets[task], cmu_run.targets[task], atol=2e-3)
