# SPDX-License-Identifier: Apache-2.0
"""``Controller.step`` under bad input: NaN/inf, wrong shapes, non-orthonormal rotations, unknown
names, bad dt. A programming error raises TargetError; missing data is a reported tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.errors import TargetError

from .conftest import REPO, outcome


@pytest.fixture(scope="module")
def ctrl() -> Controller:
    return Controller.from_yaml(REPO / "configs" / "g1_whole_body.yaml")


def _step(ctrl, targets=None, **kw):
    return outcome(lambda: ctrl.step(targets, **kw))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_targets_are_missing_data(ctrl, bad):
    ctrl.reset()
    for value in ([bad, 0.3, 1.0], np.full((3, 3), bad), np.full((4, 4), bad)):
        task = "left_hand" if np.ndim(value) == 1 else "pelvis"
        kind, res = _step(ctrl, {task: value})
        assert kind == "ok" and np.all(np.isfinite(res.q)) and res.messages
        assert res.status in ("ok", "relaxed")


@pytest.mark.parametrize(
    "target",
    [np.zeros(2), np.zeros((2, 2)), np.zeros((3, 4)), "up", [1, "a", 3], {"x": 1}, np.zeros(7)],
)
def test_wrong_shapes_are_target_errors(ctrl, target):
    ctrl.reset()
    kind, exc = _step(ctrl, {"left_hand": target})
    assert kind == "error" and isinstance(exc, TargetError)


@pytest.mark.parametrize(
    "R",
    [
        np.eye(3) * 2.0,  # scaled
        np.diag([1.0, 1.0, -1.0]),  # a reflection (orthonormal, det -1)
        np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),  # sheared
        np.zeros((3, 3)),
        np.eye(3) + 1e-3,  # almost a rotation
    ],
)
def test_non_orthonormal_rotation(ctrl, R):
    """Not a rotation: a TargetError naming the task (pose and orientation tasks alike)."""
    ctrl.reset()
    for task, target in (("torso", R), ("pelvis", np.block([[R, np.zeros((3, 1))],
                                                            [np.zeros((1, 3)), np.ones((1, 1))]]))):  # fmt: skip
        kind, out = _step(ctrl, {task: target})
        assert kind == "error" and isinstance(out, TargetError), (task, out)
        assert task in str(out)


def test_unknown_names_and_bad_containers(ctrl):
    ctrl.reset()
    for targets in ({"left_hnd": [0, 0, 1]}, ["left_hand"], 3.0):
        kind, exc = _step(ctrl, targets)
        assert kind == "error" and isinstance(exc, TargetError)
        assert "left_hand" in str(exc) or "mapping" in str(exc)


@pytest.mark.parametrize("dt", [0.0, -0.01, math.nan, math.inf, 1e9, "0.01", True])
def test_bad_dt(ctrl, dt):
    ctrl.reset()
    kind, exc = _step(ctrl, None, dt=dt)
    assert kind == "error" and isinstance(exc, TargetError)


def test_huge_finite_targets(ctrl):
    """1e300 m away: finite q, never held (the target is only unreachable)."""
    ctrl.reset()
    for _ in range(5):
        kind, res = _step(ctrl, {"left_hand": [1e300, -1e300, 1e300], "pelvis": np.full(3, 1e300)})
        assert kind == "ok" and np.all(np.isfinite(res.q)) and res.status != "held", res.messages


def test_random_targets_never_give_nan(ctrl, rng):
    """200 ticks of random (often unreachable) targets: finite q, no exception."""
    ctrl.reset()
    for _ in range(200):
        t = {"left_hand": rng.normal(0, 1.0, 3), "right_hand": rng.normal(0, 1.0, 3)}
        if rng.random() < 0.1:
            t["head"] = [np.nan, 0, 0]
        kind, res = _step(ctrl, t)
        assert kind == "ok" and np.all(np.isfinite(res.q))
