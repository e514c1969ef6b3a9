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
from .skeleton import place_beside, skeleton_segments


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
    t0 = t[0] if start is None else max(t[0], start)
    t1 = t[-1] if end is None else min(t[-1], end)
    if t1 < t0:
        raise QPRetargetError(
            f"empty time window [{t0}, {t1}] s (run spans {t[0]:.2f}-{t[-1]:.2f} s)."
        )
    times = t0 + np.arange(int(np.floor((t1 - t0) * fps + 1e-9)) + 1) / fps
    idx = np.clip(np.searchsorted(t, times - 1e-9), 0, len(t) - 1)

    ctrl = traj.make_controller()
    robot = ctrl.robot
    data = robot.model.createData()
    meshes: list[LinkMesh] = load_link_meshes(robot, simplify=True, max_points=48)
    base_colors = np.array([m.color for m in meshes])
    counts = [len(m.faces) for m in meshes]
    tris_local = [m.vertices[m.faces] for m in meshes]  # (F, 3, 3) each

    human = {}
    if show_human and traj.human:
        pin.forwardKinematics(robot.model, data, traj.q[0])
        base = traj.q[0, :2] if robot.free_flyer else np.zeros(2)
        yaw = 0.0
        if robot.free_flyer:
            R0 = pin.Quaternion(traj.q[0, 3:7]).toRotationMatrix()
            yaw = float(np.arctan2(R0[1, 0], R0[0, 0]))
        human = place_beside(
            {k: v for k, v in traj.human.items() if np.ndim(v) == 2 and np.shape(v)[1] == 3},
            base,
            yaw,
        )
        # human samples may be at another rate: map by time when a time axis is given
        if "t" in traj.human:
            pass

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
    # Fixed view box around the whole motion.
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
    # ground: a light grid around the scene
    g = np.linspace(-half, half, 9)
    for v in g:
        ax.plot(centre[0] + g, np.full(9, centre[1] + v), 0.0, color="0.85", lw=0.6, zorder=0)
        ax.plot(np.full(9, centre[0] + v), centre[1] + g, 0.0, color="0.85", lw=0.6, zorder=0)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=15, azim=-20)
    ax.set_axis_off()
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    feet = traj.foot_names
    contacts = traj.contacts if traj.contacts is not None and traj.contacts.size else None
    targets = [traj.targets[k] for k in traj.task_names if k in traj.targets]

    frames = []
    tw = time.perf_counter()
    it = range(len(idx))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="render", unit="frame")
    for n in it:
        k = int(idx[n])
        q = traj.q[k]
        pin.forwardKinematics(robot.model, data, q)
        pin.updateFramePlacements(robot.model, data)
        tris = []
        for m, loc in zip(meshes, tris_local, strict=True):
            M = data.oMi[m.parent_joint] * m.placement
            tris.append(loc @ M.rotation.T + M.translation)
        T = np.concatenate(tris)
        nrm = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-12
        shade = 0.45 + 0.55 * np.abs(nrm @ light)
        fc = np.repeat(base_colors, counts, axis=0).copy()
        fc[:, :3] *= shade[:, None]
        poly.set_verts(T)
        poly.set_facecolor(fc)
        if human:
            hk = min(k, len(next(iter(human.values()))) - 1)
            bones.set_segments(skeleton_segments(human, hk))
        if robot.free_flyer:
            com = pin.centerOfMass(robot.model, data, q)
            com_pt.set_data_3d([com[0]], [com[1]], [0.0])
            if contacts is not None:
                hull = _support_polygon(robot, data, contacts[k], feet)
                if len(hull):
                    ring = np.vstack([hull, hull[:1]])
                    segs = np.stack(
                        [
                            np.c_[ring[:-1], np.zeros(len(hull))],
                            np.c_[ring[1:], np.zeros(len(hull))],
                        ],
                        axis=1,
                    )
                    support.set_segments(segs)
        if targets:
            P = np.array([tg[k] for tg in targets])
            tgt_pts.set_data_3d(P[:, 0], P[:, 1], P[:, 2])
        title.set_text(f"{robot.name}   t = {t[k]:.2f} s")
        fig.canvas.draw()
        buf = np.asarray(fig.canvas.buffer_rgba())
        frames.append(Image.fromarray(buf[:, :, :3].copy()))
    wall = time.perf_counter() - tw
    plt.close(fig)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".gif":
        frames[0].save(
            out, save_all=True, append_images=frames[1:], duration=int(round(1000 / fps)), loop=0
        )
    else:
        try:
            import imageio.v2 as imageio

            writer: Any = imageio.get_writer(out, fps=fps)  # the ffmpeg writer (append_data)
            with writer as w:
                for f in frames:
                    w.append_data(np.asarray(f))
        except Exception as exc:
            raise QPRetargetError(
                f"writing {out.name} needs an MP4 encoder "
                f"(`pip install imageio imageio-ffmpeg`): {exc}"
            ) from None
    return RenderInfo(out, len(frames), width, height, fps, len(frames) / max(wall, 1e-9))
