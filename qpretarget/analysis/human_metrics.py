# SPDX-License-Identifier: Apache-2.0
r"""Human-referenced metrics of a run: does the robot do what the person did?

One implementation, used by the run summary of ``qpretarget retarget``, by ``qpretarget evaluate``
(``metrics.json`` key ``human``) and by the tests; the definitions are in ``docs/metrics.md``,
section "Human-referenced metrics".

**The scaled human.** The person's raw key-points (``human/<key-point>`` of the run file),
interpolated at the robot's samples, scaled by the leg-length ratio :math:`s = L_r / L_h`
(hip-knee plus knee-ankle lengths: the robot's at its reference posture, the person's median
over the first 10 samples) and aligned at the first sample on the root position and yaw:

.. math::

    \tilde p(t) = R_z(\psi_r(0) - \psi_h(0))\, s\, (p(t) - w_h(0)) + w_r(0),

with :math:`w_h` the person's waist key-point, :math:`w_r` the robot's pelvis frame and
:math:`\psi` the headings (robot: the pelvis frame's x axis; person: the normal of the hip line).
A person in the air at the first sample (a clip cut mid-jump: the lowest foot key-point then
more than :data:`~qpretarget.motion.phases.AIR_START`, 10 cm, over its lowest in the run, by
:math:`\delta`) is aligned at the floor instead: :math:`s \delta` is added to the heights
(``start_in_air_m``), so a robot standing where the person lands counts as level with them.

**Observed span.** Everything is measured over the span from the first to the last sample at
which the person's waist and hips are :func:`observed` (marker data starting or ending with
gaps is held there by the interpolation), aligned at its first sample (``observed_span_s``).

**Measures** (``T`` samples, ``dt`` the sample period):

* *root travel ratio*: horizontal path length of the robot pelvis over the scaled human's, both
  sampled every 0.1 s (pelvis sway at the control rate does not count as travel);
* *heading error*: :math:`(\psi'_r(t) - \psi'_r(0)) - (\psi_h(t) - \psi_h(0))`, both unwrapped,
  in degrees, largest magnitude and final value, with :math:`\psi'_r` the robot's heading
  built as the person's: the forward normal to its pelvis frame's y axis (the line through its
  hips; the yaw of the x axis differs from it by up to 90 deg on a pelvis tilted as far as a
  roundhouse kick's);
* *foot height*: robot, sole frame height above the floor, the lower sole's first-sample
  height (a run may start on one foot); person, the
  lowest of its foot key-points (ankle, toe, heel) above that point type's lowest height in the
  clip (either foot), times :math:`s`;
* *off the ground* (robot): the sole's lowest corner (of its rectangle) higher than 5 mm above
  the floor: a sole rolled onto its toes stands on its front edge, its
  frame 1-3 cm up;
* *steps*: foot lifts, maximal intervals with a foot higher than 3 cm (gaps under 0.1 s merged),
  counted per foot, robot and person;
* *swing-height ratio*: for each human lift higher than 5 cm above where that foot stood
  before it (its lowest height since its previous lift; the floor for a foot raised from the
  first sample), the robot foot's highest point within the lift (widened by 0.2 s each side)
  above where the robot's foot stood over the same span, over the person's;
* *lift agreement*: share of the samples with a human foot higher than 3 cm in which the robot's
  same foot is off the ground;
* *flight*: intervals with both feet higher than 3 cm (person) or off the ground (robot), and
  the share of the person's flight time in which the robot is in flight too;
* *ankle displacement error*: each ankle's displacement from its first-sample position, robot
  minus scaled human, in robot leg lengths, RMS over samples and both ankles (stance width and
  the robot's different foot placement at the start drop out);
* *pelvis height error*: robot pelvis height minus the scaled human's (equal at the first
  sample), largest magnitude and RMS;
* *pelvis tilt error*: the pelvis's lean since the first sample, robot vs person, largest
  angle in degrees (:func:`pelvis_lean`): where the direction that was vertical at the first
  sample now points, forward and sideways in the body's own heading frame; the error is the
  distance between the robot's and the person's (forward, sideways) leans, so a robot leaning
  forward while the person leans back counts both. The person's pelvis is the rigid triangle
  of the waist and hip key-points (the BVH root and the thigh joints it carries), the robot's
  its pelvis frame; only over the samples where those key-points are observed
  (:func:`observed`: not filled in across a gap over 0.1 s), from the first of them;
* *stance slip*: for each stance of a robot foot (touch-down to lift-off: its ``contacts`` column,
  else the sole lower than 5 mm), the largest horizontal distance of the sole from where it
  touched down, the largest over stances [mm] (horizontal, as ``foot_slip`` of
  ``qpretarget evaluate``); the vertical one apart as the *stance settle* (a sole put down
  a few millimetres up and pressed flat onto the floor);
* *sole below ground*: the lowest sole corner under the floor [mm];
* *held ticks*: samples with status ``held``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..motion.calibration import hip_heading
from ..motion.phases import AIR_START, foot_points
from ..robot import RobotModel, load_robot
from ..trajectory import RobotTrajectory

SIDES = ("left", "right")
#: A foot higher than this is lifted (a step) [m].
LIFT_HEIGHT = 0.03
#: A robot foot higher than this is off the ground [m].
OFF_GROUND = 0.005
#: Lifts lower than this are left out of the swing-height ratio [m].
SWING_MIN = 0.05
#: Lifts separated by less than this are one lift [s].
MERGE_GAP = 0.1
#: Sample period of the path lengths [s].
PATH_STEP = 0.1
#: Window widening of the swing-height comparison [s].
SWING_WINDOW = 0.2


class HumanMetricsError(ValueError):
    """The run cannot be compared with the person (no human key-points, no legs)."""


def _yaw(x: np.ndarray) -> np.ndarray:
    return np.arctan2(x[..., 1], x[..., 0])


def intervals(mask: np.ndarray, t: np.ndarray, *, merge: float = 0.0) -> list[tuple[int, int]]:
    """Maximal runs ``[i, j)`` of ``True`` in ``mask``; runs closer than ``merge`` [s] joined."""
    out: list[tuple[int, int]] = []
    T = len(mask)
    k = 0
    while k < T:
        if mask[k]:
            j = k
            while j < T and mask[j]:
                j += 1
            if out and merge > 0 and t[k] - t[out[-1][1] - 1] < merge:
                out[-1] = (out[-1][0], j)
            else:
                out.append((k, j))
            k = j
        else:
            k += 1
    return out


def _interp(t: np.ndarray, tp: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``(N, 3)`` samples at times ``t`` (NaN samples skipped)."""
    out = np.full((len(t), x.shape[1]), np.nan)
    for c in range(x.shape[1]):
        ok = np.isfinite(x[:, c])
        if ok.sum() >= 2:
            out[:, c] = np.interp(t, tp[ok], x[ok, c])
    return out


