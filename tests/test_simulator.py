"""desktop.simulator: self-consistent sensor physics, an independent gait model, exact truth, sampling and
reproducibility.

Every simulation is seeded.  Tolerances are stated next to each assertion;
noise-dependent ones are several standard errors wide, the others are set by
the numerical method the test itself uses (e.g. gyro integration).  The
quaternion maths comes from core.quaternion (tested in test_quaternion.py).
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core import quaternion as quat
from core.conventions import wrap_angle
from core.recording import read_recording, write_recording
from desktop.simulator import (
    DisturbanceZone,
    SimulatedWalk,
    WalkTruth,
    default_step_length_m,
    demo_walk,
    simulate_walk,
)

G = 9.80665
RECT = [(0, 0), (20, 0), (20, 10), (0, 10), (0, 0)]
#: no sensor noise and no biases (the physics alone)
QUIET = dict(gyro_noise_rad_s=0.0, gyro_bias_rad_s=(0, 0, 0), acc_noise_m_s2=0.0, mag_noise_uT=0.0)
#: a phone held perfectly still in the hand (no drift)
STILL_HAND = dict(hand_drift_deg_s=(0, 0, 0))
DEMO_FILE = Path(__file__).resolve().parents[1] / "desktop" / "data" / "demo_walk.csv.gz"


def mats(q):
    """Rotation matrices (n, 3, 3), v_n = R v_b."""
    return quat.to_matrix_array(np.atleast_2d(q))


def angle_deg(q1, q2):
    return math.degrees(2.0 * math.acos(min(1.0, abs(float(np.dot(q1, q2))))))


def integrate_gyro(t_ns, omega_b, q0):
    """q_{k+1} = q_k (x) exp(w dt / 2) with w the mean of the two samples (second order)."""
    q = tuple(float(x) for x in q0)
    dt = np.diff(t_ns) * 1e-9
    rv = 0.5 * (omega_b[1:] + omega_b[:-1]) * dt[:, None]
    for r in rv.tolist():
        q = quat.normalize(quat.multiply(q, quat.from_rotation_vector(r)))
    return np.array(q)


def window(stream, t0_ns, t1_ns):
    m = (stream.t_ns >= t0_ns) & (stream.t_ns < t1_ns)
    return stream.t_ns[m], stream.values[m]


def double_integrate(t_ns, a):
    dt = np.diff(t_ns) * 1e-9
    vel = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (a[1:] + a[:-1]) * dt[:, None], axis=0)])
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt[:, None], axis=0)])
    return vel, pos


# -- results and metadata ------------------------------------------------------


def test_result_types_and_recording_contents():
    walk = simulate_walk(RECT, seed=0)
    assert isinstance(walk, SimulatedWalk) and isinstance(walk.truth, WalkTruth)
    rec = walk.recording
    assert set(rec.streams) == {"acc", "gyro", "mag"}
    assert rec.streams["mag"].unit == "uT" and rec.streams["acc"].columns == ("x", "y", "z")
    assert rec.device == {"model": "simulator"}
    md = rec.metadata
    assert md["simulator"] == "2" and md["seed"] == 0
    # the default step length is the walk ratio's (Sekiya & Nagasaki 1998) for 1.75 m at 1.8 steps/s
    assert md["step_length_m"] == pytest.approx(default_step_length_m(1.75, 1.8), rel=1e-12)
    assert 0.68 < md["step_length_m"] < 0.72
    assert md["waypoints_en_m"][1] == [20.0, 0.0]
    assert md["truth"]["n_steps"] == walk.truth.n_steps
    assert md["phone_yaw_offset_deg"] != 0  # by default the phone does not point exactly where the walker goes
    json.dumps(md)  # the header must be JSON
    assert rec.t0_ns >= 10**12  # a large phone-like clock
    for s in rec.streams.values():
        assert s.t_ns.dtype == np.int64 and np.all(np.diff(s.t_ns) > 0)
        assert np.all(np.isfinite(s.values))
    with pytest.raises(dataclasses.FrozenInstanceError):
        walk.truth.n_steps = 3
    for arr in (walk.truth.step_east_m, walk.truth.att_q_wxyz, walk.truth.mag_field_enu_uT,
                walk.truth.att_gyro_bias_rad_s):
        with pytest.raises(ValueError):
            arr[0] = 1.0  # truth arrays are read-only
    np.testing.assert_array_equal(walk.truth.mag_t_ns, rec.streams["mag"].t_ns)


def test_recording_round_trips_through_the_file_format(tmp_path):
    walk = simulate_walk([(0, 0), (6, 0)], seed=4)
    path = tmp_path / "sim.csv.gz"
    write_recording(str(path), walk.recording)
    back = read_recording(str(path))
    assert back.metadata == walk.recording.metadata
    for name, s in walk.recording.streams.items():
        np.testing.assert_array_equal(back.streams[name].t_ns, s.t_ns)
        np.testing.assert_allclose(back.streams[name].values, s.values, rtol=0, atol=0)


def test_invalid_parameters_are_rejected():
    with pytest.raises(ValueError, match="waypoints"):
        simulate_walk([])
    with pytest.raises(ValueError, match="rate_hz"):
        simulate_walk(RECT, rate_hz=0)
    with pytest.raises(ValueError, match="timestamp_jitter"):
        simulate_walk(RECT, timestamp_jitter=0.9)
    with pytest.raises(ValueError, match="gyro_bias"):
        simulate_walk(RECT, gyro_bias_rad_s=(0, 0))
    with pytest.raises(ValueError, match="radius"):
        DisturbanceZone(center_en_m=(0, 0), radius_m=0, field_enu_uT=(1, 2, 3))
    with pytest.raises(ValueError, match="strength_scale"):
        DisturbanceZone(center_en_m=(0, 0), radius_m=1, strength_scale=0)
    with pytest.raises(ValueError, match="soft_iron"):
        simulate_walk(RECT, mag_soft_iron=np.diag([1.0, 1.0, 0.0]))
    with pytest.raises(ValueError, match="cv"):
        simulate_walk(RECT, step_length_cv=0.5)
    with pytest.raises(ValueError, match="hand_drift"):
        simulate_walk(RECT, hand_drift_deg_s=(0.1, -0.1, 0))
    with pytest.raises(ValueError, match="mag_uncalibrated_stream"):
        simulate_walk(RECT, mag_uncalibrated_stream="acc")
    with pytest.raises(TypeError):
        simulate_walk(RECT, seed=None)  # an explicit integer seed: recordings must be reproducible
    with pytest.raises(ValueError, match="nothing to simulate"):
        simulate_walk([(0, 0)], still_start_s=0, still_end_s=0)


# -- accelerometer -------------------------------------------------------------


def test_flat_still_phone_at_rest_measures_g_along_device_z():
    # a single waypoint: standing only; phone flat, screen up, hand perfectly still
    walk = simulate_walk([(0, 0)], still_start_s=4, still_end_s=0, phone_pitch_deg=0, **STILL_HAND,
                         acc_noise_m_s2=0.02, seed=1)
    acc = walk.recording.streams["acc"].values
    n = len(acc)
    assert walk.truth.n_steps == 0 and n > 350
    tol = 5 * 0.02 / math.sqrt(n)  # 5 standard errors of the mean
    np.testing.assert_allclose(acc.mean(axis=0), [0, 0, G], atol=tol)
    assert abs(np.linalg.norm(acc, axis=1).mean() - G) < tol
    assert np.all(np.abs(acc.std(axis=0) / 0.02 - 1) < 0.15)  # the noise level as asked (n > 350: +-15 %)


def test_held_phone_at_rest_measures_gravity_rotated_by_the_truth_attitude_plus_bias():
    bias = (0.05, -0.03, 0.08)
    walk = simulate_walk(RECT, acc_bias_m_s2=bias, seed=2)  # default pitch 25 deg, yaw offset and hand drift
    tr = walk.truth
    t, acc = window(walk.recording.streams["acc"], tr.walk_start_t_ns - 2 * 10**9, tr.walk_start_t_ns)
    assert len(t) > 150
    expected = np.einsum("nji,j->ni", mats(tr.attitude_at(t)), [0, 0, G]) + bias  # R^T (0, 0, g) + bias
    tol = 5 * 0.02 / math.sqrt(len(t))
    np.testing.assert_allclose((acc - expected).mean(axis=0), 0, atol=tol)
    np.testing.assert_allclose(tr.acc_bias_m_s2, bias)
    # pitched up by ~25 deg: gravity shows on the device y axis as g sin(pitch) (+- the hand drift)
    assert 20 < math.degrees(math.asin((acc[:, 1] - bias[1]).mean() / G)) < 30


def test_double_integrated_acceleration_reproduces_the_phone_trajectory():
    """The specific force rotated to ENU minus g integrates twice to the phone's truth trajectory.

    Trapezoid integration at 400 Hz of exact data over ~25 s (the heel-strike transients are 12 ms wide):
    tolerance 3 cm everywhere along the walk (measured 0.9 cm); at rest again at the end (< 0.01 m/s).
    """
    walk = simulate_walk([(0, 0), (12, 0), (12, 8)], rate_hz=400, timestamp_jitter=0.02, **QUIET, seed=5)
    tr = walk.truth
    acc = walk.recording.streams["acc"]
    a_n = np.einsum("nij,nj->ni", mats(tr.attitude_at(acc.t_ns)), acc.values) - [0, 0, G]
    vel, pos = double_integrate(acc.t_ns, a_n)
    phone = tr.phone_position_at(acc.t_ns)
    assert np.linalg.norm(vel[-1]) < 0.01  # at rest again (m/s)
    assert np.max(np.abs(pos - (phone - phone[0]))) < 0.03
    # the walker (truth positions) ends at the last waypoint; the phone at rest is above it
    end = np.array([tr.step_east_m[-1] - tr.start_east_m, tr.step_north_m[-1] - tr.start_north_m])
    np.testing.assert_allclose(end, [12, 8], atol=1e-9)
    np.testing.assert_allclose(pos[-1, :2], end, atol=0.03)
    # and in between, the phone stays within the gait's few cm of the walker
    walker = tr.position_at(acc.t_ns)
    assert np.max(np.hypot(*(phone[:, :2] - walker).T)) < 0.06


def test_gait_follows_the_inverted_pendulum_not_a_filter():
    """The phone's vertical excursion per step is the inverted pendulum's for that step's length
    (Zijlstra & Hof 2003: l = 1.25 * 2 sqrt(2 L h - h^2), L = 0.53 height) times the hand's gain 0.85.

    Read from the truth trajectory over the cruise part; the envelope interpolates between neighbouring
    steps (CV 3 %), so the check is on the median ratio, 3 %.  Then: the step length follows from h by the
    pendulum formula (the median within 3 %) for short and long steps, and the raw norm swings 4-7 m/s^2
    per step at 1.8 steps/s with 0.7 m steps (a hand-held phone in front of the chest).
    """
    for length, height in ((0.55, 1.6), (0.7, 1.75), (0.85, 1.9)):
        walk = simulate_walk([(0, 0), (30, 0)], step_length_m=length, height_m=height, **QUIET, **STILL_HAND,
                             seed=6)
        tr = walk.truth
        leg = 0.53 * height
        hs = tr.step_t_ns
        h_est, lengths = [], []
        for k in range(4, tr.n_steps - 4):
            t = np.linspace(hs[k - 1], hs[k], 400).astype(np.int64)
            z = tr.phone_position_at(t)[:, 2]
            h_est.append(np.ptp(z) / 0.85)
            lengths.append(tr.step_length_m[k])
        h_est, lengths = np.array(h_est), np.array(lengths)
        l_pendulum = 1.25 * 2 * np.sqrt(2 * leg * h_est - h_est ** 2)
        assert np.median(l_pendulum / lengths) == pytest.approx(1.0, abs=0.03), length
        assert 0.02 < np.median(h_est) < 0.07  # a few cm of vertical excursion of the body
        if length == 0.7:
            acc = walk.recording.streams["acc"]
            norm = np.linalg.norm(acc.values, axis=1)
            b = np.searchsorted(acc.t_ns, hs[3:-3])
            pp = np.array([np.ptp(norm[i0:i1]) for i0, i1 in zip(b[:-1], b[1:])])
            assert 4.0 < np.median(pp) < 7.0, np.median(pp)
            assert np.max(np.abs(norm - G)) < 6.0


def test_the_step_detector_of_core_finds_every_simulated_step():
    from core.pdr.steps import StepDetector

    for wp, seed in (([(0, 0), (30, 0)], 30), (RECT, 31)):
        walk = simulate_walk(wp, seed=seed)
        acc = walk.recording.streams["acc"]
        steps = StepDetector().run(acc.t_ns, acc.values)
        assert len(steps) == walk.truth.n_steps
        d = np.abs(np.array([s.t_ns for s in steps])[:, None] - walk.truth.step_t_ns[None, :]).min(axis=1) * 1e-9
        assert np.max(d) < 0.2  # within 0.2 s of a true heel strike


def test_walking_starts_and_stops_smoothly():
    walk = simulate_walk([(0, 0), (15, 0)], **QUIET, seed=7)
    tr = walk.truth
    acc = walk.recording.streams["acc"]
    norm = np.linalg.norm(acc.values, axis=1)
    period_ns = int(1e9 / 1.8)
    before = norm[acc.t_ns < tr.walk_start_t_ns]
    first_quarter = norm[(acc.t_ns >= tr.walk_start_t_ns) & (acc.t_ns < tr.walk_start_t_ns + period_ns // 4)]
    mid = norm[(acc.t_ns >= tr.step_t_ns[5]) & (acc.t_ns < tr.step_t_ns[9])]
    after = norm[acc.t_ns > tr.walk_end_t_ns + period_ns]  # the hand settles within one step after stopping
    # standing: no noise here, and the hand drift only rotates the phone (no linear acceleration)
    assert np.ptp(before) < 1e-6 and np.ptp(after) < 1e-6
    assert np.ptp(first_quarter) < 1.0 and np.ptp(mid) > 3.0  # the gait amplitude ramps in over the first step


C120 = (2.6 + 2.6 * math.cos(math.radians(120)), 2.6 * math.sin(math.radians(120)))


@pytest.mark.parametrize("waypoints, shortest_m", [
    ([(0, 0), (12, 0), (0, 2)], 0.5),  # a 170 deg turn: slow down to 0.8 m/s
    ([(0, 0), (6, 0), (6, 0.3), (12, 0.3)], 0.5),  # a 30 cm side-step: slow down to 0.24 m/s
    ([(0, 0), (2.6, 0), C120, (-5, 6)], 0.67),  # a 120 deg turn that just does not fit: a brief slow-down
])
def test_slowing_down_for_tight_corners_keeps_accelerations_moderate(waypoints, shortest_m):
    """The hand's acceleration stays within what steady walking produces (|norm - g| < 6 m/s^2)."""
    walk = simulate_walk(waypoints, acc_noise_m_s2=0.0, step_length_cv=0.0, seed=23)
    norm = np.linalg.norm(walk.recording.streams["acc"].values, axis=1)
    assert np.max(np.abs(norm - G)) < 6.0
    lengths = walk.truth.step_length_m[1:-1]  # without the half steps from and to rest
    assert lengths.min() < shortest_m  # the walker did slow down


