# SPDX-License-Identifier: Apache-2.0
r"""The first frame's fit: the person's pose and segment scales, and the joint centres' prior.

Mixed into the EM fit, :class:`.em.CloudRetargeter` (:class:`CalibrationMixin`).

**Limb lengths**: the first frame is fitted with the segment scales :math:`s` of
:class:`.template.Template` as extra variables (points are linear in them at fixed pose), from a
standing posture facing the sensor (:meth:`CalibrationMixin._initial_pose`:
``calibration.initial_joints``, ``calibration.initial_yaw``). The scales start from the ratio of
the cloud's height to the template's, within ``calibration.scale_bounds``; left and right
segments share one scale. EM as in :mod:`.em` (E-step eq. 4, NLL eq. 3), each M-step one QP on
the pose step and the scales' (:meth:`CalibrationMixin._calibration_equations`), a step accepted
when the complete-data objective does not increase: first with one common scale, then with one
per segment and the prior :math:`\lambda_s \sum_k (s_k - \bar s)^2` (``calibration.scale_prior``).
Both phases add the posture prior :math:`\lambda_p \|\theta - \theta_{cal}\|^2`
(``calibration.posture_weight``; not in Wang 2017), and take the dense E-step on a fixed subset of
the cloud while :math:`\sigma` is above :data:`CALIBRATION_DENSE_SIGMA`.

Then (:meth:`CalibrationMixin.calibrate`) the template takes the person's surface
(``calibration.personalize``), and the joint-centre estimate that the centre stage refines while
tracking (:mod:`.centres`) gets its basis (along each limb, ``calibration.centre_axes``; one
offset per left/right pair with ``centre_symmetric``) and its prior: mean 0, or the
anthropometric offsets of a person of the fitted height (``calibration.centre_model``: a generic
human model, as Wang 2017 IV.A takes them from one), information :math:`I/\sigma_e^2`
(``calibration.centre_prior``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..problem import QPProblem
from ..robot import RobotModel
from ..solvers import make_solver
from .anthropometry import anthropometric_offsets
from .config import CloudConfig
from .estep import EStep, e_step
from .io import estimate_normals
from .template import PosedTemplate, Template

#: The calibration uses the dense E-step while sigma is above this [m] (coarse alignment).
CALIBRATION_DENSE_SIGMA = 0.03
#: Largest initial sigma of the calibration [m] (the start pose is already roughly aligned).
CALIBRATION_SIGMA0 = 0.05


class CalibrationMixin:
    """The calibration of :class:`.em.CloudRetargeter` on the first frame (module docstring)."""

    # Of the fitter (.em.CloudRetargeter), used here: its state...
    config: CloudConfig
    robot: RobotModel
    template: Template
    model: Any  # pinocchio.Model
    sensor_position: np.ndarray | None
    calibrated: bool
    _qi: np.ndarray
    _vi: np.ndarray
    _frame_cloud: np.ndarray | None
    _rigid_segments: np.ndarray | None
    _tube_segments: np.ndarray | None
    tube_points: int
    recut_points: int
    rigid_points: int
    # ... the joint-centre estimate (.centres.CentresMixin, whose _init_centres starts it
    # empty), which calibrate sets...
    _centre_basis: np.ndarray
    _centre_mean: np.ndarray
    _centre_info: np.ndarray
    _centre_x: np.ndarray | None
    _centre_base: np.ndarray
    _estimate_centres: bool
    # ... and its methods.
    _active: Callable[[PosedTemplate], np.ndarray]
    _joint_step_bounds: Callable[[QPProblem, np.ndarray], np.ndarray]
    _clip: Callable[[np.ndarray], np.ndarray]
    _apply_centres: Callable[[np.ndarray], None]

    def _initial_pose(self, S: np.ndarray) -> np.ndarray:
        cal = self.config.calibration
        q = self.robot.q_reference.copy()
        for name, value in cal.initial_joints.items():
            j = self.robot.joint_index(name, path=f"calibration.initial_joints.{name}")
            q[self.robot.joint_q_index[j]] = float(value)
        if not self.robot.free_flyer:
            return q
        centre = np.median(S, axis=0)
        if cal.initial_yaw == "auto":
            yaw = (
                0.0
                if self.sensor_position is None
                else math.atan2(
                    self.sensor_position[1] - centre[1], self.sensor_position[0] - centre[0]
                )
            )
        else:
            yaw = float(cal.initial_yaw)
        q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw)).coeffs()
        q[:3] = 0.0
        posed = self.template.pose(q, jacobians=False)
        q[0] += centre[0] - np.median(posed.points[:, 0])
        q[1] += centre[1] - np.median(posed.points[:, 1])
        q[2] += np.percentile(S[:, 2], 1) - posed.points[:, 2].min()
        return q

    def calibrate(self, S: np.ndarray, Sn: np.ndarray | None = None) -> np.ndarray:
        """Fit pose and segment scales to a first (standing) frame; returns the fitted ``q``.

        The scales start from the ratio of the cloud's height to the template's and are bounded
        by ``calibration.scale_bounds``; left and right segments share one scale.
        """
        cal, em = self.config.calibration, self.config.em
        self._frame_cloud = S  # what the template's occlusions are checked against
        T = self.template
        T.set_scales(np.ones(len(T.segment_names)), np.zeros_like(T.centre_offsets))
        q = self.robot.q_reference.copy()
        posed = T.pose(q, jacobians=False)
        height_model = posed.points[:, 2].max() - posed.points[:, 2].min()
        height_cloud = np.percentile(S[:, 2], 99.5) - min(np.percentile(S[:, 2], 0.5), 0.0)
        lo_s, hi_s = (float(x) for x in cal.scale_bounds)
        s = np.full(len(T.segment_names), float(np.clip(height_cloud / height_model, lo_s, hi_s)))
        T.set_scales(s)
        q = self._initial_pose(S)
        self._calibration_posture = q[self._qi].copy()
        posed = T.pose(q, jacobians=False)
        active = self._active(posed)
        d2 = (
            np.einsum("na,na->n", S, S).mean()
            + np.einsum("ma,ma->m", posed.points, posed.points)[active].mean()
            - 2.0 * S.mean(0) @ posed.points[active].mean(0)
        )
        sigma2 = float(np.clip(d2 / 3.0, em.sigma2_init, CALIBRATION_SIGMA0**2))
        # Phase 1: one common scale (robust from far away); phase 2: every segment, with the prior.
        q, s, sigma2 = self._calibration_phase(
            S, q, s, sigma2, common=True, iterations=max(cal.iterations // 2, 1)
        )
        q, s, sigma2 = self._calibration_phase(
            S, q, s, sigma2, common=False, iterations=cal.iterations
        )
        T.set_scales(s)
        if cal.personalize:
            if Sn is None:
                Sn = estimate_normals(S, self.sensor_position, self.config.input.normals_k)
            active = self._active(T.pose(q, jacobians=False))
            self.personalized_points = T.personalize(
                q, S, Sn, ~active, max_distance=cal.personalize_distance
            )
        # Joint centres: offsets from the calibrated pose, where the fitted surface stays.
        T.set_centre_rest(q)
        ax, inner = T.limb_axes()
        if cal.centre_joints is not None:
            inner = inner & self._centre_selection(cal.centre_joints)
        if cal.centre_axes == "limb":
            U = np.zeros((3 * T.n_centres, T.n_centres))
            for a in range(T.n_centres):
                U[3 * a : 3 * a + 3, a] = ax[a]
            U = U[:, inner]
            if cal.centre_symmetric:
                U = self._symmetric_basis(U, np.flatnonzero(inner))
        else:
            U = np.eye(3 * T.n_centres)[:, np.repeat(inner, 3)]
        self._centre_basis = U
        self._centre_x = None
        nc = U.shape[1]
        self._centre_mean = np.zeros(nc)
        self._centre_base = np.zeros(3 * T.n_centres)
        if cal.centre_model == "anthropometric":
            # The person's centres from the standing height (a generic human model, as Wang
            # 2017 IV.A takes them from one): the prior mean of the centres estimated while
            # tracking, and fixed for the others the table places (wrists, hips, knees...).
            # The height from the fitted (personalised) template, not the raw cloud, whose
            # top percentiles hold outliers (1.94 m for a 1.76 m person at 5 % outliers).
            points = T.pose(q, jacobians=False).points
            height = float(points[:, 2].max())  # floor at z = 0
            offsets = anthropometric_offsets(T, points, height, ax)
            along = np.clip(np.einsum("ab,ab->a", offsets, ax), -cal.centre_bound, cal.centre_bound)
            full = (along[:, None] * ax).reshape(-1)
            if self._estimate_centres:  # least squares: the mean of paired sides
                self._centre_mean = np.linalg.solve(U.T @ U, U.T @ full)
            self._centre_base = full - U @ self._centre_mean
            self._apply_centres(self._centre_mean)
            if cal.centre_cuts == "centres":
                # The limbs' surfaces cut at the person's centres, not the robot's links.
                self.recut_points = T.assign_by_centres(q, reach=cal.centre_bound)
        if self._tube_segments is not None and len(self._tube_segments):
            # A person's limbs about their joint lines, not the robot's link shapes.
            self.tube_points = T.limbs_as_tubes(q, [int(k) for k in self._tube_segments])
        if self._rigid_segments is not None and len(self._rigid_segments):
            self.rigid_points = T.attach_rigidly(q, list(self._rigid_segments))
        self._centre_info = np.eye(nc) / max(cal.centre_prior, 1e-9) ** 2
        self.calibration_sigma2 = sigma2
        self.calibrated = True
        return q

    def _symmetric_basis(self, U: np.ndarray, arts: np.ndarray) -> np.ndarray:
        """Limb basis with one column per left/right pair of articulations (``centre_symmetric``).

        Column c of ``U`` moves articulation ``arts[c]`` along its limb; the columns of
        ``left_...`` and ``right_...`` joints of the same name are added: one offset along
        both limbs, whose prior standard deviation stays ``centre_prior``.
        """
        T = self.template
        names = [T.model.names[int(max(T.articulations[int(a)]))] for a in arts]
        cols, used = [], set()
        for c, name in enumerate(names):
            if c in used:
                continue
            col = U[:, c].copy()
            if name.startswith("left_"):
                twin = "right_" + name[len("left_") :]
                if twin in names:
                    t = names.index(twin)
                    col += U[:, t]
                    used.add(t)
            elif name.startswith("right_"):
                twin = "left_" + name[len("right_") :]
                if twin in names and names.index(twin) not in used:
                    t = names.index(twin)
                    col += U[:, t]
                    used.add(t)
            cols.append(col)
        return np.stack(cols, axis=1) if cols else U

    def _calibration_phase(
        self,
        S: np.ndarray,
        q: np.ndarray,
        s: np.ndarray,
        sigma2: float,
        *,
        common: bool,
        iterations: int,
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """EM on pose and scales (one common scale, or one per segment with ``scale_prior``)."""
        cal, em = self.config.calibration, self.config.em
        T = self.template
        lo_s, hi_s = (float(x) for x in cal.scale_bounds)
        nv, K = self.robot.nv, len(s)
        ns = 1 if common else K
        qp = QPProblem(nv + ns, 0)
        solver = make_solver(self.config.solver, path="solver")
        active = self._active(T.pose(q, jacobians=False))
        rng = np.random.default_rng(0)
        S_dense = S[np.sort(rng.choice(len(S), size=min(len(S), 1000), replace=False))]
        for it in range(iterations):
            posed = T.pose(q)
            if it % 5 == 0:
                active = self._active(posed)
            dense = (sigma2 > CALIBRATION_DENSE_SIGMA**2 and it < 8) or em.estep == "dense"
            # The coarse (dense) iterations use a fixed random subset of the cloud.
            est = e_step(
                S_dense if dense else S,
                posed.points,
                active,
                sigma2,
                em.outlier_weight,
                mode="dense" if dense else "kdtree",
                neighbors=max(em.neighbors, 16),
            )
            H, b = self._calibration_equations(posed, est, q, s, sigma2, common)
            qp.H[...], qp.g[...] = H, -b
            vi = self._joint_step_bounds(qp, q)
            qp.lb[nv:] = lo_s - (s.min() if common else s)
            qp.ub[nv:] = hi_s - (s.max() if common else s)
            sol = solver.solve(qp)
            if sol.x is None:
                break
            x = sol.x
            ds = np.full(K, x[nv]) if common else x[nv:]
            obj0 = est.q_value(posed, sigma2) + self._scale_prior(s) + self._posture_prior(q)
            found = self._calibration_line_search(est, q, s, x[:nv], ds, sigma2, obj0)
            if found is None:
                T.set_scales(s)
                break
            alpha, q, s, p_try = found
            sigma2 = max(est.sigma2_update(p_try), em.sigma2_min)
            if (
                np.max(np.abs(alpha * x[vi]), initial=0.0) < em.tolerance
                and np.max(np.abs(alpha * ds)) < 1e-3
                and sigma2 < CALIBRATION_DENSE_SIGMA**2
            ):
                break
        T.set_scales(s)
        return q, s, sigma2

    def _calibration_equations(
        self,
        posed: PosedTemplate,
        est: EStep,
        q: np.ndarray,
        s: np.ndarray,
        sigma2: float,
        common: bool,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton system ``(H, b)`` of a calibration M-step on pose and scales.

        The pose block by the template's moments; the scale blocks by plain sums (no large BLAS
        product: multi-threaded BLAS is slow on a loaded machine). Adds the scale prior (per
        segment), the posture prior and Levenberg damping.
        """
        cal, em = self.config.calibration, self.config.em
        T = self.template
        nv, K = self.robot.nv, len(s)
        ns = 1 if common else K
        J6 = T.joint_jacobians()
        Js = T.scale_jacobian(posed)
        if common:
            Js = Js.sum(axis=2, keepdims=True)
        E = est.Px - est.P1[:, None] * posed.points
        H = np.empty((nv + ns, nv + ns))
        b = np.empty(nv + ns)
        H[:nv, :nv], b[:nv] = T.normal_equations(posed, J6, est.P1, E)
        Jq = T.point_jacobians(posed, J6)
        PJs = Js * est.P1[:, None, None]
        H[:nv, nv:] = np.einsum("man,mak->nk", Jq, PJs)
        H[nv:, :nv] = H[:nv, nv:].T
        H[nv:, nv:] = np.einsum("man,mak->nk", Js, PJs)
        b[nv:] = np.einsum("mak,ma->k", Js, E)
        if not common and cal.scale_prior > 0:
            Pm = np.eye(K) - 1.0 / K
            H[nv:, nv:] += 2 * sigma2 * cal.scale_prior * Pm
            b[nv:] -= 2 * sigma2 * cal.scale_prior * Pm @ s
        if cal.posture_weight > 0:
            w = 2.0 * sigma2 * cal.posture_weight
            H[self._vi, self._vi] += w
            b[self._vi] -= w * (q[self._qi] - self._calibration_posture)
        H[np.diag_indices(nv + ns)] += em.damping * max(np.trace(H) / (nv + ns), 1e-12) + 1e-12
        return H, b

    def _calibration_line_search(
        self,
        est: EStep,
        q: np.ndarray,
        s: np.ndarray,
        dq: np.ndarray,
        ds: np.ndarray,
        sigma2: float,
        obj0: float,
    ) -> tuple[float, np.ndarray, np.ndarray, PosedTemplate] | None:
        """``(alpha, q, s, posed)`` of the first halving that does not increase the objective.

        ``None`` when ``em.max_backtracks`` halvings all increase it (the template keeps the
        last scales tried; the caller restores its own).
        """
        lo_s, hi_s = (float(x) for x in self.config.calibration.scale_bounds)
        T = self.template
        alpha = 1.0
        for _ in range(max(self.config.em.max_backtracks, 1)):
            s_try = np.clip(s + alpha * ds, lo_s, hi_s)
            T.set_scales(s_try)
            q_try = self._clip(pin.integrate(self.model, q, alpha * dq))
            p_try = T.pose(q_try, jacobians=False)
            obj = est.q_value(p_try, sigma2) + self._scale_prior(s_try)
            if obj + self._posture_prior(q_try) <= obj0:
                return alpha, q_try, s_try, p_try
            alpha *= 0.5
        return None

    def _centre_selection(self, names: list[str]) -> np.ndarray:
        """(A,) mask of the articulations holding one of the joints ``names``."""
        T = self.template
        groups = [{T.model.names[int(j)] for j in g} for g in T.articulations]
        mask = np.zeros(T.n_centres, bool)
        for k, name in enumerate(names):
            self.robot.joint_index(name, path=f"calibration.centre_joints[{k}]")
            hit = [a for a, g in enumerate(groups) if name in g]
            if not hit:
                firsts = ", ".join(sorted(T.model.names[int(g.max())] for g in T.articulations))
                raise ConfigError(
                    f"joint {name!r} starts no articulation of the template; articulations "
                    f"start at: {firsts}.",
                    path=f"calibration.centre_joints[{k}]",
                )
            mask[hit] = True
        return mask

    def _posture_prior(self, q: np.ndarray) -> float:
        r"""Calibration posture term :math:`\lambda_p \|\theta - \theta_{cal}\|^2`.

        The person stands in the posture the calibration asks for (``initial_joints``); what the
        cloud barely shows (a leg's twist about its own axis, seen only through the small feet)
        stays there instead of drifting. Not in Wang 2017.
        """
        w = self.config.calibration.posture_weight
        if w <= 0:
            return 0.0
        d = q[self._qi] - self._calibration_posture
        return float(w * d @ d)

    def _scale_prior(self, s: np.ndarray) -> float:
        w = self.config.calibration.scale_prior
        return float(w * np.sum((s - s.mean()) ** 2)) if w > 0 else 0.0


__all__ = ["CALIBRATION_DENSE_SIGMA", "CALIBRATION_SIGMA0", "CalibrationMixin"]
