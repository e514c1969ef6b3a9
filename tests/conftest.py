# SPDX-License-Identifier: Apache-2.0
"""Shared fixtures: the repository's configs and the ../shared data folder beside the checkout."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

# A suite started in the background of a non-interactive shell (``pytest &``) inherits SIGINT
# ignored, and so would the commands some tests stop with Ctrl-C (they then ran to their end
# and exited 0): give the suite Python's own handler, which its children reset to the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

REPO = Path(__file__).resolve().parents[1]
SHARED = (REPO.parent / "shared").resolve()
CONFIGS = REPO / "configs"


@pytest.fixture(scope="session")
def repo_dir() -> Path:
    return REPO


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not SHARED.is_dir():
        raise FileNotFoundError(
            f"the shared data folder is expected beside the checkout at {SHARED} "
            "(../shared with data/mocap and bench)."
        )
    return SHARED


@pytest.fixture(scope="session")
def mocap_dir(shared_dir: Path) -> Path:
    return shared_dir / "data" / "mocap"


@pytest.fixture(scope="session")
def configs_dir() -> Path:
    return CONFIGS


@pytest.fixture
def waist_at_hips_map() -> dict:
    """The bundled CMU map with its waist key-point at the hip joints' midpoint (``lfemur``,
    ``rfemur``), where a Biovision or DeepMimic skeleton has its root: the same real clip with
    that one convention changed (docs/motion.md, *The waist key-point*)."""
    from qpretarget.motion.keypoints import load_keypoint_map

    cmu = load_keypoint_map("cmu")
    keypoints: dict = {k: list(s.points) if len(s.points) > 1 else s.points[0]
                       for k, s in cmu.keypoints.items()}  # fmt: skip
    keypoints["waist"] = ["lfemur", "rfemur"]
    return {"name": "cmu_hips", "keypoints": keypoints, "orientations": dict(cmu.orientations)}


def _push_all(retargeter, motion) -> list:
    """``Retargeter.push`` every frame of ``motion`` at its capture rate, then ``finish``."""
    retargeter.start(motion)
    commands = []
    for k in range(len(motion)):
        commands += retargeter.push(
            motion.positions[k], motion.t[k], orientations=motion.orientations[k]
        )
    return commands + retargeter.finish()


@pytest.fixture
def push_all():
    """``push_all(retargeter, motion)``: the commands of the motion pushed frame by frame."""
    return _push_all
