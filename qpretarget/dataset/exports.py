# SPDX-License-Identifier: Apache-2.0
r"""Export formats that learning pipelines read, one class each in :data:`EXPORTS`.

``--format csv,pkl,npz`` picks them; every file is written atomically (a temporary file renamed
into place, :mod:`qpretarget.fileio`). Layouts (docs/formats.md cites the readers):

* ``csv`` — the layout of Unitree's retargeted LAFAN1 dataset, read by BeyondMimic's and mjlab's
  ``csv_to_npz`` (``np.loadtxt(file, delimiter=",")``; columns ``[:3]`` root position,
  ``[3:7]`` root quaternion x y z w, ``[7:]`` joint angles): one row per frame, no header, root
  position x y z [m], root quaternion x y z w, then the joint angles [rad] in the URDF's
  actuated-joint order. A sidecar ``<clip>.json`` holds the fps, the joint names in column order,
  the quaternion convention, robot, config, source clip, qpretarget version and the per-frame
  foot contact labels. A fixed-base robot gets the identity root (0 0 0, 0 0 0 1).
* ``pkl`` — GMR's robot-motion pickle (``fps``, ``root_pos`` (T, 3), ``root_rot`` (T, 4) x y z w,
  ``dof_pos`` (T, n), ``local_body_pos`` (T, B, 3): every link's origin in the root frame,
  ``link_body_list``: the B link names), so GMR users can swap tools.
* ``npz`` — qpretarget's own run file (docs/formats.md), at the output rate.
"""

from __future__ import annotations

import abc
import json
import pickle
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..fileio import atomic_path, write_atomic
from ..registry import Registry
from ..robot import RobotModel
from ..trajectory import RobotTrajectory

#: Export formats by ``--format`` name.
EXPORTS = Registry("export format")


def _version() -> str:
    from .. import __version__

    return str(__version__)


def root_and_joints(run: RobotTrajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(root_pos (T, 3), root_quat_xyzw (T, 4), joints (T, n))`` of a run."""
    q = np.asarray(run.q, dtype=float)
    n = len(run.joint_names)
    if q.shape[1] == n + 7:  # pinocchio free flyer: x y z, qx qy qz qw, joints
        return q[:, :3], q[:, 3:7], q[:, 7:]
    T = len(q)
    quat = np.zeros((T, 4))
    quat[:, 3] = 1.0
    return np.zeros((T, 3)), quat, q


def _fps(run: RobotTrajectory) -> float:
    return float(run.meta.get("output_fps") or (1.0 / run.dt if run.dt > 0 else 0.0))


class Exporter(abc.ABC):
    """One output format. ``write`` returns the files it wrote (atomically)."""

    suffix: ClassVar[str] = ""

    @abc.abstractmethod
    def write(
        self, run: RobotTrajectory, stem: Path, *, robot: RobotModel, source: str
    ) -> list[Path]:
        """Write ``run`` as ``stem`` + :attr:`suffix` (and sidecars)."""


@EXPORTS.register("npz")
class NpzExporter(Exporter):
    """qpretarget's run file (docs/formats.md) at the output rate."""

    suffix = ".npz"

    def write(
        self, run: RobotTrajectory, stem: Path, *, robot: RobotModel, source: str
    ) -> list[Path]:
        path = stem.with_name(stem.name + self.suffix)
        with atomic_path(path, suffix=".npz") as tmp:
            run.save(tmp)
        return [path]


@EXPORTS.register("csv")
class CsvExporter(Exporter):
    """Unitree LAFAN1 / BeyondMimic CSV (module docstring) plus a JSON sidecar."""

    suffix = ".csv"

    def write(
        self, run: RobotTrajectory, stem: Path, *, robot: RobotModel, source: str
    ) -> list[Path]:
        pos, quat, joints = root_and_joints(run)
        table = np.hstack([pos, quat, joints])
        path = stem.with_name(stem.name + self.suffix)
        write_atomic(path, lambda f: np.savetxt(f, table, delimiter=",", fmt="%.10g"), binary=True)
        side = stem.with_name(stem.name + ".json")
        contacts = None if run.contacts is None else np.asarray(run.contacts, bool)
        info: dict[str, Any] = {
            "format": "unitree-lafan1-csv",
            "fps": _fps(run),
            "frames": int(len(table)),
            "columns": ["root_x", "root_y", "root_z", "root_qx", "root_qy", "root_qz", "root_qw"]
            + list(run.joint_names),
            "joint_names": list(run.joint_names),
            "quaternion": "xyzw",
            "units": {"position": "m", "angle": "rad"},
            "robot": run.robot,
            "config": run.meta.get("config_name") or "",
            "config_sha256": run.meta.get("config_sha256", ""),
            "source": source,
            "qpretarget_version": _version(),
            "foot_names": list(run.foot_names),
            "contacts": [] if contacts is None else contacts.astype(int).tolist(),
        }
        write_atomic(side, lambda f: f.write(json.dumps(info, indent=1)), binary=False)
        return [path, side]


@EXPORTS.register("pkl")
class GmrPickleExporter(Exporter):
    """GMR's robot-motion pickle (module docstring)."""

    suffix = ".pkl"

    def write(
        self, run: RobotTrajectory, stem: Path, *, robot: RobotModel, source: str
    ) -> list[Path]:
        pos, quat, joints = root_and_joints(run)
        names, local = local_body_positions(robot, np.asarray(run.q, float))
        data = {
            "fps": _fps(run),
            "root_pos": pos.copy(),
            "root_rot": quat.copy(),
            "dof_pos": joints.copy(),
            "local_body_pos": local,
            "link_body_list": names,
        }
        path = stem.with_name(stem.name + self.suffix)
        write_atomic(path, lambda f: pickle.dump(data, f, protocol=4), binary=True)
        return [path]


def local_body_positions(robot: RobotModel, q: np.ndarray) -> tuple[list[str], np.ndarray]:
    r"""Every link's origin in the root frame, :math:`R_{root}^\top (p_{link} - p_{root})`.

    Returns:
        ``(names, (T, B, 3))`` with the links (pinocchio BODY frames) in the URDF's order.
    """
    model = robot.model
    data = model.createData()
    ids = [i for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY]
    names = [model.frames[i].name for i in ids]
    out = np.empty((len(q), len(ids), 3))
    root = 1 if robot.free_flyer else 0
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(model, data, qk)
        M = data.oMi[root]
        P = np.array([data.oMf[i].translation for i in ids])
        out[k] = (P - M.translation) @ M.rotation
    return names, out


def parse_formats(spec: str | Sequence[str]) -> list[str]:
    """``"csv,pkl"`` or ``["csv", "pkl"]`` -> validated names (close matches on a typo).

    Raises:
        ConfigError: an unknown format.
    """
    items = spec.split(",") if isinstance(spec, str) else list(spec)
    out = []
    for item in (s.strip() for s in items):
        if item:
            EXPORTS.lookup(item, path="--format")
            if item not in out:
                out.append(item)
    if not out:
        raise ConfigError("no export format given; choose from " + ", ".join(sorted(EXPORTS)))
    return out


def export_run(
    run: RobotTrajectory,
    stem: str | Path,
    formats: Sequence[str],
    *,
    robot: RobotModel,
    source: str = "",
) -> list[Path]:
    """Write ``run`` in every format of ``formats`` as ``stem.<suffix>``; return the files."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    for name in formats:
        exporter = EXPORTS.lookup(name, path="--format")()
        files += exporter.write(run, stem, robot=robot, source=source)
    return files
