# SPDX-License-Identifier: Apache-2.0
"""Fixtures of the motion tests: the real mocap clips of ../shared/data/mocap, loaded once."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import pytest

from qpretarget.motion import HumanMotion, load_motion

MOCAP = Path(__file__).resolve().parents[2].parent / "shared/data/mocap"


@functools.cache
def _load(name: str) -> HumanMotion:
    return load_motion(MOCAP / name)


@pytest.fixture(scope="session")
def mocap() -> Path:
    """The shared mocap folder; fails loudly if absent, like ``tests/conftest.py``."""
    if not MOCAP.is_dir():
        raise FileNotFoundError(
            f"the mocap clips are expected beside the checkout at {MOCAP} (../shared/data/mocap)"
        )
    return MOCAP


@pytest.fixture(scope="session")
def load_clip(mocap: Path) -> Callable[[str], HumanMotion]:
    """``load_clip(file_name)``: the clip read with default options, cached for the session."""
    return _load
