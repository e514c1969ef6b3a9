# SPDX-License-Identifier: Apache-2.0
"""The one schema of a controller YAML (issue 21): top-level keys, registered options, solvers."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest
import yaml

from qpretarget import Controller, schema
from qpretarget.constraints import CONSTRAINTS
from qpretarget.control import acceleration, controller, levels, result, velocity
from qpretarget.errors import ConfigError, SolverNotInstalledError
from qpretarget.solvers import (
    SOLVERS,
    DaqpSolver,
    ProxSuiteSolver,
    QpsolversSolver,
    make_solver,
)
from qpretarget.strategies import STRATEGIES
from qpretarget.tasks import TASKS
from qpretarget.weighting import REGULARIZATIONS


@pytest.fixture(scope="module")
def base(configs_dir) -> dict:
    return yaml.safe_load((configs_dir / "g1_augmentation.yaml").read_text())


def test_viewer_is_not_a_controller_setting(base) -> None:
    with pytest.raises(ConfigError, match=r"viewer: `viewer:` is not a controller setting.*"
                       r"qpretarget view"):  # fmt: skip
        Controller({**base, "viewer": {"port": 8080}})


def test_no_shipped_config_has_a_viewer_section(configs_dir) -> None:
    for path in Path(configs_dir).glob("*.yaml"):
        assert "viewer" not in (yaml.safe_load(path.read_text()) or {}), path


def test_unknown_top_level_key_gets_close_names(base) -> None:
    with pytest.raises(ConfigError, match=r"unknown key 'taks'\. Did you mean 'tasks'"):
        Controller({**base, "taks": []})


def test_options_list_every_registered_type_and_its_constructor_keys() -> None:
    opts = schema.options()
    assert set(opts) == {"tasks", "constraints", "strategy", "regularization", "solver"}
    for section, registry in [("tasks", TASKS), ("constraints", CONSTRAINTS),
                              ("strategy", STRATEGIES), ("regularization", REGULARIZATIONS),
                              ]:  # fmt: skip
        assert set(opts[section]) == set(registry)
    assert set(opts["solver"]) == {n for n, c in SOLVERS.items() if not c.passes_options}
    assert opts["tasks"]["frame"][:2] == ["name", "frame"]
    assert "gain" in opts["constraints"]["joint_limits"]
    assert opts["solver"]["proxsuite"] == list(ProxSuiteSolver.OPTIONS)
    assert "osqp" not in opts["solver"]  # options go to qpsolvers unchecked
    for key in opts["tasks"]["posture"]:
        assert key in inspect.signature(TASKS["posture"]).parameters


def test_solver_registry_holds_native_and_qpsolvers_backends() -> None:
    assert SOLVERS["proxsuite"] is ProxSuiteSolver and SOLVERS["daqp"] is DaqpSolver
    assert SOLVERS["osqp"] is QpsolversSolver and SOLVERS["qpsolvers/daqp"] is QpsolversSolver
    assert isinstance(make_solver(None), DaqpSolver)  # the default backend
    assert isinstance(make_solver({"name": "qpsolvers/daqp"}), QpsolversSolver)
    with pytest.raises(ConfigError, match=r"solver\.name: solver 'dap' is not known\. Did you"):
        make_solver("dap")
    with pytest.raises(SolverNotInstalledError, match="pip install"):
        make_solver("gurobi")


def _imports(module: object) -> set[str]:
    tree = ast.parse(inspect.getsource(module))  # type: ignore[arg-type]
    return {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}


def test_levels_do_not_import_the_controller() -> None:
    # One tick template in the controller; the levels only supply their solve (no import circle).
    for mod in (acceleration, velocity, levels, result):
        assert "controller" not in _imports(mod), mod
    assert "acceleration" in _imports(controller)


def test_a_level_never_writes_the_controller(base) -> None:
    ctrl = Controller({**base, "level": "acceleration"})
    assert isinstance(ctrl.level_impl, acceleration.AccelerationLevel)
    assert "ctrl" not in vars(ctrl.level_impl)
    res = ctrl.step()
    assert res.tick == ctrl.tick == 1 and res.tau is not None
    vel = Controller(base)
    assert isinstance(vel.level_impl, velocity.VelocityLevel)
    assert vel.step().tau is None
