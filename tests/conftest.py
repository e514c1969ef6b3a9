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
