# SPDX-License-Identifier: Apache-2.0
r"""Pure measures on arrays: the building blocks of every metric of a run.

One definition each, used by :mod:`qpretarget.analysis.metrics` (``qpretarget evaluate``), the
run summary of ``qpretarget retarget`` and the tests:

* :func:`rmse`, :math:`\sqrt{\tfrac1T \sum_k |x^r_k - x_k|^2}` over the frames with data;
* :func:`joint_limit_violations` (CRAC Fig. 3-4, 11);
* :func:`signed_distance_to_polygon` (CoM margin to the support polygon);
* :func:`interval_derivatives`, :func:`derivative_peaks` (velocity, acceleration, jerk);
* :func:`instantaneous_power`, :func:`average_absolute_power` (CRAC eq. 43),
  :func:`tangent_velocities`, :func:`rnea_torques`, :func:`carry_base_wrench`;
* :func:`solve_time_stats`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..errors import QPRetargetError
from ..robot import RobotModel

#: Joint positions further than this outside ``[q_min, q_max]`` count as a violation [rad]. It is
#: far above the solvers' tolerances (a constrained run stays within ~1e-9 rad) and far below any
#: violation a human would notice.
JOINT_LIMIT_TOLERANCE = 1e-6

#: Safety distance [m] used when the run's config has no self-collision constraint giving one.
DEFAULT_SAFETY_DISTANCE = 0.01


class MetricsError(QPRetargetError, ValueError):
    """A metric cannot be computed from the given run (wrong shapes, unknown names)."""


def rmse(reference: npt.ArrayLike, actual: npt.ArrayLike) -> float:
    r"""Root mean squared Euclidean error :math:`\sqrt{\tfrac1T\sum_k |r_k - a_k|^2}`.

    Rows holding NaN (missing reference data) are left out; ``nan`` if no row is left.

    Args:
        reference: (T, d) reference positions (targets).
        actual: (T, d) reached positions.

    Returns:
        The RMSE in the unit of the inputs.
    """
    r = np.asarray(reference, float)
    a = np.asarray(actual, float)
    if r.shape != a.shape:
        raise MetricsError(f"rmse: reference shape {r.shape} differs from actual shape {a.shape}.")
    e = r - a
    e = e.reshape(len(e), -1)
    ok = np.all(np.isfinite(e), axis=1)
    if not ok.any():
        return math.nan
    return float(np.sqrt(np.mean(np.sum(e[ok] ** 2, axis=1))))


def joint_limit_violations(
    q_joints: npt.ArrayLike,
    q_min: npt.ArrayLike,
    q_max: npt.ArrayLike,
    *,
    tolerance: float = JOINT_LIMIT_TOLERANCE,
) -> tuple[np.ndarray, np.ndarray]:
    """Joints outside their limits, frame by frame.

    Args:
        q_joints: (T, n) joint positions [rad or m].
        q_min: (n,) lower limits (``-inf`` for none).
        q_max: (n,) upper limits (``inf`` for none).
        tolerance: a joint counts when further than this outside its range.

    Returns:
        ``(mask, amount)``: (T, n) booleans, and (T, n) distance outside the range (0 inside).
    """
    q = np.asarray(q_joints, float)
    lo = np.asarray(q_min, float)
    hi = np.asarray(q_max, float)
    amount = np.maximum(np.maximum(lo - q, q - hi), 0.0)
    return amount > tolerance, amount


def signed_distance_to_polygon(point: npt.ArrayLike, polygon: npt.ArrayLike) -> float:
    """Signed distance of a 2-D point to a convex polygon: > 0 inside, < 0 outside [m].

    Inside, the distance to the nearest edge line; outside, minus the distance to the polygon.

    Args:
        point: (2,) point.
        polygon: (m, 2) counter-clockwise convex polygon (from :func:`convex_hull_2d`).
    """
    p = np.asarray(point, float)
    P = np.asarray(polygon, float)
    if len(P) == 0:
        return math.nan
    if len(P) == 1:
        return -float(np.linalg.norm(p - P[0]))
    a = P
    b = np.roll(P, -1, axis=0)
    ab = b - a
    ap = p - a
    L = np.linalg.norm(ab, axis=1)
    L = np.where(L > 0, L, 1.0)
    # Cross product > 0: p is left of edge a->b, i.e. inside for a counter-clockwise polygon.
    cross = (ab[:, 0] * ap[:, 1] - ab[:, 1] * ap[:, 0]) / L
    if len(P) >= 3 and np.all(cross >= 0):
        return float(np.min(cross))
    s = np.clip(np.sum(ap * ab, axis=1) / (L * L), 0.0, 1.0)
    d = np.linalg.norm(ap - s[:, None] * ab, axis=1)
    return -float(np.min(d))


def interval_derivatives(t: npt.ArrayLike, x: npt.ArrayLike, order: int) -> np.ndarray:
    """``order``-th derivative of ``x`` over ``t`` by divided differences.

    The first derivative lives on the midpoints of the sample intervals, the next one on the
    midpoints of those, and so on (exact for polynomials of degree ``order``, whatever the
    spacing).

    Args:
        t: (T,) increasing sample times [s].
        x: (T, n) samples.
        order: 1 (velocity), 2 (acceleration) or 3 (jerk).

    Returns:
        (T - order, n) derivative samples.
    """
    tt = np.asarray(t, float)
    d = np.asarray(x, float)
    if d.ndim == 1:
        d = d[:, None]
    for _ in range(order):
        if len(tt) < 2:
            return np.zeros((0, d.shape[1]))
        dt = np.diff(tt)
        if np.any(dt <= 0):
            raise MetricsError("sample times must be strictly increasing.")
        d = np.diff(d, axis=0) / dt[:, None]
        tt = 0.5 * (tt[1:] + tt[:-1])
    return d


def derivative_peaks(t: npt.ArrayLike, q: npt.ArrayLike) -> dict[str, np.ndarray]:
    """Per-joint peaks of |velocity|, |acceleration| and |jerk| by finite differences of ``q``.

    Args:
        t: (T,) sample times [s].
        q: (T, n) joint positions [rad].

    Returns:
        ``{"velocity": (n,), "acceleration": (n,), "jerk": (n,)}`` in [rad/s], [rad/s^2],
        [rad/s^3] (``nan`` when the run is too short for that order).
    """
    q = np.asarray(q, float)
    out = {}
    for order, key in ((1, "velocity"), (2, "acceleration"), (3, "jerk")):
        d = interval_derivatives(t, q, order)
        out[key] = np.max(np.abs(d), axis=0) if len(d) else np.full(q.shape[1], np.nan)
    return out


def instantaneous_power(tau: npt.ArrayLike, qdot: npt.ArrayLike) -> np.ndarray:
    r"""Absolute mechanical power :math:`|\tau_j^\top \dot q_j|` of each sample [W].

    Args:
        tau: (N, n) joint torques [N m] (forces [N] for prismatic joints).
        qdot: (N, n) joint velocities [rad/s].
    """
    tau = np.asarray(tau, float)
    qdot = np.asarray(qdot, float)
    if tau.shape != qdot.shape:
        raise MetricsError(f"power: tau shape {tau.shape} differs from qdot shape {qdot.shape}.")
    return np.abs(np.sum(tau * qdot, axis=-1))


def average_absolute_power(tau: npt.ArrayLike, qdot: npt.ArrayLike) -> float:
    r"""Average absolute power, CRAC eq. 43 [W].

    .. math:: P_{tot} = \frac{1}{N_s} \sum_{j=1}^{N_s} |\tau_j^\top \dot q_j|

    Args:
        tau: (N_s, n) joint torques [N m].
        qdot: (N_s, n) joint velocities [rad/s].
    """
    p = instantaneous_power(tau, qdot)
    return float(np.mean(p)) if p.size else math.nan


def tangent_velocities(
    robot: RobotModel, t: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Velocities and accelerations at the interior samples, by finite differences on the manifold.

    With :math:`\bar v_k = (q_{k+1} \ominus q_k) / (t_{k+1} - t_k)` on each interval, the sample
    :math:`k` (``1 <= k <= T-2``) gets :math:`\dot q_k = (\bar v_{k-1} + \bar v_k)/2` and
    :math:`\ddot q_k = (\bar v_k - \bar v_{k-1}) / ((t_{k+1} - t_{k-1})/2)`.

    Returns:
        ``(index, qdot, qddot)``: (N,) sample indices, (N, nv), (N, nv) with ``N = T - 2``.
    """
    T = len(t)
    if T < 3:
        return np.zeros(0, int), np.zeros((0, robot.nv)), np.zeros((0, robot.nv))
    vb = np.array([robot.difference(q[k], q[k + 1]) for k in range(T - 1)])
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise MetricsError("sample times must be strictly increasing.")
    vb /= dt[:, None]
    qdot = 0.5 * (vb[:-1] + vb[1:])
    qddot = (vb[1:] - vb[:-1]) / (0.5 * (t[2:] - t[:-2]))[:, None]
    return np.arange(1, T - 1), qdot, qddot


