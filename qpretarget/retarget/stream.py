# SPDX-License-Identifier: Apache-2.0
"""The key-point stream of one motion and the :class:`Command` of one control tick.

:class:`KeypointStream` extracts key-points, low-passes them (Butterworth) and up-samples them
to the control rate (cardinal spline), offline or one frame at a time.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from ..control.controller import StepResult
from ..motion.filters import Butterworth, CardinalSpline
from ..motion.human_motion import HumanMotion
from ..motion.keypoints import KeypointMap
from .spec import RetargetSpec


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

    # A sample is [positions (3K), rotations (9M)]; the spline also carries K missing flags.
    def values_of(self, positions: Mapping[str, np.ndarray], rotations: Mapping[str, np.ndarray]):
        parts = [np.asarray(positions[k], float).reshape(-1, 3) for k in self.keypoints]
        parts += [np.asarray(rotations[o], float).reshape(-1, 9) for o in self.orientations]
        return np.concatenate(parts, axis=-1) if parts else np.zeros((1, 0))

    def missing_of(self, values: np.ndarray) -> np.ndarray:
        pos = values[..., : 3 * self.K].reshape(values.shape[:-1] + (self.K, 3))
        return np.any(np.isnan(pos), axis=-1).astype(float)

    def frame_keypoints(self, frame: np.ndarray, rotations: np.ndarray | None):
        def position_of(name: str) -> np.ndarray:
            return frame[self._index[name]]

        def rotation_of(name: str) -> np.ndarray:
            if rotations is None:
                raise ValueError(f"the stream has no joint orientations for {name!r}")
            return rotations[self._index[name]]

        pts = self.kmap.evaluate(position_of, rotation_of if rotations is not None else None)
        rots = {o: rotation_of(self.kmap.orientations[o]) for o in self.orientations}
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
        rots = (
            {o: motion.joint_orientation(self.kmap.orientations[o]) for o in self.orientations}
            if self.orientations
            else {}
        )
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
