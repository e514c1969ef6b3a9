# SPDX-License-Identifier: Apache-2.0
r"""The controller: one stacked QP per tick from task and constraint modules (DESIGN.md "One tick").

.. code-block:: python

    ctrl = Controller.from_yaml("configs/g1_augmentation.yaml")
    q = ctrl.reset()
    res = ctrl.step({"left_hand": p_left, "pelvis": T_pelvis}, dt=0.01)

:meth:`Controller.step` is the one tick template: validate ``dt``, read the targets (a task left
out keeps its last target; a NaN target is missing data, its task gets weight zero for the tick
and recovers smoothly), build every task's block and every constraint's bounds/rows from one
kinematics pass (:meth:`Controller.build_tick`), let the control level solve
(:class:`~qpretarget.control.velocity.VelocityLevel` or
:class:`~qpretarget.control.acceleration.AccelerationLevel`, see
:class:`~qpretarget.control.levels.Level`), apply the motion and refresh the kinematics, then
return a :class:`~qpretarget.control.result.StepResult` and notify the observers. A failed tick
never raises: the controller brakes within the acceleration limits (status ``held``), reports why
in the result, and goes on (docs/reliability.md).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from .. import schema
from ..constraints import CONSTRAINTS, Constraint
from ..constraints.contacts import Contacts
from ..errors import ConfigError, TargetError, close_matches_hint
from ..registry import build_from_spec
from ..robot import RobotModel, RobotState, load_robot
from ..solvers import make_solver
from ..solvers.base import DEFAULT_SOLVER
from ..strategies import STRATEGIES, Strategy, TickProblem
from ..strategies.base import SoftRows
from ..tasks import TASKS, Task
from ..weighting.base import REGULARIZATIONS, Regularization
from ..yamlio import read_yaml_file
from .acceleration import PAPER_DAMPING, AccelerationLevel
from .compiled import CompiledTick
from .levels import Level, LevelOutcome
from .relaxation import Fallback, make_fallback
from .result import StepResult, TaskErrors
from .velocity import VelocityLevel

#: Top-level keys of a controller YAML (defined in :mod:`qpretarget.schema`).
TOP_LEVEL_KEYS = schema.TOP_LEVEL_KEYS

#: An observer: called with every tick's :class:`StepResult`.
Observer = Callable[[StepResult], object]


def _merge_bound(lb: np.ndarray, ub: np.ndarray, clo: np.ndarray, chi: np.ndarray) -> float | None:
    """Intersect the box ``[lb, ub]`` (in place) with a less important box ``[clo, chi]``.

    Where they conflict the less important bound gives: it is clipped into ``[lb, ub]``.

    Returns:
        How much it gave (largest gap, in its units), or ``None`` when nothing conflicted.
    """
    new_lb = np.maximum(lb, clo)
    new_ub = np.minimum(ub, chi)
    bad = new_lb > new_ub
    gave = None
    if bad.any():
        gave = float(np.max(np.maximum(new_lb - ub, lb - new_ub)[bad]))
        new_lb[bad] = np.clip(clo[bad], lb[bad], ub[bad])
        new_ub[bad] = np.clip(chi[bad], lb[bad], ub[bad])
        new_lb[bad] = np.minimum(new_lb[bad], new_ub[bad])
    lb[...] = new_lb
    ub[...] = new_ub
    return gave


class Controller:
    """A QP whole-body controller built from a configuration mapping (the YAML's content).

    Args:
        config: the controller description (see ``docs/yaml.md``; checked by
            :mod:`qpretarget.schema`).
        base_dir: directory relative paths in ``config`` are resolved against.

    Attributes:
        level: the YAML ``level:`` (``"velocity"`` or ``"acceleration"``).
        level_impl: the :class:`~qpretarget.control.levels.Level` solving each tick.
        fallback: the relaxation fallback, or ``None`` (``fallback: {enabled: false}``).
        row_constraints: constraints contributing rows, in YAML order (rows stacked so).
        bound_constraints: every constraint, hard ones first, each group most important first
            (``Constraint.merge_rank``; box bounds merged so).

    Raises:
        ConfigError: on any invalid entry, with the YAML path of the problem.
    """

    def __init__(self, config: Mapping[str, Any], *, base_dir: str | Path | None = None) -> None:
        if not isinstance(config, Mapping):
            raise ConfigError(
                f"a controller config must be a mapping, got {type(config).__name__}."
            )
        self.config = copy.deepcopy(dict(config))
        self.base_dir = Path(base_dir) if base_dir is not None else Path.cwd()
        #: The YAML file and its text when built by :meth:`from_yaml`.
        self.config_path: Path | None = None
        self.config_text: str | None = None
        cfg = self.config
        schema.check_top_level(cfg)
        self.robot: RobotModel = load_robot(schema.robot_spec(cfg, self.base_dir), path="robot")
        self.dt = schema.tick_length(cfg)
        self.level = schema.control_level(cfg)
        self.tasks: dict[str, Task] = self._build_tasks()
        self.constraints: list[Constraint] = self._build_constraints()
        self.row_constraints = [c for c in self.constraints if c.n_rows > 0]
        self.n_rows = sum(c.n_rows for c in self.row_constraints)
        # Bounds are merged from most to least important (a less important bound gives).
        # ... and the boxes of soft row constraints (a collision pair's trust region) after every
        # hard one: a soft constraint never makes the acceleration limits give.
        self.bound_constraints = sorted(self.constraints, key=lambda c: c.merge_rank())
        rtype, rkwargs = schema.typed_section(
            cfg.get("regularization"), "regularization", "identity"
        )
        self.regularization: Regularization = build_from_spec(
            REGULARIZATIONS.lookup(rtype, path="regularization.type"),
            rkwargs,
            path="regularization",
        )
        self.regularization.bind(self.robot, self.constraints)
        self.solver_spec = cfg.get("solver", {"name": DEFAULT_SOLVER})
        make_solver(self.solver_spec, path="solver")  # validate now, not at the first tick
        self.strategy: Strategy = self._build_strategy()
        self._C = np.zeros((self.n_rows, self.robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)
        self._lb = np.empty(self.robot.nv)
        self._ub = np.empty(self.robot.nv)
        self.state = RobotState(self.robot)
        self._observers: list[Observer] = []
        #: Seconds spent in each stage of the last tick (read by ``qpretarget bench``).
        self.last_timings: dict[str, float] = {}
        self.tick = 0
        self.t = 0.0
        self.v = np.zeros(self.robot.nv)
        for con in self.constraints:
            con.link(self.constraints)
        self.fallback: Fallback | None = make_fallback(self, cfg.get("fallback"))
        self.level_impl: Level = self._build_level()
        #: The compiled tick (control/compiled.py), or ``None``: then :attr:`compiled_reason`
        #: names the module (or the missing kernel) that keeps the tick in Python.
        self.compiled: CompiledTick | None
        self.compiled, self.compiled_reason = CompiledTick.compile(self)
        self._notes: list[str] = []  # reports for the next StepResult
        self.reset()

    def _build_tasks(self) -> dict[str, Task]:
        """The ``tasks:`` modules, bound, with rows in one stacked Jacobian/reference buffer."""
        tasks: dict[str, Task] = {}
        for path, type_name, kwargs in schema.typed_list(self.config, "tasks"):
            cls = TASKS.lookup(type_name, path=f"{path}.type")
            kwargs.setdefault(
                "name",
                kwargs.get("frame", type_name) if type_name != "frame" else kwargs.get("name"),
            )
            task: Task = build_from_spec(cls, kwargs, path=path)
            if task.name in tasks:
                raise ConfigError(
                    f"two tasks are named {task.name!r}; names must be unique.", path=f"{path}.name"
                )
            task.bind(self.robot, path=path)
            task.yaml_path = path
            tasks[task.name] = task
        if not tasks:
            raise ConfigError("no task: list at least one under `tasks:`.", path="tasks")
        m = sum(t.dim for t in tasks.values())
        self._J_all = np.zeros((m, self.robot.nv))
        self._v_all = np.zeros(m)
        i = 0
        for t in tasks.values():
            t.attach_buffers(self._J_all[i : i + t.dim], self._v_all[i : i + t.dim])
            i += t.dim
        return tasks

    def _build_constraints(self) -> list[Constraint]:
        """The ``constraints:`` modules, bound (names unique)."""
        constraints: list[Constraint] = []
        for path, type_name, kwargs in schema.typed_list(self.config, "constraints"):
            cls = CONSTRAINTS.lookup(type_name, path=f"{path}.type")
            soft = kwargs.pop("soft", None)  # every constraint's key (constraints/base.py)
            if soft is not None and not isinstance(soft, bool):
                raise ConfigError(f"soft must be true or false, got {soft!r}.", path=f"{path}.soft")
            con: Constraint = build_from_spec(cls, kwargs, path=path)
            con.soft_override = soft
            con.bind(self.robot, path=path)
            con.yaml_path = path
            if any(c.name == con.name for c in constraints):
                raise ConfigError(
                    f"two constraints are named {con.name!r}; give one a `name:`.", path=path
                )
            constraints.append(con)
        return constraints

    def _build_strategy(self) -> Strategy:
        """A new, bound instance of the ``strategy:`` (own solvers, own warm start)."""
        stype, skwargs = schema.typed_section(
            self.config.get("strategy"), "strategy", "augmentation"
        )
        strategy: Strategy = build_from_spec(
            STRATEGIES.lookup(stype, path="strategy.type"), skwargs, path="strategy"
        )
        strategy.bind(
            self.robot,
            [(t.name, t.dim, t.level) for t in self.tasks.values()],
            self.n_rows,
            lambda: make_solver(self.solver_spec, path="solver"),
        )
        soft = self.soft_rows() if self.level == "velocity" else []
        #: The strategy gives the soft rows exact-penalty slacks (else the fallback relaxes them).
        self.soft_in_qp = bool(soft) and strategy.set_soft_rows(soft)
        return strategy

    def soft_rows(self) -> list[SoftRows]:
        """The rows of the soft row constraints (``Constraint.is_soft``) and their weights."""
        out, i = [], 0
        for con in self.row_constraints:
            if con.is_soft():
                out.append(SoftRows(con.name, slice(i, i + con.n_rows), con.penalty_weight()))
            i += con.n_rows
        return out

    def _build_level(self) -> Level:
        """The :class:`Level` of the YAML ``level:``."""
        if self.level == "velocity":
            refiners, i = [], 0
            for con in self.row_constraints:
                if type(con).refine_rows is not Constraint.refine_rows:
                    refiners.append((con, slice(i, i + con.n_rows)))
                i += con.n_rows
            return VelocityLevel(
                self.robot, self.strategy, self.fallback, self.last_timings, refiners
            )
        reg_spec = self.config.get("regularization")
        has_damping = isinstance(reg_spec, Mapping) and "damping" in reg_spec
        return AccelerationLevel(
            self.robot,
            list(self.tasks.values()),
            self.n_rows,
            self.strategy,
            self._build_strategy,
            self.fallback,
            self.regularization.damping if has_damping else PAPER_DAMPING,
            self.last_timings,
            self.config.get("acceleration"),
        )

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_yaml(cls, path: str | Path) -> Controller:
        """Build a controller from a YAML file; relative paths resolve against its folder.

        Raises:
            ConfigError: on a missing file, YAML syntax errors (with line) or invalid content.
        """
        path = Path(path)
        text, cfg = read_yaml_file(path, ConfigError, "config file")
        if not isinstance(cfg, Mapping):
            raise ConfigError(f"{path}: the file must hold a mapping (robot:, tasks:, ...).")
        try:
            ctrl = cls(cfg, base_dir=path.parent)
        except ConfigError as exc:
            raise ConfigError(f"{path.name}: {exc}") from None
        ctrl.config_path = path
        ctrl.config_text = text
        return ctrl

    @property
    def config_yaml(self) -> str:
        """The controller's YAML text (the file's text when built from a file)."""
        if self.config_text is not None:
            return self.config_text
        return yaml.safe_dump(self.config, sort_keys=False)

    # ------------------------------------------------------------------ loop
    def reset(self, q: np.ndarray | None = None) -> np.ndarray:
        """Reset to ``q`` (default: the robot's reference posture); targets become current values.

        Returns:
            The configuration (read-only copy).
        """
        q = (
            self.robot.q_reference.copy()
            if q is None
            else self.robot.check_configuration(q, what="reset q")
        )
        self.v = np.zeros(self.robot.nv)
        self.state.update(q, self.v)
        self.tick = 0
        self.t = 0.0
        for task in self.tasks.values():
            task.reset(self.state)
        for con in self.constraints:
            con.reset(self.state)
        self.regularization.reset(self.state)
        self.strategy.reset()
        if self.fallback is not None:  # runs from reset() must be reproducible to the last bit
            self.fallback.reset()
        self.level_impl.reset()
        ct = getattr(self, "compiled", None)  # (not yet set during __init__'s first reset)
        if ct is not None:
            ct.reset()
        out = q.copy()
        out.setflags(write=False)
        return out

    @property
    def q(self) -> np.ndarray:
        """Current configuration (read-only view)."""
        q = self.state.q.view()
        q.setflags(write=False)
        return q

    def add_observer(self, fn: Observer) -> None:
        """Call ``fn(step_result)`` after every tick (e.g. a live viewer's publisher).

        Observers must be quick: the viewer's :class:`~qpretarget.viz.viewer.LivePublisher`
        only stores the latest result and sends it from its own thread. An observer that raises
        is removed and reported in the next result's messages; it never stops the loop.
        """
        if not callable(fn):
            raise TypeError(f"an observer must be callable, got {type(fn).__name__}")
        self._observers.append(fn)

    def remove_observer(self, fn: Observer) -> None:
        """Stop calling ``fn``."""
        if fn in self._observers:
            self._observers.remove(fn)

    def _notify(self, result: StepResult) -> None:
        for fn in list(self._observers):
            try:
                fn(result)
            except Exception as exc:  # an observer never kills the control loop
                self._observers.remove(fn)
                result.messages.append(f"observer {fn!r} raised {exc!r}; it was removed.")

    def task(self, name: str) -> Task:
        """Return task ``name`` (raises with close names)."""
        try:
            return self.tasks[name]
        except KeyError:
            raise TargetError(
                f"no task named {name!r}.{close_matches_hint(name, list(self.tasks))} "
                f"Tasks: {', '.join(self.tasks)}."
            ) from None

    def constraint(self, name: str) -> Constraint:
        """Return the constraint named (or typed) ``name``."""
        for c in self.constraints:
            if c.name == name:
                return c
        for c in self.constraints:
            if c.type_name == name:
                return c
        known = [c.name for c in self.constraints]
        raise KeyError(
            f"no constraint {name!r}.{close_matches_hint(name, known)} Constraints: {known}"
        )

    def set_contacts(self, feet: Sequence[str]) -> None:
        """Switch the supporting feet (delegated to the ``contacts`` constraint module).

        Every other constraint hears of it through :meth:`Constraint.on_contacts_changed`.
        """
        for c in self.constraints:
            if isinstance(c, Contacts):
                c.set_contacts(feet, self.state)
                for other in self.constraints:
                    if other is not c:
                        other.on_contacts_changed(c, self.state)
                return
        raise ConfigError(
            "set_contacts needs a `contacts` constraint in the config.", path="constraints"
        )

    def set_weight_scale(self, task: str, scale: float | npt.ArrayLike) -> None:
        r"""Weigh task ``task``'s rows :math:`s\,w` from the next tick on (``1``: as configured).

        See :meth:`Task.set_weight_scale <qpretarget.tasks.base.Task.set_weight_scale>`; the
        compiled kernel's cost block is told too.

        Raises:
            ConfigError: No task named ``task``, or ``scale`` is not a finite number >= 0.
        """
        t = self.tasks.get(task)
        if t is None:
            raise ConfigError(
                f"no task named {task!r}.{close_matches_hint(str(task), list(self.tasks))} "
                f"Tasks: {', '.join(self.tasks)}."
            )
        if t.set_weight_scale(scale) and self.compiled is not None:
            self.compiled.refresh_weight(t)

    def set_targets(self, targets: Mapping[str, Any] | None, messages: list[str]) -> None:
        """Hand each target to its task; NaN targets become missing data (reported)."""
        if not targets:
            return
        if not isinstance(targets, Mapping):
            raise TargetError(
                f"targets must be a mapping task name -> target, got {type(targets).__name__}.",
                tick=self.tick,
            )
        for name, target in targets.items():
            if name not in self.tasks:
                raise TargetError(
                    f"no task named {name!r}.{close_matches_hint(str(name), list(self.tasks))} "
                    f"Tasks: {', '.join(self.tasks)}.",
                    tick=self.tick,
                )
            if target is None:
                continue
            task = self.tasks[name]
            if not task.set_target(target, tick=self.tick):
                task.mark_missing()
                if self.compiled is not None:
                    self.compiled.note_missing(task)
                messages.append(
                    f"task {name!r}, tick {self.tick}: target contains NaN or inf; keeping the "
                    "last "
                    f"target with weight 0 this tick (recovers over {task.recovery_time} s)."
                )

    def build_tick(self, dt: float) -> TickProblem:
        """Build every block of this tick (used by ``step`` and by solver comparisons)."""
        state = self.state
        timings = self.last_timings
        perf = time.perf_counter
        t0 = perf()
        ct = self.compiled
        built = None
        if ct is not None:
            try:
                built = ct.build(dt)  # compiled modules in one kernel call, then Python ones
            except Exception as exc:  # a kernel error never stops the loop: Python from now on
                self.compiled = None
                self.compiled_reason = f"kernel error at tick {self.tick}: {exc!r}"
                for con in self.constraints:
                    con.kernel_detached()
                self._notes.append(
                    f"tick {self.tick}: the compiled kernel failed ({exc!r}); every module runs "
                    "its Python code from now on (a bug to report)."
                )
        if ct is not None and built is not None:
            blocks, gave = built
            t1 = perf()
            timings["tasks"] = t1 - t0
            bound_gave = self._merge_bounds(dt, ct) if gave is None else gave
            t2 = perf()
            timings["bounds"] = t2 - t1
            self._stack_rows(dt, only=ct.python_rows)
            timings["regularization"] = 0.0
            return TickProblem(
                state, dt, blocks, self._C, self._l, self._u, self._lb, self._ub,
                self.regularization.matrix(state, dt), self.regularization.damping, self.tick,
                self._J_all, self._v_all, bound_gave, ct,
            )  # fmt: skip
        blocks = [t.block(state, dt) for t in self.tasks.values()]
        t1 = perf()
        timings["tasks"] = t1 - t0
        bound_gave = self._merge_bounds(dt)
        t2 = perf()
        timings["bounds"] = t2 - t1
        self._stack_rows(dt)
        t3 = perf()
        W = self.regularization.matrix(state, dt)
        timings["regularization"] = perf() - t3
        return TickProblem(
            state, dt, blocks, self._C, self._l, self._u, self._lb, self._ub, W,
            self.regularization.damping, self.tick, self._J_all, self._v_all, bound_gave,
        )  # fmt: skip

    def _merge_bounds(self, dt: float, ct: CompiledTick | None = None) -> dict[str, float]:
        """Merge every constraint's box into ``self._lb, self._ub``, most important first.

        Args:
            dt: tick length [s].
            ct: the compiled tick, whose modules' boxes the kernel already computed.

        Returns:
            Constraint name -> how much its (less important) box gave to the ones before it.
        """
        lb, ub = self._lb, self._ub
        lb.fill(-np.inf)
        ub.fill(np.inf)
        gave: dict[str, float] = {}
        first = True
        for con in self.bound_constraints:
            if ct is not None and ct.computes_box(con):
                b = ct.box(con)
            else:
                b = con.compute_bounds(self.state, dt)
            if b is None:
                continue
            if first:  # the most important bounds go in as they are
                np.copyto(lb, b[0])
                np.copyto(ub, b[1])
                first = False
                continue
            amount = _merge_bound(lb, ub, b[0], b[1])
            if amount is not None:
                gave[con.name] = amount
        return gave

    def _stack_rows(self, dt: float, only: set[str] | None = None) -> None:
        """Write every row constraint's block into ``self._C, self._l, self._u`` (YAML order).

        Args:
            dt: tick length [s].
            only: names of the constraints to write (default: all; the compiled tick writes
                the others).
        """
        timings, perf = self.last_timings, time.perf_counter
        i = 0
        for con in self.row_constraints:
            if only is not None and con.name not in only:
                i += con.n_rows
                continue
            tc = perf()
            blk = con.compute_rows(self.state, dt)
            timings[con.name] = perf() - tc
            k = con.n_rows
            if blk is None:
                self._C[i : i + k] = 0.0
                self._l[i : i + k] = -np.inf
                self._u[i : i + k] = np.inf
            else:
                self._C[i : i + k] = blk.C
                self._l[i : i + k] = blk.l
                self._u[i : i + k] = blk.u
            i += k

    def step(
        self, targets: Mapping[str, Any] | None = None, *, dt: float | None = None
    ) -> StepResult:
        """Run one control tick (the tick template; the level solves, see the module docstring).

        Args:
            targets: task name -> target (3-vector, 3x3 rotation, 4x4 transform, SE3, ...). A task
                left out, or given ``None``, keeps its last target.
            dt: tick length [s] (default: the config's ``dt``).

        Returns:
            The :class:`StepResult` of the tick (``tau`` set at acceleration level).

        Raises:
            TargetError: on an unknown task name, a target of the wrong shape/type (a
                programming error) or an invalid ``dt``. NaN values are not errors: they are
                missing data.
        """
        t0 = time.perf_counter()
        dt = self._tick_length(dt)
        self.tick += 1
        messages: list[str] = []
        self.set_targets(targets, messages)
        tb = time.perf_counter()
        tp = self.build_tick(dt)
        build_time = time.perf_counter() - tb
        if self._notes:
            messages.extend(self._notes)
            self._notes.clear()
        out = self.level_impl.solve(tp)
        messages.extend(out.messages)
        errors = TaskErrors(tp.blocks, self.tasks)
        self._apply(out, dt)
        result = self._result(out, errors, messages, build_time + out.build_time, t0)
        if self._observers:
            self._notify(result)
        return result

    def _tick_length(self, dt: float | None) -> float:
        """``dt`` of this tick: the config's, or the given one checked to be in (0, 1) s."""
        if dt is None:
            return self.dt
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1:
            raise TargetError(
                f"dt must be a number of seconds in (0, 1), got {dt!r}.", tick=self.tick + 1
            )
        return float(dt)

    def _apply(self, out: LevelOutcome, dt: float) -> None:
        """Apply the level's motion: constraints' ``after_step``, new state, clock."""
        for con in self.constraints:
            con.after_step(self.state, out.v_next, dt)
        self.v = out.v_next
        tk = time.perf_counter()
        self.state.update(out.q_next, out.v_next)
        self.last_timings["kinematics"] = time.perf_counter() - tk
        self.t += dt

    def _result(
        self,
        out: LevelOutcome,
        errors: TaskErrors,
        messages: list[str],
        build_time: float,
        t0: float,
    ) -> StepResult:
        """The tick's :class:`StepResult` (read-only copies of ``q`` and ``v``)."""
        q_out = out.q_next.copy()
        q_out.setflags(write=False)
        v_out = out.v_next.copy()
        v_out.setflags(write=False)
        return StepResult(
            q=q_out,
            v=v_out,
            tick=self.tick,
            t=self.t,
            status=out.status,
            solver_status=out.solver_status,
            task_errors=errors,
            solve_time=out.solve_time,
            build_time=build_time,
            step_time=time.perf_counter() - t0,
            iterations=out.iterations,
            relaxed=out.relaxed,
            messages=messages,
            tau=out.tau,
        )

    def __repr__(self) -> str:
        return (
            f"Controller(robot={self.robot.name!r}, dt={self.dt}, level={self.level!r}, "
            f"strategy={self.strategy!r}, tasks={list(self.tasks)}, "
            f"constraints={[c.name for c in self.constraints]})"
        )
