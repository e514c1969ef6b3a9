# SPDX-License-Identifier: Apache-2.0
r"""Joint acceleration limits at velocity level: the online answer to jitter.

.. math:: v_{prev} - a_{max}\, dt \le v \le v_{prev} + a_{max}\, dt

on the actuated one-DoF joints, with :math:`v_{prev}` the velocity applied during the previous
tick (zero after reset). Bounding the change of the command per tick keeps the output smooth
without filtering it afterwards (a filter adds lag and can break the other constraints).

Acceleration limits and joint position limits conflict when a joint runs towards a limit faster
than it can stop. With ``braking`` (default) the bound also keeps every joint slow enough to stop
in time, braking at :math:`a_{max}`, while meeting the ``joint_limits`` bound
:math:`v_k \le \gamma d_k / dt` at every later tick (:math:`d` the distance to the limit,
:math:`\gamma` the joint-limit gain, 1 without a ``joint_limits`` constraint). In units of
:math:`a_{max} dt` for velocities and :math:`a_{max} dt^2` for distances
(:math:`\nu = v / (a_{max} dt)`, :math:`\delta = d / (a_{max} dt^2)`), braking from :math:`\nu`
visits :math:`\nu - j` after :math:`j` ticks, having travelled :math:`j\nu - j(j-1)/2`, so it is
admissible when :math:`\delta \ge (\nu - j)/\gamma + j\nu - j(j-1)/2` for every :math:`j`. The
maximum over real :math:`j` (at :math:`j^* = \nu + c`, :math:`c = 1/2 - 1/\gamma`) gives the
conservative closed form

.. math::
    \nu_{max}(\delta) = \begin{cases} \gamma\,\delta & \delta \le -c/\gamma \\
        \sqrt{1/4 + 2(\delta - K_0)} - 1/2 & \text{otherwise} \end{cases},
    \qquad K_0 = -c/\gamma - c(c - 1)/2,

and :math:`|v| \le a_{max} dt\, \nu_{max}` towards each limit (for large :math:`\delta` this is the
familiar :math:`v \approx \sqrt{2 a_{max} d}`). This is a *viability* constraint in the sense of
Del Prete 2018 ("Joint position and velocity bounds in discrete-time acceleration/torque control
of robot manipulators", IEEE RA-L 3(1)): the discrete-time bound on the velocity from which the
joint can still stop before its limit. It is recursively feasible: with
:math:`f(\nu) = \max_{j \ge 0} [(\nu - j)/\gamma + j\nu - j(j-1)/2]` (so that
:math:`\nu \le \nu_{max}(\delta) \Leftrightarrow f(\nu) \le \delta`), substituting
:math:`j' = j + 1` gives :math:`f(\nu - 1) = \max_{j' \ge 1}[\dots] - \nu \le f(\nu) - \nu`, so
braking one tick from an admissible :math:`(\delta, \nu)` lands on an admissible
:math:`(\delta - \nu, \nu - 1)`: from any state the controller produced, the box of joint
position, velocity and acceleration limits is never empty (``tests/test_relaxation.py``,
docs/reliability.md). The bound is clipped to
:math:`v_{prev} \mp a_{max} dt` so the module's own bounds never cross. The bounds are merged with
the other box bounds; this module's ``importance`` (80) is below joint position and velocity
limits, so when stopping in time is impossible anyway (a start outside the limits) it is the
acceleration bound that gives (reported in ``StepResult.relaxed``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from ..errors import ConfigError
from ..robot import RobotModel, RobotState
from ..validation import positive_float
from .base import CONSTRAINTS, Constraint
from .joint_limits import JointLimits


@CONSTRAINTS.register("acceleration_limits")
class AccelerationLimits(Constraint):
    r"""``|v - v_prev| <= a_max dt`` per actuated joint.

    Args:
        a_max: acceleration limit [rad/s^2]: one number for every actuated joint, or a mapping
            joint name -> limit (key ``default`` for the joints not named; joints neither named nor
            covered by ``default`` are not limited).
        braking: also bound the velocity so that each joint can stop before its position limit
            at ``a_max`` (module docstring).
        base: ``[linear m/s^2, angular rad/s^2]``: also bound the floating base's velocity
            change per tick, :math:`|v_b - v_{b,prev}| \le a_b\,dt` per coordinate (the base's
            six velocity coordinates, in its own frame); ``null`` (default): the base is free.
        name: constraint name.

    Raises:
        ConfigError: a non-positive limit or an unknown joint name.
    """

    importance = 80

    has_bounds: ClassVar[bool] = True

    def __init__(
        self,
        *,
        a_max: float | Mapping[str, float],
        braking: bool = True,
        base: Sequence[float] | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        if base is not None:
            if isinstance(base, str) or not isinstance(base, Sequence) or len(base) != 2:
                raise ConfigError(
                    f"base must be [linear m/s^2, angular rad/s^2] or null, got {base!r}."
                )
            base = (
                positive_float(base[0], "base[0] [m/s^2]"),
                positive_float(base[1], "base[1] [rad/s^2]"),
            )
        self.base = base
        if not isinstance(braking, bool):
            raise ConfigError(f"braking must be true or false, got {braking!r}.")
        self.braking = braking
        if isinstance(a_max, Mapping):
            self._spec: float | dict[str, float] = {
                str(k): positive_float(v, f"a_max[{k!r}] [rad/s^2]") for k, v in a_max.items()
            }
        else:
            self._spec = positive_float(a_max, "a_max [rad/s^2]")
        self.a_max = np.zeros(0)

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        super().bind(robot, path=path)
        nj = len(robot.joint_names)
        spec = self._spec
        if isinstance(spec, dict):
            a = np.full(nj, spec.get("default", np.inf))
            for jname, value in spec.items():
                if jname == "default":
                    continue
                a[robot.joint_index(jname, path=f"{path}.a_max.{jname}")] = value
        else:
            a = np.full(nj, spec)
        limited = np.isfinite(a)
        self.a_max = a
        # The floating base's coordinates (the velocity indices no joint owns), if bounded.
        owned = np.zeros(robot.nv, dtype=bool)
        owned[robot.joint_v_index] = True
        self._bi = np.flatnonzero(~owned)
        self._ba = np.zeros(len(self._bi))
        if self.base is not None:
            if len(self._bi) != 6:
                raise ConfigError(
                    f"base: robot {robot.name!r} has no free-flyer base "
                    f"({len(self._bi)} unactuated coordinates).",
                    path=f"{path}.base" if path else "base",
                )
            self._ba = np.array([self.base[0]] * 3 + [self.base[1]] * 3)
        self._vi = robot.joint_v_index[limited]
        self._qi = robot.joint_q_index[limited]
        self._a = a[limited]
        self._qmin = robot.q_min[self._qi]  # may be -inf: no braking on that side
        self._qmax = robot.q_max[self._qi]
        self._dist = np.zeros((2, len(self._qi)))
        self._set_gamma(1.0)
        self._v_prev = np.zeros(robot.nv)
        self._lb = np.full(robot.nv, -np.inf)
        self._ub = np.full(robot.nv, np.inf)

    def link(self, constraints: Sequence[Constraint]) -> None:
        """Read the gain and margin of the controller's ``joint_limits`` (called once built)."""
        for c in constraints:
            if isinstance(c, JointLimits):
                self._set_gamma(float(c.gain))
                margin = float(c.margin)
                qi = self._qi
                self._qmin = self.robot.q_min[qi] + margin  # type: ignore[union-attr]
                self._qmax = self.robot.q_max[qi] - margin  # type: ignore[union-attr]
                break

    def _set_gamma(self, gamma: float) -> None:
        c = 0.5 - 1.0 / gamma
        self._gamma = gamma
        self._delta_lin = -c / gamma  # end of the linear (joint-limit-bound) branch
        self._k0 = -c / gamma - 0.5 * c * (c - 1.0)

    def _nu_max(self, delta: np.ndarray) -> np.ndarray:
        """Normalized braking bound (module docstring), in place on ``delta``; 0 at the limit."""
        np.maximum(delta, 0.0, out=delta)  # beyond the limit: 0 (joint_limits pulls back)
        lin = delta <= self._delta_lin
        lin_val = self._gamma * delta
        delta -= self._k0
        np.maximum(delta, 0.0, out=delta)
        delta *= 2.0
        delta += 0.25
        np.sqrt(delta, out=delta)
        delta -= 0.5
        np.copyto(delta, lin_val, where=lin)
        return delta

    def reset(self, state: RobotState) -> None:
        self._v_prev[...] = 0.0

    def after_step(self, state: RobotState, v: np.ndarray, dt: float) -> None:
        self._v_prev[...] = v

    @property
    def v_prev(self) -> np.ndarray:
        """Velocity applied during the previous tick (nv,), read-only view."""
        out = self._v_prev.view()
        out.setflags(write=False)
        return out

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray]:
        dv = self._a * dt  # (n,)
        vp = self._v_prev[self._vi]
        lo, hi = vp - dv, vp + dv
        if self.braking:
            q = state.q[self._qi]
            d = self._dist  # (2, n): distances to the upper and lower limits
            np.subtract(self._qmax, q, out=d[0])
            np.subtract(q, self._qmin, out=d[1])
            d *= 1.0 / (dt * dt * self._a)  # in units of a_max dt^2 (inf for unlimited joints)
            nu = self._nu_max(d)
            nu *= dv
            np.minimum(hi, np.maximum(nu[0], lo), out=hi)
            np.maximum(lo, np.minimum(-nu[1], hi), out=lo)
        self._lb[self._vi] = lo
        self._ub[self._vi] = hi
        if self.base is not None:
            vb = self._v_prev[self._bi]
            self._lb[self._bi] = vb - self._ba * dt
            self._ub[self._bi] = vb + self._ba * dt
        return self._lb, self._ub

    def __repr__(self) -> str:
        spec: Any = self._spec
        return (
            f"AccelerationLimits(a_max={spec}, braking={self.braking}, base={self.base}, "
            f"name={self.name!r})"
        )
