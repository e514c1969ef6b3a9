#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Wild targets: does the controller ever freeze, slip a foot, overshoot a limit or lose balance?

The scenario (docs/reliability.md), seeded: every frame task is pulled to a random point 0.35 m
around its reference every 0.4 s (orientations to a random rotation up to 0.6 rad), the hands are
driven into the torso every 1.2 s (for 0.4 s) and the pelvis is pulled 0.35 m away while both feet
stay planted. Reported: held and relaxed ticks (with what gave), the largest foot drift, the
largest joint-limit overshoot, the smallest CoM margin to the support polygon (the soles' hull,
and the hull shrunk by the constraint's margin), and the tick time (median, p95, p99, max of the
whole ``Controller.step``, wall time and the thread's CPU time: on a shared machine the wall
time's tail is other processes' time slices).

Usage:
    python scripts/bench_wild.py                                 # configs/g1_whole_body.yaml, 2000
    python scripts/bench_wild.py --ticks 500 --seed 3 --solver proxsuite
    python scripts/bench_wild.py --json wild.json
    python scripts/bench_wild.py --clips                         # every shared mocap clip instead

``--clips`` retargets every clip of ``../shared/data/mocap`` (BVH, AMC, C3D) with the config and
counts, per clip, the held ticks and the relaxed ones by cause: a soft constraint's slack inside
the QP, a box bound that gave to a more important one in the merge, the relaxation fallback.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from qpretarget import Controller
from qpretarget.constraints.support_polygon import SupportPolygon
from qpretarget.tasks.frame import FrameTask

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "configs" / "g1_whole_body.yaml"

#: Scenario constants (docs/reliability.md).
RADIUS = 0.35  # [m] distance of a pulled target from its reference
ANGLE = 0.6  # [rad] largest rotation of a pulled orientation target
PULL_PERIOD = 0.4  # [s]
HANDS_PERIOD = 1.2  # [s]
HANDS_DURATION = 0.4  # [s]


def _random_rotation(rng: np.random.Generator, R0: np.ndarray) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return R0 @ pin.exp3(axis * rng.uniform(0.0, ANGLE))


def _random_offset(rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=3)
    return RADIUS * d / np.linalg.norm(d)


