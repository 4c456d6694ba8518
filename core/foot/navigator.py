"""Foot-mounted navigation, composed: stance detection, INS-EKF-ZUPT and the heading aids of Song & Park 2018.

:class:`FootNavigator` runs one foot-mounted IMU (and, for the course aids, a
waist-mounted magnetometer) with one of the four cases of the paper's
Tables 2-3 (``aid``):

``"zupt"``
    ZUPT only.
``"foot_mag"``
    ZUPT + the foot magnetometer's heading ("ZUPT + sensor heading"): at the
    end of each stance the mean field of the stance, rotated into ENU, is
    compared with its direction at the alignment.
``"course"``
    ZUPT + the waist magnetometer heading as the foot's heading, with the
    foot-to-waist angle of the initial standstill ("ZUPT + course": the toe
    angle is ignored).
``"tckf"``
    The two cascaded filters: :class:`core.foot.course.CourseErrorFilter`
    estimates the course-angle error from the waist heading and the course of
    successive stances (eqs. 11-19); its estimate is the heading-error
    measurement of the ZUPT filter with its variance (eqs. 22-25), with the
    tilt-coupled row of eq. 22 (the azimuth of the foot's axis,
    :func:`core.pdr.attitude.heading_jacobian`), handed over once per
    ``course.handover_strides`` strides, after which the first filter restarts
    (each stride's information counted once; see :mod:`core.foot.course`).

Samples are the foot accelerometer's events, each with the gyroscope reading
interpolated at its time (plus ``gyro_delay_s``, a sensor's inter-sensor
latency; a recording with simultaneous rows pairs them exactly).  The filter starts with the initial
alignment at the end of the first stance of at least ``align_min_s``; samples
of that stance get its attitude, zero velocity and the origin, samples before
it NaN.  A walk that starts moving has no such stance: after
``align_fallback_stances`` shorter stances the next stance of at least
``align_fallback_min_s`` aligns (counted in ``aligned_on_short_stance``).  Heading aids are applied at the end of each stance (the state is then
that of the stance's last sample).

Batch :meth:`FootNavigator.run` detects stance over the whole recording at
once (vectorised) and runs the per-sample kernel; streaming
:meth:`FootNavigator.update` detects stance with :class:`core.foot.stance.StanceStream`
(half a window late) and runs the same kernel, so both give the same result.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from core.conventions import ACC, GYRO, MAG, wrap_angle
from core.foot.course import GATED_VERDICTS, CourseErrorFilter, CourseSettings, CourseVerdict, body_heading
from core.foot.devices import stream_name
from core.foot.ins import InsSettings, ZuptEKF, horizontal_axis
from core.foot.saturation import GyroClipRepair
from core.foot.stance import StanceDetector, StanceSettings, infer_foot_axes
from core.pdr.attitude import heading_jacobian
from core.recording import MissingSensorError, Recording

AIDS = ("zupt", "foot_mag", "course", "tckf")


@dataclass(frozen=True)
class FootSettings:
    """Settings of :class:`FootNavigator` (units in the names)."""

    #: one of :data:`AIDS`
    aid: str = "zupt"
    stance: StanceSettings = field(default_factory=StanceSettings)
    ins: InsSettings = field(default_factory=InsSettings)
    course: CourseSettings = field(default_factory=CourseSettings)
    #: "song" detector axes: "auto" (:func:`core.foot.stance.infer_foot_axes`, batch only) or as in ``stance``
    song_axes: str = "auto"
    #: the gyroscope's readings lag the accelerometer's by this much (s): each accelerometer sample is
    #: paired with the gyroscope interpolated at its time plus this (a property of the sensor)
    gyro_delay_s: float = 0.0
    #: the gyroscope's full scale (rad/s, a property of the sensor; nan: unknown): readings within 1 % of it
    #: are clipped, and a clipped run is repaired by a parabola through the readings around it
    #: (:mod:`core.foot.saturation`)
    gyro_range_rad_s: float = math.nan
    #: the rate of a reading at or beyond that clip level (repaired or not) is uncertain by this much (rad/s,
    #: sd per clipped axis): its step's attitude, velocity and position get the matching process noise
    #: (:meth:`core.foot.ins.ZuptEKF.propagate`), so the next stance's ZUPT, and the smoother, put the clipped
    #: rotation's error at the clip instead of spreading it over the stride; 0: off.  1 rad/s is of the order of
    #: the repair itself (the parabola's peak above the reading on the PyShoe tuning split: median 0.12, 90th
    #: percentile 0.96, largest 2.7 rad/s), but the model is a white-noise equivalent, not that error's law: a
    #: clipped run's rate error is one-signed and correlated over the run (its attitude variance grows as
    #: (N sd T)^2, not N sd^2 T^2), and a step with one clipped reading of two errs by half; so the value is a
    #: tuned setting (0.3, 1 and 3 rad/s improved the same five tuning trials), not a derived one.  ON (issue #27, docs/foot.md "A seventh pass"): PyShoe tuning split,
    #: PyShoe's metric median / mean 0.0319 / 0.0355 -> 0.0315 / 0.0330 m, 5 trials better, none worse (the 6
    #: without a clipped step unchanged); forward filter 0.0436 / 0.0509 -> 0.0433 / 0.0489 m
    clipped_gyro_sd_rad_s: float = 1.0
    #: the alignment needs a first still period at least this long (s) ...
    align_min_s: float = 0.3
    #: ... in which gaps of non-stance up to this long do not count as motion (s)
    align_max_gap_s: float = 0.1
    #: a walk that starts moving (no still period of ``align_min_s``): after this many stances too short
    #: for the alignment (each at least ``align_fallback_min_s``), the next one at least that long aligns
    #: (a single short stance at the start may be a false detection; the second confirms the gait)
    align_fallback_stances: int = 1
    align_fallback_min_s: float = 0.05
    #: the mean rate of the still period is the initial gyroscope bias only if it lasted this long (s);
    #: after a shorter one the filter starts from zero bias (on the PyShoe tuning split the 1-4 s at the
    #: start of a trial gave worse tracks than zero: the foot is not quite still)
    align_gyro_bias_min_s: float = 5.0
    #: initial heading from the foot magnetometer when there is one (else ``initial_heading_rad``)
    initial_heading_from_mag: bool = True
    #: heading (rad, CCW from East) of the foot's most horizontal body axis at the start without magnetometer
    initial_heading_rad: float = math.pi / 2
    #: "foot_mag": sd of the foot magnetometer heading of one stance (rad)
    foot_mag_heading_sd_rad: float = math.radians(10.0)
    #: "course": sd of the waist heading used as the foot heading (rad)
    course_heading_sd_rad: float = math.radians(10.0)
    #: soft ZUPT: the zero-velocity noise is ``zupt_noise_m_s * (1 + soft_zupt_gain * statistic / threshold)``
    #: (the detector's confidence: 0 at a perfectly still sample, 1 at the threshold); 0 = a hard switch.
    #: Off by default: on the PyShoe tuning split gains 1, 3, 10 gave mean 3-D RMSE 0.115, 0.116, 0.119 m
    #: against 0.114 m (the largest error fell, 0.29 -> 0.24 m, the median rose, 0.100 -> 0.111 m)
    soft_zupt_gain: float = 0.0
    #: replays: an RTS smoother over the whole forward run (:class:`core.kalman.RtsSmoother`): every sample's
    #: state from all the samples, before and after it.  Off for the live app (:class:`core.foot.tracker.FootTracker`
    #: turns it off: a stride once shown is not moved).  On: on the PyShoe tuning split it took PyShoe's metric
    #: (median) 0.053 -> 0.037 m and the 3-D RMSE (mean) 0.112 -> 0.109 m (docs/foot.md)
    rts_smoother: bool = True
    #: the smoother keeps about 3.7 kB per sample; a longer recording is not smoothed (counted in
    #: ``smoother_skipped_too_long``; 150000 samples: 12.5 min at 200 Hz, about 560 MB)
    rts_max_samples: int = 150_000
    #: heuristic drift reduction (HDR, Borenstein et al. 2009): at the end of a stance whose foot heading is
    #: within ``hdr_gate_rad`` of the previous stance's (the walker goes straight), a heading pseudo-measurement
    #: pulls the heading toward the previous stance's with sd ``hdr_noise_rad`` (it observes the vertical gyro
    #: bias); only after a stride of at least ``hdr_min_stride_m``; not with the "tckf" aid.  0: off.  OFF by
    #: default (2026-12-07, issue #27): at 2 deg / 0.5 deg (the best of six settings) the PyShoe tuning split moves
    #: by less than that choice alone can produce (median 0.0319 -> 0.0317 m, mean 0.0355 -> 0.0352 m, 2 of 14
    #: trials change; forward filter 0.0436 -> 0.0422 m), while a gentle curve (under the gate per stride) is what
    #: HDR is known to straighten and the VICON trials do not test it (docs/foot.md, "A sixth pass").  2 deg: on
    hdr_gate_rad: float = 0.0
    hdr_noise_rad: float = math.radians(0.5)
    hdr_min_stride_m: float = 0.3

    def __post_init__(self):
        if self.aid not in AIDS:
            raise ValueError(f"unknown aid {self.aid!r}: one of {', '.join(AIDS)}")
        if not (self.clipped_gyro_sd_rad_s >= 0 and math.isfinite(self.clipped_gyro_sd_rad_s)):
            raise ValueError(f"clipped_gyro_sd_rad_s must be >= 0, not {self.clipped_gyro_sd_rad_s!r}")


@dataclass(frozen=True)
class Stride:
    """One stance phase of the foot and the stride that ended in it."""

    t_start_ns: int  #: first stance sample
    t_end_ns: int  #: last stance sample
    position_n: tuple  #: ENU position at the end of the stance (m)
    length_m: float  #: horizontal distance from the previous stance (nan for the first)
    course_rad: float  #: direction of that displacement (rad, CCW from East)
    waist_heading_rad: float  #: waist magnetometer heading over the stride (nan without waist)
    aid: str  #: what heading aid was applied at this stance ("" none)
    aid_innovation_rad: float = math.nan
    aid_nis: float = math.nan
    course_error_rad: float = math.nan  #: TCKF: first-filter estimate after this stride
    course_error_var_rad2: float = math.nan


@dataclass
class FootResult:
    """Everything a run produced: per-sample states, strides, diagnostics."""

    t_ns: np.ndarray
    position_n: np.ndarray  #: (n, 3) ENU, NaN before the alignment
    velocity_n: np.ndarray
    q_wxyz: np.ndarray
    stance: np.ndarray  #: (n,) bool
    strides: list
    zupt_nis: np.ndarray  #: NIS (3 dof) of every zero-velocity update
    heading_updates: list  #: core.foot.ins.Update of every heading aid
    course_updates: list  #: core.foot.course.CourseUpdate (TCKF)
    counters: dict
    settings: FootSettings
    recording: Recording | None = None
    #: position sd (m) of every sample (sqrt of the largest eigenvalue of the horizontal block)
    position_sd_m: np.ndarray | None = None
    hdr_updates: list = field(default_factory=list)  #: core.foot.ins.Update of every HDR pseudo-measurement

    def stride_positions(self) -> np.ndarray:
        return np.array([s.position_n for s in self.strides], dtype=float).reshape(-1, 3)

    def summary(self) -> dict:
        ok = np.isfinite(self.position_n[:, 0])
        last = self.position_n[ok][-1] if np.any(ok) else np.zeros(3)
        lengths = [s.length_m for s in self.strides if math.isfinite(s.length_m)]
        used = sum(1 for u in self.heading_updates if u.used)
        dur = (self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self.t_ns) > 1 else 0.0
        return {
            "mode": "foot",
            "aid": self.settings.aid,
            "detector": self.settings.stance.detector,
            "duration_s": float(dur),
            "rate_hz": float((len(self.t_ns) - 1) / dur) if dur > 0 else 0.0,
            "n_strides": len(self.strides),
            "distance_m": float(np.sum(lengths)) if lengths else 0.0,
            "final_east_m": float(last[0]),
            "final_north_m": float(last[1]),
            "final_up_m": float(last[2]),
            "start_to_end_m": float(math.hypot(last[0], last[1])),
            "stance_fraction": float(np.mean(self.stance)) if len(self.stance) else 0.0,
            "zupt_nis_median": float(np.median(self.zupt_nis)) if len(self.zupt_nis) else math.nan,
            "heading_updates_used": used,
            "heading_updates_total": len(self.heading_updates),
            **self.counters,
        }


@dataclass(slots=True)
class _AlignSums:
    """The still period collected for the initial alignment (:meth:`FootNavigator._align_step`)."""

    sum_acc_m_s2: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: sum of its specific forces
    sum_gyro_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: sum of its rates
    n: int = 0  #: its stance samples
    t_first_ns: int | None = None  #: its first stance sample
    t_last_ns: int | None = None  #: its last stance sample


class _Window:
    """Timestamped readings kept until a window consumes them (mean over ``(t0, t1]``)."""

    def __init__(self):
        self._buf: deque = deque()

    def add(self, t_ns: int, v) -> None:
        self._buf.append((t_ns, v))

    def mean(self, t0_ns: int, t1_ns: int):
        """Mean of the readings with ``t0 < t <= t1``; drops everything up to ``t1``; None if none."""
        acc = [0.0, 0.0, 0.0]
        n = 0
        while self._buf and self._buf[0][0] <= t1_ns:
            t, v = self._buf.popleft()
            if t > t0_ns and all(map(math.isfinite, v)):
                acc[0] += v[0]
                acc[1] += v[1]
                acc[2] += v[2]
                n += 1
        return (acc[0] / n, acc[1] / n, acc[2] / n) if n else None


class FootNavigator:
    """Foot-mounted INS with stance detection and a heading aid (see the module docstring).

    Parameters (keyword only)
    -------------------------
    settings : FootSettings, optional
    foot_device : str
        Device whose IMU is on the foot ("" = the recording's primary device; see :mod:`core.foot.devices`).
    waist_device : str or None
        Device with the waist magnetometer for ``"course"`` and ``"tckf"`` (needs ``acc`` and ``mag``).
    **overrides
        Fields of :class:`FootSettings` (``aid="tckf"``).
    """

    def __init__(self, settings: FootSettings | None = None, *, foot_device: str = "",
                 waist_device: str | None = "waist", **overrides):
        s = settings or FootSettings()
        self.settings = replace(s, **overrides) if overrides else s
        self.foot_device = foot_device
        self.waist_device = waist_device
        self.names = {k: stream_name(k, foot_device) for k in (ACC, GYRO, MAG)}
        self.waist_names = ({k: stream_name(k, waist_device) for k in (ACC, MAG)}
                            if waist_device is not None else {})
        self.reset()

    # -- state --------------------------------------------------------------------------------
    def reset(self, stance_settings: StanceSettings | None = None) -> None:
        s = self.settings
        self.stance_settings = stance_settings or s.stance
        self.ins = ZuptEKF(s.ins)
        if s.rts_smoother:
            self.ins.keep_history()
        self.course = CourseErrorFilter(s.course)
        self._stream = None
        self._gyros: deque = deque()  # streaming: recent gyroscope readings (t_ns, values)
        self._clip = GyroClipRepair(s.gyro_range_rad_s)
        self._acc_wait: deque = deque()  # streaming: accelerometer readings waiting for their gyroscope
        self._pending: deque = deque()  # streaming: samples waiting for their stance decision
        self._foot_mag = _Window()
        self._waist_acc = _Window()
        self._waist_mag = _Window()
        self._t_prev: int | None = None
        self._gyro_prev = None  # the rate reading of the previous step (clipped-rate noise)
        self._prev_stance = False
        self._stance_start: int | None = None
        self._stance_end: int | None = None  # last sample of the current (or last) stance
        self._align = _AlignSums()
        self._short_stances = 0  # stances before the alignment too short for it (see align_fallback_stances)
        self._held: list = []  # samples of the alignment stance (t_ns) waiting for their state
        self._gap: list = []  # samples of a gap in the alignment stance (t, acc, gyro, stance)
        self._last_stride_t: int | None = None
        self._last_stride_pos = None
        self._foot_axis = None
        self._waist_axis = None
        self._mag_ref_rad = math.nan
        self._course_c0 = math.nan
        self._prev_course = math.nan
        self._prev_waist = math.nan
        self.out_t, self.out_p, self.out_v, self.out_q, self.out_st, self.out_sd = [], [], [], [], [], []
        self.out_epoch: list[int] = []  # the INS epoch of each sample (the smoother's index; -1 none)
        self.strides: list[Stride] = []
        self.zupt_nis: list[float] = []
        self.heading_updates: list = []
        self.course_updates: list = []
        self.hdr_updates: list = []  #: core.foot.ins.Update of every HDR pseudo-measurement
        self._hdr_ref_rad = math.nan  # the foot heading at the end of the previous stance (HDR)
        self.counters = {"skipped_nonfinite": 0, "aid_unavailable": 0, "aid_gated": 0, "alignments_rejected": 0,
                         "aligned_on_short_stance": 0, "smoother_skipped_too_long": 0, "zero_rate_updates": 0,
                         "hdr_updates": 0, "gyro_clipped_steps": 0}

    # -- the per-sample kernel ----------------------------------------------------------------
    def _sample(self, t: int, acc, gyro, stance: bool, ratio: float = 0.0) -> None:
        if not (all(map(math.isfinite, acc)) and all(map(math.isfinite, gyro))):
            self.counters["skipped_nonfinite"] += 1
            stance = False
            if not self.ins.initialized:
                self._emit_nan(t)
                return
            acc, gyro = None, None
        ins = self.ins
        if not ins.initialized:
            self._align_step(t, acc, gyro, stance)
            return
        if self._prev_stance and not stance:
            self._end_stance()
        if acc is not None:
            if self._t_prev is not None:
                ins.propagate(acc, gyro, (t - self._t_prev) * 1e-9, self._clipped_rate_var(gyro))
            self._t_prev = t
        if stance:
            if not self._prev_stance:
                self._stance_start = t
            g = self.settings.soft_zupt_gain
            u = ins.update_zero_velocity(1.0 + g * min(max(ratio, 0.0), 1.0) if g > 0 else 1.0, gyro)
            if u.used:
                self.zupt_nis.append(u.nis)
            if ins.settings.zero_rate_update and gyro is not None:
                self.counters["zero_rate_updates"] += ins.update_zero_rate(gyro).used
            self._stance_end = t
        self._prev_stance = stance
        self._emit(t, stance)

    def _clipped_rate_var(self, gyro):
        """Per axis, the variance ((rad/s)^2) of the step's rate (the mean of the previous and this reading,
        :meth:`core.foot.ins.ZuptEKF.transition`) where either reading is at or beyond the clip level
        (:attr:`FootSettings.clipped_gyro_sd_rad_s`); None where neither is (or no range is declared)."""
        prev, self._gyro_prev = self._gyro_prev, gyro
        lvl = self._clip.level
        sd = self.settings.clipped_gyro_sd_rad_s
        if not (sd > 0 and lvl == lvl):
            return None
        clipped = [abs(gyro[k]) >= lvl or (prev is not None and abs(prev[k]) >= lvl) for k in range(3)]
        if not any(clipped):
            return None
        self.counters["gyro_clipped_steps"] += 1
        return tuple(sd * sd if c else 0.0 for c in clipped)

    def _emit(self, t, stance) -> None:
        ins = self.ins
        self.out_t.append(t)
        self.out_p.append(ins.p)
        self.out_v.append(ins.v)
        self.out_q.append(ins.q)
        self.out_st.append(bool(stance))
        self.out_sd.append(ins.horizontal_position_sd_m())
        if ins.history is not None:
            self.out_epoch.append(ins.epoch)
            if len(self.out_epoch) > self.settings.rts_max_samples:
                ins.drop_history()
                self.out_epoch = []
                self.counters["smoother_skipped_too_long"] = 1

    def _emit_nan(self, t) -> None:
        nan3 = (math.nan,) * 3
        self.out_t.append(t)
        self.out_p.append(nan3)
        self.out_v.append(nan3)
        self.out_q.append((math.nan,) * 4)
        self.out_st.append(False)
        self.out_sd.append(math.nan)
        if self.ins.history is not None:
            self.out_epoch.append(-1)

    def _align_step(self, t, acc, gyro, stance) -> None:
        """Collect the first still period: stance samples, with gaps up to ``align_max_gap_s`` bridged."""
        a = self._align
        s = self.settings
        if stance:
            if a.n == 0:
                a.t_first_ns = t
            a.sum_acc_m_s2 += acc
            a.sum_gyro_rad_s += gyro
            a.n += 1
            a.t_last_ns = t
            for g in self._gap:  # a short gap inside the still period: its samples count as still
                self._held.append(g[0])
            self._gap = []
            self._held.append(t)
            return
        if a.n == 0:
            self._emit_nan(t)
            return
        self._gap.append((t, acc, gyro, stance))
        if (t - a.t_last_ns) * 1e-9 <= s.align_max_gap_s:
            return
        gap, self._gap = self._gap, []
        dur = (a.t_last_ns - a.t_first_ns) * 1e-9
        short_ok = self._short_stances >= s.align_fallback_stances and dur >= s.align_fallback_min_s
        if dur >= s.align_min_s or short_ok:
            if dur < s.align_min_s:
                self.counters["aligned_on_short_stance"] += 1
            self._do_align()
            for th in self._held:
                self._emit(th, True)
            self._held = []
            self._t_prev = a.t_last_ns
            self._prev_stance = False  # the alignment stance is already the first stride
            self._stance_start = a.t_first_ns
            self._stance_end = a.t_last_ns
            for g in gap:  # the motion that ended the still period, from its first sample
                self._sample(*g)
            return
        self.counters["alignments_rejected"] += 1
        if dur >= s.align_fallback_min_s:
            self._short_stances += 1
        for th in self._held:
            self._emit_nan(th)
        self._held = []
        self._align = _AlignSums()
        for g in gap:
            self._emit_nan(g[0])

    def _do_align(self) -> None:
        s = self.settings
        a = self._align
        acc_m, gyro_m = a.sum_acc_m_s2 / a.n, a.sum_gyro_rad_s / a.n
        up_b = acc_m / np.linalg.norm(acc_m)
        self._foot_axis = horizontal_axis(up_b)
        mag = self._foot_mag.mean(a.t_first_ns - 1, a.t_last_ns) if (self.names[MAG] is not None) else None
        use_mag = mag is not None and s.initial_heading_from_mag
        if (a.t_last_ns - a.t_first_ns) * 1e-9 < s.align_gyro_bias_min_s:
            gyro_m = np.zeros(3)
        self.ins.align(acc_m, gyro_m, heading_axis_b=self._foot_axis, heading_rad=s.initial_heading_rad,
                       mag_mean_b=mag if use_mag else None)
        if mag is not None:
            self._mag_ref_rad = self._azimuth(self.ins.matrix() @ np.asarray(mag))
        wacc = self._waist_acc.mean(a.t_first_ns - 1, a.t_last_ns)
        wmag = self._waist_mag.mean(a.t_first_ns - 1, a.t_last_ns)
        if wacc is not None and wmag is not None:
            wup = np.asarray(wacc) / np.linalg.norm(wacc)
            self._waist_axis = horizontal_axis(wup)
            psi_w = body_heading(wacc, wmag, self._waist_axis)
            self._course_c0 = wrap_angle(self.ins.heading_of(self._foot_axis) - psi_w)
        self._last_stride_t = a.t_last_ns
        self._last_stride_pos = np.array(self.ins.p)
        self.strides.append(Stride(a.t_first_ns, a.t_last_ns, tuple(self.ins.p), math.nan, math.nan, math.nan, ""))

    @property
    def foot_axis_b(self):
        """The body axis the foot's heading is of (the most horizontal at the alignment); None before it."""
        return self._foot_axis

    @staticmethod
    def _azimuth(v) -> float:
        return math.atan2(v[1], v[0])

    def _end_stance(self, final: bool = False) -> None:
        """The stance that ended with the previous sample: a stride, and the heading aid (``final``: the
        recording ended in it; no HDR there, no later sample would carry it)."""
        s = self.settings
        ins = self.ins
        t0, t1 = self._stance_start, self._stance_end
        pos = np.array(ins.p)
        d = pos - self._last_stride_pos
        length = math.hypot(d[0], d[1])
        course = math.atan2(d[1], d[0])
        psi_w = math.nan
        wacc = self._waist_acc.mean(self._last_stride_t, t1)
        wmag = self._waist_mag.mean(self._last_stride_t, t1)
        if wacc is not None and wmag is not None:
            if self._waist_axis is None:
                self._waist_axis = horizontal_axis(np.asarray(wacc) / np.linalg.norm(wacc))
            psi_w = body_heading(wacc, wmag, self._waist_axis)
        foot_mag = self._foot_mag.mean(t0 - 1, t1)
        aid, innov, nis, x1, p1 = "", math.nan, math.nan, math.nan, math.nan
        if s.aid == "foot_mag":
            if foot_mag is not None and math.isfinite(self._mag_ref_rad):
                m_n = ins.matrix() @ np.asarray(foot_mag)
                innov = wrap_angle(self._mag_ref_rad - self._azimuth(m_n))
                u = ins.update_heading(innov, heading_jacobian(m_n), s.foot_mag_heading_sd_rad ** 2)
                self.heading_updates.append(u)
                aid, nis = "foot_mag", u.nis
            else:
                self.counters["aid_unavailable"] += 1
        elif s.aid == "course":
            refused = self._stride_gate(length, course, psi_w)
            if refused is None and math.isfinite(self._course_c0):
                fwd_n = ins.matrix() @ self._foot_axis
                innov = wrap_angle(psi_w + self._course_c0 - self._azimuth(fwd_n))
                u = ins.update_heading(innov, heading_jacobian(fwd_n), s.course_heading_sd_rad ** 2)
                self.heading_updates.append(u)
                aid, nis = "course", u.nis
            else:
                self.counters["aid_gated" if refused in GATED_VERDICTS else "aid_unavailable"] += 1
        elif s.aid == "tckf":
            fwd_n = ins.matrix() @ self._foot_axis
            h = heading_jacobian(fwd_n)  # eq. 22's first row in ENU: the tilt-coupled heading of the foot
            started = self.course.started
            cu = self.course.update(t1, psi_w, d[0], d[1], prior_var_rad2=ins.heading_variance(h))
            self.course_updates.append(cu)
            if self.course.started and not started:
                # the waist-to-course offset holds the INS heading error of the boresight strides: every
                # later course error is relative to it (a Schmidt consider term; see core.foot.course)
                c = self.settings.course
                ins.consider_heading(h, c.gamma * c.mag_heading_sd_rad ** 2 / max(c.boresight_strides, 1))
            if cu.used and cu.handover:
                # eqs. 23-25: the first filter's estimate and variance, handed over once (then it restarts)
                u = ins.update_heading_relative(cu.x_rad, h, cu.p_rad2)
                self.heading_updates.append(u)
                self.course.restart()
                aid, innov, nis = "tckf", cu.x_rad, u.nis
            elif not cu.used and cu.verdict is not CourseVerdict.BORESIGHT:
                self.counters["aid_gated" if cu.verdict in GATED_VERDICTS else "aid_unavailable"] += 1
            x1, p1 = cu.x_rad, cu.p_rad2
        if s.hdr_gate_rad > 0 and s.aid != "tckf" and not final:  # the TCKF keeps its own consider term (core.foot.course)
            self._hdr(length)
        self._prev_course, self._prev_waist = course, psi_w
        self.strides.append(Stride(t0, t1, tuple(ins.p), length, course, psi_w, aid, innov, nis, x1, p1))
        self._last_stride_t = t1
        self._last_stride_pos = np.array(ins.p)

    def _hdr(self, length: float) -> None:
        """Heuristic drift reduction (see :attr:`FootSettings.hdr_gate_rad`): the innovation is the previous
        stance's foot heading minus this one's, ``H`` the tilt-coupled heading row of the foot axis."""
        s = self.settings
        fwd_n = self.ins.matrix() @ self._foot_axis
        psi = self._azimuth(fwd_n)
        innov = wrap_angle(self._hdr_ref_rad - psi) if math.isfinite(self._hdr_ref_rad) else math.nan
        if abs(innov) <= s.hdr_gate_rad and length >= s.hdr_min_stride_m:
            u = self.ins.update_heading_relative(innov, heading_jacobian(fwd_n), s.hdr_noise_rad ** 2)
            self.hdr_updates.append(u)
            self.counters["hdr_updates"] += u.used
            if u.used:
                fwd_n = self.ins.matrix() @ self._foot_axis
                psi = self._azimuth(fwd_n)
        # the next stance's measurement is relative to this heading and its error (a Schmidt consider term)
        self.ins.consider_heading(heading_jacobian(fwd_n))
        self._hdr_ref_rad = psi

    def _stride_gate(self, length, course, psi_w) -> CourseVerdict | None:
        """Why a stride gives no course-type measurement (None if it does): the gates of :mod:`core.foot.course`."""
        c = self.settings.course
        if not math.isfinite(psi_w):
            return CourseVerdict.NO_WAIST_HEADING
        if length < c.min_stride_m:
            return CourseVerdict.SHORT_STRIDE
        if math.isnan(self._prev_course) or math.isnan(self._prev_waist):
            return CourseVerdict.TURNING
        turn = max(abs(wrap_angle(course - self._prev_course)), abs(wrap_angle(psi_w - self._prev_waist)))
        return CourseVerdict.TURNING if turn > c.max_turn_rad else None

    # -- other streams --------------------------------------------------------------------------
    def _other(self, name: str, t: int, v) -> None:
        if name == self.names[MAG]:
            self._foot_mag.add(t, v)
        elif self.waist_names and name == self.waist_names[ACC]:
            self._waist_acc.add(t, v)
        elif self.waist_names and name == self.waist_names[MAG]:
            self._waist_mag.add(t, v)

    def input_names(self, recording: Recording) -> list[str]:
        """The streams of ``recording`` this navigator reads (foot IMU, foot magnetometer, waist IMU)."""
        names = [self.names[GYRO], self.names[ACC], self.names[MAG]] + list(self.waist_names.values())
        return [n for n in names if recording.has(n)]

    # -- batch ----------------------------------------------------------------------------------
    def run(self, recording: Recording, stance=None) -> FootResult:
        """The whole recording: vectorised stance detection, then the per-sample kernel in time order.

        ``stance``: optional per-sample labels (bool, one per foot accelerometer sample) used instead of
        the detector (e.g. reference zero-velocity labels, for a best case).
        """
        acc_s = recording.stream(self.names[ACC], "foot-mounted navigation")
        gyr_s = recording.stream(self.names[GYRO], "foot-mounted navigation")
        t = acc_s.t_ns
        clip = GyroClipRepair(self.settings.gyro_range_rad_s)
        gyro = gyro_at(gyr_s.t_ns, clip.repair(gyr_s.t_ns, gyr_s.values),
                       t + int(round(self.settings.gyro_delay_s * 1e9)))
        valid = np.ones(len(t), dtype=bool)
        st = self.settings.stance
        if st.detector == "song" and self.settings.song_axes == "auto":
            ax = infer_foot_axes(acc_s.values[valid], gyro[valid])
            st = replace(st, acc_axes=ax["acc_axes"], gyro_axes=ax["gyro_axes"])
        self.reset(st)
        self._clip = clip
        det = StanceDetector(st)
        finite = valid & np.all(np.isfinite(acc_s.values), axis=1) & np.all(np.isfinite(gyro), axis=1)
        if stance is not None:
            labels = np.asarray(stance, dtype=bool).reshape(-1)
            if len(labels) != len(t):
                raise ValueError(f"{len(labels)} stance labels for {len(t)} accelerometer samples")
            stance = labels & finite
            ratio = np.zeros(len(t))
        else:
            stance = np.zeros(len(t), dtype=bool)
            ratio = np.zeros(len(t))
            if np.any(finite):
                r = det.detect(t[finite], acc_s.values[finite], gyro[finite])
                stance[finite] = r.stance
                ratio[finite] = np.where(r.stance, r.statistic / r.thresholds, 0.0)
        acc_name, gyro_name = self.names[ACC], self.names[GYRO]
        k = 0
        acc_v, gyro_v = acc_s.values, gyro
        for name, tt, v in recording.events(self.input_names(recording)):
            if name == acc_name:
                self._sample(tt, tuple(acc_v[k]), tuple(gyro_v[k]), bool(stance[k]), float(ratio[k]))
                k += 1
            elif name != gyro_name:
                self._other(name, tt, v)
        return self._finish(recording)

    # -- streaming ------------------------------------------------------------------------------
    def update(self, stream: str, t_ns: int, values) -> list:
        """One sensor event; returns the samples whose state became known, as ``(t_ns, position_n)``.

        Stance is decided :attr:`core.foot.stance.StanceSettings.delay_s` late (the
        look-ahead of the detector's windows), so the positions come that late.  The "song" detector needs its axes set
        in the settings (``song_axes`` other than "auto") for streaming.
        """
        if self._stream is None:
            if self.stance_settings.detector == "song" and self.settings.song_axes == "auto":
                raise ValueError("streaming with the 'song' detector needs song_axes='fixed' and the axes in "
                                 "StanceSettings (acc_axes, gyro_axes); 'auto' looks at the whole recording")
            self._stream = StanceDetector(self.stance_settings).stream()
        n0 = len(self.out_t)
        if stream == self.names[GYRO]:
            for tg, vg in self._clip.update(int(t_ns), tuple(values)):
                self._gyros.append((tg, vg))
            self._pair(final=False)
        elif stream == self.names[ACC]:
            self._acc_wait.append((int(t_ns), tuple(values)))
            self._pair(final=False)
        else:
            self._other(stream, t_ns, values)
        return list(zip(self.out_t[n0:], self.out_p[n0:]))

    def _pair(self, final: bool) -> None:
        """Give each waiting accelerometer reading the gyroscope reading interpolated at its time plus
        ``gyro_delay_s`` (as :func:`gyro_at` does for a whole recording), once the gyroscope has passed it."""
        delay = int(round(self.settings.gyro_delay_s * 1e9))
        g = self._gyros
        while self._acc_wait and g:
            t, acc = self._acc_wait[0]
            tq = t + delay
            if g[-1][0] < tq and not final:
                return
            while len(g) > 1 and g[1][0] <= tq:
                g.popleft()
            if tq <= g[0][0] or len(g) == 1:
                gyro = g[0][1]
            else:
                (ta, va), (tb, vb) = g[0], g[1]
                w = (tq - ta) / (tb - ta)
                gyro = tuple(va[i] + w * (vb[i] - va[i]) for i in range(3))
            self._acc_wait.popleft()
            if all(map(math.isfinite, acc)) and all(map(math.isfinite, gyro)):
                self._pending.append((t, acc, gyro))
                self._feed(self._stream.update(t, acc, gyro))
            else:
                self._pending.append((t, acc, gyro, "bad"))
                self._drain_bad()

    def _feed(self, decisions) -> None:
        for td, st, stat, thr in decisions:
            self._drain_bad()
            t, acc, gyro = self._pending.popleft()[:3]
            assert t == td
            self._sample(t, acc, gyro, st, stat / thr if st else 0.0)
        self._drain_bad()

    def _drain_bad(self) -> None:
        while self._pending and len(self._pending[0]) == 4:
            t, acc, gyro, _ = self._pending.popleft()
            self._sample(t, acc, gyro, False)

    def finish(self) -> FootResult:
        """End of a stream: decide the last samples and return the result."""
        if self._stream is not None:
            self._gyros.extend(self._clip.flush())
            self._pair(final=True)
            self._feed(self._stream.flush())
        return self._finish(None)

    def _finish(self, recording) -> FootResult:
        if self.ins.initialized and self._prev_stance and self._stance_start is not None:
            if not self.strides or self.strides[-1].t_end_ns != self._stance_end:
                self._end_stance(final=True)  # the recording ended standing: the last stance is a stride too
            self._prev_stance = False
        if self._held or self._gap:  # the recording ended during the alignment stance
            for th in self._held:
                self._emit_nan(th)
            for g in self._gap:
                self._emit_nan(g[0])
            self._held, self._gap = [], []
        if self.ins.history is not None and self.ins.initialized:
            self._smooth()
        return FootResult(
            t_ns=np.array(self.out_t, dtype=np.int64),
            position_n=np.array(self.out_p, dtype=float).reshape(-1, 3),
            velocity_n=np.array(self.out_v, dtype=float).reshape(-1, 3),
            q_wxyz=np.array(self.out_q, dtype=float).reshape(-1, 4),
            stance=np.array(self.out_st, dtype=bool),
            strides=list(self.strides),
            zupt_nis=np.array(self.zupt_nis, dtype=float),
            heading_updates=list(self.heading_updates),
            course_updates=list(self.course_updates),
            hdr_updates=list(self.hdr_updates),
            counters={**self.counters, "ins_rejected": self.ins.n_rejected,
                      "gyro_clipped_runs_repaired": self.clipped_runs_repaired},
            settings=self.settings,
            recording=recording,
            position_sd_m=np.array(self.out_sd, dtype=float),
        )


    @property
    def clipped_runs_repaired(self) -> int:
        """Clipped gyroscope runs repaired so far (:class:`core.foot.saturation.GyroClipRepair`)."""
        return self._clip.n_repaired

    def _smooth(self) -> None:
        """Replace every sample's state by the RTS-smoothed one (:meth:`core.foot.ins.ZuptEKF.smoothed`)
        and the strides' positions, lengths and courses by the smoothed stance positions."""
        q, v, p, Ps = self.ins.smoothed()
        ep = np.asarray(self.out_epoch, dtype=int)
        ok = ep >= 0
        idx = ep[ok]
        P_out = np.array(self.out_p, dtype=float)
        V_out = np.array(self.out_v, dtype=float)
        Q_out = np.array(self.out_q, dtype=float)
        P_out[ok], V_out[ok], Q_out[ok] = p[idx], v[idx], q[idx]
        sd = np.array(self.out_sd, dtype=float)
        sd[ok] = np.sqrt(np.maximum(np.maximum(Ps[idx, 6, 6], Ps[idx, 7, 7]), 0.0))
        self.out_p, self.out_v, self.out_q, self.out_sd = list(map(tuple, P_out)), list(map(tuple, V_out)), \
            list(map(tuple, Q_out)), list(sd)
        t = np.asarray(self.out_t, dtype=np.int64)
        prev = None
        for i, st in enumerate(self.strides):
            k = int(np.searchsorted(t, st.t_end_ns))
            if k >= len(t) or t[k] != st.t_end_ns or not ok[k]:
                prev = None
                continue
            pos = P_out[k]
            if prev is None:
                self.strides[i] = replace(st, position_n=tuple(pos))
            else:
                d = pos - prev
                self.strides[i] = replace(st, position_n=tuple(pos), length_m=math.hypot(d[0], d[1]),
                                          course_rad=math.atan2(d[1], d[0]))
            prev = pos


def gyro_at(t_gyro_ns, gyro_values, t_ns) -> np.ndarray:
    """Gyroscope readings linearly interpolated at ``t_ns`` (held at the first/last reading outside)."""
    tg = np.asarray(t_gyro_ns, dtype=np.int64)
    x = (np.asarray(t_ns, dtype=np.int64) - tg[0]).astype(float)
    xp = (tg - tg[0]).astype(float)
    v = np.asarray(gyro_values, dtype=float)
    return np.column_stack([np.interp(x, xp, v[:, k]) for k in range(v.shape[1])])


def run_foot(recording: Recording, **kwargs) -> FootResult:
    """``FootNavigator(**kwargs).run(recording)``; raises :class:`MissingSensorError` without a foot IMU."""
    return FootNavigator(**kwargs).run(recording)


__all__ = ["AIDS", "FootNavigator", "FootResult", "FootSettings", "Stride", "run_foot", "MissingSensorError"]
