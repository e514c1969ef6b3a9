# SPDX-License-Identifier: Apache-2.0
r"""The HUMROB template (Wang 2017 IV.A): the robot's joints with the subject's proportions.

Points and outward normals are sampled uniformly (by area) on the robot's link meshes and attached
rigidly to the joints that move them. Each body *segment* (pelvis, torso, head, upper arm, forearm,
hand, thigh, shank, foot; left and right share one value) carries a scale factor
:math:`s_k`: the joint placements inside the segment and the segment's template points are
multiplied by it, so the model keeps the robot's joint axes, limits and degrees of freedom while
its limb lengths become the subject's (estimated from a first frame, :mod:`.calibration`).

Posed template point :math:`m` on joint :math:`j` (rigid attachment):

.. math:: v_m = p_j + R_j\, (s_{k(j)}\, v_m^0),

and with linear blend skinning (Wang 2017 eq. 9), points closer than ``blend_radius`` to their
joint are also carried by the parent joint :math:`i`:
:math:`v_m = (1 - w_m)\, T_j v_m^{0} + w_m\, T_i v_m^{0,i}`, :math:`w_m = \tfrac12 (1 - d_m/r)`,
with :math:`v_m^{0,i}` the point in the parent's frame at the reference posture.

Jacobians (Wang 2017 eq. 14 linearized; :meth:`Template.normal_equations`): with :math:`J_j` the
joint's (6, nv) Jacobian in LOCAL_WORLD_ALIGNED and :math:`r_m = v_m - p_j`,

.. math:: \frac{\partial v_m}{\partial q} = J_{j,lin} - [r_m]_\times J_{j,ang},

and for a rigid template the sums over the points of one joint collapse into 6x6 moments, so the
Gauss-Newton matrix :math:`\sum_m P_m J_m^\top J_m` costs one pass over the points plus one
(6 x nv) product per joint.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..robot import RobotModel
from .meshes import LinkMeshes, load_link_meshes

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

#: Segment of each robot key-point (RobotModel.keyframes); the segment starts at that key-point's
#: joint and runs to the next key-point down the tree. Left and right share a segment.
SEGMENT_OF_KEYPOINT: dict[str, str] = {
    "torso": "torso",
    "head": "head",
    "left_shoulder": "upper_arm",
    "right_shoulder": "upper_arm",
    "left_elbow": "forearm",
    "right_elbow": "forearm",
    "left_wrist": "hand",
    "right_wrist": "hand",
    "left_hip": "thigh",
    "right_hip": "thigh",
    "left_knee": "shank",
    "right_knee": "shank",
    "left_ankle": "foot",
    "right_ankle": "foot",
}

ROOT_SEGMENT = "pelvis"


def skew_batch(r: np.ndarray) -> np.ndarray:
    """(K, 3, 3) skew matrices with ``skew(r) @ x == cross(r, x)``."""
    S = np.zeros(r.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -r[..., 2], r[..., 1]
    S[..., 1, 0], S[..., 1, 2] = r[..., 2], -r[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -r[..., 1], r[..., 0]
    return S


def _view_directions() -> np.ndarray:
    """26 unit directions: cube faces, edges and corners."""
    g = np.array(
        [
            (x, y, z)
            for x in (-1, 0, 1)
            for y in (-1, 0, 1)
            for z in (-1, 0, 1)
            if (x, y, z) != (0, 0, 0)
        ],
        float,
    )
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def _outer_points(
    points: np.ndarray, normals: np.ndarray, cell: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Points seen from one of 26 directions (point z-buffer), and normal-orientation votes.

    Returns:
        ``seen`` (K,) booleans and ``vote`` (K,): positive when the normal mostly faces the
        directions the point is seen from.
    """
    seen = np.zeros(len(points), bool)
    vote = np.zeros(len(points))
    for d in _view_directions():
        a = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(d, a)
        depth = points @ d
        cu = np.floor(points @ a / cell).astype(np.int64)
        cv = np.floor(points @ b / cell).astype(np.int64)
        key = (cu - cu.min()) * (cv.max() - cv.min() + 1) + (cv - cv.min())
        _, inv = np.unique(key, return_inverse=True)
        front = np.full(int(inv.max()) + 1, np.inf)
        np.minimum.at(front, inv, depth)
        vis = np.flatnonzero(depth <= front[inv] + cell)
        seen[vis] = True
        vote[vis] -= np.sign(normals[vis] @ d)
    return seen, vote


