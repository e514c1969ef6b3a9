# SPDX-License-Identifier: Apache-2.0
"""MuJoCo model of a qpretarget robot, built from the URDF and meshes it was retargeted with.

:func:`build_physics_model` reads the robot's URDF (the one example-robot-data ships for a bundled
robot), rewrites it for MuJoCo's URDF importer and adds what a URDF does not hold
(docs/physics.md, "Model"):

* mesh paths: ``package://`` URIs and relative paths are resolved to absolute files (MuJoCo does
  not resolve ``package://``); ``<visual>`` elements are dropped (the replay draws nothing), so
  only collision meshes must be in a format MuJoCo reads (STL, OBJ, MSH);
* a free joint on the root link (the floating base) and a floor plane;
* per joint: armature, viscous damping and friction loss, and one torque actuator limited to the
  URDF ``<limit effort>``, with the PD gains of a :mod:`~qpretarget.physics.gains` profile;
* contacts: the robot's collision geometries against the floor only (self-collision is checked
  kinematically by ``qpretarget evaluate``); ``self_collision=True`` turns robot-robot contacts on
  (parent-child pairs stay off, MuJoCo's default).

Joints are matched to pinocchio's by name, never by position: MuJoCo's order may differ.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import QPRetargetError, missing_dependency
from .gains import (
    DEFAULT_PROFILE,
    GAIN_PROFILES,
    GENERIC_OMEGA,
    GENERIC_PASSIVE,
    GENERIC_ZETA,
    STIFF_DAMPING_TIME,
    STIFF_ERROR_AT_LIMIT,
    GainProfile,
)

#: Oldest mujoco with the model-editing API used here (``MjSpec.joint(name)``); tested with
#: 3.3.7 and 4.0.0.
MIN_MUJOCO = (3, 3)
#: Mesh formats MuJoCo reads (lower-case suffixes).
MESH_SUFFIXES = (".stl", ".obj", ".msh")
#: Physics time step [s] (MuJoCo's default; Unitree's and mjlab's G1 models use 2-5 ms).
DEFAULT_TIMESTEP = 0.002
#: Time constant [s] of the assisting weld (MuJoCo ``solref``; damping ratio 1) and its
#: impedance (``solimp`` d0 = d_width): soft, so that the feet, not the weld, carry the weight
#: when they can (a stiff weld shares the load with the stance legs like a third leg).
ASSIST_TIMECONST = 0.1
ASSIST_IMPEDANCE = 0.1
#: Sliding friction coefficient of the floor (MuJoCo's default; the larger of two geoms counts).
FLOOR_FRICTION = 1.0


class PhysicsModelError(QPRetargetError, ValueError):
    """The robot's URDF does not convert to a MuJoCo model; the message names the element."""


def import_mujoco() -> Any:
    """Import ``mujoco`` or raise the one-line install hint of the ``physics`` extra."""
    try:
        import mujoco
    except ImportError:
        raise missing_dependency("physics", "the physics check (--physics)") from None
    version = tuple(int(x) for x in mujoco.__version__.split(".")[:2] if x.isdigit())
    if version < MIN_MUJOCO:
        raise missing_dependency(
            "physics",
            f"the physics check needs mujoco >= {MIN_MUJOCO[0]}.{MIN_MUJOCO[1]} (found "
            f"{mujoco.__version__}); it",
        )
    return mujoco


