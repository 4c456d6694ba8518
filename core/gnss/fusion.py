"""GPS-assisted PDR (Chen et al. 2010, Fig. 2): fix screening, online training, the eq.-13 EKF.

:class:`GpsFusion` is one stage after the hand-held chain: it takes the
pipeline's steps (length from the stride model, heading from the attitude
filter) and the GPS fixes, and gives a fused track with an uncertainty per
step.  :class:`core.pdr.pipeline.Pipeline` runs it when built with
``gnss=GpsFusion(...)``; the app and ``pdr replay --gps`` do so.

Per step
    step length ``l = scale * l_model`` (``l_model`` from the pipeline's stride
    model: Chen's one-parameter nonlinear model, eq. 3 ``K (A_max - A_min)^(1/4)``,
    is :class:`core.pdr.stride.WeinbergStride` with a constant coefficient; the
    Weinberg/BP and Chen linear/ANN models of :mod:`core.pdr.stride_models`
    plug in the same way) (``scale`` learnt from GPS by
    :class:`core.gnss.training.OnlineTrainer`, starting from the user's
    profile) and heading ``psi_c = psi + delta(psi)`` (eq. 12,
    :class:`core.gnss.heading_model.HeadingErrorModel`) are the measurements
    of the EKF of eq. 13 (:class:`core.gnss.ekf.PdrEkf`), which moves the
    position; with ``filter="reset"`` the position instead jumps to each good
    fix and dead-reckons in between (the paper's own architecture: GPS is the
    solution while it is there).

Per fix
    Screening, anchoring, the gate and the verdicts are :class:`core.gnss.base.FixFusion`'s;
    here the EKF position update, then the course of a moving receiver; accepted fixes
    train the stride and heading models.

Everything is in the walk's local ENU frame of :mod:`core` (metres about the
start point); latitude/longitude only at the edges (fix input, FusedStep
output, exports) through :mod:`core.geodesy`.
"""

from __future__ import annotations

import copy
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from core.conventions import heading_from_bearing_deg, wrap_angle
from core.gnss.base import (EVENTS_KEEP_LAST, HACC_PER_SIGMA, FixDecorrelation, FixFusion,  # noqa: F401 - re-exported
                            FixRecord, FusedStep, FusedTrack, FusionResult, OutageResult, relock_heading_error_rad)
from core.gnss.ekf import PdrEkf, UpdateResult
from core.gnss.heading_model import HeadingErrorModel, LaggedRegressors
from core.gnss.training import OnlineTrainer


FILTERS = ("ekf", "reset")
#: heading samples the heading model learns after a relock before the relock's heading SD is dropped
RELOCK_HEADING_SAMPLES = 3


@dataclass(slots=True)
class ChenFusionState:
    """What :class:`GpsFusion` remembers besides :class:`core.gnss.base.FixFusionState` and its components' own
    states (the EKF, the trainer, the fix decorrelation, the lagged regressors): made by :meth:`initial` in
    ``reset()``."""

    relock_heading_sd_rad: float  #: heading SD a relock showed the heading model did not know (rad)
    relock_heading_until: int  #: ... until the heading model has this many samples
    course_used: bool  #: a GPS course has been used (ends ``untrained_until_course``'s honest SD)
    course_innov: deque  #: the last ``course_scatter_n`` course innovations: (rad, the heading state's variance)
    course_sd_sum: float  #: the SDs the courses were used with (rad): their sum, count and largest
    course_sd_n: int
    course_sd_max: float
    fix_bias_t_ns: int | None  #: the fix the fixes' correlated error was last propagated to
    #: the heading model's regressors at the current step, lagged with ``heading_lag_s`` (None without a lag: the
    #: model then takes its heading's own)
    x: np.ndarray | None

    @classmethod
    def initial(cls, course_scatter_n: int) -> ChenFusionState:
        return cls(relock_heading_sd_rad=0.0, relock_heading_until=0, course_used=False,
                   course_innov=deque(maxlen=max(course_scatter_n, 1)), course_sd_sum=0.0, course_sd_n=0,
                   course_sd_max=0.0, fix_bias_t_ns=None, x=None)


