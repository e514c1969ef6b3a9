# SPDX-License-Identifier: Apache-2.0
"""Robot model and per-tick kinematic state.

:class:`RobotModel` wraps a pinocchio model built from a URDF (with a free-flyer base for
humanoids), its SRDF reference posture, joint limits with per-joint overrides, its feet and the
frames standing for the human key-points. :class:`RobotState` holds the kinematics of one
configuration, computed once per tick (one ``computeJointJacobians`` + ``updateFramePlacements``)
and read by every task and constraint module.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .errors import ConfigError, UnknownFrameError, UnknownJointError
from .robots import (
    FootDescription,
    RobotDescription,
    get_description,
    robots_directory,
    share_directory,
)
from .validation import check_keys

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: Prefix of a path inside example-robot-data's robots directory, e.g.
#: ``example-robot-data:panda_description/urdf/panda.urdf``.
ERD_PREFIX = "example-robot-data:"


def resolve_robot_path(path: str | Path) -> Path:
    """Resolve ``example-robot-data:REL`` against the installed package; other paths unchanged."""
    s = str(path)
    if s.startswith(ERD_PREFIX):
        return robots_directory() / s[len(ERD_PREFIX) :]
    return Path(s)


class RobotModel:
    """A robot: pinocchio model, limits, reference posture, feet and key-point frames.

    Args:
        urdf: path of the URDF file.
        srdf: path of the SRDF file (reference postures, disabled collision pairs) or ``None``.
        name: display name (registry name for bundled robots).
        free_flyer: add a free-flyer root joint (humanoids); ``False`` for fixed-base arms.
        reference: name of the SRDF reference configuration to use as standing posture.
        reference_joints: joint values [rad] applied on top of the reference posture.
        feet: foot name -> :class:`FootDescription`.
        keyframes: key-point name -> robot frame name.
        position_limits: joint -> ``(lower, upper)`` [rad] overriding the URDF.
        velocity_limits: joint -> limit [rad/s] overriding the URDF.
        place_on_ground: shift the base of the reference posture so that the soles touch z = 0
            and sit centred around the origin.

    Raises:
        ConfigError: when a file is missing; UnknownJointError / UnknownFrameError for bad names.
    """

    def __init__(
        self,
        urdf: str | Path,
        *,
        srdf: str | Path | None = None,
        name: str | None = None,
        free_flyer: bool = True,
        reference: str | None = None,
        reference_joints: Mapping[str, float] | None = None,
        feet: Mapping[str, FootDescription] | None = None,
        keyframes: Mapping[str, str] | None = None,
        position_limits: Mapping[str, Sequence[float]] | None = None,
        velocity_limits: Mapping[str, float] | None = None,
        place_on_ground: bool = True,
    ) -> None:
        urdf = resolve_robot_path(urdf)
        if not urdf.is_file():
            raise ConfigError(f"URDF file {str(urdf)!r} does not exist.", path="robot.urdf")
        self.urdf_path = urdf
        self.srdf_path = resolve_robot_path(srdf) if srdf is not None else None
        if self.srdf_path is not None and not self.srdf_path.is_file():
            raise ConfigError(f"SRDF file {str(srdf)!r} does not exist.", path="robot.srdf")
        self.name = name or urdf.stem
        self.free_flyer = free_flyer
        if free_flyer:
            self.model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
        else:
            self.model = pin.buildModelFromUrdf(str(urdf))
        model = self.model
        self.keyframes: dict[str, str] = dict(keyframes or {})
        self.feet: dict[str, FootDescription] = dict(feet or {})
        for foot_name, foot in self.feet.items():
            if foot.parent is not None and not model.existFrame(foot.frame):
                parent_id = self.frame_id(foot.parent, path=f"robot.feet.{foot_name}.parent")
                parent = model.frames[parent_id]
                placement = parent.placement * pin.SE3(np.eye(3), np.asarray(foot.offset, float))
                model.addFrame(
                    pin.Frame(foot.frame, parent.parentJoint, parent_id, placement, pin.OP_FRAME)
                )

        self._init_limits(position_limits, velocity_limits)

        q_ref = self._reference_posture(reference, reference_joints)
        self.data = model.createData()
        if free_flyer and place_on_ground and self.feet:
            q_ref = self._place_on_ground(q_ref)
        q_ref.setflags(write=False)
        self.q_reference = q_ref
        self._geometry_cache: dict[str, Any] = {}

    def _init_limits(
        self,
        position_limits: Mapping[str, Sequence[float]] | None,
        velocity_limits: Mapping[str, float] | None,
    ) -> None:
        """Joint limits of the URDF with the YAML's overrides; the one-DoF joints' indices."""
        # Free-flyer coordinates are unbounded.
        model, free_flyer = self.model, self.free_flyer
        self.root_nq = 7 if free_flyer else 0
        self.root_nv = 6 if free_flyer else 0
        self.q_min = np.array(model.lowerPositionLimit, dtype=float)
        self.q_max = np.array(model.upperPositionLimit, dtype=float)
        self.v_max = np.array(model.velocityLimit, dtype=float)
        self.q_min[: self.root_nq] = -np.inf
        self.q_max[: self.root_nq] = np.inf
        self.v_max[: self.root_nv] = np.inf
        # Joints with one position coordinate and one velocity coordinate get limits.
        self.joint_names: list[str] = []
        q_idx, v_idx = [], []
        for jid in range(1 + int(free_flyer), model.njoints):
            joint = model.joints[jid]
            if joint.nq == 1 and joint.nv == 1:
                self.joint_names.append(model.names[jid])
                q_idx.append(joint.idx_q)
                v_idx.append(joint.idx_v)
        self.joint_q_index = np.array(q_idx, dtype=int)
        self.joint_v_index = np.array(v_idx, dtype=int)
        for jname, bounds in (position_limits or {}).items():
            b = np.asarray(bounds, dtype=float)
            if b.shape != (2,) or not b[0] < b[1]:
                raise ConfigError(
                    f"position limits of {jname!r} must be [lower, upper] with lower < upper, "
                    f"got {bounds!r}.",
                    path=f"robot.position_limits.{jname}",
                )
            j = self.joint_index(jname, path=f"robot.position_limits.{jname}")
            self.q_min[self.joint_q_index[j]], self.q_max[self.joint_q_index[j]] = b
        for jname, vlim in (velocity_limits or {}).items():
            if not (isinstance(vlim, (int, float)) and vlim > 0):
                raise ConfigError(
                    f"velocity limit of {jname!r} must be a positive number [rad/s], got {vlim!r}.",
                    path=f"robot.velocity_limits.{jname}",
                )
            j = self.joint_index(jname, path=f"robot.velocity_limits.{jname}")
            self.v_max[self.joint_v_index[j]] = float(vlim)
        # A URDF without limits gives 0 or +-max float: treat as unbounded, never as "frozen".
        bad_v = self.v_max <= 0
        self.v_max[bad_v] = np.inf
        huge = 1e10
        self.q_min[self.q_min < -huge] = -np.inf
        self.q_max[self.q_max > huge] = np.inf

    def _reference_posture(
        self, reference: str | None, reference_joints: Mapping[str, float] | None
    ) -> np.ndarray:
        """The reference posture (neutral, or the SRDF's ``reference``) with joint overrides.

        Joints outside their limits are moved just inside (listed in ``reference_adjusted``).
        """
        model = self.model
        q_ref = pin.neutral(model)
        if self.srdf_path is not None:
            pin.loadReferenceConfigurations(model, str(self.srdf_path), False)
            if reference is not None:
                if reference not in model.referenceConfigurations:
                    known = list(model.referenceConfigurations.keys())
                    raise ConfigError(
                        f"SRDF {self.srdf_path.name} has no reference configuration "
                        f"{reference!r} (it has {known}).",
                        path="robot.reference",
                    )
                q_ref = np.array(model.referenceConfigurations[reference], dtype=float)
        for jname, value in (reference_joints or {}).items():
            j = self.joint_index(jname, path=f"robot.reference_joints.{jname}")
            q_ref[self.joint_q_index[j]] = float(value)
        if self.free_flyer:
            q_ref[3:7] = q_ref[3:7] / np.linalg.norm(q_ref[3:7])
        # A reference outside the joint limits is unusable by a controller: move such joints just
        # inside (by 1% of their range, at most 0.01 rad) and keep the list for `info`.
        qi = self.joint_q_index
        lo, hi = self.q_min[qi], self.q_max[qi]
        inset = np.minimum(0.01, 0.01 * (hi - lo))
        clipped = np.clip(q_ref[qi], lo + inset, hi - inset)
        outside = (q_ref[qi] < lo) | (q_ref[qi] > hi)
        self.reference_adjusted = [self.joint_names[j] for j in np.where(outside)[0]]
        q_ref[qi] = np.where(outside, clipped, q_ref[qi])
        return q_ref

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_description(cls, desc: RobotDescription, **overrides: Any) -> RobotModel:
        """Build a bundled robot from its registry entry, with keyword overrides."""
        root = robots_directory()
        kwargs: dict[str, Any] = {
            "srdf": root / desc.srdf if desc.srdf else None,
            "name": desc.name,
            "reference": desc.reference,
            "reference_joints": dict(desc.reference_joints),
            "feet": desc.feet,
            "keyframes": desc.keyframes,
            "velocity_limits": dict(desc.velocity_limit_override),
        }
        for key, value in overrides.items():
            if key in ("reference_joints", "velocity_limits", "keyframes", "feet") and value:
                merged = dict(kwargs.get(key) or {})
                merged.update(value)
                kwargs[key] = merged
            else:
                kwargs[key] = value
        return cls(root / desc.urdf, **kwargs)

    @classmethod
    def from_name(cls, name: str, **overrides: Any) -> RobotModel:
        """Build a bundled robot (``g1``, ``talos``, ``romeo``, ``icub``, ``simple_humanoid``)."""
        return cls.from_description(get_description(name), **overrides)

    def _place_on_ground(self, q: np.ndarray) -> np.ndarray:
        """Shift the base so the soles' mean height is 0 and their mean xy is the origin."""
        q = q.copy()
        pin.framesForwardKinematics(self.model, self.data, q)
        soles = np.array(
            [
                self.data.oMf[self.frame_id(f.frame, path="robot.feet")].translation
                for f in self.feet.values()
            ]
        )
        q[:3] -= soles.mean(axis=0)
        return q

    # ------------------------------------------------------------------ names
    @property
    def nq(self) -> int:
        """Dimension of the configuration vector."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Dimension of the velocity vector (and of the QP variable)."""
        return self.model.nv

    @property
    def frame_names(self) -> list[str]:
        """All frame names of the model."""
        return [f.name for f in self.model.frames]

    def frame_id(self, name: str, *, path: str = "") -> int:
        """Return the id of frame ``name``; a key-point name (``left_hand``) is resolved first.

        Raises:
            UnknownFrameError: listing the closest frame names.
        """
        if not isinstance(name, str):
            raise ConfigError(f"a frame name must be a string, got {name!r}.", path=path)
        if name in self.keyframes and not self.model.existFrame(name):
            name = self.keyframes[name]
        if not self.model.existFrame(name):
            raise UnknownFrameError(name, self.frame_names + list(self.keyframes), path=path)
        return self.model.getFrameId(name)

    def joint_index(self, name: str, *, path: str = "") -> int:
        """Index of a one-DoF joint in :attr:`joint_names` (and in the actuated coordinates).

        Raises:
            UnknownJointError: listing the closest joint names.
        """
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise UnknownJointError(name, self.joint_names, path=path) from None

    # ------------------------------------------------------------------ maths helpers
    def integrate(self, q: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """Return ``q ⊕ v dt`` on the configuration manifold."""
        return pin.integrate(self.model, q, v * dt)

    def difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """Return the tangent vector ``q1 ⊖ q0`` (nv,)."""
        return pin.difference(self.model, q0, q1)

    def check_configuration(self, q: np.ndarray, *, what: str = "q") -> np.ndarray:
        """Return ``q`` as a float array of shape (nq,), or raise a clear error."""
        arr = np.asarray(q, dtype=float)
        if arr.shape != (self.nq,):
            raise ConfigError(
                f"{what} must have shape ({self.nq},) for robot {self.name!r} "
                f"(free-flyer [x y z qx qy qz qw] then {len(self.joint_names)} joints), "
                f"got {arr.shape}."
            )
        if not np.all(np.isfinite(arr)):
            raise ConfigError(
                f"{what} contains NaN or inf at indices {np.where(~np.isfinite(arr))[0]}."
            )
        if self.free_flyer:
            arr = arr.copy()
            n = np.linalg.norm(arr[3:7])
            if n < 1e-9:
                raise ConfigError(f"{what}: the base quaternion q[3:7] is zero.")
            arr[3:7] /= n
        return arr

    def geometry(self) -> tuple[pin.GeometryModel, pin.GeometryData]:
        """Collision geometry of the URDF (raw meshes), loaded once on demand."""
        if "collision" not in self._geometry_cache:
            gmodel = pin.buildGeomFromUrdf(
                self.model,
                str(self.urdf_path),
                pin.GeometryType.COLLISION,
                package_dirs=[str(share_directory())],
            )
            self._geometry_cache["collision"] = (gmodel, gmodel.createData())
        return self._geometry_cache["collision"]

    def __repr__(self) -> str:
        return (
            f"RobotModel(name={self.name!r}, nq={self.nq}, nv={self.nv}, "
            f"joints={len(self.joint_names)}, feet={list(self.feet)}, urdf={str(self.urdf_path)!r})"
        )


def _floats3(values: Sequence[Any]) -> tuple[float, float, float]:
    """Three floats; a TypeError (reported as a ConfigError by the caller) otherwise."""
    if len(values) != 3:
        raise TypeError(f"expected 3 numbers, got {len(values)}")
    return float(values[0]), float(values[1]), float(values[2])


def _floats4(values: Sequence[Any]) -> tuple[float, float, float, float]:
    """Four floats; a TypeError (reported as a ConfigError by the caller) otherwise."""
    if len(values) != 4:
        raise TypeError(f"expected 4 numbers, got {len(values)}")
    return float(values[0]), float(values[1]), float(values[2]), float(values[3])


def load_robot(spec: str | Mapping[str, Any] | RobotModel, *, path: str = "robot") -> RobotModel:
    """Build a :class:`RobotModel` from a registry name, a YAML mapping or a model.

    The mapping form is ``{name: g1, velocity_limits: {...}, position_limits: {...},
    reference_joints: {...}}`` for a bundled robot, or ``{urdf: PATH, srdf: PATH, free_flyer:
    true, feet: {...}, keyframes: {...}}`` for any other robot.
    """
    if isinstance(spec, RobotModel):
        return spec
    if isinstance(spec, str):
        return RobotModel.from_name(spec)
    if not isinstance(spec, Mapping):
        raise ConfigError(
            f"expected a robot name or a mapping, got {type(spec).__name__}.", path=path
        )
    spec = dict(spec)
    allowed = {
        "name", "urdf", "srdf", "free_flyer", "reference", "reference_joints", "feet",
        "keyframes", "position_limits", "velocity_limits", "place_on_ground",
    }  # fmt: skip
    check_keys(spec, sorted(allowed), path)
    feet = spec.pop("feet", None)
    if feet is not None:
        if not isinstance(feet, Mapping):
            raise ConfigError(
                "feet must map a foot name to {frame, parent, offset, rectangle}.",
                path=f"{path}.feet",
            )
        parsed = {}
        for fname, f in feet.items():
            if isinstance(f, FootDescription):
                parsed[fname] = f
                continue
            try:
                parsed[fname] = FootDescription(
                    frame=f["frame"],
                    parent=f.get("parent"),
                    offset=_floats3(f.get("offset", (0, 0, 0))),
                    rectangle=_floats4(f.get("rectangle", (-0.05, 0.1, -0.03, 0.03))),
                )
            except (KeyError, TypeError) as exc:
                raise ConfigError(
                    f"foot {fname!r} needs `frame` and optional parent, offset [x,y,z], "
                    f"rectangle [x_min,x_max,y_min,y_max] ({exc}).",
                    path=f"{path}.feet.{fname}",
                ) from None
        spec["feet"] = parsed
    if "urdf" in spec:
        return RobotModel(**spec)
    name = spec.pop("name", None)
    if name is None:
        raise ConfigError("give a bundled robot `name:` or a `urdf:` path.", path=path)
    desc = get_description(str(name), path=f"{path}.name")
    return RobotModel.from_description(desc, **spec)


class RobotState:
    """Kinematics of one configuration, computed once per tick and shared by all modules.

    Frame Jacobians are expressed in ``LOCAL_WORLD_ALIGNED`` (origin at the frame, axes of the
    world), so their linear rows map ``v`` to the world velocity of the frame origin and their
    angular rows to its world angular velocity. They are computed lazily and cached per tick.
    """

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()
        self.q = robot.q_reference.copy()
        self.v = np.zeros(robot.nv)
        self._jac: dict[int, np.ndarray] = {}
        self._com: np.ndarray | None = None
        self._jcom: np.ndarray | None = None
        self.update(self.q, self.v)

    def update(self, q: np.ndarray, v: np.ndarray | None = None) -> None:
        """Run forward kinematics, joint Jacobians and frame placements for ``q``."""
        self.q = q
        if v is not None:
            self.v = v
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        self._jac.clear()
        self._com = None
        self._jcom = None

    def frame_placement(self, frame_id: int) -> pin.SE3:
        """World placement of a frame."""
        return self.data.oMf[frame_id]

    def frame_jacobian(self, frame_id: int) -> np.ndarray:
        """(6, nv) frame Jacobian in LOCAL_WORLD_ALIGNED, rows [linear; angular]."""
        J = self._jac.get(frame_id)
        if J is None:
            J = pin.getFrameJacobian(self.model, self.data, frame_id, LWA)
            self._jac[frame_id] = J
        return J

    def com(self) -> np.ndarray:
        """World position of the centre of mass (3,)."""
        if self._com is None:
            self.com_jacobian()
        return self._com  # type: ignore[return-value]

    def com_jacobian(self) -> np.ndarray:
        """(3, nv) Jacobian of the centre of mass."""
        if self._jcom is None:
            self._jcom = pin.jacobianCenterOfMass(self.model, self.data, True)
            self._com = self.data.com[0].copy()
        return self._jcom
