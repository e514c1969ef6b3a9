# SPDX-License-Identifier: Apache-2.0
"""Metrics of a physics replay (docs/physics.md, "Metrics").

One definition each, used by the CLI, the batch summary, the docs' tables and the tests.

Over the frames simulated (the unassisted replay stops at the first fallen frame):

* **fallen** at frame k when the pelvis is more than :data:`FALL_HEIGHT_M` below the reference's,
  or the torso's vertical axis is more than :data:`FALL_TILT_DEG` away from the reference torso's
  (BeyondMimic ends a tracking episode at a 0.25 m anchor-height error and a gravity-direction
  error of 0.8, about 47 deg); **survived** = frames before the first fallen frame / frames;
* **root error**: ``|p - p_ref|`` [mm] and the angle of ``R' R_ref`` [deg] of the floating base;
* **joint tracking**: ``q - q_ref`` per joint; per frame the RMS over joints; reported in deg;
* **saturation**: frames in which any joint's PD torque (replay eq. 1) reached its URDF effort
  limit, as a count and a fraction of the frames simulated;
* **feet share**: in the reference's stance frames (a foot supporting in the run's ``contacts``;
  every frame when the run has none), the normal floor force on the feet divided by the body
  weight ``m g``; ``contact_match`` the fraction of (frame, foot) where the simulated foot carries
  more than :data:`FOOT_LOADED_BW` of the weight exactly when the run says it supports;
* **assist**: in the assisted replay, the norm of the virtual root force as % of body weight
  (mean, p95, max; also its horizontal part) and of the root torque [N m], also as the lever
  ``|n| / (m g)`` [mm] — how far the centre of pressure would have to move outside what the feet
  gave.

Diagnostic (kinematic, from the run alone): ``reference_zmp`` — stance frames in which the
reference's ZMP lies outside the stance soles (:mod:`~qpretarget.physics.zmp`), the first such
time and whether it came before the fall.

Verdict: ``falls`` (survived < 1), else ``saturates`` (more than :data:`SATURATION_FRAMES_MAX` of
the frames saturated), else ``ok``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

#: Fall when the pelvis is this far below the reference pelvis [m].
FALL_HEIGHT_M = 0.25
#: Fall when the torso's vertical axis is this far from the reference torso's [deg].
FALL_TILT_DEG = 45.0
#: A foot is loaded when it carries more than this fraction of the body weight.
FOOT_LOADED_BW = 0.05
#: Verdict ``saturates`` above this fraction of saturated frames.
SATURATION_FRAMES_MAX = 0.05


def _f(x: Any) -> float | None:
    """A float for JSON (``None`` for NaN/inf)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _stats(a: np.ndarray, scale: float = 1.0) -> dict[str, float | None]:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)] * scale
    if a.size == 0:
        return {"mean": None, "p95": None, "max": None}
    return {
        "mean": _f(a.mean()),
        "p95": _f(np.percentile(a, 95)),
        "max": _f(a.max()),
    }


def survived_fraction(series: Any) -> float:
    """Frames before the first fallen frame over all frames (1.0: never fell)."""
    T = len(series.t)
    return 1.0 if series.fallen_at is None else series.fallen_at / T


def joint_rms_per_frame(series: Any) -> np.ndarray:
    """RMS over joints of ``q - q_ref`` per frame [rad] (NaN where not simulated)."""
    return np.sqrt(np.mean(series.joint_err**2, axis=1))


def feet_share_per_frame(series: Any) -> np.ndarray:
    """Normal floor force on the feet over the body weight, per frame (NaN where not simulated)."""
    return np.sum(series.foot_force, axis=1) / series.weight


def stance_frames(series: Any) -> np.ndarray:
    """Simulated frames (after the first) in which the reference has a supporting foot."""
    idx = np.arange(1, series.simulated)
    return idx[series.ref_contacts[idx].any(axis=1)]


