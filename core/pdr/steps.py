"""Step detection on the acceleration norm (Tian et al. 2014, section 3, eqs. 2-3).

The norm of the accelerometer (eq. 2) is brought onto a uniform grid
(:class:`core.dsp.GridResampler`, so the detector behaves the same at any phone
rate from 20 to 400 Hz), smoothed by a second-order Butterworth low-pass
("a single peak curve", section 3), and every local maximum that passes the
two thresholds of eq. 3 is a step:

* ``dT > T_th``: at least ``min_step_interval_s`` since the previous step;
* ``|acc_norm - g| > A_th``: the peak rises ``min_peak_height_m_s2`` above
  the local gravity ``g``.

Two additions make it hold on real phones, where the paper's fixed ``g`` and
single peak test are fragile: ``g`` is a slow running mean of the norm (phone
accelerometers read 9.6-10.1 m/s^2 at rest), and after a step the signal must
fall back below ``g`` before the next peak can count (``require_valley``),
which removes the double peaks of a heel strike.

A_max and A_min of eq. 4 and the variance of the filtered norm over each step
are collected on the way for the stride model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from core.dsp import Biquad, GridResampler, butter2_group_delay_s, butter2_lowpass
from core.conventions import STANDARD_GRAVITY_M_S2


@dataclass(frozen=True)
class StepEvent:
    """A detected step, before its length and heading are known."""

    t_ns: int  #: time of the peak, corrected for the low-pass group delay (sensor clock)
    acc_max_m_s2: float  #: filtered norm at the peak
    acc_min_m_s2: float  #: lowest filtered norm since the previous step (or bout start)
    acc_var_m2_s4: float  #: variance of the filtered norm since the previous step
    duration_s: float  #: time since the previous step; nan for the first step of a walking bout
    gravity_m_s2: float  #: local gravity estimate used for the threshold


class StepDetector:
    """Peak-based step detector, streaming (:meth:`update`) or batch (:meth:`run`), one kernel.

    Parameters
    ----------
    grid_rate_hz : float
        Rate of the uniform grid the norm is resampled to (Hz).
    cutoff_hz : float
        Cut-off of the second-order Butterworth low-pass on the norm (Hz).
        Walking cadence is 1.4-2.5 steps/s; 3 Hz keeps the step wave and
        removes the jitter of the hand.
    min_step_interval_s : float
        ``T_th`` of eq. 3 (s): the shortest time between two steps (a fast
        run is about 3.3 steps/s).
    min_peak_height_m_s2 : float
        ``A_th`` of eq. 3 (m/s^2): how far a peak must rise above ``g``.
    max_step_interval_s : float
        A longer pause ends a walking bout: the next step has no duration.
    gravity_time_constant_s : float
        Time constant of the running mean of the norm that estimates ``g`` (s).
    require_valley : bool
        After a step, the next one counts only once the filtered norm has
        been below ``g`` again.
    """

    def __init__(self, *, grid_rate_hz: float = 50.0, cutoff_hz: float = 3.0, min_step_interval_s: float = 0.3,
                 min_peak_height_m_s2: float = 0.6, max_step_interval_s: float = 1.5,
                 gravity_time_constant_s: float = 3.0, require_valley: bool = True):
        self.grid_rate_hz = float(grid_rate_hz)
        self.cutoff_hz = float(cutoff_hz)
        self.min_step_interval_s = float(min_step_interval_s)
        self.min_peak_height_m_s2 = float(min_peak_height_m_s2)
        self.max_step_interval_s = float(max_step_interval_s)
        self.gravity_time_constant_s = float(gravity_time_constant_s)
        self.require_valley = bool(require_valley)
        self.reset()

    def reset(self) -> None:
        self.resampler = GridResampler(rate_hz=self.grid_rate_hz)
        b, a = butter2_lowpass(self.cutoff_hz, self.grid_rate_hz)
        self._lp = Biquad(b, a)
        self._alpha_g = 1.0 - math.exp(-1.0 / (self.grid_rate_hz * self.gravity_time_constant_s))
        self._min_dt_ns = int(self.min_step_interval_s * 1e9)
        # the low-pass delays the peak; steps are time-stamped at the unfiltered instant
        self._delay_ns = int(round(butter2_group_delay_s(self.cutoff_hz) * 1e9))
        self._max_dt_ns = int(self.max_step_interval_s * 1e9)
        self.gravity_m_s2 = STANDARD_GRAVITY_M_S2
        self._y1 = self._y2 = None  # last two filtered values
        self._t1 = 0
        self._last_step_ns: int | None = None
        self._armed = True
        self._seg_min = math.inf
        self._seg_sum = 0.0
        self._seg_sum2 = 0.0
        self._seg_n = 0
        #: number of grid samples processed
        self.n_grid = 0
        #: last grid sample ``(t_ns, raw norm, filtered norm)`` (diagnostics)
        self.last = (0, math.nan, math.nan)

    # -- streaming ----------------------------------------------------------
    def update(self, t_ns: int, ax: float, ay: float, az: float) -> list[StepEvent]:
        """Feed one accelerometer event (m/s^2); returns the steps it completes."""
        norm = math.sqrt(ax * ax + ay * ay + az * az)  # eq. 2
        steps = []
        for tg, x in self.resampler.update(t_ns, norm):
            if self.resampler.restarted and self.n_grid:
                self.restart_bout()
            ev = self.update_grid(tg, x)
            if ev is not None:
                steps.append(ev)
        return steps

    def restart_bout(self) -> None:
        """Forget the current walking bout (after a gap in the data)."""
        self._y1 = self._y2 = None
        self._last_step_ns = None
        self._armed = True
        self._seg_min = math.inf
        self._seg_sum = self._seg_sum2 = 0.0
        self._seg_n = 0

    def update_grid(self, t_ns: int, norm: float) -> StepEvent | None:
        """Process one sample of the uniform grid (the kernel shared by streaming and batch)."""
        if self._y1 is None:
            self._lp.reset(norm)
            if self.n_grid == 0:
                self.gravity_m_s2 = norm
        self.n_grid += 1
        g = self.gravity_m_s2 = self.gravity_m_s2 + self._alpha_g * (norm - self.gravity_m_s2)
        y = self._lp.step(norm)
        self.last = (t_ns, norm, y)
        event = None
        y1, y2 = self._y1, self._y2
        if y1 is not None and y2 is not None and y1 > y2 and y1 >= y:
            # local maximum at the previous grid sample
            t_peak = self._t1
            since = None if self._last_step_ns is None else t_peak - self._last_step_ns
            if (y1 - g > self.min_peak_height_m_s2  # eq. 3, amplitude threshold
                    and (since is None or since > self._min_dt_ns)  # eq. 3, time threshold
                    and self._armed):
                n = self._seg_n
                mean = self._seg_sum / n if n else y1
                var = max(self._seg_sum2 / n - mean * mean, 0.0) if n else 0.0
                acc_min = self._seg_min if self._seg_min < math.inf else y1
                duration = since * 1e-9 if since is not None and since <= self._max_dt_ns else math.nan
                event = StepEvent(t_peak - self._delay_ns, y1, acc_min, var, duration, g)
                self._last_step_ns = t_peak
                self._armed = not self.require_valley
                self._seg_min = math.inf
                self._seg_sum = self._seg_sum2 = 0.0
                self._seg_n = 0
        if y < g:
            self._armed = True
        if self._last_step_ns is not None and t_ns - self._last_step_ns > self._max_dt_ns:
            # a pause: forget the amplitude history of the last bout
            self._last_step_ns = None
            self._seg_min = math.inf
            self._seg_sum = self._seg_sum2 = 0.0
            self._seg_n = 0
        if y < self._seg_min:
            self._seg_min = y
        self._seg_sum += y
        self._seg_sum2 += y * y
        self._seg_n += 1
        self._y2, self._y1, self._t1 = y1, y, t_ns
        return event

    # -- batch --------------------------------------------------------------
    def run(self, t_ns, acc_b) -> list[StepEvent]:
        """Detect the steps of a whole accelerometer stream: ``t_ns`` (n,), ``acc_b`` (n, 3)."""
        self.reset()
        out: list[StepEvent] = []
        for t, (ax, ay, az) in zip(list(map(int, t_ns)), acc_b.tolist() if hasattr(acc_b, "tolist") else acc_b):
            out.extend(self.update(t, ax, ay, az))
        return out
