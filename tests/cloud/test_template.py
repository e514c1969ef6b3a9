# SPDX-License-Identifier: Apache-2.0
"""HUMROB template: sampling, Jacobians (against finite differences), M-step sums, scales."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.cloud.template import Template, skew_batch


@pytest.fixture(scope="module")
def posture(g1) -> np.ndarray:
    rng = np.random.default_rng(0)
    q = g1.q_reference.copy()
    q[7:] += rng.normal(0.0, 0.3, g1.nv - 6)
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.2, -0.3, 0.5)).coeffs()
    return q


@pytest.fixture(scope="module")
def small(g1, g1_meshes) -> dict[str, Template]:
    return {
        sk: Template(g1, n_points=600, meshes=g1_meshes, skinning=sk, blend_radius=0.05)
        for sk in ("rigid", "lbs")
    }


def test_sampling(g1_template, g1, g1_meshes):
    from scipy.spatial import cKDTree

    from qpretarget.cloud.render import kinect_camera, render_cloud

    T = g1_template
    assert T.n_points == 5000
    assert T.segment_names == (
        "pelvis", "torso", "upper_arm", "forearm", "hand", "thigh", "shank", "foot",
    )  # fmt: skip
    P = T.pose(g1.q_reference, jacobians=False)
    assert np.allclose(np.linalg.norm(P.normals, axis=1), 1.0)
    # Points on the outer surface with outward normals: compared with a clean render from the
    # front, the template point nearest each seen pixel (within 1.5 cm, about the spacing) has a normal within 90 deg
    # of the true surface normal for 90 % of the pixels (edges and small parts make the rest).
    data = g1.model.createData()
    pin.forwardKinematics(g1.model, data, g1.q_reference)
    out = render_cloud(g1_meshes, data, kinect_camera([2.0, 0.3, 0.9], [0.0, 0.0, 0.7]))
    dist, nb = cKDTree(P.points).query(out["clean"])
    near = dist < 0.015
    agree = np.einsum("ka,ka->k", P.normals[nb[near]], out["normals"][near]) > 0
    assert near.mean() > 0.9 and agree.mean() > 0.9
    # Every link with geometry carries points; the small distal ones too.
    assert len(np.unique(T.link)) >= 30
    hand = T.meshes.link_names.index("left_rubber_hand")
    assert np.sum(T.link == hand) >= 40


@pytest.mark.parametrize("skinning", ["rigid", "lbs"])
def test_point_jacobians_match_finite_differences(small, posture, skinning):
    T = small[skinning]
    T.set_scales(np.linspace(0.8, 1.4, len(T.segment_names)))
    P = T.pose(posture)
    J = T.point_jacobians(P, T.joint_jacobians())
    eps = 1e-6
    fd = np.empty_like(J)
    for k in range(T.model.nv):
        dv = np.zeros(T.model.nv)
        dv[k] = eps
        fd[:, :, k] = (
            T.pose(pin.integrate(T.model, posture, dv), jacobians=False).points - P.points
        ) / eps
    # Forward differences of step 1e-6 on metre-sized lever arms: error ~1e-6 m/rad.
    assert np.abs(fd - J).max() < 5e-6
    if skinning == "lbs":
        assert len(T.blend) > 0


@pytest.mark.parametrize("skinning", ["rigid", "lbs"])
def test_normal_equations_equal_explicit_sums(small, posture, skinning):
    T = small[skinning]
    rng = np.random.default_rng(1)
    P = T.pose(posture)
    J6 = T.joint_jacobians()
    P1, E, En = (
        rng.random(T.n_points),
        rng.normal(size=(T.n_points, 3)),
        rng.normal(size=(T.n_points, 3)),
    )
    H, b = T.normal_equations(P, J6, P1, E, normal_weight=0.7, P1n=P1, En=En)
    Jm = T.point_jacobians(P, J6)
    Jn = -np.einsum("mab,mbn->man", skew_batch(P.normals), J6[T._group, 3:])
    H2 = np.einsum("man,m,mak->nk", Jm, P1, Jm) + 0.7 * np.einsum("man,m,mak->nk", Jn, P1, Jn)
    b2 = np.einsum("man,ma->n", Jm, E) + 0.7 * np.einsum("man,ma->n", Jn, En)
    # The 6x6 moment form is the same sum reordered: round-off only (1e-10 relative).
    assert np.allclose(H, H2, rtol=1e-10, atol=1e-10 * np.abs(H2).max())
    assert np.allclose(b, b2, rtol=1e-10, atol=1e-10 * np.abs(b2).max())


def test_scale_jacobian_and_scaled_kinematics(small, posture):
    T = small["rigid"]
    s0 = np.linspace(0.8, 1.4, len(T.segment_names))
    T.set_scales(s0)
    P = T.pose(posture, jacobians=False)
    Js = T.scale_jacobian(P)
    # Points are linear in the scales at fixed pose: a unit step is exact (round-off only).
    for k in range(len(s0)):
        s1 = s0.copy()
        s1[k] += 1.0
        T.set_scales(s1)
        assert np.allclose(
            T.pose(posture, jacobians=False).points - P.points, Js[:, :, k], atol=1e-10
        )
    T.set_scales(np.full(len(s0), 2.0))
    # Doubling every segment doubles the robot about its root.
    P2 = T.pose(posture, jacobians=False)
    T.set_scales(np.ones(len(s0)))
    P1 = T.pose(posture, jacobians=False)
    root = posture[:3]
    assert np.allclose(P2.points - root, 2.0 * (P1.points - root), atol=1e-12)
