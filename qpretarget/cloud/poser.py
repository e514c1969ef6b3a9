# SPDX-License-Identifier: Apache-2.0
r"""The human model of example-robot-data posed by a mocap clip: the person ``make-cloud`` renders.

:class:`HumanPoser` drives ``human_description`` (a free-flyer human with spine, clavicles,
neck and limbs) by qpretarget's own :class:`~qpretarget.Controller` so that its limbs take the
clip's directions with the model's own lengths; :func:`trunk_orientations` gives marker data
(positions only) the trunk's orientations the poser needs; :func:`interpolation_peak_rate`
measures a joint-space move for the renderer's lead-in. The rendering itself (camera, z-buffer,
noise, the calibration lead-in, the camera's placement) is :mod:`.render`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..motion.builtin import HUMAN_TO_Z_UP, HUMAN_URDF
from ..motion.calibration import KEYPOINT_TREE as STANDARD_TREE

#: Key-point tree used to re-proportion a clip to the human model: child -> parent. The standard
#: tree (:data:`~qpretarget.motion.calibration.KEYPOINT_TREE`) without the heels, and with the
#: shoulders hung from the neck, a joint of the human model.
KEYPOINT_TREE: dict[str, str] = {
    child: "neck" if child.endswith("_shoulder") else parent
    for child, parent in STANDARD_TREE.items()
    if parent is not None and not child.endswith("_heel")
}

# The human model's URDF and its axes' turn into the z-up world are motion.builtin's
# (HUMAN_URDF, HUMAN_TO_Z_UP): the built-in motion poses the same model.


def _worst(errors: np.ndarray) -> float:
    """The largest of ``errors`` that is known (0 when none is)."""
    known = errors[np.isfinite(errors)]
    return float(known.max()) if len(known) else 0.0


class HumanPoser:
    """Pose example-robot-data's ``human_description`` model from a mocap clip's key-points.

    The model's limbs follow the clip's limb *directions* with the model's own segment lengths:
    every tick, the elbow target is the model's current shoulder plus its upper-arm length along
    the clip's shoulder-to-elbow direction, the wrist target continues from there along the
    clip's forearm direction, and likewise for hands, knees, ankles and toes. The pelvis follows
    the clip's waist position and orientation, the torso and head their orientations. The model
    (with a free-flyer root) is driven by qpretarget's own :class:`~qpretarget.Controller`
    (position and orientation frame tasks, joint limits as hard bounds), several ticks per frame.
    Targets are always reachable in length, so the limb directions are the clip's wherever the
    model's joint limits allow.

    The clip's key-points determine neither the clavicles (where the shoulders sit on the thorax:
    each elbow target moves with the current shoulder, so raising a clavicle costs the limb
    tasks nothing) nor how a trunk bend is shared between the lumbar and thoracic joints. With
    the weak posture pull of the other joints these drift: on CMU 14_37 the drinking side's
    clavicle rose by 0.86 rad (the shoulder 16 cm up) and the spine took an S shape (lumbar
    -0.7, thoracic +0.7 rad) while the clip's shoulders stay still on its torso. The
    :attr:`HELD_JOINTS` get the posture weight ``held_weight`` instead, which keeps them within
    0.03 rad of neutral on that clip and changes the limb directions by less than 0.2 deg.

    Args:
        ticks_per_frame: controller ticks per clip frame (more: closer convergence).
        first_frame_ticks: ticks for the first frame (starting from the neutral pose).
        held_weight: posture weight of :attr:`HELD_JOINTS` (the other joints: 1e-3).
    """

    #: Joints the clip does not determine (clavicles, trunk), held near neutral (see above).
    HELD_JOINTS: tuple[str, ...] = (
        "left_clavicle_joint_X",
        "right_clavicle_joint_X",
        "middle_lumbar_Z",
        "middle_lumbar_X",
        "middle_thoracic_Z",
        "middle_thoracic_X",
        "middle_thoracic_Y",
    )

    #: Largest limb-direction error [deg] of the first frame posed from the neutral pose before
    #: it is posed again from bent limbs (:meth:`_first_frame`).
    FIRST_FRAME_TOLERANCE: float = 10.0
    #: Elbow and knee angles [rad] of the other starts of the first frame, tried in order.
    BENT_STARTS: tuple[float, ...] = (0.5, 1.0)
    #: The joints :attr:`BENT_STARTS` bend (the human model's elbows and knees).
    BENDING_JOINTS: tuple[str, ...] = (
        "left_elbow_Z",
        "right_elbow_Z",
        "left_knee_Z",
        "right_knee_Z",
    )

    CHAINS: tuple[tuple[str, str], ...] = tuple(
        (c, p)
        for c, p in KEYPOINT_TREE.items()
        if p not in ("waist", "neck") and c not in ("neck", "head")
    )

    #: The limb segments :meth:`limb_errors` compares (upper arms, forearms, thighs, shanks:
    #: the ones the arm-direction measure and a trainer's reference use). The hands and feet
    #: follow the clip less closely (the model's wrist and ankle limits: toes up to 39 deg off
    #: on CMU 14_14's squats) and are left out.
    SEGMENTS: tuple[tuple[str, str], ...] = tuple(
        (c, p) for c, p in CHAINS if c.rsplit("_", 1)[-1] in ("elbow", "wrist", "knee", "ankle")
    )

    def __init__(
        self, *, ticks_per_frame: int = 8, first_frame_ticks: int = 80, held_weight: float = 0.1
    ) -> None:
        from ..control.controller import Controller
        from ..motion import load_keypoint_map

        self.kmap = load_keypoint_map("human_description")
        self.driven = [c for c, _ in self.CHAINS]
        tasks: list[dict] = [
            {
                "type": "frame",
                "name": "waist",
                "frame": self.kmap.keypoints["waist"].points[0],
                "mode": "position",
                "position_weight": 100.0,
            },
        ]
        for name in self.driven:
            src = self.kmap.keypoints[name]
            spec = {
                "type": "frame",
                "name": name,
                "frame": src.points[0],
                "mode": "position",
                "position_weight": 10.0,
            }
            if src.offset is not None:
                spec["offset"] = list(src.offset)
            tasks.append(spec)
        for name, frame in self.kmap.orientations.items():
            tasks.append(
                {
                    "type": "frame",
                    "name": f"{name}_orientation",
                    "frame": frame,
                    "mode": "orientation",
                    "orientation_weight": 3.0 if name == "waist" else 1.0,
                }
            )
        tasks.append(
            {
                "type": "posture",
                "name": "posture",
                "weight": {j: float(held_weight) for j in self.HELD_JOINTS},
                "default_weight": 1e-3,
            }
        )
        self.config = {
            "name": "human_description_ik",
            "robot": {"urdf": HUMAN_URDF, "free_flyer": True},
            "dt": 0.05,
            "regularization": {"type": "identity", "damping": 1e-2},
            "tasks": tasks,
            "constraints": [{"type": "joint_limits", "gain": 0.95}],
        }
        self.controller = Controller(self.config)
        self.robot = self.controller.robot
        self.ticks_per_frame = int(ticks_per_frame)
        self.first_frame_ticks = int(first_frame_ticks)
        self.lengths = self._model_lengths()
        #: Per frame of the last :meth:`pose_sequence`, the largest limb error [deg].
        self.limb_error_deg = np.zeros(0)

    def model_keypoints(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Key-points (name -> (3,)) of the model at configuration ``q``."""
        model, data = self.robot.model, self.robot.model.createData()
        pin.framesForwardKinematics(model, data, q)

        def pos(name: str) -> np.ndarray:
            return data.oMf[model.getFrameId(name)].translation.copy()

        def rot(name: str) -> np.ndarray:
            return data.oMf[model.getFrameId(name)].rotation.copy()

        return self.kmap.evaluate(pos, rot)

    def _model_lengths(self) -> dict[str, float]:
        kp = self.model_keypoints(pin.neutral(self.robot.model))
        return {c: float(np.linalg.norm(kp[c] - kp[p])) for c, p in KEYPOINT_TREE.items()}

    def _targets(self, clip: Mapping[str, np.ndarray], q: np.ndarray) -> dict[str, np.ndarray]:
        """Each driven key-point's target: its parent's plus the model's length along the clip.

        A limb segment the clip does not give (marker data without arms, a marker hidden at
        this frame: missing or NaN at either end) is not driven: its target is where the model
        has it, so it stays as it is (hanging from the neutral pose for a clip without it).
        """
        here = self.model_keypoints(q)
        waist = np.asarray(clip["waist"], float)
        out: dict[str, np.ndarray] = {
            "waist": waist if np.all(np.isfinite(waist)) else here["waist"]
        }
        for child, parent in self.CHAINS:  # parents come first
            if child not in clip or parent not in clip:
                out[child] = here[child]
                continue
            d = np.asarray(clip[child], float) - np.asarray(clip[parent], float)
            n = float(np.linalg.norm(d))
            if not (math.isfinite(n) and n > 1e-9):
                out[child] = here[child]
                continue
            base = out.get(parent, here[parent])
            out[child] = base + self.lengths[child] * d / n
        return out

    def pose_sequence(
        self,
        keypoints: Mapping[str, np.ndarray],
        orientations: Mapping[str, np.ndarray],
        *,
        progress: bool = False,
    ) -> np.ndarray:
        """Configurations (T, nq) of the model following a clip.

        Afterwards :attr:`limb_error_deg` (T,) holds each frame's largest limb-direction error
        against the clip (:meth:`limb_errors`): how faithfully the rendered person follows it
        (within 7 deg on the 14 shared clips' first 3 s; a joint limit of the model, or a
        clip's pose the model cannot take, shows there).

        Args:
            keypoints: key-point -> (T, 3) world positions [m] (z up), e.g.
                ``keypoint_positions(motion)``.
            orientations: ``waist``/``torso``/``head`` -> (T, 3, 3) world rotations relative to the
                clip's rest pose facing +x (``keypoint_orientations(motion)``).
            progress: a progress bar on stderr.
        """
        T = len(next(iter(keypoints.values())))
        ctrl = self.controller
        q0 = pin.neutral(self.robot.model)
        q0[:3] = np.asarray(keypoints["waist"][0], float)
        q0[3:7] = pin.Quaternion(orientations["waist"][0] @ HUMAN_TO_Z_UP).coeffs()
        out = np.empty((T, self.robot.nq))
        worst = np.empty(T)
        bar = progress_bar(T, "posing", progress)
        for t in range(T):
            clip = {k: v[t] for k, v in keypoints.items()}
            rot = {  # a frame without an orientation (marker gaps) keeps the last target
                f"{n}_orientation": orientations[n][t] @ HUMAN_TO_Z_UP
                for n in self.kmap.orientations
                if n in orientations and np.all(np.isfinite(orientations[n][t]))
            }
            if t == 0:
                self._first_frame(q0, clip, rot)
            else:
                self._ticks(clip, rot, self.ticks_per_frame)
            out[t] = ctrl.q
            worst[t] = _worst(self.limb_errors(out[t], clip))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        self.limb_error_deg = worst
        return out

    def _ticks(self, clip: Mapping[str, np.ndarray], rot: Mapping[str, np.ndarray], n: int) -> None:
        ctrl = self.controller
        for _ in range(n):
            targets: dict[str, np.ndarray] = dict(rot)
            targets.update(self._targets(clip, np.asarray(ctrl.q)))
            ctrl.step(targets)

    def _first_frame(
        self, q0: np.ndarray, clip: Mapping[str, np.ndarray], rot: Mapping[str, np.ndarray]
    ) -> None:
        """Pose the clip's first frame from the neutral pose, else from bent limbs.

        From the neutral pose the arms and legs are straight, where the direction an elbow or
        a knee bends is undetermined: on CMU 01_01 (a forearm raised to the face) the first
        frame settled with the shoulder's axial rotation at its limit and the trunk rolled
        70 deg, 64 deg off the clip's forearm, and the next 50 frames stayed on that branch.
        When the first frame ends more than :attr:`FIRST_FRAME_TOLERANCE` off the clip's limb
        directions (:meth:`limb_errors`), it is posed again from each of
        :attr:`BENT_STARTS` (the elbows and knees bent by that angle) and the start whose
        pose follows the clip best is kept.
        """
        ctrl = self.controller
        ctrl.reset(q0)
        self._ticks(clip, rot, self.first_frame_ticks)
        worst = _worst(self.limb_errors(np.asarray(ctrl.q), clip))
        if worst <= self.FIRST_FRAME_TOLERANCE:
            return
        best = (worst, q0)
        for bend in self.BENT_STARTS:
            qs = q0.copy()
            for name in self.BENDING_JOINTS:
                qs[self.robot.joint_q_index[self.robot.joint_index(name)]] = bend
            ctrl.reset(qs)
            self._ticks(clip, rot, self.first_frame_ticks)
            err = _worst(self.limb_errors(np.asarray(ctrl.q), clip))
            if err < best[0]:
                best = (err, qs)
            if err <= self.FIRST_FRAME_TOLERANCE:
                return
        ctrl.reset(best[1])  # the best start again (the controller's warm start with it)
        self._ticks(clip, rot, self.first_frame_ticks)

    def limb_errors(self, q: np.ndarray, clip: Mapping[str, np.ndarray]) -> np.ndarray:
        r"""Angles [deg] between the model's limb segments at ``q`` and the clip's.

        Each segment from its parent key-point to its child, model against clip:
        :math:`\arccos(\hat a \cdot \hat b)`, in the order of :attr:`SEGMENTS`; NaN for a
        segment the clip does not give at this frame (missing or NaN key-points).
        """
        here = self.model_keypoints(q)
        out = np.full(len(self.SEGMENTS), np.nan)  # NaN: a segment the clip does not give
        for i, (child, parent) in enumerate(self.SEGMENTS):
            if child not in clip or parent not in clip:
                continue
            a = here[child] - here[parent]
            b = np.asarray(clip[child], float) - np.asarray(clip[parent], float)
            nb = float(np.linalg.norm(b))
            if not (math.isfinite(nb) and nb > 1e-9):
                continue
            c = float(a @ b) / max(float(np.linalg.norm(a)) * nb, 1e-12)
            out[i] = math.degrees(math.acos(max(-1.0, min(1.0, c))))
        return out


