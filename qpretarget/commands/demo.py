# SPDX-License-Identifier: Apache-2.0
"""``qpretarget demo``: run a bundled robot on a built-in scripted motion and print a summary.

Interim version: scripted hand/elbow/pelvis targets on G1 (until the built-in human motion lands).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

HELP = """examples:
  qpretarget demo                 G1 tracks a scripted motion for 10 s
  qpretarget demo --seconds 3
"""

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand."""
    p = sub.add_parser(
        "demo",
        help="run G1 on a built-in motion and print tracking error and ticks per second",
        description="Retarget a built-in motion on a bundled robot; nothing to download.",
        epilog=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", default="g1", help="bundled robot (default g1)")
    p.add_argument("--seconds", type=float, default=10.0, help="duration [s] (default 10)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo and print its summary."""
    from ..controller import Controller
    from ..solver_comparison import scripted_targets

    cfg = CONFIGS / f"{args.robot}_augmentation.yaml"
    ctrl = Controller.from_yaml(cfg)
    targets = list(scripted_targets(ctrl, args.seconds))
    ctrl.reset()
    errs: dict[str, list[float]] = {}
    steps = []
    t0 = time.perf_counter()
    for tg in targets:
        res = ctrl.step(tg)
        steps.append(res.step_time)
        for k, e in res.task_errors.items():
            errs.setdefault(k, []).append(e)
    wall = time.perf_counter() - t0
    r = ctrl.robot
    print(f"robot {r.name}: {len(targets)} ticks ({args.seconds:.1f} s at {1 / ctrl.dt:.0f} Hz)")
    print(f"speed: {len(targets) / wall:.0f} ticks/s, median step {np.median(steps) * 1e6:.0f} µs")
    for k, e in errs.items():
        rms = float(np.sqrt(np.mean(np.square(e))))
        task = ctrl.tasks[k]
        if getattr(task, "has_position", False):
            print(f"  {k:12s} RMS error {rms * 1e3:7.2f} mm")
        elif getattr(task, "has_orientation", False):
            print(f"  {k:12s} RMS error {np.degrees(rms):7.2f} deg")
    return 0
