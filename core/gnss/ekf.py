"""The PDR extended Kalman filter of Chen et al. (2010), eq. 13, with GPS updates.

State ``x = [E, N, l, psi, b, k, gE, gN]`` (``b, k`` are consider states, ``gE, gN`` the fixes' correlated
error, below; beside ``P`` the filter keeps ``C``, the covariance it reports, below): East and North position
(m, the walk's local ENU frame), step length (m) and walking heading (rad, counter-clockwise from
East as everywhere in :mod:`core`).  The paper writes eq. 13 with a compass
bearing ``a`` (clockwise from North)::

    E_{k+1} = E_k + l_k sin a_k,   N_{k+1} = N_k + l_k cos a_k,
    l_{k+1} = l_k + w_l,           a_{k+1} = a_k + w_a

which with ``psi = pi/2 - a`` is ``E += l cos psi, N += l sin psi``: the sign
of the heading's random walk and of every heading derivative changes with the
convention; the filter below is written in ours.

Per step (:meth:`PdrEkf.step`)
    1. the random walk of eq. 13 on ``l`` and ``psi``; the heading's process
       noise has, beside the paper's constant ``heading_walk_rad``, a term for
       the walker's own turn ``turn_gain * (psi_meas_k - psi_meas_{k-1})`` --
       without it a filter tuned for straight walking cuts every corner (a
       90-degree turn with a per-step walk of 2 deg and a 4-deg measurement
       lags by about 5 steps, ~3 m of track); not in the paper;
    2. the measurement update with the step's length from the stride model and
       its heading compensated by the unified error model (eq. 12), the
       paper's "measurement vector" -- of ``l`` and ``psi`` only: the position
       rows get no gain (the step does not observe where the walker already
       is; through the consider states' cross terms it moved the position
       sideways at every turn of an outage);
    3. the position moves by eq. 13 with the updated ``l`` and ``psi``;
       ``F = d f / d x`` (a test checks it by finite differences).

GPS (:meth:`PdrEkf.update_position`, :meth:`PdrEkf.update_course`)
    A fix at time ``t`` between step ``k`` (at ``t_k``) and the next is
    compared with the position after step ``k`` plus the part of the next
    step already walked, ``f = (t - t_k) / T`` of it (``T`` the last step's
    duration, ``f`` clipped to [0, 1]: after a pause the walker stands one step on)::

        h(x) = [E + f l cos psi,  N + f l sin psi]

    so that a 1 Hz fix is not compared with a position up to a step old.
    Updates pass a chi-square gate on their normalised innovation squared
    (NIS); rejected ones leave the state untouched and are returned as flags.
    The course of a moving receiver is a direct measurement of ``psi``.

Honest uncertainty: two consider states
    The paper's filter treats each step's heading error as white noise
    (``omega``).  It is not: what the error model has not learnt (a few
    degrees of offset, a harmonic not yet trusted) and the stride scale's
    residual error repeat at every step, so a white-noise filter's position
    uncertainty grows with the square root of the steps while the error grows
    with the steps -- after a 3-minute outage on the ETH walk it claimed
    1.3 m for an error of 50 m.  The state therefore carries two *consider*
    (Schmidt) states: ``b``, the bias of the compensated heading, and ``k``,
    the relative error of the step length, with ``z_psi = psi + b`` and
    ``z_l = l (1 + k)``.  They are never estimated here (their gain rows are
    zero: training their values is :mod:`core.gnss.training`'s job, from
    windows it can trust), but their variances -- set from the training's own
    uncertainty by :meth:`PdrEkf.set_consider_sd`, plus a slow random walk --
    make the position covariance grow with the distance walked, as the error
    does.

    The heading state is learnt from the step headings, ``z_psi = psi + b``: its error is minus the bias's
    (``psi = z - b``).  When :meth:`PdrEkf.set_consider_sd` widens ``b`` (a heading model not yet trained: a
    45-degree offset prior), the heading state is widened by the same variance, anti-correlated with ``b``
    (``heading_carries_bias``), so that ``psi + b`` stays as well known as the steps made it.  Before (issue
    #26, indoors), ``b`` alone was widened: the filter then held ``psi`` and ``b`` nearly independent, saw each
    step heading as a measurement of ``psi`` with the bias's 45 degrees of noise, and gave a turn a gain of
    about 0.05: the heading lagged every turn by 30 degrees for 20 steps, and on IPIN T21r02 without a single
    fix the EKF's track was 8.6 m off at the landmarks against the steps' own 2.1 m.

Honest fixes: their error is not white (issue #26)
    The paper (and its filter until issue #26) takes each fix's error as independent.  A phone's is
    not: its receiver smooths, and the satellite geometry, multipath and (indoors) the walls change
    slowly, so consecutive fixes are off by nearly the same vector.  On the IPIN tuning routes
    (01, 02, 22: 1.2 k fixes against the landmark path) the per-axis error over the reported SD
    (``hacc / 1.515``; :data:`core.gnss.accuracy.HACC_PER_SIGMA` is now 1.5096, a 0.35 % difference that does not
    move these statistics) has a mean square of 1.25, and its correlation between fixes ``dt`` apart is
    0.99 at 1 s, 0.80 at 10 s, 0.54 at 30 s, 0.17 at 60 s: a first-order Gauss-Markov process with a
    correlation time of about 45 s, nearly all of the error.  A filter that takes 1 Hz fixes as white
    averages 45 of them into a position it believes to ``sigma / 7`` while they are all off together:
    its covariance collapses and the track follows the fixes' common error (indoors 2-23 m for minutes).
    The fix's error is therefore split (Brown & Hwang, the paper's ref. [19]: a coloured measurement
    noise as a state): a share ``fix_bias_share`` of its reported variance is a Gauss-Markov state
    ``g`` per axis (correlation time ``fix_bias_tau_s``; :meth:`PdrEkf.propagate_fix_bias`), the rest
    is white, and ``h(x) = [E + f l cos psi + gE, N + f l sin psi + gN]``.  The filter then learns
    the position from the fixes only as fast as the error decorrelates, and when the fixes are
    coarser than dead reckoning's own uncertainty it attributes their disagreement to them: the
    fused track stays the dead-reckoned one, with an honest sigma.  ``fix_bias_share = 0`` is the
    paper's white measurement, and the default: measured on the tuning split (``benchmarks.gnss_faults``,
    the usability judge on, heading fix below in place), the statistics' own values (share 0.95, 45 s) make
    the IPIN tuning median landmark error worse (2.28 m -> 2.69 m; dead reckoning alone 2.52 m: on routes 01
    the fixes are good and the steps' heading poor, and the slower pull loses what the fixes gave), and the
    outdoor tuning walk's distance to left-out fixes grows (0.43 -> 0.80 of their accuracy).  Of a 3 x 3 grid
    (share 0.5/0.8/0.95, 15/45/120 s) only share 0.8 with 15 s gained indoors (2.23 m), by 0.05 m on four
    files, while outdoors it doubled that distance (0.90; the walk's 3-minute outage 20.6 -> 20.7 %, the
    simulator's tuning fault walks' median track error 6.0 -> 6.3 m): not enough to turn it on.  Re-measured
    2026-12-07 at the current code (IPIN tuning, the judge on): shares 0.5-0.95 x 15-45 s give 2.29-2.37 m
    against the white filter's 2.236 (T01r04 5.35 -> 11.2 m at 0.95 / 45 s), and the same state as a
    Schmidt-consider bias (its gain rows zero) 2.31-2.37 m: the filter's reported covariance models it instead
    ("What the filter reports", below).  Where the fixes' error
    is the model's (the simulator's receiver, tests/test_gnss_indoor.py), it keeps a 15-m bias held for
    3 minutes from pulling the track (3.8 m against the white filter's 14.8 m) and the NEES at 2.

What the filter reports: the error covariance of its own estimate (issue #26, 2026-12-07)
    Whatever the gain, the fused track's ``cov_en_m2`` (and the live status's sigma) is ``C``
    (:attr:`PdrEkf.reported_cov`): the covariance of this filter's error when the fixes' error is what the
    statistics above say -- a share ``reported_fix_bias_share`` (0.95) of each fix's reported variance a
    Gauss-Markov process of correlation time ``fix_bias_tau_s`` (45 s), the rest white.  ``C`` goes through
    every prediction, process noise, consider-SD change, anchor, relock and reset that ``P`` goes through, and
    through every update with the gain ``K`` the filter used (computed from ``P``) in Joseph form,
    ``C <- (I - K H) C (I - K H)^T + K R K^T`` with ``H`` the fix's measurement of position plus its correlated
    error (:meth:`PdrEkf.fix_measurement_jacobian`), which is exact for any gain: the covariance analysis of a
    sub-optimal filter.  The track, the gate, the NIS and every decision stay the white filter's (``P``); only
    what it says about its error changes.  Why not the optimal filter: the same model in the gain
    (``fix_bias_share``, above, or a Schmidt-consider bias) or the fixes' decorrelation
    (:class:`core.gnss.base.FixDecorrelation`) make IPIN's tuning median landmark error worse (2.24 ->
    2.31-2.37 m; dead reckoning alone 2.29) and the tuning outdoor walk's distance to left-out fixes too
    (decorrelation 45 s: 0.43 -> 1.77 of their accuracy): on route 01 the steps' heading is poor and its fixes
    good, and a filter that believes the fixes less follows them less.  Measured on IPIN's tuning split (176
    landmarks of 16 files, the fused position's NEES with its 2 x 2 covariance, chi-square 2 dof): landmarks
    beyond the 95 % point 8.5 % -> 5.1 %, mean NEES 4.1 -> 2.1 (T01r04, 86 fixes used: largest 188 -> 4.5),
    landmark errors identical.  ``reported_fix_bias_share=0``: ``C`` is ``P`` (the report before).

Every update uses the Joseph form (valid for the Schmidt gain too) and
refuses non-finite input, so the state never holds a NaN or an inf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core import kalman
from core.conventions import wrap_angle

#: chi-square 99.9 % points for 1 and 2 degrees of freedom
CHI2_999 = {1: 10.83, 2: 13.82}

#: state indices: East, North, step length, heading, the consider states heading bias, length scale error, and
#: the fixes' correlated error East, North
E, N, L, PSI, B, K, GE, GN = range(8)
NX = 8
FIX_BIAS = slice(GE, GN + 1)
CONSIDER = (B, K)


def sigma_max_m(cov_en_m2) -> float:
    """sqrt of the largest eigenvalue of a 2x2 position covariance given as ``(var_e, cov_en, var_n)`` (m)."""
    a, b, c = cov_en_m2
    tr, det = a + c, a * c - b * b
    return math.sqrt(max(0.5 * tr + math.sqrt(max(0.25 * tr * tr - det, 0.0)), 0.0))


def kalman_update(x: np.ndarray, P: np.ndarray, innov: np.ndarray, H: np.ndarray, R: np.ndarray, gate: float, *,
                  zero_gain_rows=(), angle_index: int | None = None) -> tuple[bool, float, np.ndarray, np.ndarray]:
    """:func:`kalman_update_gain` without the gain."""
    return kalman_update_gain(x, P, innov, H, R, gate, zero_gain_rows=zero_gain_rows, angle_index=angle_index)[:4]


def kalman_update_gain(x: np.ndarray, P: np.ndarray, innov: np.ndarray, H: np.ndarray, R: np.ndarray, gate: float,
                       *, zero_gain_rows=(), angle_index: int | None = None):
    """One gated EKF measurement update in Joseph form: ``(accepted, nis, x, P, K)`` (``K`` None when rejected),
    the update of :func:`core.kalman.correct` applied to a state vector.

    Rejected (NIS beyond ``gate``, a singular innovation covariance -- NIS inf --, a non-finite
    correction) returns the state unchanged.  ``zero_gain_rows`` are states not
    estimated (Schmidt consider states; the Joseph form stays valid for that gain);
    ``angle_index`` is wrapped to [-pi, pi).  The filters of this package share it.
    """
    rows = list(zero_gain_rows)

    def consider(K):
        K[rows, :] = 0.0

    c = kalman.correct(P, innov, H, R, gate, adjust_gain=consider if rows else None)
    if not c.used:
        return False, (c.nis if c.nis == c.nis else math.inf), x, P, None
    x = x + c.dx
    if angle_index is not None:
        x[angle_index] = wrap_angle(float(x[angle_index]))
    return True, c.nis, x, 0.5 * (c.P + c.P.T), c.K


def covariance_cover(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A positive semi-definite covariance at least as large as both ``a`` and ``b`` (Loewner order):
    ``a + [b - a]_+``, the positive part of the difference added (``np.maximum`` element by element can be
    indefinite; issue #26).  ``a`` and ``b`` must be symmetric PSD."""
    w, v = np.linalg.eigh(0.5 * ((b - a) + (b - a).T))
    out = a + (v * np.maximum(w, 0.0)) @ v.T
    return 0.5 * (out + out.T)