def _leg_length(points: Mapping[str, np.ndarray], side: str) -> float | None:
    try:
        h, k, a = (points[f"{side}_{p}"] for p in ("hip", "knee", "ankle"))
    except KeyError:
        return None
    n = float(np.linalg.norm(k - h) + np.linalg.norm(a - k))
    return n if math.isfinite(n) and n > 0 else None


def robot_leg_length(robot: RobotModel) -> float:
    """Mean hip-knee + knee-ankle length of the robot's legs at its reference posture [m].

    Hips from the ``left_hip``/``right_hip`` key-frames, else the origin of the knee joint's
    parent joint (the hip pitch joint of Talos' leg chain).

    Raises:
        HumanMetricsError: The robot has no knee or ankle key-frames.
    """
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.q_reference)
    kf = robot.keyframes
    lengths = []
    for side in SIDES:
        if f"{side}_knee" not in kf or f"{side}_ankle" not in kf:
            continue
        knee_f = robot.frame_id(kf[f"{side}_knee"])
        knee = data.oMf[knee_f].translation
        ankle = data.oMf[robot.frame_id(kf[f"{side}_ankle"])].translation
        if f"{side}_hip" in kf:
            hip = data.oMf[robot.frame_id(kf[f"{side}_hip"])].translation
        else:
            parent = model.parents[model.frames[knee_f].parentJoint]
            hip = data.oMi[parent].translation
        lengths.append(float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)))
    if not lengths:
        raise HumanMetricsError(
            f"robot {robot.name!r} has no knee and ankle key-frames: no leg length to scale the "
            "person by (add them to its registry entry or robot spec)."
        )
    return float(np.mean(lengths))