@dataclass
class PhysicsModel:
    """A compiled MuJoCo model of a robot and how it maps to the pinocchio model.

    Attributes:
        model: the ``mujoco.MjModel``.
        robot_name: registry name or URDF stem.
        joint_names: actuated one-DoF joints, in the pinocchio model's order.
        qpos_adr / dof_adr: MuJoCo ``qpos`` / ``qvel`` address of each joint of ``joint_names``.
        kp, kd, effort: PD gains [N m/rad, N m s/rad] and torque limits [N m] per joint.
        gains: profile name; gains_source: where its numbers come from.
        root_body: body id of the floating base; torso_body: body of the ``torso`` key-point.
        foot_bodies: foot name -> body id (the body carrying the sole frame).
        foot_of_body: body id -> index of the foot it belongs to (``-1``: not a foot).
        floor_geom: geom id of the floor plane.
        mass: total mass [kg].
        effort_missing: joints whose URDF gives no effort limit (left unlimited).
        notes: what was changed to convert the URDF.
        robot: the :class:`~qpretarget.robot.RobotModel` it was built from (pinocchio, for the
            gravity feed-forward).
    """

    model: Any
    robot_name: str
    joint_names: list[str]
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    effort: np.ndarray
    gains: str
    gains_source: str
    root_body: int
    torso_body: int
    foot_names: list[str]
    foot_bodies: list[int]
    foot_of_body: np.ndarray
    floor_geom: int
    assist_eq: int
    assist_mocap: int
    mass: float
    effort_missing: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    robot: Any = None

    def apply_gains(self) -> None:
        """Write ``kp``, ``kd`` and ``effort`` into the model's actuators (after changing them).

        Replay eq. 1 as MuJoCo position actuators, whose damping ``implicitfast`` integrates
        implicitly: ``force = kp ctrl - kp q - kd qdot`` with ``ctrl = q_ref + kd / kp qdot_ref``,
        clamped to ``[-effort, effort]``.
        """
        mujoco = import_mujoco()
        m = self.model
        ids = np.array([m.actuator(n).id for n in self.joint_names], dtype=int)
        m.actuator_gaintype[ids] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_biastype[ids] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_gainprm[ids, 0] = self.kp
        m.actuator_biasprm[ids, 0] = 0.0
        m.actuator_biasprm[ids, 1] = -self.kp
        m.actuator_biasprm[ids, 2] = -self.kd
        m.actuator_ctrllimited[ids] = 0
        finite = np.isfinite(self.effort)
        m.actuator_forcelimited[ids] = finite.astype(np.uint8)
        m.actuator_forcerange[ids, 0] = np.where(finite, -self.effort, 0.0)
        m.actuator_forcerange[ids, 1] = np.where(finite, self.effort, 0.0)

    @property
    def timestep(self) -> float:
        """Physics time step [s]."""
        return float(self.model.opt.timestep)

    def describe(self) -> dict[str, Any]:
        """The model's assumptions, for the metrics file."""
        m = self.model
        return {
            "engine": "mujoco",
            "robot": self.robot_name,
            "timestep_s": self.timestep,
            "integrator": "implicitfast",
            "gains": self.gains,
            "gains_source": self.gains_source,
            "mass_kg": self.mass,
            "floor_friction": FLOOR_FRICTION,
            "contact_solref": [float(x) for x in m.geom_solref[self.floor_geom]],
            "contact_solimp": [float(x) for x in m.geom_solimp[self.floor_geom]],
            "assist_weld_solref": [float(x) for x in m.eq_solref[self.assist_eq]],
            "assist_weld_solimp": [float(x) for x in m.eq_solimp[self.assist_eq]],
            "joints": {
                n: {
                    "kp": float(self.kp[i]),
                    "kd": float(self.kd[i]),
                    "effort_Nm": float(self.effort[i]),
                    "armature": float(m.dof_armature[self.dof_adr[i]]),
                    "damping": float(m.dof_damping[self.dof_adr[i]]),
                    "frictionloss": float(m.dof_frictionloss[self.dof_adr[i]]),
                }
                for i, n in enumerate(self.joint_names)
            },
            "effort_missing": list(self.effort_missing),
            "notes": list(self.notes),
        }