@dataclass(frozen=True)
class UpdateResult:
    """Diagnostics of one measurement update (data, not logs)."""

    accepted: bool
    innovation: tuple  #: measurement minus prediction (m or rad)
    nis: float  #: normalised innovation squared
    correction_m: float = 0.0  #: how far the position moved (m); 0 when rejected
    sigma_before_m: float = math.nan  #: sqrt of the largest eigenvalue of the position covariance before
    reason: str = ""


@dataclass(slots=True)
class PdrEkfState:
    """Everything :class:`PdrEkf` changes as steps and fixes come: its only state, made by :meth:`initial`.

    Read and set from outside only through :meth:`PdrEkf.snapshot` and :meth:`PdrEkf.restore`.
    """

    initialized: bool
    x: np.ndarray  #: ``[E, N, l, psi, b, k, gE, gN]`` (m, m, m, rad, rad, -, m, m)
    P: np.ndarray  #: its covariance, the gain's (NX x NX)
    #: the reported covariance (the error covariance of this filter's estimate under the correlated fix-error
    #: model, ``reported_fix_bias_share``; see "What the filter reports"); None: the filter's own ``P``
    C: np.ndarray | None
    last_heading_meas: float  #: the last step's measured heading (rad; nan before any): the turn's process noise
    n_steps: int
    fix_bias_var_m2: float  #: the fix-error process's own variance per axis now (m^2; 0 before the first fix)
    c_fix_bias_var_m2: float  #: the same for the reported covariance's own fix-error state (m^2)

    @classmethod
    def initial(cls) -> PdrEkfState:
        return cls(initialized=False, x=np.zeros(NX), P=np.eye(NX), C=None, last_heading_meas=math.nan, n_steps=0,
                   fix_bias_var_m2=0.0, c_fix_bias_var_m2=0.0)


