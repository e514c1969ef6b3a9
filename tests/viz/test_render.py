# SPDX-License-Identifier: Apache-2.0
"""Offscreen rendering writes a GIF with the expected frame count and size."""

from __future__ import annotations

import pytest

from qpretarget.cli import main
from qpretarget.errors import QPRetargetError
from qpretarget.trajectory import RobotTrajectory
from qpretarget.viz.render import render_run


@pytest.fixture(scope="module")
def run_2s(make_run):
    return make_run(2.0)


def test_render_gif_frame_count_and_size(run_2s, tmp_path) -> None:
    from PIL import Image

    out = tmp_path / "clip.gif"
    assert main(["render", str(run_2s), "-o", str(out), "--fps", "10", "--size", "320x240"]) == 0
    im = Image.open(out)
    # 2 s at 10 fps: samples at 0, 0.1, ..., 2.0 s -> 21 frames
    assert im.n_frames == 21
    assert im.size == (320, 240)


def test_render_rejects_bad_extension(run_2s, tmp_path) -> None:
    with pytest.raises(QPRetargetError, match=r"use a \.gif or \.mp4 file name"):
        render_run(RobotTrajectory.load(run_2s), tmp_path / "clip.avi")
