# SPDX-License-Identifier: Apache-2.0
"""``qpretarget compare-solvers``: a row per installed solver, missing ones marked, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from qpretarget.analysis.solver_comparison import (
    ComparisonError,
    available_solver_names,
    load_targets,
    record_run,
    scripted_targets,
    targets_from_run,
)
from qpretarget.cli import main
from qpretarget.control.controller import Controller
from qpretarget.solvers import installed_qpsolvers
from qpretarget.trajectory import RobotTrajectory


@pytest.fixture(scope="module")
def clip(configs_dir, tmp_path_factory) -> Path:
    """A 2-second run of G1 on scripted targets, saved as a run file."""
    ctrl = Controller.from_yaml(configs_dir / "g1_augmentation.yaml")
    return record_run(ctrl, scripted_targets(ctrl, 2.0)).save(
        tmp_path_factory.mktemp("clip") / "clip.npz"
    )


@pytest.fixture(scope="module")
def comparison(configs_dir, mocap_dir, tmp_path_factory) -> tuple[dict, str]:
    """Every solver on 2 s of a real CMU clip, retargeted by the config's retarget: section."""
    out = tmp_path_factory.mktemp("cmp")
    names = [*available_solver_names(), "gurobi", "nosuchsolver"]
    argv = [
        "compare-solvers",
        str(configs_dir / "g1_augmentation.yaml"),
        str(mocap_dir / "cmu_14_07_reach_up_tiptoe.bvh"),
        "--seconds",
        "2",
        "--solvers",
        ",".join(names),
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    for suffix in ("csv", "json", "md"):
        assert (out / f"comparison.{suffix}").stat().st_size > 0
    return json.loads((out / "comparison.json").read_text()), (out / "comparison.md").read_text()


def test_a_row_per_installed_solver(comparison):
    data, _ = comparison
    rows = {r["solver"]: r for r in data["rows"]}
    assert "proxsuite" in rows and set(installed_qpsolvers()) <= set(rows)
    for name in available_solver_names():
        r = rows[name]
        assert r["status"] == "ok", (name, r)
        assert r["ticks"] == 200 and r["failures"] == 0 and r["held_ticks"] == 0
        assert r["median_solve_ms"] > 0 and r["p95_solve_ms"] >= r["median_solve_ms"]
        # Every backend is asked for 1e-7 or tighter; rows are exact up to that.
        assert r["max_violation"] < 1e-6
        # Same motion, same QPs: solvers differ only by their tolerances, which closed-loop
        # integration over 200 ticks keeps well under 1e-4 rad (measured: 2e-7 rad).
        assert r["max_joint_dev_rad"] < 1e-4
        assert r["rmse_diff_mm"] < 1e-3
    assert data["reference"] == "proxsuite"
    assert rows["proxsuite"]["median_iterations"] is not None  # ProxSuite reports iterations


def test_missing_solvers_are_marked_not_crashed_on(comparison):
    data, md = comparison
    rows = {r["solver"]: r for r in data["rows"]}
    assert rows["gurobi"]["status"] == "not installed"
    assert "pip install qpsolvers[gurobi]" in rows["gurobi"]["note"]
    assert rows["nosuchsolver"]["status"] == "unknown"
    assert rows["gurobi"]["ticks"] is None
    assert "| gurobi | not installed |" in md


def test_scripted_motion_and_table_on_stdout(configs_dir, capsys):
    argv = [
        "compare-solvers",
        str(configs_dir / "g1_augmentation.yaml"),
        "scripted:0.3",
        "--solvers",
        "proxsuite,quadprog",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "median solve [ms]" in out
    rows = {line.split()[0]: line.split()[1] for line in out.splitlines()[2:4]}
    assert rows == {"proxsuite": "ok", "quadprog": "ok"}, out
    assert "Polishing" not in out


@pytest.mark.parametrize(
    ("motion", "match"),
    [
        ("scripted:abc", "scripted:SECONDS"),
        ("scripted:-1", "positive duration"),
        ("nope.npz", "is not a file"),
    ],
)
def test_bad_motion_arguments(motion, match):
    with pytest.raises(ComparisonError, match=match):
        load_targets(motion)


def test_run_motion_replays_its_targets(configs_dir, clip):
    ctrl = Controller.from_yaml(configs_dir / "g1_augmentation.yaml")
    traj = RobotTrajectory.load(clip)
    targets = targets_from_run(traj, ctrl)
    assert len(targets) == 200  # samples 1..200 each end a tick; sample 0 is the start
    assert set(targets[0]) == {
        "pelvis",
        "left_hand",
        "right_hand",
        "left_elbow",
        "right_elbow",
        "head",
    }
    np.testing.assert_array_equal(targets[9]["left_hand"], traj.targets["left_hand"][10])
    # Replaying them through the same controller reproduces the run (deterministic solver).
    replay = load_targets(clip, seconds=0.5).run(ctrl)
    assert len(replay.t) == 51
    np.testing.assert_allclose(replay.q, traj.q[:51], atol=1e-12)