# -- gyroscope -----------------------------------------------------------------


@pytest.mark.parametrize("calibration_s", [0.0, 15.0])
def test_integrated_gyro_reproduces_the_truth_attitude(calibration_s):
    """Integration error of exact 100 Hz data over ~60 s: measured < 0.01 deg, allowed 0.3 deg."""
    walk = simulate_walk(RECT, calibration_motion_s=calibration_s, **QUIET, seed=8)
    gyro = walk.recording.streams["gyro"]
    tr = walk.truth
    q_end = integrate_gyro(gyro.t_ns, gyro.values, tr.attitude_at(gyro.t_ns[0]))
    assert walk.recording.duration_s > 50
    assert angle_deg(q_end, tr.attitude_at(gyro.t_ns[-1])) < 0.3
    # and over the first half, against the dense truth grid
    half = len(gyro.t_ns) // 2
    q_half = integrate_gyro(gyro.t_ns[:half + 1], gyro.values[:half + 1], tr.attitude_at(gyro.t_ns[0]))
    i = np.searchsorted(tr.att_t_ns, gyro.t_ns[half])
    assert abs(int(tr.att_t_ns[i]) - int(gyro.t_ns[half])) <= 5_000_000
    assert angle_deg(q_half, tr.att_q_wxyz[i]) < 0.5  # the grid point is up to 5 ms off (< 0.5 deg at 90 deg/s)
    assert angle_deg(q_half, tr.attitude_at(gyro.t_ns[half])) < 0.3
    # the truth body rate is what the gyro measures without bias and noise
    np.testing.assert_allclose(tr.body_rate_at(gyro.t_ns), gyro.values, atol=1e-9)


