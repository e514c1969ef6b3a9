# SPDX-License-Identifier: Apache-2.0
"""Key-point maps: YAML data saying which joints, markers or frames give each key-point.

A key-point is a named 3D point the retargeting tasks track (Dariush 2009 Fig. 2: waist,
shoulders, elbows, wrists, head; plus neck, hands, hips, knees, ankles, toes, heels). A map is
written once per skeleton or marker set; the format is documented in ``docs/motion.md``::

    name: cmu
    kind: skeleton            # skeleton | markers | robot
    description: CMU-ASF skeleton (BVH re-encodings and ASF/AMC)
    keypoints:
      waist: root             # one joint / marker / frame
      head: [head, head_end]  # mean of several
      left_hand: {from: lwrist, offset: [0.0, 0.1, 0.0]}   # offset in the joint frame [m]
      right_hand: {extend: [RightForeArm, RightHand], by: 0.5}  # b + 0.5 (b - a)
    orientations:             # optional: name -> joint whose world rotation is used
      torso: thorax

Bundled maps live in ``qpretarget/motion/keypoint_maps/``; :func:`load_keypoint_map` takes a
bundled name or a path, :func:`guess_keypoint_map` picks a bundled map from a motion's names.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from ..yamlio import read_yaml_file
from .human_motion import MotionError

if TYPE_CHECKING:
    from .human_motion import HumanMotion


def _sides(*parts: str) -> tuple[str, ...]:
    """``left_<part>``, ``right_<part>`` of each part, in order."""
    return tuple(f"{side}_{part}" for part in parts for side in ("left", "right"))


#: Standard key-point names. Maps may define others; names one edit away from these are rejected
#: as probable typos.
KEYPOINT_NAMES: tuple[str, ...] = (
    "waist",
    "neck",
    "head",
    *_sides("shoulder", "elbow", "wrist", "hand", "hip", "knee", "ankle", "toe", "heel"),
)

#: The eight upper-body key-points of Dariush 2009 Fig. 2.
DARIUSH_KEYPOINTS: tuple[str, ...] = ("waist", *_sides("shoulder", "elbow", "wrist"), "head")

KEYPOINT_MAP_DIR = Path(__file__).resolve().parent / "keypoint_maps"

_KINDS = ("skeleton", "markers", "robot")
_TOP_KEYS = ("name", "kind", "description", "keypoints", "orientations")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class KeypointMapError(MotionError, ValueError):
    """A key-point map is malformed, cannot be found, or fits no motion."""


@dataclass(frozen=True)
class KeypointSource:
    """Where one key-point comes from.

    Attributes:
        points: Joint, marker or frame names; the key-point is their mean.
        offset: Optional ``(3,)`` offset in [m] in the frame of the single source point,
            added after rotating by that point's orientation.
        extend: With two points ``(a, b)``: the key-point is :math:`b + k (b - a)`, past ``b``
            along the segment from ``a`` by ``k`` times its length (YAML
            ``{extend: [a, b], by: k}``): a hand key-point past the wrist along the forearm for
            skeletons without a hand bone.
    """

    points: tuple[str, ...]
    offset: tuple[float, float, float] | None = None
    extend: float | None = None


@dataclass(frozen=True)
class KeypointMap:
    """A key-point map (see the module docstring for the YAML format).

    Attributes:
        name: Map name (file stem for bundled maps).
        keypoints: Key-point name -> source, in file order.
        orientations: Orientation name (``waist``, ``torso``, ``head``, ...) -> joint or frame.
        kind: ``"skeleton"``, ``"markers"`` or ``"robot"``.
        description: Free text.
        path: File it was read from, if any.
    """

    name: str
    keypoints: Mapping[str, KeypointSource]
    orientations: Mapping[str, str] = field(default_factory=dict)
    kind: str = "skeleton"
    description: str = ""
    path: str = ""

    def __repr__(self) -> str:
        """Name, kind and key-point names."""
        return (
            f"KeypointMap(name={self.name!r}, kind={self.kind!r}, "
            f"keypoints={list(self.keypoints)}, orientations={list(self.orientations)})"
        )

    def source_names(self) -> list[str]:
        """Every joint/marker/frame name the map refers to, without repeats, in file order."""
        names: list[str] = []
        for source in self.keypoints.values():
            names.extend(p for p in source.points if p not in names)
        names.extend(p for p in self.orientations.values() if p not in names)
        return names

    def evaluate(
        self,
        position_of: Callable[[str], np.ndarray],
        rotation_of: Callable[[str], np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        """Key-point positions from any source of named points.

        Args:
            position_of: Name -> ``(..., 3)`` position (a motion's joint, a robot frame, ...).
            rotation_of: Name -> ``(..., 3, 3)`` rotation; needed only for entries with an offset.

        Returns:
            Key-point -> ``(..., 3)``; a mean is NaN wherever one of its points is NaN.

        Raises:
            KeypointMapError: An entry has an offset and ``rotation_of`` is ``None``.
        """
        out: dict[str, np.ndarray] = {}
        for keypoint, source in self.keypoints.items():
            points = [np.asarray(position_of(p), dtype=float) for p in source.points]
            if source.extend is not None:
                a, b = points
                out[keypoint] = b + source.extend * (b - a)
                continue
            position = points[0].copy() if len(points) == 1 else np.mean(points, axis=0)
            if source.offset is not None:
                if rotation_of is None:
                    raise KeypointMapError(
                        f"key-point map {self.name!r}: {keypoint!r} has an offset, which needs the "
                        f"orientation of {source.points[0]!r}, but the data has no orientations"
                    )
                rotation = np.asarray(rotation_of(source.points[0]), dtype=float)
                position = position + rotation @ np.asarray(source.offset)
            out[keypoint] = position
        return out

    def positions(self, motion: HumanMotion) -> dict[str, np.ndarray]:
        """Key-point positions of a motion, ``(T, 3)`` each, in [m].

        Raises:
            UnknownMotionJointError: The map names a joint the motion does not have.
            KeypointMapError: An offset entry on a motion without orientations.
        """
        rotation_of = motion.joint_orientation if motion.orientations is not None else None
        return self.evaluate(motion.joint, rotation_of)

    def orientations_of(self, motion: HumanMotion) -> dict[str, np.ndarray]:
        """World rotations ``(T, 3, 3)`` of the map's ``orientations`` entries.

        Raises:
            UnknownMotionJointError: The map names a joint the motion does not have.
            ValueError: The map lists orientations and the motion has none.
        """
        return {name: motion.joint_orientation(j) for name, j in self.orientations.items()}

    def missing_in(self, names: list[str] | tuple[str, ...]) -> list[str]:
        """Source names of this map that a list of joint names lacks.

        A source without a ``prefix:`` also matches a single label ending in ``:source``.
        """
        present = set(names)
        stripped: dict[str, int] = {}
        for n in names:
            if ":" in n:
                key = n.rsplit(":", 1)[1]
                stripped[key] = stripped.get(key, 0) + 1
        return [s for s in self.source_names() if s not in present and stripped.get(s) != 1]

    # --------------------------------------------------------------------------- construction

    @classmethod
    def from_dict(
        cls,
        data: Mapping[str, Any],
        *,
        name: str = "",
        path: str = "",
        lines: Mapping[tuple[str, ...], int] | None = None,
    ) -> KeypointMap:
        """Build and validate a map from parsed YAML (or a plain dict).

        Args:
            data: The mapping with the keys of the YAML format.
            name: Name used when ``data`` has none.
            path: File name for messages.
            lines: Key path -> line number, for messages.

        Raises:
            KeypointMapError: Unknown key, wrong type, empty list, bad offset, misspelt
                key-point name; the message names the file, key path and line.
        """
        lines = lines or {}

        def fail(keys: tuple[str, ...], message: str) -> KeypointMapError:
            where = path or "key-point map"
            line = lines.get(keys)
            if line is not None:
                where += f", line {line}"
            key_path = ".".join(keys)
            return KeypointMapError(f"{where}: {key_path + ': ' if key_path else ''}{message}")

        if not isinstance(data, Mapping):
            raise fail(
                (), f"expected a mapping with keys {list(_TOP_KEYS)}, found {type(data).__name__}"
            )
        for key in data:
            if key not in _TOP_KEYS:
                close = difflib.get_close_matches(str(key), _TOP_KEYS, n=1)
                hint = f" Did you mean {close[0]!r}?" if close else ""
                raise fail((str(key),), f"unknown key.{hint} Known keys: {', '.join(_TOP_KEYS)}")
        kind = data.get("kind", "skeleton")
        if kind not in _KINDS:
            raise fail(("kind",), f"expected one of {list(_KINDS)}, found {kind!r}")
        raw_keypoints = data.get("keypoints")
        if not isinstance(raw_keypoints, Mapping) or not raw_keypoints:
            raise fail(("keypoints",), "expected a non-empty mapping key-point -> source")
        keypoints: dict[str, KeypointSource] = {}
        for keypoint, entry in raw_keypoints.items():
            keys = ("keypoints", str(keypoint))
            if not isinstance(keypoint, str) or not _NAME.match(keypoint):
                raise fail(keys, "key-point names must be identifiers such as 'left_wrist'")
            if keypoint not in KEYPOINT_NAMES:
                close = difflib.get_close_matches(keypoint, KEYPOINT_NAMES, n=1, cutoff=0.85)
                if close:
                    raise fail(
                        keys,
                        f"{keypoint!r} looks like a misspelling of the standard key-point "
                        f"{close[0]!r}; standard names: {', '.join(KEYPOINT_NAMES)}",
                    )
            keypoints[keypoint] = _parse_source(entry, keys, fail)
        raw_orientations = data.get("orientations") or {}
        if not isinstance(raw_orientations, Mapping):
            raise fail(("orientations",), "expected a mapping name -> joint")
        orientations: dict[str, str] = {}
        for key, joint in raw_orientations.items():
            if not isinstance(joint, str) or not joint:
                raise fail(("orientations", str(key)), f"expected one joint name, found {joint!r}")
            orientations[str(key)] = joint
        map_name = data.get("name", name)
        if not isinstance(map_name, str) or not map_name:
            raise fail(("name",), "expected a non-empty string")
        description = data.get("description", "")
        return cls(
            name=map_name,
            keypoints=keypoints,
            orientations=orientations,
            kind=kind,
            description=str(description).strip(),
            path=path,
        )


def _parse_source(
    entry: Any,
    keys: tuple[str, ...],
    fail: Callable[[tuple[str, ...], str], KeypointMapError],
) -> KeypointSource:
    offset = None
    if isinstance(entry, Mapping) and "extend" in entry:
        return _parse_extension(entry, keys, fail)
    if isinstance(entry, Mapping):
        unknown = [k for k in entry if k not in ("from", "offset")]
        if unknown or "from" not in entry:
            raise fail(
                keys,
                f"expected {{from: <name or list>, offset: [x, y, z]}}, found keys {list(entry)}",
            )
        raw_offset = entry.get("offset")
        entry = entry["from"]
        if raw_offset is not None:
            try:
                values = np.asarray(raw_offset, dtype=float)
            except (TypeError, ValueError):
                values = np.array([np.nan])
            if values.shape != (3,) or not np.all(np.isfinite(values)):
                raise fail(
                    keys + ("offset",), f"expected 3 finite numbers [m], found {raw_offset!r}"
                )
            offset = (float(values[0]), float(values[1]), float(values[2]))
    points = [entry] if isinstance(entry, str) else entry
    if (
        not isinstance(points, list)
        or not points
        or not all(isinstance(p, str) and p for p in points)
    ):
        raise fail(keys, f"expected a name or a non-empty list of names, found {entry!r}")
    if len(set(points)) != len(points):
        raise fail(keys, f"a name is repeated in {points}")
    if offset is not None and len(points) != 1:
        raise fail(keys, "an offset needs exactly one source point (its frame gives the axes)")
    return KeypointSource(points=tuple(points), offset=offset)


def _parse_extension(
    entry: Mapping[str, Any],
    keys: tuple[str, ...],
    fail: Callable[[tuple[str, ...], str], KeypointMapError],
) -> KeypointSource:
    """``{extend: [a, b], by: k}``: the point ``b + k (b - a)``."""
    unknown = [k for k in entry if k not in ("extend", "by")]
    if unknown or "by" not in entry:
        raise fail(keys, f"expected {{extend: [a, b], by: k}}, found keys {list(entry)}")
    points = entry["extend"]
    if (
        not isinstance(points, list)
        or len(points) != 2
        or not all(isinstance(p, str) and p for p in points)
        or points[0] == points[1]
    ):
        raise fail(keys + ("extend",), f"expected two different names [a, b], found {points!r}")
    by = entry["by"]
    if isinstance(by, bool) or not isinstance(by, (int, float)) or not np.isfinite(by):
        raise fail(keys + ("by",), f"expected a finite number, found {by!r}")
    return KeypointSource(points=(points[0], points[1]), extend=float(by))


def _key_lines(text: str) -> dict[tuple[str, ...], int]:
    """Key path -> 1-based line of every mapping key (two levels deep)."""
    try:
        root = yaml.compose(text)
    except yaml.YAMLError:
        return {}
    lines: dict[tuple[str, ...], int] = {}
    if not isinstance(root, yaml.MappingNode):
        return lines
    for key, value in root.value:
        lines[(str(key.value),)] = key.start_mark.line + 1
        if isinstance(value, yaml.MappingNode):
            for sub_key, sub_value in value.value:
                lines[(str(key.value), str(sub_key.value))] = sub_key.start_mark.line + 1
                if isinstance(sub_value, yaml.MappingNode):
                    for leaf, _ in sub_value.value:
                        path = (str(key.value), str(sub_key.value), str(leaf.value))
                        lines[path] = leaf.start_mark.line + 1
    return lines


def list_keypoint_maps() -> list[str]:
    """Names of the bundled key-point maps, sorted."""
    return sorted(p.stem for p in KEYPOINT_MAP_DIR.glob("*.yaml"))


def load_keypoint_map(
    name_or_path: KeypointMap | str | Path | Mapping[str, Any],
) -> KeypointMap:
    """Load a key-point map.

    Args:
        name_or_path: A bundled map name (see :func:`list_keypoint_maps`), a path to a YAML
            file, a dict in the YAML format, or a :class:`KeypointMap` (returned as is).

    Raises:
        KeypointMapError: Unknown name (with close matches), unreadable YAML, invalid content.
    """
    if isinstance(name_or_path, KeypointMap):
        return name_or_path
    if isinstance(name_or_path, Mapping):
        return KeypointMap.from_dict(name_or_path, name="<dict>")
    text_name = str(name_or_path)
    path = Path(name_or_path)
    if not path.suffix and not path.exists():
        path = KEYPOINT_MAP_DIR / f"{text_name}.yaml"
        if not path.exists():
            known = list_keypoint_maps()
            close = difflib.get_close_matches(text_name, known, n=3, cutoff=0.5)
            hint = f" Did you mean {', '.join(map(repr, close))}?" if close else ""
            raise KeypointMapError(
                f"no bundled key-point map {text_name!r}.{hint} Bundled maps: "
                f"{', '.join(known)}; or pass the path of a YAML file (format in docs/motion.md)."
            )
    text, data = read_yaml_file(path, KeypointMapError, "key-point map file")
    return KeypointMap.from_dict(data, name=path.stem, path=str(path), lines=_key_lines(text))


def identity_keypoint_map(names: list[str] | tuple[str, ...]) -> KeypointMap:
    """Map each of the given key-point names to the joint of the same name."""
    return KeypointMap(
        name="identity",
        keypoints={n: KeypointSource(points=(n,)) for n in names},
        kind="markers",
        description="points already named after key-points",
    )


def guess_keypoint_map(motion: HumanMotion) -> KeypointMap:
    """Pick the bundled map whose every source name is in the motion.

    A motion whose points are already key-points (``read_c3d(..., marker_map=...)``) gets the
    identity map. When several maps fit, the one with the most source names wins.

    Raises:
        KeypointMapError: No bundled map fits; the message lists the closest map and the names
            it misses, and how to write a map.
    """
    if motion.meta.get("keypoint_map") or all(n in KEYPOINT_NAMES for n in motion.names):
        return identity_keypoint_map([n for n in motion.names if n in KEYPOINT_NAMES])
    scored = []
    for map_name in list_keypoint_maps():
        kmap = load_keypoint_map(map_name)
        missing = kmap.missing_in(motion.names)
        scored.append((len(missing), -len(kmap.source_names()), map_name, kmap, missing))
    scored.sort(key=lambda s: s[:3])
    best_missing, _, best_name, best, missing = scored[0]
    if best_missing == 0:
        return best
    raise KeypointMapError(
        f"no bundled key-point map fits {motion.source or 'the motion'} "
        f"({len(motion.names)} joints, e.g. {list(motion.names[:5])}); closest is {best_name!r}, "
        f"which lacks {missing[:8]}. Write a YAML map (format in docs/motion.md) and pass its "
        "path, e.g. keypoint_positions(motion, 'my_skeleton.yaml')."
    )


def resolve_keypoint_map(
    kmap: KeypointMap | str | Path | Mapping[str, Any] | None, motion: HumanMotion
) -> KeypointMap:
    """``kmap`` loaded with :func:`load_keypoint_map`, or guessed for ``motion`` when ``None``."""
    return guess_keypoint_map(motion) if kmap is None else load_keypoint_map(kmap)


KeypointMapLike = KeypointMap | str | Path | Mapping[str, Any] | None


def keypoint_positions(motion: HumanMotion, kmap: KeypointMapLike = None) -> dict[str, np.ndarray]:
    """Key-point positions of ``motion`` in [m], one ``(T, 3)`` array per key-point of the map.

    Args:
        motion: The human motion.
        kmap: A :class:`KeypointMap`, the name of a bundled map (``"cmu"``, ``"cgspeed"``, ...),
            a path to a YAML map, a dict in the YAML format, or ``None`` to pick a bundled map
            with :func:`guess_keypoint_map`.

    Returns:
        Key-point name -> positions. A key-point averaging several points is NaN at frames where
        any of them is NaN.

    Raises:
        UnknownMotionJointError: If the map names a joint the motion does not have.
        KeypointMapError: If the map cannot be loaded or guessed.
    """
    return resolve_keypoint_map(kmap, motion).positions(motion)


def keypoint_orientations(
    motion: HumanMotion, kmap: KeypointMapLike = None
) -> dict[str, np.ndarray]:
    """Key-point orientations listed in the map's ``orientations`` section, ``(T, 3, 3)`` each.

    Args:
        motion: The human motion (with joint orientations: BVH, ASF/AMC).
        kmap: As for :func:`keypoint_positions`.

    Raises:
        UnknownMotionJointError: If the map names a joint the motion does not have.
        ValueError: If the map lists orientations but the motion has none.
    """
    return resolve_keypoint_map(kmap, motion).orientations_of(motion)


__all__ = [
    "DARIUSH_KEYPOINTS",
    "KEYPOINT_MAP_DIR",
    "KEYPOINT_NAMES",
    "KeypointMap",
    "KeypointMapError",
    "KeypointSource",
    "guess_keypoint_map",
    "identity_keypoint_map",
    "keypoint_orientations",
    "keypoint_positions",
    "list_keypoint_maps",
    "load_keypoint_map",
    "resolve_keypoint_map",
]
