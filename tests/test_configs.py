# SPDX-License-Identifier: Apache-2.0
"""Every shipped config builds and runs a few ticks, and the CLI describes it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.cli import main

ALL = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
# cloud_*.yaml describe the point-cloud pipeline (qpretarget.cloud), not a controller.
CONFIGS = [p for p in ALL if not p.name.startswith("cloud_")]
CLOUD_CONFIGS = [p for p in ALL if p.name.startswith("cloud_")]


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_config_runs(path: Path) -> None:
    ctrl = Controller.from_yaml(path)
    q0 = ctrl.reset()
    for _ in range(5):
        res = ctrl.step({})
    assert res.status == "ok", res.messages
    assert np.all(np.isfinite(res.q))
    # no targets given: the robot holds its pose (tasks start with zero error)
    assert np.linalg.norm(ctrl.robot.difference(q0, res.q)) < 1e-6


def test_info_command(capsys) -> None:
    assert main(["info", str(CONFIGS[0].parent / "g1_augmentation.yaml"), "--limits"]) == 0
    out = capsys.readouterr().out
    assert "nq=36 nv=35" in out and "left_knee_joint" in out and "tasks (8)" in out


def test_info_bad_target_exit_code(capsys) -> None:
    assert main(["info", "g2"]) == 1
    assert "neither a config file nor a bundled robot" in capsys.readouterr().err


@pytest.mark.parametrize("path", CLOUD_CONFIGS, ids=[p.stem for p in CLOUD_CONFIGS])
def test_cloud_config_loads(path: Path) -> None:
    from qpretarget.cloud import CloudConfig

    assert CloudConfig.from_yaml(path) is not None


def test_every_shipped_config_solver_is_a_core_dependency() -> None:
    """`pip install -e . && qpretarget demo` (the README's first command) needs no extra.

    The shipped configs' solvers must come with the base install: with daqp only in the
    `solvers` and `test` extras, a fresh environment's demo stopped with "QP solver 'daqp' is
    not installed" (CI installs the test extra and did not see it).
    """
    import re

    import tomllib
    import yaml

    root = Path(__file__).resolve().parents[1]
    deps = tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
    core = {re.split(r"[<>=!~ ;\[]", d, maxsplit=1)[0].strip().lower() for d in deps}
    used = {
        str((yaml.safe_load(p.read_text()).get("solver") or {}).get("name", "proxsuite")).lower()
        for p in ALL
    }
    assert used, "no shipped configs found"
    missing = sorted(used - core)
    assert not missing, f"shipped configs use solvers that are not core dependencies: {missing}"
