#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Tick cost of ``self_collision`` with the workload's 20 listed pairs vs ``pairs: auto``.

Runs variant B of the shared G1 workload (``../shared/bench/workload_g1.yaml`` and
``targets_g1.npz``, WORKLOAD.md) twice per pass, side by side in one process: once with the 20
pairs of the workload, once with the same constraint but ``pairs: auto`` (every body pair that
can collide, docs/collisions.md). Same tick as ``scripts/bench_workload.py`` (set the targets of
sample k -> solve -> integrate -> kinematics, one ``Controller.step`` timed with
``time.perf_counter``); 1 warm-up pass, then ``--passes`` timed passes, the two pair sets
interleaved pass by pass so that the machine's load drifts alike on both.

Printed per pair set: median, p95 and p99 tick time [µs] over every timed tick, the collision
block's median [µs] and its part in coal's distance calls (GJK/EPA, C++), the QP solve's median
[µs] (``StepResult.solve_time``), exact pair distances computed per tick (broad phase) and QP
rows with a bound (median / max), hand RMSE [mm], and the mesh audit of the last pass over every
pair (:func:`qpretarget.analysis.mesh_audit.audit_self_collision`: penetrating frames, minimum
distance).

Usage:
    python scripts/bench_collision_pairs.py                 # 3 timed passes, daqp
    python scripts/bench_collision_pairs.py --passes 1 --ticks 300
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from qpretarget.analysis.benchmark import machine_info
from qpretarget.analysis.mesh_audit import audit_self_collision
from qpretarget.control.controller import Controller

REPO = Path(__file__).resolve().parents[1]
BENCH = (REPO / ".." / "shared" / "bench").resolve()


def _bench_workload() -> Any:
    """``scripts/bench_workload.py`` as a module (the workload's config and targets)."""
    spec = importlib.util.spec_from_file_location(
        "bench_workload", REPO / "scripts" / "bench_workload.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def make_controller(bw: Any, wl: dict[str, Any], solver: dict[str, Any], pairs: str) -> Controller:
    """Workload variant B; ``pairs`` is ``listed`` (the 20 pairs) or ``auto``."""
    cfg = bw.make_config(wl, "B", solver)
    if pairs == "auto":
        for c in cfg["constraints"]:
            if c["type"] == "self_collision":
                c["pairs"] = "auto"
    return Controller(cfg)


def run_pass(ctrl: Controller, tg: Any, targets: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """One pass from ``q_init``: tick times, collision block times, pairs computed, rows."""
    col = next(c for c in ctrl.constraints if c.type_name == "self_collision")
    n = len(targets)
    ctrl.reset(np.asarray(tg["q_init"], dtype=float))
    ctrl.task("posture").set_target(tg["q_nominal"])
    out = {k: np.zeros(n) for k in ("tick", "collision", "gjk", "solve", "computed", "rows")}
    q = np.zeros((n + 1, ctrl.robot.nq))
    q[0] = tg["q_init"]
    for k in range(n):
        t0 = time.perf_counter()
        res = ctrl.step(targets[k])
        out["tick"][k] = time.perf_counter() - t0
        q[k + 1] = res.q
        out["collision"][k] = col.last_time
        out["gjk"][k] = col.model.last_gjk_time
        out["solve"][k] = res.solve_time
        out["computed"][k] = col.model.last_n_computed
        out["rows"][k] = col._row_pairs.size
    out["q"] = q
    return out


def hand_rmse_mm(ctrl: Controller, wl: dict[str, Any], tg: Any, q: np.ndarray) -> float:
    """RMSE of both hands against the workload's targets [mm] (ticks 1..n)."""
    import pinocchio as pin

    model = ctrl.robot.model
    data = model.createData()
    err = []
    for name in ("left_hand", "right_hand"):
        frame = wl["tasks"][name]["frame"]
        fid = model.getFrameId(frame)
        for k in range(1, len(q)):
            pin.framesForwardKinematics(model, data, q[k])
            err.append(np.linalg.norm(data.oMf[fid].translation - tg[f"T_{frame}"][k][:3, 3]))
    return float(np.sqrt(np.mean(np.square(err))) * 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--bench", default=str(BENCH), help="folder of workload_g1.yaml")
    ap.add_argument("--solver", default="daqp", help="QP solver (the shipped default: daqp)")
    ap.add_argument("--passes", type=int, default=3, help="timed passes per pair set")
    ap.add_argument("--ticks", type=int, default=None, help="ticks per pass (workload: 1000)")
    args = ap.parse_args()
    bw = _bench_workload()
    wl, tg = bw.load_workload(Path(args.bench))
    ticks = args.ticks or int(wl["n_ticks"])
    solver = {"name": args.solver}
    targets = [bw.sample_targets(tg, wl, k) for k in range(1, ticks + 1)]
    sets = ("listed", "auto")
    ctrls = {s: make_controller(bw, wl, solver, s) for s in sets}
    runs: dict[str, list[dict[str, np.ndarray]]] = {s: [] for s in sets}
    print(
        f"workload {wl['name']} variant B, {ticks} ticks x {args.passes} timed passes + 1 warm-up"
    )
    print("machine: " + ", ".join(f"{k} {v}" for k, v in machine_info().items()))
    for p in range(args.passes + 1):
        for s in sets:
            r = run_pass(ctrls[s], tg, targets)
            if p > 0:
                runs[s].append(r)
        print(f"pass {p}/{args.passes} done", file=sys.stderr, flush=True)
    print()
    print(
        "| pairs | candidate pairs | QP rows | median µs | p95 µs | p99 µs | collision µs "
        "(median) | of which GJK µs (median) | QP solve µs (median) | distances computed per tick "
        "(median / max) | rows with a bound (median / max) | hand RMSE mm | mesh audit: "
        "penetrating frames / min distance mm |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|---|")
    med = {}
    for s in sets:
        c = next(x for x in ctrls[s].constraints if x.type_name == "self_collision")
        tick = np.concatenate([r["tick"] for r in runs[s]]) * 1e6
        colt = np.concatenate([r["collision"] for r in runs[s]]) * 1e6
        gjk = np.concatenate([r["gjk"] for r in runs[s]]) * 1e6
        solve = np.concatenate([r["solve"] for r in runs[s]]) * 1e6
        comp = np.concatenate([r["computed"] for r in runs[s]])
        rows = np.concatenate([r["rows"] for r in runs[s]])
        q = runs[s][-1]["q"]
        audit = audit_self_collision(ctrls[s].robot, q[1:])
        med[s] = float(np.median(tick))
        print(
            f"| {s} | {len(c.pairs)} | {c.n_rows} | {med[s]:.0f} | {np.percentile(tick, 95):.0f} | "
            f"{np.percentile(tick, 99):.0f} | {np.median(colt):.0f} | {np.median(gjk):.0f} | "
            f"{np.median(solve):.0f} | "
            f"{np.median(comp):.0f} / {comp.max():.0f} | "
            f"{np.median(rows):.0f} / {rows.max():.0f} | "
            f"{hand_rmse_mm(ctrls[s], wl, tg, q):.2f} | "
            f"{audit.penetrating_frames} / {audit.min_distance_mm:.1f} ({len(audit.pairs)} pairs) |"
        )
    print(f"\nauto / listed median tick time: {med['auto'] / med['listed']:.2f}")


if __name__ == "__main__":
    main()