def run_wild(
    config: str | Path | dict[str, Any] = CONFIG,
    *,
    ticks: int = 2000,
    seed: int = 0,
    solver: Any = None,
) -> dict[str, Any]:
    """Run the wild-target scenario and return its measures (module docstring).

    Args:
        config: controller YAML path or mapping.
        ticks: number of control ticks.
        seed: seed of the random targets.
        solver: a ``solver:`` entry replacing the config's, or ``None``.

    Returns:
        A dict with ``held``, ``relaxed`` (ticks), ``relaxed_by`` (constraint -> ticks),
        ``foot_drift_m``, ``limit_overshoot_rad``, ``com_margin_m`` (soles' hull),
        ``com_margin_shrunk_m``, ``polygon_on``, ``tick_us`` (median/p95/p99/max), ``q_final``.
    """
    if isinstance(config, dict):
        cfg = dict(config)
        if solver is not None:
            cfg["solver"] = solver
        ctrl = Controller(cfg)
    else:
        ctrl = Controller.from_yaml(config)
        if solver is not None:
            cfg = dict(ctrl.config)
            cfg["solver"] = solver
            ctrl = Controller(cfg, base_dir=Path(config).parent)
    rng = np.random.default_rng(seed)
    ctrl.reset()
    robot, state = ctrl.robot, ctrl.state
    frames = {n: t for n, t in ctrl.tasks.items() if isinstance(t, FrameTask)}
    ref = {n: t.current_pose(state) for n, t in frames.items()}
    ref = {n: (p.copy(), R.copy()) for n, (p, R) in ref.items()}
    torso = next((t for n, t in frames.items() if "torso" in t.frame), None)
    hands = [n for n in frames if "hand" in n and frames[n].has_position]
    feet = [robot.frame_id(f.frame) for f in robot.feet.values()]
    feet0 = [state.frame_placement(f).translation.copy() for f in feet]
    poly = next((c for c in ctrl.constraints if isinstance(c, SupportPolygon)), None)
    qi = robot.joint_q_index
    qmin, qmax = robot.q_min[qi], robot.q_max[qi]
    n_pull = max(1, round(PULL_PERIOD / ctrl.dt))
    n_hands = max(1, round(HANDS_PERIOD / ctrl.dt))
    n_hands_on = max(1, round(HANDS_DURATION / ctrl.dt))
    targets: dict[str, Any] = {}
    held = relaxed = 0
    relaxed_by: Counter[str] = Counter()
    held_status: Counter[str] = Counter()
    drift = overshoot = 0.0
    com_margin = com_margin_shrunk = np.inf
    sc = next((c for c in ctrl.constraints if c.type_name == "self_collision"), None)
    min_pair = np.inf
    times = np.empty(ticks)
    cpu = np.empty(ticks)
    for k in range(ticks):
        if k % n_pull == 0:
            targets = {}
            for n, t in frames.items():
                p0, R0 = ref[n]
                if t.mode == "position":
                    targets[n] = p0 + _random_offset(rng)
                elif t.mode == "orientation":
                    targets[n] = _random_rotation(rng, R0)
                else:
                    T = np.eye(4)
                    T[:3, :3] = _random_rotation(rng, R0)
                    T[:3, 3] = p0 + _random_offset(rng)
                    targets[n] = T
        step_targets = dict(targets)
        if torso is not None and k % n_hands < n_hands_on:  # hands into the torso
            p_torso = torso.current_pose(state)[0]
            for n in hands:
                step_targets[n] = p_torso.copy()
        c0, t0 = time.thread_time(), time.perf_counter()
        res = ctrl.step(step_targets)
        times[k] = time.perf_counter() - t0
        cpu[k] = time.thread_time() - c0
        if res.status == "held":
            held += 1
            held_status[res.solver_status] += 1
        elif res.status == "relaxed":
            relaxed += 1
            relaxed_by.update(res.relaxed.keys())
        for f, p0 in zip(feet, feet0, strict=True):
            drift = max(drift, float(np.linalg.norm(state.frame_placement(f).translation - p0)))
        qa = res.q[qi]
        overshoot = max(overshoot, float(np.max(qmin - qa)), float(np.max(qa - qmax)))
        if sc is not None:
            min_pair = min(min_pair, float(getattr(sc, "min_distance", np.inf)))
        if poly is not None:
            m = poly.com_margin(state)
            com_margin_shrunk = min(com_margin_shrunk, m)
            com_margin = min(com_margin, m + poly.effective_margin)
    us, cpu_us = times * 1e6, cpu * 1e6
    return {
        "config": str(config) if not isinstance(config, dict) else config.get("name", "mapping"),
        "solver": str(ctrl.solver_spec),
        "ticks": ticks,
        "seed": seed,
        "held": held,
        "held_status": dict(held_status),
        "relaxed": relaxed,
        "relaxed_by": dict(relaxed_by),
        "foot_drift_m": drift,
        "limit_overshoot_rad": max(overshoot, 0.0),
        "polygon_on": poly is not None,
        "com_margin_m": float(com_margin),
        "com_margin_shrunk_m": float(com_margin_shrunk),
        "tick_us": _stats(us),
        "tick_cpu_us": _stats(cpu_us),
        "self_collision_pairs": len(getattr(sc, "pairs", [])),
        "min_pair_distance_m": float(min_pair),
        "q_final": ctrl.q.tolist(),
    }


MOCAP = REPO.parent / "shared" / "data" / "mocap"


