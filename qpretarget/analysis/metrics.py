# SPDX-License-Identifier: Apache-2.0
r"""Metrics of a retargeted run, recomputed from the saved trajectory and the robot model.

Everything here is computed from a :class:`~qpretarget.trajectory.RobotTrajectory` (``q`` over
``t``, the targets, the contacts) and the robot model rebuilt from the run's YAML, never from the
controller's own bookkeeping: forward kinematics, collision distances and inverse dynamics are
recomputed with pinocchio and coal. These are the measures of DESIGN.md "Measures" and of CRAC
section 5:

* per-task RMSE against the (scaled) reference, :math:`\sqrt{\tfrac1T \sum_k |x^r_k - x(q_k)|^2}`;
* joint-limit violations per frame (CRAC Fig. 3-4, 11);
* self-collision violations per frame and the minimum distance of every collision pair over time
  (CRAC Fig. 5, 8; Dariush 2009 Fig. 11-12);
* CoM margin to the support polygon of the feet in contact;
* foot slip during support;
* joint velocity, acceleration and jerk peaks (finite differences);
* average absolute power :math:`P = \tfrac{1}{N_s} \sum_j |\tau_j^\top \dot q_j|` (CRAC eq. 43);
* solve-time statistics.

:func:`compute_series` returns the time series (:class:`MetricSeries`, used by the figures of
:mod:`qpretarget.analysis.plots`), :func:`summarize` turns them into a JSON-serializable dict and
:func:`compute_metrics` does both. The building blocks (:func:`rmse`,
:func:`joint_limit_violations`, :func:`signed_distance_to_polygon`, :func:`derivative_peaks`,
:func:`average_absolute_power`, ...) are pure functions on arrays.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..geometry2d import convex_hull_2d
from ..trajectory import RobotTrajectory
from .measures import (
    DEFAULT_SAFETY_DISTANCE,
    JOINT_LIMIT_TOLERANCE,
    MetricsError,
    average_absolute_power,
    carry_base_wrench,
    derivative_peaks,
    instantaneous_power,
    interval_derivatives,
    joint_limit_violations,
    rmse,
    rnea_torques,
    signed_distance_to_polygon,
    solve_time_stats,
    tangent_velocities,
)
from .pair_distances import (
    DEFAULT_PAIRS,
    GeometryPairDistances,
    LinkPairDistances,
    collision_model_for,
)
from .series import MetricSeries, compute_series

#: Version tag written in ``metrics.json``.
METRICS_FORMAT = "qpretarget.analysis.metrics/1"

__all__ = [
    "DEFAULT_PAIRS",
    "DEFAULT_SAFETY_DISTANCE",
    "JOINT_LIMIT_TOLERANCE",
    "METRICS_FORMAT",
    "PER_FRAME_PAIRS",
    "GeometryPairDistances",
    "LinkPairDistances",
    "MetricSeries",
    "MetricsError",
    "average_absolute_power",
    "carry_base_wrench",
    "collision_model_for",
    "compute_metrics",
    "compute_series",
    "convex_hull_2d",
    "derivative_peaks",
    "dumps",
    "instantaneous_power",
    "interval_derivatives",
    "joint_limit_violations",
    "rmse",
    "rnea_torques",
    "signed_distance_to_polygon",
    "solve_time_stats",
    "summarize",
    "tangent_velocities",
]


def _f(x: Any) -> float | None:
    """A JSON-safe float (``None`` for NaN/inf)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _list(a: np.ndarray, digits: int = 6) -> list:
    """A JSON-safe list of a numeric array (NaN -> None), rounded to ``digits`` decimals."""
    a = np.asarray(a)
    if a.dtype.kind in "biu":
        return a.tolist()
    r = np.round(a.astype(float), digits)
    return (
        [None if not math.isfinite(v) else v for v in r.ravel().tolist()]
        if r.ndim == 1
        else [_list(row, digits) for row in r]
    )


def _peak(values: np.ndarray, names: Sequence[str]) -> dict[str, Any]:
    if values.size == 0 or not np.any(np.isfinite(values)):
        return {"value": None, "joint": None}
    j = int(np.nanargmax(values))
    return {"value": _f(values[j]), "joint": names[j]}


#: Number of pairs whose distance over time goes into ``per_frame`` (the closest ones).
PER_FRAME_PAIRS = 16


def _closest_pairs(s: MetricSeries, n: int = PER_FRAME_PAIRS) -> list[int]:
    """Indices of the ``n`` pairs that come closest, in pair order."""
    if s.pair_distance.size == 0:
        return []
    mins = np.nanmin(np.where(np.isfinite(s.pair_distance), s.pair_distance, np.inf), axis=0)
    return sorted(np.argsort(mins, kind="stable")[:n].tolist())


