# SPDX-License-Identifier: Apache-2.0
"""``qpretarget demo``: retarget the built-in human motion to a bundled robot, nothing to download.

The motion is example-robot-data's ``human_description`` model driven by a scripted wave, a reach
across the body, a squat and a step to the side (:mod:`qpretarget.motion.builtin`). The controller
is the repository's ``configs/<robot>_whole_body.yaml`` when it exists, otherwise the one
:func:`qpretarget.retarget.retargeter.whole_body_config` builds from the robot's registry entry.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from . import add_command, add_quiet

SUMMARY = "retarget the built-in human motion to G1 and print a summary"
DESCRIPTION = (
    "Retarget a built-in human motion (wave, reach across, squat, side step) to a bundled "
    "robot with the whole-body controller; nothing to download."
)

HELP = """examples:
  qpretarget demo                       G1 imitates the built-in motion (10 s), prints a summary
  qpretarget demo -o demo_g1.npz        also write the run (qpretarget evaluate/view read it)
  qpretarget demo --robot talos
  qpretarget demo --seconds 4           the first 4 s only (wave and part of the reach)
  qpretarget demo --config my.yaml      your own controller (needs a `retarget:` section)
"""

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand."""
    p = add_command(sub, "demo", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("--robot", default="g1", help="bundled robot with feet (default g1)")
    p.add_argument("-o", "--output", default=None, help="write the run file (.npz)")
    p.add_argument("--seconds", type=float, default=None, help="length of the motion [s]")
    p.add_argument("--config", default=None, help="controller YAML (default: whole-body config)")
    add_quiet(p)
    p.set_defaults(func=run)


def demo_controller(robot: str, config: str | None = None):  # noqa: ANN201
    """The demo's controller, with the support sequences (stepping) on.

    ``config`` when given; else the repository's ``configs/<robot>_whole_body.yaml`` completed
    by :func:`~qpretarget.retarget.whole_body_config` with what stepping needs (CoM and sole
    tasks, ``retarget.support``) if it lacks it; else a config generated from the robot's
    registry entry (installed package without the repository's configs).

    Returns:
        ``(controller, source)`` with ``source`` saying which config was used.
    """
    from ..control.controller import Controller
    from ..retarget.retargeter import whole_body_config
    from ..yamlio import load_yaml

    if config is not None:
        return Controller.from_yaml(config), str(config)
    path = CONFIGS / f"{robot}_whole_body.yaml"
    if path.is_file():
        base = load_yaml(path.read_text(encoding="utf-8")) or {}
        if (base.get("retarget") or {}).get("support"):
            return Controller.from_yaml(path), str(path)
        cfg = whole_body_config(robot, base=base)
        return Controller(cfg, base_dir=path.parent), f"{path} + support tasks"
    return Controller(whole_body_config(robot)), "generated (retarget.whole_body_config)"


def run(args: argparse.Namespace) -> int:
    """Run the demo and print its summary."""
    from ..errors import ConfigError
    from ..motion.builtin import DURATION, builtin_motion
    from ..retarget.retargeter import Retargeter
    from ..retarget.summary import format_summary, summarize_run

    seconds = DURATION if args.seconds is None else args.seconds
    if not 0.2 <= seconds:
        raise ConfigError(f"--seconds must be at least 0.2 s, got {seconds}.")
    t_load = time.perf_counter()
    controller, source = demo_controller(args.robot, args.config)
    motion = builtin_motion(duration=min(seconds, DURATION))
    retargeter = Retargeter(controller)
    t_load = time.perf_counter() - t_load
    t0 = time.perf_counter()
    traj = retargeter.retarget(motion, progress=not args.quiet and sys.stderr.isatty())
    wall = time.perf_counter() - t0
    summary = summarize_run(traj, controller, wall_time=wall)
    title = (
        f"qpretarget demo: built-in human motion (wave, reach across, squat, side step) -> "
        f"{controller.robot.name}\nconfig       {source}\n"
        f"pipeline     {motion.rate:g} Hz key-points, {traj.meta['filter']['cutoff_hz']:g} Hz "
        f"Butterworth, splines to {traj.meta['control_rate']:g} Hz, {traj.meta['scaling']} "
        f"scaling, support phases {'on' if retargeter.support else 'off'} "
        f"(setup {t_load:.1f} s)"
    )
    print(format_summary(summary, title=title))
    if args.output:
        print(f"wrote {traj.save(args.output)}")
    return 0
