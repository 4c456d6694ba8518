"""What every GPS fusion filter shares: fix screening, anchoring, hidden windows, verdicts, the fused track.

:class:`FixFusion` is the base of the two fusion stages, :class:`core.gnss.fusion.GpsFusion`
(Chen et al. 2010: calibration while GPS is good and the step-wise PDR EKF of eq. 13) and
:class:`core.gnss.kubrak.KubrakFusion` (Kubrak et al. 2006: the velocity-model Kalman filter of
Fig. 8 with bad-GPS detection).  It takes the pipeline's steps and the GPS fixes, in the order a
live pipeline gives them, and leaves the filtering to the subclass through a few hooks.

Per fix, in this order; every fix gets a verdict (:class:`FixRecord`: used, or rejected and why)
    1. hidden: inside a hidden window (``hidden_ns``: the benchmark's and ``--gps-outage``'s
       simulated outages), measured but never used;
    2. screening: finite position, reported accuracy ``hacc_m <= max_hacc_m`` (a fix without one
       is given ``default_hacc_m``), speed at most ``max_speed_m_s`` (a vehicle, not a walker);
    3. the usability judge (:class:`core.gnss.judge.GpsJudge`, issue #26): the stream's window of
       fixes against the steps, its accuracy and signal, the filter's NIS; until it says the stream
       is usable no fix reaches the filter (anchoring aside) and the fused position moves by the
       pipeline's own steps (the track is the dead-reckoned one);
    3b. the receiver's own signal quality where the recording carries it (the ``gnss_status``
       stream: Android ``GnssStatus`` or NMEA GSA/GSV): the rule of Kubrak et al. -- a fix whose
       4th-strongest satellite in use is below ``min_cn0_4th_dbhz`` (25 dB-Hz), or with fewer than
       4 satellites in use, is not used;
    4. the filter's own verdict (the subclass: the bad-GPS detector of Kubrak et al.);
    5. the first good fix anchors the walk (unless a known ``start`` was given): the local frame
       keeps its origin at the walk's start, whose latitude/longitude follow from the fix and the
       dead-reckoned position at that moment;
    6. the filter's position update, with a chi-square gate on its normalised innovation (NIS):
       a fix that disagrees with the track beyond what both uncertainties allow is rejected;
       fixes that keep being rejected but agree among themselves for ``relock_s`` are taken,
       with the covariance widened (after a long outage the track is more likely off than a
       steady GPS); fixes the judge found consistent with the walker's motion all along, with
       no jump away from a track that was right, re-lock the position onto them (:meth:`FixFusion._relock`);
    7. the subclass's extra use of an accepted fix (course, velocity, training).

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

History (issue #30)
    A batch run keeps every fused step and fix record in lists (``keep_history=True``, the default:
    the exports, the fixes file, the plots, the benchmarks read them).  A live app walking all day
    gives ``keep_history=False``: :attr:`FixFusion.steps` and :attr:`FixFusion.fixes` are then
    :class:`core.export.RecordFile` s (written to a temporary file in ``history_dir`` as they come,
    the last :data:`HISTORY_KEEP_LAST` in memory, read back for the exports), and the event lists
    (relocks, the subclass's) keep the last :data:`EVENTS_KEEP_LAST`; the algorithms only ever use
    their own windows, so both give the same track.

State
    Settings are the constructor's keywords; everything a run changes is one :class:`FixFusionState` (its outputs,
    the judge, and three groups: :class:`FixScreening`, what the fix handling remembers of its streams;
    :class:`RelockMemory`, the outage and relock bookkeeping; :class:`FixCounts`), made afresh by ``reset()``
    with the subclass's own (:class:`core.gnss.fusion.ChenFusionState`, :class:`core.gnss.kubrak.KubrakFusionState`)
    and its filter; other code reads it through read-only properties (``origin_lat_lon``, ``fixes``, ``n_gated``, ...).

Everything is in the walk's local ENU frame of :mod:`core` (metres about the
start point); latitude/longitude only at the edges (fix input, FusedStep
output, exports) through :mod:`core.geodesy`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from core.conventions import wrap_angle
from core.geodesy import enu_to_geodetic, geodetic_to_enu
from core.gnss.accuracy import HACC_PER_SIGMA  # the one reported-accuracy-to-SD ratio (also imported from here)
from core.gnss.ekf import UpdateResult, sigma_max_m
from core.gnss.judge import Cause, GpsJudge, GpsVerdict, JudgeSettings

#: fused steps and fix records a fusion without history keeps in memory (the rest are on disk)
HISTORY_KEEP_LAST = 64
#: events (relocks, variability detections, training windows) a fusion without history keeps in memory
EVENTS_KEEP_LAST = 8


#: the judge's causes that hold a fix back without saying anything against the stream's quality: a fix judged out
#: for these alone (and none other since the last usable verdict) still teaches once the judge's passing windows
#: cover it (:meth:`FixFusion._learn_pending`)
_HELD_BACK_ONLY = frozenset({Cause.FEW_FIXES, Cause.SETTLING, Cause.NO_EVIDENCE, Cause.INCONSISTENT})


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
    #: the first accepted fix came through a relock (the filter had refused the stream: its jump is no
    #: consistent update, and ``jump_m / sigma_m`` measures how far off the track was, not the filter's noise)
    relocked: bool = False
    sigma_at_rejoin_m: float = math.nan  #: position uncertainty just before that first accepted fix

    def as_dict(self) -> dict:
        return {"start_s": self.start_s, "length_s": self.length_s, "walked_m": self.walked_m,
                "end_error_m": self.end_error_m, "end_error_pct": self.end_error_pct, "sigma_m": self.sigma_m,
                "jump_m": self.jump_m, "jump_over_3sigma": bool(self.jump_m > 3.0 * self.sigma_m),
                "fix_accepted": self.fix_accepted, "rejoin_s": self.rejoin_s, "relocked": self.relocked,
                "sigma_at_rejoin_m": self.sigma_at_rejoin_m}


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


@dataclass(slots=True)
class FixCounts:
    """How the fixes went and what GPS did to the track (:meth:`FixFusion.counters`); read from outside through
    :class:`FixFusion`'s ``n_*``, ``fused_walked_m`` and ``moves``."""

    accepted: int = 0  #: ``n_fixes_accepted``
    hidden: int = 0  #: ``n_fixes_hidden``: inside a hidden window
    screened_out: int = 0  #: ``n_screened_out``: by the screening, the C/N0 rule or the anchor's wait
    cn0: int = 0  #: ``n_cn0``: by Kubrak et al.'s C/N0 rule
    judged_out: int = 0  #: ``n_judged_out``: held back by the usability judge
    filter_rejected: int = 0  #: ``n_filter_rejected``: the subclass filter's own verdict
    gated: int = 0  #: ``n_gated``: refused by the position update's gate
    relocked: int = 0  #: ``n_relocked``: taken by a relock
    nis_sum: float = 0.0  #: the accepted updates' NIS, summed (``position_nis_mean``)
    nis_n: int = 0
    fused_walked_m: float = 0.0  #: distance of the fused steps a fix was accepted shortly before (m)
    #: how far GPS moved the fused position, by kind of event (:meth:`FixFusion._count_move`)
    moves: dict = field(default_factory=dict)
    first_move: dict | None = None  #: the first such event
    largest_move: dict | None = None  #: the largest


@dataclass(slots=True)
class FixScreening:
    """What the fix handling remembers of its input streams between events."""

    queue: deque  #: fixes waiting for the first step after them: (t_ns, values)
    last_step_ns: int | None  #: the last step's time (None before any)
    last_step_dur_ns: int  #: its duration
    t_first_ns: int | None  #: the first sensor event's time (:meth:`FixFusion.set_time_zero`)
    status: tuple | None  #: the last ``gnss_status``: (t_ns, n_used, cn0_4th_dbhz)
    headings: deque  #: (t_ns, step heading unwrapped) of the last few seconds (:meth:`FixFusion.course_now`)
    pdr: deque  #: (t_ns, east, north) of the pipeline's dead-reckoned steps, the last few seconds
    anchor_waits: int  #: screened fixes too coarse to anchor the walk so far
    pending_learning: list  #: fixes the judge has not judged yet, for training once it has
    quality_failed: bool  #: the judge failed on the stream's quality since its last usable verdict

    @classmethod
    def initial(cls) -> FixScreening:
        return cls(queue=deque(), last_step_ns=None, last_step_dur_ns=int(0.55e9), t_first_ns=None, status=None,
                   headings=deque(), pdr=deque(), anchor_waits=0, pending_learning=[], quality_failed=False)


