# SPDX-License-Identifier: Apache-2.0
"""Time modulation for velocity limits (Dariush 2009 eq. 15-16), on the G1 benchmark trajectory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpretarget import load_robot
from qpretarget.retarget.timing import (
    TimingError,
    blend_factors,
    expand_time,
    modulation_factors,
    preserve_duration,
    resample,
    retime,
)

BENCH = Path(__file__).resolve().parents[1] / ".." / "shared" / "bench" / "targets_g1.npz"
SPEEDUP = 40.0  # 1 s of the reference played 40x faster: about twice the URDF velocity limits


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


@pytest.fixture(scope="module")
def fast_motion():
    """The benchmark's G1 trajectory (joint speeds <= 5.1 % of the limits), partly sped up.

    Samples 100-200 are replayed 40x faster (too fast), the others at the original speed
    (room to compress for the time-preserving variant).
    """
    data = np.load(BENCH)
    dt = np.diff(data["t"][:401])
    dt[100:200] /= SPEEDUP
    t = np.concatenate([[0.0], np.cumsum(dt)])
    return t, data["q_ref"][:401]


def interval_ratio(g1, t, q):
    """Largest |v| / v_max over the intervals, velocities on the manifold."""
    dq = np.array([g1.difference(q[s], q[s + 1]) for s in range(len(t) - 1)])
    return np.max(np.abs(dq) / np.diff(t)[:, None] / g1.v_max)


@pytest.mark.parametrize("blend_time", [0.0, 0.05])
@pytest.mark.parametrize("mode", ["expand", "preserve"])
def test_retimed_trajectory_respects_every_velocity_limit(g1, fast_motion, mode, blend_time):
    t, q = fast_motion
    assert interval_ratio(g1, t, q) > 1.5  # the motion is too fast before retiming
    t2, q2 = retime(t, q, robot=g1, mode=mode, blend_time=blend_time)
    # Round-off only: Delta t' >= Delta t * eps_s exactly in real numbers.
    assert interval_ratio(g1, t2, q2) <= 1.0 + 1e-9
    # Same configurations, same order: q untouched, times strictly increasing from t[0].
    assert np.array_equal(q2, q)
    assert t2[0] == t[0] and np.all(np.diff(t2) > 0)
    if mode == "preserve":
        dt = 0.01
        assert abs(t2[-1] - t[-1]) < dt  # total duration kept to one tick
        assert abs(t2[-1] - t[-1]) < 1e-9  # in fact to round-off (bisection on c)
    else:
        assert t2[-1] > t[-1]


def test_expand_is_eq_16_literally(fast_motion, g1):
    t, q = fast_motion
    eps = modulation_factors(t, q, robot=g1)
    t_ref = [t[0]]
    for s in range(len(t) - 1):  # eq. 16, sample by sample
        step = (t[s + 1] - t[s]) * (eps[s] if eps[s] >= 1 else 1.0)
        t_ref.append(t_ref[-1] + step)
    assert np.allclose(expand_time(t, q, robot=g1), t_ref, rtol=0, atol=1e-12)


def test_blending_smooths_without_going_below(fast_motion, g1):
    t, q = fast_motion
    raw = np.maximum(modulation_factors(t, q, robot=g1), 1.0)
    smooth = blend_factors(raw, t, 0.05)
    assert np.all(smooth >= raw)
    # Smoother: the largest jump between consecutive factors shrinks.
    assert np.max(np.abs(np.diff(smooth))) < 0.5 * np.max(np.abs(np.diff(raw)))


def test_plain_arrays_and_resampling_on_the_tick_grid():
    t = np.linspace(0.0, 1.0, 101)
    q = np.stack([np.sin(6 * t), 0.2 * t], axis=1)
    v_max = np.array([4.5, 1.0])  # |6 cos 6t| exceeds 4.5 on about half of the samples
    t2 = preserve_duration(t, q, v_max)
    tg, qg = resample(t2, q, 0.01)
    # One tick of tolerance on the duration: the grid has the same number of samples (+-1).
    assert abs(len(tg) - len(t)) <= 1
    v = np.abs(np.diff(qg, axis=0)) / 0.01
    # Linear interpolation averages interval velocities: the limits hold on the grid too.
    assert np.all(v <= v_max * (1 + 1e-9))


def test_errors_name_the_problem():
    t = np.linspace(0.0, 1.0, 11)
    q = np.stack([10 * t, t], axis=1)
    with pytest.raises(TimingError, match="needs at least"):
        preserve_duration(t, q, [1.0, 1.0], max_speedup=2.0)  # 10x too fast everywhere
    with pytest.raises(TimingError, match="increase strictly"):
        expand_time(t[::-1], q, [1.0, 1.0])
    with pytest.raises(TimingError, match="v_max"):
        expand_time(t, q)
    with pytest.raises(TimingError, match="mode"):
        retime(t, q, [1.0, 1.0], mode="stretch")
