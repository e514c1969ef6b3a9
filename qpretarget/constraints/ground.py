# SPDX-License-Identifier: Apache-2.0
r"""Ground and static obstacles: the velocity damper of :mod:`.self_collision` against the world.

Chosen links (default: the feet, hands and knees of the robot's key-points) stay above the ground
plane :math:`z = h` by a margin :math:`d_s`, and chosen links stay away from static obstacles
(sphere, box, capsule, cylinder or half-space, placed in the world from YAML). Each (link, ground)
and (link, obstacle) pair is a row of the same damper,

.. math::
    -\frac{\partial d}{\partial q} v \le \text{rate}\,(d - d_s) \quad \text{when } d < d_i,

computed by the same :class:`~qpretarget.collision.CollisionModel` (convex hulls or capsules of
the links; the ground is a coal half-space, so :math:`d` is the height of the link's lowest
point). A link that touches the ground when the controller is reset (a standing foot) or that
belongs to an active contact is taken as standing on it: its ground row is disarmed until the link
rises above :math:`d_s` + ``arm_height`` (the contact constraint holds it; a second, conflicting
constraint on it would only make the QP infeasible).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..collision import CollisionModel, LinkShape, link_shapes, obstacle_shape
from ..errors import ConfigError, UnknownNameError
from ..robot import RobotModel, RobotState
from ..validation import check_bool
from .base import CONSTRAINTS, Constraint, ConstraintBlock
from .contacts import Contacts
from .self_collision import DistanceDamper, resolve_link, trust_gap_value

#: Name of the ground body in pair names and reports.
GROUND = "ground"
#: Key-points constrained by default (each resolved to the link carrying its geometry).
DEFAULT_KEYPOINTS = ("left_hand", "right_hand", "left_knee", "right_knee")


@CONSTRAINTS.register("ground")
class Ground(DistanceDamper):
    r"""Keep links above the ground and away from static obstacles (velocity damper).

    Args:
        links: links (or key-points / frames, resolved to the link carrying their geometry) kept
            above the ground; default the feet, hands and knees. ``[]`` for obstacles only.
        height: ground height :math:`h` [m].
        margin: :math:`d_s` for the ground [m].
        obstacles: static obstacles, each ``{name, shape: sphere|box|capsule|cylinder|halfspace,
            radius / size / length / normal+offset, position [m], rpy [rad] (or pose 4x4)}``.
        obstacle_links: links kept away from the obstacles (default: every link with geometry).
        obstacle_margin: :math:`d_s` for the obstacles [m] (default: ``margin``).
        d_i: influence distance [m].
        xi, gain, gain_per_tick: damper gain, one form (see :mod:`.self_collision`).
        recovery_speed: largest separation speed asked of a link below :math:`d_s` [m/s].
        arm_height: a standing link's ground row arms once it is this far above :math:`d_s` [m].
        geometry: ``convex_hull`` or ``capsule``.
        max_rows: cap on the QP rows (default one per pair).
        broad_phase: skip pairs that provably stay beyond :math:`d_i`.
        trust_region: tolerated linearization error [m] (see :mod:`.self_collision`).
        plane_trust: bound each rotation in the trust region by its second-order change of
            height, :math:`\sqrt{2\varepsilon / (r\,|n \times a|)}` for an axis :math:`a` and
            the plane's normal :math:`n`, instead of :math:`\sqrt{2\varepsilon / r}` (a turn
            about the vertical is then free; see
            :meth:`~.self_collision.DistanceDamper.compute_bounds`). Off by default: the legs
            then turn faster, which the contact rows hold only with their corrector step
            (``contacts`` ``refine``, on by default); ``g1_whole_body.yaml`` turns it on
            (measured in docs/retargeting.md).
        trust_gap_fraction: the trust region of a pair grows with its gap to the ground
            (or obstacle) margin, :math:`\max(\varepsilon, f\,(d - d_s))` (the rule of the
            self-collision constraint's ``auto`` pairs; 0 by default: the trust region is
            ``trust_region`` at any gap). A standing leg's shank sits 2-5 cm over the floor, within
            ``d_i``, and the fixed 0.4 mm bound capped the base's roll and pitch near 3 rad/s
            and every leg joint near 3.4 rad/s: a roundhouse kick's pelvis, tilting at 5.7
            rad/s, stalled 35-55 deg behind the person's turn. ``g1_whole_body.yaml`` uses 0.1
            (docs/retargeting.md, *The ground's trust region grows with the gap*).
        hull_vertices: lighter conservative hulls (see :mod:`.self_collision`).
        name: constraint name.

    Raises:
        ConfigError: bad values or obstacles; UnknownNameError: unknown links.
    """

    importance = 75
    disarms_rows = True

    def __init__(
        self,
        *,
        links: Sequence[str] | None = None,
        height: float = 0.0,
        margin: float = 0.0,
        obstacles: Sequence[Mapping[str, Any]] | None = None,
        obstacle_links: Sequence[str] | None = None,
        obstacle_margin: float | None = None,
        d_i: float = 0.05,
        xi: float | None = None,
        gain: float | None = None,
        gain_per_tick: float | None = None,
        recovery_speed: float = 0.5,
        arm_height: float = 0.01,
        geometry: str = "convex_hull",
        max_rows: int | None = None,
        broad_phase: bool = True,
        trust_region: float | None = 2e-4,
        plane_trust: bool = False,
        trust_gap_fraction: float = 0.0,
        hull_vertices: int | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(
            d_s=margin, d_i=d_i, xi=xi, gain=gain, gain_per_tick=gain_per_tick,
            recovery_speed=recovery_speed, geometry=geometry, max_rows=max_rows,
            broad_phase=broad_phase, trust_region=trust_region, hull_vertices=hull_vertices,
            name=name,
        )  # fmt: skip
        self.plane_trust = check_bool(plane_trust, "plane_trust")
        self.trust_gap = trust_gap_value(trust_gap_fraction, None)
        if links is not None and (isinstance(links, str) or not isinstance(links, Sequence)):
            raise ConfigError(f"links must be a list of link names, got {links!r}.")
        if obstacles is not None and (
            isinstance(obstacles, (str, Mapping)) or not isinstance(obstacles, Sequence)
        ):
            raise ConfigError(f"obstacles must be a list of mappings, got {obstacles!r}.")
        if obstacle_links is not None and (
            isinstance(obstacle_links, str) or not isinstance(obstacle_links, Sequence)
        ):
            raise ConfigError(
                f"obstacle_links must be a list of link names, got {obstacle_links!r}."
            )
        for key, value in (("height", height), ("arm_height", arm_height)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not np.isfinite(value)
            ):
                raise ConfigError(f"{key} must be a finite number [m], got {value!r}.")
        self.height = float(height)
        self.arm_height = float(arm_height)
        if obstacle_margin is not None and (
            isinstance(obstacle_margin, bool)
            or not isinstance(obstacle_margin, (int, float))
            or not obstacle_margin < self.d_i
        ):
            raise ConfigError(
                f"obstacle_margin must be a number below d_i [m], got {obstacle_margin!r}."
            )
        self.obstacle_margin = self.d_s if obstacle_margin is None else float(obstacle_margin)
        self._links_spec = None if links is None else [str(x) for x in links]
        self._obstacles_spec = list(obstacles or [])
        self._obstacle_links_spec = (
            None if obstacle_links is None else [str(x) for x in obstacle_links]
        )
        self.links: list[str] = []
        self.obstacles: list[LinkShape] = []
        self._contacts: Contacts | None = None
        self._contacts_version = -1

    # ------------------------------------------------------------------ binding
    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        p = f"{path}." if path else ""
        shapes = link_shapes(robot, self.geometry)
        if self._links_spec is None:
            names = [f.frame for f in robot.feet.values()]
            names += [k for k in DEFAULT_KEYPOINTS if k in robot.keyframes]
            specs = [(n, f"{p}links") for n in names]
        else:
            specs = [(n, f"{p}links[{k}]") for k, n in enumerate(self._links_spec)]
        links: list[str] = []
        for n, where in specs:
            link = resolve_link(robot, shapes, n, where)
            if link not in links:
                links.append(link)
        self.links = links
        self.obstacles = [
            obstacle_shape(spec, robot.model, path=f"{p}obstacles[{k}]")
            for k, spec in enumerate(self._obstacles_spec)
        ]
        names = [o.name for o in self.obstacles]
        if len(set(names)) != len(names) or GROUND in names:
            raise ConfigError(
                f"obstacle names must be unique and not {GROUND!r}, got {names}.",
                path=f"{p}obstacles",
            )
        if self._obstacle_links_spec is None:
            olinks = list(shapes) if self.obstacles else []
        else:
            olinks = []
            for k, n in enumerate(self._obstacle_links_spec):
                link = resolve_link(robot, shapes, n, f"{p}obstacle_links[{k}]")
                if link not in olinks:
                    olinks.append(link)
        self.obstacle_links = olinks
        ground = LinkShape(
            GROUND, "halfspace", _halfspace(self.height), 0, 0, pin.SE3.Identity(), 0.0
        )
        pairs = [(link, GROUND) for link in links]
        pairs += [(link, o.name) for o in self.obstacles for link in olinks]
        if not pairs:
            raise ConfigError("no link to constrain: give `links` or `obstacles`.", path=path)
        self.pairs = pairs
        self.n_ground = len(links)
        self.model = CollisionModel(
            robot, pairs, geometry=self.geometry, obstacles=[ground, *self.obstacles],
            broad_phase=self.broad_phase, hull_vertices=self.hull_vertices, path=f"{p}links",
        )  # fmt: skip
        self.safety = np.array(
            [self.d_s] * self.n_ground + [self.obstacle_margin] * (len(pairs) - self.n_ground)
        )
        self.armed = np.ones(len(pairs), dtype=bool)
        self._setup_rows(robot)

    def link(self, constraints: Sequence[Constraint]) -> None:
        """Find the contacts constraint (called once the controller is built)."""
        for c in constraints:
            if isinstance(c, Contacts):
                self._contacts = c
                return

    def on_contacts_changed(self, contacts: Constraint, state: RobotState) -> None:
        """The supporting feet changed: disarm the ground rows of the feet now in contact."""
        if isinstance(contacts, Contacts):
            self._contacts = contacts
        self._disarm_contacts()

    def _disarm_contacts(self) -> None:
        c = self._contacts
        if c is None or self.robot is None:
            return
        self._contacts_version = c.version
        active = set(c.active_feet)
        joints = {
            self.robot.model.frames[fid].parentJoint
            for n, fid in zip(c.names, c.frame_ids, strict=False)
            if n in active
        }
        assert self.model is not None
        for k in range(self.n_ground):
            if self.model.shapes[self.model.bodies.index(self.pairs[k][0])].joint in joints:
                self.armed[k] = False

    def reset(self, state: RobotState) -> None:
        super().reset(state)
        assert self.model is not None
        d = self.model.compute_all(state)[0]
        self.armed[:] = True
        self.armed[: self.n_ground] = d[: self.n_ground] >= self.d_s + self.arm_height
        self._contacts_version = -1

    # ------------------------------------------------------------------ per tick
    def _row_mask(self, active: np.ndarray) -> np.ndarray:
        model = self.model
        assert model is not None
        c = self._contacts
        if c is not None and c.version != self._contacts_version:
            self._disarm_contacts()
        ground = active < self.n_ground
        if ground.any():
            # Standing links re-arm once they are clearly above the ground.
            d = model.distances[active]
            rise = ground & ~self.armed[active] & (d >= self.d_s + self.arm_height)
            if rise.any():
                self.armed[active[rise]] = True
        # Links far above the ground (not active) are re-armed too.
        far = np.flatnonzero(~self.armed[: self.n_ground])
        if far.size:
            gone = model.distances[far] >= self.d_s + self.arm_height
            self.armed[far[gone]] = True
        return self.armed[active]

    def describe(self) -> list[str]:
        """Lines for ``qpretarget info``."""
        lines = [
            f"ground z = {self.height} m, margin {self.d_s} m, d_i={self.d_i} m, "
            f"{self.gain_form}={self.gain_value}: {', '.join(self.links) or '-'}"
        ]
        if self.trust_gap > 0:
            lines.append(f"trust region grows to {self.trust_gap} of a pair's gap")
        for o in self.obstacles:
            lines.append(
                f"obstacle {o.name} ({o.kind}) at {np.round(o.placement.translation, 3).tolist()}, "
                f"margin {self.obstacle_margin} m, vs {len(self.obstacle_links)} links"
            )
        lines.append(f"{len(self.pairs)} pairs, {self.n_rows} QP rows")
        return lines

    def __repr__(self) -> str:
        return (
            f"Ground(links={self.links or self._links_spec}, height={self.height}, "
            f"margin={self.d_s}, obstacles={[o.get('name') for o in self._obstacles_spec]}, "
            f"name={self.name!r})"
        )


@CONSTRAINTS.register("sole_ground")
class SoleGround(Constraint):
    r"""Soles of the lifted feet stay above the ground: the sole rectangle's corners, one row each.

    For every foot that is *not* in force in the ``contacts`` constraint (a swinging foot), each
    corner :math:`c` of its sole rectangle (the sole frame's origin if it has none), at height
    :math:`z_c` above the ground :math:`z = h`, gets the damper row

    .. math::
        -\dot z_c = -(J_{v,z} + r_y J_{\omega,x} - r_x J_{\omega,y})\, v
        \le \max(\text{rate}\,(z_c - h), -\text{recovery\_speed})
        \quad \text{when } z_c < h + d_i,

    :math:`r = R\,c` the corner's lever from the sole frame (world axes), rate = ``gain_per_tick``
    / dt: with the default 1 a corner may come down as fast as it likes but not past the floor in
    one tick (first order: :math:`z_c + \dot z_c\,dt \ge h`), so a landing is not slowed; below 1
    it closes its gap by at most that fraction per tick; one under the floor is pushed up at most
    ``recovery_speed``. (0.5 slowed the soles near the floor enough to change the stride: the
    walk-stop clip's travel ratio 1.10 -> 1.14.) Rows on the sole rectangle's corners (the points
    the contact stands on) rather than the :class:`Ground` damper on the foot link's hull: no
    distance query, no arming logic, and only the lifted feet have rows (feet in contact are held
    by the contact equality).

    The first-order row is not viable under acceleration limits: a sole coming down at 3 m/s
    that meets it 5 cm over the floor must stop within a tick or two, the joint acceleration
    limits (hard, more important) forbid it, and the row gives: a kinematic landing put a
    corner 10.8 mm into the floor on the playground jumps. With ``brake_accel`` :math:`a_b`
    the descent is also bounded by the speed from which the corner can still stop at the
    floor decelerating at :math:`a_b` (the braking bound of the joint limits, docs/reliability.md,
    applied to a height):

    .. math::
        -\dot z_c \le \sqrt{2\, a_b\, (z_c - h)},

    active below :math:`h + d_i` (so :math:`d_i` should hold the braking distance from the
    fastest descent: :math:`v^2 / 2 a_b`).

    Soft, as ``ground`` (importance 75).

    Args:
        feet: the robot's feet (sole frame and rectangle of its description); default all.
        height: ground height :math:`h` [m].
        d_i: rows only for corners lower than :math:`h + d_i` [m].
        gain_per_tick: fraction of the height a corner may lose per tick near the floor, (0, 1].
        recovery_speed: largest upward speed asked of a corner under the floor [m/s].
        brake_accel: deceleration :math:`a_b` a descending corner is kept able to stop with
            [m/s^2]; ``None``: first-order rows only.
        name: constraint name.

    Raises:
        ConfigError: bad values; UnknownNameError: unknown feet.
    """

    importance = 75

    def __init__(
        self,
        *,
        feet: Sequence[str] | None = None,
        height: float = 0.0,
        d_i: float = 0.05,
        gain_per_tick: float = 1.0,
        recovery_speed: float = 0.5,
        brake_accel: float | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        if brake_accel is not None and (
            isinstance(brake_accel, bool)
            or not isinstance(brake_accel, (int, float))
            or not brake_accel > 0
            or not np.isfinite(brake_accel)
        ):
            raise ConfigError(
                f"brake_accel must be a positive number [m/s^2] or null, got {brake_accel!r}."
            )
        self.brake_accel = None if brake_accel is None else float(brake_accel)
        for key, value in (("height", height), ("d_i", d_i), ("gain_per_tick", gain_per_tick),
                           ("recovery_speed", recovery_speed)):  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"{key} must be a number, got {value!r}.")
        if not np.isfinite(height):
            raise ConfigError(f"height must be a finite number [m], got {height!r}.")
        if not d_i > 0 or not 0 < gain_per_tick <= 1 or not recovery_speed > 0:
            raise ConfigError(
                "d_i [m] and recovery_speed [m/s] must be positive and gain_per_tick in (0, 1], "
                f"got d_i={d_i!r}, gain_per_tick={gain_per_tick!r}, "
                f"recovery_speed={recovery_speed!r}."
            )
        self.height = float(height)
        self.d_i = float(d_i)
        self.gain_per_tick = float(gain_per_tick)
        self.recovery_speed = float(recovery_speed)
        if feet is not None and (isinstance(feet, str) or not isinstance(feet, Sequence)):
            raise ConfigError(f"feet must be a list of foot names, got {feet!r}.")
        self._feet_spec = None if feet is None else [str(f) for f in feet]
        self.feet: list[str] = []
        self.frame_ids: list[int] = []
        self._contacts: Contacts | None = None
        self._corners: list[np.ndarray] = []

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        p = f"{path}." if path else ""
        feet = self._feet_spec if self._feet_spec is not None else list(robot.feet)
        self.feet, self.frame_ids, self._corners = [], [], []
        for i, foot in enumerate(feet):
            if foot not in robot.feet:
                raise UnknownNameError(
                    "foot", foot, list(robot.feet), path=f"{p}feet[{i}]",
                    fix=f"Robot {robot.name!r} has feet {list(robot.feet)}.",
                )  # fmt: skip
            desc = robot.feet[foot]
            self.feet.append(foot)
            self.frame_ids.append(robot.frame_id(desc.frame, path=f"{p}feet[{i}]"))
            if desc.rectangle is None:
                self._corners.append(np.zeros((1, 3)))
            else:
                x0, x1, y0, y1 = (float(x) for x in desc.rectangle)
                self._corners.append(
                    np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
                )
        self.n_rows = sum(len(c) for c in self._corners)
        self._C = np.zeros((self.n_rows, robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)

    def link(self, constraints: Sequence[Constraint]) -> None:
        """Find the contacts constraint: a sole in contact has no row."""
        for c in constraints:
            if isinstance(c, Contacts):
                self._contacts = c
                return

    def _in_contact(self) -> set[int]:
        c = self._contacts
        if c is None:
            return set()
        active = set(c.active_feet)
        return {fid for n, fid in zip(c.names, c.frame_ids, strict=True) if n in active}

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock | None:
        C, hi = self._C, self._u
        C.fill(0.0)
        hi.fill(np.inf)
        rate = self.gain_per_tick / dt
        standing = self._in_contact()
        row = 0
        for i, fid in enumerate(self.frame_ids):
            corners = self._corners[i]
            n = len(corners)
            if fid in standing:
                row += n
                continue
            M = state.frame_placement(fid)
            r = corners @ M.rotation.T  # levers in world axes
            z = M.translation[2] + r[:, 2] - self.height
            near = np.flatnonzero(z < self.d_i)
            if near.size:
                J = state.frame_jacobian(fid)
                for k in near:
                    C[row + k] = -(J[2] + r[k, 1] * J[3] - r[k, 0] * J[4])
                    bound = rate * z[k]
                    if self.brake_accel is not None and z[k] > 0.0:
                        bound = min(bound, math.sqrt(2.0 * self.brake_accel * z[k]))
                    hi[row + k] = max(bound, -self.recovery_speed)
            row += n
        return ConstraintBlock(self.name, C, self._l, hi)

    def describe(self) -> list[str]:
        """Lines for ``qpretarget info``."""
        return [
            f"soles of lifted feet above z = {self.height} m: {self.n_rows} corner rows, "
            f"d_i={self.d_i} m, gain_per_tick={self.gain_per_tick}"
            + ("" if self.brake_accel is None else f", brake_accel={self.brake_accel} m/s^2")
        ]


def _halfspace(height: float) -> Any:
    """The solid ground ``{x : z <= height}`` as a coal half-space (``{x : n'x <= d}``)."""
    return coal.Halfspace(np.array([0.0, 0.0, 1.0]), float(height))