# ------------------------------------------------------------------------------ URDF rewrite
def _resolve_mesh(filename: str, urdf: Path) -> Path | None:
    """Absolute path of a URDF mesh ``filename`` (``package://``, ``file://`` or relative)."""
    from ..robots import share_directory

    if filename.startswith("file://"):
        p = Path(filename[7:])
        return p if p.is_file() else None
    if filename.startswith("package://"):
        rest = filename[len("package://") :]
        roots: list[Path] = []
        try:
            roots.append(share_directory())
        except FileNotFoundError:
            pass
        roots += list(urdf.resolve().parents)
        pkg, _, sub = rest.partition("/")
        for root in roots:
            for cand in (root / rest, root / sub):
                if cand.is_file():
                    return cand
            if root.name == pkg and (root / sub).is_file():
                return root / sub
        return None
    p = Path(filename)
    if not p.is_absolute():
        p = urdf.parent / p
    return p if p.is_file() else None


def _drop_visuals_resolve_meshes(root: ET.Element, urdf: Path) -> int:
    """Remove every link's ``<visual>``; make collision mesh paths absolute; the visuals dropped.

    Raises:
        PhysicsModelError: a collision mesh that is missing or in a format MuJoCo does not read.
    """
    n_visual = 0
    for link in root.findall("link"):
        for vis in link.findall("visual"):
            link.remove(vis)
            n_visual += 1
        for col in link.findall("collision"):
            for mesh in col.iter("mesh"):
                fn = mesh.get("filename", "")
                lname = link.get("name", "?")
                path = _resolve_mesh(fn, urdf)
                if path is None:
                    raise PhysicsModelError(
                        f"{urdf.name}: link {lname!r} <collision> mesh {fn!r} was not found "
                        "(package:// URIs are looked up in example-robot-data's share folder and "
                        "above the URDF)."
                    )
                if path.suffix.lower() not in MESH_SUFFIXES:
                    raise PhysicsModelError(
                        f"{urdf.name}: link {lname!r} <collision> mesh {fn!r} is a "
                        f"{path.suffix} file; MuJoCo reads {', '.join(MESH_SUFFIXES)} meshes only. "
                        "Convert it (e.g. with trimesh) and point the URDF at the copy."
                    )
                mesh.set("filename", str(path))
    return n_visual


def rewrite_urdf(urdf: Path) -> tuple[str, list[str]]:
    """URDF text MuJoCo can import: absolute mesh paths, no visuals, no simulator extensions.

    Returns:
        The text and the list of changes made (for the report).

    Raises:
        PhysicsModelError: a collision mesh that is missing or in a format MuJoCo does not read,
            naming its link and file.
    """
    try:
        tree = ET.parse(urdf)
    except (OSError, ET.ParseError) as exc:
        raise PhysicsModelError(f"{urdf}: not a readable URDF ({exc}).") from None
    root = tree.getroot()
    notes: list[str] = []
    dropped = {"gazebo": 0, "transmission": 0, "mujoco": 0}
    for tag in dropped:
        for el in root.findall(tag):
            root.remove(el)
            dropped[tag] += 1
    n_visual = _drop_visuals_resolve_meshes(root, urdf)
    if n_visual:
        notes.append(f"dropped {n_visual} <visual> elements (not simulated)")
    for tag, n in dropped.items():
        if n:
            notes.append(f"dropped {n} <{tag}> element(s)")
    for joint in root.findall("joint"):
        jtype = joint.get("type", "")
        if jtype in ("floating", "planar"):
            raise PhysicsModelError(
                f"{urdf.name}: joint {joint.get('name')!r} is of type {jtype!r}; the physics "
                "model adds the floating base itself and converts revolute, continuous, "
                "prismatic and fixed joints only."
            )
    mj = ET.SubElement(root, "mujoco")
    ET.SubElement(
        mj,
        "compiler",
        {
            "strippath": "false",
            "discardvisual": "true",
            "fusestatic": "false",
            "balanceinertia": "true",
            "angle": "radian",
        },
    )
    return ET.tostring(root, encoding="unicode"), notes


# ------------------------------------------------------------------------------ model build
def _body_of_frame(robot: Any, frame: str, mj_model: Any, mujoco: Any, root_body: int) -> int:
    """MuJoCo body moved by the joint that carries the pinocchio frame ``frame``."""
    pin_model = robot.model
    fid = robot.frame_id(frame)
    jid = pin_model.frames[fid].parentJoint
    if jid <= 1 and robot.free_flyer:
        return root_body
    jname = pin_model.names[jid]
    j = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, jname)
    if j < 0:
        raise PhysicsModelError(f"joint {jname!r} of frame {frame!r} is not in the MuJoCo model.")
    return int(mj_model.jnt_bodyid[j])


