# SPDX-License-Identifier: Apache-2.0
"""Configuration of point-cloud retargeting (``configs/cloud_*.yaml``, ``docs/point_clouds.md``).

One YAML file with the robot, the QP solver and five sections; every key has a default (the
paper's value where it gives one, Wang 2017 V.B-C) and is checked with the YAML path in errors::

    name: g1_cloud
    robot: g1
    solver: {name: proxsuite, eps_abs: 1.0e-9}
    input: {rate: 30, crop: {min: [-3, -3, 0.02], max: [3, 3, 2.5]}, voxel: 0.01, points: 2500}
    template: {points: 5000, meshes: visual, skinning: rigid}
    calibration: {enabled: true, scale_bounds: [0.5, 2.5]}
    em: {outlier_weight: 0.1, sigma2_init: 4.0e-4, tolerance: 0.002, temporal_weight: 1000.0}
    stability: {mode: qp, region: polygon, margin: 0.01}
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..constraints.self_collision import SelfCollision
from ..errors import ConfigError, close_matches_hint
from ..registry import build_from_spec
from ..yamlio import read_yaml_file
from .command import fit_spec


@dataclass
class InputConfig:
    """How clouds are read and reduced.

    Attributes:
        rate: frame rate [Hz] for inputs without times.
        crop: ``{min: [x, y, z], max: [x, y, z]}`` world box [m] (None: keep all).
        voxel: voxel edge [m] of the averaging grid (0: off).
        points: cloud points per frame after subsampling (Wang 2017 V.B: 2,500).
        normals_k: neighbours of the PCA normal estimate.
        intrinsics: ``[fx, fy, cx, cy]`` for depth images without their own.
        camera_pose: 4x4 camera-to-world transform for depth images.
        depth_scale: metres per depth unit of integer depth images.
        sensor_position: optical centre [x, y, z] in the world when the input does not say it.
        seed: random seed of the subsampling.
    """

    rate: float | None = None
    crop: dict[str, list[float]] | None = None
    voxel: float = 0.01
    points: int = 2500
    normals_k: int = 10
    intrinsics: Any = None
    camera_pose: Any = None
    depth_scale: float | None = None
    sensor_position: list[float] | None = None
    seed: int = 0


@dataclass
class TemplateConfig:
    """The HUMROB template (Wang 2017 IV.A).

    Attributes:
        points: template points (Wang 2017 V.B: 5,000).
        meshes: ``visual`` or ``collision`` link meshes.
        skinning: ``rigid`` or ``lbs`` (Wang 2017 eq. 9).
        blend_radius: LBS blend distance around each joint [m].
        seed: sampling seed.
        exclude_links: links left out of the template.
        link_density_exponent: points per link proportional to its outer area to this power
            (1: even density over the body; 0.5: the small distal links get more points).
    """

    points: int = 5000
    meshes: str = "visual"
    skinning: str = "rigid"
    blend_radius: float = 0.04
    seed: int = 0
    exclude_links: list[str] = field(default_factory=list)
    link_density_exponent: float = 0.5


@dataclass
class CalibrationConfig:
    r"""Limb lengths and initial pose from the first frame.

    Attributes:
        enabled: estimate the segment scales from the first frame (else use ``scales``).
        scales: fixed scales: one number for all segments or ``{segment: value}`` (1: the robot).
        scale_bounds: ``[low, high]`` bounds of every scale.
        scale_prior: weight pulling the scales towards their mean (0: none).
        iterations: EM iterations of each calibration phase (one common scale, then one per
            segment).
        initial_yaw: heading of the first fit [rad], or ``auto`` (face the sensor).
        initial_joints: joint values [rad] of the first fit's start (over the reference posture).
        personalize: after the fit, replace the template points the sensor saw by the frame's
            own points, attached to the joint of their nearest template point (Wang 2017 IV.A:
            the personalised model with transferred skinning).
        personalize_distance: observed points farther than this from the fitted template are
            left out (outliers) [m].
        personalize_rate: while tracking, at most this many times a second [Hz], on a frame
            fitted at least as well as the recent ones (sigma at most their median), the
            template points that are still the robot's surface and that the sensor sees now
            take the frame's own points (:meth:`~qpretarget.cloud.template.Template.
            personalize_more`): the parts the calibration frame did not show (sides, back,
            raised arms) become the person's as they come into view. 0: off (the calibration
            frame's surface only).
        personalize_segments: the template segments (:attr:`~qpretarget.cloud.template.
            Template.segment_names`: ``pelvis``, ``torso``, ``upper_arm``...) whose robot
            points ``personalize_rate`` may replace; ``null``: all of them. The shipped config
            takes the trunk's alone: the trunk's heading is what the worst arm frames were made
            of, while the limbs, personalised too, moved the fit's arms further off.
        rigid_segments: template segments made one rigid body after the calibration: their
            points on joints inside the segment ride with the segment's first joint
            (:meth:`~qpretarget.cloud.template.Template.attach_rigidly`). G1's torso segment
            holds its shoulder-pitch links, which carry the person's chest and shoulder surface
            after the calibration and would swing it about with the arms' pitch. The shipped
            config: ``[torso]``.
        posture_weight: :math:`\lambda_p` on the squared joint change from the calibration
            posture (``initial_joints``) while calibrating (0: off).
        joint_centres: go on estimating where the subject's joint centres sit in the template
            while tracking (each frame adds what its bent joints show; the calibration frame
            cannot show a centre's place along a straight limb).
        centre_joints: joints whose articulation centres are estimated (each names its
            articulation, e.g. ``left_elbow_joint``); ``null``: every articulation that has
            one further down its chain (not wrists and ankles).
        centre_prior: prior standard deviation of a joint centre's offset [m].
        centre_iterations: most joint EM iterations on pose and centres per frame (they stop
            when no joint moves more than ``em.tolerance`` and no centre more than 0.5 mm).
        centre_bound: largest offset of a joint centre [m] (along its limb, or per axis).
        centre_information: weight of a frame's information on the centres (1: all of it, as
            if every cloud point were an independent measurement; below 1 discounts the
            correlated errors of neighbouring points, so that the frames that bend a joint
            most, which come later, can still move an estimate the first frames made).
        centre_axes: ``limb``: each articulation's centre moves along its limb only (the line
            a straight limb does not show); ``free``: in 3-D.
        centre_rate: the centre stage runs on at most this many frames per second [Hz] (the
            others track the pose alone; null: every frame). ``centre_information`` counts a
            frame's information as if frames came at 10 Hz; at 30 Hz consecutive frames show
            nearly the same bends, and running on each would count them three times.
        centre_model: where the centres start (the prior mean of the estimate):
            ``robot``: the robot's own centres (offsets 0); ``anthropometric``: a person's,
            from segment-length fractions of the standing height (Winter's table,
            :mod:`qpretarget.cloud.anthropometry`), placed along each limb of the calibrated
            template from the fingertips (arms) or the floor (legs).
        centre_symmetric: one offset for each left/right pair of articulations (with
            ``centre_axes: limb``): a person's left and right joint centres sit alike, and
            each side's frames then inform both.
        centre_cuts: where a limb's surface is cut into segments once its centres are moved
            at calibration (``centre_model: anthropometric``): ``centres`` (default) cuts at
            the person's centres, the points between the robot's link boundary and the
            person's centre moving to the segment on their side
            (:meth:`~qpretarget.cloud.template.Template.assign_by_centres`); ``links``
            keeps the robot's link boundaries (before this option).
        limb_tubes: segments whose surfaces become tubes about their joint-centre lines at
            calibration (:meth:`~qpretarget.cloud.template.Template.limbs_as_tubes`; after
            the cuts, before ``rigid_segments``): the radius along the limb from the subject's
            own points, the axis the line from the segment's centre to the next one's. A
            person's long bones run down the middle of their limbs; a robot's links are not
            tubes, and a fit that lays them on a person's limb tilts the joint line by what
            their shape is off it. The shipped config: ``[upper_arm, forearm]``.
    """

    enabled: bool = True
    scales: Any = None
    scale_bounds: list[float] = field(default_factory=lambda: [0.5, 2.5])
    scale_prior: float = 1000.0
    iterations: int = 60
    initial_yaw: Any = "auto"
    initial_joints: dict[str, float] = field(default_factory=dict)
    personalize: bool = True
    personalize_distance: float = 0.025
    personalize_rate: float = 0.0
    personalize_segments: list[str] | None = None
    rigid_segments: list[str] = field(default_factory=list)
    posture_weight: float = 1000.0
    joint_centres: bool = True
    centre_joints: list[str] | None = None
    centre_prior: float = 0.1
    centre_iterations: int = 8
    centre_bound: float = 0.15
    centre_information: float = 0.1
    centre_axes: str = "limb"
    centre_rate: float | None = 10.0
    centre_model: str = "robot"
    centre_symmetric: bool = False
    centre_cuts: str = "centres"
    limb_tubes: list[str] = field(default_factory=list)


@dataclass
class EMConfig:
    r"""EM fitting per frame (Wang 2017 eq. 1-5, 12-17, 20-21, Alg. 1).

    Attributes:
        outlier_weight: :math:`\mu`, the weight of the uniform outlier term (eq. 1).
        sigma2_init: initial :math:`\sigma^2` of every frame [m^2] (V.C: 0.02^2).
        sigma2_min: floor of :math:`\sigma^2` [m^2].
        max_iterations: EM iterations of the linear stage per frame.
        tolerance: convergence when every joint moves less than this [rad] (V.C: 0.002).
        temporal_weight: :math:`\lambda_r` of eq. 16 (V.C: 1000) on the squared joint change from
            the previous frame.
        contact_weight: :math:`\lambda_c` on the squared tilt of each supporting sole (the
            horizontal part of its normal, :math:`\approx` the tilt in rad): the soles the
            support tracker marks as supporting lie flat on the floor, as the robot's will
            (0: off; not in Wang 2017, see ``docs/point_clouds.md``).
        contact_anchor: the same term also keeps each supporting sole where it was put down
            (its x, y and heading; 1 cm of slip weighs like 0.1 rad of tilt): no foot slip.
        contact_height: the term holds a supporting sole only while the fit puts it within
            this height of the floor (z = 0) [m]; ``null``: at any height (before). A sole
            higher than that is a heel raised on the ball of the foot, a person on tiptoe, or
            a foot shuffling: held flat and in place there, it twisted the fit's legs and
            pelvis away from the person's (CMU 14_07 reach-up on tiptoe: the fit's soles 10-32
            cm from the person's ankles). The support itself (balance rows, the command's
            stance) still comes from the support tracker.
        posture_weight: :math:`\lambda_q` [nats per rad^2] of a pull of the joints of
            ``posture_joints`` towards their rest angles while tracking,
            :math:`\lambda_q \sum_j (\theta_j - \bar\theta_j)^2` (0: off; not in Wang
            2017). For a joint the cloud barely determines: G1's waist yaw, the trunk's twist
            between a pelvis whose heading its few, roundish points hardly show and a torso
            whose heading the shoulders show well. Off in ``configs/cloud_g1.yaml``: on the
            waist yaw it lowered the arm error of the 3 s clips but made boxing's whip turns
            less sure (docs/point_clouds.md, thirteenth round).
        posture_joints: ``{joint: rest angle [rad]}`` of that pull (``{}``: none).
        temporal_reference: ``previous`` (eq. 16: change from the previous frame) or
            ``prediction`` (change from the auto-regressive prediction, which does not lag).
        normal_weight: :math:`\lambda_\perp = \lambda_f` of eq. 15 and 21 (V.C: 0.5).
        normal_scale: length [m] the unit normals are multiplied by so that positions and
            normals share :math:`\sigma^2` (see :mod:`qpretarget.cloud.em`).
        refine_iterations: iterations of the final refinement with normals (0: off).
        estep: ``kdtree`` (truncated to ``neighbors`` nearest template points) or ``dense``.
        neighbors: template points per cloud point in the truncated E-step.
        neighbor_refresh: search the neighbours again once a template point has moved more than
            this many sigma since the last search (the pairs are reused until then; 0: always).
        max_backtracks: step halvings before a step is refused (0: accept every full step).
        overrelaxation: largest over-relaxed step (a multiple of the M-step, grown by 1.25 while
            it keeps lowering the EM bound; 1: off). EM is slow along weakly determined
            directions; a longer step that still lowers the bound keeps the monotonicity.
        cull_backfaces: leave out template points facing away from the sensor.
        visibility_passes: linear-stage passes, each with the visible template points recomputed
            at the previous pass's fit (the first pass uses the predicted pose).
        occlusion_cell: also leave out template points hidden behind other parts, by a point
            z-buffer of this cell size [m] (0: off).
        occlusion_confirm: leave such a point out only when the frame's cloud confirms the
            occlusion, i.e. shows a surface in front of it (a cloud point in its angular cell
            nearer to the sensor by more than ``2 occlusion_cell``). Without one, the
            template part in the way is not where the person's is (the trunk behind a fitted
            arm the person holds elsewhere, a leg behind the other), and the point takes part.
            Needs ``cull_backfaces`` and ``occlusion_cell > 0``.
        silhouette_weight: :math:`\lambda_s`, the pull on template points outside the
            person's silhouette during the refinement (0: off; not in Wang 2017, whose
            mixture leaves a template point no cloud point is near free): a point taking part
            around whose ray the sensor saw nothing, or saw past it by more than 15 cm, is
            pulled across the image onto the nearest cloud point's ray at its own distance,
            with the weight of this many cloud points
            (:class:`qpretarget.cloud.visibility.Silhouette`; docs/point_clouds.md, eleventh
            round). Needs ``refine_iterations > 0`` and a sensor position.
        silhouette_segments: the template segments whose points the silhouette pulls
            (``null``: all, as shipped). Leaving out the shanks and feet, whose supporting
            soles the contact term holds, was measured and not kept (docs/point_clouds.md,
            eleventh round).
        prediction: ``ar3`` (third-order auto-regression, V.B), ``velocity`` (constant
            velocity: the last frame-to-frame step repeated) or ``constant`` (the last pose).
        ar_window: frames used to fit the auto-regression.
        damping: Levenberg-Marquardt damping relative to the mean diagonal of H.
        reinit_ratio: re-initialisation on a likelihood drop (0: off): when a frame's fitted
            sigma exceeds this many times the median of the last ``reinit_window`` frames
            that did not, the frame is fitted again from the last such frame's pose and from
            the constant-velocity prediction, and the fit with the lowest NLL (eq. 3) kept.
        reinit_window: frames of the running median of sigma.
        reinit_at_limits: joints whose fitted angle ending at the fit's limit (within
            0.01 rad, ``recovery.LIMIT_MARGIN``; :attr:`joint_limits` included) also flags the
            frame lost, whatever its sigma (``[]``: off). G1: ``[waist_yaw_joint]`` with
            the waist bounded to a person's twist: a trunk twisted as far as a person can
            twist is a pelvis and a torso that disagree on the heading (on CMU 17_10
            boxing, a whip turn of 90-135 deg in 0.3 s that the pelvis followed and the
            torso did not), and it sets off the re-initialisation, with the yaw search when
            ``reinit_yaw_starts`` > 0.
        reinit_yaw_starts: coarse search over the trunk's yaw in a re-initialisation (0: off):
            this many extra starts on each side, the last good pose with its floating base
            turned about the vertical by ``k * reinit_yaw_step`` (k = 1..n, both signs) and the
            joints ``reinit_yaw_reset`` set to 0 (the torso's heading kept; with such joints
            the untwisted pose turned by 0 is a start too). Each gets ``reinit_yaw_iterations``
            EM iterations; the one with the lowest NLL (eq. 3) is fitted on and competes with
            the other starts. Needs a trigger: ``reinit_ratio`` > 0 or ``reinit_at_limits``.
        reinit_yaw_step: grid step of those starts [rad].
        reinit_yaw_iterations: EM iterations of each yaw start before they are compared.
        reinit_yaw_reset: trunk joints the yaw starts set to 0, turning the base so that the
            last one's heading is kept (G1: ``[waist_yaw_joint]``: a trunk twisted to the
            waist's limit is untwisted).
        reinit_recentre: the re-initialisation's starts from the last good pose (the last
            frame not flagged lost, and the yaw search's around it) have their floating base
            moved horizontally to where the frame's own fit stands: the person may have walked
            on since (33 cm over CMU 17_10 boxing's whip turn; ``false``: stop 42's starts).
        reinit_release_contacts: the yaw search runs without the supporting soles' anchors
            (``contact_anchor``), and a winning start's soles are anchored anew where it puts
            them: a whip turn pivots on the feet, and the anchors, where the lost fit put
            the soles, held every turned start back (``false``: stop 42's search).
        reinit_limit_penalty: :math:`\rho` [nats per cloud point]: the re-initialisation
            ranks its fits by NLL (eq. 3) plus :math:`\rho N` for a fit ending at a limit of
            ``reinit_at_limits``, the rule that flagged the frame lost
            (``CloudRetargeter.reinit_cost``; 0: by NLL alone, stop 42). Over boxing's 15
            ten-second runs, 0.02-0.2 all kept the trunk through the whip turns better than
            0 (docs/point_clouds.md, twelfth round).
        branch_joints: triples of joint names ``[a, b, c]``, each a chain of three revolute
            joints with mutually orthogonal axes (a shoulder's pitch, roll, yaw): when a fit
            leaves one of them within ``recovery.BRANCH_MARGIN`` of a limit, the frame is
            fitted again from the other angles giving the same rotation,
            :math:`(\theta_a + \pi, \pi - \theta_b, \theta_c + \pi)`, if they are within
            the limits, and the fit with the lower NLL (eq. 3) kept (``[]``: off).
        joint_limits: ``{joint: [low, high]}`` [rad]: the fit's range of those joints, within
            the robot's (the robot's limits bound the rest). The template is the *person*
            posed with the robot's joints, and a person's trunk does not twist as far as G1's
            waist (2.6 rad): a back seen end-on explains the cloud about as well as a front,
            and on CMU 17_10 boxing the fit's waist yaw ran to G1's limit, the torso turned
            170 deg from the person's. ``{}`` (default): the robot's limits.
            ``configs/cloud_g1.yaml`` bounds the waist yaw to +-0.8 rad, a person's axial
            range, with ``reinit_at_limits`` (docs/point_clouds.md, ninth round).
    """

    outlier_weight: float = 0.1
    sigma2_init: float = 4.0e-4
    sigma2_min: float = 1.0e-6
    max_iterations: int = 30
    tolerance: float = 0.002
    temporal_weight: float = 100.0
    temporal_reference: str = "prediction"
    contact_weight: float = 1.0e4
    contact_anchor: bool = True
    contact_height: float | None = None
    posture_weight: float = 0.0
    posture_joints: dict[str, float] = field(default_factory=dict)
    normal_weight: float = 0.5
    normal_scale: float = 0.05
    refine_iterations: int = 3
    estep: str = "kdtree"
    neighbors: int = 8
    neighbor_refresh: float = 0.5
    max_backtracks: int = 10
    overrelaxation: float = 1.8
    cull_backfaces: bool = True
    occlusion_cell: float = 0.02
    occlusion_confirm: bool = False
    silhouette_weight: float = 0.0
    silhouette_segments: list[str] | None = None
    visibility_passes: int = 1
    prediction: str = "ar3"
    ar_window: int = 10
    damping: float = 1.0e-6
    reinit_ratio: float = 0.0
    reinit_window: int = 30
    reinit_at_limits: list[str] = field(default_factory=list)
    reinit_yaw_starts: int = 0
    reinit_yaw_step: float = 0.785
    reinit_yaw_iterations: int = 10
    reinit_yaw_reset: list[str] = field(default_factory=list)
    reinit_recentre: bool = True
    reinit_release_contacts: bool = True
    reinit_limit_penalty: float = 0.05
    branch_joints: list[list[str]] = field(default_factory=list)
    joint_limits: dict[str, list[float]] = field(default_factory=dict)


@dataclass
class StabilityConfig:
    """Static balance (Wang 2017 eq. 18-19).

    Attributes:
        mode: ``qp`` (CoM rows in every M-step), ``hip_offset`` (the paper's rule after the fit)
            or ``none``.
        region: ``polygon`` (SP) or ``inscribed_circle`` (the paper's :math:`C_{SP}`).
        margin: distance kept inside the region [m].
        support_height: a sole within this height of the lowest sole supports [m].
        release_height: a supporting sole stops supporting above this height [m].
        flight_height: lowest sole above this height: no support (flight) [m].
        hip_joints: joints of the paper's rule (default: ``*hip*pitch*``, ``*hip*roll*``).
        plant: how the command stands its primary sole flat on the floor: ``leg`` (the
            supporting leg's joints put it there under the fitted trunk, which keeps its
            orientation; ``CloudRetargeter.robot_configuration``) or ``rigid`` (the whole
            fitted body turned and moved with the sole).
        replant_distance: a supporting sole is put down again, that frame not in contact
            (a shuffle, a step carried low), when the person's fitted sole moves farther
            than this from where it was put down [m] (horizontally), or G1's sole at the
            fitted configuration as far from its placement
            (:meth:`.placement.SolePlacement.configuration`); ``null``: never (before stop
            49: the foot stayed where it was put down while it supported).
        replant_angle: ... or turned by more than this [rad] (a pivot).
    """

    mode: str = "qp"
    region: str = "polygon"
    margin: float = 0.01
    support_height: float = 0.04
    release_height: float = 0.07
    flight_height: float = 0.25
    hip_joints: list[str] | None = None
    plant: str = "leg"
    replant_distance: float | None = 0.08
    replant_angle: float = 0.35


TOP_KEYS = (
    "name",
    "description",
    "robot",
    "solver",
    "input",
    "template",
    "calibration",
    "em",
    "stability",
    "self_collision",
)

_CHOICES = {
    ("template", "meshes"): ("visual", "collision"),
    ("template", "skinning"): ("rigid", "lbs"),
    ("em", "estep"): ("kdtree", "dense"),
    ("calibration", "centre_axes"): ("limb", "free"),
    ("calibration", "centre_model"): ("robot", "anthropometric"),
    ("calibration", "centre_cuts"): ("centres", "links"),
    ("em", "prediction"): ("ar3", "velocity", "constant"),
    ("em", "temporal_reference"): ("previous", "prediction"),
    ("stability", "mode"): ("qp", "hip_offset", "none"),
    ("stability", "region"): ("polygon", "inscribed_circle"),
    ("stability", "plant"): ("leg", "rigid"),
}


def _section(cls: type, spec: Any, path: str) -> Any:
    if spec is None:
        return cls()
    if not isinstance(spec, Mapping):
        raise ConfigError(f"expected a mapping, got {spec!r}.", path=path)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    default = cls()
    values = {}
    for key, value in spec.items():
        if key not in fields:
            raise ConfigError(
                f"unknown key {key!r}.{close_matches_hint(str(key), list(fields))} "
                f"Keys: {', '.join(fields)}.",
                path=f"{path}.{key}",
            )
        ref = getattr(default, key)
        choices = _CHOICES.get((path, key))
        if choices is not None and value not in choices:
            raise ConfigError(
                f"must be one of {', '.join(choices)}, got {value!r}.", path=f"{path}.{key}"
            )
        if key == "replant_distance":
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0
            ):
                raise ConfigError(
                    f"must be a distance > 0 [m] or null (a supporting sole is never put down "
                    f"again), got {value!r}.",
                    path=f"{path}.{key}",
                )
            value = None if value is None else float(value)
        elif isinstance(ref, bool):
            if not isinstance(value, bool):
                raise ConfigError(f"must be true or false, got {value!r}.", path=f"{path}.{key}")
        elif isinstance(ref, int):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"must be an integer >= 0, got {value!r}.", path=f"{path}.{key}")
        elif isinstance(ref, float):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise ConfigError(f"must be a number >= 0, got {value!r}.", path=f"{path}.{key}")
            value = float(value)
        elif key == "branch_joints":
            if not isinstance(value, list) or not all(
                isinstance(t, list) and len(t) == 3 and all(isinstance(v, str) for v in t)
                for t in value
            ):
                raise ConfigError(
                    f"must be a list of [a, b, c] joint-name triples, got {value!r}.",
                    path=f"{path}.{key}",
                )
        elif key in ("reinit_yaw_reset", "reinit_at_limits"):
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise ConfigError(
                    f"must be a list of joint names, got {value!r}.", path=f"{path}.{key}"
                )
        elif key == "contact_height":
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0
            ):
                raise ConfigError(
                    f"must be a height > 0 [m] or null (no limit), got {value!r}.",
                    path=f"{path}.{key}",
                )
            value = None if value is None else float(value)
        elif key == "joint_limits":
            if not isinstance(value, Mapping) or not all(
                isinstance(k, str)
                and isinstance(v, list)
                and len(v) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
                and v[0] < v[1]
                for k, v in value.items()
            ):
                raise ConfigError(
                    "must map joint names to [low, high] in rad with low < high, e.g. "
                    f"{{waist_yaw_joint: [-0.8, 0.8]}}; got {value!r}.",
                    path=f"{path}.{key}",
                )
            value = {str(k): [float(v[0]), float(v[1])] for k, v in value.items()}
        elif key in ("initial_joints", "posture_joints"):
            if not isinstance(value, Mapping) or not all(
                isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
                for k, v in value.items()
            ):
                raise ConfigError(
                    f"must map joint names to angles in rad, e.g. {{waist_yaw_joint: 0.0}}; "
                    f"got {value!r}.",
                    path=f"{path}.{key}",
                )
            value = {str(k): float(v) for k, v in value.items()}
        elif key == "personalize_segments" and value is not None:
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise ConfigError(
                    f"must be a list of segment names or null, got {value!r}.",
                    path=f"{path}.{key}",
                )
        elif key in ("rigid_segments", "limb_tubes"):
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise ConfigError(
                    "must be a list of segment names (e.g. [torso], [upper_arm, forearm]), "
                    f"got {value!r}.",
                    path=f"{path}.{key}",
                )
        elif key == "centre_joints" and value is not None:
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise ConfigError(
                    f"must be a list of joint names or null, got {value!r}.", path=f"{path}.{key}"
                )
        values[key] = value
    return cls(**values)


def _self_collision(spec: Any) -> dict[str, Any] | None:
    """The ``self_collision`` section: ``None`` (off) or the constraint's keys, checked."""
    if spec is None or spec is False:
        return None
    if not isinstance(spec, Mapping):
        raise ConfigError(
            "must be a mapping of the self_collision constraint's keys (e.g. {pairs: auto, "
            f"d_s: 0.01}}) or null (off), got {spec!r}.",
            path="self_collision",
        )
    if "type" in spec:
        raise ConfigError(
            "the fit's self_collision section takes the constraint's keys only: remove `type`.",
            path="self_collision.type",
        )
    build_from_spec(SelfCollision, fit_spec(spec), path="self_collision")
    return dict(spec)


@dataclass
class CloudConfig:
    """The whole configuration of :class:`~qpretarget.cloud.em.CloudRetargeter`."""

    name: str = "cloud"
    description: str = ""
    robot: Any = "g1"
    solver: Any = field(default_factory=lambda: {"name": "proxsuite", "eps_abs": 1e-9})
    input: InputConfig = field(default_factory=InputConfig)
    template: TemplateConfig = field(default_factory=TemplateConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    em: EMConfig = field(default_factory=EMConfig)
    stability: StabilityConfig = field(default_factory=StabilityConfig)
    #: The robot's links kept apart (:mod:`qpretarget.cloud.command`): the keys of the
    #: controller's ``self_collision`` constraint, or ``None`` (off).
    self_collision: dict[str, Any] | None = None
    text: str = ""

    @classmethod
    def from_dict(cls, spec: Mapping[str, Any] | None, *, text: str = "") -> CloudConfig:
        """Validate a mapping (the YAML's content).

        Raises:
            ConfigError: with the YAML path of the first problem.
        """
        spec = dict(spec or {})
        for key in spec:
            if key not in TOP_KEYS:
                raise ConfigError(
                    f"unknown key {key!r}.{close_matches_hint(str(key), TOP_KEYS)} "
                    f"Top-level keys: {', '.join(TOP_KEYS)}.",
                    path=str(key),
                )
        cfg = cls(
            name=str(spec.get("name", "cloud")),
            description=str(spec.get("description", "")),
            robot=spec.get("robot", "g1"),
            solver=spec.get("solver", {"name": "proxsuite", "eps_abs": 1e-9}),
            input=_section(InputConfig, spec.get("input"), "input"),
            template=_section(TemplateConfig, spec.get("template"), "template"),
            calibration=_section(CalibrationConfig, spec.get("calibration"), "calibration"),
            em=_section(EMConfig, spec.get("em"), "em"),
            stability=_section(StabilityConfig, spec.get("stability"), "stability"),
            self_collision=_self_collision(spec.get("self_collision")),
            text=text,
        )
        cfg._check()
        return cfg

    @classmethod
    def from_yaml(cls, path: str | Path) -> CloudConfig:
        """Read and validate a YAML file.

        Raises:
            ConfigError: missing file, YAML syntax error (with line) or invalid content.
        """
        path = Path(path)
        text, spec = read_yaml_file(path, ConfigError, "config file")
        if spec is not None and not isinstance(spec, Mapping):
            raise ConfigError(f"{path}: the file must hold a mapping (robot:, em:, ...).")
        try:
            return cls.from_dict(spec, text=text)
        except ConfigError as exc:
            raise ConfigError(f"{path.name}: {exc}") from None

    def to_yaml(self) -> str:
        """The configuration as YAML (the file's own text when read from a file)."""
        if self.text:
            return self.text
        d = {k: v for k, v in dataclasses.asdict(self).items() if k != "text"}
        return yaml.safe_dump(d, sort_keys=False)

    def _check(self) -> None:
        em, st, cal, inp, tp = self.em, self.stability, self.calibration, self.input, self.template
        if not 0 <= em.outlier_weight < 1:
            raise ConfigError(
                f"must be in [0, 1), got {em.outlier_weight}.", path="em.outlier_weight"
            )
        if em.sigma2_init <= 0 or em.sigma2_min <= 0 or em.sigma2_min > em.sigma2_init:
            raise ConfigError("need 0 < sigma2_min <= sigma2_init [m^2].", path="em.sigma2_init")
        if em.tolerance <= 0:
            raise ConfigError("must be > 0 [rad].", path="em.tolerance")
        if em.neighbors < 1:
            raise ConfigError("must be >= 1.", path="em.neighbors")
        if tp.points < 50:
            raise ConfigError(f"must be >= 50, got {tp.points}.", path="template.points")
        if inp.points < 10:
            raise ConfigError(f"must be >= 10, got {inp.points}.", path="input.points")
        b = cal.scale_bounds
        if not (isinstance(b, list) and len(b) == 2 and 0 < float(b[0]) < float(b[1])):
            raise ConfigError(
                f"must be [low, high] with 0 < low < high, got {b!r}.",
                path="calibration.scale_bounds",
            )
        if cal.initial_yaw != "auto" and not isinstance(cal.initial_yaw, (int, float)):
            raise ConfigError(
                f"must be `auto` or an angle [rad], got {cal.initial_yaw!r}.",
                path="calibration.initial_yaw",
            )
        if inp.crop is not None:
            c = inp.crop
            try:
                lo, hi = [float(x) for x in c["min"]], [float(x) for x in c["max"]]
                if len(lo) != 3 or len(hi) != 3 or any(a >= b for a, b in zip(lo, hi, strict=True)):
                    raise ValueError
            except (KeyError, TypeError, ValueError):
                raise ConfigError(
                    f"must be {{min: [x, y, z], max: [x, y, z]}} with min < max [m], got {c!r}.",
                    path="input.crop",
                ) from None
        if st.margin < 0:
            raise ConfigError("must be >= 0 [m].", path="stability.margin")
        if not st.replant_angle > 0:
            raise ConfigError(
                f"must be > 0 [rad], got {st.replant_angle!r}.", path="stability.replant_angle"
            )
        if cal.centre_rate is not None and not float(cal.centre_rate) > 0:
            raise ConfigError(
                f"must be > 0 [Hz] or null (every frame), got {cal.centre_rate!r}.",
                path="calibration.centre_rate",
            )
        if em.reinit_yaw_starts and not 0 < em.reinit_yaw_step * em.reinit_yaw_starts <= math.pi:
            raise ConfigError(
                f"need 0 < reinit_yaw_starts * reinit_yaw_step <= pi (the starts turn the base "
                f"at most half a turn each way), got {em.reinit_yaw_starts} * "
                f"{em.reinit_yaw_step} rad.",
                path="em.reinit_yaw_step",
            )
        if em.reinit_yaw_starts and not (em.reinit_ratio > 0 or em.reinit_at_limits):
            raise ConfigError(
                "the yaw search runs in a re-initialisation, which nothing triggers: set "
                "em.reinit_ratio > 0 (a likelihood drop) or em.reinit_at_limits (a joint at "
                "its limit), or reinit_yaw_starts: 0.",
                path="em.reinit_yaw_starts",
            )
        if em.occlusion_confirm and not (em.cull_backfaces and em.occlusion_cell > 0):
            raise ConfigError(
                "confirms the template's own occlusions, which are off: set "
                "em.cull_backfaces: true and em.occlusion_cell > 0 (0.02 m), or "
                "occlusion_confirm: false.",
                path="em.occlusion_confirm",
            )
        if em.silhouette_weight > 0 and em.refine_iterations == 0:
            raise ConfigError(
                "the silhouette pulls act in the refinement stage, which is off: set "
                "em.refine_iterations > 0 (3), or silhouette_weight: 0.",
                path="em.silhouette_weight",
            )
        if cal.centre_symmetric and cal.centre_axes != "limb":
            raise ConfigError(
                "one offset for a left/right pair moves both along their limbs: use "
                "centre_axes: limb with centre_symmetric: true (or centre_symmetric: false).",
                path="calibration.centre_symmetric",
            )


__all__ = [
    "CalibrationConfig",
    "CloudConfig",
    "EMConfig",
    "InputConfig",
    "StabilityConfig",
    "TemplateConfig",
]
