# SPDX-License-Identifier: Apache-2.0
r"""A live run: frames from a source, the online retargeter, commands to the publishers.

:class:`LiveSession` keeps the retargeter's input a regular stream at the capture rate whatever the
network does, and measures what it costs.

**Input frames.** Frame ``j`` pushed to :meth:`Retargeter.push` has time ``t_j = j / rate`` on the
stream's clock. It is the datagram with the expected sample number when that one is there. The
expected arrival of sample ``n`` is ``a_n = b + n / rate`` with ``b`` the lower envelope of
``recv_time - seq / rate`` (so network jitter only delays, never advances, the schedule); sample
``n`` is *missing* once the clock passes ``a_n + max_wait``. Then:

* a later sample is already there: ``n`` is **lost**; it is filled in between the last pushed
  frame and that sample (linear in positions, slerp in orientations);
* nothing later is there: the stream is **late**; the first missing frame is **extrapolated** at
  constant velocity (``2 x_{n-1} - x_{n-2}``, ``R_{n-1} R_{n-2}^T R_{n-1}``), every further one
  **held** (the last pushed frame again), one per capture period, so the controller keeps running
  and its filters settle smoothly instead of the robot freezing mid-motion;
* when datagrams come back after extrapolated or held frames, the input **resumes** at once from
  the first one there (the samples skipped count as lost), blending from the last pushed frame
  into the stream over ``resume_time`` (minimum-jerk weight :math:`w = s^3 (10 - 15 s + 6 s^2)`),
  so the targets never jump. A sender whose sample counter restarted (or went back) after a hold
  is followed from its new number (a *resync*).

**Falling behind.** When the oldest datagram waiting is older than ``max_lag`` (the loop was
slower than the stream: a slow tick, a loaded machine), the backlog is **skipped**: the input jumps
to the newest datagram and blends into it as after a hold, so latency stays bounded instead of
growing with the queue; a loop stalled past ``max_lag`` while nothing arrived fills only the slot
due now.

A datagram whose sample is already pushed is a **duplicate**; one that arrives after a higher
sample but in time is **reordered** (and used); one whose slot was already filled in is **late**
(dropped). Malformed datagrams are counted by the source.

**Latency and deadlines.** A command's latency is the time from the receipt of the datagram that
made it computable (the kernel's receive time stamp where available) to the moment the command
has been handed to every publisher (for a filled-in frame, from the moment it was filled in).
Each tick has a time budget (default: the control period); a command whose latency exceeds it is
a **deadline miss**. :func:`latency_stats` is the one definition of the figures (median, p95, p99
in ms), shared by the command line, the benchmark and the tests.

With no datagram lost, reordered or late, the commands are those of the offline causal run on the
same frames (``Retargeter.retarget(motion, causal=True)``): the same code, fed the same numbers.
"""

from __future__ import annotations

import array
import collections
import math
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from .base import Frame, Source
from .mvn import matrix_to_quat, quat_to_matrix
from .publish import INPUT_KINDS, LiveCommand

#: Counters of a live run (see the module docstring).
COUNTERS = (
    "frames", "pushed", "lost", "duplicates", "reordered", "late", "extrapolated", "held_frames",
    "resumes", "resyncs", "skipped", "ticks", "held_ticks", "deadline_misses",
)  # fmt: skip


def latency_stats(latency_s: Sequence[float] | np.ndarray) -> dict[str, float]:
    """Median, p95, p99 and max of latencies, in milliseconds (NaN entries ignored).

    Returns:
        ``{"n", "median_ms", "p95_ms", "p99_ms", "max_ms"}`` (NaN figures when empty).
    """
    a = np.asarray(latency_s, float)
    a = a[np.isfinite(a)] * 1e3
    if a.size == 0:
        return {"n": 0, "median_ms": math.nan, "p95_ms": math.nan, "p99_ms": math.nan,
                "max_ms": math.nan}  # fmt: skip
    return {
        "n": int(a.size),
        "median_ms": float(np.median(a)),
        "p95_ms": float(np.percentile(a, 95)),
        "p99_ms": float(np.percentile(a, 99)),
        "max_ms": float(a.max()),
    }


