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
