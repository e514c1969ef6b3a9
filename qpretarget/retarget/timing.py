# SPDX-License-Identifier: Apache-2.0
r"""Velocity limits by time modulation (Dariush 2009 section 4.5, eq. 15-16).

Instead of clamping joint velocities (which changes the motion's shape), the time between two
samples is stretched where the motion is too fast. A trajectory sampled at times
:math:`t_{s+1} = t_s + \Delta t_s` (eq. 15) with joint velocities
:math:`\dot q_s = (q_{s+1} \ominus q_s)/\Delta t_s` gets the time-modulation factor

.. math:: \epsilon_s = \max_j \frac{|\dot q_{s,j}|}{\dot q_{lim,j}}

(the largest over the joints, "to synchronize the sample time for all joints") and new times

.. math::
    t'_{s+1} = \begin{cases} t'_s + \Delta t_s \epsilon_s & \epsilon_s \ge 1 \\
                             t'_s + \Delta t_s & \epsilon_s < 1 \end{cases}
    \qquad \text{(eq. 16, } :func:`expand_time` \text{)}

so every interval is traversed at most at the velocity limit, through the same configurations in
the same order: the profile is unchanged, the motion lasts longer.

:func:`preserve_duration` is the variant the paper outlines without equations: expand where too
fast, compress elsewhere, same total duration :math:`T`. It uses one compression level
:math:`c \in [1/\text{max\_speedup}, 1]`, :math:`\Delta t'_s = \Delta t_s \max(\epsilon_s, c)`, with
:math:`c` found by bisection so that :math:`\sum_s \Delta t'_s = T` (the left side grows with
:math:`c`); slow intervals all speed up by the same factor :math:`1/c`, limited intervals run
exactly at their limit.

**Blending** (the paper: "blending functions in the design of :math:`\epsilon_s` to maintain
smoothness"). A raw factor sequence jumps where a joint crosses its limit, which makes the retimed
velocity jump. With ``blend_time`` > 0 the factors are smoothed over a window of that length by a
running maximum followed by a Hann-weighted average of the same width: every smoothed factor is a
convex combination of window maxima that all include the raw factor at that sample, so it is never
below it and the velocity limits still hold.

Functions take times ``t`` (N,) and positions ``q`` (N, n) with limits ``v_max`` (n,); or, with
``robot=``, configurations (N, nq) differentiated on the manifold and the robot's velocity limits
(nv,) (free-flyer coordinates are unlimited).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from scipy.ndimage import maximum_filter1d

from ..errors import QPRetargetError
from ..robot import RobotModel

__all__ = [
    "TimingError",
    "modulation_factors",
    "blend_factors",
    "expand_time",
    "preserve_duration",
    "resample",
    "retime",
]


class TimingError(QPRetargetError, ValueError):
    """A trajectory cannot be retimed (bad shapes, non-increasing times, infeasible duration)."""


def _check(
    t: npt.ArrayLike, q: npt.ArrayLike, v_max: npt.ArrayLike | None, robot: RobotModel | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return ``t``, ``q``, the interval velocities (N-1, n) and the limits (n,)."""
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise TimingError(f"t must be a 1-D array of at least 2 times, got shape {t.shape}.")
    if q.ndim == 1:
        q = q[:, None]
    if q.ndim != 2 or q.shape[0] != t.shape[0]:
        raise TimingError(f"q must have shape ({t.shape[0]}, n) to match t, got {q.shape}.")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise TimingError("t and q must be finite (no NaN or inf).")
    dt = np.diff(t)
    if np.any(dt <= 0):
        s = int(np.flatnonzero(dt <= 0)[0])
        raise TimingError(f"t must increase strictly; t[{s + 1}] = {t[s + 1]} <= t[{s}] = {t[s]}.")
    if robot is not None:
        if q.shape[1] != robot.nq:
            raise TimingError(
                f"with robot=, q holds configurations (N, {robot.nq}), got {q.shape}."
            )
        dq = np.array([robot.difference(q[s], q[s + 1]) for s in range(q.shape[0] - 1)])
        lim = robot.v_max if v_max is None else np.asarray(v_max, dtype=float)
    else:
        if v_max is None:
            raise TimingError("give the velocity limits v_max (n,), or robot= to use the robot's.")
        dq = np.diff(q, axis=0)
        lim = np.asarray(v_max, dtype=float)
    lim = np.broadcast_to(lim, (dq.shape[1],)) if lim.ndim == 0 else lim
    if lim.shape != (dq.shape[1],):
        raise TimingError(f"v_max must have shape ({dq.shape[1]},), got {lim.shape}.")
    if np.any(~(lim > 0)):
        raise TimingError("velocity limits must be > 0 (inf for an unlimited coordinate).")
    return t, q, dq / dt[:, None], lim


