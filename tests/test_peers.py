"""Benchmark heading peers and harness pieces on a simulated phone (no real data needed)."""

import math

import numpy as np
import pytest

from benchmarks import guard, peers, run
from core import quaternion as quat
from core.recording import Recording, make_stream


def turning_phone(duration_s=40.0, rate_hz=100.0, yaw_rate=0.3, pitch=math.radians(30), yaw0=math.radians(20)):
    """A phone held pitched up 30 deg, turning at a constant rate; sensors noise-free. Returns (rec, t_ns, heading)."""
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    heading = yaw0 + yaw_rate * t  # of the device y axis, CCW from East
    q = np.array([quat.multiply(quat.from_axis_angle((0, 0, 1), h - math.pi / 2),
                                quat.from_axis_angle((1, 0, 0), pitch)) for h in heading])
    mats = [np.array(quat.to_matrix(tuple(qi))) for qi in q]
    acc = np.array([m.T @ [0.0, 0.0, 9.81] for m in mats])
    mag = np.array([m.T @ [0.0, 20.0, -40.0] for m in mats])
    gyr = np.array([m.T @ [0.0, 0.0, yaw_rate] for m in mats])
    tn = (t * 1e9).astype(np.int64) + 10**9
    rec = Recording({"acc": make_stream("acc", tn, acc), "gyro": make_stream("gyro", tn, gyr),
                     "mag": make_stream("mag", tn, mag), "rotvec": make_stream("rotvec", tn, q)})
    return rec, tn, heading


@pytest.mark.parametrize("name", peers.ALL_PEERS)
def test_every_peer_tracks_the_heading_of_a_tilted_turning_phone(name):
    if name not in peers.available_peers((name,)):
        pytest.skip(f"{name} not installed")
    rec, tn, heading = turning_phone()
    steps = tn[::50][10:-2]
    out, errors = peers.run_peers(rec, steps, names=(name,), delay_s=0.0, cutoff_hz=5.0)
    assert not errors
    err = np.degrees((out[name] - heading[::50][10:-2] + np.pi) % (2 * np.pi) - np.pi)
    assert np.max(np.abs(err[5:])) < 2.0  # what is left is the smoother's lag at 17 deg/s


def test_step_headings_read_after_the_delay():
    t = np.arange(0, 10_000_000_000, 10_000_000, dtype=np.int64)
    yaw = np.where(t < 5_000_000_000, 0.0, math.pi / 2)  # device y East, then North
    q = np.array([quat.from_axis_angle((0, 0, 1), y - math.pi / 2) for y in yaw])
    h = peers.step_headings(peers.Attitude(t, q), [4_000_000_000, 9_000_000_000], cutoff_hz=2.0)
    np.testing.assert_allclose(h, [0.0, math.pi / 2], atol=1e-3)


def test_dip_angle():
    acc = np.array([[0.0, 0.0, 9.81]])
    mag = np.array([[0.0, 20.0, -20.0 * math.tan(math.radians(60))]])
    assert math.degrees(peers.dip_angle_rad(acc, mag)) == pytest.approx(60.0)


def test_headline_targets_and_guard_compare():
    results = [
        {"dataset": "oxford_step_counter", "name": "a", "placement": "hand", "step_err_pct": 1.0, "step_f1": 0.99},
        {"dataset": "oxford_step_counter", "name": "b", "placement": "bag", "step_err_pct": -5.0, "step_f1": 0.9},
        {"dataset": "brajdic_harle_handheld", "name": "c", "placement": "hand", "step_err_pct": -3.0},
        {"dataset": "ipin2023_track3", "name": "d", "placement": "hand", "lm_distance_err_pct": 2.0,
         "sources": {"ours": {"lm_mean_m": 2.0, "lm_fit_mean_m": 1.0, "loop_pct": 1.5, "seg_heading_deg": 5.0},
                     "rotvec": {"lm_mean_m": 4.0, "lm_fit_mean_m": 1.0, "loop_pct": 3.0, "seg_heading_deg": 5.0}}},
    ]
    h = run.headline(results)
    assert h["handheld_step_mae_pct"] == pytest.approx(2.0)
    assert h["oxford_all_step_mae_pct"] == pytest.approx(3.0)
    assert h["ipin_rotvec_landmark_median_m"] == pytest.approx(4.0)
    assert all(t["met"] for t in run.evaluate_targets(h))
    rows, ok = guard.compare(h, {"handheld_step_mae_pct": {"max": 1.5}, "oxford_step_f1_median": {"min": 0.9},
                                 "ms_landmark_fit_median_m": {"max": 3.0}})
    assert not ok
    assert [r[3].split()[0] for r in rows] == ["WORSE", "ok", "absent"]
    th = guard.thresholds_from(h)
    assert th["handheld_step_mae_pct"] == {"max": 2.5, "baseline": 2.0}