class PdrEkf(kalman.StateSnapshots):
    """Eq. 13 with the step-length and heading measurements of each step and GPS updates.

    Settings are the keywords below; the state is one :class:`PdrEkfState` (``x``, ``P``, ``C`` ... are read-only
    views of it), changed only by the methods (the fusion's :meth:`set_position`, :meth:`set_step`,
    :meth:`restart_position`, :meth:`widen_position`) and taken out or put back whole by ``snapshot()`` /
    ``restore()``.

    Parameters
    ----------
    length_walk_m : float
        Random walk of the step length per step (the paper's ``delta_l``, m).
    heading_walk_rad : float
        Random walk of the heading per step (the paper's ``delta_a``, rad).
    turn_gain : float
        Extra heading process noise per step: this factor times the change of the
        measured heading since the last step (see the module docstring).
    length_sd_m : float
        SD of a step length measurement (the stride model's per-step error, m).
    heading_sd_rad : float
        SD of a step heading measurement (the body's oscillation, the paper's ``omega``, rad).
    gate_nis_2d, gate_nis_1d : float
        Chi-square gates on the NIS of position (2 dof) and course (1 dof) updates.
    bias_walk_rad, scale_walk : float
        Random walk per step of the consider states (heading bias, rad; relative length error).
    position_updates_heading : bool
        Whether GPS positions correct the heading state (through its correlation with the
        position); False leaves the heading to the step measurements and the GPS course.
    fix_bias_share : float
        The share (0-1) of a fix's reported variance that is correlated in time (the states ``gE, gN``;
        see "Honest fixes" in the module docstring); 0: white fixes (the paper).
    fix_bias_tau_s : float
        The correlation time of that part (s).
    heading_carries_bias : bool
        When :meth:`set_consider_sd` widens the heading-bias consider state, widen the heading state by the same
        variance, anti-correlated (see "Honest uncertainty" in the module docstring); False: the bias alone (before
        issue #26's indoor follow-up: the heading then lagged every turn).
    reported_fix_bias_share : float
        The share (0-1) of a fix's reported variance that the REPORTED covariance takes as a Gauss-Markov error
        (correlation time ``fix_bias_tau_s``); the gain, the track and the gate do not change (see "What the
        filter reports" in the module docstring).  0.95, on by default (IPIN tuning: identical tracks, NEES
        beyond the 95 % point 8.5 -> 5.1 %); 0: the filter's own ``P`` is reported.
    bias_turn_gain : float
        Extra random walk of the heading-bias consider state per step: this factor times the step's turn (rad per
        rad), for a heading error that changes with the corridor indoors (the building turns the field 10-30 deg
        per segment).  0, the default: measured with and without the fixes' decorrelation on the tuning split
        (issue #26, 2026-12-07, ``benchmarks/discussion.md``), no gain.
    dr_match_nis : float
        Covariance matching of dead reckoning's sigma, with the fixes' decorrelation only (``noise_scale > 1``):
        a fix inside the gate whose NIS against ONE fix's spread exceeds this value widens the position along its
        innovation until that NIS is this value (:func:`matching_widening`), then updates with the decorrelated
        spread.  0 (the default): off; no gain on the tuning split (issue #26, 2026-12-07).
    """

    def __init__(self, *, length_walk_m: float = 0.03, heading_walk_rad: float = math.radians(1.5),
                 turn_gain: float = 1.0, length_sd_m: float = 0.08, heading_sd_rad: float = math.radians(4.0),
                 gate_nis_2d: float = CHI2_999[2], gate_nis_1d: float = CHI2_999[1],
                 bias_walk_rad: float = math.radians(0.05), scale_walk: float = 0.0005,
                 position_updates_heading: bool = True, fix_bias_share: float = 0.0,
                 fix_bias_tau_s: float = 45.0, heading_carries_bias: bool = True,
                 reported_fix_bias_share: float = 0.95, bias_turn_gain: float = 0.0,
                 dr_match_nis: float = 0.0):
        if not (bias_turn_gain >= 0.0 and dr_match_nis >= 0.0 and math.isfinite(bias_turn_gain)
                and math.isfinite(dr_match_nis)):
            raise ValueError(f"bias_turn_gain and dr_match_nis must be finite and >= 0, got {bias_turn_gain}, "
                             f"{dr_match_nis}")
        if not (0.0 <= fix_bias_share < 1.0 and fix_bias_tau_s > 0 and 0.0 <= reported_fix_bias_share < 1.0):
            raise ValueError(f"fix_bias_share and reported_fix_bias_share must be in [0, 1) and fix_bias_tau_s > 0, "
                             f"got {fix_bias_share}, {reported_fix_bias_share}, {fix_bias_tau_s}")
        self.length_walk_m = float(length_walk_m)
        self.heading_walk_rad = float(heading_walk_rad)
        self.turn_gain = float(turn_gain)
        self.length_sd_m = float(length_sd_m)
        self.heading_sd_rad = float(heading_sd_rad)
        self.gate_nis_2d = float(gate_nis_2d)
        self.gate_nis_1d = float(gate_nis_1d)
        self.bias_walk_rad = float(bias_walk_rad)
        self.scale_walk = float(scale_walk)
        self.position_updates_heading = bool(position_updates_heading)
        self.fix_bias_share = float(fix_bias_share)
        self.fix_bias_tau_s = float(fix_bias_tau_s)
        self.heading_carries_bias = bool(heading_carries_bias)
        self.reported_fix_bias_share = float(reported_fix_bias_share)
        self.bias_turn_gain = float(bias_turn_gain)
        self.dr_match_nis = float(dr_match_nis)
        self.reset()

    State = PdrEkfState

    def reset(self) -> None:
        """Forget the state (the settings stay): :meth:`initialize` starts it again."""
        self._state = PdrEkfState.initial()

    # -- read-only views of the state (set it through the methods below, or snapshot() / restore()) ----------
    x = property(lambda self: kalman.read_only(self._state.x), doc="The state vector ``[E, N, l, psi, b, k, gE, gN]``.")
    P = property(lambda self: kalman.read_only(self._state.P), doc="Its covariance (the gain's).")
    C = property(lambda self: kalman.read_only(self._state.C), doc="The reported covariance (None: ``P`` is reported).")
    initialized = property(lambda self: self._state.initialized)
    n_steps = property(lambda self: self._state.n_steps)
    fix_bias_var_m2 = property(lambda self: self._state.fix_bias_var_m2,
                               doc="The fix-error process's own variance per axis now (m^2; 0 before the first fix).")

    def initialize(self, east_m: float, north_m: float, pos_sd_m: float, length_m: float, heading_rad: float,
                   *, length_sd_m: float = 0.15, heading_sd_rad: float = math.radians(10.0),
                   bias_sd_rad: float = math.radians(3.0), scale_sd: float = 0.03) -> None:
        """Start the filter at a position (a GPS fix or the walk's origin) with the given uncertainties."""
        vals = (east_m, north_m, pos_sd_m, length_m, heading_rad)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"PdrEkf.initialize needs finite values, got {vals}")
        st = self._state
        st.x = np.array([east_m, north_m, length_m, wrap_angle(float(heading_rad)), 0.0, 0.0, 0.0, 0.0], dtype=float)
        # the fix error's variance is set by the first fix's reported accuracy (propagate_fix_bias)
        st.P = np.diag([pos_sd_m ** 2, pos_sd_m ** 2, length_sd_m ** 2, heading_sd_rad ** 2, bias_sd_rad ** 2,
                        scale_sd ** 2, 0.0, 0.0])
        st.fix_bias_var_m2 = 0.0
        st.C = st.P.copy() if self.reported_fix_bias_share > 0.0 else None
        st.c_fix_bias_var_m2 = 0.0
        st.last_heading_meas = math.nan
        st.initialized = True

    # -- helpers --------------------------------------------------------------
    @property
    def position_cov_m2(self) -> np.ndarray:
        return self._state.P[:2, :2].copy()

    @property
    def reported_cov(self) -> np.ndarray:
        """The covariance the filter reports (the fused track's ``cov_en_m2``): ``C`` with
        ``reported_fix_bias_share``, else ``P`` (see "What the filter reports" in the module docstring)."""
        return self._state.P if self._state.C is None else self._state.C

    def reported_sigma_m(self) -> float:
        """sqrt of the largest eigenvalue of the reported position covariance (m)."""
        C = self.reported_cov
        return sigma_max_m((C[0, 0], C[0, 1], C[1, 1]))

    def _report_update(self, K: np.ndarray, H: np.ndarray, R: np.ndarray) -> None:
        """The reported covariance after an update with gain ``K`` (Joseph form: the error covariance of any
        gain), ``H`` and ``R`` the measurement as the reported model has it."""
        if self._state.C is None:
            return
        ikh = np.eye(NX) - K @ H
        C = ikh @ self._state.C @ ikh.T + K @ R @ K.T
        if np.all(np.isfinite(C)):
            self._state.C = 0.5 * (C + C.T)

    def position_sigma_m(self) -> float:
        """sqrt of the largest eigenvalue of the position covariance (m)."""
        P = self._state.P
        return sigma_max_m((P[0, 0], P[0, 1], P[1, 1]))

    def _update(self, innov: np.ndarray, H: np.ndarray, R: np.ndarray, gate: float,
                frozen: tuple = (), R_reported: np.ndarray | None = None) -> tuple[bool, float]:
        # Schmidt: the consider (and frozen) states are not estimated
        st = self._state
        ok, nis, st.x, st.P, K = kalman_update_gain(st.x, st.P, innov, H, R, gate,
                                                    zero_gain_rows=list(CONSIDER) + list(frozen), angle_index=PSI)
        if ok:
            self._report_update(K, H, R if R_reported is None else R_reported)
        return ok, nis

    # -- per step ---------------------------------------------------------------
    def step(self, length_m: float, heading_rad: float) -> UpdateResult:
        """One step: random walk (eq. 13), update with the step's length and heading, move the position."""
        if not self._state.initialized:
            raise RuntimeError("PdrEkf.step before initialize")
        if not (math.isfinite(length_m) and math.isfinite(heading_rad)):
            return UpdateResult(False, (math.nan, math.nan), math.nan, reason="not finite")
        turn = 0.0 if self._state.last_heading_meas != self._state.last_heading_meas else \
            wrap_angle(heading_rad - self._state.last_heading_meas)
        self._state.last_heading_meas = float(heading_rad)
        # eq. 13: l and psi as random walks (+ the walker's own turn)
        for M in (self._state.P,) if self._state.C is None else (self._state.P, self._state.C):
            M[L, L] += self.length_walk_m ** 2
            M[PSI, PSI] += self.heading_walk_rad ** 2 + (self.turn_gain * turn) ** 2
            M[B, B] += self.bias_walk_rad ** 2 + (self.bias_turn_gain * turn) ** 2
            M[K, K] += self.scale_walk ** 2
        # z_l = l (1 + k), z_psi = psi + b, with the consider states at 0
        innov = np.array([length_m - self._state.x[L], wrap_angle(heading_rad - self._state.x[PSI])])
        H = np.zeros((2, NX))
        H[0, L], H[0, K] = 1.0, self._state.x[L]
        H[1, PSI], H[1, B] = 1.0, 1.0
        R = np.diag([self.length_sd_m ** 2, self.heading_sd_rad ** 2])
        # the step's own length and heading say nothing about where the walker already is: the position rows
        # get no gain (issue #26: through the consider states' cross terms, rescaled by set_consider_sd at
        # every step, each turn moved the dead-reckoned position sideways, 166-174 m over a 3-minute outage)
        ok, nis = self._update(innov, H, R, math.inf, frozen=(E, N))
        # eq. 13: the position moves by the step
        F = self.transition_jacobian(self._state.x[L], self._state.x[PSI])
        self._state.x = self.transition(self._state.x)
        P = F @ self._state.P @ F.T
        self._state.P = 0.5 * (P + P.T)
        if self._state.C is not None:
            C = F @ self._state.C @ F.T
            self._state.C = 0.5 * (C + C.T)
        self._state.n_steps += 1
        return UpdateResult(ok, (float(innov[0]), float(innov[1])), nis)

    @staticmethod
    def transition(x: np.ndarray) -> np.ndarray:
        """eq. 13 (in ENU, CCW heading): the state after a step of length ``x[2]`` along ``x[3]``."""
        out = np.array(x, dtype=float)
        out[E] += x[L] * math.cos(x[PSI])
        out[N] += x[L] * math.sin(x[PSI])
        return out

    @staticmethod
    def transition_jacobian(length_m: float, heading_rad: float) -> np.ndarray:
        """``d transition / d x`` at ``(l, psi)``."""
        c, s = math.cos(heading_rad), math.sin(heading_rad)
        F = np.eye(NX)
        F[E, L], F[E, PSI] = c, -length_m * s
        F[N, L], F[N, PSI] = s, length_m * c
        return F

    # -- GPS ----------------------------------------------------------------------
    @staticmethod
    def fix_prediction(x: np.ndarray, fraction: float) -> np.ndarray:
        """``h(x)``: the position ``fraction`` of a step beyond the state's."""
        return np.array([x[E] + fraction * x[L] * math.cos(x[PSI]), x[N] + fraction * x[L] * math.sin(x[PSI])])

    @staticmethod
    def fix_jacobian(x: np.ndarray, fraction: float) -> np.ndarray:
        """``d h / d x``."""
        l, psi = x[L], x[PSI]
        c, s = math.cos(psi), math.sin(psi)
        H = np.zeros((2, NX))
        H[0, E], H[0, L], H[0, PSI] = 1.0, fraction * c, -fraction * l * s
        H[1, N], H[1, L], H[1, PSI] = 1.0, fraction * s, fraction * l * c
        return H

    @staticmethod
    def fix_measurement(x: np.ndarray, fraction: float) -> np.ndarray:
        """What a fix measures: :meth:`fix_prediction` plus the fixes' correlated error ``(gE, gN)``."""
        return PdrEkf.fix_prediction(x, fraction) + x[FIX_BIAS]

    @staticmethod
    def fix_measurement_jacobian(x: np.ndarray, fraction: float) -> np.ndarray:
        """``d fix_measurement / d x``."""
        H = PdrEkf.fix_jacobian(x, fraction)
        H[0, GE] = H[1, GN] = 1.0
        return H

    def update_position(self, east_m: float, north_m: float, sigma_m: float, fraction: float = 0.0,
                        *, gate: bool = True, noise_scale: float = 1.0) -> UpdateResult:
        """A GPS position (local ENU, m) with its per-axis SD (m).

        ``noise_scale`` (>= 1): the update uses the fix's white variance times this factor (the fixes' error
        decorrelation, :class:`core.gnss.fusion.GpsFusion`'s ``gps_error_correlation_s``), while the gate and the
        NIS it reports use the variance a single fix has (``H P H^T + R``: how far off one fix may be)."""
        sig_before = self.position_sigma_m()
        if not (math.isfinite(east_m) and math.isfinite(north_m) and sigma_m > 0 and math.isfinite(sigma_m)
                and noise_scale >= 1.0 and math.isfinite(noise_scale)):
            return UpdateResult(False, (math.nan, math.nan), math.nan, 0.0, sig_before, "not finite")
        f = min(max(float(fraction), 0.0), 1.0)
        # the fix measures the position plus its correlated error (the module docstring's "Honest fixes")
        innov = np.array([east_m, north_m]) - self.fix_measurement(self._state.x, f)
        H = self.fix_measurement_jacobian(self._state.x, f)
        before = self._state.x[:2].copy()
        frozen = () if self.position_updates_heading else (PSI,)
        white_var = (1.0 - self.fix_bias_share) * sigma_m ** 2
        gate_nis = self.gate_nis_2d if gate else math.inf
        # the reported covariance's fix: its white part (the correlated part is C's own fix-error state)
        R_rep = np.eye(2) * (1.0 - self.reported_fix_bias_share) * sigma_m ** 2
        if noise_scale > 1.0:
            # gate on one fix's spread, update with the decorrelated (inflated) one
            ok, nis, _, _ = kalman_update(self._state.x, self._state.P, innov, H, np.eye(2) * white_var, gate_nis)
            if ok and self.dr_match_nis > 0.0 and nis > self.dr_match_nis:
                # covariance matching: one fix's spread cannot explain this innovation, so dead reckoning's sigma
                # was too small; widen the position along the innovation until its NIS is dr_match_nis
                self.widen_position(matching_widening(innov, nis, self.dr_match_nis))
            if ok:
                ok, _ = self._update(innov, H, np.eye(2) * white_var * noise_scale, math.inf, frozen, R_rep)
        else:
            ok, nis = self._update(innov, H, np.eye(2) * white_var, gate_nis, frozen, R_rep)
        moved = float(np.hypot(*(self._state.x[:2] - before))) if ok else 0.0
        reason = "" if ok else f"innovation gate: NIS {nis:.1f} > {self.gate_nis_2d:.1f}"
        return UpdateResult(ok, (float(innov[0]), float(innov[1])), nis, moved, sig_before, reason)

    def propagate_fix_bias(self, dt_s: float, sigma_m: float) -> None:
        """The fixes' correlated error ``g`` (per axis) over ``dt_s`` since the last fix, to a fix reporting a
        per-axis SD ``sigma_m``: a first-order Gauss-Markov process, ``g' = a g + u``, ``a = exp(-dt / tau)``,
        whose own variance is the fix's share ``rho sigma^2`` (Brown & Hwang's discretisation, with a variance
        that follows the reported accuracy: ``var(u) = rho sigma^2 - a^2 q``, ``q`` the variance so far, at
        least 0 -- a receiver reporting a finer accuracy makes the error shrink no faster than it decorrelates).
        Before the first fix (``q = 0``) the variance starts at ``rho sigma^2``.  The reported covariance's own
        fix-error state (``reported_fix_bias_share``) moves alike.  No-op with both shares 0 or a non-finite
        input."""
        if not (dt_s >= 0.0 and math.isfinite(sigma_m) and sigma_m > 0):
            return
        a = math.exp(-max(dt_s, 0.0) / self.fix_bias_tau_s)
        st = self._state
        if self.fix_bias_share > 0.0:
            st.x[FIX_BIAS] *= a
            st.fix_bias_var_m2 = _gauss_markov(st.P, a, self.fix_bias_share * sigma_m ** 2, st.fix_bias_var_m2)
        if st.C is not None:
            st.c_fix_bias_var_m2 = _gauss_markov(st.C, a, self.reported_fix_bias_share * sigma_m ** 2,
                                                 st.c_fix_bias_var_m2)

    def place_on_fix(self, sigma_m: float) -> None:
        """The position was just put on a fix (an anchor, a relock's restart): its variance ``sigma_m^2`` per axis,
        uncorrelated with the other states but the fix's own error:
        its error is that fix's error, so the position error is minus the fix's correlated part (covariance
        ``-rho sigma^2``) -- without this the next fixes, off by the same error, would look like independent
        evidence that the position is right.  The correlated error's estimate starts at 0 with its own variance.
        The reported covariance (``reported_fix_bias_share``) alike, with its own share."""
        if not (math.isfinite(sigma_m) and sigma_m > 0):
            return
        if self.fix_bias_share > 0.0:
            self._state.x[FIX_BIAS] = 0.0
            self._state.fix_bias_var_m2 = _on_fix(self._state.P, sigma_m, self.fix_bias_share)
        if self._state.C is not None:
            self._state.c_fix_bias_var_m2 = _on_fix(self._state.C, sigma_m, self.reported_fix_bias_share)

    def update_course(self, course_rad: float, sigma_rad: float) -> UpdateResult:
        """A GPS course (rad, CCW from East) as a direct measurement of the heading."""
        if not (math.isfinite(course_rad) and sigma_rad > 0 and math.isfinite(sigma_rad)):
            return UpdateResult(False, (math.nan,), math.nan, reason="not finite")
        innov = np.array([wrap_angle(course_rad - self._state.x[3])])
        H = np.zeros((1, NX))
        H[0, PSI] = 1.0
        ok, nis = self._update(innov, H, np.array([[sigma_rad ** 2]]), self.gate_nis_1d)
        return UpdateResult(ok, (float(innov[0]),), nis, reason="" if ok else f"course gate: NIS {nis:.1f}")

    def reset_position(self, east_m: float, north_m: float, sigma_m: float) -> None:
        """Put the position on a fix (the paper's architecture: GPS is the solution while it is there)."""
        if math.isfinite(east_m) and math.isfinite(north_m) and sigma_m > 0:
            self._state.x[0], self._state.x[1] = east_m, north_m
            for M in (self._state.P,) if self._state.C is None else (self._state.P, self._state.C):
                M[:2, :] = 0.0
                M[:, :2] = 0.0
                M[0, 0] = M[1, 1] = sigma_m ** 2

    def set_position(self, east_m: float, north_m: float) -> None:
        """Move the position to ``(east_m, north_m)`` (m), its covariance unchanged (a dead-reckoned step while GPS
        is not trusted: :meth:`core.gnss.base.FixFusion._dead_reckon`)."""
        self._state.x[E], self._state.x[N] = east_m, north_m

    def set_step(self, length_m: float, heading_rad: float) -> None:
        """Set the step length (m) and heading (rad; wrapped) states, their covariance unchanged (the dead-reckoned
        step's, so that the track's output follows it)."""
        self._state.x[L], self._state.x[PSI] = length_m, wrap_angle(heading_rad)

    def restart_position(self, innovation, sigma_m: float) -> None:
        """Restart the position on a fix: moved by the fix's ``innovation`` (E, N; None: not moved), its correlations
        with the other states dropped, its per-axis SD the fix's ``sigma_m`` -- in ``P``; the reported covariance
        follows in :meth:`place_on_fix`, which the caller applies next (the anchor, the consistent-stream relock:
        :class:`core.gnss.base.FixFusion`).  :meth:`reset_position` instead puts the position on the fix itself
        in both."""
        restart_position_of(self._state.x, self._state.P, innovation, sigma_m)

    def widen_position(self, offset_m) -> None:
        """Widen the position's covariance by the outer product of ``offset_m`` (E, N) (a relock's disagreement)."""
        d = np.asarray(offset_m, dtype=float)
        if not np.all(np.isfinite(d)):
            return
        for M in (self._state.P,) if self._state.C is None else (self._state.P, self._state.C):
            M[:2, :2] += np.outer(d, d)

    def set_consider_sd(self, heading_bias_sd_rad: float, scale_sd: float) -> None:
        """Set the consider states' SDs (from the training's uncertainty), keeping ``P`` positive semi-definite.

        A smaller SD scales the state's row and column (a congruence, so the
        correlations stay); a larger one adds to its variance (the heading bias's also to the heading's,
        anti-correlated, with ``heading_carries_bias``).
        """
        for M in (self._state.P,) if self._state.C is None else (self._state.P, self._state.C):
            _set_consider_sd(M, heading_bias_sd_rad, scale_sd, self.heading_carries_bias)


