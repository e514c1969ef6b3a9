# SPDX-License-Identifier: Apache-2.0
"""The key-point stream of one motion and the :class:`Command` of one control tick.

:class:`KeypointStream` extracts key-points, low-passes them (Butterworth) and up-samples them
to the control rate (cardinal spline), offline or one frame at a time.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..control.controller import StepResult
from ..motion.calibration import triad
from ..motion.filters import Butterworth, CardinalSpline
from ..motion.human_motion import HumanMotion
from ..motion.keypoints import KeypointMap
from .spec import RetargetSpec

#: Height of the waist key-point above the hip joints' midpoint that the scaling assumes, in leg
#: lengths (hip to knee plus knee to ankle): the pelvis centre, as CMU's root (0.110-0.128 at the
#: first frame of the 14 shared CMU clips, median 0.12; SMPL's pelvis joint sits about as high).
WAIST_ABOVE_HIPS = 0.12
#: A waist key-point lower than this above the hip joints' midpoint at the first frame (in leg
#: lengths) is a skeleton rooted at the hip joints (Biovision / MotionBuilder and DeepMimic 0,
#: Mixamo 0.08): it is raised to :data:`WAIST_ABOVE_HIPS` (:meth:`KeypointStream.waist_lift`).
WAIST_ABOVE_HIPS_MIN = 0.09
#: Largest lean of the trunk (waist to neck or head) from the vertical at the first frame for
#: the waist height to be measured there [deg]: a person lying down is not measured.
WAIST_LIFT_TILT = 45.0
#: Largest angle between a joint orientation at the first frame and the body frame its
#: key-points give there (:data:`REST_FRAMES`) before the orientation is re-referenced [deg]
#: (:meth:`KeypointStream.rest_fix`). The shared CMU clips read 1-32 deg (waist), 3-13 (torso)
#: and 6-55 (head: the head's own pitch); a rest pose facing another axis reads 90 or 180.
REST_POSE_TOLERANCE = {"waist": 45.0, "torso": 45.0, "head": 75.0}
#: The key-points of each orientation's body frame (:func:`~qpretarget.motion.calibration.triad`:
#: left and right points across, lower to upper point up).
REST_FRAMES = {
    "waist": ("left_hip", "right_hip", "waist", "neck"),
    "torso": ("left_shoulder", "right_shoulder", "waist", "neck"),
    "head": ("left_shoulder", "right_shoulder", "neck", "head"),
}


def rotation_angle(R: np.ndarray) -> float:
    """Angle of the rotation ``R`` [rad]: the norm of its log (``pin.log3``)."""
    return float(np.linalg.norm(pin.log3(np.asarray(R, float))))


@dataclass(frozen=True)
class Command:
    """One control tick of the retargeter.

    Attributes:
        t: Time of the tick on the motion's clock [s].
        q: Configuration after the tick (nq,).
        v: Velocity applied during the tick (nv,).
        status: ``ok`` / ``relaxed`` / ``held``.
        result: The controller's :class:`~qpretarget.control.controller.StepResult`.
        phase: Support phase detected on the person (``double``/``left``/``right``, or ``""``).
        support: State of the support sequencer (``""`` without support handling).
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    status: str
    result: StepResult
    phase: str = ""
    support: str = ""