def progress_bar(total: int, desc: str, on: bool) -> Any:
    """A tqdm progress bar of ``total`` frames on stderr, or None when ``on`` is False."""
    if not on:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="frame", desc=desc, leave=False)


def interpolation_peak_rate(
    poser: HumanPoser, q0: np.ndarray, q1: np.ndarray, samples: int = 64
) -> float:
    r"""Fastest key-point's rate [m per unit of :math:`a`] along the joint-space line q0 -> q1.

    :math:`G = \max_k \max_a |\partial p_k(q(a)) / \partial a|` for
    :math:`q(a) =` ``pin.interpolate(q0, q1, a)``, by differences over ``samples`` steps. A
    move :math:`a = s(t / T)` then has key-point speeds at most :math:`G \max s' / T`
    (:math:`\max s' = 1.875` for the minimum-jerk profile of :func:`human_clip_sequence`).
    """
    h = poser.robot
    pts = [
        poser.model_keypoints(pin.interpolate(h.model, q0, q1, float(a)))
        for a in np.linspace(0.0, 1.0, samples + 1)
    ]
    names = list(pts[0])
    P = np.array([[p[k] for k in names] for p in pts])  # (samples + 1, K, 3)
    return float(np.linalg.norm(np.diff(P, axis=0), axis=2).max() * samples)