class GpsFusion(FixFusion):
    """Fix screening, online training and the PDR EKF (Chen et al. 2010), as one streaming stage.

    Parameters
    ----------
    filter : {"ekf", "reset"}
        ``"ekf"``: eq. 13 with GPS updates; ``"reset"``: the same filter per step, but the
        position jumps to each good fix (no GPS update).
    learn_stride, learn_heading : bool
        Train the stride scale / the heading error model from good GPS.
    use_course : bool
        Use the course of a moving receiver as a heading measurement (EKF only).
    course_min_speed_m_s, course_sd_rad : float
        The course is used above this speed, with this SD (rad).
    stride_scale : float
        Starting stride scale (the user's profile), 1 = the stride model as it is.
    heading_model : HeadingErrorModel or None
        Starting heading error model (a persisted one).
    ekf : PdrEkf or None
        The filter with its noise settings; default :class:`PdrEkf()`.
    trainer : OnlineTrainer or None
        The training stage; default one with ``learn_stride``/``learn_heading``.
    heading_floor_sd_rad : float
        Heading bias SD never claimed away by training (the consider state's floor, rad).
    uncalibrated_heading_sd_rad : float
        Heading bias SD without a heading model (rad).
    untrained_heading_sd_rad : float or None
        Heading bias SD while the heading model is learnt but has no accepted sample yet (rad): dead
        reckoning's own heading error (the attitude filter's heading error plus the device-to-walking offset),
        not the model's offset prior (45 deg), which is for the GPS course aiding, not for the position's
        sigma (issue #26). None (the default): the model's prior. Off by default: on IPIN's tuning split (16
        indoor files with their own GNSS) 15 deg makes the fused sigma cover the landmark errors (median
        error / sigma 0.35 -> 0.85, 91 % within 2 sigma; 10 deg: 1.11, 84 %; 5 deg: 1.35, 75 %) and the fused
        mean 2.838 -> 2.816 m, but the median does not improve (2.221 -> 2.222 m: the middle files take no fix;
        10 deg: 2.285), outdoor tuning is about neutral (lopen 3-min outage 20.6 -> 20.7 %, leave-out ratio
        0.433 -> 0.423), and the guard's ETH 3-min outage went 14.4 -> 19.0 % (the tighter heading state
        learns less from the first fixes). (Those numbers are for ``untrained_until_course=False``.)
    untrained_until_course : bool
        With ``untrained_heading_sd_rad``: that SD holds only until the first GPS course is used (True), and the
        course update itself is made with the model's prior spread, so that a moving receiver teaches the heading
        as fast as without the setting (the honest SD is for the POSITION of dead reckoning; the course aiding
        keeps its spread); False: until the heading model's first sample, as before.  Measured at 15 deg (issue
        #26's indoor target, fourth session): the guard's ETH 3-min outage stays 14.4 % (False: 19.0), lopen
        unchanged (leave-out 0.433 -> 0.423, 3-min 20.6 %), but indoors it gives less: IPIN TUNING median 2.221
        -> 2.222 m, mean 2.837 -> 2.851 (False: 2.816), because IPIN's receivers report a course at 0.8-1 m/s
        now and then and each ends the honest SD; with the judge's pace check off (a proxy for receivers whose
        speed follows the walker, as on the report split) 2.906 -> 2.678 m (False: 2.475; PDR alone 2.289).
        Measured again (h15/indoor, 2026-12-08, TUNING) at dead reckoning's own heading error, not tuned: the
        pipeline's per-segment heading error against the IPIN tuning landmarks' bearings is 13.1 deg RMS (16 files,
        median |error| 7.7, 90th percentile 21.4).  At 13 deg with ``untrained_until_course=False``: IPIN median
        2.236 -> 2.279 m (PDR alone 2.287), mean 2.834 -> 2.784, NEES median 0.54 -> 1.14 (chi2(2): 1.39); T01r01
        2.23 -> 2.08, T01r04 5.35 -> 4.54, T02r02 2.64 -> 2.60, T01r02 2.10 -> 2.32 (its two early fixes count
        less); every value from 8 to 35 deg betters the mean (2.78-2.81) while the median goes 2.29-2.19; the
        simulator's tuning fault walks and lopen unchanged (1e-4 m, leave-out ratio 0.434).  Left **off**: the
        median is worse.  The report split, seen once after the decision: 3.67 -> 3.54 m (PDR alone 2.44; T24r01
        10.42 -> 5.86, T04r01 2.24 -> 1.62, T04r02 3.44 -> 3.66).
    relock_s, relock_max_drift : float
        As :class:`core.gnss.base.FixFusion`'s, the same as Kubrak's filter since issue #26 (they were the
        base's 8 s and no drift limit): on the simulator's tuning fault walks (seeds 0-9) the fixes more
        than 30 m off that the filter took fell from 211 to 5 (Kubrak's: 5), the noisy minute's outage
        unchanged (median 12.3 m).
    gps_error_correlation_s : float
        The fixes' error correlation time (s) for their decorrelation (:class:`core.gnss.base.FixDecorrelation`): a
        fix ``dt`` after the last one used has its variance multiplied by ``(1 + rho) / (1 - rho)``,
        ``rho = exp(-dt / tau)``, so that a stream of fixes off together counts as one fix per ``2 tau``; the gate
        and the NIS keep one fix's variance.  0 (the default): white fixes (the paper).  **Off**: decided on the
        tuning split (issue #26, 2026-12-07) at 45 s (the IPIN tuning fixes' own correlation time): IPIN median
        landmark error 2.236 -> 2.367 m (dead reckoning alone 2.287; route 01's good fixes are followed less:
        T01r01 2.23 -> 5.86 m), the outdoor tuning walk's distance to left-out fixes 0.43 -> 1.77 of their
        accuracy (lopen's 3-min outage 12.5 -> 11.9 %, 1-min 17.2 -> 22.8 %), the simulator's tuning fault walks
        better (2-min outage after the noisy minute 10.7 -> 9.4 m; the simulator does not set defaults); at 1-15 s
        IPIN 2.29-2.37 m.  The fused sigma is made honest instead by the reported covariance
        (:class:`core.gnss.ekf.PdrEkf`'s ``reported_fix_bias_share``), which leaves the track alone.
    heading_lag_s : float
        The heading model's regressors go through a first-order lag of this time constant (s), the attitude
        filter's response to a heading-dependent magnetic error after a turn (:mod:`core.gnss.heading_model`,
        "The attitude filter's lag"); 0 (the default): eq. 12 as the paper writes it.  **Off**: decided on the
        tuning split (issue #26, 2026-12-07) at 20 s (the simulator truth's best fit, not tuned on the
        benchmarks): the simulator's 5-minute outages (``gnss_eval``, seeds 0-19) median 2.02 -> 1.72 % (mean
        2.20 -> 2.24 %, 11 of 20 walks better; the heading part of the end error 1.18 -> 0.93 %), but the real
        tuning walk ``thomasdingemanse_lopen`` loses its 3-min outage (12.5 -> 12.9 %; 1-min 12.9 / 29.5 / 17.3 ->
        13.4 / 29.7 / 17.2 %; leave-out ratio 0.434 -> 0.417), and IPIN tuning is flat (median 2.236 -> 2.233 m,
        mean 2.840 -> 2.885 m: T01r04 5.35 -> 6.08 m).
    course_scatter_n, course_scatter_min_n : int
        The GPS course's measurement noise from its own innovations (covariance matching; issue #26): each course is
        used with the larger of ``course_sd_rad`` and the spread its last ``course_scatter_n`` innovations (course
        minus the heading state, this one included) show about their circular mean -- robust, 1.4826 times their
        median absolute deviation, so that the one spike a turn gives is not noise -- less the heading state's own
        variance (their mean ``P_psi``), once ``course_scatter_min_n`` are in; 0: ``course_sd_rad`` always (the
        paper's fixed SD).  Why: the course of a phone walking indoors scatters far more than 10 deg (IPIN tuning,
        the courses Chen's filter used: T01r01 15 courses, 28-31 deg RMS about the walked legs), and taken as a
        10-deg measurement it drags the heading (T01r01 2.23 m fused, 2.08 with ``use_course=False``).  The SDs used
        are reported (``counters()["course_sd_deg"]``).  **Off by default** (TUNING split, 2026-12-07, n = 10,
        min 5): IPIN median landmark error 2.236 -> 2.204 m, from the one file it changes (T01r01 2.23 -> 2.17 m,
        a middle file), while the form without the robust spread (the circular SD) gave T01r01 2.00 m and n = 20
        2.26 m: the gain rests on one file, moves with the estimator, and is where the idea came from (within what
        the choice itself could produce); outdoors (``thomasdingemanse_lopen``) the leave-out ratio 0.434 ->
        0.434, the 1-minute outages 12.95 / 29.52 / 17.25 -> 13.47 / 29.52 / 17.25 %, the 3-minute 12.47 ->
        12.49 %; the simulator's fault walks (seeds 0-9) unchanged (noisy minute 10.71 m, track median 6.03 m,
        bad fixes 5).
    **shared
        The fix handling's settings (:class:`core.gnss.base.FixFusion`): ``max_hacc_m``,
        ``default_hacc_m``, ``max_speed_m_s``, ``hacc_scale``, ``min_sigma_m``, ``fused_timeout_s``,
        ``hold_s``, ``hidden_ns``, ``relock_s``, ``anchor_max_hacc_m``, ``anchor_max_waits``,
        ``start``, ``min_cn0_4th_dbhz``.
    """

    name = "chen"

    def __init__(self, *, filter: str = "ekf", learn_stride: bool = True, learn_heading: bool = True,
                 use_course: bool = True, course_min_speed_m_s: float = 0.8,
                 course_sd_rad: float = math.radians(10.0), stride_scale: float = 1.0,
                 heading_model: HeadingErrorModel | None = None, ekf: PdrEkf | None = None,
                 trainer: OnlineTrainer | None = None, heading_floor_sd_rad: float = math.radians(2.0),
                 uncalibrated_heading_sd_rad: float = math.radians(10.0),
                 untrained_heading_sd_rad: float | None = None, untrained_until_course: bool = True,
                 relock_s: float = 20.0,
                 relock_max_drift: float | None = 0.15, gps_error_correlation_s: float = 0.0,
                 heading_lag_s: float = 0.0, course_scatter_n: int = 0, course_scatter_min_n: int = 5, **shared):
        super().__init__(relock_s=relock_s, relock_max_drift=relock_max_drift, **shared)
        if not (gps_error_correlation_s >= 0.0 and math.isfinite(gps_error_correlation_s)):
            raise ValueError(f"gps_error_correlation_s must be finite and >= 0, got {gps_error_correlation_s!r}")
        self.gps_error_correlation_s = float(gps_error_correlation_s)
        self.lagged = LaggedRegressors(heading_lag_s)  # validates heading_lag_s
        self.heading_lag_s = self.lagged.lag_s
        if filter not in FILTERS:
            raise ValueError(f"filter must be one of {FILTERS}, got {filter!r}")
        self.filter = filter
        self.learn_stride = bool(learn_stride)
        self.learn_heading = bool(learn_heading)
        self.use_course = bool(use_course)
        if not (int(course_scatter_n) >= 0 and int(course_scatter_min_n) >= 2):
            raise ValueError(f"course_scatter_n must be >= 0 and course_scatter_min_n >= 2, got {course_scatter_n!r}, "
                             f"{course_scatter_min_n!r}")
        self.course_scatter_n = int(course_scatter_n)
        self.course_scatter_min_n = int(course_scatter_min_n)
        self.course_min_speed_m_s = float(course_min_speed_m_s)
        self.course_sd_rad = float(course_sd_rad)
        self.heading_floor_sd_rad = float(heading_floor_sd_rad)
        self.uncalibrated_heading_sd_rad = float(uncalibrated_heading_sd_rad)
        self.untrained_heading_sd_rad = None if untrained_heading_sd_rad is None else float(untrained_heading_sd_rad)
        self.untrained_until_course = bool(untrained_until_course)
        self._stride_scale0 = float(stride_scale)
        self._heading_model0 = heading_model
        self._ekf_proto = ekf
        self._trainer_proto = trainer
        self.reset()

    def _reset_filter(self) -> None:
        self._chen = ChenFusionState.initial(self.course_scatter_n)
        # the given filter is a prototype of settings: each run starts a copy of it afresh
        self.ekf = PdrEkf() if self._ekf_proto is None else copy.copy(self._ekf_proto)
        self.ekf.reset()
        self.decorrelation = FixDecorrelation(self.gps_error_correlation_s)
        self.lagged.reset()
        if self._trainer_proto is not None:
            self.trainer = self._trainer_proto
            self.trainer.reset()
        else:
            hm = self._heading_model0
            model = HeadingErrorModel(coefficients_rad=hm.coefficients_rad()) if hm is not None else None
            self.trainer = OnlineTrainer(learn_stride=self.learn_stride, learn_heading=self.learn_heading,
                                         scale_prior=self._stride_scale0, heading_model=model,
                                         keep_windows=None if self.keep_history else EVENTS_KEEP_LAST)

    @property
    def filt(self) -> PdrEkf:
        return self.ekf

    # -- the models in use ---------------------------------------------------------
    @property
    def stride_scale(self) -> float:
        return self.trainer.stride_scale if self.learn_stride else self._stride_scale0

    @property
    def heading_model(self) -> HeadingErrorModel:
        return self.trainer.heading_model

    def _heading_sd(self, heading_rad: float) -> float:
        """What the heading model does not know at this heading (rad).

        Its coefficients' uncertainty, and the scatter of its training windows
        about it: that scatter is not white at the time scale of an outage (on
        the ETH walk the deviation wanders by 10 degrees over minutes), so it
        is no smaller for having many windows.
        """
        if self.learn_heading or self._heading_model0 is not None:
            hm = self.heading_model
            if self._heading_model0 is None and hm.n_accepted == 0 and self.untrained_heading_sd_rad is not None \
                    and not (self.untrained_until_course and self._chen.course_used):
                return self.untrained_heading_sd_rad
            return self._model_heading_sd(heading_rad)
        return self.uncalibrated_heading_sd_rad

    def _model_heading_sd(self, heading_rad: float) -> float:
        """The heading model's own SD at this heading (rad): its coefficients' and its windows' scatter (the offset
        prior while it has no sample)."""
        hm = self.heading_model
        res = hm.residual_sd_rad()
        return math.hypot(hm.correction_sd_rad(heading_rad, self._chen.x), res if math.isfinite(res) else 0.0)

    def compensated_heading(self, heading_rad: float) -> float:
        """Our heading plus the eq.-12 correction (only when the model is learnt or was given)."""
        if self.learn_heading or self._heading_model0 is not None:
            return heading_rad + self.heading_model.correction_rad(heading_rad, self._chen.x)
        return heading_rad

    # -- the filter's hooks -----------------------------------------------------------
    def _before_fixes(self, step, t_prev_ns: int) -> None:
        # the trainer gets the step before the fixes it spans: a window closed by a fix inside this step's
        # interval must count the part of the step before the fix (without it the model distance of every
        # window missed half a step on average, and the stride scale came out 2.4 % long on the simulator)
        if self.heading_lag_s > 0.0:  # (off by default: no regressors built per step then)
            self._chen.x = self.lagged.update(step.t_ns, step.heading_rad)
        self.trainer.add_step(step.t_ns, t_prev_ns, step.length_m, step.heading_rad, self._chen.x)

    def _init_filter_at(self, sigma_m: float) -> None:
        self.ekf.initialize(0.0, 0.0, sigma_m, 0.7, 0.0, heading_sd_rad=math.pi)

    def _step(self, step, t_prev_ns: int, dur_ns: int) -> float:
        length = self.stride_scale * step.length_m
        heading = self.compensated_heading(step.heading_rad)
        ekf = self.ekf
        if not ekf.initialized:
            ekf.initialize(0.0, 0.0, self.start[2] if self.start is not None else 0.1, length, heading)
        if self._chen.relock_heading_sd_rad and self.trainer.n_heading_samples >= self._chen.relock_heading_until:
            self._chen.relock_heading_sd_rad = 0.0
        ekf.set_consider_sd(math.hypot(self._heading_sd(step.heading_rad), self.heading_floor_sd_rad,
                                       self._chen.relock_heading_sd_rad),
                            self._stride_scale_sd())
        ekf.step(length, heading)
        return length

    def _after_relock(self, offset_m: float, walked_m: float) -> None:
        """The track ended ``offset_m`` off after ``walked_m`` of dead reckoning: a heading error of
        ``2 asin(offset / 2 walked)`` (pi when it walked less than half the offset), which the heading model's
        SD did not cover (the gate refused the fixes).  That angle joins the heading-bias consider SD until the
        heading model has learnt from ``RELOCK_HEADING_SAMPLES`` more windows, so the position's reported
        sigma grows as the track can drift (issue #26: on liatoutou_walk2 the track was 200 m off again 90 s
        after each relock with a reported sigma of 3-15 m)."""
        angle = relock_heading_error_rad(offset_m, walked_m)
        if angle > self._chen.relock_heading_sd_rad:
            self._chen.relock_heading_sd_rad = angle
        self._chen.relock_heading_until = self.trainer.n_heading_samples + RELOCK_HEADING_SAMPLES

    def _step_output(self) -> tuple[float, float]:
        return float(self.ekf.x[2]), float(self.ekf.x[3])

    def _reported_cov(self):
        return self.ekf.reported_cov

    def _stride_scale_sd(self) -> float:
        return self.trainer.stride_scale_sd if self.learn_stride else self.trainer.prior_scale_sd

    def _dead_reckoned_step(self, step) -> tuple[float, float]:
        length, heading = self.stride_scale * step.length_m, self.compensated_heading(step.heading_rad)
        if math.isfinite(length) and math.isfinite(heading):
            self.ekf.set_step(length, heading)
        return length, heading

    def _fraction(self, t_ns: int) -> float:
        """The part of the next step already walked at a fix's time: at most the whole step (a pause: the walker
        stands there; before issue #26 the prediction snapped back to the last step after two durations)."""
        if self._state.screen.last_step_ns is None or not self._state.screen.last_step_dur_ns:
            return 0.0
        since = t_ns - self._state.screen.last_step_ns
        return min(since / self._state.screen.last_step_dur_ns, 1.0) if since > 0 else 0.0

    def _predict_fix(self, t_ns: int):
        return PdrEkf.fix_prediction(self.ekf.x, self._fraction(t_ns))

    def _update_position(self, t_ns: int, east: float, north: float, sigma_m: float, gate: bool) -> UpdateResult:
        ekf = self.ekf
        if self.filter == "reset":
            before = self.ekf.position_sigma_m()
            innov = (float(east - ekf.x[0]), float(north - ekf.x[1]))  # before the reset (issue #26: it was after)
            ekf.reset_position(east, north, sigma_m)
            return UpdateResult(True, innov, math.nan, math.hypot(*innov), before)
        if self._chen.fix_bias_t_ns != t_ns:  # once per fix (a relock updates twice with the same one)
            dt = (t_ns - self._chen.fix_bias_t_ns) * 1e-9 if self._chen.fix_bias_t_ns is not None else math.inf
            ekf.propagate_fix_bias(dt, sigma_m)
            self._chen.fix_bias_t_ns = int(t_ns)
        return ekf.update_position(east, north, sigma_m, self._fraction(t_ns), gate=gate,
                                   noise_scale=self.decorrelation.noise_scale(t_ns))

    def _placed_on_fix(self, t_ns: int, sigma_m: float, relock: bool = False) -> None:
        self.ekf.place_on_fix(sigma_m)
        self._chen.fix_bias_t_ns = int(t_ns)

    def _after_accept(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        self.decorrelation.used(t_ns)
        if self.filter == "ekf" and self.origin_lat_lon is not None and self.use_course and \
                speed >= self.course_min_speed_m_s and math.isfinite(course) and self.anchor[0] != t_ns:
            if self.untrained_until_course and not self._chen.course_used and \
                    self.untrained_heading_sd_rad is not None and self._heading_model0 is None and \
                    self.heading_model.n_accepted == 0 and self.learn_heading:
                # the first course: the heading state gets the model's prior spread back before it is measured
                hdg = self._state.screen.headings[-1][1] if self._state.screen.headings else float(self.ekf.x[3])
                self.ekf.set_consider_sd(math.hypot(self._model_heading_sd(hdg), self.heading_floor_sd_rad,
                                                    self._chen.relock_heading_sd_rad),
                                         self._stride_scale_sd())
            self._chen.course_used = True
            c = self.course_now(t_ns, heading_from_bearing_deg(course))
            self.ekf.update_course(c, self._course_sd(c))
        self._learn_from_fix(t_ns, east, north, hacc, speed, course)

    def _course_sd(self, course_rad: float) -> float:
        """The SD (rad) a course at ``course_rad`` is used with: ``course_sd_rad``, or with ``course_scatter_n`` the
        robust spread (1.4826 x the median absolute deviation) of the last ``course_scatter_n`` course innovations
        (this one's included) about their circular mean, less the heading state's mean variance over them, if
        larger, once ``course_scatter_min_n`` are in."""
        sd = self.course_sd_rad
        if self.course_scatter_n > 0 and math.isfinite(course_rad):
            q = self._chen.course_innov
            q.append((wrap_angle(course_rad - float(self.ekf.x[3])), float(self.ekf.P[3, 3])))
            if len(q) >= self.course_scatter_min_n:
                a = np.array([v[0] for v in q])
                d = np.array([wrap_angle(x) for x in a - math.atan2(float(np.mean(np.sin(a))),
                                                                      float(np.mean(np.cos(a))))])
                spread = 1.4826 * float(np.median(np.abs(d - np.median(d))))  # robust: a turn's spike is not noise
                var = spread ** 2 - float(np.mean([v[1] for v in q]))
                sd = max(sd, math.sqrt(max(var, 0.0)))
        self._chen.course_sd_sum += sd
        self._chen.course_sd_n += 1
        self._chen.course_sd_max = max(self._chen.course_sd_max, sd)
        return sd

    def _learn_from_fix(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        c_rad = heading_from_bearing_deg(course) if math.isfinite(course) else math.nan
        self.trainer.add_fix(t_ns, east, north, hacc, speed, c_rad)

    # -- output ------------------------------------------------------------------------------
    def status(self) -> dict:
        return {**super().status(), "stride_scale": self.stride_scale}

    def counters(self) -> dict:
        c = self._chen
        return {**super().counters(), "filter": self.filter, "training": self.trainer.counters(),
                "course_sd_deg": {"courses": c.course_sd_n,  # the SDs the GPS courses were used with
                                  "mean": math.degrees(c.course_sd_sum / c.course_sd_n) if c.course_sd_n else math.nan,
                                  "max": math.degrees(c.course_sd_max) if c.course_sd_n else math.nan},
                "fix_decorrelation": self.decorrelation.summary()}
