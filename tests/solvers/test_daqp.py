# SPDX-License-Identifier: Apache-2.0
"""The direct DAQP backend: rows with no finite side are left out, the hot start survives them."""

from __future__ import annotations

import numpy as np

from qpretarget.problem import QPProblem
from qpretarget.solvers import make_solver


def _problem(rng: np.random.Generator, n: int = 12, m: int = 40) -> QPProblem:
    p = QPProblem(n, m)
    A = rng.normal(size=(n, n))
    p.H[...] = A @ A.T + n * np.eye(n)
    p.g[...] = rng.normal(size=n) * 10
    p.C[...] = rng.normal(size=(m, n))
    p.u[...] = rng.uniform(0.1, 1.0, m)
    p.u[rng.random(m) < 0.7] = np.inf  # most rows inactive, as collision pairs beyond d_i
    p.lb[...], p.ub[...] = -2.0, 2.0
    return p


def test_rows_without_a_finite_side_do_not_change_the_solution():
    """Against quadprog (every row given): same solution to 1e-9 (both solve to 1e-12 here)."""
    rng = np.random.default_rng(7)
    daqp, ref = make_solver("daqp"), make_solver("quadprog")
    for _ in range(5):
        p = _problem(rng)
        a, b = daqp.solve(p), ref.solve(p)
        assert a.success and b.success
        assert np.abs(a.x - b.x).max() < 1e-9
        assert p.constraint_violation(a.x) < 1e-9


def test_hot_start_maps_multipliers_of_rows_that_come_and_go():
    """A row inactive in one solve and active in the next: the next solve is still right, and the
    same problem solved again from its own active set takes at most one iteration."""
    rng = np.random.default_rng(3)
    s = make_solver("daqp")
    p = _problem(rng)
    first = s.solve(p)
    q = p.copy()
    q.u[np.isinf(p.u)] = 0.05  # every inactive row becomes active-ish
    second = s.solve(q)
    ref = make_solver("quadprog").solve(q)
    assert second.success and np.abs(second.x - ref.x).max() < 1e-9
    again = s.solve(q)
    # (the same active set reached by another path: equal to round-off, not to the bit)
    assert again.iterations <= 1 and np.abs(again.x - second.x).max() < 1e-12, first.status