def test_gyro_bias_and_noise_are_as_asked():
    bias = (0.01, -0.02, 0.005)
    walk = simulate_walk([(0, 0)], still_start_s=5, still_end_s=0, **STILL_HAND,
                         gyro_bias_rad_s=bias, gyro_noise_rad_s=0.004, seed=9)
    g = walk.recording.streams["gyro"].values
    np.testing.assert_allclose(g.mean(axis=0), bias, atol=5 * 0.004 / math.sqrt(len(g)))
    assert np.all(np.abs(g.std(axis=0) / 0.004 - 1) < 0.15)
    np.testing.assert_allclose(walk.truth.gyro_bias_rad_s, bias)
    np.testing.assert_allclose(walk.truth.att_gyro_bias_rad_s, np.tile(bias, (len(walk.truth.att_t_ns), 1)))


def test_a_still_hand_drifts_so_a_one_second_gyro_mean_is_not_the_bias():
    """Standing with the default hand drift (RMS 0.3/0.5/0.5 deg/s, < 0.3 Hz): one-second means of the gyro
    differ from the true bias by far more than the bias itself, yet gyro - true rate - true bias is noise."""
    bias = np.array([0.002, -0.0015, 0.001])
    walk = simulate_walk([(0, 0)], still_start_s=60, still_end_s=0, gyro_bias_rad_s=bias, seed=24)
    gyro = walk.recording.streams["gyro"]
    tr = walk.truth
    sec = (gyro.t_ns - gyro.t_ns[0]) // 10**9
    means = np.array([gyro.values[sec == s].mean(axis=0) for s in range(59)])
    err_deg_s = np.degrees(np.sqrt(np.mean((means - bias) ** 2, axis=0)))
    assert np.all(err_deg_s > 0.15) and np.all(err_deg_s < 1.5), err_deg_s  # vs the bias: 0.06-0.11 deg/s
    rate = np.degrees(np.sqrt(np.mean(tr.body_rate_at(gyro.t_ns) ** 2, axis=0)))
    assert np.all(rate > 0.15) and np.all(rate < 1.0), rate  # RMS rates of about 0.3/0.5/0.5 deg/s
    # the drift is slow: the attitude wanders by degrees, not tens of degrees, over a minute
    walk_deg = [angle_deg(tr.att_q_wxyz[0], q) for q in tr.att_q_wxyz[::200]]
    assert 0.5 < max(walk_deg) < 15.0
    resid = gyro.values - tr.body_rate_at(gyro.t_ns) - tr.gyro_bias_at(gyro.t_ns)
    np.testing.assert_allclose(resid.mean(axis=0), 0, atol=5 * 0.003 / math.sqrt(len(resid)))
    assert np.all(np.abs(resid.std(axis=0) / 0.003 - 1) < 0.05)  # n ~ 6000: +-5 % is > 5 standard errors


