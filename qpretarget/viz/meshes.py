# SPDX-License-Identifier: Apache-2.0
"""Robot link meshes from the URDF (visual or collision), loaded once, posed by pinocchio.

Meshes are read with trimesh (``.dae`` through pycollada; both in the ``viz`` extra) from the files
the URDF names (``package://`` URIs resolved in example-robot-data's share directory); primitives
(box, sphere, cylinder, capsule) become trimesh primitives. ``simplify=True`` replaces each mesh by
its convex hull (tens to hundreds of faces instead of thousands), which the offscreen renderer
draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import MissingDependencyError, missing_dependency
from ..robot import RobotModel
from ..robots import share_directory


@dataclass
class LinkMesh:
    """One mesh attached to a joint of the robot.

    Attributes:
        name: geometry name (URDF link name plus index).
        parent_joint: pinocchio joint id the mesh moves with.
        placement: pose of the mesh in the joint frame.
        vertices: (V, 3) mesh vertices in the mesh frame (scaled) [m].
        faces: (F, 3) triangle vertex indices.
        color: RGBA in [0, 1].
    """

    name: str
    parent_joint: int
    placement: pin.SE3
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float, float]


def _trimesh():  # noqa: ANN202
    try:
        import trimesh
    except ImportError:  # pragma: no cover - depends on the environment
        raise missing_dependency("viz", "drawing robot meshes (trimesh)") from None
    return trimesh


def _require_collada(path: Path) -> None:
    """Raise the install hint when ``path`` is a COLLADA file and pycollada is missing.

    trimesh reads ``.dae`` (Romeo, iCub) only through pycollada; without it every mesh would be
    silently dropped and the robot drawn empty.
    """
    if path.suffix.lower() != ".dae":
        return
    try:
        import collada  # noqa: F401
    except ImportError:
        raise missing_dependency(
            "viz", f"reading COLLADA meshes such as {path.name} (pycollada)"
        ) from None


def _coarse_hull(mesh, max_points: int):  # noqa: ANN001, ANN202
    """Convex hull of at most ``max_points`` vertices (a fixed-seed subset): ~2x that many faces."""
    from scipy.spatial import ConvexHull

    trimesh = _trimesh()
    pts = np.asarray(mesh.vertices)
    if len(pts) > max_points:
        rng = np.random.default_rng(0)
        # keep the extreme points along the axes so the silhouette keeps its extent
        ext = np.concatenate([np.argmin(pts, axis=0), np.argmax(pts, axis=0)])
        idx = np.union1d(ext, rng.choice(len(pts), max_points - len(ext), replace=False))
        pts = pts[idx]
    try:
        hull = ConvexHull(pts)
    except Exception:
        return mesh.convex_hull
    # Wind every triangle counter-clockwise seen from outside: its normal must agree with the
    # outward normal qhull reports for that facet (no graph traversal needed on a convex hull).
    faces = hull.simplices.copy()
    a, b, c = (pts[faces[:, i]] for i in range(3))
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0.0
    faces[flip] = faces[flip][:, ::-1]
    used = np.unique(faces)
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    return trimesh.Trimesh(pts[used], remap[faces], process=False)


def _resolve_uri(uri: str, urdf_dir: Path) -> Path:
    if uri.startswith("package://"):
        rel = uri[len("package://") :]
        for base in (share_directory(), urdf_dir):
            cand = base / rel
            if cand.exists():
                return cand
        # package://NAME/... where NAME is a folder of example-robot-data's robots directory
        parts = rel.split("/", 1)
        cand = share_directory() / "example-robot-data" / "robots" / parts[-1]
        return cand
    if uri.startswith("file://"):
        return Path(uri[len("file://") :])
    p = Path(uri)
    return p if p.is_absolute() else urdf_dir / p


def _numbers(elem: Any, key: str) -> list[float]:
    """The numbers of the XML attribute ``key`` (ValueError when it is missing)."""
    text = elem.get(key)
    if text is None:
        raise ValueError(f"<{elem.tag}> has no {key!r} attribute")
    return [float(x) for x in text.split()]


def _origin(elem) -> pin.SE3:  # noqa: ANN001
    o = elem.find("origin")
    if o is None:
        return pin.SE3.Identity()
    xyz = np.array([float(x) for x in o.get("xyz", "0 0 0").split()])
    rpy = np.array([float(x) for x in o.get("rpy", "0 0 0").split()])
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def load_link_meshes(
    robot: RobotModel, *, kind: str = "visual", simplify: bool = False, max_points: int = 80
) -> list[LinkMesh]:
    """Meshes of every URDF link's ``<visual>`` (or ``<collision>``) elements.

    The URDF is parsed directly (no collision BVH is built), meshes are read with trimesh.

    Args:
        robot: the robot.
        kind: ``visual`` or ``collision`` geometry of the URDF.
        simplify: replace each mesh by a coarse convex hull (for the offscreen renderer).
        max_points: vertices kept per simplified hull.
    """
    import xml.etree.ElementTree as ET

    trimesh = _trimesh()
    urdf = Path(robot.urdf_path)
    root = ET.parse(urdf).getroot()
    model = robot.model
    out: list[LinkMesh] = []
    for link in root.findall("link"):
        lname = link.get("name")
        if not model.existFrame(lname):
            continue
        frame = model.frames[model.getFrameId(lname)]
        for k, el in enumerate(link.findall(kind)):
            geom = el.find("geometry")
            if geom is None or len(geom) == 0:
                continue
            g = geom[0]
            mesh = None
            try:
                if g.tag == "mesh":
                    path = _resolve_uri(g.get("filename", ""), urdf.parent)
                    _require_collada(path)
                    mesh = trimesh.load(str(path), force="mesh", process=False)
                    scale = g.get("scale")
                    if scale:
                        mesh.apply_scale(np.array([float(x) for x in scale.split()]))
                elif g.tag == "box":
                    mesh = trimesh.creation.box(extents=_numbers(g, "size"))
                elif g.tag == "sphere":
                    mesh = trimesh.creation.icosphere(
                        subdivisions=2, radius=_numbers(g, "radius")[0]
                    )
                elif g.tag == "cylinder":
                    radius, length = _numbers(g, "radius")[0], _numbers(g, "length")[0]
                    mesh = trimesh.creation.cylinder(radius=radius, height=length, sections=16)
                elif g.tag == "capsule":
                    radius, length = _numbers(g, "radius")[0], _numbers(g, "length")[0]
                    mesh = trimesh.creation.capsule(radius=radius, height=length, count=[8, 8])
            except MissingDependencyError:
                raise
            except Exception:  # an unreadable mesh is skipped: a viewer must still open
                mesh = None
            if mesh is None or len(mesh.faces) == 0:
                continue
            if simplify and len(mesh.faces) > 64:
                mesh = _coarse_hull(mesh, max_points)
            color = (0.70, 0.72, 0.76, 1.0)
            mat = el.find("material/color")
            if mat is not None and mat.get("rgba"):
                rgba = _numbers(mat, "rgba")
                if len(rgba) == 4 and rgba[3] > 0:
                    color = (rgba[0], rgba[1], rgba[2], rgba[3])
            out.append(
                LinkMesh(
                    name=f"{lname}_{k}",
                    parent_joint=int(frame.parentJoint),
                    placement=frame.placement * _origin(el),
                    vertices=np.asarray(mesh.vertices, dtype=float),
                    faces=np.asarray(mesh.faces, dtype=np.int64),
                    color=color,
                )
            )
    return out


def mesh_placements(
    robot: RobotModel, data: pin.Data, meshes: list[LinkMesh], q: np.ndarray
) -> list[pin.SE3]:
    """World pose of each mesh at configuration ``q`` (runs forward kinematics into ``data``)."""
    pin.forwardKinematics(robot.model, data, q)
    return [data.oMi[m.parent_joint] * m.placement for m in meshes]
