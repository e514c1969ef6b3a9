# SPDX-License-Identifier: Apache-2.0
r"""Self-collision avoidance by redirection with blending (Dariush 2009 eq. 17-23), closed form.

The baseline the QP's linearized self-collision rows are compared with. Each tick:

1. Tracking solution of all tasks augmented (rows scaled by :math:`\sqrt{w}`), weighted damped
   least squares (Dariush 2009 eq. 9-10): :math:`\dot q_0 = J^* v^*`,
   :math:`J^* = W^{-1} J^\top (J W^{-1} J^\top + \lambda^2 I)^{-1}`, :math:`v^* = \dot p_r + K e`.
2. For every checked pair with witness points :math:`p_a, p_b` at distance :math:`d` and unit
   normal :math:`\hat n_a = (p_b - p_a)/|p_b - p_a|` whose blending weight (eq. 23)

   .. math:: b(d) = \frac{e^{-\alpha(d/d_c - \delta)}}{1 + e^{-\alpha(d/d_c - \delta)}}

   is not negligible, the collision-point velocities :math:`\dot p_a = J_a \dot q_0` and
   :math:`\dot p_b = J_b \dot q_0` are redirected to slide along the surface (eq. 18),
   :math:`\dot p'_a = \dot p_a - \langle \dot p_a, \hat n_a\rangle \hat n_a` (and the same for
   :math:`b` with :math:`-\hat n_a`; "when both bodies move, redirect both collision points and
   augment them", Dariush 2009 4.6.2). Only an approaching normal component is removed: a point
   moving away keeps its velocity.
3. Redirected joint velocity (eq. 19):
   :math:`\dot q' = J_c^* \dot p'_c + S\, \dot q_0`, with :math:`J_c` the stacked collision-point
   Jacobians and :math:`S` selecting the joints whose column of :math:`J_c` is zero.
4. Blended reference (eq. 20, 22): :math:`v^{*\prime} = (1 - b) v^* + b J \dot q'` with
   :math:`b = \max_j b(d_j)` over the pairs, then the closed loop (eq. 21)
   :math:`\dot q = J^* v^{*\prime}` (optionally with the collision points and their redirected
   velocities augmented to the tasks, ``point_weight``).

Measured behaviour (G1, right hand driven to a target inside the torso, 4 pairs): the approach
slows down once :math:`b` rises, then the hand slides along the surface and another point of the
arm penetrates: eq. 21 re-solves the tracking from the task-space image :math:`J \dot q'` only,
so nothing keeps the collision points' normal velocities at zero. The QP's linearized distance
rows enforce that directly.

Departure from the paper: Dariush integrates a redesigned reference :math:`p'_r` and uses
:math:`e' = p'_r - p` with a gain :math:`K'` that decreases with :math:`d` (eq. 21). Tasks here
hand over :math:`v^* = \dot p_r + K e` for the tick only, so the blend is applied to :math:`v^*`
itself: the error feedback is scaled by :math:`(1 - b)` as the pair closes in, which is the role of
the decreasing :math:`K'`.

Geometry is the shared :class:`qpretarget.collision.model.CollisionModel`, the one the QP's
``self_collision`` rows use (one convex hull or capsule per link, docs/collisions.md): its
witness points :math:`p_a, p_b` and unit normal :math:`n` (from :math:`a` to :math:`b`, signed:
also valid in penetration), with the temporal-coherence broad phase, so only pairs that can be
within the blending's reach are computed: :math:`b(d) >` ``activation`` iff
:math:`d < d_c\,(\delta + \ln((1 - \epsilon)/\epsilon)/\alpha)` (8.1 cm with the defaults).
The collision-point Jacobians :math:`J_a(p_a), J_b(p_b)` (3 x nv, world axes) come from the
tick's joint Jacobians (``state.data``); their normal projections
:math:`n^\top(J_b - J_a)` are exactly the shared model's distance gradients. Box bounds are
honoured with Poubel's clamping loop on the last step (see :mod:`.nullspace`); constraint rows
cannot be, and binding with rows raises unless ``ignore_rows: true``.

YAML::

    strategy:
      type: redirection
      pairs: [[right_wrist_yaw_link, torso_link], [left_wrist_yaw_link, torso_link]]
      critical_distance: 0.05     # d_c [m]
      blend_alpha: 15.0           # alpha of eq. 23 (paper figure: 15)
      blend_delta: 1.0            # delta of eq. 23 (0.5 or 1.0 in the paper)
      geometry: convex_hull       # or capsule (qpretarget.collision.shapes)
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..collision import CollisionModel, link_shapes
from ..constraints.self_collision import resolve_link
from ..errors import ConfigError
from ..robot import LWA, RobotModel, RobotState
from ..validation import positive_float
from .base import STRATEGIES, StrategyResult, TaskDims, TickProblem
from .nullspace import ClosedFormStrategy, clamping_loop, weighted_prioritized_dls


def blending(d: np.ndarray | float, critical_distance: float, alpha: float, delta: float) -> Any:
    r"""Blending weight of Dariush 2009 eq. 23, :math:`b = \sigma(-\alpha (d/d_c - \delta))`."""
    x = -alpha * (np.asarray(d, dtype=float) / critical_distance - delta)
    return 0.5 * (1.0 + np.tanh(0.5 * x))  # = e^x / (1 + e^x), without overflow


def blending_reach(critical_distance: float, alpha: float, delta: float, level: float) -> float:
    r"""Distance below which :math:`b(d) >` ``level`` (eq. 23 inverted) [m].

    :math:`b(d) > \epsilon \iff d < d_c\,(\delta + \ln((1 - \epsilon)/\epsilon)/\alpha)`.
    """
    return critical_distance * (delta + np.log((1.0 - level) / level) / alpha)


@STRATEGIES.register("redirection")
class Redirection(ClosedFormStrategy):
    r"""Closed-form tracking with self-collision redirection and blending (Dariush 2009 eq. 17-23).

    Args:
        pairs: checked link pairs ``[[link_a, link_b], ...]`` (URDF links with collision
            geometry; key-point names such as ``right_hand`` resolve to their link).
        critical_distance: :math:`d_c` [m], thickness of the critical zone (eq. 17).
        blend_alpha: :math:`\alpha` of the blending function (eq. 23).
        blend_delta: :math:`\delta` of the blending function (eq. 23).
        damping: :math:`\lambda` of the tracking DLS inverse (``None``: the regularization's).
        point_damping: :math:`\lambda` of the collision-point inverse :math:`J_c^*` of eq. 19
            (its rows are unweighted metres, and several points conflict: a small value gives
            huge joint velocities).
        point_weight: weight of the collision points as extra tasks in the last step (eq. 21),
            tracking their redirected velocities, scaled by :math:`b` (Dariush 2009 4.6.2: "use
            task augmentation to control both critical points"); 0 is eq. 21 as printed.
        clamping: Poubel's clamping loop for the box bounds on the last step.
        ignore_rows: run even if the config has constraint rows (they are ignored).
        activation: pairs with :math:`b(d)` below this are not redirected (nor computed).
        geometry: ``convex_hull`` or ``capsule`` link shapes (:mod:`qpretarget.collision.shapes`).
    """

    def __init__(
        self,
        pairs: Sequence[Sequence[str]],
        *,
        critical_distance: float = 0.05,
        blend_alpha: float = 15.0,
        blend_delta: float = 1.0,
        damping: float | None = None,
        point_damping: float = 0.05,
        point_weight: float = 0.0,
        clamping: bool = True,
        ignore_rows: bool = False,
        activation: float = 1e-4,
        geometry: str = "convex_hull",
    ) -> None:
        if isinstance(pairs, str) or not isinstance(pairs, Sequence) or not pairs:
            raise ConfigError(f"pairs must be a non-empty list of [link_a, link_b], got {pairs!r}.")
        self.pair_spec = [list(p) if not isinstance(p, str) else p for p in pairs]
        self.critical_distance = positive_float(critical_distance, "critical_distance [m]")
        self.blend_alpha = positive_float(blend_alpha, "blend_alpha")
        self.blend_delta = positive_float(blend_delta, "blend_delta", allow_zero=True)
        self.damping = (
            None if damping is None else positive_float(damping, "damping", allow_zero=True)
        )
        self.point_damping = positive_float(point_damping, "point_damping", allow_zero=True)
        self.point_weight = positive_float(point_weight, "point_weight", allow_zero=True)
        self.clamping = bool(clamping)
        self.ignore_rows = bool(ignore_rows)
        self.activation = positive_float(activation, "activation")
        if self.activation >= 0.5:
            raise ConfigError(f"activation must be in (0, 0.5), got {activation!r}.")
        self.geometry = geometry
        #: Distances of the pairs at the start of the last tick [m] (exact below the blending's
        #: reach, :func:`blending_reach`; lower bounds beyond), and its blending weight.
        self.last_distances = np.zeros(0)
        self.last_blend = 0.0
        self._bound = False  # set by bind (the collision model exists from then on)

    def bind(
        self, robot: RobotModel, task_dims: TaskDims, n_rows: int, solver_factory: Any
    ) -> None:
        super().bind(robot, task_dims, n_rows, solver_factory)
        shapes = link_shapes(robot, self.geometry)
        pairs: list[tuple[str, str]] = []
        for k, pair in enumerate(self.pair_spec):
            if isinstance(pair, str) or len(pair) != 2:
                raise ConfigError(
                    f"a pair is [link_a, link_b], got {pair!r}.", path=f"strategy.pairs[{k}]"
                )
            a, b = (
                resolve_link(robot, shapes, str(x), f"strategy.pairs[{k}][{i}]")
                for i, x in enumerate(pair)
            )
            pairs.append((a, b))
        #: The shared collision model (docs/collisions.md), only the pairs of ``pairs``.
        self.collision = CollisionModel(robot, pairs, geometry=self.geometry, path="strategy.pairs")
        cm = self.collision
        joint = {b: sh.joint for b, sh in zip(cm.bodies, cm.shapes, strict=True)}
        self._joints = np.array([[joint[a], joint[b]] for a, b in cm.pairs])  # bodies' joints
        self.reach = blending_reach(
            self.critical_distance, self.blend_alpha, self.blend_delta, self.activation
        )
        m = sum(d for _, d, _ in task_dims)
        self._J = np.zeros((m, robot.nv))
        self._r = np.zeros(m)
        self.last_distances = np.full(self.collision.n_pairs, np.inf)
        self._bound = True

    def reset(self) -> None:
        super().reset()
        if self._bound:
            self.collision.reset()

    def collision_points(
        self, state: RobotState
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        r"""The pairs within the blending's reach and their collision points (eq. 17-19).

        Returns:
            ``(pairs (k,), d (k,), p_a (k, 3), p_b (k, 3), n (k, 3), J_c (2k, 3, nv))``: pair
            indices, distances, witness points, unit normals from :math:`a` to :math:`b` (from
            the shared :class:`CollisionModel`), and the world Jacobians of the points
            :math:`J_a(p_a)` (even rows) and :math:`J_b(p_b)` (odd rows):
            :math:`\dot p = J_o v + \omega \times (p - o)` of the body's joint.
        """
        cm = self.collision
        cm.update(state, self.reach)
        act = cm.active
        pa, pb = cm.witness_a, cm.witness_b
        data, model = state.data, self.robot.model
        Jc = np.empty((2 * act.size, 3, self.nv))
        for x in range(2 * act.size):  # the k active pairs' 2k points (few; not per joint)
            j = int(self._joints[act[x // 2], x % 2])
            Jj = pin.getJointJacobian(model, data, j, LWA)
            r = (pb if x % 2 else pa)[x // 2] - data.oMi[j].translation
            Jc[x] = Jj[:3] - np.cross(r, Jj[3:].T).T  # v_p = v_o + w x r = v_o - r x w
        return act, cm.distances[act].copy(), pa, pb, cm.normals, Jc

    def solve(self, tp: TickProblem) -> StrategyResult:
        t0 = time.perf_counter()
        J, r = self._J, self._r
        i = 0
        for b in tp.blocks:
            k = b.J.shape[0]
            sw = np.sqrt(b.weight)
            np.multiply(b.J, sw[:, None], out=J[i : i + k])
            np.multiply(b.v_star, sw, out=r[i : i + k])
            i += k
        lam = tp.damping if self.damping is None else self.damping
        W = None if np.array_equal(tp.W, np.eye(self.nv)) else tp.W
        try:
            q0 = weighted_prioritized_dls([J], [r], [lam], W)  # eq. 9
            _, d, _, _, n, Jp = self.collision_points(tp.state)
            self.last_distances = self.collision.distances.copy()
            bj = blending(d, self.critical_distance, self.blend_alpha, self.blend_delta)
            active = np.flatnonzero(bj > self.activation)
            beta = float(bj[active].max()) if active.size else 0.0  # blending b of eq. 20
            self.last_blend = beta
            r_blend = r
            if active.size:
                # Points a, b of each active pair; eq. 17's unit normals n_a = n, n_b = -n.
                pts = np.stack([2 * active, 2 * active + 1], axis=1).reshape(-1)
                N = np.repeat(n[active], 2, axis=0)
                N[1::2] *= -1.0
                Jp = Jp[pts]
                pdot = Jp @ q0  # (2k, 3) collision-point velocities of the tracking solution
                approach = np.maximum(np.einsum("ij,ij->i", pdot, N), 0.0)
                pc = (pdot - approach[:, None] * N).reshape(-1)  # eq. 18 (approach removed)
                Jc = Jp.reshape(-1, self.nv)
                S = ~np.any(np.abs(Jc) > 1e-12, axis=0)  # joints not moving any collision point
                qr = weighted_prioritized_dls([Jc], [pc], [self.point_damping], W)  # eq. 19
                qr[S] += q0[S]  # eq. 19, second term S J^* (p_r + K e)
                r_blend = (1.0 - beta) * r + beta * (J @ qr)  # eq. 20, 22
            Jf, rf = J, r_blend
            if active.size and self.point_weight > 0:
                # The collision points join the tasks (Dariush 2009 4.6.2, "task augmentation to
                # control both critical points"), with their redirected velocities, blended by b.
                sc = beta * np.sqrt(self.point_weight)
                Jf = np.vstack([J, sc * Jc])
                rf = np.concatenate([r_blend, sc * pc])
            if self.clamping:
                x, rounds, n_clamped = clamping_loop([Jf], [rf], [lam], tp.lb, tp.ub, W)
            else:
                x = weighted_prioritized_dls([Jf], [rf], [lam], W)  # eq. 21
                rounds, n_clamped = 1, 0
        except np.linalg.LinAlgError as exc:
            return StrategyResult(
                None, False, f"closed form failed: {exc}", 0, time.perf_counter() - t0
            )
        ok = bool(np.all(np.isfinite(x)))
        status = (
            f"redirection: {active.size} pair(s) active, b = {beta:.3g}, "
            f"{n_clamped} joint(s) clamped"
            if ok
            else "redirection: non-finite"
        )
        return StrategyResult(x if ok else None, ok, status, rounds, time.perf_counter() - t0)

    def __repr__(self) -> str:
        return (
            f"Redirection(pairs={self.pair_spec!r}, critical_distance={self.critical_distance}, "
            f"blend_alpha={self.blend_alpha}, blend_delta={self.blend_delta})"
        )
