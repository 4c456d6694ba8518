"""Bridging a gap in the accelerometer alone with the gyroscope's gait rhythm (issue #30).

The steps are counted on the accelerometer: when it stops for minutes while
the gyroscope and the magnetometer run on (a driver that drops one sensor, a
logger that lost one stream), the walk across the gap is missing from the
track.  The attitude filter keeps running on gyroscope and magnetometer, so the
heading is still known; what is missing is how far the walker went.

A hand-held (or carried) phone turns with the gait: its rotation rate repeats
every stride (two steps; Tian et al. 2014's sway of the held phone, and any
carried phone's).  So, while the accelerometer is silent, the gyroscope is cut
into windows of ``window_s`` and each window is asked two questions:

* **energy**: is the RMS of its rotation rate, its mean removed (bias, slow
  turns), at least ``min_rotation_rms_rad_s``?  A phone held by a standing
  person drifts at a few hundredths of a rad/s; walking sways it ten times more;
* **periodicity**: does the normalised autocorrelation of the rotation vector
  peak at a stride lag near twice the step period of the steps before the
  gap (``stride_band``), with a peak of at least ``min_periodicity``?

A window that passes both is walking at the step period read off the peak
(half the stride lag).  A single failing window with the energy between two
walking ones (a corner turn breaks the rhythm for a second) counts as walking.
At the end of the gap (the accelerometer's next reading) the walking windows
become estimated steps: one every step period, each the mean length of the
last ``n_steps_before`` steps before the gap, heading the phone's forward axis
from the attitude filter averaged over the window.  The pipeline marks them
``estimated`` (:class:`core.pdr.pipeline.Step`), reports the gap with its
:class:`GapVerdict` and adds a label.

No steps are invented without evidence: a gap whose gyroscope shows no walking
adds nothing (:attr:`GapVerdict.STILL`); a gap without the attitude, without
steps before it to take the stride from, or longer than ``max_gap_s`` is
refused with its reason.  Memory: one window of gyroscope readings and a few
numbers per window of the gap.
"""

from __future__ import annotations

import math
from array import array
from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np


class GapVerdict(Enum):
    """What was done with an accelerometer gap."""

    BRIDGED = "bridged"  #: walking found in the gyroscope: estimated steps added
    STILL = "still"  #: the gyroscope shows no walking: nothing added
    NO_STRIDE = "no_stride"  #: walking, but no recent steps before the gap to take the step length from
    NO_ATTITUDE = "no_attitude"  #: the attitude filter had not started: no heading
    TOO_LONG = "too_long"  #: longer than the bridge's limit

    @property
    def reason(self) -> str:
        return _REASONS[self]


_REASONS = {
    GapVerdict.BRIDGED: "the gyroscope shows the walker kept walking: steps estimated from its rhythm and the "
                        "stride before the gap",
    GapVerdict.STILL: "the gyroscope shows no walking (no gait rhythm): no distance added",
    GapVerdict.NO_STRIDE: "the gyroscope shows walking but no steps in the minute before the gap give its stride: "
                          "the distance walked in it is missing",
    GapVerdict.NO_ATTITUDE: "the heading filter had not started: the distance walked in it is missing",
    GapVerdict.TOO_LONG: "too long to bridge from the gyroscope: the distance walked in it is missing",
}


@dataclass(slots=True)
class GapWindow:
    """One window of the gyroscope during an accelerometer gap."""

    t0_ns: int
    t1_ns: int
    rotation_rms_rad_s: float  #: RMS of the rotation rate, its window mean removed
    periodicity: float  #: the autocorrelation's peak in the stride band (-1..1; nan: not computed)
    step_period_s: float  #: half the stride lag at that peak (s)
    east: float  #: the phone's forward axis in ENU, summed over the window's heading samples
    north: float
    walking: bool = False


@dataclass(frozen=True)
class BridgedGap:
    """An accelerometer gap as the pipeline handled it (diagnostics as data)."""

    start_ns: int  #: the last accelerometer reading before the gap
    end_ns: int  #: the first one after
    verdict: GapVerdict
    n_steps: int  #: estimated steps added
    distance_m: float
    walking_s: float  #: time the gyroscope showed walking
    step_length_m: float  #: the length given to every estimated step (nan: none)
    step_period_s: float  #: the median step period of the walking windows (nan: none)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    def as_dict(self, t0_ns: int = 0) -> dict:
        return {"start_s": round((self.start_ns - t0_ns) * 1e-9, 3), "end_s": round((self.end_ns - t0_ns) * 1e-9, 3),
                "verdict": self.verdict.name, "n_steps": self.n_steps, "distance_m": round(self.distance_m, 3),
                "walking_s": round(self.walking_s, 3), "step_length_m": self.step_length_m,
                "step_period_s": self.step_period_s, "reason": self.verdict.reason}


