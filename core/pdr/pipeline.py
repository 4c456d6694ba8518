"""The PDR pipeline: all stages composed (Tian et al. 2014, Fig. 2).

Events go in one at a time, in time order, as the phone delivers them::

    gyro  -> AttitudeEKF.predict                        (eqs. 5-7, 11)
    acc   -> AttitudeEKF.update_acc                     (eqs. 12-17)
             GridResampler (uniform grid, default 50 Hz)
               -> StepDetector.update_grid              (eqs. 2-3)
               -> RotationSmoother.update(R of the EKF) (section 4.3)
               -> steps whose heading is due: stride model (eq. 4), DeadReckoner (eq. 1)
    mag   -> AttitudeEKF.update_mag                     (eq. 18)
    gps   -> the GPS fusion (core.gnss: GpsFusion of Chen et al. or KubrakFusion of
             Kubrak et al.), when the pipeline has one: each completed step goes
             through it too, giving the fused track; gnss_status (satellites, C/N0)
             goes to it as well
    rotvec, others -> ignored by the core PDR

Two gates keep what is not walking out of the track (neither is in the paper;
both were needed on real recordings, whose first minute is often spent waving
the phone to calibrate its compass):

* **rotation gate**: a peak while the phone turns faster than
  ``max_rotation_rms_rad_s`` (RMS over the last second) is not a step.  A
  phone held in front of the chest turns at under 2 rad/s even in a corner,
  one swung in the hand at up to about 3 rad/s; waving it to calibrate the
  compass turns it at 3-8 rad/s.  At 3 rad/s the gate removed 76 % of the
  waving peaks at the start of the IPIN 2023 files and 1.6 % of the steps of
  the trundle-wheel walks (phone carried in an unknown way);
* **bout gate**: a step counts only as part of ``min_bout_steps``
  consecutive steps (each within ``max_step_interval_s`` of the last); the
  first steps of a bout are released once it is confirmed.

A step's heading is the mean smoothed walking direction over the step
interval, compensated for the smoother's delay
(:func:`core.pdr.heading.interval_heading`): the step is completed
``heading_delay_s`` after its peak, when the causal smoother has caught up
with the whole interval, and once its bout is confirmed.  The live app
therefore sees each step about a second after it happened (the first steps of a walk, held while the carry
detector settles its mode, up to ``rotation_hold_s`` later: ``hold_while_settling``);
:meth:`Pipeline.status` gives the current position at any time.

Non-finite sensor values (NaN, inf) and impossible ones (beyond any phone
sensor's range, :data:`IMPOSSIBLE`) are skipped before any stage sees them and
counted per stream (:attr:`Pipeline.n_nonfinite`, :attr:`Pipeline.n_impossible`;
the summary and the labels report them).  Sensors that misbehave within their
range are watched by :class:`SensorHealth` at O(1) cost per event and reported
as degraded modes in :meth:`Pipeline.labels`: a component stuck at the same
extreme value (saturation at the range limit), a sensor whose three values do
not change for seconds (dead: zeros or frozen), a magnetometer whose every
reading was rejected.  They only add labels and counters; the track is the same.

:meth:`Pipeline.update` (streaming, for the app) and :meth:`Pipeline.run`
(batch, for files) share this one kernel; ``tests/test_streaming_batch.py``
checks them against each other where they could differ (chunked feeding, the app's drain).
"""

from __future__ import annotations

import copy
import math
from array import array
from collections import deque
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from core.conventions import (ACC, CARRY_BAG, CARRY_EAR, CARRY_HANDHELD, CARRY_POCKET, CARRY_STILL, CARRY_SWINGING,
                              GNSS_STATUS, GPS, GYRO, MAG)
from core.dsp import GridResampler
from core.pdr.attitude import AttitudeEKF
from core.pdr.carry import CarryChange, CarryModeDetector
from core.pdr.deadreckoning import DeadReckoner
from core.pdr.gapbridge import AccGapBridge, EstimatedStep, GapVerdict
from core.pdr.heading import SMOOTHER_AXES, RotationSmoother, interval_heading
from core.pdr.heading_smoother import (HEADING_SMOOTHER_OFF, HEADING_SMOOTHER_RTS, HEADING_SMOOTHER_START,
                                      HEADING_SMOOTHERS, SmootherVerdict, StartHeading, smooth_steps)
from core.pdr.steps import GENTLE, GENTLE_SWING, STEP_GATES, UNEVEN_POCKET, StepDetector, StepEvent
from core.pdr.velocity import SpeedFeatureWindow
from core.pdr.walkdir import WALKING_DIRECTIONS, WalkingDirection
from core.pdr.stride import StepFeatures, StrideModel, WeinbergStride
from core.recording import Recording, RecordingError

#: Step duration assumed for the first step of a walking bout (s).
DEFAULT_STEP_DURATION_S = 0.55

#: Readings beyond these magnitudes per component are no phone sensor's (the widest ranges are about
#: 16 g, 70 rad/s and 5000 uT): skipped and counted like non-finite ones.  acc m/s^2, gyro rad/s, mag uT
IMPOSSIBLE = {ACC: 2000.0, GYRO: 200.0, MAG: 10000.0}

_SENSOR_NAMES = {ACC: "accelerometer", GYRO: "gyroscope", MAG: "magnetometer"}


class SensorHealth:
    """Saturation and dead-sensor detector of one 3-axis stream, O(1) time and memory per reading.

    * **saturation**: a component that keeps exactly the same value, at least
      ``floor`` in magnitude, over ``min_run_s`` or longer (and 3 readings or
      more) is at its range limit: a real signal near its peak changes from
      one reading to the next, a clipped one sits on the rail.  Each such run
      is one episode; ``saturated_s`` adds their durations and ``level`` is
      the largest magnitude seen on a rail.
    * **dead**: all three components unchanged from one reading to the next for
      ``dead_s`` or longer (zeros, or a frozen driver).  ``dead_runs`` counts
      the episodes, ``dead_s`` their total time, ``dead_zero`` whether any was
      all zeros.
    """

    def __init__(self, floor: float, *, min_run_s: float = 0.06, dead_s: float = 2.0):
        self.floor = float(floor)
        self._min_run_ns = int(min_run_s * 1e9)
        self._dead_ns = int(dead_s * 1e9)
        self.n = 0
        self.saturated_runs = 0
        self.saturated_s = 0.0
        self.level = 0.0
        self.dead_runs = 0
        self.dead_s = 0.0
        self.dead_zero = False
        self._prev = None
        self._prev_t = 0
        self._rail_t0 = [None, None, None]  # start of the current run of one value >= floor, per component
        self._rail_n = [0, 0, 0]
        self._rail_counted = [False, False, False]
        self._same_t0 = None  # start of the current run of identical readings
        self._same_counted = False

    def update(self, t_ns: int, x: float, y: float, z: float) -> None:
        self.n += 1
        prev = self._prev
        v = (x, y, z)
        if prev is None:
            self._prev, self._prev_t = v, t_ns
            return
        dt = (t_ns - self._prev_t) * 1e-9
        f = self.floor
        if not (x >= f or -x >= f or y >= f or -y >= f or z >= f or -z >= f):
            rail = self._rail_t0
            rail[0] = rail[1] = rail[2] = None  # no component on a rail
        else:
            self._rails(t_ns, v, prev, dt)
        if v == prev:
            if self._same_t0 is None:
                self._same_t0, self._same_counted = self._prev_t, False
            if self._same_counted:
                self.dead_s += dt
            elif t_ns - self._same_t0 >= self._dead_ns:
                self._same_counted = True
                self.dead_runs += 1
                self.dead_s += (t_ns - self._same_t0) * 1e-9
                if x == 0.0 and y == 0.0 and z == 0.0:
                    self.dead_zero = True
        else:
            self._same_t0 = None
        self._prev, self._prev_t = v, t_ns

    def skip_quiet(self, n: int, t_ns: int, last) -> None:
        """A new detector's state after ``n`` readings none of which is on a rail (every component under ``floor``
        in magnitude) or equal to the one before, the last ``last`` (3 floats) at ``t_ns``: only the count and the
        last reading move (what :meth:`update` leaves; the caller checked the readings: the desktop fast path's
        ``health_of``).  Refuses a detector that has seen readings, ``n < 1`` and a ``last`` on a rail."""
        if self.n:
            raise ValueError("skip_quiet sets a new detector's state only")
        last = tuple(float(x) for x in last)
        if n < 1 or len(last) != 3 or any(x >= self.floor or -x >= self.floor for x in last):
            raise ValueError("skip_quiet takes n >= 1 readings off the rails")
        self.n = int(n)
        self._prev, self._prev_t = last, int(t_ns)

    def _rails(self, t_ns: int, v, prev, dt: float) -> None:
        for i in range(3):
            vi = v[i]
            if vi == prev[i] and (vi >= self.floor or -vi >= self.floor):
                if self._rail_t0[i] is None:
                    self._rail_t0[i], self._rail_n[i], self._rail_counted[i] = self._prev_t, 1, False
                self._rail_n[i] += 1
                if self._rail_counted[i]:
                    self.saturated_s += dt
                elif self._rail_n[i] >= 3 and t_ns - self._rail_t0[i] >= self._min_run_ns:
                    self._rail_counted[i] = True
                    self.saturated_runs += 1
                    self.saturated_s += (t_ns - self._rail_t0[i]) * 1e-9
                    self.level = max(self.level, abs(vi))
            else:
                self._rail_t0[i] = None

    def as_dict(self) -> dict:
        return {"saturated_runs": self.saturated_runs, "saturated_s": round(self.saturated_s, 3),
                "saturation_level": self.level, "dead_runs": self.dead_runs, "dead_s": round(self.dead_s, 3),
                "dead_zero": self.dead_zero}


#: magnitude from which a component stuck at one value counts as saturated (acc m/s^2: +-1.6 g and up,
#: the smallest phone range being +-2 g; gyro rad/s: the smallest range is +-250 deg/s = 4.4 rad/s;
#: mag uT: far beyond the Earth's field)
SATURATION_FLOOR = {ACC: 15.5, GYRO: 4.0, MAG: 300.0}


@dataclass(frozen=True)
class Step:
    """One completed step of the track."""

    index: int  #: 0-based step number
    t_ns: int  #: time of the step (acceleration peak), sensor clock
    length_m: float  #: step length (m)
    heading_rad: float  #: walking heading, counter-clockwise from East (rad)
    east_m: float  #: position after the step (m, ENU)
    north_m: float
    features: StepFeatures  #: what the stride model saw
    mag_trusted: bool  #: whether the last magnetometer reading before the step was used by the EKF
    #: carry mode in force at the peak (core.conventions.CARRY_MODES; issue #17), never "still" for a step
    carry_mode: str = CARRY_HANDHELD
    #: not measured: placed in an accelerometer gap from the gyroscope's gait rhythm (core.pdr.gapbridge, #30)
    estimated: bool = False


@dataclass(slots=True)
class StepCandidate:
    """A peak through the rotation gate, waiting in :class:`Pipeline` (and the fast path's ``StepRelease``) to be
    completed as a :class:`Step` once its bout is confirmed and its heading is due."""

    event: StepEvent  #: the step detector's peak
    #: the walking heading over its interval (rad, CCW from East), None until due (``heading_delay_s`` after the peak)
    heading_rad: float | None
    confirmed: bool  #: its bout reached ``min_bout_steps`` (or it is a walk's first step, ``walk_start_step``)
    regressors: tuple  #: Kubrak's eq.-1 speed regressors at the peak (:class:`core.pdr.velocity.SpeedFeatureWindow`)


