# SPDX-License-Identifier: Apache-2.0
"""Point-cloud input: depth back-projection, file layouts, cropping, voxels, normals."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.cloud.io import (
    CloudFormatError,
    CloudFrame,
    CloudSequence,
    PinholeIntrinsics,
    crop,
    depth_normals,
    depth_to_points,
    estimate_normals,
    prepare_cloud,
    read_cloud_sequence,
    read_ply,
    voxel_downsample,
    write_ply,
)
from qpretarget.cloud.render import look_at

INTR = PinholeIntrinsics(fx=100.0, fy=110.0, cx=31.5, cy=23.5, width=64, height=48)


def test_depth_back_projection_inverts_the_pinhole_projection():
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 3.0, (48, 64))
    depth[5, 7] = np.nan  # invalid pixels are skipped
    depth[6, 8] = 0.0
    pts, pix = depth_to_points(depth, INTR, return_pixels=True)
    assert len(pts) == 48 * 64 - 2
    v, u = np.divmod(pix, 64)
    # Re-projecting gives the pixel centres back (float64 round-off: 1e-9 px).
    assert np.allclose(INTR.fx * pts[:, 0] / pts[:, 2] + INTR.cx, u, atol=1e-9)
    assert np.allclose(INTR.fy * pts[:, 1] / pts[:, 2] + INTR.cy, v, atol=1e-9)
    assert np.allclose(pts[:, 2], depth.reshape(-1)[pix])


def test_camera_pose_moves_points_to_the_world():
    pose = look_at([2.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    depth = np.full((48, 64), 2.0)  # a wall 2 m in front of the camera
    pts = depth_to_points(depth, INTR, pose)
    # The camera looks along -x from x = 2: the wall is the plane x = 0 (exact to 1e-12 m).
    assert np.allclose(pts[:, 0], 0.0, atol=1e-12)
    n = depth_normals(depth, INTR, pose)
    inner = n[1:-1, 1:-1].reshape(-1, 3)
    assert np.allclose(inner, [1.0, 0.0, 0.0], atol=1e-9)  # facing the camera


def test_ply_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    p = rng.normal(size=(50, 3))
    n = rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    write_ply(tmp_path / "a.ply", p, n)
    p2, n2 = read_ply(tmp_path / "a.ply")
    assert np.allclose(p, p2, atol=1e-6) and np.allclose(n, n2, atol=1e-6)  # float32 storage
    ascii_text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
    ascii_text += "property float z\nend_header\n0 1 2\n3 4 5\n"
    (tmp_path / "b.ply").write_text(ascii_text)
    p3, n3 = read_ply(tmp_path / "b.ply")
    assert np.array_equal(p3, [[0, 1, 2], [3, 4, 5]]) and n3 is None
    seq = read_cloud_sequence(tmp_path / "b.ply")
    assert len(seq) == 1


def test_npz_sequence_round_trip_and_layouts(tmp_path):
    frames = [CloudFrame(np.full((k + 3, 3), float(k)), None, 0.1 * k) for k in range(4)]
    CloudSequence(frames, sensor_position=np.array([1.0, 2.0, 3.0])).save(tmp_path / "s.npz")
    seq = read_cloud_sequence(tmp_path / "s.npz")
    assert [len(f.points) for f in seq] == [3, 4, 5, 6]
    assert np.allclose(seq.t, [0.0, 0.1, 0.2, 0.3]) and np.allclose(seq.sensor_position, [1, 2, 3])
    # (T, N, 3) stack padded with NaN rows, times from the rate.
    stack = np.full((2, 5, 3), np.nan)
    stack[0, :3] = 1.0
    stack[1, :5] = 2.0
    np.save(tmp_path / "s.npy", stack)
    seq = read_cloud_sequence(tmp_path / "s.npy", rate=10.0)
    assert [len(f.points) for f in seq] == [3, 5] and np.allclose(seq.t, [0.0, 0.1])
    # Depth images with intrinsics.
    np.savez(tmp_path / "d.npz", depth=np.full((2, 48, 64), 1500, np.uint16), depth_scale=0.001,
             intrinsics=[100.0, 110.0, 31.5, 23.5], rate=30.0)  # fmt: skip
    seq = read_cloud_sequence(tmp_path / "d.npz")
    assert len(seq) == 2 and np.allclose(seq.frames[0].points[:, 2], 1.5)


def test_bad_inputs_say_what_to_do(tmp_path):
    np.save(tmp_path / "s.npy", np.zeros((3, 4, 3)))
    with pytest.raises(CloudFormatError, match="frame rate"):
        read_cloud_sequence(tmp_path / "s.npy")
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(CloudFormatError, match="unsupported"):
        read_cloud_sequence(tmp_path / "x.txt")
    np.savez(tmp_path / "d.npz", depth=np.ones((1, 4, 4)))
    with pytest.raises(CloudFormatError, match="intrinsics"):
        read_cloud_sequence(tmp_path / "d.npz")
    with pytest.raises(CloudFormatError, match="does not exist"):
        read_cloud_sequence(tmp_path / "missing.npz")


def test_crop_voxels_and_subsampling():
    rng = np.random.default_rng(2)
    p = rng.uniform(-1, 1, (20000, 3))
    inside = crop(p, [-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])
    assert np.all(np.abs(p[inside]) <= 0.5) and np.all(np.any(np.abs(p[~inside]) > 0.5, axis=1))
    v, _ = voxel_downsample(p, 0.5)
    assert len(v) == 64  # 4 x 4 x 4 voxels of 0.5 m in the 2 m cube, all occupied
    # Each voxel's point is the mean of its points: inside its voxel.
    key = np.floor(v / 0.5)
    assert len(np.unique(key, axis=0)) == 64
    s, _ = prepare_cloud(p, box_min=[-0.5] * 3, box_max=[0.5] * 3, voxel=0.01, max_points=2500)
    assert len(s) == 2500 and np.all(np.abs(s) <= 0.5)


def test_estimated_normals_face_the_sensor():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1, 1, (2000, 2))
    plane = np.column_stack([xy, 0.002 * rng.normal(size=2000)])  # z = 0 with 2 mm noise
    n = estimate_normals(plane, viewpoint=np.array([0.0, 0.0, 3.0]), k=12)
    # Within 10 deg of +z for 99 % of the points (PCA of 12 neighbours, 2 mm noise).
    assert np.mean(n[:, 2] > np.cos(np.deg2rad(10))) > 0.99


def test_estimated_normals_are_the_pca_of_the_neighbours():
    """The vectorised scatter matrices and closed-form eigenvectors equal numpy's PCA.

    Reference: each point's 10 nearest neighbours, covariance by matrix product, eigh's
    smallest eigenvector; same neighbours, the sums in another order: 1e-9 (sign aligned).
    """
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(5)
    p = rng.normal(size=(800, 3)) * [0.3, 0.2, 0.02]  # a noisy slab: well-defined normals
    eye = np.array([0.0, 0.0, 2.0])
    n = estimate_normals(p, viewpoint=eye, k=10)
    _, idx = cKDTree(p).query(p, k=10)
    X = p[idx] - p[idx].mean(axis=1, keepdims=True)
    ref = np.linalg.eigh(np.matmul(X.transpose(0, 2, 1), X))[1][:, :, 0]
    ref[np.einsum("na,na->n", ref, eye - p) < 0] *= -1
    assert np.allclose(n, ref, atol=1e-9)
