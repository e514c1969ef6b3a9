# SPDX-License-Identifier: Apache-2.0
r"""Shape-based retargeting between serial chains (Tosun 2014), offline and online.

Offline, motion is retargeted pose by pose (Tosun 5.1): for each source pose the controller's QP is
iterated from the previous pose's solution until the step is below a tolerance, which solves the
paper's problem (Tosun eq. 4)

.. math:: q^* = \arg\min_q E(q) \quad \text{s.t.} \quad q_{min} \le q \le q_{max}

by Gauss-Newton steps (one QP per step, the ``joint_limits`` constraint as hard bounds, the
controller's damping as Levenberg-Marquardt term). Online, the same controller takes one QP step
per tick. Both reuse :meth:`~qpretarget.control.Controller.step`; there is no second QP path.

Helpers extract source chains from motion capture (:func:`arm_chain`: shoulder, elbow, wrist,
hand key-points expressed in the torso's axes, optionally projected on an anatomical plane) and
from a robot posed by a joint trajectory (:func:`robot_chain`, for robot-to-robot transfer).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, TargetError, close_matches_hint
from ..motion.keypoints import keypoint_orientations, keypoint_positions
from ..robot import RobotModel, RobotState
from ..tasks.chain_shape import ChainShapeTask, ShapeErrors

if TYPE_CHECKING:
    from ..control.controller import Controller
    from ..motion import HumanMotion

#: Arm key-points of :mod:`qpretarget.motion` key-point maps, from the base of the chain.
ARM_POINTS = ("shoulder", "elbow", "wrist", "hand")

#: Axis dropped by each anatomical plane projection, in the torso axes (x fwd, y left, z up).
PLANES = {"coronal": 0, "sagittal": 1, "transverse": 2}


@dataclass(slots=True)
class PoseResult:
    r"""Outcome of retargeting one source pose to convergence.

    Attributes:
        q: configuration reached (nq,).
        errors: :math:`E_p`, :math:`E_e`, :math:`E` at ``q`` (Tosun eq. 2-5).
        iterations: QP steps taken.
        converged: the last step was below the tolerance.
        step: infinity norm of the last step :math:`|v\,dt|_\infty` [rad or m].
        statuses: controller statuses seen (``ok``, ``relaxed``, ``held``) with their counts.
    """

    q: np.ndarray
    errors: ShapeErrors
    iterations: int
    converged: bool
    step: float
    statuses: dict[str, int] = field(default_factory=dict)


@dataclass(slots=True)
class ShapeRetargetResult:
    r"""A retargeted motion.

    Attributes:
        q: (T, nq) configurations, one per source pose.
        pose_error: (T,) :math:`E_p` (Tosun eq. 5).
        end_effector_error: (T,) :math:`E_e` (Tosun eq. 2).
        error: (T,) :math:`E = E_p + \alpha E_e` (Tosun eq. 3).
        iterations: (T,) QP steps per pose (1 online).
        converged: (T,) convergence flag per pose (always ``True`` online).
        mode: ``"offline"`` or ``"online"``.
        wall_time: total time [s].
    """

    q: np.ndarray
    pose_error: np.ndarray
    end_effector_error: np.ndarray
    error: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    mode: str
    wall_time: float

    def summary(self) -> dict[str, float]:
        """Means of the three metrics, iterations per pose and the share of converged poses."""
        return {
            "E_p": float(np.mean(self.pose_error)),
            "E_e": float(np.mean(self.end_effector_error)),
            "E": float(np.mean(self.error)),
            "iterations": float(np.mean(self.iterations)),
            "converged": float(np.mean(self.converged)),
        }


def shape_task(controller: Controller, name: str | None = None) -> ChainShapeTask:
    """The controller's ``chain_shape`` task named ``name`` (the only one when ``None``).

    Raises:
        ConfigError: no such task, or several ``chain_shape`` tasks and no name.
    """
    shapes = {n: t for n, t in controller.tasks.items() if isinstance(t, ChainShapeTask)}
    if name is None:
        if not shapes:
            raise ConfigError(
                "the controller has no chain_shape task; add one under `tasks:` "
                "(type: chain_shape, frames: [...])."
            )
        if len(shapes) > 1:
            raise ConfigError(
                f"the controller has {len(shapes)} chain_shape tasks ({', '.join(shapes)}); "
                "pass task=NAME."
            )
        return next(iter(shapes.values()))
    if name not in shapes:
        raise ConfigError(
            f"no chain_shape task named {name!r}.{close_matches_hint(name, list(shapes))} "
            f"chain_shape tasks: {', '.join(shapes) or 'none'}."
        )
    return shapes[name]


def _check_positive(value: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ConfigError(f"{what} must be a number > 0, got {value!r}.")
    return float(value)


def total_cost(controller: Controller) -> float:
    r"""Weighted cost :math:`\sum_i w_i |e_i|^2` of every task at the controller's configuration.

    With only a ``chain_shape`` task of weight 1 this is Tosun's :math:`E` (eq. 3).
    """
    state = controller.state
    cost = 0.0
    for t in controller.tasks.values():
        e = t.compute_error(state)
        cost += float(np.dot(t.weight, e * e))
    return cost


_Model = list[tuple[np.ndarray, np.ndarray, np.ndarray]]


def _linear_model(controller: Controller) -> _Model:
    """``(w, e, J)`` of every task at the controller's configuration (predicted decrease)."""
    state = controller.state
    return [
        (t.weight, t.compute_error(state), t.compute_jacobian(state))
        for t in controller.tasks.values()
    ]


