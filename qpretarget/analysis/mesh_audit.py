# SPDX-License-Identifier: Apache-2.0
r"""Self-collision audit of a run over every body pair, confirmed on the URDF's meshes.

The one definition of "the robot hits itself", used by ``qpretarget evaluate``, the run summary
and the tests, whatever pairs the controller's config constrains: the audited pairs are every
pair of bodies with collision geometry that is not on one joint, not adjacent in the kinematic
tree and not already in contact in the reference posture (:func:`~qpretarget.collision.pairs.
select_pairs` without the SRDF's heuristic "never collide" list and without the config's
``exclude:``).

Per frame and pair, the distance :math:`d` is measured on the convex hulls of the links' meshes
(coal GJK). A hull contains its mesh, so the hull distance is a lower bound of the mesh distance:
:math:`d_{hull} > 0` proves the meshes apart. Where the hulls overlap, the meshes themselves are
tested (coal BVH collision and distance): if they do not intersect, :math:`d` is their exact
distance; if they do, the pair penetrates in that frame and its depth is the hull penetration
depth :math:`-d_{hull}` (an upper bound of the mesh depth; coal gives no depth for two
triangle meshes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..collision import CollisionModel, link_shapes
from ..collision.pairs import Pair, select_pairs
from ..robot import RobotModel, RobotState


@dataclass
class PairAudit:
    """What one pair did over a run.

    Attributes:
        pair: the two body names.
        penetrating_frames: frames where the meshes intersect.
        deepest_mm: deepest penetration over the run [mm] (0 when never).
        min_distance_mm: smallest distance over the run [mm] (negative: penetration depth).
    """

    pair: Pair
    penetrating_frames: int = 0
    deepest_mm: float = 0.0
    min_distance_mm: float = float("inf")


@dataclass
class SelfCollisionAudit:
    """The audit of one run (:func:`audit_self_collision`).

    Attributes:
        pairs: every audited pair, in the order of :attr:`distance`'s columns.
        distance: (T, P) distance per frame and pair [m] (see the module docstring).
        penetrating: (T, P) the meshes intersect.
        frames: indices of the audited frames in the run.
    """

    pairs: list[Pair]
    distance: np.ndarray
    penetrating: np.ndarray
    frames: np.ndarray
    per_pair: list[PairAudit] = field(default_factory=list)

    @property
    def penetrating_frames(self) -> int:
        """Frames with at least one penetrating pair."""
        return int(np.count_nonzero(self.penetrating.any(axis=1)))

    @property
    def min_distance_mm(self) -> float:
        """Smallest distance over every pair and frame [mm]."""
        return float(self.distance.min() * 1e3) if self.distance.size else float("inf")

    def worst(self, n: int = 10) -> list[PairAudit]:
        """The ``n`` pairs with the smallest distance over the run."""
        return sorted(self.per_pair, key=lambda p: p.min_distance_mm)[:n]

    def to_dict(self, n_worst: int = 10) -> dict[str, Any]:
        """JSON-ready summary: counts, minimum distance and the worst pairs."""
        return {
            "pairs_audited": len(self.pairs),
            "frames_audited": int(len(self.frames)),
            "penetrating_frames": self.penetrating_frames,
            "min_distance_mm": round(self.min_distance_mm, 3),
            "penetrating_pairs": [
                {
                    "pair": list(p.pair),
                    "frames": p.penetrating_frames,
                    "deepest_mm": round(p.deepest_mm, 3),
                }
                for p in self.per_pair
                if p.penetrating_frames
            ],  # fmt: skip
            "closest_pairs": [
                {"pair": list(p.pair), "min_distance_mm": round(p.min_distance_mm, 3)}
                for p in self.worst(n_worst)
            ],
        }


def audited_pairs(robot: RobotModel) -> list[Pair]:
    """Every pair the audit measures (module docstring), in the URDF's body order."""
    return select_pairs(robot, link_shapes(robot, "convex_hull"), use_srdf=False).pairs


class _MeshChecker:
    """Exact mesh tests for the pairs whose hulls overlap."""

    def __init__(self, robot: RobotModel) -> None:
        self.model = robot.model
        gmodel, _ = robot.geometry()
        self.gmodel = gmodel
        self.gdata = gmodel.createData()
        self.objects: dict[str, list[int]] = {}
        for i, go in enumerate(gmodel.geometryObjects):
            self.objects.setdefault(self.model.frames[go.parentFrame].name, []).append(i)
        self._creq, self._dreq = coal.CollisionRequest(), coal.DistanceRequest()

    def update(self, data: pin.Data) -> None:
        pin.updateGeometryPlacements(self.model, data, self.gmodel, self.gdata)

    def distance(self, a: str, b: str) -> float:
        """Mesh distance of two bodies (0.0 and ``penetrates`` when they intersect)."""
        best = np.inf
        for i in self.objects[a]:
            gi, ti = self.gmodel.geometryObjects[i].geometry, self.gdata.oMg[i]
            for j in self.objects[b]:
                gj, tj = self.gmodel.geometryObjects[j].geometry, self.gdata.oMg[j]
                ta, tb = (
                    coal.Transform3s(ti.rotation, ti.translation),
                    coal.Transform3s(tj.rotation, tj.translation),
                )
                if coal.collide(gi, ta, gj, tb, self._creq, coal.CollisionResult()):
                    return 0.0
                d = coal.distance(gi, ta, gj, tb, self._dreq, coal.DistanceResult())
                best = min(best, d)
        return float(best)


def audit_self_collision(
    robot: RobotModel,
    q: np.ndarray,
    *,
    pairs: Sequence[Pair] | None = None,
    stride: int = 1,
) -> SelfCollisionAudit:
    """Audit a trajectory for self-collision over every pair (module docstring).

    Args:
        robot: the robot of the run.
        q: (T, nq) configurations.
        pairs: pairs to audit (default: :func:`audited_pairs`).
        stride: audit every ``stride``-th frame (1: all).

    Returns:
        The :class:`SelfCollisionAudit`.
    """
    pairs = list(audited_pairs(robot) if pairs is None else pairs)
    frames = np.arange(0, len(q), max(1, int(stride)))
    hulls = CollisionModel(robot, pairs, geometry="convex_hull", broad_phase=False)
    meshes = _MeshChecker(robot)
    state = RobotState(robot)
    dist = np.zeros((len(frames), len(pairs)))
    pen = np.zeros((len(frames), len(pairs)), dtype=bool)
    for row, k in enumerate(frames):
        state.update(np.asarray(q[k], dtype=float))
        d = hulls.compute_all(state)[0]
        overlap = np.flatnonzero(d <= 0.0)
        if overlap.size:
            meshes.update(state.data)
        for i in overlap.tolist():
            dm = meshes.distance(*pairs[i])
            if dm > 0.0:
                d[i] = dm
            else:
                pen[row, i] = True
                d[i] = min(d[i], -1e-9)  # a touching contact still counts as penetration
        dist[row] = d
    audit = SelfCollisionAudit(pairs, dist, pen, frames)
    for i, p in enumerate(pairs):
        col = dist[:, i]
        audit.per_pair.append(
            PairAudit(
                p,
                int(np.count_nonzero(pen[:, i])),
                float(max(0.0, -col.min()) * 1e3) if pen[:, i].any() else 0.0,
                float(col.min() * 1e3) if col.size else float("inf"),
            )
        )
    return audit
