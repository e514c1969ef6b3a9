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


def test_joint_centre_offsets(g1, g1_meshes, posture):
    """Moving articulation centres keeps the surface at the rest pose; Jacobian and sums exact."""
    T = Template(g1, n_points=600, meshes=g1_meshes)
    names = [[T.model.names[int(j)] for j in g] for g in T.articulations]
    assert ["left_shoulder_pitch_joint", "left_shoulder_roll_joint"] in names
    assert ["left_elbow_joint"] in names and ["left_knee_joint"] in names
    rng = np.random.default_rng(3)
    T.set_scales(rng.uniform(0.9, 1.4, len(T.scales)))
    rest = posture.copy()
    T.set_centre_rest(rest)
    before = T.pose(rest, jacobians=False).points
    x = rng.normal(0.0, 0.05, (T.n_centres, 3))
    T.set_centres(x)
    assert np.allclose(T.centres(), x)
    assert np.abs(T.pose(rest, jacobians=False).points - before).max() < 1e-12
    # Limb axes: unit, the elbow's points from the elbow to the wrist.
    axes, inner = T.limb_axes()
    assert np.allclose(np.linalg.norm(axes, axis=1), 1.0)
    assert not inner[names.index(["left_wrist_pitch_joint", "left_wrist_yaw_joint"])]
    a = names.index(["left_elbow_joint"])
    assert inner[a]
    q = g1.q_reference.copy()
    q[7:] += rng.normal(0.0, 0.4, g1.nv - 6)
    posed = T.pose(q)
    D = T.centre_jacobian_blocks(posed)[T._group]
    h = 1e-6
    for c in rng.choice(3 * T.n_centres, size=8, replace=False):
        xx = x.reshape(-1).copy()
        xx[c] += h
        T.set_centres(xx)
        num = (T.pose(q, jacobians=False).points - posed.points) / h
        assert np.abs(num - D[:, :, c]).max() < 1e-6
    T.set_centres(x)
    P1 = rng.uniform(0.0, 1.0, T.n_points)
    E = rng.normal(size=(T.n_points, 3))
    posed = T.pose(q)
    J6 = T.joint_jacobians()
    Hqe, Hee, be = T.centre_normal_equations(posed, J6, P1, E)
    Jm = T.point_jacobians(posed, J6)
    assert np.allclose(Hqe, np.einsum("m,man,mac->nc", P1, Jm, D), atol=1e-9)
    assert np.allclose(Hee, np.einsum("m,mac,mad->cd", P1, D, D), atol=1e-9)
    assert np.allclose(be, np.einsum("mac,ma->c", D, E), atol=1e-9)


def test_limb_surfaces_cut_at_moved_centres(g1, g1_meshes):
    """``assign_by_centres``: after moving the elbows down the arm (as a person's sit, 8-9 cm
    below G1's), the points between G1's link boundary and the moved elbow belong to the upper
    arm; the surface stays where it is at the rest pose (1e-12 m: the same positions and
    normals re-expressed in another joint's frame), and a bent elbow moves only the points
    beyond the moved centre.
    """
    T = Template(g1, n_points=2000, meshes=g1_meshes)
    q = g1.q_reference.copy()
    T.set_centre_rest(q)
    names = [[T.model.names[int(j)] for j in g] for g in T.articulations]
    axes, _ = T.limb_axes()
    x = np.zeros((T.n_centres, 3))
    for side in ("left", "right"):
        a = names.index([f"{side}_elbow_joint"])
        x[a] = 0.08 * axes[a]  # 8 cm down the arm
    T.set_centres(x)
    rest = T.pose(q, jacobians=False)
    moved = T.assign_by_centres(q, reach=0.15)
    assert moved > 20, moved
    after = T.pose(q, jacobians=False)
    # Same surface as a set (the points are re-sorted by joint).
    key = np.lexsort(rest.points.T)
    key2 = np.lexsort(after.points.T)
    assert np.abs(rest.points[key] - after.points[key2]).max() < 1e-12
    assert np.abs(rest.normals[key] - after.normals[key2]).max() < 1e-12
    for side in ("left", "right"):
        elbow = T.model.getJointId(f"{side}_elbow_joint")
        shoulder = T.model.getJointId(f"{side}_shoulder_roll_joint")
        u = after.p[elbow] - after.p[shoulder]
        u /= np.linalg.norm(u)
        s = (after.points - after.p[elbow]) @ u
        near = np.linalg.norm(after.points - after.p[elbow], axis=1) < 0.1
        upper = T.seg_of_joint[T.joint] == T.seg_of_joint[T.model.parents[elbow]]
        fore = T.seg_of_joint[T.joint] == T.seg_of_joint[elbow]
        # Every point near the elbow is on its segment's side of the moved centre.
        assert np.all(s[near & upper] <= 1e-9) and np.all(s[near & fore] >= -1e-9)
        assert (near & upper).sum() > 0 and (near & fore).sum() > 0
        # Bending the elbow moves the forearm's points only.
        qb = q.copy()
        qb[T.model.joints[elbow].idx_q] += 0.5
        bent = T.pose(qb, jacobians=False)
        still = np.linalg.norm(bent.points - after.points, axis=1) < 1e-12
        assert np.all(still[near & upper]) and not np.any(still[near & fore & (s > 0.01)])
    # Nothing moved: nothing to cut (a second call finds every point on its side).
    assert T.assign_by_centres(q, reach=0.15) == 0


