# SPDX-License-Identifier: Apache-2.0
r"""Run the same motion with several QP solvers and compare them (``qpretarget compare-solvers``).

Each solver drives its own controller, built from the same YAML with only ``solver:`` replaced,
over the same targets, in closed loop. Per solver the comparison reports the median and p95 solve
time per tick, the iterations, the largest constraint violation of any QP it returned
(:meth:`QPProblem.constraint_violation` of each tick's problem at the returned solution), the
tracking RMSE and its difference to the reference solver, the largest joint deviation from the
reference solver's trajectory, and the failures. Solvers that are not installed are listed as
such.

The motion is one of (see :func:`load_targets`):

* ``scripted`` (or ``scripted:SECONDS``): :func:`scripted_targets`, smooth sinusoidal hand,
  elbow and pelvis targets around the reference posture, for any config;
* a run file ``RUN.npz`` (:class:`~qpretarget.trajectory.RobotTrajectory`): its
  ``target/<task>`` arrays are replayed as the targets of the tasks of the same name;
* a mocap file (BVH, ASF/AMC, C3D) once the motion pipeline provides a retargeter.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..constraints.contacts import Contacts
from ..control.controller import Controller
from ..errors import ConfigError, QPRetargetError
from ..fileio import write_atomic
from ..tasks.frame import FrameTask
from ..trajectory import RobotTrajectory
from ..yamlio import load_yaml
from .metrics import rmse

#: Solvers compared when none are named: the native ProxSuite path, then every installed
#: qpsolvers backend.
DEFAULT_REFERENCE = "proxsuite"

#: File suffixes read as human motion capture.
MOCAP_SUFFIXES = (".bvh", ".amc", ".c3d")


class ComparisonError(QPRetargetError, ValueError):
    """The motion given to a solver comparison cannot be used."""


# ---------------------------------------------------------------------------------- targets
def _side(name: str) -> float:
    """+1 for a left task, -1 for a right one, 0 otherwise (the robot's y axis points left)."""
    n = name.lower()
    if n.startswith(("left", "l_")) or "_left" in n:
        return 1.0
    if n.startswith(("right", "r_")) or "_right" in n:
        return -1.0
    return 0.0


def scripted_targets(
    controller: Controller,
    seconds: float,
    *,
    dt: float | None = None,
    amplitude: float = 1.0,
    frequency: float = 0.5,
) -> Iterator[dict[str, Any]]:
    r"""Smooth sinusoidal targets around the controller's reference posture.

    Hand (and wrist) tasks move their point by up to (0.15, 0.10, 0.15) m forward, inwards and
    up, elbows by a third of that, the left side half a period ahead of the right; pose tasks on
    the pelvis sway by 2 cm sideways and dip by up to 3 cm, keeping their orientation. Other tasks
    keep their reference targets. The amplitude ramps in over the first second (a
    :math:`\sin^2` envelope) so the motion starts at rest.

    Args:
        controller: the controller; it is reset to its reference posture to read the targets.
        seconds: duration [s].
        dt: tick length [s] (default: the controller's).
        amplitude: scale of every displacement.
        frequency: frequency of the motion [Hz].

    Yields:
        One mapping task name -> target per tick (3-vectors, or ``pinocchio.SE3`` for pose tasks).
    """
    dt = controller.dt if dt is None else float(dt)
    controller.reset()
    base: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for name, task in controller.tasks.items():
        if not (isinstance(task, FrameTask) and task.has_position):
            continue
        p, R = task.current_pose(controller.state)
        lname = (name + " " + str(getattr(task, "frame", ""))).lower()
        if "pelvis" in lname and task.has_orientation:
            kind = "pelvis"
        elif "hand" in lname or "wrist" in lname:
            kind = "hand"
        elif "elbow" in lname:
            kind = "elbow"
        else:
            continue
        base[name] = (kind, p.copy(), R.copy())
    n = max(1, int(round(seconds / dt)))
    w = 2.0 * math.pi * frequency
    for k in range(1, n + 1):
        t = k * dt
        env = amplitude * (math.sin(0.5 * math.pi * min(t, 1.0)) ** 2)
        out: dict[str, Any] = {}
        for name, (kind, p, R) in base.items():
            side = _side(name)
            phase = 0.0 if side >= 0 else math.pi
            s, c = math.sin(w * t + phase), math.cos(w * t + phase)
            if kind == "pelvis":
                d = np.array([0.0, 0.02 * math.sin(w * t), -0.015 * (1.0 - math.cos(2 * w * t))])
                out[name] = pin.SE3(R, p + env * d)
                continue
            scale = 1.0 if kind == "hand" else 1.0 / 3.0
            d = scale * np.array([0.15 * s, -side * 0.10 * (1.0 - c) / 2.0, 0.15 * (1.0 - c) / 2.0])
            out[name] = p + env * d
        yield out


def targets_from_run(traj: RobotTrajectory, controller: Controller) -> list[dict[str, np.ndarray]]:
    """Targets of a saved run, one mapping per tick, for the controller's tasks of the same name.

    Sample 0 of a run is the state before the first tick; samples 1..T-1 each end a tick, whose
    targets are replayed.

    Raises:
        ComparisonError: when the run has no ``target/<task>`` the controller knows.
    """
    names = [k for k in traj.targets if k in controller.tasks]
    if not names:
        raise ComparisonError(
            f"the run has targets for {sorted(traj.targets) or 'no task'} but the config's tasks "
            f"are {sorted(controller.tasks)}: none match. Use a run made with this config."
        )
    T = len(traj.t)
    return [{k: np.asarray(traj.targets[k][i], float) for k in names} for i in range(1, T)]


@dataclass
class Motion:
    """A motion for a comparison, with where it came from.

    Attributes:
        kind: ``scripted``, ``run`` or ``mocap``.
        source: text naming the source.
        run: ``run(controller) -> RobotTrajectory``: the controller (reset first) over the motion.
        initial_sample: the trajectory's sample 0 is the state before the first tick (not a tick).
    """

    kind: str
    source: str
    run: Callable[[Controller], RobotTrajectory]
    initial_sample: bool = True


def load_targets(motion: str | Path, *, seconds: float | None = None) -> Motion:
    """Parse the MOTION argument of ``compare-solvers`` (see the module docstring).

    Raises:
        ComparisonError: on a missing file or an unsupported kind, saying what is accepted.
    """
    text = str(motion)
    if text == "scripted" or text.startswith("scripted:"):
        dur = seconds
        if text.startswith("scripted:"):
            try:
                dur = float(text.split(":", 1)[1])
            except ValueError:
                raise ComparisonError(
                    f"{text!r}: write scripted:SECONDS, e.g. scripted:2 for two seconds."
                ) from None
        dur = 2.0 if dur is None else dur
        if not dur > 0:
            raise ComparisonError(f"the scripted motion needs a positive duration, got {dur}.")
        return Motion(
            "scripted",
            f"scripted targets ({dur:g} s)",
            lambda c: record_run(c, list(scripted_targets(c, dur))),
        )
    path = Path(text)
    if not path.is_file():
        raise ComparisonError(
            f"motion {text!r} is not a file. Give a run file (RUN.npz), a mocap file "
            f"({', '.join(MOCAP_SUFFIXES)}) or 'scripted[:SECONDS]'."
        )
    if path.suffix == ".npz":
        traj = RobotTrajectory.load(path)
        if seconds is not None:
            keep = traj.t - traj.t[0] <= seconds + 1e-9
            traj.t = traj.t[keep]
            traj.targets = {k: v[keep] for k, v in traj.targets.items()}
        return Motion(
            "run",
            f"targets of {path}",
            lambda c: record_run(c, targets_from_run(traj, c), dt=traj.dt or None),
        )
    if path.suffix.lower() in MOCAP_SUFFIXES:
        return _mocap_motion(path, seconds)
    raise ComparisonError(
        f"{path.name}: unknown motion file type {path.suffix!r}. Give a run file (.npz), a mocap "
        f"file ({', '.join(MOCAP_SUFFIXES)}) or 'scripted[:SECONDS]'."
    )


def _mocap_motion(path: Path, seconds: float | None) -> Motion:
    """A mocap clip, retargeted for each solver by the config's ``retarget:`` section."""
    from ..motion import load_motion
    from ..retarget.retargeter import Retargeter

    human = load_motion(path)

    def run(controller: Controller) -> RobotTrajectory:
        controller.reset()
        return Retargeter(controller).retarget(human, end=seconds)

    span = f", first {seconds:g} s" if seconds is not None else ""
    return Motion("mocap", f"{path.name}{span}", run, initial_sample=False)


# ---------------------------------------------------------------------------------- recording
def record_run(
    controller: Controller,
    targets: Sequence[Mapping[str, Any]] | Iterator[Mapping[str, Any]],
    *,
    dt: float | None = None,
    meta: Mapping[str, Any] | None = None,
    on_step: Any = None,
) -> RobotTrajectory:
    """Reset the controller, run it over ``targets`` (one mapping per tick) and record the run.

    ``target/<task>`` holds each position task's target of the tick and ``actual/<task>`` the
    position reached after it (forward kinematics of the new configuration).

    Args:
        controller: the controller.
        targets: one target mapping per tick.
        dt: tick length [s] (default: the controller's).
        meta: extra metadata stored in the run.
        on_step: ``on_step(result)`` called after every tick (e.g. to record solver details).

    Returns:
        The run, sample 0 being the reference posture before the first tick.
    """
    controller.reset()
    dt = controller.dt if dt is None else float(dt)
    recorder = _RunRecorder(controller)
    for target in targets:
        res = controller.step(target, dt=dt)
        if on_step is not None:
            on_step(res)
        recorder.add(res)
    return recorder.trajectory(meta)


class _RunRecorder:
    """Samples of a run, the first being the state before the first tick (:func:`record_run`)."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self.frame_tasks = {
            n: t for n, t in controller.tasks.items() if isinstance(t, FrameTask) and t.has_position
        }
        self.qs = [controller.q.copy()]
        self.vs = [np.zeros(controller.robot.nv)]
        self.ts = [0.0]
        self.statuses = ["ok"]
        self.solve = [0.0]
        self.taus: list[np.ndarray] = []
        self.tgt = {n: [t.position_target.copy()] for n, t in self.frame_tasks.items()}
        self.act = {
            n: [t.current_pose(controller.state)[0].copy()] for n, t in self.frame_tasks.items()
        }
        self.contact = next((c for c in controller.constraints if isinstance(c, Contacts)), None)
        self.feet = list(self.contact.names) if self.contact is not None else []
        self.contacts = [self._active()]

    def _active(self) -> list[bool]:
        """Per foot of the ``contacts`` constraint, whether it supports now."""
        on = set(self.contact.active_feet) if self.contact is not None else set()
        return [f in on for f in self.feet]

    def add(self, res: Any) -> None:
        """Record the result of one tick and the task targets and positions after it."""
        self.qs.append(np.array(res.q))
        self.vs.append(np.array(res.v))
        self.ts.append(res.t)
        self.statuses.append(res.status)
        self.solve.append(res.solve_time)
        if res.tau is not None:
            self.taus.append(np.array(res.tau))
        self.contacts.append(self._active())
        state = self.controller.state
        for n, task in self.frame_tasks.items():
            self.tgt[n].append(task.position_target.copy())
            self.act[n].append(task.current_pose(state)[0].copy())

    def trajectory(self, meta: Mapping[str, Any] | None) -> RobotTrajectory:
        """The recorded run (torques only when every tick gave them)."""
        controller, qs, taus = self.controller, self.qs, self.taus
        tau = None
        if taus and len(taus) == len(qs) - 1:
            tau = np.vstack([taus[0], *taus])  # sample 0 repeats the first tick's torques
        return RobotTrajectory(
            t=np.asarray(self.ts),
            q=np.asarray(qs),
            v=np.asarray(self.vs),
            joint_names=list(controller.robot.joint_names),
            robot=controller.robot.name,
            config_yaml=controller.config_yaml,
            task_names=list(self.frame_tasks),
            targets={n: np.asarray(v) for n, v in self.tgt.items()},
            actual={n: np.asarray(v) for n, v in self.act.items()},
            contacts=np.asarray(self.contacts, bool).reshape(len(qs), len(self.feet)),
            foot_names=self.feet,
            status=np.asarray(self.statuses),
            solve_time=np.asarray(self.solve),
            tau=tau,
            meta={
                "config_name": controller.config.get("name", ""),
                "root_nq": controller.robot.root_nq,
                **dict(meta or {}),
            },
        )


# ---------------------------------------------------------------------------------- comparison
@dataclass
class SolverRow:
    """One solver's line of the comparison table (times in [ms], distances in [mm])."""

    solver: str
    status: str
    ticks: int | None = None
    qp_solves: int | None = None
    failures: int | None = None
    held_ticks: int | None = None
    median_solve_ms: float | None = None
    p95_solve_ms: float | None = None
    max_solve_ms: float | None = None
    median_iterations: float | None = None  # per QP solve
    max_violation: float | None = None
    tracking_rmse_mm: float | None = None
    rmse_diff_mm: float | None = None
    max_joint_dev_rad: float | None = None
    wall_time_s: float | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    note: str = ""


@dataclass
class Comparison:
    """Result of :func:`compare_solvers`."""

    config: str
    motion: str
    reference: str | None
    rows: list[SolverRow]
    machine: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        return {
            "config": self.config,
            "motion": self.motion,
            "reference": self.reference,
            "machine": self.machine,
            "rows": [asdict(r) for r in self.rows],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, allow_nan=False)

    COLUMNS = (
        ("solver", "solver", "{}"),
        ("status", "status", "{}"),
        ("ticks", "ticks", "{}"),
        ("failures", "failures", "{}"),
        ("median_solve_ms", "median solve [ms]", "{:.3f}"),
        ("p95_solve_ms", "p95 solve [ms]", "{:.3f}"),
        ("median_iterations", "iterations per QP (median)", "{:g}"),
        ("max_violation", "max violation", "{:.1e}"),
        ("tracking_rmse_mm", "tracking RMSE [mm]", "{:.3f}"),
        ("rmse_diff_mm", "RMSE diff to ref [mm]", "{:.2e}"),
        ("max_joint_dev_rad", "max joint dev to ref [rad]", "{:.1e}"),
    )

    def table_rows(self) -> list[list[str]]:
        out = []
        for r in self.rows:
            line = []
            for key, _, fmt in self.COLUMNS:
                v = getattr(r, key)
                line.append("-" if v is None else fmt.format(v))
            out.append(line)
        return out

    def to_markdown(self) -> str:
        head = [h for _, h, _ in self.COLUMNS]
        lines = [
            "| " + " | ".join(head) + " |",
            "|" + "|".join("---" if i < 2 else "---:" for i in range(len(head))) + "|",
        ]
        lines += ["| " + " | ".join(row) + " |" for row in self.table_rows()]
        return "\n".join(lines)

    def to_csv(self) -> str:
        buf = io.StringIO()
        keys = [f for f in SolverRow.__dataclass_fields__ if f != "settings"]
        w = csv.writer(buf)
        w.writerow(keys)
        for r in self.rows:
            w.writerow(["" if getattr(r, k) is None else getattr(r, k) for k in keys])
        return buf.getvalue()

    def to_text(self) -> str:
        head = [h for _, h, _ in self.COLUMNS]
        rows = self.table_rows()
        widths = [
            max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)
        ]
        fmt = "  ".join(f"{{:<{w}}}" if i < 2 else f"{{:>{w}}}" for i, w in enumerate(widths))
        lines = [fmt.format(*head)] + [fmt.format(*r) for r in rows]
        notes = [f"{r.solver}: {r.note}" for r in self.rows if r.note]
        return "\n".join(lines + ([""] + notes if notes else []))

    def save(self, out: str | Path) -> list[Path]:
        """Write ``comparison.{csv,json,md}`` into directory ``out``, or the one file ``out``."""
        out = Path(out)
        writers = {".csv": self.to_csv, ".json": self.to_json, ".md": self.markdown_report}

        def save(path: Path, text: str) -> Path:  # atomically: no half-written file
            return write_atomic(path, lambda f: f.write(text), binary=False)

        if out.suffix in writers:
            out.parent.mkdir(parents=True, exist_ok=True)
            return [save(out, writers[out.suffix]())]
        out.mkdir(parents=True, exist_ok=True)
        return [save(out / f"comparison{suffix}", w()) for suffix, w in writers.items()]

    def markdown_report(self) -> str:
        m = self.machine
        lines = [
            f"Config `{self.config}`, motion: {self.motion}; reference solver: {self.reference}.",
            f"Machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores (load average "
            f"{m.get('load_average', '?')} at the start), Python {m.get('python', '?')}, "
            f"{m.get('versions', '')}.",
            "",
            self.to_markdown(),
            "",
        ]
        notes = [f"- `{r.solver}`: {r.note}" for r in self.rows if r.note]
        settings = [f"- `{r.solver}`: {r.settings}" for r in self.rows if r.settings]
        if notes:
            lines += ["Notes:", *notes, ""]
        if settings:
            lines += ["Solver settings:", *settings, ""]
        return "\n".join(lines)


