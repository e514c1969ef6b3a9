# SPDX-License-Identifier: Apache-2.0
"""The fixed G1 workload of ``../shared/bench`` (WORKLOAD.md), run by ``qpretarget bench``.

Reads ``workload_g1.yaml`` and ``targets_g1.npz``, builds a :class:`~qpretarget.Controller` from
a config mirroring the workload (weights cost^2, task gain 1 per tick, damping 1e-6, both feet as
hard ``contacts``, position limits gain 0.95, URDF velocity limits; variant B adds the 20
``self_collision`` pairs on convex hulls, d_s = d_min = 0.03 m, d_i = 0.10 m, 0.85 per tick;
B+poly adds ``support_polygon`` with a 2 cm margin) and runs the same ticks as the anchors: for
k = 1..1000, set every target to sample k -> solve -> integrate -> kinematics, timed with
``time.perf_counter`` around ``Controller.step``; one warm-up pass and the timed passes from
``q_init``. The metrics are recomputed from the configurations with pinocchio FK and the convex
hulls (as the anchors' ``evaluate.py`` does), never from the controller's own numbers.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from ..collision import CollisionModel
from ..constraints import CONSTRAINTS
from ..control.controller import Controller
from ..robot import RobotState

#: Variants of the workload (WORKLOAD.md).
VARIANTS = ("A", "B", "B+poly")


def default_bench_dir() -> Path:
    """``../shared/bench`` beside the working directory or beside the checkout."""
    for base in (Path.cwd(), Path(__file__).resolve().parents[2]):
        cand = (base / ".." / "shared" / "bench").resolve()
        if (cand / "workload_g1.yaml").is_file():
            return cand
    return (Path.cwd() / ".." / "shared" / "bench").resolve()


COLUMNS = (
    "| variant | library / QP solver | median µs | p95 µs | p99 µs | ticks/s | QP fails | "
    "L/R hand mm | "
    "L/R elbow mm | pelvis mm / ° | torso ° | head mm | CoM xy mm | feet max mm | "
    "min pair dist mm | dmin-viol ticks | collision µs |"
)


def load_workload(bench: Path) -> tuple[dict[str, Any], Any]:
    """The workload definition and its targets (``.npz``)."""
    wl = yaml.safe_load((bench / "workload_g1.yaml").read_text())
    targets = np.load(bench / wl["targets_file"])
    return wl, targets


def make_config(wl: dict[str, Any], variant: str, solver: dict[str, Any]) -> dict[str, Any]:
    """Qpretarget config dict mirroring the workload (weights are the workload's costs squared)."""
    t = wl["tasks"]

    def w(cost: float) -> float:
        return float(cost) ** 2

    tasks: list[dict[str, Any]] = [
        {"type": "frame", "name": "pelvis", "frame": t["pelvis"]["frame"], "mode": "pose",
         "position_weight": w(t["pelvis"]["position_cost"]),
         "orientation_weight": w(t["pelvis"]["orientation_cost"])},
        {"type": "frame", "name": "torso", "frame": t["torso"]["frame"], "mode": "orientation",
         "orientation_weight": w(t["torso"]["orientation_cost"])},
    ]  # fmt: skip
    for name in ("left_hand", "right_hand", "left_elbow", "right_elbow", "head"):
        tasks.append(
            {"type": "frame", "name": name, "frame": t[name]["frame"], "mode": "position",
             "position_weight": w(t[name]["position_cost"])}
        )  # fmt: skip
    tasks.append({"type": "com", "name": "com", "axes": "xy", "weight": w(t["com"]["cost"])})
    tasks.append({"type": "posture", "name": "posture", "weight": w(t["posture"]["cost"])})
    constraints: list[dict[str, Any]] = []
    if "contacts" in CONSTRAINTS:
        constraints.append({"type": "contacts", "feet": ["left_foot", "right_foot"]})
    else:  # before the contacts module existed: stiff soft feet (reported in the header)
        for foot in ("left_foot", "right_foot"):
            frame = wl["constraints"][foot]["frame"]
            tasks.append(
                {"type": "frame", "name": foot, "frame": frame, "mode": "pose",
                 "position_weight": 1e6, "orientation_weight": 1e6}
            )  # fmt: skip
    constraints.append({"type": "joint_limits", "gain": wl["limits"]["position"]["gain"]})
    constraints.append({"type": "velocity_limits"})
    if variant in ("B", "B+poly"):
        col = wl["collision"]
        constraints.append(
            {"type": "self_collision", "pairs": col["pairs"], "d_s": col["d_min"],
             "d_i": col["activation_distance"], "gain_per_tick": col["approach_gain"],
             "geometry": col["geometry"]}
        )  # fmt: skip
    if variant == "B+poly":
        constraints.append({"type": "support_polygon", "margin": 0.02, "gain": 1.0})
    return {
        "name": f"workload_{variant}",
        "robot": "g1",
        "dt": float(wl["dt"]),
        "strategy": {"type": "augmentation"},
        "regularization": {"type": "identity", "damping": float(np.sqrt(wl["damping"]))},
        "solver": solver,
        "tasks": tasks,
        "constraints": constraints,
    }


def sample_targets(tg: Any, wl: dict[str, Any], k: int) -> dict[str, Any]:
    """Targets of sample ``k`` (the configuration after tick k is compared with sample k)."""
    t = wl["tasks"]
    out: dict[str, Any] = {
        "pelvis": tg[f"T_{t['pelvis']['frame']}"][k],
        "torso": tg[f"T_{t['torso']['frame']}"][k][:3, :3],
        "com": tg["com"][k],
    }
    for name in ("left_hand", "right_hand", "left_elbow", "right_elbow", "head"):
        out[name] = tg[f"T_{t[name]['frame']}"][k][:3, 3]
    return out


def run_variant(
    wl: dict[str, Any], tg: Any, variant: str, solver: dict[str, Any], *, passes: int, ticks: int
) -> dict[str, Any]:
    """Warm-up + timed passes; returns timings, statuses and the last pass's trajectory."""
    ctrl = Controller(make_config(wl, variant, solver))
    q_init = np.asarray(tg["q_init"], dtype=float)
    targets = [sample_targets(tg, wl, k) for k in range(1, ticks + 1)]  # built outside timing
    col = next((c for c in ctrl.constraints if c.type_name == "self_collision"), None)
    times, col_times, statuses, walls = [], [], [], []
    q_traj = np.zeros((ticks + 1, ctrl.robot.nq))
    for p in range(passes + 1):  # pass 0 is the warm-up
        ctrl.reset(q_init)
        ctrl.task("posture").set_target(tg["q_nominal"])
        q_traj[0] = q_init
        st, ct, ss = np.zeros(ticks), np.zeros(ticks), []
        w0 = time.perf_counter()
        for k in range(ticks):
            t0 = time.perf_counter()
            res = ctrl.step(targets[k])
            st[k] = time.perf_counter() - t0
            q_traj[k + 1] = res.q
            ss.append(res.status)
            if col is not None:
                ct[k] = getattr(col, "last_time", np.nan)
        wall = time.perf_counter() - w0
        if p > 0:
            times.append(st)
            col_times.append(ct)
            walls.append(wall)
            statuses = ss
    t_all = np.concatenate(times)
    return {
        "variant": variant,
        "controller": ctrl,
        "q": q_traj,
        "median_us": float(np.median(t_all) * 1e6),
        "p95_us": float(np.percentile(t_all, 95) * 1e6),
        "p99_us": float(np.percentile(t_all, 99) * 1e6),
        "ticks_per_s": float(ticks / np.median(walls)),
        "qp_fails": int(sum(s != "ok" for s in statuses)),
        "statuses": {s: statuses.count(s) for s in set(statuses)},
        "collision_us": float(np.median(np.concatenate(col_times)) * 1e6) if col else float("nan"),
    }


def evaluate(wl: dict[str, Any], tg: Any, q: np.ndarray, robot: Any) -> dict[str, Any]:
    """The anchors' metrics from the configurations (pinocchio FK, convex-hull distances)."""
    model = robot.model
    data = model.createData()
    t = wl["tasks"]
    n = q.shape[0] - 1
    names = ("left_hand", "right_hand", "left_elbow", "right_elbow", "head", "pelvis")
    pos: dict[str, list[Any]] = {name: [] for name in names}
    rot: dict[str, list[Any]] = {"pelvis": [], "torso": []}
    com, feet = [], []
    fid = {name: model.getFrameId(t[name]["frame"]) for name in [*pos, "torso"]}
    feet_id = {f: model.getFrameId(wl["constraints"][f]["frame"]) for f in wl["constraints"]}
    for k in range(1, n + 1):
        pin.framesForwardKinematics(model, data, q[k])
        for name in pos:
            ref = tg[f"T_{t[name]['frame']}"][k][:3, 3]
            pos[name].append(np.linalg.norm(data.oMf[fid[name]].translation - ref))
        for name in rot:
            R_ref = tg[f"T_{t[name]['frame']}"][k][:3, :3]
            rot[name].append(np.linalg.norm(pin.log3(R_ref.T @ data.oMf[fid[name]].rotation)))
        c = pin.centerOfMass(model, data, q[k], False)
        com.append(np.linalg.norm(c[:2] - tg["com"][k][:2]))
        for f, i in feet_id.items():
            feet.append(
                np.linalg.norm(
                    data.oMf[i].translation - tg[f"T_{wl['constraints'][f]['frame']}"][k][:3, 3]
                )
            )

    def rmse(x: list[Any]) -> float:
        return float(np.sqrt(np.mean(np.square(x))))

    cm = CollisionModel(robot, [tuple(p) for p in wl["collision"]["pairs"]], broad_phase=False)
    state = RobotState(robot)
    dmin = wl["collision"]["d_min"]
    d = np.zeros((n, cm.n_pairs))
    for k in range(1, n + 1):
        state.update(q[k])
        d[k - 1] = cm.compute_all(state)[0]
    return {
        "hand_mm": (rmse(pos["left_hand"]) * 1e3, rmse(pos["right_hand"]) * 1e3),
        "elbow_mm": (rmse(pos["left_elbow"]) * 1e3, rmse(pos["right_elbow"]) * 1e3),
        "pelvis": (rmse(pos["pelvis"]) * 1e3, np.degrees(rmse(rot["pelvis"]))),
        "torso_deg": float(np.degrees(rmse(rot["torso"]))),
        "head_mm": rmse(pos["head"]) * 1e3,
        "com_mm": rmse(com) * 1e3,
        "feet_max_mm": float(np.max(feet) * 1e3),
        "min_pair_mm": float(d.min() * 1e3),
        "dmin_viol_ticks": int(np.sum(d.min(axis=1) < dmin - 1e-3)),
        "penetration_ticks": int(np.sum(d.min(axis=1) < 0)),
        "pair_distances": d,
    }


def reference_piece(wl: dict[str, Any], tg: Any, robot: Any) -> float:
    """Median [µs] of updateGeometryPlacements + computeDistances over the 20 hull pairs.

    On consecutive reference configurations: RESULTS-anchors.md measured 18.7 µs for this piece,
    so the ratio calibrates this run's machine load against the anchors' run.
    """
    cm = CollisionModel(robot, [tuple(p) for p in wl["collision"]["pairs"]], broad_phase=False)
    state = RobotState(robot)
    times = []
    for _ in range(2):
        for k in range(len(tg["q_ref"])):
            state.update(tg["q_ref"][k])
            t0 = time.perf_counter()
            pin.updateGeometryPlacements(robot.model, state.data, cm.gmodel, cm.gdata)
            pin.computeDistances(cm.gmodel, cm.gdata)
            times.append(time.perf_counter() - t0)
    return float(np.median(times[len(tg["q_ref"]) :]) * 1e6)


def row(r: dict[str, Any], m: dict[str, Any], label: str) -> str:
    """One markdown row in the anchors' column order."""
    return (
        f"| {r['variant']} | {label} | {r['median_us']:.0f} | {r['p95_us']:.0f} | "
        f"{r['p99_us']:.0f} | "
        f"{r['ticks_per_s']:.0f} | {r['qp_fails']} | "
        f"{m['hand_mm'][0]:.2f} / {m['hand_mm'][1]:.2f} | "
        f"{m['elbow_mm'][0]:.2f} / {m['elbow_mm'][1]:.2f} | "
        f"{m['pelvis'][0]:.2f} / {m['pelvis'][1]:.3f} | "
        f"{m['torso_deg']:.3f} | {m['head_mm']:.2f} | {m['com_mm']:.2f} | {m['feet_max_mm']:.3f} | "
        f"{m['min_pair_mm']:.1f} | {m['dmin_viol_ticks']} | "
        + ("-" if np.isnan(r["collision_us"]) else f"{r['collision_us']:.1f}")
        + " |"
    )


__all__ = [
    "COLUMNS", "VARIANTS", "default_bench_dir", "evaluate", "load_workload", "make_config",
    "reference_piece", "row", "run_variant", "sample_targets",
]  # fmt: skip
