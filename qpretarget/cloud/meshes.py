# SPDX-License-Identifier: Apache-2.0
"""Triangle meshes of a robot's links, attached to its pinocchio joints.

:func:`load_link_meshes` reads the ``<visual>`` (or ``<collision>``) elements of a URDF, loads each
mesh (STL natively, binary or ASCII; other formats through coal's loader) and tessellates the
primitive shapes (box, cylinder, sphere). Every triangle is expressed in the frame of the pinocchio
joint that moves its link, so a posed mesh is one gather and one rotation per triangle
(:meth:`LinkMeshes.posed`). Both the HUMROB template (sampling, :mod:`.template`) and the depth
renderer (:mod:`.render`) start from here.

No pinocchio ``GeometryModel`` is built: that would also build collision BVHs (about 2 s for the
G1 visual meshes), which neither sampling nor rendering needs.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robots import share_directory

#: Triangles per full turn when tessellating cylinders and spheres.
PRIMITIVE_SEGMENTS = 24


@dataclass(frozen=True)
class LinkMeshes:
    """Triangles of a robot's links in the frames of the joints that move them.

    Attributes:
        triangles: (T, 3, 3) vertices [m], each in the frame of its joint ``joint[t]``.
        joint: (T,) pinocchio joint index of each triangle.
        link: (T,) index into :attr:`link_names` of each triangle.
        link_names: names of the URDF links that have geometry.
    """

    triangles: np.ndarray
    joint: np.ndarray
    link: np.ndarray
    link_names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.triangles)

    def posed(self, data: pin.Data, camera_pose: np.ndarray | None = None) -> np.ndarray:
        """Vertices (T, 3, 3) posed by the joint placements ``data.oMi`` of a kinematics pass.

        Args:
            data: pinocchio data after forward kinematics.
            camera_pose: (4, 4) camera-to-world transform: return camera coordinates instead
                of world coordinates.
        """
        out = np.empty_like(self.triangles)
        Rc, pc = np.eye(3), np.zeros(3)
        if camera_pose is not None:
            Rc, pc = camera_pose[:3, :3].T, -camera_pose[:3, :3].T @ camera_pose[:3, 3]
        # Triangles are sorted by joint at load time: one matrix product per joint.
        for j, a, b in self._slices:
            M = data.oMi[j]
            R, p = Rc @ M.rotation, Rc @ M.translation + pc
            out[a:b] = self.triangles[a:b] @ R.T + p
        return out

    @property
    def _slices(self) -> list[tuple[int, int, int]]:
        edges = np.flatnonzero(np.diff(self.joint)) + 1
        starts = np.concatenate([[0], edges])
        ends = np.concatenate([edges, [len(self.joint)]])
        return [(int(self.joint[a]), int(a), int(b)) for a, b in zip(starts, ends, strict=True)]

    def areas(self) -> np.ndarray:
        """(T,) triangle areas [m^2]."""
        e1 = self.triangles[:, 1] - self.triangles[:, 0]
        e2 = self.triangles[:, 2] - self.triangles[:, 0]
        return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def joint_placements(data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
    """Stacked world rotations (njoints, 3, 3) and translations (njoints, 3) of ``data.oMi``."""
    R = np.array([M.rotation for M in data.oMi])
    p = np.array([M.translation for M in data.oMi])
    return R, p


def posed_points(local: np.ndarray, joint: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """World coordinates of points given in joint frames: ``R[joint] @ x + p[joint]``.

    Args:
        local: (K, 3) or (K, 3, 3) points (or triangles) in their joint's frame.
        joint: (K,) joint index of each row.
        R: (njoints, 3, 3) stacked joint rotations (see :func:`joint_placements`).
        p: (njoints, 3) stacked joint translations.
    """
    Rj = R[joint]
    if local.ndim == 2:
        return np.einsum("kab,kb->ka", Rj, local) + p[joint]
    return np.einsum("kab,kvb->kva", Rj, local) + p[joint][:, None, :]


# ---------------------------------------------------------------------------------------- STL
def read_stl(path: str | Path) -> np.ndarray:
    """Triangles (T, 3, 3) of a binary or ASCII STL file, in the file's units.

    Raises:
        ConfigError: the file is missing or is not an STL file.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read mesh {str(path)!r} ({exc.strerror}).") from None
    if len(raw) >= 84:
        n = int(np.frombuffer(raw, dtype="<u4", count=1, offset=80)[0])
        if len(raw) == 84 + 50 * n:
            rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            return np.frombuffer(raw, dtype=rec, count=n, offset=84)["v"].astype(float)
    text = raw.decode("ascii", errors="replace")
    if not text.lstrip().lower().startswith("solid"):
        raise ConfigError(f"{str(path)!r} is neither a binary nor an ASCII STL file.")
    verts = [
        [float(x) for x in line.split()[1:4]]
        for line in text.splitlines()
        if line.strip().lower().startswith("vertex")
    ]
    if not verts or len(verts) % 3:
        raise ConfigError(f"{str(path)!r}: ASCII STL without complete facets.")
    return np.asarray(verts, dtype=float).reshape(-1, 3, 3)


