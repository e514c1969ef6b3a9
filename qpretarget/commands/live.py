# SPDX-License-Identifier: Apache-2.0
"""``qpretarget live``: retarget a live motion-capture stream and publish every control tick."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from . import add_command, add_config, add_control_rate, add_quiet

SUMMARY = "retarget a live mocap stream (Xsens MVN over UDP, or a file in real time)"
DESCRIPTION = (
    "Receive a motion-capture stream, run the online retargeter at the control rate "
    "(filling lost frames, extrapolating one late frame, then holding) and publish each "
    "command to UDP and/or the browser viewer, with latency and deadline figures."
)

HELP = """examples:
  qpretarget live configs/g1_whole_body.yaml --source xsens                 MVN on port 9763
  qpretarget live configs/g1_whole_body.yaml --source xsens:9763 --host 0.0.0.0 \\
      --publish udp://192.168.1.20:9870 --record run.npz                 suit on another PC
  qpretarget live configs/g1_whole_body.yaml --view \\
      --source file:../shared/data/mocap/cmu_17_10_boxing.bvh            a file in real time
  # two terminals: a clip streamed as an MVN suit would, and the live retargeter
  qpretarget stream ../shared/data/mocap/cmu_131_04_dance_spin.bvh --to udp://127.0.0.1:9763
  qpretarget live configs/g1_whole_body.yaml --source xsens:9763 --capture-rate 120
  qpretarget live CONFIG --source xsens --run live_run.npz    then: qpretarget evaluate live_run.npz

Sources: xsens[:PORT] (Xsens MVN network streamer, MXTP02 over UDP), file:CLIP (BVH, AMC, C3D).
Ctrl-C stops cleanly; --record writes the run (commands, latencies, frames) to an .npz file.
Memory: without --record and --run only the latency figures grow (16 B per tick, 6 MB per hour);
--run keeps about 8 kB per capture frame (3.5 GB per hour at 120 Hz) and --record about 0.3 MB
per second until the run stops.
Command datagram layouts, the status line and the latency figures: docs/live.md.
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``live`` subcommand."""
    p = add_command(sub, "live", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_config(p)
    _add_source_arguments(p)
    add_control_rate(p)
    _add_output_arguments(p)
    _add_loop_arguments(p)
    p.add_argument("--json", action="store_true", help="print the final report as JSON")
    add_quiet(p, "no status line")
    p.set_defaults(func=run)  # fmt: skip


def _add_source_arguments(p: argparse.ArgumentParser) -> None:
    """Where the stream comes from and how to read it."""
    p.add_argument("--source", default="xsens", help="xsens[:PORT] or file:CLIP")
    p.add_argument("--host", default=None, help="address to listen on (default 127.0.0.1)")
    p.add_argument(
        "--capture-rate",
        type=float,
        default=None,
        help="the stream's sample rate [Hz] (default: measured from time codes)",
    )
    p.add_argument(
        "--units",
        choices=("m", "cm"),
        default=None,
        help="MVN position units (default m: MVN 2018 and later)",
    )
    p.add_argument("--keypoint-map", default=None, help="key-point map of the source's joints")


def _add_output_arguments(p: argparse.ArgumentParser) -> None:
    """Where each command goes (UDP, viewer) and the files written at the end."""
    p.add_argument(
        "--publish",
        action="append",
        default=[],
        metavar="udp://HOST:PORT",
        help="send each command there (repeatable)",
    )
    p.add_argument(
        "--format",
        choices=("binary", "json"),
        default="binary",
        help="command datagram layout (docs/live.md)",
    )
    p.add_argument("--view", action="store_true", help="show the robot live in the browser")
    p.add_argument("--view-port", type=int, default=8080, help="port of the browser viewer")
    p.add_argument(
        "--record",
        default=None,
        metavar="OUT.npz",
        help="write the live record here when it stops (atomic; docs/live.md)",
    )
    p.add_argument(
        "--run",
        default=None,
        metavar="RUN.npz",
        help="also write the retargeter's run file (docs/formats.md) for evaluate / view "
        "(kept in memory until the run stops: about 8 kB per capture frame)",
    )


def _add_loop_arguments(p: argparse.ArgumentParser) -> None:
    """Deadlines, lost and late frames, scheduling, when to stop and a file source's pace."""
    p.add_argument(
        "--budget",
        type=float,
        default=None,
        help="time budget per tick [ms] (default: the control period)",
    )
    p.add_argument(
        "--max-wait",
        type=float,
        default=None,
        help="wait for a late datagram before filling in [ms] (default 2 periods)",
    )
    p.add_argument(
        "--resume-time", type=float, default=0.3, help="blend back into the stream after a hold [s]"
    )
    p.add_argument(
        "--max-lag",
        type=float,
        default=100.0,
        help="skip the backlog when the oldest waiting datagram is older than this [ms]",
    )
    p.add_argument(
        "--realtime",
        type=int,
        nargs="?",
        const=50,
        default=None,
        metavar="PRIORITY",
        help="run the loop under the real-time FIFO scheduler (Linux; default priority 50)",
    )
    p.add_argument("--duration", type=float, default=None, help="stop after this long [s]")
    p.add_argument(
        "--idle-exit", type=float, default=None, help="stop after this long without a datagram [s]"
    )
    p.add_argument("--speed", type=float, default=None, help="file source: playback speed")


