# SPDX-License-Identifier: Apache-2.0
"""The command line under bad input: missing files, folders, unwritable outputs, Ctrl-C.

A user error prints one line and exits 1 or 2 (usage), never a traceback; Ctrl-C exits 130
cleanly and leaves no file under the output's final name.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from .conftest import MOCAP, REPO

CFG = str(REPO / "configs" / "g1_whole_body.yaml")
CLIP = str(MOCAP / "cmu_29_03_teapot_arm_gestures.bvh")


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qpretarget", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)  # fmt: skip


def _one_clear_line(r: subprocess.CompletedProcess) -> None:
    """Exit 1 for a user error, 2 for a usage error, no traceback; the message is one line
    (after argparse's usage line, for exit 2)."""
    assert "Traceback" not in r.stderr, r.stderr
    lines = [s for s in r.stderr.strip().splitlines() if s.strip()]
    if lines and lines[0].startswith("usage:"):
        assert r.returncode == 2 and "error:" in lines[-1], r.stderr
    else:
        assert r.returncode == 1, (r.returncode, r.stdout, r.stderr)
        assert len(lines) == 1, r.stderr


@pytest.mark.parametrize(
    "args",
    [
        ["retarget", CFG, "no_such.bvh", "-o", "{tmp}/x.npz"],
        ["retarget", "no_such.yaml", CLIP, "-o", "{tmp}/x.npz"],
        ["retarget", CFG, str(MOCAP), "-o", "{tmp}/x.npz"],  # a folder as the motion
        ["retarget", str(MOCAP), CLIP, "-o", "{tmp}/x.npz"],  # a folder as the config
        ["retarget", CFG, CLIP, "-o", "{tmp}", "--end", "0.2"],  # a folder as the output
        ["retarget", CFG, CLIP, "-o", "{tmp}/file.txt/x.npz", "--end", "0.2"],  # under a file
        ["retarget", CFG, CLIP, "-o", "/proc/qpretarget_x.npz", "--end", "0.2"],  # unwritable
        ["retarget", CFG, CLIP, "-o", "/dev/null/x.npz", "--end", "0.2"],  # under a device
        ["retarget", CFG, "{tmp}/file.txt", "-o", "{tmp}/x.npz"],  # not a motion format
        ["retarget", "{tmp}/file.txt", CLIP, "-o", "{tmp}/x.npz"],  # not a YAML mapping
        ["evaluate", "no_such.npz", "-o", "{tmp}/report"],
        ["evaluate", str(MOCAP), "-o", "{tmp}/report"],
        ["info", "no_such_robot"],
        ["batch", CFG, "no_such_folder", "-o", "{tmp}/out"],
        ["retarget", CFG, CLIP],  # missing -o: usage
        ["no-such-command"],
    ],
)
def test_bad_arguments_give_one_clear_line(tmp_path, args):
    (tmp_path / "file.txt").write_text("a file")
    r = _cli(*[a.format(tmp=tmp_path) for a in args])
    _one_clear_line(r)
    # Nothing half-written left behind: no file but the input (``batch`` makes its empty output
    # folder before it finds that the input folder is missing).
    left = [f for f in tmp_path.rglob("*") if f.is_file() and f.name != "file.txt"]
    assert left == [], left


# The real command line, with one hook: from tick 20 on, each tick says the run is under way
# (once) and lasts 5 ms longer, so the signal lands inside the control loop whatever the machine's
# speed (a fixed sleep before the signal raced the end of the run on a fast machine).
_DRIVER = """
import sys, time
from qpretarget.cli import main
from qpretarget.control.controller import Controller

step = Controller.step

def slow_step(self, *args, **kwargs):
    if self.tick == 20:
        print("RUNNING", flush=True)
    if self.tick >= 20:
        time.sleep(0.005)
    return step(self, *args, **kwargs)

Controller.step = slow_step
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_mid_run_exits_cleanly(tmp_path):
    out = tmp_path / "run.npz"
    p = subprocess.Popen([sys.executable, "-c", _DRIVER, "retarget", CFG, CLIP, "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)  # fmt: skip
    try:
        line = p.stdout.readline()  # blocks until the loop runs (or the process ends)
        assert line.strip() == "RUNNING", (line, p.poll())
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, (p.returncode, stderr)
    assert "Traceback" not in stderr and "interrupted" in stderr, stderr
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())  # no temporary file left


def test_servers_listen_on_this_machine_only_by_default():
    """The viewer and ``qpretarget view`` bind 127.0.0.1 unless ``--host`` says otherwise."""
    import inspect

    from qpretarget.cli import build_parser
    from qpretarget.viz.viewer import Viewer

    assert inspect.signature(Viewer).parameters["host"].default == "127.0.0.1"
    args = build_parser().parse_args(["view", "run.npz"])
    assert args.host == "127.0.0.1"
