# SPDX-License-Identifier: Apache-2.0
"""Synthetic depth: exact ray depths, z-buffer occlusion, noise and outlier fractions."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.cloud.io import PinholeIntrinsics
from qpretarget.cloud.render import corrupt, look_at, rasterize, render_depth
from qpretarget.errors import ConfigError

INTR = PinholeIntrinsics(fx=80.0, fy=80.0, cx=39.5, cy=29.5, width=80, height=60)


def square(z: float, half: float) -> np.ndarray:
    c = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return np.array([[c[0], c[1], c[2]], [c[0], c[2], c[3]]])


def test_depth_is_exact_and_the_nearest_surface_wins():
    far, near = square(3.0, 2.0), square(2.0, 0.3)
    depth, index = rasterize(np.concatenate([far, near]), INTR)
    # Pixel rays hit planes z = const exactly: depth equals the plane's z (1e-12 m).
    seen = np.isfinite(depth)
    assert np.allclose(depth[seen & (index < 2)], 3.0, atol=1e-12)
    assert np.allclose(depth[index >= 2], 2.0, atol=1e-12)
    # The near square covers the centre; its pixel footprint is 0.3 / 2.0 * 80 * 2 = 24 px wide.
    assert index[30, 40] >= 2 and index[30, 5] < 2
    assert abs(int(np.sum(index[30] >= 2)) - 24) <= 1
    # Order of the triangles does not matter.
    depth2, _ = rasterize(np.concatenate([near, far]), INTR)
    assert np.array_equal(depth, depth2)


def test_self_occlusion_of_a_robot(g1, g1_meshes):
    from qpretarget.cloud.render import Camera

    intr = PinholeIntrinsics(fx=160.0, fy=160.0, cx=79.5, cy=59.5, width=160, height=120)
    data = g1.model.createData()
    pin.forwardKinematics(g1.model, data, g1.q_reference)
    seen = {}
    for side, y in (("left", 2.5), ("right", -2.5)):
        _, link = render_depth(g1_meshes, data, Camera(intr, look_at([0, y, 0.7], [0, 0, 0.7])))
        seen[side] = {n: int(np.sum(link == i)) for i, n in enumerate(g1_meshes.link_names)}
    # From the robot's left, its right upper arm is hidden behind the torso, and the reverse
    # (the z-buffer, not a back-face rule: both arms face the camera somewhere).
    assert (
        seen["left"]["left_shoulder_yaw_link"] > 20 and seen["left"]["right_shoulder_yaw_link"] == 0
    )
    assert (
        seen["right"]["right_shoulder_yaw_link"] > 20
        and seen["right"]["left_shoulder_yaw_link"] == 0
    )


def test_noise_and_outliers():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.3, -0.3, 0.0], [0.3, 0.3, 1.7], (19000, 3))
    eye = np.array([3.0, 0.0, 1.0])
    out, is_out = corrupt(pts, eye, noise=0.005, outlier_fraction=0.05, rng=rng)
    assert abs(is_out.mean() - 0.05) < 1e-3  # exactly 1000 of 20000 (rounding only)
    d = np.linalg.norm(out[~is_out] - eye, axis=1) - np.linalg.norm(pts - eye, axis=1)
    # Range noise: std 5 mm within 3 % (19,000 samples), along the ray only.
    assert abs(d.std() - 0.005) < 0.00015
    ray = (pts - eye) / np.linalg.norm(pts - eye, axis=1, keepdims=True)
    lateral = (out[~is_out] - pts) - d[:, None] * ray
    assert np.abs(lateral).max() < 1e-12


def test_the_rendered_person_stands_on_the_floor(mocap):
    """``make-cloud``'s person (``human_clip_sequence``) stands on the floor: the calibration
    posture's and each lead-in frame's lowest mesh point at z = 0, and within every 1 s window
    of the clip the lowest point of the model at z = 0 (to 1e-9 m: a shift of the root height
    by the model's own lowest point). CMU 17_10's boxer crouches: placed at the clip's root
    height, as before, the model floated 18-24 cm above the floor (its toes' key-points at
    0.21 m median against 0.027 standing)."""
    from qpretarget.cloud.meshes import load_link_meshes
    from qpretarget.cloud.render import clip_cloud_sequence

    syn, poser = clip_cloud_sequence(mocap / "cmu_17_10_boxing.bvh", rate=30.0, duration=2.0)
    h = poser.robot
    meshes = load_link_meshes(h.model, h.urdf_path)
    data = h.model.createData()
    low = []
    for q in syn.q:
        pin.forwardKinematics(h.model, data, q)
        low.append(meshes.posed(data)[..., 2].min())
    low = np.array(low)
    lead = syn.lead_in_frames  # the calibration posture and the move into the clip
    assert lead >= 5
    assert np.all(np.abs(low[:lead]) < 1e-9)
    clip = low[lead:]
    r = 15  # half of 1 s at 30 Hz
    window_min = np.array([clip[max(0, i - r) : i + r + 1].min() for i in range(len(clip))])
    assert np.all(np.abs(window_min) < 1e-9)
    toes = [min(poser.model_keypoints(q)[f"{s}_toe"][2] for s in ("left", "right")) for q in syn.q]
    assert np.median(toes) < 0.08  # on the floor or on the balls of the feet, not in the air


def test_the_move_into_the_clip_is_at_a_persons_pace(mocap):
    """``make-cloud --lead-in-speed``: the person moves from the calibration posture into the
    clip's first pose with no key-point faster than ``lead_in_speed`` (2 m/s here), instead of
    the default 4 frames whatever the distance: CMU 49_18 (one-leg balance) raises both arms,
    the left hand 1.2 m away, at 7 m/s in the default's 5 steps. Measured: 1.81 m/s at the
    fastest key-point between frames (the move's duration bounds the speed: the fastest
    key-point's rate along the interpolation times the profile's peak, which fall at
    different moments). Bounds: at most 2 % above 2 m/s (the rates are differences over 64
    steps of the interpolation), at least 1.6 m/s (the move is not needlessly slow); the move
    starts and ends at rest (the first and last steps below a tenth of the peak), frame 0 is
    the calibration posture (arms abducted 0.5 rad) and the clip follows the move unchanged.
    """
    from qpretarget.cloud.render import clip_cloud_sequence

    clip = mocap / "cmu_49_18_one_leg_balance.bvh"
    syn, poser = clip_cloud_sequence(clip, rate=30.0, duration=0.2, downscale=8, lead_in_speed=2)
    lead = syn.lead_in_frames
    names = list(poser.model_keypoints(syn.q[0]))
    P = np.array([[poser.model_keypoints(q)[k] for k in names] for q in syn.q[: lead + 1]])
    speed = np.linalg.norm(np.diff(P, axis=0), axis=2).max(axis=1) * 30.0  # (lead,) [m/s]
    assert 1.6 <= speed.max() <= 2.0 * 1.02
    assert speed[0] < 0.1 * speed.max() and speed[-1] < 0.1 * speed.max()
    assert lead > 30  # 1.2 m at a person's pace takes over a second
    h = poser.robot
    for side in ("left", "right"):
        i = h.joint_q_index[h.joint_index(f"{side}_shoulder_X")]
        assert syn.q[0][i] == 0.5
    fixed, _ = clip_cloud_sequence(clip, rate=30.0, duration=0.2, downscale=8)
    assert fixed.lead_in_frames == 5  # the default: 4 frames after the calibration posture
    np.testing.assert_allclose(fixed.q[5:], syn.q[lead:], atol=1e-12)  # the same clip after it


def test_the_first_frame_is_posed_from_bent_limbs_when_straight_ones_fail(mocap):
    """The human model follows the clip's first frame even where the neutral pose's straight
    elbows fail (``HumanPoser._first_frame``). CMU 01_01 (cgspeed's playground jumps) starts
    with the left forearm raised to the face: from the neutral pose the first frame settled
    with that forearm 64 deg off the clip's (the shoulder's axial rotation at its limit, the
    trunk rolled) and the rendering stayed on that branch for 51 of 90 frames (limbs up to
    128 deg off). Measured with the bent starts: every limb within 0.2 deg at the first frame
    and within 1.0 deg over the first 3 s. Bounds: the first frame within
    ``FIRST_FRAME_TOLERANCE`` (10 deg) on every limb, and with the bent starts taken away
    (the former behaviour) above it, so the test fails without the fallback."""
    from qpretarget.cloud.poser import HumanPoser
    from qpretarget.motion import load_motion
    from qpretarget.motion.keypoints import keypoint_orientations, keypoint_positions

    motion = load_motion(mocap / "cgspeed_cmu_01_01_playground_jumps.bvh")
    kp = {k: v[:1] for k, v in keypoint_positions(motion).items()}
    ori = {k: v[:1] for k, v in keypoint_orientations(motion).items()}
    first = {k: v[0] for k, v in kp.items()}
    poser = HumanPoser()
    q = poser.pose_sequence(kp, ori)[0]
    assert poser.limb_errors(q, first).max() <= HumanPoser.FIRST_FRAME_TOLERANCE
    poser.BENT_STARTS = ()  # the neutral start alone
    q_straight = poser.pose_sequence(kp, ori)[0]
    assert poser.limb_errors(q_straight, first).max() > HumanPoser.FIRST_FRAME_TOLERANCE


def test_camera_setback_keeps_a_travelling_person_in_view():
    """``camera_setback``: the smallest move back along the camera's line of sight that puts
    every pelvis position at least ``min_distance`` in front of it and inside the image with
    ``BODY_HALF_WIDTH`` to spare (exact to 1e-9 m on these positions: the bound's formula).
    A camera 2.8 m in front of x = 0 looking along -x: a person standing still needs none; one
    walking 3 m towards it needs 3 - 2.8 + 2 = 2.2 m; one stepping 2.5 m sideways at 2.8 m
    needs (2.5 + 0.5) / tan(alpha) - 2.8."""
    from qpretarget.cloud.render import BODY_HALF_WIDTH, camera_setback, kinect_camera

    cam = kinect_camera([2.8, 0.0, 1.2], [0.0, 0.0, 0.9])
    still = np.array([[0.0, 0.0, 1.0], [0.05, 0.02, 1.0]])
    assert camera_setback(cam, still, min_distance=2.0) == 0.0
    walk = np.array([[x, 0.0, 1.0] for x in np.linspace(0.0, 3.0, 31)])
    assert abs(camera_setback(cam, walk, min_distance=2.0) - 2.2) < 1e-9
    side = np.array([[0.0, y, 1.0] for y in np.linspace(0.0, 2.5, 11)])
    intr = cam.intrinsics
    tan_a = min(intr.cx, intr.width - intr.cx) / intr.fx
    expected = (2.5 + BODY_HALF_WIDTH) / tan_a - 2.8
    assert abs(camera_setback(cam, side, min_distance=2.0) - expected) < 1e-9
    with pytest.raises(ConfigError, match="min_distance"):
        camera_setback(cam, walk, min_distance=0.0)


def test_a_walk_towards_the_camera_stays_in_view(mocap):
    """``make-cloud``'s camera moves back for a clip that travels towards it. CMU 16_15 walks
    3.1 m in 3 s straight at the camera placed 2.8 m in front of its start: before, the walker
    passed through it after 2.5 s (frames without a point, held by the fit, arms 130-150 deg
    off); now the camera stands 2.49 m further back, every frame shows the person, the pelvis
    at least 2.0 m in front of the camera (to 1e-6 m), and the fit's worst arm segment was
    5.3-6.9 deg (docs/point_clouds.md). A clip that stays in place (CMU 14_37, drink) is
    rendered from the 2.8 m it always was: no move, the same camera."""
    from qpretarget.cloud.render import clip_cloud_sequence

    syn, _ = clip_cloud_sequence(mocap / "cmu_16_15_walk.bvh", rate=30.0, duration=3.0, downscale=8)
    assert syn.camera_shift > 2.0
    assert min(len(f.points) for f in syn.sequence.frames) > 20  # 64x fewer pixels than make-cloud
    R = syn.camera.pose[:3, :3]
    f = R[:, 2].copy()
    f[2] = 0.0
    f /= np.linalg.norm(f)
    depth = (syn.q[:, :3] - syn.camera.position) @ f
    assert depth.min() >= 2.0 - 1e-6
    assert syn.limb_error_deg is not None and syn.limb_error_deg.max() < 5.0  # the walk's 0.8
    still, _ = clip_cloud_sequence(
        mocap / "cmu_14_37_drink_soda.bvh", rate=30.0, duration=0.3, downscale=8
    )
    assert still.camera_shift == 0.0


def test_trunk_orientations_from_markers():
    """``trunk_orientations`` for a clip without joint orientations: an upright person facing
    +x gets the identity (the rest pose ``HumanPoser`` expects), one turned by 90 deg about
    the vertical gets that turn, to 1e-12 (exact rotations of exact points); orientations a
    clip has are kept; without hips the shoulders give the waist's."""
    from qpretarget.cloud.poser import trunk_orientations
    from qpretarget.motion.calibration import rotation_z

    base = {
        "waist": [0.0, 0.0, 1.0],
        "neck": [0.0, 0.0, 1.5],
        "left_hip": [0.0, 0.1, 0.95],
        "right_hip": [0.0, -0.1, 0.95],
        "left_shoulder": [0.0, 0.2, 1.45],
        "right_shoulder": [0.0, -0.2, 1.45],
    }
    R = rotation_z(np.pi / 2)
    kp = {k: np.array([v, R @ np.array(v)]) for k, v in base.items()}  # (2, 3): two frames
    ori = trunk_orientations(kp, {})
    for name in ("waist", "torso", "head"):
        np.testing.assert_allclose(ori[name][0], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(ori[name][1], R, atol=1e-12)
    given = {"waist": np.array([R, R]), "torso": np.array([R, R])}
    kept = trunk_orientations(kp, given)
    np.testing.assert_array_equal(kept["waist"], given["waist"])
    np.testing.assert_array_equal(kept["torso"], given["torso"])
    no_hips = {k: v for k, v in kp.items() if "hip" not in k}
    np.testing.assert_allclose(trunk_orientations(no_hips, {})["waist"][1], R, atol=1e-12)
    with pytest.raises(ConfigError, match="both hips or both shoulders"):
        trunk_orientations({k: v for k, v in no_hips.items() if "left" not in k}, {})


def test_noise_on_an_empty_view():
    """Nothing in view (the person walked past the sensor): an empty cloud, no outliers and no
    error (the outliers' box is the subject's, and there is none)."""
    pts, out = corrupt(
        np.zeros((0, 3)), np.zeros(3), noise=0.005, outlier_fraction=0.05,
        rng=np.random.default_rng(0),
    )  # fmt: skip
    assert pts.shape == (0, 3) and out.shape == (0,)
