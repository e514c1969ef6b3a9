# SPDX-License-Identifier: Apache-2.0
r"""Simplified link shapes (convex hulls, capsules, primitives) and obstacles, built once per robot.

The URDF collision meshes are far too heavy for a control loop (G1: 170k triangles, about 21 ms
for 20 mesh pairs). When a robot's geometry is first needed, every link's collision geometry is
replaced by one convex shape:

* ``convex_hull`` (default): the convex hull of the link's mesh vertices,
  ``coal.Convex.convexHull(points, False, "Qt")`` (coal 3.0's
  ``BVHModel.buildConvexRepresentation`` returns too large distances on these meshes). A link
  holding a single mesh keeps the mesh's placement, so its distances are bit-identical to a hull
  built by hand; a link holding several geometries gets one hull of all of them (primitives enter
  through polytopes that contain them).
* ``capsule``: a bounding capsule fitted by PCA (axis = principal direction of the points, radius
  = largest distance to the axis, segment ends shortened as far as every point stays inside).
  Conservative: distances are smaller than the hull's (3 cm median on G1).
* A link with a single primitive (sphere, box, cylinder, capsule, ellipsoid, cone) keeps it.

The distances of link pairs are computed by :class:`~qpretarget.collision.model.CollisionModel`
(``collision/model.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull

from ..errors import ConfigError
from ..robot import RobotModel

GEOMETRIES = ("convex_hull", "capsule")
_PRIMITIVES = (coal.Sphere, coal.Box, coal.Cylinder, coal.Capsule, coal.Ellipsoid, coal.Cone)
#: ``LinkShape.kind`` of a link kept as its single primitive.
_PRIMITIVE_KIND = {
    coal.Sphere: "sphere", coal.Box: "box", coal.Cylinder: "cylinder", coal.Capsule: "capsule",
    coal.Ellipsoid: "ellipsoid", coal.Cone: "cone",
}  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Conservative point sets of primitives (their convex hull contains the primitive)
# ---------------------------------------------------------------------------------------------
def _icosphere() -> np.ndarray:
    """Vertices (42, 3) of a once-subdivided icosahedron whose hull contains the unit sphere."""
    t = (1.0 + 5.0**0.5) / 2.0
    v = np.array(
        [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
        dtype=float,
    )  # fmt: skip
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    # Edges of the icosahedron: vertex pairs at the minimal distance; their midpoints subdivide.
    d = np.linalg.norm(v[:, None] - v[None], axis=2)
    i, j = np.where(np.triu(np.isclose(d, d[d > 1e-9].min()), 1))
    mid = v[i] + v[j]
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    pts = np.vstack([v, mid])
    # Scale so that the hull's inradius is 1: the hull then contains the unit sphere.
    inradius = float(np.min(-ConvexHull(pts).equations[:, 3]))
    return pts / inradius


def _circle(n: int = 16) -> np.ndarray:
    """(n, 2) vertices of a regular polygon circumscribing the unit circle."""
    a = 2.0 * np.pi * np.arange(n) / n
    return np.c_[np.cos(a), np.sin(a)] / np.cos(np.pi / n)


def _vec3s(points: np.ndarray) -> coal.StdVec_Vec3s:
    out = coal.StdVec_Vec3s()
    out.extend(list(np.ascontiguousarray(points, dtype=float)))
    return out


def primitive_points(geom: Any) -> np.ndarray:
    """Points (N, 3), in the geometry's frame, whose convex hull contains the geometry.

    Raises:
        ConfigError: for geometry that is not a bounded convex shape or a mesh.
    """
    if isinstance(geom, coal.BVHModelBase):
        return np.asarray(geom.vertices(), dtype=float).copy()
    if isinstance(geom, coal.ConvexBase):
        return np.asarray(geom.points(), dtype=float).copy()
    if isinstance(geom, coal.Sphere):
        return _ICO * geom.radius
    if isinstance(geom, coal.Ellipsoid):
        return _ICO * np.asarray(geom.radii, dtype=float)
    if isinstance(geom, coal.Box):
        h = np.asarray(geom.halfSide, dtype=float)
        return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    if isinstance(geom, coal.Cylinder):
        c = _circle() * geom.radius
        h = geom.halfLength
        return np.vstack([np.c_[c, np.full(len(c), -h)], np.c_[c, np.full(len(c), h)]])
    if isinstance(geom, coal.Cone):
        c = _circle() * geom.radius
        return np.vstack([np.c_[c, np.full(len(c), -geom.halfLength)], [[0, 0, geom.halfLength]]])
    if isinstance(geom, coal.Capsule):
        s = _ICO * geom.radius
        h = np.array([0.0, 0.0, geom.halfLength])
        return np.vstack([s - h, s + h])
    raise ConfigError(
        f"collision geometry of type {type(geom).__name__} is not supported (use meshes, "
        "spheres, boxes, cylinders, capsules, ellipsoids or cones)."
    )


_ICO = _icosphere()


def _transform(M: pin.SE3, points: np.ndarray) -> np.ndarray:
    return points @ M.rotation.T + M.translation


# ---------------------------------------------------------------------------------------------
# Per-link simplified shapes
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LinkShape:
    """The simplified collision shape of one link (or of a static obstacle).

    Attributes:
        name: link (URDF) name, or obstacle name.
        kind: ``convex_hull``, ``capsule``, or the primitive's class name (``sphere``...).
        geometry: the coal shape.
        joint: parent joint id (0 for a static obstacle).
        frame: parent frame id.
        placement: pose of the shape in the parent joint's frame.
        radius: largest distance from the parent joint's origin to a point of the shape [m].
        n_vertices: vertices of a hull (0 for primitives).
        sources: names of the URDF geometry objects it replaces.
        inflation: swept-sphere radius added to a lighter hull [m] (0 otherwise).
    """

    name: str
    kind: str
    geometry: Any
    joint: int
    frame: int
    placement: pin.SE3
    radius: float
    n_vertices: int = 0
    sources: tuple[str, ...] = ()
    inflation: float = 0.0

    def geometry_object(self) -> pin.GeometryObject:
        """A pinocchio ``GeometryObject`` of this shape."""
        return pin.GeometryObject(self.name, self.joint, self.frame, self.placement, self.geometry)


def fit_capsule(points: np.ndarray) -> tuple[coal.Capsule, pin.SE3]:
    r"""Bounding capsule of ``points`` (N, 3) by PCA; returns the capsule and its pose.

    Axis :math:`a` = principal direction through the mean, radius :math:`r = \max_i \rho_i` (the
    largest distance to the axis). A point at axial coordinate :math:`t_i` and radial distance
    :math:`\rho_i` lies within :math:`r` of the segment :math:`[t_0, t_1]` iff
    :math:`t_0 - s_i \le t_i \le t_1 + s_i` with :math:`s_i = \sqrt{r^2 - \rho_i^2}`, so the
    shortest segment is :math:`t_0 = \min_i (t_i + s_i)`, :math:`t_1 = \max_i (t_i - s_i)` (a
    sphere if :math:`t_0 > t_1`). The capsule contains every point.
    """
    P = np.asarray(points, dtype=float)
    c = P.mean(axis=0)
    X = P - c
    _, _, Vt = np.linalg.svd(X, full_matrices=False)
    a = Vt[0]
    t = X @ a
    rho = np.linalg.norm(X - np.outer(t, a), axis=1)
    r = float(max(rho.max(), 1e-4))
    s = np.sqrt(np.maximum(r * r - rho * rho, 0.0))
    lo, hi = float(np.min(t + s)), float(np.max(t - s))
    if lo > hi:
        lo = hi = 0.5 * (lo + hi)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    # Guard against rounding: grow r until every point is inside.
    seg = mid + np.clip(t - mid, -half, half)
    r = max(r, float(np.max(np.linalg.norm(X - np.outer(seg, a), axis=1))))
    return coal.Capsule(r, 2.0 * half), pin.SE3(_rotation_z_to(a), c + mid * a)


def _rotation_z_to(a: np.ndarray) -> np.ndarray:
    """A rotation matrix taking the z axis to the unit vector ``a``."""
    a = a / np.linalg.norm(a)
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, a)
    s, c = np.linalg.norm(v), float(z @ a)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / (s * s))


#: Shapes per (URDF path, free flyer, geometry): they depend on the URDF only (joint and frame
#: ids of a model built from the same file are the same), so every controller of a robot shares
#: them and the meshes are loaded and hulled once per process.
_SHAPES_CACHE: dict[tuple[Any, ...], dict[str, LinkShape]] = {}


def _link_shape(link: str, objs: list[pin.GeometryObject], geometry: str) -> LinkShape:
    """The simplified shape of one link from its collision geometries (module docstring)."""
    joint, frame = objs[0].parentJoint, objs[0].parentFrame
    sources = tuple(o.name for o in objs)
    if any(o.parentJoint != joint for o in objs):  # pragma: no cover - not produced by URDF
        raise ConfigError(f"link {link!r}: its collision geometries hang on different joints.")
    if len(objs) == 1 and isinstance(objs[0].geometry, _PRIMITIVES):
        o = objs[0]
        pts = _transform(o.placement, primitive_points(o.geometry))
        return LinkShape(
            link, _PRIMITIVE_KIND[type(o.geometry)], o.geometry, joint, frame, o.placement,
            float(np.linalg.norm(pts, axis=1).max()), 0, sources,
        )  # fmt: skip
    if geometry == "convex_hull" and len(objs) == 1:
        # One mesh: hull in the mesh's own frame and placement (same as a hand-built hull).
        o = objs[0]
        hull = coal.Convex.convexHull(_vec3s(primitive_points(o.geometry)), False, "Qt")
        pts = _transform(o.placement, np.asarray(hull.points()))
        return LinkShape(
            link, "convex_hull", hull, joint, frame, o.placement,
            float(np.linalg.norm(pts, axis=1).max()), int(hull.num_points), sources,
        )  # fmt: skip
    pts = np.vstack([_transform(o.placement, primitive_points(o.geometry)) for o in objs])
    if geometry == "convex_hull":
        hull = coal.Convex.convexHull(_vec3s(pts), False, "Qt")
        hp = np.asarray(hull.points())
        return LinkShape(
            link, "convex_hull", hull, joint, frame, pin.SE3.Identity(),
            float(np.linalg.norm(hp, axis=1).max()), int(hull.num_points), sources,
        )  # fmt: skip
    cap, M = fit_capsule(pts)  # capsule
    ends = _transform(M, np.array([[0, 0, -cap.halfLength], [0, 0, cap.halfLength]]))
    return LinkShape(
        link, "capsule", cap, joint, frame, M,
        float(np.linalg.norm(ends, axis=1).max() + cap.radius), 0, sources,
    )  # fmt: skip


def link_shapes(
    robot: RobotModel, geometry: str = "convex_hull", hull_vertices: int | None = None
) -> dict[str, LinkShape]:
    """Simplified collision shape of every link that has collision geometry, built once.

    Args:
        robot: the robot.
        geometry: ``convex_hull`` or ``capsule`` (primitives are kept in both cases).
        hull_vertices: ``convex_hull`` only: hulls with more vertices are replaced by a
            conservative lighter one (:func:`lighter_hull`); ``None`` keeps the exact hulls.

    Returns:
        Link name -> :class:`LinkShape`, in the URDF's geometry order.

    Raises:
        ConfigError: unknown ``geometry`` or a bad ``hull_vertices``.
    """
    if geometry not in GEOMETRIES:
        raise ConfigError(f"geometry must be one of {', '.join(GEOMETRIES)}, got {geometry!r}.")
    if hull_vertices is not None:
        if (
            isinstance(hull_vertices, bool)
            or not isinstance(hull_vertices, int)
            or hull_vertices < 8
        ):
            raise ConfigError(
                f"hull_vertices must be an integer >= 8 or null, got {hull_vertices!r}."
            )
        key_l = (str(robot.urdf_path), bool(robot.free_flyer), geometry, hull_vertices)
        if key_l not in _SHAPES_CACHE:
            exact = link_shapes(robot, geometry)
            _SHAPES_CACHE[key_l] = {
                n: lighter_hull(sh, hull_vertices)
                if sh.kind == "convex_hull" and sh.n_vertices > hull_vertices
                else sh
                for n, sh in exact.items()
            }
        return _SHAPES_CACHE[key_l]
    key = (str(robot.urdf_path), bool(robot.free_flyer), geometry)
    if key in _SHAPES_CACHE:
        return _SHAPES_CACHE[key]
    model = robot.model
    gmodel, _ = robot.geometry()
    groups: dict[str, list[pin.GeometryObject]] = {}
    for go in gmodel.geometryObjects:
        groups.setdefault(model.frames[go.parentFrame].name, []).append(go)
    shapes = {link: _link_shape(link, objs, geometry) for link, objs in groups.items()}
    _SHAPES_CACHE[key] = shapes
    return shapes


def lighter_hull(shape: LinkShape, n_vertices: int) -> LinkShape:
    r"""A hull with at most ``n_vertices`` vertices that still contains ``shape``'s hull.

    The hull :math:`H'` of ``n_vertices`` of the hull's vertices chosen by farthest-point
    sampling lies inside the hull :math:`H`; it is inflated by the largest distance
    :math:`\delta` from a vertex of :math:`H` to :math:`H'` (coal's swept-sphere radius), so
    :math:`H \subset H' \oplus B(\delta)`: distances stay conservative, by at most
    :math:`2\delta` per pair. GJK's cost grows with the vertex count (G1's 20 workload hulls:
    about 40% less time with 128 vertices).
    """
    P = np.asarray(shape.geometry.points(), dtype=float)
    idx = [0]
    dist = np.linalg.norm(P - P[0], axis=1)
    for _ in range(n_vertices - 1):
        i = int(np.argmax(dist))
        idx.append(i)
        np.minimum(dist, np.linalg.norm(P - P[i], axis=1), out=dist)
    light = coal.Convex.convexHull(_vec3s(P[idx]), False, "Qt")
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    point, tf = coal.Sphere(1e-12), coal.Transform3s()
    delta = 0.0
    for x in P:
        tf.setTranslation(x)
        res.clear()  # a DistanceResult keeps the smallest distance of successive calls
        delta = max(delta, coal.distance(point, tf, light, coal.Transform3s(), req, res))
    delta += 1e-6  # GJK tolerance
    light.setSweptSphereRadius(delta)
    return dataclasses.replace(
        shape, geometry=light, radius=shape.radius + delta, n_vertices=int(light.num_points),
        inflation=delta,
    )  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Static obstacles
# ---------------------------------------------------------------------------------------------
def _rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    return pin.rpy.rpyToMatrix(*[float(x) for x in rpy])


class _ObstacleReader:
    """Reads the numbers of one obstacle's YAML mapping, with errors naming the key."""

    def __init__(self, spec: Mapping[str, Any], name: str, kind: Any, path: str) -> None:
        self.spec, self.name, self.kind, self.path = spec, name, kind, path

    def num(self, key: str, n: int | None = None) -> Any:
        """A finite number (``n is None``) or ``n`` finite numbers under ``key``."""
        spec, path = self.spec, self.path
        if key not in spec:
            raise ConfigError(
                f"obstacle {self.name!r} ({self.kind}) needs `{key}`.", path=f"{path}.{key}"
            )
        try:
            arr = np.asarray(spec[key], dtype=float)
        except (TypeError, ValueError):
            arr = np.array([np.nan])
        if (n is None and arr.shape != ()) or (n is not None and arr.shape != (n,)):
            what = "a number" if n is None else f"{n} numbers"
            raise ConfigError(f"`{key}` must be {what}, got {spec[key]!r}.", path=f"{path}.{key}")
        if not np.all(np.isfinite(arr)):
            raise ConfigError(f"`{key}` must be finite, got {spec[key]!r}.", path=f"{path}.{key}")
        return float(arr) if n is None else arr

    def positive(self, key: str) -> float:
        """A length > 0 [m] under ``key``."""
        x = self.num(key)
        if x <= 0:
            raise ConfigError(f"`{key}` must be > 0 [m], got {x}.", path=f"{self.path}.{key}")
        return float(x)


