# SPDX-License-Identifier: Apache-2.0
"""Interactive 3D viewer in the browser (viser): replay a run, inspect a config, watch a live loop.

``qpretarget view RUN.npz`` shows the robot (its URDF meshes) replaying the run beside the human
key-point skeleton, the task targets (red) and reached points (blue), the support polygon and CoM
ground projection, collision pairs within the influence distance (red lines between witness
points), a timeline with play/pause and speed, and the numbers of the current frame.
``qpretarget view CONFIG.yaml`` shows the reference posture with key-point frames, the collision
geometry the controller uses and its pairs. :class:`LiveViewer` streams a running controller.

viser is an optional dependency (the ``viz`` extra, see :func:`qpretarget.errors.install_hint`).
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..collision import CollisionModel
from ..control.result import StepResult
from ..errors import QPRetargetError, missing_dependency
from ..robot import RobotModel
from .meshes import load_link_meshes
from .skeleton import beside_robot, human_samples, skeleton_segments


class ViewerError(QPRetargetError, RuntimeError):
    """The viewer cannot start (missing extra, port taken, bad input)."""


def _viser():  # noqa: ANN202
    try:
        import viser
    except ImportError:
        raise missing_dependency("viz", "the viewer (viser)") from None
    return viser


def port_is_free(host: str, port: int) -> bool:
    """``True`` when nothing listens on ``host:port``."""
    with contextlib.closing(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def choose_port(host: str, port: int, *, search: bool = True, span: int = 50) -> tuple[int, str]:
    """Return a free port (``port`` itself if free) and a message for people when it moved.

    ``port=0`` asks the OS for any free port.

    Raises:
        ViewerError: when ``port`` is taken and ``search`` is off, or no port nearby is free.
    """
    if port == 0:
        with contextlib.closing(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) as s:
            s.bind((host, 0))
            return int(s.getsockname()[1]), ""
    if port_is_free(host, port):
        return port, ""
    if not search:
        raise ViewerError(
            f"port {port} on {host} is taken (another viewer?). Pass another --port, or --port 0 "
            "for any free port."
        )
    for p in range(port + 1, port + span):
        if port_is_free(host, p):
            return p, f"port {port} is taken; using port {p} instead."
    raise ViewerError(f"ports {port}-{port + span - 1} on {host} are all taken; pass --port 0.")


def _wxyz(R: np.ndarray) -> np.ndarray:
    q = pin.Quaternion(R)
    return np.array([q.w, q.x, q.y, q.z])


class Viewer:
    """A viser server showing one robot.

    Args:
        robot: the robot to show.
        host: interface to listen on (``127.0.0.1``: this machine only).
        port: port (``0``: any free port); when taken, the next free port is used and said.
        max_points: vertices per link mesh hull sent to the browser (``None``: full meshes).

    Raises:
        ViewerError: viser missing, or no free port.
    """

    def __init__(
        self,
        robot: RobotModel,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        search_port: bool = True,
        max_points: int | None = 600,
        verbose: bool = True,
    ) -> None:
        viser = _viser()
        self.robot = robot
        self.host = host
        self.port, note = choose_port(host, port, search=search_port)
        if note and verbose:
            print(f"qpretarget view: {note}")
        self.server = viser.ViserServer(host=host, port=self.port, verbose=False)
        self.server.scene.set_up_direction("+z")
        self.server.initial_camera.position = (2.2, -2.2, 1.5)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.6)
        self.server.scene.add_grid("/ground", width=4.0, height=4.0, cell_size=0.25)
        self.data = robot.model.createData()
        self.meshes = load_link_meshes(
            robot, simplify=max_points is not None, max_points=max_points or 0
        )
        self._frames = []
        for i, m in enumerate(self.meshes):
            fr = self.server.scene.add_frame(f"/robot/{i}", show_axes=False)
            # URDF greys are very light under viser's lighting: darken them a little
            color = tuple(int(200 * c) for c in m.color[:3])
            self.server.scene.add_mesh_simple(
                f"/robot/{i}/mesh", m.vertices.astype(np.float32), m.faces.astype(np.uint32),
                color=color, flat_shading=False,
            )  # fmt: skip
            self._frames.append(fr)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.set_configuration(robot.q_reference)

    @property
    def url(self) -> str:
        """Address of the page."""
        return f"http://{self.host}:{self.port}"

    def set_configuration(self, q: np.ndarray) -> None:
        """Pose the robot meshes at configuration ``q``."""
        model, data = self.robot.model, self.data
        pin.forwardKinematics(model, data, q)
        with self.server.atomic():
            for fr, m in zip(self._frames, self.meshes, strict=True):
                M = data.oMi[m.parent_joint] * m.placement
                fr.position = M.translation
                fr.wxyz = _wxyz(M.rotation)

    # ------------------------------------------------------------------ run replay
    def show_run(self, traj: Any, *, series: dict[str, np.ndarray] | None = None) -> None:
        """Replay a :class:`~qpretarget.trajectory.RobotTrajectory` with a timeline."""
        replay = _RunReplay(self, traj, series or {})
        replay.draw(0)
        th = threading.Thread(target=replay.loop, daemon=True, name="qpretarget-viewer-playback")
        th.start()
        self._threads.append(th)

    # ------------------------------------------------------------------ config inspection
    def show_config(self, controller: Any) -> None:
        """Reference posture, key-point frames, collision geometry and pairs of a controller."""
        robot = controller.robot
        self.set_configuration(controller.q)
        data = self.data
        pin.updateFramePlacements(robot.model, data)
        for key, frame in robot.keyframes.items():
            M = data.oMf[robot.frame_id(frame)]
            self.server.scene.add_frame(
                f"/keypoints/{key}", axes_length=0.08, axes_radius=0.004,
                position=M.translation, wxyz=_wxyz(M.rotation),
            )  # fmt: skip
        lines = [f"**{robot.name}** nq={robot.nq} nv={robot.nv}", "", "**tasks**", ""]
        lines += [f"- `{n}` ({t.type_name})" for n, t in controller.tasks.items()]
        lines += ["", "**constraints**", ""]
        for c in controller.constraints:
            lines.append(f"- `{c.name}` ({c.type_name})")
            cmodel = getattr(c, "model", None)
            if isinstance(cmodel, CollisionModel):
                self._show_collision_model(c.name, cmodel)
            for line in c.describe()[:12]:
                lines.append(f"    - {line}")
        with self.server.gui.add_folder("Setup"):
            self.server.gui.add_markdown("\n".join(lines))

    def _show_collision_model(self, name: str, cmodel: Any) -> None:
        """Draw a collision model's shapes (translucent) and its pairs (lines between centres)."""
        from scipy.spatial import ConvexHull

        from ..collision import primitive_points

        data = self.data
        centres = {}
        for k, shape in enumerate(cmodel.shapes):
            try:
                pts = primitive_points(shape.geometry)
                hull = ConvexHull(pts)
            except Exception:  # a shape we cannot draw is skipped, the rest still shows
                continue
            M = (data.oMi[shape.joint] if shape.joint else pin.SE3.Identity()) * shape.placement
            self.server.scene.add_mesh_simple(
                f"/{name}/shape_{k}", pts.astype(np.float32), hull.simplices.astype(np.uint32),
                color=(240, 120, 60), opacity=0.35, position=M.translation,
                wxyz=_wxyz(M.rotation),
            )  # fmt: skip
            centres[shape.name] = M.act(pts.mean(axis=0))
        segs = [(centres[a], centres[b]) for a, b in cmodel.pairs if a in centres and b in centres]
        if segs:
            self.server.scene.add_line_segments(
                f"/{name}/pairs", np.array(segs, dtype=np.float32), (200, 40, 40), thickness=0.004
            )

    # ------------------------------------------------------------------ live
    def serve_forever(self) -> None:
        """Block until Ctrl-C, then shut down cleanly."""
        try:
            while not self._stop.is_set():
                time.sleep(0.2)
        except KeyboardInterrupt:
            print("\nqpretarget view: stopping (Ctrl-C).")
        finally:
            self.close()

    def close(self) -> None:
        """Stop the playback threads and the server."""
        self._stop.set()
        for th in self._threads:
            th.join(timeout=1.0)
        with contextlib.suppress(Exception):
            self.server.stop()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read_latest(buf: np.ndarray, out: np.ndarray, seen: int) -> int:
    """Copy the newest configuration of a seqlock buffer into ``out``; return its counter.

    ``buf = [counter, q...]``: the writer makes the counter odd, writes q, then makes it even
    (:meth:`LiveViewer.__call__`). A copy is kept only if the counter was even and unchanged
    around it; otherwise (a write in progress) ``seen`` is returned and the next poll retries.
    """
    c1 = buf[0]
    if c1 == seen or int(c1) % 2:
        return seen
    np.copyto(out, buf[1:])
    return int(c1) if buf[0] == c1 else seen


