# SPDX-License-Identifier: Apache-2.0
r"""Centre of mass over the feet: its ground projection inside the shrunk support polygon.

The support polygon is the convex hull of the corners of the active soles (at their contact
anchors), each edge :math:`k` with outward unit normal :math:`n_k` and offset :math:`o_k` moved
inwards by ``margin``: inside means :math:`n_k^\top c_{xy} \le o_k` for every edge. DESIGN.md
("One tick") linearizes the CoM one tick ahead, :math:`n_k^\top (c_{xy} + J_{com,xy} v\,dt) \le
o_k`; this module uses the velocity-damper form of it,

.. math:: n_k^\top J_{com,xy}\, v \le \gamma\, \frac{o_k - n_k^\top c_{xy}}{dt},
          \qquad 0 < \gamma \le 1,

(the same damper as the self-collision rows of DESIGN.md, Kanoun/Faverjon-Tournassoud style):
inside the polygon the CoM may close at most a fraction :math:`\gamma` of its distance to each
edge per tick, so it approaches an edge smoothly and never crosses it to first order; outside, the
right-hand side is negative and the row *demands* that the CoM move back by that fraction per
tick of its distance to a line ``recovery_depth`` inside the edge (so that it re-enters in a finite
number of ticks, about :math:`\ln(\delta / (d + \delta)) / \ln(1 - \gamma)` from a distance
:math:`d` outside), so the constraint recovers instead of being infeasible forever (when the
demand is more than the other constraints allow this tick, the relaxation of
``control.relaxation`` lets this constraint give first and reports it). :math:`\gamma = 1` is
DESIGN.md's plain linearization.

The hull is recomputed only when the contacts change (``on_contacts_changed``, reset), never per
tick. The block keeps ``max_edges`` rows (4 per contact); unused rows are inactive. With
``second_order`` (default) the rows also subtract :math:`\tfrac{dt}{2} n_k^\top \ddot c_{xy}`, the
CoM's drift acceleration at the previous velocity and zero joint acceleration, so that fast
motions do not carry the CoM over an edge between two linearizations.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..geometry2d import convex_hull_2d  # noqa: F401 (re-exported)
from ..robot import RobotModel, RobotState
from ..validation import check_bool, positive_float
from .base import CONSTRAINTS, Constraint, ConstraintBlock
from .contacts import Contacts, velocity_kinematics


def polygon_halfplanes(vertices: np.ndarray, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    r"""Half-planes :math:`n_k^\top x \le o_k` of a counter-clockwise convex polygon, shrunk.

    Args:
        vertices: (h, 2) counter-clockwise vertices, h >= 3.
        margin: distance every edge is moved inwards [m].

    Returns:
        ``(normals, offsets)``: (h, 2) outward unit normals and (h,) offsets.
    """
    a = vertices
    d = np.roll(a, -1, axis=0) - a  # edge vectors a_k -> a_{k+1}
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)  # outward for a counter-clockwise polygon
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n, np.einsum("ij,ij->i", n, a) - margin


def inscribed_radius(normals: np.ndarray, offsets: np.ndarray) -> float:
    r"""Radius of the largest disc inside :math:`\{x : N x \le o\}` (Chebyshev radius).

    The optimal centre is equidistant from three edges (for a polygon): every triple of edges
    gives a candidate :math:`[n_i^\top\ 1] [x; r] = o_i`; the largest feasible :math:`r` wins.
    Runs only when contacts change (a few hundred 3x3 systems).
    """
    k = len(normals)
    if k < 3:
        return 0.0
    idx = np.array([(i, j, m) for i in range(k) for j in range(i + 1, k) for m in range(j + 1, k)])
    A = np.concatenate([normals[idx], np.ones((len(idx), 3, 1))], axis=2)  # (T, 3, 3)
    ok = np.abs(np.linalg.det(A)) > 1e-12
    if not ok.any():
        return 0.0
    sol = np.linalg.solve(A[ok], offsets[idx[ok]][..., None])[..., 0]  # (T', 3): x, y, r
    inside = np.all(sol[:, :2] @ normals.T + sol[:, 2:3] <= offsets + 1e-12, axis=1)
    return float(max(sol[inside, 2].max(initial=0.0), 0.0))


@CONSTRAINTS.register("support_polygon")
class SupportPolygon(Constraint):
    r"""Keep the CoM ground projection inside the active soles' convex hull shrunk by ``margin``.

    Args:
        margin: distance kept from every edge of the support polygon [m].
        gain: damper gain :math:`\gamma` in (0, 1]: fraction of the distance to an edge the CoM
            may close (or, outside, must recover) per tick.
        max_edges: number of rows (default 4 per contact of the ``contacts`` constraint, or per
            robot foot without one).
        recovery_depth: when the CoM is outside an edge, it is steered towards a line this far
            inside it [m], so it re-enters in finite time.
        second_order: anticipate the CoM's second-order motion over the tick,
            :math:`\tfrac12 \ddot c(q, v_{prev}, 0)\,dt^2` (as ``contacts`` does for the soles).
        name: constraint name.

    Without a ``contacts`` constraint in the controller, the polygon is made of all the robot's
    feet at their poses at reset.
    """

    importance = 60

    def __init__(
        self,
        *,
        margin: float = 0.01,
        gain: float = 0.2,
        max_edges: int | None = None,
        recovery_depth: float = 0.002,
        second_order: bool = True,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.second_order = check_bool(second_order, "second_order")
        self.recovery_depth = positive_float(recovery_depth, "recovery_depth [m]", allow_zero=True)
        self.margin = positive_float(margin, "margin [m]", allow_zero=True)
        self.gain = positive_float(gain, "gain")
        if self.gain > 1:
            raise ConfigError(f"gain must be in (0, 1] (a fraction per tick), got {gain!r}.")
        if max_edges is not None and (
            isinstance(max_edges, bool) or not isinstance(max_edges, int) or max_edges < 3
        ):
            raise ConfigError(f"max_edges must be an integer >= 3, got {max_edges!r}.")
        self._max_edges = max_edges
        self.contacts: Contacts | None = None
        self._seen_version = -1
        self.normals = np.zeros((0, 2))
        self.offsets = np.zeros(0)
        self.vertices = np.zeros((0, 2))
        self.effective_margin = self.margin

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        self.n_rows = self._max_edges or 4 * max(len(robot.feet), 1)
        self._C = np.zeros((self.n_rows, robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)
        self._N = np.zeros((self.n_rows, 2))
        self._o = np.zeros(self.n_rows)
        self._n_edges = 0
        self._nk = np.zeros(1, dtype=np.int64)  # the edge count, for the compiled rows

    def link(self, constraints: Sequence[Constraint]) -> None:
        """Find the controller's ``contacts`` constraint (called once the controller is built).

        Raises:
            ConfigError: the contacts can make more hull edges than this block has rows.
        """
        for c in constraints:
            if isinstance(c, Contacts):
                self.contacts = c
                break
        if self.contacts is not None and 4 * len(self.contacts.names) > self.n_rows:
            raise ConfigError(
                f"{len(self.contacts.names)} contacts can make a hull of "
                f"{4 * len(self.contacts.names)} edges but max_edges is {self.n_rows}; raise "
                "max_edges.",
                path=self.yaml_path,
            )

    # ------------------------------------------------------------------ hull
    def _corners(self, state: RobotState) -> np.ndarray:
        if self.contacts is not None:
            return self.contacts.sole_corners_in_world()
        robot = self.robot
        out = []
        for foot in robot.feet.values():  # type: ignore[union-attr]
            M = state.frame_placement(robot.frame_id(foot.frame))  # type: ignore[union-attr]
            x0, x1, y0, y1 = foot.rectangle
            local = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
            out.append(local @ M.rotation.T + M.translation)
        return np.concatenate(out) if out else np.zeros((0, 3))

    def update_polygon(self, state: RobotState) -> None:
        """Recompute the shrunk hull from the active soles (call when contacts change).

        A margin larger than the polygon allows is reduced to 90 % of its inscribed radius, with
        a warning (the loop goes on).
        """
        corners = self._corners(state)
        self._N[...] = 0.0
        self._o[...] = 0.0
        self._n_edges = 0
        self._nk[0] = 0
        self.vertices = convex_hull_2d(corners[:, :2]) if len(corners) else np.zeros((0, 2))
        if self.contacts is not None:
            self._seen_version = self.contacts.version
        if len(self.vertices) < 3:  # no support (flight phase): no row
            self.normals, self.offsets = np.zeros((0, 2)), np.zeros(0)
            self._C[...] = 0.0
            self._u[...] = np.inf
            return
        normals, offsets = polygon_halfplanes(self.vertices, 0.0)
        if len(normals) > self.n_rows:
            raise ConfigError(
                f"the support polygon has {len(normals)} edges but max_edges is {self.n_rows}; "
                "raise max_edges.",
                path=self.yaml_path,
            )
        margin = self.margin
        if margin > 0:
            r = inscribed_radius(normals, offsets)
            if margin >= r:
                margin = 0.9 * r
                warnings.warn(
                    f"support_polygon: margin {self.margin} m is larger than the support "
                    f"polygon allows (inscribed radius {r:.4f} m); using {margin:.4f} m for "
                    "these contacts. Lower `margin`.",
                    RuntimeWarning,
                    stacklevel=2,
                )
        self.effective_margin = margin
        offsets = offsets - margin
        k = len(normals)
        self.normals, self.offsets = normals, offsets
        self._N[:k] = normals
        self._o[:k] = offsets
        self._n_edges = k
        self._nk[0] = k
        self._C[k:] = 0.0  # unused rows stay inactive until the next polygon
        self._u[k:] = np.inf

    def reset(self, state: RobotState) -> None:
        self._seen_version = -1
        if self.contacts is None:
            self.update_polygon(state)

    def on_contacts_changed(self, contacts: Constraint, state: RobotState) -> None:
        """Hook of ``Controller.set_contacts``: rebuild the polygon from the new contact set."""
        if self.contacts is None and isinstance(contacts, Contacts):
            self.contacts = contacts
        self.update_polygon(state)

    def com_margin(self, state: RobotState) -> float:
        r"""Signed margin of the CoM projection: :math:`\min_k (o_k - n_k^\top c_{xy})` [m].

        Positive inside the shrunk polygon, negative outside (``-inf`` without support).
        """
        self._sync(state)
        if self._n_edges == 0:
            return -np.inf
        return float(np.min(self.offsets - self.normals @ state.com()[:2]))

    def _sync(self, state: RobotState) -> None:
        if self.contacts is not None and self.contacts.version != self._seen_version:
            self.update_polygon(state)

    # ------------------------------------------------------------------ per tick
    def compile_rows_into(self, tick: Any, row: int) -> bool:
        """The same rows in the kernel; the hull stays here (recomputed on contact changes).

        The kernel compares the contacts' ``version`` with the one this hull was built from
        and calls :meth:`_kernel_sync` when they differ (a new anchor, a new contact set).
        """
        tick.add_polygon(
            self, self.contacts, row, self.n_rows, self.gain, self.recovery_depth,
            self.second_order, self._N, self._o, self._nk,
        )  # fmt: skip
        return True

    def _kernel_sync(self) -> None:
        """Rebuild the hull from the contacts' anchors (called by the kernel)."""
        self.update_polygon(None)  # type: ignore[arg-type]  # the contacts give the corners

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock:
        self._sync(state)
        k = self._n_edges
        if k:
            Jxy = state.com_jacobian()[:2]  # (2, nv)
            np.matmul(self._N[:k], Jxy, out=self._C[:k])
            d = self._o[:k] - self._N[:k] @ state.com()[:2]  # (k,) distance inside each edge
            # Outside an edge, aim `recovery_depth` inside it so that the CoM re-enters in finite
            # time instead of approaching the edge asymptotically from outside.
            d[d < 0.0] -= self.recovery_depth
            self._u[:k] = (self.gain / dt) * d
            if self.second_order and state.v.any():
                data2 = velocity_kinematics(state)
                pin.centerOfMass(state.model, data2, pin.KinematicLevel.ACCELERATION, False)
                self._u[:k] -= (0.5 * dt) * (self._N[:k] @ data2.acom[0][:2])
        return ConstraintBlock(self.name, self._C, self._l, self._u)

    def __repr__(self) -> str:
        return (
            f"SupportPolygon(margin={self.margin}, gain={self.gain}, max_edges={self.n_rows}, "
            f"recovery_depth={self.recovery_depth}, second_order={self.second_order}, "
            f"name={self.name!r})"
        )
