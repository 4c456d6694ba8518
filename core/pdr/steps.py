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

Gates per carry mode (issue #17, :data:`STEP_GATES`, chosen by the pipeline
from :class:`core.pdr.carry.CarryModeDetector`).  The settings above suit a
phone coupled to the trunk (hand-held, at the ear, in a bag), whose norm
repeats every step.  A phone on a limb sees the two half-strides differently:
in a trouser pocket the near leg's heel strike is much stronger than the far
leg's, in a swinging hand the arm is forward at one step and back at the next.
The norm then carries a strong component at the stride frequency (half the
step frequency): every other peak may stay below ``A_th``, every other valley
above ``g`` (the valley test then drops a step), and the weak half-stride's
shape can add a spurious peak.  Two gates answer it, on for ``swinging`` (and
available for ``pocket``, :data:`POCKET_GATES`, not the default: see :data:`STEP_GATES`):

* **stride comb** (``stride_comb``): the norm is averaged with itself one step
  period earlier, ``x'(t) = (x(t) + x(t - T_step)) / 2`` (``T_step`` from the
  carry detector's autocorrelation).  A component at the stride frequency is
  shifted by half its period and cancels; the step-frequency component and its
  harmonics are shifted by whole periods and pass unchanged, in phase (no delay
  at the step frequency).  The two legs' peaks become equal;
* **cadence gate** (``min_interval_period_frac``): a peak closer than this
  fraction of ``T_step`` to the previous step is not a step (the gait's
  cadence changes little from one step to the next; the spurious peak of a
  half-stride comes early).  Also available for ``bag`` (:data:`BAG_GATES`): a
  bag or pouch hangs on a strap and bounces at its own 3-6 Hz, which can put a
  second peak in a step.

The comb's echo: when the walk stops, the last step comes out of the comb a
second time, at half its height, one period later.  **Echo gate**
(``min_raw_range_m_s2``): a peak counts only if the raw norm itself varied
that much (max - min) in the last half period: the echo falls on a quiet
signal; a real step, the weak leg's too, moves the raw norm by more.

In a swinging hand two more: the arm's centripetal acceleration raises the
mean of the norm by 1-2 m/s^2 when the swing starts, so the running mean ``g``
follows faster (``gravity_time_constant_s`` 1 s instead of 3: the valleys
fall below it from the first steps), and the step's wave left after the comb
is small beside the swing (the hand damps the heel strike), so ``A_th`` is
0.3 m/s^2: the carry detector has already found the gait periodic.

