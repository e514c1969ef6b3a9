# SPDX-License-Identifier: Apache-2.0
"""``--source file:CLIP``: a BVH, ASF/AMC or C3D file played in real time, for demos and tests.

Frame ``k`` becomes available ``t_k - t_0`` seconds after :meth:`FileSource.open` (scaled by
``speed``); the frames carry the clip's own joint names, and the key-point map is the one the
clip's names call for (or ``keypoint_map``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError
from .base import Frame, Source, SourceError
from .registry import SOURCES


@SOURCES.register("file")
class FileSource(Source):
    """Play a motion file in real time.

    Args:
        path: The clip (``.bvh``, ``.amc`` with its ``.asf`` beside it, ``.c3d``).
        speed: Playback speed (1 = real time).
        start, end: Excerpt of the clip [s] (``end`` excluded).
        keypoint_map: Key-point map of the clip (``None``: guessed from its names).
    """

    def __init__(
        self,
        path: str,
        *,
        speed: float = 1.0,
        start: float | None = None,
        end: float | None = None,
        keypoint_map: Any = None,
    ) -> None:
        from ..motion import load_motion

        super().__init__()
        if not speed > 0:
            raise ConfigError(f"speed must be positive, got {speed!r}.")
        try:
            motion = load_motion(path)
        except FileNotFoundError as exc:
            raise SourceError(str(exc)) from None
        if start is not None or end is not None:
            motion = motion.slice(start or 0.0, end)
        self.motion = motion
        self.path, self.speed = str(path), float(speed)
        self.names = motion.names
        self.parents = motion.parents
        self.has_orientations = motion.orientations is not None
        self.keypoint_map = keypoint_map
        self._t0: float | None = None
        self._next = 0

    @classmethod
    def from_spec(cls, arg: str, options: Mapping[str, Any]) -> FileSource:
        """``file:PATH``; options ``speed``, ``start``, ``end``, ``keypoint_map``."""
        if not arg:
            raise ConfigError("--source file:PATH needs the clip, e.g. file:walk.bvh.")
        keys = ("speed", "start", "end", "keypoint_map")
        return cls(arg, **{k: options[k] for k in keys if options.get(k) is not None})

    @property
    def rate(self) -> float:
        """The clip's frame rate [Hz]."""
        return self.motion.rate

    def describe(self) -> str:
        """The file and its rate."""
        return f"{self.path} at {self.rate:g} Hz x {self.speed:g}"

    def open(self) -> None:
        """Start the clock: frame 0 is due now."""
        self._t0 = time.time()
        self._next = 0

    def close(self) -> None:
        """Nothing to release."""
        self._t0 = None

    @property
    def exhausted(self) -> bool:
        """Every frame has been played."""
        return self._next >= len(self.motion)

    def poll(self, timeout: float) -> list[Frame]:
        """The frames due by now, sleeping up to ``timeout`` [s] for the next one."""
        if self._t0 is None:
            raise SourceError("the source is not open; call open() first.")
        m = self.motion
        if self._next >= len(m):
            time.sleep(max(0.0, timeout))
            return []
        due = self._t0 + (float(m.t[self._next]) - float(m.t[0])) / self.speed
        now = time.time()
        if due > now:
            time.sleep(min(max(0.0, timeout), due - now))
        now = time.time()
        frames: list[Frame] = []
        while self._next < len(m):
            k = self._next
            due = self._t0 + (float(m.t[k]) - float(m.t[0])) / self.speed
            if due > now:
                break
            frames.append(
                Frame(
                    seq=k,
                    recv_time=now,
                    positions=m.positions[k],
                    orientations=None if m.orientations is None else m.orientations[k],
                    time_code=float(m.t[k]),
                )
            )
            self._next += 1
        return frames