def _machine() -> dict[str, str]:
    from importlib import metadata

    versions = []
    for dist in ("proxsuite", "qpsolvers", "osqp", "quadprog", "daqp", "clarabel", "piqp", "pin"):
        try:
            versions.append(f"{dist} {metadata.version(dist)}")
        except metadata.PackageNotFoundError:
            continue
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover - not on every platform
        load = "?"
    return {
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "load_average": load,
        "python": platform.python_version(),
        "versions": ", ".join(versions),
    }


def available_solver_names() -> list[str]:
    """``proxsuite`` (native, warm-started) followed by every installed qpsolvers backend."""
    from ..solvers import installed_qpsolvers

    return [DEFAULT_REFERENCE, *installed_qpsolvers()]


def _solver_spec(name: str, config: Mapping[str, Any]) -> dict[str, Any]:
    """The config's own solver options when it names the same solver, else defaults."""
    spec = config.get("solver")
    if isinstance(spec, Mapping):
        cname = spec.get("name") or spec.get("type") or "proxsuite"
        if cname == name:
            return dict(spec)
    elif isinstance(spec, str) and spec == name:
        return {"name": name}
    return {"name": name}


@contextlib.contextmanager
def _quiet_c_stdout(active: bool) -> Iterator[None]:
    """Silence what C backends print on file descriptor 1 (OSQP's polishing notes).

    The table is printed afterwards; progress goes to stderr. Does nothing when stdout has no
    file descriptor (e.g. captured by a test runner without one).
    """
    if not active:
        yield
        return
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, io.UnsupportedOperation):
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), fd)
            try:
                yield
            finally:
                os.dup2(saved, fd)
    finally:
        os.close(saved)


