#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Cost of streaming a 100 Hz control loop to the browser viewer (issue: <= 10% slow-down).

Runs configs/g1_augmentation.yaml on scripted targets, paced at 100 Hz, with a LiveViewer process
serving throughout. Blocks of ticks alternate between the observer attached and detached (so
machine drift and the other process's load hit both alike) and the script prints the median and
p95 step time of each, the slow-down of the median, the observer call's own cost, and the share of
the 10 ms tick. ``--browser`` connects headless Chromium so the server really sends frames.

    python scripts/bench_live_viewer.py [--seconds 5] [--blocks 6] [--browser]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from qpretarget import Controller
from qpretarget.analysis.solver_comparison import scripted_targets

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
    ap.add_argument("--seconds", type=float, default=5.0, help="length of one block [s]")
    ap.add_argument("--blocks", type=int, default=6, help="blocks per mode (alternating)")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--browser", action="store_true", help="connect headless chromium meanwhile")
    args = ap.parse_args()
    from qpretarget.viz.viewer import LiveViewer

    ctrl = Controller.from_yaml(REPO / "configs" / "g1_augmentation.yaml")
    targets = list(scripted_targets(ctrl, args.seconds))
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
    base, live = [], []
    for _ in range(args.blocks):
        base.append(paced_run(ctrl, targets, args.rate))
        ctrl.add_observer(viewer)
        live.append(paced_run(ctrl, targets, args.rate))
        ctrl.remove_observer(viewer)
    res = ctrl.step(None)
    calls = []
    for _ in range(5000):
        t0 = time.perf_counter()
        viewer(res)
        calls.append(time.perf_counter() - t0)
    viewer.close()
    if proc is not None:
        proc.terminate()
    base_all, live_all = np.concatenate(base), np.concatenate(live)
    for name, x in (("no observer", base_all), ("live viewer", live_all)):
        print(
            f"{name:12s} step median {np.median(x) * 1e6:7.1f} µs  "
            f"p95 {np.percentile(x, 95) * 1e6:7.1f} µs"
        )
    ratios = [np.median(lv) / np.median(bs) for bs, lv in zip(base, live, strict=True)]
    print(f"per-block median ratio live/none: {', '.join(f'{r:.2f}' for r in ratios)}")
    print(
        f"frames published: {viewer.sent}; slow-down of the median step: "
        f"{(np.median(live_all) / np.median(base_all) - 1) * 100:+.1f}%; observer call "
        f"{np.median(calls) * 1e6:.2f} µs median; share of the {1e3 / args.rate:.0f} ms tick: "
        f"{np.median(live_all) * args.rate * 100:.1f}%"
    )


if __name__ == "__main__":
    main()