def trunk_orientations(
    keypoints: Mapping[str, np.ndarray],
    orientations: Mapping[str, np.ndarray],
    *,
    times: np.ndarray | None = None,
    source: str = "the clip",
) -> dict[str, np.ndarray]:
    r"""The waist's and torso's orientations a clip gives, else from its key-points (markers).

    BVH and ASF/AMC clips carry joint orientations; marker data (C3D) has positions only. For
    a missing ``waist`` orientation, :func:`~qpretarget.motion.calibration.triad` of the hips
    (:math:`\hat y` right to left) and the waist-to-neck line (:math:`\hat z`, made
    orthogonal), :math:`x = y \times z`; the shoulders stand in for the hips when the clip
    has no hips. The ``torso`` likewise from the shoulders (else the hips), the ``head`` is
    the torso's. A person standing upright facing +x gets the identity, the rest pose
    :class:`HumanPoser` expects.

    Raises:
        ConfigError: the clip has no waist or neck key-point, or neither both hips nor both
            shoulders (one-arm marker sets: the trunk's heading is unknown), or they are not
            seen at its first frame.
    """
    from ..motion.calibration import triad

    out = {k: np.asarray(v, float) for k, v in orientations.items()}
    if "waist" in out and "torso" in out:
        return out
    pairs = [
        (f"left_{p}", f"right_{p}")
        for p in ("hip", "shoulder")
        if f"left_{p}" in keypoints and f"right_{p}" in keypoints
    ]
    missing = [k for k in ("waist", "neck") if k not in keypoints]
    if missing or not pairs:
        have = ", ".join(sorted(keypoints)) or "none"
        raise ConfigError(
            f"{source} has no joint orientations, and its key-points ({have}) do not give the "
            "trunk's: need the waist and the neck, and both hips or both shoulders"
            + (f" (missing: {', '.join(missing)})" if missing else "")
            + ". A full-body clip (BVH, ASF/AMC, or markers on both sides) renders; a one-arm "
            "marker set does not."
        )

    def frame(left: str, right: str) -> np.ndarray:
        return triad(keypoints[left], keypoints[right], keypoints["waist"], keypoints["neck"])

    hips = frame(*pairs[0])
    chest = frame(*pairs[-1])
    seen = np.all(np.isfinite(hips), axis=(1, 2)) & np.all(np.isfinite(chest), axis=(1, 2))
    if not seen[0]:
        names = ", ".join(dict.fromkeys([*pairs[0], *pairs[-1], "waist", "neck"]))
        when = (
            "they are never all seen in the frames asked for"
            if not seen.any()
            else f"they are first all seen {float(times[np.argmax(seen)]):.2f} s into the clip: "
            f"--start {float(times[np.argmax(seen)]):.2f}"
            if times is not None
            else f"they are first all seen at frame {int(np.argmax(seen))}"
        )
        raise ConfigError(
            f"{source}: the trunk's key-points ({names}) are not all seen at the first frame "
            f"(marker gaps), so the person's first pose is unknown; {when}."
        )
    out.setdefault("waist", hips)
    out.setdefault("torso", chest)
    out.setdefault("head", out["torso"])
    return out


__all__ = [
    "HUMAN_TO_Z_UP",
    "HUMAN_URDF",
    "KEYPOINT_TREE",
    "HumanPoser",
    "interpolation_peak_rate",
    "trunk_orientations",
]