def test_gyro_bias_random_walk_is_exposed_in_the_truth():
    sd = 2e-4  # rad/s per sqrt(s)
    walk = simulate_walk(RECT, gyro_bias_walk_rad_s_sqrt_s=sd, seed=25)
    tr = walk.truth
    gyro = walk.recording.streams["gyro"]
    b = tr.gyro_bias_at(gyro.t_ns)
    np.testing.assert_allclose(b[0], tr.gyro_bias_rad_s, atol=sd * 2)  # starts at the constant part
    # increments over 10 s have the standard deviation sd sqrt(10) (150 samples of 3 axes: +-35 %)
    grid = np.arange(tr.att_t_ns[0], tr.att_t_ns[-1], 10**9)
    d10 = np.diff(tr.gyro_bias_at(grid)[::10], axis=0)
    assert np.std(d10) == pytest.approx(sd * math.sqrt(10), rel=0.35)
    resid = gyro.values - tr.body_rate_at(gyro.t_ns) - b
    assert np.all(np.abs(resid.mean(axis=0)) < 5 * 0.003 / math.sqrt(len(resid)))


# -- magnetometer --------------------------------------------------------------


def test_magnetometer_norm_and_direction_match_the_earth_field():
    h = (1.0, 21.0, -43.0)
    walk = simulate_walk(RECT, earth_field_enu_uT=h, **QUIET, seed=10)
    mag = walk.recording.streams["mag"]
    np.testing.assert_allclose(np.linalg.norm(mag.values, axis=1), np.linalg.norm(h), rtol=1e-9)
    back = np.einsum("nij,nj->ni", mats(walk.truth.attitude_at(mag.t_ns)), mag.values)  # R m_b
    np.testing.assert_allclose(back, np.tile(h, (len(back), 1)), atol=1e-9)
    np.testing.assert_allclose(walk.truth.mag_field_enu_uT, back, atol=1e-9)
    # hard iron: a constant offset in the device frame
    hi = (12.0, -5.0, 30.0)
    walk2 = simulate_walk(RECT, earth_field_enu_uT=h, mag_hard_iron_uT=hi, **QUIET, seed=10)
    m2 = walk2.recording.streams["mag"].values
    np.testing.assert_allclose(m2 - hi, mag.values, atol=1e-9)
    # with noise the mean norm stays |h| within 5 standard errors (the noise adds sigma^2 / |h| ~ 0.003 uT)
    noisy = simulate_walk(RECT, earth_field_enu_uT=h, mag_noise_uT=0.4, seed=10).recording.streams["mag"].values
    assert abs(np.linalg.norm(noisy, axis=1).mean() - np.linalg.norm(h)) < 5 * 0.4 / math.sqrt(len(noisy)) + 0.01


