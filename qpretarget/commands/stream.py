# SPDX-License-Identifier: Apache-2.0
"""``qpretarget stream``: send a mocap file as Xsens MVN ``MXTP02`` datagrams at real-time pace.

A stand-in for a suit: ``qpretarget live`` (or MVN Analyze's Network Monitor) receives it. The
fault options drop, repeat, swap or corrupt given samples and pause the stream, to see how a
receiver copes.
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from typing import Any

import numpy as np

from . import add_clip_range, add_command, add_motion, add_quiet

SUMMARY = "send a mocap file as Xsens MVN network-stream datagrams (MXTP02) in real time"
DESCRIPTION = (
    "Play a BVH, ASF/AMC or C3D clip as the 23 segment poses of an Xsens MVN suit over "
    "UDP, at the given rate and real-time pace."
)

HELP = """examples:
  qpretarget stream ../shared/data/mocap/cmu_131_04_dance_spin.bvh --to udp://127.0.0.1:9763
  qpretarget stream clip.bvh --to udp://127.0.0.1:9763 --protocol mxtp02 --rate 120 --loop
  qpretarget stream clip.bvh --to udp://127.0.0.1:9763 --end 4 --drop 100,101 --duplicate 150 \\
      --swap 200 --malformed 250 --pause-at 2.5 --pause 2.0        faults, for testing a receiver

