# SPDX-License-Identifier: Apache-2.0
"""``qpretarget bench``: ticks per second and per-stage step time of a config or the G1 workload."""

from __future__ import annotations

import argparse
import json

from . import add_command

SUMMARY = "ticks per second, median/p95/p99 step time (a config, or the shared G1 workload)"
DESCRIPTION = (
    "Time Controller.step on scripted targets (warm-up, then timed passes), or run the fixed G1 "
    "workload of ../shared/bench (variants A, B, B+poly: the anchors' ticks, metrics and "
    "constraint-violation counts, docs/benchmarks.md)."
)

HELP = """examples:
  qpretarget bench --workload A,B,B+poly                 # the shared workload, default solver
  qpretarget bench --workload B --solvers daqp,proxsuite --passes 1 --json b.json
  qpretarget bench configs/g1_augmentation.yaml
  qpretarget bench configs/g1_whole_body.yaml --solvers proxsuite,daqp --ticks 2000
  QPRETARGET_KERNEL=0 qpretarget bench --workload A     # the pure-Python path, to compare
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` subcommand."""
    p = add_command(sub, "bench", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("config", nargs="?", default=None, help="controller YAML (or use --workload)")
    p.add_argument(
        "--workload", default=None,
        help="comma-separated variants of the shared G1 workload: A, B, B+poly",
    )  # fmt: skip
    p.add_argument(
        "--bench-dir", default=None,
        help="folder of workload_g1.yaml and targets_g1.npz (default ../shared/bench)",
    )  # fmt: skip
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
    from ..kernel import describe

    if args.ticks < 1 or args.passes < 1 or args.warmup < 0:
        raise SystemExit("qpretarget bench: --ticks and --passes must be >= 1, --warmup >= 0")
    if (args.config is None) == (args.workload is None):
        raise SystemExit("qpretarget bench: give a controller YAML or --workload A,B,B+poly.")
    solvers = [s.strip() for s in args.solvers.split(",")] if args.solvers else [None]
    info = machine_info()
    print("machine: " + ", ".join(f"{k} {v}" for k, v in info.items()))
    print(describe())
    if args.workload is not None:
        return run_workload(args, solvers, info)
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
        write_json(args.json, {"machine": info, "results": results})
    return 0


def write_json(path: str, data: dict) -> None:
    """Write ``data`` as JSON, atomically."""
    from ..fileio import write_atomic

    write_atomic(path, lambda f: json.dump(data, f, indent=2, default=float), binary=False)


def run_workload(args: argparse.Namespace, solvers: list[str | None], info: dict) -> int:
    """The shared G1 workload: the anchors' table rows (timing, tracking, violations)."""
    from pathlib import Path

    from tqdm import tqdm

    from ..analysis import workload as W

    variants = [v.strip() for v in args.workload.split(",") if v.strip()]
    bad = [v for v in variants if v not in W.VARIANTS]
    if bad or not variants:
        raise SystemExit(
            f"qpretarget bench: unknown workload variant(s) {bad}; use {', '.join(W.VARIANTS)}."
        )
    bench = Path(args.bench_dir) if args.bench_dir else W.default_bench_dir()
    if not (bench / "workload_g1.yaml").is_file():
        raise SystemExit(
            f"qpretarget bench: no workload_g1.yaml in {bench}; give --bench-dir (the folder "
            "of the shared benchmark, ../shared/bench beside the checkout)."
        )
    wl, tg = W.load_workload(bench)
    ticks = min(args.ticks, int(wl["n_ticks"]))
    print(f"workload {wl['name']} ({bench}): {ticks} ticks x {args.passes} timed passes + warm-up")
    print()
    print(W.COLUMNS)
    print("|" + "---|" * 2 + "---:|" * 15)
    out = []
    runs = [(v, s or "daqp") for v in variants for s in solvers]
    for variant, solver in tqdm(runs, desc="workload", leave=False, disable=len(runs) < 2):
        spec: dict = {"name": solver}
        r = W.run_variant(wl, tg, variant, spec, passes=args.passes, ticks=ticks)
        m = W.evaluate(wl, tg, r["q"], r["controller"].robot)
        tqdm.write(W.row(r, m, f"qpretarget / {solver}"))
        if r["qp_fails"]:
            tqdm.write(f"  statuses (last pass): {r['statuses']}")
        out.append(
            {**{k: v for k, v in r.items() if k not in ("controller", "q")},
             **{k: v for k, v in m.items() if k != "pair_distances"}, "solver": solver}
        )  # fmt: skip
    if args.json:
        write_json(args.json, {"machine": info, "workload": wl["name"], "results": out})
    return 0
