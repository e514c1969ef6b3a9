# SPDX-License-Identifier: Apache-2.0
r"""Resampling a run to an output frame rate, independent of the control rate.

The controller runs at its control rate (100 Hz by default) — tracking and constraints are
computed there — and a dataset often wants 30 or 50 fps. :func:`resample_run` samples the run at
:math:`t_k = t_0 + k / f_{out}`, :math:`k = 0 \dots \lfloor (t_{end} - t_0) f_{out} \rfloor`:

* root position: cubic spline (not-a-knot) through the control-rate samples;
* root orientation: spherical linear interpolation of the unit quaternions (scipy ``Slerp``);
* joint angles: cubic spline, then clipped to the joint limits (a spline can overshoot a limit the
  control-rate samples respect);
* contact labels, status and other per-tick labels: the nearest control-rate sample;
* task targets and reached positions (``target/<task>``, ``actual/<task>``): cubic spline, so
  that tracking errors of the resampled run are comparable with the control-rate run.

Resampling a run at its own rate returns its samples unchanged (to round-off).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from ..errors import QPRetargetError
from ..robot import RobotModel
from ..trajectory import RobotTrajectory


class ResampleError(QPRetargetError, ValueError):
    """The run cannot be resampled at the requested rate."""


def output_times(t: np.ndarray, fps: float) -> np.ndarray:
    """Sample times :math:`t_0 + k/f` within ``[t[0], t[-1]]`` (to 1e-9 s)."""
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ResampleError(f"--fps must be a positive number of frames per second, got {fps!r}.")
    n = int(math.floor((float(t[-1]) - float(t[0])) * fps + 1e-9)) + 1
    return float(t[0]) + np.arange(n) / float(fps)


def _spline(t: np.ndarray, y: np.ndarray, ts: np.ndarray) -> np.ndarray:
    if len(t) < 4:  # too few samples for a cubic: linear
        return np.stack([np.interp(ts, t, y[:, j]) for j in range(y.shape[1])], axis=1)
    return np.asarray(CubicSpline(t, y, axis=0)(ts))


def _per_tick(a: np.ndarray, n: int) -> bool:
    return bool(np.ndim(a)) and len(a) == n


def _nearest(t: np.ndarray, ts: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(t, ts), 1, len(t) - 1)
    left = ts - t[idx - 1] < t[idx] - ts
    return np.where(left, idx - 1, idx)


def resample_q(
    t: np.ndarray,
    q: np.ndarray,
    ts: np.ndarray,
    *,
    free_flyer: bool,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> np.ndarray:
    """Configurations at ``ts`` (module docstring); ``lower``/``upper`` clip the joints."""
    q = np.asarray(q, dtype=float)
    out = np.empty((len(ts), q.shape[1]))
    j0 = 7 if free_flyer else 0
    if free_flyer:
        out[:, :3] = _spline(t, q[:, :3], ts)
        rot = Rotation.from_quat(q[:, 3:7])  # pinocchio stores x y z w, as scipy
        out[:, 3:7] = Slerp(t, rot)(ts).as_quat()
        # Keep the hemisphere of the input (q and -q are one rotation; trainers like continuity).
        flip = np.sum(out[:, 3:7] * q[_nearest(t, ts), 3:7], axis=1) < 0
        out[flip, 3:7] *= -1.0
    out[:, j0:] = _spline(t, q[:, j0:], ts)
    if lower is not None and upper is not None:
        np.clip(out[:, j0:], lower, upper, out=out[:, j0:])
    return out


def resample_run(
    traj: RobotTrajectory, fps: float, *, robot: RobotModel | None = None
) -> RobotTrajectory:
    """The run sampled at ``fps`` frames per second (module docstring).

    Args:
        traj: the control-rate run.
        fps: output rate [Hz].
        robot: its :class:`~qpretarget.robot.RobotModel` (joint limits for the clip); ``None``
            leaves the joints unclipped.

    Returns:
        A new :class:`RobotTrajectory` at ``fps``; ``meta["output_fps"]`` records the rate and
        ``meta["control_rate"]`` stays the rate the controller ran at.

    Raises:
        ResampleError: ``fps`` is not a positive number or the run has fewer than 2 samples.
    """
    t = np.asarray(traj.t, dtype=float)
    if len(t) < 2:
        raise ResampleError("a run needs at least 2 samples to be resampled.")
    ts = output_times(t, fps)
    q = np.asarray(traj.q, dtype=float)
    free_flyer = q.shape[1] == len(traj.joint_names) + 7
    lower = upper = None
    if robot is not None:
        j0 = 7 if free_flyer else 0
        lower = robot.model.lowerPositionLimit[j0:]
        upper = robot.model.upperPositionLimit[j0:]
    qs = resample_q(t, q, ts, free_flyer=free_flyer, lower=lower, upper=upper)
    vs = _spline(t, np.asarray(traj.v, dtype=float), ts)
    near = _nearest(t, ts)

    def pick(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[near]

    meta = dict(traj.meta)
    meta["output_fps"] = float(fps)
    return RobotTrajectory(
        t=ts,
        q=qs,
        v=vs,
        joint_names=list(traj.joint_names),
        robot=traj.robot,
        config_yaml=traj.config_yaml,
        task_names=list(traj.task_names),
        targets={k: _spline(t, np.asarray(a, float), ts) for k, a in traj.targets.items()},
        actual={k: _spline(t, np.asarray(a, float), ts) for k, a in traj.actual.items()},
        contacts=pick(traj.contacts),
        foot_names=list(traj.foot_names),
        status=pick(traj.status),
        solve_time=pick(traj.solve_time),
        tau=None if traj.tau is None else _spline(t, np.asarray(traj.tau, float), ts),
        human={},
        extra={k: np.asarray(a)[near] for k, a in traj.extra.items() if _per_tick(a, len(t))},
        meta=meta,
    )
