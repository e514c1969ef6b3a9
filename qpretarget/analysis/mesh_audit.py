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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..collision import CollisionModel, link_shapes
from ..collision.pairs import Pair, select_pairs
from ..errors import ConfigError
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
    """Every pair the audit measures (module docstring), in the URDF's body order.

    Raises:
        ConfigError: the robot has no collision geometry.
    """
    shapes = link_shapes(robot, "convex_hull")
    if len(shapes) < 2:
        raise ConfigError(
            f"robot {robot.name!r} has no collision geometry to audit (bodies with collision "
            f"geometry: {len(shapes)})."
        )
    return select_pairs(robot, shapes, use_srdf=False).pairs


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


def has_collision_geometry(robot: RobotModel) -> bool:
    """At least two bodies with collision geometry (something to audit)."""
    return len(link_shapes(robot, "convex_hull")) >= 2


def audit_lines(
    audit: SelfCollisionAudit | Mapping[str, Any] | None, n_worst: int = 3
) -> list[str]:
    """The audit in words, as ``evaluate`` and the run summary print it (one definition).

    First line: ``N penetrating frames of T over P pairs (meshes), min distance X mm``; then,
    when some pair penetrates, the worst pairs with their frames and deepest penetration.

    Args:
        audit: the audit, its :meth:`SelfCollisionAudit.to_dict`, or ``None`` (no geometry).
        n_worst: penetrating pairs listed.
    """
    if audit is None:
        return ["not audited: the robot has no collision geometry"]
    d = audit.to_dict() if isinstance(audit, SelfCollisionAudit) else audit
    lines = [
        f"{d['penetrating_frames']} penetrating frames of {d['frames_audited']} over "
        f"{d['pairs_audited']} pairs (meshes), min distance {d['min_distance_mm']:.1f} mm"
    ]
    bad = sorted(d["penetrating_pairs"], key=lambda p: (-p["frames"], -p["deepest_mm"]))
    for p in bad[:n_worst]:
        lines.append(
            f"  {p['pair'][0]} / {p['pair'][1]}: {p['frames']} frames, deepest "
            f"{p['deepest_mm']:.1f} mm"
        )
    if len(bad) > n_worst:
        lines.append(f"  (+{len(bad) - n_worst} more penetrating pairs)")
    return lines


def audit_run(q: np.ndarray, robot: RobotModel, *, stride: int = 1) -> SelfCollisionAudit | None:
    """Audit a run's configurations over every pair (what ``evaluate`` and the summary call).

    Args:
        q: (T, nq) configurations of the run.
        robot: its robot.
        stride: every ``stride``-th frame (1: all).

    Returns:
        The audit, or ``None`` when the robot has no collision geometry.
    """
    if not has_collision_geometry(robot):
        return None
    return audit_self_collision(robot, np.asarray(q, dtype=float), stride=stride)


def plot_audit(
    audit: SelfCollisionAudit, t: np.ndarray, path: str | Path, n_worst: int = 6
) -> Path:
    """Figure: distance over time of the ``n_worst`` closest pairs, penetrations marked.

    Args:
        audit: the audit of a run.
        t: (T,) times of the run's samples [s] (indexed by :attr:`SelfCollisionAudit.frames`).
        path: PNG file to write.
        n_worst: pairs drawn.
    """
    from .plots import _figure, _pretty, _save

    fig = _figure("violations")
    ax = fig.add_subplot(1, 1, 1)
    tt = np.asarray(t, dtype=float)[audit.frames]
    index = {p: i for i, p in enumerate(audit.pairs)}
    for p in audit.worst(n_worst):
        i = index[p.pair]
        ax.plot(tt, audit.distance[:, i] * 1e3, lw=1.2,
                label=f"{_pretty(p.pair[0])} / {_pretty(p.pair[1])}")  # fmt: skip
        pen = audit.penetrating[:, i]
        if pen.any():
            ax.plot(tt[pen], audit.distance[pen, i] * 1e3, "x", color="red", ms=4)
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("distance [mm] (hulls; meshes where the hulls overlap)")
    ax.set_title(
        f"self-collision over all {len(audit.pairs)} pairs: {audit.penetrating_frames} "
        f"penetrating frames, min {audit.min_distance_mm:.1f} mm (closest {n_worst} pairs; "
        "x: meshes intersect)"
    )
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    return _save(fig, Path(path))
