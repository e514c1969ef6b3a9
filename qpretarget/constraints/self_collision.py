# SPDX-License-Identifier: Apache-2.0
r"""Self-collision avoidance: linearized distance constraints (velocity damper, DESIGN.md).

For every pair of links :math:`(a, b)` closer than the influence distance :math:`d_i`, with
distance :math:`d`, witness points :math:`p_a, p_b` and unit normal :math:`n` from :math:`a` to
:math:`b` (:mod:`qpretarget.collision`), the distance may not decrease faster than the damper
allows:

.. math::
    \dot d = n^\top \big(J_b(p_b) - J_a(p_a)\big) v \;\ge\; -\xi \frac{d - d_s}{d_i - d_s}
    \quad\Longleftrightarrow\quad
    n^\top \big(J_a(p_a) - J_b(p_b)\big) v \;\le\; \xi \frac{d - d_s}{d_i - d_s},

with :math:`d_s` the safety distance and :math:`\xi` [m/s] the approach speed allowed at
:math:`d_i` (Faverjon & Tournassoud's damper, as in DESIGN.md "One tick"). The gain can also be
given per second (``gain``: bound :math:`k (d - d_s)`) or per tick (``gain_per_tick``: bound
:math:`\gamma (d - d_s)/dt`, i.e. the gap to :math:`d_s` shrinks by at most the fraction
:math:`\gamma` per tick to first order). Below :math:`d_s` the bound is negative: the pair is
pushed apart, at most at ``recovery_speed``.

The block has one row per pair (or ``max_rows`` rows given to the closest pairs, each pair
keeping its row while it stays among them); rows of pairs beyond :math:`d_i` are zero with infinite
bounds, so the QP keeps its shape and the solver stays warm. The importance is 85: when hard
constraints conflict, the support polygon (60), the ground (75) and the acceleration limits (80)
give before a collision, contacts and joint limits after it (see
:mod:`qpretarget.control.relaxation`). Measured on the shared clips: at 70, below the
acceleration limits, an arm approaching fast could not be stopped within them and went through
(opensim_walking2: shoulder roll link into the torso, 2 frames, 0.8 mm on the meshes).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from ..collision import GEOMETRIES, CollisionModel, LinkShape, adjacent_links, link_shapes
from ..collision.pairs import Pair, select_pairs
from ..errors import ConfigError, UnknownNameError
from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import CONSTRAINTS, Constraint, ConstraintBlock

#: Smallest trust-region scale (the step bound shrinks at most by its square root, 1/64).
MIN_TRUST_SCALE = 1.0 / 4096
#: Smallest sine of the angle between a rotation axis and a pair's plane normal in the trust
#: region (a turn about the normal changes no distance to the plane; the bound of such a turn is
#: then 1000 times the lever bound instead of infinite).
MIN_PLANE_SINE = 1e-6
#: QP rows of an ``auto`` pair set unless ``max_rows`` says otherwise.
AUTO_MAX_ROWS = 24
#: ``trust_gap_fraction`` of an ``auto`` pair set unless given: a pair's linearization may err by
#: a tenth of its gap to the safety distance (pairs near at rest stay within d_i all along).
AUTO_TRUST_GAP = 0.1


def damper_rate(
    *,
    xi: float | None,
    gain: float | None,
    gain_per_tick: float | None,
    d_s: float,
    d_i: float,
    default_per_tick: float = 0.5,
) -> tuple[str, float]:
    """Validate the damper gain given in one of three forms; return ``(form, value)``.

    Raises:
        ConfigError: more than one form given, or a value out of range.
    """
    given = [(k, v) for k, v in (("xi", xi), ("gain", gain), ("gain_per_tick", gain_per_tick))
             if v is not None]  # fmt: skip
    if len(given) > 1:
        raise ConfigError(
            "give one of xi [m/s], gain [1/s] or gain_per_tick, got "
            f"{', '.join(k for k, _ in given)}."
        )
    if not given:
        return "gain_per_tick", default_per_tick
    form, value = given[0]
    value = positive_float(value, form)
    if form == "gain_per_tick" and value > 1:
        raise ConfigError(
            f"gain_per_tick must be in (0, 1] (fraction of the gap to d_s closed per tick), "
            f"got {value}."
        )
    if form == "xi" and not np.isfinite(d_i - d_s):
        raise ConfigError("xi needs a finite influence distance d_i.")
    return form, value


def resolve_link(robot: RobotModel, shapes: dict[str, LinkShape], name: str, path: str) -> str:
    """A link, key-point or frame name -> the link (with collision geometry) that carries it.

    Raises:
        UnknownNameError: listing the links with collision geometry.
    """
    if name in shapes:
        return name
    frame = robot.keyframes.get(name, name)
    if frame in shapes:
        return frame
    if robot.model.existFrame(frame):
        joint = robot.model.frames[robot.model.getFrameId(frame)].parentJoint
        links = [n for n, s in shapes.items() if s.joint == joint]
        if len(links) == 1:
            return links[0]
    raise UnknownNameError(
        "collision link", name, list(shapes), path=path,
        fix=f"Links with collision geometry: {', '.join(shapes)}.",
    )  # fmt: skip


class DistanceDamper(Constraint):
    """Base of the distance constraints: the velocity damper on a :class:`CollisionModel`.

    Subclasses build :attr:`model` (and :attr:`pairs`, :attr:`safety`, one safety distance per
    pair) in :meth:`bind`, then call :meth:`_setup_rows`.
    """

    #: The subclass overrides :meth:`_row_mask` to disarm some pairs (rows are then selected).
    disarms_rows: ClassVar[bool] = False
    has_bounds: ClassVar[bool] = True

    def __init__(
        self,
        *,
        d_s: float,
        d_i: float,
        xi: float | None,
        gain: float | None,
        gain_per_tick: float | None,
        recovery_speed: float,
        geometry: str,
        max_rows: int | None,
        broad_phase: bool,
        trust_region: float | None,
        hull_vertices: int | None,
        name: str | None,
    ) -> None:
        super().__init__(name)
        self.hull_vertices = hull_vertices
        self.trust_region = (
            None if trust_region is None else positive_float(trust_region, "trust_region [m]")
        )
        self.d_s = (
            float(d_s) if isinstance(d_s, (int, float)) and not isinstance(d_s, bool) else d_s
        )
        if not isinstance(self.d_s, float) or not np.isfinite(self.d_s):
            raise ConfigError(f"d_s must be a finite number [m], got {d_s!r}.")
        self.d_i = positive_float(d_i, "d_i [m]")
        if self.d_i <= self.d_s:
            raise ConfigError(
                f"the influence distance d_i ({self.d_i}) must be larger than the safety distance "
                f"d_s ({self.d_s})."
            )
        self.gain_form, self.gain_value = damper_rate(
            xi=xi, gain=gain, gain_per_tick=gain_per_tick, d_s=self.d_s, d_i=self.d_i
        )
        self.recovery_speed = positive_float(recovery_speed, "recovery_speed [m/s]")
        if geometry not in GEOMETRIES:
            raise ConfigError(f"geometry must be one of {', '.join(GEOMETRIES)}, got {geometry!r}.")
        self.geometry = geometry
        if max_rows is not None and (
            isinstance(max_rows, bool) or not isinstance(max_rows, int) or max_rows < 1
        ):
            raise ConfigError(f"max_rows must be a positive integer or null, got {max_rows!r}.")
        self.max_rows = max_rows
        self.broad_phase = bool(broad_phase)
        #: Trust region of a pair: max(trust_region, trust_gap * (d - safety)) (0: fixed).
        self.trust_gap = 0.0
        #: Bound the rotations of a pair against a static plane by their second-order change of
        #: distance to it, |n x a_j| (compute_bounds), rather than by their lever alone.
        self.plane_trust = False
        self.model: CollisionModel | None = None
        self.pairs: list[tuple[str, str]] = []
        self.safety = np.zeros(0)
        #: Time of the last tick's collision block [s]: distances, trust region, rows and the
        #: prediction of the next distances.
        self.last_time = 0.0
        # The compiled kernel's damper (tick, id) once its rows are compiled, else None; the
        # box is registered first (the two share the tick's distances).
        self._kd: tuple[Any, int] | None = None
        self._kd_new: tuple[Any, int] | None = None

    # ------------------------------------------------------------------ setup
    def _setup_rows(self, robot: RobotModel) -> None:
        P = len(self.pairs)
        self.n_rows = P if self.max_rows is None else min(self.max_rows, P)
        self._C = np.zeros((self.n_rows, robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)
        self._grad = np.zeros((P, robot.nv))
        self._grad_act = np.zeros((0, robot.nv))  # rows' gradients dd/dq (k, nv)
        self._row_pairs = np.zeros(0, dtype=int)  # pairs with a row this tick
        self._tr_lb = np.full(robot.nv, -np.inf)
        self._tr_ub = np.full(robot.nv, np.inf)
        self._scale = np.ones(P)
        self._sqrt_scale = np.ones(P)
        self._scaled = False
        self._pred_pairs = np.zeros(0, dtype=int)
        self._pred = np.zeros(0)
        self._last_rows = np.zeros(0, dtype=int)
        self._slot = np.full(P, -1)  # capped rows: QP row of each pair (-1: none)
        self._slot_pair = np.full(self.n_rows, -1)  # pair of each QP row (-1: free)
        self._slots_key = b""  # pairs of the last _slots call, and their rows
        self._slots_rows = np.zeros(0, dtype=int)
        self._last_pairs = np.zeros(0, dtype=int)
        self._gap = np.zeros(0)
        uniform = bool(np.all(self.safety == self.safety[0])) if P else True
        self._safety_scalar = float(self.safety[0]) if P and uniform else None
        # Direct rows (row i = pair i) unless rows are capped or a subclass disarms some.
        self._direct = self.max_rows is None and not self.disarms_rows
        self._nearest = self.n_rows if self.max_rows is not None and not self.disarms_rows else None
        # Trust-region step bound per pair and coordinate at scale 1: sqrt(2 eps / r) [rad].
        assert self.model is not None
        eps = self.trust_region if self.trust_region is not None else np.inf
        with np.errstate(divide="ignore"):  # inf where no rotation moves the pair
            self._step0 = np.sqrt(2.0 * eps / self.model.pair_levers(np.arange(P)))
        # Pairs against a static plane (the ground, a half-space obstacle): its world normal
        # (zero for the other pairs, and for all without plane_trust).
        self._plane = self.model.pair_planes() * float(self.plane_trust)
        self._planar: np.ndarray = np.asarray(self._plane.any(axis=1))
        self._has_plane = bool(self._planar.any())
        self._fp_w = np.random.default_rng(0).standard_normal(robot.nq)
        self._fp = np.nan
        self._fp_state: Any = None
        self._t_acc = 0.0

    def rate(self, dt: float) -> float:
        """Damper slope [1/s]: the bound is ``rate * (d - d_s)``."""
        if self.gain_form == "gain_per_tick":
            return self.gain_value / dt
        if self.gain_form == "gain":
            return self.gain_value
        return self.gain_value / (self.d_i - self.d_s)

    def reset(self, state: RobotState) -> None:
        if self.model is not None:
            self.model.reset()  # fresh geometry data: a run from reset repeats to the bit
            if self._kd is not None:
                self._kd[0].damper_reset(self._kd[1], self.model.gdata)
        self._fp_state = None
        self._scale.fill(1.0)
        self._sqrt_scale.fill(1.0)
        self._scaled = False
        self._pred_pairs = np.zeros(0, dtype=int)
        self._C.fill(0.0)  # a reset run is the same as a fresh one (rows and their slots)
        self._u.fill(np.inf)
        self._last_rows = np.zeros(0, dtype=int)
        self._slot.fill(-1)
        self._slot_pair.fill(-1)
        self._slots_key = b""

    # ------------------------------------------------------------------ compiled kernel
    def _kernel_damper(self, tick: Any) -> int | None:
        """This damper in the kernel ``tick`` (created once per tick object), or ``None``."""
        m = self.model
        if self.disarms_rows or m is None or m._kernel is None or self._disabled_rows():
            return None
        if self._kd_new is not None and self._kd_new[0] is tick:
            return self._kd_new[1]
        form = {"gain_per_tick": 0, "gain": 1}.get(self.gain_form, 2)
        kid = tick.add_damper(
            m.gmodel, m.gdata, m.distances, np.ascontiguousarray(m._pair_lever, dtype=float),
            np.ascontiguousarray(m._support, dtype=float), m._ga.tolist(), m._gb.tolist(),
            np.ascontiguousarray(self.safety, dtype=float),
            np.ascontiguousarray(self._step0, dtype=float),
            np.ascontiguousarray(self._plane, dtype=float), MIN_PLANE_SINE, m.broad_phase,
            m.hysteresis, m.rank_margin, self.d_i, self.d_s, form, self.gain_value,
            self.recovery_speed, -1.0 if self.trust_region is None else self.trust_region,
            self.trust_gap,
            MIN_TRUST_SCALE, self.n_rows, self._direct, self._nearest or 0,
        )  # fmt: skip
        self._kd_new = (tick, int(kid))
        return int(kid)

    def _disabled_rows(self) -> bool:
        """``True`` when the module contributes nothing (a subclass with nothing to check)."""
        return False

    def compile_bounds_into(self, tick: Any) -> bool:
        """The trust-region box, computed in the kernel with the distances of the tick."""
        kid = self._kernel_damper(tick)
        if kid is None:
            return False
        tick.add_damper_bounds(kid, self.name)
        return True

    def compile_rows_into(self, tick: Any, row: int) -> bool:
        """Broad phase, coal distances, rows, trust region and prediction in the kernel."""
        kid = self._kernel_damper(tick)
        if kid is None:
            return False
        tick.add_damper_rows(kid, row)
        self._kd = (tick, kid)
        return True

    def kernel_detached(self) -> None:
        """The kernel stopped (an error): the Python code takes over from a fresh broad phase."""
        self._kd = None
        if self.model is not None:
            self.model.invalidate()

    def _kernel_state(self) -> tuple[Any, ...]:
        """The compiled damper's active pairs, row pairs, row gradients, violations' inputs."""
        assert self._kd is not None
        return tuple(self._kd[0].damper_state(self._kd[1]))

    def after_step(self, state: RobotState, v: np.ndarray, dt: float) -> None:
        """Remember the first-order prediction of the active pairs' next distances."""
        if self._kd is not None:
            tick, kid = self._kd
            tick.damper_after_step(kid, np.ascontiguousarray(v, dtype=float), dt)
            self.last_time = float(tick.damper_last_time(kid))
            return
        model = self.model
        if self.trust_region is None or model is None or self._row_pairs.size == 0:
            return
        t0 = time.perf_counter()
        pairs = self._row_pairs
        self._pred_pairs = pairs
        self._pred = model.distances[pairs] + self._grad_act @ (v * dt)
        self.last_time += time.perf_counter() - t0

    def _row_mask(self, active: np.ndarray) -> np.ndarray:
        """Which active pairs get a row this tick (all of them unless a subclass disarms some)."""
        return np.ones(active.size, dtype=bool)

    # ------------------------------------------------------------------ per tick
    def _update(self, state: RobotState) -> None:
        """Distances and gradients of this tick, computed once per state/configuration."""
        fp = float(state.q @ self._fp_w)  # fingerprint of the configuration
        if state is self._fp_state and fp == self._fp:
            return
        t0 = time.perf_counter()
        model = self.model
        assert model is not None
        # Capped rows: only what the n_rows smallest gaps need is computed exactly
        # (CollisionModel.update), so the GJK calls per tick follow n_rows, not the pair count.
        model.update(state, self.d_i, nearest=self._nearest, offset=self.safety)
        act = model.active
        if self._direct or act.size == 0:
            pairs = act
            grad = model.gradients(state) if act.size else self._grad_act[:0]
        else:  # the pairs that get a row this tick (armed, closest max_rows)
            sel = np.flatnonzero(self._row_mask(act)) if self.disarms_rows else np.arange(act.size)
            pairs = act[sel]
            if self.max_rows is not None and pairs.size > self.n_rows:
                gap = model.distances[pairs] - self.safety[pairs]
                sel = np.sort(sel[np.argsort(gap, kind="stable")[: self.n_rows]])
                pairs = act[sel]
            grad = model.gradients(state, sel)
        self._grad_act, self._row_pairs = grad, pairs
        self._fp_state, self._fp = state, fp
        if self._pred_pairs.size:  # adapt the trust region to last tick's prediction error
            pairs = self._pred_pairs
            err = model.distances[pairs] - self._pred
            assert self.trust_region is not None  # predictions are made only with one
            tol = np.full(pairs.size, self.trust_region)
            if self.trust_gap > 0:
                tol = np.maximum(tol, self.trust_gap * (self._pred - self.safety[pairs]))
            bad = err < -tol
            if bad.any():
                # The step's error is first order in the step where facets switch, and the step
                # goes as sqrt(scale): shrink by (eps / err)^2, at least by half.
                f = np.clip((tol[bad] / err[bad]) ** 2, 1.0 / 64, 0.5)
                pb = pairs[bad]
                self._scale[pb] = np.maximum(self._scale[pb] * f, MIN_TRUST_SCALE)
                self._scaled = True
                pairs = pairs[~bad]
            if self._scaled:
                self._scale[pairs] = np.minimum(self._scale[pairs] * 1.25, 1.0)
                np.sqrt(self._scale, out=self._sqrt_scale)
                self._scaled = bool(self._scale.min() < 1.0)
            self._pred_pairs = self._pred_pairs[:0]
        self._t_acc = time.perf_counter() - t0

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        r"""Trust region of the linearization: bounded rotation per tick near a close pair.

        The rows are first-order in :math:`v\,dt`; a rotation :math:`\Delta\theta_j` moves a
        point at lever :math:`r` off its tangent by up to :math:`r \Delta\theta_j^2/2`. While a
        pair :math:`p` is within :math:`d_i`, every rotational coordinate moving one of its
        bodies is bounded by :math:`|v_j|\,dt \le \sqrt{2 s_p \varepsilon / r_{pj}}`,
        :math:`\varepsilon` = ``trust_region`` [m] (translations are exact and free). As in a
        trust-region SQP, the scale :math:`s_p \in [1/4096, 1]` shrinks by
        :math:`\min(1/2, (\varepsilon/e)^2)` after a tick whose first-order prediction of
        :math:`d_p` was optimistic by :math:`e > \varepsilon` (witness points jumping between
        facets of the hulls: an error first-order in the step) and grows back by 1.25 after an
        accurate one. Far from the speeds of a tracking motion (G1 arm, :math:`\varepsilon` =
        0.2 mm: 2-6 rad/s), it stops the two-tick oscillations that full-error-correction tasks
        start against active rows, and with them the violations of :math:`d_s`.

        With ``plane_trust`` (:class:`~qpretarget.constraints.ground.Ground`), against a static
        plane of unit normal :math:`n` (the ground, a half-space obstacle) the estimate is
        sharper: a rotation :math:`\theta` about a unit axis :math:`a` moves a point at
        :math:`r` (from a point of the axis) to
        :math:`r + \theta\, a \times r + \tfrac{\theta^2}{2}\, a \times (a \times r) + O(\theta^3)`
        (Taylor expansion of :math:`e^{\theta [a]_\times} r`), so its distance to the plane
        departs from the first-order prediction by the second-order term

        .. math::
            \tfrac{\theta^2}{2}\, n^\top \big(a \times (a \times r)\big)
            = -\tfrac{\theta^2}{2}\, n^\top r_\perp, \qquad
            |n^\top r_\perp| \le |n \times a|\, |r_\perp| \le |n \times a|\, r_{pj},

        :math:`r_\perp` the part of :math:`r` normal to :math:`a` (in that plane :math:`n`'s
        projection has length :math:`|n \times a|`). Such a pair's bound is therefore
        :math:`\sqrt{2 s_p \varepsilon / (r_{pj}\, |n \times a_j|)}`, :math:`a_j` coordinate
        :math:`j`'s rotation axis in the world at this tick (the angular rows of the WORLD
        Jacobian ``data.J``: a revolute joint's axis; for the free-flyer's angular coordinates,
        local, the columns of the base rotation). A turn about the normal (the base's yaw with
        the pelvis upright) changes no height and is not bounded (the sine is floored at
        :data:`MIN_PLANE_SINE`); a tilted axis is bounded by its tilt. As for every pair, the
        bound is per coordinate: the cross terms of simultaneous rotations are left to the
        adaptation of :math:`s_p` (a turn about the normal applied outermost, the base's yaw,
        has none: it keeps every height).
        """
        if self.trust_region is None:
            return None
        self._update(state)
        t0 = time.perf_counter()
        pairs = self._row_pairs
        if pairs.size == 0:
            return None
        step = self._step0[pairs]
        if self._has_plane:
            self._plane_steps(state, pairs, step)
        if self.trust_gap > 0:  # a pair far from its safety distance tolerates a larger error
            assert self.model is not None and self.trust_region is not None
            gap = self.model.distances[pairs] - self.safety[pairs]
            step = (
                step * np.sqrt(np.maximum(1.0, self.trust_gap * gap / self.trust_region))[:, None]
            )
        if self._scaled:
            step = step * self._sqrt_scale[pairs, None]
        np.multiply(step.min(axis=0), 1.0 / dt, out=self._tr_ub)
        np.negative(self._tr_ub, out=self._tr_lb)
        self._t_acc += time.perf_counter() - t0
        return self._tr_lb, self._tr_ub

    def _plane_steps(self, state: RobotState, pairs: np.ndarray, step: np.ndarray) -> None:
        r"""Scale ``step`` (k, nv) in place by :math:`|n \times a_j|^{-1/2}` on planar pairs."""
        on = np.flatnonzero(self._planar[pairs])
        if on.size == 0:
            return
        A = state.data.J[3:6]  # (3, nv) world rotation axes of the coordinates (0: translations)
        a2 = (A * A).sum(axis=0)
        na = self._plane[pairs[on]] @ A  # (m, nv): n . a_j
        sin2 = 1.0 - na * na / np.where(a2 > 0.0, a2, 1.0)
        step[on] *= np.maximum(sin2, MIN_PLANE_SINE**2) ** -0.25

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock:
        self._update(state)
        t0 = time.perf_counter()
        model = self.model
        assert model is not None
        C, hi = self._C, self._u
        last = self._last_rows
        pairs = self._row_pairs
        rows = pairs if self.max_rows is None else self._slots(pairs)
        if last.size and last.tobytes() != rows.tobytes():
            C[last] = 0.0  # clear last tick's rows (unless the same rows are rewritten)
            hi[last] = np.inf
        if pairs.size:
            s = self._safety_scalar
            gap = model.distances[pairs] - (self.safety[pairs] if s is None else s)
            C[rows] = -self._grad_act
            hi[rows] = np.maximum(gap * self.rate(dt), -self.recovery_speed)
            self._last_rows, self._last_pairs, self._gap = rows, pairs, gap
        else:
            self._last_rows = self._last_pairs = pairs
            self._gap = self._gap[:0]
        self.last_time = self._t_acc + time.perf_counter() - t0
        return ConstraintBlock(self.name, C, self._l, hi)

    def _slots(self, pairs: np.ndarray) -> np.ndarray:
        """QP rows of this tick's ``pairs`` (capped rows).

        A pair keeps its row while it stays among the closest, new pairs take the free rows, so
        the rows the solver's warm start remembers keep their meaning from tick to tick.
        """
        key = pairs.tobytes()
        if key == self._slots_key:  # the same pairs as last tick keep the same rows
            return self._slots_rows
        slot, owner = self._slot, self._slot_pair
        held = owner >= 0
        if held.any():
            keep = np.zeros(slot.size, dtype=bool)
            keep[pairs] = True
            gone = held & ~keep[np.maximum(owner, 0)]
            if gone.any():
                slot[owner[gone]] = -1
                owner[gone] = -1
        new = pairs[slot[pairs] < 0]
        if new.size:
            free = np.flatnonzero(owner < 0)[: new.size]
            slot[new] = free
            owner[free] = new
        self._slots_key, self._slots_rows = key, slot[pairs]
        return self._slots_rows

    @property
    def min_distance(self) -> float:
        """Smallest pair distance at the last tick [m] (a lower bound >= d_i if none is close)."""
        d = self.model.distances if self.model is not None else np.zeros(0)
        return float(d.min()) if d.size else np.inf

    @property
    def violations(self) -> dict[str, float]:
        """Pairs closer than their safety distance at the last tick: ``"a/b"`` -> depth [m]."""
        out = {}
        last_pairs, gap = self._last_pairs, self._gap
        if self._kd is not None:
            st = self._kernel_state()
            last_pairs, gap = st[3], st[4].ravel()
        for p, g in zip(last_pairs.tolist(), gap.tolist(), strict=True):
            if g < 0:
                a, b = self.pairs[p]
                out[f"{a}/{b}"] = -g
        return out

    def distances_and_gradients(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        r"""Pair distances and their gradients :math:`\partial d/\partial q` for this tick.

        Computed once per tick and shared with :meth:`compute_rows` (for the CRAC collision
        weights, CRAC eq. 22-27).

        Returns:
            ``(d (P,), grad (P, nv))``: exact distances of the pairs closer than :math:`d_i`
            (lower bounds :math:`\ge d_i` for the others); gradient rows of the pairs with a QP
            row this tick, zero for the others.
        """
        model = self.model
        assert model is not None
        grad = self._grad
        grad.fill(0.0)
        if self._kd is not None:  # the kernel's tick (it computed this state's distances)
            _, row_pairs, grad_act = self._kernel_state()[:3]
            if row_pairs.size:
                grad[row_pairs] = grad_act
            return model.distances.copy(), grad
        self._update(state)
        if self._row_pairs.size:
            grad[self._row_pairs] = self._grad_act
        return model.distances.copy(), grad

    @property
    def safety_distance(self) -> float:
        """Safety distance :math:`d_s` [m] (used by :mod:`qpretarget.analysis.metrics`)."""
        return self.d_s


def trust_gap_value(trust_gap_fraction: float | None, pairs: Any) -> float:
    """The ``trust_gap_fraction`` value (default: :data:`AUTO_TRUST_GAP` for auto pairs, else 0)."""
    if trust_gap_fraction is None:
        return AUTO_TRUST_GAP if pairs == "auto" else 0.0
    if (
        isinstance(trust_gap_fraction, bool)
        or not isinstance(trust_gap_fraction, (int, float))
        or not 0.0 <= trust_gap_fraction <= 1.0
    ):
        raise ConfigError(
            f"trust_gap_fraction must be a number in [0, 1] or null, got {trust_gap_fraction!r}."
        )
    return float(trust_gap_fraction)


def _check_pair_spec(pairs: Any, links: Any, include: Any) -> None:
    """Check the pair keys: ``auto`` or a non-empty list of ``[link_a, link_b]``.

    ``links`` and ``include`` go with ``auto`` only.
    """
    if isinstance(pairs, str):
        if pairs != "auto":
            raise ConfigError(f"pairs must be 'auto' or a list of [link_a, link_b], got {pairs!r}.")
    elif not isinstance(pairs, Sequence) or not all(
        isinstance(p, Sequence) and not isinstance(p, str) and len(p) == 2 for p in pairs
    ):
        raise ConfigError(f"pairs must be 'auto' or a list of [link_a, link_b], got {pairs!r}.")
    elif len(pairs) == 0:
        raise ConfigError("pairs is an empty list: give pairs or 'auto'.")
    if links is not None and pairs != "auto":
        raise ConfigError("`links` selects candidates for pairs: auto; drop it with a pair list.")
    if include and pairs != "auto":
        raise ConfigError("`include` adds pairs to pairs: auto; list them in `pairs` instead.")


def _check_safety_spec(safety: Any, d_i: float) -> list[tuple[str, str, float]]:
    """``safety:`` as ``[(link_a, link_b, d)]``, each ``d`` in (0, ``d_i``) [m]."""
    if safety is None:
        return []
    form = "safety must be a list of [link_a, link_b, distance in m]"
    if isinstance(safety, (str, bytes)) or not isinstance(safety, Sequence):
        raise ConfigError(f"{form}, got {safety!r}.")
    out: list[tuple[str, str, float]] = []
    for k, entry in enumerate(safety):
        if (
            isinstance(entry, (str, bytes))
            or not isinstance(entry, Sequence)
            or len(entry) != 3
            or not all(isinstance(x, str) for x in entry[:2])
        ):
            raise ConfigError(f"{form}; entry {k} is {entry!r}.", path=f"safety[{k}]")
        d = entry[2]
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not 0 < d < d_i:
            raise ConfigError(
                f"safety[{k}]: the distance must be a number in (0, d_i = {d_i}) m, got {d!r}.",
                path=f"safety[{k}]",
            )
        out.append((str(entry[0]), str(entry[1]), float(d)))
    return out


@CONSTRAINTS.register("self_collision")
class SelfCollision(DistanceDamper):
    r"""Keep link pairs at least :math:`d_s` apart (velocity damper, module docstring).

    Args:
        pairs: ``auto`` or a list of ``[link_a, link_b]`` (URDF link names with collision
            geometry; key-point names such as ``left_hand`` are resolved to their link).
        d_s: safety distance [m].
        d_i: influence distance [m]; pairs farther apart have no active row (and are not even
            computed when the broad phase proves it).
        xi: damper speed [m/s] at :math:`d_i` (DESIGN.md form); or
        gain: slope [1/s] of the bound :math:`k (d - d_s)`; or
        gain_per_tick: fraction of the gap to :math:`d_s` that may close per tick (default 0.5).
        recovery_speed: largest separation speed asked of a pair closer than :math:`d_s` [m/s].
        geometry: ``convex_hull`` or ``capsule`` (:mod:`qpretarget.collision`).
        links: ``auto`` only: restrict the candidate links to these (default: every link with
            collision geometry).
        exclude: pairs removed from the list (``auto`` or explicit).
        include: ``auto`` only: pairs added back whatever the rules say (e.g. chain neighbours
            that do collide on this robot).
        touch_distance: ``auto`` only: pairs closer than this in the reference posture are left
            out as touching [m].
        rest_fraction: ``auto`` only: a pair's safety distance is
            :math:`\min(d_s, \rho\, d_{rest})`, :math:`d_{rest}` its distance in the reference
            posture: pairs that sit close by construction (a shoulder beside the torso, a hip
            motor beside the pelvis) are kept apart without locking the joint between them.
        safety: ``[[link_a, link_b, d], ...]``: the safety distance of these pairs [m], in place
            of ``d_s`` and the ``rest_fraction`` rule: parts that nest by design (G1's hip-roll
            motor folds into the pelvis shell as the hip flexes, 0.4 mm apart at 2 rad: its
            rest rule, 6 mm, stopped the hip at 1.15 rad and a squat at the start). Each pair
            must be one of the constraint's pairs; ``d`` in (0, ``d_i``).
        use_srdf: ``auto`` only: leave out the pairs the robot's SRDF disables.
        max_rows: number of QP rows; the closest active pairs get them. Default: one row per
            pair for a listed pair set, :data:`AUTO_MAX_ROWS` for ``auto`` (hundreds of pairs).
        broad_phase: skip pairs that provably stay beyond :math:`d_i` (conservative).
        trust_region: tolerated second-order error of the linearization [m]: while a pair is
            within :math:`d_i` the rotations moving its links are bounded per tick
            (:meth:`DistanceDamper.compute_bounds`); ``null`` turns the bound off.
        trust_gap_fraction: the trust region of a pair grows with its gap to the safety
            distance: :math:`\max(\varepsilon, f\,(d - d_s))` (``auto`` default 0.1, listed
            pairs 0): an error of a tenth of the gap cannot close it in one tick, and pairs that
            sit within :math:`d_i` at rest do not hold the arms back.
        optional: on a robot without collision geometry, run without this constraint (a
            warning, and a note in ``qpretarget info``) instead of refusing the config.
        hull_vertices: lighter conservative hulls of at most this many vertices (faster GJK,
            distances smaller by at most twice their inflation); ``null``: exact hulls.
        name: constraint name.

    Raises:
        ConfigError: bad values; UnknownNameError: a link without collision geometry.
    """

    importance = 85

    def __init__(
        self,
        *,
        pairs: str | Sequence[Sequence[str]] = "auto",
        d_s: float = 0.02,
        d_i: float = 0.08,
        xi: float | None = None,
        gain: float | None = None,
        gain_per_tick: float | None = None,
        recovery_speed: float = 0.5,
        geometry: str = "convex_hull",
        links: Sequence[str] | None = None,
        exclude: Sequence[Sequence[str]] | None = None,
        include: Sequence[Sequence[str]] | None = None,
        touch_distance: float = 0.005,
        rest_fraction: float = 0.25,
        safety: Sequence[Sequence[Any]] | None = None,
        use_srdf: bool = True,
        max_rows: int | None = None,
        broad_phase: bool = True,
        trust_region: float | None = 2e-4,
        hull_vertices: int | None = None,
        trust_gap_fraction: float | None = None,
        optional: bool = False,
        name: str | None = None,
    ) -> None:
        super().__init__(
            d_s=d_s, d_i=d_i, xi=xi, gain=gain, gain_per_tick=gain_per_tick,
            recovery_speed=recovery_speed, geometry=geometry, max_rows=max_rows,
            broad_phase=broad_phase, trust_region=trust_region, hull_vertices=hull_vertices,
            name=name,
        )  # fmt: skip
        if not isinstance(optional, bool):
            raise ConfigError(f"optional must be true or false, got {optional!r}.")
        self.optional = optional
        #: The robot has no collision geometry and the constraint is ``optional``: no rows.
        self.disabled = False
        self.trust_gap = trust_gap_value(trust_gap_fraction, pairs)
        _check_pair_spec(pairs, links, include)
        self._pairs_spec = pairs
        self._links_spec = None if links is None else [str(x) for x in links]
        self._exclude = [tuple(str(x) for x in p) for p in (exclude or [])]
        self._include = [tuple(str(x) for x in p) for p in (include or [])]
        if any(len(p) != 2 for p in self._include):
            raise ConfigError(f"include must be a list of [link_a, link_b], got {include!r}.")
        if any(len(p) != 2 for p in self._exclude):
            raise ConfigError(f"exclude must be a list of [link_a, link_b], got {exclude!r}.")
        self.touch_distance = float(touch_distance)
        self.rest_fraction = positive_float(rest_fraction, "rest_fraction")
        if self.rest_fraction > 1:
            raise ConfigError(f"rest_fraction must be in (0, 1], got {rest_fraction}.")
        self._safety_spec = _check_safety_spec(safety, self.d_i)
        self.use_srdf = bool(use_srdf)
        #: Pair distances in the reference posture [m] (set by bind; reported by describe()).
        self.reference_distances: np.ndarray | None = None
        #: Why candidate pairs were left out: reason -> list of pairs.
        self.left_out: dict[str, list[tuple[str, str]]] = {}
        #: Warnings about kept pairs (explicit lists: adjacent or touching at the reference).
        self.notes: list[str] = []

    # ------------------------------------------------------------------ binding
    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        p = f"{path}." if path else ""
        shapes = link_shapes(robot, self.geometry)
        self.left_out = {}
        self.notes = []
        if len(shapes) < 2:
            msg = (
                f"robot {robot.name!r} has no collision geometry (links with collision shapes: "
                f"{len(shapes)}), so self-collision cannot be checked."
            )
            if not self.optional:
                raise ConfigError(
                    msg + " Use a URDF with <collision> elements, remove the self_collision "
                    "constraint, or set `optional: true` in it to run without it.",
                    path=path,
                )
            self._disable(robot, msg)
            return
        exclude = {
            frozenset(resolve_link(robot, shapes, x, f"{p}exclude[{k}]") for x in pair)
            for k, pair in enumerate(self._exclude)
        }
        if self._pairs_spec == "auto":
            pairs = self._auto_pairs(robot, shapes, exclude, p)
        else:
            pairs = self._listed_pairs(robot, shapes, exclude, p)
        if not pairs:
            raise ConfigError("no collision pair is left after the exclusions.", path=f"{p}pairs")
        self.pairs = pairs
        if self.max_rows is None and self._pairs_spec == "auto":
            self.max_rows = AUTO_MAX_ROWS
        self.model = CollisionModel(
            robot, pairs, geometry=self.geometry, broad_phase=self.broad_phase,
            hull_vertices=self.hull_vertices, path=f"{p}pairs",
        )  # fmt: skip
        # Distances in the reference posture (reported by describe()).
        self.reference_distances = self.model.compute_all(RobotState(robot))[0]
        given = self._given_safety(robot, shapes, pairs, p)
        self.safety = self._safety_distances(pairs, self.reference_distances, given)
        self._setup_rows(robot)

    def _listed_pairs(
        self, robot: RobotModel, shapes: dict[str, LinkShape], exclude: set[frozenset[str]], p: str
    ) -> list[Pair]:
        """The pairs of an explicit list, resolved to links, minus the excluded ones."""
        pairs: list[Pair] = []
        seen: set[frozenset[str]] = set()
        for k, pair in enumerate(self._pairs_spec):
            a, b = (
                resolve_link(robot, shapes, str(x), f"{p}pairs[{k}][{i}]")
                for i, x in enumerate(pair)
            )
            key = frozenset((a, b))
            if a == b:
                raise ConfigError(
                    f"pair [{a}, {b}] names the same link twice.", path=f"{p}pairs[{k}]"
                )
            if key in seen:
                raise ConfigError(f"pair [{a}, {b}] is listed twice.", path=f"{p}pairs[{k}]")
            seen.add(key)
            if key in exclude:
                self.left_out.setdefault("excluded in YAML", []).append((a, b))
                continue
            if adjacent_links(robot, a, b, shapes):
                self.notes.append(f"pair {a}/{b} is adjacent (parent/child joint): kept as listed")
            pairs.append((a, b))
        return pairs

    def _safety_distances(
        self, pairs: list[tuple[str, str]], ref: np.ndarray, given: dict[int, float]
    ) -> np.ndarray:
        r"""Per pair safety distance: ``d_s``, or :math:`\min(d_s, f\,d_{rest})` for auto pairs.

        ``given`` (pair index -> distance, the ``safety:`` entries) replaces either rule.
        """
        safety = np.full(len(pairs), self.d_s)
        ruled = np.ones(len(pairs), dtype=bool)
        ruled[list(given)] = False
        if self._pairs_spec != "auto":
            for (a, b), d, r in zip(pairs, ref, ruled, strict=True):
                if r and d < self.d_s:
                    self.notes.append(
                        f"pair {a}/{b} is {d * 1000:.1f} mm apart in the reference posture "
                        f"(< d_s = {self.d_s * 1000:.0f} mm): it is pushed apart from the start"
                    )
        else:
            # Pairs close at rest (neighbours along a limb, a shoulder beside the torso) would
            # lock the joint between them at d_s: their safety distance is a fraction of their
            # rest distance, min(d_s, rest_fraction * rest) (> 0: the hulls, hence the meshes,
            # stay apart).
            close = np.flatnonzero((self.rest_fraction * ref < self.d_s) & ruled)
            if close.size:
                safety[close] = self.rest_fraction * ref[close]
                examples = ", ".join(
                    f"{pairs[i][0]}/{pairs[i][1]} ({ref[i] * 1000:.1f} mm)" for i in close[:3]
                )
                more = f" (+{close.size - 3} more)" if close.size > 3 else ""
                self.notes.append(
                    f"{close.size} pairs are closer than d_s / rest_fraction in the reference "
                    f"posture: their safety distance is {self.rest_fraction:g} x their rest "
                    f"distance: {examples}{more}"
                )
        for i, d in given.items():
            safety[i] = d
        return safety

    def _given_safety(
        self, robot: RobotModel, shapes: dict[str, LinkShape], pairs: list[Pair], p: str
    ) -> dict[int, float]:
        """The ``safety:`` entries as pair index -> safety distance [m]."""
        index = {frozenset(pr): k for k, pr in enumerate(pairs)}
        given: dict[int, float] = {}
        for k, (a, b, d) in enumerate(self._safety_spec):
            la, lb = (resolve_link(robot, shapes, x, f"{p}safety[{k}]") for x in (a, b))
            i = index.get(frozenset((la, lb)))
            if i is None:
                raise ConfigError(
                    f"safety[{k}] names the pair {la}/{lb}, which the constraint does not keep "
                    "(left out or not listed): add it to `include` (pairs: auto) or to `pairs`, "
                    "or drop the entry; `qpretarget info CONFIG --pairs` lists the kept pairs.",
                    path=f"{p}safety[{k}]",
                )
            given[i] = d
        return given

    def _disable(self, robot: RobotModel, why: str) -> None:
        """``optional: true`` on a robot without collision geometry: no pairs, no rows."""
        self.disabled = True
        self.pairs = []
        self.model = None
        self.n_rows = 0
        self._C = np.zeros((0, robot.nv))
        self._l = self._u = np.zeros(0)
        self._last_pairs = self._row_pairs = np.zeros(0, dtype=int)
        self._gap = np.zeros(0)
        self._grad = np.zeros((0, robot.nv))
        self.notes.append(f"disabled (optional: true): {why}")
        warnings.warn(f"self_collision is off: {why}", stacklevel=2)

    def reset(self, state: RobotState) -> None:
        if not self.disabled:
            super().reset(state)

    def _disabled_rows(self) -> bool:
        return self.disabled

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock:
        if self.disabled:
            return ConstraintBlock(self.name, self._C, self._l, self._u)
        return super().compute_rows(state, dt)

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        if self.disabled:
            return None
        return super().compute_bounds(state, dt)

    def distances_and_gradients(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        if self.disabled:
            return np.zeros(0), self._grad
        return super().distances_and_gradients(state)

    def _auto_pairs(
        self, robot: RobotModel, shapes: dict[str, LinkShape], exclude: set[frozenset[str]], p: str
    ) -> list[Pair]:
        """``pairs: auto``: :func:`~qpretarget.collision.pairs.select_pairs` (one definition).

        Every pair of the candidate links minus same-joint, adjacent, SRDF-disabled, excluded
        and touching pairs, and chain neighbours already within :math:`d_i` at rest; the
        ``include:`` pairs come back whatever the rules say. The reasons go to :attr:`left_out`.
        """
        links: list[str] | None = None
        if self._links_spec is not None:
            links = []
            for k, name in enumerate(self._links_spec):
                link = resolve_link(robot, shapes, name, f"{p}links[{k}]")
                if link not in links:
                    links.append(link)
        include = [
            [resolve_link(robot, shapes, str(x), f"{p}include[{k}]") for x in pair]
            for k, pair in enumerate(self._include)
        ]
        sel = select_pairs(
            robot, shapes, contact_margin=self.touch_distance, include=include,
            exclude=[sorted(e) for e in exclude], use_srdf=self.use_srdf,
            geometry=self.geometry, neighbour_distance=self.d_i, links=links, path=f"{p}pairs",
        )  # fmt: skip
        for pair, why in sel.excluded.items():
            self.left_out.setdefault(why.split(" (")[0], []).append(pair)
        return sel.pairs

    # ------------------------------------------------------------------ reporting
    def describe(self, full: bool = False) -> list[str]:
        """Lines for ``qpretarget info``: the pair count, and why the other pairs were left out.

        Args:
            full: list every kept pair (with its rest distance and safety distance) and every
                left-out pair with its reason (``qpretarget info CONFIG --pairs``); otherwise
                counts per reason with three examples, and the kept pairs only when listed.
        """
        model = self.model
        src = "auto" if self._pairs_spec == "auto" else "listed"
        n_out = sum(len(v) for v in self.left_out.values())
        lines = [
            f"{len(self.pairs)} pairs ({src}; {n_out} left out), geometry {self.geometry}, "
            f"d_s={self.d_s} m, d_i={self.d_i} m, {self.gain_form}={self.gain_value}, "
            f"{self.n_rows} QP rows (the closest pairs get them)",
        ]
        if model is not None:
            kinds: dict[str, int] = {}
            for s in model.shapes:
                kinds[s.kind] = kinds.get(s.kind, 0) + 1
            lines.append(
                f"bodies: {len(model.bodies)} ("
                + ", ".join(f"{v} {k}" for k, v in sorted(kinds.items()))
                + ")"
            )
        ref = self.reference_distances
        if full or self._pairs_spec != "auto":
            for k, (a, b) in enumerate(self.pairs):
                dist = (
                    f"  {ref[k] * 1000:7.1f} mm at reference, safety {self.safety[k] * 1000:.1f} mm"
                    if ref is not None else ""
                )  # fmt: skip
                lines.append(f"  keep {a} / {b}{dist}")
        for reason, prs in self.left_out.items():
            if full:
                lines.append(f"left out: {len(prs)} {reason}:")
                lines.extend(f"  {a} / {b}" for a, b in prs)
                continue
            examples = ", ".join(f"{a}/{b}" for a, b in prs[:3])
            more = f" (+{len(prs) - 3} more)" if len(prs) > 3 else ""
            lines.append(f"left out: {len(prs)} {reason}: {examples}{more}")
        if not full and self._pairs_spec == "auto":
            lines.append("(`qpretarget info CONFIG --pairs` lists every pair and its reason)")
        lines.extend(f"note: {n}" for n in self.notes)
        return lines

    def __repr__(self) -> str:
        src = "auto" if self._pairs_spec == "auto" else f"{len(self._pairs_spec)} listed"
        return (
            f"SelfCollision(pairs={src}, d_s={self.d_s}, d_i={self.d_i}, "
            f"{self.gain_form}={self.gain_value}, geometry={self.geometry!r}, "
            f"name={self.name!r})"
        )
