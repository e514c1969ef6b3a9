#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Run the fixed G1 workload of ../shared/bench with qpretarget; print the anchors' columns.

Reads ``workload_g1.yaml`` and ``targets_g1.npz`` (WORKLOAD.md) beside the checkout, builds a
:class:`qpretarget.Controller` from a config dict mirroring the workload (weights cost^2, task gain
1 per tick, damping 1e-6, both feet as hard ``contacts``, position limits gain 0.95, URDF velocity
limits; variant B adds the 20 ``self_collision`` pairs on convex hulls, d_s = d_min = 0.03 m,
d_i = activation 0.10 m, 0.85 per tick; B+poly adds ``support_polygon`` with a 2 cm margin) and
runs the same ticks: for k = 1..1000, set every target to sample k -> solve -> integrate ->
kinematics, timed with ``time.perf_counter`` around ``Controller.step``; 1 warm-up pass and 3 timed
passes from ``q_init``. Metrics are recomputed from the saved configurations with pinocchio FK and
the convex hulls (as ``anchors/evaluate.py`` does), never from the controller's own numbers.

Usage:
    python scripts/bench_workload.py                      # variants A, B, B+poly, proxsuite
    python scripts/bench_workload.py --variants B --passes 1 --solver daqp
    python scripts/bench_workload.py --save /tmp/runs     # q trajectories as .npz
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path
from typing import Any

import numpy as np

from qpretarget.analysis.benchmark import machine_info
from qpretarget.analysis.workload import (  # noqa: F401 - re-exported for scripts importing this one
    COLUMNS,
    evaluate,
    load_workload,
    make_config,
    reference_piece,
    row,
    run_variant,
    sample_targets,
)
from qpretarget.constraints import CONSTRAINTS

REPO = Path(__file__).resolve().parents[1]
BENCH = (REPO / ".." / "shared" / "bench").resolve()


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--bench", default=str(BENCH), help="folder of workload_g1.yaml")
    ap.add_argument("--variants", default="A,B,B+poly")
    ap.add_argument("--solver", default="proxsuite", help="proxsuite or a qpsolvers name")
    ap.add_argument("--eps-abs", type=float, default=1e-6, help="ProxSuite eps_abs")
    ap.add_argument("--passes", type=int, default=None, help="timed passes (workload: 3)")
    ap.add_argument("--ticks", type=int, default=None, help="ticks per pass (workload: 1000)")
    ap.add_argument("--save", default=None, help="folder for the q trajectories (.npz)")
    ap.add_argument("--json", default=None, help="write the numbers as JSON")
    args = ap.parse_args()
    bench = Path(args.bench)
    wl, tg = load_workload(bench)
    passes = args.passes or int(wl["timing"]["timed_passes"])
    ticks = args.ticks or int(wl["n_ticks"])
    solver: dict[str, Any] = {"name": args.solver}
    if args.solver == "proxsuite":
        solver["eps_abs"] = args.eps_abs
    info = machine_info()
    print(f"workload {wl['name']} ({bench}), {ticks} ticks x {passes} timed passes + 1 warm-up")
    print("machine: " + ", ".join(f"{k} {v}" for k, v in info.items()) + f", {platform.platform()}")
    if "contacts" not in CONSTRAINTS:
        print("note: no `contacts` constraint in this checkout: feet are stiff soft tasks")
    print(f"solver: {solver}")
    print()
    print(COLUMNS)
    print("|" + "---|" * 2 + "---:|" * 15)
    out = []
    for variant in args.variants.split(","):
        r = run_variant(wl, tg, variant, solver, passes=passes, ticks=ticks)
        m = evaluate(wl, tg, r["q"], r["controller"].robot)
        print(row(r, m, f"qpretarget / {args.solver}"), flush=True)
        if r["qp_fails"]:
            print(f"  statuses (last pass): {r['statuses']}")
        if args.save:
            Path(args.save).mkdir(parents=True, exist_ok=True)
            np.savez(
                Path(args.save) / f"qpretarget_{args.solver}_{variant.replace('+', '_')}.npz",
                q=r["q"], pair_distance=m["pair_distances"],
            )  # fmt: skip
        out.append(
            {**{k: v for k, v in r.items() if k not in ("controller", "q")},
             **{k: v for k, v in m.items() if k != "pair_distances"}}
        )  # fmt: skip
    ref = reference_piece(wl, tg, r["controller"].robot)
    print(
        f"\nreference piece (updateGeometryPlacements + computeDistances, 20 hull pairs, "
        f"consecutive ticks): {ref:.1f} µs now, 18.7 µs in RESULTS-anchors.md "
        f"(load factor {ref / 18.7:.2f})"
    )
    if args.json:
        Path(args.json).write_text(
            json.dumps({"machine": info, "reference_piece_us": ref, "results": out}, indent=2)
        )


if __name__ == "__main__":
    main()
