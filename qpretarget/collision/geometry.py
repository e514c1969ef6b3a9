# SPDX-License-Identifier: Apache-2.0
r"""Collision geometry built once per robot, and the distances of link pairs for one tick.

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

:class:`CollisionModel` then holds a pinocchio ``GeometryModel`` with only the bodies of the
chosen pairs (plus static obstacles), so one ``updateGeometryPlacements`` + ``computeDistances``
gives every distance and witness point in C++. A conservative broad phase by temporal coherence
skips the pairs that cannot be closer than the influence distance: between two calls no point of
a body moves further than

.. math:: m_g = \sum_j L_{gj}\, |\Delta q_j|,

with :math:`\Delta q = q_1 \ominus q_0` and :math:`L_{gj}` the lever of velocity coordinate
:math:`j` on body :math:`g` (1 for a translation; for a rotation, the length of the kinematic
chain from the joint to the body plus the body's radius), so
:math:`d_{ab} \ge d^{prev}_{ab} - m_a - m_b` is a lower bound that costs one matrix-vector
product per tick. A coordinate that moves both bodies (a common ancestor: the base, the waist)
moves them rigidly together and leaves their distance unchanged, so a pair's bound only sums the
coordinates of the two branches below their common ancestor. Exact distances are computed only
where that bound is below the influence distance.

Distance gradient (witness points :math:`p_a, p_b`, unit normal :math:`n` from :math:`a` to
:math:`b`, :math:`p_b - p_a = d\, n`): the witness points move with their bodies, so

.. math::
    \dot d = n^\top \big(J_b(p_b) - J_a(p_a)\big) v, \qquad
    n^\top J_x(p) = n^\top J^W_{v,x} + (p \times n)^\top J^W_{\omega,x},

where :math:`J^W_x = [J^W_{v,x}; J^W_{\omega,x}]` is the WORLD-frame Jacobian of the body's joint
(linear rows: velocity of the point at the world origin), i.e. ``data.J`` restricted to the
joint's support :math:`S_x`. Since :math:`p_b \times n = p_a \times n`, both bodies share the
coefficients :math:`c = [n;\ p_a \times n]` and all rows of a tick are one
``(k, 6) @ (6, nv)`` product masked by :math:`S_b - S_a`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull

from ..errors import ConfigError, UnknownNameError
from ..robot import RobotModel, RobotState

GEOMETRIES = ("convex_hull", "capsule")
_PRIMITIVES = (coal.Sphere, coal.Box, coal.Cylinder, coal.Capsule, coal.Ellipsoid, coal.Cone)


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
#: Gather of [p | n] (k, 6) giving [p_y p_z p_x p_z p_x p_y | n_z n_x n_y n_y n_z n_x]:
#: p x n = first half * second half, left three minus right three.
_CROSS = np.array([1, 2, 0, 2, 0, 1, 5, 3, 4, 4, 5, 3])


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
_SHAPES_CACHE: dict[tuple[str, bool, str], dict[str, LinkShape]] = {}


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
            _SHAPES_CACHE[key_l] = {  # type: ignore[index]
                n: lighter_hull(sh, hull_vertices)
                if sh.kind == "convex_hull" and sh.n_vertices > hull_vertices
                else sh
                for n, sh in exact.items()
            }
        return _SHAPES_CACHE[key_l]  # type: ignore[index]
    key = (str(robot.urdf_path), bool(robot.free_flyer), geometry)
    if key in _SHAPES_CACHE:
        return _SHAPES_CACHE[key]
    model = robot.model
    gmodel, _ = robot.geometry()
    groups: dict[str, list[pin.GeometryObject]] = {}
    for go in gmodel.geometryObjects:
        groups.setdefault(model.frames[go.parentFrame].name, []).append(go)
    shapes: dict[str, LinkShape] = {}
    for link, objs in groups.items():
        joint, frame = objs[0].parentJoint, objs[0].parentFrame
        sources = tuple(o.name for o in objs)
        if any(o.parentJoint != joint for o in objs):  # pragma: no cover - not produced by URDF
            raise ConfigError(f"link {link!r}: its collision geometries hang on different joints.")
        if len(objs) == 1 and isinstance(objs[0].geometry, _PRIMITIVES):
            o = objs[0]
            pts = _transform(o.placement, primitive_points(o.geometry))
            shapes[link] = LinkShape(
                link, type(o.geometry).__name__.lower(), o.geometry, joint, frame, o.placement,
                float(np.linalg.norm(pts, axis=1).max()), 0, sources,
            )  # fmt: skip
            continue
        if geometry == "convex_hull" and len(objs) == 1:
            # One mesh: hull in the mesh's own frame and placement (same as a hand-built hull).
            o = objs[0]
            hull = coal.Convex.convexHull(_vec3s(primitive_points(o.geometry)), False, "Qt")
            pts = _transform(o.placement, np.asarray(hull.points()))
            shapes[link] = LinkShape(
                link, "convex_hull", hull, joint, frame, o.placement,
                float(np.linalg.norm(pts, axis=1).max()), int(hull.num_points), sources,
            )  # fmt: skip
            continue
        pts = np.vstack([_transform(o.placement, primitive_points(o.geometry)) for o in objs])
        if geometry == "convex_hull":
            hull = coal.Convex.convexHull(_vec3s(pts), False, "Qt")
            hp = np.asarray(hull.points())
            shapes[link] = LinkShape(
                link, "convex_hull", hull, joint, frame, pin.SE3.Identity(),
                float(np.linalg.norm(hp, axis=1).max()), int(hull.num_points), sources,
            )  # fmt: skip
        else:  # capsule
            cap, M = fit_capsule(pts)
            ends = _transform(M, np.array([[0, 0, -cap.halfLength], [0, 0, cap.halfLength]]))
            shapes[link] = LinkShape(
                link, "capsule", cap, joint, frame, M,
                float(np.linalg.norm(ends, axis=1).max() + cap.radius), 0, sources,
            )  # fmt: skip
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
    kind = spec.get("shape")

    def num(key: str, n: int | None = None) -> Any:
        if key not in spec:
            raise ConfigError(f"obstacle {name!r} ({kind}) needs `{key}`.", path=f"{path}.{key}")
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

    def positive(key: str) -> float:
        x = num(key)
        if x <= 0:
            raise ConfigError(f"`{key}` must be > 0 [m], got {x}.", path=f"{path}.{key}")
        return x

    if kind == "sphere":
        geom: Any = coal.Sphere(positive("radius"))
    elif kind == "box":
        size = num("size", 3)
        if np.any(size <= 0):
            raise ConfigError(
                f"`size` must be 3 lengths > 0 [m], got {size.tolist()}.", path=f"{path}.size"
            )
        geom = coal.Box(*size)
    elif kind == "capsule":
        geom = coal.Capsule(positive("radius"), positive("length"))
    elif kind == "cylinder":
        geom = coal.Cylinder(positive("radius"), positive("length"))
    elif kind == "halfspace":
        n = num("normal", 3)
        if np.linalg.norm(n) < 1e-9:
            raise ConfigError("`normal` must be a non-zero vector.", path=f"{path}.normal")
        geom = coal.Halfspace(n / np.linalg.norm(n), num("offset"))
    else:
        raise ConfigError(
            f"obstacle {name!r}: shape must be sphere, box, capsule, cylinder or halfspace, "
            f"got {kind!r}.",
            path=f"{path}.shape",
        )
    if "pose" in spec:
        T = np.asarray(spec["pose"], dtype=float)
        if T.shape != (4, 4) or not np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-6):
            raise ConfigError("`pose` must be a 4x4 rigid transform.", path=f"{path}.pose")
        M = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
    else:
        pos = num("position", 3) if "position" in spec else np.zeros(3)
        R = _rpy_matrix(num("rpy", 3)) if "rpy" in spec else np.eye(3)
        M = pin.SE3(R, pos)
    return LinkShape(name, str(kind), geom, 0, 0, M, 0.0)


# ---------------------------------------------------------------------------------------------
# Distances of pairs
# ---------------------------------------------------------------------------------------------
def _lever_bounds(model: pin.Model, joint: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Speed bounds of the points of a body per unit speed of each velocity coordinate.

    Returns:
        ``(L, R)`` (nv,) each: ``L[j]`` bounds the speed of any point of the body per unit of
        ``v_j`` (1 for a translation, the lever arm for a rotation); ``R[j]`` is the lever arm of
        the rotational coordinates only (0 for translations), for the trust region.
    """
    L = np.zeros(model.nv)
    R = np.zeros(model.nv)
    if joint == 0:
        return L, R
    path = list(model.supports[joint])  # universe ... joint
    # The distance from joint path[k]'s origin to any point of the body is at most the sum of
    # the (constant) origin-to-origin offsets down the chain plus the body's radius.
    offsets = [float(np.linalg.norm(model.jointPlacements[j].translation)) for j in path]
    for k, j in enumerate(path):
        if j == 0:
            continue
        lever = sum(offsets[k + 1 :]) + radius
        jm = model.joints[j]
        kind = jm.shortname()
        idx, nv = jm.idx_v, jm.nv
        if kind == "JointModelFreeFlyer":
            L[idx : idx + 3] = 1.0
            L[idx + 3 : idx + 6] = R[idx + 3 : idx + 6] = lever
        elif kind.startswith("JointModelP") and "Planar" not in kind:  # prismatic
            L[idx : idx + nv] = 1.0
        elif kind == "JointModelPlanar":
            L[idx : idx + 2] = 1.0
            L[idx + 2] = R[idx + 2] = lever
        elif kind == "JointModelTranslation":
            L[idx : idx + nv] = 1.0
        else:  # revolute, spherical, others: rotation about an axis through the joint origin
            R[idx : idx + nv] = lever
            L[idx : idx + nv] = lever + (
                0.0 if kind.startswith(("JointModelR", "JointModelS")) else 1.0
            )
    return L, R
    path = list(model.supports[joint])  # universe ... joint
    # chain[k] = length of the chain from joint path[k] to ``joint`` (sum of constant offsets).
    offsets = [float(np.linalg.norm(model.jointPlacements[j].translation)) for j in path]
    for k, j in enumerate(path):
        if j == 0:
            continue
        lever = sum(offsets[k + 1 :]) + radius
        jm = model.joints[j]
        kind = jm.shortname()
        idx, nv = jm.idx_v, jm.nv
        if kind == "JointModelFreeFlyer":
            L[idx : idx + 3] = 1.0
            L[idx + 3 : idx + 6] = lever
        elif kind.startswith("JointModelP") and "Planar" not in kind:  # prismatic
            L[idx : idx + nv] = 1.0
        elif kind == "JointModelPlanar":
            L[idx : idx + 2] = 1.0
            L[idx + 2] = lever
        elif kind == "JointModelTranslation":
            L[idx : idx + nv] = 1.0
        else:  # revolute, spherical, others: rotation about an axis through the joint origin
            L[idx : idx + nv] = lever + (
                0.0 if kind.startswith(("JointModelR", "JointModelS")) else 1.0
            )
    return L


