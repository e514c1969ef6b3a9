# SPDX-License-Identifier: Apache-2.0
"""QP solver backends: native warm-started ProxSuite, and qpsolvers for every other solver."""

from .base import QPSolution, QPSolver, make_solver
from .proxsuite_ import ProxSuiteSolver
from .qpsolvers_ import QpsolversSolver, installed_qpsolvers, known_qpsolvers

__all__ = [
    "QPSolution",
    "QPSolver",
    "make_solver",
    "ProxSuiteSolver",
    "QpsolversSolver",
    "installed_qpsolvers",
    "known_qpsolvers",
]