def restart_position_of(x: np.ndarray, P: np.ndarray, innovation, sigma_m: float) -> None:
    """The position of a state ``x`` (``x[:2]``) and covariance ``P`` restarted on a fix, in place: moved by the
    fix's ``innovation`` (None: not moved), its correlations dropped, its per-axis variance ``sigma_m^2``
    (:meth:`PdrEkf.restart_position`, :meth:`core.gnss.kubrak.KubrakKf.restart_position`)."""
    if innovation is not None:
        x[:2] += np.asarray(innovation, dtype=float)
    P[:2, :] = 0.0
    P[:, :2] = 0.0
    P[0, 0] = P[1, 1] = sigma_m ** 2


def matching_widening(innov, nis: float, target_nis: float) -> np.ndarray:
    """The offset ``o`` (m, E and N) whose outer product, added to the position covariance, brings an innovation
    ``d`` of NIS ``nis`` (against ``S = H P H^T + R``) down to ``target_nis``: ``o = d sqrt(1/target - 1/nis)``,
    since ``d^T (S + beta d d^T)^-1 d = nis / (1 + beta nis)`` (Sherman-Morrison).  Zero when ``nis <= target``
    or an input is not finite (covariance matching of dead reckoning's sigma, :class:`PdrEkf`'s ``dr_match_nis``)."""
    d = np.asarray(innov, dtype=float)
    if not (target_nis > 0 and math.isfinite(nis) and nis > target_nis and np.all(np.isfinite(d))):
        return np.zeros_like(d)
    return d * math.sqrt(1.0 / target_nis - 1.0 / nis)


