# SPDX-License-Identifier: Apache-2.0
"""``qpretarget keypoints``: the joints, the map picked, a template for an unknown skeleton."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

MOCAP = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mocap"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qpretarget", "keypoints", *args],
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def test_known_skeleton_prints_its_map():
    r = _cli(str(MOCAP / "cmu_16_15_walk.bvh"))
    assert r.returncode == 0, r.stderr
    assert "key-point map: cmu" in r.stdout and "left_elbow       <- lradius" in r.stdout
    assert "skeleton: waist and rest pose as the retargeter expects" in r.stdout


def test_the_corrections_a_skeleton_will_get_are_shown(waist_at_hips_map):
    """The same real walk with its waist at the hip joints and its rest pose turned 90 deg
    about the vertical: both corrections are named, with the lift and the angles the
    retargeter will use (the lift 0.12 leg lengths: 10.0 cm on this person, to 0.5 cm; the
    angles 90 deg to 20 deg: on this clip CMU's waist and torso frames are 2-3 deg off the
    key-points' body frames, the head's 17 deg, its own pitch; measured 90, 92, 100)."""
    from dataclasses import replace

    import numpy as np
    import pinocchio as pin

    from qpretarget.commands.keypoints import conventions
    from qpretarget.motion import load_motion
    from qpretarget.motion.keypoints import load_keypoint_map

    motion = load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 0.5)
    cmu = load_keypoint_map("cmu")
    kmap = load_keypoint_map(waist_at_hips_map)
    assert conventions(motion, cmu) == ["skeleton: waist and rest pose as the retargeter expects"]
    Q = pin.exp3(np.radians(90.0) * np.array([0.0, 0.0, 1.0]))
    lines = conventions(replace(motion, orientations=motion.orientations @ Q.T), kmap)
    lift = float(re.search(r"raised by ([0-9.]+) cm", lines[0]).group(1))
    assert abs(lift - 10.0) < 0.5, lines
    angles = [float(a) for a in re.findall(r"(\d+) deg", lines[1])]
    assert len(angles) == 3 and all(abs(a - 90.0) < 20.0 for a in angles), lines


def test_unknown_skeleton_gets_a_template_that_loads_and_retargets(tmp_path, repo_dir):
    text = (MOCAP / "cmu_29_03_teapot_arm_gestures.bvh").read_text()
    odd = tmp_path / "odd.bvh"
    odd.write_text(re.sub(r"^(\s*(?:ROOT|JOINT)\s+)(\S+)", r"\1Char1_\2", text, flags=re.M))
    r = _cli(str(odd))
    assert r.returncode == 1  # no bundled map fits: says so
    assert "no bundled key-point map fits" in r.stdout and "Char1_lhumerus" in r.stdout
    tpl = _cli(str(odd), "--template")
    kmap = tmp_path / "odd.yaml"
    kmap.write_text(tpl.stdout)
    out = tmp_path / "odd.npz"
    run = subprocess.run(
        [sys.executable, "-m", "qpretarget", "retarget", str(repo_dir / "configs" / "g1_whole_body.yaml"),
         str(odd), "-o", str(out), "--end", "1", "--keypoint-map", str(kmap)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert out.is_file()
