# SPDX-License-Identifier: Apache-2.0
r"""Acclaim ASF (skeleton) + AMC (motion) reader, the original format of the CMU database.

Forward kinematics follows the Acclaim convention used by CMU's mocapPlayer (and by the BVH
re-encodings in ``shared/data/mocap``): for bone :math:`b` with parent :math:`p`,

.. math::

    G_b = G_p \, C_b M_b C_b^{-1}, \qquad x_b^{\text{end}} = x_b + G_b \, d_b \ell_b,

where :math:`C_b` is the ASF ``axis`` rotation, :math:`M_b` the AMC rotation, :math:`d_b` the ASF
``direction`` (world rest-pose coordinates), :math:`\ell_b` the ``length`` and :math:`x_b` the start
of the bone (the end of its parent; the root position for the root's children). Rotation orders
are *application* orders: ``axis ... XYZ`` and ``dof rx ry rz`` mean
:math:`R_z R_y R_x` (x applied first).

Output joints match :func:`~qpretarget.motion.bvh.read_bvh` on the CMU re-encodings: ``root``,
then one joint per bone at its proximal end, depth first in ``:hierarchy`` order, and for every
leaf bone an extra joint ``<bone>_end`` at its distal end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ._kinematics import euler_product, skeleton_motion
from .human_motion import HumanMotion, MotionFormatError

_ROTATION_DOFS = {"rx": "x", "ry": "y", "rz": "z"}
_TRANSLATION_DOFS = {"tx": 0, "ty": 1, "tz": 2}


@dataclass
class AsfBone:
    """One ``begin ... end`` block of an ASF ``:bonedata`` section (file units, degrees/radians).

    Attributes:
        name: Bone name.
        direction: Unit direction of the bone in world rest-pose coordinates, ``(3,)``.
        length: Length in file units.
        axis: ``axis`` angles, one per letter of ``axis_order``.
        axis_order: Letters such as ``"XYZ"``; the first is applied first.
        dof: Degrees of freedom in AMC order, e.g. ``["rx", "ry", "rz"]``.
        limits: ``(low, high)`` per dof, as written.
        line: Line of the ``begin`` keyword.
    """

    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray
    axis_order: str
    dof: list[str] = field(default_factory=list)
    limits: list[tuple[float, float]] = field(default_factory=list)
    line: int = 0


@dataclass
class AsfSkeleton:
    """Content of an ASF file.

    Attributes:
        path: The file.
        length_unit: ``:units length`` factor (CMU: 0.45, i.e. 1 unit = 1/0.45 inch).
        angle_unit: ``"deg"`` or ``"rad"`` (``:units angle``).
        root_order: Root dofs in AMC order, e.g. ``["tx", "ty", "tz", "rx", "ry", "rz"]``.
        root_axis: Letters giving the order of ``root_orientation``.
        root_position: ``:root position``, file units.
        root_orientation: ``:root orientation``, angle unit.
        bones: Bones by name.
        children: Children of each bone (and of ``"root"``) in ``:hierarchy`` order.
    """

    path: Path
    length_unit: float
    angle_unit: str
    root_order: list[str]
    root_axis: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict[str, AsfBone]
    children: dict[str, list[str]]

    def depth_first(self) -> list[str]:
        """Bone names depth first from the root (``"root"`` excluded)."""
        order: list[str] = []

        def visit(name: str) -> None:
            for child in self.children.get(name, []):
                order.append(child)
                visit(child)

        visit("root")
        return order


def _floats(path: Path, line: int, words: list[str], count: int, what: str) -> np.ndarray:
    if len(words) != count:
        raise MotionFormatError(
            path, f"expected {count} numbers for {what}, found {len(words)}: {words}", line=line
        )
    try:
        return np.array([float(w) for w in words])
    except ValueError:
        raise MotionFormatError(
            path, f"expected numbers for {what}, found {words}", line=line
        ) from None


_ASF_SECTIONS = {
    ":version",
    ":name",
    ":units",
    ":documentation",
    ":root",
    ":bonedata",
    ":hierarchy",
    ":skin",
}


@dataclass
class _AsfParse:
    """What :func:`read_asf` has read so far (file units, ASF angle unit)."""

    path: Path
    length_unit: float = 1.0
    angle_unit: str = "deg"
    root_order: list[str] = field(default_factory=list)
    root_axis: str = "XYZ"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bones: dict[str, AsfBone] = field(default_factory=dict)
    children: dict[str, list[str]] = field(default_factory=dict)
    bone: dict[str, Any] | None = None  # the open ``begin ... end`` block
    hierarchy_open: bool = False
    hierarchy_seen: bool = False


def _text_lines(path: Path) -> list[str]:
    """Lines of an ASF/AMC file; a clear error for one that is not UTF-8 text."""
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise MotionFormatError(
            path, f"not a text file ({exc.reason} at byte {exc.start})"
        ) from None


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton file (LF or CRLF line endings).

    Raises:
        MotionFormatError: Unknown section or field, wrong number of values, bone missing from
            ``:hierarchy`` or vice versa; the message names the line.
    """
    path = Path(path)
    lines = _text_lines(path)
    state = _AsfParse(path)
    section = ""
    readers = {
        ":units": _asf_units_line,
        ":root": _asf_root_line,
        ":bonedata": _asf_bone_line,
        ":hierarchy": _asf_hierarchy_line,
    }
    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0].lower()
        if key.startswith(":"):
            if state.bone is not None:
                raise MotionFormatError(
                    path, f"bone block from line {state.bone['line']} has no 'end'", line=number
                )
            section = key
            if section not in _ASF_SECTIONS:
                raise MotionFormatError(path, f"unknown ASF section {words[0]!r}", line=number)
            continue
        reader = readers.get(section)
        if reader is not None:
            reader(state, number, key, words, raw)
    if not state.hierarchy_seen:
        raise MotionFormatError(path, "no :hierarchy section", line=len(lines))
    if not state.root_order:
        raise MotionFormatError(path, "no ':root order' line (expected e.g. TX TY TZ RX RY RZ)")
    skeleton = AsfSkeleton(
        path=path,
        length_unit=state.length_unit,
        angle_unit=state.angle_unit,
        root_order=state.root_order,
        root_axis=state.root_axis,
        root_position=state.root_position,
        root_orientation=state.root_orientation,
        bones=state.bones,
        children=state.children,
    )
    reached = set(skeleton.depth_first())
    orphans = [b for b in state.bones if b not in reached]
    if orphans:
        raise MotionFormatError(path, f"bones {orphans} are not reachable from root in :hierarchy")
    return skeleton


