# SPDX-License-Identifier: Apache-2.0
"""The CRAC reproduction script on a short excerpt (issue 6 acceptance): zero violations after
filtering, more than zero before."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "crac_experiments.py"


@pytest.fixture(scope="module")
def crac():
    spec = importlib.util.spec_from_file_location("crac_experiments", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_quick_reaching_excerpt(crac, mocap_dir, tmp_path):
    assert (mocap_dir / crac.CLIPS["reaching"]).is_file()
    assert crac.main(["--quick", "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    row = results["kinematic"]["reaching"]["ts2"]
    # 2 s of CMU 14_07 (both arms reach overhead) push G1's shoulders past their limits when
    # nothing stops them; with the constraints on, not one joint or pair in any frame.
    assert row["before"]["violations_per_frame"] > 0
    assert row["after"]["violations_per_frame"] == 0
    assert row["after"]["min_distance_m"] > 0
    for name in ("violations_reaching", "pair_distances_reaching", "joint_angles_reaching"):
        assert (tmp_path / "figures" / f"{name}.png").stat().st_size > 10_000


def test_before_config_drops_the_kinematic_constraints(crac):
    cfg = crac.with_self_collision(crac.load_config(2, "acceleration"))
    types = [c["type"] for c in cfg["constraints"]]
    assert "self_collision" in types and "joint_limits" in types
    before = crac.unconstrained(cfg)
    assert {c["type"] for c in before["constraints"]}.isdisjoint({"joint_limits", "self_collision"})
    assert before["regularization"]["type"] == "identity"
    assert crac.inertia(cfg, False)["regularization"]["inertia"] is False
    assert crac.retarget_spec(cfg)["tasks"] == {
        "waist": "waist",
        "left_wrist": "left_wrist",
        "right_wrist": "right_wrist",
    }
