# SPDX-License-Identifier: Apache-2.0
"""Tests of qpretarget/constraints/acceleration_limits.py: |v - v_prev| <= a_max dt."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.errors import ConfigError, UnknownJointError


def test_limits_hold_under_jumping_targets(g1, make_config, make_wild_targets) -> None:
    """Every tick in which nothing gave, every actuated joint changes its velocity by at most
    a_max dt. Tolerance 1e-9: the controller clips the solution to the merged box, so the bound
    holds to rounding (measured 0)."""
    a_max = 100.0
    ctrl = Controller(make_config(g1, a_max=a_max))
    vi = g1.joint_v_index
    v_prev = np.zeros(g1.nv)
    worst = 0.0
    checked = 0
    for targets in make_wild_targets(ctrl, 200, seed=3):
        res = ctrl.step(targets)
        if "acceleration_limits" not in res.relaxed:
            worst = max(worst, float(np.max(np.abs(res.v[vi] - v_prev[vi]) - a_max * ctrl.dt)))
            checked += 1
        v_prev = np.array(res.v)
    assert checked > 150
    assert worst <= 1e-9, worst


def test_per_joint_limits_and_default(g1, make_config) -> None:
    cfg = make_config(g1, a_max=None, polygon=False)
    cfg["constraints"].append(
        {"type": "acceleration_limits", "a_max": {"default": 50.0, "left_elbow_joint": 10.0}}
    )
    ctrl = Controller(cfg)
    con = ctrl.constraint("acceleration_limits")
    j = g1.joint_index("left_elbow_joint")
    assert con.a_max[j] == 10.0 and np.sum(con.a_max == 50.0) == len(g1.joint_names) - 1
    lo, hi = con.compute_bounds(ctrl.state, ctrl.dt)
    iv = g1.joint_v_index[j]
    # At rest and far from its limits: +-a_max dt.
    assert hi[iv] == pytest.approx(0.1) and lo[iv] == pytest.approx(-0.1)
    assert np.all(np.isinf(lo[:6])) and np.all(np.isinf(hi[:6]))  # the free-flyer is not limited
    # Without `default` only the joints named are limited.
    cfg["constraints"][-1] = {"type": "acceleration_limits", "a_max": {"left_elbow_joint": 10.0}}
    con = Controller(cfg).constraint("acceleration_limits")
    assert np.sum(np.isfinite(con.a_max)) == 1


def test_bad_values_are_config_errors(g1, make_config) -> None:
    cfg = make_config(g1, a_max=None)
    for spec, err, match in [
        (0.0, ConfigError, "a_max"),
        ({"left_elbo_joint": 10.0}, UnknownJointError, "left_elbow_joint"),
        ({"left_elbow_joint": -1.0}, ConfigError, "a_max"),
        ("fast", ConfigError, "a_max"),
    ]:
        cfg["constraints"] = cfg["constraints"][:3] + [
            {"type": "acceleration_limits", "a_max": spec}
        ]
        with pytest.raises(err, match=match):
            Controller(cfg)
    cfg["constraints"][-1] = {"type": "acceleration_limits", "a_max": 10.0, "braking": "yes"}
    with pytest.raises(ConfigError, match="braking"):
        Controller(cfg)
    for base in ([1.0], [0.0, 1.0], "fast", [1.0, -2.0]):
        cfg["constraints"][-1] = {"type": "acceleration_limits", "a_max": 10.0, "base": base}
        with pytest.raises(ConfigError, match="base"):
            Controller(cfg)


def test_base_limits_bound_the_floating_base_too(g1, make_config, make_wild_targets) -> None:
    """``base: [a_lin, a_ang]``: the free-flyer's six velocity coordinates change by at most
    a dt per tick in which nothing gave (tolerance 1e-9, as above); without it the same wild
    targets change them by up to 1.09 m/s and 2.05 rad/s in a tick (measured; with it 0.2 and
    1.0: the limits)."""
    a_lin, a_ang = 20.0, 100.0
    cfg = make_config(g1, a_max=None)
    cfg["constraints"].append(
        {"type": "acceleration_limits", "a_max": 100.0, "base": [a_lin, a_ang]}
    )
    ctrl = Controller(cfg)
    lo, hi = ctrl.constraint("acceleration_limits").compute_bounds(ctrl.state, ctrl.dt)
    assert hi[:3] == pytest.approx([a_lin * ctrl.dt] * 3) and hi[3:6] == pytest.approx([1.0] * 3)
    limit = np.array([a_lin] * 3 + [a_ang] * 3) * ctrl.dt
    v_prev = np.zeros(g1.nv)
    worst, checked = -np.inf, 0
    for targets in make_wild_targets(ctrl, 200, seed=3):
        res = ctrl.step(targets)
        if "acceleration_limits" not in res.relaxed:
            worst = max(worst, float(np.max(np.abs(res.v[:6] - v_prev[:6]) - limit)))
            checked += 1
        v_prev = np.array(res.v)
    assert checked > 150
    assert worst <= 1e-9, worst


@pytest.mark.parametrize("braking", [True, False])
def test_braking_keeps_joint_and_acceleration_limits_compatible(g1, braking) -> None:
    """A posture target far beyond the elbow's upper limit: with braking the joint slows down in
    time and no bound ever has to give; without it, joint_limits forces a stop sharper than a_max
    and the acceleration bound gives (which shows braking is what prevents the conflict)."""
    joint = "left_elbow_joint"
    cfg = {
        "robot": g1,
        "dt": 0.01,
        "tasks": [{"type": "posture", "name": "posture", "weight": 1.0, "gain": 20.0}],
        "constraints": [
            {"type": "joint_limits", "gain": 0.95},
            {"type": "velocity_limits"},
            {"type": "acceleration_limits", "a_max": 50.0, "braking": braking},
        ],
    }
    ctrl = Controller(cfg)
    j = g1.joint_index(joint)
    iq, iv = g1.joint_q_index[j], g1.joint_v_index[j]
    target = ctrl.robot.q_reference[7:].copy()
    target[j] = g1.q_max[iq] + 1.0
    gave = 0
    v_prev = 0.0
    for _ in range(150):
        res = ctrl.step({"posture": target})
        gave += bool(res.relaxed)
        if braking:  # the bound holds every tick (tolerance: rounding, the box is clipped exactly)
            assert abs(res.v[iv] - v_prev) <= 50.0 * ctrl.dt + 1e-9
        v_prev = res.v[iv]
        assert res.q[iq] <= g1.q_max[iq] + 1e-9
    assert ctrl.q[iq] > g1.q_max[iq] - 0.01  # it did reach the limit
    if braking:
        assert gave == 0
    else:
        assert gave > 0