def test_soft_and_hard_iron_and_the_uncalibrated_stream():
    h = (0.0, 20.0, -44.0)
    soft = [[1.10, 0.05, 0.00], [0.05, 0.92, 0.03], [0.00, 0.03, 1.02]]
    hi = (20.0, -8.0, 35.0)
    kw = dict(earth_field_enu_uT=h, mag_hard_iron_uT=hi, mag_soft_iron=soft, **QUIET, seed=26)
    walk = simulate_walk(RECT, **kw)
    mag = walk.recording.streams["mag"]
    # invert the iron and rotate back: the Earth field
    m = (mag.values - hi) @ np.linalg.inv(soft).T
    back = np.einsum("nij,nj->ni", mats(walk.truth.attitude_at(mag.t_ns)), m)
    np.testing.assert_allclose(back, np.tile(h, (len(back), 1)), atol=1e-9)
    np.testing.assert_allclose(walk.truth.mag_soft_iron, soft)
    # the ellipsoid is visible: the norm varies with the attitude (the phone turns through 360 deg)
    assert np.ptp(np.linalg.norm(mag.values, axis=1)) > 5.0
    # with an uncalibrated stream, "mag" is the iron-free reading and the other one is the raw reading
    both = simulate_walk(RECT, mag_uncalibrated_stream="mag_uncal", **kw).recording
    assert set(both.streams) == {"acc", "gyro", "mag", "mag_uncal"}
    np.testing.assert_allclose(both.streams["mag_uncal"].values, mag.values, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(both.streams["mag"].values, axis=1), np.linalg.norm(h), rtol=1e-9)
    np.testing.assert_array_equal(both.streams["mag"].t_ns, mag.t_ns)
    assert both.streams["mag_uncal"].unit == "uT"


def test_disturbance_zone_adds_a_field_only_inside_it():
    zone = DisturbanceZone(center_en_m=(10.0, 0.0), radius_m=2.0, field_enu_uT=(15.0, -10.0, 20.0))
    h = (0.0, 20.0, -44.0)
    walk = simulate_walk([(0, 0), (20, 0)], disturbance_zones=[zone], **QUIET, seed=11)
    mag = walk.recording.streams["mag"]
    pos = walk.truth.phone_position_at(mag.t_ns)
    dist = np.hypot(pos[:, 0] - 10.0, pos[:, 1])
    dev = np.abs(np.linalg.norm(mag.values, axis=1) - np.linalg.norm(h))
    outside = dist > 2.0
    assert outside.sum() > 300 and (dist < 0.5).sum() > 5
    assert dev[outside].max() < 1e-9
    assert dev[dist < 0.5].min() > 5.0  # near the centre the added 27 uT changes the norm a lot
    # the taper is smooth: full field at the centre, half at half the radius
    np.testing.assert_allclose(zone.field_at([10.0, 11.0, 12.0, 13.0], [0, 0, 0, 0]),
                               [[15, -10, 20], [7.5, -5, 10], [0, 0, 0], [0, 0, 0]], atol=1e-12)


def test_azimuth_zone_turns_the_field_without_changing_norm_or_dip():
    """A zone that only turns the horizontal field: invisible to a norm or dip gate, 30 deg off at the
    centre; the truth field at every magnetometer sample is the measured one rotated back."""
    zone = DisturbanceZone(center_en_m=(10.0, 0.0), radius_m=3.0, rotation_deg=30.0)
    h = np.array([0.0, 20.0, -44.0])
    walk = simulate_walk([(0, 0), (20, 0)], disturbance_zones=[zone], **QUIET, seed=27)
    tr = walk.truth
    mag = walk.recording.streams["mag"]
    back = np.einsum("nij,nj->ni", mats(tr.attitude_at(mag.t_ns)), mag.values)  # R m_b
    np.testing.assert_allclose(back, tr.mag_field_enu_uT, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), np.linalg.norm(h), rtol=1e-12)
    np.testing.assert_allclose(back[:, 2], h[2], atol=1e-9)  # the dip is kept too
    az = np.degrees(wrap_angle(np.arctan2(back[:, 1], back[:, 0]) - math.pi / 2))  # CCW from magnetic north
    pos = tr.phone_position_at(mag.t_ns)
    w = zone.weight(pos[:, 0], pos[:, 1])
    np.testing.assert_allclose(az, 30.0 * w, atol=1e-9)
    assert az.max() > 29.0 and np.all(az[np.hypot(pos[:, 0] - 10, pos[:, 1]) > 3.0] == pytest.approx(0, abs=1e-9))
    np.testing.assert_allclose(tr.mag_field_at(mag.t_ns), tr.mag_field_enu_uT, atol=1e-12)
    # dip and strength changes, applied to the field by the zone itself
    z2 = DisturbanceZone(center_en_m=(0.0, 0.0), radius_m=1.0, dip_change_deg=10.0, strength_scale=1.2)
    got = z2.apply(np.tile(h, (2, 1)), np.array([0.0, 5.0]), np.array([0.0, 0.0]))
    dip0 = math.degrees(math.atan2(-h[2], math.hypot(h[0], h[1])))
    assert math.degrees(math.atan2(-got[0, 2], math.hypot(*got[0, :2]))) == pytest.approx(dip0 + 10.0, abs=1e-9)
    assert np.linalg.norm(got[0]) == pytest.approx(1.2 * np.linalg.norm(h), rel=1e-12)
    np.testing.assert_allclose(got[1], h, atol=1e-12)  # outside the radius: unchanged


# -- truth: steps, path, heading ----------------------------------------------