def rnea_torques(
    robot: RobotModel, q: np.ndarray, qdot: np.ndarray, qddot: np.ndarray
) -> np.ndarray:
    r"""Inverse dynamics :math:`\tau = H(q)\ddot q + C(q,\dot q)\dot q + \tau_g(q)` (CRAC eq. 30).

    Computed with pinocchio's RNEA for each sample; contact forces are not modelled (the floating
    base's motion is prescribed, its wrench is the first six entries of ``tau``).

    Returns:
        (N, nv) generalized forces [N m].
    """
    data = robot.model.createData()
    return np.array(
        [pin.rnea(robot.model, data, q[k], qdot[k], qddot[k]).copy() for k in range(len(q))]
    ).reshape(len(q), robot.nv)


def carry_base_wrench(
    robot: RobotModel,
    q: np.ndarray,
    tau: np.ndarray,
    support: np.ndarray,
    foot_ids: Sequence[int],
) -> np.ndarray:
    r"""Actuated torques once the feet in support carry the floating base's wrench.

    Inverse dynamics with a prescribed base motion puts the wrench that holds the robot up on the
    (unactuated) base coordinates. With the supporting feet's contact wrenches :math:`f` the
    equations of motion read :math:`	au = S^	op 	au_j + J_c^	op f`; the base rows fix
    :math:`J_{c,b}^	op f = 	au_b` and the minimum-norm solution is taken (no internal forces
    between the feet):

    .. math:: f = (J_{c,b}^	op)^+ 	au_b, \qquad 	au_j = 	au_a - J_{c,a}^	op f,

    with :math:`J_c` the LOCAL_WORLD_ALIGNED Jacobians of the sole frames (6 rows per foot),
    split into base (``b``, first six columns) and actuated (``a``) parts. Samples without
    support keep :math:`	au_a` (in flight the base wrench has to vanish anyway).

    Args:
        robot: the robot (free-flyer first).
        q: (N, nq) configurations.
        tau: (N, nv) generalized forces of inverse dynamics.
        support: (N, F) feet in support.
        foot_ids: (F,) sole frame ids.

    Returns:
        (N, nv - 6) actuated joint torques [N m].
    """
    nb = robot.root_nv
    out = np.array(tau[:, nb:], dtype=float, copy=True)
    if nb != 6:
        return out
    model = robot.model
    data = model.createData()
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for k in range(len(q)):
        feet = [fid for fid, on in zip(foot_ids, support[k], strict=True) if on]
        if not feet:
            continue
        pin.computeJointJacobians(model, data, q[k])
        pin.updateFramePlacements(model, data)
        Jc = np.vstack([pin.getFrameJacobian(model, data, fid, lwa) for fid in feet])
        f = np.linalg.lstsq(Jc[:, :6].T, tau[k, :6], rcond=None)[0]  # minimum norm
        out[k] -= Jc[:, 6:].T @ f
    return out