def _live_main(argv: list[str] | None = None) -> int:
    """Viewer process of :class:`LiveViewer` (``python -m qpretarget.viz.viewer``).

    Hosts the viser server, prints ``PORT <n>`` once serving, then draws the newest
    configuration of the shared-memory seqlock at most ``--max-rate`` times a second until the
    stop slot is set, its parent dies, or it is interrupted.
    """
    import argparse
    import json
    import os
    import sys
    from multiprocessing import shared_memory
    from pathlib import Path

    from ..robot import load_robot

    ap = argparse.ArgumentParser(prog="python -m qpretarget.viz.viewer")
    ap.add_argument("--robot", required=True, help="robot spec as JSON")
    ap.add_argument("--base-dir", default=None)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--shm", required=True)
    ap.add_argument("--nq", type=int, required=True)
    ap.add_argument("--max-rate", type=float, default=30.0)
    args = ap.parse_args(argv)
    spec = json.loads(args.robot)
    if isinstance(spec, dict) and args.base_dir is not None:
        for k in ("urdf", "srdf"):
            if spec.get(k) and not str(spec[k]).startswith("example-robot-data:"):
                spec[k] = str((Path(args.base_dir) / str(spec[k])).resolve())
    shm = shared_memory.SharedMemory(name=args.shm)
    with contextlib.suppress(Exception):  # the parent owns the segment: never unlink it here
        from multiprocessing import resource_tracker

        resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
    try:
        # [stop flag, counter, q...]: the parent owns (and unlinks) the segment.
        flags = np.ndarray((args.nq + 2,), dtype=float, buffer=shm.buf)
        buf = flags[1:]
        viewer = Viewer(load_robot(spec), host=args.host, port=args.port, verbose=False)
        print(f"PORT {viewer.port}", flush=True)
        parent = os.getppid()
        q = np.empty(args.nq)
        period = 1.0 / args.max_rate
        seen = 0
        try:
            while flags[0] == 0.0 and os.getppid() == parent:
                time.sleep(period)
                got = _read_latest(buf, q, seen)
                if got != seen:
                    seen = got
                    viewer.set_configuration(q)
        except KeyboardInterrupt:
            pass
        finally:
            viewer.close()
            del flags, buf
    finally:
        shm.close()
    sys.stdout.flush()
    return 0


