# SPDX-License-Identifier: Apache-2.0
r"""Synthetic depth images of posed link meshes: pinhole camera, z-buffer, sensor noise, outliers.

This is the test bench of the point-cloud retargeting (Wang 2017 V.A uses a Kinect V2): real meshes
from example-robot-data -- the robot posed by known joint angles, or the human model
``human_description`` posed by a mocap clip (:class:`HumanPoser`) -- rendered from a virtual
pinhole camera.

Rasterisation (:func:`rasterize`) is exact for triangles: a pixel belongs to a triangle when its
centre falls inside the projected triangle, and its depth is the intersection of the pixel ray
:math:`d = ((u - c_x)/f_x, (v - c_y)/f_y, 1)` with the triangle's plane,
:math:`z = (n^\top x_0) / (n^\top d)`. The nearest triangle wins (z-buffer), so a body occludes
itself. The work is vectorised over triangles, grouped by the size of their pixel bounding box.

Noise model (:func:`corrupt`): Gaussian noise of standard deviation ``noise`` [m] along each pixel
ray (the depth error of a time-of-flight sensor), then outliers drawn uniformly in a box around
the subject, so that they are a given fraction of the final cloud.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from .io import CloudFrame, CloudSequence, PinholeIntrinsics, depth_to_points
from .meshes import LinkMeshes, load_link_meshes
from .poser import (
    HUMAN_TO_Z_UP,
    HumanPoser,
    interpolation_peak_rate,
    progress_bar,
    trunk_orientations,
)

#: Triangles nearer than this to the camera plane are dropped [m].
NEAR = 0.05


@dataclass(frozen=True)
class Camera:
    """A pinhole camera placed in the world.

    Attributes:
        intrinsics: focal lengths, principal point and image size.
        pose: (4, 4) camera-to-world transform; camera axes x right, y down, z forward (OpenCV).
    """

    intrinsics: PinholeIntrinsics
    pose: np.ndarray

    @property
    def position(self) -> np.ndarray:
        """Optical centre in the world (3,)."""
        return self.pose[:3, 3].copy()


def look_at(
    eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0, 0, 1)
) -> np.ndarray:
    """Camera-to-world pose (4, 4) of a camera at ``eye`` looking at ``target`` (OpenCV axes)."""
    eye_w, target_w, up_w = (np.asarray(a, float) for a in (eye, target, up))
    z = target_w - eye_w
    z /= np.linalg.norm(z)
    x = np.cross(z, up_w)
    if np.linalg.norm(x) < 1e-9:
        raise ConfigError("look_at: the viewing direction is parallel to `up`.")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye_w
    return T


def kinect_camera(eye: Sequence[float], target: Sequence[float], *, downscale: int = 2) -> Camera:
    """A Kinect V2 depth camera (512 x 424, f = 365 px, Wang 2017 V.A), optionally downscaled."""
    s = float(downscale)
    intr = PinholeIntrinsics(
        fx=365.0 / s,
        fy=365.0 / s,
        cx=(512 / s - 1) / 2,
        cy=(424 / s - 1) / 2,
        width=int(512 // s),
        height=int(424 // s),
    )
    return Camera(intr, look_at(eye, target))


def _min3(a: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])


def _max3(a: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def rasterize(
    triangles_cam: np.ndarray, intrinsics: PinholeIntrinsics
) -> tuple[np.ndarray, np.ndarray]:
    """Z-buffer rendering of triangles given in the camera frame.

    Args:
        triangles_cam: (T, 3, 3) vertices in camera coordinates [m] (z forward).
        intrinsics: the camera's intrinsics.

    Returns:
        ``depth`` (H, W) [m], ``inf`` where nothing is seen, and ``index`` (H, W) of the visible
        triangle (-1 for none).
    """
    W, H = intrinsics.width, intrinsics.height
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    depth = np.full(H * W, np.inf)
    index = np.full(H * W, -1, dtype=np.int64)
    tri = np.asarray(triangles_cam, float)
    ids = np.flatnonzero(_min3(tri[:, :, 2]) > NEAR)
    tri = tri[ids]
    if len(tri) == 0:
        return depth.reshape(H, W), index.reshape(H, W)
    z = tri[:, :, 2]
    u = fx * tri[:, :, 0] / z + cx
    v = fy * tri[:, :, 1] / z + cy
    c0 = np.maximum(np.ceil(_min3(u)), 0).astype(np.int64)
    c1 = np.minimum(np.floor(_max3(u)), W - 1).astype(np.int64)
    r0 = np.maximum(np.ceil(_min3(v)), 0).astype(np.int64)
    r1 = np.minimum(np.floor(_max3(v)), H - 1).astype(np.int64)
    keep = (c1 >= c0) & (r1 >= r0)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nx0 = np.einsum("ka,ka->k", n, tri[:, 0])
    size = np.maximum(c1 - c0, r1 - r0) + 1
    hits: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    bucket = 1
    while True:
        sel = np.flatnonzero(keep & (size <= bucket) & (size > bucket // 2))
        if len(sel):
            oy, ox = np.divmod(np.arange(bucket * bucket), bucket)
            # Process in chunks to bound memory (candidates = triangles x bucket^2).
            chunk = max(1, 2_000_000 // (bucket * bucket))
            for s in range(0, len(sel), chunk):
                k = sel[s : s + chunk]
                cols = c0[k, None] + ox[None, :]
                rows = r0[k, None] + oy[None, :]
                inb = (cols <= c1[k, None]) & (rows <= r1[k, None])
                found = _pixel_hits(k, cols, rows, inb, u[k], v[k], n, nx0, intrinsics)
                if found is not None:
                    hits.append(found)
        if bucket >= max(W, H) or not np.any(keep & (size > bucket)):
            break
        bucket *= 2
    if hits:
        pix, zs, ts = (np.concatenate(a) for a in zip(*hits, strict=True))
        order = np.argsort(zs, kind="stable")
        upix, first = np.unique(pix[order], return_index=True)
        depth[upix] = zs[order][first]
        index[upix] = ids[ts[order][first]]
    return depth.reshape(H, W), index.reshape(H, W)


def _edge(
    ku: np.ndarray, kv: np.ndarray, i: int, j: int, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """Edge function of the projected edge ``i -> j`` at the pixel centres (sign: side)."""
    return (ku[:, j, None] - ku[:, i, None]) * (rows - kv[:, i, None]) - (
        kv[:, j, None] - kv[:, i, None]
    ) * (cols - ku[:, i, None])


def _pixel_hits(
    k: np.ndarray,
    cols: np.ndarray,
    rows: np.ndarray,
    inb: np.ndarray,
    ku: np.ndarray,
    kv: np.ndarray,
    n: np.ndarray,
    nx0: np.ndarray,
    intrinsics: PinholeIntrinsics,
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(pixel, depth, triangle)`` of the candidate pixels inside triangles ``k``.

    A pixel is inside when its centre is on the same side of the three edges; its depth is the
    pixel ray's intersection with the triangle's plane (module docstring). ``None``: no hit.
    """
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    e0 = _edge(ku, kv, 0, 1, rows, cols)
    e1 = _edge(ku, kv, 1, 2, rows, cols)
    e2 = _edge(ku, kv, 2, 0, rows, cols)
    inside = inb & (((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0)))
    kk, jj = np.nonzero(inside)
    if len(kk) == 0:
        return None
    cc, rr = cols[kk, jj], rows[kk, jj]
    tk = k[kk]
    dx, dy = (cc - cx) / fx, (rr - cy) / fy
    den = n[tk, 0] * dx + n[tk, 1] * dy + n[tk, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        zz = nx0[tk] / den
    ok = np.isfinite(zz) & (zz > NEAR)
    return rr[ok] * intrinsics.width + cc[ok], zz[ok], tk[ok]


def render_depth(
    meshes: LinkMeshes, data: pin.Data, camera: Camera, *, normals: bool = False
) -> tuple[np.ndarray, ...]:
    """Depth image and per-pixel link index of meshes posed by a kinematics pass ``data``.

    Returns:
        ``depth`` (H, W) [m] (``inf`` for background), ``link`` (H, W), the index into
        ``meshes.link_names`` of the visible link (-1 for background), and with ``normals`` the
        (H, W, 3) world unit normals of the visible triangles, facing the camera (0 elsewhere).
    """
    cam = meshes.posed(data, camera.pose)
    depth, tri = rasterize(cam, camera.intrinsics)
    hit = tri >= 0
    link = np.where(hit, meshes.link[np.maximum(tri, 0)], -1)
    if not normals:
        return depth, link
    t = cam[tri[hit]]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    n[np.einsum("ka,ka->k", n, t[:, 0]) > 0] *= -1  # face the camera (at the origin)
    out = np.zeros(depth.shape + (3,))
    out[hit] = n @ camera.pose[:3, :3].T
    return depth, link, out


def corrupt(
    points: np.ndarray,
    camera_position: np.ndarray,
    *,
    noise: float,
    outlier_fraction: float,
    rng: np.random.Generator,
    box_margin: float = 0.3,
) -> tuple[np.ndarray, np.ndarray]:
    """Add depth noise along the rays and uniform outliers to a world-frame cloud.

    Args:
        points: (N, 3) clean points [m].
        camera_position: optical centre (3,) [m]; noise is applied along the ray to each point.
        noise: standard deviation of the range noise [m] (Gaussian).
        outlier_fraction: fraction of the *returned* points that are outliers, in [0, 1).
        rng: random generator.
        box_margin: outliers are uniform in the points' bounding box grown by this margin [m].

    Returns:
        ``points`` (N + K, 3) and ``is_outlier`` (N + K,) booleans.
    """
    if not 0 <= outlier_fraction < 1:
        raise ConfigError(f"outlier_fraction must be in [0, 1), got {outlier_fraction!r}.")
    rays = points - camera_position
    rng_dist = np.linalg.norm(rays, axis=1, keepdims=True)
    noisy = camera_position + rays * (
        1.0 + rng.normal(0.0, noise, size=(len(points), 1)) / rng_dist
    )
    k = int(round(outlier_fraction / (1.0 - outlier_fraction) * len(points)))
    if k == 0:  # no outliers asked, or nothing in view (the person out of the image)
        return noisy, np.zeros(len(noisy), bool)
    lo, hi = points.min(axis=0) - box_margin, points.max(axis=0) + box_margin
    lo[2] = max(lo[2], points[:, 2].min())
    out = rng.uniform(lo, hi, size=(k, 3))
    return np.concatenate([noisy, out]), np.concatenate(
        [np.zeros(len(noisy), bool), np.ones(k, bool)]
    )


def render_cloud(
    meshes: LinkMeshes,
    data: pin.Data,
    camera: Camera,
    *,
    noise: float = 0.0,
    outlier_fraction: float = 0.0,
    rng: np.random.Generator | None = None,
) -> dict[str, np.ndarray]:
    """Render, back-project and corrupt: one synthetic sensor frame in world coordinates.

    Returns:
        ``{"points": (N, 3), "link": (N,) link index (-1 for outliers), "normals": (N, 3) true
        surface normals (0 for outliers), "clean": (N, 3) points before noise, "depth": (H, W)}``.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    depth, link, nimg = render_depth(meshes, data, camera, normals=True)
    pts, pix = depth_to_points(depth, camera.intrinsics, camera.pose, return_pixels=True)
    lab = link.reshape(-1)[pix]
    nrm = nimg.reshape(-1, 3)[pix]
    clean = pts.copy()
    if noise > 0 or outlier_fraction > 0:
        pts, is_out = corrupt(
            pts, camera.position, noise=noise, outlier_fraction=outlier_fraction, rng=rng
        )
        k = int(is_out.sum())
        lab = np.concatenate([lab, np.full(k, -1)])
        nrm = np.concatenate([nrm, np.zeros((k, 3))])
        clean = np.concatenate([clean, pts[len(clean) :]])
    return {"points": pts, "link": lab, "normals": nrm, "clean": clean, "depth": depth}


@dataclass
class SyntheticSequence:
    """Rendered frames with their ground truth.

    Attributes:
        sequence: the clouds (world frame, with the sensor position).
        q: (T, nq) configurations of the rendered model.
        link: per frame, (N,) index into ``meshes.link_names`` of each point (-1: outlier).
        normals: per frame, (N, 3) true surface normals (0 for outliers).
        clean: per frame, (N, 3) points before noise.
        meshes: the rendered meshes. camera: the camera.
        lead_in_frames: frames before the clip's first (:func:`human_clip_sequence`: the
            calibration posture and the move into the clip; 0 otherwise).
        camera_shift: how far [m] :func:`human_clip_sequence` moved the camera back from
            ``distance`` to keep a travelling person in view (0: not moved).
        limb_error_deg: per clip frame, the rendered person's largest limb-direction error
            against the clip (:attr:`HumanPoser.limb_error_deg`; None: not a clip).
    """

    sequence: CloudSequence
    q: np.ndarray
    link: list[np.ndarray]
    normals: list[np.ndarray]
    clean: list[np.ndarray]
    meshes: LinkMeshes
    camera: Camera
    lead_in_frames: int = 0
    camera_shift: float = 0.0
    limb_error_deg: np.ndarray | None = None

    def with_truth(self) -> CloudSequence:
        """The clouds with what ``make-cloud`` stores beside them.

        ``meta/human_q`` (the rendered configurations, the truth the arm-direction error
        scores against), ``meta/camera_position``, ``meta/lead_in_frames`` and, for a clip,
        ``meta/limb_error_deg`` (how faithfully the rendered person follows it, per clip frame).
        """
        seq = self.sequence
        seq.meta["human_q"] = self.q
        seq.meta["camera_position"] = np.asarray(self.camera.position, float)
        seq.meta["lead_in_frames"] = np.asarray(self.lead_in_frames)
        if self.limb_error_deg is not None:
            seq.meta["limb_error_deg"] = np.asarray(self.limb_error_deg, float)
        return seq


def render_sequence(
    model: pin.Model,
    meshes: LinkMeshes,
    q: np.ndarray,
    t: np.ndarray,
    camera: Camera,
    *,
    noise: float = 0.005,
    outlier_fraction: float = 0.05,
    seed: int = 0,
    progress: bool = False,
) -> SyntheticSequence:
    """Render configurations ``q`` (T, nq) at times ``t`` (T,) into a noisy cloud sequence.

    ``progress``: a progress bar on stderr.
    """
    rng = np.random.default_rng(seed)
    data = model.createData()
    frames, link, normals, clean = [], [], [], []
    bar = progress_bar(len(q), "rendering", progress)
    for k in range(len(q)):
        pin.forwardKinematics(model, data, q[k])
        out = render_cloud(
            meshes, data, camera, noise=noise, outlier_fraction=outlier_fraction, rng=rng
        )
        frames.append(CloudFrame(out["points"], None, float(t[k])))
        link.append(out["link"])
        normals.append(out["normals"])
        clean.append(out["clean"])
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    seq = CloudSequence(frames, sensor_position=camera.position, source="synthetic")
    return SyntheticSequence(seq, np.asarray(q, float), link, normals, clean, meshes, camera)


#: Half the width [m] of a person kept inside the image around the pelvis (:func:`camera_setback`).
BODY_HALF_WIDTH = 0.5


def camera_setback(camera: Camera, roots: np.ndarray, *, min_distance: float) -> float:
    r"""How far [m] to move ``camera`` back along its horizontal line of sight to keep a person.

    For each pelvis position :math:`r_k` (rows of ``roots``, world [m]), with :math:`f` the
    camera's horizontal viewing direction and :math:`\ell` its horizontal right axis, the
    depth :math:`d_k = (r_k - e)\cdot f` and the lateral offset
    :math:`l_k = (r_k - e)\cdot \ell` from the camera at :math:`e`. Moved back by
    :math:`s`, the depths become :math:`d_k + s`; the smallest :math:`s \ge 0` with

    .. math:: d_k + s \ge d_{min}, \qquad |l_k| + w \le (d_k + s) \tan\alpha \quad
        \forall k

    (:math:`\alpha` the image's horizontal half-angle, :math:`w` :data:`BODY_HALF_WIDTH`) is
    :math:`s = \max(0, \max_k (d_{min} - d_k), \max_k ((|l_k| + w)/\tan\alpha - d_k))`.
    A walk towards a camera 2.8 m away (CMU 16_15) otherwise passes through it after 2.5 s.
    """
    if not min_distance > 0:
        raise ConfigError(f"min_distance must be > 0 m, got {min_distance}.")
    R, e = camera.pose[:3, :3], camera.pose[:3, 3]
    f = R[:, 2].copy()
    f[2] = 0.0
    f /= max(float(np.linalg.norm(f)), 1e-12)
    right = np.array([-f[1], f[0], 0.0])
    rel = np.asarray(roots, float) - e
    d = rel @ f
    lat = np.abs(rel @ right)
    intr = camera.intrinsics
    tan_a = min(intr.cx, intr.width - intr.cx) / intr.fx
    need = max(float(np.max(min_distance - d)), float(np.max((lat + BODY_HALF_WIDTH) / tan_a - d)))
    return max(0.0, need)


def human_clip_sequence(
    keypoints: Mapping[str, np.ndarray],
    orientations: Mapping[str, np.ndarray],
    t: np.ndarray,
    *,
    calibration_frames: int = 4,
    lead_in_speed: float | None = None,
    arm_abduction: float = 0.5,
    distance: float = 2.8,
    min_distance: float = 2.0,
    noise: float = 0.005,
    outlier_fraction: float = 0.05,
    seed: int = 0,
    poser: HumanPoser | None = None,
    downscale: int = 2,
    ground_window: float = 1.0,
    progress: bool = False,
) -> tuple[SyntheticSequence, HumanPoser]:
    r"""The human model posed by a clip, rendered by a Kinect-like camera in front of it.

    The sequence starts with the calibration posture (standing upright facing the camera, arms
    abducted by ``arm_abduction`` [rad], feet centred where the clip's first frame has them,
    facing the clip's first heading), then ``calibration_frames`` frames moving into the
    clip's first pose (joint-space interpolation, linear in time), then the clip. With
    ``lead_in_speed`` the move goes at a person's pace instead: a minimum-jerk profile
    :math:`s(\tau) = 10\tau^3 - 15\tau^4 + 6\tau^5` (Flash & Hogan 1985),
    :math:`\tau = t / T`, :math:`\max s' = 1.875`, over :math:`T = 1.875\,G / v` with
    :math:`G` the fastest key-point's rate along the interpolation
    (:func:`interpolation_peak_rate`), so that no key-point (hands, feet, head...) moves
    faster than :math:`v =` ``lead_in_speed``; at least ``calibration_frames`` + 1 steps.
    The 4 frames of the default take a hand 0.3-1.2 m in 0.17 s on the shared clips (2-7
    m/s), a jump a person does not make; the docs' figures are measured on it
    (docs/point_clouds.md, *Fifteenth round*, for both). The
    person stands on the floor (z = 0): the calibration posture's lowest point is on it (and
    each frame's moving into the clip), and each clip frame is lowered or raised by the lowest
    point of the model within ``ground_window`` seconds around it (a jump shorter than half
    the window keeps its flight). The clip's root heights are the performer's, and the model's
    legs are not: placed at the clip's root height, a crouched boxer floated 18-24 cm above
    the floor.

    Args:
        keypoints: clip key-points, name -> (T, 3) [m], z up (``keypoint_positions(motion)``).
        orientations: ``waist``/``torso``/``head`` -> (T, 3, 3) (``keypoint_orientations()``).
        t: (T,) clip times [s].
        calibration_frames: frames moving from the calibration posture into the clip (the
            fewest with ``lead_in_speed``).
        lead_in_speed: None, or the peak speed [m/s] of the fastest key-point while moving
            into the clip (2: a brisk arm movement; an unhurried reach peaks at about 1 m/s).
        arm_abduction: shoulder abduction of the calibration posture [rad].
        distance: horizontal distance of the camera in front of the person [m].
        min_distance: the nearest [m] a travelling person comes to the camera: a clip that
            walks, jumps or kicks its way towards the camera, or out of its field of view,
            has the camera moved back along its line of sight until every frame's pelvis is
            this far in front of it and inside the image (:func:`camera_setback`). Clips
            that stay in view at this distance are rendered from ``distance``.
        noise: range noise [m].
        outlier_fraction: fraction of outliers in each cloud.
        seed: random seed.
        poser: an existing :class:`HumanPoser` (built otherwise).
        downscale: the Kinect V2 image (512 x 424) divided by this (2: about 2,300 points on
            the person at 2.8 m; 1: about 9,000).
        ground_window: the window [s] over which the lowest point of the model is put on the
            floor.
        progress: progress bars (posing, rendering) on stderr.
    """
    poser = poser if poser is not None else HumanPoser()
    h = poser.robot
    Q = poser.pose_sequence(keypoints, orientations, progress=progress)
    fwd = np.asarray(orientations["waist"][0], float)[:, 0].copy()
    fwd[2] = 0.0
    fwd /= np.linalg.norm(fwd)
    qa = pin.neutral(h.model)
    qa[:3] = Q[0][:3]
    yaw = np.arctan2(fwd[1], fwd[0])
    qa[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw) @ HUMAN_TO_Z_UP).coeffs()
    for side in ("left", "right"):
        qa[h.joint_q_index[h.joint_index(f"{side}_shoulder_X")]] = arm_abduction
    # The person calibrates standing where the clip starts: the feet's midpoint is the clip's
    # (a pelvis-centred stance would slide both feet up to 15 cm while moving into the clip).
    here, there = poser.model_keypoints(qa), poser.model_keypoints(Q[0])
    mid = [0.5 * (k["left_ankle"] + k["right_ankle"])[:2] for k in (here, there)]
    qa[:2] += mid[1] - mid[0]
    meshes = load_link_meshes(h.model, h.urdf_path)
    data = h.model.createData()

    def lowest(q: np.ndarray) -> float:
        pin.forwardKinematics(h.model, data, q)
        return float(meshes.posed(data)[..., 2].min())

    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / 30.0
    Q = np.array(Q, float)
    low = np.array([lowest(q) for q in Q])
    r = max(int(round(0.5 * float(ground_window) / dt)), 0)
    Q[:, 2] -= [low[max(0, i - r) : i + r + 1].min() for i in range(len(Q))]
    qa[2] -= lowest(qa)
    steps = int(calibration_frames) + 1
    if lead_in_speed is None:
        profile = np.linspace(0.0, 1.0, steps + 1)[:-1]
    else:
        if not lead_in_speed > 0:
            raise ConfigError(f"lead_in_speed must be > 0 m/s, got {lead_in_speed}.")
        rate = interpolation_peak_rate(poser, qa, Q[0])
        steps = max(steps, int(np.ceil(1.875 * rate / (float(lead_in_speed) * dt))))
        tau = np.arange(steps) / steps
        profile = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    lead = [pin.interpolate(h.model, qa, Q[0], float(a)) for a in profile]
    for q in lead[1:]:  # standing on the floor while moving into the clip
        q[2] -= lowest(q)
    Qall = np.array(lead + list(Q))
    times = np.concatenate([np.arange(len(lead)) * dt, t - t[0] + len(lead) * dt])
    w0 = np.asarray(keypoints["waist"][0], float).copy()
    w0[2] = 0.0
    eye, target = w0 + distance * fwd + [0.0, 0.0, 1.2], w0 + [0.0, 0.0, 0.9]
    camera = kinect_camera(eye, target, downscale=downscale)
    shift = camera_setback(camera, Qall[:, :3], min_distance=min_distance)
    if shift > 0.0:
        camera = kinect_camera(eye + shift * fwd, target + shift * fwd, downscale=downscale)
    syn = render_sequence(
        h.model,
        meshes,
        Qall,
        times,
        camera,
        noise=noise,
        outlier_fraction=outlier_fraction,
        seed=seed,
        progress=progress,
    )
    syn.lead_in_frames = len(lead)
    syn.camera_shift = shift
    syn.limb_error_deg = poser.limb_error_deg.copy()
    return syn, poser


def clip_cloud_sequence(
    clip: str | Path,
    *,
    rate: float = 30.0,
    start: float = 0.0,
    duration: float | None = None,
    downscale: int = 1,
    **render: Any,
) -> tuple[SyntheticSequence, HumanPoser]:
    """The human model following a mocap clip, rendered at ``rate`` Hz (``make-cloud``).

    Loads the clip (any format :func:`~qpretarget.motion.load_motion` reads), resamples it by
    taking the clip frame nearest to each tick of ``rate`` from ``start`` for ``duration``
    seconds (all of it when None), and renders it with :func:`human_clip_sequence` (calibration
    posture first, then the move into the clip), by default at the
    full Kinect V2 resolution (``downscale`` 1: about 9,000 points on the person at 2.8 m).
    ``render`` holds the other options of :func:`human_clip_sequence` (``calibration_frames``,
    ``lead_in_speed``, ``distance``, ``noise``, ``outlier_fraction``, ``seed``...), with its
    defaults.

    Raises:
        ConfigError: a rate <= 0, a negative start, a duration <= 0, or a start past the clip's
            end.
    """
    from ..motion import load_motion
    from ..motion.keypoints import keypoint_orientations, keypoint_positions

    if not rate > 0:
        raise ConfigError(f"the rate must be > 0 Hz, got {rate}.")
    if start < 0 or (duration is not None and not duration > 0):
        raise ConfigError(
            f"need start >= 0 s and duration > 0 s (or none: to the end), got start {start}, "
            f"duration {duration}."
        )
    motion = load_motion(clip)
    t = np.asarray(motion.t, float)
    t_end = float(t[-1]) if duration is None else min(float(t[-1]), start + float(duration))
    ticks = np.arange(t[0] + start, t_end + 1e-9, 1.0 / rate)
    if len(ticks) == 0:
        raise ConfigError(
            f"no frame selected: the clip lasts {t[-1] - t[0]:.2f} s, start {start} s, "
            f"duration {duration} s; pick a start inside the clip."
        )
    idx = np.searchsorted(0.5 * (t[1:] + t[:-1]), ticks)  # the nearest clip frame
    kp = {k: v[idx] for k, v in keypoint_positions(motion).items()}
    ori = {k: v[idx] for k, v in keypoint_orientations(motion).items()}
    ori = trunk_orientations(kp, ori, times=ticks - t[0], source=str(clip))
    return human_clip_sequence(kp, ori, ticks - ticks[0], downscale=downscale, **render)


def _visible_joints(
    meshes: LinkMeshes, points: np.ndarray, normals: np.ndarray, link: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, normals and moving joint of the pixels that see a link (``link >= 0``).

    The joint of a point is the pinocchio joint of its link's triangles.
    """
    ok = link >= 0
    link_joint = np.zeros(len(meshes.link_names), dtype=int)
    link_joint[meshes.link] = meshes.joint
    return points[ok], normals[ok], link_joint[link[ok]]


def joint_observability(
    model: pin.Model,
    data: pin.Data,
    meshes: LinkMeshes,
    points: np.ndarray,
    normals: np.ndarray,
    link: np.ndarray,
) -> np.ndarray:
    r"""How much each one-DoF joint moves the visible surface along its normal [m/rad].

    For joint :math:`j` with world axis :math:`a_j` through :math:`o_j`, and the visible points
    :math:`p` (with normals :math:`n`) of the links it moves,
    :math:`O_j = \sqrt{\sum_p (n^\top (a_j \times (p - o_j)))^2}`. Depth data only sees motion
    along the surface normal, so with range noise :math:`\sigma` a joint's angle is measurable
    to about :math:`\sigma / O_j` (a rotation about a round limb's own axis gives :math:`O_j
    \approx 0`). ``data`` must hold ``computeJointJacobians`` of the rendered configuration.

    Returns:
        (njoints,) values indexed by pinocchio joint id (0 for the universe and multi-DoF joints).
    """
    out = np.zeros(model.njoints)
    p, n, pj = _visible_joints(meshes, points, normals, link)
    sub = {j: set(model.subtrees[j]) for j in range(model.njoints)}
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nv != 1:
            continue
        sel = np.isin(pj, list(sub[j]))
        if not sel.any():
            continue
        J = pin.getJointJacobian(model, data, j, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        a = J[3:, jm.idx_v]
        o = data.oMi[j].translation
        g = np.einsum("ka,ka->k", n[sel], np.cross(a, p[sel] - o))
        out[j] = float(np.sqrt(g @ g))
    return out


def joint_uncertainty(
    model: pin.Model,
    data: pin.Data,
    meshes: LinkMeshes,
    points: np.ndarray,
    normals: np.ndarray,
    link: np.ndarray,
    noise: float,
    ridge: float = 1e-9,
) -> np.ndarray:
    r"""Cramer-Rao standard deviation [rad] of every velocity coordinate from one depth view.

    Each visible point :math:`p` (normal :math:`n`) measures :math:`n^\top p` with range noise
    ``noise``; with the point Jacobians :math:`J_p` the Fisher information is
    :math:`F = \sum_p J_p^\top n n^\top J_p / \sigma^2` and the best possible standard deviation
    of coordinate :math:`i` is :math:`\sqrt{(F^{-1})_{ii}}`. Unlike :func:`joint_observability`
    this accounts for joints that compensate each other (a shoulder yaw against a wrist roll).
    ``data`` must hold ``computeJointJacobians`` of the rendered configuration.

    Returns:
        (nv,) standard deviations (large for coordinates the view cannot determine).
    """
    p, n, pj = _visible_joints(meshes, points, normals, link)
    rows = np.zeros((len(p), model.nv))
    for j in np.unique(pj):
        sel = pj == j
        J = pin.getJointJacobian(model, data, int(j), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        r = p[sel] - data.oMi[int(j)].translation
        # n^T (J_lin - [r]x J_ang) = n^T J_lin + (r x n)^T J_ang
        rows[sel] = n[sel] @ J[:3] + np.cross(r, n[sel]) @ J[3:]
    F = rows.T @ rows / noise**2
    F[np.diag_indices_from(F)] += ridge * max(float(np.trace(F)), 1e-300)
    return np.sqrt(np.clip(np.diag(np.linalg.pinv(F)), 0.0, None))


__all__ = [
    "BODY_HALF_WIDTH",
    "Camera",
    "SyntheticSequence",
    "camera_setback",
    "clip_cloud_sequence",
    "corrupt",
    "human_clip_sequence",
    "joint_observability",
    "joint_uncertainty",
    "kinect_camera",
    "look_at",
    "rasterize",
    "render_cloud",
    "render_depth",
    "render_sequence",
    # the posed human model (.poser), used here and kept importable from here
    "HUMAN_TO_Z_UP",
    "HumanPoser",
    "interpolation_peak_rate",
    "trunk_orientations",
]
