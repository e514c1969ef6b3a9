# SPDX-License-Identifier: Apache-2.0
"""``qpretarget compare-solvers``: one motion, each QP solver, one table (docs/solvers.md)."""

from __future__ import annotations

import argparse
import sys

from . import add_command, add_config

SUMMARY = "run the same motion with each QP solver and compare times, accuracy, failures"
DESCRIPTION = (
    "Run the same motion with each QP solver (closed loop, one controller per solver) and "
    "print a table: median/p95 solve time, iterations, max constraint violation, tracking "
    "RMSE and its difference to the reference solver, failures."
)

HELP = """examples:
  qpretarget compare-solvers configs/g1_augmentation.yaml scripted
      ProxSuite (native, warm-started) and every installed qpsolvers backend, 2 s scripted motion
  qpretarget compare-solvers configs/g1_augmentation.yaml run.npz --solvers proxsuite,daqp -o out/
      replay the targets of a saved run; write out/comparison.{csv,json,md}
  qpretarget compare-solvers configs/g1_augmentation.yaml scripted:10 --solvers proxsuite,gurobi
      a solver that is not installed is listed as such

MOTION is 'scripted' or 'scripted:SECONDS' (built-in smooth hand/elbow/pelvis targets), a run
file RUN.npz (its target/<task> arrays are replayed), or a mocap file (.bvh, .amc, .c3d)
retargeted for each solver through the config's retarget: section.
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``compare-solvers`` subcommand."""
    p = add_command(sub, "compare-solvers", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_config(p, "controller YAML")
    p.add_argument("motion", help="'scripted[:SECONDS]', a run file (.npz) or a mocap file")
    p.add_argument(
        "--solvers",
        help="comma-separated solver names (default: proxsuite + each installed qpsolvers backend)",
    )
    p.add_argument("--seconds", type=float, help="use only the first SECONDS of the motion")
    p.add_argument("--reference", help="solver the others are compared with (default: the first)")
    p.add_argument(
        "-o", "--output", help="directory for comparison.{csv,json,md}, or one .csv/.json/.md file"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the comparison, print the table, save it with ``-o``."""
    from ..analysis.solver_comparison import compare_solvers

    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()] if args.solvers else None
    result = compare_solvers(
        args.config,
        args.motion,
        solvers,
        seconds=args.seconds,
        reference=args.reference,
        progress=lambda text: print(text, file=sys.stderr, flush=True),
    )
    print(f"config {result.config}; motion: {result.motion}; reference solver: {result.reference}")
    print(result.to_text())
    if args.output:
        paths = result.save(args.output)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0
