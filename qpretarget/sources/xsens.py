# SPDX-License-Identifier: Apache-2.0
"""``--source xsens[:PORT]``: Xsens MVN's network streamer over UDP (``MXTP02`` datagrams).

Binds ``127.0.0.1`` unless ``host`` says otherwise (``0.0.0.0`` to receive from another machine:
point MVN's Network Streamer at this computer's address and the port, docs/live.md). Decoding is
in :mod:`qpretarget.sources.mvn`; a datagram that does not decode is counted in
``counts["malformed"]`` and skipped; other message types and other characters in
``counts["ignored"]``.

The capture rate is not in the datagrams: give it (``capture_rate``), or it is measured from the
time codes (ms) of the first samples and snapped to MVN's usual rates when within 3 %.
"""

from __future__ import annotations

import contextlib
import select
import socket
import struct
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import ConfigError
from . import mvn
from .base import Frame, Source, SourceError, parse_port
from .registry import SOURCES

#: Rates MVN streams at [Hz]; a measured rate within 3 % of one of them is snapped to it.
MVN_RATES = (60.0, 100.0, 120.0, 240.0)

# Linux: kernel receive time stamps (SO_TIMESTAMPNS = SCM_TIMESTAMPNS = 35, struct timespec).
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("qq")


@SOURCES.register("xsens")
class XsensSource(Source):
    """Receive Xsens MVN pose datagrams (``MXTP02``) on a UDP port.

    Args:
        port: UDP port (MVN's default 9763; 0 picks a free one, see :attr:`port`).
        host: Address to bind (default ``127.0.0.1``: this computer only).
        capture_rate: The sender's sample rate [Hz]; ``None`` measures it.
        units: Position units the sender uses: ``"m"`` (MVN 2018+) or ``"cm"``.
        character: Character ID to follow (other characters are ignored).
    """

    def __init__(
        self,
        port: int = mvn.DEFAULT_PORT,
        *,
        host: str = "127.0.0.1",
        capture_rate: float | None = None,
        units: str = "m",
        character: int = 0,
    ) -> None:
        super().__init__()
        if units not in mvn.UNITS:
            raise ConfigError(f"units must be one of {', '.join(mvn.UNITS)}, got {units!r}.")
        if capture_rate is not None and not capture_rate > 1:
            raise ConfigError(f"capture rate must be above 1 Hz, got {capture_rate!r}.")
        self.port, self.host, self.units, self.character = int(port), host, units, int(character)
        self._rate = None if capture_rate is None else float(capture_rate)
        self.names = mvn.JOINT_NAMES
        self.parents = mvn.PARENTS
        self.has_orientations = True
        self.keypoint_map = mvn.KEYPOINT_MAP
        self.counts.update({"datagrams": 0})
        self.last_error = ""
        self._sock: socket.socket | None = None
        self._kernel_stamps = False
        self._assembler = mvn.PoseAssembler()
        self._first: tuple[int, int] | None = None  # (sample, time code) of the first sample

    @classmethod
    def from_spec(cls, arg: str, options: Mapping[str, Any]) -> XsensSource:
        """``xsens`` or ``xsens:PORT``.

        Options: ``host``, ``capture_rate``, ``units``, ``character``.
        """
        port = parse_port(arg, what="--source xsens:PORT") if arg else mvn.DEFAULT_PORT
        keys = ("host", "capture_rate", "units", "character")
        return cls(port, **{k: options[k] for k in keys if options.get(k) is not None})

    @property
    def rate(self) -> float | None:
        """Capture rate [Hz]: given, or measured from the first samples' time codes."""
        return self._rate

    def describe(self) -> str:
        """Where it listens."""
        return f"Xsens MVN MXTP02 on udp://{self.host}:{self.port}"

    def open(self) -> None:
        """Bind the UDP socket.

        Raises:
            SourceError: The address cannot be bound (port taken, bad host).
        """
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise SourceError(
                f"cannot listen on udp://{self.host}:{self.port}: {exc.strerror or exc}; pick "
                "another port (--source xsens:PORT) or stop the program using it."
            ) from None
        if sys.platform.startswith("linux"):
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._kernel_stamps = True
        sock.setblocking(False)
        self.port = sock.getsockname()[1]
        self._sock = sock

    def close(self) -> None:
        """Close the socket."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _recv(self) -> tuple[bytes, float] | None:
        assert self._sock is not None
        try:
            if self._kernel_stamps:
                data, anc, _flags, _addr = self._sock.recvmsg(65536, socket.CMSG_SPACE(16))
                stamp = None
                for level, kind, payload in anc:
                    if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                        sec, nsec = _TIMESPEC.unpack(payload[: _TIMESPEC.size])
                        stamp = sec + 1e-9 * nsec
                return data, stamp if stamp is not None else time.time()
            data = self._sock.recv(65536)
            return data, time.time()
        except (BlockingIOError, InterruptedError):
            return None

    def poll(self, timeout: float) -> list[Frame]:
        """Decode every datagram waiting (waiting up to ``timeout`` [s] for the first)."""
        if self._sock is None:
            raise SourceError("the source is not open; call open() first.")
        frames: list[Frame] = []
        ready, _, _ = select.select([self._sock], [], [], max(0.0, timeout))
        if not ready:
            return frames
        while True:
            got = self._recv()
            if got is None:
                break
            data, stamp = got
            self.counts["datagrams"] += 1
            frame = self.decode(data, stamp)
            if frame is not None:
                frames.append(frame)
        return frames

    def decode(self, data: bytes, recv_time: float) -> Frame | None:
        """One datagram -> a :class:`Frame` when it completes a sample, else ``None``.

        Malformed datagrams count in ``counts["malformed"]`` (the reason in :attr:`last_error`);
        other message types and characters in ``counts["ignored"]``.
        """
        try:
            header = mvn.parse_header(data)
            if header.message_type != "02" or header.character_id != self.character:
                self.counts["ignored"] += 1
                return None
            pose = mvn.decode_pose(data, units=self.units)
        except mvn.MxtpError as exc:
            self.counts["malformed"] += 1
            self.last_error = str(exc)
            return None
        done = self._assembler.add(pose)
        if done is None:
            return None
        p, q = done
        h = pose.header
        self._measure_rate(h.sample_counter, h.time_code)
        return Frame(
            seq=h.sample_counter,
            recv_time=recv_time,
            positions=p,
            orientations=mvn.quat_to_matrix(q),
            time_code=1e-3 * h.time_code,
        )

    def _measure_rate(self, sample: int, time_code: int) -> None:
        if self._rate is not None:
            return
        if self._first is None:
            self._first = (sample, time_code)
            return
        ds, dt_ms = sample - self._first[0], time_code - self._first[1]
        if ds < 8 or dt_ms <= 0:
            return
        rate = 1000.0 * ds / dt_ms
        snap = min(MVN_RATES, key=lambda r: abs(r - rate))
        self._rate = snap if abs(snap - rate) <= 0.03 * snap else float(np.round(rate, 1))
