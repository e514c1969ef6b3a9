# SPDX-License-Identifier: Apache-2.0
r"""Measures of a point-cloud run against the rendered truth (one definition: tests, bench, docs).

The *arm-direction error* compares the robot's command with the person it was fitted to: for each
upper arm (shoulder to elbow) and forearm (elbow to wrist), the angle between the segment of the
robot, the G1 itself at the run's configurations (fitted joints, primary sole flat on the floor:
what the robot is sent), and the same segment of the human model that was rendered,

.. math:: e = \arccos \frac{u_{robot}^\top u_{human}}{\|u_{robot}\| \|u_{human}\|}.

A fit whose feet are tilted or twisted shows here as a leaning or turned robot.

The *reachability bound* (:func:`arm_direction_bound`) is the same error for the robot
configuration closest to the person's arm directions within the joint limits: what no fit can
go under where the person's arm is outside the robot's reach.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

if TYPE_CHECKING:
    from ..robot import RobotModel
    from ..trajectory import RobotTrajectory
    from .poser import HumanPoser

#: Issue 23's acceptance: every arm segment within this of the person's [deg].
ARM_TOLERANCE_DEG = 12.0
#: An arm segment further off than this is *lost* [deg] (issue 23: at most 0.5 s at a time).
ARM_LOST_DEG = 45.0
#: Run-file array of the rendered person's configurations (``make-cloud``'s ``meta/human_q``,
#: carried over by ``retarget-cloud``), the truth :func:`run_arm_direction_errors` scores.
HUMAN_Q_KEY = "cloud/human_q"

#: Column order of :func:`arm_direction_errors`.
ARM_SEGMENTS: tuple[str, ...] = (
    "left_upper_arm",
    "left_forearm",
    "right_upper_arm",
    "right_forearm",
)


def arm_direction_errors(
    robot: RobotModel, q_robot: np.ndarray, poser: HumanPoser, q_human: np.ndarray
) -> np.ndarray:
    """(T, 4) angles [deg] between the robot's and the human model's arm segments.

    Args:
        robot: the robot (its ``keyframes`` name the shoulder, elbow and wrist frames).
        q_robot: (T, nq) robot configurations (the run file's ``q``).
        poser: the :class:`~qpretarget.cloud.poser.HumanPoser` that posed the rendered model.
        q_human: (T, nq_h) configurations of the rendered human model (``SyntheticSequence.q``).

    Returns:
        Columns :data:`ARM_SEGMENTS`: left upper arm, left forearm, right upper arm, right
        forearm.
    """
    arms = _ArmDirections(robot)
    sides = ("left", "right")
    out = np.empty((len(q_robot), 4))
    for k, q in enumerate(np.asarray(q_robot, float)):
        human = poser.model_keypoints(q_human[k])
        target = np.concatenate([_unit_segments(human, s) for s in sides])
        out[k] = _angles(arms.directions(q, sides), target)
    return out


def longest_run_above(errors: np.ndarray, t: np.ndarray, threshold: float) -> float:
    """Longest time [s] the worst segment of consecutive frames stays above ``threshold`` [deg].

    A run of frames k..l above it lasts ``t[l] - t[k]`` plus one frame period (a single frame
    counts one period). ``errors``: (T, 4) from :func:`arm_direction_errors`; ``t``: (T,) [s].
    """
    above = np.asarray(errors).max(axis=1) > threshold
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    best, start = 0.0, None
    for k, a in enumerate(above):
        if a and start is None:
            start = k
        if start is not None and (not a or k == len(above) - 1):
            end = k if a else k - 1
            best = max(best, float(t[end] - t[start]) + dt)
            start = None
    return best


def arm_direction_summary(errors: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    """The figures issue 23 and ``docs/point_clouds.md`` report of a run's arm-direction errors.

    Args:
        errors: (T, 4) from :func:`arm_direction_errors` [deg].
        t: (T,) frame times [s].

    Returns:
        ``worst_deg`` (the largest error of any segment and frame) and ``worst_segment``,
        ``worst_time_s``; ``per_segment_worst_deg`` (columns :data:`ARM_SEGMENTS`);
        ``median_deg`` (over every segment and frame); ``frames_above_tolerance`` (frames whose
        worst segment exceeds :data:`ARM_TOLERANCE_DEG`) of ``frames``; ``longest_lost_s``
        (:func:`longest_run_above` :data:`ARM_LOST_DEG`); the two thresholds.
    """
    e = np.asarray(errors, float)
    t = np.asarray(t, float)
    if e.ndim != 2 or e.shape[1] != len(ARM_SEGMENTS) or len(t) != len(e) or not len(e):
        raise ValueError(
            f"need errors (T, {len(ARM_SEGMENTS)}) and t (T,) with T > 0, got {e.shape} and "
            f"{t.shape}"
        )
    k, col = np.unravel_index(int(np.argmax(e)), e.shape)
    return {
        "worst_deg": float(e[k, col]),
        "worst_segment": ARM_SEGMENTS[col],
        "worst_time_s": float(t[k] - t[0]),
        "per_segment_worst_deg": dict(zip(ARM_SEGMENTS, map(float, e.max(axis=0)), strict=True)),
        "median_deg": float(np.median(e)),
        "frames": len(e),
        "frames_above_tolerance": int((e.max(axis=1) > ARM_TOLERANCE_DEG).sum()),
        "tolerance_deg": ARM_TOLERANCE_DEG,
        "longest_lost_s": longest_run_above(e, t, ARM_LOST_DEG),
        "lost_deg": ARM_LOST_DEG,
    }


def hip_offsets(
    robot: RobotModel, q_robot: np.ndarray, poser: HumanPoser, q_human: np.ndarray
) -> np.ndarray:
    r"""(T,) horizontal distance [m] between the robot's and the person's hips.

    The midpoint of the hip key points, :math:`\| (h^{robot}_{xy} - h^{person}_{xy}) \|` with
    :math:`h = (p_{left\_hip} + p_{right\_hip}) / 2` (the robot's ``keyframes``, the human
    model's key points): where the robot stands and travels against the person, in the world
    both are given in (the clouds' frame). Robots of another size stand their hips elsewhere
    over the same feet; on G1 and the human model a standing pose reads 1-5 cm.
    """
    kf = robot.keyframes
    ids = [robot.frame_id(kf["left_hip"]), robot.frame_id(kf["right_hip"])]
    data = robot.model.createData()
    out = np.empty(len(q_robot))
    for k, q in enumerate(np.asarray(q_robot, float)):
        pin.framesForwardKinematics(robot.model, data, q)
        mine = 0.5 * (data.oMf[ids[0]].translation + data.oMf[ids[1]].translation)
        person = poser.model_keypoints(q_human[k])
        theirs = 0.5 * (person["left_hip"] + person["right_hip"])
        out[k] = float(np.linalg.norm(mine[:2] - theirs[:2]))
    return out


def run_arm_direction_errors(
    traj: RobotTrajectory, robot: RobotModel | None = None
) -> np.ndarray | None:
    """(T, 4) arm-direction errors of a ``retarget-cloud`` run against its rendered person.

    The run carries the person's configurations (:data:`HUMAN_Q_KEY`) when its clouds came from
    ``make-cloud`` (or :func:`~qpretarget.cloud.render.human_clip_sequence`); None otherwise
    (a real sensor's clouds have no truth to score against). ``robot``: the run's robot
    (default: built from the run's stored config).
    """
    human_q = traj.extra.get(HUMAN_Q_KEY)
    if human_q is None:
        return None
    human_q = np.asarray(human_q, float)
    if human_q.shape[0] != len(traj.q):
        raise ValueError(
            f"{HUMAN_Q_KEY} has {human_q.shape[0]} frames, the run {len(traj.q)}: the run file "
            "was edited; write it again with retarget-cloud"
        )
    from .poser import HumanPoser

    if robot is None:
        robot = traj.make_controller().robot
    return arm_direction_errors(robot, traj.q, HumanPoser(), human_q)


def _arm_joints(robot: RobotModel, side: str) -> list[int]:
    """Pinocchio joint ids moving the ``side`` arm's segments relative to the torso."""
    model = robot.model
    wrist = model.frames[model.getFrameId(robot.keyframes[f"{side}_wrist"])].parentJoint
    torso = model.frames[model.getFrameId(robot.keyframes["torso"])].parentJoint
    above = set(model.supports[torso])
    return [j for j in model.supports[wrist] if j not in above and model.joints[j].nv == 1]


def arm_direction_bound(
    robot: RobotModel,
    q_robot: np.ndarray,
    poser: HumanPoser,
    q_human: np.ndarray,
    *,
    trunk: str = "fit",
    starts: int = 4,
    seed: int = 0,
) -> np.ndarray:
    r"""(T, 4) arm-direction errors [deg] of the robot pose nearest the person's arms.

    For each frame, with :math:`h_s` the human model's unit segment directions and
    :math:`u_s(x)` the robot's (upper arm, forearm of each side; as in
    :func:`arm_direction_errors`), solves

    .. math:: \min_{x_{min} \le x \le x_{max}} \sum_s \Big\| \frac{u_s(x)}{\|u_s(x)\|}
        - h_s \Big\|^2, \qquad \Big\| \frac{u}{\|u\|} - h \Big\| = 2 \sin\frac{e_s}{2}

    (the chord of the angle :math:`e_s`, increasing in it) over ``x``: each arm's joints from the
    shoulder to the wrist (G1: 7 per arm) within their limits, one least-squares problem per arm
    (bounded trust region, :func:`scipy.optimize.least_squares`), the trunk held at the run's
    ``q_robot`` (``trunk="fit"``); with ``trunk="free"``, also the trunk's joints (G1: the
    waist) and the base's orientation, all in one problem: the robot's torso may then turn
    anywhere. Returns the angles :math:`e_s` at the solution. Local minima (a shoulder's two
    branches) are met with ``starts`` starts: the run's angles, the reference posture and
    uniform draws within the limits (``seed``); the best is kept. Where the bound is above a
    threshold, that error is beyond the robot's joint limits (with ``trunk="free"``: whatever
    its torso does), not the fit's.
    """
    from scipy.optimize import least_squares

    if trunk not in ("fit", "free"):
        raise ValueError(f"trunk must be 'fit' or 'free', got {trunk!r}")
    model = robot.model
    rng = np.random.default_rng(seed)
    sides = ("left", "right")
    arm = {s: [model.joints[j].idx_q for j in _arm_joints(robot, s)] for s in sides}
    torso = model.frames[model.getFrameId(robot.keyframes["torso"])].parentJoint
    trunk_q = [model.joints[j].idx_q for j in model.supports[torso] if model.joints[j].nv == 1]
    groups = [(s,) for s in sides] if trunk == "fit" else [sides]
    nb = 3 if trunk == "free" and model.joints[1].nq == 7 else 0  # the base's rotation vector
    arms = _ArmDirections(robot)
    out = np.empty((len(q_robot), 4))
    for k, q in enumerate(np.asarray(q_robot, float)):
        human = poser.model_keypoints(q_human[k])
        for group in groups:
            idx = [i for s in group for i in arm[s]] + (trunk_q if trunk == "free" else [])
            target = np.concatenate([_unit_segments(human, s) for s in group])
            lo = np.r_[np.full(nb, -np.pi), model.lowerPositionLimit[idx]]
            hi = np.r_[np.full(nb, np.pi), model.upperPositionLimit[idx]]
            x_starts = [np.r_[np.zeros(nb), q[idx]], np.r_[np.zeros(nb), robot.q_reference[idx]]]
            x_starts += [rng.uniform(lo, hi) for _ in range(max(starts - 2, 0))]
            best = None
            for x0 in x_starts[: max(starts, 1)]:
                sol = least_squares(
                    arms.residual,
                    np.clip(x0, lo, hi),
                    bounds=(lo, hi),
                    xtol=1e-10,
                    args=(q, idx, nb, group, target),
                )
                if best is None or sol.cost < best.cost:
                    best = sol
            assert best is not None
            e = _angles(arms.directions(arms.config(best.x, q, idx, nb), group), target)
            for i, s in enumerate(group):
                col = 2 * sides.index(s)
                out[k, col : col + 2] = e[2 * i : 2 * i + 2]
    return out


_SEGMENTS = (("shoulder", "elbow"), ("elbow", "wrist"))


def _unit_segments(points: dict[str, np.ndarray], side: str) -> np.ndarray:
    """(6,) unit directions of the upper arm and the forearm of ``side`` from key points."""
    u = [points[f"{side}_{b}"] - points[f"{side}_{a}"] for a, b in _SEGMENTS]
    return np.concatenate([v / np.linalg.norm(v) for v in u])


def _angles(u: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Angles [deg] between the unit 3-vectors of ``u`` and ``h`` (both (3 n,)), pairwise."""
    c = np.einsum("ij,ij->i", u.reshape(-1, 3), h.reshape(-1, 3))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


class _ArmDirections:
    """The robot's arm-segment directions as a function of some joints (and the base's turn)."""

    def __init__(self, robot: RobotModel) -> None:
        self.model = robot.model
        self.data = self.model.createData()
        self.frames = {
            f"{s}_{n}": self.model.getFrameId(robot.keyframes[f"{s}_{n}"])
            for s in ("left", "right")
            for n in ("shoulder", "elbow", "wrist")
        }

    @staticmethod
    def config(x: np.ndarray, q: np.ndarray, idx: list[int], nb: int) -> np.ndarray:
        """``q`` with ``x[nb:]`` at ``idx``, the base turned by the rotation vector ``x[:nb]``."""
        qq = q.copy()
        qq[idx] = x[nb:]
        if nb:
            R0 = pin.XYZQUATToSE3(q[:7]).rotation
            qq[3:7] = pin.SE3ToXYZQUAT(pin.SE3(pin.exp3(x[:3]) @ R0, q[:3]))[3:]
        return qq

    def directions(self, q: np.ndarray, group: tuple[str, ...]) -> np.ndarray:
        """(6 len(group),) unit upper-arm and forearm directions of the sides in ``group``."""
        pin.framesForwardKinematics(self.model, self.data, q)
        points = {k: self.data.oMf[f].translation for k, f in self.frames.items()}
        return np.concatenate([_unit_segments(points, s) for s in group])

    def residual(
        self,
        x: np.ndarray,
        q: np.ndarray,
        idx: list[int],
        nb: int,
        group: tuple[str, ...],
        target: np.ndarray,
    ) -> np.ndarray:
        """Unit directions minus the person's: the chords ``2 sin(e/2)`` in norm."""
        return self.directions(self.config(x, q, idx, nb), group) - target


__all__ = [
    "ARM_LOST_DEG",
    "ARM_SEGMENTS",
    "ARM_TOLERANCE_DEG",
    "HUMAN_Q_KEY",
    "arm_direction_bound",
    "arm_direction_errors",
    "arm_direction_summary",
    "hip_offsets",
    "longest_run_above",
    "run_arm_direction_errors",
]
