# SPDX-License-Identifier: Apache-2.0
r"""Metrics of a retargeted run, recomputed from the saved trajectory and the robot model.

Everything here is computed from a :class:`~qpretarget.trajectory.RobotTrajectory` (``q`` over
``t``, the targets, the contacts) and the robot model rebuilt from the run's YAML, never from the
controller's own bookkeeping: forward kinematics, collision distances and inverse dynamics are
recomputed with pinocchio and coal. These are the measures of DESIGN.md "Measures" and of CRAC
section 5:

* per-task RMSE against the (scaled) reference, :math:`\sqrt{\tfrac1T \sum_k |x^r_k - x(q_k)|^2}`;
* joint-limit violations per frame (CRAC Fig. 3-4, 11);
* self-collision violations per frame and the minimum distance of every collision pair over time
  (CRAC Fig. 5, 8; Dariush 2009 Fig. 11-12);
* CoM margin to the support polygon of the feet in contact;
* foot slip during support;
* joint velocity, acceleration and jerk peaks (finite differences);
* average absolute power :math:`P = \tfrac{1}{N_s} \sum_j |\tau_j^\top \dot q_j|` (CRAC eq. 43);
* solve-time statistics.

:func:`compute_series` returns the time series (:class:`MetricSeries`, used by the figures of
:mod:`qpretarget.analysis.plots`), :func:`summarize` turns them into a JSON-serializable dict and
:func:`compute_metrics` does both. The building blocks (:func:`rmse`,
:func:`joint_limit_violations`, :func:`signed_distance_to_polygon`, :func:`derivative_peaks`,
:func:`average_absolute_power`, ...) are pure functions on arrays.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..errors import ConfigError, QPRetargetError, close_matches_hint
from ..geometry2d import convex_hull_2d  # noqa: F401 (re-exported)
from ..robot import RobotModel
from ..trajectory import RobotTrajectory, TrajectoryFormatError

#: Version tag written in ``metrics.json``.
METRICS_FORMAT = "qpretarget.analysis.metrics/1"

#: Joint positions further than this outside ``[q_min, q_max]`` count as a violation [rad]. It is
#: far above the solvers' tolerances (a constrained run stays within ~1e-9 rad) and far below any
#: violation a human would notice.
JOINT_LIMIT_TOLERANCE = 1e-6

#: Safety distance [m] used when the run's config has no self-collision constraint giving one.
DEFAULT_SAFETY_DISTANCE = 0.01

#: Upper-body collision pairs used when neither the caller nor the run's config names any
#: (G1 link names; 16 pairs like CRAC section 5, N_c = 16: hands/forearms against the torso,
#: pelvis, head, thighs and the other arm).
DEFAULT_PAIRS: dict[str, list[tuple[str, str]]] = {
    "g1": [
        *[
            (f"{s}_{a}", b.format(s=s))
            for s in ("left", "right")
            for a, b in (
                ("wrist_yaw_link", "torso_link"),
                ("wrist_yaw_link", "pelvis_contour_link"),
                ("wrist_yaw_link", "head_link"),
                ("wrist_yaw_link", "{s}_hip_yaw_link"),
                ("elbow_link", "torso_link"),
                ("elbow_link", "pelvis_contour_link"),
                ("wrist_roll_link", "torso_link"),
            )
        ],
        ("left_wrist_yaw_link", "right_wrist_yaw_link"),
        ("left_elbow_link", "right_elbow_link"),
    ]
}


class MetricsError(QPRetargetError, ValueError):
    """A metric cannot be computed from the given run (wrong shapes, unknown names)."""


# ---------------------------------------------------------------------------------- pure maths
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
    if solve_time is None or len(solve_time) == 0:
        return {"median_ms": None, "p95_ms": None, "max_ms": None, "mean_ms": None, "ticks": 0}
    s = np.asarray(solve_time, float) * 1e3
    return {
        "median_ms": float(np.median(s)),
        "p95_ms": float(np.percentile(s, 95)),
        "max_ms": float(np.max(s)),
        "mean_ms": float(np.mean(s)),
        "ticks": int(len(s)),
    }


# ---------------------------------------------------------------------------------- collisions
class GeometryPairDistances:
    """Distances between pairs of bodies of a given pinocchio ``GeometryModel`` of convex shapes.

    For geometry that is not the robot's own (tests, extra bodies); the robot's links go through
    :class:`LinkPairDistances` (the shared :mod:`~qpretarget.collision` model). Each name stands for
    every geometry object of that name or attached to that frame; the distance of a pair is the
    smallest distance between their objects (negative when they interpenetrate, coal's signed
    distance).

    Args:
        robot: the robot (its pinocchio model).
        geometry: a ``pinocchio.GeometryModel`` of convex shapes (spheres, capsules, hulls...).
        pairs: pairs of geometry-object or frame names.

    Raises:
        MetricsError: when a name matches no geometry object.
    """

    def __init__(self, robot: RobotModel, geometry: Any, pairs: Sequence[tuple[str, str]]) -> None:
        self.robot = robot
        gm = geometry.copy()
        gm.removeAllCollisionPairs()
        by_name: dict[str, list[int]] = {}
        for i, obj in enumerate(gm.geometryObjects):
            by_name.setdefault(obj.name, []).append(i)
            if obj.parentFrame < len(robot.model.frames):
                frame = robot.model.frames[obj.parentFrame].name
                if frame != obj.name:
                    by_name.setdefault(frame, []).append(i)
        self.pair_names: list[str] = []
        self._groups: list[list[int]] = []
        k = 0
        for a, b in pairs:
            for n in (a, b):
                if n not in by_name:
                    raise MetricsError(
                        f"collision body {n!r} matches no geometry object."
                        f"{close_matches_hint(n, by_name)}"
                    )
            group = []
            for i in by_name[a]:
                for j in by_name[b]:
                    if i != j:
                        gm.addCollisionPair(pin.CollisionPair(i, j))
                        group.append(k)
                        k += 1
            self.pair_names.append(f"{a}/{b}")
            self._groups.append(group)
        self.geometry = gm
        self.data = robot.model.createData()
        self.gdata = gm.createData()
        for req in self.gdata.distanceRequests:
            req.enable_signed_distance = True

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Distance of every pair at configuration ``q`` [m] (P,)."""
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        pin.updateGeometryPlacements(self.robot.model, self.data, self.geometry, self.gdata)
        pin.computeDistances(self.geometry, self.gdata)
        res = self.gdata.distanceResults
        return np.array(
            [min((res[k].min_distance for k in g), default=math.nan) for g in self._groups]
        )


