# SPDX-License-Identifier: Apache-2.0
r"""Streaming-capable signal stages of the motion pipeline (Dariush 2009 Sec. 3).

* :class:`Butterworth` -- low-pass filter, offline zero-phase (:meth:`Butterworth.filtfilt`),
  offline causal (:meth:`Butterworth.lfilter`) and sample by sample (:meth:`Butterworth.push`);
  the last two give the same numbers.
* :class:`CardinalSpline` -- up-sampling to the control rate with cardinal (Hermite) splines,
  offline (:meth:`CardinalSpline.upsample`) and sample by sample (:meth:`CardinalSpline.push`)
  with the same output.

Both work on vector-valued samples of any shape (a key-point ``(3,)``, all key-points ``(K, 3)``);
time is the first axis of offline arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from scipy import signal


def _hold_nan(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Replace NaN samples by the last valid one along axis 0.

    Returns:
        ``(held, first_valid)``: ``held`` keeps NaN before the first valid sample of each
        component; ``first_valid`` is the index of that sample (``len(x)`` if none).
    """
    valid = ~np.isnan(x)
    index = np.where(valid, np.arange(x.shape[0]).reshape((-1,) + (1,) * (x.ndim - 1)), -1)
    np.maximum.accumulate(index, axis=0, out=index)
    held = np.take_along_axis(x, np.maximum(index, 0), axis=0)
    held[index < 0] = np.nan
    first_valid = np.where(valid.any(axis=0), valid.argmax(axis=0), x.shape[0])
    return held, first_valid


def _per_valid_segment(
    x: npt.ArrayLike, run: Callable[[int, np.ndarray], np.ndarray]
) -> np.ndarray:
    """Filter ``(T, ...)`` samples from each component's first valid sample on, NaNs held.

    Components whose first valid sample is the same ``start`` are filtered together:
    ``run(start, segment)`` maps the ``(T - start, n)`` held samples to their filtered values.
    Samples before ``start`` (and components never valid) stay NaN.
    """
    x = np.asarray(x, dtype=float)
    held, first = _hold_nan(x)
    out = np.full_like(x, np.nan)
    flat_x = held.reshape(x.shape[0], -1)
    flat_out = out.reshape(x.shape[0], -1)
    flat_first = np.asarray(first).reshape(-1)
    for start in np.unique(flat_first):
        if start >= x.shape[0]:
            continue
        columns = np.nonzero(flat_first == start)[0]
        flat_out[start:, columns] = run(start, flat_x[start:, columns])
    return out


