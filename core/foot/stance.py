"""Stance (zero-velocity) detection for a foot-mounted IMU.

Four detectors, selectable by name, all on a window defined in **seconds**,
so a setting means the same at 100 and at 400 Hz.  The window is centred on
the sample (samples with ``|t_j - t_k| <= window_s / 2``) or trailing
(``t_k - window_s <= t_j <= t_k``, the paper's ``k - k0 .. k``;
``window_alignment``).  Each gives a statistic per sample; the sample is
stance when the statistic is at most the threshold.

``"song"`` -- Song & Park 2018, eqs. 1-6, as written
    With ``a_x, a_z`` two accelerometer axes **in g** (the readings divided by
    ``song_acc_unit_m_s2``, standard gravity) and ``w_x, w_y`` two gyroscope
    axes in rad/s (the paper's; :func:`infer_foot_axes` finds them on any mounting)::

        E_a = Var(sqrt(a_x^2 + a_z^2))          (eq. 1)
        P_a = Var(a_x a_z)                       (eq. 2)
        S_a = Var(a_x + a_z)                     (eq. 3)
        E_r = Var(sqrt(w_x^2 + w_y^2))           (eq. 4)
        A_r = sqrt(w_x(k)^2 + w_y(k)^2)          (eq. 5, this sample only)
        J   = max(w1 E_a, w2 P_a, w3 S_a, w4 E_r, w5 A_r)   (eq. 6; stance: J <= 1)

    Weights ``w = (50, 100, 100, 3, 5)`` and the threshold 1 as in the paper;
    its window is ``k - k0 .. k`` with ``k0`` = 15 samples at 100 Hz: trailing,
    ``window_s = 0.15`` (``window_alignment="auto"`` is trailing for "song").
    The variances are population variances over the window.  (Read in SI
    units, m/s^2, the acceleration terms are ``g^2`` to ``g^4`` times larger and
    decide alone: an earlier version did that, with a threshold of 100.)
``"shoe"`` -- the stance hypothesis optimal detector (SHOE, generalised likelihood ratio; Skog et al. 2010)::

        T = 1/W sum_k ( |a_k - g a_mean/|a_mean||^2 / sigma_a^2 + |w_k|^2 / sigma_w^2 )   (dimensionless)
``"learned"`` -- a learned stance probability (:mod:`core.foot.stance_model`, issue #27)
    ``T = 1 - p(stance)`` of a logistic regression on about 1 s of samples around k (the
    model file ``StanceSettings.model``); stance when ``T <= 1 - threshold_p`` of the file.
``"amv"`` -- acceleration moving variance: ``T = 1/W sum_k |a_k - a_mean|^2`` ((m/s^2)^2)
``"are"`` -- angular rate energy: ``T = 1/W sum_k |w_k|^2`` ((rad/s)^2)

Adaptive threshold (``adaptive_floor_factor > 0`` or ``adaptive_ceiling_ratio > 0``; both the default for
"shoe", :data:`DEFAULT_FLOOR_FACTORS`, :data:`DEFAULT_CEILING_RATIOS`): the threshold of sample k is
``max(threshold, adaptive_floor_factor * floor_k, adaptive_ceiling_ratio * ceiling_k)`` where ``floor_k``
and ``ceiling_k`` are the minimum and the maximum of the statistic (in its own units) over
``adaptive_floor_window_s`` around k: centred (``|t_j - t_k| <= window / 2``, for replays) or trailing
(``t_k - window <= t_j <= t_k``, causal, ``adaptive_floor_causal``).  When
running, the foot is never as still as in a walking stance: the statistic's
floor rises by orders of magnitude and a fixed threshold finds no stance; a
threshold relative to the floor follows it, while in walking (floor far below
``threshold / factor``) nothing changes.  The ceiling is the swing's peak (for SHOE
about ``|w|^2 / sigma_w^2`` at the stride's peak angular rate): a stride swung harder lands harder, its
stance rings and rolls more, and the threshold rises with it (issue #27: a threshold that follows the
stride's own intensity instead of one per trial); a gentle stride keeps the fixed threshold.

Batch (:meth:`StanceDetector.detect`) works on whole arrays with cumulative
sums and a sparse table for the moving minimum and maximum (O(n log n), no Python loop
per sample).  Streaming (:class:`StanceStream`) buffers what the windows need
and calls the same kernels on the buffer, so it decides each sample
:attr:`StanceDetector.delay_s` late (the look-ahead of the statistic's window,
``window_s / 2`` centred and 0 trailing, plus the floor's, ``adaptive_floor_window_s
/ 2`` centred and 0 causal) and gives the same result.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from core.conventions import STANDARD_GRAVITY_M_S2
from core.foot.stance_model import DEFAULT_MODEL, load_model, motion_probability

DETECTORS = ("song", "shoe", "amv", "are", "learned")
WINDOW_ALIGNMENTS = ("auto", "centred", "trailing")

#: default threshold of each detector: "song" the paper's J <= 1; the others chosen on the PyShoe tuning
#: split with window_s = 0.1 (see docs/foot.md; "shoe" 1e5 until the stride-peak ceiling, 3e4 with it);
#: "learned": nan, ``1 - threshold_p`` of its model file
DEFAULT_THRESHOLDS = {"song": 1.0, "shoe": 3.0e4, "amv": 0.02, "are": 0.2, "learned": math.nan}

#: default adaptive-threshold factor of each detector (0 = fixed threshold): "shoe" chosen on the PyShoe
#: tuning split (factor 2 with a 1.2 s window: mean 3-D RMSE of the 14 tuning trials 1.19 -> 0.11 m, the
#: running trial 2017-11-27-11-11-53 15.1 -> 0.22 m, the walking trials unchanged); the others untuned, fixed
DEFAULT_FLOOR_FACTORS = {"song": 0.0, "shoe": 2.0, "amv": 0.0, "are": 0.0, "learned": 0.0}

#: default ratio of the threshold to the statistic's moving maximum (the stride's swing peak; 0 = off):
#: "shoe" chosen on the PyShoe tuning split with the threshold 3e4 (PyShoe's metric, median / mean of the 14
#: trials, RTS replay 0.0366 / 0.0396 -> 0.0361 / 0.0384 m, forward filter 0.053 / 0.054 -> 0.045 / 0.052 m;
#: ratio 0.007 / 0.015: 0.0358 / 0.0383, 0.0396 / 0.0394; docs/foot.md); the others untuned, off
DEFAULT_CEILING_RATIOS = {"song": 0.0, "shoe": 0.01, "amv": 0.0, "are": 0.0, "learned": 0.0}

#: eq. 6 weights (w1 .. w5) of the paper
SONG_WEIGHTS = (50.0, 100.0, 100.0, 3.0, 5.0)


@dataclass(frozen=True)
class StanceSettings:
    """Settings of :class:`StanceDetector` (units in the names)."""

    #: one of :data:`DETECTORS`
    detector: str = "shoe"
    #: width of the window (s); the paper's is 15 samples at 100 Hz (0.15 s), the tuned default 0.1 s
    window_s: float = 0.1
    #: "centred", "trailing" or "auto" (trailing for "song" as in the paper, centred for the others)
    window_alignment: str = "auto"
    #: stance when the statistic <= threshold; nan: the detector's entry of :data:`DEFAULT_THRESHOLDS`
    threshold: float = math.nan
    #: adaptive threshold: ``max(threshold, factor * moving minimum of the statistic)``; 0 = off; nan: the
    #: detector's entry of :data:`DEFAULT_FLOOR_FACTORS`
    adaptive_floor_factor: float = math.nan
    #: ... and at least this ratio times the moving maximum of the statistic (the stride's swing peak, its
    #: own units per the statistic's units); 0 = off; nan: the detector's entry of :data:`DEFAULT_CEILING_RATIOS`
    adaptive_ceiling_ratio: float = math.nan
    #: the window of that moving minimum and maximum (s)
    adaptive_floor_window_s: float = 1.2
    #: the moving minimum and maximum over the trailing window (causal, for live use) instead of the centred one
    adaptive_floor_causal: bool = False
    #: "song": eq. 6 weights
    song_weights: tuple = SONG_WEIGHTS
    #: "song": the paper's acceleration unit, g (m/s^2 per unit)
    song_acc_unit_m_s2: float = STANDARD_GRAVITY_M_S2
    #: "song": the accelerometer axes playing the paper's x (forward) and z (vertical)
    acc_axes: tuple = (0, 2)
    #: "song": the gyroscope axes playing the paper's x and y (the two not about the vertical)
    gyro_axes: tuple = (0, 1)
    #: "shoe": accelerometer and gyroscope noise (m/s^2, rad/s) of the likelihood ratio
    shoe_acc_sd_m_s2: float = 0.01
    shoe_gyro_sd_rad_s: float = math.radians(0.1)
    #: "shoe": gravity magnitude (m/s^2)
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2
    #: "learned": the model file (a name in ``core/foot/models/`` or a path to a ``.json``)
    model: str = DEFAULT_MODEL

    def __post_init__(self):
        if self.detector not in DETECTORS:
            raise ValueError(f"unknown stance detector {self.detector!r}: one of {', '.join(DETECTORS)}")
        if not (self.window_s > 0 and math.isfinite(self.window_s)):
            raise ValueError(f"window_s must be a positive number, not {self.window_s!r}")
        if self.window_alignment not in WINDOW_ALIGNMENTS:
            raise ValueError(f"unknown window_alignment {self.window_alignment!r}: one of "
                             f"{', '.join(WINDOW_ALIGNMENTS)}")
        if not (math.isnan(self.adaptive_floor_factor)
                or (self.adaptive_floor_factor >= 0 and math.isfinite(self.adaptive_floor_factor))):
            raise ValueError(f"adaptive_floor_factor must be >= 0, not {self.adaptive_floor_factor!r}")
        r = self.adaptive_ceiling_ratio
        if not (math.isnan(r) or (r >= 0 and math.isfinite(r))):
            raise ValueError(f"adaptive_ceiling_ratio must be >= 0, not {r!r}")
        if self.adaptive and not (self.adaptive_floor_window_s > 0):
            raise ValueError(f"adaptive_floor_window_s must be positive, not {self.adaptive_floor_window_s!r}")

    @property
    def threshold_value(self) -> float:
        if not math.isnan(self.threshold):
            return float(self.threshold)
        if self.detector == "learned":
            return 1.0 - load_model(self.model).threshold_p
        return DEFAULT_THRESHOLDS[self.detector]

    @property
    def floor_factor(self) -> float:
        """The adaptive threshold's factor in use (0: a fixed threshold)."""
        f = self.adaptive_floor_factor
        return DEFAULT_FLOOR_FACTORS[self.detector] if math.isnan(f) else float(f)

    @property
    def ceiling_ratio(self) -> float:
        """The stride-peak ratio of the adaptive threshold in use (0: none)."""
        r = self.adaptive_ceiling_ratio
        return DEFAULT_CEILING_RATIOS[self.detector] if math.isnan(r) else float(r)

    @property
    def adaptive(self) -> bool:
        """Whether the threshold moves with the statistic (its floor, its ceiling or both)."""
        return self.floor_factor > 0 or self.ceiling_ratio > 0

    @property
    def trailing(self) -> bool:
        """Whether the statistic's window is trailing (``k - k0 .. k``) rather than centred."""
        if self.window_alignment == "auto":
            return self.detector == "song"
        return self.window_alignment == "trailing"

    def statistic_span_ns(self) -> tuple[int, int]:
        """``(back, ahead)``: how far (ns) the statistic's window reaches before and after its sample."""
        if self.detector == "learned":  # the model's features reach this far each side (window_s unused)
            h = int(round(load_model(self.model).feature_settings.span_s * 1e9))
            return (h, h)
        w = int(round(self.window_s * 1e9))
        return (w, 0) if self.trailing else (w // 2, w // 2)

    def floor_span_ns(self) -> tuple[int, int]:
        """``(back, ahead)`` of the adaptive threshold's moving minimum and maximum ((0, 0) when off)."""
        if not self.adaptive:
            return (0, 0)
        w = int(round(self.adaptive_floor_window_s * 1e9))
        return (w, 0) if self.adaptive_floor_causal else (w // 2, w // 2)

    @property
    def delay_s(self) -> float:
        """How late (s) a streaming decision comes: the look-ahead of the two windows."""
        return (self.statistic_span_ns()[1] + self.floor_span_ns()[1]) * 1e-9


@dataclass
class StanceResult:
    """Per-sample stance decision and the statistic behind it."""

    t_ns: np.ndarray
    stance: np.ndarray  #: bool (n,)
    statistic: np.ndarray  #: (n,), stance where <= threshold
    threshold: float  #: the fixed threshold (the adaptive one's lower bound)
    detector: str
    #: (n,) the threshold of every sample (the fixed one, or the adaptive one)
    thresholds: np.ndarray | None = None
    #: (n,) int8 :class:`ThresholdSource`: which bound set each sample's threshold
    threshold_source: np.ndarray | None = None

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


def _window_bounds(t_ns: np.ndarray, back_ns: int, ahead_ns: int):
    """Index range ``[lo, hi)`` of the samples with ``t_k - back <= t_j <= t_k + ahead`` for each sample k."""
    t = np.asarray(t_ns, dtype=np.int64)
    lo = np.searchsorted(t, t - back_ns, side="left")
    hi = np.searchsorted(t, t + ahead_ns, side="right")
    return lo, hi


def window_min(x, lo, hi) -> np.ndarray:
    """Minimum of ``x`` (n,) over each window ``[lo, hi)`` (non-empty), by a sparse table: O(n log n)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n == 0:
        return np.zeros(0)
    lo = np.asarray(lo, dtype=np.int64)
    length = np.asarray(hi, dtype=np.int64) - lo
    level = np.floor(np.log2(np.maximum(length, 1))).astype(np.int64)
    out = np.empty(n)
    table = x
    for j in range(int(level.max()) + 1):
        m = level == j
        if np.any(m):
            out[m] = np.minimum(table[lo[m]], table[lo[m] + length[m] - (1 << j)])
        half = 1 << j
        if len(table) > half:
            table = np.minimum(table[:-half], table[half:])  # min over [i, i + 2^(j+1))
    return out


class ThresholdSource(IntEnum):
    """Which bound set a sample's threshold (:attr:`StanceResult.threshold_source`)."""

    FIXED = 0  #: the fixed threshold
    FLOOR = 1  #: ``adaptive_floor_factor`` times the moving minimum (a foot never quite still: running)
    CEILING = 2  #: ``adaptive_ceiling_ratio`` times the moving maximum (a stride swung hard)


def threshold_parts(settings: "StanceSettings", t_ns, stat) -> tuple[np.ndarray, np.ndarray]:
    """The threshold of every sample, ``max(threshold, factor * moving minimum, ratio * moving maximum)``
    (the fixed one when not adaptive), and which of the three set it (:class:`ThresholdSource`, int8)."""
    s = settings
    stat = np.asarray(stat, dtype=float)
    base = np.full(len(stat), s.threshold_value)
    source = np.full(len(stat), ThresholdSource.FIXED, dtype=np.int8)
    if not s.adaptive or len(stat) == 0:
        return base, source
    lo, hi = _window_bounds(t_ns, *s.floor_span_ns())
    thr = base
    if s.floor_factor > 0:
        floor = s.floor_factor * window_min(stat, lo, hi)
        source[floor > thr] = ThresholdSource.FLOOR
        thr = np.maximum(thr, floor)
    if s.ceiling_ratio > 0:
        finite = np.where(np.isfinite(stat), stat, -np.inf)  # a bad sample (inf) is no swing peak
        ceiling = s.ceiling_ratio * -window_min(-finite, lo, hi)
        source[ceiling > thr] = ThresholdSource.CEILING
        thr = np.maximum(thr, ceiling)
    return thr, source


def thresholds(settings: "StanceSettings", t_ns, stat) -> np.ndarray:
    """The threshold of every sample (:func:`threshold_parts` without the sources)."""
    return threshold_parts(settings, t_ns, stat)[0]


def _wsum(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Window sums of ``x`` (n,) or (n, k) over ``[lo, hi)``."""
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)], axis=0)
    return c[hi] - c[lo]


def _wvar(x, lo, hi, count):
    """Population variance of ``x`` (n,) over each window (never negative)."""
    x0 = x - x[0] if len(x) else x  # shifted: the cumulative sums stay small
    m = _wsum(x0, lo, hi) / count
    return np.maximum(_wsum(x0 * x0, lo, hi) / count - m * m, 0.0)


def _song_terms(s: StanceSettings, acc, gyr, lo, hi, cnt) -> np.ndarray:
    ix, iz = s.acc_axes
    gx, gy = s.gyro_axes
    ax, az = acc[:, ix] / s.song_acc_unit_m_s2, acc[:, iz] / s.song_acc_unit_m_s2  # in g, as the paper
    wr = np.sqrt(gyr[:, gx] ** 2 + gyr[:, gy] ** 2)
    w1, w2, w3, w4, w5 = s.song_weights
    return np.column_stack([
        w1 * _wvar(np.sqrt(ax * ax + az * az), lo, hi, cnt),  # eq. 1
        w2 * _wvar(ax * az, lo, hi, cnt),  # eq. 2
        w3 * _wvar(ax + az, lo, hi, cnt),  # eq. 3
        w4 * _wvar(wr, lo, hi, cnt),  # eq. 4
        w5 * wr,  # eq. 5
    ])


def song_terms(settings: StanceSettings, t_ns, acc_b, gyro_b) -> np.ndarray:
    """The five weighted terms of eq. 6 per sample, ``(n, 5)``: ``w1 E_a, w2 P_a, w3 S_a, w4 E_r, w5 A_r``
    (their maximum is the "song" statistic ``J``)."""
    acc = np.asarray(acc_b, dtype=float).reshape(-1, 3)
    gyr = np.asarray(gyro_b, dtype=float).reshape(-1, 3)
    if len(acc) == 0:
        return np.zeros((0, 5))
    lo, hi = _window_bounds(t_ns, *settings.statistic_span_ns())
    return _song_terms(settings, acc, gyr, lo, hi, (hi - lo).astype(float))


def statistic(settings: StanceSettings, t_ns, acc_b, gyro_b) -> np.ndarray:
    """The detector statistic of every sample (the kernel of batch and streaming detection)."""
    s = settings
    acc = np.asarray(acc_b, dtype=float).reshape(-1, 3)
    gyr = np.asarray(gyro_b, dtype=float).reshape(-1, 3)
    n = len(acc)
    if n == 0:
        return np.zeros(0)
    if s.detector == "learned":
        return motion_probability(load_model(s.model), t_ns, acc, gyr)
    lo, hi = _window_bounds(t_ns, *s.statistic_span_ns())
    cnt = (hi - lo).astype(float)
    if s.detector == "song":
        return np.max(_song_terms(s, acc, gyr, lo, hi, cnt), axis=1)  # eq. 6
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
        thr, source = threshold_parts(self.settings, t, stat)
        return StanceResult(t, stat <= thr, stat, self.threshold, self.settings.detector, thr, source)

    @property
    def delay_s(self) -> float:
        """How late a streaming decision comes (s): :attr:`StanceSettings.delay_s`."""
        return self.settings.delay_s

    def stream(self) -> "StanceStream":
        return StanceStream(self)


class StanceStream:
    """Streaming stance detection: :meth:`update` returns the decisions that became due.

    Each decision is ``(t_ns, stance, statistic, threshold)`` of a sample :attr:`StanceDetector.delay_s`
    in the past; :meth:`flush` decides the rest at the end.  The decisions are
    those of :meth:`StanceDetector.detect` on the whole stream: the statistic of
    a sample is computed by :func:`statistic` on the buffered samples its window
    covers, the adaptive threshold by :func:`thresholds` on the buffered statistics.
    """

    def __init__(self, detector: StanceDetector):
        self.detector = detector
        s = detector.settings
        self._back, self._ahead = s.statistic_span_ns()
        self._fback, self._fahead = s.floor_span_ns()
        self._buf: deque = deque()  # (t_ns, acc, gyro)
        self._next = 0  # index in _buf of the next sample whose statistic is due
        self._stats: deque = deque()  # (t_ns, statistic) known
        self._dnext = 0  # index in _stats of the next sample to decide

    def update(self, t_ns: int, acc_b, gyro_b) -> list[tuple[int, bool, float, float]]:
        self._buf.append((int(t_ns), tuple(acc_b), tuple(gyro_b)))
        self._statistics(int(t_ns))
        return self._decide(int(t_ns) - self._ahead)

    def flush(self) -> list[tuple[int, bool, float, float]]:
        self._statistics(None)
        return self._decide(None)

    def _statistics(self, t_now) -> None:
        s = self.detector.settings
        while self._next < len(self._buf):
            tk = self._buf[self._next][0]
            if t_now is not None and t_now < tk + self._ahead:
                break
            while self._buf[0][0] < tk - self._back:  # drop samples no window still needs
                self._buf.popleft()
                self._next -= 1
            k = self._next
            t = np.fromiter((b[0] for b in self._buf), dtype=np.int64, count=len(self._buf))
            hi = int(np.searchsorted(t, tk + self._ahead, side="right"))
            rows = list(self._buf)[:hi]
            stat = float(statistic(s, t[:hi], [b[1] for b in rows], [b[2] for b in rows])[k])
            self._stats.append((tk, stat if math.isfinite(stat) else math.inf))
            self._next += 1

    def _decide(self, t_known) -> list:
        """Decide the samples whose floor window lies within the statistics known (up to ``t_known``)."""
        s = self.detector.settings
        thr0 = self.detector.threshold
        out = []
        st = self._stats
        while self._dnext < len(st):
            tk, stat = st[self._dnext]
            if t_known is not None and t_known < tk + self._fahead:
                break
            while st[0][0] < tk - self._fback:
                st.popleft()
                self._dnext -= 1
            thr = thr0
            if s.adaptive:
                win = [v for tj, v in st if tj <= tk + self._fahead]
                if s.floor_factor > 0:
                    thr = max(thr, s.floor_factor * min(win))
                if s.ceiling_ratio > 0:
                    thr = max(thr, s.ceiling_ratio * max((v for v in win if math.isfinite(v)), default=-math.inf))
            out.append((tk, stat <= thr, stat, thr))
            self._dnext += 1
        if not s.adaptive:  # no floor window: keep nothing
            while self._dnext > 0:
                st.popleft()
                self._dnext -= 1
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