def _obstacle_geometry(r: _ObstacleReader) -> Any:
    """The coal geometry of an obstacle's ``shape:``."""
    kind, path = r.kind, r.path
    if kind == "sphere":
        return coal.Sphere(r.positive("radius"))
    if kind == "box":
        size = r.num("size", 3)
        if np.any(size <= 0):
            raise ConfigError(
                f"`size` must be 3 lengths > 0 [m], got {size.tolist()}.", path=f"{path}.size"
            )
        return coal.Box(*size)
    if kind == "capsule":
        return coal.Capsule(r.positive("radius"), r.positive("length"))
    if kind == "cylinder":
        return coal.Cylinder(r.positive("radius"), r.positive("length"))
    if kind == "halfspace":
        n = r.num("normal", 3)
        if np.linalg.norm(n) < 1e-9:
            raise ConfigError("`normal` must be a non-zero vector.", path=f"{path}.normal")
        return coal.Halfspace(n / np.linalg.norm(n), r.num("offset"))
    raise ConfigError(
        f"obstacle {r.name!r}: shape must be sphere, box, capsule, cylinder or halfspace, "
        f"got {kind!r}.",
        path=f"{path}.shape",
    )


def _obstacle_pose(r: _ObstacleReader) -> pin.SE3:
    """The obstacle's placement in the world: ``pose`` (4x4), or ``position`` and ``rpy``."""
    spec, path = r.spec, r.path
    if "pose" in spec:
        T = np.asarray(spec["pose"], dtype=float)
        if T.shape != (4, 4) or not np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-6):
            raise ConfigError("`pose` must be a 4x4 rigid transform.", path=f"{path}.pose")
        return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
    pos = r.num("position", 3) if "position" in spec else np.zeros(3)
    R = _rpy_matrix(r.num("rpy", 3)) if "rpy" in spec else np.eye(3)
    return pin.SE3(R, pos)