class _RobotSeries:
    """Pelvis, ankles and soles of the robot at every sample (forward kinematics)."""

    def __init__(self, traj: RobotTrajectory, robot: RobotModel) -> None:
        model, data = robot.model, robot.model.createData()
        kf = robot.keyframes
        pelvis = robot.frame_id(kf.get("pelvis", model.frames[2].name))
        ankles = {s: robot.frame_id(kf[f"{s}_ankle"]) for s in SIDES if f"{s}_ankle" in kf}
        feet = {s: [f for f in robot.feet if s in f.lower()] for s in SIDES}
        soles = {s: robot.frame_id(robot.feet[v[0]].frame) for s, v in feet.items() if len(v) == 1}
        q = np.asarray(traj.q, float)
        T = len(q)
        self.pelvis = np.empty((T, 3))
        self.pelvis_R = np.empty((T, 3, 3))
        self.ankle = {s: np.empty((T, 3)) for s in ankles}
        self.sole = {s: np.empty((T, 3)) for s in soles}
        #: side -> height of the sole's lowest corner [m] (a sole rolled onto its toes stands
        #: on its front edge: its origin is up, its lowest point is not).
        self.sole_low = {s: np.empty(T) for s in soles}
        corners = {}
        for s in soles:
            x0, x1, y0, y1 = robot.feet[feet[s][0]].rectangle
            corners[s] = np.array([[x, y, 0.0] for x in (x0, x1) for y in (y0, y1)]).T
        for k in range(T):
            pin.framesForwardKinematics(model, data, q[k])
            M = data.oMf[pelvis]
            self.pelvis[k] = M.translation
            self.pelvis_R[k] = M.rotation
            for s, fid in ankles.items():
                self.ankle[s][k] = data.oMf[fid].translation
            for s, fid in soles.items():
                Ms = data.oMf[fid]
                self.sole[s][k] = Ms.translation
                self.sole_low[s][k] = float(np.min(Ms.rotation[2] @ corners[s])) + Ms.translation[2]
        self.foot_columns = {
            s: traj.foot_names.index(v[0])
            for s, v in feet.items()
            if len(v) == 1 and v[0] in traj.foot_names
        }


def _air_start(kp: Mapping[str, np.ndarray]) -> float:
    """The person's height in the air at the first sample [m, unscaled], else 0.

    How far the lowest foot point at the first sample is over the lowest over the run, when
    more than :data:`~qpretarget.motion.phases.AIR_START` (the person in the air there).
    """
    feet = [kp[k] for x in SIDES for k in foot_points(kp, x)]
    if not feet:
        return 0.0
    z = np.stack([f[:, 2] for f in feet], axis=1)
    first, lowest = float(np.nanmin(z[0])), float(np.nanmin(z))
    drop = first - lowest
    return drop if math.isfinite(drop) and drop > AIR_START else 0.0


def _path(xy: np.ndarray, t: np.ndarray) -> float:
    grid = np.append(np.arange(t[0], t[-1] - 1e-9, PATH_STEP), t[-1])
    pts = np.stack([np.interp(grid, t, xy[:, 0]), np.interp(grid, t, xy[:, 1])], axis=1)
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


#: The waist key-point must be this far from the hip line (share of the hip width) for the
#: three to make a pelvis frame.
PELVIS_TRIANGLE_MIN = 0.1