def _run_one(
    name: str,
    config: Mapping[str, Any],
    base_dir: Path,
    motion: Motion,
) -> tuple[SolverRow, RobotTrajectory | None]:
    from ..solvers import installed_qpsolvers, known_qpsolvers

    if name != DEFAULT_REFERENCE and name not in installed_qpsolvers():
        if name in known_qpsolvers():
            return SolverRow(
                name, "not installed", note=f"install it with `pip install qpsolvers[{name}]`"
            ), None
        return SolverRow(name, "unknown", note="not a solver qpsolvers knows"), None
    cfg = dict(config)
    cfg["solver"] = _solver_spec(name, config)
    controller = Controller(cfg, base_dir=base_dir)
    controller.strategy.use_fused = False  # every QP through QPSolver.solve, recorded below
    solvers = controller.strategy.solvers()
    records: list[tuple[float, int, bool]] = []  # per QP solve: violation, iterations, success
    for s in solvers:
        original = s.solve

        def solve(problem: Any, _orig: Any = original) -> Any:
            sol = _orig(problem)
            viol = problem.constraint_violation(sol.x) if sol.x is not None else math.nan
            records.append((viol, sol.iterations, bool(sol.success)))
            return sol

        s.solve = solve  # type: ignore[method-assign]
    t0 = time.perf_counter()
    with _quiet_c_stdout(name != DEFAULT_REFERENCE):
        traj = motion.run(controller)
    wall = time.perf_counter() - t0
    first = 1 if motion.initial_sample else 0
    if traj.solve_time is None or traj.status is None:  # both recorded by every run above
        raise QPRetargetError(f"solver {name!r}: the run recorded no solve times or status")
    solve_ms = np.asarray(traj.solve_time[first:]) * 1e3
    status = np.asarray(traj.status[first:]).astype(str)
    viols = np.array([r[0] for r in records]) if records else np.zeros(0)
    iters = [r[1] for r in records]
    its = np.array(iters) if iters and min(iters) >= 0 else np.zeros(0)
    held = int(np.sum(status == "held"))
    failures = int(sum(1 for r in records if not r[2]))
    rmses = [rmse(v, traj.actual[n]) for n, v in traj.targets.items() if n in traj.actual]
    settings = solvers[0].settings_summary() if solvers else {}
    row = SolverRow(
        solver=name,
        status="ok" if failures == 0 and held == 0 else "failures",
        ticks=len(traj.t) - first,
        qp_solves=len(records),
        failures=failures,
        held_ticks=held,
        median_solve_ms=float(np.median(solve_ms)) if solve_ms.size else None,
        p95_solve_ms=float(np.percentile(solve_ms, 95)) if solve_ms.size else None,
        max_solve_ms=float(np.max(solve_ms)) if solve_ms.size else None,
        median_iterations=float(np.median(its)) if its.size else None,
        max_violation=float(np.nanmax(viols))
        if viols.size and np.any(np.isfinite(viols))
        else None,
        tracking_rmse_mm=1e3 * float(np.nanmean(rmses)) if rmses else None,
        wall_time_s=wall,
        settings={k: v for k, v in settings.items() if isinstance(v, (int, float, str, bool))},
    )
    return row, traj


