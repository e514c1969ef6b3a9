# SPDX-License-Identifier: Apache-2.0
r"""Task base class: a cost module contributing the rows :math:`\sqrt{w}(J v - v^*)` of one tick.

Every task computes an error :math:`e` (target minus current, so that :math:`J v = K e` reduces it)
and a Jacobian :math:`J`; the base class turns them into the closed-loop inverse kinematics
reference velocity of Dariush 2009 eq. 9 / CRAC eq. 15,

.. math:: v^* = \dot x_d + K e,

with :math:`K` the task gain [1/s]. In discrete time :math:`K\,dt` is capped at 1 (full correction
of the error in one tick), above which the loop would overshoot.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, TargetError
from ..registry import Registry
from ..robot import RobotModel, RobotState
from ..validation import positive_float, weight_vector

TASKS = Registry("task")


@dataclass(frozen=True, slots=True)
class CostBlock:
    """Rows ``sqrt(w) * (J v - v_star)`` of one task for this tick (Dariush 2009 eq. 9).

    Attributes:
        task: task name (YAML), reused in errors, metrics and logs.
        J: (k, nv) task Jacobian.
        v_star: (k,) reference task velocity.
        weight: (k,) non-negative weights (already scaled by the task's presence).
        level: priority level (1 = highest); augmentation ignores it, hierarchy sorts by it.
        error: (k,) task error ``target - current`` at the start of the tick.
    """

    task: str
    J: np.ndarray
    v_star: np.ndarray
    weight: np.ndarray
    level: int
    error: np.ndarray


class Task(abc.ABC):
    r"""A cost module; the base class builds its QP block.

    Subclasses implement :meth:`bind`, :meth:`compute_error`, :meth:`compute_jacobian` and
    :meth:`set_target`.

    Args:
        name: task name, the key of its target in :meth:`Controller.step`.
        weight: scalar or per-row weight ``w`` [cost]/[task unit]^2.
        gain: task gain ``K`` [1/s] of Dariush 2009 eq. 9; ``None`` corrects the whole error in
            one tick (``K = 1/dt``).
        level: priority level (1 = highest) used by the ``hierarchy`` strategy.
        feedforward: add the target's finite-difference velocity as :math:`\dot x_d`.
        recovery_time: after a missing (NaN) target, the weight ramps back to full over this
            time [s] instead of jumping.
    """

    type_name: ClassVar[str] = "task"

    def __init__(
        self,
        name: str,
        *,
        weight: Any = 1.0,
        gain: float | None = None,
        level: int = 1,
        feedforward: bool = False,
        recovery_time: float = 0.2,
    ) -> None:
        if not isinstance(name, str) or not name:
            raise ConfigError(f"a task needs a non-empty string `name`, got {name!r}.")
        self.name = name
        self._weight_spec = weight
        self.gain = None if gain is None else positive_float(gain, "gain [1/s]")
        if isinstance(level, bool) or not isinstance(level, int) or level < 1:
            raise ConfigError(f"level must be an integer >= 1, got {level!r}.")
        self.level = level
        self.feedforward = bool(feedforward)
        self.recovery_time = positive_float(recovery_time, "recovery_time [s]", allow_zero=True)
        self.presence = 1.0  # 0 while the target is missing, ramps back to 1
        self.dim = 0
        self.weight = np.zeros(0)
        #: Factor on the configured weights, one or one per row (:meth:`set_weight_scale`); 1
        #: after :meth:`bind`.
        self.weight_scale: float | np.ndarray = 1.0
        self._weight_full: np.ndarray | None = None  # the configured weights, once scaled
        self._prev_target: tuple[Any, ...] | None = None  # last tick's target, for feedforward
        #: Where the task sits in the YAML (``tasks[i]``), for error messages.
        self.yaml_path = ""
        self.robot: RobotModel | None = None
        self._Jbuf: np.ndarray | None = None  # rows of the controller's stacked buffers
        self._vbuf: np.ndarray | None = None

    # ------------------------------------------------------------------ lifecycle
    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        """Resolve names to ids and fix the task dimension; raise here on bad names."""
        self.robot = robot
        self.weight = weight_vector(
            self._weight_spec, self.dim, f"{path}.weight" if path else "weight"
        )
        self.weight_scale = 1.0
        self._weight_full = None

    def set_weight_scale(self, scale: float | npt.ArrayLike) -> bool:
        r"""Weigh this task's rows :math:`s\,w` instead of the configured :math:`w` from now on.

        For a caller that changes a task's importance with the situation (the retargeter lowers a
        swing sole's weight in the person's flight, and its orientation rows high above the
        floor); :meth:`bind` restores ``1``. ``scale`` is one factor or one per row (``dim``). A
        new weight array is made (strategies reuse square roots of unchanged arrays); call it
        through :meth:`~qpretarget.control.controller.Controller.set_weight_scale`, which also
        tells the compiled kernel.

        Returns:
            ``True`` when the weights changed.

        Raises:
            ConfigError: ``scale`` is not a finite number >= 0, or not one per row.
        """
        what = f"task {self.name!r}: weight scale"
        if np.ndim(scale) == 0:
            s: float | np.ndarray = positive_float(scale, what, allow_zero=True)
        else:
            arr = np.asarray(scale, dtype=float)
            if arr.shape != (self.dim,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ConfigError(
                    f"{what} must be one finite number >= 0 or {self.dim} of them (one per row), "
                    f"got {scale!r}."
                )
            s = arr.copy()
        if np.array_equal(s, self.weight_scale):
            return False
        if self._weight_full is None:
            self._weight_full = self.weight
        self.weight = self._weight_full * s
        self.weight_scale = s
        return True

    def attach_buffers(self, J: np.ndarray, v_star: np.ndarray) -> None:
        """Write this task's rows into ``J`` (dim, nv) and ``v_star`` (dim,) every tick.

        The controller stacks every task's rows in one buffer so a strategy can weight them all
        with one product; the returned :class:`CostBlock` then holds views of those rows, valid
        until the next tick.
        """
        if J.shape != (self.dim, J.shape[1]) or v_star.shape != (self.dim,):
            raise ValueError(f"task {self.name!r}: buffers of shape {J.shape}, {v_star.shape}")
        self._Jbuf, self._vbuf = J, v_star

    def reset(self, state: RobotState) -> None:
        """Set the target to the current value (zero error) and forget history."""
        self.presence = 1.0
        self._prev_target = None

    # ------------------------------------------------------------------ targets
    @abc.abstractmethod
    def set_target(self, target: Any, *, tick: int | None = None) -> bool:
        """Validate, copy and store a target. Raise :class:`TargetError` on a bad shape/type.

        Returns:
            ``False`` when the target holds NaN/inf (missing data; the last target is kept and
            the controller calls :meth:`mark_missing`), ``True`` otherwise.
        """

    def target_error(self, message: str, tick: int | None) -> TargetError:
        """A :class:`TargetError` naming this task and ``tick`` (raised by :meth:`set_target`)."""
        return TargetError(message, task=self.name, tick=tick)

    def target_array(self, target: Any, tick: int | None, expected: str) -> np.ndarray:
        """``target`` as a float array (any shape).

        Raises:
            TargetError: ``"<expected>, got <type>."`` when ``target`` is not numbers.
        """
        return float_array(target, expected, task=self.name, tick=tick)

    def mark_missing(self) -> None:
        """The target of this tick is missing (NaN): weight zero, then a smooth ramp back."""
        self.presence = 0.0

    # ------------------------------------------------------------------ maths
    @abc.abstractmethod
    def compute_error(self, state: RobotState) -> np.ndarray:
        """Task error ``target - current`` (k,)."""

    @abc.abstractmethod
    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        """Task Jacobian (k, nv): ``J v`` is the task-space velocity."""

    #: How the acceleration level gets this task's drift :math:`\dot J v` (CRAC eq. 9):
    #: ``"zero"`` (constant Jacobian), ``"com"`` (pinocchio's CoM acceleration),
    #: ``"analytic"`` (:meth:`compute_jdot_v`) or ``"finite_difference"`` of the Jacobian along
    #: :math:`v` (the default, right for any task).
    drift_kind: ClassVar[str] = "finite_difference"

    def compute_jdot_v(self, state: RobotState) -> np.ndarray:
        r"""Drift term :math:`\dot J v` (k,) for acceleration-level control (CRAC eq. 9)."""
        return np.zeros(self.dim)

    def error_norm(self, error: np.ndarray) -> float:
        """Scalar error reported in :class:`StepResult` (Euclidean norm by default)."""
        return float(np.linalg.norm(error))

    #: Attributes holding the target (replaced, never modified in place, by :meth:`set_target`):
    #: what ``feedforward`` differentiates. Empty: the task has no feed-forward.
    target_attributes: ClassVar[tuple[str, ...]] = ()

    def target_velocity(self, state: RobotState, e: np.ndarray, dt: float) -> np.ndarray | None:
        r"""Feed-forward :math:`\dot x_d` of Dariush 2009 eq. 9 / CRAC eq. 15 (backward difference).

        The target's change over the last tick, measured in the task's own error coordinates:
        :math:`\dot x_d \approx (e(x_{d,k}) - e(x_{d,k-1})) / dt` at the current state, which is
        :math:`(x_{d,k} - x_{d,k-1}) / dt` for a position and the rotation vector of the
        orientation change over :math:`dt` for an orientation. ``None`` on the first tick after
        a reset and while the target does not change (a missing target keeps the old one).
        """
        current = tuple(getattr(self, a) for a in self.target_attributes)
        prev, self._prev_target = self._prev_target, current
        if prev is None or all(p is c for p, c in zip(prev, current, strict=True)):
            return None
        try:
            for a, p in zip(self.target_attributes, prev, strict=True):
                setattr(self, a, p)
            e_prev = self.compute_error(state)
        finally:
            for a, c in zip(self.target_attributes, current, strict=True):
                setattr(self, a, c)
        return (e - e_prev) / dt

    def compile_into(self, tick: Any, row: int) -> bool:
        """Register this task's per-tick computation with the compiled kernel (``tick``).

        The kernel then writes the task's error, Jacobian and reference velocity at stacked row
        ``row`` (control/compiled.py). Returns ``False`` (the default) when the task has no
        compiled part; the controller then runs every task in Python.
        """
        return False

    def _kernel_gain(self) -> float:
        """The gain as the kernel takes it (``-1``: ``None``, a whole error per tick)."""
        return -1.0 if self.gain is None else float(self.gain)

    def effective_gain(self, dt: float) -> float:
        """``K`` with ``K dt`` capped at 1."""
        k = 1.0 / dt if self.gain is None else self.gain
        return min(k, 1.0 / dt)

    def block(self, state: RobotState, dt: float) -> CostBlock:
        """This tick's cost rows (Dariush 2009 eq. 9: ``v* = v_d + K e``)."""
        e = self.compute_error(state)
        J = self.compute_jacobian(state)
        gain = self.gain
        k = 1.0 / dt if gain is None or gain * dt > 1.0 else gain
        if self._Jbuf is not None and self._vbuf is not None:  # set together (attach_buffers)
            np.copyto(self._Jbuf, J)
            J = self._Jbuf
            v_star = self._vbuf
            np.multiply(e, k, out=v_star)
        else:
            v_star = e * k
        if self.feedforward:
            ff = self.target_velocity(state, e, dt)
            if ff is not None:
                v_star += ff
        w = self.weight
        if self.presence < 1.0:
            w = w * self.presence
            rate = dt / self.recovery_time if self.recovery_time > 0 else 1.0
            self.presence = min(1.0, self.presence + rate)
        return CostBlock(self.name, J, v_star, w, self.level, e)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, weight={self._weight_spec!r}, "
            f"gain={self.gain!r}, level={self.level})"
        )


def float_array(value: Any, expected: str, *, task: str, tick: int | None) -> np.ndarray:
    """``value`` as a float array; a TargetError ``"<expected>, got <type>."`` if not numbers."""
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise TargetError(
            f"{expected}, got {type(value).__name__}.", task=task, tick=tick
        ) from None


def as_finite_array(
    value: Any, shape: tuple[int, ...], *, task: str, tick: int | None, what: str
) -> np.ndarray | None:
    """Return ``value`` as a float array of ``shape``; ``None`` if it holds NaN (missing data).

    Raises:
        TargetError: when the shape or type is wrong.
    """
    arr = float_array(value, f"{what} must be an array of shape {shape}", task=task, tick=tick)
    if arr.shape != shape:
        raise TargetError(f"{what} must have shape {shape}, got {arr.shape}.", task=task, tick=tick)
    if not np.all(np.isfinite(arr)):
        return None
    return arr