def _asf_units_line(state: _AsfParse, number: int, key: str, words: list[str], raw: str) -> None:
    """A line of ``:units``: ``length <factor>``, ``angle deg|rad`` or ``mass <factor>``."""
    path = state.path
    if key == "length":
        state.length_unit = float(_floats(path, number, words[1:], 1, "units length")[0])
    elif key == "angle":
        if len(words) != 2 or words[1].lower() not in {"deg", "rad"}:
            raise MotionFormatError(
                path,
                f"expected 'angle deg' or 'angle rad', found {raw.strip()!r}",
                line=number,
            )
        state.angle_unit = words[1].lower()
    elif key != "mass":
        raise MotionFormatError(path, f"unknown unit {words[0]!r}", line=number)


def _asf_root_line(state: _AsfParse, number: int, key: str, words: list[str], raw: str) -> None:
    """A line of ``:root``: ``order``, ``axis``, ``position`` or ``orientation``."""
    path = state.path
    if key == "order":
        order = [w.lower() for w in words[1:]]
        bad = [w for w in order if w not in _ROTATION_DOFS and w not in _TRANSLATION_DOFS]
        if bad:
            raise MotionFormatError(
                path, f"unknown root dof {bad}; expected TX TY TZ RX RY RZ", line=number
            )
        state.root_order = order
    elif key == "axis":
        state.root_axis = _axis_letters(path, number, words[1:])
    elif key == "position":
        state.root_position = _floats(path, number, words[1:], 3, f"root {key}")
    elif key == "orientation":
        state.root_orientation = _floats(path, number, words[1:], 3, f"root {key}")
    else:
        raise MotionFormatError(path, f"unknown :root field {words[0]!r}", line=number)


