"""desktop.simulator: self-consistent sensor physics, exact truth, sampling and reproducibility.

Every simulation is seeded.  Tolerances are stated next to each assertion;
noise-dependent ones are several standard errors wide, the others are set by
the numerical method the test itself uses (e.g. gyro integration).
"""

import dataclasses
import json
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from core.recording import read_recording, write_recording
from desktop.simulator import DisturbanceZone, SimulatedWalk, WalkTruth, demo_walk, simulate_walk

G = 9.80665
RECT = [(0, 0), (20, 0), (20, 10), (0, 10), (0, 0)]
#: no sensor noise and no biases (the physics alone)
QUIET = dict(gyro_noise_rad_s=0.0, gyro_bias_rad_s=(0, 0, 0), acc_noise_m_s2=0.0, mag_noise_uT=0.0)


# -- independent helpers (deliberately not shared with the simulator) --------


def qmul(p, q):
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def qmat(q):
    """Rotation matrices (n, 3, 3), v_n = R v_b, of quaternions (n, 4)."""
    q = np.atleast_2d(q)
    w, x, y, z = q.T
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]).transpose(2, 0, 1)


def angle_deg(q1, q2):
    return math.degrees(2.0 * math.acos(min(1.0, abs(float(np.dot(q1, q2))))))


def integrate_gyro(t_ns, omega_b, q0):
    """q_{k+1} = q_k (x) exp(w dt / 2) with w the mean of the two samples (second order)."""
    q = np.asarray(q0, float)
    dt = np.diff(t_ns) * 1e-9
    w = 0.5 * (omega_b[1:] + omega_b[:-1])
    for wk, dk in zip(w, dt):
        rv = wk * dk
        a = np.linalg.norm(rv)
        dq = np.concatenate([[math.cos(a / 2)], rv / a * math.sin(a / 2)]) if a > 0 else np.array([1.0, 0, 0, 0])
        q = qmul(q, dq)
        q /= np.linalg.norm(q)
    return q


def window(stream, t0_ns, t1_ns):
    m = (stream.t_ns >= t0_ns) & (stream.t_ns < t1_ns)
    return stream.t_ns[m], stream.values[m]


# -- results and metadata ------------------------------------------------------


def test_result_types_and_recording_contents():
    walk = simulate_walk(RECT, seed=0)
    assert isinstance(walk, SimulatedWalk) and isinstance(walk.truth, WalkTruth)
    rec = walk.recording
    assert set(rec.streams) == {"acc", "gyro", "mag"}
    assert rec.streams["mag"].unit == "uT" and rec.streams["acc"].columns == ("x", "y", "z")
    assert rec.device == {"model": "simulator"}
    md = rec.metadata
    assert md["simulator"] and md["seed"] == 0 and md["step_length_m"] == 0.7
    assert md["waypoints_en_m"][1] == [20.0, 0.0]
    assert md["truth"]["n_steps"] == walk.truth.n_steps
    json.dumps(md)  # the header must be JSON
    assert rec.t0_ns >= 10**12  # a large phone-like clock
    for s in rec.streams.values():
        assert s.t_ns.dtype == np.int64 and np.all(np.diff(s.t_ns) > 0)
        assert np.all(np.isfinite(s.values))
    with pytest.raises(dataclasses.FrozenInstanceError):
        walk.truth.n_steps = 3
    with pytest.raises(ValueError):
        walk.truth.step_east_m[0] = 1.0  # truth arrays are read-only


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
    with pytest.raises(TypeError):
        simulate_walk(RECT, seed=None)  # an explicit integer seed: recordings must be reproducible
    with pytest.raises(ValueError, match="nothing to simulate"):
        simulate_walk([(0, 0)], still_start_s=0, still_end_s=0)


# -- accelerometer -------------------------------------------------------------


def test_flat_phone_at_rest_measures_g_along_device_z():
    # a single waypoint: standing only; phone flat, screen up, no hand wander
    walk = simulate_walk([(0, 0)], still_start_s=4, still_end_s=0, phone_pitch_deg=0,
                         hand_wander_deg=(0, 0, 0), acc_noise_m_s2=0.02, seed=1)
    acc = walk.recording.streams["acc"].values
    n = len(acc)
    assert walk.truth.n_steps == 0 and n > 350
    tol = 5 * 0.02 / math.sqrt(n)  # 5 standard errors of the mean
    np.testing.assert_allclose(acc.mean(axis=0), [0, 0, G], atol=tol)
    assert abs(np.linalg.norm(acc, axis=1).mean() - G) < tol
    assert np.all(np.abs(acc.std(axis=0) / 0.02 - 1) < 0.15)  # the noise level as asked (n > 350: +-15 %)