def _slerp(R0: np.ndarray, R1: np.ndarray, w: float) -> np.ndarray:
    """Per-joint slerp between ``(J, 3, 3)`` rotation stacks (NaN where either is NaN)."""
    q0, q1 = matrix_to_quat(R0), matrix_to_quat(R1)
    d = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d).clip(max=1.0)
    theta = np.arccos(d)
    s = np.sin(theta)
    small = s < 1e-9
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / np.where(small, 1.0, s))
    b = np.where(small, w, np.sin(w * theta) / np.where(small, 1.0, s))
    return quat_to_matrix(a * q0 + b * q1)


def set_realtime(priority: int = 50) -> None:
    """Run this process under the real-time FIFO scheduler (Linux), as a robot's control loop.

    A datagram then wakes the loop at once and a tick is not preempted by ordinary processes
    (the kernel still keeps 5 % of each second for them). Child processes (the viewer) keep the
    ordinary scheduler.

    Raises:
        ConfigError: Not Linux, a priority outside 1..99, or no permission (the message says how
            to get it).
    """
    import os

    if not hasattr(os, "sched_setscheduler"):
        raise ConfigError("--realtime needs Linux's real-time scheduler (os.sched_setscheduler).")
    if not 1 <= int(priority) <= 99:
        raise ConfigError(f"real-time priority must be in 1..99, got {priority!r}.")
    try:
        # Processes started from here (the viewer) keep the ordinary scheduler.
        policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
        os.sched_setscheduler(0, policy, os.sched_param(int(priority)))
    except PermissionError:
        raise ConfigError(
            "--realtime is not permitted for this user: run as root, give Python the capability "
            "(sudo setcap cap_sys_nice+ep $(readlink -f $(which python))) or allow it an rtprio "
            "in /etc/security/limits.conf."
        ) from None