@dataclass(frozen=True, slots=True)
class EstimatedStep:
    """A step the bridge places in the gap: its time, period and the phone's forward heading there."""

    t_ns: int
    period_s: float
    device_heading_rad: float  #: CCW from East, the phone's forward axis averaged over the window


class AccGapBridge:
    """Detect an accelerometer gap while the gyroscope runs, and bridge it where the gyroscope shows walking.

    Parameters
    ----------
    min_gap_s : float
        Gaps of the accelerometer at least this long are bridged or refused (s); shorter ones are left to the
        step detector's own restart.
    window_s : float
        The gyroscope's analysis window (s).
    min_rotation_rms_rad_s : float
        Energy a window needs to be walking: RMS rotation rate, its mean removed (rad/s).
    min_periodicity : float
        Normalised autocorrelation the window's stride peak needs (0..1).
    stride_band : (float, float)
        Where the stride lag is looked for, as multiples of twice the step period before the gap.
    n_steps_before : int
        Steps before the gap whose mean length and median period are used.
    max_step_age_s : float
        Those steps must end at most this long before the gap (s), else no stride is known.
    max_gap_s : float
        Longer gaps are refused (s).
    heading_interval_s : float
        Interval between samples of the phone's forward axis during the gap (s).
    """

    def __init__(self, *, min_gap_s: float = 2.0, window_s: float = 5.0, min_rotation_rms_rad_s: float = 0.08,
                 min_periodicity: float = 0.4, stride_band: tuple[float, float] = (0.7, 1.4),
                 n_steps_before: int = 10, max_step_age_s: float = 60.0, max_gap_s: float = 3600.0,
                 heading_interval_s: float = 0.1):
        self.min_gap_s = float(min_gap_s)
        self.window_s = float(window_s)
        self.min_rotation_rms_rad_s = float(min_rotation_rms_rad_s)
        self.min_periodicity = float(min_periodicity)
        self.stride_band = (float(stride_band[0]), float(stride_band[1]))
        self.n_steps_before = max(1, int(n_steps_before))
        self.max_step_age_s = float(max_step_age_s)
        self.max_gap_s = float(max_gap_s)
        self.heading_interval_s = float(heading_interval_s)
        self.reset()

    def reset(self) -> None:
        #: the gap detection threshold, ns (read by the pipeline on every gyroscope event)
        self.min_gap_ns = int(self.min_gap_s * 1e9)
        self._window_ns = int(self.window_s * 1e9)
        self._heading_ns = int(self.heading_interval_s * 1e9)
        #: the last steps before now: (t_ns, length_m, period_s)
        self._recent: deque = deque(maxlen=self.n_steps_before)
        #: whether a gap is open (the accelerometer late by min_gap_s while the gyroscope runs)
        self.open = False
        self._start_ns = 0
        self._windows: list[GapWindow] = []
        self._w_t0 = 0
        self._wt = array("q")
        self._wv = array("d")
        self._h_e = 0.0
        self._h_n = 0.0
        self._h_next = 0
        self._period_before = math.nan
        self._gyro_max_gap_ns = 0  # the longest gyroscope interval in the gap
        self._gyro_last_ns = 0
        #: every gap handled so far
        self.gaps: list[BridgedGap] = []

    # -- fed by the pipeline ------------------------------------------------------------------------------
    def note_step(self, t_ns: int, length_m: float, period_s: float) -> None:
        """A completed step (the stride and cadence a later gap takes)."""
        self._recent.append((t_ns, length_m, period_s))

    def gyro(self, t_ns: int, wx: float, wy: float, wz: float, last_acc_ns: int, prev_gyro_ns: int) -> None:
        """A gyroscope reading at ``t_ns`` (the one before at ``prev_gyro_ns``) while the accelerometer's last
        reading is ``last_acc_ns`` (the caller gives :meth:`heading` samples when :meth:`wants_heading`)."""
        if not self.open:
            self.open = True
            self._start_ns = last_acc_ns
            self._gyro_max_gap_ns = 0
            self._windows = []
            self._w_t0 = t_ns
            self._wt, self._wv = array("q"), array("d")
            self._h_e = self._h_n = 0.0
            self._h_next = t_ns
            recent = [p for t, _, p in self._recent if p == p]
            self._period_before = float(np.median(recent)) if recent else math.nan
        self._gyro_max_gap_ns = max(self._gyro_max_gap_ns, t_ns - prev_gyro_ns)
        self._gyro_last_ns = t_ns
        if t_ns - self._w_t0 >= self._window_ns:
            self._close_window(t_ns)
        self._wt.append(t_ns)
        self._wv.extend((wx, wy, wz))

    def wants_heading(self, t_ns: int) -> bool:
        return self.open and t_ns >= self._h_next

    def heading(self, t_ns: int, east: float, north: float) -> None:
        """The phone's forward axis in ENU (its horizontal part) at ``t_ns``, during the gap."""
        if east == east and north == north:
            self._h_e += east
            self._h_n += north
        self._h_next = t_ns + self._heading_ns

    def close(self, end_ns: int, attitude_started: bool) -> tuple[BridgedGap | None, list[EstimatedStep], float]:
        """The accelerometer is back at ``end_ns``: the gap's verdict, the estimated steps and their length.

        Returns ``(None, [], nan)`` for a gap shorter than ``min_gap_s`` or one the gyroscope did not run through
        (it stopped for ``min_gap_s`` or more too: a pause of the whole phone, not of the accelerometer alone)."""
        self.open = False
        start = self._start_ns
        if self._wt:
            self._close_window(end_ns)
        windows, self._windows = self._windows, []
        ran = max(self._gyro_max_gap_ns, end_ns - self._gyro_last_ns) < self.min_gap_ns
        if end_ns - start < self.min_gap_ns or not ran:
            return None, [], math.nan
        if len(windows) > 1 and windows[-1].t1_ns - windows[-1].t0_ns < self._window_ns:
            last = windows.pop()  # a short last window is too short for its rhythm: it extends the one before
            windows[-1].t1_ns = last.t1_ns
            windows[-1].east += last.east
            windows[-1].north += last.north
        if windows:  # the windows cover the whole gap: the first from the last acc reading, the last to the next
            windows[0].t0_ns = start
            windows[-1].t1_ns = end_ns
        self._mark_walking(windows)
        walking_s = sum((w.t1_ns - w.t0_ns) * 1e-9 for w in windows if w.walking)
        recent = [(t, L) for t, L, _ in self._recent if start - t <= self.max_step_age_s * 1e9]
        length = float(np.mean([L for _, L in recent])) if recent else math.nan
        periods = [w.step_period_s for w in windows if w.walking]
        period = float(np.median(periods)) if periods else math.nan
        if (end_ns - start) * 1e-9 > self.max_gap_s:
            verdict = GapVerdict.TOO_LONG
        elif not walking_s:
            verdict = GapVerdict.STILL
        elif not attitude_started:
            verdict = GapVerdict.NO_ATTITUDE
        elif not recent:
            verdict = GapVerdict.NO_STRIDE
        else:
            verdict = GapVerdict.BRIDGED
        steps = self._steps(windows) if verdict is GapVerdict.BRIDGED else []
        gap = BridgedGap(start, end_ns, verdict, len(steps), len(steps) * length if steps else 0.0, walking_s,
                         length if verdict is GapVerdict.BRIDGED else math.nan, period)
        self.gaps.append(gap)
        self._recent.clear()  # the stride after the gap is the walk after it
        return gap, steps, length

    def abandon(self) -> None:
        """The recording ended inside the gap: nothing is bridged (there is no end to bridge to)."""
        self.open = False
        self._windows = []
        self._wt, self._wv = array("q"), array("d")

    # -- the analysis -------------------------------------------------------------------------------------
    def _close_window(self, t_ns: int) -> None:
        t = np.frombuffer(self._wt, dtype=np.int64)
        v = np.frombuffer(self._wv, dtype=np.float64).reshape(-1, 3)
        rms, rho, period = self.rhythm(t, v, self._period_before)
        self._windows.append(GapWindow(self._w_t0, t_ns, rms, rho, period, self._h_e, self._h_n))
        self._w_t0 = t_ns
        self._wt, self._wv = array("q"), array("d")
        self._h_e = self._h_n = 0.0

    def rhythm(self, t_ns: np.ndarray, w: np.ndarray, step_period_s: float) -> tuple[float, float, float]:
        """``(rms, periodicity, step period)`` of the rotation rates ``w`` (n, 3) at times ``t_ns``.

        The rotation's RMS with its mean removed; the normalised autocorrelation of the rotation vector,
        ``sum w_i . w_(i+L) / sqrt(sum |w_i|^2 sum |w_(i+L)|^2)``, at its highest in the stride band around
        ``2 step_period_s``; half that lag, refined by a parabola through the peak.
        """
        n = len(t_ns)
        if n < 8:
            return 0.0, math.nan, math.nan
        x = w - w.mean(axis=0)
        rms = float(math.sqrt(float(np.mean(np.sum(x * x, axis=1)))))
        if not step_period_s == step_period_s or step_period_s <= 0:
            return rms, math.nan, math.nan
        dt = (int(t_ns[-1]) - int(t_ns[0])) * 1e-9 / (n - 1)
        lo = max(1, int(math.floor(self.stride_band[0] * 2 * step_period_s / dt)))
        hi = min(n // 2, int(math.ceil(self.stride_band[1] * 2 * step_period_s / dt)) + 1)
        if hi - lo < 3:
            return rms, math.nan, math.nan
        e = np.sum(x * x, axis=1)
        c = np.cumsum(e)
        r = np.empty(hi + 1 - lo + 1)
        for k, lag in enumerate(range(lo - 1, hi + 1)):
            num = float(np.sum(x[:-lag] * x[lag:])) if lag else float(c[-1])
            den = math.sqrt(float(c[n - 1 - lag]) * float(c[-1] - (c[lag - 1] if lag else 0.0)))
            r[k] = num / den if den > 0 else 0.0
        k = int(np.argmax(r[1:-1])) + 1
        peak = float(r[k])
        a, b, cc = float(r[k - 1]), peak, float(r[k + 1])
        den = a - 2 * b + cc
        frac = 0.5 * (a - cc) / den if den < 0 else 0.0
        lag_s = (lo - 1 + k + max(-0.5, min(0.5, frac))) * dt
        return rms, peak, 0.5 * lag_s

    def _mark_walking(self, windows: list[GapWindow]) -> None:
        for w in windows:
            w.walking = (w.rotation_rms_rad_s >= self.min_rotation_rms_rad_s
                         and w.periodicity == w.periodicity and w.periodicity >= self.min_periodicity)
        for i in range(1, len(windows) - 1):  # a corner breaks the rhythm for a window
            w = windows[i]
            if (not w.walking and windows[i - 1].walking and windows[i + 1].walking
                    and w.rotation_rms_rad_s >= self.min_rotation_rms_rad_s):
                w.walking = True
                w.step_period_s = 0.5 * (windows[i - 1].step_period_s + windows[i + 1].step_period_s)

    @staticmethod
    def _steps(windows: list[GapWindow]) -> list[EstimatedStep]:
        """One step every step period through the walking windows; the phase carries over between them."""
        out = []
        phase = 0.0  # fraction of a step walked so far
        for w in windows:
            if not w.walking:
                phase = 0.0
                continue
            p = w.step_period_s
            dur = (w.t1_ns - w.t0_ns) * 1e-9
            heading = math.atan2(w.north, w.east) if (w.east or w.north) else math.nan
            k = 1.0 - phase
            while k * p <= dur:
                out.append(EstimatedStep(w.t0_ns + int(round(k * p * 1e9)), p, heading))
                k += 1.0
            phase = (dur / p + phase) % 1.0
        # a window without heading samples takes its neighbour's
        last = math.nan
        fixed = []
        for s in out:
            h = s.device_heading_rad if s.device_heading_rad == s.device_heading_rad else last
            last = h
            fixed.append(EstimatedStep(s.t_ns, s.period_s, h))
        return fixed


def acc_gaps_with_gyro(acc_t_ns, gyro_t_ns, min_gap_s: float) -> int:
    """How many intervals between accelerometer readings are at least ``min_gap_s`` long with the gyroscope running
    through them (no interval of ``[gap start, its readings inside, gap end]`` of ``min_gap_s`` or more): every gap
    :class:`AccGapBridge` judges is one of them (the fast path refuses recordings that have any)."""
    a = np.asarray(acc_t_ns, dtype=np.int64)
    g = np.asarray(gyro_t_ns, dtype=np.int64)
    if len(a) < 2 or not len(g):
        return 0
    lim = int(min_gap_s * 1e9)
    n = 0
    for k in np.flatnonzero(np.diff(a) >= lim).tolist():
        lo, hi = int(a[k]), int(a[k + 1])
        inside = g[np.searchsorted(g, lo, side="right"):np.searchsorted(g, hi, side="left")]
        if len(inside) and int(np.max(np.diff(np.concatenate(([lo], inside, [hi]))))) < lim:
            n += 1
    return n
