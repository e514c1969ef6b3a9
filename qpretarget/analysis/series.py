# SPDX-License-Identifier: Apache-2.0
"""Time series of a run's metrics, recomputed from its trajectory and robot model.

:func:`compute_series` rebuilds the robot from the run's YAML and recomputes forward kinematics,
pair distances, the support polygon and inverse dynamics with pinocchio and coal: never the
controller's own bookkeeping. :class:`MetricSeries` holds the result (what the figures of
:mod:`qpretarget.analysis.plots` draw and :func:`qpretarget.analysis.metrics.summarize` reduces).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..geometry2d import convex_hull_2d
from ..robot import RobotModel
from ..trajectory import RobotTrajectory, TrajectoryFormatError
from .measures import (
    DEFAULT_SAFETY_DISTANCE,
    JOINT_LIMIT_TOLERANCE,
    MetricsError,
    carry_base_wrench,
    derivative_peaks,
    instantaneous_power,
    joint_limit_violations,
    rnea_torques,
    signed_distance_to_polygon,
    support_displacement,
    tangent_velocities,
)
from .pair_distances import GeometryPairDistances, LinkPairDistances, collision_model_for


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
    if collision is None:
        collision, safety = collision_model_for(robot, controller, pairs)
    else:
        safety = DEFAULT_SAFETY_DISTANCE
    if safety_distance is not None:
        safety = float(safety_distance)
    foot_names, contacts, assumed = _run_contacts(traj, robot, len(t))
    feet = [_foot_geometry(robot, controller, f) for f in foot_names]
    order = [n for n in traj.task_names if n in traj.targets]
    order += [n for n in sorted(traj.targets) if n not in order]
    kin = _kinematics_pass(robot, q, _task_points(controller, order), feet, contacts, collision)
    soles = dict(zip(foot_names, kin.soles, strict=True))
    slip, lift = _foot_slip(soles, contacts)
    qi = robot.joint_q_index
    q_joints = q[:, qi]
    viol, amount = joint_limit_violations(
        q_joints, robot.q_min[qi], robot.q_max[qi], tolerance=joint_limit_tolerance
    )
    idx, power, power_held, source = _power(traj, robot, t, q, contacts, [f[0] for f in feet])
    name = traj.meta.get("config_name") or getattr(controller, "config", {}).get("name") or ""
    return MetricSeries(
        t=t, joint_names=list(robot.joint_names), q_joints=q_joints,
        q_min=robot.q_min[qi], q_max=robot.q_max[qi],
        targets={k: np.asarray(traj.targets[k], float) for k in kin.reached},
        reached=kin.reached,
        recorded={k: np.asarray(v, float) for k, v in traj.actual.items() if k in kin.reached},
        joint_violation=viol, joint_violation_amount=amount,
        pair_names=list(collision.pair_names) if collision is not None else [],
        pair_distance=kin.pair_distance, safety_distance=safety,
        foot_names=foot_names, contacts=contacts, contacts_assumed=assumed,
        com=kin.com, com_margin=kin.com_margin, support_polygons=kin.polygons,
        sole_positions=soles, foot_slip=slip, foot_lift=lift,
        power_index=idx, power=power, power_base_held=power_held, power_source=source,
        peaks=derivative_peaks(t, q_joints), v_max=robot.v_max[robot.joint_v_index],
        solve_time=None if traj.solve_time is None else np.asarray(traj.solve_time, float),
        status=None if traj.status is None else np.asarray(traj.status).astype(str),
        robot=robot.name, config_name=str(name), joint_limit_tolerance=joint_limit_tolerance,
    )  # fmt: skip


def _run_contacts(
    traj: RobotTrajectory, robot: RobotModel, T: int
) -> tuple[list[str], np.ndarray, bool]:
    """Feet, (T, F) contact flags, and whether they were assumed.

    A run without contact columns is taken as standing on every foot of the robot.
    """
    contacts = None if traj.contacts is None else np.asarray(traj.contacts, bool)
    if contacts is not None and contacts.ndim == 2 and contacts.shape[1] > 0:
        foot_names = list(traj.foot_names)
        if contacts.shape != (T, len(foot_names)):
            raise TrajectoryFormatError(
                f"contacts has shape {contacts.shape}, expected ({T}, {len(foot_names)}) for feet "
                f"{foot_names}."
            )
        return foot_names, contacts, False
    foot_names = list(robot.feet)
    return foot_names, np.ones((T, len(foot_names)), bool), True


@dataclass
class _Kinematics:
    """What one forward-kinematics pass over the run gives."""

    reached: dict[str, np.ndarray]
    soles: list[np.ndarray]
    com: np.ndarray
    com_margin: np.ndarray
    polygons: list[np.ndarray | None]
    pair_distance: np.ndarray


def _kinematics_pass(
    robot: RobotModel,
    q: np.ndarray,
    task_pts: dict[str, tuple[int, np.ndarray | None]],
    feet: Sequence[tuple[int, tuple[float, ...]]],
    contacts: np.ndarray,
    collision: LinkPairDistances | GeometryPairDistances | None,
) -> _Kinematics:
    """One forward-kinematics pass over the run.

    Per frame: task points, soles, CoM, the support polygon (convex hull of the supporting
    soles' corners) with the CoM's signed margin to it, and pair distances.
    """
    T = len(q)
    model = robot.model
    data = model.createData()
    corners_local = [
        np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
        for _, (x0, x1, y0, y1) in feet
    ]
    out = _Kinematics(
        reached={name: np.empty((T, 3)) for name in task_pts},
        soles=[np.empty((T, 3)) for _ in feet],
        com=np.empty((T, 3)),
        com_margin=np.full(T, np.nan),
        polygons=[],
        pair_distance=np.empty((T, len(collision.pair_names) if collision is not None else 0)),
    )
    for k in range(T):
        pin.framesForwardKinematics(model, data, q[k])
        out.com[k] = pin.centerOfMass(model, data, q[k], False)
        for name, (fid, offset) in task_pts.items():
            M = data.oMf[fid]
            out.reached[name][k] = (
                M.translation if offset is None else M.translation + M.rotation @ offset
            )
        corners = []
        for i, ((fid, _), cl) in enumerate(zip(feet, corners_local, strict=True)):
            M = data.oMf[fid]
            out.soles[i][k] = M.translation
            if contacts[k, i]:
                corners.append((cl @ M.rotation.T + M.translation)[:, :2])
        if corners:
            poly = convex_hull_2d(np.vstack(corners))
            out.polygons.append(poly)
            out.com_margin[k] = signed_distance_to_polygon(out.com[k, :2], poly)
        else:
            out.polygons.append(None)
        if collision is not None:
            out.pair_distance[k] = collision.distances(q[k])
    return out


def _foot_slip(
    soles: dict[str, np.ndarray], contacts: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Foot slip and lift [m].

    Per foot, the horizontal and vertical displacement of the sole frame since the start of its
    current support phase (``nan`` while not in contact).
    """
    slip, lift = {}, {}
    for i, (f, p) in enumerate(soles.items()):
        slip[f], lift[f] = support_displacement(p, contacts[:, i])
    return slip, lift


def _power(
    traj: RobotTrajectory,
    robot: RobotModel,
    t: np.ndarray,
    q: np.ndarray,
    contacts: np.ndarray,
    foot_ids: Sequence[int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    r"""Power samples :math:`|\tau^\top \dot q|` of the actuated joints (CRAC eq. 43).

    Returns the sample indices, the power with the feet carrying the base, the power with the
    base held, and the torque source: the run's stored torques if it has them, else RNEA.
    """
    idx, qdot, qddot = tangent_velocities(robot, t, q)
    if traj.tau is not None and np.asarray(traj.tau).shape == (len(t), robot.nv):
        tau = np.asarray(traj.tau, float)[idx]
        source = "tau"
    else:
        tau = rnea_torques(robot, q[idx], qdot, qddot)
        source = "rnea"
    if not len(idx):
        return idx, np.zeros(0), np.zeros(0), source
    vi = robot.joint_v_index
    # Joint torques of a robot standing on its feet (CRAC eq. 43 sums the actuated joints).
    tau_j = carry_base_wrench(robot, q[idx], tau, contacts[idx], list(foot_ids))
    power = instantaneous_power(tau_j, qdot[:, robot.root_nv :])
    return idx, power, instantaneous_power(tau[:, vi], qdot[:, vi]), source
