"""Stance (zero-velocity) detection for a foot-mounted IMU.

Four detectors, selectable by name, all on a window defined in **seconds**
(centred on the sample; samples with ``|t_j - t_k| <= window_s / 2``), so a
setting means the same at 100 and at 400 Hz.  Each gives a statistic per
sample; the sample is stance when the statistic is at most ``threshold``.

``"song"`` -- Song & Park 2018, eqs. 1-6
    With ``a_x, a_z`` two accelerometer axes and ``w_x, w_y`` two gyroscope
    axes (the paper's; :func:`infer_foot_axes` finds them on any mounting)::

        E_a = Var(sqrt(a_x^2 + a_z^2))          (eq. 1)
        P_a = Var(a_x a_z)                       (eq. 2)
        S_a = Var(a_x + a_z)                     (eq. 3)
        E_r = Var(sqrt(w_x^2 + w_y^2))           (eq. 4)
        A_r = sqrt(w_x(k)^2 + w_y(k)^2)          (eq. 5, this sample only)
        J   = max(w1 E_a, w2 P_a, w3 S_a, w4 E_r, w5 A_r)   (eq. 6; stance: J <= 1)

    Weights ``w = (50, 100, 100, 3, 5)`` as in the paper (SI units: m/s^2,
    rad/s); the paper's window is 15 samples at 100 Hz, ``window_s = 0.15``.
    The variances are population variances over the window.
``"shoe"`` -- the stance hypothesis optimal detector (SHOE, generalised likelihood ratio; Skog et al. 2010)::

        T = 1/W sum_k ( |a_k - g a_mean/|a_mean||^2 / sigma_a^2 + |w_k|^2 / sigma_w^2 )
``"amv"`` -- acceleration moving variance: ``T = 1/W sum_k |a_k - a_mean|^2`` ((m/s^2)^2)
``"are"`` -- angular rate energy: ``T = 1/W sum_k |w_k|^2`` ((rad/s)^2)

Batch (:meth:`StanceDetector.detect`) works on whole arrays with cumulative
sums (O(n), no Python loop).  Streaming (:class:`StanceStream`) buffers one
half-window of samples and calls the same batch kernel on the buffer, so it
decides each sample ``window_s / 2`` late and gives the same result.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from core.conventions import STANDARD_GRAVITY_M_S2

DETECTORS = ("song", "shoe", "amv", "are")

#: default threshold of each detector (chosen on the PyShoe tuning split with window_s = 0.1, "song" with
#: the paper's 0.15 s; see docs/foot.md).  The paper's own J <= 1 marks almost nothing as stance on PyShoe.
DEFAULT_THRESHOLDS = {"song": 100.0, "shoe": 1.0e5, "amv": 0.02, "are": 0.2}

#: eq. 6 weights (w1 .. w5) of the paper
SONG_WEIGHTS = (50.0, 100.0, 100.0, 3.0, 5.0)


@dataclass(frozen=True)
class StanceSettings:
    """Settings of :class:`StanceDetector` (units in the names)."""

    #: one of :data:`DETECTORS`
    detector: str = "shoe"
    #: width of the centred window (s); the paper's is 15 samples at 100 Hz (0.15 s), the tuned default 0.1 s
    window_s: float = 0.1
    #: stance when the statistic <= threshold; nan: the detector's entry of :data:`DEFAULT_THRESHOLDS`
    threshold: float = math.nan
    #: "song": eq. 6 weights
    song_weights: tuple = SONG_WEIGHTS
    #: "song": the accelerometer axes playing the paper's x (forward) and z (vertical)
    acc_axes: tuple = (0, 2)
    #: "song": the gyroscope axes playing the paper's x and y (the two not about the vertical)
    gyro_axes: tuple = (0, 1)
    #: "shoe": accelerometer and gyroscope noise (m/s^2, rad/s) of the likelihood ratio
    shoe_acc_sd_m_s2: float = 0.01
    shoe_gyro_sd_rad_s: float = math.radians(0.1)
    #: "shoe": gravity magnitude (m/s^2)
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2

    def __post_init__(self):
        if self.detector not in DETECTORS:
            raise ValueError(f"unknown stance detector {self.detector!r}: one of {', '.join(DETECTORS)}")
        if not (self.window_s > 0 and math.isfinite(self.window_s)):
            raise ValueError(f"window_s must be a positive number, not {self.window_s!r}")

    @property
    def threshold_value(self) -> float:
        return DEFAULT_THRESHOLDS[self.detector] if math.isnan(self.threshold) else float(self.threshold)


@dataclass
class StanceResult:
    """Per-sample stance decision and the statistic behind it."""

    t_ns: np.ndarray
    stance: np.ndarray  #: bool (n,)
    statistic: np.ndarray  #: (n,), stance where <= threshold
    threshold: float
    detector: str

    def phases(self) -> np.ndarray:
        """Stance phases as ``(m, 2)`` sample index pairs ``[start, end]`` (inclusive)."""
        return runs(self.stance)


def runs(mask) -> np.ndarray:
    """Runs of True in a boolean array as ``(m, 2)`` inclusive index pairs."""
    m = np.asarray(mask, dtype=bool).astype(np.int8)
    d = np.diff(np.concatenate([[0], m, [0]]))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return np.column_stack([starts, ends]).astype(np.int64)


def _window_bounds(t_ns: np.ndarray, half_ns: int, lo_t=None, hi_t=None):
    """Index range ``[lo, hi)`` of the samples within ``half_ns`` of each sample."""
    t = np.asarray(t_ns, dtype=np.int64)
    lo = np.searchsorted(t, t - half_ns, side="left")
    hi = np.searchsorted(t, t + half_ns, side="right")
    return lo, hi


def _wsum(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Window sums of ``x`` (n,) or (n, k) over ``[lo, hi)``."""
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)], axis=0)
    return c[hi] - c[lo]


