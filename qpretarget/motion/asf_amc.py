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
from typing import Literal

import numpy as np

from ._kinematics import change_up_axis, euler_product, forward_kinematics
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


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton file (LF or CRLF line endings).

    Raises:
        MotionFormatError: Unknown section or field, wrong number of values, bone missing from
            ``:hierarchy`` or vice versa; the message names the line.
    """
    path = Path(path)
    lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    section = ""
    units = {"length": 1.0, "angle": "deg"}
    root = {"order": [], "axis": "XYZ", "position": np.zeros(3), "orientation": np.zeros(3)}
    bones: dict[str, AsfBone] = {}
    children: dict[str, list[str]] = {}
    bone: dict | None = None
    hierarchy_open = hierarchy_seen = False
    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0].lower()
        if key.startswith(":"):
            if bone is not None:
                raise MotionFormatError(
                    path, f"bone block from line {bone['line']} has no 'end'", line=number
                )
            section = key
            if section not in {
                ":version",
                ":name",
                ":units",
                ":documentation",
                ":root",
                ":bonedata",
                ":hierarchy",
                ":skin",
            }:
                raise MotionFormatError(path, f"unknown ASF section {words[0]!r}", line=number)
            continue
        if section == ":units":
            if key == "length":
                units["length"] = float(_floats(path, number, words[1:], 1, "units length")[0])
            elif key == "angle":
                if len(words) != 2 or words[1].lower() not in {"deg", "rad"}:
                    raise MotionFormatError(
                        path,
                        f"expected 'angle deg' or 'angle rad', found {raw.strip()!r}",
                        line=number,
                    )
                units["angle"] = words[1].lower()
            elif key != "mass":
                raise MotionFormatError(path, f"unknown unit {words[0]!r}", line=number)
        elif section == ":root":
            if key == "order":
                order = [w.lower() for w in words[1:]]
                bad = [w for w in order if w not in _ROTATION_DOFS and w not in _TRANSLATION_DOFS]
                if bad:
                    raise MotionFormatError(
                        path, f"unknown root dof {bad}; expected TX TY TZ RX RY RZ", line=number
                    )
                root["order"] = order
            elif key == "axis":
                root["axis"] = _axis_letters(path, number, words[1:])
            elif key in {"position", "orientation"}:
                root[key] = _floats(path, number, words[1:], 3, f"root {key}")
            else:
                raise MotionFormatError(path, f"unknown :root field {words[0]!r}", line=number)
        elif section == ":bonedata":
            if key == "begin":
                bone = {"line": number, "dof": [], "limits": [], "axis": None}
            elif bone is None:
                raise MotionFormatError(
                    path, f"expected 'begin', found {raw.strip()!r}", line=number
                )
            elif key == "end":
                bones_entry = _finish_bone(path, bone, number)
                if bones_entry.name in bones:
                    raise MotionFormatError(
                        path, f"bone {bones_entry.name!r} defined twice", line=bone["line"]
                    )
                bones[bones_entry.name] = bones_entry
                bone = None
            elif key == "id":
                pass
            elif key == "name":
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
            elif key in {"bodymass", "cofmass"}:
                pass
            else:
                raise MotionFormatError(path, f"unknown bone field {words[0]!r}", line=number)
        elif section == ":hierarchy":
            if key == "begin":
                hierarchy_open = hierarchy_seen = True
            elif key == "end":
                hierarchy_open = False
            elif not hierarchy_open:
                raise MotionFormatError(
                    path, f"expected 'begin' or 'end', found {raw.strip()!r}", line=number
                )
            else:
                parent_name = words[0]
                for child in words[1:]:
                    if any(child in c for c in children.values()):
                        raise MotionFormatError(
                            path, f"bone {child!r} has two parents", line=number
                        )
                    children.setdefault(parent_name, []).append(child)
                    if child not in bones:
                        raise MotionFormatError(
                            path,
                            f"bone {child!r} is in :hierarchy but not in :bonedata",
                            line=number,
                        )
                if parent_name != "root" and parent_name not in bones:
                    raise MotionFormatError(
                        path,
                        f"bone {parent_name!r} is in :hierarchy but not in :bonedata",
                        line=number,
                    )
    if not hierarchy_seen:
        raise MotionFormatError(path, "no :hierarchy section", line=len(lines))
    if not root["order"]:
        raise MotionFormatError(path, "no ':root order' line (expected e.g. TX TY TZ RX RY RZ)")
    skeleton = AsfSkeleton(
        path=path,
        length_unit=units["length"],
        angle_unit=units["angle"],
        root_order=root["order"],
        root_axis=root["axis"],
        root_position=root["position"],
        root_orientation=root["orientation"],
        bones=bones,
        children=children,
    )
    reached = set(skeleton.depth_first())
    orphans = [b for b in bones if b not in reached]
    if orphans:
        raise MotionFormatError(path, f"bones {orphans} are not reachable from root in :hierarchy")
    return skeleton


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


def _finish_bone(path: Path, bone: dict, line: int) -> AsfBone:
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
    lines = path.read_text(encoding="utf-8").splitlines()
    expected = {"root": skeleton.root_order}
    expected.update({name: b.dof for name, b in skeleton.bones.items() if b.dof})
    rows: dict[str, list[list[float]]] = {name: [] for name in expected}
    angle_unit = skeleton.angle_unit
    frame: int | None = None
    first_frame = 0
    frame_line = 0
    seen: set[str] = set()

    def close_frame(at_line: int) -> None:
        missing = [name for name in expected if name not in seen]
        if missing:
            raise MotionFormatError(
                path,
                f"frame {frame} (line {frame_line}) lacks {missing}; every frame must list all "
                f"{len(expected)} bones with dofs",
                line=at_line,
                frame=frame,
            )

    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0].startswith(":"):
            keyword = words[0].upper()
            if frame is not None:
                raise MotionFormatError(
                    path, f"keyword {words[0]!r} after the first frame", line=number
                )
            if keyword == ":DEGREES":
                angle_unit = "deg"
            elif keyword == ":RADIANS":
                angle_unit = "rad"
            elif keyword != ":FULLY-SPECIFIED":
                raise MotionFormatError(path, f"unknown AMC keyword {words[0]!r}", line=number)
            continue
        if len(words) == 1:
            try:
                number_read = int(words[0])
            except ValueError:
                raise MotionFormatError(
                    path,
                    f"expected a frame number or '<bone> <values>', found {raw.strip()!r}",
                    line=number,
                    frame=frame,
                ) from None
            if frame is None:
                first_frame = number_read
            else:
                close_frame(number)
                if number_read != frame + 1:
                    raise MotionFormatError(
                        path,
                        f"expected frame {frame + 1} after frame {frame}, "
                        f"found frame {number_read}",
                        line=number,
                        frame=number_read,
                    )
            frame, frame_line, seen = number_read, number, set()
            continue
        name = words[0]
        if frame is None:
            raise MotionFormatError(
                path, f"bone line {name!r} before the first frame number", line=number
            )
        if name not in expected:
            hint = "it has no dof in the ASF" if name in skeleton.bones else "it is not in the ASF"
            raise MotionFormatError(
                path, f"unexpected bone {name!r}: {hint}", line=number, frame=frame
            )
        if name in seen:
            raise MotionFormatError(path, f"bone {name!r} listed twice", line=number, frame=frame)
        dof = expected[name]
        if len(words) - 1 != len(dof):
            raise MotionFormatError(
                path,
                f"bone {name!r} expects {len(dof)} values ({' '.join(dof)}), "
                f"found {len(words) - 1}",
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
        rows[name].append(values)
        seen.add(name)
    if frame is None:
        raise MotionFormatError(
            path, "no frame found (expected a frame number such as '1')", line=len(lines)
        )
    close_frame(len(lines))
    values = {
        name: np.array(r, dtype=float).reshape(len(r), len(expected[name]))
        for name, r in rows.items()
    }
    return values, first_frame, angle_unit


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

    names = ["root"]
    parents = [-1]
    root_values = values["root"]
    translation = np.tile(skeleton.root_position * scale, (num_frames, 1))
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
    translations: list[np.ndarray] = [translation]
    rotations: list[np.ndarray | None] = [root_c @ root_m]
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
    positions, orientations = forward_kinematics(parents, translations, rotations, num_frames)
    positions, orientations, _ = change_up_axis(positions, orientations, up_axis)
    return HumanMotion(
        t=np.arange(num_frames) / rate,
        names=tuple(names),
        positions=positions,
        parents=tuple(parents),
        orientations=orientations,
        rate=rate,
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