def _replay_block(s: Any) -> dict[str, Any]:
    sim = slice(1, s.simulated)
    n_sim = max(1, s.simulated - 1)
    rms = joint_rms_per_frame(s)
    per_joint_rms = np.sqrt(np.nanmean(s.joint_err[sim] ** 2, axis=0)) if s.simulated > 1 else []
    sat_frames = int(np.count_nonzero(s.saturated[sim].any(axis=1)))
    sat_joint = {
        s.joint_names[i]: int(c)
        for i, c in enumerate(np.count_nonzero(s.saturated[sim], axis=0))
        if c
    }
    stance = stance_frames(s)
    share = feet_share_per_frame(s)[stance]
    loaded = s.foot_force[stance] > FOOT_LOADED_BW * s.weight
    match = float(np.mean(loaded == s.ref_contacts[stance])) if len(stance) else math.nan
    worst = int(np.argmax(per_joint_rms)) if len(per_joint_rms) else -1
    block: dict[str, Any] = {
        "survived_fraction": survived_fraction(s),
        "fallen": s.fallen_at is not None,
        "fallen_at_s": None if s.fallen_at is None else _f(s.t[s.fallen_at] - s.t[0]),
        "frames": len(s.t),
        "frames_simulated": int(s.simulated),
        "root_position_error_mm": _stats(s.root_pos_err[sim], 1e3),
        "root_orientation_error_deg": _stats(s.root_ori_err_deg[sim]),
        "joint_tracking_rms_deg": {
            "overall": _f(math.degrees(math.sqrt(np.nanmean(s.joint_err[sim] ** 2))))
            if s.simulated > 1
            else None,
            "per_frame": _stats(np.degrees(rms[sim])),
            "max_abs": _f(np.degrees(np.nanmax(np.abs(s.joint_err[sim]))))
            if s.simulated > 1
            else None,
            "worst_joint": s.joint_names[worst] if worst >= 0 else None,
            "worst_joint_rms": _f(np.degrees(per_joint_rms[worst])) if worst >= 0 else None,
        },
        "saturation": {
            "frames": sat_frames,
            "fraction": sat_frames / n_sim,
            "per_joint_frames": dict(sorted(sat_joint.items(), key=lambda kv: -kv[1])),
        },
        "feet": {
            "stance_frames": len(stance),
            "contacts_assumed": bool(s.contacts_assumed),
            "weight_share_mean": _f(np.mean(share)) if len(share) else None,
            "weight_share_p5": _f(np.percentile(share, 5)) if len(share) else None,
            "weight_share_min": _f(np.min(share)) if len(share) else None,
            "contact_match": _f(match),
            "other_body_force_max_bw": _f(np.nanmax(s.other_force[sim]) / s.weight)
            if s.simulated > 1
            else None,
        },
        "pelvis_height_min_m": _f(np.nanmin(s.pelvis_height[: s.simulated])),
        "tilt_max_deg": _f(np.nanmax(s.tilt_deg[: s.simulated])),
        "wall_time_s": _f(s.wall_time_s),
        "sim_time_s": _f(s.sim_time_s),
        "real_time_factor": _f(s.sim_time_s / s.wall_time_s) if s.wall_time_s > 0 else None,
    }
    if s.assisted:
        f = s.assist_force[sim] / s.weight * 100.0
        n = s.assist_torque[sim]
        block["assist"] = {
            "force_bw_pct": _stats(f),
            "horizontal_force_bw_pct": _stats(s.assist_horizontal[sim] / s.weight * 100.0),
            "torque_Nm": _stats(n),
            "torque_lever_mm": _stats(n / s.weight, 1e3),
        }
    return block


def verdict(block: dict[str, Any]) -> str:
    """``falls``, ``saturates`` or ``ok`` from an unassisted replay block."""
    if block["survived_fraction"] < 1.0:
        return "falls"
    if block["saturation"]["fraction"] > SATURATION_FRAMES_MAX:
        return "saturates"
    return "ok"


def zmp_block(margin: np.ndarray, t: np.ndarray, fallen_at: int | None) -> dict[str, Any]:
    """Reference ZMP summary: stance frames with the ZMP outside the soles, first such time."""
    ok = np.isfinite(margin)
    outside = ok & (margin < 0.0)
    first = int(np.argmax(outside)) if outside.any() else None
    return {
        "stance_frames": int(ok.sum()),
        "frames_outside": int(outside.sum()),
        "first_outside_s": None if first is None else _f(t[first] - t[0]),
        "min_margin_mm": _f(np.min(margin[ok]) * 1e3) if ok.any() else None,
        "outside_before_fall": None
        if fallen_at is None
        else bool(first is not None and first <= fallen_at),
    }