def _gain_profile(robot: Any, gains: str | None, timestep: float) -> GainProfile:
    """The :class:`~qpretarget.physics.gains.GainProfile` to build with, options checked.

    Raises:
        PhysicsModelError: a fixed-base robot, a time step outside (0, 0.05] s, an unknown gain
            profile or one written for another robot.
    """
    if not robot.free_flyer:
        raise PhysicsModelError(
            f"robot {robot.name!r} has a fixed base; the physics check replays floating-base "
            "humanoids (it asks whether the robot stays up)."
        )
    if not (math.isfinite(timestep) and 0.0 < timestep <= 0.05):
        raise PhysicsModelError(
            f"physics time step {timestep!r} s: give a value in (0, 0.05], e.g. 0.002."
        )
    profile_name = gains or DEFAULT_PROFILE
    if profile_name not in GAIN_PROFILES:
        raise PhysicsModelError(
            f"unknown gain profile {profile_name!r}; choose from {', '.join(GAIN_PROFILES)}."
        )
    profile = GAIN_PROFILES[profile_name]
    if profile.robots and robot.name not in profile.robots:
        raise PhysicsModelError(
            f"gain profile {profile_name!r} is written for {', '.join(profile.robots)}, not "
            f"{robot.name!r}; use --physics-gains stiff or generic."
        )
    return profile


def _import_urdf(mujoco: Any, urdf: Path) -> tuple[Any, Any, list[str]]:
    """``(spec, base body, notes)``: the rewritten URDF imported, a free joint on its root link.

    Raises:
        PhysicsModelError: MuJoCo's importer rejects it, or it has more than one root link.
    """
    text, notes = rewrite_urdf(urdf)
    try:
        spec = mujoco.MjSpec.from_string(text)
    except Exception as exc:  # mujoco raises ValueError naming the element
        raise PhysicsModelError(
            f"{urdf.name}: MuJoCo's URDF import failed: {str(exc).strip()}"
        ) from None
    roots = list(spec.worldbody.bodies)
    if len(roots) != 1:
        raise PhysicsModelError(
            f"{urdf.name}: expected one root link, MuJoCo found {[b.name for b in roots]}."
        )
    base = roots[0]
    base.add_freejoint(name="floating_base")
    return spec, base, notes


def _add_world(spec: Any, mujoco: Any, base: Any, timestep: float, self_collision: bool) -> None:
    """Time step and integrator, contact filtering, the floor and the (inactive) assisting weld."""
    spec.option.timestep = float(timestep)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    # Contacts: robot geoms (contype 1) touch the floor (conaffinity 1) only, unless
    # self-collision is asked for; then robot geoms also have conaffinity 1.
    for g in spec.geoms:
        g.contype = 1
        g.conaffinity = 1 if self_collision else 0
    floor = spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        friction=[FLOOR_FRICTION, 0.005, 0.0001],
    )
    floor.contype = 0
    floor.conaffinity = 1
    # Assisted replay: a mocap body on the reference base pose, welded to the base by a soft
    # equality constraint (integrated implicitly by the constraint solver), off by default.
    target = spec.worldbody.add_body(name="assist_target", mocap=True)
    weld = spec.add_equality(
        name="assist",
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=base.name,
        name2=target.name,
    )
    weld.data[:11] = [0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1]  # anchor, identity relative pose, torque 1
    weld.solref = [ASSIST_TIMECONST, 1.0]
    weld.solimp[:3] = [ASSIST_IMPEDANCE, ASSIST_IMPEDANCE, 0.001]
    weld.active = False


