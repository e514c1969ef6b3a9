# SPDX-License-Identifier: Apache-2.0
"""Tests of the streaming filters: Butterworth gain/phase/streaming, cardinal-spline up-sampling."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget.motion import Butterworth, CardinalSpline


def _fit_sinusoid(t: np.ndarray, y: np.ndarray, f: float) -> tuple[float, float]:
    """Amplitude and phase of y ~ A sin(2 pi f t + phi) by least squares."""
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    (s, c), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return float(np.hypot(s, c)), float(np.arctan2(c, s))


@pytest.mark.parametrize(
    ("cutoff", "rate", "order"), [(6.0, 120.0, 2), (10.0, 250.0, 2), (4, 100, 4)]
)
def test_gain_at_cutoff_is_minus_3_db(cutoff, rate, order):
    bw = Butterworth(cutoff, rate, order=order)
    # From the implemented coefficients: bilinear design with pre-warping gives exactly 1/sqrt(2).
    gain_db = 20 * np.log10(abs(bw.frequency_response([cutoff])[0]))
    assert gain_db == pytest.approx(-3.0103, abs=0.1)
    # Measured: push a sinusoid at the cut-off, fit amplitude after 2 s of transients.
    t = np.arange(int(10 * rate)) / rate
    y = np.array([bw.push(np.array([v]))[0] for v in np.sin(2 * np.pi * cutoff * t)])
    steady = t >= 2.0
    amplitude, _ = _fit_sinusoid(t[steady], y[steady], cutoff)
    assert 20 * np.log10(amplitude) == pytest.approx(-3.0103, abs=0.1)
    # Pass band and stop band: ~0 dB at cutoff/10, below -20 dB at 4 x cutoff (order 2: -24 dB).
    assert abs(bw.frequency_response([cutoff / 10])[0]) == pytest.approx(1.0, abs=1e-3)
    assert 20 * np.log10(abs(bw.frequency_response([4 * cutoff])[0])) < -20


def test_filtfilt_has_zero_phase_and_squared_gain():
    bw = Butterworth(6.0, 120.0)
    t = np.arange(1200) / 120.0
    f = 3.0
    x = np.sin(2 * np.pi * f * t + 0.4)
    middle = (t > 2.0) & (t < 8.0)  # away from the padded ends
    amplitude, phase = _fit_sinusoid(t[middle], bw.filtfilt(x)[middle], f)
    assert phase == pytest.approx(0.4, abs=1e-3)
    assert amplitude == pytest.approx(abs(bw.frequency_response([f])[0]) ** 2, abs=1e-3)
    # The causal filter does lag, so the zero-phase check above could fail.
    _, causal_phase = _fit_sinusoid(t[middle], bw.lfilter(x)[middle], f)
    assert causal_phase < 0.4 - 0.3


def test_streaming_equals_offline_lfilter_with_gaps():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(600, 4, 3)).cumsum(axis=0)
    x[100:130, 1, 2] = np.nan  # gap mid-signal: held
    x[:7, 2, 0] = np.nan  # leading gap: NaN until the first valid sample, then steady state
    x[:, 3, 1] = np.nan  # never valid
    offline = Butterworth(5.0, 120.0).lfilter(x)
    stream = Butterworth(5.0, 120.0)
    online = np.array([stream.push(sample) for sample in x])
    # 1e-12: same recursion, floating-point order may differ between scipy's C loop and ours.
    np.testing.assert_allclose(online, offline, atol=1e-12, rtol=0)
    assert np.isnan(offline[:7, 2, 0]).all() and np.isfinite(offline[7:, 2, 0]).all()
    assert offline[7, 2, 0] == pytest.approx(x[7, 2, 0], abs=1e-12)  # steady-state start
    assert np.isfinite(offline[100:130, 1, 2]).all()
    assert np.isnan(offline[:, 3, 1]).all()


def test_nan_sample_holds_the_last_valid_input():
    x = np.sin(np.arange(200) / 10.0)
    holey = x.copy()
    holey[50:60] = np.nan
    held = x.copy()
    held[50:60] = x[49]
    bw = Butterworth(3.0, 50.0)
    np.testing.assert_allclose(bw.lfilter(holey), bw.lfilter(held), atol=1e-15)
    np.testing.assert_allclose(bw.filtfilt(holey), bw.filtfilt(held), atol=1e-15)


def test_reset_starts_at_steady_state():
    bw = Butterworth(2.0, 100.0)
    x0 = np.array([[0.3, -1.0, 2.5]])
    bw.reset(x0)
    for _ in range(50):
        np.testing.assert_allclose(bw.push(x0), x0, atol=1e-12)
    with pytest.raises(ValueError, match=r"sample shape \(3,\) differs from the shape \(1, 3\)"):
        bw.push(np.zeros(3))


def test_butterworth_rejects_cutoff_above_nyquist():
    with pytest.raises(
        ValueError, match=r"cutoff_hz must lie in \(0, rate_hz / 2\) = \(0, 60\) Hz"
    ):
        Butterworth(70.0, 120.0)


def _stream(spline: CardinalSpline, t, x):
    spline.reset()
    out = []
    for ti, xi in zip(t, x, strict=True):
        out.extend(spline.push(ti, xi))
    out.extend(spline.flush())
    return np.array([o[0] for o in out]), np.array([o[1] for o in out])


@pytest.mark.parametrize(
    ("rate_out", "shared_times"),  # samples k / 120 that are also outputs i / rate_out
    [(960.0, 60), (1000.0, 20), (500.0, 10), (333.0, 2)],
)
def test_upsample_passes_through_samples_and_streaming_matches(rate_out, shared_times):
    rng = np.random.default_rng(7)
    t = np.arange(60) / 120.0
    x = rng.normal(size=(60, 5, 3))
    spline = CardinalSpline(120.0, rate_out)
    t_out, x_out = spline.upsample(t, x)
    assert t_out[0] == t[0] and t_out[-1] <= t[-1] + 1e-12
    np.testing.assert_allclose(np.diff(t_out), 1 / rate_out, rtol=1e-9)
    # Output times that land on input samples (all at 960 Hz, every 3rd at 1000 Hz).
    on_knot = np.isclose((t_out * 120.0) % 1.0, 0.0, atol=1e-9) | np.isclose(
        (t_out * 120.0) % 1.0, 1.0, atol=1e-9
    )
    knots = np.rint(t_out[on_knot] * 120.0).astype(int)
    assert knots.size == shared_times
    np.testing.assert_allclose(x_out[on_knot], x[knots], atol=1e-12, rtol=0)
    t_stream, x_stream = _stream(spline, t, x)
    np.testing.assert_allclose(t_stream, t_out, atol=1e-12, rtol=0)
    np.testing.assert_allclose(x_stream, x_out, atol=1e-12, rtol=0)


def test_catmull_rom_reproduces_quadratics_on_the_interior():
    t = np.arange(40) / 120.0

    def quadratic(s):
        return 3 * s**2 - 2 * s + 0.5

    t_out, x_out = CardinalSpline(120.0, 1000.0, tension=0.5).upsample(t, quadratic(t))
    interior = (t_out >= t[1]) & (t_out <= t[-2])
    np.testing.assert_allclose(x_out[interior], quadratic(t_out[interior]), atol=1e-12)
    # Other tensions do not (so the tension is really used).
    _, x_other = CardinalSpline(120.0, 1000.0, tension=0.3).upsample(t, quadratic(t))
    assert np.abs(x_other[interior] - quadratic(t_out[interior])).max() > 1e-6


def test_streaming_latency_is_one_input_sample():
    spline = CardinalSpline(120.0, 480.0)
    t = np.arange(10) / 120.0
    assert spline.push(t[0], [0.0]) == [] and spline.push(t[1], [1.0]) == []
    first = spline.push(t[2], [2.0])
    assert [round(o[0] * 480) for o in first] == [0, 1, 2, 3, 4]  # [t0, t1]
    for k in range(3, 10):
        out = spline.push(t[k], [float(k)])
        assert out[-1][0] == pytest.approx(t[k - 1])  # outputs reach t_{k-1} when sample k arrives
        assert len(out) == 4


def test_streaming_rejects_time_going_backwards():
    spline = CardinalSpline(120.0, 480.0)
    spline.push(0.1, [0.0])
    with pytest.raises(ValueError, match="must be after the previous one"):
        spline.push(0.1, [1.0])
