"""Benchmark metrics on hand-made cases with known answers."""

import math

import numpy as np
import pytest

from benchmarks import metrics as m
from core.conventions import wrap_angle

NS = 1_000_000_000


def steps(times_s):
    return (np.asarray(times_s, dtype=float) * NS).astype(np.int64)


def test_step_count_error_signed_percent():
    assert m.step_count_error_pct(102, 100) == pytest.approx(2.0)
    assert m.step_count_error_pct(95, 100) == pytest.approx(-5.0)
    assert math.isnan(m.step_count_error_pct(3, 0))
    assert m.mean_abs([2.0, -4.0, float("nan")]) == pytest.approx(3.0)


def test_f1_perfect_and_shifted_within_tolerance():
    truth = steps(np.arange(0, 10, 0.5))
    assert m.step_timing_f1(truth, truth) == pytest.approx(1.0)
    r = m.match_steps(truth + int(0.15 * NS), truth)
    assert r.f1 == pytest.approx(1.0)
    assert r.median_lag_s == pytest.approx(0.15)


def test_f1_shift_beyond_tolerance_matches_nothing():
    truth = steps(np.arange(0, 10, 1.0))
    r = m.match_steps(truth + int(0.3 * NS), truth)
    assert r.tp == 0 and r.f1 == 0.0


def test_f1_missed_and_extra_steps():
    truth = steps(np.arange(10) * 0.5)  # 10 steps
    est = np.concatenate([truth[:8], steps([10.0, 11.0, 12.0, 13.0])])  # 8 hits, 4 false alarms
    r = m.match_steps(est, truth)
    assert r.tp == 8
    assert r.precision == pytest.approx(8 / 12)
    assert r.recall == pytest.approx(8 / 10)
    assert r.f1 == pytest.approx(2 * 8 / (12 + 10))


def test_f1_one_to_one():
    # two detections near one true step count once
    r = m.match_steps(steps([1.0, 1.05]), steps([1.02]))
    assert r.tp == 1 and r.precision == pytest.approx(0.5) and r.recall == pytest.approx(1.0)


def test_distance_error_and_polyline():
    assert m.distance_error_pct(105.0, 100.0) == pytest.approx(5.0)
    assert m.polyline_length([0, 3, 3], [0, 0, 4]) == pytest.approx(7.0)


def test_wrap_and_circular_mean_across_pi():
    assert float(wrap_angle(3 * math.pi / 2)) == pytest.approx(-math.pi / 2)
    mean = m.circular_mean([math.pi - 0.1, -math.pi + 0.1])
    assert abs(wrap_angle(mean - math.pi)) < 1e-9


def test_positions_at_interpolates_within_steps_not_pauses():
    t = steps([1, 2, 3, 10])
    e = np.array([1.0, 2.0, 3.0, 4.0])
    p = m.positions_at(t, e, np.zeros(4), steps([0, 1.5, 5, 9.5, 12]))
    np.testing.assert_allclose(p[:, 0], [0.0, 1.5, 3.0, 3.5, 4.0])


def test_best_fit_rotation_recovers_known_rotation():
    rng = np.random.default_rng(1)
    ref = rng.uniform(-20, 20, size=(12, 2))
    for theta in (0.3, -2.0, 3.0):
        est = m.rotate(ref, -theta)  # our track is the truth rotated by -theta
        assert m.best_fit_rotation(est, ref) == pytest.approx(theta)
        np.testing.assert_allclose(m.rotate(est, theta), ref, atol=1e-9)


def square_walk(heading_offset=0.0, step=0.5, side=10.0, dt=0.5, t0=5.0):
    """A 10 m square walked counter-clockwise from (0, 0), steps of 0.5 m every 0.5 s."""
    n_side = int(round(side / step))
    headings = np.repeat([0.0, math.pi / 2, math.pi, -math.pi / 2], n_side) + heading_offset
    lengths = np.full(len(headings), step)
    t = steps(t0 + dt * np.arange(1, len(headings) + 1))
    e, n = m.dead_reckon(lengths, headings)
    lm_t = steps([t0, t0 + dt * n_side, t0 + 2 * dt * n_side, t0 + 3 * dt * n_side, t0 + 4 * dt * n_side])
    lm_e = np.array([0.0, 10.0, 10.0, 0.0, 0.0]) + 100.0  # landmarks in some other origin
    lm_n = np.array([0.0, 0.0, 10.0, 10.0, 0.0]) - 50.0
    return t, e, n, headings, lm_t, lm_e, lm_n


def test_square_exact():
    t, e, n, h, lt, le, ln = square_walk()
    r = m.landmark_errors(t, e, n, h, lt, le, ln)
    np.testing.assert_allclose(r.errors_m, 0.0, atol=1e-9)
    assert r.loop_closure_pct == pytest.approx(0.0, abs=1e-9)
    assert r.path_length_m == pytest.approx(40.0)
    np.testing.assert_allclose(r.segment_heading_err_rad, 0.0, atol=1e-9)
    assert r.fit_rotation_rad == pytest.approx(0.0, abs=1e-12)


