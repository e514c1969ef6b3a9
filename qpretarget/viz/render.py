# SPDX-License-Identifier: Apache-2.0
"""Offscreen rendering of a run to an animated GIF (or MP4) with matplotlib, no GPU, no display.

Why matplotlib: it installs everywhere from PyPI, needs neither a GPU nor a display (Agg), and at
a few thousand triangles per frame (each link mesh replaced by a coarse convex hull, see
:mod:`qpretarget.viz.meshes`) it draws a G1 frame in tens of milliseconds. MuJoCo/pyrender would
need an OpenGL context (EGL/OSMesa) that a headless CI machine may not have.

The scene: the robot (shaded hull meshes), the human key-point skeleton beside it, the task targets
(red) and reached points (blue), the support polygon of the feet in contact and the CoM ground
projection.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import QPRetargetError, missing_dependency
from ..trajectory import RobotTrajectory
from .meshes import LinkMesh, load_link_meshes
from .skeleton import beside_robot, human_samples, skeleton_segments


@dataclass
class RenderInfo:
    """What :func:`render_run` wrote: path, frame count, size and speed."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    render_fps: float  # frames rendered per second of wall time


def _require_plot():  # noqa: ANN202
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from PIL import Image
    except ImportError:  # pragma: no cover
        raise missing_dependency("plot", "rendering (matplotlib and Pillow)") from None
    return plt, Image


def _support_polygon(robot, data, contacts: np.ndarray, foot_names: list[str]) -> np.ndarray:  # noqa: ANN001
    """Convex hull (K, 2) of the active soles' corners at the current kinematics."""
    from scipy.spatial import ConvexHull

    corners = []
    for j, name in enumerate(foot_names):
        if j < len(contacts) and contacts[j] and name in robot.feet:
            f = robot.feet[name]
            M = data.oMf[robot.frame_id(f.frame)]
            x0, x1, y0, y1 = f.rectangle
            for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
                corners.append((M.act(np.array([x, y, 0.0])))[:2])
    if len(corners) < 3:
        return np.zeros((0, 2))
    pts = np.array(corners)
    try:
        hull = ConvexHull(pts)
    except Exception:
        return np.zeros((0, 2))
    return pts[hull.vertices]


def support_outline(
    robot: Any, data: Any, active: np.ndarray, foot_names: list[str], z: float
) -> np.ndarray:
    """(K, 2, 3) edges of the support polygon (:func:`_support_polygon`) drawn at height ``z``.

    Empty (0, 2, 3) when the active soles give no polygon.
    """
    hull = _support_polygon(robot, data, active, foot_names)
    if not len(hull):
        return np.zeros((0, 2, 3))
    ring = np.vstack([hull, hull[:1]])
    return np.stack(
        [np.c_[ring[:-1], np.full(len(hull), z)], np.c_[ring[1:], np.full(len(hull), z)]], axis=1
    )


@dataclass
class _Scene:
    """The matplotlib figure of a render and the artists updated every frame."""

    fig: Any
    ax: Any
    poly: Any  # robot triangles
    bones: Any  # human skeleton
    support: Any  # support polygon
    com_pt: Any
    tgt_pts: Any
    title: Any