**Weak-step rescue** (``rescue_peak_height_m_s2``, issue #25, on for the trunk's modes: :data:`TRUNK_GATES`).
Mid-walk, a single step can rise less than ``A_th``: in a trouser pocket the far leg's footfall, in a coat pocket
or in the hand a softer step (the TUNING clips of yh570/sensibility_testbed lost 1-4 % of their steps so, 0.15-0.6
m/s^2 above ``g`` in 54 of the 77 two-period gaps, below 0.15 or under ``g`` in 14, refused by the valley test in
7).  When a step follows the previous one after ``rescue_interval_periods`` (1.6-2.5) step periods of the carry
detector (which gives a period only while the gait is periodic), and the highest peak in between that only the
amplitude refused (the time, valley and echo tests passed) sits in the middle (``rescue_position_frac``, 0.3-0.7
of the interval) at least ``rescue_peak_height_m_s2`` above ``g``, that peak is a step too.  It is given out first,
and the step that revealed it one grid sample later (its time is still its peak's), so every step keeps its own
time and the steps stay in time order.  A walk's last step is never followed, so nothing is added at a stop.
**Periodic rescue** (``rescue_min_periodicity``, issue #25, OFF by default): of the 38 two-period gaps the rescue
left on the yh570 TUNING clips, 28 had a right period and a peak refused by the rescue's height (0.15) or valley
test.  While the carry detector finds the norm periodic at both legs' lags (its
:attr:`core.pdr.carry.CarryModeDetector.both_periodicity`, at least this setting), the gait's periodicity stands
for the amplitude: the held peak needs only to rise above ``g``, with or without a valley before it (the interval,
position and cadence tests stay).  TUNING, at 0.6 (the carry detector's ``gentle_min_periodicity``, chosen a
priori): 3 of the 26 counted clips gain a step (mean absolute error 1.489 -> 1.440 %), too little to tell from the
choice itself, so it stays off; the fast path refuses it.

**End-of-data flush** (:meth:`StepDetector.flush`, ``Pipeline(flush_at_end=True)``, issue #25, ON by default). A
peak is found one grid sample after it, and the low-pass puts it after the heel strike (on the simulator the norm
peaks about 0.09 s after the heel strike and the 3-Hz filter adds 0.075 s): a recording stopped within about 0.18 s
of a heel strike has no peak for it, and a step the rescue found waits for the next sample (the stash). At the end
of data the flush gives out the stash and takes a filtered norm still rising at the last sample as the maximum it is
of the data, through every other test (time, valley, amplitude, echo, cadence, the rescue); a flat or falling end
adds nothing, and the pipeline's rotation and bout gates still apply. The simulator's 20-m walks cut 0.16 s after a
heel strike (five placements, 3 seeds): that heel strike missed in 15 of 15, counted with the flush in 14. TUNING:
the 26 counted real clips all end standing (0.3-29 s after their last step): every count the same (mean absolute
error 1.489 %), and lopen 602, alex_walking 137 the same; the same clips cut at 156 seeded times inside their
walking (the full run's steps up to the cut as the reference): 37 steps missing in 31 cuts without the flush, 11 in
7 with it, none added: ON by that tuning gain (the uncut clips show nothing either way); the fast path mirrors it. A walk that
stops and stands is not concerned: its last step comes out live within one step period of its heel strike
(``tests/test_end_steps.py``).

A slow, gentle walk (issue #25: 0.5-1 m/s^2 of user acceleration at 0.8-1.2 steps/s, a phone held still in
the hand) lifts the filtered norm only 0.2-0.5 m/s^2 above ``g``, under the hand-held ``A_th``.  When the carry
detector finds the norm periodic but gentle (:attr:`core.pdr.carry.CarryModeDetector.gentle`), a trunk mode's
steps are counted with :data:`GENTLE_GATES`: ``A_th`` 0.15 m/s^2 with the cadence gate (the step period is
known then).  The periodicity decides that it is walking, not the amplitude.  Issue #25 part 2: also a slow walk
whose norm moves by up to 1 m/s^2 (the carry detector's slow band; the TUNING clip Tclack88 50_hand_slow counted
30 of its 50 steps with the hand-held ``A_th``, 50 with these gates).  The gentle gates' ``A_th`` is relative to the
gait's own amplitude (:data:`GENTLE_RELATIVE_PEAK_HEIGHT`, issue #25 section 2): at most 0.3 of the norm's standard
deviation over the carry detector's window while it knows the step period; a still or fidgeting phone is never
gentle, so never counted so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from core.dsp import Biquad, GridResampler, butter2_group_delay_s, butter2_lowpass
from core.conventions import (CARRY_BAG, CARRY_EAR, CARRY_HANDHELD, CARRY_POCKET, CARRY_STILL, CARRY_SWINGING,
                              STANDARD_GRAVITY_M_S2)


@dataclass(frozen=True)
class StepGates:
    """The step detector's per-carry-mode settings (see the module docstring)."""

    stride_comb: bool = False  #: average the norm with itself one step period earlier
    min_interval_period_frac: float = 0.0  #: a step needs this fraction of the step period since the last (0: off)
    #: ``A_th`` of eq. 3 in this mode (m/s^2); None: the detector's ``min_peak_height_m_s2``
    min_peak_height_m_s2: float | None = None
    #: time constant of the running mean ``g`` in this mode (s); None: the detector's ``gravity_time_constant_s``
    gravity_time_constant_s: float | None = None
    #: a peak needs the raw norm to vary this much (max - min) in the last half step period (m/s^2; 0: off)
    min_raw_range_m_s2: float = 0.0
    #: the weak-step rescue (module docstring): a peak under ``A_th`` but this high above ``g`` (m/s^2) is counted
    #: when it sits in the middle of an interval of two step periods between steps (0: off)
    rescue_peak_height_m_s2: float = 0.0
    #: the rescue's interval between the two steps around the weak peak, in step periods (lowest, highest)
    rescue_interval_periods: tuple = (1.6, 2.5)
    #: where the weak peak must sit in that interval, as a fraction of it from the first step (lowest, highest)
    rescue_position_frac: tuple = (0.3, 0.7)
    #: the periodic rescue (module docstring): while the carry detector's periodicity at both legs' lags
    #: (:attr:`core.pdr.carry.CarryModeDetector.both_periodicity`) is at least this, the weak peak held for the rescue
    #: needs neither ``rescue_peak_height_m_s2`` nor the valley test, only to rise above ``g`` (inf: off)
    rescue_min_periodicity: float = math.inf
    #: the amplitude threshold relative to the gait's own amplitude (issue #25): while the carry detector knows the
    #: step period (the gait is periodic), ``A_th`` is at most this fraction of the norm's standard deviation over its
    #: window (:attr:`core.pdr.carry.CarryModeDetector.gait_std_m_s2`; 0: off)
    relative_peak_height: float = 0.0


#: the limb gates of a phone in a trouser pocket (issue #25: one step per footfall): the stride comb, the cadence
#: gate and the echo gate, and ``A_th`` 0.3 m/s^2 as in a swinging hand: the comb averages the strong half-stride's
#: peak with the weak one's, and the carry detector has already found the gait periodic (a gentle swing taken for a
#: pocket, 1 step/s: 0 of 18 steps with ``A_th`` 0.6, 18 with 0.3).  The echo gate stays at 0.5 m/s^2 (1.0 would
#: remove the comb's echo after the last step of 3 of the simulator's 30 tuning pocket walks, but also every step of
#: that gentle swing).  The running mean ``g`` keeps its 3 s: a thigh adds no centripetal offset when it starts
POCKET_GATES = StepGates(stride_comb=True, min_interval_period_frac=0.6, min_raw_range_m_s2=0.5, min_peak_height_m_s2=0.3)
#: the cadence gate of a bag bouncing on its strap (not the default: see :data:`STEP_GATES`)
BAG_GATES = StepGates(min_interval_period_frac=0.6)

#: the hand-held detector's gates, also for the ear, a bag, a pocket and "not walking": eq. 3 with the weak-step
#: rescue (module docstring), ``A_th`` 0.6 m/s^2 and a rescued peak at least 0.15 m/s^2 above ``g`` (the gentle
#: gait's ``A_th``).  The rescue needs the carry detector's step period, which it gives only while the norm is
#: periodic: "not walking" rescues nothing.  TUNING: the 26 counted real clips 2.06 -> 1.50 % (yh570 pocket, coat and
#: hand walks, 37 steps), IPOL step MAE 8.59 -> 8.08 %, the simulator's carry seeds unchanged; the CI guard's
#: Brajdic-Harle report headline 2.15 -> 2.43 % (threshold 2.44): see benchmarks/REAL_WALKS_RESULTS.md
TRUNK_GATES = StepGates(rescue_peak_height_m_s2=0.15)

#: gates per carry mode (core.conventions.CARRY_MODES).  Only the swinging hand gets gates of its own by default,
#: and a pocket whose half-strides are very unlike (:data:`UNEVEN_POCKET`, below: the limb gates while the carry
#: detector's ``uneven`` holds).
#: The pocket's limb gates (:data:`POCKET_GATES`, issue #25: one step per footfall) help where a limb is taken for the
#: wrong limb: on the simulator's tuning seeds two slow swinging walks taken for a pocket counted 114 of 146 and 109
#: of 144 steps with the hand-held gates, 145 and 144 with them (swinging mean -4.10 % -> -2.58 %, pocket mean abs
#: 0.55 -> 0.87 %: the comb's echo), and on the real tuning walk thomasdingemanse_lopen they restore a footfall
#: missing in its 9 s taken for a pocket (602 -> 603).  They are not the default: a hand-held phone taken for a pocket
#: overcounts with them (the CI guard's Brajdic-Harle quick subset: one clip 86 -> 93 steps of 82, its headline 1.94
#: -> 2.60 %, over the 2.44 threshold); :data:`UNEVEN_POCKET` gives them only to a pocket whose norm repeats every
#: stride rather than every step.  The bag's gates (:data:`BAG_GATES`) counted no better than the hand-held
#: detector (bag 0.08 %, IPOL waist 8.59 % against 8.63 %).  ``Pipeline(step_gates=...)`` turns them on.
STEP_GATES = {
    CARRY_HANDHELD: TRUNK_GATES,
    CARRY_EAR: TRUNK_GATES,
    CARRY_BAG: TRUNK_GATES,
    CARRY_STILL: TRUNK_GATES,
    CARRY_POCKET: TRUNK_GATES,
    CARRY_SWINGING: StepGates(stride_comb=True, min_interval_period_frac=0.6, min_peak_height_m_s2=0.3,
                              gravity_time_constant_s=1.0, min_raw_range_m_s2=0.5),
}

#: the gentle gates' ``A_th`` relative to the gait's own amplitude (:attr:`StepGates.relative_peak_height`, issue #25
#: section 2): at most this fraction of the norm's standard deviation over the carry detector's window.  A gently
#: swung hand at 1-1.2 steps/s (the simulator's ``bounce_scale`` 0.6) lifts its combed weak leg 0.12-0.14 m/s^2
#: above ``g`` (norm SD 0.25): under the fixed 0.15 every other step was lost, the steps then 1.7 s apart, over
#: ``max_step_interval_s``, and each a new bout that the bout gate refused (3 and 16 of 34).  Applies only under the
#: gentle gates, i.e. while the carry detector finds the gait periodic at both legs (a still or fidgeting phone is
#: never gentle).  0: off (the fixed 0.15)
GENTLE_RELATIVE_PEAK_HEIGHT = 0.3
#: the key of :data:`STEP_GATES` (and ``Pipeline(step_gates=...)``) of a gentle walk, beside the carry modes
GENTLE = "gentle"
#: a slow, gentle walk on the trunk (issue #25: 0.5-1 m/s^2 of user acceleration, 0.8-1.2 steps/s; the carry
#: detector's :attr:`core.pdr.carry.CarryModeDetector.gentle`): its steps rise 0.2-0.5 m/s^2 above ``g``, under
#: the hand-held ``A_th`` of 0.6.  The carry detector has found the norm periodic, so ``A_th`` is 0.15 m/s^2;
#: the cadence gate keeps a second bump within a step out (the step period is known)
GENTLE_GATES = StepGates(min_interval_period_frac=0.6, min_peak_height_m_s2=0.15, relative_peak_height=GENTLE_RELATIVE_PEAK_HEIGHT)
STEP_GATES[GENTLE] = GENTLE_GATES

#: the key of :data:`STEP_GATES` (and ``Pipeline(step_gates=...)``) of a gentle walk in a swinging hand
GENTLE_SWING = "gentle_swinging"
#: a slow, gentle walk with the phone swung in the hand (issue #25 section 2: a gentle walk is walking, in every carry
#: mode; the carry detector's :attr:`core.pdr.carry.CarryModeDetector.gentle` in the swinging mode): the swinging
#: hand's gates (the stride comb, the cadence gate, the 1-s running mean ``g``) with the gentle gait's ``A_th`` of
#: 0.15 m/s^2 and an echo gate of 0.2 m/s^2: a gently swung hand's combed peaks rise 0.15-0.3 m/s^2 above ``g`` and
#: its raw norm moves by 0.2-0.5 m/s^2 in half a step, under the swinging gates' 0.3 and 0.5 (the simulator's gentle
#: swing at 1 step/s, ``swing_scale`` 1-1.5, bounce 0.5-0.75: 0 of 28 steps with the swinging gates, 26-28 with these).
#: The echo gate stays (0.2 m/s^2: a stopped walk's raw norm moves by a standing hand's 0.02-0.1)
GENTLE_SWING_GATES = StepGates(stride_comb=True, min_interval_period_frac=0.6, min_peak_height_m_s2=0.15,
                               gravity_time_constant_s=1.0, min_raw_range_m_s2=0.2,
                               relative_peak_height=GENTLE_RELATIVE_PEAK_HEIGHT)
STEP_GATES[GENTLE_SWING] = GENTLE_SWING_GATES

#: the key of :data:`STEP_GATES` of a pocket whose two half-strides are very unlike (the carry detector's
#: :attr:`core.pdr.carry.CarryModeDetector.uneven`, issue #25: a soft-soled walk, the far leg's footfall a small
#: bump): such a pocket is counted with the limb gates :data:`POCKET_GATES`, one step per footfall.  The
#: simulator's soft-soled pocket (a third of its heel strikes, tuning seeds 0-2, 1.6 steps/s): 23-24 of 42 steps
#: with the hand-held gates, 41-42 with these; a pocket whose norm repeats at every step keeps the hand-held gates
#: (``POCKET_GATES`` for every pocket moved the CI guard's Brajdic-Harle headline 1.94 -> 2.60 %)
UNEVEN_POCKET = "pocket_uneven"
STEP_GATES[UNEVEN_POCKET] = POCKET_GATES

#: longest step period the stride comb keeps a history for (s): the carry detector's slowest step (issue #25 section 2,
#: 0.8 steps/s: 1.25 s; it was 1.0, and a gently swung hand at 0.9 steps/s, its step 1.1 s, was not combed: 16 of 28
#: steps with its step period known, 26 with 1.3)
MAX_COMB_PERIOD_S = 1.3


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
        #: per-carry-mode gates in force (:meth:`set_gates`); the default is the hand-held detector
        self.gates = StepGates()
        #: current step period (s) from the carry detector (nan: unknown; the comb and cadence gate wait)
        self.step_period_s = math.nan
        #: the carry detector's periodicity at both legs' lags (nan: unknown; the periodic rescue waits)
        self.both_periodicity = math.nan
        #: the carry detector's gait amplitude (the norm's standard deviation, m/s^2; nan: unknown)
        self.gait_std_m_s2 = math.nan
        self.reset()

    def set_gates(self, gates: StepGates) -> None:
        """Switch to another carry mode's gates (the filters' state is kept)."""
        self.gates = gates
        tau = self.gravity_time_constant_s if gates.gravity_time_constant_s is None else gates.gravity_time_constant_s
        self._alpha_g = 1.0 - math.exp(-1.0 / (self.grid_rate_hz * tau))

    def reset(self) -> None:
        self.resampler = GridResampler(rate_hz=self.grid_rate_hz)
        b, a = butter2_lowpass(self.cutoff_hz, self.grid_rate_hz)
        self._lp = Biquad(b, a)
        self.set_gates(self.gates)  # the running mean's rate
        self._min_dt_ns = int(self.min_step_interval_s * 1e9)
        # the low-pass delays the peak; steps are time-stamped at the unfiltered instant
        self._delay_ns = int(round(butter2_group_delay_s(self.cutoff_hz) * 1e9))
        self._delay_samples = int(round(butter2_group_delay_s(self.cutoff_hz) * self.grid_rate_hz))
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
        # the raw norm of the last MAX_COMB_PERIOD_S, a ring (the stride comb's delay line)
        self._hist = [0.0] * (int(MAX_COMB_PERIOD_S * self.grid_rate_hz) + 2)
        self._hist_k = 0
        self._hist_n = 0
        self._clear_weak()
        self._stash: StepEvent | None = None  # a step found with a rescued one, given out at the next sample
        #: weak steps rescued (the weak-step rescue, module docstring)
        self.n_rescued = 0
        #: steps given out by :meth:`flush` at the end of data
        self.n_flushed = 0
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
        self._hist_n = 0
        self._clear_weak()

    def _clear_weak(self) -> None:
        """Forget the weak peak held since the last step (the weak-step rescue)."""
        # (peak time, filtered norm, g, the step's lowest norm, sum, sum of squares and count of its norms)
        self._weak: tuple | None = None
        self._after_min = math.inf  # lowest filtered norm since the weak peak

    def _comb(self, norm: float) -> float:
        """The stride comb (module docstring): ``(x(t) + x(t - T_step)) / 2`` once a period of history is there."""
        h = self._hist
        n = len(h)
        k = self._hist_k
        h[k] = norm
        self._hist_k = (k + 1) % n
        filled = self._hist_n
        if filled < n:  # (so never more than n)
            filled = self._hist_n = filled + 1
        if not self.gates.stride_comb:
            return norm
        period = self.step_period_s
        if not period > 0.0:
            return norm
        lag = round(period * self.grid_rate_hz)  # (an int: round of a float)
        if lag < 1 or lag >= filled:
            return norm
        return 0.5 * (norm + h[(k - lag) % n])

    def _raw_range(self) -> float:
        """Range (max - min) of the raw norm over the last half step period and the low-pass delay (m/s^2)."""
        h = self._hist
        n = len(h)
        back = min(n, self._hist_n, int(0.5 * self.step_period_s * self.grid_rate_hz) + self._delay_samples + 2) \
            if self.step_period_s > 0.0 else min(n, self._hist_n)
        if back < 2:
            return 0.0
        k = self._hist_k
        seg = [h[(k - 1 - i) % n] for i in range(back)]
        return max(seg) - min(seg)

    def _echo_ok(self) -> bool:
        """The echo gate (``min_raw_range_m_s2``, module docstring): computed only for a peak the cheaper tests passed."""
        r = self.gates.min_raw_range_m_s2
        return r <= 0.0 or self._raw_range() >= r

    def _peak(self, t_peak: int, y1: float, g: float) -> StepEvent | None:
        """The tests of eq. 3 (and the gates in force) on a maximum of the filtered norm ``y1`` at ``t_peak`` with
        the running mean ``g``: its step (a rescued weak step first, the step itself then waits in the stash), or
        None (a weak peak may be held for the rescue)."""
        event = None
        since = None if self._last_step_ns is None else t_peak - self._last_step_ns
        min_dt = self._min_dt_ns
        gates = self.gates
        period = self.step_period_s
        frac = gates.min_interval_period_frac
        if frac > 0.0 and period > 0.0:  # the cadence gate (module docstring)
            min_dt = max(min_dt, int(frac * period * 1e9))
        a_th = self.min_peak_height_m_s2 if gates.min_peak_height_m_s2 is None else gates.min_peak_height_m_s2
        if gates.relative_peak_height > 0.0 and self.gait_std_m_s2 > 0.0:  # the gait's own amplitude (issue #25)
            a_th = min(a_th, gates.relative_peak_height * self.gait_std_m_s2)
        timed = (since is None or since > min_dt) and self._armed  # eq. 3, time threshold; the valley
        if y1 - g > a_th and timed and self._echo_ok():  # eq. 3, amplitude threshold
            n = self._seg_n
            weak = self._weak
            rescue = (weak is not None and period > 0.0
                      and gates.rescue_interval_periods[0] * period * 1e9 <= since
                      <= gates.rescue_interval_periods[1] * period * 1e9
                      and gates.rescue_position_frac[0] * since <= weak[0] - self._last_step_ns
                      <= gates.rescue_position_frac[1] * since
                      and t_peak - weak[0] > min_dt)
            if rescue:  # the weak step first, this one at the next sample
                t_w, y_w, g_w, min_w, sum_w, sum2_w, n_w = weak
                mean = sum_w / n_w if n_w else y_w
                var = max(sum2_w / n_w - mean * mean, 0.0) if n_w else 0.0
                since_w = t_w - self._last_step_ns
                event = StepEvent(t_w - self._delay_ns, y_w, min_w if min_w < math.inf else y_w, var,
                                  since_w * 1e-9, g_w)
                n2 = n - n_w
                mean = (self._seg_sum - sum_w) / n2 if n2 else y1
                var = max((self._seg_sum2 - sum2_w) / n2 - mean * mean, 0.0) if n2 else 0.0
                acc_min = self._after_min if self._after_min < math.inf else y1
                self._stash = StepEvent(t_peak - self._delay_ns, y1, acc_min, var, (t_peak - t_w) * 1e-9, g)
                self.n_rescued += 1
            else:
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
            self._clear_weak()
        elif (since is not None and period > 0.0
              and ((gates.rescue_peak_height_m_s2 > 0.0 and timed and y1 - g > gates.rescue_peak_height_m_s2)
                   or (self.both_periodicity >= gates.rescue_min_periodicity and since > min_dt and y1 > g))
              and (self._weak is None or y1 - g > self._weak[1] - self._weak[2]) and self._echo_ok()):
            # a weak peak that only the amplitude refused: held for the rescue (the highest since the last step)
            self._weak = (t_peak, y1, g, self._seg_min, self._seg_sum, self._seg_sum2, self._seg_n)
            self._after_min = math.inf
        return event

    def update_grid(self, t_ns: int, norm: float) -> StepEvent | None:
        """Process one sample of the uniform grid (the kernel shared by streaming and batch)."""
        stash = self._stash
        if stash is not None:  # the step found with a rescued one, a sample late (its time is the peak's)
            self._stash = None
        if self._y1 is None:
            self._lp.reset(norm)
            if self.n_grid == 0:
                self.gravity_m_s2 = norm
        self.n_grid += 1
        g = self.gravity_m_s2 = self.gravity_m_s2 + self._alpha_g * (norm - self.gravity_m_s2)
        y = self._lp.step(self._comb(norm))
        self.last = (t_ns, norm, y)
        event = None
        y1, y2 = self._y1, self._y2
        if y1 is not None and y2 is not None and y1 > y2 and y1 >= y:
            event = self._peak(self._t1, y1, g)  # local maximum at the previous grid sample
        if y < g:
            self._armed = True
        if self._last_step_ns is not None and t_ns - self._last_step_ns > self._max_dt_ns:
            # a pause: forget the amplitude history of the last bout
            self._last_step_ns = None
            self._seg_min = math.inf
            self._seg_sum = self._seg_sum2 = 0.0
            self._seg_n = 0
            self._clear_weak()
        if y < self._seg_min:
            self._seg_min = y
        if y < self._after_min:
            self._after_min = y
        self._seg_sum += y
        self._seg_sum2 += y * y
        self._seg_n += 1
        self._y2, self._y1, self._t1 = y1, y, t_ns
        if stash is not None:
            return stash
        return event

    def flush(self) -> list[StepEvent]:
        """End of data (``Pipeline(flush_at_end=True)``, module docstring): the steps that only the missing next
        samples kept back.  The step found with a rescued one and waiting for the next sample (the stash); and the
        filtered norm still rising at the last sample, taken as the maximum it is of the data: every test of
        :meth:`update_grid` but the one that needs a later, lower sample (the time, valley, amplitude, echo and
        cadence tests, the rescue).  A flat or falling end adds nothing.  Call once, after the last sample."""
        out = []
        stash = self._stash
        self._stash = None
        if stash is not None:
            out.append(stash)
        y1, y2 = self._y1, self._y2
        if y1 is not None and y2 is not None and y1 > y2:
            ev = self._peak(self._t1, y1, self.gravity_m_s2)
            if ev is not None:
                out.append(ev)
            if self._stash is not None:
                out.append(self._stash)
                self._stash = None
        self.n_flushed += len(out)
        return out

    # -- batch --------------------------------------------------------------
    def run(self, t_ns, acc_b) -> list[StepEvent]:
        """Detect the steps of a whole accelerometer stream: ``t_ns`` (n,), ``acc_b`` (n, 3)."""
        self.reset()
        out: list[StepEvent] = []
        for t, (ax, ay, az) in zip(list(map(int, t_ns)), acc_b.tolist() if hasattr(acc_b, "tolist") else acc_b):
            out.extend(self.update(t, ax, ay, az))
        return out
