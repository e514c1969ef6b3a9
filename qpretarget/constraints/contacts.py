# SPDX-License-Identifier: Apache-2.0
r"""Foot contacts: a 6-D equality per supporting foot, anchored where the foot was put down.

For every active foot :math:`f` with anchor pose :math:`(p_a, R_a)` (the world pose of its sole
frame when the contact was switched on) and current pose :math:`(p, R)`, the rows

.. math::
    J_f\, v = K\, e_f, \qquad
    e_f = \begin{bmatrix} p_a - p \\ R \log_3(R^\top R_a) \end{bmatrix}

hold as equalities (DESIGN.md "One tick": :math:`A v = b`, CRAC eq. 34-42 puts the feet first).
:math:`J_f` is the LOCAL_WORLD_ALIGNED frame Jacobian (rows [linear; angular] in world axes), so
:math:`J_f v\,dt = e_f` moves the sole back onto its anchor to first order: the angular error is the
rotation vector taking :math:`R` to :math:`R_a`, expressed in world axes
(:math:`R\exp(\log_3(R^\top R_a)) = R_a`). The gain :math:`K` [1/s] is the drift correction
(default :math:`K = 1/dt`, the whole error in one tick).

Drift comes from integrating :math:`q \oplus v\,dt` with a constant :math:`v`: the sole then
moves by :math:`J_f v\,dt + \tfrac12 \dot J_f v\,dt^2 + O(dt^3)`, and at the joint speeds of
fast motions (10-30 rad/s) the second-order term alone is millimetres per tick. With
``second_order`` (default) the rows anticipate it,

.. math:: J_f\, v = K e_f - \tfrac{dt}{2}\, \alpha_f(q, v_{prev}),

where :math:`\alpha_f = \dot J_f v` is the frame's classical acceleration at zero joint acceleration
(pinocchio ``getFrameClassicalAcceleration``), evaluated with the previous tick's velocity (exact
when the velocity does not change; with ``acceleration_limits`` the change per tick is bounded).

A *moving* anchor (:meth:`Contacts.set_anchor` with ``moving=True``: a stance foot pivoting in
place, its anchor turned a little every tick) has its step over the tick,
:math:`\delta_f = [p_a - p_a^-;\ R_a^- \log_3(R_a^{-\top} R_a)]`, fed forward outside the
correction caps:

.. math:: J_f\, v = \delta_f / dt + \operatorname{cap}\big(K (e_f - \delta_f)\big)
    \;[- \tfrac{dt}{2} \alpha_f],

so a pivot is followed at its own rate (with the caps alone a 400 deg/s pivot was followed at
the angular cap), while the residual error is still corrected gently. Without a step
(:math:`\delta_f = 0`) this is the row above.

The anticipation uses the last tick's velocity. With ``refine`` (default) a *corrector step*
follows the solve (:meth:`Contacts.refine_rows`, run by the velocity level): the pose the
solved velocity reaches at :math:`q \oplus v\,dt` is compared with the pose the rows asked for,
and when they differ by more than ``refine_tolerance`` the rows are shifted by the difference
and the tick is solved again (docs/contacts_balance.md).

The block always has ``6 * n_feet`` rows; an inactive foot's rows are zero with infinite bounds, so
switching contacts never changes the QP's shape.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, UnknownNameError
from ..robot import RobotModel, RobotState
from ..robots import FootDescription
from ..validation import check_bool, positive_float
from .base import CONSTRAINTS, Constraint, ConstraintBlock

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

_VELOCITY_KINEMATICS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def velocity_kinematics(state: RobotState) -> pin.Data:
    r"""Forward kinematics of ``state`` at its velocity with zero joint acceleration (cached).

    The second-order drift terms of ``contacts`` and ``support_polygon`` read the frames'
    classical accelerations :math:`\dot J v` (and the CoM's) from it; one pass serves both, and
    it is recomputed only when ``state.q`` or ``state.v`` is a new array (``RobotState.update``
    installs new ones every tick; arrays modified in place are not detected). ``state.data`` is
    not touched.

    Returns:
        A pinocchio ``Data`` owned by the cache (do not keep it across ticks).
    """
    entry = _VELOCITY_KINEMATICS.get(state)
    if entry is None:
        entry = [state.model.createData(), None, None, np.zeros(state.model.nv)]
        _VELOCITY_KINEMATICS[state] = entry
    data, q, v, zero = entry
    # RobotState.update installs new q and v arrays every tick: identity is the cheap test (the
    # cache holds references, so an id cannot be reused while cached).
    if q is not state.q or v is not state.v:
        pin.forwardKinematics(state.model, data, state.q, state.v, zero)
        entry[1], entry[2] = state.q, state.v
    return data


@CONSTRAINTS.register("contacts")
class Contacts(Constraint):
    r"""Keep the supporting feet where they were put down (6-D equality per active foot).

    Args:
        feet: names of the robot's feet (``RobotModel.feet``, e.g. ``[left_foot, right_foot]``)
            that may be in contact; default all of them.
        frames: for robots without feet descriptions: contact name -> frame name, or
            contact name -> ``{frame: NAME, rectangle: [x_min, x_max, y_min, y_max]}`` (sole
            rectangle in the frame [m], needed by ``support_polygon``).
        active: contacts active after ``reset`` (default: all).
        gain: drift-correction gain :math:`K` [1/s]; ``None`` corrects the whole drift in one
            tick (:math:`K = 1/dt`). :math:`K\,dt` is capped at 1.
        second_order: anticipate the second-order drift of the tick (module docstring).
        max_correction: caps of the drift-correction speed ``[linear m/s, angular rad/s]``.
        refine: after a solve, correct the rows for the solved step's own drift and solve
            again (:meth:`refine_rows`), at most ``refine_iterations`` times a tick (default:
            as ``second_order``).
        refine_tolerance: residual that triggers it [m] (a rotation's times the sole's
            half-length).
        refine_iterations: most extra solves a tick.
        name: constraint name.

    Raises:
        ConfigError: unknown feet or frames, an empty contact set, a bad gain.
    """

    importance = 100

    def __init__(
        self,
        *,
        feet: Sequence[str] | None = None,
        frames: Mapping[str, Any] | None = None,
        active: Sequence[str] | None = None,
        gain: float | None = None,
        second_order: bool = True,
        max_correction: Sequence[float] = (0.5, 2.0),
        refine: bool | None = None,
        refine_tolerance: float = 5e-5,
        refine_iterations: int = 2,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.second_order = check_bool(second_order, "second_order")
        # Default: with the second-order anticipation (both go beyond the first-order rows;
        # ``second_order: false`` alone gives the plain J v = K e of a fixed benchmark).
        self.refine = self.second_order if refine is None else check_bool(refine, "refine")
        self.refine_tolerance = positive_float(refine_tolerance, "refine_tolerance [m]")
        self.refine_iterations = int(refine_iterations)
        if self.refine_iterations < 1 or self.refine_iterations != refine_iterations:
            raise ConfigError(
                f"refine_iterations must be a whole number >= 1, got {refine_iterations!r}."
            )
        if (
            isinstance(max_correction, str)
            or not isinstance(max_correction, Sequence)
            or len(max_correction) != 2
        ):
            raise ConfigError(
                f"max_correction must be [linear m/s, angular rad/s], got {max_correction!r}."
            )
        self.max_correction = (
            positive_float(max_correction[0], "max_correction[0] [m/s]"),
            positive_float(max_correction[1], "max_correction[1] [rad/s]"),
        )
        if feet is not None and (isinstance(feet, str) or not isinstance(feet, Sequence)):
            raise ConfigError(f"feet must be a list of foot names, got {feet!r}.")
        if frames is not None and not isinstance(frames, Mapping):
            raise ConfigError(
                f"frames must map a contact name to a frame name (or {{frame, rectangle}}), "
                f"got {frames!r}."
            )
        if active is not None and (isinstance(active, str) or not isinstance(active, Sequence)):
            raise ConfigError(f"active must be a list of contact names, got {active!r}.")
        self._feet_spec = None if feet is None else [str(f) for f in feet]
        self._frames_spec = None if frames is None else dict(frames)
        self._active_spec = None if active is None else [str(a) for a in active]
        self.gain = None if gain is None else positive_float(gain, "gain [1/s]")
        self.names: list[str] = []
        self.frame_ids: list[int] = []
        self.rectangles: list[tuple[float, ...] | None] = []  # (x_min, x_max, y_min, y_max)
        self._active = np.zeros(0, dtype=bool)
        self._anchor_p = np.zeros((0, 3))
        self._anchor_R = np.zeros((0, 3, 3))
        self._anchor_step = np.zeros((0, 6))
        self._kernel_index: int | None = None  # this block's index in the compiled tick
        #: Incremented whenever the active set or an anchor changes (listeners compare it).
        self.version = 0

    # ------------------------------------------------------------------ binding
    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        p = f"{path}." if path else ""
        entries: list[tuple[str, str, tuple[float, ...] | None]] = []  # (x0, x1, y0, y1)
        if self._feet_spec is not None or self._frames_spec is None:
            feet = self._feet_spec if self._feet_spec is not None else list(robot.feet)
            for i, foot in enumerate(feet):
                if foot not in robot.feet:
                    raise UnknownNameError(
                        "foot",
                        foot,
                        list(robot.feet),
                        path=f"{p}feet[{i}]",
                        fix=(
                            f"Robot {robot.name!r} has feet {list(robot.feet)}; for other "
                            "contact frames use `frames: {name: frame}`."
                        ),
                    )
                desc: FootDescription = robot.feet[foot]
                entries.append((foot, desc.frame, tuple(desc.rectangle)))
        for cname, spec in (self._frames_spec or {}).items():
            rect = None
            if isinstance(spec, str):
                frame = spec
            elif isinstance(spec, Mapping) and "frame" in spec:
                frame = spec["frame"]
                extra = set(spec) - {"frame", "rectangle"}
                if extra:
                    raise ConfigError(
                        f"unknown key(s) {sorted(extra)} for contact {cname!r}; allowed: frame, "
                        "rectangle.",
                        path=f"{p}frames.{cname}",
                    )
                if spec.get("rectangle") is not None:
                    r = np.asarray(spec["rectangle"], dtype=float)
                    if r.shape != (4,) or not (r[0] < r[1] and r[2] < r[3]):
                        raise ConfigError(
                            "rectangle must be [x_min, x_max, y_min, y_max] with x_min < x_max "
                            f"and y_min < y_max [m], got {spec['rectangle']!r}.",
                            path=f"{p}frames.{cname}.rectangle",
                        )
                    rect = tuple(float(x) for x in r)
            else:
                raise ConfigError(
                    f"contact {cname!r} must be a frame name or {{frame: NAME, rectangle: "
                    f"[x_min, x_max, y_min, y_max]}}, got {spec!r}.",
                    path=f"{p}frames.{cname}",
                )
            entries.append((str(cname), frame, rect))
        if not entries:
            raise ConfigError(
                f"robot {robot.name!r} has no feet: name the contact frames with "
                "`frames: {name: frame}`.",
                path=path,
            )
        names = [e[0] for e in entries]
        if len(set(names)) != len(names):
            raise ConfigError(f"contact names must be unique, got {names}.", path=path)
        self.names = names
        self.frame_ids = [robot.frame_id(frame, path=f"{p}frames.{n}") for n, frame, _ in entries]
        self.rectangles = [e[2] for e in entries]
        n = len(entries)
        self.n_rows = 6 * n
        self._initial_active = self._check_names(
            self._active_spec if self._active_spec is not None else names, f"{p}active"
        )
        self._active = np.zeros(n, dtype=bool)
        self._anchor_p = np.zeros((n, 3))
        self._anchor_R = np.tile(np.eye(3), (n, 1, 1))
        self._anchor_step = np.zeros((n, 6))
        self._C = np.zeros((self.n_rows, robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)
        self._refine_data = robot.model.createData()
        lengths = [0.5 * (r[1] - r[0]) for r in self.rectangles if r is not None]
        self._half_length = max(lengths) if lengths else 0.1

    def _check_names(self, feet: Sequence[str], path: str) -> np.ndarray:
        if isinstance(feet, str) or not isinstance(feet, Sequence):
            raise ConfigError(f"contacts must be a list of names, got {feet!r}.", path=path)
        mask = np.zeros(len(self.names), dtype=bool)
        for f in feet:
            if f not in self.names:
                raise UnknownNameError(
                    "contact", str(f), self.names, path=path, fix=f"Contacts: {self.names}."
                )
            mask[self.names.index(f)] = True
        return mask

    # ------------------------------------------------------------------ switching
    @property
    def active_feet(self) -> list[str]:
        """Names of the contacts in force, in declaration order."""
        return [n for n, a in zip(self.names, self._active, strict=True) if a]

    def _anchor(self, i: int, state: RobotState) -> None:
        M = state.frame_placement(self.frame_ids[i])
        self._anchor_p[i] = M.translation
        self._anchor_R[i] = M.rotation
        self._anchor_step[i] = 0.0

    def reset(self, state: RobotState) -> None:
        """Activate the configured contacts, anchored at their current poses."""
        self._active[...] = self._initial_active
        for i in np.flatnonzero(self._active):
            self._anchor(int(i), state)
        self.version += 1

    def set_contacts(self, feet: Sequence[str], state: RobotState) -> None:
        """Switch the set of supporting feet.

        A foot that becomes active is anchored at its current pose; a foot that stays active keeps
        its anchor; a foot left out is released (its rows become inactive). Call it through
        ``Controller.set_contacts``, which also tells the support polygon.

        Args:
            feet: names of the contacts in force from the next tick (may be empty).
            state: current kinematics.

        Raises:
            UnknownNameError: a name that is not one of :attr:`names`.
        """
        new = self._check_names(list(feet), "set_contacts")
        for i in np.flatnonzero(new & ~self._active):
            self._anchor(int(i), state)
        self._active[...] = new
        self.version += 1

    def set_anchor(self, foot: str, pose: Any, *, moving: bool = False) -> None:
        """Move the anchor of contact ``foot`` (e.g. to a planned footstep pose).

        The drift correction then pulls the sole there at the rate of :attr:`gain` (a far anchor
        is a contact set that cannot be kept this tick: the relaxation reports it). Listeners
        (the support polygon) see the change through :attr:`version`.

        With ``moving`` the anchor moves continuously (a stance foot pivoting in place, a small
        step every tick): its step from the previous anchor is fed forward this tick, outside
        the correction caps (module docstring); it holds until the next ``set_anchor`` of this
        foot or :meth:`clear_anchor_steps`.

        Args:
            foot: contact name.
            pose: ``pinocchio.SE3`` or 4x4 homogeneous transform of the sole in the world.
            moving: feed the anchor's step forward (see above).

        Raises:
            UnknownNameError: unknown contact. ConfigError: a malformed pose.
        """
        i = int(self._check_names([foot], "set_anchor").argmax())
        if isinstance(pose, pin.SE3):
            R, p = pose.rotation, pose.translation
        else:
            T = np.asarray(pose, dtype=float)
            if T.shape != (4, 4) or not np.isfinite(T).all():
                raise ConfigError(
                    f"anchor pose must be a pinocchio.SE3 or a finite 4x4, got {T.shape}."
                )
            R, p = T[:3, :3], T[:3, 3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
            raise ConfigError("anchor rotation must be orthonormal.")
        if moving:
            R0 = self._anchor_R[i]
            self._anchor_step[i, :3] = p - self._anchor_p[i]
            self._anchor_step[i, 3:] = R0 @ pin.log3(R0.T @ R)
        else:
            self._anchor_step[i] = 0.0
        self._anchor_R[i] = R
        self._anchor_p[i] = p
        self.version += 1

    def clear_anchor_steps(self) -> None:
        """Stop feeding every anchor's last step forward (the anchors stay where they are)."""
        self._anchor_step[...] = 0.0

    def anchor_pose(self, foot: str) -> pin.SE3:
        """World pose of the anchor of contact ``foot`` (meaningful while it is active)."""
        i = self._check_names([foot], "anchor_pose").argmax()
        return pin.SE3(self._anchor_R[i].copy(), self._anchor_p[i].copy())

    def sole_corners_in_world(self) -> np.ndarray:
        """World corners (4 per active sole, (4 k, 3)) of the active soles at their anchors.

        Raises:
            ConfigError: an active contact has no sole rectangle (``frames:`` without one).
        """
        out = []
        for i in np.flatnonzero(self._active):
            rect = self.rectangles[i]
            if rect is None:
                raise ConfigError(
                    f"contact {self.names[i]!r} has no sole rectangle; give "
                    "`frames: {name: {frame: F, rectangle: [x_min, x_max, y_min, y_max]}}` to use "
                    "a support polygon.",
                    path=self.yaml_path,
                )
            x0, x1, y0, y1 = rect
            local = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
            out.append(local @ self._anchor_R[i].T + self._anchor_p[i])
        return np.concatenate(out) if out else np.zeros((0, 3))

    # ------------------------------------------------------------------ per tick
    def errors(self, state: RobotState) -> np.ndarray:
        """Stacked 6-D errors ``[p_a - p; R log3(R' R_a)]`` of every contact (n, 6)."""
        n = len(self.names)
        e = np.zeros((n, 6))
        for i in range(n):
            M = state.frame_placement(self.frame_ids[i])
            R = M.rotation
            e[i, :3] = self._anchor_p[i] - M.translation
            e[i, 3:] = R @ pin.log3(R.T @ self._anchor_R[i])
        return e

    def compile_rows_into(self, tick: Any, row: int) -> bool:
        """The same rows (drift anticipation included), computed in the kernel.

        The kernel reads the active set and the anchors from this object's arrays, which
        :meth:`set_contacts` and :meth:`set_anchor` change in place.
        """
        index = tick.add_contacts(
            row, list(self.frame_ids), -1.0 if self.gain is None else self.gain,
            self.second_order, self.max_correction[0], self.max_correction[1], self._active,
            self._anchor_p, self._anchor_R, self._anchor_step,
        )  # fmt: skip
        # The corrector step runs in the kernel too (the same residual, to round-off). Only the
        # index is kept: the tick holds this object's arrays, a reference back would be a cycle
        # through a C++ object that the garbage collector cannot see.
        self._kernel_index = int(index) if hasattr(tick, "refine_contacts") else None
        return True

    def kernel_detached(self) -> None:
        self._kernel_index = None

    def _target_velocity(self, i: int, M: pin.SE3, k: float, dt: float) -> np.ndarray:
        """The sole's velocity over the tick that contact ``i``'s rows ask for.

        Before the second-order anticipation: the capped drift correction plus a moving
        anchor's step (module docstring).
        """
        cap_lin, cap_ang = self.max_correction
        R = M.rotation
        step = self._anchor_step[i]
        moving = bool(step.any())
        lin = self._anchor_p[i] - M.translation
        ang = R @ pin.log3(R.T @ self._anchor_R[i])
        if moving:
            lin = lin - step[:3]
            ang = ang - step[3:]
        lin *= k
        ang *= k
        n2 = lin.dot(lin)
        if n2 > cap_lin * cap_lin:
            lin *= cap_lin / np.sqrt(n2)
        n2 = ang.dot(ang)
        if n2 > cap_ang * cap_ang:
            ang *= cap_ang / np.sqrt(n2)
        if moving:
            lin += step[:3] / dt
            ang += step[3:] / dt
        out = np.empty(6)
        out[:3] = lin
        out[3:] = ang
        return out

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock:
        k = 1.0 / dt if self.gain is None else min(self.gain, 1.0 / dt)
        C, lo, hi = self._C, self._l, self._u
        active = self._active.tolist()
        drift = self.second_order and any(active) and bool(state.v.any())
        if drift:
            model = state.model
            data2 = velocity_kinematics(state)
            half_dt = 0.5 * dt
        for i, fid in enumerate(self.frame_ids):
            r0 = 6 * i
            if not active[i]:
                C[r0 : r0 + 6] = 0.0
                lo[r0 : r0 + 6] = -np.inf
                hi[r0 : r0 + 6] = np.inf
                continue
            C[r0 : r0 + 6] = state.frame_jacobian(fid)
            lo[r0 : r0 + 6] = self._target_velocity(i, state.frame_placement(fid), k, dt)
            if drift:
                acc = pin.getFrameClassicalAcceleration(model, data2, fid, LWA).vector
                acc *= half_dt
                lo[r0 : r0 + 6] -= acc
            hi[r0 : r0 + 6] = lo[r0 : r0 + 6]
        return ConstraintBlock(self.name, C, lo, hi)

    def refines(self) -> bool:
        return self.refine and bool(self._active.any())

    def refine_rows(
        self,
        state: RobotState,
        q_next: np.ndarray,
        dt: float,
        l: np.ndarray,
        u: np.ndarray,
        kernel: Any = None,
    ) -> bool:
        r"""The corrector step of the contact rows (:meth:`Constraint.refine_rows`).

        For every active contact, the pose the rows ask for at the end of the tick is
        :math:`p^* = p + b_{lin} dt`, :math:`R^* = \exp(b_{ang} dt) R` (:math:`b` the
        correction and a moving anchor's step, module docstring); the solved step reaches
        :math:`(p^+, R^+)` at ``q_next``. When the residual
        :math:`r = [p^+ - p^*;\ \log_3(R^+ R^{*\top})]` exceeds :attr:`refine_tolerance`
        (linear [m]; angular [rad] times the sole's half-length), the rows' right-hand side
        becomes :math:`b - r/dt`: the next solve's step, whose drift is close to this one's,
        lands on :math:`p^*` (a fixed-point iteration on the rows' nonlinearity, exact where
        the second-order anticipation from the last tick's velocity is not).
        """
        if not self.refine:
            return False
        if kernel is not None and self._kernel_index is not None:
            return bool(
                kernel.refine_contacts(
                    self._kernel_index, q_next, dt, self.refine_tolerance, self._half_length, l, u
                )
            )
        active = np.flatnonzero(self._active)
        if not active.size:
            return False
        model, data = state.model, self._refine_data
        pin.forwardKinematics(model, data, q_next)
        k = 1.0 / dt if self.gain is None else min(self.gain, 1.0 / dt)
        tol_lin, tol_ang = self.refine_tolerance, self.refine_tolerance / self._half_length
        worst = 0.0
        res = np.zeros((len(self.frame_ids), 6))
        for i in active.tolist():
            fid = self.frame_ids[i]
            M = state.frame_placement(fid)
            b = self._target_velocity(int(i), M, k, dt)
            Mn = pin.updateFramePlacement(model, data, fid)
            res[i, :3] = Mn.translation - (M.translation + b[:3] * dt)
            R_star = pin.exp3(b[3:] * dt) @ M.rotation
            res[i, 3:] = pin.log3(Mn.rotation @ R_star.T)
            worst = max(
                worst,
                float(np.abs(res[i, :3]).max()) / tol_lin,
                float(np.abs(res[i, 3:]).max()) / tol_ang,
            )
        if worst <= 1.0:
            return False
        for i in active.tolist():
            r0 = 6 * int(i)
            l[r0 : r0 + 6] -= res[i] / dt
            u[r0 : r0 + 6] = l[r0 : r0 + 6]
        return True

    def __repr__(self) -> str:
        return (
            f"Contacts(contacts={self.names}, active={self.active_feet}, gain={self.gain}, "
            f"second_order={self.second_order}, max_correction={self.max_correction}, "
            f"name={self.name!r})"
        )
