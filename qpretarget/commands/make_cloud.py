# SPDX-License-Identifier: Apache-2.0
"""``qpretarget make-cloud``: a depth point-cloud sequence of the human model following a clip."""

from __future__ import annotations

import argparse

from . import add_command, add_output

SUMMARY = "render depth point clouds of a human model following a mocap clip (sample input)"
DESCRIPTION = (
    "Pose example-robot-data's human model by a mocap clip (any format qpretarget "
    "reads), render it with a simulated depth camera (z-buffer, range noise, outliers) "
    "and write the point-cloud sequence that retarget-cloud reads."
)

HELP = """examples:
  qpretarget make-cloud ../shared/data/mocap/cmu_14_37_drink_soda.bvh -o clouds.npz
      3 s of the clip at 30 Hz, rendered like a Kinect V2 2.8 m in front of the person
  qpretarget retarget-cloud configs/cloud_g1.yaml clouds.npz -o run.npz
      then fit the G1 to it
  qpretarget make-cloud clip.bvh -o clouds.npz --start 2 --duration 5 --noise 0.01
      5 s from 2 s into the clip, 10 mm range noise
  qpretarget make-cloud clip.bvh -o clouds.npz --lead-in-speed 2
      move into the clip at a person's pace (hands at most 2 m/s)
  qpretarget make-cloud ../shared/data/mocap/opensim_walking2.c3d -o clouds.npz --start 1.7
      marker data: from when its trunk markers are seen

The sequence starts with the calibration posture (stand facing the sensor, arms slightly
away from the body), as retarget-cloud's calibration expects, and moves into the clip's first
pose in 4 frames (the docs' figures), or at a person's pace with --lead-in-speed (a
minimum-jerk move whose fastest key-point peaks at that speed; 2 m/s takes 0.4-2.3 s on the
shared clips where the 4 frames move a hand at 2-7 m/s).
The camera stands --distance in front of where the person starts, facing them; a clip that
walks, jumps or kicks its way towards it (or out of its field of view) has it moved back along
its line of sight until the person stays at least --min-distance away and inside the image.
The person stands on the floor (z = 0) throughout: each frame's height is set by the model's
lowest point within 1 s around it, not by the clip's root height (the performer's legs are not
the model's), so that a jump keeps its flight and a crouch does not float.
Marker data (C3D) has no joint orientations: the trunk's come from the hips (or shoulders)
and the waist-to-neck line, and limbs without markers stay as the model's neutral pose has
them; a clip whose trunk markers are not seen at --start says from when they are.
The human model's configurations are stored with the clouds (meta/human_q) as the truth.
Layout of the file and how the rendering works: docs/point_clouds.md
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``make-cloud`` subcommand."""
    p = add_command(sub, "make-cloud", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("clip", help="mocap clip (.bvh, .amc, .c3d, key-point .npz/.csv)")
    add_output(p, "cloud sequence to write (.npz)")
    p.add_argument("--rate", type=float, default=30.0, help="frames per second (default 30)")
    p.add_argument("--start", type=float, default=0.0, help="start in the clip [s] (default 0)")
    p.add_argument(
        "--duration", type=float, default=3.0, help="length [s] (default 3; 0: to the end)"
    )
    p.add_argument("--distance", type=float, default=2.8, help="camera distance [m] (2.8)")
    p.add_argument(
        "--min-distance",
        type=float,
        default=2.0,
        help="nearest a travelling person comes to the camera [m] (2.0): the camera is moved "
        "back along its line of sight when the clip walks towards it or out of view",
    )
    p.add_argument("--noise", type=float, default=0.005, help="range noise std [m] (0.005)")
    p.add_argument("--outliers", type=float, default=0.05, help="outlier fraction (0.05)")
    p.add_argument(
        "--downscale", type=int, default=1, help="Kinect V2 image divided by this (1: 512x424)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of noise and outliers")
    p.add_argument(
        "--lead-in-speed",
        type=float,
        default=None,
        help="move into the clip with no key-point faster than this [m/s] (default: 4 frames)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the clip and write the sequence; return the exit code."""
    from pathlib import Path

    import numpy as np

    from ..cloud.render import clip_cloud_sequence
    from ..errors import ConfigError
    from ..fileio import check_output_file

    out = check_output_file(args.output, ".npz")
    if not Path(args.clip).is_file():
        raise ConfigError(f"clip {args.clip!r} does not exist; give a .bvh, .amc or .c3d file.")
    positive = {
        "--rate": args.rate,
        "--distance": args.distance,
        "--min-distance": args.min_distance,
    }
    if args.lead_in_speed is not None:
        positive["--lead-in-speed"] = args.lead_in_speed
    for flag, value in positive.items():
        if not value > 0:
            raise ConfigError(f"{flag} must be > 0, got {value}.")
    if args.noise < 0 or not 0 <= args.outliers < 1 or args.downscale < 1:
        raise ConfigError("need --noise >= 0, 0 <= --outliers < 1 and --downscale >= 1.")
    if args.start < 0 or args.duration < 0:
        raise ConfigError(
            f"need --start >= 0 and --duration >= 0 (0: to the end), got {args.start} and "
            f"{args.duration}."
        )
    syn, _ = clip_cloud_sequence(
        args.clip,
        rate=args.rate,
        start=args.start,
        duration=args.duration if args.duration > 0 else None,
        distance=args.distance,
        min_distance=args.min_distance,
        noise=args.noise,
        outlier_fraction=args.outliers,
        seed=args.seed,
        downscale=args.downscale,
        lead_in_speed=args.lead_in_speed,
        progress=not args.no_progress,
    )
    seq = syn.with_truth()
    seq.save(out)
    counts = [len(f.points) for f in seq.frames]
    print(
        f"wrote {out}: {len(seq)} frames at {args.rate:g} Hz (the first {syn.lead_in_frames}: "
        f"calibration posture moving into the clip), {int(np.median(counts))} points per "
        "frame (median)"
    )
    if syn.camera_shift > 0:
        print(
            f"the clip travels towards the camera or out of its view: camera moved back "
            f"{syn.camera_shift:.2f} m (to {args.distance + syn.camera_shift:.2f} m from the "
            f"person's start), the person at least {args.min_distance:g} m from it"
        )
    if syn.limb_error_deg is not None and len(syn.limb_error_deg):
        worst = float(np.max(syn.limb_error_deg))
        print(
            f"the rendered person follows the clip's upper arms, forearms, thighs and shanks "
            f"within {worst:.1f} deg (worst frame; meta/limb_error_deg per frame)"
        )
    return 0
