# SPDX-License-Identifier: Apache-2.0
"""The run summary printed by ``qpretarget retarget`` and ``qpretarget demo``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from ..analysis.human_metrics import format_human_metrics, human_metrics_or_reason
from ..analysis.measures import (
    JOINT_LIMIT_TOLERANCE,
    joint_limit_violations,
    rmse,
    support_displacement,
)
from ..control.controller import Controller
from ..trajectory import RobotTrajectory


def summarize_run(
    traj: RobotTrajectory, controller: Controller, *, wall_time: float | None = None
) -> dict[str, Any]:
    """Per-task RMSE, joint-limit violations, feet drift during contact and timing of a run.

    Args:
        traj: The run.
        controller: The controller that produced it (robot model, limits, feet).
        wall_time: Seconds the run took (for ticks per second).

    Returns:
        A JSON-serializable dict: ``duration`` [s], ``ticks``, ``ticks_per_second``,
        ``rmse_mm`` (position tasks), ``joint_limit_violations`` (samples x joints outside the
        limits by more than 1e-6 rad), ``feet_drift_mm`` (largest displacement of a sole during
        one of its contact intervals), ``status`` counts, ``phases`` (support-state intervals),
        ``human`` (:func:`~qpretarget.analysis.human_metrics.human_metrics`, the same numbers
        as ``qpretarget evaluate``; ``human_unavailable`` says why when the run has no person).
    """
    robot = controller.robot
    q = np.asarray(traj.q, float)
    T = len(traj.t)
    out: dict[str, Any] = {
        "duration": float(traj.t[-1] - traj.t[0]) if T > 1 else 0.0,
        "ticks": T,
    }
    if wall_time:
        out["ticks_per_second"] = T / wall_time
        out["wall_time"] = wall_time
    out["rmse_mm"] = _task_rmse_mm(traj)
    out.update(_limit_violations(robot, q))
    out["feet_drift_mm"] = _feet_drift_mm(robot, traj, q)
    statuses, counts = np.unique(np.asarray(traj.status, dtype=str), return_counts=True)
    out["status"] = {str(s): int(c) for s, c in zip(statuses, counts, strict=True)}
    relaxed_by = traj.meta.get("relaxed_by")
    if relaxed_by:  # what gave on the relaxed ticks (StepResult.relaxed), ticks per constraint
        out["relaxed_by"] = {str(k): int(v) for k, v in dict(relaxed_by).items()}
    support = traj.extra.get("support_state")
    if support is not None and len(support) and str(support[0]):
        changes = [0] + [k for k in range(1, T) if support[k] != support[k - 1]]
        out["support_states"] = [(float(traj.t[k]), str(support[k])) for k in changes]
    from ..analysis.mesh_audit import audit_run  # every body pair on the meshes (one definition)

    audit = audit_run(q, robot)
    if audit is not None:
        out["mesh_self_collision"] = audit.to_dict(n_worst=3)
    human, reason = human_metrics_or_reason(traj, robot)
    if human is not None:
        out["human"] = human
    else:
        out["human_unavailable"] = reason
    if traj.solve_time is not None:
        st = np.asarray(traj.solve_time, float)
        out["solve_time_ms"] = {
            "median": float(np.median(st)) * 1e3,
            "p95": float(np.percentile(st, 95)) * 1e3,
        }
    return out


def _task_rmse_mm(traj: RobotTrajectory) -> dict[str, float]:
    """Per position task, :func:`~qpretarget.analysis.measures.rmse` of the run [mm]."""
    out = {}
    for name in traj.task_names:
        tgt = np.asarray(traj.targets[name], float)
        act = np.asarray(traj.actual[name], float)
        if np.all(np.isfinite(tgt), axis=1).any():
            out[name] = rmse(tgt, act) * 1e3
    return out


def _limit_violations(robot: Any, q: np.ndarray) -> dict[str, Any]:
    """Samples x joints outside the limits, and the worst joint.

    One definition: :func:`~qpretarget.analysis.measures.joint_limit_violations`.
    """
    qi = robot.joint_q_index
    viol, amount = joint_limit_violations(
        q[:, qi], robot.q_min[qi], robot.q_max[qi], tolerance=JOINT_LIMIT_TOLERANCE
    )
    out: dict[str, Any] = {"joint_limit_violations": int(viol.sum())}
    if viol.any():
        out["worst_joint"] = robot.joint_names[int(np.argmax(np.max(amount, axis=0)))]
    return out


def _feet_drift_mm(robot: Any, traj: RobotTrajectory, q: np.ndarray) -> dict[str, float]:
    """Largest displacement of each sole within one of its contact intervals [mm].

    The horizontal and vertical parts are :func:`~qpretarget.analysis.measures.support_displacement`
    (evaluate's foot slip and lift); the drift is their norm.
    """
    if traj.contacts is None or not np.asarray(traj.contacts).size:
        return {}
    model, data = robot.model, robot.model.createData()
    contacts = np.asarray(traj.contacts, bool)
    ids = [robot.frame_id(robot.feet[f].frame) if f in robot.feet else robot.frame_id(f)
           for f in traj.foot_names]  # fmt: skip
    soles = np.empty((len(q), len(ids), 3))
    for k in range(len(q)):
        pin.framesForwardKinematics(model, data, q[k])
        for i, fid in enumerate(ids):
            soles[k, i] = data.oMf[fid].translation
    drift = {}
    for i, name in enumerate(traj.foot_names):
        h, v = support_displacement(soles[:, i], contacts[:, i])
        d = np.hypot(h, v)
        drift[name] = float(np.nanmax(d)) * 1e3 if np.isfinite(d).any() else 0.0
    return drift


def format_summary(summary: Mapping[str, Any], *, title: str = "") -> str:
    """Readable text of :func:`summarize_run`'s dict."""
    lines = []
    if title:
        lines.append(title)
    tps = summary.get("ticks_per_second")
    speed = f", {tps:.0f} ticks/s" if tps else ""
    lines.append(f"duration     {summary['duration']:.2f} s, {summary['ticks']} ticks{speed}")
    if "solve_time_ms" in summary:
        s = summary["solve_time_ms"]
        lines.append(f"QP solve     median {s['median']:.3f} ms, p95 {s['p95']:.3f} ms")
    lines.append("tracking RMSE per task (target vs reached):")
    for name, v in summary["rmse_mm"].items():
        lines.append(f"  {name:16s} {v:8.1f} mm")
    viol = summary["joint_limit_violations"]
    lines.append(
        f"joint limits {viol} violation(s)"
        + (f" (worst joint {summary['worst_joint']})" if viol else "")
    )
    if summary.get("feet_drift_mm"):
        drift = ", ".join(f"{k} {v:.3f} mm" for k, v in summary["feet_drift_mm"].items())
        lines.append(f"feet drift   {drift} (largest sole motion while in contact)")
    if "mesh_self_collision" in summary:
        from ..analysis.mesh_audit import audit_lines

        audit = audit_lines(summary["mesh_self_collision"])
        lines += [f"{'self-collision' if i == 0 else '':12s} {x}" for i, x in enumerate(audit)]
    st = summary.get("status", {})
    lines.append("ticks        " + ", ".join(f"{k} {v}" for k, v in st.items()))
    if summary.get("relaxed_by"):
        gave = ", ".join(f"{k} {v}" for k, v in summary["relaxed_by"].items())
        lines.append(f"relaxed      ticks on which a constraint gave: {gave}")
    phases = summary.get("support_states")
    if phases:
        # Static mode: the lower_<side> sequences; kinematic mode: feet entering "landing"
        # (support_state "left-state/right-state").
        steps = sum(1 for _, s in phases if s.startswith("lower_"))
        previous = ["stance", "stance"]
        for _, s in phases:
            states = s.split("/")
            if len(states) == 2:
                steps += sum(a == "landing" != b for a, b in zip(states, previous, strict=True))
                previous = states
        lines.append(f"support      {len(phases)} state changes, {steps} step(s) placed")
    if "human" in summary:
        lines += format_human_metrics(summary["human"])
    return "\n".join(lines)
