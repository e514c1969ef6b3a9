# SPDX-License-Identifier: Apache-2.0
"""What a retargeting run records every tick, and the :class:`RobotTrajectory` built from it."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any, cast

import numpy as np

from ..control.controller import Controller, StepResult
from ..trajectory import RobotTrajectory


class RunRecorder:
    """Per-tick records of one run (configurations, statuses, contacts, targets, scaled points).

    Args:
        controller: The controller of the run.
        contacts: Its ``contacts`` constraint (``None`` without one).
    """

    def __init__(self, controller: Controller, contacts: Any) -> None:
        self.controller = controller
        self.contacts = contacts
        self.rows: dict[str, list[Any]] = {
            k: []
            for k in ("t", "q", "v", "status", "solve_time", "tau", "contacts", "phase",
                      "support", "messages")
        }  # fmt: skip
        self.pos_tasks = [
            n for n, t in controller.tasks.items() if getattr(t, "has_position", False)
        ]
        self.targets: dict[str, list[np.ndarray]] = {n: [] for n in self.pos_tasks}
        self.actual: dict[str, list[np.ndarray]] = {n: [] for n in self.pos_tasks}
        self.scaled: dict[str, list[np.ndarray]] = {}
        self.extra: dict[str, list[Any]] = {}
        #: Constraint name -> ticks on which it gave (``StepResult.relaxed``), for the summary.
        self.relaxed_by: dict[str, int] = {}

    def __len__(self) -> int:
        """Ticks recorded."""
        return len(self.rows["t"])

    def add(
        self,
        t: float,
        res: StepResult,
        phase: str,
        support: str,
        scaled: Mapping[str, np.ndarray],
        rolled: Collection[str] = (),
    ) -> None:
        """Record one tick.

        ``rolled``: contacts on with the sole rolled onto its toes (kinematic *tiptoe*): their
        front edge is pinned, not the sole, so the ``contacts`` column records them as off
        (the column is the flat soles in contact, as a one-foot toe-off, whose contact is off).
        """
        r = self.rows
        ctrl = self.controller
        r["t"].append(t)
        r["q"].append(np.array(res.q))
        r["v"].append(np.array(res.v))
        r["status"].append(res.status)
        r["solve_time"].append(res.solve_time)
        r["tau"].append(None if res.tau is None else np.array(res.tau))
        r["phase"].append(phase)
        r["support"].append(support)
        if res.messages:
            r["messages"].extend(res.messages)
        for name in res.relaxed:
            self.relaxed_by[name] = self.relaxed_by.get(name, 0) + 1
        if self.contacts is not None:
            active = set(self.contacts.active_feet) - set(rolled)
            r["contacts"].append([n in active for n in self.contacts.names])
        for n in self.pos_tasks:
            task = cast(Any, ctrl.tasks[n])  # a task with a position (pos_tasks)
            self.targets[n].append(np.array(task.position_target, float))
            self.actual[n].append(task.current_pose(ctrl.state)[0].copy())
        for k, v in scaled.items():
            self.scaled.setdefault(k, []).append(np.asarray(v, float).copy())

    def trajectory(self, human: dict[str, np.ndarray], meta: dict[str, Any]) -> RobotTrajectory:
        """The records as a :class:`RobotTrajectory` (``human``: raw key-points and ``t``)."""
        r = self.rows
        ctrl = self.controller
        T = len(r["t"])
        taus = r["tau"]
        tau = np.array(taus) if all(x is not None for x in taus) else None
        extra: dict[str, np.ndarray] = {
            "human_phase": np.asarray(r["phase"], dtype=str),
            "support_state": np.asarray(r["support"], dtype=str),
        }
        for k, v in self.scaled.items():
            extra[f"scaled/{k}"] = np.asarray(v, float)
        for k, v in self.extra.items():
            extra[k] = np.asarray(v)
        return RobotTrajectory(
            t=np.asarray(r["t"], float),
            q=np.asarray(r["q"], float),
            v=np.asarray(r["v"], float),
            joint_names=list(ctrl.robot.joint_names),
            robot=ctrl.robot.name,
            config_yaml=ctrl.config_yaml,
            task_names=list(self.pos_tasks),
            targets={n: np.asarray(v, float) for n, v in self.targets.items()},
            actual={n: np.asarray(v, float) for n, v in self.actual.items()},
            contacts=np.asarray(r["contacts"], bool).reshape(T, -1)
            if self.contacts is not None
            else None,
            foot_names=list(self.contacts.names) if self.contacts is not None else [],
            status=np.asarray(r["status"], dtype=str),
            solve_time=np.asarray(r["solve_time"], float),
            tau=tau,
            human=human,
            extra=extra,
            meta={**meta, "relaxed_by": dict(sorted(self.relaxed_by.items()))},
        )


def run_meta(
    controller: Controller,
    spec: Any,
    stream: Any,
    calibration: Any,
    rate: float,
    *,
    skipped: list[str],
    messages: list[str],
    support_log: list[tuple[float, str]],
) -> dict[str, Any]:
    """The run's ``meta`` (docs/formats.md): source, rates, filter, tasks, calibration, alignment.

    ``human_alignment`` holds the heading rotation and both origins, so that a viewer can draw
    the raw ``human/<key-point>`` next to the robot.
    """
    cal = calibration
    motion = stream.skeleton
    support = spec.support
    return {
        "source": motion.source,
        "capture_rate": motion.rate,
        "control_rate": rate,
        "keypoint_map": stream.kmap.name,
        "waist_lift_m": float(stream.lift or 0.0),
        "rest_fixes": sorted(stream.rest_fixes),
        "scaling": spec.scaling,
        "filter": {
            "cutoff_hz": None if stream.filter is None else stream.filter.cutoff_hz,
            "order": spec.filter_order,
            "zero_phase": not stream.causal,
        },
        "tension": spec.tension,
        "tasks": {n: [b.keypoint, b.orientation] for n, b in spec.tasks.items()},
        "skipped_tasks": skipped,
        "calibration": None if cal is None else cal.to_dict(),
        "human_alignment": None
        if cal is None
        else {
            "rotation": cal.rotation.round(12).tolist(),
            "human_origin": [
                float(cal.human_waist[0]),
                float(cal.human_waist[1]),
                float(cal.human_ankle_height),
            ],
            "robot_origin": [
                float(cal.robot_waist[0]),
                float(cal.robot_waist[1]),
                float(cal.robot_ankle_height),
            ],
        },  # fmt: skip
        "config_name": controller.config.get("name", ""),
        "root_nq": controller.robot.root_nq,
        "messages": messages,
        "support_log": support_log,
        "balance_mode": None if support is None else support.mode,
    }


__all__ = ["RunRecorder", "run_meta"]
