# SPDX-License-Identifier: Apache-2.0
"""``qpretarget bench``: ticks per second and per-stage step time of a config."""

from __future__ import annotations

import argparse
import json

from . import add_command, add_config

SUMMARY = "ticks per second, median/p95 step and solve time, split by stage"
DESCRIPTION = "Time Controller.step on scripted targets (warm-up, then timed passes)."

HELP = """examples:
  qpretarget bench configs/g1_augmentation.yaml
  qpretarget bench configs/g1_whole_body.yaml --solvers proxsuite,daqp --ticks 2000
  qpretarget bench configs/g1_augmentation.yaml --json bench.json
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` subcommand."""
    p = add_command(sub, "bench", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_config(p, "controller YAML")
    p.add_argument(
        "--solvers", default=None, help="comma-separated solvers (default: the config's)"
    )
    p.add_argument("--ticks", type=int, default=1000, help="timed ticks per pass (default 1000)")
    p.add_argument("--passes", type=int, default=3, help="timed passes (default 3)")
    p.add_argument("--warmup", type=int, default=200, help="untimed ticks first (default 200)")
    p.add_argument("--json", default=None, help="also write the results to this JSON file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the tables."""
    from ..analysis.benchmark import bench_config, format_stages, format_table, machine_info

    if args.ticks < 1 or args.passes < 1 or args.warmup < 0:
        raise SystemExit("qpretarget bench: --ticks and --passes must be >= 1, --warmup >= 0")
    solvers = [s.strip() for s in args.solvers.split(",")] if args.solvers else [None]
    info = machine_info()
    print("machine: " + ", ".join(f"{k} {v}" for k, v in info.items()))
    results = []
    for s in solvers:
        results.append(
            bench_config(
                args.config, solver=s, ticks=args.ticks, warmup=args.warmup, passes=args.passes
            )
        )
    print(format_table(results))
    for r in results:
        print(f"\nstages of {r['solver']}:")
        print(format_stages(r))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": info, "results": results}, f, indent=2)
    return 0
