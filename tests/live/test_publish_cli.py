# SPDX-License-Identifier: Apache-2.0
"""Command datagrams (binary and JSON), the sources registry, the file source and the commands'
error messages."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest

from qpretarget.cli import main
from qpretarget.errors import ConfigError, UnknownNameError
from qpretarget.sources import (
    SOURCES,
    LiveCommand,
    UdpPublisher,
    decode_command,
    encode_command,
    load_sources,
    open_source,
)
from qpretarget.sources.file import FileSource
from qpretarget.sources.publish import COMMAND_HEADER, STATUS_FLAGS
from qpretarget.sources.xsens import XsensSource
from qpretarget.trajectory import RobotTrajectory


def _cmd(**kw) -> LiveCommand:
    base = dict(tick=41, t=0.41, q=np.arange(36.0), v=-np.arange(35.0), status="relaxed",
                input="held", deadline_miss=True, ready_time=0.0)  # fmt: skip
    base.update(kw)
    return LiveCommand(**base)


def test_binary_layout() -> None:
    cmd = _cmd()
    data = encode_command(cmd, 123.5)
    assert len(data) == COMMAND_HEADER.size + 8 * (36 + 35) and COMMAND_HEADER.size == 32
    assert data[:4] == b"QPRC" and data[4] == 1
    assert data[5] == STATUS_FLAGS["relaxed"] | STATUS_FLAGS["held"] | STATUS_FLAGS["deadline"]
    assert int.from_bytes(data[6:8], "little") == 36 and int.from_bytes(data[8:10], "little") == 35
    assert int.from_bytes(data[12:16], "little") == 41
    assert np.frombuffer(data[16:24], "<f8")[0] == 0.41
    back = decode_command(data)
    np.testing.assert_array_equal(back["q"], cmd.q)
    np.testing.assert_array_equal(back["v"], cmd.v)
    assert back["sent"] == 123.5 and back["tick"] == 41
    with pytest.raises(ValueError, match="malformed"):
        decode_command(data[:-8])


def test_udp_publisher_sends_json_and_binary() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5.0)
    port = rx.getsockname()[1]
    for fmt in ("json", "binary"):
        pub = UdpPublisher(f"udp://127.0.0.1:{port}", fmt)
        pub(_cmd(status="ok", input="live", deadline_miss=False))
        pub.close()
        got = decode_command(rx.recv(65536))
        np.testing.assert_array_equal(got["q"], np.arange(36.0))
        assert got["tick"] == 41 and got["flags"] == 0
    rx.close()


@pytest.mark.parametrize("url", ["tcp://127.0.0.1:9", "udp://127.0.0.1", "127.0.0.1:9"])
def test_bad_publish_address(url: str) -> None:
    with pytest.raises(ConfigError, match="udp://HOST:PORT"):
        UdpPublisher(url)


def test_registry_and_specs(mocap_dir: Path) -> None:
    assert {"xsens", "file"} <= set(load_sources())
    src = open_source("xsens:0", {"host": "127.0.0.1", "capture_rate": 120.0})
    assert isinstance(src, XsensSource) and src.rate == 120.0 and src.port == 0
    assert open_source("xsens", {}).port == 9763
    with pytest.raises(UnknownNameError, match="xsens"):
        open_source("xsen", {})
    with pytest.raises(ConfigError, match="0..65535"):
        open_source("xsens:99999", {})
    assert SOURCES["file"] is FileSource


def test_port_taken_is_one_clear_error() -> None:
    from qpretarget.sources import SourceError

    a = XsensSource(0)
    a.open()
    try:
        b = XsensSource(a.port)
        with pytest.raises(SourceError, match="pick another port"):
            b.open()
    finally:
        a.close()


def test_file_source_plays_in_real_time(mocap_dir: Path) -> None:
    src = FileSource(str(mocap_dir / "cmu_17_10_boxing.bvh"), speed=10.0, end=0.5)
    src.open()
    frames = []
    while not src.exhausted:
        frames += src.poll(0.05)
    src.close()
    assert [f.seq for f in frames] == list(range(60))
    np.testing.assert_array_equal(frames[7].positions, src.motion.positions[7])
    # Frame k is not handed out before its time (10x speed: 60 frames in about 0.05 s).
    assert frames[-1].recv_time - frames[0].recv_time >= 59 / 120 / 10 - 1e-3


def test_live_on_a_file_source_runs_and_writes_the_record(
    tmp_path: Path, configs_dir: Path, mocap_dir: Path, capsys
) -> None:
    out, run_file = tmp_path / "live.npz", tmp_path / "run.npz"
    # 1.5 s of wall time from the source's opening, start-up included: 0.5 s recorded only 10
    # ticks on the 2-core machine while two other processes kept both cores busy.
    code = main(["live", str(configs_dir / "g1_whole_body.yaml"), "--source",
                 f"file:{mocap_dir / 'cmu_17_10_boxing.bvh'}", "--speed", "4", "--duration",
                 "1.5", "--record", str(out), "--run", str(run_file), "--quiet"])  # fmt: skip
    assert code == 0 and out.is_file()
    text = capsys.readouterr().out
    assert "latency" in text and "deadlines" in text
    run = np.load(out)
    assert len(run["t"]) > 10 and run["q"].shape[1] == 36
    # The run file is the retargeter's own (what evaluate / view read): the same commands.
    traj = RobotTrajectory.load(run_file)
    np.testing.assert_array_equal(traj.q, run["q"])


def test_live_records_the_retargeter_only_for_run(
    tmp_path: Path, configs_dir: Path, mocap_dir: Path, monkeypatch
) -> None:
    """Without --run the retargeter is started with record=False (memory flat over hours);
    --record alone still writes the live record (it keeps its own, not the retargeter's)."""
    from qpretarget.retarget import Retargeter

    seen: list[bool] = []
    start = Retargeter.start

    def spy(self, *args, **kwargs):
        seen.append(kwargs.get("record", True))
        return start(self, *args, **kwargs)

    monkeypatch.setattr(Retargeter, "start", spy)
    out = tmp_path / "live.npz"
    # 1 s of wall time: the calibration and the initial stance's settling (up to 3.5 s of ticks,
    # none recorded) come first; with 0.3 s a loaded machine recorded 2 ticks.
    code = main(["live", str(configs_dir / "g1_whole_body.yaml"), "--source",
                 f"file:{mocap_dir / 'cmu_17_10_boxing.bvh'}", "--speed", "4", "--duration",
                 "1.0", "--record", str(out), "--quiet"])  # fmt: skip
    assert code == 0 and seen == [False]
    assert len(np.load(out)["q"]) > 5


def test_live_prints_the_retargeters_notes(
    configs_dir: Path, mocap_dir: Path, monkeypatch, capsys
) -> None:
    """A stream whose person lies (here a file turned 90 deg about x: a suit streaming with
    the wrong up axis) is held in the start posture, and the end-of-run report says why."""
    import dataclasses

    import qpretarget.motion as motion_pkg

    load = motion_pkg.load_motion
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

    def lying(path, **kw):  # noqa: ANN001, ANN003, ANN202
        m = load(path, **kw)
        ori = np.einsum("ab,tjbc->tjac", R, m.orientations)
        return dataclasses.replace(m, positions=m.positions @ R.T, orientations=ori)

    monkeypatch.setattr(motion_pkg, "load_motion", lying)
    code = main(["live", str(configs_dir / "g1_whole_body.yaml"), "--source",
                 f"file:{mocap_dir / 'cmu_16_15_walk.bvh'}", "--speed", "4", "--duration",
                 "1.0", "--quiet"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "note: support phases: the person is not upright at the start" in text


def test_command_errors_are_one_line(tmp_path: Path, configs_dir: Path, capsys) -> None:
    cfg = str(configs_dir / "g1_whole_body.yaml")
    for argv, msg in [
        (["live", cfg, "--source", "kinect"], "source type 'kinect' is not known"),
        (["live", cfg, "--source", "xsens:0", "--budget", "0"], "--budget must be positive"),
        (["live", cfg, "--record", str(tmp_path)], "is a folder"),
        (["stream", "nope.bvh", "--to", "udp://127.0.0.1:9"], "nope.bvh"),
        (["stream", "x.bvh", "--to", "127.0.0.1:9"], "udp://HOST:PORT"),
    ]:
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1, err


def test_realtime_priority_is_checked() -> None:
    from qpretarget.sources.session import set_realtime

    with pytest.raises(ConfigError, match="1..99"):
        set_realtime(0)


@pytest.mark.parametrize("command", ["live", "stream"])
def test_help_has_examples(command: str, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text and f"qpretarget {command}" in text
