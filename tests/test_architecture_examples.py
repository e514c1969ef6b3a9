# SPDX-License-Identifier: Apache-2.0
"""The worked examples of docs/architecture.md run as written and do what the text says.

Each example's code block is executed (it registers a task, a constraint or a solver), used in
a G1 controller for a few ticks, and taken out of its registry again so that the registries
the other tests see are unchanged.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import qpretarget
from qpretarget.constraints.base import CONSTRAINTS
from qpretarget.control.controller import Controller
from qpretarget.solvers.base import SOLVERS
from qpretarget.tasks.base import TASKS

DOC = Path(qpretarget.__file__).resolve().parent.parent / "docs" / "architecture.md"


def _example(title: str) -> str:
    """The first python block after the heading ``## Worked example: <title>``."""
    text = DOC.read_text(encoding="utf-8")
    m = re.search(rf"## Worked example: {title}\n(.*?)```python\n(.*?)```", text, re.S)
    assert m, f"docs/architecture.md has no python example under 'Worked example: {title}'"
    return m.group(2)


def _config(**extra):
    cfg = {
        "name": "example",
        "robot": "g1",
        "dt": 0.01,
        "solver": {"name": "daqp"},
        "tasks": [{"type": "posture", "name": "posture", "weight": 1e-3}],
        "constraints": [{"type": "contacts", "feet": ["left_foot", "right_foot"]}],
    }
    for key, value in extra.items():
        cfg[key] = cfg.get(key, []) + value if isinstance(value, list) else value
    return cfg


@pytest.fixture
def registered():
    """Run an example's code, then take what it registered out of the registries again."""
    before = [(reg, set(reg)) for reg in (TASKS, CONSTRAINTS, SOLVERS)]
    yield lambda title: exec(_example(title), {})  # noqa: S102 - the doc's own example
    for reg, names in before:
        for name in set(reg) - names:
            del reg[name]


def test_task_example_moves_the_pelvis_to_the_height(registered):
    registered("a task")
    ctrl = Controller(
        _config(tasks=[{"type": "height", "name": "height", "height": 0.7, "weight": 10.0}])
    )
    ctrl.reset()
    z0 = ctrl.state.frame_placement(ctrl.robot.frame_id("pelvis")).translation[2]
    for _ in range(60):
        ctrl.step({"height": z0 - 0.05})
    z = ctrl.state.frame_placement(ctrl.robot.frame_id("pelvis")).translation[2]
    # 60 ticks at gain 1/dt close a 5 cm step to well under a millimetre; the feet stay planted.
    assert abs(z - (z0 - 0.05)) < 1e-3, (z0, z)


def test_constraint_example_caps_joint_speeds(registered):
    registered("a constraint")
    ctrl = Controller(
        _config(
            tasks=[{"type": "frame", "name": "hand", "frame": "left_rubber_hand",
                    "mode": "position", "position_weight": 100.0}],
            constraints=[{"type": "gentle", "fraction": 0.1}],
        )
    )  # fmt: skip
    ctrl.reset()
    hand = ctrl.state.frame_placement(ctrl.robot.frame_id("left_rubber_hand")).translation
    vi = ctrl.robot.joint_v_index
    cap = 0.1 * ctrl.robot.v_max[vi]
    for _ in range(10):
        res = ctrl.step({"hand": hand + np.array([0.3, 0.0, 0.3])})  # far: speeds saturate
        # Bounds hold to the solver's tolerance (1e-9 rad/s is far below any cap).
        assert np.all(np.abs(res.v[vi]) <= cap + 1e-9)
    assert np.max(np.abs(res.v[vi]) / cap) > 0.99  # the cap is what limits the motion


def test_solver_example_solves_like_the_default(registered):
    registered("a solver")
    targets = []
    runs = []
    for name in ("scipy_slsqp", "daqp"):
        ctrl = Controller(
            _config(
                solver={"name": name},
                tasks=[{"type": "frame", "name": "hand", "frame": "left_rubber_hand",
                        "mode": "position", "position_weight": 100.0}],
            )
        )  # fmt: skip
        ctrl.reset()
        if not targets:
            p = ctrl.state.frame_placement(ctrl.robot.frame_id("left_rubber_hand")).translation
            targets = [p + np.array([0.002 * k, 0.0, 0.001 * k]) for k in range(1, 6)]
        statuses = [ctrl.step({"hand": t}).status for t in targets]
        assert statuses == ["ok"] * len(targets), statuses
        runs.append(ctrl.q.copy())
    # SLSQP stops at its own tolerance (measured 7e-7 rad after 5 ticks with ftol 1e-12); daqp
    # is exact to 1e-12. 1e-5 still fails a solver that gets the tick's QP wrong (mm-level).
    np.testing.assert_allclose(runs[0], runs[1], atol=1e-5)
