# SPDX-License-Identifier: Apache-2.0
r"""Xsens MVN real-time network streaming: the ``MXTP02`` datagram, written from the specification.

Source: Xsens, *MVN real-time network streaming protocol specification* (document MV0305P,
revision N, 2018), sections 2.3-2.5 and 3.1. What this module implements:

* UDP, default port **9763** (section 2.3).
* Every datagram starts with a **24-byte header**, all numbers big-endian ("network byte order",
  section 2.4 and 2.5.11)::

      offset size field
       0     6   ID string, ASCII "MXTP" + two-digit message type ("02": pose, quaternion)
       6     4   sample counter (uint32, +1 per sample sent; the sender may skip samples)
      10     1   datagram counter (bit 7: last datagram of this sample; bits 0-6: index)
      11     1   number of items (segments) in this datagram
      12     4   time code (uint32, ms since the start of the recording)
      16     1   character ID (0 in a single-character setup)
      17     1   number of body segments (23; from MVN 2019, 0 before)
      18     1   number of props (0-4)
      19     1   number of finger tracking segments (0 or 40)
      20     2   reserved
      22     2   payload size [bytes] (datagram size - 24)

* **Message type 02**, *segment data quaternion* (section 2.5.3): per item 32 bytes, segment ID
  (int32), position x, y, z (float32), rotation quaternion q1..q4 = (w, x, y, z) (float32), the
  segment's absolute pose. "The coordinates use a **Z-up, right-handed** coordinate system" —
  the convention of :class:`~qpretarget.motion.HumanMotion`, so no axis change is needed.
  Items come in the order body segments, props, left then right finger segments (section 2.5.1).
* **Units.** Section 2.5.6 of the specification says positions are in cm, while the MVN user
  manual (MV0319P, "Network Streamer") and Xsens' support article on the Network Streamer say the
  quaternion stream's positions are in metres; the default follows the manual, ``units="cm"``
  reads a sender in cm.
* **Segments** (section 3.1, table 1): ID = index + 1, Pelvis 1 ... LeftToe 23 (:data:`SEGMENTS`).
  Each segment's position is its origin, the joint at its proximal end, and its orientation is the
  segment frame in the world. MVN's null pose is a T-pose "where all segment orientations are set
  to identity" (section 2.6.2): the orientations are rotations *relative to the rest pose*, as
  ``HumanMotion.orientations`` are. Type 02 is Z-up by default ("Default mode Z-Up, right-handed or
  Y-Up"); MVN's streamer must be left on Z-up.

Decoded frames name each segment after the joint at its origin in MVN's own BVH export
(:data:`SEGMENT_JOINTS`: Pelvis -> ``Hips``, RightUpperArm -> ``RightShoulder``...), so the bundled
``mvn_bvh`` key-point map applies unchanged.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import QPRetargetError

#: Default UDP port of the MVN network streamer (specification section 2.3).
DEFAULT_PORT = 9763

#: The 23 body segments of the quaternion protocol in ID order (ID = index + 1, section 3.1).
SEGMENTS: tuple[str, ...] = (
    "Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head",
    "RightShoulder", "RightUpperArm", "RightForeArm", "RightHand",
    "LeftShoulder", "LeftUpperArm", "LeftForeArm", "LeftHand",
    "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToe",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe",
)  # fmt: skip

#: Segment -> the joint at its origin as MVN's BVH export names it (the ``mvn_bvh`` key-point map).
SEGMENT_JOINTS: dict[str, str] = {
    "Pelvis": "Hips", "L5": "Chest", "L3": "Chest2", "T12": "Chest3", "T8": "Chest4",
    "Neck": "Neck", "Head": "Head",
    "RightShoulder": "RightCollar", "RightUpperArm": "RightShoulder",
    "RightForeArm": "RightElbow", "RightHand": "RightWrist",
    "LeftShoulder": "LeftCollar", "LeftUpperArm": "LeftShoulder",
    "LeftForeArm": "LeftElbow", "LeftHand": "LeftWrist",
    "RightUpperLeg": "RightHip", "RightLowerLeg": "RightKnee", "RightFoot": "RightAnkle",
    "RightToe": "RightToe",
    "LeftUpperLeg": "LeftHip", "LeftLowerLeg": "LeftKnee", "LeftFoot": "LeftAnkle",
    "LeftToe": "LeftToe",
}  # fmt: skip

#: Joint names of decoded frames, in segment order.
JOINT_NAMES: tuple[str, ...] = tuple(SEGMENT_JOINTS[s] for s in SEGMENTS)

#: Parent of each segment in MVN's tree (index, -1 for the pelvis).
PARENTS: tuple[int, ...] = (
    -1, 0, 1, 2, 3, 4, 5,
    4, 7, 8, 9,
    4, 11, 12, 13,
    0, 15, 16, 17,
    0, 19, 20, 21,
)  # fmt: skip

#: Key-point map of decoded frames (bundled, from MVN's BVH export names).
KEYPOINT_MAP = "mvn_bvh"

HEADER = struct.Struct(">6sIBBIBBBBHH")
HEADER_SIZE = HEADER.size  # 24
ITEM = np.dtype([("id", ">i4"), ("p", ">f4", (3,)), ("q", ">f4", (4,))])
ITEM_SIZE = ITEM.itemsize  # 32
N_SEGMENTS = len(SEGMENTS)
UNITS = {"m": 1.0, "cm": 0.01}


class MxtpError(QPRetargetError, ValueError):
    """A datagram that is not a well-formed MXTP02 pose datagram (the message says why)."""


@dataclass(frozen=True)
class MxtpHeader:
    """The 24-byte header of an MXTP datagram (fields of the specification, section 2.4.1)."""

    message_type: str
    sample_counter: int
    datagram_counter: int
    items: int
    time_code: int
    character_id: int
    body_segments: int
    props: int
    finger_segments: int
    payload_size: int

    @property
    def last_of_sample(self) -> bool:
        """Bit 7 of the datagram counter: this is the last datagram of its sample."""
        return bool(self.datagram_counter & 0x80)


@dataclass(frozen=True)
class MxtpPose:
    """The body segments of one decoded type-02 datagram.

    Attributes:
        header: The datagram header.
        ids: Segment IDs (1-23) of the body segments it holds, in datagram order.
        positions: ``(n, 3)`` segment origins [m] (float32 values as float64).
        quaternions: ``(n, 4)`` segment orientations ``(w, x, y, z)``.
    """

    header: MxtpHeader
    ids: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray


def parse_header(data: bytes) -> MxtpHeader:
    """Decode the header of an MXTP datagram.

    Raises:
        MxtpError: Shorter than 24 bytes, not ``MXTP``, or a payload size that disagrees with
            the datagram's length.
    """
    if len(data) < HEADER_SIZE:
        raise MxtpError(f"datagram of {len(data)} bytes is shorter than the 24-byte MXTP header")
    ident, sample, dgram, items, tc, char, nbody, nprops, nfing, _res, size = HEADER.unpack_from(
        data
    )
    if ident[:4] != b"MXTP":
        raise MxtpError(f"not an MXTP datagram (starts with {ident[:6]!r})")
    try:
        mtype = ident[4:6].decode("ascii")
    except UnicodeDecodeError:
        raise MxtpError(f"bad message type bytes {ident[4:6]!r}") from None
    if size != len(data) - HEADER_SIZE:
        raise MxtpError(
            f"payload size field says {size} bytes but the datagram carries "
            f"{len(data) - HEADER_SIZE} (truncated?)"
        )
    return MxtpHeader(mtype, sample, dgram, items, tc, char, nbody, nprops, nfing, size)


def decode_pose(data: bytes, *, units: str = "m") -> MxtpPose:
    """Decode an ``MXTP02`` datagram: its header and body segments.

    Props and finger segments (after the body segments, section 2.5.1) are dropped. A sample
    split over several datagrams (datagram counter not 0x80) yields the body segments each
    datagram holds; :class:`PoseAssembler` joins them.

    Args:
        data: The datagram.
        units: ``"m"`` (MVN 2018+) or ``"cm"`` (the specification's section 2.5.6).

    Raises:
        MxtpError: Malformed (see :func:`parse_header`), not type 02, an item count that does not
            fill the payload, a segment ID out of range or repeated, a non-normalized quaternion,
            or an infinite value.
    """
    h = parse_header(data)
    if h.message_type != "02":
        raise MxtpError(f"message type {h.message_type!r} is not pose data quaternion ('02')")
    if h.items * ITEM_SIZE != h.payload_size:
        raise MxtpError(
            f"{h.items} items of 32 bytes do not fill the {h.payload_size}-byte payload"
        )
    items = np.frombuffer(data, dtype=ITEM, count=h.items, offset=HEADER_SIZE)
    ids = items["id"].astype(np.int64)
    body = (ids >= 1) & (ids <= N_SEGMENTS)  # props are 24-27, finger segments after them
    ids = ids[body]
    if np.unique(ids).size != ids.size:
        raise MxtpError("a segment ID appears twice in one datagram")
    p = items["p"][body].astype(np.float64) * UNITS[units]
    q = items["q"][body].astype(np.float64)
    if not (np.all(np.isfinite(q)) and np.all(~np.isinf(p))):
        raise MxtpError("non-finite quaternion or infinite position")
    norms = np.linalg.norm(q, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        raise MxtpError(f"quaternion not normalized (norms {norms.min():.3g}..{norms.max():.3g})")
    return MxtpPose(h, ids, p, q)


class PoseAssembler:
    """Joins the datagrams of one sample until all 23 body segments are there.

    MVN sends one datagram per sample (datagram counter 0x80) unless finger tracking makes it
    larger than the MTU (section 2.4.1.3); then the body segments may be spread over several.
    """

    def __init__(self) -> None:
        self._sample: int | None = None
        self._p = np.full((N_SEGMENTS, 3), np.nan)
        self._q = np.full((N_SEGMENTS, 4), np.nan)
        self._have = np.zeros(N_SEGMENTS, bool)

    def add(self, pose: MxtpPose) -> tuple[np.ndarray, np.ndarray] | None:
        """Add a decoded datagram.

        Returns:
            ``(positions (23, 3), quaternions (23, 4))`` once the sample is complete, else
            ``None``.
        """
        s = pose.header.sample_counter
        if s != self._sample:
            self._sample = s
            self._have[:] = False
        idx = pose.ids - 1
        self._p[idx] = pose.positions
        self._q[idx] = pose.quaternions
        self._have[idx] = True
        if self._have.all():
            self._sample = None
            self._have[:] = False
            return self._p.copy(), self._q.copy()
        return None


def encode_pose(
    sample_counter: int,
    time_code_ms: int,
    positions: np.ndarray,
    quaternions: np.ndarray,
    *,
    character_id: int = 0,
    units: str = "m",
) -> bytes:
    """One ``MXTP02`` datagram with the 23 body segments (IDs 1-23, in order).

    Args:
        sample_counter: Sample number (uint32, wraps).
        time_code_ms: Time code [ms] (uint32, wraps).
        positions: ``(23, 3)`` segment origins [m], Z-up.
        quaternions: ``(23, 4)`` segment orientations ``(w, x, y, z)``, normalized.
        character_id: Character ID byte.
        units: Units written, ``"m"`` or ``"cm"``.
    """
    items = np.empty(N_SEGMENTS, dtype=ITEM)
    items["id"] = np.arange(1, N_SEGMENTS + 1)
    items["p"] = np.asarray(positions, float) / UNITS[units]
    items["q"] = quaternions
    payload = items.tobytes()
    header = HEADER.pack(
        b"MXTP02",
        sample_counter & 0xFFFFFFFF,
        0x80,
        N_SEGMENTS,
        time_code_ms & 0xFFFFFFFF,
        character_id & 0xFF,
        N_SEGMENTS,
        0,
        0,
        0,
        len(payload),
    )
    return header + payload


# ------------------------------------------------------------------------------ rotations
def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """``(..., 4)`` quaternions ``(w, x, y, z)`` (normalized here) -> ``(..., 3, 3)`` rotations."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations -> ``(..., 4)`` unit quaternions ``(w, x, y, z)``, ``w >= 0``.

    Shepperd's method: the largest of ``4w^2, 4x^2, 4y^2, 4z^2`` (from the trace and the diagonal)
    picks the formula, so the division is never by a small number.
    """
    R = np.asarray(R, float)
    m = R.reshape(-1, 3, 3)
    t = np.stack(
        [
            1 + m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2],
            1 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2],
            1 - m[:, 0, 0] + m[:, 1, 1] - m[:, 2, 2],
            1 - m[:, 0, 0] - m[:, 1, 1] + m[:, 2, 2],
        ],
        axis=1,
    )
    k = np.argmax(t, axis=1)
    q = np.empty((m.shape[0], 4))
    s = np.sqrt(np.maximum(t[np.arange(len(k)), k], 1e-300)) * 2  # 4 * |component|
    a = k == 0
    q[a] = np.stack(
        [
            s[a] / 4,
            (m[a, 2, 1] - m[a, 1, 2]) / s[a],
            (m[a, 0, 2] - m[a, 2, 0]) / s[a],
            (m[a, 1, 0] - m[a, 0, 1]) / s[a],
        ],
        1,
    )
    a = k == 1
    q[a] = np.stack(
        [
            (m[a, 2, 1] - m[a, 1, 2]) / s[a],
            s[a] / 4,
            (m[a, 0, 1] + m[a, 1, 0]) / s[a],
            (m[a, 0, 2] + m[a, 2, 0]) / s[a],
        ],
        1,
    )
    a = k == 2
    q[a] = np.stack(
        [
            (m[a, 0, 2] - m[a, 2, 0]) / s[a],
            (m[a, 0, 1] + m[a, 1, 0]) / s[a],
            s[a] / 4,
            (m[a, 1, 2] + m[a, 2, 1]) / s[a],
        ],
        1,
    )
    a = k == 3
    q[a] = np.stack([(m[a, 1, 0] - m[a, 0, 1]) / s[a], (m[a, 0, 2] + m[a, 2, 0]) / s[a],
                     (m[a, 1, 2] + m[a, 2, 1]) / s[a], s[a] / 4], 1)  # fmt: skip
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(R.shape[:-2] + (4,))


# ------------------------------------------------------------------------------ clip -> segments
#: Where each segment's origin comes from on a clip with key-points: the key-point named like
#: the segment's joint (``RightElbow`` -> ``right_elbow``), but for the pelvis (``waist``), and the
#: spine and the collar bones, which key-point maps do not carry: a point ``a + s (b - a)``
#: between two key-points ``(a, b, s)``.
_SEGMENT_POINTS: dict[str, str | tuple[str, str, float]] = {
    **{s: re.sub(r"(?<=[a-z])([A-Z])", r"_\1", SEGMENT_JOINTS[s]).lower() for s in SEGMENTS},
    "Pelvis": "waist",
    **{s: ("waist", "neck", f) for s, f in (("L5", 0.2), ("L3", 0.4), ("T12", 0.6), ("T8", 0.8))},
    "RightShoulder": ("neck", "right_shoulder", 0.25),
    "LeftShoulder": ("neck", "left_shoulder", 0.25),
}

#: Which orientation of the clip each segment takes (``waist``/``torso``/``head`` of the key-point
#: map's ``orientations``), or ``None``: the rotation of the joint giving its key-point.
_SEGMENT_ORIENTATION: dict[str, str | None] = {
    "Pelvis": "waist", "L5": "waist", "L3": "waist", "T12": "torso", "T8": "torso",
    "Neck": "torso", "Head": "head", "RightShoulder": "torso", "LeftShoulder": "torso",
}  # fmt: skip


def segment_poses(motion: object, keypoint_map: object = None) -> tuple[np.ndarray, np.ndarray]:
    """MVN segment poses of a clip, as a suit streaming it would send them.

    Origins from the clip's key-points (:data:`_SEGMENT_POINTS`: spine points spread between the
    waist and the neck, collar-bone origins a quarter of the way from the neck to the shoulder);
    orientations from the clip's ``waist``/``torso``/``head`` orientations, limbs from the joint
    giving their key-point, identity where the clip has none. A clip without orientations (C3D)
    gets the waist and torso frames of :func:`~qpretarget.motion.calibration.triad`.

    Args:
        motion: A :class:`~qpretarget.motion.HumanMotion`.
        keypoint_map: Its key-point map (``None``: guessed from the joint names).

    Returns:
        ``(positions (T, 23, 3) [m], quaternions (T, 23, 4) (w, x, y, z))``.

    Raises:
        KeypointMapError: No key-point map fits the clip.
    """
    from ..motion.calibration import triad
    from ..motion.keypoints import resolve_keypoint_map

    kmap = resolve_keypoint_map(keypoint_map, motion)  # type: ignore[arg-type]
    kp = kmap.positions(motion)  # type: ignore[arg-type]
    T = len(motion)  # type: ignore[arg-type]
    P = np.full((T, N_SEGMENTS, 3), np.nan)
    for i, seg in enumerate(SEGMENTS):
        src = _SEGMENT_POINTS[seg]
        if isinstance(src, str):
            if src in kp:
                P[:, i] = kp[src]
        elif src[0] in kp and src[1] in kp:
            a, b, s = kp[src[0]], kp[src[1]], src[2]
            P[:, i] = a + s * (b - a)
    R = np.broadcast_to(np.eye(3), (T, N_SEGMENTS, 3, 3)).copy()
    orient: Mapping[str, np.ndarray]
    if motion.orientations is not None:  # type: ignore[attr-defined]
        orient = kmap.orientations_of(motion)  # type: ignore[arg-type]
        for i, seg in enumerate(SEGMENTS):
            which = _SEGMENT_ORIENTATION.get(seg)
            if which is not None:
                if which in orient:
                    R[:, i] = orient[which]
                elif which == "head" and "torso" in orient:
                    R[:, i] = orient["torso"]
                continue
            src = _SEGMENT_POINTS[seg]
            if isinstance(src, str) and src in kmap.keypoints:
                R[:, i] = motion.joint_orientation(kmap.keypoints[src].points[0])  # type: ignore[attr-defined]
    else:
        frames = {}
        if all(k in kp for k in ("left_hip", "right_hip", "waist", "neck")):
            frames["waist"] = triad(kp["left_hip"], kp["right_hip"], kp["waist"], kp["neck"])
        if all(k in kp for k in ("left_shoulder", "right_shoulder", "waist", "neck")):
            frames["torso"] = triad(
                kp["left_shoulder"], kp["right_shoulder"], kp["waist"], kp["neck"]
            )
        for i, seg in enumerate(SEGMENTS):
            which = _SEGMENT_ORIENTATION.get(seg)
            which = "torso" if which == "head" else which
            if which in frames:
                Rw = frames[which]
                ok = np.all(np.isfinite(Rw), axis=(1, 2))
                R[ok, i] = Rw[ok]
    return P, matrix_to_quat(R)
