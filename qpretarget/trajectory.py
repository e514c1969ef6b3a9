# SPDX-License-Identifier: Apache-2.0
"""RobotTrajectory: a retargeted run, saved as a documented, stable ``.npz`` (docs/formats.md).

Keys (T ticks, nq/nv the robot's dimensions, F feet):

========================  ==============  =====================================================
key                       shape           meaning
========================  ==============  =====================================================
``format``                ()              ``"qpretarget.run/1"``
``t``                     (T,)            time of each sample [s]
``q``                     (T, nq)         configuration (pinocchio order, free-flyer first)
``v``                     (T, nv)         velocity applied during the tick that ended at ``t``
``joint_names``           (n_joints,)     one-DoF joint names, in ``q[7:]`` order
``robot``                 ()              registry name (``g1``) or URDF path
``config_yaml``           ()              the controller's YAML text
``task_names``            (n_tasks,)      tasks with a 3-D position target
``target/<task>``         (T, 3)          world target position of the task
``actual/<task>``         (T, 3)          world position reached (after the tick)
``contacts``              (T, F)          supporting feet (bool), columns named ``foot_names``
``foot_names``            (F,)            foot names
``status``                (T,)            ``ok`` / ``relaxed`` / ``held``
``solve_time``            (T,)            QP solve time [s]
``tau``                   (T, nv)         torques [N m] (acceleration level only)
``human/<...>``           any             the human motion it came from (optional)
``meta``                  ()              JSON text: source motion, rates, versions
========================  ==============  =====================================================

Readers should ignore keys they do not know: new keys may be added, none of the above changes
meaning within format version 1.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import QPRetargetError
from .fileio import atomic_path, load_npz
from .yamlio import load_yaml

FORMAT = "qpretarget.run/1"


class TrajectoryFormatError(QPRetargetError, ValueError):
    """A run file is not a qpretarget run or misses a required key."""


@dataclass
class RobotTrajectory:
    """A robot joint trajectory with what produced it (see the module docstring for the keys)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    joint_names: list[str]
    robot: str
    config_yaml: str
    task_names: list[str] = field(default_factory=list)
    targets: dict[str, np.ndarray] = field(default_factory=dict)
    actual: dict[str, np.ndarray] = field(default_factory=dict)
    contacts: np.ndarray | None = None
    foot_names: list[str] = field(default_factory=list)
    status: np.ndarray | None = None
    solve_time: np.ndarray | None = None
    tau: np.ndarray | None = None
    human: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def samples(self, start: int, stop: int) -> RobotTrajectory:
        """The run's samples ``start:stop`` (every per-sample array cut; ``human`` whole).

        ``targets``, ``actual`` and ``extra`` arrays are cut when their first axis has one
        entry per sample; the person's motion keeps its own time base (``human/t``).
        """
        T = len(self.t)

        def cut(x: Any) -> Any:
            return x[start:stop] if isinstance(x, np.ndarray) and x.ndim and len(x) == T else x

        return dataclasses.replace(
            self,
            t=self.t[start:stop], q=cut(np.asarray(self.q)), v=cut(np.asarray(self.v)),
            contacts=cut(self.contacts), status=cut(self.status), solve_time=cut(self.solve_time),
            tau=cut(self.tau), targets={k: cut(v) for k, v in self.targets.items()},
            actual={k: cut(v) for k, v in self.actual.items()},
            extra={k: cut(v) for k, v in self.extra.items()},
        )  # fmt: skip

    def __len__(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        """Median sample period [s]."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0

    def save(self, path: str | Path) -> Path:
        """Write the ``.npz`` file (compressed, atomically) and return its path."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        T = len(self.t)
        arrays: dict[str, Any] = {
            "format": np.array(FORMAT),
            "t": np.asarray(self.t, float),
            "q": np.asarray(self.q, float),
            "v": np.asarray(self.v, float),
            "joint_names": np.array(self.joint_names, dtype=str),
            "robot": np.array(self.robot),
            "config_yaml": np.array(self.config_yaml),
            "task_names": np.array(self.task_names, dtype=str),
            "foot_names": np.array(self.foot_names, dtype=str),
            "contacts": np.zeros((T, 0), bool)
            if self.contacts is None
            else np.asarray(self.contacts, bool),
            "status": np.array(["ok"] * T)
            if self.status is None
            else np.asarray(self.status, dtype=str),
            "solve_time": np.zeros(T)
            if self.solve_time is None
            else np.asarray(self.solve_time, float),
            "meta": np.array(json.dumps(self.meta, default=str)),
        }
        for k, a in self.targets.items():
            arrays[f"target/{k}"] = np.asarray(a, float)
        for k, a in self.actual.items():
            arrays[f"actual/{k}"] = np.asarray(a, float)
        for k, a in self.human.items():
            arrays[f"human/{k}"] = np.asarray(a)
        for k, a in self.extra.items():
            arrays[k] = np.asarray(a)
        if self.tau is not None:
            arrays["tau"] = np.asarray(self.tau, float)
        with atomic_path(path, suffix=".npz") as tmp:  # no half-written run file
            np.savez_compressed(tmp, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> RobotTrajectory:
        """Read a run file.

        Raises:
            TrajectoryFormatError: if the file is missing, not an ``.npz`` or lacks a key.
        """
        path = Path(path)
        if not path.is_file():
            raise TrajectoryFormatError(f"run file {str(path)!r} does not exist.")
        with load_npz(path, TrajectoryFormatError) as data:
            keys = set(data.files)
            for k in ("t", "q", "v", "joint_names", "robot", "config_yaml"):
                if k not in keys:
                    raise TrajectoryFormatError(
                        f"{path}: missing key {k!r}; is this a qpretarget run (format {FORMAT})?"
                    )
            known = {"format", "t", "q", "v", "joint_names", "robot", "config_yaml", "task_names",
                     "foot_names", "contacts", "status", "solve_time", "meta", "tau"}  # fmt: skip
            traj = cls(
                t=data["t"],
                q=data["q"],
                v=data["v"],
                joint_names=[str(x) for x in data["joint_names"]],
                robot=str(data["robot"]),
                config_yaml=str(data["config_yaml"]),
                task_names=[str(x) for x in data["task_names"]] if "task_names" in keys else [],
                targets={k[7:]: data[k] for k in keys if k.startswith("target/")},
                actual={k[7:]: data[k] for k in keys if k.startswith("actual/")},
                contacts=data["contacts"] if "contacts" in keys else None,
                foot_names=[str(x) for x in data["foot_names"]] if "foot_names" in keys else [],
                status=data["status"] if "status" in keys else None,
                solve_time=data["solve_time"] if "solve_time" in keys else None,
                tau=data["tau"] if "tau" in keys else None,
                human={k[6:]: data[k] for k in keys if k.startswith("human/")},
                extra={
                    k: data[k]
                    for k in keys
                    if k not in known and not k.startswith(("target/", "actual/", "human/"))
                },
                meta=json.loads(str(data["meta"])) if "meta" in keys else {},
            )
        return traj

    def make_controller(self):  # noqa: ANN201
        """Rebuild the controller that produced this run from its stored YAML."""
        from .control.controller import Controller

        return Controller(load_yaml(self.config_yaml))