def _predicted_decrease(model: _Model, dq: np.ndarray) -> float:
    r"""Cost decrease predicted by the linearization, :math:`\sum w (|e|^2 - |e - J dq|^2)`."""
    pred = 0.0
    for w, e, J in model:
        r = e - J @ dq
        pred += float(np.dot(w, e * e) - np.dot(w, r * r))
    return pred


def retarget_pose(
    controller: Controller,
    source: npt.ArrayLike,
    *,
    task: str | None = None,
    tol: float = 1e-7,
    max_iterations: int = 200,
    max_step: float = 0.5,
    max_damping: float = 1e3,
    restarts: int = 0,
    rng: np.random.Generator | int | None = 0,
) -> PoseResult:
    r"""Retarget one source pose to convergence, starting from the controller's configuration.

    Each iteration is one :meth:`Controller.step`: one QP whose unconstrained part is the
    Gauss-Newton step :math:`\Delta q = v\,dt` on the weighted cost
    :math:`\sum_i w_i |e_i|^2` (with ``gain: null``, :math:`K\,dt = 1`) and whose bounds are the
    hard joint limits: the paper's problem (Tosun eq. 4) solved by sequential QPs. The controller's
    damping :math:`\lambda` plays the Levenberg-Marquardt parameter (Nielsen's update): with
    :math:`\rho` the ratio of the actual to the predicted decrease of the cost, a step with
    :math:`\rho > 0` and :math:`|\Delta q|_\infty \le` ``max_step`` is kept and
    :math:`\lambda^2` is scaled by :math:`\max(1/3, 1 - (2\rho - 1)^3)` (never below the
    configured :math:`\lambda`); any other step is undone (``controller.reset`` to the previous
    configuration) and :math:`\lambda^2` is scaled by :math:`\nu` (doubling on each failure).
    Iterations stop when a kept step has :math:`|\Delta q|_\infty <` ``tol``, when the predicted
    decrease vanishes (a constrained stationary point), or when :math:`\lambda` exceeds
    ``max_damping``.

    The problem is not convex: the result is the local minimum reached from the start (the
    previous pose's solution, as in Tosun 5.1). ``restarts > 0`` also starts from that many
    random configurations inside the joint limits and keeps the lowest cost.

    Args:
        controller: a controller with a ``chain_shape`` task (and usually ``joint_limits``).
        source: (n, 3) source chain points, base first.
        task: name of the ``chain_shape`` task (needed only if there are several).
        tol: step tolerance [rad] (joint units).
        max_iterations: cap on QP steps per start.
        max_step: trust radius: longest step kept [rad].
        max_damping: give up increasing :math:`\lambda` beyond this value.
        restarts: extra random starts (uniform inside finite joint limits, else in
            :math:`[-\pi, \pi]`; a free-flyer base keeps its pose).
        rng: random generator or seed of the restarts.

    Returns:
        The :class:`PoseResult` of the best start (iterations summed over starts); the controller
        is left at its configuration.

    Raises:
        ConfigError: bad ``tol``/``max_iterations``/``restarts`` or no ``chain_shape`` task.
        TargetError: malformed source points.
    """
    shape = shape_task(controller, task)
    tol = _check_positive(tol, "tol")
    max_damping = _check_positive(max_damping, "max_damping")
    max_step = _check_positive(max_step, "max_step")
    for value, what, low in ((max_iterations, "max_iterations", 1), (restarts, "restarts", 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ConfigError(f"{what} must be an integer >= {low}, got {value!r}.")
    src = _source_points(source, shape.name)
    settings = (tol, max_iterations, max_step, max_damping)
    best = _solve_from_current(controller, shape, src, *settings)
    if restarts:
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        best = _best_of_restarts(controller, shape, src, settings, best, restarts, gen)
    return best


def _source_points(source: npt.ArrayLike, task: str) -> np.ndarray:
    """``source`` as finite (n >= 2, 3) points; :class:`TargetError` otherwise."""
    src = np.asarray(source, dtype=float)
    if not np.all(np.isfinite(src)):
        raise TargetError("offline retargeting needs finite source points.", task=task)
    if src.ndim != 2 or src.shape[0] < 2 or src.shape[1] != 3:
        raise TargetError(
            f"source must be an (n >= 2, 3) array of points, got shape {src.shape}.", task=task
        )
    return src


def _best_of_restarts(
    controller: Controller,
    shape: ChainShapeTask,
    src: np.ndarray,
    settings: tuple[float, int, float, float],
    best: PoseResult,
    restarts: int,
    gen: np.random.Generator,
) -> PoseResult:
    """The lowest-cost result of ``best`` and ``restarts`` random starts inside the limits."""
    best_cost = total_cost(controller)
    total_iterations = best.iterations
    robot = controller.robot
    qi = robot.joint_q_index
    lo = np.where(np.isfinite(robot.q_min[qi]), robot.q_min[qi], -np.pi)
    hi = np.where(np.isfinite(robot.q_max[qi]), robot.q_max[qi], np.pi)
    for _ in range(restarts):
        q = best.q.copy()
        q[qi] = gen.uniform(lo, hi)
        controller.reset(q)
        res = _solve_from_current(controller, shape, src, *settings)
        total_iterations += res.iterations
        cost = total_cost(controller)
        if cost < best_cost:
            best, best_cost = res, cost
    controller.reset(best.q)
    shape.set_target(src)
    best.iterations = total_iterations
    return best


def _solve_from_current(
    controller: Controller,
    shape: ChainShapeTask,
    src: np.ndarray,
    tol: float,
    max_iterations: int,
    max_step: float,
    max_damping: float,
) -> PoseResult:
    """Levenberg-Marquardt iterations of :func:`retarget_pose` from the current configuration."""
    reg = controller.regularization
    lam0 = reg.damping
    mu_min = max(lam0 * lam0, 1e-12)  # Levenberg-Marquardt parameter mu = lambda^2
    mu, nu = mu_min, 2.0
    statuses: dict[str, int] = {}
    step = np.inf
    converged = False
    it = 0
    targets: dict[str, np.ndarray] | None = {shape.name: src}
    shape.set_target(src)
    cost = total_cost(controller)
    try:
        for it in range(1, max_iterations + 1):  # noqa: B007 - `it` is reported
            q_prev = controller.q.copy()
            model = _linear_model(controller)
            reg.damping = float(np.sqrt(mu))
            res = controller.step(targets)
            targets = None  # the task keeps its source until a reset
            statuses[res.status] = statuses.get(res.status, 0) + 1
            dq = np.asarray(res.v) * controller.dt
            step = float(np.max(np.abs(dq), initial=0.0))
            pred = _predicted_decrease(model, dq)
            new_cost = total_cost(controller)
            rho = (cost - new_cost) / pred if pred > 0 else -1.0
            if step < tol and new_cost <= cost + 1e-15 * max(1.0, cost):
                cost = new_cost
                converged = True
                break
            if rho > 0 and step <= max_step:
                cost = new_cost
                mu = max(mu * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), mu_min)
                nu = 2.0
                continue
            # Not a descent step, or longer than the trust radius: undo it, damp more.
            controller.reset(q_prev)
            shape.set_target(src)
            if pred <= 1e-15 * max(1.0, cost) and step <= max_step:
                converged = True  # nothing left to gain at this point
                break
            mu *= nu
            nu *= 2.0
            if mu > max_damping**2:
                converged = True  # no descent step left: a stationary point to solver accuracy
                break
    finally:
        reg.damping = lam0
    return PoseResult(
        q=controller.q.copy(),
        errors=shape.errors(controller.state),
        iterations=it,
        converged=converged,
        step=step,
        statuses=statuses,
    )


def retarget_motion(
    controller: Controller,
    sources: npt.ArrayLike | Sequence[npt.ArrayLike],
    *,
    task: str | None = None,
    mode: Literal["offline", "online"] = "offline",
    q0: npt.ArrayLike | None = None,
    tol: float = 1e-7,
    max_iterations: int = 200,
    restarts: int = 0,
    seed: int = 0,
) -> ShapeRetargetResult:
    """Retarget a sequence of source poses.

    Offline (Tosun 5.1): each pose is solved to convergence by :func:`retarget_pose`, starting
    from the previous pose's solution. Online: one :meth:`Controller.step` per pose (per tick).

    Args:
        controller: a controller with a ``chain_shape`` task.
        sources: (T, n, 3) array, or a sequence of (n_t, 3) arrays, of source chain points.
        task: name of the ``chain_shape`` task (needed only if there are several).
        mode: ``"offline"`` or ``"online"``.
        q0: start configuration; ``None`` keeps the controller's current one.
        tol: offline step tolerance [rad].
        max_iterations: offline cap on QP steps per pose.
        restarts: offline extra random starts per pose (see :func:`retarget_pose`).
        seed: seed of the restarts' random generator.

    Returns:
        The :class:`ShapeRetargetResult`.

    Raises:
        ConfigError: bad ``mode``, ``tol``, ``max_iterations`` or no ``chain_shape`` task.
        TargetError: malformed source points.
    """
    if mode not in ("offline", "online"):
        raise ConfigError(f"mode must be 'offline' or 'online', got {mode!r}.")
    shape = shape_task(controller, task)
    if q0 is not None:
        controller.reset(np.asarray(q0, dtype=float))
    poses: list[Any] = list(cast(Any, sources))
    T = len(poses)
    nq = controller.robot.nq
    q = np.zeros((T, nq))
    e_p, e_e, e = np.zeros(T), np.zeros(T), np.zeros(T)
    iterations = np.zeros(T, dtype=int)
    converged = np.zeros(T, dtype=bool)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    for i, src in enumerate(poses):
        if mode == "offline":
            r = retarget_pose(
                controller, src, task=shape.name, tol=tol, max_iterations=max_iterations,
                restarts=restarts, rng=rng,
            )  # fmt: skip
            q[i], errs, iterations[i], converged[i] = r.q, r.errors, r.iterations, r.converged
        else:
            res = controller.step({shape.name: src})
            q[i], errs, iterations[i], converged[i] = res.q, shape.errors(controller.state), 1, True
        e_p[i], e_e[i], e[i] = errs.pose, errs.end_effector, errs.total
    return ShapeRetargetResult(
        q=q,
        pose_error=e_p,
        end_effector_error=e_e,
        error=e,
        iterations=iterations,
        converged=converged,
        mode=mode,
        wall_time=time.perf_counter() - t0,
    )


# ---------------------------------------------------------------------------- source chains
def torso_rotations(motion: HumanMotion) -> np.ndarray:
    """World rotation of the torso axes (x forward, y left, z up) per frame, (T, 3, 3).

    Uses the key-point map's ``torso`` orientation when the motion has one (BVH, ASF/AMC: the
    rest pose faces +x with z up, so the rotation maps torso axes to world axes); otherwise
    (markers) builds it from the shoulders (y: right to left) and the waist-to-neck line (z).

    Raises:
        ValueError: if neither the orientation nor the needed key-points are available.
    """
    if motion.orientations is not None:
        try:
            return np.asarray(keypoint_orientations(motion)["torso"], dtype=float)
        except KeyError:
            pass
    k = keypoint_positions(motion)
    try:
        y = k["left_shoulder"] - k["right_shoulder"]
        up_from = k["waist"]
        up_to = k["neck"] if "neck" in k else 0.5 * (k["left_shoulder"] + k["right_shoulder"])
    except KeyError as exc:
        raise ValueError(
            f"{motion.source}: no torso orientation and no {exc} key-point to build one; use "
            "frame='world'."
        ) from None
    z = up_to - up_from
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    z = z - np.einsum("ti,ti->t", z, y)[:, None] * y
    z = z / np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=2)


