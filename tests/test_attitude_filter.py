"""The error-state attitude EKF (core.pdr.attitude): Jacobians, heading-only magnetometer, bias, bad numbers.

The synthetic phones here are written from the physics (a rotation, gravity
and a field seen in the body frame), not from the filter's own models.
"""

import copy
import math

import numpy as np
import pytest

from core import quaternion as quat
from core.conventions import wrap_angle
from core.pdr.attitude import AttitudeEKF, AttitudeSettings, direction_jacobian, heading_jacobian

G = 9.81
DIP = math.radians(66.0)
FIELD_N = 48.0 * np.array([0.0, math.cos(DIP), -math.sin(DIP)])  # ENU, magnetic north = +y


def _rot(q):
    return np.array(quat.to_matrix(q))


def _perturbed(R, dtheta):
    """``exp([dtheta]x) R`` exactly (Rodrigues)."""
    return np.array(quat.to_matrix(quat.from_rotation_vector(tuple(dtheta)))) @ R


def _yaw(q):
    """Heading (CCW from East) of the device y axis' horizontal projection."""
    m = quat.to_matrix(q)
    return math.atan2(m[1][1], m[0][1])


def _tilt_between(q1, q2):
    """Angle (rad) between the body-frame "up" directions of two attitudes: what a yaw change cannot move."""
    u1 = _rot(q1)[2]
    u2 = _rot(q2)[2]
    return math.acos(min(1.0, float(u1 @ u2)))