def summarize(series: MetricSeries, *, per_frame: bool = True) -> dict[str, Any]:
    """JSON-serializable summary of a run's metrics (the content of ``metrics.json``).

    Args:
        series: from :func:`compute_series`.
        per_frame: include the per-frame arrays (violation counts, distances of the
            :data:`PER_FRAME_PAIRS` closest pairs, CoM margin, foot slip, power) under
            ``"per_frame"``.

    Returns:
        A dict of plain Python types; units are in the key names (``_m``, ``_rad``, ``_W``...).
    """
    s = series
    T = len(s.t)
    tracking = _tracking(s)
    rmses = [v["rmse_m"] for v in tracking.values() if v["rmse_m"] is not None]
    jl_per_frame = s.joint_violations_per_frame
    col = s.collision_violations_per_frame
    total = jl_per_frame + col
    status = {}
    if s.status is not None:
        vals, counts = np.unique(s.status, return_counts=True)
        status = {str(v): int(c) for v, c in zip(vals, counts, strict=True)}
    out: dict[str, Any] = {
        "format": METRICS_FORMAT,
        "run": {
            "robot": s.robot,
            "config": s.config_name,
            "samples": T,
            "duration_s": _f(s.t[-1] - s.t[0]) if T else 0.0,
            "dt_s": _f(np.median(np.diff(s.t))) if T > 1 else None,
        },
        "tracking": tracking,
        "tracking_rmse_mean_m": _f(np.mean(rmses)) if rmses else None,
        "joint_limits": _joint_limits(s),
        "self_collision": _self_collision(s),
        "violations": {
            "total_per_frame_mean": _f(total.mean()),
            "total_per_frame_max": int(total.max(initial=0)),
            "frames_with_violation": int(np.sum(total > 0)),
        },
        "support": _support(s),
        "foot_slip": _slip(s),
        "joint_motion": _joint_motion(s),
        "power": _power(s),
        "solve_time": solve_time_stats(s.solve_time),
        "status": status,
    }
    if per_frame:
        out["per_frame"] = {
            "t_s": _list(s.t),
            "joint_limit_violations": _list(jl_per_frame),
            "self_collision_violations": _list(col),
            "below_safety": _list(s.below_safety_per_frame),
            "pair_distance_m": {
                s.pair_names[p]: _list(s.pair_distance[:, p]) for p in _closest_pairs(s)
            },
            "com_margin_m": _list(s.com_margin),
            "foot_slip_m": {f: _list(s.foot_slip[f]) for f in s.foot_names},
            "power_W": _list(s.power),
            "power_t_s": _list(s.t[s.power_index]),
        }
    return out


def _tracking(s: MetricSeries) -> dict[str, dict[str, Any]]:
    """Per position task: RMSE (:func:`rmse`), per-axis RMSE, max error, frames without data."""
    tracking = {}
    for name in s.reached:
        ref, act = s.targets[name], s.reached[name]
        err = np.linalg.norm(ref - act, axis=1)
        axis = [rmse(ref[:, i : i + 1], act[:, i : i + 1]) for i in range(3)]
        entry: dict[str, Any] = {
            "rmse_m": _f(rmse(ref, act)),
            "rmse_xyz_m": [_f(x) for x in axis],
            "max_error_m": _f(np.nanmax(err)) if np.any(np.isfinite(err)) else None,
            "missing_frames": int(np.sum(~np.all(np.isfinite(ref), axis=1))),
        }
        if name in s.recorded and s.recorded[name].shape == act.shape:
            entry["recorded_vs_fk_max_m"] = _f(np.max(np.abs(s.recorded[name] - act)))
        tracking[name] = entry
    return tracking


def _joint_limits(s: MetricSeries) -> dict[str, Any]:
    """Joint-limit violations (:func:`joint_limit_violations`) and the joint closest to a limit."""
    jl_per_frame = s.joint_violations_per_frame
    per_joint = {
        s.joint_names[j]: int(c) for j, c in enumerate(s.joint_violation.sum(axis=0)) if c > 0
    }
    ranges = s.q_max - s.q_min
    margin = np.minimum(np.min(s.q_joints - s.q_min, axis=0), np.min(s.q_max - s.q_joints, axis=0))
    finite = np.isfinite(margin) & np.isfinite(ranges)
    closest = (
        {"joint": s.joint_names[int(np.argmin(np.where(finite, margin, np.inf)))],
         "margin_rad": _f(np.min(margin[finite]))}
        if finite.any() else {"joint": None, "margin_rad": None}
    )  # fmt: skip
    return {
        "tolerance_rad": s.joint_limit_tolerance,
        "total_violations": int(jl_per_frame.sum()),
        "frames_with_violation": int(np.sum(jl_per_frame > 0)),
        "mean_per_frame": _f(jl_per_frame.mean()),
        "max_per_frame": int(jl_per_frame.max(initial=0)),
        "max_violation_rad": _f(s.joint_violation_amount.max(initial=0.0)),
        "per_joint": per_joint,
        "closest_to_limit": closest,
    }


