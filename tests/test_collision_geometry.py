# SPDX-License-Identifier: Apache-2.0
"""Collision geometry (hulls, capsules, primitives), pair distances, gradients and broad phase."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget.collision import (
    CollisionModel,
    fit_capsule,
    link_shapes,
    obstacle_shape,
    pair_distances,
    primitive_points,
)
from qpretarget.errors import ConfigError, UnknownNameError
from qpretarget.robot import RobotModel, RobotState


@pytest.fixture(scope="module")
def g1() -> RobotModel:
    return RobotModel.from_name("g1")


@pytest.fixture(scope="module")
def workload(shared_dir):
    bench = shared_dir / "bench"
    wl = yaml.safe_load((bench / "workload_g1.yaml").read_text())
    return wl, np.load(bench / wl["targets_file"])


def test_every_link_gets_one_convex_shape(g1):
    shapes = link_shapes(g1)
    gmodel, _ = g1.geometry()
    links = {g1.model.frames[o.parentFrame].name for o in gmodel.geometryObjects}
    assert set(shapes) == links
    # G1's ankle-roll links carry four spheres: merged into one hull; the shoulder cylinders stay.
    assert shapes["left_ankle_roll_link"].kind == "convex_hull"
    assert len(shapes["left_ankle_roll_link"].sources) == 4
    assert shapes["left_shoulder_pitch_link"].kind == "cylinder"
    # Hulls are far smaller than the meshes (the point of building them).
    assert 0 < shapes["torso_link"].n_vertices < 2000


def test_hull_distances_equal_the_workload_reference(g1, workload):
    # The workload's ref_pair_distance was computed on Convex.convexHull(points, False, "Qt")
    # hulls of the same meshes; GJK's tolerance (1e-6 by default) bounds the difference.
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    cm = CollisionModel(g1, pairs, broad_phase=False)
    state = RobotState(g1)
    for k in range(0, 1001, 50):
        state.update(tg["q_ref"][k])
        d = cm.compute_all(state)[0]
        np.testing.assert_allclose(d, tg["ref_pair_distance"][k], atol=1e-5)


def test_witness_points_and_normals_are_consistent(g1, workload):
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    d, pa, pb, n = pair_distances(g1, tg["q_ref"][400], pairs)
    assert pa.shape == pb.shape == n.shape == (len(pairs), 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)  # unit normals
    np.testing.assert_allclose(pb - pa, d[:, None] * n, atol=1e-9)  # p_b - p_a = d n


def test_capsules_are_conservative(g1, workload):
    # A bounding capsule contains its hull, so capsule distances are never larger (1e-6: GJK).
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    hull = CollisionModel(g1, pairs, broad_phase=False)
    caps = CollisionModel(g1, pairs, geometry="capsule", broad_phase=False)
    state = RobotState(g1)
    for k in (0, 250, 500, 750):
        state.update(tg["q_ref"][k])
        assert np.all(caps.compute_all(state)[0] <= hull.compute_all(state)[0] + 1e-6)


def test_fit_capsule_contains_every_point():
    rng = np.random.default_rng(1)
    for scale in ([0.3, 0.05, 0.04], [0.05, 0.05, 0.05], [0.2, 0.2, 0.01]):
        pts = rng.standard_normal((500, 3)) * scale + rng.standard_normal(3)
        cap, M = fit_capsule(pts)
        local = (pts - M.translation) @ M.rotation
        z = np.clip(local[:, 2], -cap.halfLength, cap.halfLength)
        dist = np.linalg.norm(local - np.c_[np.zeros((len(z), 2)), z], axis=1)
        assert np.all(dist <= cap.radius + 1e-12)  # inside, up to rounding


@pytest.mark.parametrize(
    "geom",
    [coal.Sphere(0.1), coal.Box(0.1, 0.2, 0.3), coal.Cylinder(0.05, 0.3),
     coal.Capsule(0.04, 0.2), coal.Ellipsoid(0.1, 0.05, 0.2), coal.Cone(0.1, 0.2)],
)  # fmt: skip
def test_primitive_point_sets_contain_the_primitive(geom):
    # The hull of the point set must contain the primitive: its support in every direction is
    # at least the primitive's (computed by coal's distance to a far plane). 1e-9: rounding.
    hull = coal.Convex.convexHull(_vec3s(primitive_points(geom)), False, "Qt")
    rng = np.random.default_rng(2)
    req = coal.DistanceRequest()
    for u in rng.standard_normal((50, 3)):
        u /= np.linalg.norm(u)
        plane = coal.Halfspace(-u, -10.0)  # solid {x : u'x >= 10}
        # A fresh DistanceResult per call: a result keeps the smallest distance it has seen.
        d_prim = coal.distance(
            geom, coal.Transform3s(), plane, coal.Transform3s(), req, coal.DistanceResult()
        )
        d_hull = coal.distance(
            hull, coal.Transform3s(), plane, coal.Transform3s(), req, coal.DistanceResult()
        )
        assert d_hull <= d_prim + 1e-9
        assert d_hull > d_prim - 0.35 * max(d_prim, 10.0 - d_prim)  # and not absurdly loose


def _vec3s(points):
    out = coal.StdVec_Vec3s()
    out.extend(list(points))
    return out


def test_distance_gradient_matches_finite_differences(g1, workload):
    # d(q + h dv) - d(q) = h grad . dv + O(h^2). GJK's default tolerance (1e-6 m) would swamp a
    # 1e-6 step, so this test tightens it to 1e-12; tolerance 2e-5 per unit |dv| covers the
    # O(h) curvature term (observed ~1.5e-6).
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    cm = CollisionModel(g1, pairs, broad_phase=False)
    for req in cm.gdata.distanceRequests:
        req.gjk_tolerance = 1e-12
    state = RobotState(g1)
    q0 = tg["q_ref"][500]
    state.update(q0)
    cm.update(state, 1.0)
    act = cm.active.copy()
    assert act.size >= 10
    G = cm.gradients(state)
    d0 = cm.distances[act].copy()
    rng = np.random.default_rng(0)
    h = 1e-6
    for _ in range(3):
        dv = rng.standard_normal(g1.nv)
        state.update(pin.integrate(g1.model, q0, h * dv))
        d1 = cm.update(state, 1.0)[act]
        np.testing.assert_allclose((d1 - d0) / h, G @ dv, atol=2e-5 * np.linalg.norm(dv))


def test_lighter_hulls_are_conservative(g1, workload):
    # Lighter hulls (128 vertices + swept-sphere inflation) contain the exact hulls: their
    # distances are never larger (1e-6: GJK tolerance) and lose at most 2 inflations.
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    exact = CollisionModel(g1, pairs, broad_phase=False)
    light = CollisionModel(g1, pairs, broad_phase=False, hull_vertices=128)
    slack = np.array(
        [light.shapes[light.bodies.index(a)].inflation + light.shapes[light.bodies.index(b)].inflation
         for a, b in pairs]
    )  # fmt: skip
    assert all(s.n_vertices <= 128 for s in light.shapes)
    state = RobotState(g1)
    for k in (0, 300, 600, 900):
        state.update(tg["q_ref"][k])
        d0, d1 = exact.compute_all(state)[0], light.compute_all(state)[0]
        assert np.all(d1 <= d0 + 1e-6)
        assert np.all(d1 >= d0 - slack - 1e-6)


def test_broad_phase_is_conservative(g1, workload):
    # Along the workload's reference, every skipped pair has a lower bound below its exact
    # distance, and every pair closer than the influence distance is computed exactly.
    wl, tg = workload
    pairs = [tuple(p) for p in wl["collision"]["pairs"]]
    cm = CollisionModel(g1, pairs)
    exact = CollisionModel(g1, pairs, broad_phase=False)
    state = RobotState(g1)
    influence = 0.1
    skipped = 0
    for k in range(0, 1001, 2):
        state.update(tg["q_ref"][k])
        d = cm.update(state, influence).copy()
        ref = exact.compute_all(state)[0]
        assert np.all(d[~cm.exact] <= ref[~cm.exact] + 1e-12)
        np.testing.assert_allclose(d[cm.exact], ref[cm.exact], atol=1e-5)  # GJK tolerance
        assert set(np.flatnonzero(ref < influence - 1e-5)) <= set(cm.active.tolist())
        skipped += int((~cm.exact).sum())
    assert skipped > 0  # the broad phase did skip pairs


def test_obstacles_and_ground_distance(g1):
    sphere = obstacle_shape({"name": "ball", "shape": "sphere", "radius": 0.1,
                             "position": [2.0, 0.0, 0.5]}, g1.model)  # fmt: skip
    ground = obstacle_shape(
        {"name": "floor", "shape": "halfspace", "normal": [0, 0, 1], "offset": -0.5}, g1.model
    )
    cm = CollisionModel(
        g1, [("torso_link", "ball"), ("left_knee_link", "floor")], obstacles=[sphere, ground],
        broad_phase=False,
    )  # fmt: skip
    state = RobotState(g1)
    d, pa, pb, n = cm.compute_all(state)
    # Knee above a floor at z = -0.5: the distance is the height of its lowest point + 0.5.
    assert d[1] == pytest.approx(pa[1, 2] + 0.5, abs=1e-9)
    np.testing.assert_allclose(n[1], [0, 0, -1], atol=1e-9)
    assert 1.5 < d[0] < 2.0  # torso near the origin, ball 2 m ahead


def test_bad_names_and_obstacles_are_reported(g1):
    with pytest.raises(UnknownNameError, match="torso_link"):
        CollisionModel(g1, [("torso_lnk", "pelvis_contour_link")])
    with pytest.raises(ConfigError, match="needs `radius`"):
        obstacle_shape({"name": "b", "shape": "sphere", "position": [0, 0, 0]}, g1.model)
    with pytest.raises(ConfigError, match="shape must be sphere, box"):
        obstacle_shape({"name": "b", "shape": "torus"}, g1.model)
    with pytest.raises(ConfigError, match="unknown key"):
        obstacle_shape({"name": "b", "shape": "sphere", "radius": 1, "colour": "red"}, g1.model)
    with pytest.raises(ConfigError, match="geometry must be one of"):
        link_shapes(g1, "mesh")
