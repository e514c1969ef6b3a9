# SPDX-License-Identifier: Apache-2.0
"""Collision geometry: simplified link shapes (convex hulls, capsules) and pair distances."""

from .geometry import CollisionModel, LinkShape, link_shapes

__all__ = ["CollisionModel", "LinkShape", "link_shapes"]