class CollisionModel:
    r"""Distances, witness points and distance gradients of body pairs, one tick at a time.

    Args:
        robot: the robot.
        pairs: ``(body_a, body_b)`` names; a body is a link with collision geometry or the name
            of one of ``obstacles``.
        geometry: ``convex_hull`` or ``capsule`` for the links (:func:`link_shapes`).
        obstacles: extra static bodies (:class:`LinkShape` from :func:`obstacle_shape`).
        broad_phase: skip pairs whose temporal-coherence lower bound is beyond the influence
            distance (conservative; ``False`` computes every pair every call).
        hysteresis: a pair computed at the last call stays computed while its bound is below
            the influence distance plus this [m] (saves switching pairs on and off).
        hull_vertices: use conservative lighter hulls of at most this many vertices
            (:func:`lighter_hull`); ``None``: exact hulls.
        path: YAML path for error messages.

    Raises:
        UnknownNameError: a body that is neither a link with collision geometry nor an obstacle.
    """

    def __init__(
        self,
        robot: RobotModel,
        pairs: Sequence[tuple[str, str]],
        *,
        geometry: str = "convex_hull",
        obstacles: Sequence[LinkShape] = (),
        broad_phase: bool = True,
        hysteresis: float = 0.0,
        hull_vertices: int | None = None,
        path: str = "",
    ) -> None:
        self.robot = robot
        self.hysteresis = float(hysteresis)
        self.geometry = geometry
        shapes = link_shapes(robot, geometry, hull_vertices)
        known = dict(shapes)
        for ob in obstacles:
            if ob.name in known:
                raise ConfigError(
                    f"obstacle name {ob.name!r} is already a link or obstacle name.", path=path
                )
            known[ob.name] = ob
        self.pairs: list[tuple[str, str]] = []
        bodies: list[str] = []
        for k, pair in enumerate(pairs):
            if isinstance(pair, str) or len(pair) != 2:
                raise ConfigError(
                    f"a pair must be [body_a, body_b], got {pair!r}.", path=f"{path}[{k}]"
                )
            a, b = (str(x) for x in pair)
            for i, body in enumerate((a, b)):
                if body not in known:
                    raise UnknownNameError(
                        "collision body", body, list(known), path=f"{path}[{k}][{i}]",
                        fix="Bodies are links with collision geometry (`qpretarget info CONFIG` "
                        "lists them) or obstacle names.",
                    )  # fmt: skip
            if a == b:
                raise ConfigError(
                    f"pair [{a}, {b}] names the same body twice.", path=f"{path}[{k}]"
                )
            if known[a].joint == 0 and known[b].joint == 0:
                raise ConfigError(f"pair [{a}, {b}]: both bodies are static.", path=f"{path}[{k}]")
            self.pairs.append((a, b))
            for body in (a, b):
                if body not in bodies:
                    bodies.append(body)
        self.bodies = bodies
        self.shapes = [known[b] for b in bodies]
        self.n_pairs = len(self.pairs)
        model = robot.model
        self.gmodel = pin.GeometryModel()
        for s in self.shapes:
            self.gmodel.addGeometryObject(s.geometry_object())
        index = {b: i for i, b in enumerate(bodies)}
        self._ga = np.array([index[a] for a, _ in self.pairs], dtype=int)
        self._gb = np.array([index[b] for _, b in self.pairs], dtype=int)
        for a, b in zip(self._ga, self._gb, strict=True):
            self.gmodel.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self.gdata = self.gmodel.createData()
        for req in self.gdata.distanceRequests:
            req.enable_signed_distance = True
        self._results = list(self.gdata.distanceResults)
        nb = len(bodies)
        # support[g, j] = 1 if velocity coordinate j moves body g; lever[g, j] its speed bound.
        self._support = np.zeros((nb, model.nv))
        self._lever = np.zeros((nb, model.nv))
        self._rot_lever = np.zeros((nb, model.nv))
        for g, s in enumerate(self.shapes):
            if s.joint == 0:
                continue
            for j in model.supports[s.joint]:
                if j == 0:
                    continue
                jm = model.joints[j]
                self._support[g, jm.idx_v : jm.idx_v + jm.nv] = 1.0
            self._lever[g], self._rot_lever[g] = _lever_bounds(model, s.joint, s.radius)
        self.broad_phase = bool(broad_phase)
        # Per pair: bound of the rate of change of the distance per unit |v_j|. A coordinate
        # moving both bodies (a common ancestor: base, waist) moves them rigidly together and
        # leaves the distance unchanged, so only the coordinates of one body's branch count.
        Sa, Sb = self._support[self._ga], self._support[self._gb]
        self._pair_lever = self._lever[self._ga] * (1 - Sb) + self._lever[self._gb] * (1 - Sa)
        self._flags = np.ones(self.n_pairs, dtype=bool)  # mirrors gdata.activeCollisionPairs
        self._flag_bytes = self._flags.tobytes()
        self._idx = np.arange(self.n_pairs)
        self._idx_list = self._idx.tolist()
        self._thr = np.full(self.n_pairs, np.inf)
        self._thr_key = (np.nan, np.nan)
        self._mask_key = b""
        self._mask = np.zeros((0, model.nv))
        #: Distance of every pair after :meth:`update`: exact where :attr:`exact`, else a lower
        #: bound (>= the influence distance of that call).
        self.distances = np.full(self.n_pairs, np.inf)
        self.exact = np.zeros(self.n_pairs, dtype=bool)
        self._model = model
        self._q_last = np.zeros(model.nq)
        self._fresh = True
        #: Indices of the pairs closer than the influence distance, and their witness points
        #: (world, (k, 3)) and unit normals from a to b, after :meth:`update`.
        self.active = np.zeros(0, dtype=int)
        self._pa = np.zeros((0, 3))
        self._n = np.zeros((0, 3))
        #: Time spent in the last :meth:`update` [s] and number of exact pair distances.
        self.last_update_time = 0.0
        self.last_n_computed = 0

    # ------------------------------------------------------------------ per tick
    def invalidate(self) -> None:
        """Forget the temporal-coherence bounds (next :meth:`update` computes every pair)."""
        self._fresh = True

    def update(self, state: RobotState, influence: float = np.inf) -> np.ndarray:
        """Distances of this tick; witness points of the pairs closer than ``influence``.

        Args:
            state: kinematics of the tick (``state.data`` must hold the joint placements and
                ``data.J`` of ``state.q``, as after :meth:`RobotState.update`).
            influence: pairs provably farther than this are not computed exactly [m].

        Returns:
            :attr:`distances` (P,): exact where :attr:`exact`, lower bounds elsewhere.
        """
        t0 = time.perf_counter()
        q = state.q
        lb = self.distances
        if self._fresh or not self.broad_phase or influence == np.inf:
            lb.fill(-np.inf)
            self._fresh = False
        else:
            dq = pin.difference(self._model, self._q_last, q)
            lb -= self._pair_lever @ np.abs(dq, out=dq)
        self._q_last[:] = q
        # Compute a pair while its bound is below the influence distance, and keep computing
        # it until the bound exceeds influence + hysteresis (fewer on/off switches).
        if self.hysteresis > 0:
            if self._thr_key != (influence, self._flag_bytes):
                np.copyto(self._thr, influence)
                self._thr[self._flags] += self.hysteresis
                self._thr_key = (influence, self._flag_bytes)
            need = lb < self._thr
        else:
            need = lb < influence
        nb = need.tobytes()
        if nb != self._flag_bytes:
            gd = self.gdata
            for i in np.flatnonzero(need != self._flags).tolist():
                if need[i]:
                    gd.activateCollisionPair(i)
                else:
                    gd.deactivateCollisionPair(i)
            self._flags = need
            self._flag_bytes = nb
            self._idx = np.flatnonzero(need)
            self._idx_list = self._idx.tolist()
        idx = self._idx
        self.exact = self._flags
        act = idx
        sel: list[Any] = []
        dl: list[float] = []
        if idx.size:
            pin.updateGeometryPlacements(self._model, state.data, self.gmodel, self.gdata)
            pin.computeDistances(self.gmodel, self.gdata)
            res = self._results
            sel = [res[i] for i in self._idx_list]
            dl = [r.min_distance for r in sel]
            lb[idx] = dl
            if max(dl) >= influence:
                keep = [x < influence for x in dl]
                act = idx[keep]
                sel = [r for r, c in zip(sel, keep, strict=True) if c]
                dl = [x for x, c in zip(dl, keep, strict=True) if c]
        self.active = act
        if act.size:
            self._pa = np.array([r.getNearestPoint1() for r in sel])  # witness points on a
            self._n = np.array([r.normal for r in sel])  # unit, from a to b: p_b = p_a + d n
        else:
            self._pa = self._n = np.zeros((0, 3))
        self.last_n_computed = int(idx.size)
        self.last_update_time = time.perf_counter() - t0
        return lb

    @property
    def witness_a(self) -> np.ndarray:
        """World witness points on body a of the :attr:`active` pairs (k, 3)."""
        return self._pa

    @property
    def witness_b(self) -> np.ndarray:
        """World witness points on body b of the :attr:`active` pairs (k, 3)."""
        return self._pa + self.distances[self.active, None] * self._n

    @property
    def normals(self) -> np.ndarray:
        """Unit normals from a to b of the :attr:`active` pairs (k, 3)."""
        return self._n

    def gradients(self, state: RobotState) -> np.ndarray:
        r"""Rows :math:`\partial d / \partial q` (k, nv) of the last update's :attr:`active` pairs.

        :math:`\partial d/\partial q = n^\top (J_b(p_b) - J_a(p_a))` in the tangent space
        (module docstring), from ``state.data.J`` (WORLD joint Jacobians of this tick). As
        :math:`p_b - p_a = d\,n`, :math:`p_b \times n = p_a \times n`: both bodies share the
        coefficients :math:`c = [n;\ p_a \times n]` and the rows are
        :math:`(c^\top J^W) \circ (S_b - S_a)`, one ``(k, 6) @ (6, nv)`` product with the
        difference of the bodies' support masks.
        """
        if self.active.size == 0:
            return np.zeros((0, self.robot.nv))
        return self.point_rows(state, self.active, self._pa, self._n)

    def point_rows(
        self, state: RobotState, pairs: np.ndarray, points: np.ndarray, normals: np.ndarray
    ) -> np.ndarray:
        r"""Rows :math:`n^\top (J_b(p) - J_a(p))` (k, nv) for points on the line of each normal.

        Args:
            state: kinematics of the tick.
            pairs: (k,) pair indices.
            points: (k, 3) world points (witness points on body a; any point on the line
                :math:`p_a + t\,n` gives the same rows).
            normals: (k, 3) unit directions from a to b.
        """
        k = pairs.size
        c = np.empty((k, 6))
        c[:, :3] = normals
        # p x n with one gather (np.cross is slow on small arrays).
        x = np.concatenate([points, normals], axis=1)[:, _CROSS]  # (k, 12)
        prod = x[:, :6] * x[:, 6:]
        np.subtract(prod[:, :3], prod[:, 3:], out=c[:, 3:])
        R = c @ state.data.J  # (k, nv); data.J: WORLD Jacobian of every joint, by column
        key = pairs.tobytes()
        if key != self._mask_key:  # S_b - S_a of these pairs (cached while the set holds)
            self._mask = self._support[self._gb[pairs]] - self._support[self._ga[pairs]]
            self._mask_key = key
        R *= self._mask
        return R

    def pair_levers(self, pairs: np.ndarray) -> np.ndarray:
        """(k, nv) rotation lever arms [m] of each coordinate on either body of ``pairs``.

        0 for coordinates that move neither body (and for translations).
        """
        return np.maximum(self._rot_lever[self._ga[pairs]], self._rot_lever[self._gb[pairs]])

    def compute_all(
        self, state: RobotState
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact distances of every pair, witness points and normals, without the broad phase.

        Returns:
            ``(d (P,), p_a (P, 3), p_b (P, 3), n (P, 3))``.
        """
        self.invalidate()
        self.update(state, np.inf)
        self.invalidate()
        return self.distances.copy(), self.witness_a, self.witness_b, self.normals

    def __repr__(self) -> str:
        return (
            f"CollisionModel(pairs={self.n_pairs}, bodies={len(self.bodies)}, "
            f"geometry={self.geometry!r}, broad_phase={self.broad_phase})"
        )


def pair_distances(
    robot: RobotModel,
    q: np.ndarray,
    pairs: Sequence[tuple[str, str]],
    *,
    geometry: str = "convex_hull",
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact distances of link pairs at configuration ``q`` (offline use: metrics, tests).

    Returns:
        ``(d (P,), p_a (P, 3), p_b (P, 3), n (P, 3))`` with ``p_b - p_a = d n``.
    """
    cm = CollisionModel(robot, pairs, geometry=geometry, broad_phase=False)
    state = RobotState(robot)
    state.update(robot.check_configuration(q))
    return cm.compute_all(state)


def adjacent_links(robot: RobotModel, a: str, b: str, shapes: Mapping[str, LinkShape]) -> bool:
    """``True`` when links ``a`` and ``b`` are on the same joint or on a parent/child joint pair."""
    ja, jb = shapes[a].joint, shapes[b].joint
    parents = robot.model.parents
    return ja == jb or parents[ja] == jb or parents[jb] == ja