def obstacle_shape(spec: Mapping[str, Any], model: pin.Model, *, path: str = "") -> LinkShape:
    """A static obstacle from its YAML mapping.

    Keys: ``name``, ``shape`` (``sphere``: ``radius``; ``box``: ``size`` [x, y, z] full lengths;
    ``capsule`` / ``cylinder``: ``radius``, ``length`` of the segment along local z;
    ``halfspace``: ``normal``, ``offset`` = {x : n'x <= offset} is the obstacle),
    ``position`` [m] and ``rpy`` [rad] (or ``pose`` as a 4x4 matrix) in the world.

    Raises:
        ConfigError: on a missing or wrong key.
    """
    if not isinstance(spec, Mapping):
        raise ConfigError(
            f"an obstacle must be a mapping with name, shape, ..., got {spec!r}.", path=path
        )
    allowed = {"name", "shape", "radius", "size", "length", "position", "rpy", "pose", "normal",
               "offset"}  # fmt: skip
    unknown = set(spec) - allowed
    if unknown:
        raise ConfigError(
            f"unknown key(s) {sorted(unknown)} for an obstacle; allowed: "
            f"{', '.join(sorted(allowed))}.",
            path=path,
        )
    name = spec.get("name")
    if not isinstance(name, str) or not name:
        raise ConfigError("an obstacle needs a `name:` (string).", path=path)
    r = _ObstacleReader(spec, name, spec.get("shape"), path)
    return LinkShape(name, str(r.kind), _obstacle_geometry(r), 0, 0, _obstacle_pose(r), 0.0)


__all__ = [
    "GEOMETRIES",
    "LinkShape",
    "fit_capsule",
    "lighter_hull",
    "link_shapes",
    "obstacle_shape",
    "primitive_points",
]