def test_square_rotated_heading_absolute_vs_best_fit():
    off = math.radians(10)
    t, e, n, h, lt, le, ln = square_walk(heading_offset=off)
    r = m.landmark_errors(t, e, n, h, lt, le, ln)
    # absolute: landmark k at distance d from the start is off by 2 d sin(off / 2)
    d = np.array([10.0, math.hypot(10, 10), 10.0, 0.0])
    np.testing.assert_allclose(r.errors_m, 2 * d * math.sin(off / 2), atol=1e-9)
    np.testing.assert_allclose(r.errors_fit_m, 0.0, atol=1e-9)
    assert r.fit_rotation_rad == pytest.approx(-off)
    np.testing.assert_allclose(r.segment_heading_err_rad, off, atol=1e-9)
    assert r.segment_heading_mae_deg == pytest.approx(10.0)
    assert r.loop_closure_pct == pytest.approx(0.0, abs=1e-9)


def test_square_with_scale_error_loop_closure():
    t, e, n, h, lt, le, ln = square_walk()
    # the last side 20 % short: the loop misses its start by 2 m over 40 m = 5 %
    short = np.ones(len(h))
    short[-20:] = 0.8
    e2, n2 = m.dead_reckon(0.5 * short, h)
    r = m.landmark_errors(t, e2, n2, h, lt, le, ln)
    assert r.loop_closure_pct == pytest.approx(5.0)
    assert r.final_m == pytest.approx(2.0)


def test_open_path_has_no_loop_closure_and_short_segments_skipped():
    t, e, n, h, lt, le, ln = square_walk()
    r = m.landmark_errors(t[:40], e[:40], n[:40], h[:40], lt[:3], le[:3], ln[:3])
    assert math.isnan(r.loop_closure_pct)
    seg = m.segment_heading_errors(t, h, steps([5.0, 5.2, 10.0]), [0, 0.1, 10], [0, 0, 0])
    assert math.isnan(seg[0]) and seg[1] == pytest.approx(0.0)


def test_summaries_ignore_nan():
    assert m.nanmedian([1.0, float("nan"), 3.0, 10.0]) == pytest.approx(3.0)
    assert m.nanmean([1.0, None, 3.0]) == pytest.approx(2.0)
    assert math.isnan(m.nanmean([]))


def test_reference_track_errors_time_aligned_and_rotation_fitted():
    # walk 10 m East in 10 one-metre steps (one per second from t = 1 s); the GPS says the walk went North
    t_steps = (np.arange(1, 11) * 1e9).astype(np.int64)
    east, north = m.dead_reckon(np.ones(10), np.zeros(10))
    ref_t = (np.arange(0, 11) * 1e9).astype(np.int64)
    ref_e = np.full(11, 100.0)
    ref_n = 50.0 + np.arange(11.0)
    te = m.reference_track_errors(t_steps, east, north, ref_t, ref_e, ref_n)
    # at fix k the track is k m East of the start, the fix k m North: |(k, -k)| = k sqrt 2
    np.testing.assert_allclose(te.errors_m, np.arange(1, 11) * math.sqrt(2), atol=1e-9)
    assert te.median_m == pytest.approx(5.5 * math.sqrt(2))
    assert math.degrees(te.fit_rotation_rad) == pytest.approx(90.0)
    np.testing.assert_allclose(te.errors_fit_m, 0.0, atol=1e-9)
    np.testing.assert_allclose(te.est_at_fixes[0], [100.0, 50.0])
    # a fix between two steps sees the position interpolated within the step
    te = m.reference_track_errors(t_steps, east, north, [0, 2_500_000_000], [0.0, 0.0], [0.0, 0.0])
    assert te.errors_m[0] == pytest.approx(2.5)
    assert math.isnan(m.reference_track_errors(t_steps, east, north, [0], [0.0], [0.0]).median_m)


def test_proper_rotation_recovers_a_3d_rotation_and_never_a_reflection():
    # the one Kabsch fit (core.metrics.proper_rotation: the judge's shape test, the truth walks' body-to-phone fit)
    from core import quaternion as quat
    from core.metrics import proper_rotation

    rng = np.random.default_rng(7)
    b = rng.normal(size=(50, 3))
    r_true = np.array(quat.to_matrix(quat.from_axis_angle((0.3, -0.5, 0.8), 1.1)))
    a = b @ r_true + 1e-6 * rng.normal(size=(50, 3))
    r, sv = proper_rotation(b.T @ a)
    assert np.allclose(r, r_true, atol=1e-5) and np.linalg.det(r) == pytest.approx(1.0)
    assert float(np.sum(sv)) == pytest.approx(float(np.trace(r.T @ (b.T @ a))))
    mirror = a * [1.0, 1.0, -1.0]  # a reflection of a: the best rotation still has det +1
    assert np.linalg.det(proper_rotation(b.T @ mirror)[0]) == pytest.approx(1.0)
