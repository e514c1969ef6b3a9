#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Benchmark Controller.step for configs and solvers: ticks/s, median and p95 of step and solve.

Usage:
    python scripts/bench_step.py                                  # g1_augmentation, proxsuite
    python scripts/bench_step.py configs/g1_whole_body.yaml --solvers proxsuite,daqp,quadprog,osqp
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from qpretarget.analysis.benchmark import bench_config, format_stages, format_table, machine_info

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("configs", nargs="*", default=[str(REPO / "configs" / "g1_augmentation.yaml")])
    ap.add_argument("--solvers", default="proxsuite")
    ap.add_argument("--ticks", type=int, default=1000)
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    info = machine_info()
    print("machine: " + ", ".join(f"{k} {v}" for k, v in info.items()))
    results = [
        bench_config(c, solver=s, ticks=args.ticks, passes=args.passes)
        for c in args.configs
        for s in args.solvers.split(",")
    ]
    print(format_table(results))
    for r in results:
        print(f"\n{Path(r['config']).stem} / {r['solver']} stages:")
        print(format_stages(r))
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": info, "results": results}, indent=2))


if __name__ == "__main__":
    main()