def test_held_phone_at_rest_measures_gravity_rotated_by_the_truth_attitude():
    walk = simulate_walk(RECT, seed=2)  # default pitch 25 deg and hand wander
    tr = walk.truth
    t, acc = window(walk.recording.streams["acc"], tr.walk_start_t_ns - 2 * 10**9, tr.walk_start_t_ns)
    assert len(t) > 150
    expected = np.einsum("nji,j->ni", qmat(tr.attitude_at(t)), [0, 0, G])  # R^T (0, 0, g)
    resid = acc - expected
    tol = 5 * 0.02 / math.sqrt(len(t))
    np.testing.assert_allclose(resid.mean(axis=0), 0, atol=tol)
    assert abs(np.linalg.norm(acc, axis=1).mean() - G) < tol
    # pitched up by ~25 deg: gravity shows on the device y axis as g sin(pitch)
    assert 20 < math.degrees(math.asin(acc[:, 1].mean() / G)) < 30


def test_double_integrated_acceleration_reproduces_the_walk():
    """Rest to rest, the specific force rotated to ENU minus g integrates twice to the walker's displacement.

    The phone is at rest at both ends (no gait displacement), so the phone's displacement equals the
    walker's.  Trapezoid integration at 400 Hz of exact data: tolerance 0.1 m over ~20 m.
    """
    walk = simulate_walk([(0, 0), (12, 0), (12, 8)], rate_hz=400, timestamp_jitter=0.02, **QUIET, seed=5)
    tr = walk.truth
    acc = walk.recording.streams["acc"]
    a_n = np.einsum("nij,nj->ni", qmat(tr.attitude_at(acc.t_ns)), acc.values) - [0, 0, G]
    dt = np.diff(acc.t_ns) * 1e-9
    vel = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (a_n[1:] + a_n[:-1]) * dt[:, None], axis=0)])
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt[:, None], axis=0)])
    assert np.linalg.norm(vel[-1]) < 0.02  # at rest again (m/s)
    end = np.array([tr.step_east_m[-1] - tr.start_east_m, tr.step_north_m[-1] - tr.start_north_m, 0.0])
    np.testing.assert_allclose(end, [12, 8, 0], atol=1e-9)
    np.testing.assert_allclose(pos[-1], end, atol=0.1)


def test_weinberg_relation_holds_for_the_low_passed_norm():
    """C (A_max - A_min)^(1/4) of the 3 Hz second-order Butterworth low-passed norm = truth step length.

    Per detected peak: A_max at the peak, A_min the lowest value since the previous peak (like
    core.pdr.steps).  Tolerance 2 % on the median over the steady part of the walk, for a short and a long step
    (measured: 0.3 % and 0.1 %; an exponent of 3.8 instead of 4 in the simulator would be 3 % off at 0.9 m).
    """
    from scipy.signal import butter, lfilter

    for length in (0.5, 0.9):
        walk = simulate_walk([(0, 0), (30, 0)], step_length_m=length, seed=6)
        tr = walk.truth
        acc = walk.recording.streams["acc"]
        grid = np.arange(acc.t_ns[0], acc.t_ns[-1], 10_000_000)  # 100 Hz
        norm = np.interp(grid, acc.t_ns, np.linalg.norm(acc.values, axis=1))
        b, a = butter(2, 3.0, fs=100.0)
        y = lfilter(b, a, norm - norm[0]) + norm[0]
        steps = tr.step_t_ns[3:-3]
        bounds = np.searchsorted(grid, steps)
        peaks = [i0 + int(np.argmax(y[i0:i1])) for i0, i1 in zip(bounds[:-1], bounds[1:])]
        pp = np.array([y[p1] - y[p0:p1 + 1].min() for p0, p1 in zip(peaks[:-1], peaks[1:])])
        estimate = 0.47 * np.median(pp) ** 0.25
        truth_len = np.median(tr.step_length_m)
        assert abs(truth_len - length) < 0.01
        assert abs(estimate / truth_len - 1) < 0.02, (length, estimate)
        assert np.median(pp) == pytest.approx((truth_len / 0.47) ** 4, rel=0.08)  # 1.3 and 14 m/s^2


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
    assert np.ptp(before) < 1e-6 and np.ptp(after) < 1e-6  # standing still (no noise here)
    assert np.ptp(first_quarter) < 1.0 and np.ptp(mid) > 3.0  # the gait amplitude ramps in over the first step


