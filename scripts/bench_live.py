#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""End-to-end latency of ``qpretarget live`` on shared clips streamed as Xsens MVN datagrams.

Usage:
    python scripts/bench_live.py                                  # dance + boxing, config's solver
    python scripts/bench_live.py --solvers daqp proxsuite --seconds 20
    python scripts/bench_live.py --clips cmu_17_10_boxing.bvh --rate 100

For each clip and QP backend, ``qpretarget stream`` sends the clip over UDP on 127.0.0.1 at its
capture rate (a separate process, as a suit would), and a :class:`LiveSession` in this process
receives it, retargets it with the controller config at the control rate and publishes each
command over UDP. Latency: from the kernel's receive time stamp of the datagram that made a command
computable to the command having been sent (``latency_stats``: median, p95, p99, max);
deadline misses: commands later than the budget (the control period). The machine's load is
printed: on a shared machine, other processes' time slices show up in p99 and max.
"""

from __future__ import annotations

import argparse
import copy
import os
import subprocess
import sys
from pathlib import Path

from qpretarget.analysis.benchmark import machine_info
from qpretarget.control.controller import Controller
from qpretarget.retarget import Retargeter
from qpretarget.sources import LiveSession, UdpPublisher
from qpretarget.sources.session import set_realtime
from qpretarget.sources.xsens import XsensSource
from qpretarget.yamlio import load_yaml

REPO = Path(__file__).resolve().parents[1]
MOCAP = REPO.parent / "shared" / "data" / "mocap"
CLIPS = ("cmu_131_04_dance_spin.bvh", "cmu_17_10_boxing.bvh")


def bench(config: Path, solver: str | None, clip: Path, args: argparse.Namespace) -> dict:
    """One live run: returns the session report."""
    with open(config, encoding="utf-8") as f:
        cfg = load_yaml(f)
    if solver is not None or args.solver_options:
        cfg = copy.deepcopy(cfg)
        name = solver or (cfg.get("solver") or {}).get("name", "daqp")
        cfg["solver"] = {"name": name, **args.solver_options}
    ctrl = Controller(cfg, base_dir=config.parent)
    retargeter = Retargeter(ctrl, rate=args.rate)
    source = XsensSource(0, capture_rate=args.capture_rate)
    sink = UdpPublisher("udp://127.0.0.1:9")  # discard port: the cost of sending is measured
    session = LiveSession(retargeter, source, publishers=[sink], record=False, record_run=False)
    proc: list[subprocess.Popen] = []

    def start_stream(src: object) -> None:
        cmd = [
            sys.executable,
            "-m",
            "qpretarget",
            "stream",
            str(clip),
            "--to",
            f"udp://127.0.0.1:{source.port}",
            "--rate",
            str(args.capture_rate),
            "--quiet",
        ]
        if args.seconds:
            cmd += ["--end", str(args.seconds)]
        proc.append(subprocess.Popen(cmd))

    # Stop when the sender is done (no hold at the end of the clip).
    report = session.run(
        on_open=start_stream, until=lambda: bool(proc) and proc[0].poll() is not None
    )
    proc[0].wait(timeout=60)
    sink.close()
    opts = ", ".join(f"{k}={v}" for k, v in args.solver_options.items())
    report["solver"] = (solver or cfg.get("solver", {}).get("name", "default")) + (
        f" ({opts})" if opts else ""
    )
    return report


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config", default=str(REPO / "configs" / "g1_whole_body.yaml"))
    ap.add_argument("--clips", nargs="+", default=list(CLIPS))
    ap.add_argument("--solvers", nargs="+", default=[None], help="QP backends (default: config's)")
    ap.add_argument("--capture-rate", type=float, default=120.0, help="stream rate [Hz]")
    ap.add_argument("--rate", type=float, default=None, help="control rate [Hz] (default 1/dt)")
    ap.add_argument("--seconds", type=float, default=None, help="excerpt length (default all)")
    ap.add_argument("--realtime", action="store_true", help="receive loop under SCHED_FIFO 50")
    ap.add_argument(
        "--solver-options",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="solver options, e.g. max_iter=50 (ProxSuite) or iter_limit=100 (daqp)",
    )
    args = ap.parse_args()
    args.solver_options = {
        k: float(v) if "." in v else int(v)
        for k, v in (o.split("=", 1) for o in args.solver_options)
    }  # fmt: skip
    if args.realtime:
        set_realtime(50)
    info = machine_info()
    print(f"machine: {info.get('cpu', '?')}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f} at start")  # fmt: skip
    print(
        "| clip | backend | ticks | median ms | p95 ms | p99 ms | max ms | deadline misses "
        "| held ticks | controller step median / p99 ms | relaxed / held by the controller |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.clips:
        clip = Path(name) if Path(name).is_file() else MOCAP / name
        for solver in args.solvers:
            rep = bench(Path(args.config), solver, clip, args)
            lat, c, step = rep["latency"], rep["counts"], rep["controller_step"]
            status = rep["controller_status"]
            print(
                f"| {clip.stem} | {rep['solver']} | {c['ticks']} | {lat['median_ms']:.2f} | "
                f"{lat['p95_ms']:.2f} | {lat['p99_ms']:.2f} | {lat['max_ms']:.2f} | "
                f"{c['deadline_misses']} | {c['held_ticks']} | "
                f"{step['median_ms']:.2f} / {step['p99_ms']:.2f} | "
                f"{status.get('relaxed', 0)} / {status.get('held', 0)} |",
                flush=True,
            )
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
