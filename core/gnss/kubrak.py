"""Real-time GPS/PDR fusion with bad-GPS detection (Kubrak, Macabiau & Monnerat 2006).

The pedestrian navigation system (PNS) of the paper dead-reckons with the velocity
model of eq. 1 (:mod:`core.pdr.velocity`) and the heading of an attitude filter,
by eq. 2::

    N_k = N_{k-1} + dd_[k-1,k] cos(psi_k),   E_k = E_{k-1} + dd_[k-1,k] sin(psi_k)     (eq. 2)

with ``psi`` a bearing (clockwise from North).  In our ENU convention (heading
CCW from East, :mod:`core`) that is ``E += dd cos(psi)``, ``N += dd sin(psi)``;
every heading derivative below is written in ours (the paper's ``d/dpsi`` of
``N`` is ``-dd sin``, ours of ``E`` is ``-dd sin``: the same sign, on the other axis).

The loosely coupled Kalman filter of the paper's Figure 8 (:class:`KubrakKf`)
has seven states: the position errors ``dN, dE``, the velocity error ``dv``,
the heading error ``dpsi`` and the regression coefficients' errors ``dA, dB,
dC``.  It is written here on the total state (closed-loop error-state, the
same filter), with two more states the paper does not have, the correlated
part of the GPS position error (``bE, bN``: see ``KubrakKf``'s ``fix_bias_sd_m``)::

    x = [E, N, dv, dpsi, A, B, C, bE, bN]
    v   = A MEAN + B FREQ + C STD + dv        (eq. 1 plus what it does not explain)
    psi = psi_pdr + dpsi                     (the pipeline's step heading, corrected)

An epoch is a step of the hand-held chain (about 2 Hz): its eq.-1 regressors
are those of the 2 s window ending at the step's peak, its heading the step's,
and ``dd = v * dt`` over the time since the previous step (so that a missed
step does not lose distance, the velocity model's advantage over counting
steps; after a pause ``dt`` is the step's own duration).  ``dv`` is a
first-order Gauss-Markov process (``dv_sd_m_s``, ``dv_tau_s``), ``dpsi`` and
the coefficients random walks; each epoch also adds the white noise of the
step heading and speed to the position.  The paper gives no noise values;
ours are documented per setting.

Measurements: GPS position (E, N) -- at the fix's time, the last epoch moved on
by the time since it -- and GPS velocity (Doppler speed and course as East and
North components, or the speed alone where the course is missing).  The
Doppler speed is not taken as reported (the paper's choice): on several phones
it reads 15-25 % low against the chords between fixes (issue #26), and the
velocity model then learns a walker too slow for every outage.  By default it
is multiplied by a scale learnt online from the chords of long straight
stretches (:class:`core.gnss.training.OnlineTrainer` with
``reference=ChordReference.DOPPLER``, the chord logic of Chen's stride scale),
and until a chord has measured that scale only the course is used, as an
angle (:class:`DopplerSpeed`).  Every
update passes a chi-square gate on its normalised innovation squared (NIS).
Jacobians are written out and checked by finite differences in the tests.

Bad GPS (the paper's Figures 14-16, and what a phone adds):

* the receiver's reported accuracy (``max_hacc_m``) and, where the recording
  has the receiver's status, the paper's first rule: the 4th-strongest
  satellite in use below 25 dB-Hz (:class:`core.gnss.base.FixFusion`);
* the innovation gates of position and velocity;
* **coefficient variability**, the paper's recommended test: when the speed
  the coefficients predict at the walker's usual regressors (the mean of the
  last minute's epochs) changes over ``variability_window_s`` by more than a
  walker's pace can -- more than ``max_speed_change_m_s`` *and* more than the
  filter's own uncertainty allows (the change's chi-square against the
  variance the window's updates removed plus the random walk's) -- GPS is
  declared unreliable: the coefficients are replaced by their mean over the
  minute before the window (the paper's correction) and fixes are not used
  for ``unreliable_hold_s``.  Meanwhile a shadow copy of the filter keeps
  taking them; GPS is trusted again once the shadow's coefficients stay steady
  for a whole hold.  A genuine change of pace also trips the test (issue #26:
  on the tuning walk ``thomasdingemanse_lopen`` a speed-up at 112 s, after
  which 176 good fixes were refused to the end): with ``adopt_shadow`` the
  shadow re-locks its position onto fixes the usability judge has found
  consistent for ``relock_s`` (the base class's consistent-stream rule,
  :meth:`core.gnss.base.FixFusion._consistent_stream`) instead of extending
  the hold while its gate rejects them, and when the hold ends a shadow that
  follows the fixes hands its state (the speed it learnt meanwhile) to the
  filter, instead of the filter going on from the reverted coefficients
  (which learnt the new pace again and tripped the test anew, 29 s of every
  50 refused).  Both are reported (``shadow_events``).

Every fix gets a verdict (:class:`core.gnss.base.FixRecord`): used, or why not.
"""

from __future__ import annotations

import copy
import enum
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from core import kalman
from core.conventions import heading_from_bearing_deg, wrap_angle
from core.gnss.base import EVENTS_KEEP_LAST, FixFusion, relock_heading_error_rad
from core.gnss.ekf import (CHI2_999, UpdateResult, covariance_cover, kalman_update, restart_position_of,
                           sigma_max_m)
from core.gnss.training import ChordReference, OnlineTrainer
from core.pdr.velocity import VelocityModel, step_regressors

class DopplerSpeed(enum.Enum):
    """How the receiver's Doppler speed enters the velocity measurement (issue #26, bug 4)."""

    #: as reported (the paper)
    RAW = "raw"
    #: times a scale learnt online from position chords over long straight stretches
    #: (:class:`core.gnss.training.OnlineTrainer` with ``reference=ChordReference.DOPPLER``)
    CHORD_SCALED = "chord_scaled"
    #: not at all: the course alone (the velocity's cross-track component); the fixes' positions teach the speed
    COURSE_ONLY = "course_only"


#: state indices
E, N, DV, DPSI, A, B, C, BE, BN = range(9)
NX = 9
COEF = slice(A, C + 1)


@dataclass(slots=True)
class KubrakKfState:
    """Everything :class:`KubrakKf` changes as epochs and fixes come: its only state, made by :meth:`initial`.

    Read and set from outside only through :meth:`KubrakKf.snapshot` and :meth:`KubrakKf.restore`.
    """

    initialized: bool
    x: np.ndarray  #: ``[E, N, dv, dpsi, A, B, C, bE, bN]`` (m, m, m/s, rad, s, m, s, m, m)
    P: np.ndarray  #: its covariance (NX x NX)
    reg: np.ndarray  #: the last epoch's eq.-1 regressors (3,; nan before any)
    psi_pdr: float  #: the last epoch's PDR heading (rad, CCW from East; nan before any)
    t_ns: int | None  #: the last epoch's time (ns)

    @classmethod
    def initial(cls) -> KubrakKfState:
        return cls(initialized=False, x=np.zeros(NX), P=np.eye(NX), reg=np.full(3, math.nan), psi_pdr=math.nan,
                   t_ns=None)


