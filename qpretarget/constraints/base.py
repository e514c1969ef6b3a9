# SPDX-License-Identifier: Apache-2.0
r"""Constraint base class: a hard-constraint module contributing bounds or rows to the QP.

A constraint contributes either box bounds :math:`v_{min} \le v \le v_{max}` on the decision
variable, or a fixed number of rows :math:`l \le C v \le u` (an equality is a row with
:math:`l = u`; an inactive row has infinite bounds so the QP's shape never changes and the solver
stays warm). ``importance`` orders what gives first when the hard constraints cannot all hold in a
tick (lowest first; contacts and limits give last).

**Hard and soft rows** (docs/reliability.md). Only what must hold is hard: the contact equalities
and the box (joint position limits made viable under the velocity and acceleration limits, see
:mod:`.acceleration_limits`). A row constraint that can conflict with them or with another one
(collision and ground margins, the CoM polygon) is *soft*: the strategy gives each of its rows a
slack :math:`s_i \ge 0` behind an exact (L1) penalty,

.. math:: C_i v - s_i \le u_i, \qquad \text{cost} \mathrel{+}= w\, s_i + \tfrac{\epsilon}{2} s_i^2,

so the tick's QP always has a solution and a conflict costs accuracy, not motion. With
:math:`w` above the row's Lagrange multiplier the slack is exactly zero whenever the rows can hold
(exact penalty: Nocedal & Wright 2006, Theorem 17.3; Fletcher 1987, 12.3), so a soft row is as
hard as a hard one until the hard set leaves no room. :attr:`Constraint.soft` declares it (by
default: rows of constraints with ``importance`` below :data:`SOFT_BELOW`), the YAML key
``soft: true|false`` of any constraint overrides it (:attr:`Constraint.soft_override`), and
:meth:`Constraint.penalty_weight` gives :math:`w`. A soft constraint's box bounds are merged after
every hard constraint's, so they give to the hard box.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import ConfigError
from ..registry import Registry
from ..robot import RobotModel, RobotState

CONSTRAINTS = Registry("constraint")

#: Row constraints less important than this are soft unless they (or the YAML ``soft:``) say
#: otherwise (module docstring): ``support_polygon`` (60), ``ground`` (75); ``self_collision`` (85)
#: and ``contacts`` (100) are hard by default.
SOFT_BELOW = 80
#: Exact-penalty weight of the least important soft constraint, per unit of slack (the rows' own
#: units, [m/s] for distances and the CoM): 9 times the largest CoM-polygon multiplier (1.1e4)
#: measured on the wild-target scenario (docs/reliability.md). Each importance step of 10 multiplies
#: it by 10, so the CoM polygon gives before the ground, and the ground before a collision margin.
SOFT_WEIGHT = 1e5


@dataclass(frozen=True, slots=True)
class ConstraintBlock:
    """Rows ``l <= C v <= u`` of one constraint for this tick.

    Attributes:
        constraint: constraint name.
        C: (k, nv) rows.
        l: (k,) lower bounds (``-inf`` for none).
        u: (k,) upper bounds (``+inf`` for none); ``l == u`` for an equality row.
    """

    constraint: str
    C: np.ndarray
    l: np.ndarray
    u: np.ndarray


class Constraint(abc.ABC):  # noqa: B024 - every hook has a default; subclasses pick theirs
    """A hard-constraint module.

    Args:
        name: constraint name (defaults to its type name), used in reports.

    Subclasses set :attr:`n_rows` in :meth:`bind` (0 for a bounds-only module) and override
    :meth:`compute_bounds` and/or :meth:`compute_rows`.
    """

    type_name: ClassVar[str] = "constraint"
    #: Relaxation order: when the hard constraints conflict, lower importance gives first.
    importance: ClassVar[int] = 50
    #: The module overrides :meth:`compute_bounds` (the relaxation fallback slacks its box).
    has_bounds: ClassVar[bool] = False
    #: Rows may give behind an exact-penalty slack (module docstring); ``None``: soft when
    #: ``importance < SOFT_BELOW``. Box bounds are never soft (they give in the bound merge).
    soft: ClassVar[bool | None] = None
    #: Where the module's *box* bounds sit in the merge (``None``: :attr:`importance`). A box that
    #: is only an accuracy device (a collision pair's trust region) can sit below the
    #: acceleration limits (80) while its rows stay above them.
    box_importance: ClassVar[int | None] = None
    #: Most corrector solves a tick this module asks for (:meth:`refine_rows`).
    refine_iterations: int = 1

    def __init__(self, name: str | None = None) -> None:
        if name is not None and (not isinstance(name, str) or not name):
            raise ConfigError(f"name must be a non-empty string, got {name!r}.")
        self.name = name or self.type_name
        #: The YAML ``soft:`` of this constraint (``None``: the class's :attr:`soft`).
        self.soft_override: bool | None = None
        self.n_rows = 0
        self.robot: RobotModel | None = None
        #: Where the constraint sits in the YAML (``constraints[i]``), for error messages.
        self.yaml_path = ""

    def is_soft(self) -> bool:
        """Whether this constraint's rows get exact-penalty slacks (see :attr:`soft`)."""
        if self.soft_override is not None:
            return self.soft_override
        return self.importance < SOFT_BELOW if self.soft is None else bool(self.soft)

    def merge_rank(self) -> tuple[bool, int]:
        """Sort key of the box merge: hard before soft, then most important first."""
        imp = self.importance if self.box_importance is None else self.box_importance
        return (self.n_rows > 0 and self.is_soft(), -imp)

    def penalty_weight(self) -> float:
        r"""Exact-penalty weight :math:`w` of this constraint's slacks [cost per row unit].

        :math:`w = ` :data:`SOFT_WEIGHT` :math:`\cdot 10^{(\text{importance} - 60)/10}`.
        """
        return float(SOFT_WEIGHT * 10.0 ** ((self.importance - 60) / 10.0))

    def bind(self, robot: RobotModel, *, path: str = "") -> None:
        """Resolve names and fix :attr:`n_rows`; raise here on bad names."""
        self.robot = robot

    def link(self, constraints: Sequence[Constraint]) -> None:
        """Find the other constraints this one works with (e.g. the contacts).

        Called once by the controller after every constraint is bound, with all of them (this
        one included). Default: nothing to find.
        """

    def on_contacts_changed(self, contacts: Constraint, state: RobotState) -> None:
        """The supporting feet of ``contacts`` (a ``contacts`` constraint) changed.

        Called by ``Controller.set_contacts`` on every other constraint. Default: nothing to do.
        """

    def reset(self, state: RobotState) -> None:
        """Forget history (anchors, previous velocities) at ``Controller.reset``."""

    def describe(self) -> list[str]:
        """Lines describing the module's settings, for ``qpretarget info`` and the viewer."""
        return []

    def compile_bounds_into(self, tick: Any) -> bool:
        """Register this module's box bounds with the compiled kernel (control/compiled.py).

        ``False`` (the default): no compiled part; the controller then runs in Python.
        """
        return False

    def compile_rows_into(self, tick: Any, row: int) -> bool:
        """Register this module's rows (from stacked row ``row``) with the compiled kernel."""
        return False

    def kernel_detached(self) -> None:
        """The compiled kernel stopped: from the next tick this module runs its Python code."""

    def after_step(self, state: RobotState, v: np.ndarray, dt: float) -> None:
        """Called with the applied velocity once a tick is done (e.g. to remember it)."""

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Box bounds ``(lb, ub)`` on ``v`` (nv,), or ``None`` if the module has none."""
        return None

    def refines(self) -> bool:
        """Whether :meth:`refine_rows` may correct this module's rows after a solve."""
        return False

    def refine_rows(
        self,
        state: RobotState,
        q_next: np.ndarray,
        dt: float,
        l: np.ndarray,
        u: np.ndarray,
        kernel: Any = None,
    ) -> bool:
        r"""Correct this tick's rows for what the solved step really does (a corrector step).

        The rows are linear in :math:`v`; integrating :math:`q \oplus v\,dt` is not. Given
        the configuration ``q_next`` the solved velocity reaches, a module may shift its rows'
        bounds ``l``, ``u`` (views of its own rows, changed in place) by the part of the
        step its rows did not predict; the level then solves the tick again with them
        (``control/velocity.py``). ``kernel`` is the compiled tick (``qpretarget._kernel``)
        when the tick was compiled, for a module that registered a compiled part. Default:
        nothing to correct.

        Returns:
            ``True`` when the bounds changed (the level solves again).
        """
        return False

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock | None:
        """``n_rows`` rows ``l <= C v <= u``, or ``None`` if the module has none."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"
