"""The paper's adaptive quaternion EKF (Tian et al. 2014, section 4), kept for comparison.

The product's filter is :class:`core.pdr.attitude.AttitudeEKF` (error state with gyro bias);
this one is selectable with ``Pipeline(attitude=QuaternionEKF())`` and in the benchmark.

State: the attitude quaternion ``q = (w, x, y, z)`` (body -> ENU, see
:mod:`core`), covariance ``P`` (4 x 4).

Prediction (eqs. 5-7, 11), on every gyroscope event with the measured time
step ``T`` since the previous one::

    q_k+1 = F q_k,   F = I cos(|w|T/2) + Omega(w T) sin(|w|T/2) / (|w|T)       (eq. 7)
    P_k+1 = F P F^T + Q,   Q = (sigma_g^2 T / 4) Xi(q) Xi(q)^T

``Omega`` is the matrix of eq. 6 (``dq/dt = q (x) (0, w) / 2``) and ``Xi(q)``
maps a body-rate error to ``dq/dt``; ``sigma_g`` is the gyroscope's angle
random walk (rad/sqrt(s)) widened to cover bias and timing errors.

Measurement (eqs. 12-15): the normalised accelerometer and magnetometer are
``h(q) = R(q)^T v`` for the reference directions ``v = g = (0, 0, 1)``
(eq. 13) and ``v = h = (0, b_y, b_z)`` (eq. 14; with a declination ``D`` its
horizontal part is turned to ``(b_y sin D, b_y cos D)``).  They arrive at
their own times, so each is applied on its own, as three sequential scalar
updates (``R`` is diagonal, eq. 15).  The Jacobian is derived for these
conventions rather than taken from eq. 16: writing ``u = (x, y, z)``,
``R^T v = (w^2 - u.u) v + 2 u (u.v) - 2 w (u x v)``, so::

    d h / d w = 2 (w v - u x v)
    d h / d u = 2 ((u.v) I + u v^T - v u^T + w [v]x)

(``[v]x`` is the cross-product matrix).  On the unit sphere its first three
rows agree with the paper's eq. 16 for ``v = g`` except the third, which the
paper simplifies with ``|q| = 1``; a test checks ours by finite differences.

Adaptive noise (eqs. 17-18)::

    sigma_a^2 = s_a0^2 + k_a1 | |a| - |g| | + k_a2 var(|a| over the window)
    sigma_m^2 = s_m0^2 + k_m1 | |m| - |h| | + k_m2 var(|m| over the window)

The paper centres the variance window on the sample; a live filter cannot
look ahead, so the window here is the trailing ``variance_window_s``.  The
base terms ``s_a0, s_m0`` (not in the paper) keep the filter from trusting a
measurement completely when the formula gives zero.  A magnetometer reading
whose norm is off by more than ``mag_reject_ratio`` or whose dip angle
(measured against the current gravity estimate) is off by more than
``mag_reject_dip_rad`` is not used at all (flagged ``mag_rejected``).
"""

from __future__ import annotations

import math

import numpy as np

from core import quaternion as quat
from core.dsp import WindowMeanSpread, WindowVariance
from core.pdr.attitude import _ACC_IMPOSSIBLE, _GYRO_IMPOSSIBLE, _MAG_IMPOSSIBLE, AttitudeFilterBase, _plausible

_EYE4 = np.eye(4)
_EYE4.flags.writeable = False


def measurement_jacobian(q, v) -> np.ndarray:
    """``d (R(q)^T v) / d q`` (3 x 4) for ``q = (w, x, y, z)``; see the module docstring."""
    w, x, y, z = q
    v0, v1, v2 = v
    udv = x * v0 + y * v1 + z * v2
    # u x v
    c0 = y * v2 - z * v1
    c1 = z * v0 - x * v2
    c2 = x * v1 - y * v0
    return 2.0 * np.array([
        [w * v0 - c0, udv + x * v0 - v0 * x, x * v1 - v0 * y - w * v2, x * v2 - v0 * z + w * v1],
        [w * v1 - c1, y * v0 - v1 * x + w * v2, udv + y * v1 - v1 * y, y * v2 - v1 * z - w * v0],
        [w * v2 - c2, z * v0 - v2 * x - w * v1, z * v1 - v2 * y + w * v0, udv + z * v2 - v2 * z],
    ])


