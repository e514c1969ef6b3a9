# SPDX-License-Identifier: Apache-2.0
r"""Key-point files: named 3-D joint positions and a frame rate, from any pose source.

For motion that does not come from a mocap skeleton file: an SMPL/SMPL-X forward pass over AMASS
parameters, a markerless pose estimator, another retargeting tool's export. Two layouts
(docs/formats.md, "Key-point files"):

* **npz**: ``names`` (J,) strings; ``positions`` (T, J, 3); ``fps`` (scalar, Hz) or ``t`` (T,)
  strictly increasing times [s]; optional ``up`` (``"z"``, default, or ``"y"``) and ``units``
  (``"m"``, default, ``"cm"`` or ``"mm"``).
* **csv**: optional comment lines ``# fps: 30``, ``# up: y``, ``# units: mm``; then a header
  ``t`` (or ``time``, seconds; or ``frame`` with ``# fps:``) followed by ``NAME_x, NAME_y,
  NAME_z`` for each joint (``NAME.x`` also accepted); one row per frame. Empty cells or ``nan``
  are missing samples.

A y-up file is turned z-up by the rotation of +90 deg about x, :math:`(x, y, z) \mapsto
(x, -z, y)`. Names that are already key-point names (``waist``, ``left_wrist``, ...) need no
map; SMPL/SMPL-X joint names use the bundled ``smpl`` map; any other naming takes a YAML map as
for BVH skeletons.
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path
from typing import Any

import numpy as np

from .human_motion import HumanMotion, MotionFormatError

#: Length of one file unit in metres.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}

_COLUMN = re.compile(r"^(?P<name>.+?)[_.](?P<axis>[xyzXYZ])$")
_KEYS = ("names", "positions", "fps", "t", "up", "units")


def read_positions(path: str | Path) -> HumanMotion:
    """Read a key-point file (``.npz`` or ``.csv``, layouts in the module docstring).

    Raises:
        MotionFormatError: The file does not follow the layout; the message says what is
            missing or wrong and what was expected.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        names, positions, t, up, units = _read_npz(path)
    elif suffix == ".csv":
        names, positions, t, up, units = _read_csv(path)
    else:
        raise MotionFormatError(path, "a key-point file must end in .npz or .csv")
    return _motion(path, names, positions, t, up, units)


def _motion(
    path: Path, names: list[str], positions: np.ndarray, t: np.ndarray, up: str, units: str
) -> HumanMotion:
    """Check the arrays, convert to metres and z up, and build the motion."""
    if up not in ("z", "y"):
        raise MotionFormatError(path, f"up must be 'z' or 'y', got {up!r}")
    if units not in UNITS:
        raise MotionFormatError(path, f"units must be one of {sorted(UNITS)}, got {units!r}")
    if positions.ndim != 3 or positions.shape[1:] != (len(names), 3):
        raise MotionFormatError(
            path, f"positions must be (T, {len(names)}, 3) for {len(names)} names, "
            f"got {positions.shape}"
        )  # fmt: skip
    if len(positions) == 0:
        raise MotionFormatError(path, "the file has no frame")
    if len(set(names)) != len(names):
        raise MotionFormatError(path, "joint names must be unique")
    if np.any(np.isinf(positions)):
        raise MotionFormatError(path, "positions hold inf values (use NaN for missing samples)")
    if not np.all(np.isfinite(t)) or (len(t) > 1 and not np.all(np.diff(t) > 0)):
        raise MotionFormatError(path, "times must be finite and strictly increasing")
    p = positions.astype(float) * UNITS[units]
    if up == "y":
        p = np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 30.0
    return HumanMotion(
        t=t - t[0],
        names=tuple(names),
        positions=p,
        parents=(-1,) * len(names),
        rate=rate,
        source=str(path),
        meta={"format": "keypoints", "up_axis": up, "length_scale": UNITS[units]},
    )


