# SPDX-License-Identifier: Apache-2.0
"""Distances of robot body pairs over a run (the pairs ``evaluate`` measures on hulls).

:class:`LinkPairDistances` wraps the shared :mod:`qpretarget.collision` model (the geometry the
``self_collision`` constraint uses in the loop); :class:`GeometryPairDistances` measures any
pinocchio ``GeometryModel``; :func:`collision_model_for` picks the pairs of a run. The audit over
every body pair on the meshes is :mod:`qpretarget.analysis.mesh_audit`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import close_matches_hint
from ..robot import RobotModel
from .measures import DEFAULT_SAFETY_DISTANCE, MetricsError

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
                        f"{close_matches_hint(n, list(by_name))}"
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
