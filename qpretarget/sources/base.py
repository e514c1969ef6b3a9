# SPDX-License-Identifier: Apache-2.0
"""The interface every live source implements.

Frames come with a sample number, a receive time and named joint positions (and orientations).

A source is opened, polled for frames and closed. It knows its skeleton (joint names, parents,
whether frames carry orientations), the key-point map that fits it and its capture rate (which a
network source may only learn from its first frames). Bad input (malformed datagrams, other
message types) is counted in :attr:`Source.counts`, never raised.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import ConfigError, QPRetargetError


class SourceError(QPRetargetError, RuntimeError):
    """A source cannot be opened or read (port taken, file unreadable...)."""


@dataclass(frozen=True)
class Frame:
    """One captured sample.

    Attributes:
        seq: Sample number (MVN's sample counter; a file's frame index). Consecutive samples
            differ by one; gaps, repeats and reversals are the network's doing.
        recv_time: Wall-clock time it was received [s since the epoch] (the kernel's receive
            timestamp for UDP sources when the system gives one).
        positions: ``(J, 3)`` joint positions [m], z up.
        orientations: ``(J, 3, 3)`` joint orientations relative to the rest pose, or ``None``.
        time_code: The sender's own time stamp [s], if any.
    """

    seq: int
    recv_time: float
    positions: np.ndarray
    orientations: np.ndarray | None = None
    time_code: float | None = None


class Source(ABC):
    """A live motion source (see the module docstring).

    Attributes:
        type_name: Registered name (``xsens``, ``file``), set by the registry.
        names: Joint names of the frames.
        parents: Parent index of each joint (-1 for roots).
        has_orientations: Whether frames carry orientations.
        keypoint_map: Key-point map that fits :attr:`names` (bundled name), or ``None`` to guess.
        counts: Problems seen at the source: ``malformed`` (counted and skipped), ``ignored``
            (well-formed but not pose data of our character).
    """

    type_name: ClassVar[str] = ""
    names: tuple[str, ...]
    parents: tuple[int, ...]
    has_orientations: bool
    keypoint_map: Any

    def __init__(self) -> None:
        self.counts: dict[str, int] = {"malformed": 0, "ignored": 0}

    @classmethod
    @abstractmethod
    def from_spec(cls, arg: str, options: Mapping[str, Any]) -> Source:
        """Build the source from ``--source NAME:ARG``'s ``ARG`` and options.

        Options are ``host``, ``capture_rate``, ``units``...; a source ignores the ones it has no
        use for.

        Raises:
            ConfigError: A bad argument, with the expected form.
        """

    @property
    @abstractmethod
    def rate(self) -> float | None:
        """Capture rate [Hz], or ``None`` while a network source has not measured it yet."""

    @abstractmethod
    def open(self) -> None:
        """Start receiving (bind the socket, start the clock).

        Raises:
            SourceError: It cannot be opened (the message says why and what to do).
        """

    @abstractmethod
    def poll(self, timeout: float) -> list[Frame]:
        """Frames received since the last call, waiting at most ``timeout`` [s] for the first."""

    @abstractmethod
    def close(self) -> None:
        """Stop receiving; safe to call twice."""

    def describe(self) -> str:
        """One line saying what the source listens to or plays."""
        return self.type_name

    @property
    def exhausted(self) -> bool:
        """True when a finite source (a file) has sent its last frame."""
        return False

    def __enter__(self) -> Source:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_port(text: str, *, what: str) -> int:
    """A UDP port number from text.

    Raises:
        ConfigError: Not an integer in 0..65535.
    """
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise ConfigError(f"{what}: port must be an integer in 0..65535, got {text!r}.")
    return port