class Butterworth:
    r"""Butterworth low-pass filter, offline and streaming.

    The digital filter comes from ``scipy.signal.butter`` (bilinear transform with pre-warping),
    so the magnitude at the cut-off is exactly :math:`1/\sqrt{2}` (-3.01 dB):

    .. math::

        |H(e^{j\omega})|^2 = \frac{1}{1 + \left(\tan(\omega/2) / \tan(\omega_c/2)\right)^{2n}},
        \qquad \omega_c = 2\pi f_c / f_s.

    Streaming uses the direct form II transposed (the structure of ``scipy.signal.lfilter``),
    with state :math:`z \in \mathbb{R}^{n \times d}`:

    .. math::

        y_k = b_0 x_k + z_{0},\quad
        z_{i} \leftarrow b_{i+1} x_k + z_{i+1} - a_{i+1} y_k \quad (z_{n} = 0),

    initialised at the steady state of a constant input :math:`x_0` (``scipy.signal.lfilter_zi``),
    so a motion that starts at rest produces no start-up transient.

    Missing samples (NaN) are replaced by the last valid input of the same component (hold), so
    the output stays finite once a component has been seen. Before the first valid sample of a
    component its output is NaN, and its state is initialised at that first valid sample.

    Args:
        cutoff_hz: Cut-off frequency in [Hz], ``0 < cutoff_hz < rate_hz / 2``.
        rate_hz: Sampling rate in [Hz].
        order: Filter order (Dariush 2009: 2).

    Raises:
        ValueError: If the cut-off is not below the Nyquist frequency or the order is not >= 1.
    """

    def __init__(self, cutoff_hz: float, rate_hz: float, order: int = 2) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
        if not (0 < cutoff_hz < rate_hz / 2):
            raise ValueError(
                f"cutoff_hz must lie in (0, rate_hz / 2) = (0, {rate_hz / 2:g}) Hz, "
                f"got {cutoff_hz!r}"
            )
        if int(order) != order or order < 1:
            raise ValueError(f"order must be a positive integer, got {order!r}")
        self.cutoff_hz = float(cutoff_hz)
        self.rate_hz = float(rate_hz)
        self.order = int(order)
        b, a = signal.butter(self.order, self.cutoff_hz, btype="low", fs=self.rate_hz)
        self.b: np.ndarray = b  # (order + 1,)
        self.a: np.ndarray = a  # (order + 1,), a[0] = 1
        self.zi: np.ndarray = signal.lfilter_zi(b, a)  # (order,), steady state for a unit step
        self._state: np.ndarray | None = None  # (order, *shape)
        self._last: np.ndarray | None = None  # last valid input, (*shape)
        self._started: np.ndarray | None = None  # (*shape) bool

    def __repr__(self) -> str:
        """Parameters."""
        return (
            f"Butterworth(cutoff_hz={self.cutoff_hz:g}, rate_hz={self.rate_hz:g}, "
            f"order={self.order})"
        )

    def frequency_response(self, frequencies_hz: npt.ArrayLike) -> np.ndarray:
        r"""Complex response :math:`H(e^{j 2 \pi f / f_s})` of the causal filter at [Hz]."""
        _, h = signal.freqz(self.b, self.a, worN=np.asarray(frequencies_hz, float), fs=self.rate_hz)
        return h

    # ------------------------------------------------------------------------------ streaming

    def reset(self, x0: npt.ArrayLike) -> None:
        """Initialise the state at the steady state of a constant input ``x0``.

        NaN components of ``x0`` start at their first valid sample instead.
        """
        x0 = np.asarray(x0, dtype=float)
        self._state = np.zeros((self.order,) + x0.shape)
        self._last = np.full(x0.shape, np.nan)
        self._started = np.zeros(x0.shape, dtype=bool)
        self._start(x0)

    def _start(self, x: np.ndarray) -> None:
        assert self._state is not None and self._started is not None and self._last is not None
        new = ~self._started & ~np.isnan(x)
        if np.any(new):
            self._state[:, new] = self.zi[:, None] * x[new][None, :]
            self._started |= new

    def push(self, x: npt.ArrayLike) -> np.ndarray:
        """Filter one sample; the first call after construction acts as :meth:`reset` on it.

        Args:
            x: Sample of any fixed shape, e.g. ``(3,)`` or ``(K, 3)``; NaN means missing.

        Returns:
            Filtered sample, same shape (NaN for components never seen yet).

        Raises:
            ValueError: If the shape differs from the first sample's.
        """
        x = np.asarray(x, dtype=float)
        if self._state is None:
            self.reset(x)
        assert self._state is not None and self._last is not None
        if x.shape != self._last.shape:
            raise ValueError(
                f"sample shape {x.shape} differs from the shape {self._last.shape} this filter was "
                "started with; call reset(x0) to change it"
            )
        self._start(x)
        x = np.where(np.isnan(x), self._last, x)
        self._last = x
        z, b, a = self._state, self.b, self.a
        y = b[0] * x + z[0]
        for i in range(self.order - 1):
            z[i] = b[i + 1] * x + z[i + 1] - a[i + 1] * y
        z[self.order - 1] = b[self.order] * x - a[self.order] * y
        return y

    # ------------------------------------------------------------------------------ offline

    def lfilter(self, x: npt.ArrayLike) -> np.ndarray:
        """Offline causal filtering along axis 0, equal to :meth:`push` sample by sample.

        The state starts at the steady state of the first valid sample of each component
        (same as a fresh filter fed with :meth:`push`); NaN samples are held.

        Args:
            x: ``(T, ...)`` samples.

        Returns:
            ``(T, ...)`` filtered samples.
        """

        def run(start: int, segment: np.ndarray) -> np.ndarray:
            zi = self.zi[:, None] * segment[0][None, :]
            return signal.lfilter(self.b, self.a, segment, axis=0, zi=zi)[0]

        return _per_valid_segment(x, run)

    def filtfilt(self, x: npt.ArrayLike) -> np.ndarray:
        """Offline zero-phase filtering along axis 0 (``scipy.signal.filtfilt``, odd padding).

        The magnitude response is :math:`|H|^2` (-6 dB at the cut-off) and the phase is zero.
        NaN samples are held as in :meth:`lfilter`; samples before the first valid one of a
        component stay NaN.

        Args:
            x: ``(T, ...)`` samples, ``T > 3 (order + 1)`` after the leading NaNs.

        Raises:
            ValueError: If a component has too few valid samples for the padding.
        """
        padlen = 3 * (self.order + 1)

        def run(start: int, segment: np.ndarray) -> np.ndarray:
            if segment.shape[0] <= padlen:
                raise ValueError(
                    f"filtfilt needs more than {padlen} samples, got {segment.shape[0]} "
                    f"(from sample {start}); use lfilter for short signals"
                )
            return signal.filtfilt(self.b, self.a, segment, axis=0)

        return _per_valid_segment(x, run)