def _human_frame(kp: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """Person's pelvis frames ``(T, 3, 3)``: y along the hips, z from their midpoint to the waist.

    ``None`` without the waist and hips, or when the waist lies on the hip line (a key-point map
    whose waist is the hips' midpoint has no pelvis orientation).
    """
    if not all(k in kp for k in ("left_hip", "right_hip", "waist")):
        return None
    y = kp["left_hip"] - kp["right_hip"]
    up = kp["waist"] - 0.5 * (kp["left_hip"] + kp["right_hip"])
    width = np.linalg.norm(y, axis=1)
    off = np.linalg.norm(np.cross(y, up), axis=1) / np.maximum(width, 1e-12)
    if not float(np.nanmedian(off / np.maximum(width, 1e-12))) >= PELVIS_TRIANGLE_MIN:
        return None
    x = np.cross(y, up)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = y / width[:, None]
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=2)


#: A key-point is *observed* at a sample between two of its recorded samples at most this far
#: apart [s] (a longer gap, or before its first and after its last record, is filled in).
OBSERVED_GAP = 0.1


def observed(
    t: np.ndarray, tp: np.ndarray, x: np.ndarray, max_gap: float = OBSERVED_GAP
) -> np.ndarray:
    """Samples ``t`` at which ``(N, 3)`` records ``x`` at ``tp`` are observed (bool mask).

    Between two finite records at most ``max_gap`` apart (or on one): not before the first
    record, after the last, or inside a longer gap, where :func:`_interp` holds or bridges.
    """
    ok = np.all(np.isfinite(x), axis=1)
    tv = tp[ok]
    out = np.zeros(len(t), dtype=bool)
    if len(tv) == 0:
        return out
    i = np.searchsorted(tv, t)
    exact = (i < len(tv)) & (tv[np.minimum(i, len(tv) - 1)] == t)
    inside = (i > 0) & (i < len(tv))
    gap = np.full(len(t), np.inf)
    gap[inside] = tv[i[inside]] - tv[i[inside] - 1]
    return exact | (inside & (gap <= max_gap + 1e-12))


def pelvis_lean(R: np.ndarray) -> np.ndarray:
    r"""Lean of a body since its first sample, forward and sideways [deg], ``(T, 2)``.

    With :math:`\Delta R(t) = R(t) R(0)^\top` (the body's rotation since the first sample, the
    same for every frame fixed to it) and :math:`u = \Delta R(t)\,e_z` (where the direction
    that was vertical points now), the lean is
    :math:`(\operatorname{atan2}(u \cdot h_x, u_z), \operatorname{atan2}(u \cdot h_y, u_z))`
    in the body's current heading frame :math:`h` (its x axis's yaw): positive forward and
    to the left.
    """
    u = np.einsum("tij,j->ti", R @ R[0].T, np.array([0.0, 0.0, 1.0]))
    psi = _yaw(R[:, :, 0])
    c, s_ = np.cos(psi), np.sin(psi)
    fwd = c * u[:, 0] + s_ * u[:, 1]
    side = -s_ * u[:, 0] + c * u[:, 1]
    return np.degrees(np.stack([np.arctan2(fwd, u[:, 2]), np.arctan2(side, u[:, 2])], axis=1))


def _root_observed(t: np.ndarray, th: np.ndarray, human: Mapping[str, Any]) -> np.ndarray:
    """Samples ``t`` at which the person's waist and both hips are all :func:`observed`."""
    seen = np.ones(len(t), dtype=bool)
    for k in ("waist", "left_hip", "right_hip"):
        if k in human:
            seen &= observed(t, th, np.asarray(human[k], float).reshape(len(th), 3))
    return seen


def _observed_span(
    traj: RobotTrajectory, th: np.ndarray, human: Mapping[str, Any]
) -> tuple[RobotTrajectory, list[float] | None, np.ndarray]:
    """The run cut to the span where the person's waist and hips are observed.

    Before the first and after the last sample at which all three are :func:`observed` the
    person's root is only held by the interpolation (marker data that starts or ends with
    gaps): nothing there is compared. Returns the run (unchanged, with ``None``, when the span is
    the whole run), the span [s] and the :func:`_root_observed` mask of the returned samples.

    Raises:
        HumanMetricsError: They are observed at fewer than 2 samples.
    """
    t = np.asarray(traj.t, float)
    seen = _root_observed(t, th, human)
    if seen.all():
        return traj, None, seen
    idx = np.flatnonzero(seen)
    if len(idx) < 2:
        raise HumanMetricsError(
            "the person's waist and hips are observed at fewer than 2 samples of the run "
            "(marker gaps longer than 0.1 s everywhere): nothing to compare the robot with."
        )
    a, b = int(idx[0]), int(idx[-1]) + 1
    return traj.samples(a, b), [float(t[a]), float(t[b - 1])], seen[a:b]