def _asf_bone_line(state: _AsfParse, number: int, key: str, words: list[str], raw: str) -> None:
    """A line of ``:bonedata``: ``begin``, ``end`` or a field of the open bone block."""
    path = state.path
    bone = state.bone
    if key == "begin":
        state.bone = {"line": number, "dof": [], "limits": [], "axis": None}
    elif bone is None:
        raise MotionFormatError(path, f"expected 'begin', found {raw.strip()!r}", line=number)
    elif key == "end":
        entry = _finish_bone(path, bone, number)
        if entry.name in state.bones:
            raise MotionFormatError(path, f"bone {entry.name!r} defined twice", line=bone["line"])
        state.bones[entry.name] = entry
        state.bone = None
    elif key in {"id", "bodymass", "cofmass"}:
        pass
    else:
        _asf_bone_field(path, bone, number, key, words, raw)


def _asf_bone_field(
    path: Path, bone: dict[str, Any], number: int, key: str, words: list[str], raw: str
) -> None:
    """Store one ``name``/``direction``/``length``/``axis``/``dof``/``limits`` line in ``bone``."""
    if key == "name":
        if len(words) != 2:
            raise MotionFormatError(
                path, f"expected 'name <bone>', found {raw.strip()!r}", line=number
            )
        bone["name"] = words[1]
    elif key == "direction":
        bone["direction"] = _floats(path, number, words[1:], 3, "direction")
    elif key == "length":
        bone["length"] = float(_floats(path, number, words[1:], 1, "length")[0])
    elif key == "axis":
        bone["axis"] = _floats(path, number, words[1:4], 3, "axis angles")
        bone["axis_order"] = _axis_letters(path, number, words[4:])
    elif key == "dof":
        dof = [w.lower() for w in words[1:]]
        bad = [w for w in dof if w not in _ROTATION_DOFS]
        if bad:
            raise MotionFormatError(
                path,
                f"dof {bad} is not supported (only rx ry rz on bones; translations and "
                "'l' only on the root)",
                line=number,
            )
        bone["dof"] = dof
    elif key.startswith("limits") or key.startswith("("):
        text = raw.strip()[len("limits") :] if key.startswith("limits") else raw.strip()
        bone["limits"].extend(_limits(path, number, text))
    else:
        raise MotionFormatError(path, f"unknown bone field {words[0]!r}", line=number)


def _asf_hierarchy_line(
    state: _AsfParse, number: int, key: str, words: list[str], raw: str
) -> None:
    """A line of ``:hierarchy``: ``begin``, ``end`` or ``<parent> <child> ...``."""
    path = state.path
    if key == "begin":
        state.hierarchy_open = state.hierarchy_seen = True
    elif key == "end":
        state.hierarchy_open = False
    elif not state.hierarchy_open:
        raise MotionFormatError(
            path, f"expected 'begin' or 'end', found {raw.strip()!r}", line=number
        )
    else:
        parent_name = words[0]
        children = state.children
        for child in words[1:]:
            if any(child in c for c in children.values()):
                raise MotionFormatError(path, f"bone {child!r} has two parents", line=number)
            children.setdefault(parent_name, []).append(child)
            if child not in state.bones:
                raise MotionFormatError(
                    path,
                    f"bone {child!r} is in :hierarchy but not in :bonedata",
                    line=number,
                )
        if parent_name != "root" and parent_name not in state.bones:
            raise MotionFormatError(
                path,
                f"bone {parent_name!r} is in :hierarchy but not in :bonedata",
                line=number,
            )


def _axis_letters(path: Path, line: int, words: list[str]) -> str:
    letters = "".join(words).upper()
    if len(letters) != 3 or sorted(letters) != ["X", "Y", "Z"]:
        raise MotionFormatError(
            path, f"expected an axis order such as XYZ, found {words}", line=line
        )
    return letters