def modulation_factors(
    t: npt.ArrayLike,
    q: npt.ArrayLike,
    v_max: npt.ArrayLike | None = None,
    *,
    robot: RobotModel | None = None,
) -> np.ndarray:
    r"""Time-modulation factors :math:`\epsilon_s = \max_j |\dot q_{s,j}|/\dot q_{lim,j}` (N-1,).

    Dariush 2009 eq. 16, synchronized over the joints (largest factor); interval velocities by
    forward differences.

    Raises:
        TimingError: on bad shapes, non-finite values, non-increasing times or bad limits.
    """
    _, _, qd, lim = _check(t, q, v_max, robot)
    return np.max(np.abs(qd) / lim, axis=1)


def blend_factors(factors: np.ndarray, t: np.ndarray, blend_time: float) -> np.ndarray:
    """Smooth a factor sequence without going below it (running max, then Hann average).

    Args:
        factors: per-interval factors (N-1,).
        t: sample times (N,), used for the median interval to size the window.
        blend_time: window length [s]; 0 returns the factors unchanged.
    """
    if blend_time < 0 or not np.isfinite(blend_time):
        raise TimingError(
            f"blend_time must be a finite number of seconds >= 0, got {blend_time!r}."
        )
    h = int(round(0.5 * blend_time / float(np.median(np.diff(t)))))
    if h <= 0 or factors.size < 2:
        return factors.copy()
    w = 2 * h + 1
    m = maximum_filter1d(factors, size=w, mode="nearest")
    kernel = np.hanning(w + 2)[1:-1]
    kernel /= kernel.sum()
    smooth = np.convolve(np.pad(m, h, mode="edge"), kernel, mode="valid")
    return np.maximum(smooth, factors)  # round-off guard: never below the raw factors


def expand_time(
    t: npt.ArrayLike,
    q: npt.ArrayLike,
    v_max: npt.ArrayLike | None = None,
    *,
    robot: RobotModel | None = None,
    blend_time: float = 0.0,
) -> np.ndarray:
    r"""Retime by Dariush 2009 eq. 16: :math:`\Delta t'_s = \Delta t_s \max(\epsilon_s, 1)`.

    Args:
        t: sample times (N,) [s], strictly increasing.
        q: positions (N, n), or configurations (N, nq) with ``robot``.
        v_max: velocity limits (n,) (default with ``robot``: the robot's).
        robot: differentiate configurations on the robot's manifold.
        blend_time: smoothing window of the factors [s] (0: the paper's raw eq. 16).

    Returns:
        The retimed sample times (N,), starting at ``t[0]``; ``q`` is unchanged.
    """
    t = np.asarray(t, dtype=float)
    eps = modulation_factors(t, q, v_max, robot=robot)
    f = blend_factors(np.maximum(eps, 1.0), t, blend_time)
    return np.concatenate([[t[0]], t[0] + np.cumsum(np.diff(t) * f)])