def human_metrics(traj: RobotTrajectory, robot: RobotModel | None = None) -> dict[str, Any]:
    """The human-referenced metrics of a run (see the module docstring).

    Args:
        traj: A run with the person's key-points (``human/<key-point>``: any run written by
            ``qpretarget retarget``).
        robot: Its robot model (default: loaded from ``traj.robot``).

    Returns:
        A JSON-serializable dict (lengths in m unless the key says mm, angles in degrees).

    Raises:
        HumanMetricsError: The run has no human key-points, or they have no waist, hips and
            legs, or the robot has no knee and ankle key-frames.
    """
    if robot is None:
        robot = load_robot(traj.robot)
    human = traj.human or {}
    if "t" not in human or "waist" not in human:
        raise HumanMetricsError(
            "the run has no human key-points (human/t, human/waist): it was not written by "
            "qpretarget retarget, or with an old version; retarget the clip again."
        )
    th = np.asarray(human["t"], float)
    traj, span, seen = _observed_span(traj, th, human)
    t = np.asarray(traj.t, float)
    T = len(t)
    if T < 2:
        raise HumanMetricsError(f"the run has {T} sample(s); the metrics need at least 2.")
    kp = {
        k: _interp(t, th, np.asarray(v, float).reshape(len(th), 3))
        for k, v in human.items()
        if k != "t" and np.asarray(v).size == 3 * len(th)
    }
    for k in ("left_hip", "right_hip"):
        if k not in kp:
            raise HumanMetricsError(f"the run's human key-points have no {k}: no heading.")
    legs_h = [
        x
        for k in range(min(10, T))
        for x in (_leg_length({n: v[k] for n, v in kp.items()}, side) for side in SIDES)
        if x is not None
    ]
    if not legs_h:
        raise HumanMetricsError("the run's human key-points have no hip, knee and ankle.")
    L_r = robot_leg_length(robot)
    s = L_r / float(np.median(legs_h))
    rs = _RobotSeries(traj, robot)

    # Alignment at the first sample.
    psi_h = np.unwrap(hip_heading(kp["left_hip"], kp["right_hip"]))
    # The alignment: the yaw of the robot pelvis's x axis at the first sample (the retargeter's
    # absolute foot placement aligns the same way, FootTargets.start).
    psi_r = np.unwrap(_yaw(rs.pelvis_R[:, :, 0]))
    # The heading error: the robot's heading from its pelvis frame's y axis (the line through
    # its hips), as the person's from the hip line, one construction for both. The yaw of the
    # pelvis's x axis differs from it when the pelvis tilts far: by up to 90 deg under a
    # roundhouse kick's 45-65 deg hip tilt, with the robot's pelvis on the person's in 3-D
    # (docs/metrics.md).
    psi_rh = np.unwrap(hip_heading(rs.pelvis_R[:, :, 1], np.zeros(3)))
    Rz = np.array(
        [
            [math.cos(psi_r[0] - psi_h[0]), -math.sin(psi_r[0] - psi_h[0]), 0.0],
            [math.sin(psi_r[0] - psi_h[0]), math.cos(psi_r[0] - psi_h[0]), 0.0],
            [0.0, 0.0, 1.0],
        ]
    )
    w0 = kp["waist"][0]
    # Vertically at the floor for a person in the air at the first sample (AIR_START).
    lift0 = s * _air_start(kp)
    up = np.array([0.0, 0.0, lift0])
    out_air = {"start_in_air_m": lift0} if lift0 > 0.0 else {}

    def scaled(p: np.ndarray) -> np.ndarray:
        return (s * (p - w0)) @ Rz.T + rs.pelvis[0] + up

    out: dict[str, Any] = {"leg_length_ratio": s, "robot_leg_length_m": L_r, **out_air}
    if span is not None:
        out["observed_span_s"] = span
    waist = scaled(kp["waist"])
    human_path = _path(waist[:, :2], t)
    robot_path = _path(rs.pelvis[:, :2], t)
    out["root_travel"] = {
        "robot_m": robot_path,
        "human_m": human_path,
        "ratio": robot_path / human_path if human_path > 1e-9 else None,
        "final_offset_m": float(np.linalg.norm(rs.pelvis[-1, :2] - waist[-1, :2])),
    }
    dpsi = np.degrees((psi_rh - psi_rh[0]) - (psi_h - psi_h[0]))
    out["heading_error_deg"] = {
        "max": float(np.nanmax(np.abs(dpsi))),
        "final": float(dpsi[-1]),
        "human_turn": float(np.degrees(psi_h[-1] - psi_h[0])),
    }
    dz = rs.pelvis[:, 2] - waist[:, 2]
    out["pelvis_height_error_m"] = {
        "max": float(np.nanmax(np.abs(dz))),
        "rms": float(np.sqrt(np.nanmean(dz**2))),
    }
    Rh = _human_frame(kp)
    # The lean only where the person's pelvis is observed (marker data has gaps: CMU BVH none,
    # the OpenSim C3D walk its waist and hips for 1.5-3.5 s of 5 s only, held before and after
    # by the interpolation), from the first such sample.
    if Rh is not None and int(seen.sum()) >= 2:
        idx = np.flatnonzero(seen)
        lean = np.linalg.norm(pelvis_lean(rs.pelvis_R[idx]) - pelvis_lean(Rh[idx]), axis=1)
        worst = int(np.nanargmax(lean))
        out["pelvis_tilt_error_deg"] = {
            "max": float(lean[worst]),
            "rms": float(np.sqrt(np.nanmean(lean**2))),
            "at_s": float(t[idx[worst]] - t[0]),
            "observed_share": float(len(idx) / T),
        }

    # Feet.
    h_r: dict[str, np.ndarray] = {}
    low_r: dict[str, np.ndarray] = {}
    h_h: dict[str, np.ndarray] = {}
    if rs.sole:
        # The floor: the lower sole at the first sample (a run may start on one foot, the
        # other raised: the mean of the two put the floor 39 mm up on CMU 49_18).
        ground = float(min(rs.sole[x][0, 2] for x in rs.sole))
        h_r = {x: rs.sole[x][:, 2] - ground for x in rs.sole}
        low_r = {x: rs.sole_low[x] - ground for x in rs.sole}
        out["sole_below_ground_mm"] = max(0.0, -min(float(v.min()) for v in low_r.values())) * 1e3
    types = [p for p in ("ankle", "toe", "heel") if all(f"{x}_{p}" in kp for x in SIDES)]
    if types and rs.sole:
        gnd = {p: min(np.nanmin(kp[f"{x}_{p}"][:, 2]) for x in SIDES) for p in types}
        for x in SIDES:
            hs = np.stack([kp[f"{x}_{p}"][:, 2] - gnd[p] for p in types], axis=1)
            h_h[x] = s * np.nanmin(hs, axis=1)
    if h_r and h_h:
        out.update(_feet_metrics(t, h_r, low_r, h_h, traj, rs))
    # Ankle displacement error.
    errs = []
    final: dict[str, float] = {}
    for x in SIDES:
        a = f"{x}_ankle"
        if a in kp and x in rs.ankle:
            d_h = (s * (kp[a] - kp[a][0])) @ Rz.T + up
            d_r = rs.ankle[x] - rs.ankle[x][0]
            errs.append(np.linalg.norm(d_r - d_h, axis=1) / L_r)
            final[x] = float(np.linalg.norm((d_r - d_h)[-1, :2]))
    if errs:
        e = np.concatenate(errs)
        out["ankle_displacement_error_legs"] = {
            "rms": float(np.sqrt(np.nanmean(e**2))),
            "max": float(np.nanmax(e)),
            "final_m": final,
        }
    status = np.asarray(traj.status, dtype=str) if traj.status is not None else np.array([])
    out["held_ticks"] = int(np.sum(status == "held"))
    phase = traj.extra.get("human_phase") if traj.extra else None
    if phase is not None and len(phase) > 1:
        switches = int(np.sum(np.asarray(phase[1:]) != np.asarray(phase[:-1])))
        out["phase_switches_per_s"] = switches / max(float(t[-1] - t[0]), 1e-9)
    return out