C120 = (2.6 + 2.6 * math.cos(math.radians(120)), 2.6 * math.sin(math.radians(120)))


@pytest.mark.parametrize("waypoints, shortest_m", [
    ([(0, 0), (12, 0), (0, 2)], 0.5),  # a 170 deg turn: slow down to 0.8 m/s
    ([(0, 0), (6, 0), (6, 0.3), (12, 0.3)], 0.5),  # a 30 cm side-step: slow down to 0.24 m/s
    ([(0, 0), (2.6, 0), C120, (-5, 6)], 0.67),  # a 120 deg turn that just does not fit: a brief 7 % slow-down
])
def test_slowing_down_for_tight_corners_keeps_accelerations_moderate(waypoints, shortest_m):
    """The hand's acceleration stays within what steady walking produces (|norm - g| < 6 m/s^2; 4.3 when
    walking straight) however large or small the slow-down."""
    walk = simulate_walk(waypoints, acc_noise_m_s2=0.0, seed=23)
    norm = np.linalg.norm(walk.recording.streams["acc"].values, axis=1)
    assert np.max(np.abs(norm - G)) < 6.0
    lengths = walk.truth.step_length_m[1:-1]  # without the half steps from and to rest
    assert lengths.min() < shortest_m  # the walker did slow down


# -- gyroscope -----------------------------------------------------------------


@pytest.mark.parametrize("calibration_s", [0.0, 15.0])
def test_integrated_gyro_reproduces_the_truth_attitude(calibration_s):
    walk = simulate_walk(RECT, calibration_motion_s=calibration_s, **QUIET, seed=8)
    gyro = walk.recording.streams["gyro"]
    tr = walk.truth
    q_end = integrate_gyro(gyro.t_ns, gyro.values, tr.attitude_at(gyro.t_ns[0]))
    assert walk.recording.duration_s > 50
    assert angle_deg(q_end, tr.attitude_at(gyro.t_ns[-1])) < 0.5
    # and over the first half, against the dense truth grid
    half = len(gyro.t_ns) // 2
    q_half = integrate_gyro(gyro.t_ns[:half + 1], gyro.values[:half + 1], tr.attitude_at(gyro.t_ns[0]))
    i = np.searchsorted(tr.att_t_ns, gyro.t_ns[half])
    assert abs(int(tr.att_t_ns[i]) - int(gyro.t_ns[half])) <= 5_000_000
    assert angle_deg(q_half, tr.attitude_at(gyro.t_ns[half])) < 0.5


def test_gyro_bias_and_noise_are_as_asked():
    bias = (0.01, -0.02, 0.005)
    walk = simulate_walk([(0, 0)], still_start_s=5, still_end_s=0, hand_wander_deg=(0, 0, 0),
                         gyro_bias_rad_s=bias, gyro_noise_rad_s=0.004, seed=9)
    g = walk.recording.streams["gyro"].values
    np.testing.assert_allclose(g.mean(axis=0), bias, atol=5 * 0.004 / math.sqrt(len(g)))
    assert np.all(np.abs(g.std(axis=0) / 0.004 - 1) < 0.15)


# -- magnetometer --------------------------------------------------------------