def compare_solvers(
    config: str | Path | Mapping[str, Any],
    motion: str | Path | Motion,
    solvers: Sequence[str] | None = None,
    *,
    seconds: float | None = None,
    reference: str | None = None,
    progress: Any = None,
) -> Comparison:
    """Run ``motion`` with each solver and compare (see the module docstring).

    Args:
        config: controller YAML path or mapping.
        motion: see :func:`load_targets`, or a ready :class:`Motion`.
        solvers: solver names (default: :func:`available_solver_names`).
        seconds: keep only the first ``seconds`` of the motion.
        reference: solver the others are compared with (default: the first one that ran).
        progress: ``progress(text)`` called before each solver.

    Raises:
        ConfigError: on a bad config. ComparisonError: on a bad motion.
    """
    if isinstance(config, Mapping):
        cfg, base_dir, label = dict(config), Path.cwd(), str(config.get("name", "<mapping>"))
    else:
        path = Path(config)
        if not path.is_file():
            raise ConfigError(f"config file {str(path)!r} does not exist.")
        cfg = load_yaml(path.read_text(encoding="utf-8"))
        if not isinstance(cfg, Mapping):
            raise ConfigError(f"{path}: the file must hold a mapping (robot:, tasks:, ...).")
        base_dir, label = path.parent, str(path)
    Controller(cfg, base_dir=base_dir)  # validate the config once, before any long run
    mot = motion if isinstance(motion, Motion) else load_targets(motion, seconds=seconds)
    machine = _machine()  # before the runs: the load average of the machine as they start
    names = list(solvers) if solvers else available_solver_names()
    rows: list[SolverRow] = []
    trajs: dict[str, RobotTrajectory] = {}
    for name in names:
        if progress is not None:
            progress(f"running {name} ...")
        try:
            row, traj = _run_one(name, cfg, base_dir, mot)
        except QPRetargetError:
            raise
        except Exception as exc:  # noqa: BLE001 - a crashing backend is a result, not a crash
            row, traj = SolverRow(name, "error", note=f"{type(exc).__name__}: {exc}"), None
        rows.append(row)
        if traj is not None:
            trajs[name] = traj
    ref = reference if reference in trajs else next(iter(trajs), None)
    if ref is not None:
        rt = trajs[ref]
        ref_row = next(r for r in rows if r.solver == ref)
        for r in rows:
            tr = trajs.get(r.solver)
            if tr is None or len(tr.t) != len(rt.t):
                continue
            if r.tracking_rmse_mm is not None and ref_row.tracking_rmse_mm is not None:
                r.rmse_diff_mm = abs(r.tracking_rmse_mm - ref_row.tracking_rmse_mm)
            k = int(rt.meta.get("root_nq", 0))
            dq = tr.q[:, k:] - rt.q[:, k:]
            r.max_joint_dev_rad = float(np.max(np.abs(dq))) if dq.size else 0.0
    return Comparison(label, mot.source, ref, rows, machine)


__all__ = [
    "Comparison",
    "ComparisonError",
    "Motion",
    "SolverRow",
    "available_solver_names",
    "compare_solvers",
    "load_targets",
    "record_run",
    "scripted_targets",
    "targets_from_run",
]
