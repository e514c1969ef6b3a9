# SPDX-License-Identifier: Apache-2.0
"""QP solver backends, registered by name in :data:`SOLVERS`.

Native warm-started ProxSuite, and qpsolvers for every other solver. Adding a backend: one module
with a ``@SOLVERS.register("name")`` class, and its import line below.
"""

from .base import SOLVERS, QPSolution, QPSolver, make_solver, split_solver_spec
from .daqp_ import DaqpSolver
from .proxsuite_ import ProxSuiteSolver
from .qpsolvers_ import QpsolversSolver, installed_qpsolvers, known_qpsolvers

__all__ = [
    "SOLVERS",
    "QPSolution",
    "QPSolver",
    "make_solver",
    "split_solver_spec",
    "ProxSuiteSolver",
    "DaqpSolver",
    "QpsolversSolver",
    "installed_qpsolvers",
    "known_qpsolvers",
]