@dataclass(slots=True)
class RelockMemory:
    """The outage and relock bookkeeping: what the filter last took, the gated run, the hidden windows."""

    last_accept_ns: int | None  #: the filter's last accepted fix
    first_inconsistent_ns: int | None  #: the judge's first inconsistent window since then
    memory_ended_by_lock: bool  #: the last :meth:`FixFusion._stream_jumped` said no jump because the lock held
    walked_since_accept_m: float  #: distance the filter walked since its last accepted fix (m)
    rejected_run: deque  #: the gated fixes since the last accepted one: (t_ns, innovation E, N)
    windows: list  #: the hidden windows (:class:`_Window`), as they are measured

    @classmethod
    def initial(cls, hidden_ns) -> RelockMemory:
        return cls(last_accept_ns=None, first_inconsistent_ns=None, memory_ended_by_lock=False,
                   walked_since_accept_m=0.0, rejected_run=deque(), windows=[_Window(a, b) for a, b in hidden_ns])


@dataclass(slots=True)
class FixFusionState:
    """Everything :class:`FixFusion` changes as steps and fixes come (the subclass's filter apart), made by
    :meth:`initial` in :meth:`FixFusion.reset`; its outputs are read through :class:`FixFusion`'s read-only
    properties of the same names (``origin_lat_lon``, ``anchor``, ``fixes``, ``steps``, ``outages``, ``relocks``,
    ``judge``)."""

    origin_lat_lon: tuple | None  #: the walk's start (lat_deg, lon_deg); None before it is anchored
    #: the fix that anchored the walk (or the first used, after a known start): (t_ns, lat, lon, alt); None before
    anchor: tuple | None
    fixes: list  #: every fix's :class:`FixRecord` (a list, or a record file without ``keep_history``)
    steps: list  #: every :class:`FusedStep` (the same)
    outages: list  #: the hidden windows' :class:`OutageResult`
    relocks: list  #: when the filter re-locked to GPS, by how far, by which rule (the last few without history)
    judge: GpsJudge | None  #: the usability judge (None: none)
    screen: FixScreening
    lock: RelockMemory
    counts: FixCounts

    @classmethod
    def initial(cls, *, fixes, steps, relocks, judge, start, hidden_ns) -> FixFusionState:
        return cls(origin_lat_lon=(start[0], start[1]) if start is not None else None, anchor=None, fixes=fixes,
                   steps=steps, outages=[], relocks=relocks, judge=judge, screen=FixScreening.initial(),
                   lock=RelockMemory.initial(hidden_ns), counts=FixCounts())


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

    @classmethod
    def from_steps(cls, steps) -> "FusedTrack":
        """The arrays of fused steps (:class:`FusedStep`, any iterable: a list or a record file read back once)."""
        from array import array

        t, cols, source = array("q"), [array("d") for _ in range(5)], []
        for s in steps:
            t.append(s.t_ns)
            for c, v in zip(cols, (s.length_m, s.heading_rad, s.east_m, s.north_m, sigma_max_m(s.cov_en_m2))):
                c.append(v)
            source.append(s.source)
        return cls(np.array(t, dtype=np.int64), *(np.array(c, dtype=float) for c in cols), source)

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
        return FusedTrack.from_steps(self.steps)


#: a hidden fix's verdict (:class:`FixRecord` ``reason``)
HIDDEN = "hidden (outage)"

#: when the consistent-stream relock obeys the drift limit (:class:`FixFusion`'s ``relock_stream_drift_limit``)
RELOCK_STREAM_DRIFT_LIMITS = ("never", "known_start", "always")

#: a fix this accurate (reported 68 % radius, m) may place a walk on the map: the first one is the origin
ANCHOR_MAX_HACC_M = 12.0


def first_good_fix(gps, max_hacc_m: float = ANCHOR_MAX_HACC_M):
    """``(t_ns, lat_deg, lon_deg, alt_m)`` of the first fix of a ``gps`` stream with a finite position and a
    reported accuracy within ``max_hacc_m`` (the origin of a walk, as the fusion anchors it), or None.

    Not simply the first fix: phones start with fixes tens of metres off (on the IPIN walks the first is
    18 m inaccurate and 9.8 m off)."""
    if gps is None or not len(gps.t_ns):
        return None
    v = np.asarray(gps.values, dtype=float)
    ok = np.isfinite(v[:, 0]) & np.isfinite(v[:, 1]) & (v[:, 3] <= max_hacc_m)
    idx = np.flatnonzero(ok)
    if not len(idx):
        return None
    k = int(idx[0])
    return int(gps.t_ns[k]), float(v[k, 0]), float(v[k, 1]), float(v[k, 2])


class FixDecorrelation:
    """What a fix adds to the fixes the filter took before it, when their errors are correlated in time: the cheap
    form of a time-correlated fix error (issue #26).

    A phone's position error is not white: on IPIN's tuning routes the per-axis error of consecutive fixes
    correlates 0.99 at 1 s, 0.80 at 10 s, 0.54 at 30 s (see :mod:`core.gnss.ekf`, "Honest fixes"), a first-order
    Gauss-Markov process, ``rho(dt) = exp(-dt / tau)``.  A filter that takes each 1-Hz fix as independent
    believes the mean of ``n`` of them to ``sigma / sqrt(n)`` while they are off together: its covariance
    collapses and the track follows a biased stream.  For samples of such a process (per-axis SD ``sigma``) the
    best estimate of a constant from ``n`` fixes ``dt`` apart has the information (generalised least squares with
    the covariance ``sigma^2 rho^|i - j|``, whose inverse is tridiagonal)::

        1^T C^-1 1 = (1 + (n - 1) (1 - rho) / (1 + rho)) / sigma^2

    the first fix counts whole, every further one ``(1 - rho) / (1 + rho)`` of an independent fix: the new part of
    its error (``e_k - rho e_{k-1}``, white, variance ``sigma^2 (1 - rho^2)``) measures ``(1 - rho)`` of the
    position.  So a fix ``dt`` after the last one the filter used gets its variance multiplied by::

        s = (1 + rho) / (1 - rho),   rho = exp(-dt / tau)

    (``2 tau / dt`` for ``dt << tau``: one independent fix per ``2 tau``; 1 after a gap of several ``tau``).  This
    is the Kalman filter's weighting of that information for a position that stays put; for a walker it gives up
    what the fixes' differences say about the motion (the state-augmenting form that keeps it, a Gauss-Markov
    error state, is :class:`core.gnss.ekf.PdrEkf`'s ``fix_bias_share``, after Brown & Hwang, Chen et al. 2010's
    ref. [19], which the EKF of eq. 13 follows).

    ``tau_s`` 0: white fixes (the scale is 1).  State: the last used fix's time, set in :meth:`reset`;
    diagnostics as data: :meth:`summary`.
    """

    #: the largest variance factor (two fixes at one time: the second adds nothing)
    MAX_SCALE = 1e6

    def __init__(self, tau_s: float = 0.0):
        if not (tau_s >= 0.0 and math.isfinite(tau_s)):
            raise ValueError(f"tau_s must be finite and >= 0, got {tau_s!r}")
        self.tau_s = float(tau_s)
        self.reset()

    def reset(self) -> None:
        self._t_last_ns: int | None = None
        self.n_used = 0
        self._scale_sum = 0.0
        self.scale_max = 1.0

    def noise_scale(self, t_ns: int) -> float:
        """The factor on a fix's variance at ``t_ns`` (>= 1; 1 with ``tau_s`` 0 or before any fix was used)."""
        if self._t_last_ns is None or self.tau_s <= 0.0:
            return 1.0
        x = max(int(t_ns) - self._t_last_ns, 0) * 1e-9 / self.tau_s
        if x <= 0.0:
            return self.MAX_SCALE
        # (1 + rho) / (1 - rho) = coth(x / 2), written so that it stays exact for small x
        return min(1.0 + 2.0 / math.expm1(x), self.MAX_SCALE)

    def used(self, t_ns: int) -> None:
        """The filter took the fix at ``t_ns`` (its scale joins the diagnostics)."""
        t_ns = int(t_ns)
        scale = self.noise_scale(t_ns)
        self.n_used += 1
        self._scale_sum += scale
        self.scale_max = max(self.scale_max, scale)
        self._t_last_ns = t_ns if self._t_last_ns is None else max(t_ns, self._t_last_ns)

    def summary(self) -> dict:
        """``tau_s``, the fixes used, the mean and largest variance factor they were given."""
        return {"tau_s": self.tau_s, "fixes_used": self.n_used,
                "noise_scale_mean": self._scale_sum / self.n_used if self.n_used else math.nan,
                "noise_scale_max": self.scale_max}