@dataclass(frozen=True)
class Status:
    """Snapshot of the pipeline for a live display."""

    t_ns: int
    n_steps: int
    distance_m: float
    east_m: float
    north_m: float
    heading_rad: float  #: current smoothed walking heading (rad, CCW from East); nan before the first sample
    mag_trusted: bool
    acc_sigma2: float  #: latest adaptive accelerometer variance (eq. 17)
    mag_sigma2: float  #: latest adaptive magnetometer variance (eq. 18)
    labels: tuple[str, ...]  #: degraded modes in force
    carry_mode: str = CARRY_HANDHELD  #: how the phone is carried (core.conventions.CARRY_MODES; issue #17)
    carry_confidence: float = math.nan  #: the carry detector's confidence in it, 0..1 (nan: detection off)
    #: steps found but held while the carry detector settles a walk's mode (``hold_while_settling``): they are
    #: counted (or replaced by the settled mode's detector) up to ``rotation_hold_s`` later; 0 otherwise
    n_held: int = 0


@dataclass
class Track:
    """The walked track, one row per step (numpy arrays)."""

    t_ns: np.ndarray
    length_m: np.ndarray
    heading_rad: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    #: bool per step: estimated in an accelerometer gap (:attr:`Step.estimated`); None: none was
    estimated: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t_ns)

    @classmethod
    def from_steps(cls, steps: list[Step]) -> Track:
        est = np.array([s.estimated for s in steps], dtype=bool)
        return cls(
            np.array([s.t_ns for s in steps], dtype=np.int64),
            np.array([s.length_m for s in steps], dtype=float),
            np.array([s.heading_rad for s in steps], dtype=float),
            np.array([s.east_m for s in steps], dtype=float),
            np.array([s.north_m for s in steps], dtype=float),
            est if est.any() else None,
        )


@dataclass
class AttitudeLog:
    """Attitude diagnostics on the pipeline's grid (batch runs)."""

    t_ns: np.ndarray
    q_wxyz: np.ndarray  #: (n, 4) EKF attitude, body -> ENU
    heading_rad: np.ndarray  #: smoothed walking heading
    acc_sigma2: np.ndarray
    mag_sigma2: np.ndarray
    mag_rejected: np.ndarray  #: bool: last magnetometer reading rejected


def heading_key(ev: StepEvent) -> tuple:
    """What a step's heading depends on of its :class:`StepEvent` (its interval: peak time and duration; nan, the
    first step of a bout, as -1): a recount (``Pipeline(recount_at_settle=True)``) keeps the heading of a candidate
    whose peak comes back with the same key.  The fast path (desktop.fast.gates) uses it too."""
    return ev.t_ns, ev.duration_s if ev.duration_s == ev.duration_s else -1.0


def _mode_at(t_ns: int, changes: list[CarryChange], mode: str) -> str:
    """The carry mode in force at ``t_ns`` from a detector's change log and its current ``mode``: the last change
    at or before it, else the first change's "from", else ``mode``."""
    for k in range(len(changes) - 1, -1, -1):
        if changes[k].t_ns <= t_ns:
            return changes[k].to_mode
    return changes[0].from_mode if changes else mode


@dataclass
class PipelineResult:
    steps: list[Step]
    track: Track
    attitude: AttitudeLog
    labels: tuple[str, ...]
    recording: Recording
    #: counts of what the attitude filter used and rejected
    counters: dict = field(default_factory=dict)
    #: the GPS fusion's track, fixes and outages (None without a fusion stage)
    fusion: object = None

    def summary(self) -> dict:
        rec = self.recording
        tr = self.track
        dist = float(np.sum(tr.length_m))
        fe = float(tr.east_m[-1]) if len(tr) else 0.0
        fn = float(tr.north_m[-1]) if len(tr) else 0.0
        return {
            "duration_s": rec.duration_s,
            "rates_hz": {n: s.rate_hz for n, s in rec.streams.items() if len(s)},
            "n_steps": len(tr),
            "distance_m": dist,
            "final_east_m": fe,
            "final_north_m": fn,
            "start_to_end_m": math.hypot(fe, fn),
            "labels": list(self.labels),
            **self.counters,
            **({"gps": self.fusion.counters, "outages": [o.as_dict() for o in self.fusion.outages]}
               if self.fusion is not None else {}),
        }


