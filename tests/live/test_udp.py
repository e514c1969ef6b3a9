# SPDX-License-Identifier: Apache-2.0
"""`qpretarget stream` and `qpretarget live` in two processes over UDP on 127.0.0.1 (G1 whole
body, daqp, a shared dance clip): commands for every control tick, equal to the offline causal
run on the same float32 frames; and a stream with lost, repeated, swapped and broken datagrams and
a 2-second pause."""

from __future__ import annotations

import json
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from qpretarget.control.controller import Controller
from qpretarget.motion import load_motion
from qpretarget.motion.human_motion import HumanMotion
from qpretarget.retarget import Retargeter
from qpretarget.sources import decode_command, mvn

CAPTURE = 120.0


def run_pair(
    tmp_path: Path, config: Path, clip: Path, stream_args: list[str], max_wait_ms: int = 100
) -> dict:
    """Start `live` on a free port, stream the clip to it, stop `live` with Ctrl-C (SIGINT).

    ``--max-lag`` is large so that a stalled test machine never skips a backlog (the counts and
    the comparison stay deterministic); ``max_wait_ms`` is how late the sender may be before a
    frame is extrapolated.
    """
    record = tmp_path / "live.npz"
    # The robot's side: a socket drained by a thread, receiving the published commands.
    robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    robot.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    robot.bind(("127.0.0.1", 0))
    robot.settimeout(0.2)
    received: list[bytes] = []
    done = threading.Event()

    def drain() -> None:  # until `live` has exited and the socket stayed empty for 0.2 s
        while True:
            try:
                received.append(robot.recv(65536))
            except TimeoutError:
                if done.is_set():
                    return

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    live = subprocess.Popen(
        [sys.executable, "-m", "qpretarget", "live", str(config), "--source", "xsens:0",
         "--capture-rate", str(CAPTURE), "--max-wait", str(max_wait_ms), "--max-lag", "10000",
         "--record", str(record), "--publish", f"udp://127.0.0.1:{robot.getsockname()[1]}",
         "--json", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        ready, _, _ = select.select([live.stderr], [], [], 120.0)
        assert ready, "qpretarget live did not start within 120 s"
        line = live.stderr.readline()  # printed once the socket is bound
        assert "listening" in line, line + live.stderr.read()
        port = int(line.split("udp://127.0.0.1:")[1].split()[0])
        subprocess.run(
            [sys.executable, "-m", "qpretarget", "stream", str(clip), "--to",
             f"udp://127.0.0.1:{port}", "--rate", str(CAPTURE), "--quiet", *stream_args],
            check=True, timeout=60,
        )  # fmt: skip
        time.sleep(0.5)
        live.send_signal(signal.SIGINT)
        out, err = live.communicate(timeout=60)
    finally:
        if live.poll() is None:
            live.kill()
        done.set()
        reader.join()
        robot.close()
    assert live.returncode == 0, err
    report = json.loads(out.strip().splitlines()[-1])
    data = dict(np.load(record))
    assert json.loads(str(data["report"]))["counts"] == report["counts"]
    data["report"] = report
    data["published"] = [decode_command(d) for d in received]
    return data


def offline_reference(config: Path, frames: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    motion = HumanMotion(
        t=np.arange(len(frames)) / CAPTURE, names=mvn.JOINT_NAMES, positions=frames,
        parents=mvn.PARENTS, orientations=rotations, rate=CAPTURE,
    )  # fmt: skip
    ctrl = Controller.from_yaml(config)
    return Retargeter(ctrl, keypoint_map=mvn.KEYPOINT_MAP).retarget(motion, causal=True).q


def test_live_equals_offline_causal_run(tmp_path: Path, configs_dir: Path, mocap_dir: Path):
    config = configs_dir / "g1_whole_body.yaml"
    clip = mocap_dir / "cmu_131_04_dance_spin.bvh"
    # A sender late by up to 5 s (a stalled test machine) is waited for, never extrapolated:
    # the comparison with the offline run needs every frame as it was sent.
    run = run_pair(tmp_path, config, clip, ["--end", "2.5"], max_wait_ms=5000)
    rep = run["report"]
    assert rep["source"]["malformed"] == 0
    # The frames that arrived are the clip's segments through float32, bit for bit.
    P, Q = mvn.segment_poses(load_motion(clip).slice(0, 2.5))
    live_frames = run["frame_kind"] == "live"
    n = int(live_frames.sum())
    assert n == len(P) == rep["counts"]["frames"]  # nothing lost on the loopback
    decoded = [mvn.decode_pose(mvn.encode_pose(k, 0, P[k], Q[k])) for k in range(n)]
    expected_p = np.array([d.positions for d in decoded])
    expected_R = mvn.quat_to_matrix(np.array([d.quaternions for d in decoded]))
    np.testing.assert_array_equal(run["frame_positions"][live_frames], expected_p)
    np.testing.assert_array_equal(run["frame_orientations"][live_frames], expected_R)
    # A command for every control tick: consecutive ticks 10 ms apart, none missing.
    t = run["t"]
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)
    assert t[0] == 0.0
    # Equal to the offline causal run on the same frames: same code, same numbers (1e-6 is the
    # acceptance bound; daqp is deterministic, so this is exact in practice).
    q_ref = offline_reference(config, expected_p, expected_R)
    live = run["input"] == "live"
    k = int(live.sum())
    assert k >= len(q_ref) - 2
    np.testing.assert_allclose(run["q"][live], q_ref[:k], rtol=0, atol=1e-6)
    # What the robot received over UDP: every tick once, in order, the same commands.
    pub = run["published"]
    ticks = [c["tick"] for c in pub]
    assert ticks == list(range(len(t))), (
        len(ticks),
        len(t),
        sorted(set(range(len(t))) - set(ticks)),
    )
    np.testing.assert_array_equal(np.array([c["q"] for c in pub]), run["q"])
    np.testing.assert_array_equal([c["t"] for c in pub], t)
    lat = rep["latency"]
    assert lat["n"] == k and 0 < lat["median_ms"] <= lat["p95_ms"] <= lat["p99_ms"]
    assert np.all(np.isfinite(run["latency"][live]))


def test_faults_and_a_two_second_pause(tmp_path: Path, configs_dir: Path, mocap_dir: Path):
    config = configs_dir / "g1_whole_body.yaml"
    clip = mocap_dir / "cmu_131_04_dance_spin.bvh"
    faults = ["--end", "4.5", "--drop", "100,101", "--duplicate", "150", "--swap", "200",
              "--malformed", "230", "--pause-at", "2.0", "--pause", "2.0"]  # fmt: skip
    run = run_pair(tmp_path, config, clip, faults, max_wait_ms=300)
    c, src = run["report"]["counts"], run["report"]["source"]
    assert src["malformed"] == 2  # a truncated datagram and one whose size field lies
    assert c["duplicates"] == 1 and c["reordered"] == 1
    # 100 and 101 filled in; the pause's 240 samples: one extrapolated, then held one per
    # capture period until the stream is overdue again, the rest skipped on resume (lost).
    # (>= 1: a sender stalled over 300 ms by a loaded test machine adds a hold of its own.)
    assert c["lost"] >= 2 and c["extrapolated"] >= 1 and c["resumes"] >= 1
    assert c["held_frames"] + c["lost"] + c["extrapolated"] >= 240
    t = run["t"]
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)  # every tick, through the pause
    # Smooth hold and resume: every tick within the joints' velocity limits and the config's
    # acceleration limit (its a_max [rad/s^2]), through the hold and the resume (1e-9:
    # round-off).
    ctrl = Controller.from_yaml(config)
    a_max = next(c.a_max for c in ctrl.constraints if c.name == "acceleration_limits").max()
    v_max = ctrl.robot.model.velocityLimit[6:]
    v = run["v"][:, 6:]
    assert np.all(np.abs(v) <= v_max * (1 + 1e-9))
    dv = np.abs(np.diff(v, axis=0)).max(axis=1)
    assert np.all(dv[run["status"][1:] == "ok"] <= a_max * 0.01 + 1e-9)