class LiveSession:
    """Run the online retargeter on a live source (see the module docstring).

    Args:
        retargeter: A :class:`~qpretarget.retarget.Retargeter` (its controller config gives the
            control rate and the tasks).
        source: The :class:`~qpretarget.sources.base.Source` (opened by :meth:`run`).
        publishers: Callables taking each :class:`~qpretarget.sources.publish.LiveCommand`.
        budget: Time budget per tick [s] (default: the control period).
        max_wait: How long after its expected arrival a sample is declared missing [s]
            (default: two capture periods).
        resume_time: Blend time back into the stream after a hold [s].
        max_lag: Age of the oldest waiting datagram beyond which the backlog is skipped [s].
        record: Keep every command and pushed frame for :meth:`save` (``--record``; about
            0.3 MB per second on G1 with MVN frames, held until the run stops).
        record_run: Start the retargeter recording its run, for its
            :meth:`~qpretarget.retarget.Retargeter.trajectory` (``--run``; about 8 kB per
            capture frame). ``False`` keeps the retargeter's memory flat over hours.
        keypoint_map: Key-point map of the source's joints (default: the source's, else guessed).
        clock: Wall clock [s] (tests pass a fake one).

    Raises:
        ConfigError: A non-positive budget, wait or resume time.
    """

    def __init__(
        self,
        retargeter: Any,
        source: Source,
        *,
        publishers: Iterable[Callable[[LiveCommand], None]] = (),
        budget: float | None = None,
        max_wait: float | None = None,
        resume_time: float = 0.3,
        max_lag: float = 0.1,
        record: bool = True,
        record_run: bool = True,
        keypoint_map: Any = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        for name, value in (("budget", budget), ("max_wait", max_wait), ("max_lag", max_lag)):
            if value is not None and not value > 0:
                raise ConfigError(f"{name} must be a positive time [s], got {value!r}.")
        if not resume_time >= 0:
            raise ConfigError(f"resume_time must be >= 0 [s], got {resume_time!r}.")
        self.retargeter = retargeter
        self.source = source
        self.publishers = list(publishers)
        self.control_dt = float(retargeter.dt)
        self.budget = float(budget) if budget is not None else self.control_dt
        self._max_wait = max_wait
        self.resume_time = float(resume_time)
        self.max_lag = float(max_lag)
        self._catch_up = False
        self.record = record
        self.record_run = bool(record_run)
        self.keypoint_map = keypoint_map
        self.clock = clock
        self.counts: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.started = False
        self.rate: float | None = None
        self._buffer: dict[int, Frame] = {}
        self._next_seq: int | None = None
        self._max_seen: int | None = None
        self._base = 0.0
        self._j = 0
        self._last: tuple[np.ndarray, np.ndarray | None] | None = None
        self._prev: tuple[np.ndarray, np.ndarray | None] | None = None
        self._synthetic_run = 0
        self._blend: tuple[int, tuple[np.ndarray, np.ndarray | None], int] | None = None
        self._recent_real: collections.OrderedDict[int, None] = collections.OrderedDict()
        self._overtaken: set[int] = set()
        self._status_mark: tuple[float, int] | None = None
        # Every tick's latency and step time (8 bytes each) for the exact percentiles of the
        # report: 5.8 MB per hour at 100 Hz, the only per-tick growth without the records.
        self._latency = array.array("d")
        self._step_time = array.array("d")
        #: Ticks per controller status (``ok``, ``relaxed``, ``held``).
        self.controller_status: dict[str, int] = {}
        self._rec: dict[str, list[Any]] = collections.defaultdict(list)
        self.t_open: float | None = None

    # ------------------------------------------------------------------------------ setup
    @property
    def max_wait(self) -> float:
        """Wait before a sample is declared missing [s]."""
        if self._max_wait is not None:
            return self._max_wait
        return 2.0 / self.rate if self.rate else 0.02

    def _start(self) -> None:
        from ..motion.human_motion import HumanMotion

        rate = self.source.rate
        assert rate is not None
        self.rate = float(rate)
        names = self.source.names
        J = len(names)
        skeleton = HumanMotion(
            t=np.zeros(1),
            names=names,
            positions=np.zeros((1, J, 3)),
            parents=self.source.parents,
            orientations=np.broadcast_to(np.eye(3), (1, J, 3, 3))
            if self.source.has_orientations
            else None,
            rate=self.rate,
            source=self.source.describe(),
        )
        # An explicit map, else the source's own (MVN's names are fixed), else the retargeter's.
        kmap = self.keypoint_map if self.keypoint_map is not None else self.source.keypoint_map
        self.retargeter.start(skeleton, keypoint_map=kmap, record=self.record_run)
        P = 1.0 / self.rate
        first = min(self._buffer)
        self._next_seq = first
        self._base = min(f.recv_time - f.seq * P for f in self._buffer.values())
        self.started = True

    # ------------------------------------------------------------------------------ run
    def run(
        self,
        *,
        duration: float | None = None,
        idle_exit: float | None = None,
        status: Callable[[LiveSession], None] | None = None,
        status_period: float = 1.0,
        on_open: Callable[[Source], None] | None = None,
        until: Callable[[], bool] | None = None,
    ) -> dict[str, Any]:
        """Open the source and run until stopped.

        It stops after ``duration`` [s], ``idle_exit`` [s] without a datagram, the end of a file
        source, or Ctrl-C (cleanly: the report and the record are complete).

        Args:
            duration: Wall time to run [s] (``None``: until stopped).
            idle_exit: Stop after this long without any datagram once the stream started.
            status: Called about every ``status_period`` seconds (the status line).
            status_period: Seconds between two ``status`` calls.
            on_open: Called once the source is open (a UDP source then knows its port).
            until: Stop when it returns true (after taking the datagrams already received).

        Returns:
            :meth:`report`.
        """
        import gc

        src = self.source
        src.open()
        self.t_open = self.clock()
        last_status = last_frame_time = self.t_open
        try:
            if on_open is not None:
                on_open(src)
            gc.collect()
            gc.freeze()  # the setup's objects leave the collector's generations: shorter pauses
            while True:
                now = self.clock()
                if duration is not None and now - self.t_open >= duration:
                    break
                if src.exhausted and not self._buffer:
                    break
                if idle_exit is not None and self.started and now - last_frame_time > idle_exit:
                    break
                if until is not None and until():
                    self.feed(src.poll(0.0))
                    self.advance(self.clock())
                    break
                timeout = 0.05
                due = self.next_deadline()
                if due is not None:
                    timeout = min(timeout, max(0.0, due - now))
                frames = src.poll(timeout)
                if frames:
                    last_frame_time = self.clock()
                self.feed(frames)
                self.advance(self.clock())
                if status is not None and self.clock() - last_status >= status_period:
                    last_status = self.clock()
                    status(self)
        except KeyboardInterrupt:
            pass
        finally:
            src.close()
            gc.unfreeze()
        return self.report()

    def next_deadline(self) -> float | None:
        """Wall time at which the expected sample is declared missing (``None`` before start)."""
        if not self.started or self._next_seq is None or self.rate is None:
            return None
        return self._base + self._next_seq / self.rate + self.max_wait

    # ------------------------------------------------------------------------------ frames
    def feed(self, frames: Iterable[Frame]) -> None:
        """Take received frames (classify duplicates, late and reordered ones; buffer the rest)."""
        for f in frames:
            self.counts["frames"] += 1
            seq = int(f.seq)
            if seq in self._buffer:
                self.counts["duplicates"] += 1
                continue
            if self.started and (seq in self._recent_real or seq < (self._next_seq or 0)):
                assert self.rate is not None
                if self._synthetic_run > 2:
                    # Holding, and the sender's counter went back: it restarted; follow it.
                    self.counts["resyncs"] += 1
                    self._buffer = {s: g for s, g in self._buffer.items() if s > seq}
                    self._recent_real.clear()
                    self._overtaken.clear()
                    self._max_seen = None
                    self._next_seq = seq
                    self._base = f.recv_time - seq / self.rate
                elif seq in self._recent_real:
                    self.counts["duplicates"] += 1
                    continue
                else:
                    self.counts["late"] += 1  # its slot was already filled in
                    continue
            if self._max_seen is not None and seq < self._max_seen:
                self._overtaken.add(seq)  # a later sample arrived first
            self._max_seen = seq if self._max_seen is None else max(self._max_seen, seq)
            self._buffer[seq] = f
        if not self.started and self._buffer:
            if self.source.rate is not None:
                self._start()
            elif len(self._buffer) > 1000:  # the rate cannot be measured: keep the newest
                for seq in sorted(self._buffer)[:-1000]:
                    del self._buffer[seq]

    def advance(self, now: float) -> None:
        """Push every frame that is due by ``now``: received ones, filled-in ones, held ones."""
        if not self.started:
            return
        assert self._next_seq is not None and self.rate is not None
        P = 1.0 / self.rate
        while True:
            n = self._next_seq
            oldest = min((g.recv_time for g in self._buffer.values()), default=math.inf)
            if max(now, self.clock()) - oldest > self.max_lag:
                # Behind the stream: skip the backlog, blend into the newest datagram.
                m = max(self._buffer)
                self.counts["skipped"] += m - n
                self._buffer = {m: self._buffer[m]}
                self._overtaken.clear()
                self._next_seq = n = m
                self._catch_up = self._last is not None
            f = self._buffer.pop(n, None)
            if f is not None:
                if n in self._overtaken:
                    self._overtaken.discard(n)
                    self.counts["reordered"] += 1
                self._base = min(self._base + 1e-3 * P, f.recv_time - n * P)  # clock drift < 0.1 %
                self._push_real(f)
                continue
            if self._buffer and self._synthetic_run > 0:
                # Datagrams are back after a hold: skip to the first one and blend into it.
                m = min(self._buffer)
                self.counts["lost"] += m - n
                self._next_seq = m
                continue
            deadline = self._base + n * P + self.max_wait
            if now < deadline:
                return
            overdue = int((now - deadline) * self.rate)
            if not self._buffer and now - deadline > self.max_lag and overdue > 0:
                # The loop itself was stalled past max_lag: fill only the slot due now.
                self.counts["skipped"] += overdue
                n += overdue
                deadline += overdue * P
            if self._buffer and self._last is not None:
                m = min(self._buffer)
                w = 1.0 / (m - n + 1)
                pos, rot = self._mix(self._last, (self._buffer[m].positions,
                                                  self._buffer[m].orientations), w)  # fmt: skip
                self.counts["lost"] += 1
                self._push(pos, rot, "interpolated", deadline, synthetic=False)
            elif self._prev is None:
                return  # fewer than two frames yet: nothing to extrapolate or hold, wait
            elif self._synthetic_run == 0:
                pos, rot = self._extrapolate()
                self.counts["extrapolated"] += 1
                self._push(pos, rot, "extrapolated", deadline, synthetic=True)
            else:
                assert self._last is not None
                pos, rot = self._last
                self.counts["held_frames"] += 1
                self._push(pos, rot, "held", deadline, synthetic=True)
            self._next_seq = n + 1

    def _push_real(self, f: Frame) -> None:
        n = int(f.seq)
        self._recent_real[n] = None
        while len(self._recent_real) > 4096:
            self._recent_real.popitem(last=False)
        pos = np.asarray(f.positions, float)
        rot = None if f.orientations is None else np.asarray(f.orientations, float)
        kind = "live"
        if (self._synthetic_run > 0 or self._catch_up) and self._last is not None:
            n_blend = max(1, round(self.resume_time * (self.rate or 1.0)))
            self._blend = (self._j, self._last, n_blend)
            if self._synthetic_run > 0:
                self.counts["resumes"] += 1
        self._catch_up = False
        if self._blend is not None:
            j0, origin, n_blend = self._blend
            s = (self._j - j0 + 1) / n_blend
            if s >= 1.0:
                self._blend = None
            else:
                w = s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
                pos, rot = self._mix(origin, (pos, rot), w)
                kind = "resume"
        self._next_seq = n + 1
        self._push(pos, rot, kind, f.recv_time, synthetic=False, frame=f)

    def _mix(
        self,
        a: tuple[np.ndarray, np.ndarray | None],
        b: tuple[np.ndarray, np.ndarray | None],
        w: float,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        pos = a[0] + w * (np.asarray(b[0], float) - a[0])
        if a[1] is None or b[1] is None:
            return pos, None
        return pos, _slerp(a[1], np.asarray(b[1], float), w)

    def _extrapolate(self) -> tuple[np.ndarray, np.ndarray | None]:
        assert self._last is not None and self._prev is not None
        (p1, R1), (p0, R0) = self._last, self._prev
        pos = 2.0 * p1 - p0
        rot = None if R1 is None or R0 is None else R1 @ np.swapaxes(R0, -1, -2) @ R1
        return pos, rot

    # ------------------------------------------------------------------------------ ticks
    def _push(
        self,
        pos: np.ndarray,
        rot: np.ndarray | None,
        kind: str,
        ref_time: float,
        *,
        synthetic: bool,
        frame: Frame | None = None,
    ) -> None:
        t = self._j / self.rate  # type: ignore[operator]
        self._j += 1
        self._prev, self._last = self._last, (pos, rot)
        self._synthetic_run = self._synthetic_run + 1 if synthetic else 0
        self.counts["pushed"] += 1
        if self.record:
            r = self._rec
            r["frame_t"].append(t)
            r["frame_seq"].append(-1 if frame is None else int(frame.seq))
            r["frame_kind"].append(kind)
            r["frame_recv"].append(ref_time)
            r["frame_positions"].append(np.array(pos, np.float64))
            if rot is not None:
                r["frame_orientations"].append(np.array(rot, np.float64))
        commands = self.retargeter.push(pos, t, orientations=rot)
        for c in commands:
            self._publish(c, kind, ref_time)

    def _publish(self, c: Any, kind: str, ref_time: float) -> None:
        ready = self.clock()
        miss = ready - ref_time > self.budget
        cmd = LiveCommand(
            tick=self.counts["ticks"], t=float(c.t), q=c.q, v=c.v, status=str(c.status),
            input=kind, deadline_miss=miss, ready_time=ready, result=getattr(c, "result", None),
        )  # fmt: skip
        for pub in self.publishers:
            pub(cmd)
        sent = self.clock()
        latency = sent - ref_time
        miss = latency > self.budget
        self.counts["ticks"] += 1
        if kind in ("extrapolated", "held"):
            self.counts["held_ticks"] += 1
        if miss:
            self.counts["deadline_misses"] += 1
        if kind == "live" or kind == "resume":
            self._latency.append(latency)
        self._step_time.append(getattr(cmd.result, "step_time", math.nan))
        self.controller_status[cmd.status] = self.controller_status.get(cmd.status, 0) + 1
        if self.record:
            r = self._rec
            res = cmd.result
            r["t"].append(cmd.t)
            r["q"].append(np.array(cmd.q))
            r["v"].append(np.array(cmd.v))
            r["status"].append(cmd.status)
            r["input"].append(kind)
            r["latency"].append(latency if kind in ("live", "resume") else math.nan)
            r["deadline_miss"].append(miss)
            r["step_time"].append(getattr(res, "step_time", math.nan))
            r["solve_time"].append(getattr(res, "solve_time", math.nan))
            r["iterations"].append(getattr(res, "iterations", -1))

    # ------------------------------------------------------------------------------ output
    def report(self) -> dict[str, Any]:
        """Counters, latency figures (:func:`latency_stats`), rates and the source's counts.

        ``controller_step`` has the same figures for the controller's own time per tick
        (``StepResult.step_time``), the part of the latency the QP tick takes.
        """
        wall = (self.clock() - self.t_open) if self.t_open is not None else 0.0
        return {
            "counts": dict(self.counts),
            "source": dict(self.source.counts),
            "latency": latency_stats(self._latency),
            "controller_step": latency_stats(self._step_time),
            "controller_status": dict(self.controller_status),
            "budget_ms": 1e3 * self.budget,
            "capture_rate": self.rate,
            "control_rate": 1.0 / self.control_dt,
            "wall_time": wall,
            "source_name": self.source.describe(),
        }

    def status_line(self) -> str:
        """The status line.

        Ticks/s since the last line, latency (last 1000 commands), deadline misses, frame
        problems, held ticks.
        """
        c, s = self.counts, self.source.counts
        lat = latency_stats(self._latency[-1000:])
        now = self.clock()
        t_prev, ticks_prev = self._status_mark or (self.t_open or now, 0)
        rate = (c["ticks"] - ticks_prev) / max(1e-9, now - t_prev)
        self._status_mark = (now, c["ticks"])
        wall = now - (self.t_open or now)
        if not self.started and c["frames"]:
            return (
                f"{wall:6.1f} s | {c['frames']} frames received, waiting for the capture rate "
                "(the time codes do not give it: pass --capture-rate)"
            )
        return (
            f"{wall:6.1f} s | {rate:6.1f} ticks/s | latency p50 {lat['median_ms']:.2f} "
            f"p99 {lat['p99_ms']:.2f} ms | misses {c['deadline_misses']} | frames {c['frames']} "
            f"lost {c['lost']} dup {c['duplicates']} late {c['late']} reord {c['reordered']} "
            f"bad {s.get('malformed', 0)} | held ticks {c['held_ticks']}"
        )

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded run as arrays (keys of docs/live.md, "Record")."""
        import json

        r = self._rec
        out: dict[str, np.ndarray] = {
            "t": np.asarray(r["t"], float),
            "tick": np.arange(len(r["t"])),
            "q": np.asarray(r["q"], float),
            "v": np.asarray(r["v"], float),
            "status": np.asarray(r["status"], dtype=str),
            "input": np.asarray(r["input"], dtype=str),
            "latency": np.asarray(r["latency"], float),
            "deadline_miss": np.asarray(r["deadline_miss"], bool),
            "step_time": np.asarray(r["step_time"], float),
            "solve_time": np.asarray(r["solve_time"], float),
            "iterations": np.asarray(r["iterations"], int),
            "frame_t": np.asarray(r["frame_t"], float),
            "frame_seq": np.asarray(r["frame_seq"], int),
            "frame_kind": np.asarray(r["frame_kind"], dtype=str),
            "frame_recv": np.asarray(r["frame_recv"], float),
            "frame_positions": np.asarray(r["frame_positions"], float),
            "joint_names": np.asarray(self.source.names, dtype=str),
            "report": np.asarray(json.dumps(self.report())),
        }
        if r["frame_orientations"]:
            out["frame_orientations"] = np.asarray(r["frame_orientations"], float)
        return out

    def save(self, path: str | Path) -> Path:
        """Write the record atomically to an ``.npz`` file (docs/live.md, "Record")."""
        from ..fileio import atomic_path

        path = Path(path)
        arrays = self.arrays()
        with atomic_path(path, suffix=".npz") as tmp:
            np.savez(tmp, **arrays)  # type: ignore[arg-type]
        return path


__all__ = ["COUNTERS", "INPUT_KINDS", "LiveSession", "latency_stats", "set_realtime"]
