# SPDX-License-Identifier: Apache-2.0
"""``qpretarget retarget-cloud``: fit the robot-shaped HUMROB template to depth point clouds."""

from __future__ import annotations

import argparse
from pathlib import Path

from . import add_command, add_output

SUMMARY = "retarget from depth point clouds (Wang 2017 HUMROB, EM with a QP M-step)"
DESCRIPTION = (
    "Fit a template made of the robot's link meshes (scaled to the person from the first "
    "frame) to each point cloud by EM; the M-step is a QP with joint limits and the "
    "robot's balance as constraints. Writes the run format of the other retargeting "
    "commands."
)

HELP = """examples:
  qpretarget retarget-cloud configs/cloud_g1.yaml clouds.npz -o run.npz
      fit every frame of a point-cloud sequence, write the run (evaluate/view read it)
  qpretarget retarget-cloud configs/cloud_g1.yaml frames/ -o run.npz --rate 30
      a directory of .ply / .npy clouds or 16-bit .png depth images (sorted by name)
  qpretarget retarget-cloud configs/cloud_g1.yaml depth.npz -o run.npz --frames 0:90
      the first 90 frames of a depth-image sequence (intrinsics in the file or the config)
  qpretarget evaluate run.npz -o report/
      joint limits, CoM margin, foot slip of the result

input layouts and the config keys: docs/point_clouds.md
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``retarget-cloud`` subcommand."""
    p = add_command(sub, "retarget-cloud", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("config", help="cloud retargeting config (YAML), e.g. configs/cloud_g1.yaml")
    p.add_argument("input", help=".npz / .npy / .ply file, or a directory of frames")
    add_output(p, "run file to write (.npz)")
    p.add_argument("--rate", type=float, help="frame rate [Hz] when the input has no times")
    p.add_argument("--frames", help="frame range START:STOP[:STEP] (Python slice)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _slice(spec: str | None) -> slice:
    from ..errors import ConfigError

    if not spec:
        return slice(None)
    try:
        parts = [int(x) if x else None for x in spec.split(":")]
        if not 1 <= len(parts) <= 3:
            raise ValueError
    except ValueError:
        raise ConfigError(f"--frames must look like START:STOP[:STEP], got {spec!r}.") from None
    if len(parts) == 1:  # a single frame
        start = parts[0] or 0
        return slice(start, start + 1)
    return slice(*parts)


def run(args: argparse.Namespace) -> int:
    """Read the config and the clouds, fit every frame, write the run; return the exit code."""
    import numpy as np

    from ..cloud.config import CloudConfig
    from ..cloud.em import CloudRetargeter
    from ..cloud.io import CloudSequence, read_cloud_sequence

    cfg = CloudConfig.from_yaml(args.config)
    inp = cfg.input
    seq = read_cloud_sequence(
        args.input,
        rate=args.rate if args.rate is not None else inp.rate,
        intrinsics=inp.intrinsics,
        camera_pose=None if inp.camera_pose is None else np.asarray(inp.camera_pose, float),
        depth_scale=inp.depth_scale,
    )
    chosen = _slice(args.frames)
    frames = seq.frames[chosen]
    if not frames:
        from ..errors import ConfigError

        raise ConfigError(f"no frame selected (the input has {len(seq)} frames).")
    meta = dict(seq.meta)
    human_q = meta.get("human_q")  # make-cloud's truth, per frame: the same frames
    if human_q is not None and np.ndim(human_q) == 2 and len(human_q) == len(seq):
        meta["human_q"] = np.asarray(human_q)[chosen]
    else:
        meta.pop("human_q", None)  # not one row per frame: nothing to score against
    seq = CloudSequence(frames, seq.sensor_position, seq.source, meta)
    fitter = CloudRetargeter(cfg)
    traj, results = fitter.run(seq, progress=not args.no_progress)
    traj.meta["input"] = str(Path(args.input))
    out = traj.save(args.output)
    times = np.array([r.time for r in results])
    status = np.array([r.status for r in results])
    print(
        f"wrote {out}: {len(results)} frames, scales "
        + ", ".join(f"{k}={v:.2f}" for k, v in traj.meta["scales"].items())
        + f"; {np.median(times) * 1000:.0f} ms/frame median; "
        + f"{int(np.sum(status != 'ok'))} frames not ok"
    )
    if fitter.command.constraint is not None:
        moved = sum(r.command_steps > 0 for r in results)
        clear = min(r.clearance for r in results)
        print(
            f"self-collision: {moved} frames moved off the fit to keep the robot's links apart; "
            + (
                f"smallest clearance {1000 * clear:+.1f} mm over the safety distance"
                if np.isfinite(clear)
                else "no pair came within the influence distance"
            )
        )
    return 0