def render_run(
    traj: RobotTrajectory,
    out: str | Path,
    *,
    fps: float = 20.0,
    width: int = 640,
    height: int = 480,
    start: float | None = None,
    end: float | None = None,
    show_human: bool = True,
    progress: bool = False,
) -> RenderInfo:
    """Render ``traj`` to ``out`` (``.gif``; ``.mp4`` when imageio-ffmpeg is installed).

    Frames are sampled at ``fps`` from the run's time axis, so a 2-second run at 20 fps gives 40
    frames (the last sample included when it falls on the grid).

    Raises:
        QPRetargetError: unknown output extension, missing encoder, empty time window.
    """
    plt, Image = _require_plot()
    out = Path(out)
    if out.suffix.lower() not in (".gif", ".mp4"):
        raise QPRetargetError(f"output {out.name!r}: use a .gif or .mp4 file name.")
    if fps <= 0 or width < 64 or height < 64:
        raise QPRetargetError("fps must be > 0 and the image at least 64x64 pixels.")
    t = np.asarray(traj.t, dtype=float)
    idx = _frame_samples(t, fps, start, end)

    ctrl = traj.make_controller()
    robot = ctrl.robot
    data = robot.model.createData()
    meshes: list[LinkMesh] = load_link_meshes(robot, simplify=True, max_points=48)
    human = beside_robot(traj.human, traj.q[0], robot.free_flyer) if show_human else {}
    scene = _make_scene(plt, width, height)
    _fix_view(scene.ax, traj, robot, data, idx, human)

    frames = []
    tw = time.perf_counter()
    it: Any = range(len(idx))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="render", unit="frame")
    draw = _FrameDrawer(scene, traj, robot, data, meshes, human)
    for n in it:
        k = int(idx[n])
        draw(k, f"{robot.name}   t = {t[k]:.2f} s")
        scene.fig.canvas.draw()
        buf = np.asarray(scene.fig.canvas.buffer_rgba())
        frames.append(Image.fromarray(buf[:, :, :3].copy()))
    wall = time.perf_counter() - tw
    plt.close(scene.fig)
    _write_frames(out, frames, fps)
    return RenderInfo(out, len(frames), width, height, fps, len(frames) / max(wall, 1e-9))


def _frame_samples(t: np.ndarray, fps: float, start: float | None, end: float | None) -> np.ndarray:
    """Indices of the run samples shown at ``fps`` over ``[start, end]`` (clipped to the run)."""
    t0 = t[0] if start is None else max(t[0], start)
    t1 = t[-1] if end is None else min(t[-1], end)
    if t1 < t0:
        raise QPRetargetError(
            f"empty time window [{t0}, {t1}] s (run spans {t[0]:.2f}-{t[-1]:.2f} s)."
        )
    times = t0 + np.arange(int(np.floor((t1 - t0) * fps + 1e-9)) + 1) / fps
    return np.clip(np.searchsorted(t, times - 1e-9), 0, len(t) - 1)


def _make_scene(plt: Any, width: int, height: int) -> _Scene:
    """A borderless 3D figure of ``width x height`` pixels with empty artists."""
    dpi = 100
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    ax = fig.add_axes([0, 0, 1, 1], projection="3d", computed_zorder=False)
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    z3 = np.zeros((1, 3, 3))
    z2 = np.zeros((1, 2, 3))
    poly = Poly3DCollection(z3, linewidths=0.0, zorder=2)
    ax.add_collection3d(poly, autolim=False)
    bones = Line3DCollection(z2, colors="tab:orange", linewidths=2.0)
    ax.add_collection3d(bones, autolim=False)
    support = Line3DCollection(z2, colors="tab:green", linewidths=1.5)
    ax.add_collection3d(support, autolim=False)
    (com_pt,) = ax.plot([], [], [], "o", color="tab:green", ms=4, zorder=1)
    (tgt_pts,) = ax.plot([], [], [], "o", color="tab:red", ms=3, zorder=3)
    title = ax.text2D(0.02, 0.96, "", transform=ax.transAxes, fontsize=9)
    return _Scene(fig, ax, poly, bones, support, com_pt, tgt_pts, title)


def _fix_view(
    ax: Any,
    traj: RobotTrajectory,
    robot: Any,
    data: Any,
    idx: np.ndarray,
    human: dict[str, np.ndarray],
) -> None:
    """Fixed view box around the whole motion, with a light ground grid."""
    pin.forwardKinematics(robot.model, data, traj.q[idx[0]])
    robot_height = max(
        float(max(data.oMi[j].translation[2] for j in range(robot.model.njoints))), 0.5
    )
    allq = traj.q[idx]
    centre = np.array([allq[:, 0].mean(), allq[:, 1].mean()]) if robot.free_flyer else np.zeros(2)
    if human:
        hum = np.concatenate(list(human.values()))
        centre = 0.5 * (centre + np.nanmean(hum, axis=0)[:2])
    half = 0.6 * robot_height + (0.5 if human else 0.0)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(0.0, 2 * half)
    g = np.linspace(-half, half, 9)
    for v in g:
        ax.plot(centre[0] + g, np.full(9, centre[1] + v), 0.0, color="0.85", lw=0.6, zorder=0)
        ax.plot(np.full(9, centre[0] + v), centre[1] + g, 0.0, color="0.85", lw=0.6, zorder=0)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=15, azim=-20)
    ax.set_axis_off()