def test_magnetometer_norm_and_direction_match_the_earth_field():
    h = (1.0, 21.0, -43.0)
    walk = simulate_walk(RECT, earth_field_enu_uT=h, **QUIET, seed=10)
    mag = walk.recording.streams["mag"]
    np.testing.assert_allclose(np.linalg.norm(mag.values, axis=1), np.linalg.norm(h), rtol=1e-9)
    back = np.einsum("nij,nj->ni", qmat(walk.truth.attitude_at(mag.t_ns)), mag.values)  # R m_b
    np.testing.assert_allclose(back, np.tile(h, (len(back), 1)), atol=1e-9)
    # hard iron: a constant offset in the device frame
    hi = (12.0, -5.0, 30.0)
    walk2 = simulate_walk(RECT, earth_field_enu_uT=h, mag_hard_iron_uT=hi, **QUIET, seed=10)
    m2 = walk2.recording.streams["mag"].values
    np.testing.assert_allclose(m2 - hi, mag.values, atol=1e-9)
    # with noise the mean norm stays |h| within 5 standard errors (the noise adds sigma^2 / |h| ~ 0.003 uT)
    noisy = simulate_walk(RECT, earth_field_enu_uT=h, mag_noise_uT=0.4, seed=10).recording.streams["mag"].values
    assert abs(np.linalg.norm(noisy, axis=1).mean() - np.linalg.norm(h)) < 5 * 0.4 / math.sqrt(len(noisy)) + 0.01


def test_disturbance_zone_changes_the_field_only_inside_it():
    zone = DisturbanceZone(center_en_m=(10.0, 0.0), radius_m=2.0, field_enu_uT=(15.0, -10.0, 20.0))
    h = (0.0, 20.0, -44.0)
    walk = simulate_walk([(0, 0), (20, 0)], disturbance_zones=[zone], **QUIET, seed=11)
    mag = walk.recording.streams["mag"]
    pos = walk.truth.position_at(mag.t_ns)
    dist = np.hypot(pos[:, 0] - 10.0, pos[:, 1])
    dev = np.abs(np.linalg.norm(mag.values, axis=1) - np.linalg.norm(h))
    outside = dist > 2.0 + 0.1  # 0.1 m margin: the phone sways a few cm around the walker's path
    assert outside.sum() > 300 and (dist < 0.5).sum() > 5
    assert dev[outside].max() < 1e-9
    assert dev[dist < 0.5].min() > 5.0  # near the centre the added 27 uT changes the norm a lot
    # the taper is smooth: full field at the centre, half at half the radius
    np.testing.assert_allclose(zone.field_at([10.0, 11.0, 12.0, 13.0], [0, 0, 0, 0]),
                               [[15, -10, 20], [7.5, -5, 10], [0, 0, 0], [0, 0, 0]], atol=1e-12)


# -- truth: steps, path, heading ----------------------------------------------


