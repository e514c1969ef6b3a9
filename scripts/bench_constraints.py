# SPDX-License-Identifier: Apache-2.0
"""Time the whole-body constraint modules per tick on G1 (contacts, support polygon,
acceleration limits) and the relaxation fallback.

Runs the G1 whole-body controller (g1_augmentation's tasks with gain 15/s, damping 0.3, joint,
velocity and acceleration limits, contacts, support polygon) on targets that jump 4 times a
second, wraps each constraint's ``compute_rows`` / ``compute_bounds`` and the fallback with
timers, and prints median / p95 microseconds per call, plus the step time with and without the
three modules and a load calibration (one ``computeJointJacobians`` pass, ~4 us idle).

    python scripts/bench_constraints.py [--ticks 600]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from typing import Any

import numpy as np
import pinocchio as pin

from qpretarget import Controller, load_robot


def config(robot: Any, whole_body: bool) -> dict[str, Any]:
    tasks = [
        {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "pose",
         "position_weight": 100.0, "orientation_weight": 100.0},
        {"type": "frame", "name": "torso", "frame": "torso_link", "mode": "orientation",
         "orientation_weight": 100.0},
        {"type": "frame", "name": "left_hand", "frame": "left_rubber_hand", "mode": "position",
         "position_weight": 100.0},
        {"type": "frame", "name": "right_hand", "frame": "right_rubber_hand", "mode": "position",
         "position_weight": 100.0},
        {"type": "frame", "name": "left_elbow", "frame": "left_elbow_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "frame", "name": "right_elbow", "frame": "right_elbow_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "frame", "name": "head", "frame": "mid360_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "posture", "name": "posture", "weight": 1.0e-3},
    ]  # fmt: skip
    for t in tasks:
        t["gain"] = 15.0
    cons: list[dict[str, Any]] = [
        {"type": "joint_limits", "gain": 0.95},
        {"type": "velocity_limits"},
    ]
    if whole_body:
        cons += [
            {"type": "contacts", "feet": ["left_foot", "right_foot"]},
            {"type": "support_polygon", "margin": 0.01},
            {"type": "acceleration_limits", "a_max": 100.0},
        ]
    return {
        "robot": robot,
        "dt": 0.01,
        "regularization": {"type": "identity", "damping": 0.3},
        "solver": {"name": "proxsuite", "eps_abs": 1e-9},
        "tasks": tasks,
        "constraints": cons,
    }


def targets(ctrl: Controller, n: int, seed: int = 1):  # noqa: ANN201
    rng = np.random.default_rng(seed)
    start = {
        k: ctrl.state.frame_placement(ctrl.robot.frame_id(ctrl.tasks[k].frame)).translation.copy()
        for k in ("left_hand", "right_hand", "pelvis")
    }
    tg: dict[str, Any] = {}
    for i in range(n):
        if i % 25 == 0:
            T = np.eye(4)
            T[:3, :3] = pin.exp3(rng.uniform(-0.4, 0.4, 3))
            T[:3, 3] = start["pelvis"] + rng.uniform(-0.15, 0.15, 3)
            tg = {
                "left_hand": start["left_hand"] + rng.uniform(-0.4, 0.4, 3),
                "right_hand": start["right_hand"] + rng.uniform(-0.4, 0.4, 3),
                "pelvis": T,
            }
        yield tg


def timed(obj: Any, attr: str, sink: list[float]) -> None:
    fn = getattr(obj, attr)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        sink.append(time.perf_counter() - t0)
        return out

    setattr(obj, attr, wrapper)


def stats(xs: list[float]) -> str:
    if not xs:
        return "n=0"
    a = np.array(xs) * 1e6
    return f"median {np.median(a):8.1f} us   p95 {np.percentile(a, 95):8.1f} us   n={len(a)}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=600)
    args = ap.parse_args()
    cpu = platform.processor() or platform.machine()
    print(f"{cpu}, {os.cpu_count()} cpus, load average {os.getloadavg()}")
    print(f"pinocchio {pin.__version__}")
    robot = load_robot("g1")
    ctrl = Controller(config(robot, True))
    times: dict[str, list[float]] = {}
    for name, attr in [("contacts", "compute_rows"), ("support_polygon", "compute_rows"),
                       ("acceleration_limits", "compute_bounds")]:  # fmt: skip
        timed(ctrl.constraint(name), attr, times.setdefault(name, []))
    timed(ctrl.fallback, "solve", times.setdefault("fallback (relaxed ticks)", []))
    runs: dict[str, list[Any]] = {"whole-body": [], "limits only": []}
    for tg in targets(ctrl, args.ticks):
        runs["whole-body"].append(ctrl.step(tg))
    base = Controller(config(robot, False))
    for tg in targets(base, args.ticks):
        runs["limits only"].append(base.step(tg))
    # Load calibration: one computeJointJacobians pass of G1 (about 5 us on an idle core).
    calib = []
    data = robot.model.createData()
    for _ in range(2000):
        t0 = time.perf_counter()
        pin.computeJointJacobians(robot.model, data, robot.q_reference)
        calib.append(time.perf_counter() - t0)
    for name, xs in times.items():
        print(f"{name:26s} {stats(xs)}")
    per_tick = [
        sum(v)
        for v in zip(
            *(times[k] for k in ("contacts", "support_polygon", "acceleration_limits")),
            strict=False,
        )
    ]
    print(f"{'three modules per tick':26s} {stats(per_tick)}")
    for name, res in runs.items():
        print(f"{'step, ' + name:26s} {stats([r.step_time for r in res])}")
        print(f"{'  solve, ' + name:26s} {stats([r.solve_time for r in res])}", end="")
        print(f"   iterations median {np.median([r.iterations for r in res]):.0f}")
        print(f"{'  ticks relaxed':26s} {sum(r.status == 'relaxed' for r in res)}")
    print(f"{'calib: computeJointJacobians':26s} {stats(calib)}")


if __name__ == "__main__":
    main()
