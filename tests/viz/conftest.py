# SPDX-License-Identifier: Apache-2.0
"""A short recorded G1 run shared by the viewer and renderer tests."""

from __future__ import annotations

import pytest

from qpretarget.analysis.solver_comparison import record_run, scripted_targets
from qpretarget.control.controller import Controller


@pytest.fixture(scope="package")
def make_run(configs_dir, tmp_path_factory):
    """``make_run(seconds)`` -> path of a saved run of g1_augmentation on scripted targets."""

    def make(seconds: float):
        ctrl = Controller.from_yaml(configs_dir / "g1_augmentation.yaml")
        traj = record_run(ctrl, list(scripted_targets(ctrl, seconds)))
        path = tmp_path_factory.mktemp("run") / "run.npz"
        traj.save(path)
        return path

    return make
