# SPDX-License-Identifier: Apache-2.0
r"""The controller: one stacked QP per tick from task and constraint modules (DESIGN.md "One tick").

.. code-block:: python

    ctrl = Controller.from_yaml("configs/g1_augmentation.yaml")
    q = ctrl.reset()
    res = ctrl.step({"left_hand": p_left, "pelvis": T_pelvis}, dt=0.01)

Each tick: read the targets (a task left out keeps its last target; a NaN target is missing data,
its task gets weight zero for the tick and recovers smoothly), build every task's block and every
constraint's bounds/rows from one kinematics pass, let the strategy solve, integrate
:math:`q \leftarrow q \oplus v\,dt` and refresh the kinematics. A failed tick never raises: the
controller holds (``v = 0``), reports why in :class:`StepResult`, and goes on.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..constraints import CONSTRAINTS, Constraint
from ..errors import ConfigError, TargetError, close_matches_hint
from ..registry import build_from_spec
from ..robot import ERD_PREFIX, RobotModel, RobotState, load_robot
from ..solvers import make_solver
from ..strategies import STRATEGIES, Strategy, TickProblem
from ..tasks import TASKS, Task
from ..weighting.base import REGULARIZATIONS, Regularization
from ..yamlio import load_yaml

TOP_LEVEL_KEYS = (
    "name", "description", "robot", "dt", "level", "strategy", "regularization", "solver",
    "tasks", "constraints", "fallback", "retarget", "viewer", "acceleration",
)  # fmt: skip


class TaskErrors(Mapping[str, float]):
    """Task name -> error norm, computed on first access (keeps ``step`` cheap when unread)."""

    __slots__ = ("_blocks", "_tasks", "_d")

    def __init__(self, blocks: list, tasks: Mapping[str, Task]) -> None:
        self._blocks, self._tasks, self._d = blocks, tasks, None

    def _dict(self) -> dict[str, float]:
        if self._d is None:
            self._d = {b.task: self._tasks[b.task].error_norm(b.error) for b in self._blocks}
        return self._d

    def __getitem__(self, key: str) -> float:
        return self._dict()[key]

    def __iter__(self):  # noqa: ANN204
        return iter(self._dict())

    def __len__(self) -> int:
        return len(self._blocks)

    def __repr__(self) -> str:
        return repr(self._dict())


@dataclass(slots=True)
class StepResult:
    """Outcome of one tick.

    Attributes:
        q: configuration after the tick (nq,), read-only.
        v: velocity applied during the tick (nv,), read-only.
        tick: tick counter (1 for the first step after ``reset``).
        t: controller time after the tick [s].
        status: ``"ok"``, ``"relaxed"`` (a hard constraint gave, see ``relaxed``) or ``"held"``
            (no usable solution: the robot holds its configuration).
        solver_status: status text of the solver.
        task_errors: task name -> error norm at the start of the tick against this tick's target
            (position tasks in [m], orientation-only tasks in [rad]; see each task's error_norm).
        solve_time: time spent in the QP solver(s) [s].
        build_time: time spent building the QP (kinematics excluded) [s].
        step_time: whole ``step`` call [s].
        iterations: solver iterations.
        relaxed: constraint name -> amount it gave (in its own units).
        messages: what a person should know about this tick (missing targets, fallbacks).
        tau: joint torques (nv,) at acceleration level, else ``None``.
    """

    q: np.ndarray
    v: np.ndarray
    tick: int
    t: float
    status: str
    solver_status: str
    task_errors: Mapping[str, float]
    solve_time: float
    build_time: float
    step_time: float
    iterations: int = 0
    relaxed: dict[str, float] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    tau: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        """``True`` when the tick solved without relaxing anything."""
        return self.status == "ok"


def _section(spec: Any, path: str, default_type: str | None = None) -> tuple[str, dict[str, Any]]:
    if spec is None:
        spec = {}
    if isinstance(spec, str):
        spec = {"type": spec}
    if not isinstance(spec, Mapping):
        raise ConfigError(f"expected a mapping with a `type:` key, got {spec!r}.", path=path)
    spec = dict(spec)
    type_name = spec.pop("type", default_type)
    if type_name is None:
        raise ConfigError("missing `type:`.", path=path)
    return type_name, spec


class Controller:
    """A QP whole-body controller built from a configuration mapping (the YAML's content).

    Args:
        config: the controller description (see ``docs/yaml.md``).
        base_dir: directory relative paths in ``config`` are resolved against.

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
        cfg = self.config
        for key in cfg:
            if key not in TOP_LEVEL_KEYS:
                raise ConfigError(
                    f"unknown key {key!r}.{close_matches_hint(key, TOP_LEVEL_KEYS)} "
                    f"Top-level keys: {', '.join(TOP_LEVEL_KEYS)}.",
                    path=key,
                )
        if "robot" not in cfg:
            raise ConfigError(
                "missing `robot:` (a bundled name such as g1, or {urdf: PATH}).", path="robot"
            )
        robot_spec = cfg["robot"]
        if isinstance(robot_spec, Mapping):
            robot_spec = dict(robot_spec)
            for k in ("urdf", "srdf"):
                value = robot_spec.get(k)
                if value is not None and not str(value).startswith(ERD_PREFIX):
                    robot_spec[k] = str((self.base_dir / str(value)).resolve())
        self.robot: RobotModel = load_robot(robot_spec, path="robot")
        dt = cfg.get("dt", 0.01)
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1:
            raise ConfigError(f"dt must be a number of seconds in (0, 1), got {dt!r}.", path="dt")
        self.dt = float(dt)
        self.level = cfg.get("level", "velocity")
        if self.level not in ("velocity", "acceleration"):
            raise ConfigError(
                f"level must be 'velocity' or 'acceleration', got {self.level!r}.", path="level"
            )

        # Tasks.
        tasks_spec = cfg.get("tasks") or []
        if not isinstance(tasks_spec, Sequence) or isinstance(tasks_spec, str):
            raise ConfigError("tasks must be a list of mappings with a `type:`.", path="tasks")
        self.tasks: dict[str, Task] = {}
        for i, spec in enumerate(tasks_spec):
            path = f"tasks[{i}]"
            type_name, kwargs = _section(spec, path)
            cls = TASKS.lookup(type_name, path=f"{path}.type")
            kwargs.setdefault(
                "name",
                kwargs.get("frame", type_name) if type_name != "frame" else kwargs.get("name"),
            )
            task = build_from_spec(cls, kwargs, path=path)
            if task.name in self.tasks:
                raise ConfigError(
                    f"two tasks are named {task.name!r}; names must be unique.", path=f"{path}.name"
                )
            task.bind(self.robot, path=path)
            task.yaml_path = path  # type: ignore[attr-defined]
            self.tasks[task.name] = task
        if not self.tasks:
            raise ConfigError("no task: list at least one under `tasks:`.", path="tasks")
        m = sum(t.dim for t in self.tasks.values())
        self._J_all = np.zeros((m, self.robot.nv))
        self._v_all = np.zeros(m)
        i = 0
        for t in self.tasks.values():
            t.attach_buffers(self._J_all[i : i + t.dim], self._v_all[i : i + t.dim])
            i += t.dim

        # Constraints.
        cons_spec = cfg.get("constraints") or []
        if not isinstance(cons_spec, Sequence) or isinstance(cons_spec, str):
            raise ConfigError(
                "constraints must be a list of mappings with a `type:`.", path="constraints"
            )
        self.constraints: list[Constraint] = []
        for i, spec in enumerate(cons_spec):
            path = f"constraints[{i}]"
            type_name, kwargs = _section(spec, path)
            cls = CONSTRAINTS.lookup(type_name, path=f"{path}.type")
            con = build_from_spec(cls, kwargs, path=path)
            con.bind(self.robot, path=path)
            con.yaml_path = path  # type: ignore[attr-defined]
            if any(c.name == con.name for c in self.constraints):
                raise ConfigError(
                    f"two constraints are named {con.name!r}; give one a `name:`.", path=path
                )
            self.constraints.append(con)
        self._row_constraints = [c for c in self.constraints if c.n_rows > 0]
        self.n_rows = sum(c.n_rows for c in self._row_constraints)
        # Bounds are merged from most to least important (a less important bound gives).
        self._bound_constraints = sorted(self.constraints, key=lambda c: -c.importance)

        # Regularization, solver, strategy.
        rtype, rkwargs = _section(cfg.get("regularization"), "regularization", "identity")
        self.regularization: Regularization = build_from_spec(
            REGULARIZATIONS.lookup(rtype, path="regularization.type"),
            rkwargs,
            path="regularization",
        )
        self.regularization.bind(self.robot, self)
        solver_spec = cfg.get("solver", {"name": "proxsuite"})
        make_solver(solver_spec, path="solver")  # validate now, not at the first tick
        self.solver_spec = solver_spec
        stype, skwargs = _section(cfg.get("strategy"), "strategy", "augmentation")
        self.strategy: Strategy = build_from_spec(
            STRATEGIES.lookup(stype, path="strategy.type"), skwargs, path="strategy"
        )
        self.strategy.bind(
            self.robot,
            [(t.name, t.dim, t.level) for t in self.tasks.values()],
            self.n_rows,
            lambda: make_solver(self.solver_spec, path="solver"),
        )
        self._C = np.zeros((self.n_rows, self.robot.nv))
        self._l = np.full(self.n_rows, -np.inf)
        self._u = np.full(self.n_rows, np.inf)
        self._lb = np.empty(self.robot.nv)
        self._ub = np.empty(self.robot.nv)
        self.state = RobotState(self.robot)
        #: Called with each StepResult (live viewers, loggers): see :meth:`add_observer`.
        self._observers: list[Any] = []
        #: Seconds spent in each stage of the last tick (read by ``qpretarget bench``).
        self.last_timings: dict[str, float] = {}
        self.tick = 0
        self.t = 0.0
        self.v = np.zeros(self.robot.nv)
        self.fallback = None  # set by modules that provide a relaxation (see constraints)
        self._init_fallback()
        # Acceleration level (CRAC eq. 30-42) lives in its own module and takes over step().
        self._level_impl: Any = None
        if self.level == "acceleration":
            from .acceleration import AccelerationLevel

            self._level_impl = AccelerationLevel(self, self.config.get("acceleration"))
        elif self.config.get("acceleration") is not None:
            raise ConfigError(
                "an `acceleration:` section needs `level: acceleration`.", path="acceleration"
            )
        self.reset()

    def _init_fallback(self) -> None:
        """Install the relaxation fallback if the relaxation module is available."""
        try:
            from .relaxation import make_fallback  # type: ignore[attr-defined]
        except ImportError:
            return
        self.fallback = make_fallback(self, self.config.get("fallback"))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_yaml(cls, path: str | Path) -> Controller:
        """Build a controller from a YAML file; relative paths resolve against its folder.

        Raises:
            ConfigError: on a missing file, YAML syntax errors (with line) or invalid content.
        """
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file {str(path)!r} does not exist.")
        try:
            with open(path, encoding="utf-8") as f:
                cfg = load_yaml(f)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
            raise ConfigError(
                f"{path}: invalid YAML{where}: {getattr(exc, 'problem', exc)}"
            ) from None
        if not isinstance(cfg, Mapping):
            raise ConfigError(f"{path}: the file must hold a mapping (robot:, tasks:, ...).")
        try:
            ctrl = cls(cfg, base_dir=path.parent)
        except ConfigError as exc:
            raise ConfigError(f"{path.name}: {exc}") from None
        ctrl.config_path = path  # type: ignore[attr-defined]
        ctrl.config_text = path.read_text(encoding="utf-8")  # type: ignore[attr-defined]
        return ctrl

    @property
    def config_yaml(self) -> str:
        """The controller's YAML text (the file's text when built from a file)."""
        text = getattr(self, "config_text", None)
        return text if text is not None else yaml.safe_dump(self.config, sort_keys=False)

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
        fb_solver = getattr(self.fallback, "solver", None)
        if fb_solver is not None:  # runs from reset() must be reproducible to the last bit
            fb_solver.reset()
        if self._level_impl is not None:
            self._level_impl.reset()
        out = q.copy()
        out.setflags(write=False)
        return out

    @property
    def level_impl(self) -> Any:
        """The acceleration-level implementation (``None`` at velocity level)."""
        return self._level_impl

    @property
    def q(self) -> np.ndarray:
        """Current configuration (read-only view)."""
        q = self.state.q.view()
        q.setflags(write=False)
        return q

    def add_observer(self, fn: Any) -> None:
        """Call ``fn(step_result)`` after every tick (e.g. a live viewer's publisher).

        Observers must be quick: the viewer's :class:`~qpretarget.viz.viewer.LivePublisher`
        only stores the latest result and sends it from its own thread. An observer that raises
        is removed and reported in the next result's messages; it never stops the loop.
        """
        if not callable(fn):
            raise TypeError(f"an observer must be callable, got {type(fn).__name__}")
        self._observers.append(fn)

    def remove_observer(self, fn: Any) -> None:
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
        """Switch the supporting feet (delegated to the ``contacts`` constraint module)."""
        for c in self.constraints:
            if hasattr(c, "set_contacts"):
                c.set_contacts(feet, self.state)
                for other in self.constraints:
                    if other is not c and hasattr(other, "on_contacts_changed"):
                        other.on_contacts_changed(c, self.state)
                return
        raise ConfigError(
            "set_contacts needs a `contacts` constraint in the config.", path="constraints"
        )

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
        blocks = [t.block(state, dt) for t in self.tasks.values()]
        t1 = perf()
        timings["tasks"] = t1 - t0
        lb, ub = self._lb, self._ub
        lb.fill(-np.inf)
        ub.fill(np.inf)
        self._bound_gave: dict[str, float] = {}
        first = True
        for con in self._bound_constraints:
            b = con.compute_bounds(state, dt)
            if b is None:
                continue
            clo, chi = b
            if first:  # the most important bounds go in as they are
                np.copyto(lb, clo)
                np.copyto(ub, chi)
                first = False
                continue
            new_lb = np.maximum(lb, clo)
            new_ub = np.minimum(ub, chi)
            bad = new_lb > new_ub
            if bad.any():
                # This (less important) bound conflicts with the ones already in: it gives.
                gave = float(np.max(np.maximum(new_lb - ub, lb - new_ub)[bad]))
                self._bound_gave[con.name] = gave
                new_lb[bad] = np.clip(clo[bad], lb[bad], ub[bad])
                new_ub[bad] = np.clip(chi[bad], lb[bad], ub[bad])
                new_lb[bad] = np.minimum(new_lb[bad], new_ub[bad])
            lb[...] = new_lb
            ub[...] = new_ub
        t2 = perf()
        timings["bounds"] = t2 - t1
        i = 0
        for con in self._row_constraints:
            tc = perf()
            blk = con.compute_rows(state, dt)
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
        t3 = perf()
        W = self.regularization.matrix(state, dt)
        timings["regularization"] = perf() - t3
        return TickProblem(
            state,
            dt,
            blocks,
            self._C,
            self._l,
            self._u,
            lb,
            ub,
            W,
            self.regularization.damping,
            self.tick,
            self._J_all,
            self._v_all,
        )

    def step(
        self, targets: Mapping[str, Any] | None = None, *, dt: float | None = None
    ) -> StepResult:
        """Run one control tick.

        Args:
            targets: task name -> target (3-vector, 3x3 rotation, 4x4 transform, SE3, ...). A task
                left out, or given ``None``, keeps its last target.
            dt: tick length [s] (default: the config's ``dt``).

        Returns:
            The :class:`StepResult` of the tick.

        Raises:
            TargetError: on an unknown task name or a target of the wrong shape/type (a
                programming error). NaN values are not errors: they are missing data.
        """
        if self._level_impl is not None:
            return self._level_impl.step(targets, dt=dt)  # notifies observers itself
        t0 = time.perf_counter()
        if dt is None:
            dt = self.dt
        elif isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1:
            raise TargetError(
                f"dt must be a number of seconds in (0, 1), got {dt!r}.", tick=self.tick + 1
            )
        self.tick += 1
        messages: list[str] = []
        self.set_targets(targets, messages)
        tb = time.perf_counter()
        tp = self.build_tick(dt)
        build_time = time.perf_counter() - tb
        status = "ok"
        relaxed = dict(self._bound_gave)
        ts = time.perf_counter()
        res = self.strategy.solve(tp)
        self.last_timings["assembly"] = time.perf_counter() - ts - res.solve_time
        self.last_timings["solve"] = res.solve_time
        v = res.x
        if v is not None and not res.success:
            v = None
        if v is None and self.fallback is not None:
            fb = self.fallback.solve(tp, res)
            if fb is not None and fb.x is not None and np.all(np.isfinite(fb.x)):
                v = fb.x
                relaxed.update(fb.relaxed)
                if fb.relaxed:
                    status = "relaxed"
                    messages.append(
                        f"tick {self.tick}: hard constraints conflicted ({res.status}); "
                        f"relaxed {fb.relaxed}."
                    )
                else:
                    messages.append(
                        f"tick {self.tick}: the QP solver reported {res.status}; the fallback "
                        "solved it without relaxing anything."
                    )
        if relaxed and status == "ok":
            status = "relaxed"
        if v is None or not np.all(np.isfinite(v)):
            messages.append(
                f"tick {self.tick}: no usable QP solution (solver status {res.status}); "
                "holding the "
                f"configuration (v = 0)."
            )
            v = np.zeros(self.robot.nv)
            status = "held"
        else:
            # Solvers meet bounds to their tolerance; the box is cheap to meet exactly.
            np.clip(v, tp.lb, tp.ub, out=v)
        state = self.state
        errors = TaskErrors(tp.blocks, self.tasks)
        q_next = self.robot.integrate(state.q, v, dt)
        for con in self.constraints:
            con.after_step(state, v, dt)
        self.v = v
        tk = time.perf_counter()
        state.update(q_next, v)
        self.last_timings["kinematics"] = time.perf_counter() - tk
        self.t += dt
        q_out = q_next.copy()
        q_out.setflags(write=False)
        v_out = v.copy()
        v_out.setflags(write=False)
        result = StepResult(
            q=q_out,
            v=v_out,
            tick=self.tick,
            t=self.t,
            status=status,
            solver_status=res.status,
            task_errors=errors,
            solve_time=res.solve_time,
            build_time=build_time,
            step_time=time.perf_counter() - t0,
            iterations=res.iterations,
            relaxed=relaxed,
            messages=messages,
        )
        if self._observers:
            self._notify(result)
        return result

    def __repr__(self) -> str:
        return (
            f"Controller(robot={self.robot.name!r}, dt={self.dt}, level={self.level!r}, "
            f"strategy={self.strategy!r}, tasks={list(self.tasks)}, "
            f"constraints={[c.name for c in self.constraints]})"
        )
