# SPDX-License-Identifier: Apache-2.0
"""Link meshes: the coarse convex hull is wound outward; COLLADA robots need pycollada."""

from __future__ import annotations

import sys

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="the viz extra is part of the test extra")

from qpretarget.errors import MissingDependencyError  # noqa: E402
from qpretarget.robot import load_robot  # noqa: E402
from qpretarget.viz.meshes import _coarse_hull, load_link_meshes  # noqa: E402


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


@pytest.mark.parametrize("name", ["romeo", "icub"])
def test_collada_robots_have_meshes(name) -> None:
    # Romeo's and iCub's meshes are .dae files, which trimesh reads only through pycollada (in the
    # viz and test extras). Without it every mesh used to be dropped and the renderer crashed.
    pytest.importorskip("collada", reason="pycollada is in the viz extra")
    meshes = load_link_meshes(load_robot(name), simplify=True, max_points=48)
    assert len(meshes) >= 10
    assert all(len(m.faces) > 0 for m in meshes)


def test_collada_without_pycollada_names_the_extra(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "collada", None)  # import collada -> ImportError
    with pytest.raises(MissingDependencyError, match=r"`viz` extra: pip install (-e )?\"") as info:
        load_link_meshes(load_robot("romeo"), simplify=True)
    assert "[viz]" in str(info.value) and ".dae" in str(info.value)
    assert info.value.extra == "viz"
