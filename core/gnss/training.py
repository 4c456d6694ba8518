"""Online training of the walker's stride and the heading error model while GPS is good.

Chen et al. (2010) calibrate in a sports field before the walk and leave
real-time training as future work; Kubrak et al. (2006) train their velocity
model online and show what goes wrong: noisy GPS just before an outage ruins
the coefficients the outage then has to live with.  :class:`OnlineTrainer`
learns continuously, but only from windows that deserve it.

A training window
    Every ``window_s`` seconds of good GPS (non-overlapping windows, ending at
    a fix) is one candidate.  It is used only if

    * every fix in it reports ``hacc_m <= max_hacc_m`` (``max_hacc_doppler_m``
      where the receiver gives speed and course) and the fixes cover
      the window without gaps longer than ``max_fix_gap_s``;
    * the walker walks: at least ``min_steps`` steps and a GPS speed between
      ``min_speed_m_s`` and ``max_speed_m_s``;
    * straight: the circular SD of our step headings is below
      ``straight_sd_rad`` (a turn mixes headings and smears the course);
    * at steady speed: the coefficient of variation of the fixes' speed is
      below ``max_speed_cv``.

What a window gives
    *Stride*: ``scale = GPS distance / model distance`` over a straight
    *stretch* of consecutive usable windows, the GPS distance being the chord
    between the stretch's end fixes once the model distance over it reaches
    ``stride_chord_m`` (the walk is straight, so the chord is the path), and the model distance the
    sum of the stride model's step lengths over the same time span (a step
    counts with the part of its interval inside a window).  Not the
    receivers' Doppler speed: steadier, but on the iOS walks it reads 15-25 %
    low against the chords (issue #26).  With ``reference=ChordReference.DOPPLER`` the chord is
    compared with the Doppler speed integrated over the same fixes instead: the scale is then the
    correction on the receiver's speed (Kubrak's velocity measurement, :mod:`core.gnss.kubrak`).

    *Heading*: ``delta = course - mean(our heading)`` for eq. 12
    (:class:`core.gnss.heading_model.HeadingErrorModel`), the course being the
    circular mean of the Doppler courses or the chord's bearing.

Safeguards (flags returned with every window)
    * a stride sample more than ``scale_gate`` (relative) from the current
      estimate is rejected once ``min_samples`` have been accepted;
    * **variability check** (Kubrak et al.): when the spread (coefficient of
      variation) of the last ``noisy_window`` raw stride samples exceeds
      ``noisy_cv``, GPS is called noisy and nothing is learnt until it
      settles: the estimate keeps the mean of the samples before, instead of
      following noise into the outage that often comes next;
    * the estimate is clipped to ``scale_limits``.

The stride estimate (``stride_weighting``, :class:`StrideWeighting`)
    * ``INFORMATION``: a scalar Kalman (Bayes) update of the scale
      (:func:`core.kalman.correct`), started from the prior ``scale_prior``
      (the user's profile from earlier walks) with relative SD
      ``prior_scale_sd``.  A chord sample ``z = chord / model distance`` counts with its
      information: its SD is the chord's error from its end fixes' reported
      accuracies, ``sqrt(sd_a^2 + sd_b^2) / model distance`` with
      ``sd = hacc / 1.5096`` (hacc is a 68 % radius, per-axis SD each end),
      combined with ``chord_model_sd`` (relative), the model distance's own
      noise (the stride model's error changes with speed and ground from one
      stretch to the next).  Before each accepted sample the variance is
      divided by ``forgetting`` (the same exponential forgetting).  So a short
      chord between 10-m fixes moves the scale little, a long one between
      3-m fixes much, and :attr:`OnlineTrainer.stride_scale_sd` is the
      filter's own posterior SD.
    * ``CHORD_LENGTH`` (before issue #26's review): a chord-length-weighted
      mean of the accepted samples with exponential forgetting (``forgetting``
      per sample), started from the prior worth ``scale_prior_weight_m``
      metres of walking -- one 30-m sample weighs as much as the prior,
      whatever its fixes' accuracy.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np

from core.conventions import wrap_angle
from core.gnss.base import HACC_PER_SIGMA
from core.gnss.heading_model import HeadingErrorModel
from core.kalman import correct


class StrideWeighting(Enum):
    """How the chord samples of the stride scale are combined (module docstring)."""

    INFORMATION = "information"  #: scalar Kalman update, each sample by its SD from its fixes' accuracies
    CHORD_LENGTH = "chord_length"  #: the mean weighted by chord length, the prior worth ``scale_prior_weight_m``


@dataclass(frozen=True)
class StrideSample:
    """One chord sample of the stride scale."""

    scale: float  #: chord / model distance
    chord_m: float
    sd: float  #: its SD (absolute, on the scale) from the end fixes' accuracies and ``chord_model_sd``


class ChordReference(Enum):
    """What distance a straight stretch's chord is compared with (what :attr:`OnlineTrainer.stride_scale` scales)."""

    #: the stride model's step lengths (Chen's stride scale)
    STEPS = "steps"
    #: the receiver's Doppler speed integrated over the fixes (Kubrak's Doppler speed correction, issue #26)
    DOPPLER = "doppler"


