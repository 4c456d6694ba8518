"""desktop.simulator's GPS receiver model (GpsModel), street routes and outdoor walks.

The statistics are checked against the model's settings on seeded walks.
Tolerances are stated beside each assertion; the noise-dependent ones are
3-5 standard errors wide, the standard errors taken from the sample sizes
(or, for the slowly wandering bias, from the number of correlation times
walked).  The long statistical walks use a 10 Hz IMU (the GPS does not
depend on the IMU rate) to keep the tests quick.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from core.conventions import bearing_deg, wrap_angle
from core.geodesy import declination_rad, geodetic_to_enu
from core.recording import STREAM_SPECS, read_recording, write_recording
from desktop.simulator import (
    DEMO_WALK_KW,
    DEMO_WAYPOINTS_EN_M,
    GpsModel,
    OUTDOOR_HEIGHT_M,
    OUTDOOR_YAW_OFFSET_DEG,
    outdoor_walk,
    simulate_walk,
    street_route,
)

DEMO_FILE = Path(__file__).resolve().parents[1] / "desktop" / "data" / "demo_walk.csv.gz"  # made before the GPS

GPS_COLUMNS = tuple(STREAM_SPECS["gps"]["columns"])
#: the statistical walks: a short bias correlation time and frequent multipath, so that 3 x 53 minutes hold
#: ~300 bias correlation times and ~160 episodes
STATS_MODEL = GpsModel(bias_tau_s=30.0, multipath_per_min=1.0)
STATS_SEEDS = (101, 102, 103)


def gps_en(walk):
    """The recording's fixes as ENU (east, north) about the walk's origin (core.geodesy), (n, 2)."""
    g = walk.recording.streams["gps"].values
    e, n = geodetic_to_enu(g[:, 0], g[:, 1], walk.truth.origin_lat_lon)
    return np.stack([e, n], axis=1)


def gps_error(walk):
    """Reported minus true horizontal position of each fix (m), (n, 2)."""
    return gps_en(walk) - walk.truth.gps.pos_enu_m[:, :2]


def lag_correlation(x, ok, lag):
    """Correlation of the rows of x (n, 2) ``lag`` fixes apart, over pairs where both are ``ok``."""
    x = x - x[ok].mean(axis=0)
    both = ok[lag:] & ok[:-lag]
    return float((x[lag:][both] * x[:-lag][both]).sum(axis=1).mean() / (x[ok] ** 2).sum(axis=1).mean())


@pytest.fixture(scope="module")
def stats_walks():
    """Three 4 km (53 min) street walks with STATS_MODEL."""
    return [simulate_walk(street_route(4000.0, seed=s), rate_hz=10.0, truth_rate_hz=2.0, gps=STATS_MODEL, seed=s)
            for s in STATS_SEEDS]


@pytest.fixture(scope="module")
def outdoor():
    """A 10-minute outdoor walk with the default GPS; the IMU at 20 Hz (the tests here read its GPS and truth,
    which do not depend on the IMU's rate: the same 597 fixes bit for bit as at the default 100 Hz; 0.3 s of CPU
    instead of 0.9 s)."""
    return outdoor_walk(7, minutes=10, rate_hz=20.0)


# -- the stream, the file, the geodesy ---------------------------------------------------------------------


def test_gps_stream_has_the_six_columns_and_survives_the_file_format(tmp_path, outdoor):
    rec = outdoor.recording
    gps = rec.streams["gps"]
    assert gps.columns == GPS_COLUMNS and gps.values.shape == (len(gps.t_ns), 6)
    assert gps.unit == STREAM_SPECS["gps"]["unit"]
    assert gps.t_ns.dtype == np.int64 and np.all(np.diff(gps.t_ns) > 0)
    np.testing.assert_array_equal(outdoor.truth.gps.t_ns, gps.t_ns)
    # 1 Hz from the first fix (3 s after the clock start) to the end, each stamp off its grid by 5 ms jitter
    t = (gps.t_ns - rec.metadata["clock_start_ns"]) * 1e-9
    off = t - (3.0 + np.arange(len(t)))
    assert abs(off.mean()) < 0.002 and 0.004 < off.std() < 0.006  # 600 draws: SE of the SD 3 %
    assert len(t) == pytest.approx(rec.duration_s - 3.0, abs=1.5)
    json.dumps(rec.metadata)
    assert rec.metadata["gps"]["rate_hz"] == 1.0 and rec.metadata["origin_lat_lon"] == [60.1699, 24.9384]

    # the file: the walk's last minute (its last fixes, standing, have no course), not ten minutes of IMU
    last = rec.slice_time(rec.t1_ns - 60 * 10 ** 9, rec.t1_ns + 1)
    gps = last.streams["gps"]
    assert np.isnan(gps.values[:, 5]).sum() == 2
    path = tmp_path / "outdoor.csv.gz"
    write_recording(str(path), last)
    back = read_recording(str(path))
    assert back.streams["gps"].columns == GPS_COLUMNS
    np.testing.assert_array_equal(back.streams["gps"].t_ns, gps.t_ns)
    np.testing.assert_allclose(back.streams["gps"].values, gps.values, rtol=0, atol=0)  # nan course kept as nan
    assert back.metadata == rec.metadata


def test_lat_lon_round_trip_through_core_geodesy_and_north_is_plus_y(outdoor):
    tr = outdoor.truth
    t = tr.gps.t_ns
    geo = tr.phone_geodetic_at(t)
    e, n = geodetic_to_enu(geo[:, 0], geo[:, 1], tr.origin_lat_lon)
    np.testing.assert_allclose(np.stack([e, n], axis=1), tr.phone_position_at(t)[:, :2], rtol=0, atol=1e-6)
    np.testing.assert_allclose(geo[:, 2], tr.origin_alt_m + tr.phone_position_at(t)[:, 2], rtol=0, atol=1e-9)
    assert tr.phone_geodetic_at(int(t[5])).shape == (3,)
    # the reported fix is the truth plus exactly the injected errors plus white noise of at most a few sigma
    white = gps_error(outdoor) - tr.gps.error_model_en_m
    assert np.max(np.abs(white)) < 6 * tr.gps.model.noise_sd_m

    # walking due north (+y): latitude grows, longitude stays (to the noise), the course is about 0 deg
    walk = simulate_walk([(0, 0), (0, 120)], rate_hz=20.0, gps=GpsModel(bias_sd_m=0.5, multipath_per_min=0.0),
                         seed=3)
    g = walk.recording.streams["gps"].values
    assert g[-1, 0] - g[0, 0] == pytest.approx(120 / 111_412, rel=0.05)  # a degree of latitude at 60 N: 111.4 km
    assert abs(g[-1, 1] - g[0, 1]) * 55_800 < 10  # a degree of longitude there: 55.8 km; white noise 1.5 m
    moving = ~np.isnan(g[:, 5])
    assert moving.sum() > 60
    assert np.median(np.abs(wrap_angle(np.radians(g[moving, 5])))) < math.radians(5)


# -- position errors against the settings -------------------------------------------------------------


def test_white_noise_has_the_set_sd_and_is_white(stats_walks):
    white = np.concatenate([gps_error(w) - w.truth.gps.error_model_en_m for w in stats_walks])
    # ~9,500 fixes x 2 axes: the SE of the SD is 0.5 %
    assert white.std(axis=0) == pytest.approx([STATS_MODEL.noise_sd_m] * 2, rel=0.03)
    assert abs(white.mean()) < 0.05
    ok = np.ones(len(white), bool)
    assert abs(lag_correlation(white, ok, 1)) < 0.05  # SE 0.01


def test_bias_wanders_with_the_set_sd_and_correlation_time(stats_walks):
    bias = np.concatenate([w.truth.gps.bias_en_m for w in stats_walks])
    # ~300 correlation times x 2 axes: the SE of the SD is ~4 %
    assert np.sqrt((bias ** 2).mean()) == pytest.approx(STATS_MODEL.bias_sd_m, rel=0.15)
    # correlation time from the lag-10 correlation of the injected bias, and from the recording's own errors
    # outside multipath: the white noise does not correlate, so r(2) / r(30) = exp(28 / tau) (SE ~10 %)
    r10 = np.mean([lag_correlation(w.truth.gps.bias_en_m, np.ones(len(w.truth.gps.t_ns), bool), 10)
                   for w in stats_walks])
    assert -10.0 / math.log(r10) == pytest.approx(STATS_MODEL.bias_tau_s, rel=0.3)
    r2, r30 = (np.mean([lag_correlation(gps_error(w), ~w.truth.gps.multipath, lag) for w in stats_walks])
               for lag in (2, 30))
    assert 28.0 / math.log(r2 / r30) == pytest.approx(STATS_MODEL.bias_tau_s, rel=0.35)
    # and its size from the recording: var(error) - noise^2 outside multipath
    err = np.concatenate([gps_error(w)[~w.truth.gps.multipath] for w in stats_walks])
    assert math.sqrt(err.var(axis=0).mean() - STATS_MODEL.noise_sd_m ** 2) == pytest.approx(STATS_MODEL.bias_sd_m,
                                                                                            rel=0.15)


def test_multipath_episodes_come_at_the_set_rate_with_the_set_jumps(stats_walks):
    n_start, minutes = 0, 0.0
    lo_m, hi_m = STATS_MODEL.multipath_jump_m
    lo_s, hi_s = STATS_MODEL.multipath_duration_s
    for w in stats_walks:
        tr = w.truth.gps
        n_start += int(np.sum(tr.multipath_t_ns[:, 0] >= tr.t_ns[0]))
        minutes += (tr.t_ns[-1] - tr.t_ns[0]) * 1e-9 / 60.0
        dur = np.diff(tr.multipath_t_ns, axis=1)[:, 0] * 1e-9
        assert np.all((dur > lo_s - 1e-6) & (dur < hi_s + 1e-6))
        jump = np.hypot(*tr.multipath_offset_en_m.T)
        assert np.all((jump > lo_m - 1e-9) & (jump < hi_m + 1e-9))
        # a fix is flagged exactly when it lies in an episode, and is then off by the episodes' offsets
        t = tr.t_ns[:, None]
        inside = (t >= tr.multipath_t_ns[:, 0]) & (t < tr.multipath_t_ns[:, 1])
        np.testing.assert_array_equal(inside.any(axis=1), tr.multipath)
        np.testing.assert_allclose(tr.multipath_en_m, inside @ tr.multipath_offset_en_m, rtol=0, atol=1e-6)
        resid = gps_error(w)[tr.multipath] - tr.multipath_en_m[tr.multipath] - tr.bias_en_m[tr.multipath]
        assert np.sqrt((resid ** 2).mean()) == pytest.approx(STATS_MODEL.noise_sd_m, rel=0.25)
    # ~160 episodes (Poisson: SE 8 %)
    assert n_start / minutes == pytest.approx(STATS_MODEL.multipath_per_min, rel=0.3)


def test_hacc_is_an_honest_68_percent_radius_outside_multipath_and_under_reported_inside(stats_walks):
    inside_frac, within_mp, ratio_mp = [], [], []
    for w in stats_walks:
        tr = w.truth.gps
        hacc = w.recording.streams["gps"].values[:, 3]
        r = np.hypot(*gps_error(w).T)
        ok = ~tr.multipath
        inside_frac.append(np.mean(r[ok] < hacc[ok]))
        within_mp.append(np.mean(r[~ok] < hacc[~ok]))
        ratio_mp.append(np.median(hacc[~ok] / r[~ok]))
        # the jitter is multiplicative with median 1 around the model's honest radius (~5 m with these settings)
        assert np.median(hacc[ok] / tr.hacc_normal_m[ok]) == pytest.approx(1.0, abs=0.03)
        assert np.std(np.log(hacc[ok] / tr.hacc_normal_m[ok])) == pytest.approx(
            math.sqrt(math.log1p(STATS_MODEL.hacc_jitter_cv ** 2)), rel=0.1)
        assert 4.5 < tr.hacc_normal_m[0] < 5.6  # about the 68 % radius of sqrt(1.5^2 + 3^2) = 3.35 m per axis
    # the bias makes neighbouring fixes alike: ~300 independent ones, SE of the fraction ~0.02
    assert np.mean(inside_frac) == pytest.approx(0.68, abs=0.06)
    # during multipath (10-40 m off) the receiver claims ~1.5 x its usual ~5 m: most fixes lie outside
    assert np.mean(within_mp) < 0.2 and np.mean(ratio_mp) < 0.5


def test_altitude_is_ground_plus_phone_height_plus_its_own_errors(stats_walks):
    w = stats_walks[0]
    tr = w.truth.gps
    alt = w.recording.streams["gps"].values[:, 2]
    white = alt - (tr.pos_enu_m[:, 2] + w.truth.origin_alt_m) - tr.alt_bias_m
    assert white.std() == pytest.approx(STATS_MODEL.alt_noise_sd_m, rel=0.06)  # 3,150 fixes: SE 1.3 %
    assert np.sqrt((tr.alt_bias_m ** 2).mean()) == pytest.approx(STATS_MODEL.alt_bias_sd_m, rel=0.3)  # ~100 tau
    assert np.all(np.abs(tr.pos_enu_m[:, 2] - 0.75 * w.recording.metadata["height_m"]) < 0.1)  # phone in the hand


def test_cold_start_and_time_to_first_fix():
    model = GpsModel(first_fix_s=30.0, cold_start_fixes=10, cold_start_error_m=60.0, multipath_per_min=0.0)
    walk = simulate_walk([(0, 0), (60, 0)], rate_hz=20.0, still_start_s=20.0, gps=model, seed=8)
    rec, tr = walk.recording, walk.truth.gps
    assert (rec.streams["gps"].t_ns[0] - rec.metadata["clock_start_ns"]) * 1e-9 == pytest.approx(30.0, abs=0.03)
    cold = np.hypot(*tr.cold_start_en_m.T)
    np.testing.assert_allclose(cold[:10], 60.0 * (1.0 - np.arange(10) / 10), rtol=1e-12)
    assert np.all(cold[10:] == 0.0)
    r = np.hypot(*gps_error(walk).T)
    hacc = rec.streams["gps"].values[:, 3]
    assert 45.0 < r[0] < 75.0 and hacc[0] > 50.0  # 60 m off, the other errors ~5 m; the receiver says so
    assert np.all(hacc[:5] > 30.0) and np.median(hacc[12:]) < 8.0


# -- speed and course --------------------------------------------------------------------------------------


def test_speed_and_course_follow_the_true_velocity(outdoor):
    tr = outdoor.truth
    g = outdoor.recording.streams["gps"].values
    speed, course = g[:, 4], g[:, 5]
    v_true = np.hypot(*tr.gps.vel_en_m_s.T)
    moving = v_true > 0.8
    assert moving.sum() > 500
    noise = tr.gps.model.speed_noise_m_s
    # |v + n| - |v| is the along-track noise when |v| >> noise; the course error times |v| the cross-track one
    assert np.std(speed[moving] - v_true[moving]) == pytest.approx(noise, rel=0.15)  # 580 fixes: SE 3 %
    assert abs(np.mean(speed[moving] - v_true[moving])) < 0.02
    true_bearing = np.array([bearing_deg(h) for h in np.arctan2(tr.gps.vel_en_m_s[:, 1], tr.gps.vel_en_m_s[:, 0])])
    cross = wrap_angle(np.radians(course[moving] - true_bearing[moving])) * v_true[moving]
    assert np.std(cross) == pytest.approx(noise, rel=0.15)
    # course is nan exactly where the reported speed is below 0.3 m/s (the standing ends)
    np.testing.assert_array_equal(np.isnan(course), speed < tr.gps.model.course_min_speed_m_s)
    assert np.all(np.isfinite(speed)) and np.all(speed >= 0)
    assert np.all((course[~np.isnan(course)] >= 0) & (course[~np.isnan(course)] < 360))
    # the true velocity is the walker's: on straight legs its course is the walking heading within 2 deg
    # (hand sway averaged over a second) and its speed the cruise speed
    h = np.unwrap(tr.heading_at(tr.gps.t_ns))
    straight = moving & (np.abs(np.gradient(h)) < 1e-3)
    walk_bearing = np.array([bearing_deg(x) for x in h[straight]])
    assert np.max(np.abs(wrap_angle(np.radians(true_bearing[straight] - walk_bearing)))) < math.radians(2)
    md = outdoor.recording.metadata
    assert np.median(v_true[straight]) == pytest.approx(md["step_frequency_hz"] * md["step_length_m"], rel=0.05)
    # the exact velocity of the truth agrees with the GPS truth's one-second mean on straight legs
    v_exact = tr.phone_velocity_at(tr.gps.t_ns)[:, :2]
    assert np.median(np.hypot(*(v_exact[straight] - tr.gps.vel_en_m_s[straight]).T)) < 0.25


# -- reproducibility: the GPS never moves the IMU ------------------------------------------------------------


def test_gps_leaves_the_imu_streams_bit_identical():
    # the bundled demo file was made before the GPS existed: with a GPS the same call gives the same IMU data
    back = read_recording(str(DEMO_FILE))
    with_gps = simulate_walk(DEMO_WAYPOINTS_EN_M, **DEMO_WALK_KW, gps=GpsModel(multipath_per_min=2.0), seed=0)
    without = simulate_walk(DEMO_WAYPOINTS_EN_M, **DEMO_WALK_KW, seed=0)
    assert set(with_gps.recording.streams) == {"acc", "gyro", "mag", "gps"}
    assert set(without.recording.streams) == {"acc", "gyro", "mag"} and without.truth.gps is None
    assert "gps" not in without.recording.metadata
    for name in ("acc", "gyro", "mag"):
        for other in (back, without.recording):
            np.testing.assert_array_equal(with_gps.recording.streams[name].t_ns, other.streams[name].t_ns)
        # bit for bit in one process; against the file to 1e-9 (numpy releases move the last bits: see
        # test_simulator.test_bundled_demo_file_is_the_current_demo_walk)
        np.testing.assert_array_equal(with_gps.recording.streams[name].values, without.recording.streams[name].values)
        np.testing.assert_allclose(with_gps.recording.streams[name].values, back.streams[name].values,
                                   rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(with_gps.truth.att_q_wxyz, without.truth.att_q_wxyz)


def test_one_seed_one_gps_and_a_setting_does_not_move_the_other_draws():
    kw = dict(rate_hz=10.0, truth_rate_hz=2.0)
    route = [(0, 0), (80, 0), (80, 40)]
    a = simulate_walk(route, gps=GpsModel(), seed=5, **kw).recording.streams["gps"]
    b = simulate_walk(route, gps=GpsModel(), seed=5, **kw).recording.streams["gps"]
    c = simulate_walk(route, gps=GpsModel(), seed=6, **kw).recording.streams["gps"]
    np.testing.assert_array_equal(a.values, b.values)
    assert not np.allclose(a.values[:, :2], c.values[:, :2], rtol=0, atol=1e-7)
    # more white noise: the same time stamps, bias and multipath; the white part scaled exactly
    w1 = simulate_walk(route, gps=GpsModel(), seed=5, **kw)
    w2 = simulate_walk(route, gps=GpsModel(noise_sd_m=3.0), seed=5, **kw)
    np.testing.assert_array_equal(w1.truth.gps.t_ns, w2.truth.gps.t_ns)
    np.testing.assert_array_equal(w1.truth.gps.bias_en_m, w2.truth.gps.bias_en_m)
    np.testing.assert_array_equal(w1.truth.gps.multipath, w2.truth.gps.multipath)
    white1 = gps_error(w1) - w1.truth.gps.error_model_en_m
    white2 = gps_error(w2) - w2.truth.gps.error_model_en_m
    np.testing.assert_allclose(white2, 2.0 * white1, rtol=0, atol=1e-6)


def test_invalid_gps_settings_are_rejected():
    with pytest.raises(ValueError, match="rate_hz"):
        GpsModel(rate_hz=0)
    with pytest.raises(ValueError, match="noise_sd_m"):
        GpsModel(noise_sd_m=-1)
    with pytest.raises(ValueError, match="multipath_jump_m"):
        GpsModel(multipath_jump_m=(40, 10))
    with pytest.raises(ValueError, match="cold_start_fixes"):
        GpsModel(cold_start_fixes=-2)
    with pytest.raises(ValueError, match="position error"):
        GpsModel(noise_sd_m=0, bias_sd_m=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        GpsModel().rate_hz = 5.0
    with pytest.raises(ValueError, match="gps"):
        simulate_walk([(0, 0), (5, 0)], gps={"rate_hz": 1})
    with pytest.raises(ValueError, match="origin_lat_lon"):
        simulate_walk([(0, 0), (5, 0)], gps=GpsModel(), origin_lat_lon=(95.0, 0.0))
    # a recording shorter than the time to first fix has an empty GPS stream
    short = simulate_walk([(0, 0)], still_start_s=1.0, still_end_s=0.0, gps=GpsModel(first_fix_s=5.0), seed=1)
    assert short.recording.streams["gps"].values.shape == (0, 6)


# -- street routes and outdoor walks -------------------------------------------------------------------------


def legs_and_turns(points):
    seg = np.diff(points, axis=0)
    legs = np.hypot(seg[:, 0], seg[:, 1])
    turns = np.degrees(wrap_angle(np.diff(np.arctan2(seg[:, 1], seg[:, 0]))))
    return legs, turns


@pytest.mark.parametrize("seed", range(8))
def test_street_route_has_block_legs_and_right_angle_turns(seed):
    route = street_route(1200.0, seed=seed)
    legs, turns = legs_and_turns(route)
    np.testing.assert_allclose(route[0], (0.0, 0.0))
    assert legs.sum() == pytest.approx(1200.0, rel=1e-9)
    assert np.all(legs[:-1] >= 40.0 - 1e-9) and legs[-1] >= 20.0 - 1e-9  # blocks; the last absorbs a stub
    right = np.abs(np.abs(turns) - 90.0) < 1e-6
    bend = (np.abs(turns) >= 10.0 - 1e-6) & (np.abs(turns) <= 30.0 + 1e-6)
    assert np.all(right | bend)  # nothing else: no reversal, nothing sharper than a right angle
    signs = np.sign(turns[right])
    assert not any(signs[i] == signs[i + 1] == signs[i + 2] for i in range(len(signs) - 2))  # no circling a block


def test_street_route_statistics_and_options():
    legs, turns, n_bend = [], [], 0
    for seed in range(40):
        lg, tn = legs_and_turns(street_route(1500.0, seed=seed, straight_prob=0.0))
        legs.extend(lg[:-1])
        turns.extend(tn)
    legs, turns = np.array(legs), np.array(turns)
    assert np.all((legs >= 40.0 - 1e-9) & (legs <= 120.0 + 1e-9))  # without going straight on: one block each
    assert legs.mean() == pytest.approx(80.0, rel=0.06)  # ~720 uniform blocks: SE 1 %
    bends = np.abs(np.abs(turns) - 90.0) > 1e-6
    assert bends.mean() == pytest.approx(0.2, abs=0.05)  # bend_prob, ~750 junctions: SE 0.015
    assert np.mean(turns > 0) == pytest.approx(0.5, abs=0.06)  # left and right alike
    # going straight on through junctions makes longer legs; one seed, one route; a given start heading
    long_legs = legs_and_turns(street_route(3000.0, seed=1, straight_prob=0.6))[0]
    assert long_legs[:-1].mean() > 150.0
    np.testing.assert_array_equal(street_route(900.0, seed=4), street_route(900.0, seed=4))
    assert not np.allclose(street_route(900.0, seed=4)[1], street_route(900.0, seed=5)[1])
    r = street_route(500.0, seed=2, start_heading_deg=90.0, start_en_m=(3.0, 4.0))
    np.testing.assert_allclose(r[0], (3.0, 4.0))
    assert r[1, 0] == pytest.approx(3.0, abs=1e-9) and r[1, 1] > 4.0 + 39.0
    with pytest.raises(ValueError, match="block_m"):
        street_route(500.0, seed=1, block_m=(100.0, 50.0))
    with pytest.raises(ValueError, match="bend_prob"):
        street_route(500.0, seed=1, bend_prob=1.0)


def test_outdoor_walk_lasts_the_minutes_with_a_per_seed_walker_and_the_site_field(outdoor):
    rec = outdoor.recording
    md = rec.metadata
    assert rec.duration_s == pytest.approx(600.0, abs=15.0)
    assert set(rec.streams) == {"acc", "gyro", "mag", "gps"}
    assert rec.streams["acc"].rate_hz == pytest.approx(20.0, rel=0.01)  # the fixture's; the default below
    assert rec.streams["gps"].rate_hz == pytest.approx(1.0, rel=0.01)
    assert OUTDOOR_HEIGHT_M[0] <= md["height_m"] <= OUTDOOR_HEIGHT_M[1]
    lo, hi = OUTDOOR_YAW_OFFSET_DEG
    assert lo <= md["phone_yaw_offset_deg"] <= hi and md["disturbance_zones"] == []
    assert 0.0 < np.linalg.norm(md["mag_hard_iron_uT"]) < 5.0  # a small residual
    # the field is the WMM's at the origin: declination east of the +y axis (true north), about 10 deg here
    h = np.array(md["earth_field_enu_uT"])
    dec = declination_rad(60.1699, 24.9384, 30.0, 2025.5)
    assert math.atan2(h[0], h[1]) == pytest.approx(dec, abs=1e-9)
    assert 8.0 < math.degrees(dec) < 13.0 and 50.0 < np.linalg.norm(h) < 54.0 and h[2] < -45.0
    assert md["outdoor_walk"]["declination_deg"] == pytest.approx(math.degrees(dec), abs=1e-9)
    # another seed: another walker and route; keywords override the draws
    other = outdoor_walk(8, minutes=1.0, height_m=1.6, gps=GpsModel(rate_hz=2.0))
    assert other.recording.metadata["height_m"] == 1.6
    assert other.recording.metadata["step_frequency_hz"] != md["step_frequency_hz"]
    assert other.recording.streams["gps"].rate_hz == pytest.approx(2.0, rel=0.01)
    assert other.recording.streams["acc"].rate_hz == pytest.approx(100.0, rel=0.01)  # the IMU's default rate
    assert other.recording.duration_s == pytest.approx(60.0, abs=5.0)
