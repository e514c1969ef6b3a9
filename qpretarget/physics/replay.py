# SPDX-License-Identifier: Apache-2.0
"""Replay a retargeted run in MuJoCo with joint PD tracking, the floating base free.

Each physics step (``h`` = the model's time step, a whole number of steps per run frame) every
actuated joint gets

    tau = clip(kp (q_ref - q) + kd (qdot_ref - qdot) + tau_ff, -tau_max, tau_max)        (1)

with ``q_ref`` linear between the run's frames, ``qdot_ref`` the run's joint velocity ``v`` (the
velocity the controller applied over the frame: the velocity feed-forward) and ``tau_ff`` the
gravity feed-forward of :func:`gravity_feedforward` (static torques holding the reference posture
on its stance feet; ``feedforward="none"`` drops it). Nothing else acts: no balance controller, no
feedback on the base. The floating base is free, so the robot stands, stumbles or falls on its
own.

The *assisted* replay adds a virtual wrench on the floating base that pulls it toward the
reference base pose: a MuJoCo weld equality between the base and a mocap body moved along the
reference, a soft constraint (``solref = (0.1 s, 1)``, ``solimp`` impedance 0.1) that the
constraint solver integrates implicitly; soft, so the feet carry the weight when they can (on a
clip that stands unassisted the weld still takes about 7 % of the weight at p95, mostly
horizontal, pulling the swaying base back: that is the floor of this measure). Its constraint force
``(f, n)`` is the effort the robot's own feet could not provide
(:mod:`~qpretarget.physics.metrics` reports ``|f|`` as % of body weight and ``|n|``).

The floor is placed at the lowest point of the robot's collision geometry in the first frame, so a
run whose soles sit a few millimetres off z = 0 neither drops nor starts in penetration (the offset
is reported). Deterministic: the same run and options give bit-identical series.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import QPRetargetError
from .model import PhysicsModel, import_mujoco, set_configuration

#: Torque feed-forwards added to eq. 1 (``--physics-feedforward``).
FEEDFORWARDS = ("gravity", "none")
#: Standard gravity [m/s^2] (MuJoCo's default gravity vector is (0, 0, -9.81)).
GRAVITY = 9.81


class PhysicsInputError(QPRetargetError, ValueError):
    """A run that cannot be replayed on the robot (joint count or names, bad samples)."""


@dataclass
class ReplaySeries:
    """Per-frame series of one replay (frames after a fall are NaN / False).

    Attributes:
        t: frame times [s] (the run's).
        assisted: the replay had the virtual root wrench.
        simulated: frames simulated (the replay stops at the first fallen frame).
        fallen_at: index of the first fallen frame, ``None`` if the robot stayed up.
        pelvis_height, pelvis_height_ref: base height [m], simulated and reference.
        tilt_deg: angle between the torso's vertical axis and the reference torso's [deg].
        root_pos_err: base position error [m]; root_ori_err_deg: base orientation error [deg].
        joint_err: ``q - q_ref`` per joint [rad], shape (T, n).
        saturated: (T, n) the joint's PD torque hit its limit in any step of the frame.
        foot_force: (T, F) mean normal floor force on each foot over the frame [N].
        other_force: (T,) mean normal floor force on the rest of the body [N].
        assist_force, assist_torque: (T,) mean norm of the assisting weld's force [N] and
            torque [N m]; assist_horizontal: of its horizontal force [N].
        ref_contacts: (T, F) the run's supporting feet.
        floor_height: floor placement [m] (lowest collision point in the first frame).
        wall_time_s: time the replay took; sim_time_s: simulated time.
        ref_zmp_margin: (T,) the reference ZMP's signed margin to the stance soles [m]
            (:func:`~qpretarget.physics.zmp.reference_zmp_margin`), set by :func:`check_run`.
    """

    t: np.ndarray
    assisted: bool
    simulated: int
    fallen_at: int | None
    pelvis_height: np.ndarray
    pelvis_height_ref: np.ndarray
    tilt_deg: np.ndarray
    root_pos_err: np.ndarray
    root_ori_err_deg: np.ndarray
    joint_err: np.ndarray
    saturated: np.ndarray
    foot_force: np.ndarray
    other_force: np.ndarray
    assist_force: np.ndarray
    assist_torque: np.ndarray
    assist_horizontal: np.ndarray
    ref_contacts: np.ndarray
    joint_names: list[str]
    foot_names: list[str]
    mass: float
    floor_height: float
    wall_time_s: float = 0.0
    sim_time_s: float = 0.0
    contacts_assumed: bool = False
    ref_zmp_margin: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def weight(self) -> float:
        """Body weight m g [N]."""
        return self.mass * GRAVITY


# --------------------------------------------------------------------------- quaternion helpers
def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions ``w x y z``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def _quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vector of a unit quaternion ``w x y z`` (shortest rotation)."""
    if q[0] < 0.0:
        q = -q
    s = float(np.linalg.norm(q[1:]))
    if s < 1e-12:
        return 2.0 * q[1:]
    return (2.0 * math.atan2(s, q[0]) / s) * q[1:]


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _wxyz(root: np.ndarray) -> np.ndarray:
    """Pinocchio free-flyer quaternion (``qx qy qz qw`` at ``root[3:7]``) as ``w x y z``."""
    q = np.array([root[6], root[3], root[4], root[5]], dtype=float)
    return q / np.linalg.norm(q)


# ------------------------------------------------------------------------------- validation
def joint_columns(traj: Any, pm: PhysicsModel) -> np.ndarray:
    """Columns of ``traj.q[:, 7:]`` holding each joint of ``pm.joint_names`` (matched by name).

    Raises:
        PhysicsInputError: the run's joint count, names or shape do not match the robot.
    """
    q = np.asarray(traj.q)
    n = len(pm.joint_names)
    names = list(traj.joint_names)
    if q.ndim != 2 or len(q) < 2:
        raise PhysicsInputError(
            f"the run holds {0 if q.ndim != 2 else len(q)} frame(s) of q; the physics replay "
            "needs at least 2."
        )
    if len(names) != n or q.shape[1] != 7 + n:
        raise PhysicsInputError(
            f"the run has {len(names)} joints (q of width {q.shape[1]}) but robot "
            f"{pm.robot_name!r} has {n} actuated joints (q of width {7 + n} with the free "
            "flyer): was it retargeted to another robot? Replay it with that robot's config."
        )
    missing = [j for j in pm.joint_names if j not in names]
    if missing:
        unknown = [j for j in names if j not in pm.joint_names]
        raise PhysicsInputError(
            f"the run's joints do not match robot {pm.robot_name!r}: missing {missing[:5]}, "
            f"unknown {unknown[:5]}."
        )
    if not np.all(np.isfinite(q)):
        bad = int(np.argwhere(~np.isfinite(q))[0, 0])
        raise PhysicsInputError(f"the run's q has a non-finite value at frame {bad}.")
    t = np.asarray(traj.t, float)
    if len(t) != len(q) or np.any(np.diff(t) <= 0):
        raise PhysicsInputError("the run's time axis t must increase and match q's frames.")
    return np.array([names.index(j) for j in pm.joint_names], dtype=int)


def gravity_feedforward(
    pm: PhysicsModel, root: np.ndarray, joints: np.ndarray, stance: np.ndarray
) -> np.ndarray:
    """Joint torques that hold each reference posture still on its stance feet (T, n) [N m].

    Static equilibrium of the floating base (pinocchio): the generalized gravity ``g(q)`` (RNEA
    at zero velocity and acceleration) with the base's wrench carried by the stance soles,
    least-norm, by :func:`~qpretarget.analysis.measures.carry_base_wrench` (the same definition
    ``qpretarget evaluate`` uses for its torques): ``J_c,base' f = g_base``,
    ``tau = g_joints - J_c,joints' f``. Without a stance foot: ``tau = g_joints`` (limbs held
    against gravity relative to the base). The PD of eq. 1 then only corrects errors, so a servo
    does not sag by ``tau / kp`` (which, at the ankles, moves the CoM toward the toes).
    """
    import pinocchio as pin

    from ..analysis.measures import carry_base_wrench

    robot = pm.robot
    T = len(joints)
    q = np.tile(np.asarray(robot.q_reference, dtype=float), (T, 1))
    q[:, :7] = root
    q[:, robot.joint_q_index] = joints
    g = np.array([pin.computeGeneralizedGravity(robot.model, robot.data, qk) for qk in q])
    foot_ids = [robot.frame_id(f.frame) for f in robot.feet.values()]
    tau = carry_base_wrench(robot, q, g, stance, foot_ids)
    return tau[:, robot.joint_v_index - robot.root_nv]


def _floor_height(pm: PhysicsModel, d: Any, mujoco: Any) -> float:
    """Height of the lowest point of the robot's collision geometry in ``d``'s configuration."""
    m = pm.model
    m.geom_pos[pm.floor_geom] = 0.0
    mujoco.mj_forward(m, d)
    lowest = math.inf
    fromto = np.zeros(6)
    for g in range(m.ngeom):
        if g == pm.floor_geom or m.geom_contype[g] == 0:
            continue
        dist = mujoco.mj_geomDistance(m, d, g, pm.floor_geom, 10.0, fromto)
        lowest = min(lowest, float(dist))
    return 0.0 if not math.isfinite(lowest) else lowest


# ------------------------------------------------------------------------------------ replay
@dataclass
class _Reference:
    """The run's reference series in the model's joint and foot order (one row a frame)."""

    t: np.ndarray
    root: np.ndarray
    joints: np.ndarray
    joint_vel: np.ndarray
    base_vel: np.ndarray
    contacts: np.ndarray
    contacts_assumed: bool


def _reference(traj: Any, pm: PhysicsModel, cols: np.ndarray) -> _Reference:
    """The run's base pose, joints, velocities and supporting feet, matched to ``pm``.

    A run without a velocity of the model's width gets zero velocities; a run without contact
    flags (or with flags of another shape) has every foot supporting (``contacts_assumed``).
    """
    t = np.asarray(traj.t, float)
    T, n, F = len(t), len(pm.joint_names), len(pm.foot_names)
    q_all = np.asarray(traj.q, float)
    v_all = np.asarray(traj.v, float)
    has_v = v_all.shape == (T, 6 + n)
    contacts = np.asarray(traj.contacts, bool) if traj.contacts is not None else None
    ref_contacts = np.ones((T, F), bool)
    contacts_assumed = True
    if contacts is not None and contacts.shape == (T, len(traj.foot_names)) and F:
        ref_contacts = np.zeros((T, F), bool)
        for i, name in enumerate(pm.foot_names):
            if name in traj.foot_names:
                ref_contacts[:, i] = contacts[:, list(traj.foot_names).index(name)]
        contacts_assumed = False
    return _Reference(
        t=t,
        root=q_all[:, :7],
        joints=q_all[:, 7:][:, cols],
        joint_vel=v_all[:, 6:][:, cols] if has_v else np.zeros((T, n)),
        base_vel=v_all[:, :6] if has_v else np.zeros((T, 6)),
        contacts=ref_contacts,
        contacts_assumed=contacts_assumed,
    )


def _feedforward(pm: PhysicsModel, ref: _Reference, feedforward: str) -> np.ndarray:
    """``tau_ff`` of eq. 1 per frame (T, n): :func:`gravity_feedforward` or zeros.

    Raises:
        PhysicsInputError: ``feedforward`` is not one of :data:`FEEDFORWARDS`.
    """
    if feedforward not in FEEDFORWARDS:
        raise PhysicsInputError(
            f"unknown feed-forward {feedforward!r}; choose from {', '.join(FEEDFORWARDS)}."
        )
    if feedforward == "gravity" and pm.robot is not None:
        return gravity_feedforward(pm, ref.root, ref.joints, ref.contacts)
    return np.zeros((len(ref.t), len(pm.joint_names)))


def _progress_bar(total: int, desc: str) -> Any:
    """A tqdm bar counting frames."""
    from tqdm import tqdm

    return tqdm(total=total, unit="frame", desc=desc)


#: The per-frame series :class:`_Replay` fills, named as :class:`ReplaySeries`'s fields.
_SERIES = (
    "pelvis_height",
    "pelvis_height_ref",
    "tilt_deg",
    "root_pos_err",
    "root_ori_err_deg",
    "joint_err",
    "saturated",
    "foot_force",
    "other_force",
    "assist_force",
    "assist_torque",
    "assist_horizontal",
)


class _Replay:
    """One replay in progress: the MuJoCo state, the reference and the series being filled.

    :meth:`frame` simulates one run frame in the sub-steps of eq. 1 and records it; the caller
    owns the loop (progress bar, fall test), :meth:`series` hands the result over.
    """

    def __init__(
        self, pm: PhysicsModel, mujoco: Any, ref: _Reference, tau_ff: np.ndarray, assisted: bool
    ) -> None:
        self.pm, self.mujoco, self.ref, self.tau_ff, self.assisted = (
            pm,
            mujoco,
            ref,
            tau_ff,
            assisted,
        )
        self.m = m = pm.model
        pm.apply_gains()
        self.d = mujoco.MjData(m)
        self.dref = mujoco.MjData(m)
        self.d.eq_active[pm.assist_eq] = 1 if assisted else 0
        self.eq_type = mujoco.mjtConstraint.mjCNSTR_EQUALITY
        self.floor = self._start()
        self.h0 = float(m.opt.timestep)
        self.f6 = np.zeros(6)
        self.simulated = 1
        self._allocate()

    def _start(self) -> float:
        """Place the floor under the first frame, set the first pose and velocity; the floor."""
        mujoco, m, d, ref, pm = self.mujoco, self.m, self.d, self.ref, self.pm
        root_ref, vb_ref = ref.root, ref.base_vel
        set_configuration(d, root_ref[0], ref.joints[0], pm.qpos_adr)
        floor = _floor_height(pm, d, mujoco)
        m.geom_pos[pm.floor_geom] = [0.0, 0.0, floor]
        R0 = _quat_to_mat(_wxyz(root_ref[0]))
        d.qvel[:] = 0.0
        d.qvel[0:3] = R0 @ vb_ref[0, :3]
        d.qvel[3:6] = vb_ref[0, 3:6]
        d.qvel[pm.dof_adr] = ref.joint_vel[0]
        d.mocap_pos[pm.assist_mocap] = root_ref[0, :3]
        d.mocap_quat[pm.assist_mocap] = _wxyz(root_ref[0])
        mujoco.mj_forward(m, d)
        return floor

    def _allocate(self) -> None:
        """The per-frame series (NaN until simulated) with frame 0 filled in."""
        T, n, F = len(self.ref.t), len(self.pm.joint_names), len(self.pm.foot_names)
        nan = np.full(T, np.nan)
        self.pelvis_height, self.pelvis_height_ref = nan.copy(), self.ref.root[:, 2].copy()
        self.tilt_deg, self.root_pos_err, self.root_ori_err_deg = nan.copy(), nan.copy(), nan.copy()
        self.joint_err = np.full((T, n), np.nan)
        self.saturated = np.zeros((T, n), bool)
        self.foot_force = np.full((T, F), np.nan)
        self.other_force = nan.copy()
        self.assist_force, self.assist_torque = nan.copy(), nan.copy()
        self.assist_horizontal = nan.copy()
        d = self.d
        self.pelvis_height[0] = d.qpos[2]
        self.tilt_deg[0] = self.root_pos_err[0] = self.root_ori_err_deg[0] = 0.0
        self.joint_err[0] = d.qpos[self.pm.qpos_adr] - self.ref.joints[0]
        self.foot_force[0], self.other_force[0] = np.nan, np.nan

    def _base_quats(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Reference base orientations of frames ``k - 1`` and ``k``, on one hemisphere."""
        r0, r1 = _wxyz(self.ref.root[k - 1]), _wxyz(self.ref.root[k])
        if float(np.dot(r0, r1)) < 0.0:
            r1 = -r1
        return r0, r1

    def frame(self, k: int) -> None:
        """Simulate from frame ``k - 1`` to ``k`` (eq. 1 each sub-step) and record frame ``k``."""
        m, d, pm, ref = self.m, self.d, self.pm, self.ref
        n, F = len(pm.joint_names), len(pm.foot_names)
        dt = float(ref.t[k] - ref.t[k - 1])
        n_sub = max(1, int(round(dt / self.h0)))
        m.opt.timestep = dt / n_sub
        r0, r1 = self._base_quats(k)
        sat = np.zeros(n, bool)
        ff = np.zeros(F)
        fo = 0.0
        af = ah = an = 0.0
        for j in range(n_sub):
            self._drive(k, j / n_sub, r0, r1, sat)
            self.mujoco.mj_step(m, d)
            if self.assisted:
                w = self._weld_wrench()
                if len(w) == 6:  # rows in world axes: x y z force, then torque
                    af += float(np.linalg.norm(w[:3]))
                    ah += float(np.linalg.norm(w[:2]))
                    an += float(np.linalg.norm(w[3:]))
            fo = self._floor_forces(ff, fo)
        m.opt.timestep = self.h0
        self.simulated = k + 1
        self.saturated[k] = sat
        self.foot_force[k] = ff / n_sub
        self.other_force[k] = fo / n_sub
        if self.assisted:
            self.assist_force[k], self.assist_torque[k] = af / n_sub, an / n_sub
            self.assist_horizontal[k] = ah / n_sub
        self._measure(k, r1)

    def _drive(self, k: int, a: float, r0: np.ndarray, r1: np.ndarray, sat: np.ndarray) -> None:
        """Set the actuators (eq. 1) and the assisting target at fraction ``a`` of frame ``k``.

        ``sat`` collects the joints whose unclamped torque reaches the limit.
        """
        pm, d, ref = self.pm, self.d, self.ref
        q0, q1 = ref.joints[k - 1], ref.joints[k]
        vff = ref.joint_vel[k]
        f0, f1 = self.tau_ff[k - 1], self.tau_ff[k]
        qr = q0 + a * (q1 - q0)
        tff = f0 + a * (f1 - f0)
        u = pm.kp * (qr - d.qpos[pm.qpos_adr]) + pm.kd * (vff - d.qvel[pm.dof_adr]) + tff  # eq. 1
        sat |= np.abs(u) >= pm.effort
        d.ctrl[:] = qr + (pm.kd / pm.kp) * vff + tff / pm.kp  # position actuators, clamped
        if self.assisted:
            p0, p1 = ref.root[k - 1, :3], ref.root[k, :3]
            rr = r0 + a * (r1 - r0)
            d.mocap_pos[pm.assist_mocap] = p0 + a * (p1 - p0)
            d.mocap_quat[pm.assist_mocap] = rr / np.linalg.norm(rr)

    def _weld_wrench(self) -> np.ndarray:
        """The assisting weld's constraint force rows: 3 force rows, 3 torque rows."""
        d = self.d
        rows = (d.efc_type == self.eq_type) & (d.efc_id == self.pm.assist_eq)
        return np.asarray(d.efc_force[rows])

    def _floor_forces(self, ff: np.ndarray, fo: float) -> float:
        """Add this step's normal floor forces to ``ff`` (per foot) and ``fo`` (the rest)."""
        m, d, pm = self.m, self.d, self.pm
        for c in range(d.ncon):
            con = d.contact[c]
            g1, g2 = int(con.geom1), int(con.geom2)
            if g1 == pm.floor_geom:
                other = g2
            elif g2 == pm.floor_geom:
                other = g1
            else:
                continue
            self.mujoco.mj_contactForce(m, d, c, self.f6)
            foot = pm.foot_of_body[m.geom_bodyid[other]]
            if foot >= 0:
                ff[foot] += self.f6[0]
            else:
                fo += self.f6[0]
        return fo

    def _measure(self, k: int, r1: np.ndarray) -> None:
        """Base height, pose errors, joint errors and torso tilt of frame ``k``."""
        mujoco, m, d, dref, pm, ref = self.mujoco, self.m, self.d, self.dref, self.pm, self.ref
        q1, p1 = ref.joints[k], ref.root[k, :3]
        qb = d.qpos[3:7]
        self.pelvis_height[k] = d.qpos[2]
        self.root_pos_err[k] = float(np.linalg.norm(d.qpos[0:3] - p1))
        conj = np.array([qb[0], -qb[1], -qb[2], -qb[3]])
        self.root_ori_err_deg[k] = math.degrees(
            float(np.linalg.norm(_quat_log(_quat_mul(conj, r1))))
        )
        self.joint_err[k] = d.qpos[pm.qpos_adr] - q1
        # torso's vertical axis, simulated and reference (FK of the reference frame)
        set_configuration(dref, ref.root[k], q1, pm.qpos_adr)
        mujoco.mj_kinematics(m, dref)
        mujoco.mj_kinematics(m, d)  # after mj_step, xmat still holds the step's start
        z_sim = d.xmat[pm.torso_body].reshape(3, 3)[:, 2]
        z_ref = dref.xmat[pm.torso_body].reshape(3, 3)[:, 2]
        cos = max(-1.0, min(1.0, float(np.dot(z_sim, z_ref))))
        self.tilt_deg[k] = math.degrees(math.acos(cos))

    def fallen(self, k: int, fall_height: float, fall_tilt: float) -> bool:
        """Whether frame ``k`` has fallen: pelvis ``fall_height`` [m] low or tilt > ``fall_tilt``.

        The pelvis is compared with the reference's height, the torso's tilt [rad] with the
        reference torso's vertical axis.
        """
        down = self.pelvis_height_ref[k] - self.pelvis_height[k] > fall_height
        return bool(down or math.radians(self.tilt_deg[k]) > fall_tilt)

    def series(self, fallen_at: int | None, wall: float) -> ReplaySeries:
        """The recorded series."""
        pm, t = self.pm, self.ref.t
        return ReplaySeries(
            t=t,
            assisted=self.assisted,
            simulated=self.simulated,
            fallen_at=fallen_at,
            **{name: getattr(self, name) for name in _SERIES},
            ref_contacts=self.ref.contacts,
            joint_names=list(pm.joint_names),
            foot_names=list(pm.foot_names),
            mass=pm.mass,
            floor_height=self.floor,
            wall_time_s=wall,
            sim_time_s=float(t[self.simulated - 1] - t[0]),
            contacts_assumed=self.ref.contacts_assumed,
        )


def replay_run(
    traj: Any,
    pm: PhysicsModel,
    *,
    assisted: bool = False,
    stop_on_fall: bool = True,
    fall_height: float | None = None,
    fall_tilt_deg: float | None = None,
    progress: bool = False,
    feedforward: str = "gravity",
) -> ReplaySeries:
    """Replay ``traj`` (a :class:`~qpretarget.trajectory.RobotTrajectory`) on ``pm``.

    Args:
        traj: the run; its joints are matched to the model's by name.
        pm: the model (:func:`~qpretarget.physics.model.build_physics_model`).
        assisted: weld the base to the reference base pose (the virtual root wrench).
        stop_on_fall: stop at the first fallen frame (frames after it are NaN).
        fall_height: fall when the pelvis is this far below the reference's [m] (default
            :data:`~qpretarget.physics.metrics.FALL_HEIGHT_M`).
        fall_tilt_deg: fall when the torso tilts this far from the reference's [deg] (default
            :data:`~qpretarget.physics.metrics.FALL_TILT_DEG`).
        progress: show a progress bar (frames).
        feedforward: ``gravity`` adds :func:`gravity_feedforward` to eq. 1; ``none``: PD and
            velocity feed-forward only.

    Raises:
        PhysicsInputError: the run does not match the robot (before any simulation).
    """
    from .metrics import FALL_HEIGHT_M, FALL_TILT_DEG

    fall_height = FALL_HEIGHT_M if fall_height is None else fall_height
    fall_tilt = math.radians(FALL_TILT_DEG if fall_tilt_deg is None else fall_tilt_deg)
    cols = joint_columns(traj, pm)
    mujoco = import_mujoco()
    ref = _reference(traj, pm, cols)
    T = len(ref.t)
    sim = _Replay(pm, mujoco, ref, _feedforward(pm, ref, feedforward), assisted)
    fallen_at: int | None = None
    bar = _progress_bar(T - 1, "assisted" if assisted else "physics") if progress else None
    t0 = time.perf_counter()
    for k in range(1, T):
        if bar is not None:
            bar.update(1)
        sim.frame(k)
        if fallen_at is None and sim.fallen(k, fall_height, fall_tilt):
            fallen_at = k
            if stop_on_fall:
                break
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    return sim.series(fallen_at, wall)


def robot_of_run(traj: Any) -> Any:
    """The :class:`~qpretarget.robot.RobotModel` a run was retargeted with (from its config)."""
    from ..robot import load_robot
    from ..yamlio import load_yaml

    spec: Any = traj.robot
    try:
        cfg = load_yaml(traj.config_yaml) if traj.config_yaml else None
    except Exception:  # noqa: BLE001  (a run without a readable config: use its robot name)
        cfg = None
    if isinstance(cfg, dict) and "robot" in cfg:
        spec = cfg["robot"]
    return load_robot(spec)


def check_run(
    traj: Any,
    *,
    robot: Any = None,
    pm: PhysicsModel | None = None,
    gains: str | None = None,
    timestep: float | None = None,
    assisted: bool = True,
    progress: bool = False,
    feedforward: str = "gravity",
) -> tuple[dict[str, Any], ReplaySeries, ReplaySeries | None]:
    """Build the model, replay the run unassisted (and assisted), return the metrics.

    Args:
        traj: the run (:class:`~qpretarget.trajectory.RobotTrajectory`).
        robot: its robot model (default: built from the run's stored config).
        pm: a model built beforehand (reused across runs of the same robot).
        gains: gain profile name (default ``stiff``).
        timestep: physics time step [s] (default 2 ms).
        assisted: also run the assisted replay.
        progress: progress bars.
        feedforward: ``gravity`` (default) or ``none`` (see :func:`replay_run`).

    Returns:
        ``(metrics, unassisted series, assisted series or None)``; metrics as
        :func:`~qpretarget.physics.metrics.summarize`.

    Raises:
        PhysicsInputError: the run does not match the robot (checked before any simulation).
        PhysicsModelError: the URDF does not convert.
    """
    from .metrics import summarize
    from .model import DEFAULT_TIMESTEP, build_physics_model

    if pm is None:
        robot = robot if robot is not None else robot_of_run(traj)
        pm = build_physics_model(
            robot, gains=gains, timestep=timestep if timestep is not None else DEFAULT_TIMESTEP
        )
    cols = joint_columns(traj, pm)
    free = replay_run(traj, pm, assisted=False, progress=progress, feedforward=feedforward)
    helped = (
        replay_run(traj, pm, assisted=True, progress=progress, feedforward=feedforward)
        if assisted
        else None
    )
    if pm.robot is not None:
        free.ref_zmp_margin = _reference_zmp_margin(traj, pm.robot, cols, free)
    return summarize(free, helped, pm), free, helped


def _reference_zmp_margin(
    traj: Any, robot: Any, cols: np.ndarray, free: ReplaySeries
) -> np.ndarray:
    """The run's reference ZMP margin (T,) [m] on the replay's stance feet and floor.

    The run's q and v are written into ``robot``'s configuration order (joints by name).
    """
    from .zmp import reference_zmp_margin

    T = len(traj.t)
    q = np.tile(np.asarray(robot.q_reference, float), (T, 1))
    q[:, :7] = np.asarray(traj.q)[:, :7]
    q[:, robot.joint_q_index] = np.asarray(traj.q)[:, 7:][:, cols]
    v = np.zeros((T, robot.nv))
    if np.shape(traj.v) == (T, robot.nv):
        v[:, :6] = np.asarray(traj.v)[:, :6]
        v[:, robot.joint_v_index] = np.asarray(traj.v)[:, 6:][:, cols]
    return reference_zmp_margin(
        robot, np.asarray(traj.t, float), q, v, free.ref_contacts, free.floor_height
    )[1]