def _read_mesh_other(path: Path) -> np.ndarray:
    """Triangles of a non-STL mesh through coal's assimp loader."""
    try:
        import coal

        bvh = coal.MeshLoader().load(str(path), np.ones(3))
        V = np.asarray(bvh.vertices(), dtype=float)
        F = np.array(
            [[bvh.tri_indices(i)[k] for k in range(3)] for i in range(bvh.num_tris)], dtype=int
        )
        return V[F]
    except Exception as exc:  # noqa: BLE001 - any loader failure becomes a config error
        raise ConfigError(
            f"cannot load mesh {str(path)!r} ({exc}); convert it to STL or use the other "
            "geometry kind (template.meshes: visual|collision)."
        ) from None


# ---------------------------------------------------------------------------------- primitives
def box_triangles(size: np.ndarray) -> np.ndarray:
    """12 triangles of a box of edge lengths ``size`` centred on the origin."""
    h = 0.5 * np.asarray(size, float)
    c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, cc, d in quads:
        tris += [(a, b, cc), (a, cc, d)]
    return c[np.array(tris)]


def cylinder_triangles(radius: float, length: float, n: int = PRIMITIVE_SEGMENTS) -> np.ndarray:
    """Triangles of a closed cylinder along z, centred on the origin."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)], axis=1)
    top, bot = ring + [0, 0, length / 2], ring - [0, 0, length / 2]
    j = np.roll(np.arange(n), -1)
    i = np.arange(n)
    side = np.concatenate(
        [np.stack([bot[i], bot[j], top[j]], 1), np.stack([bot[i], top[j], top[i]], 1)]
    )
    ct, cb = np.array([0, 0, length / 2]), np.array([0, 0, -length / 2])
    caps = np.concatenate(
        [
            np.stack([np.broadcast_to(ct, (n, 3)), top[i], top[j]], 1),
            np.stack([np.broadcast_to(cb, (n, 3)), bot[j], bot[i]], 1),
        ]
    )
    return np.concatenate([side, caps])


def sphere_triangles(radius: float, n: int = PRIMITIVE_SEGMENTS) -> np.ndarray:
    """Triangles of a latitude-longitude sphere centred on the origin."""
    th = np.linspace(0.0, np.pi, n // 2 + 1)
    ph = np.linspace(0.0, 2 * np.pi, n + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    V = radius * np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    a, b, c, d = V[:-1, :-1], V[1:, :-1], V[1:, 1:], V[:-1, 1:]
    tris = np.concatenate(
        [np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)]
    )
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    return tris[np.linalg.norm(np.cross(e1, e2), axis=1) > 1e-14]


# ---------------------------------------------------------------------------------------- URDF
def _resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    """Resolve ``package://PKG/REL``, ``file://ABS`` and relative mesh paths."""
    if filename.startswith("file://"):
        return Path(filename[7:])
    if filename.startswith("package://"):
        rest = filename[len("package://") :]
        candidates = []
        try:
            candidates.append(share_directory() / rest)
        except FileNotFoundError:
            pass
        pkg, _, rel = rest.partition("/")
        for parent in [urdf_dir, *urdf_dir.parents]:
            if parent.name == pkg:
                candidates.append(parent / rel)
            candidates.append(parent / rest)
        for c in candidates:
            if c.is_file():
                return c
        raise ConfigError(
            f"mesh {filename!r} not found (looked in {[str(c) for c in candidates[:3]]})."
        )
    p = Path(filename)
    return p if p.is_absolute() else urdf_dir / p


