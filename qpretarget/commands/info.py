# SPDX-License-Identifier: Apache-2.0
"""``qpretarget info``: robot, DoF, frames, limits, tasks and constraints of a config or robot."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from . import add_command

SUMMARY = "robot, DoF, frames, limits, tasks and constraints of a config"
DESCRIPTION = "Describe a controller config (YAML) or a bundled robot."

HELP = """examples:
  qpretarget info configs/g1_augmentation.yaml          summary of a controller config
  qpretarget info configs/g1_augmentation.yaml --limits  joint position and velocity limits
  qpretarget info g1 --frames                           every frame of a bundled robot
  qpretarget info --robots                              the bundled robots
  qpretarget info configs/g1_whole_body.yaml --pairs    every collision pair, and why the
                                                        others are left out
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` subcommand."""
    p = add_command(sub, "info", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("target", nargs="?", help="config YAML, or a bundled robot name")
    p.add_argument("--frames", action="store_true", help="list every frame")
    p.add_argument("--limits", action="store_true", help="list joint limits")
    p.add_argument("--robots", action="store_true", help="list the bundled robots")
    p.add_argument(
        "--pairs",
        action="store_true",
        help="self-collision: list every kept pair and every left-out pair with its reason",
    )
    p.set_defaults(func=run)


def describe_robot(robot, *, frames: bool, limits: bool) -> list[str]:  # noqa: ANN001
    """Lines describing a :class:`RobotModel`."""
    lines = [
        f"robot        {robot.name}  ({robot.urdf_path.name})",
        f"dimensions   nq={robot.nq} nv={robot.nv}  free-flyer={robot.free_flyer}  "
        f"joints={len(robot.joint_names)}",
        f"SRDF         {robot.srdf_path.name if robot.srdf_path else '-'}",
        "feet         "
        + ", ".join(f"{k}: {f.frame} {list(f.rectangle)}" for k, f in robot.feet.items()),
        "key-points   " + ", ".join(f"{k}->{v}" for k, v in robot.keyframes.items()),
    ]
    if limits:
        lines.append("joint limits (position [rad], velocity [rad/s], reference posture):")
        for j, name in enumerate(robot.joint_names):
            qi, vi = robot.joint_q_index[j], robot.joint_v_index[j]
            lines.append(
                f"  {name:32s} [{robot.q_min[qi]:+8.4f}, {robot.q_max[qi]:+8.4f}]  "
                f"{robot.v_max[vi]:8.3f}   ref {robot.q_reference[qi]:+.4f}"
            )
    if frames:
        lines.append(f"frames ({len(robot.model.frames)}):")
        lines.extend(f"  {f.name}" for f in robot.model.frames)
    return lines


def run(args: argparse.Namespace) -> int:
    """Print the description; return the exit code."""
    from ..robots import ROBOTS

    if args.robots or args.target is None:
        print("bundled robots:")
        for name, d in sorted(ROBOTS.items()):
            print(f"  {name:16s} {d.description}")
        if args.target is None and not args.robots:
            print("\nrun `qpretarget info CONFIG.yaml` or `qpretarget info ROBOT` for details.")
        return 0
    if args.target in ROBOTS:
        from ..robot import load_robot

        robot = load_robot(args.target)
        print("\n".join(describe_robot(robot, frames=args.frames, limits=args.limits)))
        return 0
    from ..control.controller import Controller
    from ..errors import ConfigError

    path = Path(args.target)
    if not path.exists():
        raise ConfigError(
            f"{args.target!r} is neither a config file nor a bundled robot "
            f"({', '.join(sorted(ROBOTS))})."
        )
    ctrl = Controller.from_yaml(path)
    lines = describe_robot(ctrl.robot, frames=args.frames, limits=args.limits)
    lines.append(f"control      dt={ctrl.dt} s  level={ctrl.level}  strategy={ctrl.strategy!r}")
    lines.append(f"regularization {ctrl.regularization!r}")
    lines.append(f"solver       {ctrl.solver_spec}")
    lines.append(f"tasks ({len(ctrl.tasks)}):")
    lines.extend(f"  {t!r}" for t in ctrl.tasks.values())
    lines.append(f"constraints ({len(ctrl.constraints)}, {ctrl.n_rows} QP rows):")
    for c in ctrl.constraints:
        lines.append(f"  {c!r}")
        describe = getattr(c, "describe", None)
        if describe is not None:
            full = args.pairs and c.type_name == "self_collision"
            lines.extend(f"    {x}" for x in (describe(full=True) if full else describe()))
    q = ctrl.q
    inside = np.all((q >= ctrl.robot.q_min - 1e-12) & (q <= ctrl.robot.q_max + 1e-12))
    lines.append(f"reference posture inside joint limits: {bool(inside)}")
    print("\n".join(lines))
    return 0
