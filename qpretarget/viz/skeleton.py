# SPDX-License-Identifier: Apache-2.0
"""Human key-point skeleton: the bones between key-points, placed beside the robot."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

#: Bones between key-points (Dariush 2009 Fig. 2 plus legs), drawn where both ends exist.
BONES: tuple[tuple[str, str], ...] = (
    ("waist", "neck"), ("neck", "head"),
    ("neck", "left_shoulder"), ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"),
    ("left_wrist", "left_hand"),
    ("neck", "right_shoulder"), ("right_shoulder", "right_elbow"), ("right_elbow", "right_wrist"),
    ("right_wrist", "right_hand"),
    ("waist", "left_hip"), ("left_hip", "left_knee"), ("left_knee", "left_ankle"),
    ("left_ankle", "left_toe"),
    ("waist", "right_hip"), ("right_hip", "right_knee"), ("right_knee", "right_ankle"),
    ("right_ankle", "right_toe"),
    ("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"),
)  # fmt: skip


def skeleton_segments(points: dict[str, np.ndarray], frame: int) -> np.ndarray:
    """(S, 2, 3) bone segments of one frame (bones with a missing end are left out)."""
    segs = []
    for a, b in BONES:
        if a in points and b in points:
            pa, pb = points[a][frame], points[b][frame]
            if np.all(np.isfinite(pa)) and np.all(np.isfinite(pb)):
                segs.append((pa, pb))
    return np.array(segs).reshape(-1, 2, 3)


def place_beside(
    points: dict[str, np.ndarray], robot_base_xy: np.ndarray, robot_heading: float, gap: float = 1.0
) -> dict[str, np.ndarray]:
    """Rigidly move the human so it stands ``gap`` metres to the robot's left, same heading.

    The human's heading is taken from its first frame (shoulder or hip line, whichever exists);
    its floor is its lowest point over the clip.
    """
    pts = {k: np.asarray(v, dtype=float) for k, v in points.items()}
    heading = 0.0
    for a, b in (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip")):
        if a in pts and b in pts:
            d = pts[a][0] - pts[b][0]
            if np.all(np.isfinite(d)):
                heading = float(np.arctan2(d[1], d[0]) - np.pi / 2)  # left points +y at heading 0
                break
    all_pts = np.concatenate([v for v in pts.values()], axis=0)
    floor = float(np.nanmin(all_pts[:, 2])) if np.isfinite(all_pts[:, 2]).any() else 0.0
    ref = pts.get("waist", next(iter(pts.values())))[0]
    ref = np.where(np.isfinite(ref), ref, 0.0)
    c, s = np.cos(robot_heading - heading), np.sin(robot_heading - heading)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    left = np.array([-np.sin(robot_heading), np.cos(robot_heading), 0.0])
    target = np.array([robot_base_xy[0], robot_base_xy[1], 0.0]) + gap * left
    out = {}
    for k, v in pts.items():
        w = (v - np.array([ref[0], ref[1], floor])) @ R.T
        out[k] = w + target
    return out


def beside_robot(
    human: Mapping[str, Any], q0: np.ndarray, free_flyer: bool
) -> dict[str, np.ndarray]:
    """The ``(T, 3)`` key-point tracks of ``human`` placed beside a robot at configuration ``q0``.

    The robot's base position and heading (yaw of its base x axis) come from ``q0`` when it has a
    free flyer, else the origin and heading 0; see :func:`place_beside`. Entries that are not
    ``(T, 3)`` tracks are left out; ``{}`` when none is.
    """
    pts = {k: np.asarray(v) for k, v in human.items() if np.ndim(v) == 2 and np.shape(v)[1] == 3}
    if not pts:
        return {}
    base = q0[:2] if free_flyer else np.zeros(2)
    yaw = 0.0
    if free_flyer:
        R0 = pin.Quaternion(q0[3:7]).toRotationMatrix()
        yaw = float(np.arctan2(R0[1, 0], R0[0, 0]))
    return place_beside(pts, base, yaw)


def human_samples(human: Mapping[str, Any], t: np.ndarray) -> np.ndarray:
    """Index of the human sample to show with each robot sample of times ``t`` [s].

    The run's ``human`` tracks are at the capture rate and the robot at the control rate (a
    120 Hz clip run at 100 Hz, a 30 Hz one at 100 Hz): the human sample nearest in time on the
    motion's clock (``human["t"]``). Without ``human["t"]``, the sample of the same index,
    clamped to the last.
    """
    t = np.asarray(t, float)
    th = human.get("t")
    if th is None or np.ndim(th) != 1 or len(th) == 0:
        tracks = [np.asarray(v) for v in human.values() if np.ndim(v) == 2]
        n = len(tracks[0]) if tracks else 1
        return np.minimum(np.arange(len(t)), n - 1)
    th = np.asarray(th, float)
    i = np.clip(np.searchsorted(th, t), 1, max(len(th) - 1, 1))
    before = np.abs(t - th[i - 1]) <= np.abs(th[np.minimum(i, len(th) - 1)] - t)
    return np.where(before | (len(th) == 1), i - 1, i).astype(int)
