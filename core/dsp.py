"""Signal processing without scipy: Butterworth design, a per-sample biquad, a uniform-grid resampler.

Phones deliver sensor events at uneven intervals and at rates from about 20
to 400 Hz.  The pipeline therefore first brings the accelerometer onto a
uniform time grid (:class:`GridResampler`, default 50 Hz) and runs every
fixed-rate filter there, so that filter coefficients, thresholds in samples
and the cost per second do not depend on the phone.
"""

from __future__ import annotations

import math
from collections import deque


def butter2_lowpass(cutoff_hz: float, fs_hz: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Second-order Butterworth low-pass ``(b, a)`` by the bilinear transform with prewarping.

    Same result as ``scipy.signal.butter(2, cutoff_hz, fs=fs_hz)`` (a test
    checks it): analogue prototype ``H(s) = 1 / (s^2 + sqrt(2) s + 1)``,
    ``K = tan(pi fc / fs)``.
    """
    if not 0 < cutoff_hz < fs_hz / 2:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2} Hz")
    k = math.tan(math.pi * cutoff_hz / fs_hz)
    k2 = k * k
    sq2 = math.sqrt(2.0)
    norm = 1.0 / (1.0 + sq2 * k + k2)
    b0 = k2 * norm
    return (b0, 2.0 * b0, b0), (1.0, 2.0 * (k2 - 1.0) * norm, (1.0 - sq2 * k + k2) * norm)


def butter2_group_delay_s(cutoff_hz: float) -> float:
    """Low-frequency group delay of a second-order Butterworth low-pass: ``sqrt(2) / (2 pi fc)`` seconds."""
    return math.sqrt(2.0) / (2.0 * math.pi * cutoff_hz)


class Biquad:
    """One second-order section in direct form II transposed, state carried between calls.

    ``step(x)`` filters one sample; ``reset(x0)`` sets the state to the
    steady state of a constant input ``x0`` (same as ``scipy.signal.lfilter_zi * x0``).
    """

    __slots__ = ("b0", "b1", "b2", "a1", "a2", "z1", "z2")

    def __init__(self, b, a):
        a0 = a[0]
        self.b0, self.b1, self.b2 = b[0] / a0, b[1] / a0, b[2] / a0
        self.a1, self.a2 = a[1] / a0, a[2] / a0
        self.z1 = self.z2 = 0.0

    def reset(self, x0: float = 0.0) -> None:
        gain = (self.b0 + self.b1 + self.b2) / (1.0 + self.a1 + self.a2)
        y0 = gain * x0
        self.z1 = y0 - self.b0 * x0
        self.z2 = self.b2 * x0 - self.a2 * y0

    def step(self, x: float) -> float:
        y = self.b0 * x + self.z1
        self.z1 = self.b1 * x - self.a1 * y + self.z2
        self.z2 = self.b2 * x - self.a2 * y
        return y


class GridResampler:
    """Brings an unevenly sampled scalar signal onto a uniform grid, one event at a time.

    Grid point ``t_g`` gets the mean of the events in ``(t_g - T, t_g]`` when
    there are at least two (a box anti-alias filter for fast phones), else the
    linear interpolation between the events around it (slow phones).  A gap
    longer than ``max_gap_s`` restarts the grid at the next event; the caller
    learns of it from :attr:`restarted`.

    Parameters
    ----------
    rate_hz : float
        Grid rate (Hz).
    max_gap_s : float
        Longest gap between events bridged by interpolation (s).
    """

    def __init__(self, *, rate_hz: float = 50.0, max_gap_s: float = 0.5):
        self.rate_hz = float(rate_hz)
        self.period_ns = int(round(1e9 / rate_hz))
        self.max_gap_ns = int(max_gap_s * 1e9)
        self.next_t_ns: int | None = None
        self._prev_t = 0
        self._prev_x = 0.0
        self._sum = 0.0
        self._n = 0
        #: True after an event that started a new grid (first event or after a gap)
        self.restarted = False

    def update(self, t_ns: int, x: float) -> list[tuple[int, float]]:
        """Feed one event; returns the grid points ``(t_ns, value)`` completed by it."""
        out = []
        nxt = self.next_t_ns
        if nxt is None or t_ns - self._prev_t > self.max_gap_ns:
            self.restarted = True
            out.append((t_ns, x))
            self.next_t_ns = t_ns + self.period_ns
            self._prev_t, self._prev_x = t_ns, x
            self._sum, self._n = 0.0, 0
            return out
        self.restarted = False
        if t_ns <= self._prev_t:  # not monotonic: ignore (recordings are repaired before replay)
            return out
        while t_ns >= nxt:
            if self._n >= 2 and nxt == t_ns:
                value = (self._sum + x) / (self._n + 1)
            elif self._n >= 2:
                value = self._sum / self._n
            else:
                w = (nxt - self._prev_t) / (t_ns - self._prev_t)
                value = self._prev_x + w * (x - self._prev_x)
            out.append((nxt, value))
            self._sum, self._n = 0.0, 0
            nxt += self.period_ns
        self.next_t_ns = nxt
        if out and out[-1][0] == t_ns:
            pass  # the event sat exactly on the grid point and was used there
        else:
            self._sum += x
            self._n += 1
        self._prev_t, self._prev_x = t_ns, x
        return out


class WindowVariance:
    """Variance of a scalar over a trailing time window, O(1) per sample."""

    __slots__ = ("window_ns", "buf", "s1", "s2")

    def __init__(self, window_s: float):
        self.window_ns = int(window_s * 1e9)
        self.buf: deque = deque()
        self.s1 = self.s2 = 0.0

    def update(self, t_ns: int, x: float) -> float:
        buf = self.buf
        buf.append((t_ns, x))
        # the sums in locals, the variance inline: this runs on every accelerometer and magnetometer event
        s1 = self.s1 + x
        s2 = self.s2 + x * x
        limit = t_ns - self.window_ns
        while buf[0][0] < limit:
            old = buf.popleft()[1]
            s1 -= old
            s2 -= old * old
        self.s1, self.s2 = s1, s2
        n = len(buf)
        if n < 2:
            return 0.0
        mean = s1 / n
        v = s2 / n - mean * mean
        return 0.0 if 0.0 > v else v  # max(v, 0.0)

    def variance(self) -> float:
        """Variance of the values in the window (0 with fewer than two)."""
        n = len(self.buf)
        if n < 2:
            return 0.0
        mean = self.s1 / n
        return max(self.s2 / n - mean * mean, 0.0)


class RunningMedian:
    """Median of every value seen so far, from a fixed-bin histogram (O(1) to add, O(bins) to query at worst).

    The median's bin is kept between queries with the count of the values below it, so a query walks from the
    last median's bin over the few bins the median moved since (not the thousands of the histogram).  ``counts``
    and ``n`` may be set from outside (the desktop fast path restores them): a query then starts again from the
    first bin.
    """

    __slots__ = ("lo", "width", "counts", "n", "_i", "_below", "_of")

    def __init__(self, lo: float, hi: float, width: float):
        self.lo, self.width = lo, width
        self.counts = [0] * (int((hi - lo) / width) + 1)
        self.n = 0
        #: the last median's bin, the count of the values in the bins below it, and the ``counts`` list they are of
        self._i, self._below, self._of = 0, 0, self.counts

    def add(self, x: float) -> None:
        i = int((x - self.lo) / self.width)
        if 0 <= i < len(self.counts):
            self.counts[i] += 1
            self.n += 1
            if i < self._i:
                self._below += 1

    def median(self) -> float:
        """The centre of the first bin whose cumulative count reaches half the values (nan if none does)."""
        counts = self.counts
        if counts is not self._of:  # set from outside: from the first bin
            self._i, self._below, self._of = 0, 0, counts
        half = 0.5 * self.n
        i, below = self._i, self._below  # below: the cumulative count up to bin i - 1
        while i > 0 and below >= half:  # the cumulative count reaches half before bin i
            i -= 1
            below -= counts[i]
        while i < len(counts) and below + counts[i] < half:  # ... not yet at bin i
            below += counts[i]
            i += 1
        self._i, self._below = i, below
        return self.lo + (i + 0.5) * self.width if i < len(counts) else math.nan


class WindowMeanSpread:
    """Mean and largest per-axis spread of a 3-vector over a trailing time window (O(1) per sample)."""

    __slots__ = ("window_ns", "buf", "s", "s2")

    def __init__(self, window_s: float):
        self.window_ns = int(window_s * 1e9)
        self.buf: deque = deque()
        self.s = [0.0, 0.0, 0.0]
        self.s2 = [0.0, 0.0, 0.0]

    def update(self, t_ns: int, w) -> None:
        # written out per axis: loops over range(3) and indexing cost more than the arithmetic here
        buf = self.buf
        buf.append((t_ns, w))
        s, s2 = self.s, self.s2
        x, y, z = w
        s0, s1, s2_ = s[0] + x, s[1] + y, s[2] + z
        q0, q1, q2 = s2[0] + x * x, s2[1] + y * y, s2[2] + z * z
        limit = t_ns - self.window_ns
        while buf[0][0] < limit:
            x, y, z = buf.popleft()[1]
            s0 -= x
            s1 -= y
            s2_ -= z
            q0 -= x * x
            q1 -= y * y
            q2 -= z * z
        s[0], s[1], s[2] = s0, s1, s2_
        s2[0], s2[1], s2[2] = q0, q1, q2

    def span_ns(self) -> int:
        """Time between the oldest and the newest sample of the window (ns)."""
        buf = self.buf
        return buf[-1][0] - buf[0][0]

    def stats(self):
        """(mean (3), largest per-axis standard deviation, span in ns) of the window."""
        n = len(self.buf)
        s, s2 = self.s, self.s2
        mean = [s[0] / n, s[1] / n, s[2] / n]
        sqrt = math.sqrt
        sd = max(sqrt(max(s2[0] / n - mean[0] * mean[0], 0.0)), sqrt(max(s2[1] / n - mean[1] * mean[1], 0.0)),
                 sqrt(max(s2[2] / n - mean[2] * mean[2], 0.0)))
        return mean, sd, self.buf[-1][0] - self.buf[0][0]