def _even_subset(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``n`` evenly spread points: one per voxel (size by bisection), ``n`` at random."""
    if len(points) <= n:
        return np.arange(len(points))
    extent = float(np.max(points.max(0) - points.min(0)))
    lo, hi = 1e-5, extent
    best = None
    perm = rng.permutation(len(points))
    pp = points[perm] - points.min(0)
    for _ in range(30):
        v = 0.5 * (lo + hi)
        key = np.floor(pp / v).astype(np.int64)
        dims = key.max(0) + 1
        lin = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
        _, first = np.unique(lin, return_index=True)
        if len(first) >= n:
            best, lo = perm[first], v
        else:
            hi = v
        if hi - lo < 1e-4 * extent:
            break
    if best is None:
        best = perm
    return np.sort(rng.choice(best, size=n, replace=False))


def _rotate_rows(G: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(M, 3) rows ``R_m v_m`` from ``G`` (9, M), the rotations' entries row-major, by component.

    Numpy is slow on many 3x3 products (``einsum("mab,mb->ma")``); nine products of
    contiguous (M,) rows are not.
    """
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    out = np.empty((G.shape[1], 3))
    out[:, 0] = G[0] * x + G[1] * y + G[2] * z
    out[:, 1] = G[3] * x + G[4] * y + G[5] * z
    out[:, 2] = G[6] * x + G[7] * y + G[8] * z
    return out


def _moment_columns(P: np.ndarray, r: np.ndarray, E: np.ndarray) -> np.ndarray:
    """(M, 19) columns P, P r (3), P r r^T (9, row-major), E (3), r x E (3), column by column.

    Filled one column at a time: numpy is slow on many rows of 3 or 9 entries.
    """
    W = np.empty((19, len(P)))  # rows contiguous; returned transposed
    x, y, z = r[:, 0], r[:, 1], r[:, 2]
    W[0] = P
    np.multiply(P, x, out=W[1])
    np.multiply(P, y, out=W[2])
    np.multiply(P, z, out=W[3])
    np.multiply(W[1], x, out=W[4])
    np.multiply(W[1], y, out=W[5])
    np.multiply(W[1], z, out=W[6])
    W[7] = W[5]
    np.multiply(W[2], y, out=W[8])
    np.multiply(W[2], z, out=W[9])
    W[10] = W[6]
    W[11] = W[9]
    np.multiply(W[3], z, out=W[12])
    W[13:16] = E.T
    ex, ey, ez = E[:, 0], E[:, 1], E[:, 2]
    W[16] = y * ez - z * ey
    W[17] = z * ex - x * ez
    W[18] = x * ey - y * ex
    return W.T


def _sandwich(J: np.ndarray, K: np.ndarray) -> np.ndarray:
    r""":math:`\sum_j J_j^\top K_j J_j` for stacks J (n, a, nv) and K (n, a, a), as one product."""
    n, a, nv = J.shape
    return J.reshape(n * a, nv).T @ np.matmul(K, J).reshape(n * a, nv)


@dataclass
class PosedTemplate:
    """Template at one configuration: world points (M, 3), unit normals (M, 3) and the data."""

    points: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray  # (M, 3) r_m = v_m - p_j (world axes), rigid part
    R: np.ndarray  # (njoints, 3, 3)
    p: np.ndarray  # (njoints, 3)
    index: np.ndarray | None = None  # the template points posed (None: all of them, in order)


def segments_of_joints(robot: RobotModel) -> tuple[np.ndarray, tuple[str, ...]]:
    """Segment index of every pinocchio joint (njoints,), and the segment names.

    A joint belongs to the segment of its nearest key-point joint, itself included, going up the
    tree; joints above every key-point belong to the pelvis.
    """
    model = robot.model
    names = [ROOT_SEGMENT]
    key_seg: dict[int, int] = {}
    for key, seg in SEGMENT_OF_KEYPOINT.items():
        frame = robot.keyframes.get(key)
        if frame is None or not model.existFrame(frame):
            continue
        j = model.frames[model.getFrameId(frame)].parentJoint
        if j in key_seg or j <= 1:  # the joint already starts a segment (or is the root)
            continue
        if seg not in names:
            names.append(seg)
        key_seg[j] = names.index(seg)
    segment = np.zeros(model.njoints, dtype=int)
    for j in range(1, model.njoints):
        i = j
        while i > 0 and i not in key_seg:
            i = model.parents[i]
        segment[j] = key_seg.get(i, 0)
    return segment, tuple(names)


#: Joints within this distance of an articulation's first joint move with it [m, robot scale].
ARTICULATION_RADIUS = 0.07


def articulations(robot: RobotModel, seg_of_joint: np.ndarray) -> list[np.ndarray]:
    """Joint groups whose common centre the template may move (one per segment start).

    An articulation is the first joint of a segment (:func:`segments_of_joints`) with the joints
    just above it in the chain whose centres, at the reference posture, are within
    :data:`ARTICULATION_RADIUS` of it (e.g. G1's shoulder pitch and roll, 4 cm apart; hip pitch
    and roll; the three waist joints). A free-flyer root is never part of one.
    """
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, robot.q_reference)
    first = 2 if robot.free_flyer else 1
    par = model.parents
    out = []
    for j in range(first, model.njoints):
        if model.joints[j].nv == 0 or seg_of_joint[j] == seg_of_joint[par[j]]:
            continue
        group = [j]
        i = par[j]
        while i >= first and model.joints[i].nv > 0 and seg_of_joint[i] == seg_of_joint[par[i]]:
            if np.linalg.norm(data.oMi[i].translation - data.oMi[j].translation) > (
                ARTICULATION_RADIUS
            ):
                break
            group.append(i)
            i = par[i]
        out.append(np.array(sorted(group), dtype=int))
    return out


