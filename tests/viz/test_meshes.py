# SPDX-License-Identifier: Apache-2.0
"""Simplified link meshes: the coarse convex hull is wound outward without a graph library."""

from __future__ import annotations

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="the viz extra is part of the test extra")

from qpretarget.viz.meshes import _coarse_hull  # noqa: E402


def test_coarse_hull_faces_point_outward() -> None:
    # A dense sphere cloud, subsampled to 60 hull points: every face normal must point away from
    # the centre (dot > 0) and the signed volume must be positive (it is negative, with the same
    # magnitude, when the winding is inverted).
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(2000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    hull = _coarse_hull(trimesh.Trimesh(pts + [1.0, -2.0, 0.5], np.zeros((0, 3), int)), 60)
    centroids = hull.triangles_center - np.array([1.0, -2.0, 0.5])
    assert np.all(np.einsum("ij,ij->i", hull.face_normals, centroids) > 0.0)
    assert hull.volume > 0.0
    assert len(hull.vertices) <= 60
