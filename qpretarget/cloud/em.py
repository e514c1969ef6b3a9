# SPDX-License-Identifier: Apache-2.0
r"""Generative retargeting from point clouds: EM fit of the HUMROB template, one QP per M-step.

Wang 2017 (HUMROB) fits a robot-shaped template to each depth frame with a Gaussian mixture whose
centroids are the template points :math:`v_m(\Theta)` (M of them) and whose data are the cloud
points :math:`s_n` (N of them), plus a uniform outlier term of weight :math:`\mu` (eq. 1-2). The
negative log-likelihood (eq. 3) is

.. math::
    E(\Theta, \sigma^2) = -\sum_n \log\Big(\frac{1-\mu}{M} \sum_m
        \mathcal N(s_n; v_m(\Theta), \sigma^2 I) + \frac{\mu}{N}\Big).

**E-step** (eq. 4, 20, 21): posteriors, the NLL and their sums, in :mod:`.estep`.

**M-step** (eq. 5, 13-14 linearized, 16-17): with :math:`P_m = \sum_n p_{mn}`, the template's
linearization :math:`v_m + J_m \Delta` and the temporal term
:math:`\lambda_r E_r = \lambda_r \|\theta + \Delta - \theta_{t-1}\|^2` (eq. 16, squared so that the
step is a QP), the step solves

.. math::
    \min_\Delta\ \tfrac12 \Delta^\top H \Delta - b^\top \Delta + \sigma^2 \lambda_r
    \|\theta + \Delta - \theta_{t-1}\|^2
    \quad\text{s.t.}\quad \theta_{min} \le \theta + \Delta \le \theta_{max},\
    n_k^\top (c_{F,xy} + J_{F,xy}\Delta) \le o_k

(:meth:`Template.normal_equations` for H, b; joint limits are hard bounds, eq. 17; the CoM rows
are :mod:`.stability`), with ProxSuite. Then :math:`\sigma^2 = \sum p_{mn}\|s_n - v_m\|^2 / 3N_P`.

**Monotonicity.** A linearized step can increase the objective. The step
:math:`\alpha\Delta` is accepted only when the complete-data objective with the E-step's
posteriors, :math:`Q(\Theta) + \lambda_r E_r(\Theta)` (eq. 5 plus the prior), does not exceed its
value at the current :math:`\Theta`; otherwise :math:`\alpha` is halved (``max_backtracks`` times,
after which the frame stops). Since the posteriors make Q an upper bound of the NLL that touches it
at the current point (EM), and the :math:`\sigma^2` update minimises Q, every accepted iteration
lowers :math:`E + \lambda_r E_r` -- eq. 3 itself when :math:`\lambda_r = 0`. With the kd-tree
E-step the k nearest neighbours give the largest truncated sum, so the argument holds for the
truncated NLL.

**Contact term** (not in the paper): :math:`\lambda_c E_c` keeps the soles the support tracker
marks as supporting flat on the floor and where they were put down
(:meth:`CloudRetargeter._contact_residual`); it enters the M-step and the acceptance rule like
:math:`\lambda_r E_r`, so the monotone objective is :math:`E + \lambda_r E_r + \lambda_c E_c`.

**Refinement** (eq. 15, 21): a few more iterations of EM on position and normal together, i.e. a
mixture in 6-D with
:math:`\mathcal N(s; v, \sigma^2)\,\mathcal N(\ell s^\perp; \ell v^\perp, \sigma^2/\lambda_\perp)`,
whose posteriors are eq. 21 and whose M-step adds :math:`\lambda_\perp E_\perp` (eq. 15) with the
normal's linearization :math:`v^\perp + \omega \times v^\perp`; same acceptance rule, on its own
NLL; :math:`\sigma^2 = \sum p_{mn}(\|s_n - v_m\|^2
+ \lambda_\perp \ell^2 \|s^\perp_n - v^\perp_m\|^2)/6N_P`.
The paper shares one :math:`\sigma^2` between positions [m] and unit normals without saying in
which units; read literally (:math:`\ell` = 1 m) a 20 deg normal error would weigh like a 25 cm
position error at :math:`\lambda_\perp = 0.5`. Here the normals are scaled by the length
``normal_scale`` :math:`\ell` (default 5 cm, which makes both terms of the same order for a
1 cm fit and normals estimated within about 20 deg).

**Silhouette pulls** (not in the paper; ``em.silhouette_weight`` :math:`\lambda_s`): in the
refinement, template points taking part that lie outside the person's silhouette
(:class:`Silhouette`) add :math:`\lambda_s \sum_{m \in O} \|v_m - t_m\|^2` to the bracket of
Q (as :math:`\lambda_s` cloud points each, towards targets :math:`t_m` on the outline held for
the iteration like the posteriors), so the acceptance rule and the M-step take them; the
:math:`\sigma^2` update leaves them out.

**Initialization** (V.B): a third-order auto-regression of the previous poses (an AR(2) on the
frame-to-frame steps, i.e. an AR(3) on poses whose coefficients sum to one), its two coefficients
fitted by ridge least squares over the last ``ar_window`` frames pooled over the joints.
**Convergence** (V.C): every joint moves less than ``tolerance`` (0.002 rad) in an iteration.

**A lost frame** (not in the paper): fitted again from other starts, and a shoulder stuck at a
joint limit from its other angles, in :mod:`.recovery`.

**Limb lengths**: the first frame's fit of the pose and the segment scales, in :mod:`.calibration`;
the joint centres learnt while tracking (not in the paper), in :mod:`.centres`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from ..errors import ConfigError, close_matches_hint
from ..problem import QPProblem
from ..robot import RobotModel, load_robot
from ..solvers import make_solver
from ..trajectory import RobotTrajectory
from .calibration import CalibrationMixin
from .centres import CentresMixin
from .command import CLEAR_TOLERANCE, CommandProjection
from .compiled import overlap
from .config import CloudConfig
from .estep import EStep, _Neighbours, e_step, search_coordinates
from .io import (
    CloudFrame,
    CloudSequence,
    crop_hint,
    estimate_normals,
    normals_in_background,
    prepare_cloud,
)
from .iterations import IterationLog, _Trial
from .placement import SolePlacement
from .recovery import RecoveryMixin
from .stability import (
    HipRuleState,
    StabilityRows,
    Support,
    SupportTracker,
    hip_joint_indices,
    hip_offset_rule,
)
from .template import PosedTemplate, Template
from .visibility import Silhouette, behind_cloud, visible_from

#: Length [m] dividing a supporting sole's slip in the contact term (``em.contact_weight``).
CONTACT_LENGTH = 0.1


# ------------------------------------------------------------------------------ results
@dataclass
class FrameResult:
    """Outcome of one frame.

    Attributes:
        q_fit: fitted HUMROB configuration (nq,): the person's pose in the world, robot joints.
        q_robot: robot configuration (nq,): same joints, the stance's soles flat on the floor.
        sigma2: final variance [m^2]. nll: final NLL of the linear stage (eq. 3).
        iterations: EM iterations (both stages). support: supporting feet.
        com_margin: signed distance of the robot's CoM projection inside the unshrunk support
            polygon [m] (NaN in flight).
        status: ``ok``, ``relaxed`` (balance could not be restored) or ``held`` (not fitted:
            fewer than :data:`MIN_CLOUD_POINTS` cloud points, the person out of view; the
            last frame's pose kept).
        log: per-iteration log. time: wall time [s]. rule: what the hip-offset rule did.
        clearance: the command's smallest link-pair distance above its safety distance [m]
            (config ``self_collision``; NaN when off, inf when no pair is within d_i;
            negative: a pair the steps could not clear, :mod:`.command`).
        command_steps: steps that moved the command off the fit's configuration to keep its
            links apart, its soles on their placements and its CoM over them
            (:meth:`CloudRetargeter._command`; 0: the fit's could be held as it was).
        contacts: the feet the command stands on: the stance of
            :meth:`.placement.SolePlacement.configuration` whose soles are on their
            placements (:data:`CONTACT_TOLERANCE`); the run's ``contacts``.
        person_com_margin: the person's balance over the same stance [m]: at the fitted
            configuration, the CoM (G1's masses) inside the polygon of those feet's soles (NaN
            without a stance or ``stability.mode: qp``). The command is kept inside its own
            polygon on every frame (:meth:`CloudRetargeter._command_balance`); this tells the
            frames where the person is not balanced over the same feet (a step).
    """

    q_fit: np.ndarray
    q_robot: np.ndarray
    sigma2: float
    nll: float
    iterations: int
    support: Support
    com_margin: float
    status: str
    log: list[IterationLog] = field(default_factory=list)
    time: float = 0.0
    rule: str = ""
    clearance: float = np.nan
    command_steps: int = 0
    contacts: tuple[str, ...] = ()
    person_com_margin: float = np.nan


#: Fewest cloud points (after cropping) a frame is fitted on; with fewer a tracking fit holds
#: its last pose (status ``held``) and the first frame is refused.
MIN_CLOUD_POINTS = 10


class TooFewPoints(ConfigError):
    """A frame with fewer than :data:`MIN_CLOUD_POINTS` cloud points after cropping."""


# ------------------------------------------------------------------------------ the fitter
#: Margin [m] the command's CoM is kept inside the polygon of the soles it stands on, every
#: frame (the fit keeps ``stability.margin``; the command is only kept inside, with what the
#: linearization may eat).
COMMAND_MARGIN = 0.002
#: Farthest a commanded sole may be from its placement [m, rad] to be recorded in contact.
CONTACT_TOLERANCE = (0.005, 0.05)


class CloudRetargeter(CalibrationMixin, CentresMixin, RecoveryMixin):
    """Fit the HUMROB template to a sequence of clouds; the joint angles drive the robot.

    Args:
        config: a :class:`CloudConfig` (or its mapping).
        robot: an already built robot (default: ``config.robot``).
        template: an already built template (default: built from ``config.template``).

    Use :meth:`run` on a :class:`~.io.CloudSequence`, or :meth:`fit` frame by frame (the first
    call calibrates the limb lengths unless ``calibration.enabled`` is false).
    """

    def __init__(
        self,
        config: CloudConfig | dict[str, Any] | None = None,
        *,
        robot: RobotModel | None = None,
        template: Template | None = None,
    ) -> None:
        cfg = config if isinstance(config, CloudConfig) else CloudConfig.from_dict(config)
        self.config = cfg
        self.robot = robot if robot is not None else load_robot(cfg.robot, path="robot")
        tc = cfg.template
        self.template = (
            template
            if template is not None
            else Template(
                self.robot,
                n_points=tc.points,
                meshes=tc.meshes,
                skinning=tc.skinning,
                blend_radius=tc.blend_radius,
                seed=tc.seed,
                exclude_links=tc.exclude_links,
                link_density_exponent=tc.link_density_exponent,
            )
        )
        self.model = self.template.model
        self._init_centres()  # the joint-centre estimate (empty until the calibration)
        make_solver(cfg.solver, path="solver")  # validate now
        self._solver = make_solver(cfg.solver, path="solver")
        self._solver_restore = make_solver(cfg.solver, path="solver")
        self._solver_clear = make_solver(cfg.solver, path="solver")  # the command's projection
        st = cfg.stability
        self.stability_mode = st.mode
        nv = self.robot.nv
        self._n_rows = 0
        if st.mode != "none":
            self.tracker = SupportTracker(
                self.robot,
                support_height=st.support_height,
                release_height=st.release_height,
                flight_height=st.flight_height,
            )
            self.rows = StabilityRows(self.robot, margin=st.margin, region=st.region)
            self._n_rows = self.rows.n_rows if st.mode == "qp" else 0
            if st.mode == "hip_offset":
                self._hips = hip_joint_indices(self.robot, st.hip_joints)
        #: The command with the robot's links apart (:mod:`.command`, ``self_collision``),
        #: its CoM kept over its soles while they are moved apart (``stability.mode: qp``).
        self.command = CommandProjection(self.robot, cfg.self_collision)
        self._command_rows = (
            StabilityRows(self.robot, margin=COMMAND_MARGIN, region=st.region, frame="upright")
            if st.mode == "qp"
            else None
        )
        self._qp = QPProblem(nv, self._n_rows)
        qi = self.robot.joint_q_index
        vi = self.robot.joint_v_index
        self._qi, self._vi = qi, vi
        self.q_min, self.q_max = self._fit_limits(cfg.em.joint_limits)
        self._posture_q, self._posture_v, self._posture_ref = self._posture_joints(
            cfg.em.posture_joints
        )
        self._personal_segments = self._segment_ids(cfg.calibration.personalize_segments)
        self._rigid_segments = self._segment_ids(
            cfg.calibration.rigid_segments, path="calibration.rigid_segments"
        )
        self._silhouette_segments = self._segment_ids(
            cfg.em.silhouette_segments, path="em.silhouette_segments"
        )
        self._tube_segments = self._segment_ids(
            cfg.calibration.limb_tubes, path="calibration.limb_tubes"
        )
        lo, hi = self.q_min[qi], self.q_max[qi]
        self._bounded = np.isfinite(lo) & np.isfinite(hi)
        #: The robot's configuration from the fit (:meth:`robot_configuration`).
        self.placement = SolePlacement(
            self.robot,
            self.template,
            st.plant,
            replant_distance=st.replant_distance if st.mode != "none" else None,
            replant_angle=st.replant_angle,
        )
        self._sole_ids = self.placement.sole_ids  # the fitted soles' frames
        self._contact_data = self.model.createData()
        self._init_recovery()  # em.branch_joints, em.reinit_* (checked)
        self._contact_feet: tuple[str, ...] = ()
        self._person_margin = np.nan  # the last frame's FrameResult.person_com_margin
        # The frame's cloud normals when computed in the background (_prepare, _take_normals).
        self._normals_job: Callable[[], np.ndarray] | None = None
        self._frame_normals: np.ndarray | None = None
        #: Template points moved to the segment on their side of a person's centre at the
        #: calibration (``calibration.centre_cuts``).
        self.recut_points = 0
        #: Template points ``calibration.rigid_segments`` moved to their segment's first joint.
        self.rigid_points = 0
        #: Template points ``calibration.limb_tubes`` replaced by the limbs' tubes.
        self.tube_points = 0
        # The template as built: every run (reset) starts from it, not from the surface the
        # previous subject left (calibration and online personalisation change it).
        self._template_state = self.template.surface_state()
        self.reset()

    # ------------------------------------------------------------------ state
    def _fit_limits(self, spec: dict[str, list[float]]) -> tuple[np.ndarray, np.ndarray]:
        """The fit's joint range (nq,): the robot's, narrowed by ``em.joint_limits``.

        Raises:
            ConfigError: a joint the robot does not have, or a range outside the robot's.
        """
        lo, hi = self.robot.q_min.copy(), self.robot.q_max.copy()
        model = self.robot.model
        for name, (a, b) in spec.items():
            self.robot.joint_index(name, path=f"em.joint_limits.{name}")  # a joint of the robot
            iq = model.joints[model.getJointId(name)].idx_q
            if a > hi[iq] or b < lo[iq]:
                raise ConfigError(
                    f"[{a}, {b}] rad lies outside the robot's range [{lo[iq]:.3f}, "
                    f"{hi[iq]:.3f}] of {name!r}; give a range that overlaps it.",
                    path=f"em.joint_limits.{name}",
                )
            lo[iq], hi[iq] = max(lo[iq], a), min(hi[iq], b)
        return lo, hi

    def _posture_joints(self, spec: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Configuration and velocity indices and rest angles of ``em.posture_joints``.

        Raises:
            ConfigError: a joint the robot does not have, a rest angle outside the fit's
                range (``em.joint_limits`` within the robot's), or a weight with no joint.
        """
        if self.config.em.posture_weight > 0 and not spec:
            raise ConfigError(
                f"em.posture_weight is {self.config.em.posture_weight} but no joint is listed to "
                "pull; list them with their rest angles, e.g. em.posture_joints: "
                "{waist_yaw_joint: 0.0}, or set the weight to 0.",
                path="em.posture_joints",
            )
        model = self.robot.model
        iq, iv, ref = [], [], []
        for name, angle in spec.items():
            path = f"em.posture_joints.{name}"
            self.robot.joint_index(name, path=path)  # a joint of the robot
            joint = model.joints[model.getJointId(name)]
            if not self.q_min[joint.idx_q] <= float(angle) <= self.q_max[joint.idx_q]:
                raise ConfigError(
                    f"rest angle {angle} rad of {name!r} lies outside the fit's range "
                    f"[{self.q_min[joint.idx_q]:.3f}, {self.q_max[joint.idx_q]:.3f}]; give an "
                    "angle within it.",
                    path=path,
                )
            iq.append(joint.idx_q)
            iv.append(joint.idx_v)
            ref.append(float(angle))
        return np.array(iq, dtype=int), np.array(iv, dtype=int), np.array(ref, float)

    def _segment_ids(
        self, names: list[str] | None, path: str = "calibration.personalize_segments"
    ) -> np.ndarray | None:
        """Indices of the template segments ``names`` (the config key ``path``).

        Raises:
            ConfigError: a name that is not one of the template's segments.
        """
        if names is None:
            return None
        known = list(self.template.segment_names)
        for n in names:
            if n not in known:
                raise ConfigError(
                    f"no template segment {n!r}.{close_matches_hint(n, known)} "
                    f"Segments: {', '.join(known)}.",
                    path=path,
                )
        return np.array([known.index(n) for n in names], dtype=int)

    def reset(self) -> None:
        """Forget the history and the subject; the template as it was built.

        The next :meth:`fit` calibrates again if enabled. The template is put back as it was
        when the fitter was built: calibration and online personalisation gave it the last
        subject's surface, which a new run would otherwise start from.
        """
        self.template.restore_surface(self._template_state)
        self.history: list[np.ndarray] = []
        self.sensor_position: np.ndarray | None = None
        self.calibrated = not self.config.calibration.enabled
        if self.calibrated:
            self.template.set_scales(self._fixed_scales())
        self._hip_memory = HipRuleState()
        self.placement.reset()
        self._anchors: dict[str, tuple[np.ndarray, float]] = {}
        self._centre_time: float | None = None  # time of the last frame with a centre stage
        self._personal_time: float | None = None  # ... and with online personalisation
        self.personalized_online = 0  # cloud points the template took while tracking
        self._sub: np.ndarray | None = None  # the frame's visible template points (_pose)
        self._frame_cloud: np.ndarray | None = None  # the frame's cloud (em.occlusion_confirm)
        self._silhouette: Silhouette | None = None  # its outline (em.silhouette_weight)
        self._sigmas: list[float] = []  # sigma of the last frames that were not lost
        self._good: np.ndarray | None = None  # the last such frame's fit
        self._last: FrameResult | None = None  # the last frame fitted (what a held one keeps)
        if self.stability_mode != "none":
            self.tracker.reset()
        self.command.reset()
        self._solver_clear.reset()
        self._solver.reset()

    def _fixed_scales(self) -> np.ndarray:
        spec = self.config.calibration.scales
        names = self.template.segment_names
        s = np.ones(len(names))
        if spec is None:
            return s
        if isinstance(spec, (int, float)) and not isinstance(spec, bool):
            return s * float(spec)
        if isinstance(spec, dict):
            for k, v in spec.items():
                if k not in names:
                    raise ConfigError(
                        f"unknown segment {k!r}; segments: {', '.join(names)}.",
                        path=f"calibration.scales.{k}",
                    )
                s[names.index(k)] = float(v)
            return s
        raise ConfigError(
            f"must be a number or {{segment: scale}}, got {spec!r}.", path="calibration.scales"
        )

    def _remember(self, q: np.ndarray) -> None:
        """Append ``q`` to the history the prediction reads (its last frames only)."""
        self.history.append(q.copy())
        del self.history[: -max(self.config.em.ar_window + 2, 4)]

    def _personalize_online(
        self,
        S: np.ndarray,
        Sn: np.ndarray | None,
        q: np.ndarray,
        sigma2: float,
        frame: CloudFrame | np.ndarray,
    ) -> None:
        """Online personalisation (``calibration.personalize_rate``) after a frame's fit.

        On a frame whose sigma is at most the median of the recent frames' (a fit as good as
        usual: a lagging or lost fit would attach the person's surface in the wrong place),
        at most ``personalize_rate`` times a second (by the frames' times; every frame without
        them), the robot's template points in view, of the ``personalize_segments``, take the
        frame's points (:meth:`Template.personalize_more`).
        """
        cal = self.config.calibration
        if not (cal.personalize and cal.personalize_rate > 0) or Sn is None:
            return
        if len(self._sigmas) < 3 or math.sqrt(sigma2) > float(np.median(self._sigmas)):
            return
        t = frame.t if isinstance(frame, CloudFrame) else None
        if t is not None and math.isfinite(t):
            last = self._personal_time
            if last is not None and t - last < 1.0 / float(cal.personalize_rate) - 1e-3:
                return
            self._personal_time = float(t)
        T = self.template
        visible = self._active(T.pose(q, jacobians=False))
        segs = self._personal_segments
        allowed = None if segs is None else np.isin(T.point_segment, segs)
        self.personalized_online += T.personalize_more(
            q, S, Sn, visible, max_distance=cal.personalize_distance, allowed=allowed
        )

    # ------------------------------------------------------------------ helpers
    def _prepare(
        self, frame: CloudFrame | np.ndarray, rng_seed: int
    ) -> tuple[np.ndarray, np.ndarray | None]:
        inp = self.config.input
        pts = frame.points if isinstance(frame, CloudFrame) else np.asarray(frame, float)
        nrm = frame.normals if isinstance(frame, CloudFrame) else None
        box = inp.crop
        S, Sn = prepare_cloud(
            pts,
            nrm,
            box_min=box["min"] if box else None,
            box_max=box["max"] if box else None,
            voxel=inp.voxel,
            max_points=inp.points,
            rng=np.random.default_rng(inp.seed + rng_seed),
        )
        if len(S) < MIN_CLOUD_POINTS:
            raise TooFewPoints(
                f"only {len(S)} cloud points left after cropping; check input.crop and the "
                "world frame (z up, floor at z = 0)." + crop_hint(pts, box),
                path="input.crop",
            )
        if Sn is None and self.config.em.refine_iterations > 0:
            if self.calibrated and overlap():
                # Only the refinement needs them: computed while the first stages run
                # (_take_normals joins), the same normals.
                self._normals_job = normals_in_background(S, self.sensor_position, inp.normals_k)
                return S, None
            Sn = estimate_normals(S, self.sensor_position, inp.normals_k)
        return S, Sn

    def _take_normals(self, Sn: np.ndarray | None) -> np.ndarray | None:
        """The frame's cloud normals: ``Sn``, or the ones computed in the background."""
        if Sn is not None:
            return Sn
        if self._normals_job is not None:
            job, self._normals_job = self._normals_job, None
            self._frame_normals = job()
        return self._frame_normals

    def _pose(
        self, q: np.ndarray, *, jacobians: bool = True, normals: bool = True
    ) -> PosedTemplate:
        """The template posed at ``q``: while a frame is fitted, its visible points only.

        Points the sensor cannot see get no posterior mass, so the frame's stages pose, sum
        and search over the visible ones alone (``self._sub``, set by :meth:`fit`): the same
        sums without their zero terms.
        """
        return self.template.pose(q, jacobians=jacobians, index=self._sub, normals=normals)

    def _use_visible(self, visible: np.ndarray) -> np.ndarray:
        """Fit the frame on the ``visible`` template points alone; the stages' active mask.

        With rigid skinning the frame poses only those points (:meth:`_pose`), all of them
        active; LBS templates pose every point and mask the hidden ones.
        """
        if len(self.template.blend):
            self._sub = None
            return visible
        self._sub = np.flatnonzero(visible)
        return np.ones(len(self._sub), bool)

    def visible(self, q: np.ndarray, cloud: np.ndarray | None = None) -> np.ndarray:
        """(M,) the template points that take part in a fit at pose ``q`` against ``cloud``.

        Those facing the sensor (``em.cull_backfaces``) and not hidden behind another part of
        the template (``em.occlusion_cell``); with ``em.occlusion_confirm`` and a ``cloud``
        (N, 3), a hidden point takes part all the same when the cloud shows no surface in
        front of it (:func:`behind_cloud`). The sensor's position is the one of the last
        :meth:`fit` (or set ``sensor_position``); without one every point takes part.
        """
        S = None if cloud is None else np.asarray(cloud, float).reshape(-1, 3)
        return self._visible(self.template.pose(np.asarray(q, float), jacobians=False), S)

    def _active(self, posed: PosedTemplate) -> np.ndarray:
        """:meth:`_visible` against the frame being fitted (its cloud, ``_frame_cloud``)."""
        return self._visible(posed, self._frame_cloud)

    def _visible(self, posed: PosedTemplate, cloud: np.ndarray | None) -> np.ndarray:
        """Template points the sensor can see: facing it, and not behind another part.

        With ``em.occlusion_confirm``, a hidden point counts as seen when ``cloud`` shows no
        surface in front of it (:func:`behind_cloud`).
        """
        em = self.config.em
        if not em.cull_backfaces or self.sensor_position is None:
            return np.ones(self.template.n_points, bool)
        view = posed.points - self.sensor_position
        active = np.einsum("ma,ma->m", posed.normals, view) < 0.0
        if em.occlusion_cell > 0:
            seen = visible_from(posed.points, self.sensor_position, em.occlusion_cell)
            if em.occlusion_confirm and cloud is not None:
                # Hidden by the template, but the cloud shows nothing in front: the part in
                # the way is not where the person's is, and the point takes part.
                seen |= ~behind_cloud(posed.points, cloud, self.sensor_position, em.occlusion_cell)
            active &= seen
        return active

    def _pulled(self, active: np.ndarray) -> np.ndarray:
        """Indices of the posed points the silhouette may pull.

        The ``active`` ones of the ``em.silhouette_segments`` (all segments when null).
        """
        idx = np.flatnonzero(active)
        if self._silhouette_segments is None:
            return idx
        T = self.template
        of = idx if self._sub is None else self._sub[idx]  # template point of each posed one
        return idx[np.isin(T.point_segment[of], self._silhouette_segments)]

    def silhouette(self, cloud: np.ndarray) -> Silhouette | None:
        """The :class:`Silhouette` of ``cloud`` (N, 3) the fit pulls by (``em.silhouette_weight``).

        Cells of ``em.occlusion_cell`` (2 cm if 0); points within one cell above the crop's
        floor are not pulled. None without a sensor position.
        """
        if self.sensor_position is None:
            return None
        em = self.config.em
        crop = self.config.input.crop
        cell = em.occlusion_cell if em.occlusion_cell > 0 else 0.02
        floor = (crop["min"][2] if crop is not None else -np.inf) + cell
        return Silhouette(
            np.asarray(cloud, float).reshape(-1, 3), self.sensor_position, cell, floor
        )

    def _prior(self, q: np.ndarray, q_prev: np.ndarray | None) -> float:
        r"""The EM objective's penalties: :math:`\lambda_r E_r + \lambda_c E_c + \lambda_q E_q`.

        :math:`E_q = \sum_j (\theta_j - \bar\theta_j)^2` over ``em.posture_joints`` while
        tracking (with ``q_prev``; the calibration frame has its own posture term).
        """
        out = 0.0
        if q_prev is not None and self.config.em.temporal_weight > 0:
            d = q[self._qi] - q_prev[self._qi]
            out += float(self.config.em.temporal_weight * d @ d)
        if self._contact_feet and self.config.em.contact_weight > 0:
            r, _ = self._contact_residual(q, jacobian=False)
            out += float(self.config.em.contact_weight * r @ r)
        if q_prev is not None and self.config.em.posture_weight > 0 and self._posture_q.size:
            d = q[self._posture_q] - self._posture_ref
            out += float(self.config.em.posture_weight * d @ d)
        return out

    def _contact_residual(self, q: np.ndarray, *, jacobian: bool) -> tuple[np.ndarray, Any]:
        r"""Contact residual of the supporting soles and its Jacobian (the term :math:`E_c`).

        For each supporting sole f with world rotation :math:`R_f`, normal :math:`n_f = R_f e_z`
        and forward axis :math:`x_f = R_f e_x`: the tilt :math:`(n_{f,x}, n_{f,y})` (the sines
        of its tilt, 0 when it lies flat) and, with ``contact_anchor`` once the sole has an
        anchor (its fitted place when it was put down), the slip
        :math:`(p_{f,xy} - a_{f,xy}) / \ell_c` and the heading change
        :math:`\psi_f - \psi_{a,f}`, :math:`\psi_f = \mathrm{atan2}(x_{f,y}, x_{f,x})`
        (:data:`CONTACT_LENGTH` :math:`\ell_c`: 1 cm of slip weighs like 0.1 rad of tilt).
        For a rotation :math:`\omega` of the sole, :math:`\dot n = \omega \times n`, so
        :math:`\partial n_{xy} / \partial\Delta = -[n]_{\times,xy} J_{f,\omega}`,
        :math:`\partial \psi / \partial\Delta = (x_x \dot x_y - x_y \dot x_x)/(x_x^2 + x_y^2)`
        with :math:`\dot x = -[x]_\times J_{f,\omega}`, and the slip's is
        :math:`J_{f,v,xy} / \ell_c` (sole frame's Jacobian, world axes).
        """
        model, data = self.model, self._contact_data
        feet = self._contact_feet
        anchors = self._anchors if self.config.em.contact_anchor else {}
        rows = sum(5 if f in anchors else 2 for f in feet)
        r = np.zeros(rows)
        Jr = np.zeros((rows, self.robot.nv)) if jacobian else None
        if jacobian:
            pin.computeJointJacobians(model, data, q)
        else:
            pin.forwardKinematics(model, data, q)
        k = 0
        for f in feet:
            fid = self._sole_ids[f]
            M = pin.updateFramePlacement(model, data, fid)
            n, x = M.rotation[:, 2], M.rotation[:, 0]
            r[k : k + 2] = n[:2]
            J = None
            if Jr is not None:
                J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
                Jr[k : k + 2] = (-pin.skew(n) @ J[3:])[:2]
            k += 2
            if f in anchors:
                axy, ayaw = anchors[f]
                r[k : k + 2] = (M.translation[:2] - axy) / CONTACT_LENGTH
                r[k + 2] = (math.atan2(x[1], x[0]) - ayaw + math.pi) % (2.0 * math.pi) - math.pi
                if Jr is not None and J is not None:
                    Jr[k : k + 2] = J[:2] / CONTACT_LENGTH
                    dx = -pin.skew(x) @ J[3:]
                    Jr[k + 2] = (x[0] * dx[1] - x[1] * dx[0]) / max(x[0] ** 2 + x[1] ** 2, 1e-12)
                k += 3
        return r, Jr

    def _update_anchors(self) -> None:
        """Anchor the fit's soles of the command's stance where the person put them down.

        :attr:`.placement.SolePlacement.fit_placed` of its stance (the person-sized soles,
        laid flat, at the moments the command's feet were put down): a foot put down is
        anchored there, a foot put down again (moved) is free for a frame, a lifted one is
        freed, so the fit and the command agree on when a foot stands and moves.
        """
        pl = self.placement
        self._anchors = {
            f: (pl.fit_placed[f].translation[:2].copy(), pl.heading(pl.fit_placed[f]))
            for f in pl.stance
        }

    def _add_priors(
        self,
        H: np.ndarray,
        g: np.ndarray,
        q: np.ndarray,
        q_prev: np.ndarray | None,
        sigma2: float,
    ) -> None:
        r"""Add the penalties of :meth:`_prior`, linearized at ``q``, to the QP's (nv) block.

        The QP is the M-step objective times :math:`\sigma^2` (:meth:`Template.normal_equations`),
        so a penalty :math:`\lambda \|r + J\Delta\|^2` adds :math:`2\sigma^2\lambda J^\top J`
        to H and :math:`2\sigma^2\lambda J^\top r` to g (temporal term: J = I on the joints).
        """
        em = self.config.em
        if q_prev is not None and em.temporal_weight > 0:
            w = 2.0 * sigma2 * em.temporal_weight
            H[self._vi, self._vi] += w
            g[self._vi] += w * (q[self._qi] - q_prev[self._qi])
        if self._contact_feet and em.contact_weight > 0:
            r, Jr = self._contact_residual(q, jacobian=True)
            w = 2.0 * sigma2 * em.contact_weight
            nv = self.robot.nv
            H[:nv, :nv] += w * (Jr.T @ Jr)
            g[:nv] += w * (Jr.T @ r)
        if q_prev is not None and em.posture_weight > 0 and self._posture_q.size:
            w = 2.0 * sigma2 * em.posture_weight
            H[self._posture_v, self._posture_v] += w
            g[self._posture_v] += w * (q[self._posture_q] - self._posture_ref)

    def sole_heights(self, q: np.ndarray) -> dict[str, float]:
        """World height of each sole of the fitted (HUMROB) model."""
        pin.framesForwardKinematics(self.model, self.template.data, q)
        return {
            f: float(self.template.data.oMf[i].translation[2]) for f, i in self._sole_ids.items()
        }

    # ------------------------------------------------------------------ the QP step
    def _joint_step_bounds(self, qp: QPProblem, q: np.ndarray) -> np.ndarray:
        r"""Set the step's bounds (eq. 17); return the bounded joints' tangent indices.

        :math:`\theta_{min} - \theta \le \Delta \le \theta_{max} - \theta` on the bounded
        joints (widened to 0 where ``q`` is outside), none on the other variables.
        """
        vi, qi = self._vi[self._bounded], self._qi[self._bounded]
        qp.lb[...], qp.ub[...] = -np.inf, np.inf
        qp.lb[vi] = np.minimum(self.q_min[qi] - q[qi], 0.0)
        qp.ub[vi] = np.maximum(self.q_max[qi] - q[qi], 0.0)
        return vi

    def _e_step(
        self, S: np.ndarray, posed: PosedTemplate, active: np.ndarray, sigma2: float, **extra: Any
    ) -> EStep:
        """:func:`e_step` with the fit's ``em.outlier_weight``, ``estep`` and ``neighbors``."""
        em = self.config.em
        return e_step(
            S,
            posed.points,
            active,
            sigma2,
            em.outlier_weight,
            mode=em.estep,
            neighbors=em.neighbors,
            **extra,
        )

    def _damping(self, H: np.ndarray) -> float:
        """Levenberg damping of the pose block: ``em.damping`` times its mean diagonal."""
        nv = self.robot.nv
        return self.config.em.damping * max(float(np.trace(H[:nv, :nv])) / nv, 1e-12)

    def _set_rows(self, qp: QPProblem, q: np.ndarray, with_rows: bool) -> None:
        """The support-polygon rows on the QP's pose variables (none: free rows)."""
        if not self._n_rows:
            return
        qp.C[...] = 0.0
        if with_rows and self.rows.support.feet:
            C, lo, up = self.rows.rows(q)
            qp.C[:, : self.robot.nv], qp.l[...], qp.u[...] = C, lo, up
        else:
            qp.l[...], qp.u[...] = -np.inf, np.inf

    def _solve_step(
        self,
        H: np.ndarray,
        b: np.ndarray,
        q: np.ndarray,
        q_prev: np.ndarray | None,
        sigma2: float,
        with_rows: bool,
    ) -> np.ndarray | None:
        qp = self._qp
        nv = self.robot.nv
        qp.H[...] = H
        qp.g[...] = -b
        self._add_priors(qp.H, qp.g, q, q_prev, sigma2)
        qp.H[np.diag_indices(nv)] += self._damping(H)
        vi = self._joint_step_bounds(qp, q)
        self._set_rows(qp, q, with_rows)
        sol = self._solver.solve(qp)
        if sol.x is None or not np.all(np.isfinite(sol.x)):
            return None
        x = sol.x
        x[vi] = np.clip(x[vi], qp.lb[vi], qp.ub[vi])
        return x

    def _stable(self, q: np.ndarray) -> bool:
        if self._n_rows == 0 or not self.rows.support.feet:
            return True
        return self.rows.margin_of(q) >= -0.5 * self.rows.margin - 1e-9

    def _restore_balance(self, q: np.ndarray) -> tuple[np.ndarray, bool]:
        """Smallest joint change putting the robot's CoM back in the shrunk region (a few QPs)."""
        if self._n_rows == 0 or not self.rows.support.feet or self.rows.margin_of(q) >= 0:
            return q, True
        nv = self.robot.nv
        qp = QPProblem(nv, self._n_rows)
        for _ in range(8):
            qp.H[...] = np.eye(nv)
            qp.H[:6, :6] *= 1e3  # balance by the joints, not by moving the (free) base
            qp.g[...] = 0.0
            self._joint_step_bounds(qp, q)
            C, lo, up = self.rows.rows(q)
            qp.C[...], qp.l[...], qp.u[...] = C, lo, up
            sol = self._solver_restore.solve(qp)
            if sol.x is None:
                return q, False
            q = pin.integrate(self.model, q, sol.x)
            if self.rows.margin_of(q) >= -1e-6:
                return q, True
        return q, self.rows.margin_of(q) >= -0.5 * self.rows.margin

    # ------------------------------------------------------------------ EM loop
    def _em_stage(
        self,
        stage: str,
        S: np.ndarray,
        Sn: np.ndarray | None,
        q: np.ndarray,
        sigma2: float,
        q_prev: np.ndarray | None,
        active: np.ndarray,
        iterations: int,
        log: list[IterationLog],
        neighbours: _Neighbours | None = None,
        *,
        silhouette: bool = False,
    ) -> tuple[np.ndarray, float, float]:
        """EM iterations of one stage (``neighbours``: kd-tree pairs shared with other stages).

        ``silhouette``: with the pulls of the points outside the frame's silhouette
        (``em.silhouette_weight``, :class:`Silhouette`) added to the M-steps' objective.
        """
        em = self.config.em
        T = self.template
        lam = em.normal_weight if stage == "refine" else 0.0
        ell = em.normal_scale
        use_rows = self.stability_mode == "qp"
        nll = np.nan
        neighbours = neighbours if neighbours is not None else _Neighbours(self)
        eta = 1.0
        for _ in range(iterations):
            posed = self._pose(q, normals=lam > 0)
            est = neighbours.e_step(
                S,
                posed,
                active,
                sigma2,
                Sn=Sn if lam > 0 else None,
                Vn=posed.normals if lam > 0 else None,
                normal_weight=lam,
                normal_scale=ell,
            )
            nll = est.nll
            J6 = T.joint_jacobians()
            E = est.Px - est.P1[:, None] * posed.points
            En = None if est.Pn is None else est.Pn / ell - est.P1[:, None] * posed.normals
            P1 = est.P1
            if silhouette and self._silhouette is not None:
                est.silhouette = self._silhouette.pulls(
                    posed.points, self._pulled(active), em.silhouette_weight
                )
                P1, E = est.silhouette.add_to(P1, E, posed.points)
            H, b = T.normal_equations(
                posed, J6, P1, E, normal_weight=lam * ell * ell, P1n=est.P1, En=En
            )
            prior0 = self._prior(q, q_prev)
            obj0 = est.q_value(posed, sigma2) + prior0
            step = self._solve_step(H, b, q, q_prev, sigma2, use_rows)
            if step is None:
                log.append(IterationLog(stage, nll, nll + prior0, 0.0, 0, sigma2, 0.0))
                break
            trial = self._line_search(est, q, step, q_prev, sigma2, obj0, eta)
            if not trial.accepted:
                log.append(
                    IterationLog(
                        stage, nll, nll + prior0, 0.0, trial.halvings, sigma2, 0.0, trial.increase
                    )
                )
                break
            alpha, q_try = trial.alpha, trial.q
            eta = min(eta * 1.25, em.overrelaxation) if alpha >= max(eta, 1.0) else 1.0
            move, base = self._moves(q, q_try)
            q = q_try
            sigma2 = max(est.sigma2_update(trial.posed), em.sigma2_min)
            log.append(
                IterationLog(
                    stage, nll, nll + prior0, alpha, trial.halvings, sigma2, move, trial.increase
                )
            )
            if max(move, base) < em.tolerance:
                break
        return q, sigma2, nll

    def _line_search(
        self,
        est: EStep,
        q: np.ndarray,
        step: np.ndarray,
        q_prev: np.ndarray | None,
        sigma2: float,
        obj0: float,
        eta: float,
    ) -> _Trial:
        """Step length of an M-step (module docstring, *Monotonicity*).

        Over-relaxation first (alpha = ``eta`` > 1, kept only if Q still decreases), then the
        plain step, then ``em.max_backtracks`` halvings; a step must also keep the robot stable.
        """
        em = self.config.em
        halvings, increase = 0, False
        alphas = ([eta] if eta > 1.0 and em.max_backtracks > 0 else []) + [1.0]
        alpha = alphas[0]
        while True:
            q_try = self._clip(pin.integrate(self.model, q, alpha * step))
            posed_try = self._pose(q_try, jacobians=False, normals=est.Pn is not None)
            obj = est.q_value(posed_try, sigma2) + self._prior(q_try, q_prev)
            ok = obj <= obj0
            if alpha == 1.0 and halvings == 0 and not ok:
                increase = True
            if (ok and self._stable(q_try)) or em.max_backtracks == 0:
                return _Trial(True, alpha, halvings, increase, q_try, posed_try)
            if alpha > 1.0:
                alpha = 1.0
                continue
            if halvings >= em.max_backtracks:
                return _Trial(False, alpha, halvings, increase, q_try, posed_try)
            alpha *= 0.5
            halvings += 1

    def _moves(self, q: np.ndarray, q_new: np.ndarray) -> tuple[float, float]:
        """Largest joint move [rad] and largest base move from ``q`` to ``q_new`` (V.C)."""
        applied = self.model_difference(q, q_new)
        move = float(np.max(np.abs(applied[self._vi]), initial=0.0))
        base = float(np.max(np.abs(applied[: self.robot.root_nv]), initial=0.0))
        return move, base

    def final_nll(
        self,
        S: np.ndarray,
        q: np.ndarray,
        sigma2: float,
        active: np.ndarray,
        neighbours: _Neighbours | None = None,
    ) -> float:
        """Eq. 3 at ``q`` (same E-step mode as the fit; ``neighbours``: the fit's kept pairs)."""
        posed = self._pose(q, jacobians=False, normals=False)
        if neighbours is not None:
            return neighbours.e_step(S, posed, active, sigma2).nll
        return self._e_step(S, posed, active, sigma2).nll

    # ------------------------------------------------------------------ prediction
    def predict(self) -> np.ndarray:
        """Initial pose of the next frame: third-order auto-regression of the fitted poses (V.B)."""
        h = self.history
        if not h:
            return self.robot.q_reference.copy()
        if self.config.em.prediction == "constant" or len(h) < 2:
            return h[-1].copy()
        model = self.model
        if self.config.em.prediction == "velocity":  # q_t + (q_t - q_{t-1})
            return pin.integrate(model, h[-1], pin.difference(model, h[-2], h[-1]))
        W = self.config.em.ar_window
        hh = h[-(W + 1) :]
        u = np.array([pin.difference(model, a, b) for a, b in zip(hh[:-1], hh[1:], strict=True)])
        if len(u) < 3:
            coef = np.array([0.5, 0.0])
        else:
            X = np.stack([u[1:-1].reshape(-1), u[:-2].reshape(-1)], axis=1)
            y = u[2:].reshape(-1)
            ridge = 1e-3 * max(float(y @ y), 1e-12)
            coef = np.linalg.solve(X.T @ X + ridge * np.eye(2), X.T @ y)
            tot = np.abs(coef).sum()
            if tot > 1.0:
                coef /= tot
        u_pred = coef[0] * u[-1] + (coef[1] * u[-2] if len(u) >= 2 else 0.0)
        return pin.integrate(model, h[-1], u_pred)

    def model_difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """Tangent step ``q1 - q0`` (nv,)."""
        return pin.difference(self.model, q0, q1)

    def _clip(self, q: np.ndarray) -> np.ndarray:
        q = q.copy()
        qi = self._qi
        q[qi] = np.clip(q[qi], self.q_min[qi], self.q_max[qi])
        return q

    # ------------------------------------------------------------------ robot output
    def robot_configuration(self, q_fit: np.ndarray, support: Support) -> np.ndarray:
        """Robot configuration: the fitted joints, the supporting soles flat on the floor (z = 0).

        :meth:`.placement.SolePlacement.configuration` (``stability.plant``).
        """
        return self.placement.configuration(q_fit, support)

    # ------------------------------------------------------------------ one frame
    def fit(self, frame: CloudFrame | np.ndarray, *, index: int = 0) -> FrameResult:
        """Fit one frame (calibrating on the first one) and return its :class:`FrameResult`."""
        t0 = time.perf_counter()
        em = self.config.em
        self._sub = None
        self._normals_job, self._frame_normals = None, None
        try:
            S, Sn = self._prepare(frame, index)
            self._frame_cloud = S
            self._silhouette = self.silhouette(S) if self.config.em.silhouette_weight > 0 else None
        except TooFewPoints:
            if not (self.calibrated and self.history and self._last is not None):
                raise  # nothing to hold: the first frame must show the person
            # The person out of view (walked past the sensor, occluded): hold the last pose
            # and say so; the run goes on with the next frame that shows them.
            self._remember(self.history[-1])
            last = self._last
            return replace(
                last,
                q_fit=last.q_fit.copy(),
                q_robot=last.q_robot.copy(),
                iterations=0,
                status="held",
                log=[],
                time=time.perf_counter() - t0,
                rule="",
                command_steps=0,
            )
        log: list[IterationLog] = []
        q_prev = self.history[-1] if self.history else None
        if not self.calibrated:
            q = self.calibrate(S, Sn)
            sigma2 = max(self.calibration_sigma2, em.sigma2_min)
            q_prev = None
        else:
            q = self._clip(self.predict()) if self.history else self._clip(self._initial_pose(S))
            sigma2 = em.sigma2_init
            if em.temporal_reference == "prediction" and q_prev is not None:
                q_prev = q.copy()
        status = "ok"
        support = Support()
        self._contact_feet = ()
        if self.stability_mode != "none":
            heights = self.sole_heights(q)
            support = self.tracker.update(heights)
            top = em.contact_height
            self._contact_feet = tuple(f for f in support.feet if top is None or heights[f] <= top)
            self.rows.set_support(support, q)
            if self.stability_mode == "qp":
                q, ok = self._restore_balance(q)
                if not ok:
                    status = "relaxed"
        q, sigma2, nll = self._stages(S, Sn, q, sigma2, q_prev, frame, log, centres=True)
        Sn = self._take_normals(Sn)
        if self._branches:
            q, sigma2, nll = self._switch_branches(S, Sn, (q, sigma2, nll), log)
        if self._lost(sigma2) or self._at_limits(q):
            q, sigma2, nll = self._reinitialise(S, Sn, (q, sigma2, nll), log)
        else:
            self._sigmas.append(math.sqrt(sigma2))
            self._good = q.copy()
            del self._sigmas[: -max(self.config.em.reinit_window, 1)]
            self._personalize_online(S, Sn, q, sigma2, frame)
        self._sub = None
        rule = ""
        if self.stability_mode == "hip_offset":
            self.rows.set_support(support, q)
            q, rule = hip_offset_rule(self.rows, q, self._hips, self._hip_memory)
        if self.stability_mode == "qp" and support.feet:
            # The stages keep the CoM over the polygon of the soles where the frame started;
            # a fit that moved the soles can end with the CoM just outside their polygon:
            # the smallest joint change puts it back, as at the frame's start.
            self.rows.set_support(support, q)
            if self.rows.margin_of(q, full=True) < 0:
                q, _ = self._restore_balance(q)
        q_robot = self.robot_configuration(q, support)
        q_robot, clearance, contacts = self._command(q_robot, q)
        if self.stability_mode != "none":
            self._update_anchors()
        margin = np.nan
        if self.stability_mode != "none" and support.feet:
            self.rows.set_support(support, q)
            margin = self.rows.margin_of(q, full=True)
            if margin < 0 and status == "ok" and self.stability_mode == "qp":
                status = "relaxed"
        self._remember(q)
        self._last = FrameResult(
            q,
            q_robot,
            sigma2,
            nll,
            len(log),
            support,
            margin,
            status,
            log,
            time.perf_counter() - t0,
            rule,
            clearance,
            self.command.steps,
            contacts,
            self._person_margin,
        )
        return self._last

    def _command(
        self, q_robot: np.ndarray, q_fit: np.ndarray
    ) -> tuple[np.ndarray, float, tuple[str, ...]]:
        """The command the robot can hold (:meth:`.command.CommandProjection.follow`).

        The placed configuration ``q_robot`` when its links are apart (``self_collision``),
        its stance's soles on their placements and, with ``stability.mode: qp``, its CoM over
        their polygon (:meth:`_command_balance`); otherwise the nearest such. Where a stance
        sole cannot be put on its placement within the steps (a stance wider than G1's legs
        reach, a pair in the way), the command stands on the soles that are (else on the
        primary's) and is balanced over those: the feet it records as contacts are the feet
        its CoM is over. Returns ``(q_robot, clearance [m] (NaN without self_collision),
        contacts)``: the feet whose soles are on their placements.
        """
        pl = self.placement
        start = None if self._last is None else self._last.q_robot
        self._person_margin = np.nan
        stance = tuple(pl.stance)
        q, gap = self._follow(q_robot, start, q_fit, stance)
        contacts = pl.on_placements(q, stance, CONTACT_TOLERANCE)
        if stance and contacts != stance:
            held = contacts or stance[:1]
            first, first_gap, steps = q, gap, self.command.steps
            q, gap = self._follow(q_robot, start, q_fit, held)
            steps += self.command.steps
            if gap < -CLEAR_TOLERANCE <= first_gap:
                # Not clear from the last command: from the first try, which is (the steps
                # then never enter a pair).
                q, gap = self._follow(q_robot, first, q_fit, held)
                steps += self.command.steps
            self.command.steps = steps  # the frame's, FrameResult.command_steps
            contacts = pl.on_placements(q, held, CONTACT_TOLERANCE)
        clearance = np.nan if self.command.constraint is None else gap
        return q, clearance, contacts

    def _follow(
        self,
        q_robot: np.ndarray,
        start: np.ndarray | None,
        q_fit: np.ndarray,
        feet: tuple[str, ...],
    ) -> tuple[np.ndarray, float]:
        """:meth:`.command.CommandProjection.follow` with the soles and balance of ``feet``."""
        pl = self.placement
        return self.command.follow(
            q_robot,
            start,
            [(pl.sole_frame(f), pl.placed[f]) for f in feet],
            self.q_min,
            self.q_max,
            self._solver_clear,
            lambda qq: self._command_balance(qq, q_fit, feet),
        )

    def _command_balance(
        self, q_robot: np.ndarray, q_fit: np.ndarray, feet: tuple[str, ...]
    ) -> tuple[StabilityRows, bool] | None:
        """The balance rows of the command standing on ``feet``: its CoM kept over them.

        ``None`` without feet or ``stability.mode: qp``. The robot balances over its feet
        on every frame, as the controller's support-polygon constraint does (Wang 2017 eq.
        18-19): also where the person's CoM is outside the same feet (a walk's weight between
        steps, a foot just lifted), which a robot cannot stand statically. That person's
        margin (at the fitted configuration, G1's masses, its soles under the person's
        pelvis, projected along the vertical) is kept as
        :attr:`FrameResult.person_com_margin`.
        """
        rows = self._command_rows
        if rows is None or not feet:
            return None
        sup = Support(list(feet), feet[0])
        rows.set_support(sup, q_fit)
        self._person_margin = rows.margin_of(q_fit, full=True)
        rows.set_support(sup, q_robot)
        return rows, True

    def _stages(
        self,
        S: np.ndarray,
        Sn: np.ndarray | None,
        q: np.ndarray,
        sigma2: float,
        q_prev: np.ndarray | None,
        frame: CloudFrame | np.ndarray | None,
        log: list[IterationLog],
        *,
        centres: bool,
        tag: str = "",
        iterations: int | None = None,
        refine: bool = True,
    ) -> tuple[np.ndarray, float, float]:
        """The EM stages of a frame from ``q``: linear, joint centres, refinement.

        ``iterations`` caps the linear stage (default ``em.max_iterations``); ``refine``: False
        skips the refinement. Returns the fit, its sigma^2 and the NLL (eq. 3) after the
        position stages.
        """
        em = self.config.em
        n_linear = em.max_iterations if iterations is None else iterations
        visible = self._active(self.template.pose(q, jacobians=False))
        active = self._use_visible(visible)
        # One set of kd-tree pairs for the position stages of the frame (searched again where
        # stale, _Neighbours): the cloud and the active points are the same throughout.
        neighbours = _Neighbours(self)
        q, sigma2, _ = self._em_stage(
            tag + "linear", S, Sn, q, sigma2, q_prev, active, n_linear, log, neighbours
        )
        for p in range(1, em.visibility_passes):
            # The visible template points depend on the pose: recompute them at the fit and go on
            # (a new objective: monotonicity holds within each pass).
            new_visible = self._active(self.template.pose(q, jacobians=False))
            if np.array_equal(new_visible, visible):
                break
            visible = new_visible
            active = self._use_visible(visible)
            neighbours = _Neighbours(self)
            q, sigma2, _ = self._em_stage(
                f"{tag}linear{p + 1}",
                S,
                Sn,
                q,
                sigma2,
                q_prev,
                active,
                em.max_iterations,
                log,
                neighbours,
            )
        if centres and self._estimate_centres and q_prev is not None and frame is not None:
            if self._centre_due(frame):
                q, sigma2 = self._centre_stage(S, q, sigma2, q_prev, active, log, neighbours)
        nll = self.final_nll(S, q, sigma2, active, neighbours)
        if refine and em.refine_iterations:
            Sn = self._take_normals(Sn)
        if refine and em.refine_iterations and Sn is not None:
            q, sigma2, _ = self._em_stage(
                tag + "refine",
                S,
                Sn,
                q,
                sigma2,
                q_prev,
                active,
                em.refine_iterations,
                log,
                silhouette=True,
            )
        return q, sigma2, nll

    def _trial(
        self,
        S: np.ndarray,
        Sn: np.ndarray | None,
        q0: np.ndarray,
        q_prev: np.ndarray | None,
        log: list[IterationLog],
        tag: str,
        *,
        sigma2: float | None = None,
        iterations: int | None = None,
        refine: bool = True,
    ) -> tuple[np.ndarray, float, float]:
        """:meth:`_stages` of a candidate start (re-initialisation, shoulder branches).

        No centre stage; from ``em.sigma2_init`` unless ``sigma2`` is given; the iterations go
        to ``log`` under ``tag``.
        """
        s2 = self.config.em.sigma2_init if sigma2 is None else sigma2
        return self._stages(
            S, Sn, q0, s2, q_prev, None, log, centres=False, tag=tag,
            iterations=iterations, refine=refine,
        )  # fmt: skip

    # ------------------------------------------------------------------ a sequence
    def run(
        self,
        sequence: CloudSequence,
        *,
        progress: bool = False,
        callback: Callable[[int, FrameResult], None] | None = None,
    ) -> tuple[RobotTrajectory, list[FrameResult]]:
        """Fit every frame of ``sequence``; return the run (RobotTrajectory) and frame results."""
        self.reset()
        self.sensor_position = sequence.sensor_position
        if self.sensor_position is None and self.config.input.sensor_position is not None:
            self.sensor_position = np.asarray(self.config.input.sensor_position, float)
        frames: Iterable[tuple[int, CloudFrame]] = enumerate(sequence.frames)
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(sequence), unit="frame", desc="retarget-cloud")
        results: list[FrameResult] = []
        for i, fr in frames:
            res = self.fit(fr, index=i)
            results.append(res)
            if callback is not None:
                callback(i, res)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(sigma=f"{math.sqrt(res.sigma2) * 1000:.1f}mm", it=res.iterations)
        if bar is not None:
            bar.close()
        return self.trajectory(sequence, results), results

    def trajectory(self, sequence: CloudSequence, results: list[FrameResult]) -> RobotTrajectory:
        """The run file content (``docs/formats.md``) of fitted frames."""
        robot = self.robot
        t = sequence.t[: len(results)]
        q = np.array([r.q_robot for r in results])
        v = np.zeros((len(results), robot.nv))
        for k in range(1, len(results)):
            dt = max(t[k] - t[k - 1], 1e-9)
            v[k] = pin.difference(robot.model, q[k - 1], q[k]) / dt
        feet = list(robot.feet)
        contacts = np.array([[f in r.contacts for f in feet] for r in results], bool).reshape(
            len(results), len(feet)
        )
        robot_spec = self.config.robot
        controller_yaml = yaml.safe_dump(
            {
                "name": f"{self.config.name}_robot",
                "description": "Robot model of a point-cloud run (qpretarget retarget-cloud); the "
                "fit's own configuration is in meta.cloud_config.",
                "robot": robot_spec,
                "tasks": [{"type": "posture", "name": "posture", "weight": 1.0}],
                "constraints": [{"type": "joint_limits"}],
            },
            sort_keys=False,
        )
        extra = {
            "cloud/q_fit": np.array([r.q_fit for r in results]),
            "cloud/scales": self.template.scales.copy(),
            "cloud/segment_names": np.array(self.template.segment_names, dtype=str),
            "cloud/centres": self.template.centres(),
            "cloud/centre_joints": np.array(
                [self.model.names[int(g.max())] for g in self.template.articulations], dtype=str
            ),
            "cloud/sigma2": np.array([r.sigma2 for r in results]),
            "cloud/nll": np.array([r.nll for r in results]),
            "cloud/iterations": np.array([r.iterations for r in results]),
            "cloud/com_margin": np.array([r.com_margin for r in results]),
            "cloud/backtracks": np.array([sum(x.backtracks for x in r.log) for r in results]),
            "cloud/clearance": np.array([r.clearance for r in results]),
            "cloud/command_steps": np.array([r.command_steps for r in results]),
            "cloud/person_com_margin": np.array([r.person_com_margin for r in results]),
        }
        human_q = sequence.meta.get("human_q")  # make-cloud's truth: evaluate scores the arms
        if human_q is not None and np.ndim(human_q) == 2 and len(human_q) >= len(results):
            from .measures import HUMAN_Q_KEY

            extra[HUMAN_Q_KEY] = np.asarray(human_q, float)[: len(results)]
        return RobotTrajectory(
            t=t,
            q=q,
            v=v,
            joint_names=list(robot.joint_names),
            robot=robot_spec if isinstance(robot_spec, str) else str(robot.urdf_path),
            config_yaml=controller_yaml,
            contacts=contacts,
            foot_names=feet,
            status=np.array([r.status for r in results]),
            solve_time=np.array([r.time for r in results]),
            extra=extra,
            meta={
                "command": "retarget-cloud",
                "source": sequence.source,
                "cloud_config": self.config.to_yaml(),
                "template_points": self.template.n_points,
                "cloud_points": self.config.input.points,
                "scales": dict(
                    zip(self.template.segment_names, map(float, self.template.scales), strict=True)
                ),
            },
        )


__all__ = [
    "CloudRetargeter",
    "EStep",
    "FrameResult",
    "IterationLog",
    "e_step",
    "search_coordinates",
]
