# SPDX-License-Identifier: Apache-2.0
"""Short real clips for the dataset tests: shared BVH files cut to their first seconds."""

from __future__ import annotations

from pathlib import Path

import pytest

MOCAP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "mocap"


def cut_bvh(src: Path, dst: Path, seconds: float) -> Path:
    """Write ``src`` with only its first ``seconds`` of frames (header updated)."""
    lines = src.read_text().splitlines()
    i = next(k for k, s in enumerate(lines) if s.strip().startswith("Frames:"))
    dt = float(lines[i + 1].split(":")[1])
    n = min(int(seconds / dt), len(lines) - i - 2)
    lines[i] = f"Frames: {n}"
    dst.write_text("\n".join(lines[: i + 2 + n]) + "\n")
    return dst


@pytest.fixture(scope="session")
def clip_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three real clips, 2 s each, in a folder with a sub-folder (a small dataset)."""
    root = tmp_path_factory.mktemp("clips")
    (root / "walks").mkdir()
    cut_bvh(MOCAP / "cmu_29_03_teapot_arm_gestures.bvh", root / "teapot.bvh", 2.0)
    cut_bvh(MOCAP / "cmu_16_33_walk_stop.bvh", root / "walks" / "walk_stop.bvh", 2.0)
    cut_bvh(MOCAP / "cmu_17_10_boxing.bvh", root / "boxing.bvh", 2.0)
    return root
