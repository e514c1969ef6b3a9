# SPDX-License-Identifier: Apache-2.0
"""Fixtures of the whole-body constraint tests: G1 loaded once, whole-body controller configs."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from qpretarget import load_robot
from qpretarget.robot import RobotModel


@pytest.fixture(scope="session")
def g1() -> RobotModel:
    return load_robot("g1")


def g1_tasks(gain: float | None = 15.0, *, com: bool = False) -> list[dict[str, Any]]:
    """The tasks of configs/g1_augmentation.yaml (optionally with a CoM task), with a task gain."""
    tasks: list[dict[str, Any]] = [
        {"type": "frame", "name": "pelvis", "frame": "pelvis", "mode": "pose",
         "position_weight": 100.0, "orientation_weight": 100.0},
        {"type": "frame", "name": "torso", "frame": "torso_link", "mode": "orientation",
         "orientation_weight": 100.0},
        {"type": "frame", "name": "left_hand", "frame": "left_rubber_hand", "mode": "position",
         "position_weight": 100.0},
        {"type": "frame", "name": "right_hand", "frame": "right_rubber_hand", "mode": "position",
         "position_weight": 100.0},
        {"type": "frame", "name": "left_elbow", "frame": "left_elbow_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "frame", "name": "right_elbow", "frame": "right_elbow_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "frame", "name": "head", "frame": "mid360_link", "mode": "position",
         "position_weight": 25.0},
        {"type": "posture", "name": "posture", "weight": 1.0e-3},
    ]  # fmt: skip
    if com:
        tasks.append({"type": "com", "name": "com", "axes": "xy", "weight": 100.0})
    if gain is not None:
        for t in tasks:
            t["gain"] = gain
    return tasks


def whole_body_config(
    robot: RobotModel,
    *,
    polygon: bool = True,
    a_max: float | None = 100.0,
    margin: float = 0.01,
    gain: float | None = 15.0,
    com: bool = False,
    damping: float = 0.3,
) -> dict[str, Any]:
    """G1 whole-body controller: g1_augmentation's tasks plus contacts, polygon, acc. limits.

    Damping 0.3 (lambda of the damped least squares): at 1e-3 the closed loop is chaotic under
    jumping targets (1e-16 input differences grow to visible ones within a second), which makes
    worst-case numbers depend on rounding.
    """
    constraints: list[dict[str, Any]] = [
        {"type": "joint_limits", "gain": 0.95},
        {"type": "velocity_limits"},
        {"type": "contacts", "feet": ["left_foot", "right_foot"]},
    ]
    if polygon:
        constraints.append({"type": "support_polygon", "margin": margin})
    if a_max is not None:
        constraints.append({"type": "acceleration_limits", "a_max": a_max})
    return {
        "robot": robot,
        "dt": 0.01,
        "strategy": {"type": "augmentation"},
        "regularization": {"type": "identity", "damping": damping},
        "solver": {"name": "proxsuite", "eps_abs": 1.0e-9},
        "tasks": g1_tasks(gain, com=com),
        "constraints": constraints,
    }


def shrunk_polygon_margin(corners: np.ndarray, com_xy: np.ndarray, margin: float) -> float:
    """Signed distance margin of a point to a hull shrunk by ``margin`` (scipy, independent).

    Positive inside: ``min_k (-(n_k . c + b_k) - margin)`` over qhull's facet equations.
    """
    from scipy.spatial import ConvexHull

    hull = ConvexHull(corners[:, :2])
    eq = hull.equations  # n . x + b <= 0 inside, unit n
    return float(np.min(-(eq[:, :2] @ com_xy + eq[:, 2]) - margin))


@pytest.fixture(scope="session")
def make_config():  # noqa: ANN201 - returns the builder
    """The :func:`whole_body_config` builder."""
    return whole_body_config


@pytest.fixture(scope="session")
def polygon_margin():  # noqa: ANN201
    """The :func:`shrunk_polygon_margin` check."""
    return shrunk_polygon_margin


def wild_targets(ctrl: Any, n: int, *, seed: int = 1, every: int = 25) -> Any:
    """Yield ``n`` target dicts jumping every ``every`` ticks: hands +-0.4 m, pelvis +-0.15 m and
    +-0.4 rad around where they start (steps, so the controller sees 4 jumps per second)."""
    import pinocchio as pin

    rng = np.random.default_rng(seed)
    robot = ctrl.robot
    start = {
        k: ctrl.state.frame_placement(robot.frame_id(ctrl.tasks[k].frame)).translation.copy()
        for k in ("left_hand", "right_hand", "pelvis")
    }
    targets: dict[str, Any] = {}
    for i in range(n):
        if i % every == 0:
            T = np.eye(4)
            T[:3, :3] = pin.exp3(rng.uniform(-0.4, 0.4, 3))
            T[:3, 3] = start["pelvis"] + rng.uniform(-0.15, 0.15, 3)
            targets = {
                "left_hand": start["left_hand"] + rng.uniform(-0.4, 0.4, 3),
                "right_hand": start["right_hand"] + rng.uniform(-0.4, 0.4, 3),
                "pelvis": T,
            }
        yield targets


@pytest.fixture(scope="session")
def make_wild_targets():  # noqa: ANN201
    """The :func:`wild_targets` generator."""
    return wild_targets