def _limits(path: Path, line: int, text: str) -> list[tuple[float, float]]:
    out = []
    for chunk in text.replace(")", "(").split("("):
        words = chunk.split()
        if not words:
            continue
        if len(words) != 2:
            raise MotionFormatError(
                path, f"expected '(low high)' limits, found {text!r}", line=line
            )
        try:
            out.append((float(words[0]), float(words[1])))
        except ValueError:
            raise MotionFormatError(
                path, f"expected numeric limits, found {text!r}", line=line
            ) from None
    return out


def _finish_bone(path: Path, bone: dict[str, Any], line: int) -> AsfBone:
    for required in ("name", "direction", "length"):
        if required not in bone:
            raise MotionFormatError(
                path, f"bone block from line {bone['line']} has no {required!r}", line=line
            )
    if bone["axis"] is None:
        bone["axis"], bone["axis_order"] = np.zeros(3), "XYZ"
    if bone["limits"] and len(bone["limits"]) != len(bone["dof"]):
        raise MotionFormatError(
            path,
            f"bone {bone['name']!r} has {len(bone['dof'])} dof but {len(bone['limits'])} limits",
            line=bone["line"],
        )
    return AsfBone(
        name=bone["name"],
        direction=bone["direction"],
        length=bone["length"],
        axis=bone["axis"],
        axis_order=bone["axis_order"],
        dof=bone["dof"],
        limits=bone["limits"],
        line=bone["line"],
    )


@dataclass
class _AmcParse:
    """What :func:`read_amc` has read so far."""

    path: Path
    expected: dict[str, list[str]]  # bone (and "root") -> its dofs, in AMC order
    angle_unit: str
    rows: dict[str, list[list[float]]] = field(default_factory=dict)
    frame: int | None = None  # number of the frame being read
    first_frame: int = 0
    frame_line: int = 0
    seen: set[str] = field(default_factory=set)  # bones listed in the current frame

    def close_frame(self, at_line: int) -> None:
        """Check that the current frame listed every bone with dofs."""
        missing = [name for name in self.expected if name not in self.seen]
        if missing:
            raise MotionFormatError(
                self.path,
                f"frame {self.frame} (line {self.frame_line}) lacks {missing}; every frame must "
                f"list all {len(self.expected)} bones with dofs",
                line=at_line,
                frame=self.frame,
            )


def read_amc(path: str | Path, skeleton: AsfSkeleton) -> tuple[dict[str, np.ndarray], int, str]:
    """Parse an AMC file against its skeleton.

    Every frame must list every bone with dofs (and ``root``) exactly once, with one value per dof;
    frame numbers must be consecutive.

    Args:
        path: The ``.amc`` file.
        skeleton: The skeleton from :func:`read_asf`.

    Returns:
        ``(values, first_frame, angle_unit)``: ``values[bone]`` is ``(T, len(dof))`` as written,
        ``first_frame`` the number of the first frame, ``angle_unit`` ``"deg"`` or ``"rad"``.

    Raises:
        MotionFormatError: Missing, repeated or out-of-order frame; missing, repeated or unknown
            bone; wrong number of values; non-numeric value. The message names line and frame.
    """
    path = Path(path)
    lines = _text_lines(path)
    expected = {"root": skeleton.root_order}
    expected.update({name: b.dof for name, b in skeleton.bones.items() if b.dof})
    state = _AmcParse(path, expected, skeleton.angle_unit, {name: [] for name in expected})
    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0].startswith(":"):
            _amc_keyword(state, number, words)
        elif len(words) == 1:
            _amc_frame_number(state, number, words[0], raw)
        else:
            _amc_bone_line(state, skeleton, number, words)
    if state.frame is None:
        raise MotionFormatError(
            path, "no frame found (expected a frame number such as '1')", line=len(lines)
        )
    state.close_frame(len(lines))
    values = {
        name: np.array(r, dtype=float).reshape(len(r), len(expected[name]))
        for name, r in state.rows.items()
    }
    return values, state.first_frame, state.angle_unit


