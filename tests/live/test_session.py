# SPDX-License-Identifier: Apache-2.0
"""LiveSession's input logic on synthetic frames (unit tests: a recording stand-in for the
retargeter and a hand-driven clock): lost, duplicated, reordered, late datagrams, a 2-second
pause, a sender whose counter restarts. The real robot is in test_udp.py."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from qpretarget.sources import Frame, LiveSession, Source
from qpretarget.sources.mvn import quat_to_matrix

RATE = 100.0
P = 1.0 / RATE


class FakeSource(Source):
    type_name = "fake"

    def __init__(self) -> None:
        super().__init__()
        self.names, self.parents, self.has_orientations = ("a", "b"), (-1, 0), True
        self.keypoint_map = None

    @classmethod
    def from_spec(cls, arg: str, options: Any) -> FakeSource:
        return cls()

    @property
    def rate(self) -> float:
        return RATE

    def open(self) -> None:
        pass

    def poll(self, timeout: float) -> list[Frame]:
        return []

    def close(self) -> None:
        pass


class Recorder:
    """Stands in for the Retargeter: records every pushed frame, one command per push."""

    dt = 0.01
    keypoint_map = None

    def __init__(self) -> None:
        self.pushed: list[tuple[float, np.ndarray, np.ndarray]] = []

    def start(self, skeleton: Any, keypoint_map: Any = None, record: bool = True) -> None:
        self.skeleton = skeleton
        self.record = record

    def push(self, pos: np.ndarray, t: float, *, orientations: np.ndarray) -> list[Any]:
        self.pushed.append((t, np.array(pos), np.array(orientations)))
        return [SimpleNamespace(t=t, q=pos.ravel(), v=np.zeros(1), status="ok", result=None)]


def pose(k: float) -> tuple[np.ndarray, np.ndarray]:
    """A joint moving at 1 m/s along x and turning at 1 rad/s about z (exactly linear)."""
    x = np.array([[k * P, 0.0, 1.0], [k * P, 0.2, 1.0]])
    a = 0.5 * k * P
    R = quat_to_matrix(np.array([[np.cos(a), 0, 0, np.sin(a)]] * 2))
    return x, R


def frame(seq: int, recv: float) -> Frame:
    x, R = pose(seq)
    return Frame(seq, recv, x, R)


def session() -> tuple[LiveSession, Recorder]:
    rec = Recorder()
    s = LiveSession(rec, FakeSource(), max_wait=0.025, resume_time=0.1, clock=lambda: 0.0)
    return s, rec


def deliver(
    s: LiveSession, seqs: list[int], t0: float = 0.0, *, at: dict[int, float] | None = None
) -> None:
    at = at or {}
    for k in seqs:
        now = at.get(k, t0 + k * P)
        s.feed([frame(k, now)])
        s.advance(now)


def pushed_x(rec: Recorder) -> np.ndarray:
    return np.array([p[1][0, 0] for p in rec.pushed])


def test_in_order_frames_are_pushed_as_they_are() -> None:
    s, rec = session()
    deliver(s, list(range(10)))
    assert [p[0] for p in rec.pushed] == [j / RATE for j in range(10)]
    np.testing.assert_array_equal(pushed_x(rec), np.arange(10) * P)
    c = s.counts
    assert c["pushed"] == c["ticks"] == 10 and c["lost"] == c["held_frames"] == 0


def test_lost_datagram_is_filled_between_its_neighbours() -> None:
    s, rec = session()
    deliver(s, [0, 1, 2, 3, 4, 6])
    assert len(rec.pushed) == 5  # 6 waits for 5 until 5's deadline
    s.advance(5 * P + 0.025)
    assert s.counts["lost"] == 1 and len(rec.pushed) == 7
    # The motion is linear: the filled-in frame is exactly the missing one (1e-12: slerp).
    np.testing.assert_allclose(rec.pushed[5][1], pose(5)[0], atol=1e-12)
    np.testing.assert_allclose(rec.pushed[5][2], pose(5)[1], atol=1e-12)


def test_duplicates_and_reordered_datagrams() -> None:
    s, rec = session()
    deliver(s, [0, 1, 2, 2, 4, 3, 5], at={4: 3 * P + 0.001})
    assert s.counts["duplicates"] == 1 and s.counts["reordered"] == 1
    np.testing.assert_array_equal(pushed_x(rec), np.arange(6) * P)


def test_late_datagram_extrapolates_one_frame_then_resumes() -> None:
    s, rec = session()
    deliver(s, [0, 1, 2, 3, 4])
    s.advance(5 * P + 0.026)  # 5 is overdue: extrapolated at constant velocity
    assert s.counts["extrapolated"] == 1
    np.testing.assert_allclose(rec.pushed[5][1], pose(5)[0], atol=1e-12)
    np.testing.assert_allclose(rec.pushed[5][2], pose(5)[1], atol=1e-12)
    deliver(s, [5], at={5: 0.08})  # its slot was filled: late, dropped
    assert s.counts["late"] == 1 and len(rec.pushed) == 6
    deliver(s, [6, 7], at={6: 0.081, 7: 0.082})
    assert s.counts["resumes"] == 1 and len(rec.pushed) == 8


def test_two_second_pause_holds_then_blends_back() -> None:
    s, rec = session()
    deliver(s, list(range(20)))
    now = 19 * P
    while now < 19 * P + 2.0:  # the stream pauses for 2 s; the loop keeps polling
        now += 0.001
        s.advance(now)
    c = s.counts
    assert c["extrapolated"] == 1
    assert 190 <= c["held_frames"] <= 200  # one per capture period
    held = pushed_x(rec)[21:]
    assert np.all(held == held[0])  # held: the same frame again
    times = [p[0] for p in rec.pushed]
    np.testing.assert_allclose(np.diff(times), P, rtol=1e-9)  # no gap in the input clock
    # The sender resumes 2 s later (its counter went on): blend back, no jump.
    n0 = len(rec.pushed)
    first = 220
    deliver(s, list(range(first, first + 30)), t0=now - first * P)
    assert c["resumes"] == 1 and c["lost"] == first - (
        19 + 1 + c["extrapolated"] + c["held_frames"]
    )
    x = pushed_x(rec)[n0 - 1 :]
    jump = (pose(first)[0][0, 0] - x[0]) / 10  # the gap spread over resume_time (10 frames)
    assert np.max(np.abs(np.diff(x))) <= 1.875 * jump + P  # minimum-jerk peak slope + motion
    assert x[-1] == pose(first + 29)[0][0, 0]  # and then the stream itself


def test_counter_restart_after_a_hold_is_followed() -> None:
    s, rec = session()
    deliver(s, list(range(10)))
    for k in range(50):
        s.advance(9 * P + 0.03 + k * P)
    held = len(rec.pushed)
    deliver(s, [0, 1, 2], t0=1.0)  # the sender restarted its sample counter
    assert s.counts["resyncs"] == 1 and len(rec.pushed) == held + 3


@pytest.mark.parametrize("bad", [{"budget": 0.0}, {"max_wait": -1.0}, {"resume_time": -0.1}])
def test_bad_settings_are_refused(bad: dict[str, float]) -> None:
    from qpretarget.errors import ConfigError

    with pytest.raises(ConfigError):
        LiveSession(Recorder(), FakeSource(), **bad)


def test_a_backlog_older_than_max_lag_is_skipped() -> None:
    s, rec = session()
    s.max_lag = 0.05
    deliver(s, list(range(5)))
    # The loop stalled: samples 5..19 all arrived meanwhile, the oldest 0.15 s ago.
    s.feed([frame(k, k * P) for k in range(5, 20)])
    s.advance(0.2)
    assert s.counts["skipped"] == 14 and s.counts["resumes"] == 0
    assert len(rec.pushed) == 6  # straight to the newest, blending into it
    x = pushed_x(rec)
    assert x[4] < x[5] < pose(19)[0][0, 0]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_network_keeps_the_input_regular(seed: int) -> None:
    """Drops, duplicates, swaps, jitter, a sender clock 0.05 % slow and two pauses: every pushed
    frame sits on the regular input clock, no sample is pushed twice, the counts add up."""
    rng = np.random.default_rng(seed)
    s, rec = session()
    events: list[tuple[float, int]] = []
    pauses = [(rng.uniform(0.5, 1.0), 0.3), (rng.uniform(1.5, 2.0), 1.0)]
    for k in range(400):
        t = k * P * 1.0005 + rng.uniform(0, 0.008)  # jitter under max_wait (25 ms)
        if any(a <= k * P < a + d for a, d in pauses) or rng.random() < 0.05:
            continue
        events.append((t, k))
        if rng.random() < 0.03:
            events.append((t + 0.001, k))
    for i in range(len(events) - 1):
        if rng.random() < 0.05:
            events[i], events[i + 1] = (
                (events[i][0], events[i + 1][1]),
                (events[i + 1][0], events[i][1]),
            )
    now, i = 0.0, 0
    while now < 4.5:
        now += 0.001
        batch = []
        while i < len(events) and events[i][0] <= now:
            batch.append(frame(events[i][1], events[i][0]))
            i += 1
        s.feed(batch)
        s.advance(now)
    c = s.counts
    times = np.array([p[0] for p in rec.pushed])
    np.testing.assert_array_equal(times, np.arange(len(times)) / RATE)
    kinds = s.arrays()["frame_kind"]
    seqs = s.arrays()["frame_seq"]
    real = seqs[seqs >= 0]
    assert len(np.unique(real)) == len(real)  # no sample pushed twice
    assert c["pushed"] == len(rec.pushed) == len(kinds)
    assert (kinds == "extrapolated").sum() == c["extrapolated"] >= 2  # one per pause at least
    assert (kinds == "held").sum() == c["held_frames"] and c["resumes"] >= 2
    assert (kinds == "interpolated").sum() <= c["lost"]
    assert c["frames"] == len(events)
    assert np.all(np.isfinite([p[1] for p in rec.pushed]))


def test_a_stalled_loop_does_not_replay_every_missed_hold() -> None:
    s, rec = session()
    s.max_lag = 0.05
    deliver(s, list(range(10)))
    s.advance(9 * P + 2.0)  # nothing came and the loop itself slept for 2 s
    assert len(rec.pushed) <= 12 and s.counts["skipped"] >= 190
    times = np.array([p[0] for p in rec.pushed])
    np.testing.assert_array_equal(times, np.arange(len(times)) / RATE)


@pytest.mark.parametrize("record_run", [True, False])
def test_the_retargeter_records_only_when_asked(record_run: bool) -> None:
    """``record_run`` is what the retargeter is started with (``--run``); ``record`` (``--record``)
    is the session's own record and does not need the retargeter's."""
    rec = Recorder()
    s = LiveSession(rec, FakeSource(), record=True, record_run=record_run, clock=lambda: 0.0)
    s.feed([frame(0, 0.0), frame(1, P)])
    s.advance(P)
    assert rec.record is record_run
    assert len(s.arrays()["frame_t"]) == 2
