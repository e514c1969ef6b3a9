# SPDX-License-Identifier: Apache-2.0
r"""Constraint base class: a hard-constraint module contributing bounds or rows to the QP.

A constraint contributes either box bounds :math:`v_{min} \le v \le v_{max}` on the decision
variable, or a fixed number of rows :math:`l \le C v \le u` (an equality is a row with
:math:`l = u`; an inactive row has infinite bounds so the QP's shape never changes and the solver
stays warm). ``importance`` orders what gives first when the hard constraints cannot all hold in a
tick (lowest first; contacts and limits give last).
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import ConfigError
from ..registry import Registry
from ..robot import RobotModel, RobotState

CONSTRAINTS = Registry("constraint")


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

    def __init__(self, name: str | None = None) -> None:
        if name is not None and (not isinstance(name, str) or not name):
            raise ConfigError(f"name must be a non-empty string, got {name!r}.")
        self.name = name or self.type_name
        self.n_rows = 0
        self.robot: RobotModel | None = None
        #: Where the constraint sits in the YAML (``constraints[i]``), for error messages.
        self.yaml_path = ""

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

    def after_step(self, state: RobotState, v: np.ndarray, dt: float) -> None:
        """Called with the applied velocity once a tick is done (e.g. to remember it)."""

    def compute_bounds(self, state: RobotState, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Box bounds ``(lb, ub)`` on ``v`` (nv,), or ``None`` if the module has none."""
        return None

    def compute_rows(self, state: RobotState, dt: float) -> ConstraintBlock | None:
        """``n_rows`` rows ``l <= C v <= u``, or ``None`` if the module has none."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"
