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


def test_the_human_is_shown_at_the_robot_sample_s_time() -> None:
    """The human tracks are at the capture rate, the run at the control rate.

    Until stop 37 the human sample of the robot's index was drawn: a 30 Hz clip run at 100 Hz
    played the person 3.3 times too fast (its last frame from a third of the run on), a 120 Hz
    one at 0.83 of its speed (its last sixth never shown).
    """
    import numpy as np

    from qpretarget.viz.skeleton import human_samples

    t_human = np.arange(0, 3.0, 1 / 30)  # a 30 Hz capture
    t_robot = np.arange(0, 3.0, 0.01)  # run at 100 Hz
    k = human_samples({"t": t_human, "waist": np.zeros((len(t_human), 3))}, t_robot)
    # Nearest in time: within half a capture period of each robot sample inside the capture
    # (1e-12 s: round-off of the clocks), the last capture frame after it.
    inside = t_robot <= t_human[-1]
    assert np.max(np.abs(t_human[k] - t_robot)[inside]) <= 0.5 / 30 + 1e-12
    assert np.all(k[~inside] == len(t_human) - 1) and k[150] == 45  # 1.5 s -> frame 45
    # A run file without the human clock keeps the former index mapping, clamped.
    assert human_samples({"waist": np.zeros((3, 3))}, np.arange(5) * 0.01).tolist() == [
        0, 1, 2, 2, 2
    ]  # fmt: skip