def _amc_keyword(state: _AmcParse, number: int, words: list[str]) -> None:
    """``:DEGREES``, ``:RADIANS`` or ``:FULLY-SPECIFIED`` before the first frame."""
    keyword = words[0].upper()
    if state.frame is not None:
        raise MotionFormatError(
            state.path, f"keyword {words[0]!r} after the first frame", line=number
        )
    if keyword == ":DEGREES":
        state.angle_unit = "deg"
    elif keyword == ":RADIANS":
        state.angle_unit = "rad"
    elif keyword != ":FULLY-SPECIFIED":
        raise MotionFormatError(state.path, f"unknown AMC keyword {words[0]!r}", line=number)


def _amc_frame_number(state: _AmcParse, number: int, word: str, raw: str) -> None:
    """A frame number: close the previous frame (consecutive numbers) and open a new one."""
    frame = state.frame
    try:
        number_read = int(word)
    except ValueError:
        raise MotionFormatError(
            state.path,
            f"expected a frame number or '<bone> <values>', found {raw.strip()!r}",
            line=number,
            frame=frame,
        ) from None
    if frame is None:
        state.first_frame = number_read
    else:
        state.close_frame(number)
        if number_read != frame + 1:
            raise MotionFormatError(
                state.path,
                f"expected frame {frame + 1} after frame {frame}, found frame {number_read}",
                line=number,
                frame=number_read,
            )
    state.frame, state.frame_line, state.seen = number_read, number, set()


def _amc_bone_line(state: _AmcParse, skeleton: AsfSkeleton, number: int, words: list[str]) -> None:
    """``<bone> <value> ...``: one finite value per dof of a bone not yet listed in the frame."""
    path, frame, name = state.path, state.frame, words[0]
    if frame is None:
        raise MotionFormatError(
            path, f"bone line {name!r} before the first frame number", line=number
        )
    if name not in state.expected:
        hint = "it has no dof in the ASF" if name in skeleton.bones else "it is not in the ASF"
        raise MotionFormatError(path, f"unexpected bone {name!r}: {hint}", line=number, frame=frame)
    if name in state.seen:
        raise MotionFormatError(path, f"bone {name!r} listed twice", line=number, frame=frame)
    dof = state.expected[name]
    if len(words) - 1 != len(dof):
        raise MotionFormatError(
            path,
            f"bone {name!r} expects {len(dof)} values ({' '.join(dof)}), found {len(words) - 1}",
            line=number,
            frame=frame,
        )
    try:
        values = [float(w) for w in words[1:]]
    except ValueError:
        raise MotionFormatError(
            path,
            f"bone {name!r} expects numbers, found {words[1:]}",
            line=number,
            frame=frame,
        ) from None
    if not all(math.isfinite(v) for v in values):
        raise MotionFormatError(
            path, f"bone {name!r} has non-finite values {words[1:]}", line=number, frame=frame
        )
    state.rows[name].append(values)
    state.seen.add(name)


def read_asf_amc(
    asf_path: str | Path,
    amc_path: str | Path,
    *,
    rate: float = 120.0,
    length_scale: float | None = None,
    up_axis: Literal["y", "z"] = "y",
) -> HumanMotion:
    """Read a CMU/Acclaim skeleton and motion into a :class:`HumanMotion` (metres, z up).

    Args:
        asf_path: The ``.asf`` skeleton.
        amc_path: The ``.amc`` motion (frame numbers in the file; the first becomes ``t = 0``).
        rate: Frame rate in [Hz]; AMC files do not store it (CMU: 120 Hz).
        length_scale: Metres per file unit. ``None`` uses ``0.0254 / <:units length>``: CMU ASF
            files say ``length 0.45``, meaning 1 unit = 1/0.45 inch = 0.0564444 m (CMU FAQ).
        up_axis: Up axis of the file, ``"y"`` for CMU (converted as in
            :func:`~qpretarget.motion.bvh.read_bvh`) or ``"z"``.

    Returns:
        The motion, joints as described in the module docstring, with orientations.

    Raises:
        MotionFormatError: Malformed ASF or AMC (see :func:`read_asf`, :func:`read_amc`).
        ValueError: Non-positive ``rate`` or ``length_scale``, unknown ``up_axis``.
    """
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number of frames per second, got {rate!r}")
    skeleton = read_asf(asf_path)
    values, first_frame, amc_angle_unit = read_amc(amc_path, skeleton)
    if length_scale is None:
        scale = 0.0254 / skeleton.length_unit
    else:
        scale = float(length_scale)
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"length_scale must be a positive number, got {length_scale!r}")
    to_rad = math.pi / 180.0 if amc_angle_unit == "deg" else 1.0
    asf_to_rad = math.pi / 180.0 if skeleton.angle_unit == "deg" else 1.0
    num_frames = values["root"].shape[0]
    names, parents, translations, rotations = _joint_motions(
        skeleton, values, scale, to_rad, asf_to_rad
    )
    return skeleton_motion(
        names,
        parents,
        translations,
        rotations,
        num_frames=num_frames,
        rate=rate,
        up_axis=up_axis,
        source=str(amc_path),
        meta={
            "format": "asf/amc",
            "asf": str(asf_path),
            "length_scale": scale,
            "length_unit": f"inch/{skeleton.length_unit:g}" if length_scale is None else "explicit",
            "up_axis": up_axis,
            "first_frame": first_frame,
            "dof": {n: list(b.dof) for n, b in skeleton.bones.items()},
            "limits_deg": {n: list(b.limits) for n, b in skeleton.bones.items() if b.limits},
        },
    )