def preserve_duration(
    t: npt.ArrayLike,
    q: npt.ArrayLike,
    v_max: npt.ArrayLike | None = None,
    *,
    robot: RobotModel | None = None,
    blend_time: float = 0.0,
    max_speedup: float = 4.0,
) -> np.ndarray:
    r"""Retime within the same total duration: expand too-fast intervals, compress the others.

    :math:`\Delta t'_s = \Delta t_s\, \tilde f_s(c)` with :math:`\tilde f(c)` the blended
    :math:`\max(\epsilon_s, c)` and :math:`c \in [1/\text{max\_speedup}, 1]` solved by bisection
    so that :math:`\sum_s \Delta t'_s = t_{N-1} - t_0`.

    Args:
        t: sample times (N,) [s].
        q: positions (N, n), or configurations (N, nq) with ``robot``.
        v_max: velocity limits (n,).
        robot: differentiate configurations on the robot's manifold.
        blend_time: smoothing window of the factors [s].
        max_speedup: no interval is compressed by more than this factor (> 1).

    Returns:
        The retimed sample times (N,), same first and (to round-off) last time.

    Raises:
        TimingError: when even the largest allowed compression cannot absorb the expansion
            (the message gives the shortest duration possible).
    """
    t = np.asarray(t, dtype=float)
    if not (isinstance(max_speedup, (int, float)) and max_speedup > 1):
        raise TimingError(f"max_speedup must be a number > 1, got {max_speedup!r}.")
    eps = modulation_factors(t, q, v_max, robot=robot)
    dt = np.diff(t)
    total = float(dt.sum())

    def duration(c: float) -> tuple[float, np.ndarray]:
        f = blend_factors(np.maximum(eps, c), t, blend_time)
        return float(dt @ f), f

    lo, hi = 1.0 / max_speedup, 1.0
    d_hi, _ = duration(hi)
    if d_hi <= total:  # nothing exceeds a limit (after blending): keep the timing
        return t.copy()
    d_lo, f_lo = duration(lo)
    if d_lo > total:
        raise TimingError(
            f"the motion cannot respect the velocity limits within its duration {total:.4g} s: "
            f"it needs at least {d_lo:.4g} s with max_speedup={max_speedup} (use expand_time, a "
            f"larger max_speedup or a shorter blend_time)."
        )
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        d_mid, f_mid = duration(mid)
        if d_mid > total:
            hi = mid
        else:
            lo, f_lo = mid, f_mid
        if hi - lo < 1e-15:
            break
    return np.concatenate([[t[0]], t[0] + np.cumsum(dt * f_lo)])  # f_lo: duration <= total


def resample(
    t: npt.ArrayLike, q: npt.ArrayLike, dt: float, *, robot: RobotModel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Resample a (retimed) trajectory on a uniform grid of step ``dt`` by linear interpolation.

    Linear interpolation keeps the velocity limits: the velocity between two grid points is an
    average of the interval velocities it spans. With ``robot``, configurations are interpolated
    on the manifold (``pinocchio.interpolate``).

    Returns:
        ``(t_grid, q_grid)``, ``t_grid = t[0] + k dt`` up to ``t[-1]`` (included to round-off).
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if not (isinstance(dt, (int, float)) and dt > 0):
        raise TimingError(f"dt must be a positive number of seconds, got {dt!r}.")
    n = int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    tg = t[0] + dt * np.arange(n)
    idx = np.clip(np.searchsorted(t, tg, side="right") - 1, 0, t.shape[0] - 2)
    a = np.clip((tg - t[idx]) / (t[idx + 1] - t[idx]), 0.0, 1.0)
    if robot is None:
        q2 = q if q.ndim == 2 else q[:, None]
        qg = q2[idx] + a[:, None] * (q2[idx + 1] - q2[idx])
        return tg, qg if q.ndim == 2 else qg[:, 0]
    qg = np.array(
        [pin.interpolate(robot.model, q[i], q[i + 1], ai) for i, ai in zip(idx, a, strict=True)]
    )
    return tg, qg


def retime(
    t: npt.ArrayLike,
    q: npt.ArrayLike,
    v_max: npt.ArrayLike | None = None,
    *,
    robot: RobotModel | None = None,
    mode: str = "expand",
    blend_time: float = 0.0,
    dt: float | None = None,
    **kwargs: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """Retime a trajectory to its velocity limits; optionally resample it on a ``dt`` grid.

    Args:
        t: sample times (N,) [s].
        q: positions (N, n), or configurations (N, nq) with ``robot``.
        v_max: velocity limits (n,) (default with ``robot``: the robot's).
        robot: differentiate and interpolate configurations on the robot's manifold.
        blend_time: smoothing window of the factors [s].
        mode: ``expand`` (:func:`expand_time`) or ``preserve`` (:func:`preserve_duration`).
        dt: resample on a uniform grid of this step [s] (``None``: keep the samples).
        **kwargs: ``max_speedup`` for ``preserve``.

    Returns:
        ``(t_new, q_new)``.
    """
    if mode == "expand":
        if kwargs:
            raise TimingError(f"mode 'expand' takes no {sorted(kwargs)}.")
        t_new = expand_time(t, q, v_max, robot=robot, blend_time=blend_time)
    elif mode == "preserve":
        t_new = preserve_duration(t, q, v_max, robot=robot, blend_time=blend_time, **kwargs)
    else:
        raise TimingError(f"mode must be 'expand' or 'preserve', got {mode!r}.")
    q = np.asarray(q, dtype=float)
    if dt is None:
        return t_new, q.copy()
    return resample(t_new, q, dt, robot=robot)