def _heading_of_field(R, m_b):
    m_n = R @ m_b
    return math.atan2(m_n[1], m_n[0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_direction_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    R = _rot(quat.normalize(tuple(rng.normal(size=4))))
    v = rng.normal(size=3)
    H = direction_jacobian(R, v)
    eps = 1e-6
    num = np.zeros((3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = eps
        num[:, j] = (_perturbed(R, d).T @ v - _perturbed(R, -d).T @ v) / (2 * eps)
    np.testing.assert_allclose(H, num, atol=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_heading_jacobian_matches_finite_differences(seed):
    """alpha_meas(dtheta) = azimuth of R_est m_b with R_est = exp(-[dtheta]x) R_true: slope is -H."""
    rng = np.random.default_rng(seed)
    R = _rot(quat.normalize(tuple(rng.normal(size=4))))
    m_b = R.T @ FIELD_N
    m_n = R @ m_b
    H = heading_jacobian(m_n)
    eps = 1e-6
    num = np.zeros(3)
    for j in range(3):
        d = np.zeros(3)
        d[j] = eps
        a_plus = _heading_of_field(_perturbed(R, -d), m_b)
        a_minus = _heading_of_field(_perturbed(R, d), m_b)
        num[j] = -wrap_angle(a_plus - a_minus) / (2 * eps)
    np.testing.assert_allclose(H, num, atol=1e-6)


def _still_events(q_true, seconds, *, rate=100.0, seed=7, gyro_bias=(0.0, 0.0, 0.0), field_n=FIELD_N,
                  gyro_sd=0.002, acc_sd=0.02, mag_sd=0.3, t0=10**12):
    """A phone lying still at ``q_true``: gyro = bias + noise, acc = R^T g, mag = R^T field (every other tick)."""
    rng = np.random.default_rng(seed)
    R = _rot(q_true)
    acc = R.T @ np.array([0.0, 0.0, G])
    mag = R.T @ np.asarray(field_n)
    t = t0
    for k in range(int(seconds * rate)):
        t += int(1e9 / rate)
        yield "gyro", t, tuple(np.array(gyro_bias) + rng.normal(0, gyro_sd, 3))
        yield "acc", t + 1000, tuple(acc + rng.normal(0, acc_sd, 3))
        if k % 2 == 0:
            yield "mag", t + 2000, tuple(mag + rng.normal(0, mag_sd, 3))


def _feed(ekf, events):
    flags = []
    for name, t, v in events:
        if name == "gyro":
            ekf.predict(t, *v)
        else:
            flags.append(getattr(ekf, "update_" + name)(t, *v))
    return flags


Q_TILTED = quat.normalize((0.9, 0.3, -0.1, 0.4))


@pytest.mark.parametrize("q_true", [(1.0, 0.0, 0.0, 0.0), Q_TILTED, quat.normalize((0.2, 0.7, 0.6, -0.3))])
def test_still_phone_keeps_its_attitude_and_learns_the_bias(q_true):
    bias = (0.004, -0.003, 0.005)
    ekf = AttitudeEKF()
    _feed(ekf, _still_events(q_true, 30.0, gyro_bias=bias))
    assert ekf.initialized
    d = abs(sum(a * b for a, b in zip(ekf.q, q_true)))
    assert math.degrees(2 * math.acos(min(1.0, d))) < 1.0
    # a truly still phone: the zero-rate updates and the references pin the bias within 0.5 mrad/s
    assert ekf.n_zero_rate > 5
    np.testing.assert_allclose(ekf.gyro_bias, bias, atol=5e-4)


def _max_tilt_under_azimuth_disturbance(make):
    """Settle on a clean field, then turn the field 25 deg in azimuth (same norm and dip: passes every gate).

    Two filters from ``make()`` see the same readings, one with the turned
    field and one without; returns the largest difference of their tilts
    (deg) while the first follows the bent field, and its heading change
    against the second (deg).
    """
    bent_ekf = make()
    _feed(bent_ekf, _still_events(Q_TILTED, 20.0, seed=3))
    clean_ekf = copy.deepcopy(bent_ekf)  # the same readings so far: settled once (for CI's time), then copied
    turn = math.radians(25.0)
    c, s = math.cos(turn), math.sin(turn)
    bent = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ FIELD_N
    t0 = bent_ekf.t_ns + 10_000_000
    worst = 0.0
    for ev_bent, ev_clean in zip(_still_events(Q_TILTED, 20.0, seed=4, field_n=bent, t0=t0),
                                 _still_events(Q_TILTED, 20.0, seed=4, t0=t0)):
        _feed(bent_ekf, [ev_bent])
        _feed(clean_ekf, [ev_clean])
        worst = max(worst, math.degrees(_tilt_between(bent_ekf.q, clean_ekf.q)))
    return worst, math.degrees(wrap_angle(_yaw(bent_ekf.q) - _yaw(clean_ekf.q)))


# a weak accelerometer, as while walking, so that a magnetometer update could move the tilt; the noise floors'
# scale fixed (noise_scale_rate=0): the bent and the clean filter would learn different scales, and their tilts
# would differ by that, not by what the magnetometer update does
WEAK_ACC = {"acc_noise_base": 0.1, "mag_gate_nis": 1e9, "noise_scale_rate": 0.0}


class _TiltWatch(AttitudeEKF):
    """Records how far each magnetometer update itself moves the body-frame "up" direction."""

    max_mag_tilt_deg = 0.0

    def update_mag(self, t_ns, mx, my, mz):
        before = self.q
        flags = super().update_mag(t_ns, mx, my, mz)
        if self.initialized and before != (1.0, 0.0, 0.0, 0.0):
            self.max_mag_tilt_deg = max(self.max_mag_tilt_deg, math.degrees(_tilt_between(before, self.q)))
        return flags


def test_heading_only_magnetometer_never_tilts_the_attitude():
    made = []

    def make():
        made.append(_TiltWatch(**WEAK_ACC))
        return made[-1]

    worst, turned = _max_tilt_under_azimuth_disturbance(make)
    assert turned < -10.0  # it follows the bent field (the gate is off here) ...
    assert made[0].max_mag_tilt_deg < 1e-4  # ... no magnetometer update moves roll or pitch (acos floor ~1e-6 deg);
    assert worst < 0.5  # the tilt differs only by what the other heading changes the accelerometer's updates


def test_a_full_vector_update_tilts_under_the_same_disturbance():
    """What makes the test above able to fail: the paper's eq. 12, in our filter and in the paper's."""
    from core.pdr.attitude_qekf import QuaternionEKF

    worst_full, _ = _max_tilt_under_azimuth_disturbance(lambda: AttitudeEKF(mag_mode="full", **WEAK_ACC))
    assert worst_full > 2.0
    # the old "heading-only" option of the paper's filter rewrote the vector but kept the full Jacobian
    worst_old, _ = _max_tilt_under_azimuth_disturbance(lambda: QuaternionEKF(mag_heading_only=True))
    assert worst_old > 1.0


@pytest.mark.parametrize("sensor", ["gyro", "acc", "mag"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_inputs_are_skipped_counted_and_never_reach_the_state(sensor, bad):
    events = list(_still_events(Q_TILTED, 10.0, seed=5))
    clean = AttitudeEKF()
    _feed(clean, events)
    hit = [i for i, e in enumerate(events) if e[0] == sensor][300]
    name, t, v = events[hit]
    events[hit] = (name, t, (v[0], bad, v[2]))
    ekf = AttitudeEKF()
    _feed(ekf, events)
    assert ekf.n_skipped_nonfinite == 1
    assert all(math.isfinite(x) for x in ekf.q + ekf.gyro_bias)
    assert np.all(np.isfinite(ekf.P))
    d = abs(sum(a * b for a, b in zip(ekf.q, clean.q)))
    assert math.degrees(2 * math.acos(min(1.0, d))) < 0.05


def test_a_heading_started_wrong_is_released_and_recovered():
    """Start from a field 170 deg off (as when Android re-calibrates after the waving): the relock fixes it."""
    ekf = AttitudeEKF()
    turn = math.radians(170.0)
    c, s = math.cos(turn), math.sin(turn)
    wrong = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ FIELD_N
    _feed(ekf, _still_events(Q_TILTED, 1.0, seed=8, field_n=wrong))
    assert abs(math.degrees(wrap_angle(_yaw(ekf.q) - _yaw(Q_TILTED)))) > 90
    _feed(ekf, _still_events(Q_TILTED, 20.0, seed=9, t0=ekf.t_ns + 10_000_000))
    assert ekf.n_heading_relocks >= 1
    assert abs(math.degrees(wrap_angle(_yaw(ekf.q) - _yaw(Q_TILTED)))) < 1.0


def test_nis_of_a_still_phone_is_near_its_dimension_when_the_noise_is_stated():
    """With the settings matched to the sensor noise, the mean NIS is within a stated band of its dof."""
    rate = 100.0
    n_avg = 0.1 * rate  # readings per update (update_interval_s = 0.1)
    acc_sd = 0.05
    mag_sd = 0.6
    # per-update variance of the unit vectors' averaged directions
    s = AttitudeSettings(acc_noise_base=acc_sd / G / math.sqrt(n_avg), k_a1=0.0, k_a2=0.0,
                         mag_noise_base=mag_sd / 48.0 / math.sqrt(n_avg / 2), k_m1=0.0, k_m2=0.0,
                         gyro_noise_rad_sqrt_s=0.002 / math.sqrt(rate), gyro_scale_noise_sqrt_s=0.0,
                         still_gyro_sd_rad_s=0.0, mag_offset_sd_rad=0.0)  # the synthetic field is not bent
    ekf = AttitudeEKF(s)
    flags = _feed(ekf, _still_events(Q_TILTED, 120.0, seed=11, acc_sd=acc_sd, mag_sd=mag_sd))
    acc = [f.nis for f in flags if f.kind == "acc" and f.nis == f.nis][50:]
    mag = [f.nis for f in flags if f.kind == "mag" and f.nis == f.nis][50:]
    assert 1.5 < np.mean(acc) < 2.6  # dof 2
    assert 0.7 < np.mean(mag) < 1.4  # dof 1


def test_settings_are_validated_and_overridable():
    with pytest.raises(ValueError, match="mag_mode"):
        AttitudeSettings(mag_mode="sideways")
    with pytest.raises(ValueError, match="acc_noise_base"):
        AttitudeEKF(acc_noise_base=-1.0)
    ekf = AttitudeEKF(declination_rad=0.1)
    assert ekf.settings.declination_rad == pytest.approx(0.1)
    assert ekf.status().initialized is False


def test_batch_run_restarts_and_matches_a_fresh_stream_fed_in_chunks():
    """run() must reset whatever state an earlier stream left (here: a wrong start and a learnt bias)."""
    from core.recording import Recording, make_stream

    events = list(_still_events(Q_TILTED, 8.0, seed=12, gyro_bias=(0.003, 0.0, -0.002)))
    streams = {}
    for name in ("gyro", "acc", "mag"):
        rows = [(t, v) for n, t, v in events if n == name]
        streams[name] = make_stream(name, [t for t, _ in rows], [v for _, v in rows])
    rec = Recording(streams)
    used = AttitudeEKF()
    _feed(used, _still_events(quat.normalize((0.3, 0.1, 0.9, 0.2)), 3.0, seed=13))  # some other phone first
    t_run, q_run = used.run(rec)
    fresh = AttitudeEKF()
    ordered = list(rec.events(["gyro", "acc", "mag"]))
    rng = np.random.default_rng(14)
    i = 0
    while i < len(ordered):
        k = int(rng.integers(1, 400))
        _feed(fresh, ordered[i:i + k])
        fresh.status()  # what the app asks between chunks
        i += k
    assert len(t_run) == len(ordered)
    np.testing.assert_allclose(q_run[-1], fresh.q, atol=1e-12)
    np.testing.assert_allclose(used.gyro_bias, fresh.gyro_bias, atol=1e-12)


def _flat_turning_events(seconds, *, z_offset_uT, seed=21, rate=50.0, t0=10**12):
    """A phone held nearly flat (tilt wobbling +-8 deg), turning slowly about the vertical; mag with a z offset."""
    rng = np.random.default_rng(seed)
    t = t0
    dt = 1.0 / rate
    yaw_rate = 0.25
    for k in range(int(seconds * rate)):
        t += int(1e9 * dt)
        tau = k * dt
        yaw = yaw_rate * tau
        roll = math.radians(8.0) * math.sin(0.7 * tau)
        pitch = math.radians(6.0) * math.sin(0.45 * tau + 1.0)
        q = quat.multiply(quat.multiply(quat.from_axis_angle((0, 0, 1), yaw), quat.from_axis_angle((1, 0, 0), pitch)),
                          quat.from_axis_angle((0, 1, 0), roll))
        R = _rot(q)
        # body rate by finite difference of the attitude
        tau2 = tau + 1e-4
        q2 = quat.multiply(quat.multiply(quat.from_axis_angle((0, 0, 1), yaw_rate * tau2),
                                         quat.from_axis_angle((1, 0, 0), math.radians(6.0) * math.sin(0.45 * tau2 + 1.0))),
                           quat.from_axis_angle((0, 1, 0), math.radians(8.0) * math.sin(0.7 * tau2)))
        dq = quat.multiply(quat.conjugate(q), q2)
        w = np.array(dq[1:]) * 2.0 / 1e-4
        yield "gyro", t, tuple(w + rng.normal(0, 0.002, 3))
        yield "acc", t + 1000, tuple(R.T @ np.array([0.0, 0.0, G]) + rng.normal(0, 0.02, 3))
        yield "mag", t + 2000, tuple(R.T @ FIELD_N + np.array([0.0, 0.0, z_offset_uT]) + rng.normal(0, 0.3, 3))
    return q


def test_the_sites_field_removes_a_vertical_offset_no_rotation_can_see():
    """ETH-like: a flat phone's calibration 40 uT off in z gives heading errors as it wobbles; the WMM field fixes it."""
    events = list(_flat_turning_events(150.0, z_offset_uT=40.0))  # the same readings for both (tuples: not changed)

    def run(with_site):
        # the field's heading offset state off in both (a site's field drops it; without one it would carry part
        # of the miscalibration's heading error: 3.6 deg instead of 4+)
        ekf = AttitudeEKF(mag_offset_sd_rad=0.0)
        if with_site:
            ekf.set_site_field(48.0, DIP)
        errs = []
        t_end = events[-1][1]
        for name, t, v in events:
            _feed(ekf, [(name, t, v)])
            if name == "gyro" and t > t_end - 30e9:
                tau = (t - 10**12) * 1e-9
                errs.append(abs(math.degrees(wrap_angle(_yaw(ekf.q) - (0.25 * tau + math.pi / 2)))))
        return ekf, float(np.median(errs))

    plain, err_plain = run(False)
    fixed, err_fixed = run(True)
    assert fixed.vertical_offset_uT[2] == pytest.approx(40.0, abs=3.0)
    assert abs(fixed.vertical_offset_uT[0]) < 5.0 and abs(fixed.vertical_offset_uT[1]) < 5.0
    assert plain.vertical_offset_uT == (0.0, 0.0, 0.0)
    assert err_fixed < 2.0
    assert err_plain > 2 * err_fixed