def run_clips(config: str | Path = CONFIG, folder: Path = MOCAP) -> list[dict[str, Any]]:
    """Retarget every clip in ``folder``; per clip: ticks, held, relaxed ticks by cause."""
    from qpretarget.errors import QPRetargetError
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter

    rows = []
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in (".bvh", ".amc", ".c3d"):
            continue
        row: dict[str, Any] = {"clip": path.name, "ticks": 0, "held": 0, "relaxed": 0}
        causes: Counter[str] = Counter()
        gave: Counter[str] = Counter()

        def observe(res: Any, row: dict[str, Any] = row, causes: Counter[str] = causes,
                    gave: Counter[str] = gave) -> None:  # fmt: skip
            row["ticks"] += 1
            row["held"] += res.status == "held"
            if res.status == "relaxed":
                row["relaxed"] += 1
                gave.update(res.relaxed.keys())
                for m in res.messages:
                    if "soft constraints gave" in m:
                        causes["slack"] += 1
                    elif "box bounds gave" in m:
                        causes["box"] += 1
                    elif "relaxed" in m or "fallback" in m:
                        causes["fallback"] += 1

        try:
            ctrl = Controller.from_yaml(config)
            ctrl.add_observer(observe)
            Retargeter(ctrl).retarget(load_motion(path))
        except QPRetargetError as exc:
            row["error"] = str(exc).splitlines()[0]
        row["causes"], row["gave"] = dict(causes), dict(gave)
        rows.append(row)
        print(
            f"  {path.name:42s} {row['ticks']:6d} ticks, held {row['held']}, relaxed "
            f"{row['relaxed']} {row['gave'] or ''} {row['causes'] or ''} {row.get('error', '')}",
            flush=True,
        )
    return rows


def _stats(us: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(us)),
        "p95": float(np.percentile(us, 95)),
        "p99": float(np.percentile(us, 99)),
        "max": float(us.max()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("config", nargs="?", default=str(CONFIG))
    ap.add_argument("--ticks", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--solver", default=None, help="replace the config's solver (a name)")
    ap.add_argument("--json", default=None, help="also write the measures to this file")
    ap.add_argument("--clips", action="store_true", help="every shared mocap clip instead")
    args = ap.parse_args()
    from qpretarget.analysis.benchmark import machine_info

    info = machine_info()
    print("machine: " + ", ".join(f"{k} {v}" for k, v in info.items()))
    if args.clips:
        rows = run_clips(args.config)
        print(
            f"{len(rows)} clips, {sum(r['ticks'] for r in rows)} ticks, held "
            f"{sum(r['held'] for r in rows)}, relaxed {sum(r['relaxed'] for r in rows)}"
        )
        if args.json:
            Path(args.json).write_text(json.dumps({"machine": info, "clips": rows}, indent=2))
        return
    r = run_wild(args.config, ticks=args.ticks, seed=args.seed, solver=args.solver)
    t, c = r["tick_us"], r["tick_cpu_us"]
    print(f"{Path(args.config).name}, solver {r['solver']}, {r['ticks']} ticks, seed {r['seed']}")
    print(f"  held ticks       {r['held']} {r['held_status'] or ''}")
    print(f"  relaxed ticks    {r['relaxed']} {r['relaxed_by'] or ''}")
    print(f"  foot drift       {r['foot_drift_m'] * 1e3:.4f} mm")
    print(f"  limit overshoot  {r['limit_overshoot_rad']:.2e} rad")
    if r["polygon_on"]:
        print(
            f"  CoM margin       {r['com_margin_m'] * 1e3:.2f} mm to the soles' hull, "
            f"{r['com_margin_shrunk_m'] * 1e3:.2f} mm to the shrunk hull"
        )
    print(
        f"  self-collision   {r['self_collision_pairs']} pairs, closest "
        f"{r['min_pair_distance_m'] * 1e3:.1f} mm (hulls; negative: penetration)"
    )
    for label, x in (("wall", t), ("thread CPU", c)):
        print(
            f"  tick [us] {label:10s} median {x['median']:.0f}, p95 {x['p95']:.0f}, "
            f"p99 {x['p99']:.0f}, max {x['max']:.0f}"
        )
    if args.json:
        r.pop("q_final")
        r["machine"] = info
        Path(args.json).write_text(json.dumps(r, indent=2))


if __name__ == "__main__":
    main()