def test_step_count_is_duration_times_frequency_and_heel_strikes_are_even():
    # 14 m straight at 0.7 m: 20 full steps of travel plus the start and stop ramps (half a step each)
    walk = simulate_walk([(0, 0), (14, 0)], seed=12)
    tr = walk.truth
    assert tr.n_steps == 21 == len(tr.step_t_ns)
    duration_s = (tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9
    assert abs(duration_s * 1.8 - tr.n_steps) < 1e-6
    period_ns = 1e9 / 1.8
    assert np.all(np.abs(np.diff(tr.step_t_ns) - period_ns) <= 1.0)  # rounding to integer ns
    assert abs(tr.step_t_ns[0] - tr.walk_start_t_ns - period_ns) <= 1.0
    assert tr.step_t_ns[-1] == tr.walk_end_t_ns
    np.testing.assert_allclose(tr.step_length_m[1:-1], 0.7, atol=1e-9)
    np.testing.assert_allclose(tr.step_length_m[[0, -1]], 0.35, atol=1e-9)  # from and to rest
    np.testing.assert_allclose(tr.step_east_m, np.cumsum(tr.step_length_m), atol=1e-9)
    np.testing.assert_allclose(tr.step_north_m, 0, atol=1e-9)
    # with corners (walked at full speed): the same rule on the rounded path's length, within half a step
    rect = simulate_walk(RECT, seed=12).truth
    assert rect.n_steps == round(rect.path_length_m / 0.7 + 1)
    assert abs((rect.walk_end_t_ns - rect.walk_start_t_ns) * 1e-9 * 1.8 - rect.n_steps) < 1e-6
    assert abs(rect.path_length_m / 0.7 + 1 - rect.n_steps) <= 0.5


def test_path_length_is_the_polyline_length_minus_the_rounded_corners():
    tr = simulate_walk(RECT, seed=13).truth
    assert tr.polyline_length_m == pytest.approx(60.0, abs=1e-9)
    # three 90 deg corners rounded with r = v / turn rate = 1.26 / (pi/2) m each cut r (2 - pi/2) = 0.344 m
    r = 1.8 * 0.7 / math.radians(90.0)
    cut = 3 * r * (2 - math.pi / 2)
    assert tr.path_length_m == pytest.approx(60.0 - cut, abs=1e-6)
    assert 60.0 - 1.05 < tr.path_length_m < 60.0  # stated tolerance: 0.35 m per 90 deg corner
    assert tr.path_length_m == pytest.approx(tr.step_length_m.sum(), rel=1e-12)
    # ends at the last waypoint; positions between consecutive steps are one step length apart on straights
    assert math.hypot(tr.step_east_m[-1], tr.step_north_m[-1]) < 1e-6
    chord = np.hypot(np.diff(tr.step_east_m), np.diff(tr.step_north_m))
    assert np.all(chord <= tr.step_length_m[1:] + 1e-9)


def test_device_y_axis_averaged_over_a_stride_points_along_the_walking_heading():
    walk = simulate_walk([(0, 0), (3, 4), (3 + 30 * 0.8, 4 - 30 * 0.6)], seed=14)  # second leg heading -36.87 deg
    tr = walk.truth
    heel = tr.step_t_ns
    leg_start = np.flatnonzero(np.abs(np.degrees(tr.step_heading_rad) + 36.87) < 0.01)
    assert len(leg_start) > 20
    errors = []
    for k in range(leg_start[2], leg_start[-4], 2):  # strides in the straight cruise part of the second leg
        t = np.linspace(heel[k], heel[k + 2], 200, endpoint=False).astype(np.int64)
        y_axis = qmat(tr.attitude_at(t))[:, :, 1]  # device y in ENU
        mean = y_axis[:, :2].mean(axis=0)
        heading = tr.heading_at(int(t[100]))
        errors.append(math.degrees(math.remainder(math.atan2(mean[1], mean[0]) - heading, 2 * math.pi)))
        # the phone is pitched up and the hand sways: single samples differ from the mean
        assert np.degrees(np.ptp(np.arctan2(y_axis[:, 1], y_axis[:, 0]))) > 2.0
    assert len(errors) >= 8
    assert np.max(np.abs(errors)) < 1.0
    assert heading == pytest.approx(math.atan2(-0.6, 0.8), abs=1e-9)


def test_step_headings_and_lengths_reproduce_the_positions():
    tr = simulate_walk(RECT, seed=15).truth
    # eq. 1 of the paper with the chord length of each step and the truth step heading
    east = tr.start_east_m + np.cumsum(np.hypot(*np.diff(np.r_[[[tr.start_east_m, tr.start_north_m]],
                                                                np.c_[tr.step_east_m, tr.step_north_m]], axis=0).T)
                                         * np.cos(tr.step_heading_rad))
    np.testing.assert_allclose(east, tr.step_east_m, atol=1e-9)
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
    assert np.max(np.abs(gz)) < 3.0  # the turn at 90 deg/s, plus hand sway


# -- calibration motion --------------------------------------------------------


def test_calibration_motion_tumbles_the_phone_and_returns_to_the_walking_pose():
    walk = simulate_walk(RECT, calibration_motion_s=20.0, **QUIET, seed=17)
    tr = walk.truth
    assert tr.calibration_end_t_ns - tr.calibration_start_t_ns == 20 * 10**9
    assert tr.walk_start_t_ns - tr.calibration_end_t_ns == 2 * 10**9
    t = np.arange(tr.calibration_start_t_ns, tr.calibration_end_t_ns, 20_000_000)
    up_of_axes = qmat(tr.attitude_at(t))[:, 2, :]  # the Up component of the device x, y and z axes
    # every device axis is tilted both well above and well below the horizon at some point
    assert np.all(up_of_axes.max(axis=0) > 0.6) and np.all(up_of_axes.min(axis=0) < -0.3)
    # back to the walking pose: the attitude at the end equals the standing pose before walking (hand wander only)
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
    a = simulate_walk(RECT, seed=20).recording
    b = simulate_walk(RECT, seed=20).recording
    c = simulate_walk(RECT, seed=21).recording
    for name in a.streams:
        # identical output is the contract here, so exact equality is the right check
        assert np.array_equal(a.streams[name].t_ns, b.streams[name].t_ns)
        assert np.array_equal(a.streams[name].values, b.streams[name].values)
        assert not np.array_equal(a.streams[name].t_ns, c.streams[name].t_ns)
    # the noise itself: each recording minus its noise-free twin (same seed: same timestamps and hand wander)
    def noise(seed):
        noisy = simulate_walk(RECT, gyro_bias_rad_s=(0, 0, 0), seed=seed).recording.streams["gyro"].values
        return noisy - simulate_walk(RECT, **QUIET, seed=seed).recording.streams["gyro"].values

    n20, n21 = noise(20), noise(21)
    n = min(len(n20), len(n21))
    assert np.allclose(n20.std(axis=0), 0.003, rtol=0.1) and np.allclose(n21.std(axis=0), 0.003, rtol=0.1)
    assert abs(np.corrcoef(n20[:n, 0], n21[:n, 0])[0, 1]) < 0.1  # independent draws (n > 5000: |r| ~ 0.014)


def test_changing_a_noise_level_keeps_the_timestamps():
    a = simulate_walk(RECT, seed=22).recording
    b = simulate_walk(RECT, acc_noise_m_s2=0.5, seed=22).recording
    for name in a.streams:
        assert np.array_equal(a.streams[name].t_ns, b.streams[name].t_ns)
    assert np.std(a.streams["acc"].values - b.streams["acc"].values) > 0.2


# -- the demo and speed -------------------------------------------------------


def test_demo_walk_is_a_closed_loop_of_realistic_size():
    walk = demo_walk()
    tr = walk.truth
    rec = walk.recording
    assert math.hypot(tr.step_east_m[-1] - tr.start_east_m, tr.step_north_m[-1] - tr.start_north_m) < 0.5
    assert 120 <= tr.path_length_m <= 200
    assert 120 <= rec.duration_s <= 180
    headings = np.degrees(np.unwrap(tr.step_heading_rad))
    assert np.ptp(headings) >= 180  # several turns
    assert rec.streams["acc"].rate_hz == pytest.approx(100, rel=0.01)
    assert rec.metadata["disturbance_zones"] == [] and any(rec.metadata["gyro_bias_rad_s"])
    assert np.array_equal(demo_walk().recording.streams["mag"].values, rec.streams["mag"].values)


def test_a_three_minute_walk_simulates_quickly():
    # ~220 m loop: about three minutes at 1.26 m/s
    loop = [(0, 0), (70, 0), (70, 40), (0, 40), (0, 0)]
    simulate_walk([(0, 0), (1, 0)], seed=0)  # warm-up (imports, caches)
    t0 = time.perf_counter()
    walk = simulate_walk(loop, rate_hz=100.0, seed=0)
    elapsed = time.perf_counter() - t0
    assert walk.recording.duration_s > 170
    assert elapsed < 2.0, f"simulation took {elapsed:.2f} s"


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
    assert math.hypot(tr.step_east_m[-1] - pts[-1, 0], tr.step_north_m[-1] - pts[-1, 1]) < 1e-6
    assert tr.n_steps >= 1 and abs((tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9 * 1.8 - tr.n_steps) < 1e-6
    assert np.all(tr.step_length_m >= -1e-12)
    stretch = 1 + 0.5 / tr.n_steps  # the plan is stretched to a whole number of steps: speeds up by at most this
    assert np.all(tr.step_length_m <= 0.7 * stretch + 1e-9)  # never faster than the cruise speed
    assert tr.path_length_m == pytest.approx(tr.step_length_m.sum(), rel=1e-9, abs=1e-9)
    assert tr.path_length_m <= tr.polyline_length_m + 1e-9
    # heading is continuous and never turns faster than the turn rate (+ the time stretch)
    t = np.arange(tr.walk_start_t_ns, tr.walk_end_t_ns, 5_000_000)
    h = tr.heading_at(t)
    assert np.max(np.abs(np.diff(h))) <= math.radians(turn) * 0.005 * stretch + 1e-9
    for s in walk.recording.streams.values():
        assert np.all(np.isfinite(s.values))
