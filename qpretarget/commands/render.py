# SPDX-License-Identifier: Apache-2.0
"""``qpretarget render``: write a run as an animated GIF (or MP4), offscreen."""

from __future__ import annotations

import argparse

from . import add_command, add_output

SUMMARY = "render a run to an animated GIF/MP4 (robot beside the human, targets, CoM)"
DESCRIPTION = "Offscreen rendering (matplotlib, no GPU, no display)."

HELP = """examples:
  qpretarget render walk_g1.npz -o walk_g1.gif
  qpretarget render walk_g1.npz -o clip.gif --fps 15 --start 2 --end 6 --size 480x360
  qpretarget render walk_g1.npz -o clip.mp4            (needs imageio-ffmpeg)
"""


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None
    if w < 64 or h < 64:
        raise argparse.ArgumentTypeError("size must be at least 64x64")
    return w, h


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``render`` subcommand."""
    p = add_command(sub, "render", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("run", help="run .npz")
    add_output(p, "output .gif or .mp4")
    p.add_argument("--fps", type=float, default=20.0, help="frames per second (default 20)")
    p.add_argument("--size", type=_size, default=(640, 480), help="WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--start", type=float, default=None, help="start time [s]")
    p.add_argument("--end", type=float, default=None, help="end time [s]")
    p.add_argument("--no-human", action="store_true", help="robot only")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render and report."""
    from ..trajectory import RobotTrajectory
    from ..viz.render import render_run

    traj = RobotTrajectory.load(args.run)
    info = render_run(
        traj, args.output, fps=args.fps, width=args.size[0], height=args.size[1],
        start=args.start, end=args.end, show_human=not args.no_human, progress=True,
    )  # fmt: skip
    print(
        f"wrote {info.path}: {info.frames} frames {info.width}x{info.height} at {info.fps:g} fps "
        f"(rendered {info.render_fps:.1f} frames/s)"
    )
    return 0