class Pipeline:
    """Step detection, step length, adaptive EKF heading and dead reckoning, composed.

    Parameters
    ----------
    height_m : float or None
        The walker's height (m), passed to the stride model with every step.
    stride_model : core.pdr.stride.StrideModel or None
        Step length model; default :class:`core.pdr.stride.WeinbergStride` with a constant coefficient.
    step_detector, attitude, smoother : optional
        Pre-configured stages (:class:`StepDetector`, :class:`AttitudeEKF`,
        :class:`RotationSmoother`); defaults suit a hand-held phone (the
        smoother's walking axis is the top edge, the back of the phone while it
        stands upright: ``forward_b="auto"``).  The
        default attitude filter takes the phone's calibrated field as it is:
        the online hard/soft-iron calibration (:class:`core.pdr.magcal.MagCalibrator`,
        ``AttitudeEKF(mag_calibrator=MagCalibrator())``) is off by default since
        the ablation of issue #27 (``benchmarks/ABLATION_RESULTS.md``: on the tuning
        split the IPIN median landmark error was 2.93 m with it, 2.49 m without).
    grid_rate_hz : float
        Uniform grid rate for the step detector and the heading smoother (Hz).
    heading_delay_s : float or None
        Delay compensation of the smoothed heading (s): a step's heading is
        the mean over ``[t_prev + delay, t_step + delay]``; ``None`` uses the
        smoother's group delay.
    use_magnetometer : bool
        False: heading from gyroscope and accelerometer only, relative to the start.
    max_rotation_rms_rad_s : float
        Peaks while the phone rotates faster than this (RMS over the last
        ``rotation_window_s``) are not steps (rad/s); ``inf`` turns the gate off.
    rotation_window_s : float
        Window of the rotation gate (s).
    min_bout_steps : int
        Steps count only in runs of at least this many (1 turns the gate off).
    mag_stream : str
        Which stream feeds the attitude filter's magnetometer: ``"mag"``
        (the phone's calibrated field) or an uncalibrated one such as
        ``"mag_uncal"``, for a filter with a calibrator
        (``AttitudeEKF(mag_calibrator=MagCalibrator(), mag_requires_calibration=True)``).
    log : bool
        Keep an :class:`AttitudeLog` (batch runs turn it on).
    walking_direction : str
        Where a step's heading comes from (issue #17): ``"device"`` -- the smoothed device axis, as
        before (the walking-direction stage does not run); ``"acceleration"`` -- the smoothed device
        axis plus the offset that :class:`core.pdr.walkdir.WalkingDirection` estimates from the
        acceleration; ``"auto"`` (default) -- that offset only where the device axis is not the walking
        direction (:meth:`core.pdr.walkdir.WalkingDirection.step_heading`): a carry mode neither
        hand-held nor still, or a confident offset far from 0.  A hand-held phone keeps today's heading.
    walkdir : core.pdr.walkdir.WalkingDirection or None
        A pre-configured walking-direction stage (default: its defaults, with the smoother's delay).
    keep_steps : bool or int
        Keep every completed step in :attr:`steps` (True, the default; a batch
        :meth:`run` keeps every step whatever this says), none (False) or the last ``n`` (an int): a live session
        that keeps its own track gives False or a small number, and the
        pipeline's memory stays flat however long the walk.  The steps returned
        by :meth:`update` and the track are the same either way.
    gnss : core.gnss.base.FixFusion or None
        GPS fusion after the steps (``core.gnss.make_fusion``: Chen et al. 2010 or
        Kubrak et al. 2006): fixes of the ``gps`` (and ``gnss_status``)
        stream and every completed step go through it; :attr:`fused` holds the
        fused steps, :meth:`run` returns them in ``result.fusion``.
    site_from_gps : bool
        When the fusion's first good fix anchors the walk, give the attitude
        filter the site's magnetic declination (unless one was set) and, as the
        walk is then outdoors, its World Magnetic Model field strength and dip
        (:meth:`core.pdr.attitude.AttitudeEKF.set_site_field`): what a live app
        knows from its first fix.  Needs the date: ``unix_offset_ns``.
    unix_offset_ns : int or None
        Unix time minus sensor-clock time (ns); :meth:`run` takes it from the
        recording's metadata when not given.
    carry : bool or core.pdr.carry.CarryModeDetector
        Carry-mode detection (issue #17; True: a default
        :class:`core.pdr.carry.CarryModeDetector`; False: none, every step is
        detected as hand-held, as before #17).  The mode chooses the step
        detector's gates (``step_gates``) and the rotation gate; it is in
        :meth:`status`, in every :class:`Step` and in the batch counters
        (``carry``: time per mode, changes).
    step_gates : dict or None
        Carry mode -> :class:`core.pdr.steps.StepGates`; default
        :data:`core.pdr.steps.STEP_GATES`.
    swinging_max_rotation_rms_rad_s : float
        The rotation gate in the swinging mode while the carry detector finds
        the rotation periodic at the stride (a swinging arm turns the phone at
        2-10 rad/s, on one axis or twisting over two, issue #25; the irregular waving of a compass calibration is
        still held to ``max_rotation_rms_rad_s``) (rad/s).
    wide_rotation_modes : tuple of str
        The carry modes in which the wide rotation gate (``swinging_max_rotation_rms_rad_s``) holds while the carry
        detector finds the rotation periodic at the stride (:attr:`core.pdr.carry.CarryModeDetector.rotation_periodic`:
        the window's best mode a walking one, its rotation periodic at the stride about one axis or twisting with a
        swing's tilt).  Issue #25: the gate is there to keep a compass calibration's waving out, not a gait's
        rotation.  A gait turns the phone fast only where it hangs or rides on a limb: the arm ("swinging"), the
        thigh ("pocket"), a bag on its strap; and a hand swung hard at a slow cadence is easily taken for a pocket
        or a bag (the simulator's ``swing_scale`` 2.5 at 1.5 steps/s, 3.4 rad/s RMS, peaks 5: every step fell to
        the 3 rad/s gate, 0 of 53).  Not where the phone is before the eyes or at the ear (hand-held, ear): a
        compass calibration is made looking at the screen, and the IPIN tuning routes' rhythmic ones are called
        hand-held, periodic at a "stride" with a twisting swing's axis share (0.77) and tilt (0.4-0.55): the wide
        gate there added 1-4 of their waving peaks to 7 of 16 routes.  Outside "swinging" the wide gate is closed
        while the detector waits out its hysteresis towards a mode counted with other gates
        (:attr:`core.pdr.carry.CarryModeDetector.pending_mode`): the mode in force's detector then commits no steps
        through it, and the next mode's detector recounts them at the change (the simulator's tuning swinging seed
        9, whose first 3.5 s are taken for a bag: 106 of 115 steps without this, 113 with it, as before).
        ``(CARRY_SWINGING,)``: as before.
    wide_while_pending_limb : bool
        Issue #25 (h15/swingsteps): the wide gate stays open while the detector waits out its hysteresis towards a
        mode that is itself in ``wide_rotation_modes`` (a limb's periodic rotation passes the gate in both the mode in
        force and the pending one).  Without it a hand swung hard and called a bag or a pocket, whose raw decision
        goes to "swinging" and back before the 3-s hysteresis completes, loses those steps to the 3 rad/s gate: the
        switch never comes, so nothing recounts them (TUNING Tyrex ``Jakob_iPhone4S_Dist_Swinging``: 18 peaks at 3.1-3.7
        rad/s refused in bag / pocket with "swinging" pending).  **Off by default** (no threshold of its own): TUNING,
        with ``CarryModeDetector(ear_max_swing_deg=20)``, Jakob's six swinging walks against the Tyrex step truth 753
        -> 766 of 784 steps (mean error -3.8 -> -2.3 %; ``iPhone4S_Dist`` -12.3 -> -2.7 %, ``Nexus5_Dist`` -3.2 ->
        -4.0 %, the other four identical); the 30 other tuning truth walks, the 28 real tuning walks, the main
        benchmark's 92 tuning recordings and the carry benchmark's 60 tuning seeds (the simulator's seed 9 above
        included) identical.  One walk's gain, and a cost the closure was also there for: the steps it lets through
        are committed in the mode in force, with its heading, where the closure had the pending mode's detector
        recount them at the change with that mode's walking direction (the simulator's swinging hand taken for a bag
        for its first 4 s, ``tests/test_heading_axis.py``: two steps 87 deg off the walk instead of 1-2 deg, the same
        count).  False: as before (closed).  The fast path mirrors it (``benchmarks/discussion.md``, h15/swingsteps).
    rotation_hold_s : float
        The carry detector needs a few seconds of walking (its window, then its hysteresis) to call a
        mode; every mode's step detector runs and its peaks of the last ``rotation_hold_s`` seconds are
        held, and at a change of mode the new mode's peaks since the last confirmed step replace the
        unconfirmed candidates (through the new mode's rotation gate) (s).
    hold_while_settling : bool
        On by default (issue #25, steps lost at a walk's start): while the carry detector settles the mode of a walk
        (:attr:`core.pdr.carry.CarryModeDetector.settling`: before its first window, and while the mode is "not
        walking" with a walking mode waiting out the hysteresis), confirmed steps wait (at most ``rotation_hold_s``)
        instead of completing; when the settled mode has another step detector, its held peaks since the last
        completed step replace them.  Without it the first seconds of a walk in a swinging hand, a pocket or a gentle
        walk are counted with the hand-held gates, which miss a limb's weak half-stride or a gentle gait's low peaks
        (the simulator's swinging clips: 5 of the first 9 steps, at the start and again after a pause).  The tuning
        split's 26 counted real clips: Tclack88 50_hand_slow 46 -> 50 of 50 ("not walking" until 9.5 s, the
        gentle detector's held peaks recounted), every other clip the same (mean absolute error 2.36 -> 2.06 %); the
        same clips with their first 0.1-0.4 s cut off (other hop phases): 2.43 -> 2.26 %.  **The live app sees a
        walk's first steps late**: up to ``rotation_hold_s`` (8 s) after they happened, at the start of a walk and
        after a pause the carry detector called "not walking"; batch, streaming and the fast path give the same
        steps (``tests/test_walk_start_steps.py``).
    recount_at_settle : bool
        On by default (issue #25, a swinging hand's first steps; with ``hold_while_settling``).  When the carry mode
        changes while the carry detector is :attr:`core.pdr.carry.CarryModeDetector.settling` (before this sample) to a
        mode counted by the same step detector, the held candidates are recounted as at a change of detector: that
        detector's held peaks since the last completed step (at most ``rotation_hold_s`` old) replace them, through the
        new mode's rotation gate (with the rotation RMS each peak had).  Without it the peaks that the 3 rad/s rotation
        gate refused while the mode was "not walking" (a hand swung hard, 3-3.6 rad/s RMS) stay refused when the walk is
        then called a pocket or a bag, whose periodic rotation opens the wide gate.  With the detector's
        ``settle_walk_s`` (a walk's start held open for a second after its first walking call, and on through that
        call's hysteresis towards another walking mode) a hand first called a pocket or a bag and a swinging hand 3 s
        later has its first steps recounted by the swinging detector; while the start is only held open, a gentle or
        uneven walk's detector switched in without a change of mode keeps the confirmed steps (as outside the settling).
        Steps are never completed before a recount, so they stay in time order (batch = streaming = fast path).  The
        live app then sees a walk's first steps up to ``settle_walk_s`` plus the detector's ``switch_s`` later (never
        more than ``rotation_hold_s``).  A recount (with this option, at every change of detector that ends or happens
        in the settling) keeps the heading a replaced candidate had when its peak comes back with the same interval
        (:func:`heading_key`): the recount decides which peaks are steps, not their headings (without this, a hand-held
        Microsoft tuning trace whose first window was called a pocket had its first steps' headings taken again with the
        pocket's walking-direction offset: landmark error 1.0 -> 13.9 m).
    walk_start_step, walk_start_cadence_frac : bool, float
        Off by default (issue #25, steps lost at a walk's start).  A walk's first step from standing rises less than
        the steps that follow, and the hand-held gates (``A_th`` 0.6 m/s^2) can miss it.  With carry detection the
        gentle gait's detector (:data:`core.pdr.steps.GENTLE_GATES`, ``A_th`` 0.15 m/s^2) runs on every sample: when a
        new bout (its first step after a pause) is confirmed by another detector, that detector's held peak one step
        period (the bout's first interval, within ``walk_start_cadence_frac``) before the bout's first step is counted
        as the walk's first step.  Its time lies in the past; it is inserted before the bout, whose steps are never
        completed before the bout is confirmed, so the steps stay in time order (batch = streaming).  Tuning split:
        the 26 counted real clips 2.06 -> 1.69 % (yh570 hand_1_28_21_39 18 -> 20 of 20, hand_1_28_21_35 364 -> 375 of
        372: its bouts after lap turns; three clips +1 too many), IPOL 6.54 -> 5.00 % (58 trials, the walks after
        the U-turn).  Not the default: the IPIN tuning routes (hand-held, ``python -m benchmarks --split tuning``)
        get worse with it, landmark median 2.29 -> 2.37 m, fit 1.75 -> 1.84 m, distance 3.89 -> 4.02 %, and IPOL's
        distance 5.91 -> 6.30 % (steps added where no step was).  The live app would get the walk's first step with
        the bout's third (about two steps late).  The same rule one step period after a bout's last step
        overcounted the tuning clips (2.06 -> 1.98 %, both rules 2.52 %): not built.
    flush_at_end : bool
        On by default (issue #25, a walk's last step lost when the recording stops mid-walk).  At :meth:`finish`
        (the end of a replay, the app's Stop) the step detector in force gives out the steps that only the missing
        next samples kept back (:meth:`core.pdr.steps.StepDetector.flush`: the norm still rising at the last sample
        through every other test, and a step held one sample behind a rescued one); they pass the rotation and bout
        gates as any peak, in time order, the same in batch and streaming.  Never a step without a rising peak.
        TUNING: the 26 counted real clips end standing and count the same; cut at 156 seeded times inside their
        walking, 37 steps missing against the full run without it, 11 with it, none added
        (:mod:`core.pdr.steps`): on by that tuning gain (h11, the lead's decision; the helper had left it off because
        the uncut clips show nothing).  The fast path mirrors it (:func:`desktop.fast.steps.detect`).
    acc_gap_bridge : bool or core.pdr.gapbridge.AccGapBridge
        A gap of the accelerometer alone (the gyroscope running on) of at least the bridge's ``min_gap_s``:
        where the gyroscope shows the walker kept walking, steps are estimated across it from the gyroscope's
        gait rhythm, the stride before the gap and the attitude filter's heading, marked
        :attr:`Step.estimated`; otherwise nothing is added and the reason is in the labels (issue #30;
        True: a default :class:`core.pdr.gapbridge.AccGapBridge`; False: no bridging, the walk in the gap
        is missing from the track).
    heading_smoother : str
        Replays only (issue #27), one of :data:`core.pdr.heading_smoother.HEADING_SMOOTHERS`: ``"off"`` (the
        default: the live app's forward heading); ``"rts"``: after a batch :meth:`run`, a Rauch-Tung-Striebel
        backward pass over the attitude filter's run (:mod:`core.pdr.heading_smoother`) turns every step's
        heading by the smoothed heading correction at its time, and the track is dead-reckoned again (later
        magnetometer readings, carried back by the gyroscope, correct a heading taken in a bent field);
        ``"start"``: two passes, the second a forward run like the first but started from the heading that the
        first pass's backward pass gives at the start (turned by its correction, with its smoothed sd), so the
        walk's own gates judge the magnetometer from a start heading that the whole walk agrees on.  The
        streaming :meth:`update` (the live app) never applies either; with a GPS fusion stage the steps are
        left as they were (the fused track was made from them; ``counters["heading_smoother"]`` says so).
        Needs :class:`core.pdr.attitude.AttitudeEKF`; the fast path refuses it (the engine falls back to the
        reference).  Off by default (``benchmarks/ABLATION_RESULTS.md``: the tuning split's numbers).
    limb_upright_exit : float or None
        Issue #25 section 3, on by default (0.85; None: off, the smoother's own threshold in every mode).  While
        the carry mode is swinging or pocket (a limb), the heading smoother leaves its upright state (the back of
        the phone as the walking axis) only once the smoothed top edge's horizontal length exceeds this (0.85: 58
        deg from the vertical) instead of its own ``upright_exit`` (0.65, 49 deg).  A phone hanging top down in a
        swinging hand leans its smoothed top edge 40-50 deg off the vertical (the forearm's flexion, the swing,
        the attitude's tilt error under the swing): at 0.65 the axis flickered between the back and the top edge,
        up to every step, and each switch handed the step heading to the other axis's walking-direction offset
        (the top edge near the vertical has hardly a heading).  Simulator, 36 swinging walks with a magnetometer:
        30-s SD of step heading minus true walking direction, median 6.3 -> 2.5 deg (mean 15.7 -> 7.2), walks over
        6 deg 18 -> 10.  Not in every mode: in the hand-held mode, the IPIN routes (TUNING T21r03; REPORT T04r01 also
        seen when the choice was made) (a phone held in front that had
        stood upright kept its back at 32-49 deg of pitch, where the back's heading turns with the roll and the top
        edge's does not) got worse with 0.85 everywhere.  TUNING: the real walks and every guard recording
        identical (no tuning walk swings a phone that switches axis), so on by the bar for defect fixes.  The fast
        path mirrors it (the exit per grid sample from the carry track).
    limb_upright_modes : tuple of carry modes
        The carry modes in which ``limb_upright_exit`` holds (the smoother's own exit in the others).  Default
        swinging and pocket, as before; adding the ear (built by h13/tyrexswing) is **off by default**: on the two
        tuning walks it changes, the offset against the truth got better and the track (end error after the best
        rotation) worse, from one walker in a 5 x 5 m room; the report walks are identical either way (seen
        once).  On the Tyrex tuning walk ``Jakob_Nexus5_NoDist_Swinging`` the carry detector took a gently swinging hand, phone top up, for the ear
        on 55 % of the time (the arm's centripetal acceleration the same at both passes: no stride share; a rotation
        of 2.5 rad/s, at ``hard_arm_gyro_rad_s``); there the smoothed top edge crossed the ear's exit (0.65, 49 deg
        from the vertical) again and again: 78 axis switches in 140 steps (14 with the ear here): the open stride of
        the walking-direction estimate restarted at each switch and the top edge's offset never got three strides,
        so most steps had no offset.  A phone really at the ear stands upright too (``upright_y``), so the wider
        band keeps its back as well.  TUNING, offset error against the truth attitude (median / p90 deg, steps > 90
        deg off): ``NoDist_Swinging`` 96.5 / 142.4 (54 %) -> 14.5 / 108.4 (17.5 %), ``Dist_Swinging`` 118.8 / 173.5
        (74 %) -> 107.9 / 168.5 (64 %) (its end error after the best rotation 20.3 -> 25.9 % of the path, 1.2 -> 1.8
        % on ``NoDist``); every other tuning walk identical: the other Tyrex, RIDI and OxIOD truth walks, the 28
        real walks (``sensibility_testbed/hand_1_28_21_44`` has 16.5 s of ear) and the main benchmark's 92 (IPIN,
        Microsoft, IPOL).  ``benchmarks/discussion.md``.  The fast path mirrors it.
    cross_axis_modes : tuple of carry modes
        Issue #25 (h14/swinglimb), **off by default** (empty).  In these modes a step whose smoothed device axis
        (``forward_b="auto"``: the top edge ``y`` or the back ``-z``) has fewer than the walking-direction
        estimate's ``auto_min_strides`` accepted strides, while the other candidate axis has enough, takes the
        other axis's smoothed heading over the step plus that axis's offset: the walking direction is the
        walker's, whichever axis it is measured from.  Without it such a step keeps its axis's raw heading: on
        Jakob's Tyrex swinging walks (TUNING) the axis flickered between the back and the top edge, up to every
        step (76 switches in 131 steps on ``iPhone4S_NoDist_Swinging``), and every top-edge step went without an
        offset, 80-115 deg off the steps beside it.  The fast path refuses it (the reference runs).
    turning_keeps_modes : tuple of carry modes
        Issue #25 (h14/swinglimb), **off by default** (empty).  In these modes the walking-direction estimate's
        ``gap_keeps_turning`` holds (a stride rejected only for turning restarts its forgetting clock: the walker
        walks on, turning, and the phone stays where it is), in the others not (the estimate's own setting is
        overwritten on every grid sample while this is not empty).  In the 5 x 5 m Tyrex room 53-75 % of a
        swinging hand's strides turn more than 30 deg and the estimate was forgotten mid-walk.  The fast path
        refuses it.
    """

    def __init__(self, *, height_m: float | None = None, stride_model: StrideModel | None = None,
                 step_detector: StepDetector | None = None, attitude: AttitudeEKF | None = None,
                 smoother: RotationSmoother | None = None, grid_rate_hz: float = 50.0,
                 heading_delay_s: float | None = None, use_magnetometer: bool = True,
                 max_rotation_rms_rad_s: float = 3.0, rotation_window_s: float = 1.0, min_bout_steps: int = 3,
                 walking_direction: str = "auto", walkdir: WalkingDirection | None = None,
                 mag_stream: str = MAG, log: bool = False, gnss=None, site_from_gps: bool = True,
                 unix_offset_ns: int | None = None, keep_steps: bool | int = True,
                 carry: bool | CarryModeDetector = True, step_gates: dict | None = None,
                 swinging_max_rotation_rms_rad_s: float = 12.0,
                 wide_rotation_modes: tuple = (CARRY_SWINGING, CARRY_POCKET, CARRY_BAG), wide_while_pending_limb: bool = False,
                 rotation_hold_s: float = 8.0,
                 hold_while_settling: bool = True, recount_at_settle: bool = True, walk_start_step: bool = False,
                 walk_start_cadence_frac: float = 0.3, flush_at_end: bool = True,
                 acc_gap_bridge: bool | AccGapBridge = True, heading_smoother: str = HEADING_SMOOTHER_OFF,
                 limb_upright_exit: float | None = 0.85,
                 limb_upright_modes: tuple = (CARRY_SWINGING, CARRY_POCKET), cross_axis_modes: tuple = (),
                 turning_keeps_modes: tuple = ()):
        self.keep_steps = keep_steps
        if acc_gap_bridge is True:
            acc_gap_bridge = AccGapBridge()
        #: the accelerometer-gap bridge (None: off)
        self.bridge = acc_gap_bridge or None
        if carry is True:
            carry = CarryModeDetector(grid_rate_hz=grid_rate_hz)
        #: the carry-mode detector (None: off)
        self.carry = carry or None
        self.step_gates = dict(STEP_GATES if step_gates is None else step_gates)
        self.swinging_max_rotation_rms_rad_s = float(swinging_max_rotation_rms_rad_s)
        self.wide_rotation_modes = tuple(wide_rotation_modes)
        self.wide_while_pending_limb = bool(wide_while_pending_limb)
        self.rotation_hold_s = float(rotation_hold_s)
        self.hold_while_settling = bool(hold_while_settling)
        self.recount_at_settle = bool(recount_at_settle)
        self.walk_start_step = bool(walk_start_step)
        self.walk_start_cadence_frac = float(walk_start_cadence_frac)
        self.flush_at_end = bool(flush_at_end)
        self.limb_upright_exit = None if limb_upright_exit is None else float(limb_upright_exit)
        self.cross_axis_modes = tuple(cross_axis_modes)
        self.turning_keeps_modes = tuple(turning_keeps_modes)
        self.limb_upright_modes = tuple(limb_upright_modes)
        self.gnss = gnss
        self.site_from_gps = bool(site_from_gps)
        self.unix_offset_ns = unix_offset_ns
        self.mag_stream = str(mag_stream)
        self.height_m = height_m
        self.stride_model = stride_model or WeinbergStride()
        self.grid_rate_hz = float(grid_rate_hz)
        self.detector = step_detector or StepDetector(grid_rate_hz=grid_rate_hz)
        self._mode_detectors, self._det_of = self._make_mode_detectors()
        self.attitude = attitude or AttitudeEKF(use_magnetometer=use_magnetometer)
        if not use_magnetometer:
            self.attitude.use_magnetometer = False
        if heading_smoother not in HEADING_SMOOTHERS:
            raise ValueError(f"heading_smoother must be one of {HEADING_SMOOTHERS}, got {heading_smoother!r}")
        self.heading_smoother = heading_smoother
        if heading_smoother != HEADING_SMOOTHER_OFF:
            if not isinstance(self.attitude, AttitudeEKF):
                raise ValueError("heading_smoother needs core.pdr.attitude.AttitudeEKF (its error state), not "
                                 f"{type(self.attitude).__name__}")
            self.attitude.keep_history = True
        self.smoother = smoother or RotationSmoother(grid_rate_hz=grid_rate_hz, forward_b="auto")
        for stage in (self.detector, self.smoother):
            if abs(stage.grid_rate_hz - self.grid_rate_hz) > 1e-9:
                raise ValueError("step detector, smoother and pipeline must share one grid_rate_hz")
        #: the smoother's own exit threshold, restored outside a limb mode (``limb_upright_exit``)
        self._upright_exit = self.smoother.upright_exit
        self.heading_delay_s = self.smoother.delay_s if heading_delay_s is None else float(heading_delay_s)
        self.max_rotation_rms_rad_s = float(max_rotation_rms_rad_s)
        self.rotation_window_s = float(rotation_window_s)
        self.min_bout_steps = max(1, int(min_bout_steps))
        if walking_direction not in WALKING_DIRECTIONS:
            raise ValueError(f"walking_direction must be one of {WALKING_DIRECTIONS}, got {walking_direction!r}")
        self.walking_direction = walking_direction
        #: the walking-direction stage (None with walking_direction="device")
        self.walkdir = None if walking_direction == "device" else (
            walkdir or WalkingDirection(grid_rate_hz=self.grid_rate_hz, delay_s=self.heading_delay_s))
        #: the walking-direction estimate's own ``gap_keeps_turning`` (``turning_keeps_modes`` overrides it per mode)
        self._walkdir_keeps_turning = bool(getattr(self.walkdir, "gap_keeps_turning", False))
        self.log = log
        self.reset()

    def reset(self) -> None:
        self.detector.reset()
        self.detector.set_gates(self.step_gates[CARRY_HANDHELD])
        self.detector.step_period_s = math.nan
        self.detector.both_periodicity = math.nan
        self.detector.gait_std_m_s2 = math.nan
        if self.carry is not None:
            self.carry.reset()
        self._carry_mode = CARRY_HANDHELD
        self._gyro_last = None  # the last gyroscope reading, for the carry detector's grid
        # every mode detector's peaks of the last rotation_hold_s: (event, regressors, rotation RMS)
        for d in self._mode_detectors:
            if d is not self.detector:
                d.reset()
            d.step_period_s = math.nan
            d.both_periodicity = math.nan
            d.gait_std_m_s2 = math.nan
        self._held = {d: deque() for d in self._mode_detectors}
        self._active_det = self.detector
        self._rot_hold_ns = int(self.rotation_hold_s * 1e9)
        self._min_gap_ns = int(self.detector.min_step_interval_s * 1e9)
        self._confirmed_ns = -(1 << 62)  # the last confirmed candidate's peak time
        self._completed_ns = -(1 << 62)  # the last completed step's peak time
        #: held peaks made candidates at a change of the step detector (mode change); unconfirmed
        #: candidates replaced by them
        self.n_replayed = 0
        self.n_replaced_mode = 0
        #: walks' first steps taken from the gentle detector's held peaks (``walk_start_step``)
        self.n_walk_start_steps = 0
        #: steps the step detector gave out at the end of data (``flush_at_end``)
        self.n_flushed = 0
        self._start_counted_ns = None  # the last one's peak time
        # the gentle gait's detector, when walk_start_step looks back with it (None: off, or no carry detection)
        self._start_det = self._det_of.get(GENTLE) if self.walk_start_step else None
        self.attitude.reset()
        self.smoother.reset()
        self.smoother.upright_exit = self._upright_exit
        self.reckoner = DeadReckoner()
        self.grid = GridResampler(rate_hz=self.grid_rate_hz)
        #: Kubrak et al.'s eq.-1 regressors of |a| over the last 2 s (every step carries them)
        self.speed_window = SpeedFeatureWindow(grid_rate_hz=self.grid_rate_hz)
        # candidate steps in time order
        self._candidates: list[StepCandidate] = []
        self._bout_len = 0
        self._delay_ns = int(self.heading_delay_s * 1e9)
        self._bout_gap_ns = int(self.detector.max_step_interval_s * 1e9)
        self._rot = deque()  # (t_ns, |w|^2) of the gyroscope over the rotation window
        self._rot_sum = 0.0
        self._rot_window_ns = int(self.rotation_window_s * 1e9)
        self.n_rejected_rotation = 0
        self.n_rejected_bout = 0
        ks = self.keep_steps
        #: completed steps (all of them, or the last few: see ``keep_steps``)
        self.steps: list[Step] | deque = [] if ks is True else deque(maxlen=0 if ks is False else max(0, int(ks)))
        #: completed steps so far (``len(steps)`` unless ``keep_steps`` bounds the list)
        self.n_steps = 0
        #: fused steps (core.gnss.fusion.FusedStep), one per step, when there is a GPS fusion stage: all of them,
        #: or the last ``keep_steps`` (at least the last one) when that bounds the steps (the fusion's own
        #: ``keep_history`` says whether it keeps them all, issue #30)
        self.fused: list | deque = [] if ks is True else deque(maxlen=max(1, 0 if ks is False else int(ks)))
        #: the site the GPS gave the attitude filter (declination, field), or why not
        self.site: dict | None = None
        if self.gnss is not None:
            self.gnss.reset()
        #: smoothed forward vector on the grid, (t_ns, east, north), the last few seconds
        self._fwd = deque()
        #: ``cross_axis_modes``: both candidate axes' smoothed forward vectors, (t_ns, (top (e, n), back (e, n)))
        self._fwd_axes = deque()
        self._fwd_keep_ns = self._bout_gap_ns + self._delay_ns + 1_000_000_000
        if self.carry is not None:  # peaks replayed at a mode change are up to rotation_hold_s old
            self._fwd_keep_ns += int(self.rotation_hold_s * 1e9)
        #: non-finite sensor values skipped, per stream
        self.n_nonfinite: dict[str, int] = {}
        #: finite values beyond any phone sensor's range (IMPOSSIBLE) skipped, per stream
        self.n_impossible: dict[str, int] = {}
        #: saturation and dead-sensor detectors, per stream
        self.health = {GYRO: SensorHealth(SATURATION_FLOOR[GYRO]), ACC: SensorHealth(SATURATION_FLOOR[ACC]),
                       self.mag_stream: SensorHealth(SATURATION_FLOOR[MAG])}
        self.t_ns = 0
        self.seen: dict[str, int] = {}
        if self.walkdir is not None:
            if self.turning_keeps_modes:  # the estimate's own rule back (``_sync_turning_rule`` overwrites it)
                self.walkdir.gap_keeps_turning = self._walkdir_keeps_turning
            self.walkdir.reset()
        self._log: list[tuple] = []
        if self.bridge is not None:
            self.bridge.reset()
        self._acc_last_ns = -1  # the last accelerometer reading (-1: none yet)
        self._gyro_t_ns = -(1 << 62)  # the last gyroscope reading (the bridge checks that it ran through a gap)
        self._t_first_ns = -1  # the first event's time (the labels' time origin)

    # -- streaming --------------------------------------------------------------
    def update(self, stream: str, t_ns: int, values) -> list[Step]:
        """Process one sensor event; returns the steps it completed (usually none)."""
        self.seen[stream] = self.seen.get(stream, 0) + 1
        health = self.health.get(stream)
        if health is not None:
            x, y, z = values[0], values[1], values[2]
            lim = IMPOSSIBLE[stream if stream in IMPOSSIBLE else MAG]
            if not (-lim <= x <= lim and -lim <= y <= lim and -lim <= z <= lim):  # false for NaN too
                if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                    self.n_nonfinite[stream] = self.n_nonfinite.get(stream, 0) + 1
                else:
                    self.n_impossible[stream] = self.n_impossible.get(stream, 0) + 1
                return []
            health.update(t_ns, x, y, z)
        self.t_ns = t_ns
        if self._t_first_ns < 0:
            self._t_first_ns = t_ns
        if stream == GYRO:
            wx, wy, wz = values[0], values[1], values[2]
            self.attitude.predict(t_ns, wx, wy, wz)
            self._gyro_last = (wx, wy, wz)
            b = self.bridge
            if b is not None:
                if self._acc_last_ns >= 0 and t_ns - self._acc_last_ns >= b.min_gap_ns:
                    self._gap_gyro(t_ns, wx, wy, wz)
                self._gyro_t_ns = t_ns
            w2 = wx * wx + wy * wy + wz * wz
            rot = self._rot
            rot.append((t_ns, w2))
            self._rot_sum += w2
            limit = t_ns - self._rot_window_ns
            while rot[0][0] < limit:
                self._rot_sum -= rot.popleft()[1]
            return []
        if stream == self.mag_stream:
            self.attitude.update_mag(t_ns, values[0], values[1], values[2])
            return []
        if stream != ACC:
            if stream == GPS and self.gnss is not None:
                self.gnss.add_fix(t_ns, values)
                if self.site is None and self.site_from_gps and self.gnss.anchor is not None:
                    self.apply_site(self.gnss.anchor)
            elif stream == GNSS_STATUS and self.gnss is not None:
                self.gnss.add_status(t_ns, values)
            return []  # rotvec, ...: not used by the core PDR
        ax, ay, az = values[0], values[1], values[2]
        done: list[Step] = self._bridge_gap(t_ns) if self.bridge is not None and self.bridge.open else []
        self._acc_last_ns = t_ns
        att, grid, sm = self.attitude, self.grid, self.smoother  # (locals: read on every grid sample)
        att.update_acc(t_ns, ax, ay, az)
        norm = math.sqrt(ax * ax + ay * ay + az * az)  # eq. 2
        for tg, x in grid.update(t_ns, norm):
            if grid.restarted and self.detector.n_grid:
                self.detector.restart_bout()
                self.speed_window.reset()
                if self.carry is not None:
                    self.carry.restart()
                    for d in self._mode_detectors:
                        d.restart_bout()
            self.speed_window.update(tg, x)
            if self.carry is None:
                ev = self.detector.update_grid(tg, x)
                if ev is not None:
                    self._candidate(ev)
            else:
                ev = self._carry_steps(tg, x, ax, ay, az)
            if att.initialized:
                if self.limb_upright_exit is not None:  # the exit of the upright state on a limb (issue #25)
                    sm.upright_exit = (self.limb_upright_exit if self._carry_mode in self.limb_upright_modes
                                       else self._upright_exit)
                mat = att.matrix()
                heading = sm.update(mat)
                fe, fn = sm.forward_east, sm.forward_north
                fwd = self._fwd
                fwd.append((tg, fe, fn))
                while fwd[0][0] < tg - self._fwd_keep_ns:
                    fwd.popleft()
                if self.cross_axis_modes and sm.axis_forward is not None:
                    fa = self._fwd_axes
                    fa.append((tg, sm.axis_forward))
                    while fa[0][0] < tg - self._fwd_keep_ns:
                        fa.popleft()
                if self.walkdir is not None:
                    if self.turning_keeps_modes:
                        self._sync_turning_rule()
                    self.walkdir.update(tg, att.q, ax, ay, az, fe, fn, ev is not None, sm.forward_b, mat)
            else:
                heading = math.nan
            if self.log:
                self._log.append((tg, att.q, heading, att.acc_sigma2, att.mag_sigma2, att.mag_rejected))
            done.extend(self._release(tg))
        return done

    def _gap_gyro(self, t_ns: int, wx: float, wy: float, wz: float) -> None:
        """A gyroscope reading inside an accelerometer gap: to the bridge, with the phone's forward axis from the
        attitude filter (running on gyroscope and magnetometer) every ``heading_interval_s``."""
        b = self.bridge
        a = self.attitude
        b.gyro(t_ns, wx, wy, wz, self._acc_last_ns, self._gyro_t_ns)
        if b.wants_heading(t_ns) and a.initialized:
            m = a.matrix()
            fx, fy, fz = self.smoother.forward_b
            b.heading(t_ns, m[0][0] * fx + m[0][1] * fy + m[0][2] * fz, m[1][0] * fx + m[1][1] * fy + m[1][2] * fz)

    def _bridge_gap(self, t_ns: int) -> list[Step]:
        """The accelerometer is back after a gap the gyroscope ran through: its estimated steps, if any.

        The confirmed steps before the gap are completed first (their headings from before it), an unconfirmed
        bout is dropped (as at the end of data), then the estimated steps follow in time order."""
        _, est, length = self.bridge.close(t_ns, self.attitude.initialized)
        if not est:
            return []
        done = self.finish_candidates()
        for s in est:
            done.append(self._estimated_step(s, length))
        return done

    def _estimated_step(self, s: EstimatedStep, length: float) -> Step:
        heading = s.device_heading_rad
        if self.walkdir is not None:
            heading = self.walkdir.step_heading(heading, self.walking_direction,
                                                self._carry_mode if self.carry is not None else None)
        feats = StepFeatures(t_ns=s.t_ns, duration_s=s.period_s, acc_max_m_s2=math.nan, acc_min_m_s2=math.nan,
                             acc_var_m2_s4=math.nan, height_m=self.height_m)
        step = self._append_step(s.t_ns, length, heading, feats, self.attitude.mag_rejected,
                                 self.step_carry_mode(s.t_ns), estimated=True)
        if self.gnss is not None:
            self.fused.append(self.gnss.add_step(step))
        return step

    def apply_site(self, anchor) -> None:
        """The anchoring fix's (``(t_ns, lat, lon, alt)``) magnetic declination and field for the attitude filter
        (see ``site_from_gps``); what was applied in :attr:`site`.  The pipeline calls it at the first anchoring fix,
        the desktop fast path at the same event."""
        t_ns, lat, lon, alt = anchor
        if self.unix_offset_ns is None:
            # no WMM field without a date, but a good fix still says the walk is outdoors, as a dated one does
            if hasattr(self.attitude, "set_outdoors"):
                self.attitude.set_outdoors()
            self.site = {"applied": False, "why": "no date for the magnetic model", "outdoors": True}
            return
        try:
            self.site = self.set_site(lat, lon, alt, int(self.unix_offset_ns) + int(t_ns))
        except (ImportError, ValueError) as e:
            self.site = {"applied": False, "why": str(e)}

    def set_site(self, lat_deg: float, lon_deg: float, alt_m: float, unix_ns: int) -> dict:
        """Give the attitude filter a place's WMM declination (unless one is set) and field strength and dip.

        What the first GPS fix does (``site_from_gps``); callers that know the place before the
        run (the GPS benchmark) call it directly.  Returns what was applied.
        """
        from core.geodesy import magnetic_field, unix_ns_to_datetime

        decl, dip, total = magnetic_field(lat_deg, lon_deg, alt_m if math.isfinite(alt_m) else 0.0,
                                          unix_ns_to_datetime(int(unix_ns)))
        a = self.attitude
        set_decl = hasattr(a, "declination_rad") and a.declination_rad == 0.0
        if set_decl:
            a.declination_rad = decl
        if hasattr(a, "set_site_field"):
            a.set_site_field(total, dip)
        return {"applied": True, "declination_deg": math.degrees(decl) if set_decl else None,
                "dip_deg": math.degrees(dip), "field_uT": total}

    def rotation_rms_rad_s(self) -> float:
        """RMS rotation rate of the phone over the last ``rotation_window_s`` (rad/s; 0 without gyroscope)."""
        n = len(self._rot)
        return math.sqrt(max(self._rot_sum, 0.0) / n) if n else 0.0

    def _make_mode_detectors(self) -> tuple[list, dict]:
        """One step detector per distinct gates of ``step_gates`` (the hand-held gates: ``self.detector``);
        returns ``(detectors, {mode: detector})``.  Without carry detection: ``self.detector`` alone."""
        base = self.detector
        if self.carry is None:
            return [base], {}
        default = self.step_gates[CARRY_HANDHELD]
        by_gates = {default: base}
        # the uneven pocket's gates only where the carry detector can call a pocket uneven (an option): otherwise
        # their detector would be fed every grid sample and never chosen
        gates_of = {m: g for m, g in self.step_gates.items()
                    if m != UNEVEN_POCKET or math.isfinite(self.carry.uneven_on_share)}
        for gates in gates_of.values():
            if gates not in by_gates:
                det = copy.copy(base)  # the same settings; reset() gives it its own state
                det.reset()
                det.set_gates(gates)
                by_gates[gates] = det
        return list(by_gates.values()), {m: by_gates[g] for m, g in gates_of.items()}

    def _carry_steps(self, tg: int, x: float, ax: float, ay: float, az: float) -> StepEvent | None:
        """One grid sample with carry detection: the mode, every mode's step detector, the active one's peak.

        Each distinct :class:`core.pdr.steps.StepGates` has its own detector, all fed the same norm (a few
        microseconds each); the one of the mode in force gives the candidates.  Every detector's peaks of
        the last ``rotation_hold_s`` are held with the rotation and regressors at the peak: when the mode
        changes to one with another detector, the unconfirmed candidates are replaced by the new detector's
        held peaks since the last confirmed step (:meth:`_switch_detector`), so the seconds the carry
        detector needed to decide (its window, its hysteresis) are counted with the right gates.
        """
        c = self.carry
        g = self._gyro_last
        settling = self.hold_while_settling and c.settling  # before this sample's decision
        walk_start = c.settling_walk  # only the walk's start held open (the detector's settle_walk_s)
        n_changes = len(c.changes)
        mode = c.update_grid(tg, ax, ay, az) if g is None else c.update_grid(tg, ax, ay, az, g[0], g[1], g[2])
        self._carry_mode = mode
        period = c.step_period_s
        active = self._active_det
        out = None
        regs = None
        both = c.both_periodicity
        amp = c.gait_std_m_s2
        for det in self._mode_detectors:
            det.step_period_s = period
            det.both_periodicity = both
            det.gait_std_m_s2 = amp
            ev = det.update_grid(tg, x)
            if ev is not None:
                if regs is None:
                    regs, rot = self.speed_window.features(), self.rotation_rms_rad_s()
                held = self._held[det]
                held.append((ev, regs, rot))
                while held[0][0].t_ns < ev.t_ns - self._rot_hold_ns:
                    held.popleft()
                if det is active:
                    out = ev
        new = self._det_of[self._gates_key(mode, c.gentle, c.uneven)]
        changed = len(c.changes) != n_changes
        if new is not active:
            # while the walk's start is only held open, a gentle or uneven walk's detector without a change of mode
            # switches as outside the settling (its confirmed steps stay)
            self._switch_detector(new, tg, settling and (changed or not walk_start))
            return None
        if settling and changed and self.recount_at_settle:  # a change of mode on the same detector: recount
            self._switch_detector(new, tg, True)  # (this sample's peak among the held ones: still a peak now)
            return out
        if out is not None:
            self._candidate(out, regs, rot)
        return out

    def _gates_key(self, mode: str, gentle: bool, uneven: bool) -> str:
        """The key of ``step_gates`` in force: the mode's, a gentle walk's (:meth:`gentle_applies`) or, in a pocket
        whose two half-strides are very unlike (the carry detector's ``uneven``), the limb gates of
        ``UNEVEN_POCKET`` (issue #25)."""
        if gentle and self.gentle_applies(mode):
            return GENTLE
        if gentle and mode == CARRY_SWINGING and GENTLE_SWING in self._det_of:  # a gently swung hand (issue #25)
            return GENTLE_SWING
        if uneven and mode == CARRY_POCKET and UNEVEN_POCKET in self._det_of:
            return UNEVEN_POCKET
        return mode

    def gentle_applies(self, mode: str) -> bool:
        """A gentle walk (the carry detector's ``gentle``) is counted with the ``GENTLE`` gates in the modes that
        count with the hand-held gates (the trunk's) while walking; a limb's gates stay, and "not walking" keeps the
        hand-held gates (standing, turning on the spot: weak peaks there are no steps)."""
        return (GENTLE in self.step_gates and mode != CARRY_STILL
                and self.step_gates.get(mode) == self.step_gates[CARRY_HANDHELD])

    def _switch_detector(self, det: StepDetector, t_grid_ns: int, settled: bool = False) -> None:
        """The mode in force has another step detector: its held peaks replace the unconfirmed candidates, and
        when the change ends a walk's settling (``settled``: the carry detector's ``settling`` until now, the steps
        held meanwhile, ``hold_while_settling``) every candidate not yet completed: the walk's first steps are
        counted with its mode's gates (a limb's weak half-stride too: one step per footfall, issue #25)."""
        self._active_det = det
        # a recount keeps the headings the replaced candidates had (the same peak comes back: the same interval)
        headings = {heading_key(c.event): c.heading_rad for c in self._candidates
                    if c.heading_rad is not None} if settled and self.recount_at_settle else None
        kept = [] if settled else [c for c in self._candidates if c.confirmed]
        self.n_replaced_mode += len(self._candidates) - len(kept)
        self._candidates = kept
        self._bout_len = 0
        if settled:
            self._confirmed_ns = self._completed_ns
        after = self._confirmed_ns + self._min_gap_ns
        n_rot = self.n_rejected_rotation  # counted once, when the peak was live
        for ev, regs, rot in self._held[det]:
            if ev.t_ns > after and ev.t_ns >= t_grid_ns - self._rot_hold_ns:
                self.n_replayed += 1
                self._candidate(ev, regs, rot)
        self.n_rejected_rotation = n_rot
        if headings:
            for c in self._candidates:
                if c.heading_rad is None:
                    c.heading_rad = headings.get(heading_key(c.event))

    def step_carry_mode(self, t_ns: int, changes: list[CarryChange] | None = None, mode: str | None = None) -> str:
        """The carry mode a step is labelled with: the mode in force at its peak, except that a counted step is
        never "not walking" (the detector's hysteresis lags the first steps of a walk): then the walking mode
        that follows, or the one before, or hand-held.  ``changes`` and ``mode``: the detector's change log and
        current mode to read (default: the detector's own; the fast path gives them as they were at a grid sample)."""
        if self.carry is None:
            return CARRY_HANDHELD
        changes = self.carry.changes if changes is None else changes
        current = self.carry.mode if mode is None else mode
        at = _mode_at(t_ns, changes, current)
        if at != CARRY_STILL:
            return at
        after = [c.to_mode for c in changes if c.t_ns > t_ns and c.to_mode != CARRY_STILL]
        if after:
            return after[0]
        before = [c.from_mode for c in changes if c.t_ns <= t_ns and c.from_mode != CARRY_STILL]
        return before[-1] if before else (current if current != CARRY_STILL else CARRY_HANDHELD)

    def carry_mode_at(self, t_ns: int) -> str:
        """The carry mode in force at ``t_ns`` (the last change at or before it; hand-held without detection)."""
        if self.carry is None:
            return CARRY_HANDHELD
        return _mode_at(t_ns, self.carry.changes, self.carry.mode)

    #: carry-mode names in the labels
    _CARRY_WORDS = {CARRY_SWINGING: "in a swinging hand", CARRY_POCKET: "in a trouser pocket",
                    CARRY_BAG: "in a bag or on the trunk", CARRY_EAR: "at the ear"}

    def _carry_label(self) -> str | None:
        """A label when the phone was walked with mostly otherwise than in the hand (issue #17)."""
        if self.carry is None:
            return None
        walking = {m: s for m, s in self.carry.time_s.items() if m != CARRY_STILL and s > 0}
        total = sum(walking.values())
        if total < 10.0:
            return None
        mode = max(walking, key=walking.get)
        if mode not in self._CARRY_WORDS:
            return None
        wd = self.walkdir
        how = []
        if self.step_gates.get(mode) != self.step_gates.get(CARRY_HANDHELD):
            how.append("steps counted with that mode's gates")
        if wd is not None and wd.n_steps_offset:
            how.append(f"walking direction from the acceleration on {wd.n_steps_offset} of {self.n_steps} steps "
                       f"(offset {math.degrees(wd.offset_rad):+.0f} deg from the phone's axis at the end)")
        else:
            how.append("walking direction from the phone's axis (no walking-direction estimate yet)")
        return (f"phone carried {self._CARRY_WORDS[mode]} {100 * walking[mode] / total:.0f} % of the walking time "
                f"({len(self.carry.changes)} carry-mode change{'s' if len(self.carry.changes) != 1 else ''}): "
                + "; ".join(how))

    def _rotation_limit_rad_s(self) -> float:
        """The rotation gate in force: wider for a limb whose rotation is periodic at the stride
        (``wide_rotation_modes``)."""
        c = self.carry
        mode = self._carry_mode
        if c is None or not c.rotation_periodic or mode not in self.wide_rotation_modes:
            return self.max_rotation_rms_rad_s
        pending = c.pending_mode
        wide = (mode == CARRY_SWINGING or pending is None or self.step_gates.get(pending) == self.step_gates.get(mode)
                or (self.wide_while_pending_limb and pending in self.wide_rotation_modes))
        return max(self.max_rotation_rms_rad_s, self.swinging_max_rotation_rms_rad_s) if wide \
            else self.max_rotation_rms_rad_s

    def _candidate(self, ev: StepEvent, regressors: tuple | None = None, rot: float | None = None) -> None:
        """A peak from the detector: apply the rotation and bout gates.

        ``regressors`` and ``rot``: the speed regressors and the rotation RMS at the peak (default: now)."""
        if ev.duration_s != ev.duration_s:  # first step after a pause: a new bout
            self._drop_unconfirmed()
        if (self.rotation_rms_rad_s() if rot is None else rot) > self._rotation_limit_rad_s():
            self.n_rejected_rotation += 1
            self._drop_unconfirmed()
            return
        self._candidates.append(StepCandidate(ev, None, False,
                                              self.speed_window.features() if regressors is None else regressors))
        self._bout_len += 1
        if self._bout_len >= self.min_bout_steps:
            before_ns = self._confirmed_ns
            for c in self._candidates:
                c.confirmed = True
            self._confirmed_ns = ev.t_ns
            if self._start_det is not None and self._bout_len == self.min_bout_steps:
                self._walk_start_step(before_ns)

    def _walk_start_step(self, before_ns: int) -> None:
        """``walk_start_step``: the bout just confirmed began after a pause: the gentle detector's held peak one step
        period before its first step (``walk_start_cadence_frac``), after the steps before (``before_ns``: the last
        confirmed one) and through the rotation gate, is inserted before the bout as the walk's first step."""
        k = len(self._candidates) - self._bout_len
        if self._start_det is self._active_det or k < 0 or self._bout_len < 2:
            return
        first, second = self._candidates[k].event, self._candidates[k + 1].event
        if first.duration_s == first.duration_s:  # not a walk's start: the detector's bout went on
            return
        p = second.t_ns - first.t_ns
        f = self.walk_start_cadence_frac
        lo, hi = first.t_ns - (1.0 + f) * p, first.t_ns - (1.0 - f) * p
        after = max(before_ns, self._completed_ns) + self._min_gap_ns
        for ev, regs, rot in reversed(self._held[self._start_det]):
            if ev.t_ns < lo or ev.t_ns <= after:
                return
            if ev.t_ns <= hi and rot <= self._rotation_limit_rad_s():
                self._candidates.insert(k, StepCandidate(ev, None, True, regs))
                self.count_walk_start_step(ev.t_ns)
                return

    def count_walk_start_step(self, t_ns: int) -> None:
        """A walk's first step (peak at ``t_ns``) was inserted by ``walk_start_step``: counted in
        ``n_walk_start_steps`` once (a recount inserts the same one again).  :meth:`_walk_start_step` and the desktop
        fast path's mirror of it (``desktop/fast/gates.py``) both count through here."""
        if t_ns != self._start_counted_ns:
            self.n_walk_start_steps += 1
            self._start_counted_ns = t_ns

    def set_carry_state(self, mode: str, detector: StepDetector) -> None:
        """The carry mode and the step detector (one of the mode detectors) in force: how the desktop fast path,
        which runs the carry detector over the whole recording at once, leaves the pipeline as its last grid sample
        would (``desktop/fast/pipeline.py``)."""
        if not any(detector is d for d in self._mode_detectors):
            raise ValueError("set_carry_state takes one of the pipeline's own step detectors")
        self._carry_mode = mode
        self._active_det = detector

    @property
    def mode_detectors(self) -> tuple:
        """The step detectors, one per distinct gates of ``step_gates`` (the hand-held one, :attr:`detector`,
        first; it alone without carry detection), in the order the pipeline feeds them (a new tuple)."""
        return tuple(self._mode_detectors)

    @property
    def detector_of(self) -> MappingProxyType:
        """``{gates key: step detector}`` (a carry mode, or GENTLE / GENTLE_SWING / UNEVEN_POCKET where those gates
        are set; empty without carry detection): which of :attr:`mode_detectors` counts the steps (read-only)."""
        return MappingProxyType(self._det_of)

    @property
    def active_detector(self):
        """The step detector whose peaks are candidates now (one of :attr:`mode_detectors`)."""
        return self._active_det

    @property
    def walk_start_detector(self):
        """The gentle gait's detector that looks back for a walk's first step (``walk_start_step``; None: off)."""
        return self._start_det

    @property
    def base_upright_exit(self) -> float:
        """The smoother's own exit threshold of the upright state, in force outside a limb mode
        (``limb_upright_exit``)."""
        return self._upright_exit

    @property
    def rotation_window_ns(self) -> int:
        """``rotation_window_s`` in ns: the window of the rotation RMS gate."""
        return self._rot_window_ns

    def _drop_unconfirmed(self) -> None:
        kept = [c for c in self._candidates if c.confirmed]
        self.n_rejected_bout += len(self._candidates) - len(kept)
        self._candidates = kept
        self._bout_len = 0

    def _release(self, t_grid_ns: int) -> list[Step]:
        """Give due candidates their heading; complete confirmed ones from the front."""
        cands = self._candidates
        if not cands:
            return []
        for c in cands:
            if c.heading_rad is None and c.event.t_ns + self._delay_ns <= t_grid_ns:
                c.heading_rad = self._step_heading(c.event)
        if not cands[-1].confirmed and t_grid_ns - cands[-1].event.t_ns > self._bout_gap_ns:
            self._drop_unconfirmed()  # the bout ended too short
            cands = self._candidates  # the list it kept (before: the old list, whose released steps stayed in it)
        done = []
        # while the carry detector settles a walk's mode, its steps wait (within the peaks' hold)
        hold = self._rot_hold_ns if self.hold_while_settling and self.carry is not None and self.carry.settling \
            else -(1 << 62)
        while cands and cands[0].confirmed and cands[0].heading_rad is not None \
                and t_grid_ns - cands[0].event.t_ns >= hold:
            c = cands.pop(0)
            done.append(self._complete(c.event, c.heading_rad, c.regressors))
        return done

    def _step_heading(self, ev: StepEvent) -> float:
        """Mean smoothed heading over the delay-compensated step interval (nan before the attitude starts)."""
        fwd = self._fwd
        if not fwd:
            return math.nan
        duration = ev.duration_s if ev.duration_s == ev.duration_s else DEFAULT_STEP_DURATION_S
        t1 = ev.t_ns + self._delay_ns
        t0 = t1 - int(duration * 1e9)
        t, e, n = zip(*fwd)
        heading = interval_heading(t, e, n, t0, t1)
        if self.walkdir is None:
            return heading
        # the carry mode in force, when a carry-mode detector runs (core.pdr.carry); None without one
        mode = self._carry_mode if self.carry is not None else None
        if mode in self.cross_axis_modes and self._fwd_axes:
            other = self._other_axis_heading(t0, t1)
            if other is not None:
                return self.walkdir.step_heading(other[1], self.walking_direction, mode, axis=other[0])
        return self.walkdir.step_heading(heading, self.walking_direction, mode)

    def _sync_turning_rule(self) -> None:
        """``turning_keeps_modes``: the walking-direction estimate's ``gap_keeps_turning`` for the carry mode now."""
        self.walkdir.gap_keeps_turning = self._carry_mode in self.turning_keeps_modes

    def _other_axis_heading(self, t0_ns: int, t1_ns: int):
        """``cross_axis_modes``: ``(axis, its smoothed heading over the step)`` of the other candidate axis where
        the current axis has fewer than ``auto_min_strides`` accepted strides and the other has enough; else None."""
        wd = self.walkdir
        if self.walking_direction == "device" or wd.n_used >= wd.auto_min_strides:
            return None
        for i, axis in enumerate(SMOOTHER_AXES):
            if axis == wd.axis_key:
                continue
            st = wd.axis_state(axis)
            if st is not None and st.n >= wd.auto_min_strides:
                t = [x[0] for x in self._fwd_axes]
                e = [x[1][i][0] for x in self._fwd_axes]
                n = [x[1][i][1] for x in self._fwd_axes]
                h = interval_heading(t, e, n, t0_ns, t1_ns)
                if h == h:
                    return axis, h
        return None

    def finish(self) -> list[Step]:
        """End of data: complete the confirmed steps still waiting for their heading; drop an unconfirmed bout.

        A recording that ends inside an accelerometer gap has nothing to bridge to: the gap is dropped."""
        if self.bridge is not None and self.bridge.open:
            self.bridge.abandon()
        if self.flush_at_end:
            self._flush_detector()
        done = self.finish_candidates()
        if self.gnss is not None:
            self.gnss.finish()
        return done

    def _flush_detector(self) -> None:
        """``flush_at_end``: the step detector in force gives the steps only the missing next samples kept back
        (:meth:`core.pdr.steps.StepDetector.flush`); they go through the rotation and bout gates as any peak."""
        det = self.detector if self.carry is None else self._active_det
        for ev in det.flush():
            self._candidate(ev)
        self.n_flushed = det.n_flushed

    def finish_candidates(self) -> list[Step]:
        """Complete the confirmed candidates now (headings from what the smoother has), drop an unconfirmed bout."""
        self._drop_unconfirmed()
        done = [self._complete(c.event, self._step_heading(c.event) if c.heading_rad is None else c.heading_rad,
                               c.regressors) for c in self._candidates]
        self._candidates = []
        return done

    def step_features(self, ev: StepEvent, regressors: tuple) -> StepFeatures:
        """What the stride model sees of a step (eq. 4's inputs and Kubrak's eq.-1 regressors); the fast path
        (desktop.fast) builds its steps with it too."""
        duration = ev.duration_s if ev.duration_s == ev.duration_s else DEFAULT_STEP_DURATION_S
        return StepFeatures(t_ns=ev.t_ns, duration_s=duration, acc_max_m_s2=ev.acc_max_m_s2,
                            acc_min_m_s2=ev.acc_min_m_s2, acc_var_m2_s4=ev.acc_var_m2_s4, height_m=self.height_m,
                            window_mean_m_s2=regressors[0], window_freq_hz=regressors[1],
                            window_std_m_s2=regressors[2])

    def _complete(self, ev: StepEvent, heading: float, regressors: tuple) -> Step:
        self._completed_ns = ev.t_ns
        step = self.add_step(ev, heading, regressors, self.attitude.mag_rejected, self.step_carry_mode(ev.t_ns))
        if self.gnss is not None:
            self.fused.append(self.gnss.add_step(step))
        return step

    def add_step(self, ev: StepEvent, heading: float, regressors: tuple, mag_rejected: bool,
                 carry_mode: str) -> Step:
        """A confirmed step with its heading: its length (eq. 4), the dead reckoning (eq. 1), the step list.
        ``mag_rejected``: the filter's flag for the last magnetometer reading; the fast path (desktop.fast)
        completes its steps with it too."""
        feats = self.step_features(ev, regressors)
        length = self.stride_model.length_m(feats)  # eq. 4
        if self.bridge is not None:
            self.bridge.note_step(ev.t_ns, length, ev.duration_s)
        return self._append_step(ev.t_ns, length, heading, feats, mag_rejected, carry_mode)

    def _append_step(self, t_ns: int, length: float, heading: float, feats: StepFeatures, mag_rejected: bool,
                     carry_mode: str, estimated: bool = False) -> Step:
        if heading != heading:  # no attitude yet (no magnetometer reading so far)
            heading = self.attitude.initial_yaw_rad
        east, north = self.reckoner.update(length, heading)  # eq. 1
        step = Step(self.n_steps, t_ns, length, heading, east, north, feats,
                    not mag_rejected and self.attitude.use_magnetometer, carry_mode=carry_mode, estimated=estimated)
        self.steps.append(step)
        self.n_steps += 1
        return step

    #: share of rejected magnetometer readings above which the summary warns
    MAG_REJECTED_WARN = 0.3

    def labels(self) -> tuple[str, ...]:
        out = []
        a = self.attitude
        used, rej = getattr(a, "n_mag_used", 0), getattr(a, "n_mag_rejected", 0)
        if self.mag_all_rejected():
            top = sorted(((v, k) for k, v in a.mag_reasons.items() if k not in ("used", "initialising")),
                         reverse=True)[:2]
            why = ", ".join(f"{k} {v}" for v, k in top)
            out.append(f"magnetometer rejected 100 % of the time ({why}): no compass correction, the heading "
                       f"rests on the gyroscope from the start and its absolute direction is not to be trusted")
        elif a.use_magnetometer and used + rej > 100 and rej > self.MAG_REJECTED_WARN * (used + rej):
            out.append(f"magnetometer {100 * rej / (used + rej):.0f} % rejected: the heading leans on the "
                       f"gyroscope (bent or miscalibrated field)")
        sm = self.smoother
        wd = self.walkdir
        by_acc = wd is not None and wd.n_steps_offset > 0.5 * max(self.n_steps, 1)
        if getattr(sm, "auto_axis", False) and sm.n_upright > 0.5 * max(self.detector.n_grid, 1) and not by_acc:
            out.append("phone upright most of the time (pocket or hanging hand): walking direction from the back "
                       "of the phone, off by an unknown constant without GPS")
        if self.n_nonfinite:
            what = ", ".join(f"{k} {v}" for k, v in sorted(self.n_nonfinite.items()))
            out.append(f"non-finite sensor values skipped ({what})")
        if self.n_impossible:
            what = ", ".join(f"{k} {v}" for k, v in sorted(self.n_impossible.items()))
            out.append(f"impossible sensor values (beyond any phone sensor's range) skipped ({what})")
        out.extend(self._health_labels())
        out.extend(self._gap_labels())
        carry = self._carry_label()
        if carry:
            out.append(carry)
        if not self.seen.get(GYRO) and self.seen.get(ACC):
            out.append("no gyroscope: heading from accelerometer and magnetometer only (noisy while walking)")
        if not self.attitude.use_magnetometer:
            out.append("magnetometer off: heading is relative to the start (first step points North)")
        elif not self.seen.get(self.mag_stream) and self.seen.get(ACC):
            out.append("no magnetometer: heading is relative to the start (first step points North)")
        return tuple(out)

    #: a stream counts as saturated from this many runs on a rail, or this long on one (s)
    SATURATED_MIN_RUNS = 2
    SATURATED_MIN_S = 0.5

    _SATURATION_EFFECT = {ACC: "peaks clipped: steps and step lengths unreliable",
                          GYRO: "turns faster than its range are lost from the heading",
                          MAG: "the heading leans on the gyroscope"}
    _DEAD_EFFECT = {ACC: "no steps are detected there", GYRO: "the heading does not follow turns there",
                    MAG: "its readings carry no heading"}
    _UNIT = {ACC: "m/s^2", GYRO: "rad/s", MAG: "uT"}

    def _health_labels(self) -> list[str]:
        out = []
        for stream, h in self.health.items():
            kind = MAG if stream == self.mag_stream else stream
            name = _SENSOR_NAMES[kind] + ("" if stream == kind else f" ({stream})")
            if h.saturated_runs >= self.SATURATED_MIN_RUNS or h.saturated_s >= self.SATURATED_MIN_S:
                out.append(f"{name} saturated: stuck at +-{h.level:.4g} {self._UNIT[kind]} (its range limit) for "
                           f"{h.saturated_s:.1f} s in {h.saturated_runs} run(s); {self._SATURATION_EFFECT[kind]}")
            if h.dead_runs:
                what = "all zeros" if h.dead_zero else "frozen at one value"
                out.append(f"{name} dead: {what} for {h.dead_s:.0f} s in {h.dead_runs} stretch(es); "
                           f"{self._DEAD_EFFECT[kind]}")
        return out

    def _gap_labels(self) -> list[str]:
        out = []
        for g in (self.bridge.gaps if self.bridge is not None else ()):
            where = (f"accelerometer gap of {g.duration_s:.1f} s ({(g.start_ns - self._t_first_ns) * 1e-9:.1f} s to "
                     f"{(g.end_ns - self._t_first_ns) * 1e-9:.1f} s) while the gyroscope ran")
            if g.verdict is GapVerdict.BRIDGED:
                out.append(f"{where}: {g.n_steps} steps ({g.distance_m:.1f} m) estimated, not measured: the gyroscope "
                           f"shows walking for {g.walking_s:.0f} s at {1 / g.step_period_s:.2f} steps/s, each step "
                           f"{g.step_length_m:.2f} m (the mean before the gap), heading from the attitude filter")
            else:
                out.append(f"{where}: {g.verdict.reason}")
        return out

    def gap_counters(self) -> dict:
        """The accelerometer gaps the bridge handled, for the summary (times from the first event)."""
        gaps = self.bridge.gaps if self.bridge is not None else []
        return {"acc_gaps": [g.as_dict(self._t_first_ns) for g in gaps],
                "n_steps_estimated": sum(g.n_steps for g in gaps)}

    def mag_all_rejected(self) -> bool:
        """The magnetometer is on and gave readings, and the attitude filter rejected every one of them."""
        a = self.attitude
        used, rej = getattr(a, "n_mag_used", 0), getattr(a, "n_mag_rejected", 0)
        return bool(a.use_magnetometer and used == 0 and rej >= self.MAG_ALL_REJECTED_MIN)

    #: readings rejected before "rejected 100 % of the time" is said (2 s at 50 Hz)
    MAG_ALL_REJECTED_MIN = 100

    def health_counters(self) -> dict:
        """Counters of the degraded-mode detectors, for the summary."""
        return {"impossible_skipped": dict(self.n_impossible),
                "sensor_health": {k: h.as_dict() for k, h in self.health.items() if h.n},
                "mag_all_rejected": self.mag_all_rejected()}

    def held_items(self) -> int:
        """How many items the pipeline holds in its lists, deques, dicts and arrays (a few levels deep).

        A memory diagnostic: in streaming mode with ``keep_steps`` bounded it
        stays flat however long the walk (``tests/test_pipeline.py``,
        ``benchmarks/long_walk.py``).
        """
        return _held_items(self, 3, set())

    def status(self) -> Status:
        a = self.attitude
        return Status(self.t_ns, self.reckoner.n_steps, self.reckoner.distance_m, self.reckoner.east_m,
                      self.reckoner.north_m, self.smoother.heading_rad,
                      a.use_magnetometer and a.n_mag_used > 0 and not a.mag_rejected,
                      a.acc_sigma2, a.mag_sigma2, self.labels(), self._carry_mode,
                      self.carry.confidence if self.carry is not None else math.nan,
                      len(self._candidates) if self.hold_while_settling and self.carry is not None
                      and self.carry.settling else 0)

    # -- batch -----------------------------------------------------------------
    def run(self, recording: Recording, progress=None) -> PipelineResult:
        """Process a whole recording with the streaming kernel; returns track and diagnostics.

        ``progress``, if given, is called with the fraction done (0..1) every
        few thousand events.  Raises :class:`core.recording.MissingSensorError`
        without an accelerometer.
        """
        recording.stream(ACC, "step detection needs the accelerometer")
        smoothed = None
        if self.heading_smoother == HEADING_SMOOTHER_START and self.gnss is None:
            # pass 1: the forward run and its backward pass give the start heading; pass 2 starts from it
            self._run_pass(recording, None if progress is None else (lambda f: progress(0.5 * f)))
            sm = self.attitude.smoothed_heading()
            if len(sm.t_ns):
                start = self.attitude.start_heading = StartHeading.of(sm)
                smoothed = {"verdict": SmootherVerdict.APPLIED.value,
                            "start_correction_deg": math.degrees(start.correction_rad),
                            "start_sd_deg": math.degrees(start.sd_rad),
                            "start_forward_sd_deg": math.degrees(sm.forward_sd_rad[0]),
                            "start_offset_deg": math.degrees(start.offset_rad)}
            else:
                smoothed = {"verdict": SmootherVerdict.NO_HISTORY.value}
            try:
                self._run_pass(recording, None if progress is None else (lambda f: progress(0.5 + 0.5 * f)))
            finally:
                self.attitude.start_heading = None
        else:
            self._run_pass(recording, progress)
        att = self._log.attitude_log()
        self._log = []
        if self.heading_smoother == HEADING_SMOOTHER_RTS or (self.heading_smoother == HEADING_SMOOTHER_START
                                                              and self.gnss is not None):
            smoothed = self._smooth_headings()
        a = self.attitude
        counters = {"mag_used": a.n_mag_used, "mag_rejected": a.n_mag_rejected, "acc_rejected": a.n_acc_rejected,
                    "peaks_rejected_rotation": self.n_rejected_rotation, "peaks_rejected_bout": self.n_rejected_bout,
                    "peaks_replayed_mode_change": self.n_replayed, "peaks_replaced_mode_change": self.n_replaced_mode,
                    "walk_start_steps": self.n_walk_start_steps,
                    "nonfinite_skipped": dict(self.n_nonfinite), **self.health_counters(), **self.gap_counters()}
        if self.flush_at_end:
            counters["steps_flushed_at_end"] = self.n_flushed
        if hasattr(a, "counters"):
            counters["attitude"] = a.counters()
        if self.carry is not None:
            counters["carry"] = self.carry.counters()
        if smoothed is not None:
            counters["heading_smoother"] = smoothed
        fusion = self.gnss.result() if self.gnss is not None else None
        if fusion is not None:
            fusion.counters["site"] = self.site
        return PipelineResult(list(self.steps), Track.from_steps(self.steps), att, self.labels(), recording,
                              counters, fusion)

    def _run_pass(self, recording: Recording, progress) -> None:
        """One pass of the streaming kernel over the whole recording, from :meth:`reset` (the body of :meth:`run`)."""
        log, self.log = self.log, True
        keep, self.keep_steps = self.keep_steps, True  # a batch run returns every step, whatever keep_steps
        try:
            self.reset()
        finally:
            self.keep_steps = keep
        use = [n for n in (GYRO, ACC, self.mag_stream) if recording.has(n)]
        if self.gnss is not None and recording.has(GPS):
            use.append(GPS)
            if recording.has(GNSS_STATUS):
                use.append(GNSS_STATUS)
            self.gnss.set_time_zero(recording.t0_ns)
            off = recording.metadata.get("unix_offset_ns")
            if self.unix_offset_ns is None and isinstance(off, int):
                self.unix_offset_ns = off
        self._log = _LogColumns()  # the log's rows go into typed columns, not tuples (memory, #13)
        try:
            total = sum(len(recording.streams[n]) for n in use)
            update = self.update
            k = 0
            for chunk in _event_chunks(recording, use):
                for name, t, vals in chunk:
                    update(name, t, vals)
                    if progress is not None and k % 5000 == 0:
                        progress(k / total)
                    k += 1
            self.finish()
            if progress is not None:
                progress(1.0)
        finally:
            self.log = log

    def _smooth_headings(self) -> dict:
        """The replay's heading smoother (``heading_smoother``): turn the steps, dead-reckon them again; its counters."""
        if self.gnss is not None:
            return {"verdict": SmootherVerdict.GPS_FUSION.value}
        sm = self.attitude.smoothed_heading()
        if not len(sm.t_ns):
            return {"verdict": SmootherVerdict.NO_HISTORY.value}
        self.steps = smooth_steps(list(self.steps), sm)
        c = np.degrees(np.abs(sm.correction_rad))
        return {"verdict": SmootherVerdict.APPLIED.value, "epochs": int(len(sm.t_ns)),
                "start_correction_deg": float(np.degrees(sm.correction_rad[0])),
                "median_abs_correction_deg": float(np.median(c)), "max_abs_correction_deg": float(np.max(c)),
                "median_sd_deg": float(np.degrees(np.median(sm.sd_rad))),
                "median_forward_sd_deg": float(np.degrees(np.median(sm.forward_sd_rad)))}