def _times(path: Path, n: int, fps: Any, t: Any) -> np.ndarray:
    """Frame times from ``t`` or ``fps``."""
    if t is not None:
        times = np.asarray(t, dtype=float).reshape(-1)
        if times.shape != (n,):
            raise MotionFormatError(path, f"t must have {n} entries (one per frame)")
        return times
    if fps is None:
        raise MotionFormatError(path, "give the frame rate: an 'fps' entry or a time column 't'")
    rate = float(np.asarray(fps, dtype=float).reshape(-1)[0])
    if not np.isfinite(rate) or rate <= 0:
        raise MotionFormatError(path, f"fps must be a positive number, got {rate}")
    return np.arange(n) / rate


def _read_npz(path: Path) -> tuple[list[str], np.ndarray, np.ndarray, str, str]:
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise MotionFormatError(path, f"not a readable npz file ({exc})") from None
    if "q" in data and "positions" not in data:
        raise MotionFormatError(
            path, "this is a robot run (it has 'q'), not key-point positions; key-point files "
            "hold 'names', 'positions' and 'fps' (docs/formats.md)"
        )  # fmt: skip
    missing = [k for k in ("names", "positions") if k not in data]
    if missing:
        raise MotionFormatError(
            path, f"missing {missing}; a key-point npz holds 'names' (J,), 'positions' "
            f"(T, J, 3) and 'fps' or 't' (found {sorted(data)})"
        )  # fmt: skip
    names = [str(n) for n in np.asarray(data["names"]).reshape(-1)]
    try:
        positions = np.asarray(data["positions"], dtype=float)
    except (TypeError, ValueError):
        raise MotionFormatError(path, "positions must be numbers") from None
    t = _times(path, len(positions), data.get("fps"), data.get("t"))
    up = str(data["up"]) if "up" in data else "z"
    units = str(data["units"]) if "units" in data else "m"
    return names, positions, t, up, units


def _read_csv(path: Path) -> tuple[list[str], np.ndarray, np.ndarray, str, str]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MotionFormatError(path, f"not a readable text file ({exc})") from None
    settings: dict[str, str] = {}
    lines = text.splitlines()
    body_start = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if s.startswith("#"):
            key, _, value = s[1:].partition(":")
            settings[key.strip().lower()] = value.strip()
            body_start = i + 1
        elif s:
            break
    rows = list(csv.reader(io.StringIO("\n".join(lines[body_start:]))))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise MotionFormatError(path, "no header row (t, NAME_x, NAME_y, NAME_z, ...)")
    header = [h.strip() for h in rows[0]]
    time_col = header[0].lower() if header else ""
    if time_col not in ("t", "time", "frame"):
        raise MotionFormatError(
            path, f"the first column must be 't' (seconds) or 'frame', got {header[0]!r}", line=1
        )
    names, columns = _columns(path, header[1:])
    try:
        values = np.array(
            [[float(c) if c.strip() else np.nan for c in r] for r in rows[1:]], dtype=float
        ).reshape(len(rows) - 1, -1)
    except ValueError as exc:
        raise MotionFormatError(path, f"a value is not a number ({exc})") from None
    if values.shape[1] != len(header):
        raise MotionFormatError(path, f"rows must have {len(header)} values like the header")
    positions = values[:, 1:][:, columns].reshape(len(values), len(names), 3)
    t = (
        _times(path, len(values), settings.get("fps"), None)
        if time_col == "frame"
        else values[:, 0]
    )
    return names, positions, t, settings.get("up", "z"), settings.get("units", "m")


def _columns(path: Path, header: list[str]) -> tuple[list[str], list[int]]:
    """Joint names in order and the column index of each one's x, y, z."""
    where: dict[str, dict[str, int]] = {}
    for i, h in enumerate(header):
        m = _COLUMN.match(h)
        if m is None:
            raise MotionFormatError(path, f"column {h!r} is not NAME_x, NAME_y or NAME_z", line=1)
        where.setdefault(m["name"], {})[m["axis"].lower()] = i
    names = list(where)
    for n in names:
        if set(where[n]) != {"x", "y", "z"}:
            missing = sorted({"x", "y", "z"} - set(where[n]))
            raise MotionFormatError(path, f"joint {n!r} lacks its {missing} column(s)", line=1)
    return names, [where[n][a] for n in names for a in "xyz"]


__all__ = ["UNITS", "read_positions"]
