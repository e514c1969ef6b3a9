# SPDX-License-Identifier: Apache-2.0
r"""Distances of link pairs for one tick: :class:`CollisionModel` (broad phase, gradients).

Built from the link shapes of ``collision/shapes.py``, :class:`CollisionModel` holds a pinocchio
``GeometryModel`` with only the bodies of the chosen pairs (plus static obstacles), so one
``updateGeometryPlacements`` + ``computeDistances`` gives every distance and witness point in
C++. A conservative broad phase by temporal coherence skips the pairs that cannot be closer than the
influence distance: between two calls no point of
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

import time
from collections.abc import Sequence
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..errors import ConfigError, UnknownNameError
from ..kernel import kernel
from ..robot import RobotModel, RobotState
from .shapes import LinkShape, link_shapes

#: Gather of [p | n] (k, 6) giving [p_y p_z p_x p_z p_x p_y | n_z n_x n_y n_y n_z n_x]:
#: p x n = first half * second half, left three minus right three.
_CROSS = np.array([1, 2, 0, 2, 0, 1, 5, 3, 4, 4, 5, 3])


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


def _check_pairs(
    pairs: Sequence[tuple[str, str]], known: dict[str, LinkShape], path: str
) -> tuple[list[tuple[str, str]], list[str]]:
    """Check the pairs' body names; return the pairs and the bodies in first-seen order.

    Raises:
        ConfigError: a malformed pair, a body twice, two static bodies.
        UnknownNameError: a body that is neither a link with collision geometry nor an obstacle.
    """
    out: list[tuple[str, str]] = []
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
            raise ConfigError(f"pair [{a}, {b}] names the same body twice.", path=f"{path}[{k}]")
        if known[a].joint == 0 and known[b].joint == 0:
            raise ConfigError(f"pair [{a}, {b}]: both bodies are static.", path=f"{path}[{k}]")
        out.append((a, b))
        for body in (a, b):
            if body not in bodies:
                bodies.append(body)
    return out, bodies


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
        # With the compiled kernel, the pairs of `need` are computed in one call (no activation
        # flags in the geometry data, witness points and normals read into arrays).
        self._kernel = kernel()
        self.hysteresis = float(hysteresis)
        self.geometry = geometry
        known = dict(link_shapes(robot, geometry, hull_vertices))
        for ob in obstacles:
            if ob.name in known:
                raise ConfigError(
                    f"obstacle name {ob.name!r} is already a link or obstacle name.", path=path
                )
            known[ob.name] = ob
        self.pairs, self.bodies = _check_pairs(pairs, known, path)
        self.shapes = [known[b] for b in self.bodies]
        self.n_pairs = len(self.pairs)
        self._build_geometry()
        self._build_levers(robot.model)
        self.broad_phase = bool(broad_phase)
        self._init_buffers(robot.model)

    def _build_geometry(self) -> None:
        """The pinocchio geometry model and data of the bodies and pairs (signed distances)."""
        self.gmodel = pin.GeometryModel()
        for s in self.shapes:
            self.gmodel.addGeometryObject(s.geometry_object())
        index = {b: i for i, b in enumerate(self.bodies)}
        self._ga = np.array([index[a] for a, _ in self.pairs], dtype=int)
        self._gb = np.array([index[b] for _, b in self.pairs], dtype=int)
        for a, b in zip(self._ga, self._gb, strict=True):
            self.gmodel.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self._new_geometry_data()

    def _new_geometry_data(self) -> None:
        """Fresh geometry data: every pair active, signed distances, no GJK warm start.

        coal keeps each pair's last witness points as the next query's initial guess, so data
        that lived through earlier ticks gives other witness points (same distance, other row
        gradients) than fresh data: a run after :meth:`invalidate` (``Controller.reset``) must
        start from fresh data to repeat a first run bit for bit.
        """
        self.gdata = self.gmodel.createData()
        for req in self.gdata.distanceRequests:
            req.enable_signed_distance = True
        self._results = list(self.gdata.distanceResults)
        self._dbuf = np.full(self.n_pairs, np.inf)
        self._wpa = np.zeros((self.n_pairs, 3))
        self._wn = np.zeros((self.n_pairs, 3))
        self._flags = np.ones(self.n_pairs, dtype=bool)  # mirrors gdata.activeCollisionPairs
        self._flag_bytes = self._flags.tobytes()
        self._idx = np.arange(self.n_pairs)
        self._idx_list = self._idx.tolist()

    def _build_levers(self, model: pin.Model) -> None:
        """Supports and lever bounds of every body and pair (the broad phase's bound)."""
        nb = len(self.bodies)
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
        # Per pair: bound of the rate of change of the distance per unit |v_j|. A coordinate
        # moving both bodies (a common ancestor: base, waist) moves them rigidly together and
        # leaves the distance unchanged, so only the coordinates of one body's branch count.
        Sa, Sb = self._support[self._ga], self._support[self._gb]
        self._pair_lever = self._lever[self._ga] * (1 - Sb) + self._lever[self._gb] * (1 - Sa)

    def _init_buffers(self, model: pin.Model) -> None:
        """Per-pair state of the broad phase and the results of :meth:`update`."""
        self._thr = np.full(self.n_pairs, np.inf)
        self._thr_key: tuple[float, bytes | float] = (np.nan, np.nan)
        self._mask_key = b""
        self._mask = np.zeros((0, model.nv))
        #: Distance of every pair after :meth:`update`: exact where :attr:`exact`, else a lower
        #: bound (>= the influence distance of that call).
        self.distances = np.full(self.n_pairs, np.inf)
        self.exact = np.zeros(self.n_pairs, dtype=bool)
        self._model = model
        self._q_last = np.zeros(model.nq)
        self._fresh = True
        self._zero = np.zeros(self.n_pairs)
        self._no_distance = np.zeros(0)
        self._cut = np.inf  # ranked updates: last K-th smallest gap + rank_margin
        #: Margin added to the last call's K-th smallest gap to make the next cut [m].
        self.rank_margin = 0.005
        #: Indices of the pairs closer than the influence distance, and their witness points
        #: (world, (k, 3)) and unit normals from a to b, after :meth:`update`.
        self.active = np.zeros(0, dtype=int)
        self._sel: list[Any] = []
        self._pa: np.ndarray | None = np.zeros((0, 3))
        self._n: np.ndarray | None = np.zeros((0, 3))
        #: Time spent in the last :meth:`update` [s], of which in coal's distance calls
        #: (``computeDistances``: GJK/EPA in C++) [s], and the number of exact pair distances.
        self.last_update_time = 0.0
        self.last_gjk_time = 0.0
        self.last_n_computed = 0

    # ------------------------------------------------------------------ per tick
    def invalidate(self) -> None:
        """Forget the temporal-coherence bounds (next :meth:`update` computes every pair)."""
        self._fresh = True

    def reset(self) -> None:
        """A new run starts: :meth:`invalidate` and forget coal's warm starts too.

        The next :meth:`update` computes every pair on fresh geometry data, so a run after
        ``Controller.reset`` repeats a first run to the bit.
        """
        self._new_geometry_data()
        self._thr_key = (np.nan, np.nan)
        self.invalidate()

    def update(
        self,
        state: RobotState,
        influence: float = np.inf,
        *,
        nearest: int | None = None,
        offset: np.ndarray | None = None,
    ) -> np.ndarray:
        r"""Distances of this tick; witness points of the pairs closer than ``influence``.

        With ``nearest = K`` (capped rows), only what the :math:`K` smallest gaps
        :math:`g = d - o` (``offset`` :math:`o`: the safety distances) need is computed. The
        last call's :math:`K`-th smallest gap plus a margin is the cut :math:`X`; the first round
        computes the candidates whose lower bound has :math:`\underline d - o < X`. Every other
        pair then has :math:`g \ge \underline d - o \ge X`, so if :math:`K` computed gaps are
        below :math:`X` they are the :math:`K` smallest, exactly as if every candidate had been
        computed; otherwise a second round computes the remaining candidates. The pairs left out
        keep their lower bounds.

        Args:
            state: kinematics of the tick (``state.data`` must hold the joint placements and
                ``data.J`` of ``state.q``, as after :meth:`RobotState.update`).
            influence: pairs provably farther than this are not computed exactly [m].
            nearest: compute only what the ``nearest`` smallest gaps need (``None``: every
                candidate).
            offset: (P,) subtracted from the distances to rank the gaps [m] (default 0).

        Returns:
            :attr:`distances` (P,): exact where :attr:`exact`, lower bounds elsewhere.
        """
        t0 = time.perf_counter()
        lb = self.distances
        full = self._fresh or not self.broad_phase or influence == np.inf
        ranked = nearest is not None and not full  # a full update computes every candidate
        cand = self._candidates(state.q, influence)
        off = self._zero if offset is None else offset
        need = cand & (lb - off < self._cut) if ranked else cand
        self._set_flags(need)
        self.last_gjk_time = 0.0
        d = self._exact_distances(state, placed=False)
        if ranked and nearest is not None:
            g = d - off[self._idx]
            found = int(np.count_nonzero((g < self._cut) & (d < influence)))
            if found < nearest and (cand & ~need).any():  # second round: every candidate
                self._set_flags(cand)
                d = self._exact_distances(state, placed=bool(need.any()))
        idx = self._idx
        close = d < influence
        act = idx[close]
        if nearest is not None:  # next call's cut: this K-th smallest gap + rank_margin
            g = d[close] - off[act]
            self._cut = (
                float(np.partition(g, nearest - 1)[nearest - 1]) + self.rank_margin
                if g.size >= nearest
                else np.inf
            )
        self.exact = self._flags
        self.active = act
        # Witness points and normals are read from the results on demand (:meth:`witnesses`):
        # each read crosses into C++, and capped rows need only the closest pairs'.
        if self._kernel is not None:  # witness points already read by the kernel
            self._pa, self._n = self._wpa[act], self._wn[act]
        else:
            res = self._results
            self._sel = [res[i] for i in act.tolist()]
            self._pa = self._n = None
        self.last_n_computed = int(idx.size)
        self.last_update_time = time.perf_counter() - t0
        return lb

    def _candidates(self, q: np.ndarray, influence: float) -> np.ndarray:
        """Lower bounds of every distance after the motion since the last call; the candidates.

        A pair is a candidate while its bound is below the influence distance, and stays one
        until the bound exceeds influence + hysteresis (fewer on/off switches). A fresh call, a
        broad phase switched off or an infinite influence makes every pair a candidate.
        """
        lb = self.distances
        if self._fresh or not self.broad_phase or influence == np.inf:
            lb.fill(-np.inf)
            self._fresh = False
        else:
            dq = pin.difference(self._model, self._q_last, q)
            lb -= self._pair_lever @ np.abs(dq, out=dq)
        self._q_last[:] = q
        if self.hysteresis > 0:
            if self._thr_key != (influence, self._flag_bytes):
                np.copyto(self._thr, influence)
                self._thr[self._flags] += self.hysteresis
                self._thr_key = (influence, self._flag_bytes)
            return lb < self._thr
        return lb < influence

    def _exact_distances(self, state: RobotState, *, placed: bool) -> np.ndarray:
        """Exact (coal) distances of the active pairs (:attr:`_idx`), written into the bounds."""
        if not self._idx.size:
            return self._no_distance
        if self._kernel is not None:
            t1 = time.perf_counter()
            self._kernel.geometry_distances(
                self._model, state.data, self.gmodel, self.gdata, self._flags, placed,
                self._dbuf, self._wpa, self._wn,
            )  # fmt: skip
            self.last_gjk_time += time.perf_counter() - t1
            d = self._dbuf[self._idx]
            self.distances[self._idx] = d
            return d
        if not placed:
            pin.updateGeometryPlacements(self._model, state.data, self.gmodel, self.gdata)
        t1 = time.perf_counter()
        pin.computeDistances(self.gmodel, self.gdata)
        self.last_gjk_time += time.perf_counter() - t1
        res = self._results
        d = np.array([res[i].min_distance for i in self._idx_list])
        self.distances[self._idx] = d
        return d

    def _set_flags(self, need: np.ndarray) -> None:
        """Switch the geometry data's active pairs to ``need`` (only the changed ones)."""
        nb = need.tobytes()
        if nb == self._flag_bytes:
            return
        if self._kernel is None:  # the kernel computes the pairs of `need` directly
            gd = self.gdata
            flips = np.flatnonzero(need != self._flags)
            for i, on in zip(flips.tolist(), need[flips].tolist(), strict=True):
                if on:
                    gd.activateCollisionPair(i)
                else:
                    gd.deactivateCollisionPair(i)
        self._flags = need
        self._flag_bytes = nb
        self._idx = np.flatnonzero(need)
        self._idx_list = self._idx.tolist()

    def witnesses(self, sub: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Witness points on body a and unit normals from a to b, (k, 3) each.

        Args:
            sub: positions in :attr:`active` (default: every active pair).
        """
        if sub is None:
            if self._pa is None or self._n is None:
                self._pa, self._n = self._read(self._sel)
            return self._pa, self._n
        if self._pa is not None and self._n is not None:
            return self._pa[sub], self._n[sub]
        return self._read([self._sel[i] for i in sub.tolist()])

    @staticmethod
    def _read(results: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
        if not results:
            return np.zeros((0, 3)), np.zeros((0, 3))
        pa = np.array([r.getNearestPoint1() for r in results])  # witness points on a
        n = np.array([r.normal for r in results])  # unit, from a to b: p_b = p_a + d n
        return pa, n

    @property
    def witness_a(self) -> np.ndarray:
        """World witness points on body a of the :attr:`active` pairs (k, 3)."""
        return self.witnesses()[0]

    @property
    def witness_b(self) -> np.ndarray:
        """World witness points on body b of the :attr:`active` pairs (k, 3)."""
        pa, n = self.witnesses()
        return pa + self.distances[self.active, None] * n

    @property
    def normals(self) -> np.ndarray:
        """Unit normals from a to b of the :attr:`active` pairs (k, 3)."""
        return self.witnesses()[1]

    def gradients(self, state: RobotState, sub: np.ndarray | None = None) -> np.ndarray:
        r"""Rows :math:`\partial d / \partial q` (k, nv) of the last update's :attr:`active` pairs.

        :math:`\partial d/\partial q = n^\top (J_b(p_b) - J_a(p_a))` in the tangent space
        (module docstring), from ``state.data.J`` (WORLD joint Jacobians of this tick). As
        :math:`p_b - p_a = d\,n`, :math:`p_b \times n = p_a \times n`: both bodies share the
        coefficients :math:`c = [n;\ p_a \times n]` and the rows are
        :math:`(c^\top J^W) \circ (S_b - S_a)`, one ``(k, 6) @ (6, nv)`` product with the
        difference of the bodies' support masks.

        Args:
            state: kinematics of the tick.
            sub: positions in :attr:`active` of the rows wanted (default: every active pair).
        """
        pairs = self.active if sub is None else self.active[sub]
        if pairs.size == 0:
            return np.zeros((0, self.robot.nv))
        pa, n = self.witnesses(sub)
        return self.point_rows(state, pairs, pa, n)

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

        0 for coordinates that move neither body (and for translations), and for those that
        move both (a common ancestor: base, waist): they move the pair rigidly, leaving its
        distance unchanged to every order.
        """
        ga, gb = self._ga[pairs], self._gb[pairs]
        lever = np.maximum(self._rot_lever[ga], self._rot_lever[gb])
        return lever * (1.0 - self._support[ga] * self._support[gb])

    def pair_planes(self) -> np.ndarray:
        """(P, 3) world unit normal of the static half-space of each pair, zero for other pairs.

        A pair against a plane (the ground, a half-space obstacle) has a distance whose
        second-order change under a rotation depends on the rotation axis's tilt from the
        normal (:meth:`qpretarget.constraints.self_collision.DistanceDamper.compute_bounds`).
        """
        out = np.zeros((self.n_pairs, 3))
        for k, (a, b) in enumerate(zip(self._ga, self._gb, strict=True)):
            for g in (a, b):
                s = self.shapes[g]
                if s.joint == 0 and isinstance(s.geometry, coal.Halfspace):
                    n = s.placement.rotation @ np.asarray(s.geometry.n, dtype=float)
                    out[k] = n / np.linalg.norm(n)
        return out

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


__all__ = ["CollisionModel", "pair_distances"]