def relock_heading_error_rad(offset_m: float, walked_m: float) -> float:
    """The heading error a relock showed: a track ``offset_m`` off after ``walked_m`` of dead reckoning since the
    last accepted fix turned by ``2 asin(offset / 2 walked)`` (pi when it walked less than half the offset)."""
    ratio = offset_m / (2.0 * walked_m) if walked_m > 0 else math.inf
    return 2.0 * math.asin(ratio) if ratio < 1.0 else math.pi


class FixFusion:
    """The fix handling both fusion filters share (see the module docstring); a subclass filters.

    Parameters (shared by both filters)
    -----------------------------------
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
    fused_timeout_s : float
        A step is "fused" when a fix was accepted within this time before it (s).
    hold_s : float
        Longest time a fix waits for the step after it (s).
    hidden_ns : sequence of (t_start_ns, t_end_ns)
        Windows whose fixes are hidden (simulated outages).
    relock_s : float
        Fixes rejected by the gate for this long, agreeing among themselves (their
        innovations' SD within twice a fix's SD), are taken (s).
    relock_max_drift : float or None
        If set, a relock also needs the disagreement to be one the track could have
        built up since the last fix it took: at most this share of the distance walked
        since then, plus three fix SDs (a steady multipath offset right after good
        fixes is not the track's error).  None: no such limit.
    relock_gated_s : float or None
        The "consistent stream" relock (:meth:`FixFusion._consistent_stream`) counts ``relock_s`` from the start of
        the judge's first passing window (the fixes agree with each other and the steps since then) and needs the
        gate to have refused fixes for only this long (s), so that it fires ``relock_s`` after good fixes return,
        whatever the judge's settling took.  None: the rule before (the gate refusing for ``relock_s`` after the
        judge's settling: 38-40 s after the fixes return, issue #26).
    relock_jump_hold_s : float
        A jump in the fix stream right after the filter's last accepted fix (a multipath episode) blocks the
        "consistent stream" relock for at most this long after the judge last saw it (s); a stream consistent
        that long afterwards is taken back (:meth:`FixFusion._stream_jumped`).
    relock_stream_drift_limit : {"never", "known_start", "always"}
        When the "consistent stream" relock obeys ``relock_max_drift`` too (:meth:`FixFusion._within_drift`): it
        moves the track onto the fix only if the fix's innovation is one dead reckoning can have built up since the
        filter's last accepted fix (or the start): ``relock_max_drift`` times the distance walked since then plus
        three SDs of the fix.  ``"known_start"``: on a walk with a known ``start`` (indoors: the user or the
        competition gives it); ``"always"`` (needs a ``relock_max_drift``: refused without one); ``"never"``: the rule before (the consistent stream whatever its
        offset; ``relock_max_drift`` for the "gated fixes agree" rule only).  Why (issue #26, indoors): the judge's
        tests are translation-free (the fixes' shape against the steps', among themselves), so an indoor stream
        25 m off that moves as the walker does passes them, and the relock then put the track on it whatever dead
        reckoning from the known start said (IPIN tuning T22r03 with the judge's pace check off, a proxy for an
        indoor receiver whose pace passes: one relock 28 s after the start, 25.6 m after 31 m walked, dead
        reckoning 1.1 m off: the landmark error 2.0 -> 16.5 m; with the limit 6.0 m).  Not ``"always"``: outdoors
        the relock is how a filter whose dead reckoning went wrong takes a good stream back (a phone turned 45 deg
        in the hand during an outage: 70 m off after 140 m walked; steps counted 0.4x or 2.4x), the issue's "never
        lose a consistent stream", and six tests of it fail with the limit there.
    anchor_max_hacc_m, anchor_max_waits : float, int
        The first fix used (the anchor) must report at most this accuracy (m), unless this
        many screened fixes came without one (then any fix within ``max_hacc_m`` anchors).
    start : (lat_deg, lon_deg, sd_m) or None
        A known start position (the user said where the walk starts, a competition gives it):
        the walk is placed there with this per-axis SD, and fixes only correct.
    min_cn0_4th_dbhz : float
        Kubrak et al.'s rule, applied where the recording has a ``gnss_status`` stream: fixes
        whose 4th-strongest satellite in use is weaker than this are not used (dB-Hz; 0 turns
        it off).
    status_max_age_s : float
        A ``gnss_status`` reading older than this does not describe a fix (s).
    judge : JudgeSettings or None
        The usability judge's settings (:mod:`core.gnss.judge`); None: no judge, every screened fix
        goes to the filter (the behaviour before issue #26).
    learn_held_back : bool
        Fixes the judge held back for too few fixes, settling, or a window that still held a jump (no failure of the
        stream's quality since its last usable verdict) train the stride and heading model once it finds the stream
        usable, from the first fix of its first passing window but none up to its last window that failed on its
        shape (a multipath episode's tail that a passing window's shape test fits) (issue #26).  Off: only the fixes
        of a stream never judged yet.  **Off by default** (the lead's review of h6/faults: the real TUNING walks, lopen and
        the IPIN routes, come out identical with it, so no real data shows a gain; the simulator's do), with the last-failing-window rule and the
        trainer's jump check (:meth:`core.gnss.training.OnlineTrainer._jump_m`), TUNING split: the simulator's fault
        walks (seeds 0-9, Chen) 2-minute outage after the noisy minute, median 10.71 -> 7.85 m (seeds 1 and 7
        11.3 / 23.0 -> 2.0 / 7.0 m; seed 4 12.8 -> 15.6 m), bad fixes 5 -> 5; gnss_eval's simulated 5-minute outages
        (seeds 0-19, ekf) median 2.02 -> 1.86 %, mean 2.20 -> 2.36 %; the guard's quick subset (seeds 0-2) 0.90 ->
        1.11 %.  Without the last-failing-window rule (b76360e, off then): 10.71 -> 8.48 m but 5-minute outages
        2.12 -> 2.25 % (seed 13 1.78 -> 7.78 %: the first passing window began with an episode's tail).
    pause_s : float
        A longer time between two steps is a pause (the step detector's ``max_step_interval_s``):
        the step after it spans its own duration; a shorter gap up to three durations is a missed
        step and its distance still counts (s).
    course_latency_s : float
        The GPS course lags the walking direction by this much (the receiver's smoothing): it is compared
        with our heading that long before the fix (:meth:`course_now`).  1.5 s: on the tuning walk
        ``thomasdingemanse_lopen`` the course scatters least about the step headings 1.5 s earlier
        (12.5 deg RMS, against 13.8 deg at no lag; lags from -1 to 4 s in 0.25-s steps).  0 turns it off.
    keep_history : bool
        Keep every fused step and fix record in memory (True: a batch run), or write them to disk as they
        come and keep the last few (False: a live app; see "History" in the module docstring).
    history_dir : str or None
        Where the files of ``keep_history=False`` go (None: the system's temporary folder); may be set
        until the first step or fix.
    """

    #: the filter's name (``make_fusion``, summaries)
    name = "fusion"

    def __init__(self, *, max_hacc_m: float = 25.0, default_hacc_m: float = 10.0, max_speed_m_s: float = 3.0,
                 hacc_scale: float = 1.0, min_sigma_m: float = 1.0, fused_timeout_s: float = 5.0,
                 hold_s: float = 3.0, hidden_ns=(), relock_s: float = 8.0, anchor_max_hacc_m: float = ANCHOR_MAX_HACC_M,
                 anchor_max_waits: int = 30, start: tuple | None = None, min_cn0_4th_dbhz: float = 25.0,
                 status_max_age_s: float = 2.0, relock_max_drift: float | None = None, relock_jump_hold_s: float = 60.0,
                 relock_gated_s: float | None = 5.0, relock_stream_drift_limit: str = "known_start",
                 pause_s: float = 1.5,
                 course_latency_s: float = 1.5, judge: JudgeSettings | None = JudgeSettings(),
                 keep_history: bool = True, history_dir: str | None = None, learn_held_back: bool = False):
        self.learn_held_back = bool(learn_held_back)
        self.max_hacc_m = float(max_hacc_m)
        self.default_hacc_m = float(default_hacc_m)
        self.max_speed_m_s = float(max_speed_m_s)
        self.hacc_scale = float(hacc_scale)
        self.min_sigma_m = float(min_sigma_m)
        self.fused_timeout_ns = int(fused_timeout_s * 1e9)
        self.hold_ns = int(hold_s * 1e9)
        self.relock_ns = int(relock_s * 1e9)
        self.relock_max_drift = None if relock_max_drift is None else float(relock_max_drift)
        self.relock_jump_hold_ns = int(relock_jump_hold_s * 1e9)
        self.relock_gated_ns = None if relock_gated_s is None else int(relock_gated_s * 1e9)
        if relock_stream_drift_limit not in RELOCK_STREAM_DRIFT_LIMITS:
            raise ValueError(f"relock_stream_drift_limit must be one of {RELOCK_STREAM_DRIFT_LIMITS}, "
                             f"got {relock_stream_drift_limit!r}")
        if relock_stream_drift_limit == "always" and self.relock_max_drift is None:
            raise ValueError('relock_stream_drift_limit="always" needs a relock_max_drift (a share of the distance '
                             'walked); without one there is no limit to obey')
        self.relock_stream_drift_limit = relock_stream_drift_limit
        self.anchor_max_hacc_m = float(anchor_max_hacc_m)
        self.anchor_max_waits = int(anchor_max_waits)
        self.hidden_ns = [(int(a), int(b)) for a, b in hidden_ns]
        if start is not None:
            lat, lon, sd = (float(v) for v in start)
            if not (math.isfinite(lat) and math.isfinite(lon) and -90.0 <= lat <= 90.0 and sd > 0):
                raise ValueError(f"start must be (lat_deg, lon_deg, sd_m) with a finite position and sd_m > 0, "
                                 f"got {start!r}")
            start = (lat, lon, sd)
        self.start = start
        self.min_cn0_4th_dbhz = float(min_cn0_4th_dbhz)
        self.status_max_age_ns = int(status_max_age_s * 1e9)
        self.pause_ns = int(pause_s * 1e9)
        self.course_latency_ns = int(course_latency_s * 1e9)
        self.judge_settings = judge
        self.keep_history = bool(keep_history)
        self.history_dir = history_dir

    @property
    def history_dir(self) -> str | None:
        """Where the files of ``keep_history=False`` go (None: the system's temporary folder)."""
        return self._history_dir

    @history_dir.setter
    def history_dir(self, directory: str | None) -> None:
        self._history_dir = directory
        for f in (getattr(self, "steps", None), getattr(self, "fixes", None)):
            if hasattr(f, "directory"):  # a record file opens at its first record: it goes there
                f.directory = directory

    def _history(self, kind):
        """A list (``keep_history``) or a record file of ``kind`` (:class:`core.export.RecordFile`)."""
        if self.keep_history:
            return []
        from core.export import RecordFile

        return RecordFile(kind, directory=self.history_dir, keep_last=HISTORY_KEEP_LAST)

    def _events(self):
        """A list for events (relocks, detections): every one (``keep_history``) or the last few."""
        return [] if self.keep_history else deque(maxlen=EVENTS_KEEP_LAST)

    def reset(self) -> None:
        """A new run: the whole :class:`FixFusionState` made afresh (the history files of the last closed), then the
        subclass's filter (:meth:`_reset_filter`)."""
        for old in (getattr(self, "fixes", None), getattr(self, "steps", None)):
            if hasattr(old, "close"):
                old.close()
        fixes, steps = self._history(FixRecord), self._history(FusedStep)
        judge = GpsJudge(self.judge_settings) if self.judge_settings is not None else None
        if judge is not None and self.start is not None:
            judge.known_start(self.start[2])
        self._state = FixFusionState.initial(fixes=fixes, steps=steps, relocks=self._events(), judge=judge,
                                             start=self.start, hidden_ns=self.hidden_ns)
        self._reset_filter()

    # -- read-only views of the state (it changes only through the fixes and steps; a new run: reset()) -----------
    origin_lat_lon = property(lambda self: self._state.origin_lat_lon,
                              doc="The walk's start (lat_deg, lon_deg); None before it is anchored.")
    anchor = property(lambda self: self._state.anchor,
                      doc="The fix that anchored the walk (or the first used, after a known start): (t_ns, lat, lon, "
                          "alt); None before.")
    fixes = property(lambda self: self._state.fixes, doc="Every fix's :class:`FixRecord` (a list, or a "
                                                         ":class:`core.export.RecordFile` without ``keep_history``).")
    steps = property(lambda self: self._state.steps, doc="Every :class:`FusedStep` (as ``fixes``).")
    outages = property(lambda self: self._state.outages, doc="The hidden windows' :class:`OutageResult`.")
    relocks = property(lambda self: self._state.relocks,
                       doc="When the filter re-locked to GPS, by how far, by which rule (the last few without "
                           "history).")
    judge = property(lambda self: self._state.judge, doc="The usability judge (None: built without one).")
    moves = property(lambda self: self._state.counts.moves,
                     doc="How far GPS moved the fused position, by kind of event (:meth:`gps_moves` gives a copy).")
    fused_walked_m = property(lambda self: self._state.counts.fused_walked_m,
                              doc="Distance of the fused steps a fix was accepted shortly before (m).")
    n_fixes_accepted = property(lambda self: self._state.counts.accepted)
    n_fixes_hidden = property(lambda self: self._state.counts.hidden)
    n_screened_out = property(lambda self: self._state.counts.screened_out)
    n_cn0 = property(lambda self: self._state.counts.cn0)
    n_judged_out = property(lambda self: self._state.counts.judged_out)
    n_filter_rejected = property(lambda self: self._state.counts.filter_rejected)
    n_gated = property(lambda self: self._state.counts.gated)
    n_relocked = property(lambda self: self._state.counts.relocked)
    last_step_ns = property(lambda self: self._state.screen.last_step_ns,
                            doc="The last step's time (None before any).")

    # -- the subclass's filter -----------------------------------------------------
    def _reset_filter(self) -> None:
        raise NotImplementedError

    @property
    def filt(self):
        """The Kalman filter (:class:`core.gnss.ekf.PdrEkf`, :class:`core.gnss.kubrak.KubrakKf`): ``x[0:2]`` is the
        position (E, N), ``P[:2, :2]`` its covariance, both read-only here; this class changes them only through the
        filter's ``set_position``, ``restart_position`` and ``widen_position``."""
        raise NotImplementedError

    def _init_filter_at(self, sigma_m: float) -> None:
        """Start the filter at (0, 0) with this position SD when a fix comes before any step."""
        raise NotImplementedError

    def _step(self, step, t_prev_ns: int, dur_ns: int) -> float:
        """One step through the filter; returns the distance it walked (m)."""
        raise NotImplementedError

    def _predict_fix(self, t_ns: int) -> np.ndarray:
        """The filter's position at a fix's time (E, N)."""
        raise NotImplementedError

    def _update_position(self, t_ns: int, east: float, north: float, sigma_m: float, gate: bool) -> UpdateResult:
        raise NotImplementedError

    def _filter_verdict(self, t_ns: int) -> str:
        """Why the filter will not use a screened fix now ("" to go on)."""
        return ""

    def _filter_rejected(self, t_ns: int, east: float, north: float, sigma_m: float, speed: float,
                         course: float) -> None:
        """A fix :meth:`_filter_verdict` turned away (local ENU, its per-axis SD): a subclass may still look at it."""

    def _after_accept(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        """An accepted fix's further use (course, velocity, training)."""

    def _placed_on_fix(self, t_ns: int, sigma_m: float, relock: bool = False) -> None:
        """The position was just put on the fix at ``t_ns`` (the anchor, or with ``relock`` a consistent-stream
        relock's restart) with per-axis SD ``sigma_m``: a filter that models the fixes' correlated error correlates
        the two (Chen's: :meth:`core.gnss.ekf.PdrEkf.place_on_fix`; Kubrak's on a relock:
        :meth:`core.gnss.kubrak.KubrakKf.place_on_fix`)."""

    def _step_output(self) -> tuple[float, float]:
        """(length_m, heading_rad) of the step just filtered, for the fused track."""
        raise NotImplementedError

    def _stride_scale_sd(self) -> float:
        """The filter's posterior SD (relative) of the stride scale it walks with (the drift check's
        ``scale_sd_from_filter``); nan: the subclass does not learn one."""
        return math.nan

    def _reported_cov(self) -> np.ndarray:
        """The covariance the fused track reports (its ``[:2, :2]``): the filter's ``P`` unless the subclass keeps
        one that models what its gain does not (Chen's: :attr:`core.gnss.ekf.PdrEkf.reported_cov`)."""
        return self.filt.P

    def _widen_position(self, offset_m) -> None:
        """A relock takes a gated fix with the position's covariance widened by ``offset_m`` (E, N) outer itself."""
        self.filt.widen_position(offset_m)

    # -- input ------------------------------------------------------------------------
    def add_fix(self, t_ns: int, values) -> None:
        """A GPS event (``values`` as the ``gps`` stream: lat, lon, alt, hacc, speed, course)."""
        queue = self._state.screen.queue
        queue.append((int(t_ns), tuple(float(v) for v in values)))
        last = self._state.screen.last_step_ns
        while queue and ((last is not None and queue[0][0] <= last) or queue[0][0] < int(t_ns) - self.hold_ns):
            self._fix(*queue.popleft())

    def add_status(self, t_ns: int, values) -> None:
        """A ``gnss_status`` event: satellites used, C/N0 of the 4th strongest (dB-Hz)."""
        n_used = float(values[0]) if len(values) > 0 else math.nan
        cn0 = float(values[1]) if len(values) > 1 else math.nan
        self._state.screen.status = (int(t_ns), n_used, cn0)

    def _step_times(self, step) -> tuple[int, int]:
        """(start of the step's interval, its duration) in ns."""
        prev = self._state.screen.last_step_ns
        d = step.features.duration_s
        dur = int(d * 1e9) if d == d else self._state.screen.last_step_dur_ns
        if prev is None or step.t_ns - prev > self.pause_ns:
            # the first step, or the first after a pause: its own duration (issue #26: it covered three)
            return step.t_ns - dur, dur
        # a missed step (up to two more durations) still counts its distance
        return max(prev, step.t_ns - 3 * dur), dur

    def _remember_heading(self, t_ns: int, heading_rad: float) -> None:
        if not math.isfinite(heading_rad):
            return
        h = self._state.screen.headings
        if h:
            heading_rad = h[-1][1] + wrap_angle(heading_rad - h[-1][1])  # unwrapped
        h.append((int(t_ns), float(heading_rad)))
        while len(h) > 2 and h[1][0] < t_ns - 2 * self.course_latency_ns - int(3e9):
            h.popleft()

    def course_now(self, t_ns: int, course_rad: float) -> float:
        """A GPS course at fix time ``t_ns`` (rad, CCW from East) as a measurement of the heading of the last
        step: the course describes the walking direction ``course_latency_s`` earlier (the receiver's
        smoothing), so the turn our steps made since then is added."""
        h = self._state.screen.headings
        if not h or self.course_latency_ns <= 0 or not math.isfinite(course_rad):
            return course_rad
        t = np.array([x[0] for x in h], dtype=np.int64)
        v = np.array([x[1] for x in h])
        then = float(np.interp(t_ns - self.course_latency_ns, t, v))
        return wrap_angle(course_rad + v[-1] - then)

    def _before_fixes(self, step, t_prev_ns: int) -> None:
        """Called with each step before the fixes inside its interval are processed."""

    @property
    def trusting_gps(self) -> bool:
        """Whether the judge lets fixes into the filter now (always, without a judge)."""
        return self.judge is None or self.judge.verdict is GpsVerdict.USABLE

    def _pdr_at(self, t_ns: int) -> tuple[float, float]:
        """The pipeline's dead-reckoned position at ``t_ns`` (between the steps around it; nan before any)."""
        p = self._state.screen.pdr
        if not p:
            return math.nan, math.nan
        t = np.array([x[0] for x in p], dtype=np.int64)
        return (float(np.interp(t_ns, t, [x[1] for x in p])), float(np.interp(t_ns, t, [x[2] for x in p])))

    def _dead_reckon(self, step, t_prev_ns: int, dur_ns: int) -> float:
        """A step while GPS is not trusted: the filter runs (its covariance grows), but the position moves by the
        step itself -- the pipeline's length and heading, with what good GPS taught before, if any -- so that
        the fused track is the dead-reckoned one (Chen's EKF and Kubrak's velocity model would otherwise make
        a track of their own: on IPIN T21r02, without a single fix, Chen's 7.0 m against dead reckoning's 3.0)."""
        filt = self.filt
        e0, n0 = (float(filt.x[0]), float(filt.x[1])) if filt.initialized else (0.0, 0.0)
        self._step(step, t_prev_ns, dur_ns)
        length, heading = self._dead_reckoned_step(step)
        if not (math.isfinite(length) and math.isfinite(heading)):
            return 0.0
        filt.set_position(e0 + length * math.cos(heading), n0 + length * math.sin(heading))
        return length

    def _dead_reckoned_step(self, step) -> tuple[float, float]:
        """(length_m, heading_rad) of a step while GPS is not trusted; the subclass's output follows them."""
        raise NotImplementedError

    def add_step(self, step) -> FusedStep:
        """A completed :class:`core.pdr.pipeline.Step`; returns its fused counterpart."""
        state = self._state
        t_prev, dur = self._step_times(step)
        self._before_fixes(step, t_prev)
        pdr = state.screen.pdr
        pdr.append((int(step.t_ns), float(step.east_m), float(step.north_m)))
        while len(pdr) > 2 and pdr[1][0] < step.t_ns - self.hold_ns - int(5e9):
            pdr.popleft()
        while state.screen.queue and state.screen.queue[0][0] <= step.t_ns:
            self._fix(*state.screen.queue.popleft())
        if self.trusting_gps:
            walked = self._step(step, t_prev, dur)
        else:
            walked = self._dead_reckon(step, t_prev, dur)
        self._remember_heading(step.t_ns, step.heading_rad)
        if self.judge is not None:  # the drift check's dead reckoning: the step as this filter walked it
            self.judge.add_step(step.t_ns, *self._step_output(), self._stride_scale_sd())
        state.lock.walked_since_accept_m += walked
        state.screen.last_step_ns = step.t_ns
        state.screen.last_step_dur_ns = dur
        for w in state.lock.windows:
            if w.start_ns <= step.t_ns < w.end_ns:
                w.walked_m += walked
        fused = self._emit(step.index, step.t_ns)
        self.steps.append(fused)
        if fused.source == "fused":
            state.counts.fused_walked_m += fused.length_m
        return fused

    def finish(self) -> None:
        state = self._state
        while state.screen.queue:
            self._fix(*state.screen.queue.popleft())
        for w in state.lock.windows:
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

    def _cn0_verdict(self, t_ns: int) -> str:
        """Kubrak et al.'s C/N0 rule on the receiver status of this fix ("" when none or when it passes)."""
        st = self._state.screen.status
        if st is None or self.min_cn0_4th_dbhz <= 0 or abs(t_ns - st[0]) > self.status_max_age_ns:
            return ""
        n_used, cn0 = st[1], st[2]
        if n_used == n_used and n_used < 4:
            return f"{n_used:.0f} satellites in use (< 4)"
        if cn0 == cn0 and cn0 < self.min_cn0_4th_dbhz:
            return f"C/N0 of the 4th satellite {cn0:.0f} dB-Hz < {self.min_cn0_4th_dbhz:.0f}"
        return ""

    def _record(self, t_ns, v, east, north, accepted, reason, nis=math.nan, moved=0.0) -> None:
        self._state.counts.accepted += bool(accepted)
        self._state.counts.hidden += reason == HIDDEN
        self.fixes.append(FixRecord(t_ns, v[0], v[1], east, north, v[3] if len(v) > 3 else math.nan,
                                    v[4] if len(v) > 4 else math.nan, v[5] if len(v) > 5 else math.nan,
                                    accepted, reason, nis, moved))

    def _fix(self, t_ns: int, v: tuple) -> None:
        state = self._state
        lat, lon = v[0], v[1]
        hacc = v[3] if len(v) > 3 else math.nan
        speed = v[4] if len(v) > 4 else math.nan
        course = v[5] if len(v) > 5 else math.nan
        nan = math.nan
        hacc_eff = hacc if hacc > 0 else self.default_hacc_m
        if self._hidden(t_ns):
            self._record(t_ns, v, nan, nan, False, HIDDEN)
            return
        reason = self._screen(t_ns, lat, lon, hacc, speed)
        judged = None
        if not reason:
            reason = self._cn0_verdict(t_ns)
            state.counts.cn0 += bool(reason)
            if self.judge is not None:
                st = state.screen.status
                fresh = st is not None and self.min_cn0_4th_dbhz > 0 and abs(t_ns - st[0]) <= self.status_max_age_ns
                sats = st[1] if st is not None and abs(t_ns - st[0]) <= self.status_max_age_ns else math.nan
                judged = self.judge.add_fix(t_ns, lat, lon, hacc_eff, self._pdr_at(t_ns), (not reason) if fresh else None,
                                            speed, sats)
                if self.judge.last_inconsistent_ns == t_ns and state.lock.first_inconsistent_ns is None:
                    state.lock.first_inconsistent_ns = int(t_ns)
        elif self.judge is not None and reason != "no position":
            self.judge.add_screened_out(t_ns)  # too coarse or too fast: the stream is bad, not merely absent
        if reason:
            state.counts.screened_out += 1
            self._record(t_ns, v, nan, nan, False, reason)
            return
        filt = self.filt
        sigma = max(hacc_eff * self.hacc_scale / HACC_PER_SIGMA, self.min_sigma_m)
        if self.origin_lat_lon is None and hacc_eff > self.anchor_max_hacc_m and \
                state.screen.anchor_waits < self.anchor_max_waits:
            # a phone's first fixes are often coarse (the ETH walk's first three are 65 m off): wait for a good one
            state.screen.anchor_waits += 1
            state.counts.screened_out += 1
            self._record(t_ns, v, nan, nan, False, f"waiting for a first fix within {self.anchor_max_hacc_m:.0f} m")
            return
        if self.origin_lat_lon is None:
            # anchor: the walk's start lies where dead reckoning says, seen from this fix
            e0, n0 = (float(filt.x[0]), float(filt.x[1])) if filt.initialized else (0.0, 0.0)
            lat0, lon0 = enu_to_geodetic(-e0, -n0, (lat, lon))
            state.origin_lat_lon = (float(lat0), float(lon0))
            state.anchor = (int(t_ns), float(lat), float(lon), float(v[2]) if len(v) > 2 else math.nan)
            if not filt.initialized:
                self._init_filter_at(sigma)
                filt = self.filt
            filt.restart_position(None, sigma)  # where it is: its correlations dropped, the fix's SD
            self._placed_on_fix(t_ns, sigma)
            self._accepted(t_ns, v, e0, n0, hacc, speed, course, nan, 0.0)
            return
        if not filt.initialized:  # a known start, and a fix before the first step
            self._init_filter_at(self.start[2] if self.start is not None else sigma)
            filt = self.filt
        east, north = geodetic_to_enu(lat, lon, self.origin_lat_lon)
        pred = self._predict_fix(t_ns)
        self._outage_end(t_ns, east, north, pred, filt.position_sigma_m())
        if judged is not None and judged.verdict is not GpsVerdict.USABLE:
            if not self.learn_held_back:
                if judged.verdict is GpsVerdict.UNKNOWN:
                    # not yet judged (too few fixes, settling): what it teaches waits for the verdict
                    state.screen.pending_learning.append((t_ns, east, north, hacc_eff, speed, course))
                else:
                    state.screen.pending_learning.clear()
            elif not set(judged.causes) <= _HELD_BACK_ONLY:
                # the stream's own quality failed (accuracy, signal, pace, drift, NIS): nothing held back since the
                # last usable verdict teaches (on the real tuning walk a cold start's converging fixes, 12-19 m
                # reported, then 10 s settling, taught a wrong stride: Chen's leave-out ratio 0.43 -> 0.59)
                state.screen.quality_failed = True
                state.screen.pending_learning.clear()
            elif not state.screen.quality_failed:
                # held back (too few fixes, settling, or a window that still holds a jump): what it teaches waits
                # for the verdict.  Kept while a window that first passes could still cover it: since the first
                # fix of the passing windows, or within the last window while the judge fails (issue #26: clearing
                # them at an inconsistent window threw away the clean fixes after a multipath episode -- on the
                # simulator's tuning seeds 1 and 7 the good fixes before the noisy minute taught nothing)
                since = self.judge.consistent_since_ns
                keep = since if since is not None else t_ns - int(self.judge.settings.window_s * 1e9)
                state.screen.pending_learning = [p for p in state.screen.pending_learning if p[0] >= keep]
                state.screen.pending_learning.append((t_ns, east, north, hacc_eff, speed, course))
            state.counts.judged_out += 1
            self._record(t_ns, v, east, north, False,
                         f"GPS judged {judged.verdict.value}: " + "; ".join(c.value for c in judged.causes))
            return
        state.screen.quality_failed = False
        if state.screen.pending_learning:
            self._learn_pending()
        reason = self._filter_verdict(t_ns)
        if reason:
            state.counts.filter_rejected += 1
            self._record(t_ns, v, east, north, False, reason)
            self._filter_rejected(t_ns, east, north, sigma, speed, course)
            return
        res = self._update_position(t_ns, east, north, sigma, True)
        relocked = False
        if not res.accepted and self._relock(t_ns, res.innovation, sigma):
            # the track, not the GPS, is wrong: take the fix with the position uncertainty widened by
            # the disagreement (so its NIS is acceptable) instead of rejecting GPS for ever
            d = np.array(res.innovation)
            if self.relocks[-1]["rule"] == "consistent stream":
                # a stream consistent with the walker's motion all along: the position restarts on the fix,
                # its correlations with the rest dropped (widening it by the disagreement let the next fixes
                # pull the heading through them: on the tuning walk the track then ran 40-150 m off again)
                filt.restart_position(d, sigma)
                self._placed_on_fix(t_ns, sigma, relock=True)
                res = UpdateResult(True, res.innovation, math.nan, float(np.hypot(*d)), res.sigma_before_m)
            else:
                self._widen_position(d)
                res = self._update_position(t_ns, east, north, sigma, False)
            state.counts.relocked += 1
            relocked = True
            self._after_relock(float(np.hypot(*d)), state.lock.walked_since_accept_m)
        if not res.accepted:
            state.counts.gated += 1
            self._record(t_ns, v, east, north, False, res.reason, res.nis)
            return
        state.lock.rejected_run.clear()
        if res.nis == res.nis:
            state.counts.nis_sum += res.nis
            state.counts.nis_n += 1
            if self.judge is not None:
                self.judge.add_nis(res.nis)
        self._outage_jump(t_ns, res.correction_m, relocked, res.sigma_before_m)
        self._count_move(f"relock ({self.relocks[-1]['rule']})" if relocked else "update", t_ns, res.correction_m,
                         res.sigma_before_m)
        if self.anchor is None:
            state.anchor = (int(t_ns), float(lat), float(lon), float(v[2]) if len(v) > 2 else math.nan)
        self._accepted(t_ns, v, east, north, hacc, speed, course, res.nis, res.correction_m)

    def _relock(self, t_ns: int, innovation, sigma_m: float) -> bool:
        """Consecutive gated fixes that agree among themselves for ``relock_s``: the track is off, not GPS.

        With a judge, gated fixes for ``relock_s`` that it found usable all along, with no jump in the stream away
        from a track that was right (:meth:`_stream_jumped`: the track drifted away from the fixes, not the fixes
        from it), are taken back, whatever the covariance says (issue #26: on one phone walk 270 of 545 fixes
        that formed a smooth path were rejected).  Otherwise they must agree among themselves for ``relock_s``
        and, with ``relock_max_drift``, by no more than the track can have drifted.
        """
        run = self._state.lock.rejected_run
        run.append((t_ns, innovation[0], innovation[1]))
        while run and run[0][0] < t_ns - 2 * self.relock_ns:
            run.popleft()
        if self._consistent_stream(t_ns, run[0][0]) and \
                (not self._stream_drift_limited() or self._within_drift(math.hypot(*innovation[:2]), sigma_m)):
            # gated, and judged consistent, for relock_s (where ``relock_stream_drift_limit`` applies: no further off
            # than dead reckoning can have drifted)
            self.relocks.append({"t_ns": int(t_ns), "offset_m": float(math.hypot(innovation[0], innovation[1])),
                                 "rule": "consistent stream", "consistent_s": self._consistent_s(t_ns),
                                 "gated_s": (t_ns - run[0][0]) * 1e-9,
                                 # usable by the judge's stream lock (``JudgeSettings.lock_window_s``): what it overrode
                                 "stream_lock": [c.value for c in self.judge.last.locked_over],
                                 # the jump memory would still hold it back, but the stream lock held over a whole
                                 # window since its last inconsistent one (``JudgeSettings.lock_ends_jump_memory``)
                                 "jump_memory_ended_by_lock": self._state.lock.memory_ended_by_lock})
            run.clear()
            return True
        if len(run) < 3 or t_ns - run[0][0] < self.relock_ns:
            return False
        d = np.array([(r[1], r[2]) for r in run])
        if float(np.max(np.std(d, axis=0))) > 2.0 * sigma_m:
            return False  # they disagree with each other too: bad GPS, keep rejecting
        if not self._within_drift(float(np.hypot(*np.mean(d, axis=0))), sigma_m):
            return False  # more than the track can have drifted since its last fix: a steady multipath
        self.relocks.append({"t_ns": int(t_ns), "offset_m": float(np.hypot(*np.mean(d, axis=0))),
                             "rule": "gated fixes agree", "consistent_s": (t_ns - run[0][0]) * 1e-9})
        run.clear()
        return True

    def _stream_drift_limited(self) -> bool:
        """Whether the consistent-stream relock obeys ``relock_max_drift`` (``relock_stream_drift_limit``)."""
        mode = self.relock_stream_drift_limit
        return mode == "always" or (mode == "known_start" and self.start is not None)

    def _within_drift(self, offset_m: float, sigma_m: float) -> bool:
        """Whether a relock's offset ``offset_m`` (m) is one the track can have drifted since the filter's last
        accepted fix (or its start): at most ``relock_max_drift`` times the distance walked since then plus three
        of the fix's per-axis SD ``sigma_m`` (always, with ``relock_max_drift`` None)."""
        return self.relock_max_drift is None or \
            offset_m <= self.relock_max_drift * self._state.lock.walked_since_accept_m + 3.0 * sigma_m

    def _consistent_stream(self, t_ns: int, gated_since_ns: int, last_accept_ns: int | None = None) -> bool:
        """The "consistent stream" relock rule: the judge finds the stream usable, with no jump away from a track
        that was right (:meth:`_stream_jumped`, against the filter's last accepted fix or ``last_accept_ns``), the
        fixes have agreed with each other and the steps for ``relock_s`` (:attr:`GpsJudge.consistent_since_ns`)
        and the gate has refused them since ``gated_since_ns`` for ``relock_gated_s`` (with ``relock_gated_s``
        None: for ``relock_s`` of fixes gated after the judge's passing began)."""
        j = self.judge
        if j is None or j.verdict is not GpsVerdict.USABLE or j.passing_since_ns is None or \
                self._stream_jumped(t_ns, last_accept_ns):
            return False
        if self.relock_gated_ns is None:
            return t_ns - max(j.passing_since_ns, gated_since_ns) >= self.relock_ns
        return t_ns - j.consistent_since_ns >= self.relock_ns and t_ns - gated_since_ns >= self.relock_gated_ns

    def _consistent_s(self, t_ns: int) -> float:
        """How long (s) the judge has found the stream consistent at ``t_ns`` (the relock events' ``consistent_s``)."""
        j = self.judge
        since = j.passing_since_ns if self.relock_gated_ns is None else j.consistent_since_ns
        return (t_ns - since) * 1e-9

    def _stream_jumped(self, t_ns: int, last_accept_ns: int | None = None) -> bool:
        """Whether the fixes jumped away from a track that was right: the judge's first inconsistent window after
        the last accepted fix came while that fix was recent (within the judge's window plus ``relock_s``: the
        time a jump stays in the window, and the time the relock waits anyway), and its last inconsistent window
        less than ``relock_jump_hold_s`` ago.  A stream that turns inconsistent long after the last accepted fix
        says nothing of where the track is (it has drifted since), and a stream consistent for
        ``relock_jump_hold_s`` after its jump is taken back whatever it jumped from (before: blocked until another
        fix was accepted, which the gate could refuse for ever: on one phone walk 837 s of good fixes)."""
        last, first = self.judge.last_inconsistent_ns, self._state.lock.first_inconsistent_ns
        self._state.lock.memory_ended_by_lock = False
        if last is None or first is None or t_ns - last >= self.relock_jump_hold_ns:
            return False
        if self.judge.lock_holds_since(last, first):  # the stream lock's whole window since: no jump (``lock_ends_jump_memory``)
            self._state.lock.memory_ended_by_lock = True
            return False
        accept = self._state.lock.last_accept_ns if last_accept_ns is None else last_accept_ns
        if accept is None:
            return True
        return first - accept <= int(self.judge.settings.window_s * 1e9) + self.relock_ns

    def _learn_pending(self) -> None:
        """The judge has just found the stream usable: the fixes it held back while it had too few to judge, or
        while they settled, and that its passing windows covered, teach the subclass (:meth:`_learn_from_fix`) in
        time order.  Without this a walk's first 15-20 s of good GPS taught nothing (a straight 140-m walk
        then learnt too little stride for the profile: 79 m of the 100 m needed)."""
        j = self.judge
        pending, self._state.screen.pending_learning = self._state.screen.pending_learning, []
        if j is None or j.passing_since_ns is None:
            return
        # the first fix of the window that first passed (``learn_held_back``), or that window's start
        first = j.consistent_since_ns if self.learn_held_back else j.passing_since_ns - int(j.settings.window_s * 1e9)
        if self.learn_held_back and j.last_inconsistent_ns is not None:
            # not the fixes of a window that failed on its shape: the first passing window may still begin with the
            # tail of a multipath episode whose constant offset its shape test fits (gnss_eval's simulated walk,
            # tuning seed 13: those fixes taught a stride sample of 1.43 against 1.10 and the 5-minute outage ended
            # 8.4 % off instead of 2.0 %; from the last failing window on: 2.2 %)
            first = max(first, j.last_inconsistent_ns + 1)
        for t, e, n, h, sp, c in pending:
            if t >= first:
                self._learn_from_fix(t, e, n, h, sp, c)

    def _learn_from_fix(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        """A good fix's use for training (stride, heading model): with every accepted fix, and with the fixes the
        judge held back before it found the stream usable (:meth:`_learn_pending`)."""

    def _accepted(self, t_ns, v, east, north, hacc, speed, course, nis, moved) -> None:
        if self.judge is not None:
            self.judge.fix_used(t_ns)
        self._state.lock.last_accept_ns = t_ns
        self._state.lock.first_inconsistent_ns = None
        self._state.lock.walked_since_accept_m = 0.0
        self._record(t_ns, v, east, north, True, "", nis, moved)
        self._after_accept(t_ns, east, north, hacc if hacc > 0 else self.default_hacc_m, speed, course)

    def _outage_end(self, t_ns, east, north, pred, sigma) -> None:
        """The first screened fix after a hidden window: the error before the update."""
        for w in self._state.lock.windows:
            if w.end_error_m is None and t_ns >= w.end_ns:
                w.end_error_m = math.hypot(east - pred[0], north - pred[1])
                w.sigma_m = sigma
                w.fix_t_ns = t_ns

    def _outage_jump(self, t_ns, moved, relocked: bool = False, sigma_before_m: float = math.nan) -> None:
        """... and the jump at the first fix after it that the filter accepts (the track rejoining GPS), saying
        whether that fix came through a relock."""
        for w in self._state.lock.windows:
            if w.fix_t_ns is not None and not w.done:
                self._close_window(w, moved, t_ns, relocked, sigma_before_m)

    def _count_move(self, kind: str, t_ns: int, moved_m: float, sigma_before_m: float = math.nan) -> None:
        """GPS moved the fused position by ``moved_m`` at ``t_ns`` through an event of ``kind`` ("update": a fix the
        gate took; "relock (consistent stream)", "relock (gated fixes agree)": :meth:`_relock`; a subclass's own, e.g.
        Kubrak's "shadow adopted"), the position's SD before it ``sigma_before_m``: the per-kind count, sum and
        largest jump, and the first and the largest event (diagnostics as data, issue #26: on IPIN's tuning files
        every move is an ordinary update, the first at a sigma of 8-13 m)."""
        if not math.isfinite(moved_m):
            return
        m = self.moves.setdefault(kind, {"n": 0, "moved_m": 0.0, "max_m": 0.0})
        m["n"] += 1
        m["moved_m"] += float(moved_m)
        m["max_m"] = max(m["max_m"], float(moved_m))
        event = {"t_ns": int(t_ns), "kind": kind, "moved_m": float(moved_m), "sigma_before_m": float(sigma_before_m)}
        self._state.counts.first_move = self._state.counts.first_move or event
        if self._state.counts.largest_move is None or moved_m > self._state.counts.largest_move["moved_m"]:
            self._state.counts.largest_move = event

    def gps_moves(self) -> dict:
        """How far GPS moved the fused position (:meth:`_count_move`): ``{"by_kind": {kind: {n, moved_m, max_m}},
        "first": event, "largest": event}`` (an event: ``t_ns``, ``kind``, ``moved_m``, ``sigma_before_m``; None
        before any)."""
        return {"by_kind": {k: dict(v) for k, v in self.moves.items()}, "first": self._state.counts.first_move,
                "largest": self._state.counts.largest_move}

    def _after_relock(self, offset_m: float, walked_m: float) -> None:
        """A relock moved the position by ``offset_m`` after ``walked_m`` of walking since the last accepted
        fix: the filter's own uncertainty was wrong (the subclass may widen what caused it)."""

    def _close_window(self, w, jump_m: float, accept_t_ns: int | None, relocked: bool = False,
                      sigma_before_m: float = math.nan) -> None:
        w.done = True
        t0 = self._state.screen.t_first_ns if self._state.screen.t_first_ns is not None else 0
        pct = 100.0 * w.end_error_m / w.walked_m if w.walked_m > 0 else math.nan
        self.outages.append(OutageResult((w.start_ns - t0) * 1e-9, (w.end_ns - w.start_ns) * 1e-9, w.walked_m,
                                         w.end_error_m, pct, w.sigma_m, jump_m, w.fix_t_ns,
                                         accept_t_ns == w.fix_t_ns,
                                         (accept_t_ns - w.fix_t_ns) * 1e-9 if accept_t_ns is not None else math.nan,
                                         bool(relocked), float(sigma_before_m)))

    def set_time_zero(self, t0_ns: int) -> None:
        """The first sensor event's time, for outage start times in seconds."""
        self._state.screen.t_first_ns = int(t0_ns)

    # -- output ------------------------------------------------------------------------------
    def _emit(self, index: int, t_ns: int) -> FusedStep:
        filt = self.filt
        e, n = float(filt.x[0]), float(filt.x[1])
        lat = lon = math.nan
        if self.origin_lat_lon is not None:
            lat, lon = enu_to_geodetic(e, n, self.origin_lat_lon)
        last = self._state.lock.last_accept_ns
        fused = last is not None and t_ns - last <= self.fused_timeout_ns
        P = self._reported_cov()
        length, heading = self._step_output()
        return FusedStep(index, t_ns, e, n, float(lat), float(lon), float(length), float(heading),
                         (float(P[0, 0]), float(P[0, 1]), float(P[1, 1])), "fused" if fused else "dr")

    def status(self) -> dict:
        """Live position and uncertainty for the app (local ENU)."""
        filt = self.filt
        return {"east_m": float(filt.x[0]), "north_m": float(filt.x[1]),
                "sigma_m": sigma_max_m(tuple(self._reported_cov()[[0, 0, 1], [0, 1, 1]])) if filt.initialized
                else math.nan,
                "anchored": self.origin_lat_lon is not None, "filter": self.name}

    def counters(self) -> dict:
        counts = self._state.counts
        return {"fixes": len(self.fixes), "fixes_accepted": self.n_fixes_accepted,
                "fixes_screened_out": self.n_screened_out,
                "fixes_cn0": self.n_cn0, "fixes_filter_rejected": self.n_filter_rejected,
                "fixes_gated": self.n_gated, "fixes_relocked": self.n_relocked,
                "fixes_hidden": self.n_fixes_hidden,
                "position_nis_mean": counts.nis_sum / counts.nis_n if counts.nis_n else math.nan,
                "fixes_judged_out": self.n_judged_out, "relocks": list(self.relocks), "gps_moves": self.gps_moves(),
                "gps_judge": self.judge.summary() if self.judge is not None else None,
                "fusion": self.name}

    def run(self, steps, gps_stream=None, t0_ns: int | None = None, status_stream=None) -> FusionResult:
        """Batch: fuse a finished walk's steps (:class:`core.pdr.pipeline.Step`) with its ``gps`` stream.

        The same kernel as streaming: fixes and steps meet the filter in the order a
        live pipeline gives them (each fix before the first step after it), so
        ``Pipeline(gnss=F()).run(rec)`` and ``F().run(Pipeline().run(rec).steps,
        rec.streams["gps"])`` agree (a test checks it); this one is much faster for sweeps.
        ``status_stream`` is the recording's ``gnss_status`` stream, if any.
        """
        self.reset()
        if t0_ns is not None:
            self.set_time_zero(t0_ns)
        if gps_stream is not None and len(gps_stream):
            ft, fv = gps_stream.t_ns, gps_stream.values
        else:
            ft, fv = np.zeros(0, np.int64), np.zeros((0, 6))
        if status_stream is not None and len(status_stream):
            st, sv = status_stream.t_ns, status_stream.values
        else:
            st, sv = np.zeros(0, np.int64), np.zeros((0, 2))
        j = k = 0

        def fixes_until(t):
            nonlocal j, k
            while j < len(ft) and ft[j] <= t:
                while k < len(st) and st[k] <= ft[j]:  # a status at a fix's time comes before it (STREAM_ORDER)
                    self.add_status(int(st[k]), sv[k].tolist())
                    k += 1
                self.add_fix(int(ft[j]), fv[j].tolist())
                j += 1

        for s in steps:
            fixes_until(s.t_ns)
            self.add_step(s)
        fixes_until(np.iinfo(np.int64).max)
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
