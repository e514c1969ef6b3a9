"""Shared fixtures of the physics tests: one short retargeted G1 run (real clip, real solver)."""

from __future__ import annotations

from pathlib import Path

import pytest

#: Static-balance config: configs/g1_whole_body_static.yaml when present, else g1_whole_body.yaml;
#: the start ramp is lengthened to 2 s because the default 0.5 s ramp moves the CoM 6 cm forward
#: and stops it within 0.25 s, which puts the ZMP past the toes (docs/physics.md).
RAMP_TIME = 2.0


def static_config(configs_dir: Path, tmp: Path) -> Path:
    import yaml

    from qpretarget.yamlio import load_yaml

    base = configs_dir / "g1_whole_body_static.yaml"
    if not base.is_file():
        base = configs_dir / "g1_whole_body.yaml"
    cfg = load_yaml(base.read_text(encoding="utf-8"))
    calib = dict(cfg["retarget"].get("calibration") or {})
    calib["ramp_time"] = RAMP_TIME
    cfg["retarget"]["calibration"] = calib
    path = tmp / f"{base.stem}_ramp2.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return path


@pytest.fixture(scope="session")
def static_cfg(tmp_path_factory, configs_dir) -> Path:
    """The static-balance G1 config with a 2 s start ramp (a file in a temporary folder)."""
    return static_config(configs_dir, tmp_path_factory.mktemp("physics_cfg"))


@pytest.fixture(scope="session")
def drink_run(tmp_path_factory, static_cfg, mocap_dir) -> Path:
    """CMU 14_37 (drink soda), first 3 s, retargeted to the G1 with the static-balance config."""
    from qpretarget.cli import main

    tmp = tmp_path_factory.mktemp("physics")
    cfg = static_cfg
    out = tmp / "drink.npz"
    clip = mocap_dir / "cmu_14_37_drink_soda.bvh"
    assert main(["retarget", str(cfg), str(clip), "-o", str(out), "--end", "3.0", "--quiet"]) == 0
    return out


@pytest.fixture(scope="session")
def g1_physics():
    from qpretarget.physics.model import build_physics_model
    from qpretarget.robot import RobotModel

    robot = RobotModel.from_name("g1")
    return robot, build_physics_model(robot)