def summarize(
    free: Any,
    assisted: Any | None,
    pm: Any,
    *,
    per_frame: bool = False,
) -> dict[str, Any]:
    """The metrics of an unassisted replay and, optionally, an assisted one.

    Args:
        free: :class:`~qpretarget.physics.replay.ReplaySeries` without assistance.
        assisted: the same run replayed with the virtual root wrench, or ``None``.
        pm: the :class:`~qpretarget.physics.model.PhysicsModel` (its assumptions are recorded).
        per_frame: add the per-frame series (lists, ``null`` where not simulated).

    The unassisted series' ``ref_zmp_margin`` (set by
    :func:`~qpretarget.physics.replay.check_run`), when present, is summarized as
    ``reference_zmp`` (a kinematic diagnostic of the run, not simulated).
    """
    out: dict[str, Any] = {
        "thresholds": {
            "fall_height_m": FALL_HEIGHT_M,
            "fall_tilt_deg": FALL_TILT_DEG,
            "foot_loaded_bw": FOOT_LOADED_BW,
            "saturation_frames_max": SATURATION_FRAMES_MAX,
        },
        "model": pm.describe(),
        "floor_height_m": _f(free.floor_height),
        "unassisted": _replay_block(free),
    }
    out["verdict"] = verdict(out["unassisted"])
    if assisted is not None:
        out["assisted"] = _replay_block(assisted)
    zmp_margin = getattr(free, "ref_zmp_margin", None)
    if zmp_margin is not None:
        out["reference_zmp"] = zmp_block(np.asarray(zmp_margin, float), free.t, free.fallen_at)
    if per_frame:
        out["per_frame"] = per_frame_series(free, assisted)
    return out


def per_frame_series(free: Any, assisted: Any | None) -> dict[str, Any]:
    """Per-frame lists of the metrics (``null`` where a replay did not simulate the frame)."""

    def lst(a: np.ndarray, scale: float = 1.0) -> list[float | None]:
        return [_f(x * scale) for x in np.asarray(a, float)]

    out: dict[str, Any] = {
        "t": lst(free.t),
        "pelvis_height_m": lst(free.pelvis_height),
        "pelvis_height_ref_m": lst(free.pelvis_height_ref),
        "tilt_deg": lst(free.tilt_deg),
        "root_position_error_mm": lst(free.root_pos_err, 1e3),
        "root_orientation_error_deg": lst(free.root_ori_err_deg),
        "joint_tracking_rms_deg": lst(np.degrees(joint_rms_per_frame(free))),
        "saturated_joints": [int(x) for x in np.count_nonzero(free.saturated, axis=1)],
        "feet_weight_share": lst(feet_share_per_frame(free)),
    }
    zmp_margin = getattr(free, "ref_zmp_margin", None)
    if zmp_margin is not None:
        out["reference_zmp_margin_mm"] = lst(zmp_margin, 1e3)
    if assisted is not None:
        out["assisted_force_bw_pct"] = lst(assisted.assist_force / assisted.weight * 100.0)
        out["assisted_torque_Nm"] = lst(assisted.assist_torque)
        out["assisted_feet_weight_share"] = lst(feet_share_per_frame(assisted))
    return out


def dumps(metrics: dict[str, Any]) -> str:
    """Strict JSON text of the metrics (no NaN)."""
    return json.dumps(metrics, indent=1, allow_nan=False)


#: Columns of the batch summary (``physics/<column>``) and where each comes from.
SUMMARY_COLUMNS = (
    "verdict", "survived", "saturated_frames", "root_pos_p95_mm", "joint_rms_deg",
    "feet_share", "assist_force_p95_bw_pct", "assist_horizontal_p95_bw_pct", "assist_torque_p95_Nm",
    "real_time_factor",
)  # fmt: skip


def summary_row(metrics: dict[str, Any]) -> dict[str, Any]:
    """The batch-summary columns (:data:`SUMMARY_COLUMNS`) of one clip's physics metrics."""
    u = metrics["unassisted"]
    a = metrics.get("assisted") or {}
    assist = a.get("assist", {})

    def num(x: Any) -> float:
        return math.nan if x is None else float(x)

    return {
        "verdict": metrics["verdict"],
        "survived": u["survived_fraction"],
        "saturated_frames": u["saturation"]["frames"],
        "root_pos_p95_mm": num(u["root_position_error_mm"]["p95"]),
        "joint_rms_deg": num(u["joint_tracking_rms_deg"]["overall"]),
        "feet_share": num(u["feet"]["weight_share_mean"]),
        "assist_force_p95_bw_pct": num(assist.get("force_bw_pct", {}).get("p95")),
        "assist_horizontal_p95_bw_pct": num(assist.get("horizontal_force_bw_pct", {}).get("p95")),
        "assist_torque_p95_Nm": num(assist.get("torque_Nm", {}).get("p95")),
        "real_time_factor": num(u["real_time_factor"]),
    }