def test_step_count_timing_and_lengths_vary_realistically():
    # 60 m straight at 0.7 m: ~86 steps of travel; the speed ramps from and to rest take 1.5 steps for 0.75 L
    L = 0.7
    walk = simulate_walk([(0, 0), (60, 0)], step_length_m=L, step_length_cv=0.03, step_time_cv=0.02, seed=12)
    tr = walk.truth
    assert tr.n_steps == round(60 / L + 1.5) == len(tr.step_t_ns)
    duration_s = (tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9
    assert abs(duration_s * 1.8 - tr.n_steps) < 1e-6  # a whole number of mean periods
    assert tr.step_t_ns[-1] == tr.walk_end_t_ns
    dt = np.diff(np.r_[tr.walk_start_t_ns, tr.step_t_ns]) * 1e-9
    # step durations: mean 1/f, CV 2 % (n = 86: the CV itself is known to +-15 % x 1.5)
    assert np.mean(dt) == pytest.approx(1 / 1.8, rel=1e-6)
    assert np.std(dt[2:-2]) / np.mean(dt[2:-2]) == pytest.approx(0.02, rel=0.35)
    lengths = tr.step_length_m
    cruise = lengths[2:-2]
    assert np.mean(cruise) == pytest.approx(L, rel=0.01)
    assert np.std(cruise) / np.mean(cruise) == pytest.approx(0.03, rel=0.35)
    np.testing.assert_allclose(lengths.sum(), tr.path_length_m, rtol=1e-12)
    np.testing.assert_allclose(tr.step_east_m, np.cumsum(lengths), atol=1e-9)
    np.testing.assert_allclose(tr.step_north_m, 0, atol=1e-9)
    # no variability asked: heel strikes exactly 1/f apart, all cruise steps exactly L
    exact = simulate_walk([(0, 0), (0.7 * 19.5, 0)], step_length_m=L, step_length_cv=0, step_time_cv=0,
                          seed=12).truth
    assert exact.n_steps == 21  # 19.5 + 1.5: no time stretch
    assert np.all(np.abs(np.diff(exact.step_t_ns) - 1e9 / 1.8) <= 1.0)  # rounding to integer ns
    np.testing.assert_allclose(exact.step_length_m[2:-2], L, atol=1e-9)
    # the cosine speed ramp over 1.5 steps from and to rest: its first step, then the rest of 1.25 L
    first = L / 2 * (1 - 1.5 / math.pi * math.sin(math.pi / 1.5))
    np.testing.assert_allclose(exact.step_length_m[[0, -1]], first, atol=1e-9)
    np.testing.assert_allclose(exact.step_length_m[[1, -2]], 1.25 * L - first, atol=1e-9)
    # with corners (walked at full speed): the same rule on the rounded path's length, within half a step
    rect = simulate_walk(RECT, seed=12).truth
    mean_len = default_step_length_m(1.75, 1.8)
    assert abs(rect.path_length_m / mean_len + 1.5 - rect.n_steps) <= 0.5


def test_path_length_is_the_polyline_length_minus_the_rounded_corners():
    tr = simulate_walk(RECT, step_length_m=0.7, seed=13).truth
    assert tr.polyline_length_m == pytest.approx(60.0, abs=1e-9)
    # three 90 deg corners rounded with r = v / turn rate = 1.26 / (pi/2) m each cut r (2 - pi/2) = 0.344 m
    r = 1.8 * 0.7 / math.radians(90.0)
    cut = 3 * r * (2 - math.pi / 2)
    assert tr.path_length_m == pytest.approx(60.0 - cut, abs=1e-6)
    assert tr.path_length_m == pytest.approx(tr.step_length_m.sum(), rel=1e-12)
    # ends at the last waypoint; positions between consecutive steps are at most one step length apart
    assert math.hypot(tr.step_east_m[-1], tr.step_north_m[-1]) < 1e-6
    chord = np.hypot(np.diff(tr.step_east_m), np.diff(tr.step_north_m))
    assert np.all(chord <= tr.step_length_m[1:] + 1e-9)


@pytest.mark.parametrize("offset_deg", [0.0, 12.0, -7.0])
def test_device_y_axis_points_off_the_walking_heading_by_the_yaw_offset(offset_deg):
    """Averaged over a stride, the device y axis' horizontal projection is the walking heading plus the yaw
    offset, within the hand's yaw drift (0.3 deg/s RMS below 0.3 Hz: about 1 deg) -- 2.5 deg allowed."""
    walk = simulate_walk([(0, 0), (3, 4), (3 + 30 * 0.8, 4 - 30 * 0.6)], phone_yaw_offset_deg=offset_deg,
                         seed=14)  # second leg heading -36.87 deg
    tr = walk.truth
    assert tr.phone_yaw_offset_rad == pytest.approx(math.radians(offset_deg))
    heel = tr.step_t_ns
    leg_start = np.flatnonzero(np.abs(np.degrees(tr.step_heading_rad) + 36.87) < 0.01)
    assert len(leg_start) > 20
    errors = []
    for k in range(leg_start[2], leg_start[-4], 2):  # strides in the straight cruise part of the second leg
        t = np.linspace(heel[k], heel[k + 2], 200, endpoint=False).astype(np.int64)
        y_axis = mats(tr.attitude_at(t))[:, :, 1]  # device y in ENU
        mean = y_axis[:, :2].mean(axis=0)
        heading = tr.heading_at(int(t[100]))
        assert heading == pytest.approx(math.atan2(-0.6, 0.8), abs=1e-9)
        errors.append(math.degrees(wrap_angle(math.atan2(mean[1], mean[0]) - heading)) - offset_deg)
        # the truth's device heading is that projection, sample by sample
        np.testing.assert_allclose(tr.device_heading_at(t), np.arctan2(y_axis[:, 1], y_axis[:, 0]), atol=1e-12)
        # the phone is pitched up and the hand sways: single samples differ from the mean
        assert np.degrees(np.ptp(np.arctan2(y_axis[:, 1], y_axis[:, 0]))) > 2.0
    assert len(errors) >= 8
    assert np.max(np.abs(errors)) < 2.5
    # the dense truth grid carries both headings
    i = np.searchsorted(tr.att_t_ns, heel[leg_start[5]])
    assert tr.att_walk_heading_rad[i] == pytest.approx(math.atan2(-0.6, 0.8), abs=1e-9)
    d = math.degrees(wrap_angle(tr.att_device_heading_rad[i] - tr.att_walk_heading_rad[i])) - offset_deg
    assert abs(d) < 8.0  # sway (3 deg) + drift
    np.testing.assert_allclose(tr.step_device_heading_rad, wrap_angle(tr.device_heading_at(tr.step_t_ns)),
                               atol=1e-12)


def test_step_headings_and_lengths_reproduce_the_positions():
    tr = simulate_walk(RECT, seed=15).truth
    # eq. 1 of the paper with the chord length of each step and the truth step heading
    xy = np.r_[[[tr.start_east_m, tr.start_north_m]], np.c_[tr.step_east_m, tr.step_north_m]]
    chord = np.hypot(*np.diff(xy, axis=0).T)
    np.testing.assert_allclose(tr.start_east_m + np.cumsum(chord * np.cos(tr.step_heading_rad)), tr.step_east_m,
                               atol=1e-9)
    np.testing.assert_allclose(tr.start_north_m + np.cumsum(chord * np.sin(tr.step_heading_rad)), tr.step_north_m,
                               atol=1e-9)
    # headings at heel strikes on the first leg are East, on the last leg South
    assert abs(tr.heading_at(int(tr.step_t_ns[5]))) < 1e-9
    assert math.cos(tr.heading_at(int(tr.step_t_ns[-3])) + math.pi / 2) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(tr.position_at(tr.step_t_ns), np.c_[tr.step_east_m, tr.step_north_m], atol=1e-12)


def test_u_turn_is_walked_by_slowing_down_and_turning_on_the_spot():
    walk = simulate_walk([(0, 0), (10, 0), (0, 0)], **QUIET, seed=16)
    tr = walk.truth
    assert math.hypot(tr.step_east_m[-1], tr.step_north_m[-1]) < 1e-6
    assert tr.path_length_m == pytest.approx(20.0, abs=1e-9)  # nothing cut: the walker turns at (10, 0)
    assert np.max(tr.step_east_m) <= 10.0 + 1e-9
    assert math.remainder(tr.heading_at(tr.walk_end_t_ns) - math.pi, 2 * math.pi) == pytest.approx(0, abs=1e-9)
    assert np.all(np.isfinite(walk.recording.streams["acc"].values))
    gz = walk.recording.streams["gyro"].values
    assert np.max(np.abs(gz)) < 3.0  # the turn at ~90 deg/s, plus hand sway


# -- calibration motion --------------------------------------------------------


def test_calibration_motion_tumbles_the_phone_and_returns_to_the_walking_pose():
    walk = simulate_walk(RECT, calibration_motion_s=20.0, **QUIET, seed=17)
    tr = walk.truth
    assert tr.calibration_end_t_ns - tr.calibration_start_t_ns == 20 * 10**9
    assert tr.walk_start_t_ns - tr.calibration_end_t_ns == 2 * 10**9
    t = np.arange(tr.calibration_start_t_ns, tr.calibration_end_t_ns, 20_000_000)
    up_of_axes = mats(tr.attitude_at(t))[:, 2, :]  # the Up component of the device x, y and z axes
    # every device axis is tilted both well above and well below the horizon at some point
    assert np.all(up_of_axes.max(axis=0) > 0.6) and np.all(up_of_axes.min(axis=0) < -0.3)
    # back to the walking pose: the attitude at the end equals the standing pose before walking (hand drift only)
    assert angle_deg(tr.attitude_at(tr.calibration_end_t_ns), tr.attitude_at(tr.walk_start_t_ns)) < 8.0
    _, acc = window(walk.recording.streams["acc"], tr.calibration_start_t_ns, tr.calibration_end_t_ns)
    assert np.all(np.abs(np.linalg.norm(acc, axis=1) - G) < 1.5)  # only small hand accelerations
    assert np.all(tr.step_t_ns > tr.walk_start_t_ns)  # no heel strikes while calibrating
    _, mag = window(walk.recording.streams["mag"], tr.calibration_start_t_ns, tr.calibration_end_t_ns)
    unit = mag / np.linalg.norm(mag, axis=1, keepdims=True)
    assert np.all(unit.max(axis=0) - unit.min(axis=0) > 1.2)  # the field sweeps widely in the device frame


# -- sampling ------------------------------------------------------------------


@pytest.mark.parametrize("rate", [20.0, 100.0, 400.0])
def test_sample_rates_and_jitter_are_as_asked(rate):
    walk = simulate_walk([(0, 0), (10, 0)], rate_hz=rate, timestamp_jitter=0.05, seed=18)
    streams = walk.recording.streams
    expected = {"acc": rate, "gyro": rate, "mag": min(rate, 50.0)}
    for name, r in expected.items():
        s = streams[name]
        dt = np.diff(s.t_ns) * 1e-9
        assert s.rate_hz == pytest.approx(r, rel=0.01)
        # relative jitter: standard error of a std over n >= 190 intervals is < 6 %, allow 20 %
        assert np.std(dt) / np.mean(dt) == pytest.approx(0.05, rel=0.2)
        assert dt.min() > 0
    # explicit rates and no jitter
    walk = simulate_walk([(0, 0), (10, 0)], rate_hz=rate, gyro_rate_hz=200.0, mag_rate_hz=10.0,
                         timestamp_jitter=0.0, seed=18)
    for name, r in {"acc": rate, "gyro": 200.0, "mag": 10.0}.items():
        dt = np.diff(walk.recording.streams[name].t_ns)
        assert np.all(np.abs(dt - 1e9 / r) <= 1.0)  # exact up to integer-ns rounding


def test_streams_have_independent_start_phases_and_cover_the_walk():
    walk = simulate_walk([(0, 0), (10, 0)], seed=19)
    s = walk.recording.streams
    assert len({int(s[n].t_ns[0]) for n in s}) == 3
    for n in s:
        assert s[n].t_ns[0] - 10**12 < 1e9 / 50 and walk.truth.walk_end_t_ns + 1.9e9 < s[n].t_ns[-1]


def test_same_seed_same_recording_different_seed_different_noise():
    a = simulate_walk(RECT, seed=20)
    b = simulate_walk(RECT, seed=20)
    c = simulate_walk(RECT, seed=21)
    for name in a.recording.streams:
        sa, sb, sc = (w.recording.streams[name] for w in (a, b, c))
        # identical output is the contract here, so exact equality is the right check
        assert np.array_equal(sa.t_ns, sb.t_ns) and np.array_equal(sa.values, sb.values)
        assert not np.array_equal(sa.t_ns, sc.t_ns)
    assert np.array_equal(a.truth.step_length_m, b.truth.step_length_m)
    assert np.array_equal(a.truth.att_q_wxyz, b.truth.att_q_wxyz)
    assert not np.allclose(a.truth.step_length_m, c.truth.step_length_m)  # the gait draws differ too

    # the noise itself: each recording minus its noise-free twin (same seed: same timestamps, gait and drift)
    def noise(seed):
        noisy = simulate_walk(RECT, gyro_bias_rad_s=(0, 0, 0), seed=seed).recording.streams["gyro"].values
        return noisy - simulate_walk(RECT, **QUIET, seed=seed).recording.streams["gyro"].values

    n20, n21 = noise(20), noise(21)
    n = min(len(n20), len(n21))
    assert np.allclose(n20.std(axis=0), 0.003, rtol=0.1) and np.allclose(n21.std(axis=0), 0.003, rtol=0.1)
    assert abs(np.corrcoef(n20[:n, 0], n21[:n, 0])[0, 1]) < 0.1  # independent draws (n > 5000: |r| ~ 0.014)


def test_changing_a_noise_or_gait_parameter_keeps_the_timestamps():
    a = simulate_walk(RECT, seed=22).recording
    b = simulate_walk(RECT, acc_noise_m_s2=0.5, seed=22).recording
    c = simulate_walk(RECT, step_length_cv=0.05, phone_yaw_offset_deg=20, seed=22).recording
    for name in a.streams:
        assert np.array_equal(a.streams[name].t_ns, b.streams[name].t_ns)
        assert np.array_equal(a.streams[name].t_ns, c.streams[name].t_ns)
    assert np.std(a.streams["acc"].values - b.streams["acc"].values) > 0.2


# -- the demo ------------------------------------------------------------------


def test_demo_walk_is_a_moderately_hard_closed_loop_of_realistic_size():
    walk = demo_walk()
    tr = walk.truth
    rec = walk.recording
    assert math.hypot(tr.step_east_m[-1] - tr.start_east_m, tr.step_north_m[-1] - tr.start_north_m) < 0.5
    assert 120 <= tr.path_length_m <= 200
    assert 120 <= rec.duration_s <= 180
    headings = np.degrees(np.unwrap(tr.step_heading_rad))
    assert np.ptp(headings) >= 180  # several turns
    assert rec.streams["acc"].rate_hz == pytest.approx(100, rel=0.01)
    md = rec.metadata
    assert md["disturbance_zones"] == [] and 2 <= abs(md["phone_yaw_offset_deg"]) <= 10
    assert np.all(np.abs(tr.gyro_bias_rad_s) >= 0.001) and min(md["hand_drift_deg_s"]) > 0
    assert np.array_equal(demo_walk().recording.streams["mag"].values, rec.streams["mag"].values)


def test_bundled_demo_file_is_the_current_demo_walk():
    """desktop/data/demo_walk.csv.gz is regenerated by tools/make_demo.py whenever the simulator changes.

    To 1e-9 only: numpy releases change the last bit of sin/cos/exp, which the simulator's integrations
    carry on (with numpy 2.4.6 the gyroscope moved by up to 4e-11 rad/s); that is not a change of the
    simulator, whose changes move values by far more."""
    back = read_recording(str(DEMO_FILE))
    rec = demo_walk().recording
    assert back.metadata["simulator"] == rec.metadata["simulator"]
    assert back.metadata["truth"] == rec.metadata["truth"]
    for name, s in rec.streams.items():
        np.testing.assert_array_equal(back.streams[name].t_ns, s.t_ns)
        np.testing.assert_allclose(back.streams[name].values, s.values, rtol=1e-9, atol=1e-9)


# -- properties on random polylines --------------------------------------------

coord = st.floats(-15, 15, allow_nan=False).map(lambda x: round(x, 1))


@settings(max_examples=30, deadline=None)
@given(points=st.lists(st.tuples(coord, coord), min_size=2, max_size=6), turn=st.sampled_from([45.0, 90.0, 180.0]))
def test_random_polylines_give_a_consistent_truth(points, turn):
    pts = np.asarray(points)
    if np.hypot(*np.diff(pts, axis=0).T).sum() < 0.5:
        return  # (almost) no walking
    walk = simulate_walk(points, rate_hz=20.0, still_start_s=0.5, still_end_s=0.5, turn_rate_deg_s=turn, seed=3)
    tr = walk.truth
    L = default_step_length_m(1.75, 1.8)
    assert math.hypot(tr.step_east_m[-1] - pts[-1, 0], tr.step_north_m[-1] - pts[-1, 1]) < 1e-6
    assert tr.n_steps >= 1 and abs((tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9 * 1.8 - tr.n_steps) < 1e-6
    assert np.all(np.diff(np.r_[tr.walk_start_t_ns, tr.step_t_ns]) > 0)
    assert np.all(tr.step_length_m >= -1e-12)
    stretch = 1 + 0.5 / tr.n_steps  # the plan is stretched to a whole number of steps: speeds up by at most this
    # the variability moves each heel strike by at most 30 % of the adjacent plan steps: at most 1.6 x a plan step
    assert np.all(tr.step_length_m <= 1.6 * L * stretch + 1e-9)
    assert tr.path_length_m == pytest.approx(tr.step_length_m.sum(), rel=1e-9, abs=1e-9)
    assert tr.path_length_m <= tr.polyline_length_m + 1e-9
    # heading is continuous and turns at about the turn rate (the time warp: at most 1.5 x)
    t = np.arange(tr.walk_start_t_ns, tr.walk_end_t_ns, 5_000_000)
    h = tr.heading_at(t)
    assert np.max(np.abs(np.diff(h))) <= math.radians(turn) * 0.005 * stretch * 1.5 + 1e-9
    for s in walk.recording.streams.values():
        assert np.all(np.isfinite(s.values))
