# SPDX-License-Identifier: Apache-2.0
"""``qpretarget evaluate`` on a short real run: metrics.json with every field and the figures."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from PIL import Image

from qpretarget.analysis.plots import FIGSIZE, figure_pixels
from qpretarget.analysis.solver_comparison import record_run, scripted_targets
from qpretarget.cli import main
from qpretarget.control.controller import Controller


@pytest.fixture(scope="module")
def runs(configs_dir, tmp_path_factory) -> tuple[Path, Path]:
    """A 2 s G1 run with joint limits on (after), and the same targets with constraints off."""
    d = tmp_path_factory.mktemp("runs")
    cfg = yaml.safe_load((configs_dir / "g1_augmentation.yaml").read_text())
    ctrl = Controller(cfg)
    targets = list(scripted_targets(ctrl, 2.0))
    after = record_run(ctrl, targets).save(d / "run.npz")
    off = Controller({**cfg, "constraints": []})
    before = record_run(off, targets).save(d / "run_unconstrained.npz")
    return after, before


@pytest.fixture(scope="module")
def report(runs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report")
    after, before = runs
    assert main(["evaluate", str(after), "-o", str(out), "--before", str(before)]) == 0
    return out


def test_metrics_json_has_every_field(report):
    m = json.loads((report / "metrics.json").read_text())
    expected = {
        "tracking": ["left_hand", "right_hand", "left_elbow", "right_elbow", "pelvis", "head"],
        "joint_limits": [
            "total_violations",
            "frames_with_violation",
            "max_violation_rad",
            "per_joint",
        ],
        "self_collision": [
            "pairs",
            "safety_distance_m",
            "total_violations",
            "min_distance_per_pair",
        ],
        "support": ["min_com_margin_m", "frames_com_outside"],
        "foot_slip": ["left_foot", "right_foot"],
        "joint_motion": ["velocity_peak_rad_s", "acceleration_peak_rad_s2", "jerk_peak_rad_s3"],
        "power": ["mean_abs_power_W", "source"],
        "solve_time": ["median_ms", "p95_ms", "max_ms"],
        "per_frame": [
            "joint_limit_violations",
            "self_collision_violations",
            "pair_distance_m",
            "com_margin_m",
        ],
        "before": ["joint_limits", "self_collision", "violations", "power"],
    }
    for section, keys in expected.items():
        assert section in m, section
        for key in keys:
            assert key in m[section], f"{section}.{key}"
    assert len(m["per_frame"]["joint_limit_violations"]) == 201
    assert len(m["self_collision"]["pairs"]) == len(m["per_frame"]["pair_distance_m"]) > 0
    # After: the joint-limit constraint holds; before (constraints off) the same targets violate.
    assert m["joint_limits"]["total_violations"] == 0
    assert m["before"]["joint_limits"]["total_violations"] > 0
    assert m["tracking"]["left_hand"]["rmse_m"] < 0.02
    assert m["solve_time"]["median_ms"] > 0
    assert m["power"]["mean_abs_power_W"] > 0


@pytest.mark.parametrize("name", sorted(FIGSIZE))
def test_figures_are_images_of_the_expected_size(report, name):
    path = report / f"{name}.png"
    assert path.is_file() and path.stat().st_size > 10_000  # a blank 1000x500 PNG is ~5 kB
    with Image.open(path) as im:
        assert im.format == "PNG"
        assert im.size == figure_pixels(name)
        # Not blank: the figure has drawn content (more than a handful of distinct colours).
        assert len(im.convert("RGB").getcolors(maxcolors=1 << 20)) > 20


def test_evaluate_metrics_only_and_bad_pairs(runs, tmp_path, capsys):
    after, _ = runs
    assert (
        main(["evaluate", str(after), "-o", str(tmp_path), "--no-figures", "--no-per-frame"]) == 0
    )
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert "per_frame" not in m and not list(tmp_path.glob("*.png"))
    assert (
        main(["evaluate", str(after), "-o", str(tmp_path), "--pairs", "left_wrist_yaw_link"]) == 1
    )
    assert "must be LINK_A:LINK_B" in capsys.readouterr().err


def test_evaluate_missing_run_is_one_clear_line(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nope.npz"), "-o", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "does not exist" in err and "Traceback" not in err