def solve_time_stats(solve_time: npt.ArrayLike | None) -> dict[str, float | None]:
    """Median, p95, max and mean of per-tick solve times, in [ms]."""
    s = np.zeros(0) if solve_time is None else np.asarray(solve_time, float).reshape(-1) * 1e3
    if s.size == 0:
        return {"median_ms": None, "p95_ms": None, "max_ms": None, "mean_ms": None, "ticks": 0}
    return {
        "median_ms": float(np.median(s)),
        "p95_ms": float(np.percentile(s, 95)),
        "max_ms": float(np.max(s)),
        "mean_ms": float(np.mean(s)),
        "ticks": int(len(s)),
    }


def support_displacement(
    positions: npt.ArrayLike, contact: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    r"""Displacement of a sole since the start of its current support phase (foot slip).

    For each frame :math:`k` in contact, with :math:`k_0` the first frame of its contact phase:
    horizontal :math:`|p_{k,xy} - p_{k_0,xy}|` and vertical :math:`|p_{k,z} - p_{k_0,z}|`;
    ``nan`` while the foot is not in contact.

    Args:
        positions: (T, 3) sole frame positions [m].
        contact: (T,) the foot supports.

    Returns:
        ``(horizontal, vertical)``, each (T,) [m].
    """
    p = np.asarray(positions, float)
    c = np.asarray(contact, bool)
    start = np.full(len(c), -1)
    s = -1
    for k, on in enumerate(c.tolist()):
        s = (k if s < 0 else s) if on else -1
        start[k] = s
    h = np.full(len(p), np.nan)
    v = np.full(len(p), np.nan)
    on = start >= 0
    h[on] = np.linalg.norm(p[on, :2] - p[start[on], :2], axis=1)
    v[on] = np.abs(p[on, 2] - p[start[on], 2])
    return h, v
