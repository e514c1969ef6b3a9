#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Cost of streaming a 100 Hz control loop to the browser viewer (issue: <= 10% slow-down).

Runs configs/g1_augmentation.yaml on scripted targets, paced at 100 Hz, first without a viewer,
then with a Viewer + LivePublisher attached as a controller observer, and prints the median and
p95 step time of both and the relative slow-down. A headless browser can be connected meanwhile to
make the server really send (``--browser``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from qpretarget import Controller
from qpretarget.solver_comparison import scripted_targets

REPO = Path(__file__).resolve().parents[1]


def paced_run(ctrl: Controller, targets: list, rate: float) -> np.ndarray:
    ctrl.reset()
    period = 1.0 / rate
    steps = []
    nxt = time.perf_counter()
    for tg in targets:
        t0 = time.perf_counter()
        ctrl.step(tg)
        steps.append(time.perf_counter() - t0)
        nxt += period
        delay = nxt - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return np.array(steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--browser", action="store_true", help="connect headless chromium meanwhile")
    args = ap.parse_args()
    ctrl = Controller.from_yaml(REPO / "configs" / "g1_augmentation.yaml")
    targets = list(scripted_targets(ctrl, args.seconds))
    base = paced_run(ctrl, targets, args.rate)
    from qpretarget.viz.viewer import LiveViewer

    viewer = LiveViewer(ctrl, port=0)
    proc = None
    if args.browser:
        import subprocess

        proc = subprocess.Popen(
            ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--use-gl=angle",
             "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--disable-background-networking", "--remote-debugging-port=0", viewer.url],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        time.sleep(5.0)
    ctrl.add_observer(viewer)
    live = paced_run(ctrl, targets, args.rate)
    viewer.close()
    if proc is not None:
        proc.terminate()
    for name, x in (("no viewer", base), ("live viewer", live)):
        print(
            f"{name:12s} step median {np.median(x) * 1e6:7.1f} µs  "
            f"p95 {np.percentile(x, 95) * 1e6:7.1f} µs"
        )
    print(
        f"frames published: {viewer.sent}; slow-down of the median step: "
        f"{(np.median(live) / np.median(base) - 1) * 100:+.1f}% "
        f"(share of the 10 ms tick: {np.median(live) * args.rate * 100:.1f}%)"
    )


if __name__ == "__main__":
    main()