def _wvar(x, lo, hi, count):
    """Population variance of ``x`` (n,) over each window (never negative)."""
    x0 = x - x[0] if len(x) else x  # shifted: the cumulative sums stay small
    m = _wsum(x0, lo, hi) / count
    return np.maximum(_wsum(x0 * x0, lo, hi) / count - m * m, 0.0)


def statistic(settings: StanceSettings, t_ns, acc_b, gyro_b) -> np.ndarray:
    """The detector statistic of every sample (the kernel of batch and streaming detection)."""
    s = settings
    acc = np.asarray(acc_b, dtype=float).reshape(-1, 3)
    gyr = np.asarray(gyro_b, dtype=float).reshape(-1, 3)
    n = len(acc)
    if n == 0:
        return np.zeros(0)
    lo, hi = _window_bounds(t_ns, int(round(s.window_s * 0.5e9)))
    cnt = (hi - lo).astype(float)
    if s.detector == "song":
        ix, iz = s.acc_axes
        gx, gy = s.gyro_axes
        ax, az = acc[:, ix], acc[:, iz]
        wr = np.sqrt(gyr[:, gx] ** 2 + gyr[:, gy] ** 2)
        w1, w2, w3, w4, w5 = s.song_weights
        return np.maximum.reduce([
            w1 * _wvar(np.sqrt(ax * ax + az * az), lo, hi, cnt),  # eq. 1
            w2 * _wvar(ax * az, lo, hi, cnt),  # eq. 2
            w3 * _wvar(ax + az, lo, hi, cnt),  # eq. 3
            w4 * _wvar(wr, lo, hi, cnt),  # eq. 4
            w5 * wr,  # eq. 5
        ])  # eq. 6
    w2sum = _wsum(np.einsum("ij,ij->i", gyr, gyr), lo, hi)
    if s.detector == "are":
        return w2sum / cnt
    a0 = acc - acc[0]  # shifted sums for the variance
    sa = _wsum(a0, lo, hi)
    sa2 = _wsum(np.einsum("ij,ij->i", a0, a0), lo, hi)
    if s.detector == "amv":
        return np.maximum(sa2 - np.einsum("ij,ij->i", sa, sa) / cnt, 0.0) / cnt
    # shoe: sum |a_k - g u|^2 = sum |a_k|^2 - 2 g |sum a_k| + W g^2 with u = mean direction
    g = s.gravity_m_s2
    sum_a = sa + cnt[:, None] * acc[0]
    sum_a2 = sa2 + 2.0 * np.einsum("ij,j->i", sa, acc[0]) + cnt * float(acc[0] @ acc[0])
    acc_term = np.maximum(sum_a2 - 2.0 * g * np.linalg.norm(sum_a, axis=1) + cnt * g * g, 0.0)
    return (acc_term / s.shoe_acc_sd_m_s2 ** 2 + w2sum / s.shoe_gyro_sd_rad_s ** 2) / cnt


