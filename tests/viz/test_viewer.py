# SPDX-License-Identifier: Apache-2.0
"""The browser viewer: served on a free localhost port, drawn in headless Chromium, port handling.

Needs the `viz` extra (viser, selenium) and Debian's chromium + chromium-driver. .ci/run installs
them and sets CI=true: there a missing browser is a test failure. Elsewhere the browser test skips
with the apt-get line to run.
"""

from __future__ import annotations

import os
import shutil
import socket

import numpy as np
import pytest

from qpretarget.analysis.solver_comparison import scripted_targets
from qpretarget.control.controller import Controller
from qpretarget.viz.screenshot import screenshot
from qpretarget.viz.viewer import ViewerError, choose_port


@pytest.fixture(scope="module")
def short_run(make_run):
    return make_run(1.0)


APT_LINE = "sudo apt-get install chromium chromium-driver"


def require_browser() -> None:
    """Skip (outside CI) or fail (CI=true) when headless Chromium or chromedriver is missing."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    missing = [
        n
        for n, p in (("chromium", chromium), ("chromedriver", shutil.which("chromedriver")))
        if not p
    ]
    if not missing:
        return
    reason = f"{' and '.join(missing)} not found: install them with `{APT_LINE}`"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason} (CI=true: .ci/run installs them, so this is a failure)")
    pytest.skip(reason)


def test_viewer_draws_robot_and_timeline(short_run, tmp_path) -> None:
    require_browser()
    from PIL import Image

    from qpretarget.commands.view import build_viewer

    viewer = build_viewer(short_run, host="127.0.0.1", port=0)
    shot = tmp_path / "view.png"
    try:
        found = screenshot(viewer.url, shot, wait_for=("Frame", "Play / pause"))
    finally:
        viewer.close()
    assert found, "the timeline controls never appeared"
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    h, w, _ = img.shape
    # The robot stands at the origin, which the initial camera puts in the left-centre of the page
    # (the GUI panel covers the right third). Count pixels clearly darker than the white/grey
    # background there: the grid lines alone are a few percent.
    region = img[int(0.2 * h) : int(0.8 * h), int(0.25 * w) : int(0.6 * w)]
    background = np.array([255, 255, 255])
    dark = np.abs(region - background).sum(axis=2) > 120
    assert dark.mean() > 0.02, f"robot not drawn ({dark.mean():.3%} non-background pixels)"


def test_taken_port_moves_or_fails() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        taken = s.getsockname()[1]
        port, note = choose_port("127.0.0.1", taken)
        assert port != taken and f"port {taken} is taken; using port {port}" in note
        with pytest.raises(
            ViewerError, match=rf"port {taken} on 127\.0\.0\.1 is taken .* --port 0"
        ):
            choose_port("127.0.0.1", taken, search=False)


def test_live_viewer_streams_a_running_controller(configs_dir) -> None:
    from qpretarget.viz.viewer import LiveViewer

    ctrl = Controller.from_yaml(configs_dir / "g1_augmentation.yaml")
    with LiveViewer(ctrl, port=0) as live:
        ctrl.add_observer(live)
        ctrl.reset()
        for tg in scripted_targets(ctrl, 0.3):
            res = ctrl.step(tg)
        assert not res.messages  # the observer never raised
        assert live.sent == 30
        # the viewer process serves the page
        import urllib.request

        with urllib.request.urlopen(live.url, timeout=30) as page:
            assert page.status == 200 and b"<html" in page.read(2000).lower()


def test_view_command_stops_cleanly_on_ctrl_c(configs_dir) -> None:
    """`qpretarget view CONFIG` serves until Ctrl-C, then says so, exits 0 and frees its port."""
    import os
    import re
    import signal
    import subprocess
    import sys
    import time
    import urllib.request

    proc = subprocess.Popen(
        [sys.executable, "-m", "qpretarget", "view", str(configs_dir / "g1_whole_body.yaml"),
         "--port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        url = None
        deadline = time.monotonic() + 120.0
        lines = []
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line and proc.poll() is not None:
                break
            lines.append(line)
            m = re.search(r"on (http://127\.0\.0\.1:(\d+))", line)
            if m:
                url, port = m.group(1), int(m.group(2))
        assert url is not None, "viewer did not start:\n" + "".join(lines)
        with urllib.request.urlopen(url, timeout=10) as page:  # serving the client page
            assert page.status == 200
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, out
    assert "stopping (Ctrl-C)" in out
    assert "Traceback" not in out
    with socket.socket() as s:  # the port is free again
        s.bind(("127.0.0.1", port))


def test_live_viewer_from_a_plain_script(configs_dir, tmp_path) -> None:
    """A user's top-level loop (no `if __name__ == "__main__":` guard) can stream to a viewer."""
    import subprocess
    import sys

    script = tmp_path / "loop.py"
    script.write_text(
        "from qpretarget import Controller\n"
        "from qpretarget.analysis.solver_comparison import scripted_targets\n"
        "from qpretarget.viz.viewer import LiveViewer\n"
        f"ctrl = Controller.from_yaml({str(configs_dir / 'g1_augmentation.yaml')!r})\n"
        "live = LiveViewer(ctrl, port=0)\n"
        "ctrl.add_observer(live)\n"
        "for tg in scripted_targets(ctrl, 0.2):\n"
        "    res = ctrl.step(tg)\n"
        "live.close()\n"
        "print('sent', live.sent, 'messages', res.messages)\n"
    )
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    assert "sent 20 messages []" in out.stdout
    assert "leaked" not in out.stderr and "Traceback" not in out.stderr


def test_missing_browser_skips_outside_ci_and_fails_in_ci(monkeypatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="apt-get install chromium chromium-driver"):
        require_browser()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="chromium and chromedriver not found"):
        require_browser()


def test_view_stops_cleanly_on_an_early_ctrl_c(configs_dir, monkeypatch, capsys) -> None:
    """A Ctrl-C between the "on URL" line and serve_forever's handler (a loaded machine gets
    there late: CI saw exit 130, "interrupted.") stops the viewer cleanly all the same."""
    import argparse

    from qpretarget.commands import view

    def interrupt(url: str) -> None:  # the browser call sits in that window
        raise KeyboardInterrupt

    monkeypatch.setattr(view.webbrowser, "open", interrupt)
    args = argparse.Namespace(
        input=str(configs_dir / "g1_whole_body.yaml"), host="127.0.0.1", port=0,
        strict_port=False, open=True,
    )  # fmt: skip
    try:
        rc = view.run(args)
    except KeyboardInterrupt:
        pytest.fail("the early Ctrl-C escaped the view command")
    assert rc == 0
    out = capsys.readouterr().out
    assert "on http://127.0.0.1:" in out and "stopping (Ctrl-C)" in out
    port = int(out.split("127.0.0.1:")[1].split()[0].rstrip("/"))
    with socket.socket() as s:  # the server is stopped: its port is free again
        s.bind(("127.0.0.1", port))