def predicted_measurement(q, v):
    """``R(q)^T v``: the reference direction ``v`` (navigation frame) seen in the body frame.

    Written in the homogeneous form ``(w^2 - u.u) v + 2 u (u.v) - 2 w (u x v)``,
    which equals ``R(q)^T v`` on the unit sphere and is the function whose
    derivative :func:`measurement_jacobian` is.
    """
    w, x, y, z = q
    v0, v1, v2 = v
    s = w * w - (x * x + y * y + z * z)
    udv2 = 2.0 * (x * v0 + y * v1 + z * v2)
    w2 = 2.0 * w
    return (
        s * v0 + udv2 * x - w2 * (y * v2 - z * v1),
        s * v1 + udv2 * y - w2 * (z * v0 - x * v2),
        s * v2 + udv2 * z - w2 * (x * v1 - y * v0),
    )


def transition_matrix(wx: float, wy: float, wz: float, dt_s: float) -> np.ndarray:
    """``F = exp(Omega(w T) / 2)`` of eq. 7 for a body rate held constant over ``dt_s``."""
    ax, ay, az = wx * dt_s, wy * dt_s, wz * dt_s
    theta = math.sqrt(ax * ax + ay * ay + az * az)
    c = math.cos(0.5 * theta)
    s = 0.5 if theta < 1e-9 else math.sin(0.5 * theta) / theta
    return np.array([  # eq. 6 / eq. 7
        [c, -s * ax, -s * ay, -s * az],
        [s * ax, c, s * az, -s * ay],
        [s * ay, -s * az, c, s * ax],
        [s * az, s * ay, -s * ax, c],
    ])