class LinkPairDistances:
    """Exact distances of robot link pairs, from the shared collision model (convex hulls).

    A thin offline wrapper of :class:`~qpretarget.collision.CollisionModel` (broad phase off):
    the same geometry the ``self_collision`` constraint uses in the loop.

    Args:
        robot: the robot.
        pairs: link-name pairs; a key-point name (``left_hand``) is resolved to the link that
            carries its frame's geometry.
        geometry: ``convex_hull`` or ``capsule`` (see :mod:`qpretarget.collision`).
    """

    def __init__(
        self, robot: RobotModel, pairs: Sequence[tuple[str, str]], *, geometry: str = "convex_hull"
    ) -> None:
        from ..collision import CollisionModel
        from ..robot import RobotState

        resolved = [(self._link(robot, a), self._link(robot, b)) for a, b in pairs]
        self.robot = robot
        self.model = CollisionModel(robot, resolved, geometry=geometry, broad_phase=False)
        self.pair_names = [f"{a}/{b}" for a, b in resolved]
        self._state = RobotState(robot)

    @staticmethod
    def _link(robot: RobotModel, name: str) -> str:
        """A key-point or frame name -> the link (body frame) holding its collision geometry."""
        from ..collision import link_shapes
        from ..constraints.self_collision import resolve_link
        from ..errors import UnknownNameError

        shapes = link_shapes(robot)
        try:
            return resolve_link(robot, shapes, name, "pairs")
        except UnknownNameError:
            raise MetricsError(
                f"collision pair body {name!r} is not a link with collision geometry."
                f"{close_matches_hint(name, list(shapes))} "
                f"Links with geometry: {', '.join(shapes)}."
            ) from None

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Distance of every pair at configuration ``q`` [m] (P,)."""
        self._state.update(q)
        return self.model.compute_all(self._state)[0]


def collision_model_for(
    robot: RobotModel,
    controller: Any = None,
    pairs: Sequence[tuple[str, str]] | None = None,
) -> tuple[LinkPairDistances | None, float]:
    """The pair-distance model and safety distance [m] to evaluate a run with.

    Pairs come from, in order: ``pairs``; the run's ``self_collision`` constraint (its pairs,
    geometry and safety distance ``d_s``); :data:`DEFAULT_PAIRS` for the robot. ``None`` when
    there is none.
    """
    safety = DEFAULT_SAFETY_DISTANCE
    geometry = "convex_hull"
    constraint = next(
        (
            c
            for c in getattr(controller, "constraints", [])
            if getattr(c, "type_name", "") == "self_collision"
        ),
        None,
    )
    if constraint is not None:
        value = getattr(constraint, "safety_distance", None)
        if isinstance(value, (int, float)):
            safety = float(value)
        geometry = str(getattr(constraint, "geometry", geometry))
        if pairs is None:
            pairs = [(str(a), str(b)) for a, b in getattr(constraint, "pairs", [])] or None
    if pairs is None:
        pairs = DEFAULT_PAIRS.get(robot.name)
    if not pairs:
        return None, safety
    return LinkPairDistances(robot, [(str(a), str(b)) for a, b in pairs], geometry=geometry), safety


# ---------------------------------------------------------------------------------- series
@dataclass
class MetricSeries:
    """Time series of a run's metrics (what the figures plot).

    Attributes:
        t: (T,) sample times [s].
        joint_names: actuated one-DoF joints, in ``q[7:]`` order.
        q_joints: (T, n) joint positions [rad].
        q_min, q_max: (n,) joint limits.
        targets, reached: task -> (T, 3) reference and recomputed (FK) positions [m].
        joint_violation: (T, n) joints outside their limits.
        joint_violation_amount: (T, n) distance outside the limits [rad].
        pair_names: collision pairs ``"link_a/link_b"``.
        pair_distance: (T, P) pair distances [m] (negative: interpenetration).
        safety_distance: safety distance of the self-collision constraint [m].
        foot_names: feet; contacts: (T, F) supporting feet.
        com: (T, 3) centre of mass [m]; com_margin: (T,) signed distance of its ground projection
            to the support polygon [m] (> 0 inside, ``nan`` without support).
        support_polygons: polygon (m, 2) of every frame (``None`` without support).
        sole_positions: foot -> (T, 3) sole frame positions [m]; foot_slip: foot -> (T,)
            horizontal displacement since the start of the current support phase [m] (``nan``
            while not in contact); foot_lift: foot -> (T,) vertical displacement [m].
        power_index: (N,) samples of the power; power: (N,) |tau' qdot| of the actuated joints
            with the base wrench carried by the feet in support (:func:`carry_base_wrench`) [W];
            power_base_held: the same with the base held in place (no contact forces) [W];
            power_source: ``"tau"`` (stored torques) or ``"rnea"``.
        peaks: ``velocity``/``acceleration``/``jerk`` -> (n,) per-joint peaks.
        v_max: (n,) joint velocity limits [rad/s].
        solve_time: (T,) [s]; status: (T,) tick status.
        robot: the robot name; config_name: the config's ``name:``.
    """

    t: np.ndarray
    joint_names: list[str]
    q_joints: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    targets: dict[str, np.ndarray]
    reached: dict[str, np.ndarray]
    recorded: dict[str, np.ndarray]
    joint_violation: np.ndarray
    joint_violation_amount: np.ndarray
    pair_names: list[str]
    pair_distance: np.ndarray
    safety_distance: float
    foot_names: list[str]
    contacts: np.ndarray
    contacts_assumed: bool
    com: np.ndarray
    com_margin: np.ndarray
    support_polygons: list[np.ndarray | None]
    sole_positions: dict[str, np.ndarray]
    foot_slip: dict[str, np.ndarray]
    foot_lift: dict[str, np.ndarray]
    power_index: np.ndarray
    power: np.ndarray
    power_base_held: np.ndarray
    power_source: str
    peaks: dict[str, np.ndarray]
    v_max: np.ndarray
    solve_time: np.ndarray | None
    status: np.ndarray | None
    robot: str
    config_name: str
    joint_limit_tolerance: float = JOINT_LIMIT_TOLERANCE
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def joint_violations_per_frame(self) -> np.ndarray:
        """(T,) number of joints outside their limits."""
        return self.joint_violation.sum(axis=1)

    @property
    def collision_violations_per_frame(self) -> np.ndarray:
        """(T,) number of pairs in collision (distance < 0)."""
        if self.pair_distance.size == 0:
            return np.zeros(len(self.t), int)
        return np.sum(self.pair_distance < 0.0, axis=1)

    @property
    def below_safety_per_frame(self) -> np.ndarray:
        """(T,) number of pairs closer than the safety distance."""
        if self.pair_distance.size == 0:
            return np.zeros(len(self.t), int)
        return np.sum(self.pair_distance < self.safety_distance, axis=1)


def _check_run(traj: RobotTrajectory, robot: RobotModel) -> None:
    T = len(traj.t)
    if T == 0:
        raise MetricsError("the run has no sample.")
    if traj.q.shape != (T, robot.nq):
        raise TrajectoryFormatError(
            f"q has shape {traj.q.shape}, expected ({T}, {robot.nq}) for robot {robot.name!r}."
        )
    if list(traj.joint_names) and list(traj.joint_names) != list(robot.joint_names):
        raise TrajectoryFormatError(
            "the run's joint_names differ from the robot rebuilt from its config_yaml "
            f"(first difference at {_first_diff(traj.joint_names, robot.joint_names)}); was the "
            "run saved with another robot model?"
        )


def _first_diff(a: Sequence[str], b: Sequence[str]) -> str:
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return f"index {i}: {x!r} vs {y!r}"
    return f"lengths {len(a)} vs {len(b)}"


def _task_points(controller: Any, names: Iterable[str]) -> dict[str, tuple[int, np.ndarray | None]]:
    """Frame id and offset of each position task named in ``names``."""
    out = {}
    for name in names:
        task = getattr(controller, "tasks", {}).get(name)
        if task is None or not getattr(task, "has_position", False):
            continue
        out[name] = (int(task.frame_id), getattr(task, "offset", None))
    return out


def _foot_geometry(robot: RobotModel, controller: Any, name: str) -> tuple[int, tuple[float, ...]]:
    """Sole frame id and sole rectangle of a foot / contact name."""
    if name in robot.feet:
        foot = robot.feet[name]
        return robot.frame_id(foot.frame), tuple(foot.rectangle)
    for c in getattr(controller, "constraints", []):
        names = getattr(c, "names", None)
        if getattr(c, "type_name", "") == "contacts" and names and name in names:
            i = list(names).index(name)
            rect = c.rectangles[i] if getattr(c, "rectangles", None) else None
            return int(c.frame_ids[i]), tuple(rect) if rect is not None else (0.0, 0.0, 0.0, 0.0)
    raise TrajectoryFormatError(
        f"contact {name!r} of the run is neither a foot of robot {robot.name!r} "
        f"({', '.join(robot.feet)}) nor a contact of its config."
    )


def _support_phases(contact: np.ndarray) -> np.ndarray:
    """Index of the first frame of the current contact phase, per frame (-1 when not in contact)."""
    start = np.full(len(contact), -1)
    s = -1
    for k, c in enumerate(contact):
        if c:
            if s < 0:
                s = k
            start[k] = s
        else:
            s = -1
    return start


def compute_series(
    traj: RobotTrajectory,
    *,
    controller: Any = None,
    pairs: Sequence[tuple[str, str]] | None = None,
    collision: LinkPairDistances | GeometryPairDistances | None = None,
    safety_distance: float | None = None,
    joint_limit_tolerance: float = JOINT_LIMIT_TOLERANCE,
) -> MetricSeries:
    """Recompute every metric's time series from a run.

    Args:
        traj: the run.
        controller: the controller that produced it (default: rebuilt from ``traj.config_yaml``
            with :meth:`RobotTrajectory.make_controller`); only its robot model, task frames and
            constraint settings are read.
        pairs: collision pairs (link names) to measure (see :func:`collision_model_for`).
        collision: a ready distance model (overrides ``pairs``): anything with ``pair_names``
            and ``distances(q) -> (P,)``.
        safety_distance: override the safety distance [m].
        joint_limit_tolerance: see :data:`JOINT_LIMIT_TOLERANCE` [rad].

    Raises:
        TrajectoryFormatError: when the run does not match its robot.
        MetricsError: on unknown collision links.
    """
    if controller is None:
        try:
            controller = traj.make_controller()
        except ConfigError as exc:
            raise TrajectoryFormatError(
                f"cannot rebuild the run's controller from its config_yaml: {exc}"
            ) from None
    robot: RobotModel = controller.robot
    _check_run(traj, robot)
    t = np.asarray(traj.t, float)
    q = np.asarray(traj.q, float)
    T = len(t)
    model = robot.model
    data = model.createData()

    # Collision model.
    if collision is None:
        collision, safety = collision_model_for(robot, controller, pairs)
    else:
        safety = DEFAULT_SAFETY_DISTANCE
    if safety_distance is not None:
        safety = float(safety_distance)

    # Feet and contacts: a run without contact columns is taken as standing on every foot.
    contacts = None if traj.contacts is None else np.asarray(traj.contacts, bool)
    if contacts is not None and contacts.ndim == 2 and contacts.shape[1] > 0:
        foot_names = list(traj.foot_names)
        if contacts.shape != (T, len(foot_names)):
            raise TrajectoryFormatError(
                f"contacts has shape {contacts.shape}, expected ({T}, {len(foot_names)}) for feet "
                f"{foot_names}."
            )
        assumed = False
    else:
        foot_names = list(robot.feet)
        contacts = np.ones((T, len(foot_names)), bool)
        assumed = True
    foot_ids, corners_local = [], []
    for f in foot_names:
        fid, rect = _foot_geometry(robot, controller, f)
        x0, x1, y0, y1 = rect
        foot_ids.append(fid)
        corners_local.append(np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]))

    order = [n for n in traj.task_names if n in traj.targets]
    order += [n for n in sorted(traj.targets) if n not in order]
    task_pts = _task_points(controller, order)
    reached = {name: np.empty((T, 3)) for name in task_pts}
    sole_pos = {f: np.empty((T, 3)) for f in foot_names}
    com = np.empty((T, 3))
    com_margin = np.full(T, np.nan)
    polygons: list[np.ndarray | None] = []
    P = len(collision.pair_names) if collision is not None else 0
    dist = np.empty((T, P))
    for k in range(T):
        pin.framesForwardKinematics(model, data, q[k])
        com[k] = pin.centerOfMass(model, data, q[k], False)
        for name, (fid, offset) in task_pts.items():
            M = data.oMf[fid]
            reached[name][k] = (
                M.translation if offset is None else M.translation + M.rotation @ offset
            )
        corners = []
        for f, fid in zip(foot_names, foot_ids, strict=True):
            sole_pos[f][k] = data.oMf[fid].translation
        for i, (fid, cl) in enumerate(zip(foot_ids, corners_local, strict=True)):
            if contacts[k, i]:
                M = data.oMf[fid]
                corners.append((cl @ M.rotation.T + M.translation)[:, :2])
        if corners:
            poly = convex_hull_2d(np.vstack(corners))
            polygons.append(poly)
            com_margin[k] = signed_distance_to_polygon(com[k, :2], poly)
        else:
            polygons.append(None)
        if collision is not None:
            dist[k] = collision.distances(q[k])

    # Foot slip: displacement of the sole frame since the start of the support phase.
    slip, lift = {}, {}
    for i, f in enumerate(foot_names):
        start = _support_phases(contacts[:, i])
        s = np.full(T, np.nan)
        z = np.full(T, np.nan)
        on = start >= 0
        p = sole_pos[f]
        s[on] = np.linalg.norm(p[on, :2] - p[start[on], :2], axis=1)
        z[on] = np.abs(p[on, 2] - p[start[on], 2])
        slip[f], lift[f] = s, z

    # Joint limits and motion peaks.
    qi, vi = robot.joint_q_index, robot.joint_v_index
    q_joints = q[:, qi]
    q_min, q_max = robot.q_min[qi], robot.q_max[qi]
    viol, amount = joint_limit_violations(q_joints, q_min, q_max, tolerance=joint_limit_tolerance)
    peaks = derivative_peaks(t, q_joints)

    # Power (CRAC eq. 43): stored torques if the run has them, else RNEA.
    idx, qdot, qddot = tangent_velocities(robot, t, q)
    if traj.tau is not None and np.asarray(traj.tau).shape == (T, robot.nv):
        tau = np.asarray(traj.tau, float)[idx]
        source = "tau"
    else:
        tau = rnea_torques(robot, q[idx], qdot, qddot)
        source = "rnea"
    if len(idx):
        # Joint torques of a robot standing on its feet (CRAC eq. 43 sums the actuated joints).
        tau_j = carry_base_wrench(robot, q[idx], tau, contacts[idx], foot_ids)
        power = instantaneous_power(tau_j, qdot[:, robot.root_nv :])
        power_held = instantaneous_power(tau[:, vi], qdot[:, vi])
    else:
        power = power_held = np.zeros(0)

    recorded = {k: np.asarray(v, float) for k, v in traj.actual.items() if k in reached}
    name = traj.meta.get("config_name") or getattr(controller, "config", {}).get("name") or ""
    return MetricSeries(
        t=t,
        joint_names=list(robot.joint_names),
        q_joints=q_joints,
        q_min=q_min,
        q_max=q_max,
        targets={k: np.asarray(traj.targets[k], float) for k in reached},
        reached=reached,
        recorded=recorded,
        joint_violation=viol,
        joint_violation_amount=amount,
        pair_names=list(collision.pair_names) if collision is not None else [],
        pair_distance=dist,
        safety_distance=safety,
        foot_names=foot_names,
        contacts=contacts,
        contacts_assumed=assumed,
        com=com,
        com_margin=com_margin,
        support_polygons=polygons,
        sole_positions=sole_pos,
        foot_slip=slip,
        foot_lift=lift,
        power_index=idx,
        power=power,
        power_base_held=power_held,
        power_source=source,
        peaks=peaks,
        v_max=robot.v_max[vi],
        solve_time=None if traj.solve_time is None else np.asarray(traj.solve_time, float),
        status=None if traj.status is None else np.asarray(traj.status).astype(str),
        robot=robot.name,
        config_name=str(name),
        joint_limit_tolerance=joint_limit_tolerance,
    )


# ---------------------------------------------------------------------------------- summary
def _f(x: Any) -> float | None:
    """A JSON-safe float (``None`` for NaN/inf)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _list(a: np.ndarray, digits: int = 6) -> list:
    """A JSON-safe list of a numeric array (NaN -> None), rounded to ``digits`` decimals."""
    a = np.asarray(a)
    if a.dtype.kind in "biu":
        return a.tolist()
    r = np.round(a.astype(float), digits)
    return (
        [None if not math.isfinite(v) else v for v in r.ravel().tolist()]
        if r.ndim == 1
        else [_list(row, digits) for row in r]
    )


