# SPDX-License-Identifier: Apache-2.0
"""MXTP02 encoder/decoder, the segment table and the Xsens source's handling of bad datagrams."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import load_motion
from qpretarget.motion.keypoints import load_keypoint_map
from qpretarget.sources import mvn
from qpretarget.sources.xsens import XsensSource


def _random_rotations(n: int, seed: int = 0) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return mvn.quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))


def _pose(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    P = rng.uniform(-2, 2, size=(23, 3))
    return P, mvn.matrix_to_quat(_random_rotations(23, seed))


def test_header_layout_follows_the_specification() -> None:
    P, Q = _pose()
    data = mvn.encode_pose(1234, 5678, P, Q, character_id=0)
    # 24-byte header + 23 segments x 32 bytes; ID string, big-endian counters (spec 2.4.1).
    assert len(data) == 24 + 23 * 32
    assert data[:6] == b"MXTP02"
    assert data[6:10] == (1234).to_bytes(4, "big")
    assert data[10] == 0x80 and data[11] == 23
    assert data[12:16] == (5678).to_bytes(4, "big")
    assert data[17] == 23 and data[22:24] == (23 * 32).to_bytes(2, "big")
    # First segment: ID 1 (Pelvis) as a big-endian int32, then x as a big-endian float32.
    assert data[24:28] == (1).to_bytes(4, "big")
    assert np.frombuffer(data[28:32], ">f4")[0] == np.float32(P[0, 0])


def test_round_trip_is_float32_exact() -> None:
    P, Q = _pose(1)
    pose = mvn.decode_pose(mvn.encode_pose(7, 70, P, Q))
    assert pose.header.sample_counter == 7 and pose.header.time_code == 70
    assert pose.header.last_of_sample
    np.testing.assert_array_equal(pose.ids, np.arange(1, 24))
    # The wire carries float32: decoded values are exactly the float32-rounded inputs.
    np.testing.assert_array_equal(pose.positions, P.astype(np.float32).astype(float))
    np.testing.assert_array_equal(pose.quaternions, Q.astype(np.float32).astype(float))
    cm = mvn.decode_pose(mvn.encode_pose(7, 70, P, Q, units="cm"), units="cm")
    np.testing.assert_allclose(cm.positions, P, rtol=1e-6)  # float32 of cm values


def test_quaternion_conversions_round_trip() -> None:
    R = _random_rotations(500, 3)
    R[:4] = [np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])]
    q = mvn.matrix_to_quat(R)
    assert np.all(q[:, 0] >= 0)
    # 1e-12: a few float64 roundings in each direction.
    np.testing.assert_allclose(mvn.quat_to_matrix(q), R, atol=1e-12)


@pytest.mark.parametrize(
    ("mutate", "reason"),
    [
        (lambda d: d[:20], "shorter than the 24-byte"),
        (lambda d: d[:-7], "truncated"),
        (lambda d: b"XXXX" + d[4:], "not an MXTP"),
        (lambda d: d[:11] + bytes([22]) + d[12:], "do not fill"),
        (lambda d: d[:24] + (2).to_bytes(4, "big") + d[28:], "appears twice"),
        (lambda d: d[:44] + np.array([3.0], ">f4").tobytes() + d[48:], "not normalized"),
        (lambda d: d[:4] + b"01" + d[6:], "is not pose data quaternion"),
    ],
)
def test_malformed_datagrams_raise_one_clear_error(mutate, reason: str) -> None:
    data = mvn.encode_pose(1, 1, *_pose(2))
    with pytest.raises(mvn.MxtpError, match=reason):
        mvn.decode_pose(mutate(data))


def test_source_counts_and_skips_bad_datagrams_never_raises() -> None:
    src = XsensSource(0, capture_rate=120.0)
    good = mvn.encode_pose(5, 40, *_pose(4))
    rng = np.random.default_rng(5)
    bad = [good[:n] for n in range(0, len(good), 37)] + [rng.bytes(n) for n in (0, 3, 24, 760)]
    bad.append(good[:22] + b"\x00\x00" + good[24:])  # payload size 0
    for data in bad:
        assert src.decode(data, 0.0) is None
    assert src.counts["malformed"] == len(bad)
    meta = b"MXTP12" + good[6:22] + (0).to_bytes(2, "big")
    assert src.decode(meta, 0.0) is None and src.counts["ignored"] == 1
    other = good[:16] + bytes([3]) + good[17:]  # character 3
    assert src.decode(other, 0.0) is None and src.counts["ignored"] == 2
    frame = src.decode(good, 1.5)
    assert frame is not None and frame.seq == 5 and frame.recv_time == 1.5
    assert frame.positions.shape == (23, 3) and frame.orientations.shape == (23, 3, 3)


def test_split_sample_is_assembled() -> None:
    P, Q = _pose(6)
    full = mvn.encode_pose(9, 90, P, Q)
    items = full[24:]
    first = bytearray(full[:24] + items[: 10 * 32])
    first[10], first[11] = 0x00, 10
    first[22:24] = (10 * 32).to_bytes(2, "big")
    second = bytearray(full[:24] + items[10 * 32 :])
    second[10], second[11] = 0x81, 13
    second[22:24] = (13 * 32).to_bytes(2, "big")
    src = XsensSource(0, capture_rate=60.0)
    assert src.decode(bytes(first), 0.0) is None
    frame = src.decode(bytes(second), 0.0)
    assert frame is not None
    np.testing.assert_array_equal(frame.positions, P.astype(np.float32).astype(float))


def test_rate_is_measured_from_time_codes() -> None:
    src = XsensSource(0)
    P, Q = _pose(7)
    for k in range(10):
        src.decode(mvn.encode_pose(100 + k, int(round(1000 * k / 120)), P, Q), 0.0)
    assert src.rate == 120.0


def test_segments_of_a_real_clip(mocap_dir) -> None:
    motion = load_motion(mocap_dir / "cmu_17_10_boxing.bvh").slice(0, 0.5)
    P, Q = mvn.segment_poses(motion)
    kp = load_keypoint_map("cmu").positions(motion)
    names = list(mvn.JOINT_NAMES)
    # Decoded names resolve with the bundled MVN BVH map, key-points land where the clip's are.
    kmap = load_keypoint_map(mvn.KEYPOINT_MAP)
    assert not kmap.missing_in(names)
    np.testing.assert_array_equal(P[:, names.index("Hips")], kp["waist"])
    np.testing.assert_array_equal(P[:, names.index("LeftElbow")], kp["left_elbow"])
    np.testing.assert_array_equal(P[:, names.index("RightToe")], kp["right_toe"])
    R = mvn.quat_to_matrix(Q[:, names.index("Hips")])
    np.testing.assert_allclose(R, motion.joint_orientation("root"), atol=1e-12)
    assert np.all(np.isfinite(P))


def test_stream_resampling() -> None:
    from qpretarget.commands.stream import resample_poses

    t = np.arange(13) / 120.0
    P = np.random.default_rng(8).normal(size=(13, 23, 3))
    Q = mvn.matrix_to_quat(_random_rotations(13 * 23, 9)).reshape(13, 23, 4)
    same = resample_poses(t, P, Q, 120.0)
    assert same[0] is t and same[1] is P  # the clip's own samples at its own rate
    t60, P60, Q60 = resample_poses(t, P, Q, 60.0)
    np.testing.assert_allclose(t60, t[::2], atol=1e-12)
    np.testing.assert_allclose(P60, P[::2], atol=1e-12)  # every other frame (1e-12: weights 0/1)
    np.testing.assert_allclose(np.abs(np.sum(Q60 * Q[::2], axis=-1)), 1.0, atol=1e-12)
    t100, P100, _ = resample_poses(t, P, Q, 100.0)
    k = 3  # t = 0.03 s lies 60 % of the way from frame 3 to frame 4 of the 120 Hz clip
    np.testing.assert_allclose(P100[k], 0.4 * P[3] + 0.6 * P[4], atol=1e-12)
