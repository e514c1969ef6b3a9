# SPDX-License-Identifier: Apache-2.0
r"""Shape task between serial chains (Tosun 2014): match the normalized pose of a source chain.

The source chain is an ordered list of 3-D points (human key-points such as shoulder, elbow, wrist,
hand, or another robot's frames); the target chain is an ordered list of robot frames, the first
one being its base. Both are reduced to their *normalized pose* (Tosun 3.1): the polyline through
their points, translated so the base is at the origin and scaled to unit total length,

.. math::
    P(s) = \frac{p_k - p_0}{L} + (s - \hat c_k)\,u_k, \qquad
    s \in (\hat c_k, \hat c_{k+1}],

with :math:`l_k = |p_{k+1} - p_k|`, :math:`L = \sum_k l_k`, :math:`\hat c_k = \sum_{j<k} l_j / L`
and :math:`u_k = (p_{k+1} - p_k) / l_k`. The pose error is sampled at :math:`N` points
:math:`s_n = n\delta`, :math:`\delta = 1/N` (Tosun eq. 5, the finite sum of eq. 1), the
end-effector error is the squared distance of the chain ends (Tosun eq. 2), and the retargeting
error is their weighted sum (Tosun eq. 3):

.. math::
    E_p = \sum_{n=1}^{N} \delta\,|P_S(s_n) - P_T(q, s_n)|^2, \quad
    E_e = |P_S(1) - P_T(q, 1)|^2, \quad
    E = E_p + \alpha E_e.

The task's residual stacks :math:`e_n = P_S(s_n) - P_T(q, s_n)` for :math:`n = 1..N` and
:math:`e_{N+1} = P_S(1) - P_T(q, 1)`, with row weights :math:`\delta` and :math:`\alpha`, so that
:math:`E = \sum_i w_i |e_i|^2` and the task enters the QP like any other (Dariush 2009 eq. 9).

Jacobian. Each sample point lies on a segment between two consecutive chain frames. When both
ends of that segment are fixed in one body (the next frame's origin lies on the joint axis, the
usual case of joint frames) the point is a point of that link and its Jacobian is the point
Jacobian :math:`(1 - t) J_{p_k} + t J_{p_{k+1}}` (equal to the frame Jacobian of frame :math:`k`
shifted to the point), scaled by :math:`1/L`, with :math:`L` constant. In general (several joints
between two chain frames, e.g. a 3-DoF shoulder whose joint origins are offset) the segment lengths
change with :math:`q`; the task then differentiates the normalization exactly:

.. math::
    dP = \frac{dp_k - dp_0}{L} - \frac{(p_k - p_0)\,dL}{L^2} - d\hat c_k\,u_k
         + (s - \hat c_k)\,\frac{(I - u_k u_k^\top)(dp_{k+1} - dp_k)}{l_k},

with :math:`dl_j = u_j^\top (dp_{j+1} - dp_j)`, :math:`dL = \sum_j dl_j`,
:math:`d\hat c_k = (\sum_{j<k} dl_j - \hat c_k\,dL)/L` and :math:`dp_i = J_{p_i} v` the linear rows
of the LOCAL_WORLD_ALIGNED frame Jacobians. For rigid segments :math:`dl_j = 0` and the formula
reduces to the point Jacobian above.

Both chains are compared in the axes of ``reference_frame`` (a robot frame such as the torso, or
the world when ``None``): the robot's points become :math:`x = R^\top y` with Jacobian
:math:`R^\top (J_y + [y]_\times J_\omega)`, :math:`J_\omega` the reference frame's angular rows.
The source points, given in the same axes, can be turned first by ``source_rotation`` (how the
source is mounted on the robot, e.g. a human arm onto an industrial arm).

At acceleration level the drift :math:`\dot J v` of this task is taken as zero (not derived).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from .base import TASKS, Task

#: Segments shorter than this [m] (or [normalized length]) are treated as zero length.
_EPS_LENGTH = 1e-12


@dataclass(frozen=True, slots=True)
class ShapeErrors:
    r"""The three metrics of Tosun 2014 (dimensionless, chains normalized to unit length).

    Attributes:
        pose: :math:`E_p`, the sampled integral of the squared distance between the normalized
            poses (Tosun eq. 5).
        end_effector: :math:`E_e`, squared distance between the normalized chain ends (eq. 2).
        total: :math:`E = E_p + \alpha E_e` (eq. 3).
    """

    pose: float
    end_effector: float
    total: float


def sample_parameters(n_samples: int) -> np.ndarray:
    r"""The :math:`N + 1` arc-length parameters of the residual: :math:`s_n = n/N` then :math:`1`.

    The first :math:`N` are the samples of :math:`E_p` (Tosun eq. 5), the last one the
    end-effector of :math:`E_e` (eq. 2).
    """
    return np.concatenate([np.arange(1, n_samples + 1) / n_samples, [1.0]])


def rpy_matrix(rpy: npt.ArrayLike) -> np.ndarray:
    """Rotation matrix :math:`R_z(y) R_y(p) R_x(r)` of roll-pitch-yaw angles [rad]."""
    r, p, y = (float(a) for a in np.asarray(rpy, dtype=float))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _segments(
    points: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """Segment geometry of a polyline and the segment of every sample (shared by both chains)."""
    d = points[1:] - points[:-1]  # (M, 3)
    lengths = np.sqrt(np.einsum("mi,mi->m", d, d))  # (M,)
    total = float(lengths.sum())
    safe = np.where(lengths > _EPS_LENGTH, lengths, 1.0)
    u = d / safe[:, None] * (lengths > _EPS_LENGTH)[:, None]  # (M, 3) unit vectors, 0 if l = 0
    c_hat = np.concatenate([[0.0], np.cumsum(lengths)]) / (total if total > 0 else 1.0)
    # Sample s lies on segment k with c_hat[k] < s <= c_hat[k+1] (the first one for s = 0).
    k = np.clip(np.searchsorted(c_hat[1:], s, side="left"), 0, len(lengths) - 1)
    return d, lengths, safe, total, u, c_hat, k


def normalized_pose(points: npt.ArrayLike, s: npt.ArrayLike) -> np.ndarray:
    r"""Normalized pose :math:`P(s)` of a polyline (Tosun 3.1) at arc-length parameters ``s``.

    Args:
        points: (n, 3) chain points, base first [m] (any unit: the result is dimensionless).
        s: parameters in [0, 1] along the unit-length normalized chain.

    Returns:
        (len(s), 3) points of the chain translated to its base and scaled to unit length.

    Raises:
        ValueError: fewer than two points, or a chain of zero total length.
    """
    P = np.asarray(points, dtype=float)
    s = np.atleast_1d(np.asarray(s, dtype=float))
    if P.ndim != 2 or P.shape[0] < 2 or P.shape[1] != 3:
        raise ValueError(f"a chain needs (n >= 2, 3) points, got shape {P.shape}.")
    _, _, _, total, u, c_hat, k = _segments(P, s)
    if not total > _EPS_LENGTH:
        raise ValueError("the chain has zero total length (all its points coincide).")
    return (P[k] - P[0]) / total + (s - c_hat[k])[:, None] * u[k]


def shape_errors(
    source: npt.ArrayLike, target: npt.ArrayLike, *, n_samples: int = 100, alpha: float = 0.5
) -> ShapeErrors:
    r"""Tosun 2014 metrics between two chains given as points (eq. 2, 3, 5).

    Args:
        source: (n_s, 3) source chain points, base first.
        target: (n_t, 3) target chain points, base first, in the same axes.
        n_samples: :math:`N` of eq. 5.
        alpha: :math:`\alpha` of eq. 3.

    Returns:
        :math:`E_p`, :math:`E_e` and :math:`E`.
    """
    s = sample_parameters(n_samples)
    diff = normalized_pose(source, s) - normalized_pose(target, s)
    sq = np.einsum("ni,ni->n", diff, diff)
    e_p = float(sq[:n_samples].sum() / n_samples)
    e_e = float(sq[-1])
    return ShapeErrors(e_p, e_e, e_p + alpha * e_e)


def _check_alpha(alpha: Any) -> float:
    r""":math:`\alpha` of Tosun eq. 3 as a float; a ConfigError unless a finite number >= 0."""
    if (
        isinstance(alpha, bool)
        or not isinstance(alpha, (int, float, np.floating, np.integer))
        or not np.isfinite(alpha)
        or alpha < 0
    ):
        raise ConfigError(f"alpha must be a finite number >= 0, got {alpha!r}.")
    return float(alpha)


@TASKS.register("chain_shape")
class ChainShapeTask(Task):
    r"""Make a chain of robot frames take the normalized shape of a source chain (Tosun 2014).

    Args:
        name: task name (key of its target in ``Controller.step``).
        frames: the target chain, an ordered list of at least two robot frames, base first
            (e.g. shoulder, elbow, wrist, hand frames of an arm).
        n_samples: :math:`N`, number of samples of the pose error (Tosun eq. 5; the paper uses
            100 and reports good results down to 10).
        alpha: :math:`\alpha \ge 0`, weight of the end-effector error (Tosun eq. 3; 0.5 is the
            paper's recommended starting point).
        reference_frame: robot frame whose axes both chains are compared in (e.g. the torso of a
            humanoid); ``None`` for the world axes.
        source_rotation: rotation applied to every source point before the comparison, as
            roll-pitch-yaw [rad] (3 numbers, :math:`R_z R_y R_x`) or a 3x3 matrix; maps the
            source's axes to the reference frame's (how the source is mounted on the robot).
        weight: overall weight multiplying :math:`E` in the QP cost [cost].
        gain: task gain :math:`K` [1/s]; ``None`` corrects the whole linearized error in one
            tick (a Gauss-Newton step).
        level: priority level (``hierarchy`` strategy).
        recovery_time: ramp-back time after a missing (NaN) target [s].

    Targets accepted by ``step``: an (n_src, 3) array of source points, base first, with
    ``n_src >= 2`` (it may change from tick to tick). The source needs no kinematic model: its
    points are normalized as given (Tosun 4.1).

    Raises:
        ConfigError: on fewer than two frames, repeated frames, ``n_samples < 1``, negative
            ``alpha``, a bad rotation, or unknown frame names (at bind).
    """

    def __init__(
        self,
        name: str,
        frames: Sequence[str],
        *,
        n_samples: int = 100,
        alpha: float = 0.5,
        reference_frame: str | None = None,
        source_rotation: Any = None,
        weight: Any = 1.0,
        gain: float | None = None,
        level: int = 1,
        recovery_time: float = 0.2,
    ) -> None:
        super().__init__(name, weight=weight, gain=gain, level=level, recovery_time=recovery_time)
        if isinstance(frames, str) or not isinstance(frames, Sequence):
            raise ConfigError(f"frames must be a list of robot frame names, got {frames!r}.")
        frames = list(frames)
        if len(frames) < 2 or not all(isinstance(f, str) and f for f in frames):
            raise ConfigError(
                f"frames must list at least two robot frame names (base first), got {frames!r}."
            )
        if len(set(frames)) != len(frames):
            raise ConfigError(f"frames must be distinct, got {frames!r}.")
        if (
            isinstance(n_samples, bool)
            or not isinstance(n_samples, (int, np.integer))
            or n_samples < 1
        ):
            raise ConfigError(f"n_samples must be an integer >= 1, got {n_samples!r}.")
        alpha = _check_alpha(alpha)
        if reference_frame is not None and not isinstance(reference_frame, str):
            raise ConfigError(
                f"reference_frame must be a frame name or null, got {reference_frame!r}."
            )
        self.frames = frames
        self.n_samples = int(n_samples)
        self.alpha = alpha
        self.reference_frame = reference_frame
        self.source_rotation_spec = source_rotation
        self.source_rotation = self._parse_rotation(source_rotation)
        self.s = sample_parameters(self.n_samples)  # (N+1,)
        self.dim = 3 * (self.n_samples + 1)
        # Row weights of E = sum_i w_i e_i^2: delta on the E_p samples, alpha on the end-effector.
        self.metric_weight = np.concatenate(
            [np.full(3 * self.n_samples, 1.0 / self.n_samples), np.full(3, self.alpha)]
        )
        self.frame_ids: list[int] = []
        self.reference_id: int | None = None
        self.source_points: np.ndarray | None = None  # (n_src, 3) in the reference axes
        self.source_samples = np.zeros((self.n_samples + 1, 3))
        self._cache_q: np.ndarray | None = None
        self._cache_version = -1
        self._version = 0
        self._error = np.zeros(self.dim)
        self._jacobian = np.zeros((self.dim, 0))
        self._samples = np.zeros((self.n_samples + 1, 3))

    @staticmethod
    def _parse_rotation(spec: Any) -> np.ndarray | None:
        if spec is None:
            return None
        try:
            arr = np.asarray(spec, dtype=float)
        except (TypeError, ValueError):
            arr = None
        if arr is not None and arr.shape == (3,) and np.all(np.isfinite(arr)):
            return rpy_matrix(arr)
        if arr is not None and arr.shape == (3, 3) and np.all(np.isfinite(arr)):
            if (
                np.allclose(arr.T @ arr, np.eye(3), atol=1e-6)
                and abs(np.linalg.det(arr) - 1) < 1e-6
            ):
                return arr.copy()
        raise ConfigError(
            "source_rotation must be roll-pitch-yaw angles [r, p, y] in radians or a 3x3 "
            f"rotation matrix, got {spec!r}."
        )

    # ------------------------------------------------------------------ lifecycle
    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        prefix = f"{path}." if path else ""
        self.frame_ids = [
            robot.frame_id(f, path=f"{prefix}frames[{i}]") for i, f in enumerate(self.frames)
        ]
        if self.reference_frame is not None:
            self.reference_id = robot.frame_id(
                self.reference_frame, path=f"{prefix}reference_frame"
            )
        super().bind(robot, path=path)
        self._base_weight = self.weight.copy()
        self.weight = self._base_weight * self.metric_weight
        self._jacobian = np.zeros((self.dim, robot.nv))
        self._eye = np.eye(3)
        state = RobotState(robot)
        P = np.array([state.frame_placement(f).translation for f in self.frame_ids])
        if not np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1)) > 1e-9:
            raise ConfigError(
                f"the frames {self.frames} all sit at the same point in the robot's reference "
                "posture: the chain has no length to normalize. List frames along the chain.",
                path=f"{prefix}frames",
            )

    def reset(self, state: RobotState) -> None:
        """Take the robot chain's current normalized pose as the source (zero error)."""
        super().reset(state)
        self._update(state)
        self.source_points = None
        self.source_samples = self._samples.copy()
        self._version += 1

    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        """Set the source chain: (n_src, 3) points, base first, in the source's axes.

        Returns:
            ``False`` when the points hold NaN/inf (missing data): the last source is kept.

        Raises:
            TargetError: on a wrong shape or type, or a source chain of zero length.
        """
        arr = self.target_array(
            target, tick, "target must be an (n, 3) array of source chain points"
        )
        if arr.ndim != 2 or arr.shape[0] < 2 or arr.shape[1] != 3:
            raise self.target_error(
                f"target must be an (n, 3) array of n >= 2 source chain points (base first), "
                f"got shape {arr.shape}.",
                tick,
            )
        if not np.all(np.isfinite(arr)):
            return False
        if self.source_rotation is not None:
            arr = arr @ self.source_rotation.T
        try:
            samples = normalized_pose(arr, self.s)
        except ValueError:
            raise self.target_error(
                "the source chain has zero total length (all its points coincide).", tick
            ) from None
        self.source_points = arr
        self.source_samples = samples
        self._version += 1
        return True

    def set_alpha(self, alpha: float) -> None:
        r"""Change :math:`\alpha` (Tosun eq. 3) without rebuilding the controller.

        Raises:
            ConfigError: when ``alpha`` is not a finite number >= 0.
        """
        self.alpha = _check_alpha(alpha)
        self.metric_weight[-3:] = self.alpha
        if self.weight.shape == self.metric_weight.shape:  # bound
            self.weight = self._base_weight * self.metric_weight

    # ------------------------------------------------------------------ maths
    def _update(self, state: RobotState) -> None:
        """Normalized robot samples, residual and Jacobian of ``state`` (cached per q/target)."""
        if (
            self._cache_q is not None
            and self._cache_version == self._version
            and self._cache_q.shape == state.q.shape
            and np.array_equal(self._cache_q, state.q)
        ):
            return
        ids = self.frame_ids
        P = np.array([state.frame_placement(f).translation for f in ids])  # (M+1, 3)
        nv = state.model.nv
        # reshape: pinocchio hands back a (6,) array, not (6, 1), when nv == 1.
        JP = np.array([state.frame_jacobian(f)[:3] for f in ids]).reshape(len(ids), 3, nv)
        s = self.s
        d, lengths, safe, L, u, c_hat, k = _segments(P, s)
        if not L > _EPS_LENGTH:
            # Degenerate configuration (all frames at one point): no shape, no gradient.
            self._samples[...] = 0.0
            self._jacobian[...] = 0.0
            self._error[...] = (self.source_samples - self._samples).ravel()
            self._cache_q, self._cache_version = state.q.copy(), self._version
            return
        a = s - c_hat[k]  # (S,) normalized arc length into the segment
        base = P[k] - P[0]  # (S, 3)
        Y = base / L + a[:, None] * u[k]  # (S, 3) world-aligned normalized pose
        D = JP[1:] - JP[:-1]  # (M, 3, nv)
        dl = np.einsum("mi,miv->mv", u, D)  # (M, nv)
        dL = dl.sum(axis=0)  # (nv,)
        dc = np.concatenate([np.zeros((1, dL.shape[0])), np.cumsum(dl, axis=0)])  # (M+1, nv)
        dc_hat = (dc - c_hat[:, None] * dL[None, :]) / L  # (M+1, nv)
        proj = self._eye[None] - u[:, :, None] * u[:, None, :]  # (M, 3, 3)
        du = np.einsum("mij,mjv->miv", proj, D) / safe[:, None, None]  # (M, 3, nv)
        JY = (
            (JP[k] - JP[0][None]) / L
            - base[:, :, None] * (dL / (L * L))[None, None, :]
            - u[k][:, :, None] * dc_hat[k][:, None, :]
            + a[:, None, None] * du[k]
        )  # (S, 3, nv)
        if self.reference_id is not None:
            M = state.frame_placement(self.reference_id)
            R = M.rotation
            Jw = state.frame_jacobian(self.reference_id).reshape(6, nv)[3:]  # (3, nv)
            # d(R^T y) = R^T (dy + y x omega): add [y]x J_w row by row.
            cross = np.empty_like(JY)
            cross[:, 0] = Y[:, 1, None] * Jw[2] - Y[:, 2, None] * Jw[1]
            cross[:, 1] = Y[:, 2, None] * Jw[0] - Y[:, 0, None] * Jw[2]
            cross[:, 2] = Y[:, 0, None] * Jw[1] - Y[:, 1, None] * Jw[0]
            JY = np.einsum("ji,sjv->siv", R, JY + cross)
            Y = Y @ R
        self._samples[...] = Y
        self._jacobian[...] = JY.reshape(self.dim, -1)
        self._error[...] = (self.source_samples - Y).ravel()
        self._cache_q, self._cache_version = state.q.copy(), self._version

    def compute_error(self, state: RobotState) -> np.ndarray:
        r"""Stacked :math:`P_S(s_n) - P_T(q, s_n)`, n = 1..N, then the chain end (3(N+1),)."""
        self._update(state)
        return self._error.copy()

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        r""":math:`\partial P_T(q, s_n) / \partial q` stacked like the error (3(N+1), nv)."""
        self._update(state)
        return self._jacobian.copy()

    def error_norm(self, error: np.ndarray) -> float:
        r"""The retargeting error :math:`E = E_p + \alpha E_e` (Tosun eq. 3) of a residual."""
        return float(np.dot(self.metric_weight, error * error))

    def errors(self, state: RobotState) -> ShapeErrors:
        """:math:`E_p`, :math:`E_e` and :math:`E` of the chain in ``state`` (Tosun eq. 2-5)."""
        self._update(state)
        sq = (self._error * self._error).reshape(-1, 3).sum(axis=1)
        e_p = float(sq[: self.n_samples].sum() / self.n_samples)
        e_e = float(sq[-1])
        return ShapeErrors(e_p, e_e, e_p + self.alpha * e_e)

    def robot_samples(self, state: RobotState) -> np.ndarray:
        """Normalized pose of the robot chain at the samples, in the reference axes (N+1, 3)."""
        self._update(state)
        return self._samples.copy()

    def robot_points(self, state: RobotState) -> np.ndarray:
        """The robot chain's frame origins, base at 0, scaled to unit length, reference axes."""
        P = np.array([state.frame_placement(f).translation for f in self.frame_ids])
        P = P - P[0]
        P = P / np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1))
        if self.reference_id is not None:
            P = P @ state.frame_placement(self.reference_id).rotation
        return P

    def __repr__(self) -> str:
        return (
            f"ChainShapeTask(frames={self.frames!r}, n_samples={self.n_samples}, "
            f"alpha={self.alpha}, reference_frame={self.reference_frame!r}, "
            f"source_rotation={self.source_rotation_spec!r}, name={self.name!r}, "
            f"weight={self._weight_spec!r}, gain={self.gain!r}, level={self.level})"
        )
