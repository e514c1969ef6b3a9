# SPDX-License-Identifier: Apache-2.0
r"""Calibration of a human motion to a robot: heading and position alignment, segment lengths.

Nothing here is hand-tuned per clip. A :class:`Calibration` is computed once, from the first
samples of the motion (a rest pose or the first frames) and from the robot model in its reference
posture:

* **Heading.** The human's initial heading :math:`\psi_h` is the yaw of the waist frame's x axis
  when the motion has orientations, else the yaw of :math:`\hat y \times \hat z` with
  :math:`\hat y` the direction from the right to the left hip (or shoulder). The robot's heading
  :math:`\psi_r` is the yaw of its waist frame in the reference posture. Every human direction is
  then rotated by :math:`R_a = R_z(\psi_r - \psi_h)`, so a clip that starts facing backwards
  (180 degrees) is retargeted exactly like the same clip facing forwards.
* **Position.** The human waist at calibration is mapped onto the robot waist of the reference
  posture (horizontally), ankles onto ankles (vertically).
* **Segments.** For every segment (child, parent) of the key-point tree present on both sides, the
  human length :math:`\ell_h` (median over the calibration samples) and the robot length
  :math:`\ell_r` (distance between the robot frames the two key-points map to, reference posture)
  give the per-link scale :math:`s = \ell_r / \ell_h` of Dariush 2009 Sec. 3.

The key-point tree (:data:`KEYPOINT_TREE`) is the skeleton of Dariush 2009 Fig. 2 extended to the
legs: the waist is the root; the neck, both shoulders and both hips hang from the waist (the
trunk, rigid on most robots, like Poubel 2014's mid-hip to mid-shoulder segment); the head hangs
from the neck, each arm and leg from its shoulder or hip. The shoulders hang from the waist and
not from the neck because "neck" means different points on different skeletons (the base of the
neck on CMU data, the cervical joint on the human model, the middle of the shoulders on G1),
while the waist-to-shoulder direction agrees within a few degrees (26 deg from vertical on CMU
subject 14 and on G1). :func:`build_tree` keeps the key-points two sides share and hangs each on
its nearest available ancestor.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .human_motion import MotionError

#: Parent of each standard key-point (``None`` for the root), Dariush 2009 Fig. 2 plus the legs.
KEYPOINT_TREE: dict[str, str | None] = {
    "waist": None,
    "neck": "waist",
    "head": "neck",
    "left_shoulder": "waist",
    "left_elbow": "left_shoulder",
    "left_wrist": "left_elbow",
    "left_hand": "left_wrist",
    "right_shoulder": "waist",
    "right_elbow": "right_shoulder",
    "right_wrist": "right_elbow",
    "right_hand": "right_wrist",
    "left_hip": "waist",
    "left_knee": "left_hip",
    "left_ankle": "left_knee",
    "left_toe": "left_ankle",
    "left_heel": "left_ankle",
    "right_hip": "waist",
    "right_knee": "right_hip",
    "right_ankle": "right_knee",
    "right_toe": "right_ankle",
    "right_heel": "right_ankle",
}

#: Both feet: side -> (ankle, toe, hip, knee) key-point names.
FEET: dict[str, dict[str, str]] = {
    side: {
        "ankle": f"{side}_ankle",
        "toe": f"{side}_toe",
        "heel": f"{side}_heel",
        "hip": f"{side}_hip",
        "knee": f"{side}_knee",
    }
    for side in ("left", "right")
}


class CalibrationError(MotionError, ValueError):
    """The motion or the robot lacks what calibration needs (e.g. no waist, no valid sample)."""


def build_tree(
    available: Iterable[str], tree: Mapping[str, str | None] = KEYPOINT_TREE
) -> dict[str, str | None]:
    """Restrict a key-point tree to the available names, re-hanging orphans on their ancestors.

    Args:
        available: Key-points present on both the human and the robot.
        tree: Parent table (child -> parent, ``None`` for the root).

    Returns:
        Child -> parent for every available key-point of ``tree``, in the order of ``tree``
        (parents first); a key-point whose parent is missing hangs from the nearest available
        ancestor, and one without any available ancestor becomes a root (parent ``None``).
    """
    present = set(available)
    out: dict[str, str | None] = {}
    for name, parent in tree.items():
        if name not in present:
            continue
        while parent is not None and parent not in present:
            parent = tree.get(parent)
        out[name] = parent
    return out


def yaw_of(vector: npt.ArrayLike) -> float:
    """Yaw [rad] of the horizontal part of a vector (``atan2(y, x)``)."""
    v = np.asarray(vector, dtype=float)
    return float(math.atan2(v[1], v[0]))


def hip_heading(left_hip: npt.ArrayLike, right_hip: npt.ArrayLike) -> np.ndarray:
    r"""Heading [rad] of a person from the hip line: the yaw of :math:`(l - r) \times e_z`.

    The forward normal of the line from the right hip to the left one, for points ``(..., 3)``
    (an array of the leading shape; NaN where a point is). The person's heading of the
    human-referenced metrics (:mod:`qpretarget.analysis.human_metrics`) and of the absolute foot
    placement (:meth:`~qpretarget.retarget.feet.FootTargets.absolute_ankle`): one definition.
    """
    d = np.asarray(left_hip, float) - np.asarray(right_hip, float)
    return np.arctan2(-d[..., 0], d[..., 1])


def rotation_z(angle: float) -> np.ndarray:
    """Rotation by ``angle`` [rad] about the world z axis, (3, 3)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def triad(left: np.ndarray, right: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    r"""A body frame from key-points: :math:`y` right to left, :math:`z` up, :math:`x = y \times z`.

    :math:`\hat z` is the direction from ``lower`` to ``upper`` made orthogonal to :math:`\hat y`
    (Gram-Schmidt), so the frame is exactly a rotation. Used for the waist (hips, waist -> neck) and
    the torso (shoulders, waist -> neck) of marker data, which has no joint orientations.

    Args:
        left: ``(..., 3)`` positions of the left point (hip or shoulder).
        right: ``(..., 3)`` positions of the right point.
        lower: ``(..., 3)`` lower point of the up direction (waist).
        upper: ``(..., 3)`` upper point of the up direction (neck).

    Returns:
        ``(..., 3, 3)`` rotations (columns x, y, z); NaN where an input is NaN or degenerate.
    """
    left = np.asarray(left, float)
    if left.shape == (3,):
        return _triad3(left, np.asarray(right, float), np.asarray(lower, float), upper)
    y = left - np.asarray(right, float)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    up = np.asarray(upper, float) - np.asarray(lower, float)
    z = up - np.sum(up * y, axis=-1, keepdims=True) * y
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def _triad3(left: np.ndarray, right: np.ndarray, lower: np.ndarray, upper: Any) -> np.ndarray:
    """:func:`triad` of single points, with scalar arithmetic (called every control tick)."""
    y0, y1, y2 = (float(a - b) for a, b in zip(left, right, strict=True))
    n = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    up = np.asarray(upper, float) - lower
    if not n > 1e-12:
        return np.full((3, 3), np.nan)
    y0, y1, y2 = y0 / n, y1 / n, y2 / n
    d = float(up[0]) * y0 + float(up[1]) * y1 + float(up[2]) * y2
    z0, z1, z2 = float(up[0]) - d * y0, float(up[1]) - d * y1, float(up[2]) - d * y2
    n = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
    if not n > 1e-12:
        return np.full((3, 3), np.nan)
    z0, z1, z2 = z0 / n, z1 / n, z2 / n
    x0, x1, x2 = y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0
    return np.array([[x0, y0, z0], [x1, y1, z1], [x2, y2, z2]])


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to ``M`` in Frobenius norm (polar factor by SVD), ``(..., 3, 3)``."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def _median_length(a: np.ndarray, b: np.ndarray) -> float:
    d = np.linalg.norm(np.atleast_2d(a) - np.atleast_2d(b), axis=-1)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else math.nan


def _first_valid(x: np.ndarray) -> np.ndarray:
    """Mean of the finite rows of ``(N, 3)`` samples (NaN if none)."""
    x = np.atleast_2d(np.asarray(x, float))
    ok = np.all(np.isfinite(x), axis=-1)
    return x[ok].mean(axis=0) if ok.any() else np.full(3, np.nan)


@dataclass
class Calibration:
    r"""How a human motion maps onto a robot (see the module docstring).

    Attributes:
        tree: Key-point tree shared by the human and the robot (child -> parent).
        yaw: Heading correction :math:`\psi_r - \psi_h` [rad].
        rotation: :math:`R_a = R_z(\text{yaw})`, applied to every human direction.
        human_waist: Human waist position at calibration [m], ``(3,)``.
        robot_waist: Robot waist position in the reference posture [m], ``(3,)``.
        human_ankle_height: Mean human ankle height at calibration [m].
        robot_ankle_height: Mean robot ankle height in the reference posture [m].
        human_lengths: Segment (child key-point) -> human length [m].
        robot_lengths: Segment (child key-point) -> robot length [m].
        robot_points: Robot key-points in the reference posture, name -> ``(3,)`` [m].
        human_heading: :math:`\psi_h` [rad]; ``robot_heading``: :math:`\psi_r` [rad].
        human_foot_yaw, robot_foot_yaw: Per side (``left``/``right``), the yaw of each foot at
            calibration [rad] (human: ankle -> toe; robot: the sole frame's x axis).
        double_support_ratio: :math:`L_r / L_h`, ratio of the mid-ankle to mid-hip distances of
            the robot's reference posture and the human at calibration (Poubel 2014 Sec. III.A
            double-support scaling).
        notes: What calibration had to assume.
    """

    tree: dict[str, str | None]
    yaw: float
    rotation: np.ndarray
    human_waist: np.ndarray
    robot_waist: np.ndarray
    human_ankle_height: float
    robot_ankle_height: float
    human_lengths: dict[str, float]
    robot_lengths: dict[str, float]
    robot_points: dict[str, np.ndarray]
    human_heading: float = 0.0
    robot_heading: float = 0.0
    human_foot_yaw: dict[str, float] = field(default_factory=dict)
    robot_foot_yaw: dict[str, float] = field(default_factory=dict)
    double_support_ratio: float = 1.0
    notes: list[str] = field(default_factory=list)

    @property
    def scales(self) -> dict[str, float]:
        r"""Per-link scales :math:`s = \ell_r / \ell_h` (Dariush 2009 Sec. 3), segment -> scale."""
        return {
            k: self.robot_lengths[k] / self.human_lengths[k]
            for k in self.robot_lengths
            if k in self.human_lengths and self.human_lengths[k] > 0
        }

    @property
    def root_scale(self) -> float:
        """Scale of the waist displacement: robot over human waist height above the ankles."""
        h = float(self.human_waist[2] - self.human_ankle_height)
        r = float(self.robot_waist[2] - self.robot_ankle_height)
        return r / h if h > 1e-6 and math.isfinite(h) else 1.0

    def align_direction(self, v: npt.ArrayLike) -> np.ndarray:
        r"""Rotate human vectors ``(..., 3)`` by :math:`R_a` (heading alignment)."""
        return np.asarray(v, float) @ self.rotation.T

    def align_point(self, p: npt.ArrayLike) -> np.ndarray:
        r"""Map human points ``(..., 3)`` rigidly onto the robot: :math:`R_a (p - w_h) + w_r`.

        Horizontally the calibration waist lands on the robot waist; vertically the human ankles
        land on the robot ankles.
        """
        p = np.asarray(p, float)
        origin = np.array([self.human_waist[0], self.human_waist[1], self.human_ankle_height])
        target = np.array([self.robot_waist[0], self.robot_waist[1], self.robot_ankle_height])
        return (p - origin) @ self.rotation.T + target

    def align_rotation(self, R: npt.ArrayLike) -> np.ndarray:
        r"""Heading-aligned rotation :math:`R_a R` for world rotations ``(..., 3, 3)``."""
        return self.rotation @ np.asarray(R, float)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serializable summary (stored in the run's ``meta``)."""
        return {
            "yaw_deg": math.degrees(self.yaw),
            "human_heading_deg": math.degrees(self.human_heading),
            "robot_heading_deg": math.degrees(self.robot_heading),
            "human_waist": self.human_waist.round(6).tolist(),
            "robot_waist": self.robot_waist.round(6).tolist(),
            "human_lengths": {k: round(v, 6) for k, v in self.human_lengths.items()},
            "robot_lengths": {k: round(v, 6) for k, v in self.robot_lengths.items()},
            "scales": {k: round(v, 6) for k, v in self.scales.items()},
            "root_scale": round(self.root_scale, 6),
            "double_support_ratio": round(self.double_support_ratio, 6),
            "tree": dict(self.tree),
            "notes": list(self.notes),
        }


def calibrate(
    human: Mapping[str, npt.ArrayLike],
    robot: Mapping[str, npt.ArrayLike],
    *,
    human_waist_rotation: npt.ArrayLike | None = None,
    robot_waist_rotation: npt.ArrayLike | None = None,
    robot_foot_rotations: Mapping[str, npt.ArrayLike] | None = None,
    tree: Mapping[str, str | None] = KEYPOINT_TREE,
) -> Calibration:
    """Compute the :class:`Calibration` of a human motion to a robot.

    Args:
        human: Human key-points at the calibration samples, name -> ``(N, 3)`` (or ``(3,)``)
            positions [m] in the z-up world; NaN samples are ignored.
        robot: Robot key-points in the reference posture, name -> ``(3,)`` [m].
        human_waist_rotation: ``(N, 3, 3)`` or ``(3, 3)`` waist orientation of the human, if the
            motion has orientations (the heading is then its x axis).
        robot_waist_rotation: ``(3, 3)`` world rotation of the robot's waist frame.
        robot_foot_rotations: side (``left``/``right``) -> ``(3, 3)`` sole rotation of the robot.
        tree: Key-point tree (default :data:`KEYPOINT_TREE`).

    Returns:
        The calibration.

    Raises:
        CalibrationError: If the waist is missing on either side, or no calibration sample of the
            human waist is valid.
    """
    notes: list[str] = []
    human_pts = {k: _first_valid(np.asarray(v, float).reshape(-1, 3)) for k, v in human.items()}
    robot_pts = {k: np.asarray(v, float).reshape(3) for k, v in robot.items()}
    shared = [k for k in tree if k in human_pts and k in robot_pts]
    if "waist" not in shared:
        raise CalibrationError(
            "calibration needs the 'waist' key-point on both the human (key-point map) and the "
            f"robot (retarget.robot_keypoints); human has {sorted(human_pts)}, robot has "
            f"{sorted(robot_pts)}"
        )
    if not np.all(np.isfinite(human_pts["waist"])):
        raise CalibrationError(
            "the human waist is missing (NaN) in every calibration sample; start the clip later "
            "(--start) or raise retarget.calibration.frames"
        )
    kept_tree = build_tree(shared, tree)
    human_lengths, robot_lengths = _segment_lengths(kept_tree, human, robot_pts)
    human_heading, robot_heading = _headings(
        human_pts, robot_pts, human_waist_rotation, robot_waist_rotation, notes
    )
    yaw = wrap_angle(robot_heading - human_heading)
    h_ankle, r_ankle = _ankle_heights(human_pts, robot_pts, notes)
    human_foot_yaw, robot_foot_yaw = _foot_yaws(human_pts, robot_foot_rotations)
    ratio = _double_support_ratio(human_pts, robot_pts)
    return Calibration(
        tree=kept_tree,
        yaw=yaw,
        rotation=rotation_z(yaw),
        human_waist=human_pts["waist"].copy(),
        robot_waist=robot_pts["waist"].copy(),
        human_ankle_height=h_ankle,
        robot_ankle_height=r_ankle,
        human_lengths=human_lengths,
        robot_lengths=robot_lengths,
        robot_points={k: robot_pts[k].copy() for k in kept_tree},
        human_heading=human_heading,
        robot_heading=robot_heading,
        human_foot_yaw=human_foot_yaw,
        robot_foot_yaw=robot_foot_yaw,
        double_support_ratio=ratio,
        notes=notes,
    )


def _segment_lengths(
    tree: Mapping[str, str | None],
    human: Mapping[str, npt.ArrayLike],
    robot_pts: Mapping[str, np.ndarray],
) -> tuple[dict[str, float], dict[str, float]]:
    """Segment (child) -> length [m], human (median over the samples) and robot (reference).

    A human segment never measured (NaN in every sample) is left out.
    """
    human_lengths: dict[str, float] = {}
    robot_lengths: dict[str, float] = {}
    for child, parent in tree.items():
        if parent is None:
            continue
        lh = _median_length(np.asarray(human[child], float), np.asarray(human[parent], float))
        if math.isfinite(lh):
            human_lengths[child] = lh
        robot_lengths[child] = float(np.linalg.norm(robot_pts[child] - robot_pts[parent]))
    return human_lengths, robot_lengths


def _headings(
    human_pts: Mapping[str, np.ndarray],
    robot_pts: Mapping[str, np.ndarray],
    human_waist_rotation: npt.ArrayLike | None,
    robot_waist_rotation: npt.ArrayLike | None,
    notes: list[str],
) -> tuple[float, float]:
    r""":math:`(\psi_h, \psi_r)`: yaw of the waist x axis, else from hips or shoulders, else 0."""
    if human_waist_rotation is not None:
        Rw = np.asarray(human_waist_rotation, float).reshape(-1, 3, 3)
        ok = np.all(np.isfinite(Rw), axis=(1, 2))
        human_heading = yaw_of(Rw[ok][0][:, 0]) if ok.any() else math.nan
    else:
        human_heading = math.nan
    if not math.isfinite(human_heading):
        human_heading = _heading_from_points(human_pts)
        if not math.isfinite(human_heading):
            human_heading = 0.0
            notes.append("no waist orientation, hips or shoulders: human heading taken as 0")
    if robot_waist_rotation is not None:
        robot_heading = yaw_of(np.asarray(robot_waist_rotation, float)[:, 0])
    else:
        robot_heading = _heading_from_points(robot_pts)
        if not math.isfinite(robot_heading):
            robot_heading = 0.0
    return human_heading, robot_heading


def _ankle_height(points: Mapping[str, np.ndarray]) -> float:
    """Mean height of the finite ankles [m], NaN if none."""
    zs = [points[k][2] for k in ("left_ankle", "right_ankle") if k in points]
    zs = [z for z in zs if math.isfinite(z)]
    return float(np.mean(zs)) if zs else math.nan


def _ankle_heights(
    human_pts: Mapping[str, np.ndarray], robot_pts: Mapping[str, np.ndarray], notes: list[str]
) -> tuple[float, float]:
    """Human and robot ankle heights; without ankles on both sides, the waists are matched."""
    h_ankle = _ankle_height(human_pts)
    r_ankle = _ankle_height(robot_pts)
    if not math.isfinite(h_ankle) or not math.isfinite(r_ankle):
        # Upper-body data: keep the waist heights as they are (no vertical scaling reference).
        notes.append("no ankles on both sides: waist heights are matched instead of ankles")
        h_ankle = float(human_pts["waist"][2]) - float(robot_pts["waist"][2])
        r_ankle = 0.0
    return h_ankle, r_ankle


def _foot_yaws(
    human_pts: Mapping[str, np.ndarray],
    robot_foot_rotations: Mapping[str, npt.ArrayLike] | None,
) -> tuple[dict[str, float], dict[str, float]]:
    """Per side, the foot yaw [rad]: human ankle -> toe, robot sole x axis."""
    human_foot_yaw: dict[str, float] = {}
    robot_foot_yaw: dict[str, float] = {}
    for side, names in FEET.items():
        a, t = human_pts.get(names["ankle"]), human_pts.get(names["toe"])
        if a is not None and t is not None and np.all(np.isfinite(t - a)):
            human_foot_yaw[side] = yaw_of(t - a)
        if robot_foot_rotations is not None and side in robot_foot_rotations:
            robot_foot_yaw[side] = yaw_of(np.asarray(robot_foot_rotations[side], float)[:, 0])
    return human_foot_yaw, robot_foot_yaw


def _hip_to_ankle(points: Mapping[str, np.ndarray]) -> float:
    """Distance from the mid-ankle to the mid-hip point [m]."""
    return float(
        np.linalg.norm(
            0.5 * (points["left_hip"] + points["right_hip"])
            - 0.5 * (points["left_ankle"] + points["right_ankle"])
        )
    )


def _double_support_ratio(
    human_pts: Mapping[str, np.ndarray], robot_pts: Mapping[str, np.ndarray]
) -> float:
    """Poubel 2014 Sec. III.A: :math:`L_r / L_h` of the mid-ankle to mid-hip distances.

    1 when a side lacks a hip or an ankle, or the human distance is not positive.
    """
    needed = ("left_ankle", "right_ankle", "left_hip", "right_hip")
    if not all(k in human_pts and k in robot_pts for k in needed):
        return 1.0
    lh = _hip_to_ankle(human_pts)
    lr = _hip_to_ankle(robot_pts)
    if math.isfinite(lh) and lh > 1e-6:
        return lr / lh
    return 1.0


def _heading_from_points(points: Mapping[str, np.ndarray]) -> float:
    r"""Yaw of :math:`\hat y \times \hat z` with :math:`\hat y` from the right to the left hip."""
    for left, right in (("left_hip", "right_hip"), ("left_shoulder", "right_shoulder")):
        if left in points and right in points:
            y = points[left] - points[right]
            if np.all(np.isfinite(y)) and np.linalg.norm(y[:2]) > 1e-6:
                forward = np.cross(y, [0.0, 0.0, 1.0])
                return yaw_of(forward)
    return math.nan


#: Largest tilt of the person's body axis from the vertical at calibration for a standing
#: person [deg] (:func:`body_tilt`): a deep squat, a bow or a kick keeps the waist within about
#: 45 deg of straight over the standing ankle; lying down is about 90, upside down 180.
UPRIGHT_TILT = 60.0


def body_tilt(points: Mapping[str, npt.ArrayLike]) -> float | None:
    r"""Tilt of the person's body axis from the vertical [deg]: lying down about 90.

    The axis runs from the lower ankle :math:`a` (the standing foot's: a kick's raised foot does
    not tilt it) to the waist :math:`w`:
    :math:`\theta = \arccos\big((w - a)_z / \lVert w - a \rVert\big)`, the median over the
    samples given (``(3,)`` or ``(N, 3)`` arrays of ``waist``, ``left_ankle`` and
    ``right_ankle``; samples with a missing point are left out). ``None`` without those
    key-points or a usable sample.
    """
    need = ("waist", "left_ankle", "right_ankle")
    if not all(k in points for k in need):
        return None
    w, al, ar = (np.asarray(points[k], float).reshape(-1, 3) for k in need)
    ok_l, ok_r = np.all(np.isfinite(al), axis=1), np.all(np.isfinite(ar), axis=1)
    a = np.where((ok_l & (~ok_r | (al[:, 2] <= ar[:, 2])))[:, None], al, ar)
    d = w - a
    n = np.linalg.norm(d, axis=1)
    ok = np.isfinite(n) & (n > 1e-6)
    if not ok.any():
        return None
    c = np.clip(d[ok, 2] / n[ok], -1.0, 1.0)
    return float(np.degrees(np.median(np.arccos(c))))


def wrap_angle(angle: float) -> float:
    """Angle wrapped to (-pi, pi] [rad]."""
    return float(math.atan2(math.sin(angle), math.cos(angle)))


__all__ = [
    "FEET",
    "KEYPOINT_TREE",
    "UPRIGHT_TILT",
    "Calibration",
    "CalibrationError",
    "body_tilt",
    "build_tree",
    "calibrate",
    "nearest_rotation",
    "rotation_z",
    "triad",
    "wrap_angle",
    "yaw_of",
]
