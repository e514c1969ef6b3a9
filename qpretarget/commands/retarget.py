# SPDX-License-Identifier: Apache-2.0
"""``qpretarget retarget``: a mocap file through a controller config to a robot run (.npz)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from . import (
    add_clip_range,
    add_command,
    add_config,
    add_control_rate,
    add_motion,
    add_output,
    add_quiet,
)

SUMMARY = "retarget a mocap file (BVH, ASF/AMC, C3D) to a robot trajectory (.npz)"
DESCRIPTION = (
    "Filter, up-sample, scale and track a human motion with a controller config; write "
    "the robot trajectory at the control rate and print the tracking summary."
)

HELP = """examples:
  qpretarget retarget configs/g1_whole_body.yaml walk.bvh -o walk_g1.npz
  qpretarget retarget configs/g1_whole_body.yaml ../shared/data/mocap/cmu_16_33_walk_stop.bvh \\
      -o walk_stop.npz --start 0.5 --end 2.3
  qpretarget retarget configs/g1_augmentation.yaml trial.amc --asf subject.asf -o trial.npz
  qpretarget retarget configs/g1_whole_body.yaml gait.c3d --keypoint-map opensim_walking -o gait.npz
  qpretarget retarget CONFIG MOTION -o OUT.npz --causal --rate 200   filter as online, 200 Hz

The config's `retarget:` section maps key-points to tasks (docs/retargeting.md). The output is
the run file of docs/formats.md (qpretarget evaluate / view read it).
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``retarget`` subcommand."""
    p = add_command(sub, "retarget", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_config(p)
    add_motion(p)
    add_output(p, "run file to write (.npz)")
    add_clip_range(p)
    add_control_rate(p)
    p.add_argument(
        "--causal", action="store_true", help="causal filtering (as online) instead of zero phase"
    )
    p.add_argument("--keypoint-map", default=None, help="key-point map (bundled name or YAML)")
    p.add_argument("--asf", default=None, help="skeleton of an .amc file (default: found beside)")
    p.add_argument(
        "--length-scale", type=float, default=None, help="metres per file unit (default: auto)"
    )
    p.add_argument("--up-axis", choices=("y", "z"), default=None, help="up axis of the file")
    p.add_argument(
        "--keep-leading-cut",
        action="store_true",
        help="keep the frames before a cut at the clip's start (a reference T-pose in frame 0, "
        "a dropout), which are dropped by default with a note",
    )
    add_quiet(p)
    p.set_defaults(func=run)


def _load(args: argparse.Namespace):  # noqa: ANN202
    from ..motion import MotionError, load_motion

    path = Path(args.motion)
    options = {}
    if args.length_scale is not None:
        options["length_scale"] = args.length_scale
    if args.up_axis is not None:
        options["up_axis"] = args.up_axis
    if args.asf is not None:
        options["asf"] = args.asf
    try:
        return load_motion(path, keep_leading_cut=args.keep_leading_cut, **options)
    except (FileNotFoundError, ValueError, TypeError) as exc:
        if isinstance(exc, MotionError):
            raise
        raise MotionError(str(exc)) from None


def run(args: argparse.Namespace) -> int:
    """Retarget, save, print the summary; return the exit code."""
    from ..control.controller import Controller
    from ..errors import ConfigError
    from ..fileio import atomic_path, check_output_file
    from ..retarget.retargeter import Retargeter
    from ..retarget.summary import format_summary, summarize_run

    if args.rate is not None and not args.rate > 1:
        raise ConfigError(f"--rate must be above 1 Hz, got {args.rate}.")
    output = check_output_file(args.output, ".npz")
    controller = Controller.from_yaml(args.config)
    retargeter = Retargeter(controller, keypoint_map=args.keypoint_map, rate=args.rate)
    motion = _load(args)
    t0 = time.perf_counter()
    traj = retargeter.retarget(
        motion,
        start=args.start,
        end=args.end,
        causal=True if args.causal else None,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    wall = time.perf_counter() - t0
    with atomic_path(output, suffix=".npz") as tmp:
        traj.save(tmp)
    out = output
    summary = summarize_run(traj, controller, wall_time=wall)
    title = (
        f"{Path(args.motion).name} -> {controller.robot.name} "
        f"({traj.meta['keypoint_map']} key-points, {traj.meta['scaling']} scaling, "
        f"{traj.meta['capture_rate']:g} Hz -> {traj.meta['control_rate']:g} Hz)"
    )
    print(format_summary(summary, title=title))
    for note in traj.meta["motion_notes"]:
        print(f"note: {note}")
    for note in traj.meta.get("skipped_tasks", []):
        print(f"note: task {note!r} has no key-point in this motion; it kept its reference target")
    for message in traj.meta.get("messages", []):
        if message.startswith(("support phases:", "key-points:")):
            print(f"note: {message}")
    print(f"wrote {out}")
    return 0