def _peak(values: np.ndarray, names: Sequence[str]) -> dict[str, Any]:
    if values.size == 0 or not np.any(np.isfinite(values)):
        return {"value": None, "joint": None}
    j = int(np.nanargmax(values))
    return {"value": _f(values[j]), "joint": names[j]}


#: Number of pairs whose distance over time goes into ``per_frame`` (the closest ones).
PER_FRAME_PAIRS = 16


def _closest_pairs(s: MetricSeries, n: int = PER_FRAME_PAIRS) -> list[int]:
    """Indices of the ``n`` pairs that come closest, in pair order."""
    if s.pair_distance.size == 0:
        return []
    mins = np.nanmin(np.where(np.isfinite(s.pair_distance), s.pair_distance, np.inf), axis=0)
    return sorted(np.argsort(mins, kind="stable")[:n].tolist())


def summarize(series: MetricSeries, *, per_frame: bool = True) -> dict[str, Any]:
    """JSON-serializable summary of a run's metrics (the content of ``metrics.json``).

    Args:
        series: from :func:`compute_series`.
        per_frame: include the per-frame arrays (violation counts, distances of the
            :data:`PER_FRAME_PAIRS` closest pairs, CoM margin, foot slip, power) under
            ``"per_frame"``.

    Returns:
        A dict of plain Python types; units are in the key names (``_m``, ``_rad``, ``_W``...).
    """
    s = series
    T = len(s.t)
    tracking = {}
    for name in s.reached:
        ref, act = s.targets[name], s.reached[name]
        err = np.linalg.norm(ref - act, axis=1)
        axis = [rmse(ref[:, i : i + 1], act[:, i : i + 1]) for i in range(3)]
        entry: dict[str, Any] = {
            "rmse_m": _f(rmse(ref, act)),
            "rmse_xyz_m": [_f(x) for x in axis],
            "max_error_m": _f(np.nanmax(err)) if np.any(np.isfinite(err)) else None,
            "missing_frames": int(np.sum(~np.all(np.isfinite(ref), axis=1))),
        }
        if name in s.recorded and s.recorded[name].shape == act.shape:
            entry["recorded_vs_fk_max_m"] = _f(np.max(np.abs(s.recorded[name] - act)))
        tracking[name] = entry
    rmses = [v["rmse_m"] for v in tracking.values() if v["rmse_m"] is not None]

    jl_per_frame = s.joint_violations_per_frame
    per_joint = {
        s.joint_names[j]: int(c) for j, c in enumerate(s.joint_violation.sum(axis=0)) if c > 0
    }
    ranges = s.q_max - s.q_min
    margin_lo = np.min(s.q_joints - s.q_min, axis=0)
    margin_hi = np.min(s.q_max - s.q_joints, axis=0)
    margin = np.minimum(margin_lo, margin_hi)
    finite = np.isfinite(margin) & np.isfinite(ranges)
    closest = (
        {"joint": s.joint_names[int(np.argmin(np.where(finite, margin, np.inf)))],
         "margin_rad": _f(np.min(margin[finite]))}
        if finite.any() else {"joint": None, "margin_rad": None}
    )  # fmt: skip
    joint_limits = {
        "tolerance_rad": s.joint_limit_tolerance,
        "total_violations": int(jl_per_frame.sum()),
        "frames_with_violation": int(np.sum(jl_per_frame > 0)),
        "mean_per_frame": _f(jl_per_frame.mean()),
        "max_per_frame": int(jl_per_frame.max(initial=0)),
        "max_violation_rad": _f(s.joint_violation_amount.max(initial=0.0)),
        "per_joint": per_joint,
        "closest_to_limit": closest,
    }

    col = s.collision_violations_per_frame
    below = s.below_safety_per_frame
    min_dist = {}
    for p, name in enumerate(s.pair_names):
        d = s.pair_distance[:, p]
        k = int(np.nanargmin(d)) if np.any(np.isfinite(d)) else 0
        min_dist[name] = {"min_m": _f(d[k]) if d.size else None, "at_s": _f(s.t[k])}
    overall = (
        _f(np.nanmin(s.pair_distance))
        if s.pair_distance.size and np.any(np.isfinite(s.pair_distance))
        else None
    )
    self_collision = {
        "pairs": list(s.pair_names),
        "safety_distance_m": s.safety_distance,
        "total_violations": int(col.sum()),
        "frames_with_violation": int(np.sum(col > 0)),
        "mean_per_frame": _f(col.mean()) if T else None,
        "max_per_frame": int(col.max(initial=0)),
        "frames_below_safety": int(np.sum(below > 0)),
        "min_distance_m": overall,
        "min_distance_per_pair": min_dist,
    }
    total = jl_per_frame + col
    violations = {
        "total_per_frame_mean": _f(total.mean()),
        "total_per_frame_max": int(total.max(initial=0)),
        "frames_with_violation": int(np.sum(total > 0)),
    }

    cm = s.com_margin
    support = {
        "contacts_assumed": s.contacts_assumed,
        "feet": list(s.foot_names),
        "min_com_margin_m": _f(np.nanmin(cm)) if np.any(np.isfinite(cm)) else None,
        "mean_com_margin_m": _f(np.nanmean(cm)) if np.any(np.isfinite(cm)) else None,
        "frames_com_outside": int(np.sum(cm < 0)),
        "frames_without_support": int(np.sum(~np.isfinite(cm))),
    }
    slip = {}
    for f in s.foot_names:
        d, z = s.foot_slip[f], s.foot_lift[f]
        on = np.isfinite(d)
        slip[f] = {
            "frames_in_contact": int(on.sum()),
            "max_slip_m": _f(np.max(d[on])) if on.any() else None,
            "max_vertical_m": _f(np.max(z[on])) if on.any() else None,
        }

    names = s.joint_names
    motion = {
        "velocity_peak_rad_s": _peak(s.peaks["velocity"], names),
        "acceleration_peak_rad_s2": _peak(s.peaks["acceleration"], names),
        "jerk_peak_rad_s3": _peak(s.peaks["jerk"], names),
        "per_joint": {
            n: {
                "velocity_rad_s": _f(s.peaks["velocity"][j]),
                "acceleration_rad_s2": _f(s.peaks["acceleration"][j]),
                "jerk_rad_s3": _f(s.peaks["jerk"][j]),
            }
            for j, n in enumerate(names)
        },
        "joints_over_velocity_limit": [
            names[j] for j in np.flatnonzero(s.peaks["velocity"] > s.v_max * (1 + 1e-6))
        ],
    }
    power = {
        "mean_abs_power_W": _f(np.mean(s.power)) if s.power.size else None,
        "mean_abs_power_base_held_W": _f(np.mean(s.power_base_held)) if s.power.size else None,
        "peak_power_W": _f(np.max(s.power)) if s.power.size else None,
        "source": s.power_source,
        "contact_forces": "minimum-norm wrenches of the feet in support",
        "samples": int(s.power.size),
    }
    status = {}
    if s.status is not None:
        vals, counts = np.unique(s.status, return_counts=True)
        status = {str(v): int(c) for v, c in zip(vals, counts, strict=True)}
    out: dict[str, Any] = {
        "format": METRICS_FORMAT,
        "run": {
            "robot": s.robot,
            "config": s.config_name,
            "samples": T,
            "duration_s": _f(s.t[-1] - s.t[0]) if T else 0.0,
            "dt_s": _f(np.median(np.diff(s.t))) if T > 1 else None,
        },
        "tracking": tracking,
        "tracking_rmse_mean_m": _f(np.mean(rmses)) if rmses else None,
        "joint_limits": joint_limits,
        "self_collision": self_collision,
        "violations": violations,
        "support": support,
        "foot_slip": slip,
        "joint_motion": motion,
        "power": power,
        "solve_time": solve_time_stats(s.solve_time),
        "status": status,
    }
    if per_frame:
        out["per_frame"] = {
            "t_s": _list(s.t),
            "joint_limit_violations": _list(jl_per_frame),
            "self_collision_violations": _list(col),
            "below_safety": _list(below),
            "pair_distance_m": {
                s.pair_names[p]: _list(s.pair_distance[:, p]) for p in _closest_pairs(s)
            },
            "com_margin_m": _list(cm),
            "foot_slip_m": {f: _list(s.foot_slip[f]) for f in s.foot_names},
            "power_W": _list(s.power),
            "power_t_s": _list(s.t[s.power_index]),
        }
    return out


def compute_metrics(
    traj: RobotTrajectory, *, per_frame: bool = True, **kwargs: Any
) -> dict[str, Any]:
    """Every metric of a run as a JSON-serializable dict (compute_series + summarize).

    Args:
        traj: the run.
        per_frame: include per-frame arrays.
        **kwargs: options of :func:`compute_series` (``controller``, ``pairs``, ...).
    """
    return summarize(compute_series(traj, **kwargs), per_frame=per_frame)


def dumps(metrics: Mapping[str, Any]) -> str:
    """``metrics.json`` text (strict JSON: no NaN)."""
    return json.dumps(metrics, indent=1, allow_nan=False)