class StanceDetector:
    """Stance detection over a whole recording (vectorised); see the module docstring.

    ``StanceDetector(detector="song")`` or ``StanceDetector(StanceSettings(...), threshold=...)``.
    """

    def __init__(self, settings: StanceSettings | None = None, **overrides):
        s = settings or StanceSettings()
        self.settings = replace(s, **overrides) if overrides else s

    @property
    def threshold(self) -> float:
        return self.settings.threshold_value

    def detect(self, t_ns, acc_b, gyro_b) -> StanceResult:
        """Stance of every sample of simultaneous accelerometer and gyroscope rows."""
        t = np.asarray(t_ns, dtype=np.int64)
        stat = statistic(self.settings, t, acc_b, gyro_b)
        stat = np.where(np.isfinite(stat), stat, np.inf)  # a bad number is never stance
        return StanceResult(t, stat <= self.threshold, stat, self.threshold, self.settings.detector)

    def stream(self) -> "StanceStream":
        return StanceStream(self)


class StanceStream:
    """Streaming stance detection: :meth:`update` returns the decisions that became due.

    Each decision is ``(t_ns, stance, statistic)`` of a sample ``window_s / 2``
    in the past; :meth:`flush` decides the rest at the end.  The decisions are
    those of :meth:`StanceDetector.detect` on the whole stream.
    """

    def __init__(self, detector: StanceDetector):
        self.detector = detector
        self._half_ns = int(round(detector.settings.window_s * 0.5e9))
        self._buf: deque = deque()  # (t_ns, acc, gyro)
        self._next = 0  # index in _buf of the next sample to decide

    def update(self, t_ns: int, acc_b, gyro_b) -> list[tuple[int, bool, float]]:
        self._buf.append((int(t_ns), tuple(acc_b), tuple(gyro_b)))
        return self._decide(int(t_ns))

    def flush(self) -> list[tuple[int, bool, float]]:
        return self._decide(None)

    def _decide(self, t_now) -> list:
        out = []
        while self._next < len(self._buf):
            tk = self._buf[self._next][0]
            if t_now is not None and t_now < tk + self._half_ns:
                break
            # drop samples no window still needs
            while self._buf[0][0] < tk - self._half_ns:
                self._buf.popleft()
                self._next -= 1
            k = self._next
            m = len(self._buf)
            t = np.fromiter((b[0] for b in self._buf), dtype=np.int64, count=m)
            hi = np.searchsorted(t, tk + self._half_ns, side="right")
            acc = np.array([b[1] for b in list(self._buf)[:hi]])
            gyr = np.array([b[2] for b in list(self._buf)[:hi]])
            stat = float(statistic(self.detector.settings, t[:hi], acc, gyr)[k])
            if not math.isfinite(stat):
                stat = math.inf
            out.append((tk, stat <= self.detector.threshold, stat))
            self._next += 1
        return out


def infer_foot_axes(acc_b, gyro_b, still=None) -> dict:
    """The body axes of a foot-mounted IMU: ``vertical`` (along gravity when the foot is flat),
    ``lateral`` (the pitch axis: the other axis with the most rotation while walking) and ``forward``.

    ``still``: optional mask of samples taken as flat (default: the 20 % of
    samples with the lowest rotation rate).  Returns axis indices and the
    ``song`` detector's ``acc_axes`` / ``gyro_axes``.
    """
    acc = np.asarray(acc_b, dtype=float).reshape(-1, 3)
    gyr = np.asarray(gyro_b, dtype=float).reshape(-1, 3)
    rate = np.linalg.norm(gyr, axis=1)
    if still is None:
        still = rate <= np.quantile(rate, 0.2) if len(rate) else np.zeros(0, bool)
    g_mean = np.mean(acc[still], axis=0) if np.any(still) else np.mean(acc, axis=0)
    vertical = int(np.argmax(np.abs(g_mean)))
    others = [i for i in range(3) if i != vertical]
    energy = np.mean(gyr[:, others] ** 2, axis=0)
    lateral = others[int(np.argmax(energy))]
    forward = others[int(np.argmin(energy))]
    return {"vertical": vertical, "lateral": lateral, "forward": forward,
            "acc_axes": (forward, vertical), "gyro_axes": (forward, lateral)}
