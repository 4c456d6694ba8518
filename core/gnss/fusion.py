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
    1. screening: finite position, reported accuracy ``hacc_m <= max_hacc_m``
       (a fix without one is given ``default_hacc_m``), speed at most
       ``max_speed_m_s`` (a vehicle, not a walker), not inside a hidden window
       (``hidden_ns``: the benchmark's and ``--gps-outage``'s simulated outages);
    2. the first good fix anchors the walk: the local frame keeps its origin
       at the walk's start, whose latitude/longitude follow from the fix and
       the dead-reckoned position at that moment;
    3. the EKF position update (a chi-square gate on its NIS rejects a fix
       that disagrees with the track beyond what both uncertainties allow:
       multipath; fixes that keep disagreeing but agree among themselves for
       ``relock_s`` are taken, with the covariance widened), then the course
       of a moving receiver;
    4. accepted fixes train the stride and heading models.

Fix times and step times
    Steps leave the pipeline about a second after they happen (the heading
    smoother's delay), fixes arrive at once.  A fix waits until the first
    step after it has been processed (or until ``hold_s`` has passed without
    one: the walker stands), so that fixes and steps meet the filter in time
    order, as in a batch run.

Outages
    For every hidden window the first screened fix after it gives the
    end-of-outage error (the prediction against the fix, before the update),
    the distance walked in the window, the position uncertainty before the
    update and the jump the update made (:class:`OutageResult`).

Everything is in the walk's local ENU frame of :mod:`core` (metres about the
start point); latitude/longitude only at the edges (fix input, FusedStep
output, exports) through :mod:`core.geodesy`.
"""

from __future__ import annotations

import copy
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from core.conventions import heading_from_bearing_deg
from core.geodesy import enu_to_geodetic, geodetic_to_enu
from core.gnss.ekf import PdrEkf, sigma_max_m
from core.gnss.heading_model import HeadingErrorModel
from core.gnss.training import OnlineTrainer

#: 68 % radius of a circular 2-D Gaussian, in units of its per-axis SD: hacc = 1.515 sigma
HACC_PER_SIGMA = math.sqrt(-2.0 * math.log(1.0 - 0.68))

FILTERS = ("ekf", "reset")


@dataclass(frozen=True)
class FixRecord:
    """One GPS fix as the fusion saw it."""

    t_ns: int
    lat_deg: float
    lon_deg: float
    east_m: float  #: local frame (nan before the walk is anchored)
    north_m: float
    hacc_m: float
    speed_m_s: float
    course_deg: float
    accepted: bool
    reason: str = ""  #: why it was not used ("" when accepted)
    nis: float = math.nan
    correction_m: float = 0.0  #: how far the fused position moved


@dataclass(frozen=True)
class FusedStep:
    """One step of the fused track."""

    index: int
    t_ns: int
    east_m: float  #: local ENU (m) about the walk's start, like the dead-reckoned track
    north_m: float
    lat_deg: float  #: nan until a fix anchors the walk (batch results fill every step)
    lon_deg: float
    length_m: float  #: fused step length (m)
    heading_rad: float  #: fused heading (rad, CCW from East)
    cov_en_m2: tuple  #: (var_east, cov_east_north, var_north) of the position (m^2)
    source: str  #: "fused" (a fix was accepted within ``fused_timeout_s``) or "dr" (dead reckoning only)


@dataclass(frozen=True)
class OutageResult:
    """The end of one hidden window, measured at the first screened fix after it."""

    start_s: float  #: from the first sensor event (as given)
    length_s: float
    walked_m: float  #: fused distance walked inside the window
    end_error_m: float  #: prediction minus that fix (m)
    end_error_pct: float  #: of ``walked_m``
    sigma_m: float  #: position uncertainty (sqrt of the largest eigenvalue) before the fix
    jump_m: float  #: how far the first accepted fix after the window moved the position (nan: none was)
    fix_t_ns: int  #: the fix that measured the end error
    fix_accepted: bool  #: whether that fix was accepted at once (else GPS was taken back later)
    rejoin_s: float = math.nan  #: from that fix to the first accepted one (s)

    def as_dict(self) -> dict:
        return {"start_s": self.start_s, "length_s": self.length_s, "walked_m": self.walked_m,
                "end_error_m": self.end_error_m, "end_error_pct": self.end_error_pct, "sigma_m": self.sigma_m,
                "jump_m": self.jump_m, "jump_over_3sigma": bool(self.jump_m > 3.0 * self.sigma_m),
                "fix_accepted": self.fix_accepted, "rejoin_s": self.rejoin_s}


@dataclass
class _Window:
    """A hidden window while the fusion runs."""

    start_ns: int
    end_ns: int
    walked_m: float = 0.0
    end_error_m: float | None = None
    sigma_m: float = math.nan
    fix_t_ns: int | None = None
    done: bool = False


@dataclass
class FusedTrack:
    """The fused track as arrays (the shape :mod:`core.export` and the plots take)."""

    t_ns: np.ndarray
    length_m: np.ndarray
    heading_rad: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    sigma_m: np.ndarray  #: sqrt of the largest eigenvalue of the position covariance (m)
    source: list  #: "fused" / "dr" per step

    def __len__(self) -> int:
        return len(self.t_ns)

    def point_properties(self) -> dict:
        """Per-step extras for the exports: uncertainty and source."""
        return {"sigma_m": [round(float(v), 3) for v in self.sigma_m], "source": list(self.source)}


@dataclass
class FusionResult:
    steps: list
    fixes: list
    outages: list
    origin_lat_lon: tuple | None
    counters: dict = field(default_factory=dict)

    def track(self) -> FusedTrack:
        st = self.steps
        return FusedTrack(np.array([s.t_ns for s in st], dtype=np.int64), np.array([s.length_m for s in st]),
                          np.array([s.heading_rad for s in st]), np.array([s.east_m for s in st]),
                          np.array([s.north_m for s in st]), np.array([sigma_max_m(s.cov_en_m2) for s in st]),
                          [s.source for s in st])


class GpsFusion:
    """Fix screening, online training and the PDR EKF, as one streaming stage.

    Parameters
    ----------
    filter : {"ekf", "reset"}
        ``"ekf"``: eq. 13 with GPS updates; ``"reset"``: the same filter per step, but the
        position jumps to each good fix (no GPS update).
    learn_stride, learn_heading : bool
        Train the stride scale / the heading error model from good GPS.
    use_course : bool
        Use the course of a moving receiver as a heading measurement (EKF only).
    max_hacc_m : float
        Fixes reporting a worse horizontal accuracy are not used (m).
    default_hacc_m : float
        Accuracy assumed for a fix that reports none (m).
    max_speed_m_s : float
        Fixes reporting a higher speed are not a walker's (m/s).
    hacc_scale : float
        Factor on the reported accuracy for the measurement noise (phones are often optimistic).
    min_sigma_m : float
        Floor on the per-axis SD of a fix position (m).
    course_min_speed_m_s, course_sd_rad : float
        The course is used above this speed, with this SD (rad).
    fused_timeout_s : float
        A step is "fused" when a fix was accepted within this time before it (s).
    hold_s : float
        Longest time a fix waits for the step after it (s).
    hidden_ns : sequence of (t_start_ns, t_end_ns)
        Windows whose fixes are hidden (simulated outages).
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
    anchor_max_hacc_m, anchor_max_waits : float, int
        The first fix used (the anchor) must report at most this accuracy (m), unless this
        many screened fixes came without one (then any fix within ``max_hacc_m`` anchors).
    relock_s : float
        Fixes rejected by the gate for this long, agreeing among themselves (their
        innovations' SD within twice a fix's SD), are taken: after a long outage the
        track is more likely off than a steady GPS (s).
    """

    def __init__(self, *, filter: str = "ekf", learn_stride: bool = True, learn_heading: bool = True,
                 use_course: bool = True, max_hacc_m: float = 25.0, default_hacc_m: float = 10.0,
                 max_speed_m_s: float = 3.0, hacc_scale: float = 1.0, min_sigma_m: float = 1.0,
                 course_min_speed_m_s: float = 0.8, course_sd_rad: float = math.radians(10.0),
                 fused_timeout_s: float = 5.0, hold_s: float = 3.0, hidden_ns=(), stride_scale: float = 1.0,
                 heading_model: HeadingErrorModel | None = None, ekf: PdrEkf | None = None,
                 trainer: OnlineTrainer | None = None, heading_floor_sd_rad: float = math.radians(2.0),
                 uncalibrated_heading_sd_rad: float = math.radians(10.0), relock_s: float = 8.0,
                 anchor_max_hacc_m: float = 12.0, anchor_max_waits: int = 30):
        if filter not in FILTERS:
            raise ValueError(f"filter must be one of {FILTERS}, got {filter!r}")
        self.filter = filter
        self.learn_stride = bool(learn_stride)
        self.learn_heading = bool(learn_heading)
        self.use_course = bool(use_course)
        self.max_hacc_m = float(max_hacc_m)
        self.default_hacc_m = float(default_hacc_m)
        self.max_speed_m_s = float(max_speed_m_s)
        self.hacc_scale = float(hacc_scale)
        self.min_sigma_m = float(min_sigma_m)
        self.course_min_speed_m_s = float(course_min_speed_m_s)
        self.course_sd_rad = float(course_sd_rad)
        self.fused_timeout_ns = int(fused_timeout_s * 1e9)
        self.hold_ns = int(hold_s * 1e9)
        self.relock_ns = int(relock_s * 1e9)
        self.anchor_max_hacc_m = float(anchor_max_hacc_m)
        self.anchor_max_waits = int(anchor_max_waits)
        self.hidden_ns = [(int(a), int(b)) for a, b in hidden_ns]
        self.heading_floor_sd_rad = float(heading_floor_sd_rad)
        self.uncalibrated_heading_sd_rad = float(uncalibrated_heading_sd_rad)
        self._stride_scale0 = float(stride_scale)
        self._heading_model0 = heading_model
        self._ekf_proto = ekf
        self._trainer_proto = trainer
        self.reset()

    def reset(self) -> None:
        # the given filter is a prototype of settings: each run starts a copy of it afresh
        self.ekf = PdrEkf() if self._ekf_proto is None else copy.copy(self._ekf_proto)
        self.ekf.reset()
        if self._trainer_proto is not None:
            self.trainer = self._trainer_proto
            self.trainer.reset()
        else:
            hm = self._heading_model0
            model = HeadingErrorModel(coefficients_rad=hm.coefficients_rad()) if hm is not None else None
            self.trainer = OnlineTrainer(learn_stride=self.learn_stride, learn_heading=self.learn_heading,
                                         scale_prior=self._stride_scale0, heading_model=model)
        self.origin_lat_lon: tuple[float, float] | None = None
        #: the fix that anchored the walk: (t_ns, lat_deg, lon_deg, alt_m); None before
        self.anchor: tuple | None = None
        self.fixes: list[FixRecord] = []
        self.steps: list[FusedStep] = []
        self.outages: list[OutageResult] = []
        self._queue: deque = deque()
        self._last_step_ns: int | None = None
        self._last_step_dur_ns = int(0.55e9)
        self._last_accept_ns: int | None = None
        self._windows = [_Window(a, b) for a, b in self.hidden_ns]
        self._t_first_ns: int | None = None
        self.n_screened_out = 0
        self.n_gated = 0
        self.n_relocked = 0
        self._anchor_waits = 0
        self._rejected_run: deque = deque()
        self._nis_sum = 0.0
        self._nis_n = 0
        self._reset_pos_var = 0.0

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
            res = hm.residual_sd_rad()
            return math.hypot(hm.correction_sd_rad(heading_rad), res if math.isfinite(res) else 0.0)
        return self.uncalibrated_heading_sd_rad

    def compensated_heading(self, heading_rad: float) -> float:
        """Our heading plus the eq.-12 correction (only when the model is learnt or was given)."""
        if self.learn_heading or self._heading_model0 is not None:
            return heading_rad + self.heading_model.correction_rad(heading_rad)
        return heading_rad

    # -- input ------------------------------------------------------------------------
    def add_fix(self, t_ns: int, values) -> None:
        """A GPS event (``values`` as the ``gps`` stream: lat, lon, alt, hacc, speed, course)."""
        self._queue.append((int(t_ns), tuple(float(v) for v in values)))
        last = self._last_step_ns
        while self._queue and ((last is not None and self._queue[0][0] <= last)
                               or self._queue[0][0] < int(t_ns) - self.hold_ns):
            self._fix(*self._queue.popleft())

    def add_step(self, step) -> FusedStep:
        """A completed :class:`core.pdr.pipeline.Step`; returns its fused counterpart."""
        prev = self._last_step_ns
        dur = int(step.features.duration_s * 1e9) if step.features.duration_s == step.features.duration_s else \
            self._last_step_dur_ns
        t_prev = step.t_ns - dur if prev is None else max(prev, step.t_ns - 3 * dur)
        # the trainer gets the step before the fixes it spans: a window closed by a fix inside this step's
        # interval must count the part of the step before the fix (without it the model distance of every
        # window missed half a step on average, and the stride scale came out 2.4 % long on the simulator)
        self.trainer.add_step(step.t_ns, t_prev, step.length_m, step.heading_rad)
        while self._queue and self._queue[0][0] <= step.t_ns:
            self._fix(*self._queue.popleft())
        length = self.stride_scale * step.length_m
        heading = self.compensated_heading(step.heading_rad)
        ekf = self.ekf
        if not ekf.initialized:
            ekf.initialize(0.0, 0.0, 0.1, length, heading)
        ekf.set_consider_sd(math.hypot(self._heading_sd(step.heading_rad), self.heading_floor_sd_rad),
                            self.trainer.stride_scale_sd if self.learn_stride else self.trainer.prior_scale_sd)
        ekf.step(length, heading)
        self._last_step_ns = step.t_ns
        self._last_step_dur_ns = dur
        for w in self._windows:
            if w.start_ns <= step.t_ns < w.end_ns:
                w.walked_m += length
        fused = self._emit(step.index, step.t_ns)
        self.steps.append(fused)
        return fused

    def finish(self) -> None:
        while self._queue:
            self._fix(*self._queue.popleft())
        for w in self._windows:
            if w.fix_t_ns is not None and not w.done:
                self._close_window(w, math.nan, None)

    # -- fixes ----------------------------------------------------------------------------
    def _hidden(self, t_ns: int) -> bool:
        return any(a <= t_ns < b for a, b in self.hidden_ns)

    def _screen(self, t_ns, lat, lon, hacc, speed) -> str:
        if not (math.isfinite(lat) and math.isfinite(lon)) or not (-90.0 <= lat <= 90.0):
            return "no position"
        if hacc > self.max_hacc_m:
            return f"accuracy {hacc:.0f} m > {self.max_hacc_m:.0f} m"
        if speed > self.max_speed_m_s:
            return f"speed {speed:.1f} m/s is not walking"
        return ""

    def _fix(self, t_ns: int, v: tuple) -> None:
        lat, lon = v[0], v[1]
        hacc = v[3] if len(v) > 3 else math.nan
        speed = v[4] if len(v) > 4 else math.nan
        course = v[5] if len(v) > 5 else math.nan
        nan = math.nan
        hacc_eff = hacc if hacc > 0 else self.default_hacc_m
        if self._hidden(t_ns):
            self.fixes.append(FixRecord(t_ns, lat, lon, nan, nan, hacc, speed, course, False, "hidden (outage)"))
            return
        reason = self._screen(t_ns, lat, lon, hacc, speed)
        if reason:
            self.n_screened_out += 1
            self.fixes.append(FixRecord(t_ns, lat, lon, nan, nan, hacc, speed, course, False, reason))
            return
        ekf = self.ekf
        sigma = max(hacc_eff * self.hacc_scale / HACC_PER_SIGMA, self.min_sigma_m)
        if self.origin_lat_lon is None and hacc_eff > self.anchor_max_hacc_m and \
                self._anchor_waits < self.anchor_max_waits:
            # a phone's first fixes are often coarse (the ETH walk's first three are 65 m off): wait for a good one
            self._anchor_waits += 1
            self.n_screened_out += 1
            self.fixes.append(FixRecord(t_ns, lat, lon, nan, nan, hacc, speed, course, False,
                                        f"waiting for a first fix within {self.anchor_max_hacc_m:.0f} m"))
            return
        if self.origin_lat_lon is None:
            # anchor: the walk's start lies where dead reckoning says, seen from this fix
            e0, n0 = (float(ekf.x[0]), float(ekf.x[1])) if ekf.initialized else (0.0, 0.0)
            lat0, lon0 = enu_to_geodetic(-e0, -n0, (lat, lon))
            self.origin_lat_lon = (float(lat0), float(lon0))
            self.anchor = (int(t_ns), float(lat), float(lon), float(v[2]) if len(v) > 2 else math.nan)
            if not ekf.initialized:
                ekf.initialize(0.0, 0.0, sigma, 0.7, 0.0, heading_sd_rad=math.pi)
            ekf.P[:2, :] = 0.0
            ekf.P[:, :2] = 0.0
            ekf.P[0, 0] = ekf.P[1, 1] = sigma ** 2
            self._accepted(t_ns, lat, lon, e0, n0, hacc, speed, course, nan, 0.0)
            return
        east, north = geodetic_to_enu(lat, lon, self.origin_lat_lon)
        frac = 0.0
        if self._last_step_ns is not None:
            since = t_ns - self._last_step_ns
            if 0 <= since <= 2 * self._last_step_dur_ns:
                frac = since / self._last_step_dur_ns
        pred = PdrEkf.fix_prediction(ekf.x, min(frac, 1.0))
        sig_before = ekf.position_sigma_m()
        self._outage_end(t_ns, east, north, pred, sig_before)
        if self.filter == "ekf":
            res = ekf.update_position(east, north, sigma, frac)
            if not res.accepted and self._relock(t_ns, res.innovation, sigma):
                # the track, not the GPS, is wrong: take the fix with the position uncertainty widened by
                # the disagreement (so its NIS is acceptable) instead of rejecting GPS for ever
                d = np.array(res.innovation)
                ekf.P[:2, :2] += np.outer(d, d)
                res = ekf.update_position(east, north, sigma, frac, gate=False)
                self.n_relocked += 1
            if not res.accepted:
                self.n_gated += 1
                self.fixes.append(FixRecord(t_ns, lat, lon, east, north, hacc, speed, course, False, res.reason,
                                            res.nis))
                self._outage_jump(t_ns, 0.0, False)
                return
            self._rejected_run.clear()
            self._nis_sum += res.nis
            self._nis_n += 1
            moved, nis = res.correction_m, res.nis
            if self.use_course and speed >= self.course_min_speed_m_s and math.isfinite(course):
                ekf.update_course(heading_from_bearing_deg(course), self.course_sd_rad)
        else:
            moved = math.hypot(east - ekf.x[0], north - ekf.x[1])
            ekf.reset_position(east, north, sigma)
            nis = nan
        self._outage_jump(t_ns, moved, True)
        self._accepted(t_ns, lat, lon, east, north, hacc, speed, course, nis, moved)

    def _relock(self, t_ns: int, innovation, sigma_m: float) -> bool:
        """Consecutive gated fixes that agree among themselves for ``relock_s``: the track is off, not GPS."""
        run = self._rejected_run
        run.append((t_ns, innovation[0], innovation[1]))
        while run and run[0][0] < t_ns - 2 * self.relock_ns:
            run.popleft()
        if len(run) < 3 or t_ns - run[0][0] < self.relock_ns:
            return False
        d = np.array([(r[1], r[2]) for r in run])
        if float(np.max(np.std(d, axis=0))) > 2.0 * sigma_m:
            return False  # they disagree with each other too: bad GPS, keep rejecting
        run.clear()
        return True

    def _accepted(self, t_ns, lat, lon, east, north, hacc, speed, course, nis, moved) -> None:
        self._last_accept_ns = t_ns
        self.fixes.append(FixRecord(t_ns, lat, lon, east, north, hacc, speed, course, True, "", nis, moved))
        c_rad = heading_from_bearing_deg(course) if math.isfinite(course) else math.nan
        self.trainer.add_fix(t_ns, east, north, hacc if hacc > 0 else self.default_hacc_m, speed, c_rad)

    def _outage_end(self, t_ns, east, north, pred, sigma) -> None:
        """The first screened fix after a hidden window: the error before the update."""
        for w in self._windows:
            if w.end_error_m is None and t_ns >= w.end_ns:
                w.end_error_m = math.hypot(east - pred[0], north - pred[1])
                w.sigma_m = sigma
                w.fix_t_ns = t_ns

    def _outage_jump(self, t_ns, moved, accepted) -> None:
        """... and the jump at the first fix after it that the filter accepts (the track rejoining GPS)."""
        if not accepted:
            return
        for w in self._windows:
            if w.fix_t_ns is not None and not w.done:
                self._close_window(w, moved, t_ns)

    def _close_window(self, w, jump_m: float, accept_t_ns: int | None) -> None:
        w.done = True
        t0 = self._t_first_ns if self._t_first_ns is not None else 0
        pct = 100.0 * w.end_error_m / w.walked_m if w.walked_m > 0 else math.nan
        self.outages.append(OutageResult((w.start_ns - t0) * 1e-9, (w.end_ns - w.start_ns) * 1e-9, w.walked_m,
                                         w.end_error_m, pct, w.sigma_m, jump_m, w.fix_t_ns,
                                         accept_t_ns == w.fix_t_ns,
                                         (accept_t_ns - w.fix_t_ns) * 1e-9 if accept_t_ns is not None else math.nan))

    def set_time_zero(self, t0_ns: int) -> None:
        """The first sensor event's time, for outage start times in seconds."""
        self._t_first_ns = int(t0_ns)

    # -- output ------------------------------------------------------------------------------
    def _emit(self, index: int, t_ns: int) -> FusedStep:
        ekf = self.ekf
        e, n = float(ekf.x[0]), float(ekf.x[1])
        lat = lon = math.nan
        if self.origin_lat_lon is not None:
            lat, lon = enu_to_geodetic(e, n, self.origin_lat_lon)
        fused = self._last_accept_ns is not None and t_ns - self._last_accept_ns <= self.fused_timeout_ns
        P = ekf.P
        return FusedStep(index, t_ns, e, n, float(lat), float(lon), float(ekf.x[2]), float(ekf.x[3]),
                         (float(P[0, 0]), float(P[0, 1]), float(P[1, 1])), "fused" if fused else "dr")

    def status(self) -> dict:
        """Live position and uncertainty for the app (local ENU)."""
        ekf = self.ekf
        return {"east_m": float(ekf.x[0]), "north_m": float(ekf.x[1]),
                "sigma_m": ekf.position_sigma_m() if ekf.initialized else math.nan,
                "anchored": self.origin_lat_lon is not None, "stride_scale": self.stride_scale}

    def counters(self) -> dict:
        n_acc = sum(1 for f in self.fixes if f.accepted)
        return {"fixes": len(self.fixes), "fixes_accepted": n_acc, "fixes_screened_out": self.n_screened_out,
                "fixes_gated": self.n_gated, "fixes_relocked": self.n_relocked,
                "fixes_hidden": sum(1 for f in self.fixes if f.reason == "hidden (outage)"),
                "position_nis_mean": self._nis_sum / self._nis_n if self._nis_n else math.nan,
                "filter": self.filter, "training": self.trainer.counters()}

    def run(self, steps, gps_stream=None, t0_ns: int | None = None) -> FusionResult:
        """Batch: fuse a finished walk's steps (:class:`core.pdr.pipeline.Step`) with its ``gps`` stream.

        The same kernel as streaming: fixes and steps meet the filter in the order a
        live pipeline gives them (each fix before the first step after it), so
        ``Pipeline(gnss=GpsFusion()).run(rec)`` and ``GpsFusion().run(Pipeline().run(rec).steps,
        rec.streams["gps"])`` agree (a test checks it); this one is much faster for sweeps.
        """
        self.reset()
        if t0_ns is not None:
            self.set_time_zero(t0_ns)
        if gps_stream is not None and len(gps_stream):
            ft, fv = gps_stream.t_ns, gps_stream.values
        else:
            ft, fv = np.zeros(0, np.int64), np.zeros((0, 6))
        j = 0
        for st in steps:
            while j < len(ft) and ft[j] <= st.t_ns:
                self.add_fix(int(ft[j]), fv[j].tolist())
                j += 1
            self.add_step(st)
        while j < len(ft):
            self.add_fix(int(ft[j]), fv[j].tolist())
            j += 1
        self.finish()
        return self.result()

    def result(self) -> FusionResult:
        """Everything so far, with latitude/longitude filled for every step once the walk is anchored."""
        steps = self.steps
        if self.origin_lat_lon is not None:
            out = []
            for s in steps:
                if s.lat_deg != s.lat_deg:
                    lat, lon = enu_to_geodetic(s.east_m, s.north_m, self.origin_lat_lon)
                    s = FusedStep(s.index, s.t_ns, s.east_m, s.north_m, float(lat), float(lon), s.length_m,
                                  s.heading_rad, s.cov_en_m2, s.source)
                out.append(s)
            steps = out
        return FusionResult(steps, list(self.fixes), list(self.outages), self.origin_lat_lon, self.counters())