class Template:
    """HUMROB template: sampled surface points on the robot's links, scalable per segment.

    Args:
        robot: the robot (its kinematics, limits and key-points).
        n_points: number of template points (Wang 2017 V.B: 5,000).
        meshes: ``"visual"`` or ``"collision"`` link meshes, or a ready :class:`LinkMeshes`.
        skinning: ``"rigid"`` or ``"lbs"`` (linear blend skinning, Wang 2017 eq. 9).
        blend_radius: distance from a joint within which points are blended with the parent [m].
        seed: random seed of the sampling.
        exclude_links: link names left out of the template (e.g. props, logos).
        link_density_exponent: points per link proportional to its outer area to this power
            (1: uniform density; below 1: small links, which carry the distal joints, get more).

    Attributes:
        model: the HUMROB kinematic model (a copy of the robot's, with scaled segments).
        scales: (K,) current segment scales, in the order of :attr:`segment_names`.
    """

    def __init__(
        self,
        robot: RobotModel,
        *,
        n_points: int = 5000,
        meshes: str | LinkMeshes = "visual",
        skinning: str = "rigid",
        blend_radius: float = 0.04,
        seed: int = 0,
        exclude_links: Sequence[str] = (),
        link_density_exponent: float = 1.0,
    ) -> None:
        if skinning not in ("rigid", "lbs"):
            raise ConfigError(
                f"skinning must be 'rigid' or 'lbs', got {skinning!r}.", path="template.skinning"
            )
        if not (isinstance(n_points, int) and n_points >= 50):
            raise ConfigError(
                f"template points must be an integer >= 50, got {n_points!r}.",
                path="template.points",
            )
        self.robot = robot
        self.skinning = skinning
        self.blend_radius = float(blend_radius)
        self.link_density_exponent = float(link_density_exponent)
        lm = (
            meshes
            if isinstance(meshes, LinkMeshes)
            else load_link_meshes(robot.model, robot.urdf_path, meshes)
        )
        self.meshes = lm
        keep = ~np.isin(np.array(lm.link_names)[lm.link], list(exclude_links))
        self._sample(lm, keep, n_points, np.random.default_rng(seed))
        self.seg_of_joint, self.segment_names = segments_of_joints(robot)
        self.point_segment = self.seg_of_joint[self.joint]
        # Placement translations live in the parent joint's link: scale with the parent's segment.
        model0 = robot.model
        self._t0 = np.array([M.translation.copy() for M in model0.jointPlacements])
        self._seg_t = np.array(
            [self.seg_of_joint[model0.parents[j]] if j > 0 else 0 for j in range(model0.njoints)]
        )
        self._frame_t0 = np.array([f.placement.translation.copy() for f in model0.frames])
        self._frame_seg = np.array([self.seg_of_joint[f.parentJoint] for f in model0.frames])
        self._frame_joint = np.array([f.parentJoint for f in model0.frames])
        # Frames at their joint's origin (the joint and its body frame) mark the joint centre and
        # move with it; the others (soles, hands, sensors) keep their place on the surface.
        self._frame_at_joint = np.linalg.norm(self._frame_t0, axis=1) < 1e-12
        # Joint orientations at the rest configuration of the centre offsets (neutral until
        # set_centre_rest): the surface does not move at that configuration when a centre does.
        data0 = model0.createData()
        pin.forwardKinematics(model0, data0, pin.neutral(model0))
        self._R0 = np.array([M.rotation.copy() for M in data0.oMi])
        self.articulations = articulations(robot, self.seg_of_joint)
        self._articulation_of_joint = np.full(model0.njoints, -1)
        for a, group in enumerate(self.articulations):
            self._articulation_of_joint[group] = a
        self.centre_offsets = np.zeros((model0.njoints, 3))
        self.model = pin.Model(model0)
        self.data = self.model.createData()
        # Ancestor matrix: A[j, i] = 1 when joint i is j or one of its ancestors (i >= 1).
        nj = model0.njoints
        A = np.zeros((nj, nj))
        for j in range(1, nj):
            i = j
            while i > 0:
                A[j, i] = 1.0
                i = model0.parents[i]
        self._ancestors = A
        self._parents = np.array(model0.parents)
        self.scales = np.ones(len(self.segment_names))
        self.set_scales(self.scales)

    # ------------------------------------------------------------------ sampling
    def _sample(self, lm: LinkMeshes, keep: np.ndarray, n: int, rng: np.random.Generator) -> None:
        """Outer-surface, evenly spaced template points with outward normals.

        1. ``max(12 n, 40000)`` candidates uniform by area on the link triangles;
        2. at the reference posture, keep the candidates seen from at least one of 26 directions
           (cube faces, edges and corners) by a point z-buffer of 1 cm cells: the meshes' inner
           faces and hidden parts are dropped, and each normal is turned towards the directions
           it is seen from;
        3. one candidate per voxel, with the voxel size that leaves at least ``n`` voxels, then
           ``n`` of them at random: an even spacing (random sampling leaves clumps and holes,
           which make the mixture's likelihood rugged).
        """
        tris = lm.triangles[keep]
        joint, link = lm.joint[keep], lm.link[keep]
        cr = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        area = 0.5 * np.linalg.norm(cr, axis=1)
        ok = area > 1e-12
        tris, joint, link, cr, area = tris[ok], joint[ok], link[ok], cr[ok], area[ok]
        normal = cr / (2 * area[:, None])
        n_cand = max(12 * n, 40000)
        idx = rng.choice(len(tris), size=n_cand, p=area / area.sum())
        r1, r2 = rng.random(n_cand), rng.random(n_cand)
        s1 = np.sqrt(r1)
        T = tris[idx]
        pts = (
            (1 - s1)[:, None] * T[:, 0]
            + (s1 * (1 - r2))[:, None] * T[:, 1]
            + (s1 * r2)[:, None] * T[:, 2]
        )
        nrm, jnt, lnk = normal[idx], joint[idx], link[idx]
        data = self.robot.model.createData()
        pin.forwardKinematics(self.robot.model, data, self.robot.q_reference)
        R = np.array([M.rotation for M in data.oMi])
        p = np.array([M.translation for M in data.oMi])
        world = np.einsum("kab,kb->ka", R[jnt], pts) + p[jnt]
        wn = np.einsum("kab,kb->ka", R[jnt], nrm)
        seen, vote = _outer_points(world, wn)
        if seen.sum() < n:  # degenerate geometry: keep everything
            seen[:] = True
        flip = vote < 0
        nrm[flip] *= -1
        cand = np.flatnonzero(seen)
        gamma = self.link_density_exponent
        if gamma >= 1.0:
            sel = cand[_even_subset(world[cand], n, rng)]
        else:
            # Points per link proportional to (outer area)^gamma: small distal links get more.
            lk = lnk[cand]
            cnt = np.bincount(lk, minlength=int(lnk.max()) + 1).astype(float)
            share = np.where(cnt > 0, cnt**gamma, 0.0)
            quota = np.floor(n * share / share.sum()).astype(int)
            quota = np.minimum(quota, cnt.astype(int))
            short = n - quota.sum()
            while short > 0:  # hand out the remainder where candidates are left
                room = np.flatnonzero(quota < cnt)
                add = room[np.argsort(-(share[room] - quota[room]))][:short]
                quota[add] += 1
                short = n - quota.sum()
            parts = []
            for li in np.flatnonzero(quota):
                c = cand[lk == li]
                parts.append(c[_even_subset(world[c], int(quota[li]), rng)])
            sel = np.concatenate(parts)
        order = np.argsort(jnt[sel], kind="stable")
        sel = sel[order]
        self.points0 = pts[sel]
        self.normals0 = nrm[sel]
        self.joint = jnt[sel]
        self.link = lnk[sel]
        #: (M,) True where the point is the subject's own surface (:meth:`personalize`), False
        #: where it is still the robot's.
        self.observed = np.zeros(len(sel), bool)

    @property
    def n_points(self) -> int:
        """Number of template points M."""
        return len(self.points0)

    # ------------------------------------------------------------------ scaling
    def set_scales(self, scales: np.ndarray, centre_offsets: np.ndarray | None = None) -> None:
        r"""Apply segment scales (K,) and joint-centre offsets to the model and the points.

        ``centre_offsets`` (njoints, 3) (default: the current ones) moves the centre of joint
        :math:`j` by :math:`e_j` (world axes of the rest configuration, :meth:`set_centre_rest`,
        neutral by default) while the surface stays where it is at that configuration: with
        :math:`R^0_j` the joint's world orientation there and :math:`\pi(j)` its parent,

        .. math::
            t_j = s_{k(\pi(j))}\, t^0_j + R^{0\top}_{\pi(j)} (e_j - e_{\pi(j)}),\qquad
            v^{loc}_m = s_{k(j)}\, v^0_m - R^{0\top}_j e_j .
        """
        s = np.asarray(scales, float).copy()
        if s.shape != (len(self.segment_names),) or np.any(s <= 0):
            raise ConfigError(
                f"scales must be {len(self.segment_names)} positive numbers, got {scales!r}."
            )
        if centre_offsets is not None:
            e = np.asarray(centre_offsets, float)
            if e.shape != self.centre_offsets.shape:
                raise ConfigError(
                    f"centre offsets must be ({self.model.njoints}, 3), got {e.shape}."
                )
            self.centre_offsets = e.copy()
        e = self.centre_offsets
        self.scales = s
        R0, par = self._R0, self._parents
        # All translations computed at once; the loops only hand them to pinocchio.
        tj = self._t0 * s[self._seg_t][:, None] + np.einsum("jba,jb->ja", R0[par], e - e[par])
        placements = self.model.jointPlacements
        for j in range(1, self.model.njoints):
            placements[j].translation = tj[j]
        ej_loc = np.einsum("jba,jb->ja", R0, e)  # R0_j^T e_j
        fj = np.asarray(self._frame_joint)
        tf = np.asarray(self._frame_t0) * s[np.asarray(self._frame_seg)][:, None]
        tf -= np.where(np.asarray(self._frame_at_joint)[:, None], 0.0, ej_loc[fj])
        frames = self.model.frames
        for f in range(len(frames)):
            frames[f].placement.translation = tf[f]
        # self.data stays: placements are read by every kinematics pass, the structure is fixed.
        self.local = self.points0 * s[self.point_segment][:, None] - ej_loc[self.joint]
        self._setup_blend()

    def set_centre_rest(self, q: np.ndarray) -> None:
        """Make ``q`` the configuration at which moving a joint centre leaves the surface in place.

        The calibration sets it to the calibrated pose: the surface fitted there stays, and a
        centre offset shows only where a joint bends away from its calibration angle. Resets
        the centre offsets to zero.
        """
        pin.forwardKinematics(self.model, self.data, np.asarray(q, float))
        self._R0 = np.array([M.rotation.copy() for M in self.data.oMi])
        self._p0 = np.array([M.translation.copy() for M in self.data.oMi])
        self.set_scales(self.scales, np.zeros_like(self.centre_offsets))

    def limb_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit limb direction through each articulation at the rest configuration (A, 3).

        From the articulation's first joint towards the mean of the next articulations down the
        tree (elbow -> wrist); for the last of a chain, from the previous one (elbow -> wrist
        for the wrist). Along this line a straight limb does not show its centres.

        Returns:
            The directions and (A,) booleans: True where an articulation lies further down
            the tree (False for the last of a chain: wrists, ankles).
        """
        p0 = getattr(self, "_p0", None)
        if p0 is None:
            self.set_centre_rest(pin.neutral(self.model))
            p0 = self._p0
        first, below_of, up = self._articulation_tree()
        out = np.zeros((self.n_centres, 3))
        inner = np.zeros(self.n_centres, bool)
        for a, j in enumerate(first):
            below = below_of[a]
            inner[a] = bool(below)
            if below:
                d = np.mean([p0[first[b]] for b in below], axis=0) - p0[j]
            elif up[a] >= 0:
                d = p0[j] - p0[first[up[a]]]
            else:
                d = np.array([0.0, 0.0, 1.0])
            out[a] = d / max(np.linalg.norm(d), 1e-12)
        return out, inner

    def _articulation_tree(self) -> tuple[list[int], list[list[int]], list[int]]:
        """The articulations' tree.

        Returns:
            Each articulation's own joint (its segment's first), the articulations just below
            it, and the one just above it (-1: none).
        """
        first = [int(g.max()) for g in self.articulations]
        up = [self._parent_articulation(a) for a in range(self.n_centres)]
        below = [[b for b, u in enumerate(up) if u == a] for a in range(self.n_centres)]
        return first, below, up

    def _parent_articulation(self, a: int) -> int:
        """The articulation next up the tree from articulation ``a`` (-1: none below the root)."""
        art, par = self._articulation_of_joint, self._parents
        i = int(par[int(min(self.articulations[a]))])
        while i > 0 and art[i] < 0:
            i = int(par[i])
        return int(art[i]) if i > 0 else -1

    def _setup_blend(self) -> None:
        """Blend weights and parent-frame coordinates of the LBS points (reference posture)."""
        self.blend = np.zeros(0, dtype=int)
        self.used_joints = np.unique(self.joint)
        self._group = np.searchsorted(self.used_joints, self.joint)
        if self.skinning != "lbs":
            return
        parent = self._parents[self.joint]
        d = np.linalg.norm(self.local, axis=1)
        sel = np.flatnonzero((parent > 0) & (d < self.blend_radius))
        self.blend = sel
        self.blend_weight = 0.5 * (1.0 - d[sel] / self.blend_radius)
        self.blend_parent = parent[sel]
        # Jacobians are needed for the parents too.
        self.used_joints = np.union1d(self.used_joints, self.blend_parent)
        self._group = np.searchsorted(self.used_joints, self.joint)
        self._blend_group = np.searchsorted(self.used_joints, self.blend_parent)
        pin.forwardKinematics(self.model, self.data, self.robot.q_reference)
        R = np.array([M.rotation for M in self.data.oMi])
        p = np.array([M.translation for M in self.data.oMi])
        j, i = self.joint[sel], self.blend_parent
        world = np.einsum("kab,kb->ka", R[j], self.local[sel]) + p[j]
        self.blend_local = np.einsum("kba,kb->ka", R[i], world - p[i])

    def personalize(
        self,
        q: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        keep: np.ndarray,
        *,
        max_distance: float,
    ) -> int:
        """Give the template the subject's own surface (Wang 2017 IV.A, personalised model).

        Observed points (world, fitted at configuration ``q`` with the current scales) closer than
        ``max_distance`` to a template point are attached rigidly to that point's joint (nearest
        neighbour, the k-NN transfer of the paper) and replace the template points ``~keep``
        (those the sensor saw); the others (back side, hidden parts) stay the robot's.

        Returns:
            The number of observed points attached.
        """
        from scipy.spatial import cKDTree

        posed = self.pose(q, jacobians=False)
        seen = np.flatnonzero(~keep)
        if len(seen) == 0:
            return 0
        dist, nb = cKDTree(posed.points[seen]).query(points)
        ok = dist <= max_distance
        if not ok.any():
            return 0
        src = seen[nb[ok]]
        j = self.joint[src]
        R, p = posed.R[j], posed.p[j]
        local = np.einsum("kba,kb->ka", R, points[ok] - p)
        nloc = np.einsum("kba,kb->ka", R, normals[ok])
        seg = self.seg_of_joint[j]
        kept = np.flatnonzero(keep)
        ej = np.einsum("kba,kb->ka", self._R0[j], self.centre_offsets[j])
        self.points0 = np.concatenate(
            [self.points0[kept], (local + ej) / self.scales[seg][:, None]]
        )
        self.normals0 = np.concatenate([self.normals0[kept], nloc])
        self.joint = np.concatenate([self.joint[kept], j])
        self.link = np.concatenate([self.link[kept], self.link[src]])
        self.observed = np.concatenate([self.observed[kept], np.ones(len(j), bool)])
        order = np.argsort(self.joint, kind="stable")
        self.points0, self.normals0 = self.points0[order], self.normals0[order]
        self.joint, self.link = self.joint[order], self.link[order]
        self.observed = self.observed[order]
        self.point_segment = self.seg_of_joint[self.joint]
        self.set_scales(self.scales)
        return int(ok.sum())

    #: What :meth:`personalize`, :meth:`personalize_more`, :meth:`assign_by_centres`,
    #: :meth:`set_scales` and :meth:`set_centre_rest` change (:meth:`surface_state`).
    _STATE = (
        "points0",
        "normals0",
        "joint",
        "link",
        "observed",
        "point_segment",
        "scales",
        "centre_offsets",
        "_R0",
    )

    def surface_state(self) -> dict[str, np.ndarray]:
        """Copies of the template's points, their joints, scales and centres (a snapshot).

        :meth:`restore_surface` puts them back: a fitter that calibrates again (a new person,
        a new run) starts from the template as it was built, not from the previous subject's
        personalised surface.
        """
        return {k: np.array(getattr(self, k), copy=True) for k in self._STATE}

    def restore_surface(self, state: dict[str, np.ndarray]) -> None:
        """Put back a :meth:`surface_state` (and the model's placements with its scales)."""
        for k in self._STATE:
            setattr(self, k, np.array(state[k], copy=True))
        self.set_scales(self.scales)

    def personalize_more(
        self,
        q: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        visible: np.ndarray,
        *,
        max_distance: float,
        allowed: np.ndarray | None = None,
    ) -> int:
        r"""Give the subject's surface to the robot's points the sensor sees now (online IV.A).

        The calibration frame shows one side of the person (:meth:`personalize`); the rest of
        the template stays the robot's surface, scaled. When the person turns, raises an arm or
        bends, parts the calibration never saw come into view, and there the robot's shape
        (G1's boxy torso and thin arms) biases the fit: on CMU 17_10 boxing the torso settled
        20 deg from the person's heading at a lower NLL than the person's own heading.

        Of the cloud ``points`` (world, fitted at ``q``), those whose nearest ``visible``
        template point is still the robot's (``~observed``) and within ``max_distance`` of it
        are attached to that point's joint; the robot's visible points with such a cloud point
        within ``max_distance`` are dropped (:meth:`personalize` with them as the seen ones).
        The subject's points already in the template stay. ``allowed`` (M,) limits the points
        that may be replaced (e.g. the trunk's segments): a cloud point whose nearest visible
        template point is not allowed is left out.

        Returns:
            The number of cloud points attached (0: nothing new in view).
        """
        from .neighbours import knn

        fresh = np.asarray(visible, bool) & ~self.observed
        if allowed is not None:
            fresh &= np.asarray(allowed, bool)
        vis = np.flatnonzero(visible)
        if not fresh.any() or len(points) == 0:
            return 0
        posed = self.pose(q, jacobians=False, normals=False)
        d2, nb = knn(posed.points[vis], points, 1)
        take = (d2[:, 0] <= max_distance**2) & fresh[vis[nb[:, 0]]]
        if not take.any():
            return 0
        cand = np.flatnonzero(fresh)
        d2_back, _ = knn(points[take], posed.points[cand], 1)
        drop = np.zeros(self.n_points, bool)
        drop[cand[d2_back[:, 0] <= max_distance**2]] = True
        if not drop.any():
            return 0
        return self.personalize(q, points[take], normals[take], ~drop, max_distance=max_distance)

    def assign_by_centres(self, q: np.ndarray, *, reach: float = 0.15) -> int:
        r"""Cut each limb's surface into segments at the moved joint centres.

        The template's points belong to the joint of the robot's link they were sampled on
        (personalised: of the nearest such point), so a limb's surface is cut where the
        *robot's* links meet. Once an articulation's centre is moved to the person's
        (:meth:`set_centres`; G1's elbows sit 8-9 cm up the arm from a person's), the points
        between the two cuts ride on the wrong segment: bending the elbow moves part of the
        upper arm's surface with the forearm. (Departs from Wang 2017 IV.A, whose template
        takes its segments from a parametric human model; ours are the robot's links.)

        At ``q`` (the centres' rest configuration, where moving a centre leaves the surface in
        place), for each articulation :math:`a` with a moved centre :math:`c_a` and a parent
        articulation :math:`b` up the same limb (not the trunk's: shoulders and hips are
        left), with :math:`u = (c_a - c_b)/\|c_a - c_b\|` and a point's
        :math:`s = u^\top (v_m - c_a)`, among the points within ``reach`` of :math:`c_a`
        along :math:`u` and of the axis: a point of the parent segment with :math:`s > 0`
        moves to the articulation's own joint, a point of the child segment with
        :math:`s < 0` to the joint carrying the parent segment's last link. Its position and
        normal at ``q`` stay (new local coordinates in its new joint's frame).

        Returns:
            The number of points moved to another joint.
        """
        posed = self.pose(q, jacobians=False)
        w, p = posed.points, posed.p
        seg = self.seg_of_joint
        trunk = [k for k, n in enumerate(self.segment_names) if n in (ROOT_SEGMENT, "torso")]
        joint = self.joint.copy()
        for a, group in enumerate(self.articulations):
            own = int(max(group))
            above = int(self._parents[int(min(group))])  # carries the parent segment's last link
            b = self._parent_articulation(a)
            if np.linalg.norm(self.centre_offsets[own]) < 1e-3 or seg[above] in trunk or b < 0:
                continue
            u = p[own] - p[int(max(self.articulations[b]))]
            u /= max(float(np.linalg.norm(u)), 1e-12)
            d = w - p[own]
            s = d @ u
            radial = np.linalg.norm(d - s[:, None] * u, axis=1)
            near = (np.abs(s) <= reach) & (radial <= reach)
            joint[near & (s > 0) & (seg[self.joint] == seg[above])] = own
            joint[near & (s < 0) & (seg[self.joint] == seg[own])] = above
        return self._reattach(posed, joint)

    def limbs_as_tubes(self, q: np.ndarray, segments: list[int], *, bin_width: float = 0.02) -> int:
        r"""Replace the limbs' surfaces by tubes about their joint-centre lines (a person's limb).

        For each articulation whose segment is in ``segments`` (e.g. upper arm, forearm) with
        an articulation below it, the line from its centre :math:`c_0` to the next one's
        :math:`c_1` at ``q`` (:math:`u = (c_1 - c_0)/|c_1 - c_0|`), and the segment's points
        on that side: :math:`s = u^\top (v - c_0)`, :math:`\rho = |(I - u u^\top)(v - c_0)|`.
        The radius profile :math:`r(s)` is the median :math:`\rho` of the subject's own
        points (:attr:`observed`; all points when fewer than 20) in ``bin_width`` bins, the
        empty bins interpolated; the segment's points are replaced by as many points evenly
        spread on the surface of revolution :math:`c_0 + s u + r(s)(\cos\varphi\, a +
        \sin\varphi\, b)` over the points' range of :math:`s` (not above :math:`c_0`),
        normals radial, each attached to the joint of the nearest point it replaces.

        A person's long bones run along the middle of their limbs, so that the limb's axis and
        its centre line are one; the robot's links are not tubes (G1's shoulder-roll housing
        stands off the upper arm's side), and a fit that lays them on a person's arm tilts the
        centre line by what their shape is off it (on CMU 14_37's calibration frame, the left
        upper arm's points' axis 5.9 deg from its centre line).

        Returns:
            The number of points replaced.
        """
        first, below_of, _ = self._articulation_tree()
        replaced = 0
        for a, j0 in enumerate(first):
            k = int(self.seg_of_joint[j0])
            below = below_of[a]
            if k not in segments or not below:
                continue
            posed = self.pose(q, jacobians=False)  # the points are re-sorted by each tube
            c0, c1 = posed.p[j0], posed.p[first[below[0]]]
            length = float(np.linalg.norm(c1 - c0))
            mine = (self.point_segment == k) & (self._ancestors[self.joint, j0] > 0)
            if length < 1e-6 or mine.sum() < 10:
                continue
            u = (c1 - c0) / length
            d = posed.points[mine] - c0
            sv = d @ u
            rho = np.linalg.norm(d - np.outer(sv, u), axis=1)
            obs = self.observed[mine]
            src = obs if obs.sum() >= 20 else np.ones(len(sv), bool)
            lo, hi = max(float(np.percentile(sv, 2)), 0.0), float(np.percentile(sv, 98))
            if hi - lo < 2 * bin_width:
                continue
            edges = np.linspace(lo, hi, max(int(round((hi - lo) / bin_width)), 2) + 1)
            mids = 0.5 * (edges[1:] + edges[:-1])
            med = np.full(len(mids), np.nan)
            for i in range(len(mids)):
                sel = src & (sv >= edges[i]) & (sv <= edges[i + 1])
                if sel.sum() >= 3:
                    med[i] = np.median(rho[sel])
            ok = np.isfinite(med)
            if not ok.any():
                continue
            med = np.interp(mids, mids[ok], med[ok])
            n = int(mine.sum())
            h = np.sqrt(2.0 * np.pi * float(med.mean()) * (hi - lo) / n)
            n_s = max(int(np.ceil((hi - lo) / h)), 2)
            n_phi = max(int(round(n / n_s)), 6)
            e1 = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(u, e1)
            pts, nrm = [], []
            for i, si in enumerate(lo + (np.arange(n_s) + 0.5) * (hi - lo) / n_s):
                phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5 * (i % 2)) / n_phi
                radial = np.outer(np.cos(phi), e1) + np.outer(np.sin(phi), e2)
                pts.append(c0 + si * u + float(np.interp(si, mids, med)) * radial)
                nrm.append(radial)
            # each attached to the joint of the nearest point it replaces (this limb's only)
            self.personalize(q, np.concatenate(pts), np.concatenate(nrm), ~mine, max_distance=1.0)
            replaced += n
        return replaced

    def attach_rigidly(self, q: np.ndarray, segments: list[int]) -> int:
        r"""Make each of ``segments`` one rigid body: its points ride with its first joint.

        A segment runs from the joint that starts it (:func:`segments_of_joints`) down to the
        next key-point; the joints in between move parts of it. G1's torso segment holds its
        shoulder-pitch links, which turn with the arms' pitch: after the calibration they carry
        the person's chest and shoulder surface (:meth:`personalize`), and a raised arm then
        swings that surface about, which pulls the fit's torso and the shoulders' centre
        estimate (docs/point_clouds.md, *Ninth* and *Tenth rounds*). At ``q`` (the
        calibrated pose) every point of a segment in ``segments`` on a joint :math:`j` that is
        not the segment's first joint :math:`j_0` is attached to :math:`j_0`, its position and
        normal at ``q`` kept (new local coordinates in :math:`j_0`'s frame).

        Returns:
            The number of points moved to another joint.
        """
        seg = self.seg_of_joint
        first = np.arange(len(seg))  # each joint's first joint of its segment (left, right apart)
        for j in range(1, len(seg)):  # parents come first
            parent = int(self._parents[j])
            if parent > 0 and seg[parent] == seg[j]:
                first[j] = first[parent]
        rigid = np.isin(seg[self.joint], segments)
        joint = np.where(rigid, first[self.joint], self.joint)
        return self._reattach(self.pose(q, jacobians=False), joint)

    def _reattach(self, posed: PosedTemplate, joint: np.ndarray) -> int:
        """Attach the points to ``joint`` (M,), keeping their place and normal at ``posed``."""
        moved = np.flatnonzero(joint != self.joint)
        if len(moved) == 0:
            return 0
        w, nw, p, R = posed.points, posed.normals, posed.p, posed.R
        seg = self.seg_of_joint
        j = joint[moved]
        e_loc = np.einsum("kba,kb->ka", self._R0[j], self.centre_offsets[j])
        local = np.einsum("kba,kb->ka", R[j], w[moved] - p[j])
        self.points0[moved] = (local + e_loc) / self.scales[seg[j]][:, None]
        self.normals0[moved] = np.einsum("kba,kb->ka", R[j], nw[moved])
        self.joint = joint
        order = np.argsort(self.joint, kind="stable")
        self.points0, self.normals0 = self.points0[order], self.normals0[order]
        self.joint, self.link = self.joint[order], self.link[order]
        self.observed = self.observed[order]
        self.point_segment = self.seg_of_joint[self.joint]
        self.set_scales(self.scales)
        return len(moved)

    def frame_scale(self, frame_id: int) -> float:
        """Scale factor of the segment a frame belongs to."""
        return float(self.scales[self._frame_seg[frame_id]])

    # ------------------------------------------------------------------ kinematics
    def pose(
        self,
        q: np.ndarray,
        *,
        jacobians: bool = True,
        index: np.ndarray | None = None,
        normals: bool = True,
    ) -> PosedTemplate:
        """Forward kinematics (and joint Jacobians) of the HUMROB model: points and normals.

        ``index`` (sorted point indices, rigid skinning only) poses those points alone, in
        that order: a frame's fit uses only the points the sensor can see, which are the same
        throughout the frame (:meth:`subset`). With ``normals=False`` (the position stages'
        line searches) the normals are not computed: an empty (0, 3) array.
        """
        model, data = self.model, self.data
        if jacobians:
            pin.computeJointJacobians(model, data, q)
        else:
            pin.forwardKinematics(model, data, q)
        Hom = np.array([M.homogeneous for M in data.oMi])  # one pass over the joints
        R = Hom[:, :3, :3]
        p = Hom[:, :3, 3]
        joint, local, normals0 = self.joint, self.local, self.normals0
        if index is not None:
            if len(self.blend):
                raise ValueError("posing a subset of the points needs rigid skinning")
            joint, local, normals0 = self.subset(index)
        G = np.take(R.reshape(len(R), 9).T, joint, axis=1)  # (9, M) rows contiguous
        off = _rotate_rows(G, local)
        pts = off + np.take(p, joint, axis=0)
        nrm = _rotate_rows(G, normals0) if normals else np.zeros((0, 3))
        if index is not None:
            return PosedTemplate(pts, nrm, off, R, p, index)
        if len(self.blend):
            w = self.blend_weight[:, None]
            i = self.blend_parent
            other = np.einsum("kab,kb->ka", R[i], self.blend_local) + p[i]
            pts[self.blend] = (1 - w) * pts[self.blend] + w * other
        return PosedTemplate(pts, nrm, off, R, p)

    def subset(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joints, local coordinates and normals of the points ``index`` (kept while both stay).

        The gathers are cached: a frame poses the same subset 20-30 times, and the local
        coordinates change only with :meth:`set_scales` (a new array each time).
        """
        c = getattr(self, "_subset_cache", None)
        if (
            c is None
            or c[1] is not self.local
            or c[0].shape != index.shape
            or not np.array_equal(c[0], index)
        ):
            index = np.array(index)
            c = (index, self.local, self.joint[index], self.local[index], self.normals0[index])
            self._subset_cache = c
        return c[2], c[3], c[4]

    def joint_jacobians(self) -> np.ndarray:
        """(J, 6, nv) LOCAL_WORLD_ALIGNED Jacobians of :attr:`used_joints` (after :meth:`pose`)."""
        return np.array(
            [pin.getJointJacobian(self.model, self.data, int(j), LWA) for j in self.used_joints]
        )

    def point_jacobians(
        self, posed: PosedTemplate, J6: np.ndarray, index: np.ndarray | None = None
    ) -> np.ndarray:
        """Explicit (K, 3, nv) Jacobians of template points ``index`` (default: all).

        Used for blended (LBS) points and in tests; the rigid M-step uses
        :meth:`normal_equations` instead.
        """
        idx = np.arange(self.n_points) if index is None else np.asarray(index)
        g = self._group[idx]
        Jl, Ja = J6[g, :3], J6[g, 3:]
        r = posed.offsets[idx]
        out = Jl - np.einsum("kab,kbn->kan", skew_batch(r), Ja)
        if len(self.blend):
            pos = np.minimum(np.searchsorted(self.blend, idx), len(self.blend) - 1)
            hit = self.blend[pos] == idx
            if hit.any():
                k = pos[hit]
                Jp = J6[self._blend_group[k]]
                rp = np.einsum("kab,kb->ka", posed.R[self.blend_parent[k]], self.blend_local[k])
                Jpar = Jp[:, :3] - np.einsum("kab,kbn->kan", skew_batch(rp), Jp[:, 3:])
                w = self.blend_weight[k][:, None, None]
                out[hit] = (1 - w) * out[hit] + w * Jpar
        return out

    def _group_sums(self, W: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """(J, c) sums of the rows of ``W`` (M, c) over the points of each used joint.

        ``index``: the rows of ``W`` are the template points ``index`` (a posed subset).
        """
        g = self._group
        cache = getattr(self, "_group_matrix", None)
        if (
            cache is None
            or not (cache[0] is g or np.array_equal(cache[0], g))  # set_scales makes a new g
            or (cache[1] is None) != (index is None)
            or (index is not None and not np.array_equal(cache[1], index))
        ):
            from scipy.sparse import csr_matrix

            gi = g if index is None else g[index]
            M = len(gi)
            G = csr_matrix((np.ones(M), (gi, np.arange(M))), shape=(len(self.used_joints), M))
            cache = self._group_matrix = (g, None if index is None else np.array(index), G)
        return np.asarray(cache[2] @ W)

    def normal_equations(
        self,
        posed: PosedTemplate,
        J6: np.ndarray,
        P1: np.ndarray,
        E: np.ndarray,
        *,
        normal_weight: float = 0.0,
        P1n: np.ndarray | None = None,
        En: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Gauss-Newton matrix and vector of the M-step (Wang 2017 eq. 13, 15 linearized).

        .. math::
            H = \sum_m P_m J_m^\top J_m
                + \lambda_\perp \sum_m P_m J_{\omega}^\top (I - n_m n_m^\top) J_{\omega},\quad
            b = \sum_m J_m^\top e_m + \lambda_\perp \sum_m J_\omega^\top (n_m \times e^\perp_m)

        with :math:`P_m = \sum_n p_{mn}`, :math:`e_m = \sum_n p_{mn} s_n - P_m v_m` and
        :math:`e^\perp_m = \sum_n p_{mn} s^\perp_n - P_m n_m`; the step minimises
        :math:`\tfrac12 \Delta^\top H \Delta - b^\top \Delta` (divide both by :math:`\sigma^2`).

        Args:
            posed: the posed template.
            J6: (J, 6, nv) joint Jacobians (:meth:`joint_jacobians`).
            P1: (M,) posterior mass per point.
            E: (M, 3) position residual sums :math:`e_m`.
            normal_weight: :math:`\lambda_\perp`.
            P1n: (M,) posterior mass per point of the normal term.
            En: (M, 3) normal residual sums :math:`e^\perp_m`.
        """
        if len(self.blend):
            Jm = self.point_jacobians(posed, J6)
            Jw = Jm * np.sqrt(P1)[:, None, None]
            H = np.einsum("man,mak->nk", Jw, Jw)
            b = np.einsum("man,ma->n", Jm, E)
        else:
            nJ = len(self.used_joints)
            r = posed.offsets
            # Per-joint sums of P, P r, P r r^T, e, r x e: one sparse product.
            sums = self._group_sums(_moment_columns(P1, r, E), posed.index)
            w0, c, rr = sums[:, 0], sums[:, 1:4], sums[:, 4:13].reshape(nJ, 3, 3)
            f, tau = sums[:, 13:16], sums[:, 16:19]
            K = np.zeros((nJ, 6, 6))
            K[:, 0, 0] = K[:, 1, 1] = K[:, 2, 2] = w0
            Sc = skew_batch(c)
            K[:, :3, 3:] = -Sc
            K[:, 3:, :3] = Sc
            K[:, 3:, 3:] = np.trace(rr, axis1=1, axis2=2)[:, None, None] * np.eye(3) - rr
            H = _sandwich(J6, K)
            b = np.einsum("jan,ja->n", J6, np.concatenate([f, tau], 1))
        if normal_weight > 0 and P1n is not None and En is not None:
            nJ = len(self.used_joints)
            n = posed.normals
            sums = self._group_sums(_moment_columns(P1n, n, En), posed.index)
            w0, nn, tau = sums[:, 0], sums[:, 4:13].reshape(nJ, 3, 3), sums[:, 16:19]
            Kn = w0[:, None, None] * np.eye(3) - nn
            Ja = J6[:, 3:]
            H = H + normal_weight * _sandwich(Ja, Kn)
            b = b + normal_weight * np.einsum("jan,ja->n", Ja, tau)
        return H, b

    # ------------------------------------------------------------------ scale Jacobian
    def scale_jacobian(self, posed: PosedTemplate) -> np.ndarray:
        r"""(M, 3, K) derivative of the posed points with respect to the segment scales.

        Points are linear in the scales at fixed joint angles:
        :math:`v_m = p_{root} + \sum_{i \preceq j} s_{k(i)} R_{\pi(i)} t_i^0 + s_{k(j)} R_j v^0_m`.
        """
        K = len(self.segment_names)
        R, par = posed.R, self._parents
        D = np.zeros((self.model.njoints, 3))
        D[1:] = np.einsum("iab,ib->ia", R[par[1:]], self._t0[1:])
        Dk = np.zeros((self.model.njoints, 3, K))
        Dk[np.arange(self.model.njoints), :, self._seg_t] = D
        P = np.einsum("ji,iak->jak", self._ancestors, Dk)
        out = P[self.joint].copy()
        own = np.einsum("mab,mb->ma", R[self.joint], self.points0)
        out[np.arange(self.n_points), :, self.point_segment] += own
        return out

    # ------------------------------------------------------------------ joint centres
    @property
    def n_centres(self) -> int:
        """Number of articulations whose centre can move (3 offset coordinates each)."""
        return len(self.articulations)

    def centres(self) -> np.ndarray:
        """(A, 3) offsets of the articulations' centres (rest-configuration world axes) [m]."""
        return np.array([self.centre_offsets[g[0]] for g in self.articulations]).reshape(-1, 3)

    def set_centres(self, offsets: np.ndarray) -> None:
        """Move every articulation's joints by its offset (A, 3); the scales stay."""
        x = np.asarray(offsets, float).reshape(-1, 3)
        e = np.zeros_like(self.centre_offsets)
        for a, group in enumerate(self.articulations):
            e[group] = x[a]
        self.set_scales(self.scales, e)

    def centre_jacobian_blocks(self, posed: PosedTemplate) -> np.ndarray:
        r"""(J, 3, 3A) derivative of the points of each used joint w.r.t. the centre offsets.

        The offsets enter linearly at fixed joint angles; for a point of joint :math:`j` (rigid)
        and every joint :math:`i` on the path from the root to :math:`j`,

        .. math:: \frac{\partial v_m}{\partial e_i} = R_{\pi(i)} R^{0\top}_{\pi(i)}
            - R_i R^{0\top}_i ,

        zero while joint :math:`i` is at its rest angle: a joint centre is seen only when the
        joint bends. The joints of an articulation share one offset (their terms add up). The
        derivative is the same for all points of a joint.
        """
        R, R0, par = posed.R, self._R0, self._parents
        art = self._articulation_of_joint
        moving = np.flatnonzero(art >= 0)  # joints of an articulation
        p = par[moving]
        G = R[p] @ np.swapaxes(R0[p], 1, 2) - R[moving] @ np.swapaxes(R0[moving], 1, 2)
        # Sum over each point joint's ancestors i, into the block of art[i].
        W = self._ancestors[np.ix_(self.used_joints, moving)]  # (J, I)
        onehot = np.eye(self.n_centres)[art[moving]]  # (I, A)
        out = np.einsum("ji,ia,ibc->jbac", W, onehot, G)
        return out.reshape(len(self.used_joints), 3, 3 * self.n_centres)

    def centre_normal_equations(
        self,
        posed: PosedTemplate,
        J6: np.ndarray,
        P1: np.ndarray,
        E: np.ndarray,
        basis: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""Blocks of the Gauss-Newton system in the centre offsets (rigid template).

        Returns ``H_qe`` (nv, 3C), ``H_ee`` (3C, 3C) and ``b_e`` (3C,): with :math:`D_j` the
        points' common derivative (:meth:`centre_jacobian_blocks`), :math:`w_j = \sum P_m`,
        :math:`c_j = \sum P_m r_m` and :math:`f_j = \sum e_m` over the points of joint j,
        :math:`H_{ee} = \sum_j w_j D_j^\top D_j`, :math:`b_e = \sum_j D_j^\top f_j`,
        :math:`H_{qe} = \sum_j (w_j J_{j,lin} - [c_j]_\times J_{j,ang})^\top D_j`.
        LBS points count with their own joint only (an approximation; the step is checked).
        With ``basis`` U (3C, c) the offsets are :math:`U x` and the blocks are those of x:
        :math:`U^\top H_{ee} U`, :math:`H_{qe} U`, :math:`U^\top b_e` (D projected first).
        """
        D = self.centre_jacobian_blocks(posed)
        if basis is not None:
            D = D @ basis
        W = _moment_columns(P1, posed.offsets, E)
        sums = self._group_sums(W[:, [0, 1, 2, 3, 13, 14, 15]], posed.index)
        w0, c, f = sums[:, 0], sums[:, 1:4], sums[:, 4:7]
        A = w0[:, None, None] * J6[:, :3] - np.matmul(skew_batch(c), J6[:, 3:])  # (J, 3, nv)
        H_qe = np.einsum("jan,jac->nc", A, D)
        Dw = D * w0[:, None, None]
        H_ee = Dw.reshape(-1, D.shape[2]).T @ D.reshape(-1, D.shape[2])
        b_e = np.einsum("jac,ja->c", D, f)
        return H_qe, H_ee, b_e

    def __repr__(self) -> str:
        sc = ", ".join(f"{n}={s:.3f}" for n, s in zip(self.segment_names, self.scales, strict=True))
        return (
            f"Template(robot={self.robot.name!r}, points={self.n_points}, "
            f"skinning={self.skinning!r}, scales=({sc}))"
        )


__all__ = ["PosedTemplate", "Template", "articulations", "segments_of_joints", "skew_batch"]
