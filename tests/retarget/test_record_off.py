# SPDX-License-Identifier: Apache-2.0
"""``Retargeter.start(..., record=False)``: the same commands, memory flat over a long stream.

Real robot (G1, configs/g1_whole_body.yaml: kinematic stepping), real mocap (the shared boxing
clip, played forward then backward in a loop so that the stream is long and continuous).
"""

from __future__ import annotations

import gc
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from qpretarget.control.controller import Controller
from qpretarget.motion import HumanMotion, load_motion
from qpretarget.retarget import Retargeter
from qpretarget.retarget.spec import RetargetError

REPO = Path(__file__).resolve().parents[2]
MOCAP = REPO.parent / "shared" / "data" / "mocap"


@pytest.fixture(scope="module")
def boxing() -> HumanMotion:
    return load_motion(MOCAP / "cmu_17_10_boxing.bvh")


def _retargeter() -> Retargeter:
    return Retargeter(Controller.from_yaml(REPO / "configs" / "g1_whole_body.yaml"))


class _Loop:
    """Frames of a clip forward then backward, forever, at the capture rate."""

    def __init__(self, motion: HumanMotion) -> None:
        self.m = motion
        n = len(motion)
        self.order = list(range(n)) + list(range(n - 2, 0, -1))
        self.j = 0

    def push(self, rt: Retargeter, n: int) -> list:
        out = []
        m = self.m
        assert m.orientations is not None
        for _ in range(n):
            k = self.order[self.j % len(self.order)]
            out += rt.push(m.positions[k], self.j / m.rate, orientations=m.orientations[k])
            self.j += 1
        return out


def test_commands_are_identical_with_and_without_recording(boxing):
    """Recording only copies what a tick computed: q, v, status, phase and support state of every
    command are equal to the last bit (no tolerance: the same code on the same numbers)."""
    on, off = _retargeter(), _retargeter()
    on.start(boxing, record=True)
    off.start(boxing, record=False)
    loop_on, loop_off = _Loop(boxing), _Loop(boxing)
    c_on = loop_on.push(on, 400) + on.finish()
    c_off = loop_off.push(off, 400) + off.finish()
    assert len(c_on) == len(c_off) > 300
    for a, b in zip(c_on, c_off, strict=True):
        assert a.t == b.t
        assert np.array_equal(a.q, b.q) and np.array_equal(a.v, b.v)
        assert (a.status, a.phase, a.support) == (b.status, b.phase, b.support)
    # The stepper switched states (the trimmed support log was exercised) ...
    assert len({c.support for c in c_on}) > 1
    assert len(on.trajectory().t) == len(c_on)
    # ... and without records trajectory() says how to get a run.
    with pytest.raises(RetargetError, match=r"without recording.*record=True.*--run"):
        off.trajectory()


def test_memory_stays_flat_without_recording(boxing):
    """2000 frames pushed after a warm-up grow the traced memory by less than 100 kB.

    Tolerance: 50 B per frame, below the smallest per-frame leak worth having (one numpy array is
    over 100 B with its header) and far below the 8.2 kB per frame kept when recording; the
    remaining wobble (measured within +-15 kB over 6000 frames) is numpy's small-block cache and
    the solver's work buffers. A garbage collection before each reading removes cycles not yet
    collected.
    """
    rt = _retargeter()
    rt.start(boxing, record=False)
    loop = _Loop(boxing)
    loop.push(rt, 300)  # calibration, ramp, first steps
    tracemalloc.start(1)
    try:
        loop.push(rt, 500)  # warm the allocator caches under tracing
        gc.collect()
        before = tracemalloc.get_traced_memory()[0]
        loop.push(rt, 2000)
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 100_000, f"{grown} B over 2000 frames ({grown / 2000:.1f} B per frame)"