def _feet_metrics(
    t: np.ndarray,
    h_r: Mapping[str, np.ndarray],
    low_r: Mapping[str, np.ndarray],
    h_h: Mapping[str, np.ndarray],
    traj: RobotTrajectory,
    rs: _RobotSeries,
) -> dict[str, Any]:
    out: dict[str, Any] = {}
    steps: dict[str, dict[str, int]] = {}
    ratios: list[float] = []
    agree_num = agree_den = 0
    for x in SIDES:
        if x not in h_r or x not in h_h:
            continue
        lifts_h = intervals(h_h[x] > LIFT_HEIGHT, t, merge=MERGE_GAP)
        lifts_r = intervals(h_r[x] > LIFT_HEIGHT, t, merge=MERGE_GAP)
        steps[x] = {"robot": len(lifts_r), "human": len(lifts_h)}
        end = 0  # the previous lift's end: the foot stood from there to this lift
        for i, j in lifts_h:
            # Above where the foot stood before the lift (its lowest point since the previous
            # lift): the person's floor is not level (standing ankles 6.2-8.5 cm high across the
            # kata's capture volume). A foot raised from the first sample: above the floor.
            base_h = float(np.nanmin(h_h[x][end : i + 1])) if i > 0 else 0.0
            base_r = float(np.nanmin(h_r[x][end : i + 1])) if i > 0 else 0.0
            end = j
            peak = float(np.nanmax(h_h[x][i:j])) - base_h
            if peak < SWING_MIN:
                continue
            lo = int(np.searchsorted(t, t[i] - SWING_WINDOW))
            hi = int(np.searchsorted(t, t[j - 1] + SWING_WINDOW, side="right"))
            ratios.append((float(np.max(h_r[x][lo:hi])) - base_r) / peak)
        lifted = h_h[x] > LIFT_HEIGHT
        agree_den += int(lifted.sum())
        agree_num += int(np.sum(lifted & (low_r[x] > OFF_GROUND)))
    out["steps"] = steps
    out["steps_total"] = {
        "robot": sum(v["robot"] for v in steps.values()),
        "human": sum(v["human"] for v in steps.values()),
    }
    out["swing_height_ratio"] = {
        "min": min(ratios) if ratios else None,
        "median": float(np.median(ratios)) if ratios else None,
        "lifts": len(ratios),
    }
    out["lift_agreement"] = agree_num / agree_den if agree_den else None
    fly_h = np.logical_and.reduce([h_h[x] > LIFT_HEIGHT for x in SIDES if x in h_h])
    fly_r = np.logical_and.reduce([low_r[x] > OFF_GROUND for x in SIDES if x in low_r])
    out["flight"] = {
        "human": len(intervals(fly_h, t, merge=MERGE_GAP)),
        "robot": len(intervals(fly_r, t, merge=MERGE_GAP)),
        "shared_share": float(np.sum(fly_h & fly_r) / fly_h.sum()) if fly_h.any() else None,
    }
    # Stance slip.
    slip: dict[str, float] = {}
    settles: dict[str, float] = {}
    stances = 0
    contacts = None if traj.contacts is None else np.asarray(traj.contacts, bool)
    for x, sole in rs.sole.items():
        col = rs.foot_columns.get(x)
        if contacts is not None and contacts.size and col is not None:
            on = contacts[:, col]
        else:
            on = low_r[x] < OFF_GROUND
        worst = settle = 0.0
        for i, j in intervals(on, t):
            stances += 1
            d = sole[i:j] - sole[i]
            worst = max(worst, float(np.max(np.linalg.norm(d[:, :2], axis=1))))
            settle = max(settle, float(np.max(np.abs(d[:, 2]))))
        slip[x] = worst * 1e3
        settles[x] = settle * 1e3
    out["stance_slip_mm"] = {"max": max(slip.values()) if slip else 0.0, **slip}
    out["stance_settle_mm"] = {"max": max(settles.values()) if settles else 0.0, **settles}
    out["stances"] = stances
    return out


