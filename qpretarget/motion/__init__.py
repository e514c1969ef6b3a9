# SPDX-License-Identifier: Apache-2.0
"""Human motion in: readers (BVH, ASF/AMC, C3D), key-point maps and streaming filters.

Every reader returns a :class:`HumanMotion` in metres, z up, time in seconds from the first
frame (``docs/motion.md``).
"""

from .asf_amc import read_amc, read_asf, read_asf_amc
from .bvh import read_bvh
from .c3d_ import read_c3d
from .filters import Butterworth, CardinalSpline
from .human_motion import HumanMotion, MotionError, MotionFormatError, UnknownMotionJointError
from .keypoints import (
    DARIUSH_KEYPOINTS,
    KEYPOINT_NAMES,
    KeypointMap,
    KeypointMapError,
    KeypointSource,
    guess_keypoint_map,
    keypoint_orientations,
    keypoint_positions,
    list_keypoint_maps,
    load_keypoint_map,
)
from .load import find_asf, load_motion

__all__ = [
    "DARIUSH_KEYPOINTS",
    "KEYPOINT_NAMES",
    "Butterworth",
    "CardinalSpline",
    "HumanMotion",
    "KeypointMap",
    "KeypointMapError",
    "KeypointSource",
    "MotionError",
    "MotionFormatError",
    "UnknownMotionJointError",
    "find_asf",
    "guess_keypoint_map",
    "keypoint_orientations",
    "keypoint_positions",
    "list_keypoint_maps",
    "load_keypoint_map",
    "load_motion",
    "read_amc",
    "read_asf",
    "read_asf_amc",
    "read_bvh",
    "read_c3d",
]