@dataclass(frozen=True)
class WindowFlags:
    """What one training window gave (diagnostics as data)."""

    t_ns: int  #: end of the window (the fix that closed it)
    used_stride: bool
    used_heading: bool
    scale_sample: float  #: GPS / model distance of this window (nan if not computed)
    deviation_rad: float  #: course minus our mean heading (nan if not computed)
    heading_rad: float  #: our mean heading over the window
    gps_distance_m: float
    reason: str = ""  #: why the window (or a part of it) was not used
    #: the deviation minus the heading model's prediction *before* this window (out-of-sample residual, rad)
    heading_residual_rad: float = float("nan")


def _circ_mean_sd(angles, weights=None) -> tuple[float, float]:
    a = np.asarray(angles, dtype=float)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float)
    c, s = float(np.sum(w * np.cos(a))), float(np.sum(w * np.sin(a)))
    sw = float(np.sum(w))
    if sw <= 0:
        return math.nan, math.nan
    r = min(math.hypot(c, s) / sw, 1.0)
    sd = math.sqrt(-2.0 * math.log(r)) if r > 1e-12 else math.inf
    return math.atan2(s, c), sd


class OnlineTrainer:
    """Learns a stride scale and the heading error model from good GPS windows.

    Parameters
    ----------
    window_s : float
        Length of a training window (s).
    min_steps : int
        Steps a window must hold.
    max_hacc_m : float
        Worst reported horizontal accuracy of a fix in a usable window (m) ...
    max_hacc_doppler_m : float
        ... and in one whose distance and course come from the receivers' Doppler
        speed and course, which stay good when the position is only 10-20 m good.
    max_fix_gap_s : float
        Longest gap between the window's fixes (s).
    min_speed_m_s, max_speed_m_s : float
        Walking speeds (GPS) a window may have (m/s).
    max_speed_cv : float
        Steady speed: coefficient of variation of the fixes' speed in the window.
    straight_sd_rad : float
        Straight walking: circular SD of the step headings in the window (rad).
    min_chord_m : float
        Shortest chord when positions, not Doppler speed, give the distance (m).
    position_sd_m : float
        Per-axis SD assumed for a fix position when the chord gives the course (m).
    course_sd_rad : float
        SD of a window's mean Doppler course (rad).
    step_heading_sd_rad : float
        Per-step SD of our heading about its window mean (rad), for the sample weight.
    scale_prior : float
        Starting stride scale (its relative SD: ``prior_scale_sd``).
    scale_prior_weight_m : float
        The prior's weight in metres of walking (``CHORD_LENGTH`` weighting only).  After a short training the
        prior still counts: on the simulated noisy-minute walks (gnss_faults, tuning seeds 0-9) 0-3 samples in
        the first 2 minutes leave it 18-40 % of the weight (100 % on seed 1, no sample), while the simulated
        walkers need 0.99-1.14 (median 1.03): the learnt scale ends short (median 0.967 of the truth; the samples
        alone 0.985, per sample unbiased: mean 0.998 of the truth, n = 20).  The samples themselves are unbiased
        (gnss_eval's 5-minute outages, tuning seeds 0-19: per sample 0.996 of the truth, n = 145, SD 8.5 %; the
        learnt scale at the outage 1.002 median).  Weight 10 m: noisy-minute outage end 10.72 -> 10.44 m,
        1 m: 10.67 m; the true scale itself: 8.36 m (issue #26, measured 2026-12-07, not changed).
    scale_limits : (float, float)
        The stride scale is kept within these.
    scale_gate : float
        Relative distance from the estimate beyond which a stride sample is an outlier.
    min_samples : int
        Accepted stride samples before the gate applies.
    noisy_window : int
        Raw stride samples in the variability check.
    noisy_cv : float
        Their coefficient of variation above which GPS is noisy (nothing learnt).
    forgetting : float
        Factor on the old samples' weight per accepted sample (0 < f <= 1).
    prior_scale_sd, min_scale_sd : float
        Relative uncertainty of the stride scale before training, and the floor of the one reported after.
        With ``INFORMATION`` weighting ``prior_scale_sd`` is the prior's SD in the update: the stride model's
        error for a walker it has not seen.  0.08: on the real tuning walk 0.15 was no better (leave-one-out
        ratio 0.420 vs 0.401); on the simulator, whose walkers need 0.99-1.13, 0.15 learns faster from clean
        GPS (benchmarks/gnss_eval seeds 0-1, issue #26).
    stride_weighting : StrideWeighting
        How the chord samples are combined (module docstring).  ``CHORD_LENGTH`` by default: ``INFORMATION``
        was mixed on the tuning split (issue #26 stride weighting, measured 2026-12-06): better on the real
        tuning walk's leave-one-out fixes (Chen's ratio 0.551 -> 0.401) and the simulated noisy minute
        (median 10.30 -> 10.03 m), flat on its hidden windows, worse on gnss_eval's clean simulated 5-minute
        outages (seeds 0-1: 0.77/0.31 -> 3.28/2.21 %; the guard's ``gps_outage_sim_quick_5min_pct``).
    chord_model_sd : float
        Relative SD of a chord sample beyond its fixes' errors: the model distance's own noise
        (``INFORMATION`` weighting).
    learn_stride, learn_heading : bool
        What to learn (the benchmark switches them to isolate each part).
    stride_chord_m : float
        A stride sample is the chord of a straight stretch of consecutive windows once it reaches this
        length (m), against the model distance over the stretch; its end fixes must report ``max_hacc_m``.
    stretch_turn_rad : float
        A window whose mean heading differs more from the stretch's first starts a new stretch (rad).
    stretch_follows_bends : bool
        A stretch may follow a bending street: every straight window (step heading SD within
        ``straight_sd_rad``) that starts at the stretch's last fix continues it, whatever its heading, and the
        stretch's GPS distance is the sum of its windows' chords, each projected on its window's mean Doppler
        course (a projection is linear in the fixes' errors, so their cross-track noise does not lengthen it as
        the chords' lengths would; a course 5 deg off shortens it by 0.4 %).  A window without a Doppler course
        continues a stretch by the first rule (whole chord).  Off by default (issue #25 part 3, measured on the
        tuning walk ``thomasdingemanse_lopen``, default path): stride samples 3 -> 5 in 5 minutes (a street
        bending 10-13 deg per window broke every stretch), but none comes before the first outage window (61 s:
        GPS usable from 48 s), so its 3-min outage stays 20.6 % (PDR alone 19.3 %), and the 1-min outages go
        24.7 / 33.3 / 22.7 -> 24.7 / 33.8 / 23.4 %: no gain on the tuning split.  The simulator's street walks
        (``gnss_eval``, TUNING seeds 0-3, 5-min outage, ``ekf``; a check, not a reason): 0.82 / 0.90 / 1.26 / 2.08
        -> 0.85 / 1.18 / 1.15 / 1.86 %, median 1.08 -> 1.16 % (a window just after a corner may still hold the
        receiver's lagging course, which shortens its projection).
    reference : ChordReference
        What the chord is compared with: the stride model's step lengths (the stride scale) or the
        receivers' Doppler speed integrated over the fixes (a correction of the Doppler speed; a window
        without Doppler speed then gives no sample).
    heading_model : HeadingErrorModel or None
        The model to refine (a persisted one); a new one if None.
    jump_per_hacc, jump_floor_m : float or None, float
        A window in which two consecutive fixes move off the window's own pace by more than the larger of
        ``jump_floor_m`` and ``jump_per_hacc`` times their reported accuracies' root sum square gives no stride
        sample and ends the stretch (a multipath jump: :meth:`_jump_m`); its Doppler course still teaches the
        heading.  None (the default): off -- the real TUNING walks come out identical with it, so no real data shows a
        gain (the lead's review of h6/faults).  1.0: on the simulator's TUNING fault walks with ``learn_held_back`` (seeds 0-9, Chen)
        the noisy-minute outage 9.42 -> 7.85 m (1.5 and 2.0: 9.42, they miss the 8-15 m episodes); alone (fixes
        held back teaching nothing) 10.71 -> 10.71 m, gnss_eval's 5-minute outages median 2.02 -> 1.94 %, mean
        2.20 -> 2.34 % (seeds 0-19).
    keep_windows : int or None
        Keep every window's flags in :attr:`windows` (None: a batch run) or the last this many (a live
        app walking all day, issue #30); the training uses none of them.
    """

    def __init__(self, *, window_s: float = 10.0, min_steps: int = 8, max_hacc_m: float = 12.0,
                 max_hacc_doppler_m: float = 20.0,
                 max_fix_gap_s: float = 3.0, min_speed_m_s: float = 0.5, max_speed_m_s: float = 2.5,
                 max_speed_cv: float = 0.25, straight_sd_rad: float = math.radians(7.0), min_chord_m: float = 8.0,
                 position_sd_m: float = 2.5, course_sd_rad: float = math.radians(4.0),
                 step_heading_sd_rad: float = math.radians(5.0), scale_prior: float = 1.0,
                 scale_prior_weight_m: float = 30.0, scale_limits: tuple[float, float] = (0.6, 1.7),
                 scale_gate: float = 0.3, min_samples: int = 3, noisy_window: int = 4, noisy_cv: float = 0.15,
                 forgetting: float = 0.98, prior_scale_sd: float = 0.08, min_scale_sd: float = 0.015,
                 learn_stride: bool = True, learn_heading: bool = True,
                 heading_model: HeadingErrorModel | None = None, stride_chord_m: float = 30.0,
                 stretch_turn_rad: float = math.radians(10.0), keep_windows: int | None = None,
                 reference: ChordReference = ChordReference.STEPS,
                 stride_weighting: StrideWeighting = StrideWeighting.CHORD_LENGTH, chord_model_sd: float = 0.03,
                 stretch_follows_bends: bool = False, jump_per_hacc: float | None = None, jump_floor_m: float = 5.0):
        self.window_s = float(window_s)
        self.jump_per_hacc = None if jump_per_hacc is None else float(jump_per_hacc)
        self.jump_floor_m = float(jump_floor_m)
        self.keep_windows = None if keep_windows is None else int(keep_windows)
        self.min_steps = int(min_steps)
        self.max_hacc_m = float(max_hacc_m)
        self.max_hacc_doppler_m = float(max_hacc_doppler_m)
        self.max_fix_gap_s = float(max_fix_gap_s)
        self.min_speed_m_s = float(min_speed_m_s)
        self.max_speed_m_s = float(max_speed_m_s)
        self.max_speed_cv = float(max_speed_cv)
        self.straight_sd_rad = float(straight_sd_rad)
        self.min_chord_m = float(min_chord_m)
        self.position_sd_m = float(position_sd_m)
        self.course_sd_rad = float(course_sd_rad)
        self.step_heading_sd_rad = float(step_heading_sd_rad)
        self.scale_prior = float(scale_prior)
        self.scale_prior_weight_m = float(scale_prior_weight_m)
        self.scale_limits = (float(scale_limits[0]), float(scale_limits[1]))
        self.scale_gate = float(scale_gate)
        self.min_samples = int(min_samples)
        self.noisy_window = int(noisy_window)
        self.noisy_cv = float(noisy_cv)
        self.forgetting = float(forgetting)
        self.prior_scale_sd = float(prior_scale_sd)
        self.min_scale_sd = float(min_scale_sd)
        self.stride_weighting = StrideWeighting(stride_weighting)
        self.chord_model_sd = float(chord_model_sd)
        self.learn_stride = bool(learn_stride)
        self.learn_heading = bool(learn_heading)
        self.stride_chord_m = float(stride_chord_m)
        self.stretch_turn_rad = float(stretch_turn_rad)
        self.stretch_follows_bends = bool(stretch_follows_bends)
        self.reference = ChordReference(reference)
        self.heading_model = heading_model if heading_model is not None else HeadingErrorModel()
        self.reset()

    def reset(self) -> None:
        self._steps: deque = deque()  # (t_ns, t_prev_ns, length_m, heading_rad, regressors or None)
        self._fixes: deque = deque()  # (t_ns, east, north, hacc, speed, course_rad)
        self._window_start_ns: int | None = None
        self._stretch: dict | None = None  # the straight stretch the stride sample grows over
        self._w = self.scale_prior_weight_m
        self._ws = self.scale_prior * self.scale_prior_weight_m
        self._wss = 0.0  # weighted sum of squared deviations of the accepted samples
        self._n_eff = 0.0
        self._scale = self.scale_prior  # INFORMATION: the scale's posterior mean and variance
        self._scale_var = (self.prior_scale_sd * self.scale_prior) ** 2
        self._recent: deque = deque(maxlen=max(self.noisy_window, 2))
        self.n_stride_samples = 0
        self.n_heading_samples = 0
        #: every closed window's flags (or the last ``keep_windows``)
        self.windows: list[WindowFlags] = [] if self.keep_windows is None else deque(maxlen=self.keep_windows)
        self.n_windows = 0
        self.noisy = False
        self.heading_model.reset()  # back to its start (a persisted model stays the prior): a new walk

    @property
    def stride_scale(self) -> float:
        """The learnt factor on the stride model's step length."""
        if self.stride_weighting is StrideWeighting.INFORMATION:
            s = self._scale
        else:
            s = self._ws / self._w if self._w > 0 else self.scale_prior
        return min(max(s, self.scale_limits[0]), self.scale_limits[1])

    @property
    def stride_scale_sd(self) -> float:
        """Uncertainty of :attr:`stride_scale` (relative).

        ``INFORMATION``: the posterior SD (``prior_scale_sd`` before any sample, at least ``min_scale_sd``);
        ``CHORD_LENGTH``: ``prior_scale_sd`` until two samples, then: the weighted spread
        of the samples over the root of their effective number, within [``min_scale_sd``, ``prior_scale_sd``]."""
        if self.stride_weighting is StrideWeighting.INFORMATION:
            return max(math.sqrt(self._scale_var) / max(self._scale, 1e-6), self.min_scale_sd)
        if self._n_eff < 2:
            return self.prior_scale_sd
        spread = math.sqrt(self._wss / (self._w - self.scale_prior_weight_m * self.forgetting ** self.n_stride_samples))
        return max(min(spread / math.sqrt(self._n_eff), self.prior_scale_sd), self.min_scale_sd)

    @property
    def stride_gps_distance_m(self) -> float:
        """Metres of GPS walking behind the stride estimate (its weight, after forgetting)."""
        return self._w - self.scale_prior_weight_m * self.forgetting ** self.n_stride_samples

    def add_step(self, t_ns: int, t_prev_ns: int, length_m: float, heading_rad: float, x=None) -> None:
        """A step of the raw track: its time, the previous step's time, model length and our heading; ``x``: the
        heading model's regressors at the step if not its heading's own (the lagged ones,
        :class:`core.gnss.heading_model.LaggedRegressors`)."""
        if math.isfinite(length_m) and math.isfinite(heading_rad):
            self._steps.append((int(t_ns), int(t_prev_ns), float(length_m), float(heading_rad), x))
        keep = int(t_ns) - int(3 * self.window_s * 1e9)
        while self._steps and self._steps[0][0] < keep:
            self._steps.popleft()

    def add_fix(self, t_ns: int, east_m: float, north_m: float, hacc_m: float, speed_m_s: float,
                course_rad: float) -> WindowFlags | None:
        """A fix the fusion accepted (local ENU); returns the window it closed, if any."""
        fixes = self._fixes
        if fixes and t_ns - fixes[-1][0] > self.max_fix_gap_s * 1e9:
            fixes.clear()  # a gap: a new window starts here
            self._window_start_ns = None
        fixes.append((int(t_ns), float(east_m), float(north_m), float(hacc_m), float(speed_m_s), float(course_rad)))
        if self._window_start_ns is None:
            self._window_start_ns = int(t_ns)
        if t_ns - self._window_start_ns < self.window_s * 1e9:
            return None
        window = [f for f in fixes if f[0] >= self._window_start_ns]
        fixes.clear()
        fixes.append(window[-1])
        self._window_start_ns = int(t_ns)
        flags = self._window(window)
        self.windows.append(flags)
        self.n_windows += 1
        return flags

    # -- one window ------------------------------------------------------------
    def _window(self, fx) -> WindowFlags:
        t0, t1 = fx[0][0], fx[-1][0]
        nan = math.nan

        def refuse(reason, heading=nan, dist=nan):
            self._stretch = None  # a refused window ends a straight stretch
            return WindowFlags(t1, False, False, nan, nan, heading, dist, reason)

        hacc = np.array([f[3] for f in fx])
        speeds = np.array([f[4] for f in fx])
        doppler = np.isfinite(speeds).mean() >= 0.8
        limit = self.max_hacc_doppler_m if doppler else self.max_hacc_m
        if not np.all(hacc <= limit):
            return refuse(f"fix accuracy up to {np.nanmax(hacc):.0f} m > {limit:.0f} m")
        # steps with the part of their interval inside [t0, t1]
        parts, heads, xs = [], [], []
        for ts, tp, ln, hd, x in self._steps:
            lo, hi = max(tp, t0), min(ts, t1)
            if hi > lo and ts > tp:
                parts.append(ln * (hi - lo) / (ts - tp))
                heads.append(hd)
                xs.append(x)
        n_steps = sum(1 for ts, _, _, _, _ in self._steps if t0 < ts <= t1)
        if n_steps < self.min_steps:
            return refuse(f"{n_steps} steps < {self.min_steps}: not walking")
        mean_h, sd_h = _circ_mean_sd(heads, parts)
        if not sd_h <= self.straight_sd_rad:
            return refuse(f"turning: heading SD {math.degrees(sd_h):.1f} deg", mean_h)
        model_d = float(sum(parts))
        dur = (t1 - t0) * 1e-9
        courses = np.array([f[5] for f in fx])
        chord = math.hypot(fx[-1][1] - fx[0][1], fx[-1][2] - fx[0][2])
        if doppler:
            sp = speeds[np.isfinite(speeds)]
            mean_sp = float(np.mean(sp))
            if not self.min_speed_m_s <= mean_sp <= self.max_speed_m_s:
                return refuse(f"GPS speed {mean_sp:.2f} m/s is not walking", mean_h)
            if float(np.std(sp)) > self.max_speed_cv * mean_sp:
                return refuse(f"unsteady speed (CV {np.std(sp) / mean_sp:.2f})", mean_h)
        else:
            if chord < self.min_chord_m:
                return refuse(f"chord {chord:.1f} m < {self.min_chord_m:.0f} m", mean_h, chord)
            if not self.min_speed_m_s <= chord / dur <= self.max_speed_m_s:
                return refuse(f"GPS speed {chord / dur:.2f} m/s is not walking", mean_h, chord)
        reasons = []
        # -- stride: the chord of a long straight stretch of such windows against the model distance over it
        used_s = False
        if self.reference is ChordReference.DOPPLER:
            ref_d = self._doppler_distance(fx) if doppler else nan
        else:
            ref_d = model_d
        jump = self._jump_m(fx)
        if jump > 0.0:
            # no chord across it: the stretch ends here (the Doppler course still teaches the heading)
            self._stretch = None
            sample = None
            reasons.append(f"the fixes jump {jump:.0f} m off the window's pace (multipath): no stride sample")
        else:
            course = self._doppler_course(fx, courses, speeds) if self.stretch_follows_bends else math.nan
            sample = self._stretch_sample(fx, mean_h, ref_d, course)
        scale, gps_d = (sample.scale, sample.chord_m) if sample is not None else (nan, nan)
        if self.learn_stride and math.isfinite(scale):
            self._recent.append(scale)
            rec = np.array(self._recent)
            cv = float(np.std(rec) / np.mean(rec)) if len(rec) >= 3 else 0.0
            self.noisy = cv > self.noisy_cv
            est = self.stride_scale
            if self.noisy:
                reasons.append(f"GPS too variable (stride samples CV {cv:.2f}): keeping the recent mean")
            elif self.n_stride_samples >= self.min_samples and abs(scale - est) > self.scale_gate * est:
                reasons.append(f"stride sample {scale:.2f} too far from {est:.2f}")
            else:
                used_s = self._learn_stride(sample)
                if not used_s:
                    reasons.append(f"stride sample {scale:.2f}: numerical failure of the update")
        # -- heading
        used_h = False
        dev = nan
        res_h = nan
        if self.learn_heading:
            good_c = np.isfinite(courses) & np.isfinite(speeds) & (speeds >= self.min_speed_m_s)
            if good_c.mean() >= 0.8:
                course, csd = _circ_mean_sd(courses[good_c])
                ref_sd = self.course_sd_rad
                if csd > 3.0 * self.straight_sd_rad:
                    course = nan
                    reasons.append(f"GPS course scattered (SD {math.degrees(csd):.0f} deg)")
            elif chord >= self.min_chord_m and not jump > 0.0:
                course = math.atan2(fx[-1][2] - fx[0][2], fx[-1][1] - fx[0][1])
                ref_sd = math.atan2(math.sqrt(2.0) * self.position_sd_m, chord)
            else:
                course, ref_sd = nan, nan
                reasons.append("no course: neither Doppler course nor a long enough chord")
            if math.isfinite(course):
                dev = wrap_angle(course - mean_h)
                var = ref_sd ** 2 + self.step_heading_sd_rad ** 2 / max(len(heads), 1)
                # the window's regressors: the steps' own (lagged) ones, averaged as the heading is
                x_win = None if any(x is None for x in xs) or not sum(parts) > 0 else \
                    np.average(np.array(xs, dtype=float), axis=0, weights=parts)
                fl = self.heading_model.add(mean_h, dev, 1.0 / var, x_win)
                used_h = fl.accepted
                res_h = fl.residual_rad
                if used_h:
                    self.n_heading_samples += 1
                else:
                    reasons.append(f"heading sample rejected: {fl.reason}")
        return WindowFlags(t1, used_s, used_h, scale, dev, mean_h, gps_d, "; ".join(reasons), res_h)

    def _doppler_course(self, fx, courses, speeds) -> float:
        """The window's mean Doppler course (rad), nan unless most fixes give one and they agree
        (circular SD within ``3 straight_sd_rad``, the heading samples' rule)."""
        good = np.isfinite(courses) & np.isfinite(speeds) & (speeds >= self.min_speed_m_s)
        if len(fx) == 0 or good.mean() < 0.8:
            return math.nan
        course, csd = _circ_mean_sd(courses[good])
        return course if csd <= 3.0 * self.straight_sd_rad else math.nan

    def _jump_m(self, fx) -> float:
        """How far (m) the largest move between two consecutive fixes of a straight window departs from the
        window's own pace (the median velocity of its fix pairs, per axis) beyond the larger of ``jump_floor_m``
        and ``jump_per_hacc`` times the root sum square of the pair's reported accuracies; > 0: a jump (a
        multipath episode starting or ending inside the window); nan: off or fewer than three fixes.

        A constant multipath offset cancels in a chord whose two ends share it, but a chord across the episode's
        start or end carries it whole, and a refused window ends the stretch a chord grows over, so no stride
        sample spans a jump.  Only the fixes: the steps' heading is what is being learnt (a jump back along the
        walking direction shortens the move between two fixes without making it longer than a walk).  On the
        simulator's fault walks a multipath episode the usability judge let through (its shape test fits a
        constant offset) taught a stride sample 30 % long once the fixes it held back taught (``learn_held_back``).
        """
        if self.jump_per_hacc is None or len(fx) < 3:
            return math.nan
        a = np.array([(f[0] * 1e-9, f[1], f[2], f[3]) for f in fx], dtype=float)
        dt = np.diff(a[:, 0])
        ok = dt > 0
        if ok.sum() < 2:
            return math.nan
        d = np.diff(a[:, 1:3], axis=0)[ok]
        v = np.median(d / dt[ok, None], axis=0)  # the window's pace (robust to the one jump)
        dev = np.hypot(*(d - v * dt[ok, None]).T)
        tol = np.maximum(self.jump_floor_m, self.jump_per_hacc * np.hypot(a[:-1, 3], a[1:, 3])[ok])
        return float(np.max(dev - tol))

    @staticmethod
    def _doppler_distance(fx) -> float:
        """The receiver's speed integrated over a window's fixes (trapezoids between fixes that both have one; m)."""
        t = np.array([f[0] for f in fx], dtype=float) * 1e-9
        sp = np.array([f[4] for f in fx])
        ok = np.isfinite(sp[1:]) & np.isfinite(sp[:-1])
        return float(np.sum((0.5 * (sp[1:] + sp[:-1]) * np.diff(t))[ok]))

    def _learn_stride(self, sample: StrideSample) -> bool:
        """Combine an accepted chord sample into the estimate; False if the update failed numerically."""
        f = self.forgetting
        est0 = self.stride_scale
        if self.stride_weighting is StrideWeighting.INFORMATION:
            P = np.array([[self._scale_var / f]])  # forgetting: the old information fades by f per sample
            c = correct(P, np.array([sample.scale - self._scale]), slice(0, 1), np.array([[sample.sd ** 2]]))
            if not c.used:
                return False
            self._scale = float(self._scale + c.dx[0])
            self._scale_var = float(c.P[0, 0])
        self._w = f * self._w + sample.chord_m
        self._ws = f * self._ws + sample.chord_m * sample.scale
        self._wss = f * self._wss + sample.chord_m * (sample.scale - est0) ** 2
        self._n_eff = f * self._n_eff + 1.0
        self.n_stride_samples += 1
        return True

    def _stretch_sample(self, fx, mean_h: float, ref_d: float, course_rad: float = math.nan) -> StrideSample | None:
        """Add a straight window to the current stretch; its :class:`StrideSample` once the stretch's reference
        distance reaches ``stride_chord_m`` (then a new stretch starts at its end), else None.
        ``ref_d`` is the window's distance by the :attr:`reference` (m): the scale is the chord over the
        stretch's sum of them.  The stretch ends on that sum, not on its noisy chord: stopping on the chord
        picks the chords the noise lengthened (the stride scale came out 5-13 % long on the simulator's city
        blocks, the 5-minute outage regression 1.23 -> 1.89 % of 78f5c93).

        The chord between the stretch's end fixes, not the Doppler speed: on the iOS walks the speed reads
        15-25 % low (issue #26), and over 30 m or more the fixes' own errors are a few per cent of the chord.
        A window continues the stretch if it starts at the stretch's last fix and its mean heading is within
        ``stretch_turn_rad`` of the stretch's first window (with ``stretch_follows_bends`` and a Doppler course,
        whatever its heading: the chord is then the sum of the windows' chords on their courses).
        """
        st = self._stretch
        first, last = fx[0], fx[-1]
        if not math.isfinite(ref_d):
            self._stretch = None  # no reference distance (no Doppler speed): the stretch ends here
            return None
        bend = self.stretch_follows_bends and math.isfinite(course_rad)
        if st is not None and bend and st["bent"] is not None:
            turned = False  # each window straight, each chord on its own course: the street may bend between them
        elif st is not None:
            turned = abs(wrap_angle(mean_h - st["heading"])) > self.stretch_turn_rad
        if st is None or st["t_end"] != first[0] or turned or (st["bent"] is not None and not bend):
            st = self._stretch = {"start": first, "t_end": first[0], "heading": mean_h, "model_m": 0.0,
                                  "bent": 0.0 if bend else None}
        st["t_end"] = last[0]
        st["model_m"] += ref_d
        a = st["start"]
        if st["bent"] is not None:  # the windows' chords, each on its own Doppler course
            st["bent"] += (last[1] - first[1]) * math.cos(course_rad) + (last[2] - first[2]) * math.sin(course_rad)
            chord = st["bent"]
        else:
            chord = math.hypot(last[1] - a[1], last[2] - a[2])
        if st["model_m"] < self.stride_chord_m:  # not the noisy chord: stopping on it selects long ones
            return None
        good = a[3] <= self.max_hacc_m and last[3] <= self.max_hacc_m
        model_m = st["model_m"]
        scale = chord / model_m
        self._stretch = {"start": last, "t_end": last[0], "heading": mean_h, "model_m": 0.0,
                         "bent": 0.0 if bend else None}
        if not good or not chord > 0.0:
            return None
        chord_sd = math.hypot(a[3], last[3]) / HACC_PER_SIGMA  # the end fixes' errors along the chord
        return StrideSample(scale, chord, math.hypot(chord_sd / model_m, self.chord_model_sd * scale))

    def counters(self) -> dict:
        return {"windows": self.n_windows, "stride_samples": self.n_stride_samples,
                "heading_samples": self.n_heading_samples, "stride_scale": self.stride_scale,
                "gps_noisy": self.noisy, "heading_model": self.heading_model.to_dict()}