Datagrams: docs/live.md ("MXTP02"); sample counter = frame number from 0, time code = ms.
"""


def _ints(text: str) -> set[int]:
    from ..errors import ConfigError

    try:
        return {int(x) for x in text.split(",") if x.strip()}
    except ValueError:
        raise ConfigError(f"expected sample numbers separated by commas, got {text!r}.") from None


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``stream`` subcommand."""
    p = add_command(sub, "stream", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_motion(p)
    p.add_argument("--to", default="udp://127.0.0.1:9763", help="udp://HOST:PORT to send to")
    p.add_argument("--protocol", default="mxtp02", choices=("mxtp02",), help="datagram format")
    p.add_argument("--rate", type=float, default=None, help="sample rate [Hz] (default: clip's)")
    add_clip_range(p)
    p.add_argument("--speed", type=float, default=1.0, help="pace (1 = real time)")
    p.add_argument("--loop", action="store_true", help="play the clip again and again")
    p.add_argument("--units", choices=("m", "cm"), default="m", help="position units sent")
    p.add_argument("--keypoint-map", default=None, help="key-point map of the clip")
    p.add_argument("--delay", type=float, default=0.0, help="wait before the first datagram [s]")
    p.add_argument("--drop", default="", help="sample numbers not to send (N,N,...)")
    p.add_argument("--duplicate", default="", help="sample numbers to send twice")
    p.add_argument("--swap", default="", help="sample numbers N sent after N+1")
    p.add_argument("--malformed", default="", help="after these samples send a broken datagram")
    p.add_argument("--pause-at", type=float, default=None, help="stop sending at this time [s]")
    p.add_argument("--pause", type=float, default=0.0, help="for this long [s] (samples lost)")
    add_quiet(p, "no summary line")
    p.set_defaults(func=run)


def resample_poses(
    t: np.ndarray, P: np.ndarray, Q: np.ndarray, rate: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segment poses at ``rate`` over the clip: positions linear, quaternions normalized-lerp.

    Returns ``(t_new, P_new, Q_new)``; the clip's own samples when ``rate`` is its rate.
    """
    t = np.asarray(t, float)
    duration = t[-1] - t[0]
    n = int(np.floor(duration * rate + 1e-9)) + 1
    tn = t[0] + np.arange(n) / rate
    if len(t) == n and np.allclose(tn, t, atol=1e-9):
        return t, P, Q
    idx = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 2)
    w = ((tn - t[idx]) / (t[idx + 1] - t[idx]))[:, None, None]
    Pn = (1 - w) * P[idx] + w * P[idx + 1]
    q0, q1 = Q[idx], Q[idx + 1]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    Qn = (1 - w) * q0 + w * q1
    Qn /= np.linalg.norm(Qn, axis=-1, keepdims=True)
    return tn, Pn, Qn


def run(args: argparse.Namespace) -> int:
    """Send the clip; return the exit code."""
    from ..errors import ConfigError
    from ..sources import mvn
    from ..sources.publish import parse_udp_url

    address = parse_udp_url(args.to, what="--to")
    if args.rate is not None and not args.rate > 1:
        raise ConfigError(f"--rate must be above 1 Hz, got {args.rate}.")
    if not args.speed > 0:
        raise ConfigError(f"--speed must be positive, got {args.speed}.")
    t, P, Q, rate = _clip_poses(args)
    datagrams = [
        mvn.encode_pose(k, int(round(1000.0 * t[k])), P[k], Q[k], units=args.units)
        for k in range(len(t))
    ]
    sender = _Sender(args, address, t, P, Q, rate)
    wall = sender.play(datagrams)
    if not args.quiet:
        print(
            f"sent {sender.sent} datagrams ({len(datagrams)} samples x {sender.loop or 1}) to "
            f"udp://{address[0]}:{address[1]} at {rate:g} Hz in {wall:.2f} s"
            + (f", paused {args.pause:g} s" if sender.paused else ""),
            file=sys.stderr,
        )
    return 0


def _clip_poses(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``(t, P, Q, rate)``: the clip's MVN segment poses at the sending rate, ``t`` from 0."""
    from ..motion import MotionError, load_motion
    from ..sources import mvn

    try:
        motion = load_motion(args.motion)
    except (FileNotFoundError, ValueError) as exc:
        if isinstance(exc, MotionError):
            raise
        raise MotionError(str(exc)) from None
    if args.start is not None or args.end is not None:
        motion = motion.slice(args.start or 0.0, args.end)
    P, Q = mvn.segment_poses(motion, args.keypoint_map)
    rate = float(args.rate or motion.rate)
    t, P, Q = resample_poses(motion.t - motion.t[0], P, Q, rate)
    return t, P, Q, rate


class _Sender:
    """Sends the datagrams at real-time pace (``--speed``), with the fault options applied.

    ``sent`` counts the datagrams sent, ``loop`` the passes over the clip completed, ``paused``
    says whether ``--pause-at`` held samples back.
    """

    def __init__(
        self,
        args: argparse.Namespace,
        address: tuple[str, int],
        t: np.ndarray,
        P: np.ndarray,
        Q: np.ndarray,
        rate: float,
    ) -> None:
        self.args, self.address, self.t, self.P, self.Q, self.rate = args, address, t, P, Q, rate
        self.faults: dict[str, Any] = {
            name: _ints(getattr(args, name)) for name in ("drop", "duplicate", "swap", "malformed")
        }
        self.sent = 0
        self.loop = 0
        self.paused = False

    def play(self, datagrams: list[bytes]) -> float:
        """Send every pass (one, or until Ctrl-C with ``--loop``); the wall time [s]."""
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if self.args.delay > 0:
            time.sleep(self.args.delay)
        t0 = time.perf_counter()
        try:
            while True:
                self._one_pass(datagrams, t0)
                self.loop += 1
                if not self.args.loop:
                    break
        except KeyboardInterrupt:
            pass
        finally:
            self.sock.close()
        return time.perf_counter() - t0

    def _one_pass(self, datagrams: list[bytes], t0: float) -> None:
        """Send the clip once, each sample at its time; pass ``loop`` renumbers the samples."""
        from ..sources.mvn import encode_pose

        args, faults, period, rate = self.args, self.faults, len(datagrams), self.rate
        held_back: bytes | None = None
        for k, data in enumerate(datagrams):
            seq = k + self.loop * period
            if self.loop:
                data = encode_pose(
                    seq, int(round(1000.0 * (self.t[k] + self.loop * period / rate))),
                    self.P[k], self.Q[k], units=args.units,
                )  # fmt: skip
            due = t0 + seq / (rate * args.speed)
            delay = due - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            if self._withheld(seq):
                continue
            if seq in faults["swap"] and held_back is None:
                held_back = data
                continue
            self._send(data)
            if held_back is not None:
                self._send(held_back)
                held_back = None
            if seq in faults["duplicate"]:
                self._send(data)
            if seq in faults["malformed"]:
                self._send(data[: len(data) // 2])  # truncated
                self._send(b"MXTP02" + bytes(40))  # size field disagrees

    def _withheld(self, seq: int) -> bool:
        """Sample ``seq`` falls in the ``--pause`` or is dropped (``--drop``)."""
        args = self.args
        tk = seq / self.rate
        if args.pause_at is not None and args.pause_at <= tk < args.pause_at + args.pause:
            self.paused = True
            return True
        return seq in self.faults["drop"]

    def _send(self, data: bytes) -> None:
        """Send one datagram."""
        self.sock.sendto(data, self.address)
        self.sent += 1