class _FrameDrawer:
    """Updates the scene's artists to one sample of the run (robot, human, support, targets)."""

    def __init__(
        self,
        scene: _Scene,
        traj: RobotTrajectory,
        robot: Any,
        data: Any,
        meshes: list[LinkMesh],
        human: dict[str, np.ndarray],
    ) -> None:
        self.scene, self.traj, self.robot, self.data = scene, traj, robot, data
        self.meshes, self.human = meshes, human
        self.base_colors = np.array([m.color for m in meshes])
        self.counts = [len(m.faces) for m in meshes]
        self.tris_local = [m.vertices[m.faces] for m in meshes]  # (F, 3, 3) each
        light = np.array([0.3, -0.5, 0.8])
        self.light = light / np.linalg.norm(light)
        self.contacts = traj.contacts if traj.contacts is not None and traj.contacts.size else None
        self.targets = [traj.targets[k] for k in traj.task_names if k in traj.targets]
        #: The human sample shown with each robot sample (the capture rate's, nearest in time).
        self.human_k = human_samples(traj.human or {}, traj.t) if human else None

    def __call__(self, k: int, title: str) -> None:
        """Show sample ``k`` with ``title``."""
        scene, robot, data = self.scene, self.robot, self.data
        q = self.traj.q[k]
        pin.forwardKinematics(robot.model, data, q)
        pin.updateFramePlacements(robot.model, data)
        self._robot_mesh()
        if self.human and self.human_k is not None:
            scene.bones.set_segments(skeleton_segments(self.human, int(self.human_k[k])))
        if robot.free_flyer:
            com = pin.centerOfMass(robot.model, data, q)
            scene.com_pt.set_data_3d([com[0]], [com[1]], [0.0])
            if self.contacts is not None:
                self._support(self.contacts[k])
        if self.targets:
            P = np.array([tg[k] for tg in self.targets])
            scene.tgt_pts.set_data_3d(P[:, 0], P[:, 1], P[:, 2])
        scene.title.set_text(title)

    def _robot_mesh(self) -> None:
        """Link hulls at the current kinematics, shaded by a fixed directional light."""
        tris = []
        for m, loc in zip(self.meshes, self.tris_local, strict=True):
            M = self.data.oMi[m.parent_joint] * m.placement
            tris.append(loc @ M.rotation.T + M.translation)
        T = np.concatenate(tris)
        nrm = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-12
        shade = 0.45 + 0.55 * np.abs(nrm @ self.light)
        fc = np.repeat(self.base_colors, self.counts, axis=0).copy()
        fc[:, :3] *= shade[:, None]
        self.scene.poly.set_verts(T)
        self.scene.poly.set_facecolor(fc)

    def _support(self, active: np.ndarray) -> None:
        """Outline of the support polygon of the feet in contact (kept when it is degenerate)."""
        segs = support_outline(self.robot, self.data, active, self.traj.foot_names, 0.0)
        if len(segs):
            self.scene.support.set_segments(segs)


def _write_frames(out: Path, frames: list[Any], fps: float) -> None:
    """Write the frames as an animated GIF, or an MP4 through imageio-ffmpeg."""
    from ..fileio import atomic_path

    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".gif":
        with atomic_path(out, suffix=".gif") as tmp:  # no half-written animation
            frames[0].save(
                tmp,
                save_all=True,
                append_images=frames[1:],
                duration=int(round(1000 / fps)),
                loop=0,
            )
    else:
        try:
            import imageio.v2 as imageio

            with atomic_path(out, suffix=out.suffix) as tmp:
                writer: Any = imageio.get_writer(tmp, fps=fps)  # the ffmpeg writer
                with writer as w:
                    for f in frames:
                        w.append_data(np.asarray(f))
        except Exception as exc:
            raise QPRetargetError(
                f"writing {out.name} needs an MP4 encoder "
                f"(`pip install imageio imageio-ffmpeg`): {exc}"
            ) from None