#: events a batch run turns into Python objects at a time (:func:`_event_chunks`)
EVENT_CHUNK = 1 << 14


def _event_chunks(recording: Recording, names: list[str], chunk: int = EVENT_CHUNK):
    """The events of ``recording.events(names)``, in the same order, a time slice of about ``chunk`` at a time.

    ``recording.events`` makes three Python lists of the whole merged recording
    (about 80 bytes an event); a slice of ``[t_lo, t_hi)`` of every stream,
    merged as :meth:`core.recording.Recording.merged` merges (time, then
    :data:`core.recording.STREAM_ORDER`, then row), gives the same sequence
    with memory for one slice.  Streams whose times are not sorted (never
    after a reader's repair) are merged whole, as before.
    """
    order = recording.stream_order(names)
    streams = [recording.streams[n] for n in order]
    times = [np.asarray(s.t_ns) for s in streams]
    if not times or any(len(t) > 1 and bool(np.any(t[1:] < t[:-1])) for t in times):
        yield recording.events(names)
        return
    longest = max(times, key=len)
    if not len(longest):
        return
    step = max(1, chunk * len(longest) // max(sum(len(t) for t in times), 1))
    bounds = [int(b) for b in longest[step::step]]
    vals = [s.values for s in streams]
    lo = [0] * len(times)
    for b in [*bounds, None]:
        hi = [len(t) if b is None else int(np.searchsorted(t, b, side="left")) for t in times]
        t_all = np.concatenate([t[i:j] for t, i, j in zip(times, lo, hi)])
        s_all = np.concatenate([np.full(j - i, k, dtype=np.int64) for k, (i, j) in enumerate(zip(lo, hi))])
        r_all = np.concatenate([np.arange(j - i, dtype=np.int64) for i, j in zip(lo, hi)])  # rows in the slice
        idx = np.lexsort((s_all, t_all))
        rows = [v[i:j].tolist() for v, i, j in zip(vals, lo, hi)]  # one tolist a slice, not a numpy row an event
        yield [(order[si], ti, tuple(rows[si][ri]))
               for ti, si, ri in zip(t_all[idx].tolist(), s_all[idx].tolist(), r_all[idx].tolist())]
        lo = hi


class _LogColumns:
    """The attitude log of a batch run as typed columns (``array.array``), 57 bytes a grid sample.

    :meth:`Pipeline.update` appends one row tuple per grid sample; a list of
    those tuples held about 400 bytes a sample (80 a pipeline event).
    """

    __slots__ = ("t", "q", "heading", "acc_s2", "mag_s2", "rejected")

    def __init__(self):
        self.t, self.q, self.heading = array("q"), array("d"), array("d")
        self.acc_s2, self.mag_s2, self.rejected = array("d"), array("d"), array("b")

    def append(self, row) -> None:
        tg, q, heading, acc_s2, mag_s2, rejected = row
        self.t.append(tg)
        self.q.extend(q)
        self.heading.append(heading)
        self.acc_s2.append(acc_s2)
        self.mag_s2.append(mag_s2)
        self.rejected.append(rejected)

    def __len__(self) -> int:
        return len(self.t)

    def attitude_log(self) -> AttitudeLog:
        return AttitudeLog(np.array(self.t, dtype=np.int64), np.array(self.q, dtype=float).reshape(-1, 4),
                           np.array(self.heading, dtype=float), np.array(self.acc_s2, dtype=float),
                           np.array(self.mag_s2, dtype=float), np.array(self.rejected, dtype=bool))


def _held_items(obj, depth: int, seen: set) -> int:
    if id(obj) in seen or depth < 0:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return int(obj.size)
    if isinstance(obj, (list, tuple, deque, set, dict)):
        items = list(obj.values() if isinstance(obj, dict) else obj)
        return len(items) + sum(_held_items(x, depth - 1, seen) for x in items[:64])
    if hasattr(obj, "__dict__") and type(obj).__module__.startswith("core"):
        return sum(_held_items(x, depth - 1, seen) for x in vars(obj).values())
    return 0


def run_recording(recording: Recording, **params) -> PipelineResult:
    """Convenience: ``Pipeline(**params).run(recording)``."""
    if not isinstance(recording, Recording):
        raise RecordingError("run_recording needs a core.recording.Recording")
    return Pipeline(**params).run(recording)
