# SPDX-License-Identifier: Apache-2.0
"""Collision geometry: simplified link shapes, pair selection and pair distances.

* ``shapes.py``: link shapes (convex hulls, capsules, primitives) and static obstacles.
* ``model.py``: :class:`CollisionModel`, distances, witness points and gradients of pairs.
* ``pairs.py``: which body pairs to check (automatic selection with reasons).
"""

from .model import CollisionModel, pair_distances
from .pairs import adjacent_links
from .shapes import (
    GEOMETRIES,
    LinkShape,
    fit_capsule,
    lighter_hull,
    link_shapes,
    obstacle_shape,
    primitive_points,
)

__all__ = [
    "GEOMETRIES",
    "CollisionModel",
    "LinkShape",
    "adjacent_links",
    "fit_capsule",
    "lighter_hull",
    "link_shapes",
    "obstacle_shape",
    "pair_distances",
    "primitive_points",
]