def _origin(elem: ET.Element | None) -> pin.SE3:
    if elem is None:
        return pin.SE3.Identity()
    xyz = np.array([float(x) for x in elem.get("xyz", "0 0 0").split()])
    rpy = np.array([float(x) for x in elem.get("rpy", "0 0 0").split()])
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)


def _geometry_triangles(
    geom: ET.Element, urdf_dir: Path, cache: dict[str, np.ndarray]
) -> np.ndarray | None:
    mesh = geom.find("mesh")
    if mesh is not None:
        path = _resolve_mesh(mesh.get("filename", ""), urdf_dir)
        key = str(path)
        if key not in cache:
            cache[key] = read_stl(path) if path.suffix.lower() == ".stl" else _read_mesh_other(path)
        scale = np.array([float(x) for x in mesh.get("scale", "1 1 1").split()])
        return cache[key] * scale
    box = geom.find("box")
    if box is not None:
        return box_triangles(np.array([float(x) for x in box.get("size", "0 0 0").split()]))
    cyl = geom.find("cylinder")
    if cyl is not None:
        return cylinder_triangles(float(cyl.get("radius", 0)), float(cyl.get("length", 0)))
    sph = geom.find("sphere")
    if sph is not None:
        return sphere_triangles(float(sph.get("radius", 0)))
    return None


def load_link_meshes(model: pin.Model, urdf: str | Path, kind: str = "visual") -> LinkMeshes:
    """Triangles of every link of a URDF, in the frames of the pinocchio joints of ``model``.

    Args:
        model: pinocchio model built from the same URDF (any root joint).
        urdf: the URDF file.
        kind: ``"visual"`` or ``"collision"`` elements; falls back to the other kind for a robot
            that has none of the requested one.

    Raises:
        ConfigError: unknown kind, unreadable URDF or mesh, or a robot without any geometry.
    """
    if kind not in ("visual", "collision"):
        raise ConfigError(
            f"mesh kind must be 'visual' or 'collision', got {kind!r}.", path="template.meshes"
        )
    urdf = Path(urdf)
    try:
        root = ET.parse(urdf).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"cannot read URDF {str(urdf)!r} ({exc}).") from None
    cache: dict[str, np.ndarray] = {}
    for k in (kind, "collision" if kind == "visual" else "visual"):
        tris, joints, links, names = [], [], [], []
        for link in root.findall("link"):
            name = link.get("name", "")
            elems = link.findall(k)
            if not elems or not model.existFrame(name, pin.BODY):
                continue
            frame = model.frames[model.getFrameId(name, pin.BODY)]
            for e in elems:
                g = e.find("geometry")
                if g is None:
                    continue
                T = _geometry_triangles(g, urdf.parent, cache)
                if T is None or len(T) == 0:
                    continue
                M = frame.placement * _origin(e.find("origin"))
                T = T @ M.rotation.T + M.translation
                if name not in names:
                    names.append(name)
                tris.append(T)
                joints.append(np.full(len(T), frame.parentJoint))
                links.append(np.full(len(T), names.index(name)))
        if tris:
            joint = np.concatenate(joints).astype(int)
            order = np.argsort(joint, kind="stable")
            return LinkMeshes(
                triangles=np.concatenate(tris)[order],
                joint=joint[order],
                link=np.concatenate(links).astype(int)[order],
                link_names=tuple(names),
            )
    raise ConfigError(f"URDF {urdf.name} has no visual or collision geometry to sample or render.")


__all__ = [
    "LinkMeshes",
    "joint_placements",
    "load_link_meshes",
    "posed_points",
    "read_stl",
]
