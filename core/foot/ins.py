"""Strapdown INS of a foot-mounted IMU with an error-state EKF and zero-velocity updates (INS-EKF-ZUPT).

Song & Park 2018, section 2, eqs. 7-10, in the project's conventions (ENU,
quaternion body -> ENU, errors "true minus estimate"; see :mod:`core`).

Nominal state: attitude ``q``, velocity ``v_n``, position ``p_n``, gyroscope
bias ``b_g`` and accelerometer bias ``b_a`` (body frame).  Error state (15)::

    dx = (dtheta_n, dv_n, dp_n, db_g, db_a)
    R_true = exp([dtheta_n]x) R(q),  v_true = v + dv,  p_true = p + dp,  b_true = b + db

The paper's eq. 7 has 12 states (no position: ZUPT does not observe it); we
carry the position error too, so that the position covariance is known (for
the course measurements and the consistency tests).  It changes nothing else:
the position block only receives.

Mechanisation, every accelerometer sample with the measured ``T`` (s), trapezoidal between the previous
reading (index 0) and this one (1), each rotated with the attitude of its own time::

    w = (w0 + w1) / 2 - b_g ;  q1 = q0 (x) exp(w T)
    a_i = R(q_i) (f_i - b_a) + g_n,  g_n = (0, 0, -g)
    v <- v + (a0 + a1) T / 2 ;  p <- p + v T + (2 a0 + a1) T^2 / 6

(a first-order version drifts vertically by about 0.7 cm per stride at 200 Hz on the simulator: the
foot's acceleration jumps at lift-off and strike).

Error dynamics (eq. 8 in ENU, errors true - estimate)::

    dtheta' = -R db_g - R n_g
    dv'     = -[f_n]x dtheta - R db_a - R n_a          (eq. 10: S = [f_n]x)
    dp'     = dv
    db_g'   = -beta_g db_g + w_g ,  db_a' = -beta_a db_a + w_a   (first-order Gauss-Markov)

Where the paper's signs differ: its eq. 8 has ``+S`` and ``+C`` for the
velocity row and ``-C`` for the attitude row because its errors are
"estimate minus true" with the attitude error of Titterton's
``C_est = (I - [phi]x) C``; with "true minus estimate" every sign of that row
flips and the attitude row's ``-C`` stays.  In NED the specific force at rest
is ``(0, 0, -g)``, here ``(0, 0, +g)``: ``S`` is built from ENU components.
Heading in ENU is counter-clockwise about Up, in NED clockwise about Down:
the paper's yaw row of eq. 22 (``[.., .., -1]`` on ``dphi_D``) is
``[0, 0, +1]`` on ``dtheta_U`` here.

The transition matrix ``Phi`` is the exact first-order error propagation of
the discrete mechanisation above (tested by finite differences).

A clipped gyroscope reading (option; :mod:`core.foot.saturation`) carries an error beyond the white noise:
an error ``dw`` of a step's rate (the mean of its two readings) moves the error state as a bias error does,
``dx <- dx + Phi[:, BG] dw`` (the bias rows left out: the bias itself is not changed), so the step's ``Q``
gains ``Phi[:9, BG] diag(var) Phi[:9, BG]^T`` (:meth:`ZuptEKF.propagate`).

Measurements (eq. 9 and the options):

* zero velocity during stance: ``z = 0 = v + dv`` -> ``y = -v``, ``H = [0 I 0 0 0]``, ``R = sigma_z^2 I``;
* rolling ZUPT (option, a foot rolling heel-to-toe about a contact point ``r_b`` below the sensor): the
  sensor moves at ``u = R (w x r_b)``, ``w = w_meas - b_g``; with the errors above
  ``z = 0 = v_true - R_true (w_true x r_b) = v - u + dv + [u]x dtheta - R [r_b]x db_g`` ->
  ``y = u - v``, ``H = [[u]x I 0 -R[r_b]x 0]`` (tested by finite differences);
* zero angular rate during stance (option): ``y = w_meas - b_g``, ``H = [0 0 0 I 0]``, only where every axis
  of ``y`` is within ``zaru_gate_rad_s`` (the foot truly still: no heel-to-toe roll);
* a heading angle: ``y = wrap(psi_meas - psi_est) = h . dtheta``, ``H = [h 0 0 0 0]``.

Every update returns its innovation and normalised innovation squared (NIS);
an update whose result would not be finite is discarded and counted.  The
update, the injection and the reset after it (``P <- G P G^T``,
``G = I + [dtheta / 2]x`` on the attitude block) are :mod:`core.kalman`'s,
shared with the phone's attitude filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from core import kalman
from core import quaternion as quat
from core.conventions import STANDARD_GRAVITY_M_S2
from core.kalman import skew

N_STATES = 15
ATT, VEL, POS, BG, BA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)


@dataclass(frozen=True)
class InsSettings:
    """Noise, bias model and priors of :class:`ZuptEKF` (units in the names)."""

    #: angle random walk of the gyroscope (rad/sqrt(s))
    gyro_noise_rad_sqrt_s: float = 0.002
    #: velocity random walk of the accelerometer (m/s/sqrt(s))
    acc_noise_m_s_sqrt_s: float = 0.02
    #: Gauss-Markov gyroscope bias: steady-state sd (rad/s) and time constant 1/beta_g (s)
    gyro_bias_sd_rad_s: float = 0.002
    gyro_bias_tau_s: float = 300.0
    #: Gauss-Markov accelerometer bias: steady-state sd (m/s^2) and time constant 1/beta_a (s)
    acc_bias_sd_m_s2: float = 0.05
    acc_bias_tau_s: float = 300.0
    #: zero-velocity measurement noise sigma_z (m/s)
    zupt_noise_m_s: float = 0.01
    #: zero angular rate updates in stance (the reading is the gyroscope bias: the one measurement of the
    #: vertical bias, which ZUPT does not observe), per sample, with this noise (rad/s) ...
    zero_rate_update: bool = True
    zaru_noise_rad_s: float = 0.02
    #: ... only where the foot is truly still: every axis of ``w_meas - b_g`` within this (rad/s; about 4 x the
    #: PyShoe IMU's per-sample noise at rest, 0.005 rad/s); inf: every stance sample.  The stance phases the
    #: detectors find hold the heel-to-toe roll (tenths of rad/s): ungated, ZARU made tracks 2-5x worse.  On
    #: (2026-12-07, issue #27): PyShoe tuning split, PyShoe's metric median 0.0328 -> 0.0319 m, mean 0.0369 ->
    #: 0.0355 m (docs/foot.md, "A fifth pass")
    zaru_gate_rad_s: float = 0.02
    #: rolling ZUPT: height (m) of the sensor above the point the foot rolls about during stance (heel, then
    #: toe); the stance measurement is then ``v = R (w x r_b)``, ``r_b = h up_b`` (``up_b``: the body's up
    #: at the alignment), instead of ``v = 0``.  0: the plain ZUPT (eq. 9).  Off: on the PyShoe tuning split
    #: 0.045 / 0.06 m took PyShoe's metric median 0.037 -> 0.036 / 0.036 m but the mean 0.040 -> 0.041 / 0.043
    #: (one trial doubles; the lever scales every stride by +0.3-2.7 %; docs/foot.md)
    zupt_lever_up_m: float = 0.0
    #: rolling ZUPT noise: the zero-velocity sd becomes ``sqrt(sigma_z^2 + (|w| r)^2)`` with this ``r`` (m),
    #: the largest lever arm the rotation may act on; 0: off (tuning split, 0.03 / 0.06 m: median 0.037 ->
    #: 0.038 / 0.042 m)
    zupt_rate_lever_m: float = 0.0
    #: prior sd of roll/pitch and heading after the initial alignment (rad)
    initial_tilt_sd_rad: float = math.radians(1.0)
    initial_heading_sd_rad: float = math.radians(1.0)
    #: prior sd of the velocity after the initial alignment (m/s)
    initial_velocity_sd_m_s: float = 0.01
    #: gravity magnitude (m/s^2); nan: the norm of the mean specific force during the alignment
    gravity_m_s2: float = math.nan
    #: a sample interval longer than this is not integrated (s): the covariance grows, the state is held
    max_dt_s: float = 0.1


@dataclass(frozen=True)
class Update:
    """What one measurement update did."""

    kind: str  #: "zupt", "zaru" or "heading"
    used: bool
    innovation: tuple
    nis: float
    dof: int


def _mv(m, v) -> tuple:
    """Matrix (3 row tuples) times vector, plain floats."""
    return (m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2])


@dataclass(slots=True)
class InsState:
    """Everything :class:`ZuptEKF` changes as samples come: its only state, made by :meth:`initial`.

    Read and set from outside only through :meth:`ZuptEKF.snapshot` and :meth:`ZuptEKF.restore` (the
    read-only properties of :class:`ZuptEKF` show single fields).
    """

    initialized: bool  #: :meth:`ZuptEKF.align` was called
    #: nominal state: plain float tuples (fast per sample); v, p in ENU (m/s, m), biases in the body frame
    q: tuple  #: attitude quaternion body -> ENU (w, x, y, z)
    v: tuple
    p: tuple
    bg: tuple  #: gyroscope bias (rad/s)
    ba: tuple  #: accelerometer bias (m/s^2)
    P: np.ndarray  #: error-state covariance (15, 15)
    g: float  #: gravity magnitude (m/s^2)
    n_rejected: int  #: updates and steps discarded as not finite
    last_dx: np.ndarray  #: the last error estimate folded in (15,)
    #: Schmidt "consider" term (see :meth:`ZuptEKF.consider_heading`): cross-covariance (15,) of the error state
    #: with a past heading error that later measurements are relative to, and that error's variance
    consider: np.ndarray | None
    consider_var: float
    f_prev: tuple  #: the previous accelerometer reading (m/s^2; the trapezoidal mechanisation)
    w_prev: tuple  #: the previous gyroscope reading (rad/s)
    lever_b: tuple  #: rolling ZUPT lever arm (body, m): set by :meth:`ZuptEKF.align`

    @classmethod
    def initial(cls, settings: InsSettings) -> InsState:  # noqa: ARG003 - nothing depends on it before align()
        return cls(initialized=False, q=(1.0, 0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0), p=(0.0, 0.0, 0.0),
                   bg=(0.0, 0.0, 0.0), ba=(0.0, 0.0, 0.0), P=np.zeros((N_STATES, N_STATES)),
                   g=STANDARD_GRAVITY_M_S2, n_rejected=0, last_dx=np.zeros(N_STATES), consider=None,
                   consider_var=math.nan, f_prev=(0.0, 0.0, STANDARD_GRAVITY_M_S2), w_prev=(0.0, 0.0, 0.0),
                   lever_b=(0.0, 0.0, 0.0))


class ZuptEKF(kalman.StateSnapshots):
    """The INS-EKF-ZUPT kernel (see the module docstring): :meth:`align`, :meth:`propagate`, updates.

    ``ZuptEKF(settings)`` or ``ZuptEKF(zupt_noise_m_s=0.02)`` (keyword overrides of :class:`InsSettings`).
    Settings (frozen), state (:class:`InsState`, in and out through :meth:`snapshot` / :meth:`restore`) and
    results (:class:`Update`) are kept apart, as in :class:`core.pdr.attitude.AttitudeEKF`.
    """

    State = InsState

    _state: InsState

    def __init__(self, settings: InsSettings | None = None, **overrides):
        s = settings or InsSettings()
        self.settings = replace(s, **overrides) if overrides else s
        s = self.settings
        # constants of the settings
        self._eye3 = np.eye(3)
        self._r_zupt = np.eye(3) * s.zupt_noise_m_s ** 2
        self._r_zaru = np.eye(3) * s.zaru_noise_rad_s ** 2
        # Q = q1 T + q2 T^2 + q3 T^3: gyro and accelerometer white noise integrated into attitude, velocity
        # and position; Gauss-Markov bias driving noise 2 sd^2 / tau per second
        qv = s.acc_noise_m_s_sqrt_s ** 2
        self._q1 = np.diag([s.gyro_noise_rad_sqrt_s ** 2] * 3 + [qv] * 3 + [0.0] * 3
                           + [2.0 * s.gyro_bias_sd_rad_s ** 2 / s.gyro_bias_tau_s] * 3
                           + [2.0 * s.acc_bias_sd_m_s2 ** 2 / s.acc_bias_tau_s] * 3)
        self._q2 = np.zeros((N_STATES, N_STATES))
        self._q2[VEL, POS] = self._q2[POS, VEL] = np.eye(3) * (qv / 2.0)
        self._q3 = np.zeros((N_STATES, N_STATES))
        self._q3[POS, POS] = np.eye(3) * (qv / 3.0)
        self.reset()

    def reset(self) -> None:
        """Back to a new filter's state (not aligned, no history)."""
        self._state = InsState.initial(self.settings)
        self._forget_caches()
        #: replays: the forward run kept for the RTS smoother (:meth:`keep_history`, :meth:`smoothed`)
        self.history: kalman.RtsSmoother | None = None
        self._nominal: list = []  # the nominal state (q, v, p) of each closed epoch

    def _forget_caches(self) -> None:
        """Caches of values the state and settings determine (recomputed on the next use)."""
        self._phi = np.eye(N_STATES)  # transition buffer (see transition)
        self._phi_bg = self._phi[BG, BG]  # views of the bias blocks
        self._phi_ba = self._phi[BA, BA]
        self._dt_phi = math.nan  # the step the time-step parts of _phi are for
        self._dt_q = math.nan  # ... and of the process noise _q
        self._q = None
        self._m_cache = None  # (q, rotation matrix rows, array) of the last new attitude

    def restore(self, state: InsState) -> None:
        """Continue from ``state`` (a :meth:`snapshot`, possibly changed; the filter takes a copy).  A filter that
        keeps the smoother's history refuses: the history would mix two runs (:meth:`drop_history` first)."""
        if self.history is not None and type(state) is InsState:
            raise ValueError("restore into a filter that keeps the RTS history would mix two runs in smoothed(): "
                             "drop_history() first")
        super().restore(state)

    # -- read-only views of the state (set it through snapshot() / restore()) -------------------
    initialized = property(lambda self: self._state.initialized, doc="align() was called.")
    q = property(lambda self: self._state.q, doc="Attitude quaternion body -> ENU (w, x, y, z).")
    v = property(lambda self: self._state.v, doc="Velocity (ENU, m/s).")
    p = property(lambda self: self._state.p, doc="Position (ENU, m).")
    bg = property(lambda self: self._state.bg, doc="Gyroscope bias (body, rad/s).")
    ba = property(lambda self: self._state.ba, doc="Accelerometer bias (body, m/s^2).")
    P = property(lambda self: kalman.read_only(self._state.P), doc="Error-state covariance (15, 15), read only.")
    g = property(lambda self: self._state.g, doc="Gravity magnitude (m/s^2).")
    n_rejected = property(lambda self: self._state.n_rejected, doc="Steps and updates discarded as not finite.")
    lever_b = property(lambda self: self._state.lever_b, doc="Rolling ZUPT lever arm (body, m).")

    def horizontal_position_sd_m(self) -> float:
        """The larger of the East and North position sd (m)."""
        P = self._state.P
        return math.sqrt(max(P[6, 6], P[7, 7], 0.0))

    def heading_variance(self, h_att) -> float:
        """Variance (rad^2) of the heading error ``h_att . dtheta``."""
        return float(h_att @ self._state.P[ATT, ATT] @ h_att)

    # -- start --------------------------------------------------------------------------------
    def align(self, acc_mean_b, gyro_mean_b, *, heading_axis_b=None, heading_rad: float = 0.0,
              mag_mean_b=None) -> None:
        """Initial alignment from a still period: tilt from the mean specific force, gyroscope bias from
        the mean rate, heading either from the magnetometer (``mag_mean_b``: magnetic north is +y) or
        ``heading_rad`` for the body axis ``heading_axis_b`` (default: the most horizontal body axis)."""
        st = self._state
        s = self.settings
        f = np.asarray(acc_mean_b, dtype=float)
        if mag_mean_b is not None:
            q = quat.from_two_vectors_enu(tuple(f), tuple(mag_mean_b))
        else:
            up_b = f / np.linalg.norm(f)
            axis = np.asarray(heading_axis_b if heading_axis_b is not None else horizontal_axis(up_b), float)
            # TRIAD with a pseudo "north" along the chosen axis, then turned to the wanted heading
            q0 = quat.from_two_vectors_enu(tuple(f), tuple(axis))
            q = quat.multiply(quat.from_axis_angle((0.0, 0.0, 1.0), heading_rad - math.pi / 2), q0)
        st.q = quat.normalize(q)
        st.g = float(np.linalg.norm(f)) if math.isnan(s.gravity_m_s2) else s.gravity_m_s2
        st.v = (0.0, 0.0, 0.0)
        st.p = (0.0, 0.0, 0.0)
        st.bg = tuple(float(x) for x in gyro_mean_b)
        st.ba = (0.0, 0.0, 0.0)
        h = s.zupt_lever_up_m
        st.lever_b = tuple(float(x) for x in f * (h / np.linalg.norm(f))) if h else (0.0, 0.0, 0.0)
        st.f_prev = tuple(float(x) for x in f)  # the previous reading (trapezoidal mechanisation)
        st.w_prev = st.bg
        st.P = np.diag([s.initial_tilt_sd_rad ** 2] * 2 + [s.initial_heading_sd_rad ** 2]
                       + [s.initial_velocity_sd_m_s ** 2] * 3 + [0.0] * 3
                       + [s.gyro_bias_sd_rad_s ** 2] * 3 + [s.acc_bias_sd_m_s2 ** 2] * 3)
        st.initialized = True
        if self.history is not None:
            self.history.start()
            self._nominal = []

    # -- the smoother (replays) -----------------------------------------------------------------
    def keep_history(self) -> None:
        """Keep what the RTS smoother needs from the next :meth:`align` on (two 15 x 15 matrices and the
        nominal state per sample: about 3.7 kB a sample; a replay only)."""
        self.history = kalman.RtsSmoother(N_STATES, ATT)
        self._nominal = []

    def drop_history(self) -> None:
        """Stop keeping the history (the smoother is then not run)."""
        self.history = None
        self._nominal = []

    @property
    def epoch(self) -> int:
        """Index of the current epoch of the history (the state since the last prediction); -1 without one."""
        return self.history.n_epochs - 1 if self.history is not None else -1

    def smoothed(self):
        """The RTS-smoothed state of every epoch (:class:`core.kalman.RtsSmoother`): ``(q (N, 4), v (N, 3),
        p (N, 3), P (N, 15, 15))``, each epoch's nominal state with its smoothed error folded in."""
        st = self._state
        if self.history is None or not self.history.started:
            raise ValueError("no history: call keep_history() before align()")
        e, Ps = self.history.smooth(st.P)
        nom = self._nominal + [(st.q, st.v, st.p)]
        q = np.array([kalman.inject_rotation(x[0], e[j, ATT]) for j, x in enumerate(nom)])
        v = np.array([x[1] for x in nom]) + e[:, VEL]
        p = np.array([x[2] for x in nom]) + e[:, POS]
        return q, v, p, Ps

    def _close_epoch(self, phi, Q) -> None:
        st = self._state
        self.history.predict(st.P, phi, Q)
        self._nominal.append((st.q, st.v, st.p))

    # -- prediction ---------------------------------------------------------------------------
    def transition(self, acc_b, gyro_b, dt_s: float):
        """``(Phi, q_new, v_new, p_new)`` of one mechanisation step, without changing the state.

        Second order (trapezoidal) between the previous reading (the state's ``f_prev``, ``w_prev``, taken with
        the attitude of its own time, ``q``) and this one (taken with the new attitude).  ``Phi`` is a
        buffer reused by the next call (copy it to keep it).
        """
        st = self._state
        bg, ba, v, p = st.bg, st.ba, st.v, st.p
        wp = st.w_prev
        q_new = quat.normalize(quat.multiply(st.q, quat.from_rotation_vector(
            ((0.5 * (gyro_b[0] + wp[0]) - bg[0]) * dt_s, (0.5 * (gyro_b[1] + wp[1]) - bg[1]) * dt_s,
             (0.5 * (gyro_b[2] + wp[2]) - bg[2]) * dt_s))))
        c = self._m_cache  # the previous step's new attitude is this step's old one (unless corrected since)
        if c is not None and c[0] is st.q:
            m0, mat0 = c[1], c[2]
        else:
            m0 = quat.to_matrix(st.q)  # attitude at the previous reading
            mat0 = np.array(m0)
        m1 = quat.to_matrix(q_new)  # ... and at this one
        mat1 = np.array(m1)
        self._m_cache = (q_new, m1, mat1)
        fp = st.f_prev
        f0 = _mv(m0, (fp[0] - ba[0], fp[1] - ba[1], fp[2] - ba[2]))
        f1 = _mv(m1, (acc_b[0] - ba[0], acc_b[1] - ba[1], acc_b[2] - ba[2]))
        g = st.g
        a0 = (f0[0], f0[1], f0[2] - g)
        a1 = (f1[0], f1[1], f1[2] - g)
        h = dt_s * dt_s / 6.0
        p_new = tuple(p[i] + v[i] * dt_s + (2.0 * a0[i] + a1[i]) * h for i in range(3))
        v_new = tuple(v[i] + 0.5 * (a0[i] + a1[i]) * dt_s for i in range(3))
        sf0 = skew(f0)
        sf1 = skew(f1)
        sfm1 = sf1 @ mat1
        phi = self._phi
        half = 0.5 * dt_s
        phi[ATT, BG] = mat1 * (-dt_s)
        phi[VEL, ATT] = (sf0 + sf1) * (-half)
        phi[VEL, BG] = sfm1 * (half * dt_s)
        phi[VEL, BA] = (mat0 + mat1) * (-half)
        phi[POS, ATT] = (2.0 * sf0 + sf1) * (-h)
        phi[POS, BG] = sfm1 * (h * dt_s)
        phi[POS, BA] = (2.0 * mat0 + mat1) * (-h)
        if dt_s != self._dt_phi:  # the parts that depend on the time step alone
            self._dt_phi = dt_s
            phi[POS, VEL] = self._eye3 * dt_s
            np.fill_diagonal(self._phi_bg, math.exp(-dt_s / self.settings.gyro_bias_tau_s))
            np.fill_diagonal(self._phi_ba, math.exp(-dt_s / self.settings.acc_bias_tau_s))
        return phi, q_new, v_new, p_new

    def process_noise(self, dt_s: float) -> np.ndarray:
        """Discrete process noise ``Q`` of one step of ``dt_s`` (white noise integrated over the step)."""
        if dt_s != self._dt_q:
            self._dt_q = dt_s
            self._q = self._q1 * dt_s + self._q2 * (dt_s * dt_s) + self._q3 * (dt_s * dt_s * dt_s)
        return self._q

    def propagate(self, acc_b, gyro_b, dt_s: float, rate_var_rad2_s2=None) -> None:
        """One strapdown step (measured ``dt_s``) and the covariance propagation ``P <- Phi P Phi^T + Q``.

        ``rate_var_rad2_s2``: optional variance ((rad/s)^2, per body axis) of an error of this step's rate
        (the mean of the previous and this reading) beyond the white noise (a clipped reading, repaired or
        not: the true rate is beyond the range by an unknown amount).  Over the step such an error moves the
        error state as a gyroscope bias error does, so it adds ``G diag(var) G^T`` to ``Q``, ``G`` the bias
        columns of ``Phi`` without the bias rows (attitude ``-R T``, velocity ``[f1]x R T^2 / 2``, position
        ``[f1]x R T^3 / 6``; module docstring).  A variance that is not finite and >= 0 is ignored.
        """
        st = self._state
        s = self.settings
        if not (dt_s > 0):
            return
        if dt_s > s.max_dt_s:  # a gap: hold the state, let the uncertainty grow
            if self.history is not None:
                self._close_epoch(np.eye(N_STATES), self._q1 * dt_s)
            st.P = st.P + self._q1 * dt_s
            st.f_prev, st.w_prev = tuple(acc_b), tuple(gyro_b)
            return
        phi, q_new, v_new, p_new = self.transition(acc_b, gyro_b, dt_s)
        if not all(map(math.isfinite, v_new + p_new + q_new)):
            st.n_rejected += 1
            return
        Q = self.process_noise(dt_s)
        if rate_var_rad2_s2 is not None:
            var = np.asarray(rate_var_rad2_s2, dtype=float)
            if np.all(np.isfinite(var)) and np.all(var >= 0.0) and np.any(var > 0.0):
                G = phi[0:9, BG]
                Q = Q.copy()
                Q[0:9, 0:9] += (G * var) @ G.T
        if self.history is not None:
            self._close_epoch(phi, Q)
        st.P = phi @ st.P @ phi.T + Q
        if st.consider is not None:
            st.consider = phi @ st.consider
        st.q, st.v, st.p = q_new, v_new, p_new
        st.f_prev, st.w_prev = tuple(acc_b), tuple(gyro_b)

    # -- updates ------------------------------------------------------------------------------
    def _update(self, kind: str, y: np.ndarray, H, Rm: np.ndarray) -> Update:
        """One update through the shared kernel (:func:`core.kalman.correct`; ``H`` an array, or the slice of
        the states it selects), the error folded in and reset (:func:`core.kalman.reset_covariance`)."""
        st = self._state
        c = kalman.correct(st.P, y, H, Rm)
        if not c.used:
            st.n_rejected += 1
            return Update(kind, False, tuple(float(v) for v in y), c.nis, len(y))
        if st.consider is not None:  # the considered error is not estimated; its correlation shrinks
            hc = st.consider[H] if isinstance(H, slice) else H @ st.consider
            st.consider = st.consider - c.K @ hc
        return self._fold(kind, y, c.dx, c.P, c.nis)

    def _fold(self, kind: str, y: np.ndarray, dx: np.ndarray, P_new: np.ndarray, nis: float) -> Update:
        """Fold a used update's ``dx`` into the nominal state and reset the error (:func:`core.kalman.reset_covariance`;
        the consider term's cross-covariance goes through the same reset Jacobian)."""
        st = self._state
        G = kalman.reset_jacobian(dx[ATT], N_STATES, ATT)
        self.correct(dx)
        if self.history is not None:
            self.history.inject(dx, G)
        st.P = kalman.reset_covariance(P_new, dx[ATT], ATT, G)
        if st.consider is not None:
            st.consider = G @ st.consider
        st.last_dx = dx
        return Update(kind, True, tuple(float(v) for v in y), nis, len(y))

    def _update_block(self, kind: str, y: np.ndarray, sl: slice, Rm: np.ndarray) -> Update:
        """Update with ``H`` selecting the states ``sl``: ``P H^T = P[:, sl]``, ``P <- P - K (P H^T)^T``."""
        return self._update(kind, y, sl, Rm)

    def correct(self, dx) -> None:
        """Fold an error estimate into the nominal state (and reset it to zero)."""
        st = self._state
        st.q = kalman.inject_rotation(st.q, dx[ATT])
        d = dx.tolist()
        v, p, bg, ba = st.v, st.p, st.bg, st.ba
        st.v = (v[0] + d[3], v[1] + d[4], v[2] + d[5])
        st.p = (p[0] + d[6], p[1] + d[7], p[2] + d[8])
        st.bg = (bg[0] + d[9], bg[1] + d[10], bg[2] + d[11])
        st.ba = (ba[0] + d[12], ba[1] + d[13], ba[2] + d[14])

    def update_zero_velocity(self, noise_scale: float = 1.0, gyro_b=None) -> Update:
        """eq. 9: ``z = 0`` during stance (``H = [0 I 0 0 0]``); ``noise_scale`` multiplies ``sigma_z``
        (a soft ZUPT: less weight where the detector is less sure).  With ``gyro_b`` (the rate reading) and
        a rolling lever arm or rate noise in the settings: the rolling ZUPT of the module docstring."""
        st = self._state
        s = self.settings
        r = self._r_zupt if noise_scale == 1.0 else self._r_zupt * (noise_scale * noise_scale)
        if gyro_b is None or not (s.zupt_lever_up_m or s.zupt_rate_lever_m):
            y = np.array((-st.v[0], -st.v[1], -st.v[2]))
            return self._update_block("zupt", y, VEL, r)
        bg = st.bg
        w = (gyro_b[0] - bg[0], gyro_b[1] - bg[1], gyro_b[2] - bg[2])
        if s.zupt_rate_lever_m:
            r = r + np.eye(3) * ((s.zupt_rate_lever_m * math.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2)) ** 2)
        if not s.zupt_lever_up_m:
            y = np.array((-st.v[0], -st.v[1], -st.v[2]))
            return self._update_block("zupt", y, VEL, r)
        u, H = self.rolling_velocity(gyro_b)
        return self._update("zupt", u - np.asarray(st.v), H, r)

    def rolling_velocity(self, gyro_b):
        """Rolling ZUPT: the sensor's velocity ``u = R (w x r_b)`` (ENU, m/s) for the rate reading ``gyro_b``,
        and the Jacobian ``H`` (3 x 15) of ``v - R (w x r_b)`` w.r.t. the error state (module docstring)."""
        st = self._state
        bg = st.bg
        w = (gyro_b[0] - bg[0], gyro_b[1] - bg[1], gyro_b[2] - bg[2])
        m = self.matrix()
        lb = np.asarray(st.lever_b)
        u = m @ np.cross(w, lb)
        H = np.zeros((3, N_STATES))
        H[:, ATT] = skew(u)
        H[:, VEL] = self._eye3
        H[:, BG] = -m @ skew(lb)
        return u, H

    def update_zero_rate(self, gyro_b) -> Update:
        """Zero angular rate during stance: the reading is the bias (``H = [0 0 0 I 0]``).  Not used (not a
        rejection: ``used`` False, NIS nan) where an axis of ``w_meas - b_g`` exceeds ``zaru_gate_rad_s``."""
        st = self._state
        y = np.array((gyro_b[0] - st.bg[0], gyro_b[1] - st.bg[1], gyro_b[2] - st.bg[2]))
        g = self.settings.zaru_gate_rad_s
        if not (abs(y[0]) <= g and abs(y[1]) <= g and abs(y[2]) <= g):
            return Update("zaru", False, tuple(float(v) for v in y), math.nan, 3)
        return self._update_block("zaru", y, BG, self._r_zaru)

    def update_heading(self, innovation_rad: float, h_att, variance_rad2: float) -> Update:
        """A heading measurement: ``innovation = wrap(psi_meas - psi_est) = h_att . dtheta + v``."""
        H = np.zeros((1, N_STATES))
        H[0, ATT] = h_att
        return self._update("heading", np.array([float(innovation_rad)]), H, np.array([[float(variance_rad2)]]))

    def consider_heading(self, h_att, extra_var_rad2: float = 0.0) -> None:
        """Keep the heading error ``c = h_att . dtheta`` of now (plus independent noise of ``extra_var_rad2``)
        as a constant that later measurements are relative to (:meth:`update_heading_relative`): a Schmidt
        consider parameter, never estimated, its cross-covariance with the error state carried."""
        h = np.asarray(h_att, dtype=float)
        st = self._state
        st.consider = st.P[:, ATT] @ h
        st.consider_var = self.heading_variance(h) + float(extra_var_rad2)

    def update_heading_relative(self, innovation_rad: float, h_att, variance_rad2: float) -> Update:
        """A heading measurement relative to the considered one: ``innovation = h_att . dtheta - c + v``
        (Schmidt-Kalman: ``c`` is not estimated, the gain and covariance account for it)."""
        st = self._state
        if st.consider is None:
            return self.update_heading(innovation_rad, h_att, variance_rad2)
        h = np.asarray(h_att, dtype=float)
        y = np.array([float(innovation_rad)])
        ph = st.P[:, ATT] @ h - st.consider  # P_a H_a^T (state rows), H_a = [h, -1]
        hc = float(h @ st.consider[ATT]) - st.consider_var  # H_a P_a[:, c]
        s_ = float(h @ ph[ATT]) - float(h @ st.consider[ATT]) + st.consider_var + float(variance_rad2)
        if not s_ > 0:
            st.n_rejected += 1
            return Update("heading", False, (float(y[0]),), math.nan, 1)
        K = (ph / s_).reshape(-1, 1)
        P_new = st.P - s_ * (K @ K.T)
        dx = K[:, 0] * float(y[0])
        if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(P_new))):
            st.n_rejected += 1
            return Update("heading", False, (float(y[0]),), math.nan, 1)
        st.consider = st.consider - K[:, 0] * hc
        return self._fold("heading", y, dx, P_new, float(y[0] * y[0] / s_))

    # -- views --------------------------------------------------------------------------------
    def matrix(self) -> np.ndarray:
        return np.array(quat.to_matrix(self._state.q))

    def heading_of(self, axis_b) -> float:
        """Azimuth (rad, CCW from East) of a body axis in the navigation frame."""
        a = self.matrix() @ np.asarray(axis_b, dtype=float)
        return math.atan2(a[1], a[0])


def horizontal_axis(up_b) -> np.ndarray:
    """The body unit axis most perpendicular to ``up_b`` (a heading reference when there is no magnetometer)."""
    k = int(np.argmin(np.abs(np.asarray(up_b, dtype=float))))
    e = np.zeros(3)
    e[k] = 1.0
    return e
