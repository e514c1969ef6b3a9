# SPDX-License-Identifier: Apache-2.0
"""Biovision Hierarchy (BVH) reader: any skeleton, any channel order, End Sites as joints.

Conventions (see ``docs/motion.md``):

* ``CHANNELS ... Zrotation Yrotation Xrotation`` means :math:`L = R_z R_y R_x`: rotations
  compose left to right in the order listed, angles in degrees.
* Position channels replace the matching component of the joint's ``OFFSET`` (the MotionBuilder
  and Blender reading); the CMU files have zero root offsets, so both readings agree there.
* Each ``End Site`` becomes a joint named ``<parent>_end`` (``<parent>_end2`` ... if a joint has
  several, or if the name is taken) with the parent's orientation.
* Lengths are multiplied by ``length_scale`` [m / file unit]; see :func:`read_bvh` for the
  ``"auto"`` rule. The world is converted to z up with :data:`~._kinematics.Y_UP_TO_Z_UP`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, NoReturn

import numpy as np

from ._kinematics import euler_product, forward_kinematics, skeleton_motion
from .human_motion import HumanMotion, MotionFormatError

#: File units tried by ``length_scale="auto"``: name -> metres per file unit.
LENGTH_UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "CMU unit (inch/0.45)": 0.0254 / 0.45,
}

#: Rest-pose size the ``"auto"`` rule aims at: largest extent of the skeleton in [m].
TYPICAL_HUMAN_EXTENT = 1.7

#: Position channels (lower case) -> component of the joint translation they set.
_POSITION_CHANNELS = {"xposition": 0, "yposition": 1, "zposition": 2}
#: Rotation channels (lower case) -> axis of the elementary rotation.
_ROTATION_CHANNELS = {"xrotation": "x", "yrotation": "y", "zrotation": "z"}
_CHANNELS = {**_POSITION_CHANNELS, **_ROTATION_CHANNELS}


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    line: int
    channels: list[str] = field(default_factory=list)
    first_channel: int = 0
    is_end_site: bool = False


class _Tokens:
    """Whitespace tokens of the HIERARCHY section with their 1-based line numbers."""

    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.items: list[tuple[str, int]] = []
        self.motion_line = -1
        for number, line in enumerate(lines, start=1):
            words = line.replace("{", " { ").replace("}", " } ").split()
            if words and words[0].upper() == "MOTION":
                self.motion_line = number
                break
            self.items.extend((w, number) for w in words)
        self.pos = 0

    def peek(self) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise MotionFormatError(self.path, "unexpected end of the HIERARCHY section", line=last)
        return self.items[self.pos]

    def take(self) -> tuple[str, int]:
        item = self.peek()
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        token, line = self.take()
        if token.upper() != word.upper():
            raise MotionFormatError(self.path, f"expected {word!r}, found {token!r}", line=line)
        return line

    def rest_of_line(self, line: int) -> list[str]:
        words = []
        while self.pos < len(self.items) and self.items[self.pos][1] == line:
            words.append(self.items[self.pos][0])
            self.pos += 1
        return words

    def floats(self, count: int, what: str) -> np.ndarray:
        values = []
        for _ in range(count):
            token, line = self.take()
            try:
                value = float(token)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise MotionFormatError(
                    self.path, f"expected {count} numbers for {what}, found {token!r}", line=line
                ) from None
            values.append(value)
        return np.array(values)


def _parse_joint(tokens: _Tokens, joints: list[_Joint], parent: int, keyword_line: int) -> None:
    words = tokens.rest_of_line(keyword_line)
    if not words:
        raise MotionFormatError(tokens.path, "joint without a name", line=keyword_line)
    name = " ".join(words)
    tokens.expect("{")
    offset_line = tokens.expect("OFFSET")
    joint = _Joint(name, parent, tokens.floats(3, f"the OFFSET of {name!r}"), offset_line)
    index = len(joints)
    joints.append(joint)
    token, line = tokens.peek()
    if token.upper() == "CHANNELS":
        tokens.take()
        count_token, _ = tokens.take()
        listed = tokens.rest_of_line(line)
        if not count_token.isdigit():
            raise MotionFormatError(
                tokens.path,
                f"expected a channel count after CHANNELS, found {count_token!r}",
                line=line,
            )
        if int(count_token) != len(listed):
            raise MotionFormatError(
                tokens.path,
                f"CHANNELS of {name!r} says {count_token} channels but lists {len(listed)}: "
                f"{' '.join(listed)}",
                line=line,
            )
        for channel in listed:
            if channel.lower() not in _CHANNELS:
                raise MotionFormatError(
                    tokens.path,
                    f"unknown channel {channel!r} of {name!r}; expected X/Y/Z + position/rotation",
                    line=line,
                )
        joint.channels = listed
    while True:
        token, line = tokens.take()
        keyword = token.upper()
        if keyword == "JOINT":
            _parse_joint(tokens, joints, index, line)
        elif keyword == "END":
            tokens.expect("Site")
            tokens.expect("{")
            end_line = tokens.expect("OFFSET")
            end_offset = tokens.floats(3, f"the End Site OFFSET of {name!r}")
            tokens.expect("}")
            joints.append(_Joint("", index, end_offset, end_line, is_end_site=True))
        elif keyword == "}":
            return
        else:
            raise MotionFormatError(
                tokens.path,
                f"expected JOINT, End Site or '}}' inside {name!r}, found {token!r}",
                line=line,
            )


def _name_end_sites(joints: list[_Joint]) -> None:
    taken = {j.name for j in joints if not j.is_end_site}
    for joint in joints:
        if not joint.is_end_site:
            continue
        base = f"{joints[joint.parent].name}_end"
        name, k = base, 2
        while name in taken:
            name, k = f"{base}{k}", k + 1
        joint.name = name
        taken.add(name)


def _parse_hierarchy(path: Path, lines: list[str]) -> tuple[list[_Joint], int]:
    tokens = _Tokens(path, lines)
    if tokens.motion_line < 0:
        raise MotionFormatError(path, "no MOTION section (is this a BVH file?)")
    tokens.expect("HIERARCHY")
    joints: list[_Joint] = []
    while tokens.pos < len(tokens.items):
        token, line = tokens.take()
        if token.upper() != "ROOT":
            raise MotionFormatError(path, f"expected ROOT or MOTION, found {token!r}", line=line)
        _parse_joint(tokens, joints, -1, line)
    if not joints:
        raise MotionFormatError(path, "the HIERARCHY section holds no ROOT", line=1)
    names = [j.name for j in joints if not j.is_end_site]
    for joint in joints:
        if not joint.is_end_site and names.count(joint.name) > 1:
            raise MotionFormatError(
                path, f"joint name {joint.name!r} is used more than once", line=joint.line
            )
    _name_end_sites(joints)
    first = 0
    for joint in joints:
        joint.first_channel = first
        first += len(joint.channels)
    return joints, tokens.motion_line


_FRAMES = re.compile(r"^\s*Frames\s*:\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME = re.compile(r"^\s*Frame\s+Time\s*:\s*(\S+)\s*$", re.IGNORECASE)


def _parse_motion(
    path: Path, lines: list[str], motion_line: int, num_channels: int
) -> tuple[np.ndarray, float]:
    """Channel values ``(frames, num_channels)`` and the frame time [s] of the MOTION section."""
    num_frames, frame_time = _motion_header(path, lines, motion_line)
    first_row_line = motion_line + 3
    rows = _data_rows(path, lines, motion_line, num_frames, num_channels)
    try:
        values = np.array(" ".join(rows).split(), dtype=float)
    except ValueError:
        _raise_bad_row(path, lines, first_row_line, rows)
    if not np.all(np.isfinite(values)):
        _raise_bad_row(path, lines, first_row_line, rows)
    return values.reshape(num_frames, num_channels), frame_time


#: Longest plausible frame period [s]: beyond it the header is corrupt (a 1e30 s frame time once
#: went through and broke every later time computation).
MAX_FRAME_TIME = 10.0


def _motion_header(path: Path, lines: list[str], motion_line: int) -> tuple[int, float]:
    """``Frames:`` and ``Frame Time:`` (the two lines after ``MOTION``), checked."""

    def header(offset: int, pattern: re.Pattern[str], what: str) -> str:
        number = motion_line + offset
        text = lines[number - 1] if number <= len(lines) else "<end of file>"
        match = pattern.match(text)
        if not match:
            raise MotionFormatError(path, f"expected {what!r}, found {text.strip()!r}", line=number)
        return match.group(1)

    frames_text = header(1, _FRAMES, "Frames: <count>")
    time_text = header(2, _FRAME_TIME, "Frame Time: <seconds>")
    try:
        num_frames = int(frames_text)
    except ValueError:
        raise MotionFormatError(
            path, f"Frames must be an integer, found {frames_text!r}", line=motion_line + 1
        ) from None
    try:
        frame_time = float(time_text)
    except ValueError:
        frame_time = math.nan
    if not 0 < frame_time <= MAX_FRAME_TIME:
        raise MotionFormatError(
            path,
            f"Frame Time must be a positive number of seconds up to {MAX_FRAME_TIME:g}, found "
            f"{time_text!r}",
            line=motion_line + 2,
        )
    if num_frames < 1:
        raise MotionFormatError(
            path, f"Frames must be at least 1, found {num_frames}", line=motion_line + 1
        )
    return num_frames, frame_time


def _data_rows(
    path: Path, lines: list[str], motion_line: int, num_frames: int, num_channels: int
) -> list[str]:
    """The ``num_frames`` non-blank data lines, each with ``num_channels`` words."""
    rows: list[str] = []
    for number in range(motion_line + 3, len(lines) + 1):
        text = lines[number - 1]
        count = len(text.split())
        if count == 0:
            continue  # blank lines carry no frame
        if len(rows) == num_frames:
            raise MotionFormatError(
                path,
                f"more data rows than 'Frames: {num_frames}' (line {motion_line + 1}); "
                "expected the file to end here",
                line=number,
            )
        if count != num_channels:
            raise MotionFormatError(
                path,
                f"expected {num_channels} channel values (the HIERARCHY declares "
                f"{num_channels} channels), found {count}",
                line=number,
                frame=len(rows) + 1,
            )
        rows.append(text)
    if len(rows) < num_frames:
        raise MotionFormatError(
            path,
            f"motion section is truncated: 'Frames: {num_frames}' (line {motion_line + 1}) but "
            f"only {len(rows)} data rows before the end of the file",
            line=len(lines),
        )
    return rows


def _raise_bad_row(path: Path, lines: list[str], first_row_line: int, rows: list[str]) -> NoReturn:
    """Raise for the first data row holding a word that is not a finite number."""
    for i, text in enumerate(rows):
        try:
            ok = bool(np.all(np.isfinite(np.array(text.split(), dtype=float))))
        except ValueError:
            ok = False
        if not ok:
            raise MotionFormatError(
                path,
                "expected finite numbers, found "
                f"{[w for w in text.split() if not _is_finite_number(w)][:3]}",
                line=_row_line(lines, first_row_line, i),
                frame=i + 1,
            )
    raise AssertionError("a row failed to parse but every word is a finite number")


def _is_finite_number(word: str) -> bool:
    try:
        return math.isfinite(float(word))
    except ValueError:
        return False


def _row_line(lines: list[str], first_row_line: int, row: int) -> int:
    seen = -1
    for number in range(first_row_line, len(lines) + 1):
        if lines[number - 1].split():
            seen += 1
            if seen == row:
                return number
    return len(lines)


def rate_from_frame_time(frame_time: float) -> float:
    """Frame rate in [Hz] from a frame period, snapped to an integer when within 1e-5 of one.

    BVH files print the period with 5-8 digits (``0.0083333`` for 120 Hz), so the exact inverse
    is off by a few parts per million; snapping keeps a 120 Hz clip at exactly 120 Hz.
    """
    rate = 1.0 / frame_time
    nearest = round(rate)
    if nearest > 0 and abs(rate - nearest) <= 1e-5 * rate:
        return float(nearest)
    return rate


def guess_length_scale(extent: float) -> tuple[float, str]:
    """Pick the file unit that makes a skeleton of this rest-pose extent human-sized.

    Tries each unit of :data:`LENGTH_UNITS` and keeps the one whose extent in metres is closest
    to :data:`TYPICAL_HUMAN_EXTENT` on a log scale. Neighbouring units differ by at least a
    factor 2.2, so adult skeletons (0.98-2.9 m) are never ambiguous.

    Args:
        extent: Largest axis-aligned extent of the rest pose, in file units.

    Returns:
        ``(length_scale, unit_name)``.

    Raises:
        ValueError: If no unit gives an extent between 0.98 and 2.9 m.
    """
    if not extent > 0:
        raise ValueError(
            "cannot guess the length unit of a skeleton with zero rest-pose extent; "
            "pass length_scale=<metres per file unit>"
        )
    best = min(LENGTH_UNITS, key=lambda u: abs(math.log(extent * LENGTH_UNITS[u] / 1.7)))
    scale = LENGTH_UNITS[best]
    if abs(math.log(extent * scale / TYPICAL_HUMAN_EXTENT)) > 0.55:
        raise ValueError(
            f"rest-pose extent {extent:g} file units does not look human in any known unit "
            f"({', '.join(LENGTH_UNITS)}); pass length_scale=<metres per file unit>, "
            "e.g. 0.0564444 for CMU files or 0.01 for centimetres"
        )
    return scale, best


def read_bvh(
    path: str | Path,
    *,
    length_scale: float | Literal["auto"] | None = None,
    up_axis: Literal["y", "z"] = "y",
) -> HumanMotion:
    r"""Read a BVH file into a :class:`HumanMotion` (metres, z up).

    Args:
        path: The ``.bvh`` file.
        length_scale: Metres per file unit. ``None`` or ``"auto"`` picks the unit among
            :data:`LENGTH_UNITS` (m, cm, mm, inch, CMU unit = inch/0.45 = 0.0564444 m) that makes
            the rest pose about 1.7 m across (:func:`guess_length_scale`); the choice is stored
            in ``motion.meta["length_unit"]``. Give a number when you know the unit.
        up_axis: Axis that points up in the file: ``"y"`` (CMU and most BVH files) is converted
            with :math:`(x, y, z) \mapsto (z, x, y)`; ``"z"`` is kept as is.

    Returns:
        The motion: one joint per BVH joint and per End Site, world orientations of every joint
        relative to the rest pose (End Sites copy their parent's), ``t = k / rate``.

    Raises:
        MotionFormatError: Malformed file; the message names the line (and frame), the expected
            and the found content. Truncated motion sections and rows with the wrong number of
            values are errors, never padded or dropped.
        ValueError: Bad ``length_scale`` or ``up_axis``, or ``"auto"`` found no human-sized unit.
    """
    path = Path(path)
    lines = _read_lines(path)
    joints, motion_line = _parse_hierarchy(path, lines)
    num_channels = sum(len(j.channels) for j in joints)
    values, frame_time = _parse_motion(path, lines, motion_line, num_channels)
    num_frames = values.shape[0]

    parents = [j.parent for j in joints]
    offsets = np.array([j.offset for j in joints])
    rest_positions, _ = forward_kinematics(parents, list(offsets), [None] * len(joints))
    extent = float(np.ptp(rest_positions[0], axis=0).max())
    try:
        scale, unit = _length_scale(length_scale, extent)
    except ValueError as exc:  # an absurd or empty skeleton (corrupt OFFSETs): the file's fault
        raise MotionFormatError(path, str(exc)) from None
    translations, rotations = _joint_motions(joints, values, scale)
    return skeleton_motion(
        [j.name for j in joints],
        parents,
        translations,
        rotations,
        num_frames=num_frames,
        rate=rate_from_frame_time(frame_time),
        up_axis=up_axis,
        source=str(path),
        meta={
            "format": "bvh",
            "length_scale": scale,
            "length_unit": unit,
            "up_axis": up_axis,
            "frame_time": frame_time,
            "first_frame": 1,
            "end_sites": [j.name for j in joints if j.is_end_site],
            "channels": {j.name: list(j.channels) for j in joints if j.channels},
        },
    )


def _read_lines(path: Path) -> list[str]:
    """Lines of a text file; a clear error for a binary one."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise MotionFormatError(
            path, f"not a text file ({exc.reason} at byte {exc.start})"
        ) from None
    return text.splitlines()


