# SPDX-License-Identifier: Apache-2.0
r"""The joint centres learnt while tracking: EM on the pose and the centres' offsets together.

Mixed into the EM fit, :class:`.em.CloudRetargeter` (:class:`CentresMixin`). Not in Wang 2017,
which takes the joint centres from a generic human model (IV.A).

The offsets of the articulation centres (:meth:`.template.Template.set_centres`) are static
parameters :math:`e` of the subject with a Gaussian estimate :math:`(\hat e, \Lambda)`, whose
basis and prior the calibration sets (:mod:`.calibration`). On a frame with a centre stage
(``calibration.centre_rate``; :meth:`CentresMixin._centre_stage`), each M-step solves the pose
step and the offset step in one QP, the objective of :mod:`.em` (eq. 5 with its priors) gaining
:math:`\tfrac12 (e - \hat e)^\top \Lambda (e - \hat e)`, and a step is accepted when that
objective does not increase. The stage stops when no joint moves more than ``em.tolerance`` and
no centre more than :data:`CENTRE_TOLERANCE`. Then :math:`\hat e = e`, and :math:`\Lambda` gains
the frame's information on :math:`e` with the pose marginalized: the Schur complement
:math:`(H_{ee} - H_{qe}^\top A^{-1} H_{qe}) / \sigma^2` of the Gauss-Newton matrix, A its pose
block with the temporal term and the damping, times ``calibration.centre_information``
(:meth:`CentresMixin._learn_centres`): a recursive least-squares estimate over the frames seen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..problem import QPProblem
from ..robot import RobotModel
from ..solvers import make_solver
from .config import CloudConfig
from .estep import EStep, _Neighbours
from .io import CloudFrame
from .iterations import IterationLog, _Trial
from .template import PosedTemplate, Template

#: The joint pose + centre iterations of a frame stop when no centre moves more than this [m]
#: (and no joint more than ``em.tolerance``).
CENTRE_TOLERANCE = 5.0e-4


class CentresMixin:
    """The centre stage of :class:`.em.CloudRetargeter` and its joint-centre estimate."""

    # Set up here (_init_centres, which the fitter's __init__ calls): the joint-centre estimate,
    # which the calibration sets, and the centre stage's QP...
    _centre_mean: np.ndarray
    _centre_info: np.ndarray
    _centre_x: np.ndarray | None
    _centre_base: np.ndarray
    _qp_centres: QPProblem | None
    # Of the fitter (.em.CloudRetargeter), used here: its state...
    config: CloudConfig
    robot: RobotModel
    template: Template
    model: Any  # pinocchio.Model
    stability_mode: str
    _n_rows: int
    _vi: np.ndarray
    # ... the estimate's basis (the calibration sets it), the last centre stage's time (its
    # reset starts it)...
    _centre_basis: np.ndarray
    _centre_time: float | None
    # ... and its methods.
    _pose: Callable[..., PosedTemplate]  # CloudRetargeter._pose
    _e_step: Callable[..., EStep]  # CloudRetargeter._e_step
    _prior: Callable[[np.ndarray, np.ndarray | None], float]
    _add_priors: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, float], None]
    _damping: Callable[[np.ndarray], float]
    _joint_step_bounds: Callable[[QPProblem, np.ndarray], np.ndarray]
    _set_rows: Callable[[QPProblem, np.ndarray, bool], None]
    _stable: Callable[[np.ndarray], bool]
    _moves: Callable[[np.ndarray, np.ndarray], tuple[float, float]]
    _clip: Callable[[np.ndarray], np.ndarray]

    def _init_centres(self) -> None:
        r"""Start the joint-centre estimate empty: no offsets until the calibration.

        The mean :math:`\hat e` (``_centre_mean``), the information :math:`\Lambda`
        (``_centre_info``), the current value :math:`e` (``_centre_x``; None: the centre stage
        starts from :math:`\hat e`) and the fixed offsets (``_centre_base``, the anthropometric
        model's); the centre stage's QP (``_qp_centres``) is built at the first centre stage.
        """
        self._centre_mean = np.zeros(0)
        self._centre_info = np.zeros((0, 0))
        self._centre_x = None
        self._centre_base = np.zeros(0)
        self._qp_centres = None

    def _centre_due(self, frame: CloudFrame | np.ndarray) -> bool:
        """Whether this frame gets a centre stage (``calibration.centre_rate``); records it."""
        rate = self.config.calibration.centre_rate
        t = frame.t if isinstance(frame, CloudFrame) else None
        if rate is None or t is None or not math.isfinite(t):
            return True
        last = self._centre_time
        # Half a frame's slack at 30 Hz input: 10 Hz keeps every third frame.
        if last is not None and t - last < 1.0 / float(rate) - 1e-3:
            return False
        self._centre_time = float(t)
        return True

    @property
    def _estimate_centres(self) -> bool:
        cal = self.config.calibration
        return bool(cal.enabled and cal.joint_centres and cal.centre_iterations > 0)

    def _centre_stage(
        self,
        S: np.ndarray,
        q: np.ndarray,
        sigma2: float,
        q_prev: np.ndarray | None,
        active: np.ndarray,
        log: list[IterationLog],
        neighbours: _Neighbours | None = None,
    ) -> tuple[np.ndarray, float]:
        r"""EM on the pose and the joint-centre offsets together, then the centres' update.

        The offsets of the articulation centres (:meth:`Template.set_centres`; by default
        along each limb, ``calibration.centre_axes``, and not for the last articulation of a
        chain, wrists and ankles, whose short end segment shows them poorly) are static
        parameters :math:`e` of the subject; frame after frame they get a Gaussian estimate
        :math:`(\hat e, \Lambda)`
        (start: 0, or the anthropometric offsets with ``calibration.centre_model``, and
        :math:`I/\sigma_e^2`, ``calibration.centre_prior``; with ``centre_symmetric`` a
        left/right pair shares one offset). Each M-step solves
        the pose step and the offset step in one QP, the objective gaining
        :math:`\tfrac12 (e - \hat e)^\top \Lambda (e - \hat e)`; steps are accepted by the
        rule of :meth:`_em_stage`. Then :math:`\hat e = e` and :math:`\Lambda` gains this
        frame's information on :math:`e` with the pose marginalized (the Schur complement of
        the Gauss-Newton matrix, times ``centre_information``): a recursive least-squares
        estimate over the frames seen, which learns a centre's place along a limb once that
        joint bends.
        """
        cal, em = self.config.calibration, self.config.em
        nv, ne = self.robot.nv, self._centre_basis.shape[1]
        if self._qp_centres is None or self._qp_centres.n != nv + ne:
            self._qp_centres = QPProblem(nv + ne, self._n_rows)
            self._solver_centres = make_solver(self.config.solver, path="solver")
        qp = self._qp_centres
        e = self._centre_mean.copy() if self._centre_x is None else self._centre_x.copy()
        blocks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        neighbours = neighbours if neighbours is not None else _Neighbours(self)
        for _ in range(cal.centre_iterations):
            posed = self._pose(q, normals=False)
            est = neighbours.e_step(S, posed, active, sigma2)
            blocks = self._centre_qp(qp, est, posed, q, q_prev, e, sigma2)
            sol = self._solver_centres.solve(qp)
            prior0 = self._prior(q, q_prev) + self._centre_prior(e)
            obj0 = est.q_value(posed, sigma2) + prior0
            if sol.x is None or not np.all(np.isfinite(sol.x)):
                log.append(IterationLog("centres", est.nll, est.nll + prior0, 0.0, 0, sigma2, 0.0))
                break
            x = np.clip(sol.x, qp.lb, qp.ub)
            trial, e_try = self._centre_line_search(est, q, e, x, q_prev, sigma2, obj0)
            if not trial.accepted:
                self._apply_centres(e)
                log.append(
                    IterationLog(
                        "centres", est.nll, est.nll + prior0, 0.0, trial.halvings, sigma2, 0.0
                    )
                )
                break
            move, base = self._moves(q, trial.q)
            shift = float(np.max(np.abs(e_try - e), initial=0.0))
            q, e = trial.q, e_try
            sigma2 = max(est.sigma2_update(trial.posed), em.sigma2_min)
            log.append(
                IterationLog(
                    "centres", est.nll, est.nll + prior0, trial.alpha, trial.halvings, sigma2, move
                )
            )
            # Converged: the paper's joint criterion (V.C) and the centres moving less than
            # CENTRE_TOLERANCE.
            if max(move, base) < em.tolerance and shift < CENTRE_TOLERANCE:
                break
        if blocks is not None:
            self._learn_centres(*blocks, q_prev, sigma2, e)
        self._centre_x = e.copy()
        return q, sigma2

    def _apply_centres(self, e: np.ndarray) -> None:
        """Set the template's joint-centre offsets to ``e_0 + U e`` (``e_0``: the fixed ones)."""
        self.template.set_centres((self._centre_base + self._centre_basis @ e).reshape(-1, 3))

    def _centre_prior(self, e: np.ndarray) -> float:
        r""":math:`\tfrac12 (e - \hat e)^\top \Lambda (e - \hat e)`."""
        d = e - self._centre_mean
        return 0.5 * float(d @ self._centre_info @ d)

    def _centre_qp(
        self,
        qp: QPProblem,
        est: EStep,
        posed: PosedTemplate,
        q: np.ndarray,
        q_prev: np.ndarray | None,
        e: np.ndarray,
        sigma2: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fill the pose + centre-offset QP of one M-step; return its blocks (Hqq, Hqe, Hee)."""
        T, U = self.template, self._centre_basis
        nv = self.robot.nv
        e_hat, Lam = self._centre_mean, self._centre_info
        bound = self.config.calibration.centre_bound
        J6 = T.joint_jacobians()
        E = est.Px - est.P1[:, None] * posed.points
        Hqq, bq = T.normal_equations(posed, J6, est.P1, E)
        Hqe, Hee, be = T.centre_normal_equations(posed, J6, est.P1, E, basis=U)
        qp.H[:nv, :nv] = Hqq
        qp.H[:nv, nv:] = Hqe
        qp.H[nv:, :nv] = Hqe.T
        qp.H[nv:, nv:] = Hee + sigma2 * Lam
        qp.g[:nv] = -bq
        qp.g[nv:] = -be + sigma2 * (Lam @ (e - e_hat))
        self._add_priors(qp.H, qp.g, q, q_prev, sigma2)
        qp.H[np.diag_indices(nv)] += self._damping(Hqq)
        self._joint_step_bounds(qp, q)
        qp.lb[nv:] = np.minimum(-bound - e, 0.0)
        qp.ub[nv:] = np.maximum(bound - e, 0.0)
        self._set_rows(qp, q, self.stability_mode == "qp")
        return Hqq, Hqe, Hee

    def _centre_line_search(
        self,
        est: EStep,
        q: np.ndarray,
        e: np.ndarray,
        x: np.ndarray,
        q_prev: np.ndarray | None,
        sigma2: float,
        obj0: float,
    ) -> tuple[_Trial, np.ndarray]:
        """Halve the pose + centre step ``x`` until the objective does not increase (stable)."""
        nv = self.robot.nv
        bound = self.config.calibration.centre_bound
        max_halvings = max(self.config.em.max_backtracks, 1)
        alpha, halvings = 1.0, 0
        while True:
            q_try = self._clip(pin.integrate(self.model, q, alpha * x[:nv]))
            e_try = np.clip(e + alpha * x[nv:], -bound, bound)
            self._apply_centres(e_try)
            posed_try = self._pose(q_try, jacobians=False, normals=False)
            obj = (
                est.q_value(posed_try, sigma2)
                + self._prior(q_try, q_prev)
                + self._centre_prior(e_try)
            )
            if obj <= obj0 and self._stable(q_try):
                return _Trial(True, alpha, halvings, False, q_try, posed_try), e_try
            if halvings >= max_halvings:
                return _Trial(False, alpha, halvings, False, q_try, posed_try), e_try
            alpha *= 0.5
            halvings += 1

    def _learn_centres(
        self,
        Hqq: np.ndarray,
        Hqe: np.ndarray,
        Hee: np.ndarray,
        q_prev: np.ndarray | None,
        sigma2: float,
        e: np.ndarray,
    ) -> None:
        """Add this frame's information on the centres, the pose marginalized (Schur complement).

        At the last linearization; the temporal term counts as the pose's prior.
        """
        em, nv = self.config.em, self.robot.nv
        A = Hqq.copy()
        if q_prev is not None and em.temporal_weight > 0:
            A[self._vi, self._vi] += 2.0 * sigma2 * em.temporal_weight
        A[np.diag_indices(nv)] += self._damping(Hqq) + 1e-12
        info = (Hee - Hqe.T @ np.linalg.solve(A, Hqe)) / sigma2
        info = 0.5 * (info + info.T)
        self._centre_info = self._centre_info + self.config.calibration.centre_information * info
        self._centre_mean = e.copy()


__all__ = ["CENTRE_TOLERANCE", "CentresMixin"]
