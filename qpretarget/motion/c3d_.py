# SPDX-License-Identifier: Apache-2.0
"""C3D marker reader built on the PyPI ``c3d`` package (named ``c3d_`` so it never shadows it).

Markers become points with parent -1 and no orientation. Units come from ``POINT:UNITS``
(``mm`` -> 0.001 m). Samples the file marks invalid (residual < 0) become NaN; no frame and no
marker is dropped. Analog channels (force plates, EMG) are not part of a
:class:`~qpretarget.motion.human_motion.HumanMotion`; their count is kept in ``meta``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..errors import missing_dependency
from ._kinematics import change_up_axis
from .human_motion import HumanMotion, MotionFormatError

if TYPE_CHECKING:
    from .keypoints import KeypointMap

_UNITS = {"mm": 0.001, "cm": 0.01, "dm": 0.1, "m": 1.0}


def _labels(reader: Any, count: int) -> tuple[list[str], list[int]]:
    labels: list[str] = []
    for key in ["POINT:LABELS"] + [f"POINT:LABELS{k}" for k in range(2, 100)]:
        param = reader.get(key)
        if param is None:
            break
        labels.extend(str(s).strip() for s in param.string_array)
    labels = labels[:count]
    unnamed = []
    for i in range(count):
        if i >= len(labels):
            labels.append("")
        if not labels[i]:
            labels[i] = f"point_{i + 1}"
            unnamed.append(i)
    seen: dict[str, int] = {}
    for i, label in enumerate(labels):
        if label in seen:
            seen[label] += 1
            labels[i] = f"{label}#{seen[label]}"
        else:
            seen[label] = 1
    return labels, unnamed


@dataclass
class _C3dPoints:
    """The 3D points of a C3D file as stored (file units, lab axes)."""

    data: np.ndarray  # (frames, points, 4): x, y, z, residual (< 0: invalid sample)
    first_frame: int
    rate: float  # POINT:RATE [Hz]
    units: str  # POINT:UNITS, lower case, "" when absent
    labels: list[str]
    unnamed: list[int]  # points that had no label
    analog_used: int
    analog_rate: float

    @property
    def num_frames(self) -> int:
        return self.data.shape[0]


def _read_points(path: Path, reader_class: Any) -> _C3dPoints:
    """Header, labels and every frame of the points; a truncated file is an error."""
    with path.open("rb") as handle:
        try:
            reader = reader_class(handle)
        # The c3d package raises bare ValueError, AssertionError or struct.error on bad input.
        except Exception as exc:
            raise MotionFormatError(path, f"not a readable C3D file: {exc}") from None
        count = int(reader.point_used)
        if count == 0:
            raise MotionFormatError(path, "the file holds no 3D points (POINT:USED = 0)")
        first, last = int(reader.first_frame), int(reader.last_frame)
        expected = last - first + 1
        rate = float(reader.point_rate)
        units_param = reader.get("POINT:UNITS")
        units = units_param.string_value.strip().lower() if units_param is not None else ""
        labels, unnamed = _labels(reader, count)
        data = np.empty((expected, count, 4))
        read = 0
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _, points, _ in reader.read_frames(copy=False):
                if read == expected:
                    read += 1
                    break
                data[read] = points[:, :4]
                read += 1
        if read != expected:
            detail = f" ({' '.join(str(caught[0].message).split())})" if caught else ""
            raise MotionFormatError(
                path,
                f"header says frames {first}..{last} ({expected} frames), found {read}; "
                f"the file is truncated{detail}",
                frame=first + min(read, expected),
            )
        return _C3dPoints(
            data, first, rate, units, labels, unnamed, int(reader.analog_used),
            float(reader.analog_rate),
        )  # fmt: skip


def read_c3d(
    path: str | Path,
    *,
    marker_map: KeypointMap | str | Path | Mapping[str, Any] | None = None,
    length_scale: float | None = None,
    up_axis: Literal["y", "z"] = "z",
) -> HumanMotion:
    """Read the 3D points of a C3D file into a :class:`HumanMotion` (metres, z up).

    Args:
        path: The ``.c3d`` file.
        marker_map: ``None`` returns every marker under its full label (``Daphnee:ASISr``; look it
            up as ``"ASISr"`` too, see :meth:`HumanMotion.index`). Otherwise a key-point map
            (bundled name such as ``"opensim_walking"``, YAML path, dict or
            :class:`~qpretarget.motion.keypoints.KeypointMap`) whose ``keypoints`` name marker
            labels or lists of labels to average: the motion then holds one point per key-point.
        length_scale: Metres per file unit; ``None`` reads ``POINT:UNITS`` (mm, cm, dm, m).
        up_axis: Up axis of the lab frame. Both bundled files are z up (``POINT:Y_SCREEN = +Z``).

    Returns:
        Markers or key-points, ``t = k / point_rate`` from the first frame of the file.

    Raises:
        MotionFormatError: Unreadable file, unknown units, or fewer frames than the header says.
        UnknownMotionJointError: ``marker_map`` names a marker the file does not have.
    """
    try:
        import c3d
    except ImportError:
        raise missing_dependency("mocap", "reading C3D files (the c3d package)") from None
    path = Path(path)
    stored = _read_points(path, c3d.Reader)
    rate, units, labels, expected = stored.rate, stored.units, stored.labels, stored.num_frames
    data, first, unnamed, count = stored.data, stored.first_frame, stored.unnamed, len(labels)
    if not (math.isfinite(rate) and rate > 0):
        raise MotionFormatError(path, f"POINT:RATE must be positive, found {rate}")
    scale = _length_scale(path, units, length_scale)
    positions = data[:, :, :3] * scale
    missing = data[:, :, 3] < 0
    positions[missing] = np.nan
    positions, _, _ = change_up_axis(positions, None, up_axis)
    motion = HumanMotion(
        t=np.arange(expected) / rate,
        names=tuple(labels),
        positions=positions,
        parents=(-1,) * count,
        orientations=None,
        rate=rate,
        source=str(path),
        meta={
            "format": "c3d",
            "length_scale": scale,
            "length_unit": units or "explicit",
            "up_axis": up_axis,
            "first_frame": first,
            "missing_fraction": float(missing.mean()),
            "unnamed_points": [labels[i] for i in unnamed],
            "analog_channels": stored.analog_used,
            "analog_rate": stored.analog_rate,
        },
    )
    if marker_map is None:
        return motion
    return _keypoints(motion, marker_map)


def _length_scale(path: Path, units: str, length_scale: float | None) -> float:
    """Metres per file unit: ``length_scale``, or the one ``POINT:UNITS`` names."""
    if length_scale is not None:
        return float(length_scale)
    if units not in _UNITS:
        raise MotionFormatError(
            path,
            f"unknown POINT:UNITS {units!r}; expected one of {sorted(_UNITS)}, "
            "or pass length_scale=<metres per file unit>",
        )
    return _UNITS[units]


def _keypoints(
    motion: HumanMotion, marker_map: KeypointMap | str | Path | Mapping[str, Any]
) -> HumanMotion:
    """The motion with one point per key-point of ``marker_map`` (averaged markers)."""
    from .keypoints import load_keypoint_map

    kmap = load_keypoint_map(marker_map)
    points = kmap.positions(motion)
    return motion.with_positions(
        list(points),
        np.stack(list(points.values()), axis=1),
        meta={"keypoint_map": kmap.name},
    )