# ---------------------------------------------------------------------------
# the user's profile: the next walk starts calibrated

#: a GPS stride scale learnt over less than this (m) is not saved
MIN_PROFILE_GPS_M = 100.0


def fusion_settings_from_profile(profile) -> dict:
    """``GpsFusion`` keywords that start from what earlier walks taught (:attr:`UserProfile.gps`)."""
    g = getattr(profile, "gps", None) or {}
    kw = {}
    scale = g.get("stride_scale")
    if isinstance(scale, (int, float)) and 0.5 <= scale <= 2.0:
        kw["stride_scale"] = float(scale)
    coef = (g.get("heading_model") or {}).get("coefficients_deg")
    if isinstance(coef, list) and len(coef) == 5 and all(isinstance(c, (int, float)) for c in coef):
        kw["heading_model"] = HeadingErrorModel(coefficients_rad=[math.radians(c) for c in coef])
    return kw


def profile_with_gps_training(profile, trainer: OnlineTrainer, now=None):
    """A new profile with what ``trainer`` learnt (the input unchanged); ``profile`` itself if it learnt too little."""
    from dataclasses import replace
    from datetime import datetime, timezone

    gps = dict(getattr(profile, "gps", None) or {})
    changed = False
    if trainer.learn_stride and trainer.stride_gps_distance_m >= MIN_PROFILE_GPS_M:
        gps["stride_scale"] = round(trainer.stride_scale, 4)
        gps["stride_gps_m"] = round(trainer.stride_gps_distance_m, 1)
        changed = True
    if trainer.learn_heading and trainer.n_heading_samples >= trainer.heading_model.min_samples:
        gps["heading_model"] = trainer.heading_model.to_dict()
        changed = True
    if not changed:
        return profile
    gps["updated"] = (now or datetime.now(timezone.utc)).isoformat(timespec="seconds")
    return replace(profile, gps=gps)
