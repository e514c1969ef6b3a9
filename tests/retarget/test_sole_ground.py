# SPDX-License-Identifier: Apache-2.0
"""sole_ground rows (constraints/ground.py): a lifted sole's corners may not go under the floor."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.constraints.contacts import Contacts
from qpretarget.constraints.ground import SoleGround
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotState, load_robot


def test_rows_only_for_the_lifted_sole_and_they_stop_it_at_the_floor():
    robot = load_robot("g1")
    q = robot.q_reference.copy()
    q[2] += 0.01  # the whole robot 1 cm up: both soles 1 cm above the floor
    state = RobotState(robot)
    state.update(q)
    contacts = Contacts(feet=["left_foot", "right_foot"], active=["left_foot"])
    contacts.bind(robot)
    contacts.reset(state)
    sg = SoleGround()
    sg.bind(robot)
    sg.link([contacts, sg])
    assert sg.n_rows == 8  # 4 corners per sole
    dt = 0.01
    block = sg.compute_rows(state, dt)
    assert block is not None
    left = sg.feet.index("left_foot")
    lrows = slice(4 * left, 4 * left + 4)
    rrows = slice(4 * (1 - left), 4 * (1 - left) + 4)
    assert np.all(np.isinf(block.u[lrows])) and not block.C[lrows].any()  # standing: no row
    # The lifted sole: -z_dot <= z / dt (gain_per_tick 1), z = 1 cm at every corner (flat sole;
    # 1e-9 m: the reference posture's sole is flat to round-off).
    assert np.allclose(block.u[rrows], 0.01 / dt, atol=1e-6)
    # The rows are the corners' vertical velocities: a base moving down at 1 m/s lowers every
    # corner at 1 m/s (exact for a translation).
    v = np.zeros(robot.nv)
    v[2] = -1.0
    assert np.allclose(block.C[rrows] @ v, 1.0, atol=1e-9)
    # Far above the floor (beyond d_i = 5 cm): no row.
    q[2] += 0.1
    state.update(q)
    block = sg.compute_rows(state, dt)
    assert np.all(np.isinf(block.u))


def test_bad_values_are_refused():
    with pytest.raises(ConfigError, match="gain_per_tick"):
        SoleGround(gain_per_tick=2.0)
    with pytest.raises(ConfigError, match="feet must be a list"):
        SoleGround(feet="left_foot")


def test_brake_accel_keeps_a_descending_corner_able_to_stop_at_the_floor():
    robot = load_robot("g1")
    state = RobotState(robot)
    dt = 0.01
    for height, expected in ((0.04, 0.04 / dt), (0.002, 0.002 / dt)):
        q = robot.q_reference.copy()
        q[2] += height  # both soles `height` above the floor, neither in contact
        state.update(q)
        plain, braked = SoleGround(), SoleGround(brake_accel=30.0, d_i=0.15)
        for sg in (plain, braked):
            sg.bind(robot)
        u_plain = plain.compute_rows(state, dt).u
        u_braked = braked.compute_rows(state, dt).u
        # First order alone: a corner may come down z/dt (4 m/s from 4 cm in one tick).
        assert np.allclose(u_plain, expected, atol=1e-6)
        # Braked: at most sqrt(2 a z), the speed it can still stop from at 30 m/s^2 (1.55 m/s
        # at 4 cm); near the floor the first-order bound is the smaller (0.2 m/s at 2 mm).
        assert np.allclose(u_braked, min(expected, np.sqrt(2 * 30.0 * height)), atol=1e-6)
    # The braking bound reaches up to d_i: 10 cm up, rows only with the wider band.
    q = robot.q_reference.copy()
    q[2] += 0.10
    state.update(q)
    assert np.all(np.isinf(plain.compute_rows(state, dt).u))
    assert np.allclose(braked.compute_rows(state, dt).u, np.sqrt(2 * 30.0 * 0.10), atol=1e-6)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), "fast", True])
def test_bad_brake_accel_is_refused(bad):
    with pytest.raises(ConfigError, match="brake_accel"):
        SoleGround(brake_accel=bad)