def arm_chain(
    motion: HumanMotion,
    side: Literal["left", "right"] = "left",
    *,
    points: Sequence[str] = ARM_POINTS,
    frame: Literal["torso", "world"] = "torso",
    plane: Literal["coronal", "sagittal", "transverse"] | None = None,
) -> np.ndarray:
    """Human arm chains from motion capture, relative to the shoulder, (T, n, 3) [m].

    Args:
        motion: a :class:`~qpretarget.motion.HumanMotion` with the arm key-points (any bundled
            key-point map: CMU BVH/ASF-AMC, cgspeed BVH, the upper-limb C3D marker set).
        side: ``"left"`` or ``"right"`` arm.
        points: key-points from the base, among ``shoulder``, ``elbow``, ``wrist``, ``hand``.
        frame: ``"torso"`` expresses the points in the torso axes (x forward, y left, z up; the
            axes of a humanoid's torso frame), ``"world"`` keeps the world axes.
        plane: project on an anatomical plane of the torso (``coronal`` drops x, Tosun 4.1;
            ``sagittal`` drops y; ``transverse`` drops z). Needs ``frame="torso"``.

    Returns:
        (T, n, 3) points, the shoulder at the origin; NaN where the capture has a gap.

    Raises:
        ValueError: unknown side, point or plane.
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}.")
    unknown = [p for p in points if p not in ARM_POINTS]
    if unknown or len(points) < 2:
        raise ValueError(f"points must be at least two of {ARM_POINTS}, got {list(points)!r}.")
    if plane is not None and (plane not in PLANES or frame != "torso"):
        raise ValueError(
            f"plane must be one of {sorted(PLANES)} (with frame='torso'), got {plane!r}."
        )
    k = keypoint_positions(motion)
    P = np.stack([np.asarray(k[f"{side}_{p}"], dtype=float) for p in points], axis=1)  # (T, n, 3)
    P = P - P[:, :1]
    if frame == "torso":
        R = torso_rotations(motion)
        P = np.einsum("tji,tnj->tni", R, P)  # R^T p per frame
        if plane is not None:
            P[:, :, PLANES[plane]] = 0.0
    elif frame != "world":
        raise ValueError(f"frame must be 'torso' or 'world', got {frame!r}.")
    return P


def robot_chain(
    robot: RobotModel,
    frames: Sequence[str],
    configurations: npt.ArrayLike,
    *,
    reference_frame: str | None = None,
) -> np.ndarray:
    """Frame origins of a robot posed by a joint trajectory, base at 0, (T, n, 3) [m].

    Use it as the source of a robot-to-robot transfer (e.g. a G1 arm trajectory onto Talos).

    Args:
        robot: the source robot.
        frames: its chain frames, base first.
        configurations: (T, nq) joint trajectory (or one (nq,) configuration).
        reference_frame: express the points in this frame's axes (``None``: world axes).

    Returns:
        (T, n, 3) points relative to the first frame.
    """
    qs = np.atleast_2d(np.asarray(configurations, dtype=float))
    ids = [robot.frame_id(f, path=f"frames[{i}]") for i, f in enumerate(frames)]
    ref = None
    if reference_frame is not None:
        ref = robot.frame_id(reference_frame, path="reference_frame")
    state = RobotState(robot)
    out = np.zeros((qs.shape[0], len(ids), 3))
    for t, q in enumerate(qs):
        state.update(robot.check_configuration(q, what=f"configurations[{t}]"))
        P = np.array([state.frame_placement(f).translation for f in ids])
        P -= P[0]
        if ref is not None:
            P = P @ state.frame_placement(ref).rotation
        out[t] = P
    return out
