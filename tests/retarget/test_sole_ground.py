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