class _RunReplay:
    """The timeline of :meth:`Viewer.show_run`: GUI, playback loop and drawing of one frame."""

    def __init__(self, viewer: Viewer, traj: Any, series: dict[str, np.ndarray]) -> None:
        self.viewer, self.traj, self.series = viewer, traj, series
        self.T = len(traj.t)
        self.targets = {
            k: np.asarray(traj.targets[k]) for k in traj.task_names if k in traj.targets
        }
        self.actual = {k: np.asarray(traj.actual[k]) for k in traj.task_names if k in traj.actual}
        self.human = (
            beside_robot(traj.human, traj.q[0], viewer.robot.free_flyer) if traj.human else {}
        )
        #: The human sample shown with each robot sample (the capture rate's, nearest in time).
        self.human_k = human_samples(traj.human or {}, traj.t)
        gui = viewer.server.gui
        with gui.add_folder("Timeline"):
            self.slider = gui.add_slider(
                "Frame", min=0, max=max(self.T - 1, 1), step=1, initial_value=0
            )
            play = gui.add_button("Play / pause")
            self.speed = gui.add_dropdown(
                "Speed", ("0.25x", "0.5x", "1x", "2x"), initial_value="1x"
            )
        self.numbers = gui.add_markdown("")
        self.playing = False
        self.handles: dict[str, Any] = {}  # the scene nodes drawn last

        @play.on_click
        def _(_event: Any) -> None:
            self.playing = not self.playing

        @self.slider.on_update
        def _(_event: Any) -> None:
            self.draw(self.slider.value)

    def draw(self, k: int) -> None:
        """Show frame ``k`` (clipped to the run)."""
        k = int(min(max(k, 0), self.T - 1))
        self.viewer.set_configuration(self.traj.q[k])
        self._draw_points(k)
        if self.human:
            self._draw_human(k)
        if self.viewer.robot.free_flyer:
            self._draw_balance(k)
        self.numbers.content = self._numbers(k)

    def _draw_points(self, k: int) -> None:
        """Task targets (red) and reached points (blue)."""
        if not self.targets:
            return
        scene = self.viewer.server.scene
        P = np.array([v[k] for v in self.targets.values()], dtype=np.float32)
        A = np.array([v[k] for v in self.actual.values()], dtype=np.float32) if self.actual else P
        self.handles["targets"] = scene.add_point_cloud(
            "/targets", P, (230, 40, 40), point_size=0.03, point_shape="circle"
        )
        self.handles["actual"] = scene.add_point_cloud(
            "/actual", A, (40, 90, 230), point_size=0.02, point_shape="circle"
        )

    def _draw_human(self, k: int) -> None:
        """The human skeleton beside the robot."""
        human = self.human
        segs = skeleton_segments(human, int(self.human_k[k]))
        if len(segs):
            self.handles["human"] = self.viewer.server.scene.add_line_segments(
                "/human", segs.astype(np.float32), (240, 140, 20), thickness=0.02
            )

    def _draw_balance(self, k: int) -> None:
        """CoM ground projection and the support polygon of the feet in contact."""
        viewer, traj = self.viewer, self.traj
        robot, data, scene = viewer.robot, viewer.data, viewer.server.scene
        c = pin.centerOfMass(robot.model, data, traj.q[k])
        self.handles["com"] = scene.add_icosphere(
            "/com", radius=0.02, color=(30, 160, 60), position=(c[0], c[1], 0.002)
        )
        if traj.contacts is not None and traj.contacts.size:
            from .render import support_outline

            pin.updateFramePlacements(robot.model, data)
            segs = support_outline(robot, data, traj.contacts[k], traj.foot_names, 0.003)
            if len(segs):
                self.handles["support"] = scene.add_line_segments(
                    "/support", segs.astype(np.float32), (30, 160, 60), thickness=0.008
                )

    def _numbers(self, k: int) -> str:
        """Markdown: time, per-task error [mm], pair distance, CoM margin and status at ``k``."""
        traj, series = self.traj, self.series
        lines = [f"**t = {traj.t[k]:.2f} s** (frame {k + 1}/{self.T})", ""]
        for name in self.targets:
            if name in self.actual:
                e = np.linalg.norm(self.targets[name][k] - self.actual[name][k]) * 1e3
                lines.append(f"- {name}: {e:.1f} mm")
        for key, label, scale, unit in (
            ("min_distance", "min pair distance", 1e3, "mm"),
            ("com_margin", "CoM margin", 1e3, "mm"),
        ):
            if key in series and k < len(series[key]) and np.isfinite(series[key][k]):
                lines.append(f"- {label}: {series[key][k] * scale:.1f} {unit}")
        if traj.status is not None:
            lines.append(f"- status: {traj.status[k]}")
        return "\n".join(lines)

    def loop(self) -> None:
        """Advance the slider in real time (times the chosen speed) while playing."""
        traj, T = self.traj, self.T
        dt = float(np.median(np.diff(traj.t))) if T > 1 else 0.01
        last = time.perf_counter()
        acc = 0.0
        while not self.viewer._stop.is_set():
            time.sleep(1 / 60)
            now = time.perf_counter()
            if self.playing:
                acc += (now - last) * float(self.speed.value.rstrip("x"))
                steps = int(acc / dt)
                if steps:
                    acc -= steps * dt
                    self.slider.value = (self.slider.value + steps) % T
            last = now