def _root_motion(
    skeleton: AsfSkeleton, root_values: np.ndarray, scale: float, to_rad: float, asf_to_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """Root translation ``(T, 3)`` [m] and rotation :math:`C M` ``(T, 3, 3)`` from its AMC dofs."""
    translation = np.tile(skeleton.root_position * scale, (root_values.shape[0], 1))
    rot_axes, rot_columns = [], []
    for k, dof in enumerate(skeleton.root_order):
        if dof in _TRANSLATION_DOFS:
            translation[:, _TRANSLATION_DOFS[dof]] += root_values[:, k] * scale
        else:
            rot_axes.append(_ROTATION_DOFS[dof])
            rot_columns.append(k)
    # Acclaim orders are application orders: the first listed rotation is applied first.
    root_m = euler_product(root_values[:, rot_columns[::-1]] * to_rad, rot_axes[::-1])
    root_c = euler_product(
        skeleton.root_orientation[::-1] * asf_to_rad, skeleton.root_axis.lower()[::-1]
    )
    return translation, root_c @ root_m


def _joint_motions(
    skeleton: AsfSkeleton,
    values: dict[str, np.ndarray],
    scale: float,
    to_rad: float,
    asf_to_rad: float,
) -> tuple[list[str], list[int], list[np.ndarray], list[np.ndarray | None]]:
    r"""Joints (root, one per bone, ``<leaf>_end``) with translations and rotations in the parent.

    A bone's local rotation is :math:`C_b M_b C_b^{-1}` (module docstring); its joint sits at the
    end of the parent bone, so its translation is the parent's :math:`d_p \ell_p`.
    """
    translation, root_rotation = _root_motion(skeleton, values["root"], scale, to_rad, asf_to_rad)
    names = ["root"]
    parents = [-1]
    translations: list[np.ndarray] = [translation]
    rotations: list[np.ndarray | None] = [root_rotation]
    index = {"root": 0}
    bone_vectors = {"root": np.zeros(3)}
    for name in skeleton.depth_first():
        bone = skeleton.bones[name]
        parent = next(p for p, c in skeleton.children.items() if name in c)
        c = euler_product(bone.axis[::-1] * asf_to_rad, bone.axis_order.lower()[::-1])
        if bone.dof:
            m = euler_product(
                values[name][:, ::-1] * to_rad, [_ROTATION_DOFS[d] for d in bone.dof[::-1]]
            )
            local = c @ m @ c.T
        else:
            local = None
        index[name] = len(names)
        names.append(name)
        parents.append(index[parent])
        translations.append(bone_vectors[parent])
        rotations.append(local)
        bone_vectors[name] = bone.direction * bone.length * scale
        if not skeleton.children.get(name):
            names.append(f"{name}_end")
            parents.append(index[name])
            translations.append(bone_vectors[name])
            rotations.append(None)
    return names, parents, translations, rotations
