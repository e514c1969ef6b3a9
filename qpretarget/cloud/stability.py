# SPDX-License-Identifier: Apache-2.0
r"""Static balance of the fitted robot (Wang 2017 IV.B.2, eq. 18-19): QP rows and the paper's rule.

The robot is assumed quasi-static, so it balances when the floor projection of its centre of mass
(eq. 18) lies in the support polygon SP, the convex hull of the supporting soles. The fitted
configuration has a free-floating base (the person's pose in the camera's world, z up from the
floor), so the CoM is expressed in a frame :math:`F` at the *primary* supporting sole,
invariant to the base's translation and heading:

.. math::
    c_F = R_F^\top (c - p_F), \qquad
    \frac{\partial c_F}{\partial q} =
    R_F^\top \left(J_c - J_{F,lin} + [c - p_F]_\times\, \omega_F(J_{F,ang})\right).

``frame="sole"`` (the fit's rows, the paper's): :math:`R_F` the sole's own orientation,
:math:`\omega_F = J_{F,ang}`; SP and :math:`c_F` are projected along the sole's normal, which
is the floor's where the sole is flat. ``frame="upright"`` (the command's rows and the person's
margin): :math:`R_F = R_z(\psi)`, the sole's heading :math:`\psi` kept upright, and
:math:`\omega_F = e_z\, a^\top J_{F,ang}` with :math:`\dot\psi = a^\top \omega`,
:math:`a = (-x_z x_x / h^2, -x_z x_y / h^2, 1)` (:math:`x` the sole's x axis in the world,
:math:`h^2 = x_x^2 + x_y^2`): the projection along the vertical, gravity's, whatever the
sole's tilt. The two agree on a flat sole (the command's soles are put down flat). On a tilted
fitted sole they do not: a support sole the fit pitched by 27 deg (boxing, where the cloud
barely shows the foot) put the sole frame's projection of the CoM 0.6 m x sin 27 deg = 27 cm
from the vertical's. The fit keeps the sole frame: its rows are a prior of the fit, and with
the vertical they held the template against the cloud (stop 50, 54 runs: boxing lost, 66-112
deg worst; chicken 5 of 9 runs above 12 deg; docs/point_clouds.md, *Nineteenth round*).

With SP's edges :math:`n_k^\top x \le o_k` (shrunk by
``margin``), each M-step gets the linearized rows
:math:`n_k^\top (c_{F,xy} + J_{F,xy} \Delta) \le o_k` -- this replaces the paper's after-the-fact
hip offsets. ``region: inscribed_circle`` uses the paper's stricter region :math:`C_{SP}`, the
largest disc inside SP (its Chebyshev centre, an LP), as a 16-gon.

:func:`hip_offset_rule` is the paper's own procedure, kept for comparison: :math:`E_b` of eq. 19
is 0 inside :math:`C_{SP}`, infinite outside SP (offset the hips' pitch/roll by 0.3 rad), and
otherwise the vector :math:`\vec{op} = o - p_{FCoM}`; when it grows while keeping its direction
(cosine above cos 30 deg) from one frame to the next, the hips get 0.05 rad. The offset's sign
moves the CoM towards :math:`o` (read from the CoM Jacobian).

Polygon helpers (convex hull, half-planes) come from :mod:`qpretarget.constraints.support_polygon`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..constraints.support_polygon import convex_hull_2d, polygon_halfplanes
from ..errors import ConfigError
from ..robot import RobotModel

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

#: Number of edges of the polygon approximating the inscribed circle.
CIRCLE_EDGES = 16


def chebyshev_centre(normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, float]:
    r"""Centre and radius of the largest disc inside :math:`\{x : N x \le o\}` (unit normals).

    The LP :math:`\max r` s.t. :math:`n_k^\top x + r \le o_k` has an optimal vertex where three
    constraints are active; with the few edges of a support polygon (at most a dozen) every
    triple is solved (a 3x3 system each, vectorised) and the feasible one with the largest
    :math:`r` kept: the LP's optimum, without an LP solver's overhead (2.7 ms per call with
    HiGHS, this one 0.1 ms). Returns (0, 0) and radius 0 for an unbounded region.
    """
    from itertools import combinations

    N = np.asarray(normals, float)
    o = np.asarray(offsets, float)
    K = len(N)
    if K < 3:
        return np.zeros(2), 0.0
    tri = np.array(list(combinations(range(K), 3)))
    A = np.concatenate([N[tri], np.ones((len(tri), 3, 1))], axis=2)  # (T, 3, 3)
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-12
    if not np.any(ok):
        return np.zeros(2), 0.0
    x = np.linalg.solve(A[ok], o[tri[ok]][..., None])[..., 0]  # (T', 3): centre, radius
    feasible = np.all(x[:, :2] @ N.T + x[:, 2:3] <= o + 1e-9, axis=1)
    if not np.any(feasible):
        return np.zeros(2), 0.0
    best = x[feasible][np.argmax(x[feasible, 2])]
    return best[:2].copy(), float(best[2])


_EZ = np.array([0.0, 0.0, 1.0])


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def upright(R: np.ndarray) -> np.ndarray:
    r"""The rotation about the vertical with ``R``'s heading, :math:`R_z(\psi)`.

    :math:`\psi = \operatorname{atan2}(R_{10}, R_{00})`; ``R`` itself when it is flat.
    """
    h = math.hypot(R[0, 0], R[1, 0])
    if h < 1e-12:  # the x axis vertical: no heading
        return np.eye(3)
    c, s = R[0, 0] / h, R[1, 0] / h
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class Support:
    """Supporting feet of one frame.

    Attributes:
        feet: names of the supporting feet (robot foot names); empty in flight.
        primary: the foot at whose sole the polygon is expressed (module docstring).
    """

    feet: list[str] = field(default_factory=list)
    primary: str | None = None


class SupportTracker:
    """Support feet from the sole heights of the fitted (HUMROB) model, with hysteresis.

    A foot is supporting when its sole is within ``support_height`` of the lowest sole; it stays
    supporting until it rises ``release_height`` above it. With the lowest sole higher than
    ``flight_height`` above the floor (z = 0) nobody supports (flight).
    """

    def __init__(
        self,
        robot: RobotModel,
        *,
        support_height: float = 0.04,
        release_height: float = 0.07,
        flight_height: float = 0.25,
    ) -> None:
        if not robot.feet:
            raise ConfigError(
                f"robot {robot.name!r} has no feet: stability needs `feet:` in the robot config "
                "or `stability: {mode: none}`.",
                path="stability",
            )
        self.robot = robot
        self.support_height = float(support_height)
        self.release_height = float(max(release_height, support_height))
        self.flight_height = float(flight_height)
        self.previous = Support()

    def reset(self) -> None:
        self.previous = Support()

    def update(self, sole_heights: dict[str, float]) -> Support:
        """Support of this frame from the sole heights [m] (world z) of the fitted model."""
        zmin = min(sole_heights.values())
        if zmin > self.flight_height:
            self.previous = Support()
            return self.previous
        feet = []
        for f, z in sole_heights.items():
            thr = self.release_height if f in self.previous.feet else self.support_height
            if z - zmin <= thr:
                feet.append(f)
        primary = (
            self.previous.primary
            if self.previous.primary in feet
            else min(feet, key=lambda f: sole_heights[f])
        )
        self.previous = Support(feet, primary)
        return self.previous


class StabilityRows:
    """Linearized CoM-in-support-polygon rows of the robot model, at the primary sole.

    Args:
        robot: the robot (its own masses and lengths, not the HUMROB scaling).
        margin: distance kept from every edge [m].
        region: ``"polygon"`` (SP) or ``"inscribed_circle"`` (:math:`C_{SP}`, Wang 2017 eq. 19).
        n_rows: fixed number of rows (inactive rows have infinite bounds).
        frame: ``"sole"`` (projected along the primary sole's normal, the fit's) or
            ``"upright"`` (along the vertical) (module docstring).
    """

    def __init__(
        self,
        robot: RobotModel,
        *,
        margin: float = 0.01,
        region: str = "polygon",
        n_rows: int = 16,
        frame: str = "sole",
    ) -> None:
        if region not in ("polygon", "inscribed_circle"):
            raise ConfigError(
                f"region must be 'polygon' or 'inscribed_circle', got {region!r}.",
                path="stability.region",
            )
        if frame not in ("sole", "upright"):
            raise ValueError(f"frame must be 'sole' or 'upright', got {frame!r}")
        self.frame = frame
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()
        self.margin = float(margin)
        self.region = region
        self.n_rows = int(max(n_rows, CIRCLE_EDGES))
        self.C = np.zeros((self.n_rows, robot.nv))
        self.u = np.full(self.n_rows, np.inf)
        self.l = np.full(self.n_rows, -np.inf)
        self.normals = np.zeros((0, 2))
        self.offsets = np.zeros(0)
        self.hull = np.zeros((0, 2))
        self.support = Support()
        self._sole_ids = {f: robot.frame_id(d.frame) for f, d in robot.feet.items()}

    # ------------------------------------------------------------------ kinematics
    def _kinematics(self, q: np.ndarray, jacobians: bool) -> None:
        if jacobians:
            pin.computeJointJacobians(self.model, self.data, q)
            pin.updateFramePlacements(self.model, self.data)
        else:
            pin.framesForwardKinematics(self.model, self.data, q)

    def sole_placement(self, q: np.ndarray, foot: str) -> pin.SE3:
        """World placement of a foot's sole frame for the robot at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self._sole_ids[foot]].copy()

    def com_in_sole(
        self, q: np.ndarray, *, jacobian: bool = False
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """CoM in the primary sole frame (3,), and its (3, nv) Jacobian if asked."""
        self._kinematics(q, jacobian)
        fid = self._sole_ids[self.support.primary]  # type: ignore[index]
        M = self.data.oMf[fid]
        if jacobian:
            Jc = pin.jacobianCenterOfMass(self.model, self.data, False)
            c = self.data.com[0]
        else:
            c = pin.centerOfMass(self.model, self.data, q, False)
        d = c - M.translation
        RF = self._frame_rotation(M.rotation)
        cF = RF.T @ d
        if not jacobian:
            return cF, None
        Jf = pin.getFrameJacobian(self.model, self.data, fid, LWA)
        if self.frame == "sole":
            return cF, RF.T @ (Jc - Jf[:3] + _skew(d) @ Jf[3:])
        x = M.rotation[:, 0]
        h2 = max(float(x[0] * x[0] + x[1] * x[1]), 1e-12)
        a = np.array([-x[2] * x[0] / h2, -x[2] * x[1] / h2, 1.0])  # heading rate per omega
        return cF, RF.T @ (Jc - Jf[:3] + np.outer(np.cross(d, _EZ), a @ Jf[3:]))

    def _frame_rotation(self, R: np.ndarray) -> np.ndarray:
        """:math:`R_F` of a primary sole turned ``R``: its own, or upright (``frame``)."""
        return R if self.frame == "sole" else upright(R)

    # ------------------------------------------------------------------ polygon
    def set_support(self, support: Support, q: np.ndarray) -> None:
        """Build the (shrunk) support region in the primary sole frame for the robot at ``q``."""
        self.support = support
        if not support.feet:
            self.normals, self.offsets, self.hull = np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2))
            return
        n, o = self._polygon(q)
        self.centre, self.radius = chebyshev_centre(n, o)
        margin = self._margin = min(self.margin, 0.9 * self.radius)
        if self.region == "polygon":
            self.normals, self.offsets = n, o - margin
        else:
            a = 2 * np.pi * (np.arange(CIRCLE_EDGES) + 0.5) / CIRCLE_EDGES
            nc = np.stack([np.cos(a), np.sin(a)], axis=1)
            self.normals = nc
            self.offsets = nc @ self.centre + np.cos(np.pi / CIRCLE_EDGES) * max(
                self.radius - margin, 0.0
            )
        if len(self.normals) > self.n_rows:
            raise ConfigError(
                f"the support polygon has {len(self.normals)} edges, more than {self.n_rows} rows."
            )

    def _polygon(self, q: np.ndarray, *, kinematics: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Set :attr:`hull` and the unshrunk half-planes at ``q``; return ``(normals, offsets)``.

        ``kinematics=False``: the frames of :attr:`data` are already at ``q``.
        """
        self.hull = self._hull(q, kinematics=kinematics)
        n, o = polygon_halfplanes(self.hull, 0.0)
        self.full_normals, self.full_offsets = n, o
        return n, o

    def _hull(self, q: np.ndarray, *, kinematics: bool = True) -> np.ndarray:
        """Convex hull (K, 2) of the supporting soles at ``q``.

        Their corners projected into the primary sole's frame (``frame``, module docstring).
        """
        if kinematics:
            self._kinematics(q, False)
        MF = self.data.oMf[self._sole_ids[self.support.primary]]  # type: ignore[index]
        RF = self._frame_rotation(MF.rotation)
        pts = []
        for f in self.support.feet:
            x0, x1, y0, y1 = self.robot.feet[f].rectangle
            local = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
            M = self.data.oMf[self._sole_ids[f]]
            world = local @ M.rotation.T + M.translation
            pts.append(((world - MF.translation) @ RF)[:, :2])
        return convex_hull_2d(np.concatenate(pts))

    def _refresh(self, q: np.ndarray, *, kinematics: bool = True) -> None:
        """Rebuild the polygon of a double support at ``q``.

        The margin and, for ``inscribed_circle``, the disc stay those of :meth:`set_support`.
        """
        if len(self.support.feet) < 2:
            return
        n, o = self._polygon(q, kinematics=kinematics)
        if self.region == "polygon" and len(n) <= self.n_rows:
            self.normals, self.offsets = n, o - self._margin

    def margin_of(self, q: np.ndarray, *, full: bool = False) -> float:
        """Signed distance [m] of the projected CoM inside the region (``full``: unshrunk SP).

        ``full`` rebuilds the polygon at ``q`` first (the other soles move with the joints);
        otherwise the region is the one of the last :meth:`rows` (the linearization point).
        """
        if not self.support.feet:
            return np.inf
        if full:
            self._refresh(q)
        cF, _ = self.com_in_sole(q)
        n, o = (self.full_normals, self.full_offsets) if full else (self.normals, self.offsets)
        return float(np.min(o - n @ cF[:2]))

    def rows(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""Rows ``(C, l, u)``: :math:`n_k^\top J_{F,xy} \Delta \le o_k - n_k^\top c_{F,xy}`.

        The region is rebuilt at ``q`` first: in a double support the second sole's corners
        move with the leg joints, and a region kept from the frame's start let the CoM end up
        to a few mm outside the support polygon of the fitted pose.
        """
        self.C[...] = 0.0
        self.u[...] = np.inf
        if not self.support.feet:
            return self.C, self.l, self.u
        cF, JF = self.com_in_sole(q, jacobian=True)  # kinematics and frames at q
        self._refresh(q, kinematics=False)
        k = len(self.normals)
        if k:
            self.C[:k] = self.normals @ JF[:2]  # type: ignore[index]
            self.u[:k] = self.offsets - self.normals @ cF[:2]
        return self.C, self.l, self.u


def hip_joint_indices(robot: RobotModel, names: Sequence[str] | None = None) -> np.ndarray:
    """Velocity indices of the hip pitch/roll joints (names containing ``hip`` and pitch/roll)."""
    if names is None:
        names = [
            n
            for n in robot.joint_names
            if "hip" in n.lower() and ("pitch" in n.lower() or "roll" in n.lower())
        ]
        if not names:
            raise ConfigError(
                f"robot {robot.name!r} has no joint named like '*hip*pitch*' or '*hip*roll*'; "
                "list them in stability.hip_joints.",
                path="stability.hip_joints",
            )
    return np.array(
        [robot.joint_v_index[robot.joint_index(n, path="stability.hip_joints")] for n in names],
        dtype=int,
    )


@dataclass
class HipRuleState:
    r"""Memory of the paper's rule: the previous :math:`\vec{op}` (or None)."""

    op: np.ndarray | None = None


def hip_offset_rule(
    rows: StabilityRows,
    q: np.ndarray,
    hips: np.ndarray,
    memory: HipRuleState,
    *,
    large: float = 0.3,
    small: float = 0.05,
) -> tuple[np.ndarray, str]:
    """Wang 2017 eq. 19 and IV.B.2: offset the hips when the CoM leaves (or heads out of) C_SP.

    Args:
        rows: stability rows with the frame's support set (:meth:`StabilityRows.set_support`).
        q: fitted configuration (nq,).
        hips: velocity indices of the hip pitch/roll joints.
        memory: the rule's state across frames (updated).
        large: the paper's offset outside SP [rad] (0.3).
        small: the paper's offset when the CoM heads out of C_SP [rad] (0.05).

    Returns:
        The corrected configuration and what the rule did (``inside``, ``outside``, ``heading``,
        ``margin``, ``flight``).
    """
    robot = rows.robot
    if not rows.support.feet:
        memory.op = None
        return q, "flight"
    cF, JF = rows.com_in_sole(q, jacobian=True)
    c = cF[:2]
    inside_sp = bool(np.all(rows.full_normals @ c <= rows.full_offsets))
    if np.linalg.norm(c - rows.centre) <= rows.radius:
        memory.op = None
        return q, "inside"
    op = rows.centre - c
    prev = memory.op
    memory.op = op
    if not inside_sp:
        offset, what = large, "outside"
    else:
        if prev is None:
            return q, "margin"
        cos = float(op @ prev / max(np.linalg.norm(op) * np.linalg.norm(prev), 1e-12))
        if not (cos > np.cos(np.deg2rad(30.0)) and np.linalg.norm(op) > np.linalg.norm(prev)):
            return q, "margin"
        offset, what = small, "heading"
    step = np.zeros(robot.nv)
    step[hips] = offset * np.sign(op @ JF[:2, hips])  # type: ignore[index]
    q_new = pin.integrate(robot.model, q, step)
    qi = robot.joint_q_index
    q_new[qi] = np.clip(q_new[qi], robot.q_min[qi], robot.q_max[qi])
    return q_new, what


__all__ = [
    "HipRuleState",
    "StabilityRows",
    "Support",
    "SupportTracker",
    "chebyshev_centre",
    "hip_joint_indices",
    "hip_offset_rule",
]