def _set_consider_sd(P: np.ndarray, heading_bias_sd_rad: float, scale_sd: float, heading_carries_bias: bool) -> None:
    """:meth:`PdrEkf.set_consider_sd` on one covariance (the filter's, the reported one), in place."""
    for i, sd in ((B, heading_bias_sd_rad), (K, scale_sd)):
        if not (sd > 0 and math.isfinite(sd)):
            continue
        var = P[i, i]
        if sd * sd < var:
            f = sd / math.sqrt(var)
            P[i, :] *= f
            P[:, i] *= f
        elif i == B and heading_carries_bias:
            # the heading state was learnt from the step headings, which carry the bias: a bias known less
            # well by d leaves the heading known less well by d too, anti-correlated (psi = z - b)
            d = sd * sd - var
            P[B, B] += d
            P[PSI, PSI] += d
            P[PSI, B] -= d
            P[B, PSI] -= d
        else:
            P[i, i] = sd * sd


def _gauss_markov(P: np.ndarray, a: float, target_var: float, var: float) -> float:
    """The fix-error states of ``P`` one Gauss-Markov step on (:meth:`PdrEkf.propagate_fix_bias`: their rows and
    columns times ``a``, the process's own variance ``var`` brought to ``target_var`` no faster than ``a``
    allows), in place; returns the process's variance now."""
    add = max(target_var - a * a * var, 0.0)
    P[FIX_BIAS, :] *= a
    P[:, FIX_BIAS] *= a
    P[GE, GE] += add
    P[GN, GN] += add
    return a * a * var + add


def _on_fix(P: np.ndarray, sigma_m: float, share: float) -> float:
    """``P`` with the position just put on a fix of per-axis SD ``sigma_m`` whose correlated share is ``share``
    (:meth:`PdrEkf.place_on_fix`), in place; returns the fix-error process's variance."""
    q = share * sigma_m ** 2
    P[FIX_BIAS, :] = 0.0
    P[:, FIX_BIAS] = 0.0
    P[:2, :] = 0.0
    P[:, :2] = 0.0
    P[E, E] = P[N, N] = sigma_m ** 2
    P[GE, GE] = P[GN, GN] = q
    P[E, GE] = P[GE, E] = P[N, GN] = P[GN, N] = -q
    return q