class KubrakKf(kalman.StateSnapshots):
    """The 7-state filter of Kubrak et al. (2006), Fig. 8, plus a GPS bias (see the module docstring).

    Settings are the keywords below; the state is one :class:`KubrakKfState` (``x``, ``P``, ``reg``, ``psi_pdr``
    ... are read-only views of it), changed only by the methods and taken out or put back whole by
    ``snapshot()`` / ``restore()``.

    Parameters
    ----------
    model : VelocityModel
        eq. 1's starting coefficients and their prior SDs.
    dv_sd_m_s, dv_tau_s : float
        Gauss-Markov velocity error: SD (m/s) and correlation time (s).
    heading_bias_sd_rad : float
        Starting SD of the heading error (rad): the phone's yaw offset, declination, a bent field.
    heading_bias_walk_rad_sqrt_s : float
        Random walk of the heading error (rad/sqrt(s)).
    coef_walk_sqrt_s : (float, float, float)
        Random walk of A (s), B (m), C (s) per sqrt(s).
    step_heading_sd_rad : float
        White noise of an epoch's heading (the body's sway; rad).
    step_speed_sd_m_s : float
        White noise of an epoch's speed (m/s).
    gate_nis_2d, gate_nis_1d : float
        Chi-square gates of 2-D (position, velocity) and 1-D (speed) updates.
    fix_bias_sd_m, fix_bias_tau_s : float
        The GPS position error that is not white: a first-order Gauss-Markov bias per axis (SD m,
        correlation time s), two states beyond the paper's seven.  The paper's filter takes each fix's
        error as independent; a phone's is correlated over a minute or more (multipath, geometry; the
        IPIN museum's indoor fixes are 5-20 m off in the same direction for minutes), and a filter
        that averages them believes it knows the position to a metre while it is 10 m off.  0 gives
        the paper's filter.  Measured (issue #26, not changed): on the tuning walk thomasdingemanse_lopen
        (every 10th fix left out) the estimate builds up to 5-6 m, mostly across the track, within about 100 s
        of each restart (after the coefficient hold's relock as before the hold: it is this model, not the
        hold), and the track sits that far beside the fixes: leave-out ratio 1.04 at 3 m, 0.80 at 1.5 m, 0.55
        at 0; at 3 m without the GPS velocity 0.76 (the courses hold the heading, so a lateral disagreement
        with the positions goes to the bias).  The IPIN and simulator tuning evidence for another value was
        not run.
    """

    def __init__(self, model: VelocityModel | None = None, *, dv_sd_m_s: float = 0.1, dv_tau_s: float = 10.0,
                 heading_bias_sd_rad: float = math.radians(15.0),
                 heading_bias_walk_rad_sqrt_s: float = math.radians(0.3),
                 coef_walk_sqrt_s: tuple = (1e-4, 1e-3, 1e-3), step_heading_sd_rad: float = math.radians(3.0),
                 step_speed_sd_m_s: float = 0.05, gate_nis_2d: float = CHI2_999[2],
                 gate_nis_1d: float = CHI2_999[1], fix_bias_sd_m: float = 3.0, fix_bias_tau_s: float = 60.0):
        self.model = model or VelocityModel.load()
        self.dv_sd_m_s = float(dv_sd_m_s)
        self.dv_tau_s = float(dv_tau_s)
        self.heading_bias_sd_rad = float(heading_bias_sd_rad)
        self.heading_bias_walk_rad_sqrt_s = float(heading_bias_walk_rad_sqrt_s)
        self.coef_walk_sqrt_s = np.array(coef_walk_sqrt_s, dtype=float)
        self.step_heading_sd_rad = float(step_heading_sd_rad)
        self.step_speed_sd_m_s = float(step_speed_sd_m_s)
        self.gate_nis_2d = float(gate_nis_2d)
        self.gate_nis_1d = float(gate_nis_1d)
        self.fix_bias_sd_m = float(fix_bias_sd_m)
        self.fix_bias_tau_s = float(fix_bias_tau_s)
        self.reset()

    State = KubrakKfState

    def reset(self) -> None:
        """Forget the state (the settings stay): :meth:`initialize` starts it again."""
        self._state = KubrakKfState.initial()

    # -- read-only views of the state (set it through the methods below, or snapshot() / restore()) ----------
    x = property(lambda self: kalman.read_only(self._state.x), doc="The state vector ``[E, N, dv, dpsi, A, B, C, bE, bN]``.")
    P = property(lambda self: kalman.read_only(self._state.P), doc="Its covariance.")
    reg = property(lambda self: kalman.read_only(self._state.reg),
                   doc="The last epoch's eq.-1 regressors (nan before any).")
    psi_pdr = property(lambda self: self._state.psi_pdr, doc="The last epoch's PDR heading (rad; nan before any).")
    t_ns = property(lambda self: self._state.t_ns, doc="The last epoch's time (ns; None before any).")
    initialized = property(lambda self: self._state.initialized)

    def initialize(self, east_m: float, north_m: float, pos_sd_m: float) -> None:
        if not all(math.isfinite(v) for v in (east_m, north_m, pos_sd_m)):
            raise ValueError(f"KubrakKf.initialize needs finite values, got {(east_m, north_m, pos_sd_m)}")
        m, st = self.model, self._state
        st.x = np.array([east_m, north_m, 0.0, 0.0, m.a_s, m.b_m, m.c_s, 0.0, 0.0])
        st.P = np.diag([pos_sd_m ** 2, pos_sd_m ** 2, self.dv_sd_m_s ** 2, self.heading_bias_sd_rad ** 2,
                        *np.square(m.sd), self.fix_bias_sd_m ** 2, self.fix_bias_sd_m ** 2])
        st.initialized = True

    # -- the model ------------------------------------------------------------------
    @staticmethod
    def speed(x: np.ndarray, reg: np.ndarray) -> float:
        """eq. 1 plus the velocity error: ``A MEAN + B FREQ + C STD + dv`` (m/s)."""
        return float(x[A] * reg[0] + x[B] * reg[1] + x[C] * reg[2] + x[DV])

    def heading(self) -> float:
        """The corrected heading of the last epoch (rad, CCW from East)."""
        return wrap_angle(self._state.psi_pdr + float(self._state.x[DPSI]))

    @staticmethod
    def move(x: np.ndarray, reg: np.ndarray, psi_pdr: float, dt_s: float) -> np.ndarray:
        """eq. 2 in ENU: the position after ``dt_s`` at the model's speed along the corrected heading."""
        out = np.array(x, dtype=float)
        d = KubrakKf.speed(x, reg) * dt_s
        psi = psi_pdr + x[DPSI]
        out[E] += d * math.cos(psi)
        out[N] += d * math.sin(psi)
        return out

    @staticmethod
    def move_jacobian(x: np.ndarray, reg: np.ndarray, psi_pdr: float, dt_s: float) -> np.ndarray:
        """``d move / d x`` (the position rows; the others are the identity)."""
        v = KubrakKf.speed(x, reg)
        psi = psi_pdr + x[DPSI]
        c, s = math.cos(psi), math.sin(psi)
        F = np.eye(NX)
        for row, u, du in ((E, c, -s), (N, s, c)):
            F[row, DV] = dt_s * u
            F[row, DPSI] = v * dt_s * du
            F[row, A:C + 1] = reg * dt_s * u
        return F

    # -- per epoch -----------------------------------------------------------------
    def epoch(self, t_ns: int, dt_s: float, reg, psi_pdr: float) -> float:
        """One epoch (a step): predict by eq. 2; returns the distance moved (m)."""
        reg = np.asarray(reg, dtype=float)
        if not (self._state.initialized and dt_s > 0 and math.isfinite(dt_s) and math.isfinite(psi_pdr)
                and np.all(np.isfinite(reg))):
            return 0.0
        F = self.move_jacobian(self._state.x, reg, psi_pdr, dt_s)
        x = self.move(self._state.x, reg, psi_pdr, dt_s)
        a = math.exp(-dt_s / self.dv_tau_s)
        F[DV, DV] = a
        x[DV] *= a
        Q = np.zeros((NX, NX))
        Q[DV, DV] = self.dv_sd_m_s ** 2 * (1.0 - a * a)
        Q[DPSI, DPSI] = self.heading_bias_walk_rad_sqrt_s ** 2 * dt_s
        Q[COEF, COEF] = np.diag(np.square(self.coef_walk_sqrt_s) * dt_s)
        if self.fix_bias_sd_m > 0:
            ab = math.exp(-dt_s / self.fix_bias_tau_s)
            F[BE, BE] = F[BN, BN] = ab
            x[BE] *= ab
            x[BN] *= ab
            Q[BE, BE] = Q[BN, BN] = self.fix_bias_sd_m ** 2 * (1.0 - ab * ab)
        # the epoch's own white speed and heading noise, mapped into the position
        v = self.speed(self._state.x, reg)
        psi = psi_pdr + self._state.x[DPSI]
        c, s = math.cos(psi), math.sin(psi)
        G = np.array([[dt_s * c, -v * dt_s * s], [dt_s * s, v * dt_s * c]])
        Q[:2, :2] += G @ np.diag([self.step_speed_sd_m_s ** 2, self.step_heading_sd_rad ** 2]) @ G.T
        P = F @ self._state.P @ F.T + Q
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            return 0.0
        st = self._state
        moved = math.hypot(x[E] - st.x[E], x[N] - st.x[N])
        st.x, st.P = x, 0.5 * (P + P.T)
        st.reg, st.psi_pdr, st.t_ns = reg, float(psi_pdr), int(t_ns)
        return moved

    def dead_reckon(self, t_ns: int, length_m: float, heading_rad: float) -> None:
        """An epoch without eq.-1 regressors (the first 2 s): the position moves by the step model's ``length_m``
        along the PDR heading ``heading_rad`` corrected by the heading error; the covariance stays."""
        st = self._state
        psi = heading_rad + float(st.x[DPSI])
        st.x[E] += length_m * math.cos(psi)
        st.x[N] += length_m * math.sin(psi)
        st.psi_pdr, st.t_ns = float(heading_rad), int(t_ns)

    # -- GPS ----------------------------------------------------------------------------
    def _since_s(self, t_ns: int, max_s: float) -> float:
        if self._state.t_ns is None or not np.all(np.isfinite(self._state.reg)):
            return 0.0
        since = (t_ns - self._state.t_ns) * 1e-9
        return min(since, max_s) if since > 0.0 else 0.0

    def fix_prediction(self, t_ns: int, max_s: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
        """``h(x)`` of a position fix at ``t_ns`` and its Jacobian: the last epoch moved on to the fix (by at most
        ``max_s`` of walking: a longer gap is a pause, and the walker stands there rather than snapping back
        to the last epoch as before issue #26), plus the fix's correlated error (the bias states)."""
        tau = self._since_s(t_ns, max_s)
        if tau == 0.0:
            H = np.zeros((2, NX))
            H[0, E] = H[1, N] = 1.0
            pos = self._state.x[:2].copy()
        else:
            pos = self.move(self._state.x, self._state.reg, self._state.psi_pdr, tau)[:2]
            H = self.move_jacobian(self._state.x, self._state.reg, self._state.psi_pdr, tau)[:2]
        H[0, BE] = H[1, BN] = 1.0
        return pos + self._state.x[BE:BN + 1], H

    def update_position(self, t_ns: int, east_m: float, north_m: float, sigma_m: float, *,
                        gate: bool = True, frozen=()) -> UpdateResult:
        sig_before = sigma_max_m((self._state.P[0, 0], self._state.P[0, 1], self._state.P[1, 1]))
        if not (math.isfinite(east_m) and math.isfinite(north_m) and sigma_m > 0 and math.isfinite(sigma_m)):
            return UpdateResult(False, (math.nan, math.nan), math.nan, 0.0, sig_before, "not finite")
        pred, H = self.fix_prediction(t_ns)
        innov = np.array([east_m, north_m]) - pred
        before = self._state.x[:2].copy()
        st = self._state
        ok, nis, st.x, st.P = kalman_update(st.x, st.P, innov, H, np.eye(2) * sigma_m ** 2,
                                            self.gate_nis_2d if gate else math.inf, zero_gain_rows=frozen,
                                            angle_index=DPSI)
        moved = float(np.hypot(*(st.x[:2] - before))) if ok else 0.0
        reason = "" if ok else f"innovation gate: NIS {nis:.1f} > {self.gate_nis_2d:.1f}"
        return UpdateResult(ok, (float(innov[0]), float(innov[1])), nis, moved, sig_before, reason)

    def velocity_prediction(self) -> tuple[np.ndarray, np.ndarray]:
        """``h(x) = v (cos psi, sin psi)`` of a GPS velocity and its Jacobian."""
        x, reg = self._state.x, self._state.reg
        v = self.speed(x, reg)
        psi = self._state.psi_pdr + x[DPSI]
        c, s = math.cos(psi), math.sin(psi)
        H = np.zeros((2, NX))
        for row, u, du in ((0, c, -s), (1, s, c)):
            H[row, DV] = u
            H[row, DPSI] = v * du
            H[row, A:C + 1] = reg * u
        return np.array([v * c, v * s]), H

    def update_velocity(self, speed_m_s: float, course_rad: float, sigma_m_s: float, *, use_speed: bool = True,
                        speed_sd_m_s: float = 0.0) -> UpdateResult:
        """A GPS velocity: speed and course (rad, CCW from East) as East/North components, or the speed alone.

        ``use_speed=False``: the course alone, as the velocity's component across it (``z = 0``; the speed is
        left to the position fixes).  ``speed_sd_m_s``: a further SD of the speed along the course (a scale's
        uncertainty), added to the along-track variance."""
        if not (self._state.initialized and np.all(np.isfinite(self._state.reg)) and math.isfinite(self._state.psi_pdr)
                and math.isfinite(speed_m_s) and sigma_m_s > 0):
            return UpdateResult(False, (math.nan,), math.nan, reason="no epoch or not finite")
        if math.isfinite(course_rad):
            pred, H = self.velocity_prediction()
            u = np.array([math.cos(course_rad), math.sin(course_rad)])
            if use_speed:
                z = speed_m_s * u
                gate, R = self.gate_nis_2d, np.eye(2) * sigma_m_s ** 2 + speed_sd_m_s ** 2 * np.outer(u, u)
            else:  # the course as an angle: the heading alone (a cross-track velocity would also shrink the speed)
                H = np.zeros((1, NX))
                H[0, DPSI] = 1.0
                pred, z = np.array([self.heading()]), np.array([course_rad])
                gate, R = self.gate_nis_1d, np.array([[(sigma_m_s / max(speed_m_s, 0.1)) ** 2]])
        elif use_speed:
            pred = np.array([self.speed(self._state.x, self._state.reg)])
            H = np.zeros((1, NX))
            H[0, DV] = 1.0
            H[0, A:C + 1] = self._state.reg
            z = np.array([speed_m_s])
            gate, R = self.gate_nis_1d, np.array([[sigma_m_s ** 2 + speed_sd_m_s ** 2]])
        else:
            return UpdateResult(False, (math.nan,), math.nan, reason="no course, and the speed is not used")
        innov = z - pred
        if math.isfinite(course_rad) and not use_speed:
            innov[0] = wrap_angle(float(innov[0]))
        st = self._state
        ok, nis, st.x, st.P = kalman_update(st.x, st.P, innov, H, R, gate, angle_index=DPSI)
        return UpdateResult(ok, tuple(float(v) for v in innov), nis,
                            reason="" if ok else f"velocity gate: NIS {nis:.1f} > {gate:.1f}")

    def place_on_fix(self, sigma_m: float) -> None:
        """The position was just restarted on a fix by a relock (the fix's white per-axis SD ``sigma_m``): the
        fix's correlated error estimate (the bias states), which the restart left in place, moves into the
        position and starts at 0 with its prior variance, the position's error being that fix's whole error
        (variance ``sigma^2 + fix_bias_sd^2``, covariance ``-fix_bias_sd^2`` with the bias error).  Before, the
        bias a drifting track had built up against the fixes stayed: on the tuning walk thomasdingemanse_lopen
        the track then ran 6-10 m beside the fixes for minutes after the hold ended."""
        if self.fix_bias_sd_m <= 0.0 or not (math.isfinite(sigma_m) and sigma_m > 0):
            return
        b2 = self.fix_bias_sd_m ** 2
        x, P = self._state.x, self._state.P
        x[:2] += x[BE:BN + 1]
        x[BE:BN + 1] = 0.0
        for rows in ([E, N], [BE, BN]):
            P[rows, :] = 0.0
            P[:, rows] = 0.0
        P[E, E] = P[N, N] = sigma_m ** 2 + b2
        P[BE, BE] = P[BN, BN] = b2
        P[E, BE] = P[BE, E] = P[N, BN] = P[BN, N] = -b2

    def set_position(self, east_m: float, north_m: float) -> None:
        """Move the position to ``(east_m, north_m)`` (m), its covariance unchanged (a dead-reckoned step while GPS
        is not trusted: :meth:`core.gnss.base.FixFusion._dead_reckon`)."""
        self._state.x[E], self._state.x[N] = east_m, north_m

    def restart_position(self, innovation, sigma_m: float) -> None:
        """Restart the position on a fix: moved by the fix's ``innovation`` (E, N; None: not moved), its correlations
        with the other states dropped, its per-axis SD the fix's ``sigma_m`` (the anchor, the consistent-stream
        relock of :class:`core.gnss.base.FixFusion` and of the shadow filter; :meth:`place_on_fix` may follow)."""
        restart_position_of(self._state.x, self._state.P, innovation, sigma_m)

    def widen_position(self, offset_m) -> None:
        """Widen the position's covariance by the outer product of ``offset_m`` (E, N) (a relock's disagreement; a
        non-finite offset is ignored, as :meth:`core.gnss.ekf.PdrEkf.widen_position` does)."""
        d = np.asarray(offset_m, dtype=float)
        if np.all(np.isfinite(d)):
            self._state.P[:2, :2] += np.outer(d, d)

    def widen_heading(self, sd_rad: float) -> None:
        """The heading error's variance at least ``sd_rad^2`` (its correlations kept: a larger diagonal stays a
        covariance; a relock's heading error, :meth:`KubrakFusion._after_relock`)."""
        P = self._state.P
        P[DPSI, DPSI] = max(float(P[DPSI, DPSI]), sd_rad ** 2)

    def revert_coefficients(self, coef: np.ndarray, Pc: np.ndarray, cover: bool) -> None:
        """The coefficients set to ``coef`` with covariance ``Pc`` (``cover``: at least the current one too, in
        the PSD sense), uncorrelated with the other states, as a new start of them (the coefficient test's
        correction, :meth:`KubrakFusion._check_variability`)."""
        x, P = self._state.x, self._state.P
        x[COEF] = coef
        keep = P[COEF, COEF].copy()
        P[COEF, :] = 0.0
        P[:, COEF] = 0.0
        P[COEF, COEF] = covariance_cover(Pc, keep) if cover else Pc

    def position_sigma_m(self) -> float:
        P = self._state.P
        return sigma_max_m((P[0, 0], P[0, 1], P[1, 1]))

    def align_heading(self, offset_rad: float, sd_rad: float) -> None:
        """Coarse alignment: the heading error set from GPS courses (its correlations dropped, as a new start)."""
        x, P = self._state.x, self._state.P
        x[DPSI] = wrap_angle(float(offset_rad))
        P[DPSI, :] = 0.0
        P[:, DPSI] = 0.0
        P[DPSI, DPSI] = sd_rad ** 2


@dataclass(slots=True)
class KubrakFusionState:
    """What :class:`KubrakFusion` remembers besides :class:`core.gnss.base.FixFusionState` and its filters' own
    states: made by :meth:`initial` in ``reset()``; read from outside through :class:`KubrakFusion`'s read-only
    properties of the public names (``shadow``, ``shadow_events``, ``unreliable_until_ns``, ``n_variability``,
    ``n_velocity_used``, ``n_velocity_gated``, ``variability_events``, ``aligned``)."""

    shadow: KubrakKf | None  #: the filter run on without the unreliable stream's fixes (None: no hold)
    shadow_gated_since_ns: int | None  #: the shadow's first gated fix since it last took one
    shadow_accept_ns: int | None  #: the shadow's last accepted fix (or its start)
    shadow_events: list  #: the shadow's consistent-stream relocks and the holds it ended by handing over (issue #26)
    #: (t_ns, coefficients (3,), their covariance (3, 3)) after every GPS update, the last few minutes
    coef_hist: deque
    shadow_hist: deque  #: the same of the shadow
    reg_hist: deque  #: (t_ns, regressors) of the walking epochs, last mean_window_s
    unreliable_until_ns: int | None  #: the variability test's hold on GPS lasts until then (None: no hold)
    n_variability: int  #: times the variability test fired
    n_velocity_used: int
    n_velocity_gated: int
    variability_events: list  #: when, how much, what the coefficients became
    last_walked: float  #: the last epoch's distance (m)
    last_verdict: str  #: the variability test's last reason (the filter's verdict while the hold lasts)
    aligned: bool  #: the coarse heading alignment is done
    align: deque  #: (course - PDR heading) of moving fixes until it is done; only the last 2 align_fixes count

    @classmethod
    def initial(cls, *, shadow_events, variability_events, align_fixes: int) -> KubrakFusionState:
        return cls(shadow=None, shadow_gated_since_ns=None, shadow_accept_ns=None, shadow_events=shadow_events,
                   coef_hist=deque(), shadow_hist=deque(), reg_hist=deque(), unreliable_until_ns=None,
                   n_variability=0, n_velocity_used=0, n_velocity_gated=0, variability_events=variability_events,
                   last_walked=0.0, last_verdict="", aligned=False, align=deque(maxlen=2 * max(align_fixes, 1)))


class KubrakFusion(FixFusion):
    """The real-time GPS/PNS fusion of Kubrak et al. (2006) as a streaming stage (see the module docstring).

    Parameters
    ----------
    kf : KubrakKf or None
        The filter with its noise settings (a prototype: each run starts a copy); default ``KubrakKf()``.
    velocity_model : VelocityModel or None
        eq. 1's starting coefficients (what earlier walks taught, :func:`profile_with_learning`),
        when no ``kf`` is given; default the shipped ones.
    use_velocity : bool
        Use the GPS Doppler velocity (speed and course) as a measurement.
    doppler_speed : DopplerSpeed
        How its speed is used: as reported (the paper), corrected by a scale learnt from position chords over
        long straight stretches (``speed_trainer``: on several phones the Doppler speed reads 15-25 % low
        against the chords, issue #26, and the velocity model then learns a walker too slow for every outage),
        or not at all (the course alone).
        ``CHORD_SCALED`` (the default): on the tuning walk ``thomasdingemanse_lopen`` the Doppler speed reads
        27 % below the chords in the first minute and the model learnt a walker 25 % slower than the steps;
        1-/3-minute outage end errors 88.8 / 56.5 % (raw) -> 82.5 / 47.6 % (median of 3 / 1 outages).  The
        simulator's tuning seeds 0-19, 5-minute outage: with the Doppler speed scaled 0.8, median 9.82 -> 2.94 %;
        with its unbiased Doppler a small cost, median 2.50 -> 2.55 % (mean 3.67 -> 3.99 %: the chord scale's
        own noise, a few per cent per walk).
    speed_trainer : OnlineTrainer or None
        The chord trainer of ``DopplerSpeed.CHORD_SCALED`` (a prototype: each run starts a copy; its
        ``reference`` is set to the Doppler speed); default ``OnlineTrainer(learn_heading=False)``.
    doppler_min_chords : int
        ``CHORD_SCALED``: the Doppler speed is used once this many chord samples have measured its scale; until
        then the course alone (a speed no chord has checked must not train the model: see above).
    velocity_sd_m_s : float
        SD of a GPS velocity component (m/s).
    velocity_min_speed_m_s : float
        The course is used from this reported speed on (below it, the speed alone).
    detect_variability : bool
        The paper's bad-GPS test on the coefficients.
    variability_window_s : float
        Window over which the coefficients' predicted speed may not jump (s).
    max_speed_change_m_s : float
        Largest change of that speed over the window a walker's pace allows (m/s) ...
    variability_gate : float
        ... when the change is also beyond this chi-square (1 dof) of what the filter expected.
    mean_window_s : float
        The coefficients are replaced by their mean over this much time before the window (s).
    unreliable_hold_s : float
        How long GPS stays unreliable after the test fired (s), extended while the shadow filter's
        coefficients keep varying.
    align_fixes, align_min_speed_m_s, align_max_sd_rad : int, float, float
        Coarse heading alignment before the filter learns: the heading error is set to the circular mean of
        (GPS course - PDR heading) over ``align_fixes`` fixes of a receiver moving at least this fast, once
        their circular SD (over the last ``2 align_fixes``) is below ``align_max_sd_rad``; until then fixes
        move the position only and the GPS velocity is not used (courses that scatter, as indoors, are
        never taken for the phone's offset).
    adopt_on_relock : bool
        With ``adopt_shadow``: a shadow that re-locks to a consistent stream ends the hold there (the next fix hands
        its state over), rather than at the hold's end: the relock showed the fixes right and the filter, which
        took none, no better than the shadow was.  On by the tuning split: ``thomasdingemanse_lopen`` with every
        10th fix left out, the longest stretch of good fixes all refused 43 -> 30 s, ratio 1.07 -> 1.04; the
        simulator's tuning fault walks and the IPIN tuning routes unchanged.
    adopt_shadow : bool
        While GPS is declared unreliable, the shadow filter re-locks to a stream the judge found consistent
        for ``relock_s`` (rather than rejecting it, each rejection extending the hold), and at the end of the
        hold a shadow that took a fix within ``relock_s`` becomes the filter (see the module docstring).
        False: the paper's rule alone (the shadow only decides when the hold ends).  On (the default) by the
        tuning split: on ``thomasdingemanse_lopen`` the leave-out ratio 8.5 -> 1.42, the longest stretch of good
        fixes all refused 192 -> 57 s, 1-min outages median 82.5 -> 54.2 % (the third 117.5 -> 27.2 %), 3-min
        47.6 % either way; the simulator's fault walks (seeds 0-9) and the IPIN tuning routes unchanged (the
        coefficient test never fires there with the judge on).
    relock_s, relock_max_drift : float
        As :class:`core.gnss.base.FixFusion`'s, stricter than Chen's defaults (8 s, no drift limit):
        a minute-long multipath offset must not be taken for the track's own error.
    **shared
        The fix handling's settings (:class:`core.gnss.base.FixFusion`).
    """

    name = "kubrak"

    def __init__(self, *, kf: KubrakKf | None = None, velocity_model: VelocityModel | None = None,
                 use_velocity: bool = True, doppler_speed: DopplerSpeed = DopplerSpeed.CHORD_SCALED,
                 speed_trainer: OnlineTrainer | None = None, doppler_min_chords: int = 1,
                 velocity_sd_m_s: float = 0.3,
                 velocity_min_speed_m_s: float = 0.5, detect_variability: bool = True,
                 variability_window_s: float = 20.0, max_speed_change_m_s: float = 0.04,
                 variability_gate: float = CHI2_999[1], mean_window_s: float = 60.0,
                 unreliable_hold_s: float = 30.0, relock_s: float = 20.0, relock_max_drift: float | None = 0.15,
                 align_fixes: int = 5, align_min_speed_m_s: float = 0.8, align_max_sd_rad: float = math.radians(20.0),
                 adopt_shadow: bool = True, adopt_on_relock: bool = True, **shared):
        super().__init__(relock_s=relock_s, relock_max_drift=relock_max_drift, **shared)
        if kf is None and velocity_model is not None:
            kf = KubrakKf(velocity_model)
        self._kf_proto = kf
        self.use_velocity = bool(use_velocity)
        self.doppler_speed = DopplerSpeed(doppler_speed)
        self._speed_trainer_proto = speed_trainer
        self.doppler_min_chords = int(doppler_min_chords)
        self.velocity_sd_m_s = float(velocity_sd_m_s)
        self.velocity_min_speed_m_s = float(velocity_min_speed_m_s)
        self.detect_variability = bool(detect_variability)
        self.variability_window_ns = int(variability_window_s * 1e9)
        self.max_speed_change_m_s = float(max_speed_change_m_s)
        self.variability_gate = float(variability_gate)
        self.mean_window_ns = int(mean_window_s * 1e9)
        self.unreliable_hold_ns = int(unreliable_hold_s * 1e9)
        self.align_fixes = int(align_fixes)
        self.align_min_speed_m_s = float(align_min_speed_m_s)
        self.align_max_sd_rad = float(align_max_sd_rad)
        self.adopt_shadow = bool(adopt_shadow)
        self.adopt_on_relock = bool(adopt_on_relock)
        self.reset()

    def _reset_filter(self) -> None:
        self.kf = KubrakKf() if self._kf_proto is None else copy.deepcopy(self._kf_proto)
        self.kf.reset()
        #: the Doppler speed's chord scale (``DopplerSpeed.CHORD_SCALED``), else None
        self.speed_trainer: OnlineTrainer | None = None
        if self.doppler_speed is DopplerSpeed.CHORD_SCALED:
            self.speed_trainer = copy.deepcopy(self._speed_trainer_proto) if self._speed_trainer_proto is not None \
                else OnlineTrainer(learn_heading=False, keep_windows=None if self.keep_history else EVENTS_KEEP_LAST)
            self.speed_trainer.reference = ChordReference.DOPPLER
            self.speed_trainer.learn_heading = False
            self.speed_trainer.reset()
        self._kub = KubrakFusionState.initial(shadow_events=self._events(), variability_events=self._events(),
                                              align_fixes=self.align_fixes)

    @property
    def filt(self) -> KubrakKf:
        return self.kf

    # -- read-only views of the state -----------------------------------------------------------------------
    shadow = property(lambda self: self._kub.shadow, doc="The filter run on without the unreliable stream's fixes "
                                                         "while the variability hold lasts (None: none).")
    shadow_events = property(lambda self: self._kub.shadow_events, doc="The shadow's consistent-stream relocks and "
                                                                       "the holds it ended by handing its state over.")
    unreliable_until_ns = property(lambda self: self._kub.unreliable_until_ns,
                                   doc="The variability test's hold on GPS lasts until then (None: no hold).")
    n_variability = property(lambda self: self._kub.n_variability, doc="Times the variability test fired.")
    n_velocity_used = property(lambda self: self._kub.n_velocity_used)
    n_velocity_gated = property(lambda self: self._kub.n_velocity_gated)
    variability_events = property(lambda self: self._kub.variability_events,
                                  doc="When the variability test fired, how much, what the coefficients became.")
    aligned = property(lambda self: self._kub.aligned, doc="The coarse heading alignment is done.")

    def _init_filter_at(self, sigma_m: float) -> None:
        self.kf.initialize(0.0, 0.0, sigma_m)

    # -- epochs ---------------------------------------------------------------------------
    def _before_fixes(self, step, t_prev_ns: int) -> None:
        if self.speed_trainer is not None:  # before the fixes it spans, as Chen's trainer (core.gnss.fusion)
            self.speed_trainer.add_step(step.t_ns, t_prev_ns, step.length_m, step.heading_rad)

    def _step(self, step, t_prev_ns: int, dur_ns: int) -> float:
        kf = self.kf
        if not kf.initialized:
            kf.initialize(0.0, 0.0, self.start[2] if self.start is not None else 0.1)
        reg = np.array(step_regressors(step.features), dtype=float)
        dt = (step.t_ns - t_prev_ns) * 1e-9
        if not np.all(np.isfinite(reg)):
            # no eq.-1 window yet (the first 2 s): the epoch moves by the step model's length instead
            reg = kf.reg if np.all(np.isfinite(kf.reg)) else None
        if reg is None:
            walked = step.length_m
            kf.dead_reckon(step.t_ns, walked, step.heading_rad)
        else:
            walked = kf.epoch(step.t_ns, dt, reg, step.heading_rad)
            self._kub.reg_hist.append((step.t_ns, reg))
            while self._kub.reg_hist[0][0] < step.t_ns - self.mean_window_ns:
                self._kub.reg_hist.popleft()
            if self._kub.shadow is not None:
                self._kub.shadow.epoch(step.t_ns, dt, reg, step.heading_rad)
        self._kub.last_walked = walked
        return walked

    def _step_output(self) -> tuple[float, float]:
        return self._kub.last_walked, self.kf.heading()

    def _dead_reckoned_step(self, step) -> tuple[float, float]:
        self._kub.last_walked = step.length_m
        return step.length_m, wrap_angle(step.heading_rad + float(self.kf.x[DPSI]))

    # -- fixes ------------------------------------------------------------------------------
    def _predict_fix(self, t_ns: int):
        return self.kf.fix_prediction(t_ns)[0]

    def _update_position(self, t_ns: int, east: float, north: float, sigma_m: float, gate: bool) -> UpdateResult:
        # before the coarse alignment the heading error may be anything: fixes move the position only
        frozen = () if self._kub.aligned else (DV, DPSI, A, B, C)
        return self.kf.update_position(t_ns, east, north, sigma_m, gate=gate, frozen=frozen)

    def _try_align(self, speed: float, course: float) -> None:  # course: rad, CCW from East, as of now
        """Coarse alignment from the GPS course of a walking receiver: the phone's yaw offset (a pocket, a bag,
        the back of an upright phone) may be anything, far beyond what the EKF's linearisation can learn."""
        kf = self.kf
        if not (math.isfinite(course) and speed >= self.align_min_speed_m_s and math.isfinite(kf.psi_pdr)):
            return
        self._kub.align.append(wrap_angle(course - kf.psi_pdr))
        if len(self._kub.align) < self.align_fixes:
            return
        a = np.array(self._kub.align)
        r = math.hypot(float(np.mean(np.cos(a))), float(np.mean(np.sin(a))))
        sd = math.sqrt(-2.0 * math.log(max(min(r, 1.0), 1e-12)))
        if sd > self.align_max_sd_rad:
            return  # turning, or courses that scatter (indoors): wait for a steadier stretch, never guess
        kf.align_heading(math.atan2(float(np.mean(np.sin(a))), float(np.mean(np.cos(a)))),
                         max(sd / math.sqrt(len(a)) * 3.0, kf.heading_bias_sd_rad / 3.0))
        self._kub.aligned = True

    def _filter_verdict(self, t_ns: int) -> str:
        """GPS declared unreliable by the coefficient test: the shadow filter takes the fix instead."""
        until = self._kub.unreliable_until_ns
        if until is None:
            return ""
        if t_ns >= until:
            self._kub.unreliable_until_ns = None
            sh = self._kub.shadow
            if self.adopt_shadow and sh is not None and self._kub.shadow_accept_ns is not None and \
                    t_ns - self._kub.shadow_accept_ns <= self.relock_ns:
                # the shadow follows the fixes (it took one within relock_s): its state, learnt from them while the
                # main filter waited with the reverted coefficients, becomes the filter's
                self._count_move("shadow adopted", t_ns, float(np.hypot(*(sh.x[:2] - self.kf.x[:2]))),
                                 self.kf.position_sigma_m())
                self.kf = sh
                self._kub.coef_hist.clear()
                self._record_coef(self._kub.coef_hist, t_ns, sh)
                self._kub.shadow_events.append({"t_ns": int(t_ns), "event": "adopted"})
            self._kub.shadow_hist.clear()
            self._kub.shadow = None
            return ""
        return self._kub.last_verdict

    def _learn_from_fix(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        if self.speed_trainer is not None:
            self.speed_trainer.add_fix(t_ns, east, north, hacc, speed,
                                       heading_from_bearing_deg(course) if math.isfinite(course) else math.nan)

    def _velocity(self, kf: KubrakKf, t_ns: int, speed: float, course: float) -> UpdateResult:
        """A fix's Doppler velocity into ``kf`` (the filter or its shadow), its speed as :attr:`doppler_speed` says."""
        c = self.course_now(t_ns, heading_from_bearing_deg(course)) \
            if speed >= self.velocity_min_speed_m_s and math.isfinite(course) else math.nan
        tr = self.speed_trainer
        if tr is not None:  # the speed once chords have measured its scale, the course alone until then
            return kf.update_velocity(speed * tr.stride_scale, c, self.velocity_sd_m_s,
                                      use_speed=tr.n_stride_samples >= self.doppler_min_chords,
                                      speed_sd_m_s=speed * tr.stride_scale * tr.stride_scale_sd)
        return kf.update_velocity(speed, c, self.velocity_sd_m_s,
                                  use_speed=self.doppler_speed is not DopplerSpeed.COURSE_ONLY)

    def _after_accept(self, t_ns: int, east: float, north: float, hacc: float, speed: float, course: float) -> None:
        kf = self.kf
        self._learn_from_fix(t_ns, east, north, hacc, speed, course)
        if not self._kub.aligned:
            self._try_align(speed, self.course_now(t_ns, heading_from_bearing_deg(course)) if math.isfinite(course)
                            else math.nan)
            return
        if self.use_velocity and math.isfinite(speed) and self.anchor is not None and self.anchor[0] != t_ns:
            res = self._velocity(kf, t_ns, speed, course)
            if res.accepted:
                self._kub.n_velocity_used += 1
            elif res.nis == res.nis:
                self._kub.n_velocity_gated += 1
        if self.detect_variability:
            self._check_variability(t_ns)

    # -- the coefficient test --------------------------------------------------------------------
    def _reference_regressors(self) -> np.ndarray | None:
        if not self._kub.reg_hist:
            return None
        return np.mean(np.array([r for _, r in self._kub.reg_hist]), axis=0)

    def _variability(self, hist: deque, t_ns: int, ref: np.ndarray, kf: KubrakKf) -> tuple[float, float]:
        """(change of the predicted speed over the window (m/s), its chi-square against what the filter expected).

        (0, 0) until the history reaches half a minute (``mean_window_s / 2``) before the window: the first
        learning after a start (or after a revert) is the coefficients' legitimate convergence, and there
        would be nothing to revert to.
        """
        limit = t_ns - self.variability_window_ns
        if not hist or hist[0][0] > limit - self.mean_window_ns // 2:
            return 0.0, 0.0
        old = None
        for h in hist:
            if h[0] >= limit:
                old = h
                break
        if old is None or old[0] == t_ns:
            return 0.0, 0.0
        now_c, now_P = kf.x[COEF], kf.P[COEF, COEF]
        dv = float(ref @ (now_c - old[1]))
        # a consistent filter's estimate moves by at most what its updates removed from the variance, plus the walk
        removed = float(ref @ (old[2] - now_P) @ ref)
        walk = float(ref @ np.diag(np.square(kf.coef_walk_sqrt_s)) @ ref) * (t_ns - old[0]) * 1e-9
        return dv, dv * dv / max(removed + walk, 1e-12)

    def _record_coef(self, hist: deque, t_ns: int, kf: KubrakKf) -> None:
        hist.append((t_ns, kf.x[COEF].copy(), kf.P[COEF, COEF].copy()))
        keep = self.variability_window_ns + self.mean_window_ns + int(5e9)
        while hist[0][0] < t_ns - keep:
            hist.popleft()

    def _check_variability(self, t_ns: int) -> None:
        kf = self.kf
        self._record_coef(self._kub.coef_hist, t_ns, kf)
        ref = self._reference_regressors()
        if ref is None:
            return
        dv, chi2 = self._variability(self._kub.coef_hist, t_ns, ref, kf)
        if abs(dv) <= self.max_speed_change_m_s or chi2 <= self.variability_gate:
            return
        # the paper's correction: the coefficients' mean over the minute before the window
        limit = t_ns - self.variability_window_ns
        before = [(c, P) for t, c, P in self._kub.coef_hist if limit - self.mean_window_ns <= t < limit]
        if before:
            coef = np.mean(np.array([c for c, _ in before]), axis=0)
            Pc = before[-1][1]
        else:
            m = kf.model
            coef, Pc = m.coefficients, np.diag(np.square(m.sd))
        self._revert_coefficients(coef, Pc, bool(before))
        self._kub.n_variability += 1
        self._kub.last_verdict = (f"GPS unreliable: the velocity model's coefficients changed the walker's speed by "
                              f"{dv:+.2f} m/s in {self.variability_window_ns * 1e-9:.0f} s")
        self._kub.variability_events.append({"t_ns": int(t_ns), "speed_change_m_s": dv, "chi2": chi2,
                                        "coefficients": [float(c) for c in coef]})
        self._kub.unreliable_until_ns = t_ns + self.unreliable_hold_ns
        self._kub.coef_hist.clear()
        self._record_coef(self._kub.coef_hist, t_ns, kf)
        self._start_shadow(t_ns)

    def _start_shadow(self, t_ns: int) -> None:
        """A shadow copy of the filter (as it is now) that keeps taking the fixes while GPS is unreliable."""
        self._kub.shadow = copy.deepcopy(self.kf)
        self._kub.shadow_hist.clear()
        self._record_coef(self._kub.shadow_hist, t_ns, self._kub.shadow)
        self._kub.shadow_gated_since_ns = None
        self._kub.shadow_accept_ns = t_ns

    def _revert_coefficients(self, coef: np.ndarray, Pc: np.ndarray, cover: bool) -> None:
        """The coefficients set to ``coef`` with covariance ``Pc`` (``cover``: at least the current one too, in
        the PSD sense), uncorrelated with the other states, as a new start of them."""
        self.kf.revert_coefficients(coef, Pc, cover)

    def _placed_on_fix(self, t_ns: int, sigma_m: float, relock: bool = False) -> None:
        if relock:
            self.kf.place_on_fix(sigma_m)

    def _after_relock(self, offset_m: float, walked_m: float) -> None:
        """The track ended ``offset_m`` off after ``walked_m`` of walking: the heading error that showed
        (:func:`core.gnss.base.relock_heading_error_rad`) joins the heading state's variance (its correlations kept:
        a larger diagonal stays a covariance), so that the next fixes correct the heading instead of the track
        drifting off again with it (issue #26: on a simulated walk whose phone turned 45 deg in the hand during an
        outage the track was 17-21 m off again 2-7 s after the relock, and the filter needed a second one)."""
        self.kf.widen_heading(relock_heading_error_rad(offset_m, walked_m))

    def _filter_rejected(self, t_ns: int, east: float, north: float, sigma_m: float, speed: float,
                         course: float) -> None:
        """While GPS is unreliable the shadow filter takes the fixes; if its coefficients vary too, the hold goes on."""
        sh = self._kub.shadow
        if sh is None:
            return
        res = sh.update_position(t_ns, east, north, sigma_m)
        if not res.accepted:
            if self._kub.shadow_gated_since_ns is None:
                self._kub.shadow_gated_since_ns = t_ns
            if not (self.adopt_shadow and
                    self._consistent_stream(t_ns, self._kub.shadow_gated_since_ns, self._kub.shadow_accept_ns)):
                self._kub.unreliable_until_ns = max(self._kub.unreliable_until_ns, t_ns + self.unreliable_hold_ns // 2)
                return
            # the base class's consistent-stream relock, for the shadow: it lost the track, not GPS
            sh.restart_position(res.innovation, sigma_m)
            sh.place_on_fix(sigma_m)
            self._kub.shadow_events.append({"t_ns": int(t_ns), "event": "relocked",
                                       "offset_m": float(math.hypot(*res.innovation)),
                                       "consistent_s": self._consistent_s(t_ns)})
            if self.adopt_on_relock:
                self._kub.unreliable_until_ns = t_ns  # the hold ends: the next fix hands the shadow's state over
        self._kub.shadow_gated_since_ns = None
        self._kub.shadow_accept_ns = t_ns
        if self.use_velocity and math.isfinite(speed):
            self._velocity(sh, t_ns, speed, course)
        self._record_coef(self._kub.shadow_hist, t_ns, sh)
        ref = self._reference_regressors()
        if ref is None:
            return
        dv, chi2 = self._variability(self._kub.shadow_hist, t_ns, ref, sh)
        if abs(dv) > self.max_speed_change_m_s and chi2 > self.variability_gate:
            self._kub.unreliable_until_ns = t_ns + self.unreliable_hold_ns
            self._start_shadow(t_ns)

    # -- output ------------------------------------------------------------------------------------
    def status(self) -> dict:
        kf = self.kf
        return {**super().status(), "speed_model_m_s": kf.speed(kf.x, kf.reg) if kf.initialized else math.nan,
                "gps_unreliable": self._kub.unreliable_until_ns is not None}

    def counters(self) -> dict:
        kf = self.kf
        return {**super().counters(), "variability_detections": self._kub.n_variability,
                "velocity_used": self._kub.n_velocity_used, "velocity_gated": self._kub.n_velocity_gated,
                "doppler_speed": self.doppler_speed.value,
                "doppler_scale": self.speed_trainer.stride_scale if self.speed_trainer is not None else None,
                "doppler_scale_samples": self.speed_trainer.n_stride_samples if self.speed_trainer is not None else 0,
                "coefficients": [float(v) for v in kf.x[COEF]],
                "heading_bias_deg": math.degrees(float(kf.x[DPSI])),
                "variability_events": list(self.variability_events), "shadow_events": list(self.shadow_events)}


#: GPS-aided walking (m) a walk needs before what it taught goes into the profile
MIN_PROFILE_WALKED_M = 200.0


def learned_model(fusion: KubrakFusion) -> VelocityModel | None:
    """eq. 1's coefficients as the walk's GPS left them, with their SDs (never below half the prior's:
    the next walk may be at another pace); None when GPS aided too little walking to say."""
    kf = fusion.kf
    walked = fusion.fused_walked_m
    if not kf.initialized or walked < MIN_PROFILE_WALKED_M or fusion.n_velocity_used < 60:
        return None
    prior = kf.model
    sd = np.sqrt(np.maximum(np.diag(kf.P[COEF, COEF]), 0.0))
    sd = tuple(float(max(a, 0.5 * b)) for a, b in zip(sd, prior.sd))
    c = kf.x[COEF]
    return VelocityModel(float(c[0]), float(c[1]), float(c[2]), sd=sd, max_speed_m_s=prior.max_speed_m_s)


def settings_from_profile(profile) -> dict:
    """``KubrakFusion`` keywords that start from what earlier walks taught (``UserProfile.gps["velocity_model"]``)."""
    d = (getattr(profile, "gps", None) or {}).get("velocity_model")
    if not isinstance(d, dict):
        return {}
    try:
        return {"velocity_model": VelocityModel.from_dict(d)}
    except (KeyError, TypeError, ValueError):
        return {}


def profile_with_learning(profile, fusion: KubrakFusion, now=None):
    """A new profile with the velocity model this walk's GPS taught; ``profile`` itself if it taught too little."""
    from dataclasses import replace
    from datetime import datetime, timezone

    model = learned_model(fusion)
    if model is None:
        return profile
    gps = dict(getattr(profile, "gps", None) or {})
    gps["velocity_model"] = model.to_dict()
    gps["updated"] = (now or datetime.now(timezone.utc)).isoformat(timespec="seconds")
    return replace(profile, gps=gps)