def _add_actuated_joints(
    spec: Any, mujoco: Any, robot: Any, profile: GainProfile, urdf: Path
) -> tuple[list[tuple[float, float] | None], np.ndarray, list[str]]:
    """Passive joint terms, torque limits and one actuator per joint of ``robot``.

    Returns:
        ``(gains, effort, effort_missing)``: the profile's ``(kp, kd)`` per joint (``None`` where
        a rule computes them after compiling), the URDF effort limits [N m] (``inf`` where
        missing) and the joints without one.

    Raises:
        PhysicsModelError: a joint missing from the MuJoCo model or from a gain table.
    """
    pin_model = robot.model
    generic = profile.rule != "table"
    gain_list: list[tuple[float, float] | None] = []
    effort = np.zeros(len(robot.joint_names))
    effort_missing = []
    for i, jname in enumerate(robot.joint_names):
        sj = spec.joint(jname)
        if sj is None:
            raise PhysicsModelError(
                f"{urdf.name}: joint {jname!r} of the pinocchio model is not in the MuJoCo model."
            )
        g = None if generic else profile.gains(jname)
        if g is None and not generic:
            raise PhysicsModelError(
                f"gain profile {profile.name!r} has no gains for joint {jname!r}."
            )
        passive = g or GENERIC_PASSIVE
        sj.armature = passive.armature
        _set_scalar(sj, "damping", passive.damping)
        sj.frictionloss = passive.frictionloss
        gain_list.append(None if g is None else (g.kp, g.kd))
        idx_v = pin_model.joints[pin_model.getJointId(jname)].idx_v
        e = float(pin_model.effortLimit[idx_v])
        if not (math.isfinite(e) and e > 0):
            effort_missing.append(jname)
            e = math.inf
        effort[i] = e
        act = spec.add_actuator(name=jname, target=jname)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
    return gain_list, effort, effort_missing