class LiveViewer:
    """A browser viewer in its own process, fed by a running controller.

    ``ctrl.add_observer(LiveViewer(ctrl))`` streams every tick: the control loop only copies the
    new configuration into shared memory (about a microsecond, never blocking on the viewer), and
    the viewer process draws the newest one at most ``max_rate`` times per second. Being another
    process, it takes no time from the loop's interpreter (no GIL contention, no pickling). The
    process is started with ``python -m qpretarget.viz.viewer``, so a plain script without an
    ``if __name__ == "__main__":`` guard can use it.

    Args:
        controller: the controller whose robot is shown.
        host, port: where to serve (``port=0``: any free port; a taken port moves to a free one).
        max_rate: drawing rate cap [Hz].
        timeout: how long to wait for the viewer process to serve [s].
    """

    def __init__(self, controller: Any, *, host: str = "127.0.0.1", port: int = 8080,
                 max_rate: float = 30.0, timeout: float = 120.0) -> None:  # fmt: skip
        import json
        import subprocess
        import sys
        from multiprocessing import shared_memory

        _viser()  # fail early, in this process, when the extra is missing
        nq = controller.robot.nq
        shm = shared_memory.SharedMemory(create=True, size=8 * (nq + 2))
        self._shm: shared_memory.SharedMemory | None = shm
        self._flags: Any = np.ndarray((nq + 2,), dtype=float, buffer=shm.buf)
        self._flags[:] = 0.0
        self._buf = self._flags[1:]  # [counter, q...] (seqlock, see _read_latest)
        self._q = self._buf[1:]
        port, note = choose_port(host, port)
        if note:
            print(f"qpretarget live viewer: {note}")
        base = getattr(controller, "base_dir", None)
        cmd = [sys.executable, "-m", "qpretarget.viz.viewer",
               "--robot", json.dumps(controller.config["robot"]), "--host", host,
               "--port", str(port), "--shm", shm.name, "--nq", str(nq),
               "--max-rate", str(float(max_rate))]  # fmt: skip
        if base:
            cmd += ["--base-dir", str(base)]
        self._proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        self.port = self._wait_for_port(timeout)
        self.url = f"http://{host}:{self.port}"
        self.sent = 0

    def _wait_for_port(self, timeout: float) -> int:
        out: list[str] = []

        def read() -> None:
            for line in self._proc.stdout:  # type: ignore[union-attr]
                out.append(line)
                if line.startswith("PORT "):
                    return

        th = threading.Thread(target=read, daemon=True)
        th.start()
        th.join(timeout)
        for line in out:
            if line.startswith("PORT "):
                return int(line.split()[1])
        self.close()
        raise ViewerError(
            "the live viewer process did not start within "
            f"{timeout:.0f} s (its output is above{': ' + ''.join(out).strip() if out else ''})."
        )

    def __call__(self, result: Any) -> None:
        """Publish the tick's configuration to the viewer process (seqlock write)."""
        q = result.q if isinstance(result, StepResult) else result
        buf = self._buf
        buf[0] += 1.0  # odd: writing
        np.copyto(self._q, q)
        buf[0] += 1.0  # even: consistent
        self.sent += 1

    def close(self) -> None:
        """Stop the viewer process and free the shared memory."""
        proc = getattr(self, "_proc", None)
        if proc is not None and proc.poll() is None:
            self._flags[0] = 1.0
            try:
                proc.wait(timeout=5.0)
            except Exception:
                proc.terminate()
                proc.wait(timeout=5.0)
        if proc is not None and proc.stdout is not None:
            proc.stdout.close()
        shm = getattr(self, "_shm", None)
        if shm is not None:
            self._flags = self._buf = self._q = None
            shm.close()
            with contextlib.suppress(FileNotFoundError):
                shm.unlink()
            self._shm = None

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


ObserverFn = Callable[[Any], None]


if __name__ == "__main__":  # the LiveViewer process
    import sys

    sys.exit(_live_main())
