# SPDX-License-Identifier: Apache-2.0
"""``qpretarget view``: open a run or a config in the browser viewer (viser)."""

from __future__ import annotations

import argparse
import webbrowser
from pathlib import Path

from . import add_command

SUMMARY = "interactive 3D viewer in the browser for a run (.npz) or a config (.yaml)"
DESCRIPTION = "Serve a 3D view of a run or of a controller config on localhost."

HELP = """examples:
  qpretarget view walk_g1.npz                       replay a run beside the human motion
  qpretarget view configs/g1_whole_body.yaml        check a robot setup: frames, collision pairs
  qpretarget view walk_g1.npz --port 0              any free port
  qpretarget view walk_g1.npz --host 0.0.0.0        reachable from other machines

The page is served on http://HOST:PORT; press Ctrl-C to stop. Needs the `viz` extra.
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``view`` subcommand."""
    p = add_command(sub, "view", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("input", help="a run .npz or a controller .yaml")
    p.add_argument("--host", default="127.0.0.1", help="interface (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free)")
    p.add_argument("--strict-port", action="store_true", help="fail if the port is taken")
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.set_defaults(func=run)


def build_viewer(path: Path, *, host: str, port: int, strict_port: bool = False):  # noqa: ANN201
    """Build the viewer for a run or a config (used by the command and by tests)."""
    from ..control.controller import Controller
    from ..errors import ConfigError
    from ..trajectory import RobotTrajectory
    from ..viz.viewer import Viewer

    if path.suffix == ".npz":
        traj = RobotTrajectory.load(path)
        ctrl = traj.make_controller()
        viewer = Viewer(ctrl.robot, host=host, port=port, search_port=not strict_port)
        series = None
        try:
            from ..analysis.metrics import compute_series

            s = compute_series(traj)
            series = {"com_margin": s.com_margin}
            if s.pair_distance is not None and len(s.pair_distance):
                series["min_distance"] = s.pair_distance.min(axis=1)
        except Exception:  # numbers are a bonus; the replay works without them
            series = None
        viewer.show_run(traj, series=series)
        return viewer
    if path.suffix in (".yaml", ".yml"):
        ctrl = Controller.from_yaml(path)
        viewer = Viewer(ctrl.robot, host=host, port=port, search_port=not strict_port)
        viewer.show_config(ctrl)
        return viewer
    raise ConfigError(f"{path.name}: give a run (.npz) or a controller config (.yaml).")


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C."""
    from ..errors import ConfigError

    path = Path(args.input)
    if not path.exists():
        raise ConfigError(f"{args.input!r} does not exist.")
    viewer = build_viewer(path, host=args.host, port=args.port, strict_port=args.strict_port)
    try:
        # From here on the page is served: a Ctrl-C stops it cleanly, also one that comes
        # before serve_forever's own handler is in place (a loaded machine gets there late).
        print(f"qpretarget view: {path.name} on {viewer.url}  (Ctrl-C to stop)")
        if args.open:
            webbrowser.open(viewer.url)
        viewer.serve_forever()
    except KeyboardInterrupt:
        print("\nqpretarget view: stopping (Ctrl-C).")
        viewer.close()
    return 0