def format_report(report: dict) -> str:
    """The end-of-run summary: counts and latency figures."""
    c, s, lat = report["counts"], report["source"], report["latency"]
    return "\n".join(
        [
            f"source        {report['source_name']}",
            f"rates         capture {report['capture_rate'] or 0:g} Hz -> control "
            f"{report['control_rate']:g} Hz, {c['ticks']} ticks in {report['wall_time']:.1f} s",
            f"latency       median {lat['median_ms']:.3f} ms, p95 {lat['p95_ms']:.3f} ms, "
            f"p99 {lat['p99_ms']:.3f} ms, max {lat['max_ms']:.3f} ms ({lat['n']} commands, "
            "datagram received -> command sent)",
            f"deadlines     {c['deadline_misses']} misses (budget {report['budget_ms']:.1f} ms); "
            "controller: "
            + ", ".join(f"{n} {k}" for k, n in sorted(report["controller_status"].items())),
            f"frames        {c['frames']} received, {c['lost']} lost (filled in), "
            f"{c['duplicates']} duplicates, {c['reordered']} reordered, {c['late']} late, "
            f"{s.get('malformed', 0)} malformed, {s.get('ignored', 0)} ignored",
            f"holds         {c['extrapolated']} extrapolated + {c['held_frames']} held frames, "
            f"{c['held_ticks']} held ticks, {c['resumes']} resumes, {c['resyncs']} resyncs, "
            f"{c['skipped']} samples skipped to catch up",
        ]
    )


_POSITIVE = ("budget", "max_wait", "max_lag", "duration", "idle_exit", "capture_rate", "speed")


def run(args: argparse.Namespace) -> int:
    """Run the live loop until Ctrl-C (or --duration / --idle-exit); return the exit code."""
    from ..control.controller import Controller
    from ..errors import ConfigError
    from ..fileio import check_output_file
    from ..retarget import Retargeter
    from ..sources import open_source
    from ..sources.session import set_realtime

    for name in _POSITIVE:
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise ConfigError(f"--{name.replace('_', '-')} must be positive, got {value}.")
    record = check_output_file(args.record, ".npz") if args.record else None
    run_file = check_output_file(args.run, ".npz") if args.run else None
    options = {
        "host": args.host,
        "capture_rate": args.capture_rate,
        "units": args.units,
        "speed": args.speed,
        "keypoint_map": args.keypoint_map,
    }
    source = open_source(args.source, options)
    controller = Controller.from_yaml(args.config)
    retargeter = Retargeter(controller, keypoint_map=args.keypoint_map, rate=args.rate)
    publishers, viewer = _publishers(args, controller)
    session = _session(
        args, retargeter, source, publishers, record is not None, record_run=run_file is not None
    )
    if args.realtime is not None:
        set_realtime(args.realtime)
    report = _run_session(args, session, source, publishers)
    if record is not None:
        _write_record(session, record)
    if run_file is not None:
        _write_run(session, retargeter, run_file)
    report["notes"] = list(retargeter.notes)  # a person lying, a start in the air, no feet
    if args.json:
        print(json.dumps(report))
    else:
        print(format_report(report))
        for note in report["notes"]:
            print(f"note: {note}")
    _ = viewer
    return 0


def _publishers(args: argparse.Namespace, controller: Any) -> tuple[list, Any]:
    """The UDP publishers of ``--publish`` and the browser viewer of ``--view`` (or ``None``)."""
    from ..sources import UdpPublisher

    publishers: list = [UdpPublisher(url, args.format) for url in args.publish]
    viewer = None
    if args.view:
        from ..viz.viewer import LiveViewer

        viewer = LiveViewer(controller, port=args.view_port)
        print(f"viewer: {viewer.url}", file=sys.stderr)
        publishers.append(viewer)
    return publishers, viewer


def _session(
    args: argparse.Namespace,
    retargeter: Any,
    source: Any,
    publishers: list,
    record: bool,
    *,
    record_run: bool = False,
) -> Any:
    """The :class:`~qpretarget.sources.LiveSession` with the loop options (ms -> s).

    The retargeter records its run only for ``--run`` (else its memory stays flat).
    """
    from ..sources import LiveSession

    return LiveSession(
        retargeter,
        source,
        publishers=publishers,
        budget=None if args.budget is None else 1e-3 * args.budget,
        max_wait=None if args.max_wait is None else 1e-3 * args.max_wait,
        resume_time=args.resume_time,
        max_lag=1e-3 * args.max_lag,
        record=record,
        record_run=record_run,
        keypoint_map=args.keypoint_map,
    )


def _run_session(args: argparse.Namespace, session: Any, source: Any, publishers: list) -> dict:
    """Run the loop with the status line on stderr; close the publishers however it ends."""
    tty = sys.stderr.isatty()

    def status(s: Any) -> None:
        line = s.status_line()
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)

    def opened(src: object) -> None:
        print(f"listening: {source.describe()} (Ctrl-C stops)", file=sys.stderr, flush=True)

    try:
        report = session.run(
            duration=args.duration,
            idle_exit=args.idle_exit,
            status=None if args.quiet else status,
            on_open=opened,
        )
    finally:
        for pub in publishers:
            close = getattr(pub, "close", None)
            if close is not None:
                close()
    if tty and not args.quiet:
        print(file=sys.stderr)
    return report


def _write_record(session: Any, record: Path) -> None:
    """Save the live record (``--record``) unless nothing was received."""
    if session.counts["ticks"]:
        session.save(record)
        print(f"wrote {record}", file=sys.stderr)
    else:
        print(f"nothing received: {record} not written", file=sys.stderr)


def _write_run(session: Any, retargeter: Any, run_file: Path) -> None:
    """Save the retargeter's run file (``--run``, atomic) unless nothing was received."""
    if session.counts["ticks"]:
        from ..fileio import atomic_path

        with atomic_path(run_file, suffix=".npz") as tmp:
            retargeter.trajectory().save(tmp)
        print(f"wrote {run_file}", file=sys.stderr)
    else:
        print(f"nothing received: {run_file} not written", file=sys.stderr)
