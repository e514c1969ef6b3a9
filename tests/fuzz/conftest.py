# SPDX-License-Identifier: Apache-2.0
"""The fuzz suite (docs/reliability.md): seeded, fast, every family of bad input.

Every case must end in a documented error (a :class:`~qpretarget.errors.QPRetargetError`
subclass from the API, one line and exit 1/2 from the CLI) or in a held-and-reported tick —
never an uncaught exception from deep inside numpy/yaml, a NaN in the output, a hang, or a
half-written output file under its final name.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from qpretarget.errors import QPRetargetError

REPO = Path(__file__).resolve().parents[2]
MOCAP = REPO.parent / "shared" / "data" / "mocap"
SEED = 20261124


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(SEED)


def outcome(fn: Callable[[], Any]) -> tuple[str, Any]:
    """``("ok", value)`` or ``("error", exc)`` for a documented error; fails on anything else."""
    try:
        return "ok", fn()
    except QPRetargetError as exc:
        msg = str(exc)
        assert msg and "Traceback" not in msg, repr(exc)
        return "error", exc
    except Exception:  # noqa: BLE001  (the point of the suite)
        pytest.fail("undocumented exception:\n" + traceback.format_exc())


def cut_frames(text: str, n: int) -> str:
    """A BVH text with only its first ``n`` frames (header updated)."""
    lines = text.splitlines()
    i = next(k for k, s in enumerate(lines) if s.strip().startswith("Frames:"))
    lines[i] = f"Frames: {n}"
    return "\n".join(lines[: i + 2 + n]) + "\n"
