# SPDX-License-Identifier: Apache-2.0
r"""The QP of one tick, with fixed shapes.

.. math::
    \min_x \tfrac12 x^\top H x + g^\top x \quad \text{s.t.} \quad
    l \le C x \le u, \qquad x_{min} \le x \le x_{max}

Equalities are rows with :math:`l = u`; inactive rows have infinite bounds. Shapes never change
from tick to tick, so ProxSuite reuses its workspace and warm-starts (DESIGN.md).
"""

from __future__ import annotations

import numpy as np

#: Finite stand-in for infinity handed to solvers that dislike ``inf`` bounds.
INF = 1e20


class QPProblem:
    """Preallocated arrays of a QP with ``n`` variables and ``n_in`` general rows.

    Attributes:
        H: (n, n) symmetric positive semi-definite Hessian.
        g: (n,) linear term.
        C: (n_in, n) rows; l, u: (n_in,) bounds (``l == u`` for equalities).
        lb, ub: (n,) box bounds on the variable.
    """

    def __init__(self, n: int, n_in: int) -> None:
        self.n, self.n_in = n, n_in
        self.H = np.zeros((n, n))
        self.g = np.zeros(n)
        self.C = np.zeros((n_in, n))
        self.l = np.full(n_in, -np.inf)
        self.u = np.full(n_in, np.inf)
        self.lb = np.full(n, -np.inf)
        self.ub = np.full(n, np.inf)

    def set_constraints(
        self, C: np.ndarray, l: np.ndarray, u: np.ndarray, lb: np.ndarray, ub: np.ndarray
    ) -> None:
        """Copy rows ``l <= C x <= u`` (when the problem has rows) and the box ``lb, ub``."""
        if self.n_in:
            self.C[...] = C
            self.l[...] = l
            self.u[...] = u
        self.lb[...] = lb
        self.ub[...] = ub

    def copy(self) -> QPProblem:
        """Deep copy."""
        p = QPProblem(self.n, self.n_in)
        for k in ("H", "g", "C", "l", "u", "lb", "ub"):
            getattr(p, k)[...] = getattr(self, k)
        return p

    def objective(self, x: np.ndarray) -> float:
        r""":math:`\tfrac12 x^\top H x + g^\top x`."""
        return float(0.5 * x @ self.H @ x + self.g @ x)

    def constraint_violation(self, x: np.ndarray) -> float:
        """Largest violation of any row or bound at ``x`` (0 when feasible)."""
        viol = 0.0
        if self.n_in:
            Cx = self.C @ x
            viol = max(
                viol,
                float(np.max(self.l - Cx, initial=0.0)),
                float(np.max(Cx - self.u, initial=0.0)),
            )
        viol = max(
            viol, float(np.max(self.lb - x, initial=0.0)), float(np.max(x - self.ub, initial=0.0))
        )
        return viol

    def is_finite(self) -> bool:
        """``True`` when H, g, C hold no NaN/inf and no bound is NaN."""
        return bool(
            np.isfinite(self.H).all()
            and np.isfinite(self.g).all()
            and np.isfinite(self.C).all()
            and not np.isnan(self.l).any()
            and not np.isnan(self.u).any()
            and not np.isnan(self.lb).any()
            and not np.isnan(self.ub).any()
        )

    def split(self) -> dict[str, np.ndarray | None]:
        """Return the problem in qpsolvers' form ``P, q, G, h, A, b, lb, ub``.

        Rows with ``l == u`` become equalities ``A x = b``; finite sides of the other rows become
        ``G x <= h``; rows with both sides infinite are dropped.
        """
        l, u, C = self.l, self.u, self.C
        eq = np.isfinite(l) & np.isfinite(u) & (l == u)
        up = np.isfinite(u) & ~eq
        lo = np.isfinite(l) & ~eq
        G = np.vstack([C[up], -C[lo]]) if (up.any() or lo.any()) else None
        h = np.concatenate([u[up], -l[lo]]) if G is not None else None
        A = C[eq] if eq.any() else None
        b = u[eq] if eq.any() else None
        lb, ub = self.lb.copy(), self.ub.copy()  # infinite entries stay inf (qpsolvers maps them)
        has_box = np.isfinite(self.lb).any() or np.isfinite(self.ub).any()
        return {
            "P": self.H,
            "q": self.g,
            "G": G,
            "h": h,
            "A": A,
            "b": b,
            "lb": lb if has_box else None,
            "ub": ub if has_box else None,
        }
