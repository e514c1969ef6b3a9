# SPDX-License-Identifier: Apache-2.0
"""Shared fixtures: the repository's configs and the ../shared data folder beside the checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

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