def test_posing_a_subset_is_the_same_rows(g1_template, posture):
    """A frame poses only its visible points (``index``): the same rows, the same M-step sums.

    Rows are computed by the same operations: equal to round-off (1e-15 m). The normal
    equations of the subset equal those of the whole template with zero weight elsewhere
    (the zero rows add nothing): 1e-12 relative.
    """
    T = g1_template
    rng = np.random.default_rng(4)
    idx = np.sort(rng.choice(T.n_points, size=T.n_points // 3, replace=False))
    full = T.pose(posture)
    J6 = T.joint_jacobians()
    sub = T.pose(posture, index=idx)
    assert np.allclose(sub.points, full.points[idx], atol=1e-15, rtol=0)
    assert np.allclose(sub.normals, full.normals[idx], atol=1e-15, rtol=0)
    assert np.allclose(sub.offsets, full.offsets[idx], atol=1e-15, rtol=0)
    assert T.pose(posture, index=idx, normals=False).normals.shape == (0, 3)
    P1 = np.zeros(T.n_points)
    E, En = np.zeros((T.n_points, 3)), np.zeros((T.n_points, 3))
    P1[idx] = rng.random(len(idx))
    E[idx] = rng.normal(size=(len(idx), 3))
    En[idx] = rng.normal(size=(len(idx), 3))
    H, b = T.normal_equations(full, J6, P1, E, normal_weight=0.5, P1n=P1, En=En)
    Hs, bs = T.normal_equations(
        sub, J6, P1[idx], E[idx], normal_weight=0.5, P1n=P1[idx], En=En[idx]
    )
    assert np.allclose(Hs, H, rtol=1e-12, atol=1e-12 * np.abs(H).max())
    assert np.allclose(bs, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
    Hqe, Hee, be = T.centre_normal_equations(full, J6, P1, E)
    Hqe_s, Hee_s, be_s = T.centre_normal_equations(sub, J6, P1[idx], E[idx])
    for a, c in ((Hqe_s, Hqe), (Hee_s, Hee), (be_s, be)):
        assert np.allclose(a, c, rtol=1e-12, atol=1e-12 * max(np.abs(c).max(), 1e-300))


def _facing(posed, eye: np.ndarray) -> np.ndarray:
    """Template points whose normals face a sensor at ``eye`` (the back-face test of the fit)."""
    return np.einsum("ma,ma->m", posed.normals, posed.points - eye) < 0.0


def test_personalize_more_takes_the_newly_seen_surface(g1, g1_meshes):
    """Online personalisation (``Template.personalize_more``): after the front view made the
    front the subject's own surface, a view from behind replaces the robot's points it sees by
    the cloud's, attached to their joints; the front's points stay as they were. Exact
    bookkeeping (counts, flags, distances) and the new points posed exactly where the cloud's
    are (1e-9 m: a rigid attachment evaluated at the pose it was taken at)."""
    from qpretarget.cloud.render import kinect_camera, render_cloud

    T = Template(g1, n_points=1500, meshes=g1_meshes, link_density_exponent=0.5)
    q = g1.q_reference.copy()
    data = g1.model.createData()
    pin.forwardKinematics(g1.model, data, q)
    front = kinect_camera([1.8, 0.0, 1.0], [0.0, 0.0, 0.65], downscale=2)
    back = kinect_camera([-1.8, 0.0, 1.0], [0.0, 0.0, 0.65], downscale=2)
    clouds = [
        render_cloud(g1_meshes, data, cam, noise=0.0, rng=np.random.default_rng(k))
        for k, cam in enumerate((front, back))
    ]
    n_front = T.personalize(
        q,
        clouds[0]["points"],
        clouds[0]["normals"],
        ~_facing(T.pose(q), front.position),
        max_distance=0.025,
    )
    assert n_front > 0 and T.observed.sum() == n_front
    before = T.pose(q).points[T.observed].copy()
    seen = _facing(T.pose(q), back.position)
    # The back is still the robot's (some of the front's points at the silhouette face back).
    assert (seen & ~T.observed).sum() > 0.7 * seen.sum() > 0  # measured 0.79
    P, N = clouds[1]["points"], clouds[1]["normals"]
    n_back = T.personalize_more(q, P, N, seen, max_distance=0.025)
    assert n_back > 0
    assert T.observed.sum() == n_front + n_back
    posed = T.pose(q)
    # The front's points are the same points (the order within a joint may change).
    kept = posed.points[T.observed]
    from scipy.spatial import cKDTree

    assert np.max(cKDTree(kept).query(before)[0]) < 1e-9
    # Every new point is one of the back cloud's points, on its joint's rigid frame.
    d_new = cKDTree(P).query(kept)[0]
    assert np.sum(d_new < 1e-9) == n_back
    # The robot's points left that the back sees have no new point within the distance.
    new = kept[d_new < 1e-9]
    left = ~T.observed & _facing(posed, back.position)
    if left.any():
        assert np.min(cKDTree(new).query(posed.points[left])[0]) > 0.025
    # Nothing in view that is still the robot's: nothing to take.
    assert T.personalize_more(q, P, N, np.zeros(T.n_points, bool), max_distance=0.025) == 0


def test_attach_rigidly_makes_a_segment_one_body(g1, g1_meshes):
    """``attach_rigidly``: the torso's points on G1's shoulder-pitch links ride with the torso.

    At the calibrated pose nothing moves (1e-9 m: a change of frames, round-off only); with the
    shoulders pitched those points stay where the torso carries them, where before they turned
    with the arms. A segment shared by both sides (``upper_arm``) keeps each side's points on
    its own side: every point goes to its own joint or an ancestor of it.
    """
    T = Template(g1, n_points=1500, meshes=g1_meshes, link_density_exponent=0.5, seed=3)
    model = T.model
    q0 = g1.q_reference.copy()
    pitched = q0.copy()
    for side in ("left", "right"):
        pitched[g1.joint_q_index[g1.joint_index(f"{side}_shoulder_pitch_joint")]] = -1.0
    torso = T.segment_names.index("torso")
    pitch = [model.getJointId(f"{s}_shoulder_pitch_joint") for s in ("left", "right")]
    on_pitch = np.isin(T.joint, pitch) & (T.point_segment == torso)
    assert on_pitch.sum() > 20  # the premise: G1's torso segment has shoulder-pitch points
    before = T.pose(q0, jacobians=False).points.copy()
    swung = T.pose(pitched, jacobians=False).points[on_pitch].copy()
    key = np.lexsort(before.T)  # the re-attachment reorders the points: compare as sets

    assert T.attach_rigidly(q0, [torso]) == on_pitch.sum()
    assert not np.isin(T.joint[T.point_segment == torso], pitch).any()
    after = T.pose(q0, jacobians=False).points
    assert np.abs(after[np.lexsort(after.T)] - before[key]).max() < 1e-9
    # Pitched arms: the former shoulder-pitch points are where the unpitched torso has them.
    waist = model.getJointId("waist_pitch_joint")
    moved = T.joint == waist
    rigid = T.pose(pitched, jacobians=False).points[moved]
    still = T.pose(q0, jacobians=False).points[moved]
    assert np.abs(rigid - still).max() < 1e-9  # the arms' pitch moves no torso point now
    assert np.abs(swung - before[on_pitch]).max() > 0.02  # ... where it moved them 2+ cm

    T2 = Template(g1, n_points=1500, meshes=g1_meshes, link_density_exponent=0.5, seed=3)
    count = {n: int((T2.joint == model.getJointId(n)).sum()) for n in model.names[1:]}
    T2.attach_rigidly(q0, [T2.segment_names.index("upper_arm")])
    for side in ("left", "right"):
        roll, yaw = (model.getJointId(f"{side}_shoulder_{n}_joint") for n in ("roll", "yaw"))
        assert count[f"{side}_shoulder_yaw_joint"] > 0
        assert not (T2.joint == yaw).any()
        assert (T2.joint == roll).sum() == (
            count[f"{side}_shoulder_roll_joint"] + count[f"{side}_shoulder_yaw_joint"]
        )


def test_limbs_as_tubes_centre_the_surface_on_the_joint_line(g1, g1_meshes):
    """``limbs_as_tubes``: each arm segment's surface becomes a tube about its joint-centre
    line (shoulder -> elbow, elbow -> wrist), so the points' principal axis is that line.

    G1's own upper-arm points are 2-6 deg off the line (the shoulder-roll housing stands off
    the arm's side); the tube's within 1 deg (its rings sample the circle evenly: the axis is
    exact up to the sampling of the radius profile). The point count and each point's segment
    and side stay; the points lie at the profile's radius, between 2 and 8 cm (G1's arms);
    a bent elbow moves the forearm's tube, not the upper arm's.
    """
    T = Template(g1, n_points=2000, meshes=g1_meshes, link_density_exponent=0.5)
    q = g1.q_reference.copy()
    model = T.model

    def axis_error(side: str, seg: str, a: str, b: str) -> float:
        posed = T.pose(q, jacobians=False)
        j0 = model.getJointId(f"{side}_{a}_joint")
        mine = (T.point_segment == T.segment_names.index(seg)) & (T._ancestors[T.joint, j0] > 0)
        X = posed.points[mine] - posed.points[mine].mean(0)
        v = np.linalg.eigh(X.T @ X)[1][:, -1]
        u = posed.p[model.getJointId(f"{side}_{b}_joint")] - posed.p[j0]
        return float(np.degrees(np.arccos(min(abs(v @ u) / np.linalg.norm(u), 1.0))))

    lines = [("upper_arm", "shoulder_roll", "elbow"), ("forearm", "elbow", "wrist_yaw")]
    before = {(s, seg): axis_error(s, seg, a, b) for s in ("left", "right") for seg, a, b in lines}
    count = {k: int((T.point_segment == T.segment_names.index(k)).sum()) for k in T.segment_names}
    arms = [T.segment_names.index("upper_arm"), T.segment_names.index("forearm")]
    replaced = T.limbs_as_tubes(q, arms)
    assert replaced > 0.8 * (count["upper_arm"] + count["forearm"])
    after = {(s, seg): axis_error(s, seg, a, b) for s in ("left", "right") for seg, a, b in lines}
    assert max(before[(s, "upper_arm")] for s in ("left", "right")) > 2.0, before
    assert max(after.values()) < 1.0, after
    for k in T.segment_names:  # as many points per segment, within the rings' rounding
        n = int((T.point_segment == T.segment_names.index(k)).sum())
        assert abs(n - count[k]) <= 0.1 * count[k] + 12, (k, n, count[k])
    posed = T.pose(q, jacobians=False)
    for side in ("left", "right"):
        sh = posed.p[model.getJointId(f"{side}_shoulder_roll_joint")]
        el = posed.p[model.getJointId(f"{side}_elbow_joint")]
        u = (el - sh) / np.linalg.norm(el - sh)
        mine = (T.point_segment == arms[0]) & (
            T._ancestors[T.joint, model.getJointId(f"{side}_shoulder_roll_joint")] > 0
        )
        d = posed.points[mine] - sh
        rho = np.linalg.norm(d - np.outer(d @ u, u), axis=1)
        assert 0.02 < rho.min() and rho.max() < 0.08, (rho.min(), rho.max())
        assert np.sign(posed.points[mine][:, 1].mean()) == (1 if side == "left" else -1)
    bent = q.copy()
    elbow = model.getJointId("left_elbow_joint")
    bent[model.joints[elbow].idx_q] += 0.5
    moved = np.linalg.norm(T.pose(bent, jacobians=False).points - posed.points, axis=1) > 1e-9
    upper_left = (T.point_segment == arms[0]) & (
        T._ancestors[T.joint, model.getJointId("left_shoulder_roll_joint")] > 0
    )
    fore_left = (T.point_segment == arms[1]) & (T._ancestors[T.joint, elbow] > 0)
    assert not moved[upper_left].any() and moved[fore_left].all()