def _self_collision(s: MetricSeries) -> dict[str, Any]:
    """Pairs in collision per frame, frames below the safety distance, minimum distances."""
    col = s.collision_violations_per_frame
    below = s.below_safety_per_frame
    min_dist = {}
    for p, name in enumerate(s.pair_names):
        d = s.pair_distance[:, p]
        k = int(np.nanargmin(d)) if np.any(np.isfinite(d)) else 0
        min_dist[name] = {"min_m": _f(d[k]) if d.size else None, "at_s": _f(s.t[k])}
    overall = (
        _f(np.nanmin(s.pair_distance))
        if s.pair_distance.size and np.any(np.isfinite(s.pair_distance))
        else None
    )
    return {
        "pairs": list(s.pair_names),
        "safety_distance_m": s.safety_distance,
        "total_violations": int(col.sum()),
        "frames_with_violation": int(np.sum(col > 0)),
        "mean_per_frame": _f(col.mean()) if len(s.t) else None,
        "max_per_frame": int(col.max(initial=0)),
        "frames_below_safety": int(np.sum(below > 0)),
        "min_distance_m": overall,
        "min_distance_per_pair": min_dist,
    }


def _support(s: MetricSeries) -> dict[str, Any]:
    """CoM margin to the support polygon (:func:`signed_distance_to_polygon`)."""
    cm = s.com_margin
    finite = bool(np.any(np.isfinite(cm)))
    return {
        "contacts_assumed": s.contacts_assumed,
        "feet": list(s.foot_names),
        "min_com_margin_m": _f(np.nanmin(cm)) if finite else None,
        "mean_com_margin_m": _f(np.nanmean(cm)) if finite else None,
        "frames_com_outside": int(np.sum(cm < 0)),
        "frames_without_support": int(np.sum(~np.isfinite(cm))),
    }


def _slip(s: MetricSeries) -> dict[str, dict[str, Any]]:
    """Per foot: frames in contact, largest horizontal slip and vertical motion in support."""
    slip = {}
    for f in s.foot_names:
        d, z = s.foot_slip[f], s.foot_lift[f]
        on = np.isfinite(d)
        slip[f] = {
            "frames_in_contact": int(on.sum()),
            "max_slip_m": _f(np.max(d[on])) if on.any() else None,
            "max_vertical_m": _f(np.max(z[on])) if on.any() else None,
        }
    return slip


def _joint_motion(s: MetricSeries) -> dict[str, Any]:
    """Velocity, acceleration and jerk peaks (:func:`derivative_peaks`), per joint and overall."""
    names = s.joint_names
    return {
        "velocity_peak_rad_s": _peak(s.peaks["velocity"], names),
        "acceleration_peak_rad_s2": _peak(s.peaks["acceleration"], names),
        "jerk_peak_rad_s3": _peak(s.peaks["jerk"], names),
        "per_joint": {
            n: {
                "velocity_rad_s": _f(s.peaks["velocity"][j]),
                "acceleration_rad_s2": _f(s.peaks["acceleration"][j]),
                "jerk_rad_s3": _f(s.peaks["jerk"][j]),
            }
            for j, n in enumerate(names)
        },
        "joints_over_velocity_limit": [
            names[j] for j in np.flatnonzero(s.peaks["velocity"] > s.v_max * (1 + 1e-6))
        ],
    }


def _power(s: MetricSeries) -> dict[str, Any]:
    """Average absolute power (CRAC eq. 43), with the feet carrying the base and base held."""
    has = bool(s.power.size)
    return {
        "mean_abs_power_W": _f(np.mean(s.power)) if has else None,
        "mean_abs_power_base_held_W": _f(np.mean(s.power_base_held)) if has else None,
        "peak_power_W": _f(np.max(s.power)) if has else None,
        "source": s.power_source,
        "contact_forces": "minimum-norm wrenches of the feet in support",
        "samples": int(s.power.size),
    }


def compute_metrics(
    traj: RobotTrajectory, *, per_frame: bool = True, **kwargs: Any
) -> dict[str, Any]:
    """Every metric of a run as a JSON-serializable dict (compute_series + summarize).

    Args:
        traj: the run.
        per_frame: include per-frame arrays.
        **kwargs: options of :func:`compute_series` (``controller``, ``pairs``, ...).
    """
    return summarize(compute_series(traj, **kwargs), per_frame=per_frame)


def dumps(metrics: Mapping[str, Any]) -> str:
    """``metrics.json`` text (strict JSON: no NaN)."""
    return json.dumps(metrics, indent=1, allow_nan=False)