class KeypointStream:
    """Key-point extraction, Butterworth and cardinal spline for one motion (offline or online)."""

    def __init__(
        self,
        kmap: KeypointMap,
        skeleton: HumanMotion,
        keypoints: list[str],
        orientations: list[str],
        spec: RetargetSpec,
        rate_out: float,
        *,
        causal: bool,
    ) -> None:
        self.kmap = kmap
        self.skeleton = skeleton
        self.keypoints = keypoints
        self.orientations = orientations
        self.rate_in = skeleton.rate
        self.K, self.M = len(keypoints), len(orientations)
        self.causal = causal
        self.filter = (
            None
            if spec.cutoff_hz is None
            else Butterworth(
                _cutoff(spec.cutoff_hz, skeleton.rate), skeleton.rate, spec.filter_order
            )
        )
        self.spline = CardinalSpline(skeleton.rate, rate_out, spec.tension)
        self._index = {name: skeleton.index(name) for name in kmap.source_names()}
        #: How far the waist key-point is raised [m] (:meth:`waist_lift`; ``None`` until the
        #: first frame is seen), and the waist joint's orientation at that frame.
        self.lift: float | None = None
        self._lift_R0: np.ndarray | None = None
        self._waist_joint = kmap.orientations.get("waist")
        if skeleton.orientations is None or self._waist_joint not in self._index:
            self._waist_joint = None
        #: Orientation -> the constant rotation its joint orientations are right-multiplied
        #: by (:meth:`rest_fix`; empty until the first frame, and for motions as expected).
        self.rest_fixes: dict[str, np.ndarray] = {}
        self._rest_checked = False

    # A sample is [positions (3K), rotations (9M)]; the spline also carries K missing flags.
    def values_of(self, positions: Mapping[str, np.ndarray], rotations: Mapping[str, np.ndarray]):
        parts = [np.asarray(positions[k], float).reshape(-1, 3) for k in self.keypoints]
        parts += [np.asarray(rotations[o], float).reshape(-1, 9) for o in self.orientations]
        return np.concatenate(parts, axis=-1) if parts else np.zeros((1, 0))

    def missing_of(self, values: np.ndarray) -> np.ndarray:
        pos = values[..., : 3 * self.K].reshape(values.shape[:-1] + (self.K, 3))
        return np.any(np.isnan(pos), axis=-1).astype(float)

    @staticmethod
    def waist_lift(points: Mapping[str, np.ndarray], waist_rotation: np.ndarray | None) -> float:
        r"""How far to raise the waist key-point, from the first frame ``points`` [m].

        The scaling roots the body at the feet (Poubel 2014 eq. 1): the robot's pelvis target
        is as high above its ankles as the person's waist key-point above theirs, times the
        leg-length ratio. Skeletons put their root at different heights: CMU's root is the
        pelvis centre, :data:`WAIST_ABOVE_HIPS` leg lengths above the hip joints' midpoint
        :math:`m`; Biovision's and DeepMimic's roots sit at the hip joints. With those the
        pelvis target was 8-9 cm lower on G1 and the robot crouched (knees at 1.5 rad on a
        Biovision clip of a person standing still). With :math:`e = (w - m) \cdot \hat z` at
        the first frame and :math:`\ell` the leg length (mean of both legs' hip-knee and
        knee-ankle distances), the lift is

        .. math:: \lambda = \ell\,\mathrm{WAIST\_ABOVE\_HIPS} - e
            \quad \text{if } e < \ell\,\mathrm{WAIST\_ABOVE\_HIPS\_MIN}, \text{ else } 0,

        and 0 when a point is missing or the trunk (waist to neck, else head) leans more than
        :data:`WAIST_LIFT_TILT` from the vertical (a person lying down). The waist then moves
        by :math:`\lambda R(t) R(0)^T \hat z` (:math:`R` the waist joint's orientation: the
        lift turns with the pelvis), or :math:`\lambda \hat z` without orientations.
        """
        need = ("waist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
                "right_ankle")  # fmt: skip
        p = {k: np.asarray(points[k], float).reshape(3) for k in need if k in points}
        top = next((points[k] for k in ("neck", "head") if k in points), None)
        unknown = waist_rotation is not None and not np.all(np.isfinite(waist_rotation))
        if len(p) < len(need) or top is None or unknown:
            return 0.0
        trunk = np.asarray(top, float).reshape(3) - p["waist"]
        if not (np.all(np.isfinite(trunk)) and all(np.all(np.isfinite(v)) for v in p.values())):
            return 0.0
        if trunk[2] < np.linalg.norm(trunk) * np.cos(np.radians(WAIST_LIFT_TILT)):
            return 0.0
        leg = 0.5 * sum(
            np.linalg.norm(p[f"{s}_hip"] - p[f"{s}_knee"])
            + np.linalg.norm(p[f"{s}_knee"] - p[f"{s}_ankle"])
            for s in ("left", "right")
        )
        e = float(p["waist"][2] - 0.5 * (p["left_hip"][2] + p["right_hip"][2]))
        if not leg > 0 or e >= WAIST_ABOVE_HIPS_MIN * leg:
            return 0.0
        return float(WAIST_ABOVE_HIPS * leg - e)

    @staticmethod
    def rest_fix(
        points: Mapping[str, np.ndarray], rotations: Mapping[str, np.ndarray]
    ) -> dict[str, np.ndarray]:
        r"""Re-referencing of joint orientations whose rest pose is not the expected one.

        A motion's joint orientations are relative to its rest pose (docs/motion.md), and the
        tasks read them as the body's orientation: the rest pose upright, facing +x (the BVH
        convention of CMU, Biovision and MVN: facing +Z, y up). A skeleton whose rest pose
        faces another axis, or whose bones all point along one axis with the pose in the
        rotations (Maya-style pre-rotations), made the pelvis, torso and head targets point
        that far off the person's body: a walk with its rest pose facing sideways was walked
        sideways, legs crossed (ankle error 2.7 leg lengths against 0.08). For each
        orientation ``o`` with :math:`R_o(0)` at the first frame and :math:`T_o(0)` the body
        frame its key-points give there (:data:`REST_FRAMES`,
        :func:`~qpretarget.motion.calibration.triad`), when the angle between them exceeds
        :data:`REST_POSE_TOLERANCE`, the orientation becomes

        .. math:: R'_o(t) = R_o(t)\, R_o(0)^T T_o(0),

        the person's first-frame body frame turned as the joint turns since; the head's is
        re-referenced with the torso's too. Returns ``{o: R_o(0)^T T_o(0)}`` of the orientations
        re-referenced; none when the trunk (waist to neck) leans more than
        :data:`WAIST_LIFT_TILT` from the vertical at the first frame or a point is missing.
        """
        out: dict[str, np.ndarray] = {}
        need = ("waist", "neck")
        if not all(k in points and np.all(np.isfinite(points[k])) for k in need):
            return out
        trunk = np.asarray(points["neck"], float) - np.asarray(points["waist"], float)
        if trunk[2] < np.linalg.norm(trunk) * np.cos(np.radians(WAIST_LIFT_TILT)):
            return out
        for o in ("waist", "torso", "head"):
            R = rotations.get(o)
            frame = REST_FRAMES[o]
            if R is None or not all(k in points for k in frame):
                continue
            R = np.asarray(R, float).reshape(3, 3)
            T = triad(*(np.asarray(points[k], float).reshape(3) for k in frame))
            if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
                continue
            if np.degrees(rotation_angle(R.T @ T)) > REST_POSE_TOLERANCE[o] or (
                o == "head" and "torso" in out
            ):
                out[o] = R.T @ T
        return out

    def _fixed(self, rots: dict[str, np.ndarray]) -> None:
        """Right-multiply ``rots`` (one frame or (T, 3, 3) arrays) by :attr:`rest_fixes`."""
        for o, C in self.rest_fixes.items():
            if o in rots:
                rots[o] = np.asarray(rots[o], float) @ C

    def _check_rest(self, points: Mapping[str, np.ndarray], rots: Mapping[str, np.ndarray]) -> None:
        """Decide :attr:`rest_fixes` on the first frame (``points``/``rots``: (3,) or (T, 3))."""
        if self._rest_checked:
            return
        self._rest_checked = True
        first = {k: np.asarray(v, float).reshape(-1, 3)[0] for k, v in points.items()}
        rot0 = {o: np.asarray(R, float).reshape(-1, 3, 3)[0] for o, R in rots.items()}
        self.rest_fixes = self.rest_fix(first, rot0)

    def _lifted(self, points: dict[str, np.ndarray], waist_rotation: np.ndarray | None) -> None:
        """Raise ``points["waist"]`` (one frame (3,) or frames (T, 3)) by :attr:`lift`."""
        if self.lift is None:
            first = {k: np.asarray(v, float).reshape(-1, 3)[0] for k, v in points.items()}
            r0 = None if waist_rotation is None else np.asarray(waist_rotation).reshape(-1, 3, 3)[0]
            self._lift_R0 = None if r0 is None else np.asarray(r0, float)
            self.lift = self.waist_lift(first, r0)
        if not self.lift or "waist" not in points:
            return
        up = np.array([0.0, 0.0, self.lift])
        if waist_rotation is not None and self._lift_R0 is not None:
            R = np.asarray(waist_rotation, float)
            up = np.einsum("...ij,j->...i", R, self._lift_R0.T @ up)
        points["waist"] = np.asarray(points["waist"], float) + up

    def frame_keypoints(self, frame: np.ndarray, rotations: np.ndarray | None):
        def position_of(name: str) -> np.ndarray:
            return frame[self._index[name]]

        def rotation_of(name: str) -> np.ndarray:
            if rotations is None:
                raise ValueError(f"the stream has no joint orientations for {name!r}")
            return rotations[self._index[name]]

        pts = self.kmap.evaluate(position_of, rotation_of if rotations is not None else None)
        waist_R = None
        if self._waist_joint is not None and rotations is not None:
            waist_R = rotation_of(self._waist_joint)
        self._lifted(pts, waist_R)
        rots = {o: rotation_of(self.kmap.orientations[o]) for o in self.orientations}
        self._check_rest(pts, rots)
        self._fixed(rots)
        return pts, rots

    # -------------------------------------------------------------------- offline
    def offline(self, motion: HumanMotion) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Control-rate samples of a whole motion: ``(t_out, y, raw key-points)``.

        Zero phase: batch ``filtfilt`` and ``upsample``. Causal: the streaming code of
        :meth:`push`, sample by sample, so that an online run reproduces it bit for bit (the
        batch ``lfilter`` agrees with it only to ~1e-12, which a sensitive controller amplifies).
        """
        if self.causal:
            self.spline.reset()
            if self.filter is not None:
                self.filter = Butterworth(self.filter.cutoff_hz, self.rate_in, self.filter.order)
            outputs: list[tuple[float, np.ndarray]] = []
            raw: dict[str, list[np.ndarray]] = {k: [] for k in self.kmap.keypoints}
            rotations = motion.orientations
            for k in range(len(motion)):
                out, pts = self.push(
                    float(motion.t[k]),
                    motion.positions[k],
                    None if rotations is None else rotations[k],
                )
                outputs += out
                for name, value in pts.items():
                    raw[name].append(np.asarray(value, float))
            outputs += self.flush()
            t_out = np.array([o[0] for o in outputs])
            y = np.array([o[1] for o in outputs])
            return t_out, y, {k: np.array(v) for k, v in raw.items()}
        pts = self.kmap.positions(motion)
        self._lifted(
            pts,
            None if self._waist_joint is None else motion.joint_orientation(self._waist_joint),
        )
        rots = (
            {o: motion.joint_orientation(self.kmap.orientations[o]) for o in self.orientations}
            if self.orientations
            else {}
        )
        self._check_rest(pts, rots)
        self._fixed(rots)
        x = self.values_of(pts, rots)
        missing = self.missing_of(x)
        if self.filter is not None:
            x = self.filter.filtfilt(x)
        t_out, y = self.spline.upsample(motion.t, np.concatenate([x, missing], axis=-1))
        return t_out, y, _raw(pts)

    # -------------------------------------------------------------------- online
    def push(self, t: float, frame: np.ndarray, rotations: np.ndarray | None):
        pts, rots = self.frame_keypoints(frame, rotations)
        x = self.values_of(pts, rots)[0]
        missing = self.missing_of(x)
        if self.filter is not None:
            x = self.filter.push(x)
        return self.spline.push(t, np.concatenate([x, missing])), pts

    def flush(self):
        return self.spline.flush()

    def unpack(self, y: np.ndarray):
        K, M = self.K, self.M
        pos = y[: 3 * K].reshape(K, 3)
        rot = y[3 * K : 3 * K + 9 * M].reshape(M, 3, 3)
        miss = np.abs(y[3 * K + 9 * M :]) > 1e-9
        return (
            {k: pos[i] for i, k in enumerate(self.keypoints)},
            {o: rot[i] for i, o in enumerate(self.orientations)},
            {k: bool(miss[i]) for i, k in enumerate(self.keypoints)},
        )


def _cutoff(cutoff: float, rate: float) -> float:
    """The cut-off, kept below 45 % of the capture rate (a 7 Hz filter on 10 Hz data would fail)."""
    return min(cutoff, 0.45 * rate)


def _raw(points: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.asarray(v, float) for k, v in points.items()}


def iter_frames(motion: HumanMotion) -> Iterable[tuple[float, np.ndarray, np.ndarray | None]]:
    """``(t, positions (J, 3), orientations (J, 3, 3) or None)`` of every frame (for ``push``)."""
    for k in range(len(motion)):
        yield (
            float(motion.t[k]),
            motion.positions[k],
            None if motion.orientations is None else motion.orientations[k],
        )
