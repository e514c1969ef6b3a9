# SPDX-License-Identifier: Apache-2.0
r"""Where the live commands go: a Python callback, UDP datagrams, the browser viewer.

A publisher is any callable taking a :class:`LiveCommand` (the live viewer of
:class:`qpretarget.viz.viewer.LiveViewer` is one: it reads ``.q``). :class:`UdpPublisher` sends one
datagram per command to ``udp://HOST:PORT``, binary or JSON.

Binary layout (``format="binary"``, little-endian, :data:`COMMAND_HEADER` then two arrays)::

    offset size type     field
     0      4   char[4]  magic "QPRC"
     4      1   uint8    layout version (1)
     5      1   uint8    status flags (:data:`STATUS_FLAGS`)
     6      2   uint16   nq
     8      2   uint16   nv
    10      2   uint16   reserved (0)
    12      4   uint32   tick (0, 1, 2, ... one per control period)
    16      8   float64  t: time of the tick on the stream's clock [s]
    24      8   float64  sent: wall-clock time the datagram was sent [s since the epoch]
    32   8*nq   float64  q: configuration (pinocchio order: free-flyer x y z qx qy qz qw, joints)
    32+8nq 8*nv float64  v: velocity applied during the tick

JSON layout (``format="json"``): one UTF-8 object per datagram,
``{"tick", "t", "sent", "q": [...], "v": [...], "status", "input", "flags"}``.
"""

from __future__ import annotations

import json
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlparse

import numpy as np

from ..errors import ConfigError

COMMAND_MAGIC = b"QPRC"
COMMAND_VERSION = 1
COMMAND_HEADER = struct.Struct("<4sBBHHHIdd")  # 32 bytes

#: Bits of the status byte.
STATUS_FLAGS = {
    "relaxed": 1,  # a hard constraint gave this tick (controller status "relaxed")
    "controller_held": 2,  # no usable QP solution: the robot holds (controller status "held")
    "interpolated": 4,  # input filled in for a lost datagram (between received frames)
    "extrapolated": 8,  # input extrapolated one frame past the last datagram (late stream)
    "held": 16,  # input held: the stream stopped (after one extrapolated frame)
    "resume": 32,  # input blending back into the stream after a hold
    "deadline": 64,  # the command left later than the tick's time budget after its datagram
}

#: Input kinds of a command (what fed the tick that made it).
INPUT_KINDS = ("live", "interpolated", "extrapolated", "held", "resume")


@dataclass
class LiveCommand:
    """One published control tick.

    Attributes:
        tick: Tick number (0, 1, ...; one per control period of the stream's clock).
        t: Time of the tick on the stream's clock [s].
        q: Configuration (nq,).
        v: Velocity applied during the tick (nv,).
        status: The controller's status (``ok``, ``relaxed``, ``held``).
        input: What fed it (:data:`INPUT_KINDS`).
        deadline_miss: It was ready later than the budget after its datagram (or after the
            moment a missing frame was filled in).
        ready_time: Wall-clock time it was ready to publish [s].
        result: The controller's step result (or ``None``).
    """

    tick: int
    t: float
    q: np.ndarray
    v: np.ndarray
    status: str
    input: str
    deadline_miss: bool
    ready_time: float
    result: Any = None

    @property
    def flags(self) -> int:
        """The status byte of the binary layout."""
        f = 0
        if self.status == "relaxed":
            f |= STATUS_FLAGS["relaxed"]
        elif self.status == "held":
            f |= STATUS_FLAGS["controller_held"]
        if self.input != "live":
            f |= STATUS_FLAGS[self.input]
        if self.deadline_miss:
            f |= STATUS_FLAGS["deadline"]
        return f


Publisher = Callable[[LiveCommand], None]


def encode_command(cmd: LiveCommand, sent: float, fmt: str = "binary") -> bytes:
    """The datagram of one command (layouts in the module docstring)."""
    q = np.ascontiguousarray(cmd.q, dtype="<f8")
    v = np.ascontiguousarray(cmd.v, dtype="<f8")
    if fmt == "json":
        return json.dumps(
            {
                "tick": cmd.tick,
                "t": cmd.t,
                "sent": sent,
                "q": q.tolist(),
                "v": v.tolist(),
                "status": cmd.status,
                "input": cmd.input,
                "flags": cmd.flags,
            }  # fmt: skip
        ).encode()
    head = COMMAND_HEADER.pack(
        COMMAND_MAGIC, COMMAND_VERSION, cmd.flags, q.size, v.size, 0, cmd.tick & 0xFFFFFFFF,
        cmd.t, sent,
    )  # fmt: skip
    return head + q.tobytes() + v.tobytes()


def decode_command(data: bytes) -> dict[str, Any]:
    """Read a command datagram (either layout) back into a dict (for clients and tests).

    Raises:
        ValueError: Not a command datagram of this layout.
    """
    if data[:1] == b"{":
        out = json.loads(data)
        out["q"], out["v"] = np.asarray(out["q"]), np.asarray(out["v"])
        return dict(out)
    if len(data) < COMMAND_HEADER.size or data[:4] != COMMAND_MAGIC:
        raise ValueError("not a qpretarget command datagram (magic 'QPRC')")
    magic, ver, flags, nq, nv, _r, tick, t, sent = COMMAND_HEADER.unpack_from(data)
    if ver != COMMAND_VERSION or len(data) != COMMAND_HEADER.size + 8 * (nq + nv):
        raise ValueError(f"command datagram of version {ver} and {len(data)} bytes is malformed")
    arr = np.frombuffer(data, dtype="<f8", offset=COMMAND_HEADER.size)
    return {"tick": tick, "t": t, "sent": sent, "flags": flags, "q": arr[:nq].copy(),
            "v": arr[nq:].copy()}  # fmt: skip


class UdpPublisher:
    """Send each command as one UDP datagram to ``udp://HOST:PORT``.

    Args:
        url: ``udp://HOST:PORT``.
        fmt: ``binary`` or ``json`` (module docstring).

    Raises:
        ConfigError: Not a ``udp://HOST:PORT`` address, or an unknown format.
    """

    def __init__(self, url: str, fmt: str = "binary") -> None:
        self.address = parse_udp_url(url, what="--publish")
        if fmt not in ("binary", "json"):
            raise ConfigError(f"--format must be binary or json, got {fmt!r}.")
        self.fmt = fmt
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0
        self.errors = 0

    def __call__(self, cmd: LiveCommand) -> None:
        """Send one command (a send error is counted, not raised: the loop must go on)."""
        try:
            self.sock.sendto(encode_command(cmd, time.time(), self.fmt), self.address)
            self.sent += 1
        except OSError:
            self.errors += 1

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


def parse_udp_url(url: str, *, what: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` -> ``(host, port)``.

    Raises:
        ConfigError: Another scheme, or no host or port.
    """
    u = urlparse(url)
    try:
        port = u.port
    except ValueError:
        port = None
    if u.scheme != "udp" or not u.hostname or port is None:
        raise ConfigError(
            f"{what}: expected udp://HOST:PORT, e.g. udp://127.0.0.1:9763, got {url!r}."
        )
    return u.hostname, port