class CardinalSpline:
    r"""Up-sampling with a cardinal spline (cubic Hermite with finite-difference tangents).

    Between knots :math:`t_k` and :math:`t_{k+1}`, with :math:`h = t_{k+1} - t_k` and
    :math:`u = (t - t_k) / h`:

    .. math::

        x(t) = h_{00}(u) x_k + h_{10}(u)\, h\, m_k + h_{01}(u) x_{k+1} + h_{11}(u)\, h\, m_{k+1},

    with the Hermite basis :math:`h_{00} = 2u^3 - 3u^2 + 1`, :math:`h_{10} = u^3 - 2u^2 + u`,
    :math:`h_{01} = -2u^3 + 3u^2`, :math:`h_{11} = u^3 - u^2`, and tangents

    .. math::

        m_k = 2 s \, \frac{x_{k+1} - x_{k-1}}{t_{k+1} - t_{k-1}},

    where :math:`s` is ``tension`` (for uniform knots :math:`h m_k = s (x_{k+1} - x_{k-1})`;
    :math:`s = 1/2` is Catmull-Rom, :math:`s = 0` flat tangents). At the first and last knots the
    missing neighbour is the reflection :math:`2 x_0 - x_1` (resp. :math:`2 x_N - x_{N-1}`), i.e.
    :math:`m_0 = 2 s (x_1 - x_0) / (t_1 - t_0)`.

    The curve passes through every sample (at :math:`u = 0` only :math:`h_{00} = 1`), output
    times are :math:`t_0 + i / f_{out}` up to the last sample, and an output time within
    :math:`10^{-9}` of a knot interval of that knot returns the sample exactly.

    **Latency (streaming).** The segment :math:`[t_{k-1}, t_k]` needs :math:`m_k`, hence sample
    :math:`k + 1`: outputs up to :math:`t_k` are emitted when sample :math:`k + 1` arrives, one
    input period late (8.3 ms at 120 Hz); an output just after :math:`t_{k-1}` waits up to two
    input periods. A player with a fixed delay must run :math:`2 / f_{in}` behind the input.
    :meth:`flush` emits the last segment (with the end-point rule) once the input ends.

    Args:
        rate_in: Nominal input rate in [Hz] (used when :meth:`upsample` gets no timestamps).
        rate_out: Output rate in [Hz], typically the control rate.
        tension: :math:`s` above; 0.5 is Catmull-Rom.

    Raises:
        ValueError: If a rate is not positive or the tension is not finite.
    """

    def __init__(self, rate_in: float, rate_out: float, tension: float = 0.5) -> None:
        for label, value in (("rate_in", rate_in), ("rate_out", rate_out)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{label} must be a positive number of Hz, got {value!r}")
        if not math.isfinite(tension):
            raise ValueError(f"tension must be finite, got {tension!r}")
        self.rate_in = float(rate_in)
        self.rate_out = float(rate_out)
        self.tension = float(tension)
        self._t: list[float] = []  # last (up to) four sample times
        self._x: list[np.ndarray] = []  # and samples
        self._t0: float | None = None  # first sample time: outputs are t0 + i / rate_out
        self._count = 0  # samples pushed since reset
        self._next_out = 0  # index i of the next output time

    def __repr__(self) -> str:
        """Parameters."""
        return (
            f"CardinalSpline(rate_in={self.rate_in:g}, rate_out={self.rate_out:g}, "
            f"tension={self.tension:g})"
        )

    # --------------------------------------------------------------------------- shared math

    def _tangent(
        self,
        t_prev: float | np.ndarray,
        x_prev: np.ndarray,
        t_next: float | np.ndarray,
        x_next: np.ndarray,
    ) -> np.ndarray:
        return 2.0 * self.tension * (x_next - x_prev) / (t_next - t_prev)

    def _out_times(self, t0: float, first: int, upto: float) -> np.ndarray:
        """Output times ``t0 + i / rate_out`` for ``i >= first`` and time ``<= upto`` (+tol)."""
        period = 1.0 / self.rate_out
        last = math.floor((upto - t0) * self.rate_out + 1e-9)
        if last < first:
            return np.empty(0)
        return t0 + np.arange(first, last + 1) * period

    @staticmethod
    def _hermite(
        t_out: np.ndarray,
        t_k: np.ndarray,
        t_k1: np.ndarray,
        x_k: np.ndarray,
        x_k1: np.ndarray,
        m_k: np.ndarray,
        m_k1: np.ndarray,
    ) -> np.ndarray:
        h = t_k1 - t_k
        u = (t_out - t_k) / h
        u = np.where(np.abs(u) < 1e-9, 0.0, np.where(np.abs(u - 1.0) < 1e-9, 1.0, u))
        u2, u3 = u * u, u * u * u
        shape = (-1,) + (1,) * (x_k.ndim - 1)
        h00 = (2 * u3 - 3 * u2 + 1).reshape(shape)
        h10 = (u3 - 2 * u2 + u).reshape(shape)
        h01 = (-2 * u3 + 3 * u2).reshape(shape)
        h11 = (u3 - u2).reshape(shape)
        hh = h.reshape(shape)
        return h00 * x_k + h10 * hh * m_k + h01 * x_k1 + h11 * hh * m_k1

    # --------------------------------------------------------------------------- offline

    def upsample(self, t: npt.ArrayLike | None, x: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Offline up-sampling of a whole signal.

        Args:
            t: ``(N,)`` strictly increasing sample times in [s], or ``None`` for
                ``k / rate_in``.
            x: ``(N, ...)`` samples, ``N >= 2``.

        Returns:
            ``(t_out, x_out)``: times ``t_0 + i / rate_out`` up to ``t_{N-1}``, and the spline
            there, shape ``(M, ...)``.

        Raises:
            ValueError: Fewer than two samples, mismatched lengths, or non-increasing times.
        """
        x = np.asarray(x, dtype=float)
        n = x.shape[0]
        t = np.arange(n) / self.rate_in if t is None else np.asarray(t, dtype=float)
        if t.shape != (n,):
            raise ValueError(f"t must have shape ({n},) to match x {x.shape}, got {t.shape}")
        if n < 2:
            raise ValueError("upsampling needs at least two samples")
        if not np.all(np.diff(t) > 0):
            raise ValueError("sample times must be strictly increasing")
        # Tangents with reflected end neighbours (their spacing mirrors the first/last interval).
        t_ext = np.concatenate([[2 * t[0] - t[1]], t, [2 * t[-1] - t[-2]]])
        x_ext = np.concatenate([2 * x[:1] - x[1:2], x, 2 * x[-1:] - x[-2:-1]])
        m = self._tangent(
            t_ext[:-2].reshape((-1,) + (1,) * (x.ndim - 1)),
            x_ext[:-2],
            t_ext[2:].reshape((-1,) + (1,) * (x.ndim - 1)),
            x_ext[2:],
        )
        t_out = self._out_times(t[0], 0, t[-1])
        # Segment of each output; a time on a knot evaluates to that sample exactly (u snapped to
        # 0 or 1 in _hermite), whichever side it falls.
        k = np.clip(np.searchsorted(t, t_out, side="right") - 1, 0, n - 2)
        x_out = self._hermite(t_out, t[k], t[k + 1], x[k], x[k + 1], m[k], m[k + 1])
        return t_out, x_out

    # --------------------------------------------------------------------------- streaming

    def reset(self) -> None:
        """Forget all samples; the next :meth:`push` starts a new signal."""
        self._t, self._x = [], []
        self._t0 = None
        self._count = 0
        self._next_out = 0

    def push(self, t: float, x: npt.ArrayLike) -> list[tuple[float, np.ndarray]]:
        """Add one sample; return the output samples that became computable.

        Args:
            t: Sample time in [s], larger than the previous one.
            x: Sample, fixed shape.

        Returns:
            ``(t_out, x_out)`` pairs in time order: nothing for the first two samples, the outputs
            in ``[t_0, t_1]`` at the third, and those in ``(t_{k-1}, t_k]`` at sample ``k + 1``.

        Raises:
            ValueError: Non-increasing time or changed sample shape.
        """
        x = np.array(x, dtype=float)
        t = float(t)
        if self._t:
            if not t > self._t[-1]:
                raise ValueError(f"sample time {t} must be after the previous one {self._t[-1]}")
            if x.shape != self._x[-1].shape:
                raise ValueError(f"sample shape {x.shape} differs from {self._x[-1].shape}")
        else:
            self._t0 = t
        self._t.append(t)
        self._x.append(x)
        self._count += 1
        if len(self._t) > 4:  # the segment [t_{k-1}, t_k] needs samples k-2 .. k+1
            del self._t[0], self._x[0]
        if self._count < 3:
            return []
        ts, xs = self._t, self._x
        if self._count == 3:  # first segment: reflected neighbour before t_0
            before = (2 * ts[0] - ts[1], 2 * xs[0] - xs[1])
            return self._segment(before, (ts[0], xs[0]), (ts[1], xs[1]), (ts[2], xs[2]))
        return self._segment((ts[0], xs[0]), (ts[1], xs[1]), (ts[2], xs[2]), (ts[3], xs[3]))

    def flush(self) -> list[tuple[float, np.ndarray]]:
        """Emit the last segment, treating the last sample as the end of the signal.

        Call it once when the input ends; :meth:`reset` before reusing the spline.
        """
        if self._count < 2:
            return []
        ts, xs = self._t, self._x
        a, b = (ts[-2], xs[-2]), (ts[-1], xs[-1])
        after = (2 * b[0] - a[0], 2 * b[1] - a[1])
        before = (ts[-3], xs[-3]) if self._count >= 3 else (2 * a[0] - b[0], 2 * a[1] - b[1])
        return self._segment(before, a, b, after)

    def _segment(self, before, a, b, after) -> list[tuple[float, np.ndarray]]:
        """Outputs on ``(t_a, t_b]`` (from ``t_0`` on the first segment) not yet emitted."""
        assert self._t0 is not None
        t_out = self._out_times(self._t0, self._next_out, b[0])
        if t_out.size == 0:
            return []
        self._next_out += t_out.size
        m_a = self._tangent(before[0], before[1], b[0], b[1])
        m_b = self._tangent(a[0], a[1], after[0], after[1])
        n = t_out.size
        shape = (n,) + a[1].shape
        x_out = self._hermite(
            t_out,
            np.full(n, a[0]),
            np.full(n, b[0]),
            np.broadcast_to(a[1], shape),
            np.broadcast_to(b[1], shape),
            np.broadcast_to(m_a, shape),
            np.broadcast_to(m_b, shape),
        )
        return list(zip(t_out.tolist(), x_out, strict=True))
