# SPDX-License-Identifier: Apache-2.0
"""``feedforward: true`` adds the target's velocity to v* (Dariush 2009 eq. 9, CRAC eq. 15).

A hand target moving at a constant velocity: with a finite gain K the error settles at the
lag v/K without feed-forward; with it, the lag vanishes (the backward difference of a linear
target is exact). Same for an orientation target turning at a constant rate, and at the
acceleration level (CRAC eq. 11: v_d and its difference a_d).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.control.controller import Controller

SPEED = np.array([0.05, 0.0, 0.03])  # [m/s], slow and reachable for 0.6 s
GAIN = 20.0  # [1/s]


def _controller(feedforward: bool, *, level: str = "velocity", mode: str = "position"):
    task = {"type": "frame", "name": "hand", "frame": "left_rubber_hand", "mode": mode,
            "gain": GAIN, "feedforward": feedforward}  # fmt: skip
    task.update({"position_weight": 100.0} if mode == "position" else {"orientation_weight": 10.0})
    cfg = {
        "robot": "g1", "dt": 0.01, "level": level, "solver": {"name": "daqp"},
        "tasks": [task, {"type": "posture", "name": "posture", "weight": 1e-4}],
        "constraints": [{"type": "contacts", "feet": ["left_foot", "right_foot"]}],
    }  # fmt: skip
    ctrl = Controller(cfg)
    ctrl.reset()
    return ctrl


@pytest.mark.parametrize("level", ["velocity", "acceleration"])
def test_position_lag_vanishes_with_feedforward(level):
    lags = {}
    for ff in (False, True):
        ctrl = _controller(ff, level=level)
        fid = ctrl.robot.frame_id("left_rubber_hand")
        p0 = ctrl.state.frame_placement(fid).translation.copy()
        for k in range(1, 61):
            ctrl.step({"hand": p0 + SPEED * k * ctrl.dt})
        # The configuration after tick k is that of time k+1: compare with the target there.
        reached = ctrl.state.frame_placement(fid).translation
        lags[ff] = np.linalg.norm(p0 + SPEED * 61 * ctrl.dt - reached)
    if level == "velocity":
        # Discrete steady state: the lag is |v|/K = 2.9 mm (5%: the arm's motion is not
        # exactly the task's, and 0.6 s is 12 time constants).
        assert lags[False] == pytest.approx(np.linalg.norm(SPEED) / GAIN, rel=0.05)
        assert lags[True] < 0.1 * lags[False], lags
    else:
        # CRAC's second-order loop (K_p, K_v) settles slower.
        assert lags[True] < 0.25 * lags[False], lags


def test_orientation_lag_vanishes_with_feedforward():
    w = np.array([0.0, 0.0, 0.5])  # [rad/s] about world z
    lags = {}
    for ff in (False, True):
        ctrl = _controller(ff, mode="orientation")
        fid = ctrl.robot.frame_id("left_rubber_hand")
        R0 = ctrl.state.frame_placement(fid).rotation.copy()
        for k in range(1, 61):
            ctrl.step({"hand": pin.exp3(w * k * ctrl.dt) @ R0})
        R = ctrl.state.frame_placement(fid).rotation
        lags[ff] = np.linalg.norm(pin.log3(R.T @ pin.exp3(w * 61 * ctrl.dt) @ R0))
    # Discrete steady state |w|/K = 0.025 rad, as for positions.
    assert lags[False] == pytest.approx(np.linalg.norm(w) / GAIN, rel=0.05)
    assert lags[True] < 0.1 * lags[False], lags


def test_no_feedforward_while_the_target_holds_still():
    ctrl = _controller(True)
    fid = ctrl.robot.frame_id("left_rubber_hand")
    p0 = ctrl.state.frame_placement(fid).translation.copy()
    ctrl.step({"hand": p0 + np.array([0.0, 0.0, 0.02])})  # a jump, then the same target
    q1 = ctrl.q.copy()
    for _ in range(3):
        ctrl.step({"hand": p0 + np.array([0.0, 0.0, 0.02])})
    # The jump is not differentiated again on later ticks: the hand converges, no overshoot.
    z = ctrl.state.frame_placement(fid).translation[2]
    assert z <= p0[2] + 0.02 + 1e-6 and not np.allclose(ctrl.q, q1)