def _length_scale(length_scale: float | str | None, extent: float) -> tuple[float, str]:
    """``(metres per file unit, how it was chosen)`` for ``read_bvh``'s ``length_scale``."""
    if length_scale is None or length_scale == "auto":
        scale, unit = guess_length_scale(extent)
        return scale, f"{unit} (auto: rest-pose extent {extent:.4g} file units)"
    scale = float(length_scale)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"length_scale must be a positive number or 'auto', got {length_scale!r}")
    return scale, "explicit"


def _joint_motions(
    joints: list[_Joint], values: np.ndarray, scale: float
) -> tuple[list[np.ndarray], list[np.ndarray | None]]:
    """Per joint: translation in its parent [m] (``(3,)`` or ``(T, 3)``) and rotation stack.

    Position channels replace the matching ``OFFSET`` component; rotation channels compose left
    to right (``Zrotation Yrotation Xrotation`` is :math:`R_z R_y R_x`), angles in degrees.
    """
    num_frames = values.shape[0]
    translations: list[np.ndarray] = []
    rotations: list[np.ndarray | None] = []
    for joint in joints:
        columns = values[:, joint.first_channel : joint.first_channel + len(joint.channels)]
        translation: np.ndarray = joint.offset * scale
        axes: list[str] = []
        angle_columns: list[int] = []
        for k, channel in enumerate(joint.channels):
            component = _POSITION_CHANNELS.get(channel.lower())
            if component is not None:
                if translation.ndim == 1:
                    translation = np.tile(translation, (num_frames, 1))
                translation[:, component] = columns[:, k] * scale
            else:
                axes.append(_ROTATION_CHANNELS[channel.lower()])
                angle_columns.append(k)
        translations.append(translation)
        rotations.append(
            euler_product(np.deg2rad(columns[:, angle_columns]), axes) if axes else None
        )
    return translations, rotations