def format_human_metrics(m: Mapping[str, Any]) -> list[str]:
    """Readable lines of :func:`human_metrics`'s dict (run summary, ``evaluate``)."""

    def f(x: float | None, spec: str = ".2f") -> str:
        return "-" if x is None else format(x, spec)

    rt, hd, ph = m["root_travel"], m["heading_error_deg"], m["pelvis_height_error_m"]
    air = m.get("start_in_air_m")
    floor = "" if air is None else f"; in the air at t0, heights aligned {air * 100:.0f} cm up"
    lines = [
        f"vs the person (scaled by the leg ratio {m['leg_length_ratio']:.3f}, aligned at t0"
        f"{floor}):",
        f"  root travel     robot {rt['robot_m']:.2f} m / human {rt['human_m']:.2f} m "
        f"(ratio {f(rt['ratio'])})",
        f"  heading error   max {hd['max']:.1f} deg, final {hd['final']:.1f} deg "
        f"(human turned {hd['human_turn']:.0f} deg)",
        f"  pelvis height   error max {ph['max'] * 100:.1f} cm, RMS {ph['rms'] * 100:.1f} cm",
    ]
    if "pelvis_tilt_error_deg" in m:
        tilt = m["pelvis_tilt_error_deg"]
        seen = tilt.get("observed_share", 1.0)
        lines.append(
            f"  pelvis tilt     error max {tilt['max']:.1f} deg (at {tilt['at_s']:.2f} s), "
            f"RMS {tilt['rms']:.1f} deg"
            + (
                ""
                if seen >= 0.999
                else f" over the {100 * seen:.0f} % of samples the pelvis is seen"
            )
        )
    if "steps" in m:
        st = m["steps_total"]
        sw = m["swing_height_ratio"]
        fl = m["flight"]
        lines += [
            f"  steps (>3 cm)   robot {st['robot']}, human {st['human']}"
            + "".join(f"; {k} {v['robot']}/{v['human']}" for k, v in m["steps"].items()),
            f"  swing height    ratio min {f(sw['min'])}, median {f(sw['median'])} "
            f"over {sw['lifts']} lift(s) > 5 cm; lift agreement {f(m['lift_agreement'])}",
            f"  flight          robot {fl['robot']}, human {fl['human']} interval(s)",
            f"  stance slip     max {m['stance_slip_mm']['max']:.3f} mm (settle "
            f"{m['stance_settle_mm']['max']:.2f} mm) over {m['stances']} stance(s); "
            f"sole below ground {m['sole_below_ground_mm']:.2f} mm",
        ]
    if "ankle_displacement_error_legs" in m:
        a = m["ankle_displacement_error_legs"]
        line = f"  ankle displ.    error RMS {a['rms']:.3f} leg lengths, max {a['max']:.3f}"
        if a.get("final_m"):
            ends = ", ".join(f"{x} {100 * v:.1f}" for x, v in a["final_m"].items())
            line += f"; at the end {ends} cm"
        lines.append(line)
    extra = f"  held ticks      {m['held_ticks']}"
    if "phase_switches_per_s" in m:
        extra += f"; human support phase switches {m['phase_switches_per_s']:.2f}/s"
    lines.append(extra)
    return lines


def human_metrics_or_reason(
    traj: RobotTrajectory, robot: RobotModel | None = None
) -> tuple[dict[str, Any] | None, str | None]:
    """:func:`human_metrics`, or ``(None, reason)`` when the run cannot be compared."""
    try:
        return human_metrics(traj, robot), None
    except HumanMetricsError as exc:
        return None, str(exc)


__all__: Sequence[str] = [
    "HumanMetricsError",
    "format_human_metrics",
    "human_metrics",
    "human_metrics_or_reason",
    "intervals",
    "robot_leg_length",
]