class QuaternionEKF(AttitudeFilterBase):
    """Quaternion EKF with adaptive accelerometer / magnetometer noise (eqs. 5-18).

    Feed events in time order: :meth:`predict` (gyroscope), :meth:`update_acc`,
    :meth:`update_mag`.  The filter initialises itself from the first
    accelerometer and magnetometer readings (TRIAD) and owns all its state.

    Parameters
    ----------
    gyro_noise_rad_sqrt_s : float
        Angle random walk ``sigma_g`` of the prediction (rad/sqrt(s)),
        widened to absorb gyroscope bias and timing errors.
    acc_noise_base : float
        ``s_a0``: base standard deviation of the normalised accelerometer (unitless).
    k_a1 : float
        Weight of ``| |a| - |g| |`` in eq. 17 (per m/s^2).
    k_a2 : float
        Weight of the windowed variance of ``|a|`` in eq. 17 (per (m/s^2)^2).
    mag_noise_base : float
        ``s_m0``: base standard deviation of the normalised magnetometer (unitless).
    k_m1 : float
        Weight of ``| |m| - |h| |`` in eq. 18 (per uT).
    k_m2 : float
        Weight of the windowed variance of ``|m|`` in eq. 18 (per uT^2).
    variance_window_s : float
        Length of the trailing window of eqs. 17-18 (s).
    acc_reject_m_s2 : float
        Accelerometer readings whose norm is further than this from ``|g|`` are not used (m/s^2).
    mag_reject_ratio : float
        Magnetometer readings with ``| |m| - |h| | > ratio |h|`` are not used.
    mag_reject_dip_rad : float
        Magnetometer readings whose dip angle differs from the reference by more than this are not used (rad).
    mag_valid_range_uT : tuple of 2 floats
        Readings outside this range are not a geomagnetic field at all (the
        Earth's is 22-67 uT; an uncalibrated phone can report 1700 uT) and are
        used for nothing: not the references, not the initial attitude, not
        the updates.
    mag_heading_only : bool
        Let the magnetometer correct the heading only: the reading is
        replaced by the vector with the same horizontal direction (in the
        current navigation-frame estimate) and the reference dip, so a
        disturbed field cannot tilt the attitude.  Off: the paper's full
        vector update (eq. 12).
    reference_update_s : float
        ``|g|``, ``|h|`` and the dip angle of ``h`` are the running medians of
        every reading so far (indoors the field is disturbed in places, so a
        median over the whole walk beats the first seconds), refreshed this
        often (s).
    declination_rad : float
        Magnetic declination (east of true north positive, rad); 0 gives headings relative to magnetic north.
    initial_yaw_rad : float
        Heading of the device y axis at the start when there is no magnetometer (rad, CCW from East).
    use_magnetometer : bool
        False ignores magnetometer events (heading relative to the start).
    mag_wait_s : float
        How long to wait for a first magnetometer reading before starting from
        the accelerometer alone with ``initial_yaw_rad`` (s).
    still_window_s : float
        The gyroscope bias is learnt as its mean over this long a window in
        which the phone is still (s): accelerometer norm standard deviation
        below ``still_acc_sd_m_s2``, gyroscope standard deviation below
        ``still_gyro_sd_rad_s`` on every axis and mean rate below
        ``max_gyro_bias_rad_s``.  Phones are put down or held still at the
        start of most walks; the heading without magnetometer depends on it.
    still_acc_sd_m_s2, still_gyro_sd_rad_s, max_gyro_bias_rad_s : float
        Thresholds of the stillness test (m/s^2, rad/s, rad/s).
    no_gyro_random_walk_rad_sqrt_s : float
        Attitude random walk assumed between measurements when no gyroscope event has come for 0.1 s.
    max_gyro_gap_s : float
        A gyroscope gap longer than this (s) is not integrated, only the uncertainty grows; every stream silent
        this long is a hole in the recording.  Either grows the covariance once over the real elapsed time,
        whichever stream's event comes first after it (the growth shared with
        :class:`core.pdr.attitude.AttitudeEKF`: :meth:`AttitudeFilterBase._grow_over_hole`,
        :meth:`AttitudeFilterBase._grow_over_gyro_gap`; before, an accelerometer event after a hole grew it over
        the hole and the gyroscope's event again).  This filter keeps no intervals: nothing else is dropped.
    """

    def __init__(self, *, gyro_noise_rad_sqrt_s: float = 0.015, acc_noise_base: float = 0.05, k_a1: float = 0.02,
                 k_a2: float = 0.05, mag_noise_base: float = 0.05, k_m1: float = 0.01, k_m2: float = 0.01,
                 variance_window_s: float = 1.0, acc_reject_m_s2: float = 4.0, mag_reject_ratio: float = 0.4,
                 mag_reject_dip_rad: float = math.radians(23.0), mag_valid_range_uT=(10.0, 150.0),
                 mag_heading_only: bool = True, reference_update_s: float = 1.0,
                 declination_rad: float = 0.0, initial_yaw_rad: float = math.pi / 2,
                 use_magnetometer: bool = True, mag_wait_s: float = 1.0, still_window_s: float = 1.0,
                 still_acc_sd_m_s2: float = 0.1, still_gyro_sd_rad_s: float = 0.02, max_gyro_bias_rad_s: float = 0.05,
                 no_gyro_random_walk_rad_sqrt_s: float = 0.5, max_gyro_gap_s: float = 0.5):
        self.gyro_noise_rad_sqrt_s = gyro_noise_rad_sqrt_s
        self.acc_noise_base = acc_noise_base
        self.k_a1, self.k_a2 = k_a1, k_a2
        self.mag_noise_base = mag_noise_base
        self.k_m1, self.k_m2 = k_m1, k_m2
        self.variance_window_s = variance_window_s
        self.acc_reject_m_s2 = acc_reject_m_s2
        self.mag_reject_ratio = mag_reject_ratio
        self.mag_reject_dip_rad = mag_reject_dip_rad
        self.mag_valid_range_uT = (float(mag_valid_range_uT[0]), float(mag_valid_range_uT[1]))
        self.reference_update_s = reference_update_s
        self.mag_heading_only = mag_heading_only
        self.declination_rad = declination_rad
        self.initial_yaw_rad = initial_yaw_rad
        self.use_magnetometer = use_magnetometer
        self.mag_wait_s = mag_wait_s
        self.still_window_s = still_window_s
        self.still_acc_sd_m_s2 = still_acc_sd_m_s2
        self.still_gyro_sd_rad_s = still_gyro_sd_rad_s
        self.max_gyro_bias_rad_s = max_gyro_bias_rad_s
        self.no_gyro_random_walk_rad_sqrt_s = no_gyro_random_walk_rad_sqrt_s
        self.max_gyro_gap_s = max_gyro_gap_s
        self.reset()

    def reset(self) -> None:
        self._reset_common()
        self.P = np.eye(4) * 0.05
        self._gyro_still = WindowMeanSpread(self.still_window_s)
        self._acc_sd = math.inf
        #: current gyroscope bias estimate (rad/s), subtracted before prediction
        self.gyro_bias = (0.0, 0.0, 0.0)
        self.n_bias_updates = 0
        self._acc_var = WindowVariance(self.variance_window_s)
        self._mag_var = WindowVariance(self.variance_window_s)
        self._h_ref = (0.0, 1.0, 0.0)
        # diagnostics (latest values)
        self.acc_sigma2 = math.nan
        self.mag_sigma2 = math.nan
        self.mag_rejected = False
        self.acc_rejected = False
        self.n_mag_used = 0
        self.n_mag_rejected = 0
        self.n_mag_invalid = 0
        self.n_numerical_resets = 0
        self.n_acc_rejected = 0
        self.n_gyro = 0
        self.acc_innovation = (0.0, 0.0, 0.0)
        self.mag_innovation = (0.0, 0.0, 0.0)

    # -- initialisation -------------------------------------------------------
    def _param(self, name: str):
        return getattr(self, name)

    def _set_field_reference(self) -> None:
        if self._state.refs.h.n:
            c, s = math.cos(self._state.dip_rad), math.sin(self._state.dip_rad)
            d = self.declination_rad
            # eq. 14, turned by the declination: magnetic north lies D east of true north
            self._h_ref = (c * math.sin(d), c * math.cos(d), -s)

    # -- prediction -------------------------------------------------------------
    def predict(self, t_ns: int, wx: float, wy: float, wz: float) -> None:
        """Propagate with one gyroscope event (rad/s) over the time since the previous one (eqs. 7, 11)."""
        if not _plausible(wx, wy, wz, _GYRO_IMPOSSIBLE):  # NaN, inf or beyond any phone gyroscope: skipped
            self._state.n_skipped_nonfinite += 1
            return
        self.n_gyro += 1
        gs = self._gyro_still
        gs.update(t_ns, (wx, wy, wz))
        if self._acc_sd < self.still_acc_sd_m_s2:
            mean, sd, span = gs.stats()
            if (sd < self.still_gyro_sd_rad_s and span >= 0.9 * gs.window_ns
                    and math.sqrt(mean[0] ** 2 + mean[1] ** 2 + mean[2] ** 2) < self.max_gyro_bias_rad_s):
                self.gyro_bias = (mean[0], mean[1], mean[2])
                self.n_bias_updates += 1
        b = self.gyro_bias
        wx, wy, wz = wx - b[0], wy - b[1], wz - b[2]
        if not self._state.initialized:
            self._state.t_gyro_ns = t_ns
            return
        self._grow_over_hole(t_ns)
        t_prev = self._state.t_gyro_ns if self._state.t_gyro_ns is not None else self._state.t_ns
        self._state.t_gyro_ns = t_ns
        dt = (t_ns - t_prev) * 1e-9
        if dt <= 0.0:
            return
        if dt > self.max_gyro_gap_s:  # a gap: do not integrate a stale rate over it, grow the uncertainty once
            self._grow_over_gyro_gap(t_ns)
            return
        F = transition_matrix(wx, wy, wz, dt)
        q = F @ np.array(self._state.q)
        self._state.q = quat.normalize(tuple(q.tolist()))
        w, x, y, z = self._state.q
        xi = np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])
        Q = (self.gyro_noise_rad_sqrt_s ** 2 * dt * 0.25) * (xi @ xi.T)
        self.P = F @ self.P @ F.T + Q
        self._state.t_ns = t_ns

    def _random_walk(self, dt: float) -> None:
        sigma = self.no_gyro_random_walk_rad_sqrt_s
        w, x, y, z = self._state.q
        xi = np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])
        self.P = self.P + (sigma ** 2 * dt * 0.25) * (xi @ xi.T)

    # -- measurement updates ---------------------------------------------------
    def _vector_update(self, z, v, sigma2: float):
        """Three sequential scalar updates of ``z = R(q)^T v + noise`` (eq. 12); returns the innovation."""
        q0 = np.array(self._state.q)
        q = q0
        hq = predicted_measurement(self._state.q, v)
        H = measurement_jacobian(self._state.q, v)
        P = self.P
        innov = (z[0] - hq[0], z[1] - hq[1], z[2] - hq[2])
        for i in range(3):
            h = H[i]
            ph = P @ h
            s = float(h @ ph) + sigma2
            k = ph / s
            # the innovation of row i re-linearised at the current estimate
            r = innov[i] - float(h @ (q - q0))
            q = q + k * r
            P = P - np.outer(k, ph)
        P = 0.5 * (P + P.T)
        n = math.sqrt(float(q @ q))
        if not (n > 0.0 and math.isfinite(n) and np.all(np.isfinite(P))):
            self.n_numerical_resets += 1  # keep the prior state rather than poison the filter
            return innov
        q = q / n
        # keep P consistent with the normalisation (project out the radial direction)
        J = _EYE4 - np.outer(q, q)
        self.P = J @ P @ J.T + _EYE4 * 1e-12
        self._state.q = tuple(q.tolist())
        return innov

    def update_acc(self, t_ns: int, ax: float, ay: float, az: float) -> None:
        """Accelerometer update (m/s^2, gravity included) with the adaptive variance of eq. 17."""
        if not _plausible(ax, ay, az, _ACC_IMPOSSIBLE):
            self._state.n_skipped_nonfinite += 1
            return
        self._state.acc_reading = (ax, ay, az)
        self._accumulate_references(t_ns, acc=self._state.acc_reading)
        if not self._state.initialized:
            self._try_initialize(t_ns)
            return
        self._grow_over_hole(t_ns)
        self._propagate_without_gyro(t_ns)
        na = math.sqrt(ax * ax + ay * ay + az * az)
        var = self._acc_var.update(t_ns, na)
        self._acc_sd = math.sqrt(var) if len(self._acc_var.buf) > 5 else math.inf
        dev = abs(na - self._state.gravity_m_s2)
        self.acc_sigma2 = self.acc_noise_base ** 2 + self.k_a1 * dev + self.k_a2 * var  # eq. 17
        if dev > self.acc_reject_m_s2 or na == 0.0:
            self.acc_rejected = True
            self.n_acc_rejected += 1
            return
        self.acc_rejected = False
        self.acc_innovation = self._vector_update((ax / na, ay / na, az / na), (0.0, 0.0, 1.0), self.acc_sigma2)

    def update_mag(self, t_ns: int, mx: float, my: float, mz: float) -> None:
        """Magnetometer update (uT) with the adaptive variance of eq. 18 and outright rejection."""
        if not self.use_magnetometer:
            return
        if not _plausible(mx, my, mz, _MAG_IMPOSSIBLE):
            self._state.n_skipped_nonfinite += 1
            return
        nm = math.sqrt(mx * mx + my * my + mz * mz)
        lo, hi = self.mag_valid_range_uT
        if not lo <= nm <= hi:
            self.mag_rejected = True
            self.n_mag_rejected += 1
            self.n_mag_invalid += 1
            return
        self._state.mag_reading = (mx, my, mz)
        self._accumulate_references(t_ns, mag=self._state.mag_reading)
        if not self._state.initialized:
            self._try_initialize(t_ns)
            return
        self._grow_over_hole(t_ns)
        self._propagate_without_gyro(t_ns)
        var = self._mag_var.update(t_ns, nm)
        dev = abs(nm - self._state.field_uT)
        self.mag_sigma2 = self.mag_noise_base ** 2 + self.k_m1 * dev + self.k_m2 * var  # eq. 18
        # dip angle of this reading against the current estimate of "up" in the body frame
        up_b = predicted_measurement(self._state.q, (0.0, 0.0, 1.0))
        sin_dip = -(up_b[0] * mx + up_b[1] * my + up_b[2] * mz) / nm if nm > 0 else 0.0
        dip = math.asin(max(-1.0, min(1.0, sin_dip)))
        if nm == 0.0 or dev > self.mag_reject_ratio * self._state.field_uT or abs(dip - self._state.dip_rad) > self.mag_reject_dip_rad:
            self.mag_rejected = True
            self.n_mag_rejected += 1
            return
        self.mag_rejected = False
        self.n_mag_used += 1
        z = (mx / nm, my / nm, mz / nm)
        if self.mag_heading_only:
            z = self._heading_only(z)
        self.mag_innovation = self._vector_update(z, self._h_ref, self.mag_sigma2)

    def _heading_only(self, m_b):
        """The unit field with the measured horizontal direction and the reference dip, in the body frame."""
        r = quat.to_matrix(self._state.q)
        m_n = [r[i][0] * m_b[0] + r[i][1] * m_b[1] + r[i][2] * m_b[2] for i in range(3)]
        hn = math.hypot(m_n[0], m_n[1])
        if hn < 1e-6:
            return m_b
        c, s = math.cos(self._state.dip_rad), math.sin(self._state.dip_rad)
        v = (c * m_n[0] / hn, c * m_n[1] / hn, -s)
        return tuple(r[0][j] * v[0] + r[1][j] * v[1] + r[2][j] * v[2] for j in range(3))
