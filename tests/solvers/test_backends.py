# SPDX-License-Identifier: Apache-2.0
"""ProxSuite and qpsolvers backends solve the same tick's QP to the same step."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from qpretarget import Controller
from qpretarget.errors import ConfigError, SolverNotInstalledError
from qpretarget.solvers import installed_qpsolvers, make_solver


@pytest.fixture(scope="module")
def problems(configs_dir) -> list:
    """Three QPs of a G1 run, the last with velocity bounds active (targets 0.3 m away)."""
    ctrl = Controller(yaml.safe_load((configs_dir / "g1_augmentation.yaml").read_text()))
    ctrl.reset()
    out = []
    hand = ctrl.tasks["left_hand"].position_target.copy()
    for offset in ([0.01, 0, 0], [0.0, 0.02, 0.01], [0.3, -0.2, 0.2]):
        ctrl.set_targets({"left_hand": hand + offset}, [])
        tp = ctrl.build_tick(0.01)
        out.append(ctrl.strategy.assemble(tp).copy())
        ctrl.step({})
    return out


# Per-solver agreement with ProxSuite [rad/s]: the issue asks 1e-5 for all; OSQP is an ADMM
# solver and reaches it only with polishing (on by default here).
TOL = {"osqp": 1e-5, "quadprog": 1e-5, "daqp": 1e-5, "proxqp": 1e-5}


@pytest.mark.parametrize("name", ["osqp", "quadprog", "daqp"])
def test_qpsolvers_backends_match_proxsuite(problems: list, name: str) -> None:
    if name not in installed_qpsolvers():
        pytest.fail(f"{name} must be installed for the test suite (pip install .[test])")
    ref_solver = make_solver("proxsuite")
    other = make_solver(name)
    for p in problems:
        ref = ref_solver.solve(p)
        sol = other.solve(p)
        assert ref.success and sol.success, (ref.status, sol.status)
        assert np.abs(sol.x - ref.x).max() < TOL[name], np.abs(sol.x - ref.x).max()
    # The last problem has active bounds: the comparison covers inequality handling.
    assert np.any(
        np.isclose(ref.x, problems[-1].ub, atol=1e-7)
        | np.isclose(ref.x, problems[-1].lb, atol=1e-7)
    )


def test_proxsuite_warm_start_is_reused(problems: list) -> None:
    s = make_solver({"name": "proxsuite", "eps_abs": 1e-9})
    s.solve(problems[0])
    qp = s._qp
    s.solve(problems[1])
    assert s._qp is qp  # same workspace, updated in place


def test_unknown_solver_lists_known_names() -> None:
    with pytest.raises(
        ConfigError, match=r"solver 'prosuite' is not known\. Did you mean 'proxsuite'"
    ):
        make_solver("prosuite")


def test_not_installed_solver_says_how_to_install() -> None:
    with pytest.raises(SolverNotInstalledError, match=r"pip install"):
        make_solver("gurobi")


def test_unknown_proxsuite_option() -> None:
    with pytest.raises(
        ConfigError,
        match=r"solver\.eps_ab: unknown ProxSuite option 'eps_ab'\. Did you mean 'eps_abs'",
    ):
        make_solver({"name": "proxsuite", "eps_ab": 1e-6})


def test_osqp_prints_nothing_when_not_verbose(problems: list, capfd) -> None:
    # OSQP 1.x prints "Polishing not needed ..." on the second problem (no active bound at its
    # optimum) even with verbose off; the backend silences stdout around the call, and only there.
    solver = make_solver("osqp")
    capfd.readouterr()
    sols = [solver.solve(p) for p in problems]
    print("after the solve")
    out = capfd.readouterr().out
    assert all(s.success for s in sols)
    assert "Polishing" not in out
    assert "after the solve" in out