def _pd_gains(
    m: Any,
    profile: GainProfile,
    gain_list: list[tuple[float, float] | None],
    effort: np.ndarray,
    dof_adr: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(kp, kd)`` per joint: the profile's table, else its rule (on the compiled model ``m``).

    The ``effort`` rule makes a stiff servo (full effort at ``STIFF_ERROR_AT_LIMIT``); the
    ``generic`` rule sets a natural frequency and damping ratio on the joint's apparent inertia
    (``dof_M0``, computed at compile time).
    """
    kp = np.zeros(len(gain_list))
    kd = np.zeros(len(gain_list))
    for i, gl in enumerate(gain_list):
        if gl is not None:
            kp[i], kd[i] = gl
        elif profile.rule == "effort":  # stiff servo: full effort at STIFF_ERROR_AT_LIMIT
            e = effort[i] if math.isfinite(effort[i]) else 100.0
            kp[i] = e / STIFF_ERROR_AT_LIMIT
            kd[i] = STIFF_DAMPING_TIME * kp[i]
        else:  # generic rule on the apparent inertia (dof_M0, computed at compile time)
            inertia = float(m.dof_M0[dof_adr[i]])
            kp[i] = inertia * GENERIC_OMEGA**2
            kd[i] = 2.0 * GENERIC_ZETA * inertia * GENERIC_OMEGA
    return kp, kd


def _foot_of_body(m: Any, foot_bodies: list[int]) -> np.ndarray:
    """Body id -> index of the foot it belongs to (a foot's descendants too), ``-1`` elsewhere."""
    foot_of_body = np.full(m.nbody, -1, dtype=int)
    for b in range(1, m.nbody):  # a foot's descendants (toes, sole links) belong to it
        a = b
        while a > 0:
            if a in foot_bodies:
                foot_of_body[b] = foot_bodies.index(a)
                break
            a = int(m.body_parentid[a])
    return foot_of_body


def _key_bodies(robot: Any, m: Any, mujoco: Any, base_name: str) -> tuple[int, int, list[int]]:
    """``(root body, torso body, foot bodies)`` of the compiled model ``m``.

    The torso is the body of the ``torso`` key-point (else ``pelvis``, else the root).
    """
    root_body = int(m.body(base_name).id)
    torso_frame = robot.keyframes.get("torso", robot.keyframes.get("pelvis"))
    torso_body = (
        _body_of_frame(robot, torso_frame, m, mujoco, root_body) if torso_frame else root_body
    )
    foot_bodies = [
        _body_of_frame(robot, f.frame, m, mujoco, root_body) for f in robot.feet.values()
    ]
    return root_body, torso_body, foot_bodies


def build_physics_model(
    robot: Any,
    *,
    gains: str | None = None,
    timestep: float = DEFAULT_TIMESTEP,
    self_collision: bool = False,
) -> PhysicsModel:
    """Build the MuJoCo model of ``robot`` (a :class:`~qpretarget.robot.RobotModel`).

    Args:
        robot: the robot the run was retargeted with (``load_robot(config["robot"])``).
        gains: a :data:`~qpretarget.physics.gains.GAIN_PROFILES` name; ``None``: ``stiff``.
        timestep: physics time step [s].
        self_collision: robot-robot contacts on (off: robot against the floor only).

    Raises:
        MissingDependencyError: mujoco is not installed (one-line install hint).
        PhysicsModelError: the URDF does not convert (the message names the element), or the
            robot has no floating base.
    """
    mujoco = import_mujoco()
    profile = _gain_profile(robot, gains, timestep)
    urdf = Path(robot.urdf_path)
    spec, base, notes = _import_urdf(mujoco, urdf)
    _add_world(spec, mujoco, base, timestep, self_collision)
    gain_list, effort, effort_missing = _add_actuated_joints(spec, mujoco, robot, profile, urdf)
    try:
        m = spec.compile()
    except Exception as exc:
        raise PhysicsModelError(f"{urdf.name}: MuJoCo could not compile the model: {exc}") from None
    qpos_adr = np.array([m.jnt_qposadr[m.joint(n).id] for n in robot.joint_names], dtype=int)
    dof_adr = np.array([m.jnt_dofadr[m.joint(n).id] for n in robot.joint_names], dtype=int)
    kp, kd = _pd_gains(m, profile, gain_list, effort, dof_adr)
    root_body, torso_body, foot_bodies = _key_bodies(robot, m, mujoco, base.name)
    pm = PhysicsModel(
        model=m,
        robot_name=robot.name,
        joint_names=list(robot.joint_names),
        qpos_adr=qpos_adr,
        dof_adr=dof_adr,
        kp=kp,
        kd=kd,
        effort=effort,
        gains=profile.name,
        gains_source=profile.source,
        root_body=root_body,
        torso_body=torso_body,
        foot_names=list(robot.feet),
        foot_bodies=foot_bodies,
        foot_of_body=_foot_of_body(m, foot_bodies),
        floor_geom=int(m.geom("floor").id),
        assist_eq=int(m.equality("assist").id),
        assist_mocap=int(m.body_mocapid[m.body("assist_target").id]),
        mass=float(np.sum(m.body_mass)),
        effort_missing=effort_missing,
        notes=notes,
        robot=robot,
    )
    pm.apply_gains()
    return pm


def _set_scalar(obj: Any, attr: str, value: float) -> None:
    """Set a spec attribute that is a scalar in MuJoCo 3 and a 3-vector (polynomial) in 4."""
    try:
        setattr(obj, attr, value)
    except TypeError:
        setattr(obj, attr, [value, 0.0, 0.0])


def set_configuration(d: Any, root: np.ndarray, joints: np.ndarray, qpos_adr: np.ndarray) -> None:
    """Write a configuration into ``d.qpos``.

    Args:
        d: ``mujoco.MjData``.
        root: pinocchio free flyer ``x y z qx qy qz qw``; MuJoCo's free joint is
            ``x y z qw qx qy qz``.
        joints: joint values, in the order of ``qpos_adr``.
        qpos_adr: MuJoCo ``qpos`` address of each joint.
    """
    d.qpos[0:3] = root[0:3]
    d.qpos[3] = root[6]
    d.qpos[4:7] = root[3:6]
    d.qpos[qpos_adr] = joints
