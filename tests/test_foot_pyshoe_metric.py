"""PyShoe's published error (benchmarks.foot.pyshoe_metric) and the PyShoe-style peer filter, on exact cases."""

import math

import numpy as np

from benchmarks.foot import peer_shoe_statistic, position_errors, pyshoe_metric, pyshoe_peer
from desktop.foot_simulator import footprints, simulate_foot


def _track(n=400):
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack([3.0 * t, 0.5 * np.sin(3.0 * t), 0.05 * np.sin(20.0 * t)])


def test_rotated_and_shifted_copy_scores_zero():
    truth = _track()
    c, s = math.cos(0.7), math.sin(0.7)
    est = np.column_stack([c * truth[:, 0] - s * truth[:, 1], s * truth[:, 0] + c * truth[:, 1], truth[:, 2]])
    est = est + np.array([5.0, -2.0, 1.0])
    m = pyshoe_metric(est, truth)
    assert m["pyshoe_2d_m"] < 1e-12 and m["pyshoe_3d_m"] < 1e-12


def test_mean_of_per_sample_rms_not_rmse():
    """A lateral error growing linearly to d: PyShoe's 2-D number is mean(|e|)/sqrt(2) = d/(2 sqrt 2), our
    RMSE is d/sqrt(3) (the alignment point is on the x axis where the error is still ~0)."""
    n, d = 2001, 0.3
    truth = np.column_stack([np.linspace(0.0, 10.0, n), np.zeros(n), np.zeros(n)])
    est = truth.copy()
    est[:, 1] = d * np.linspace(0.0, 1.0, n) ** 8  # negligible at the 0.8 m alignment sample
    m = pyshoe_metric(est, truth)
    expect = d / 9.0 / math.sqrt(2.0)  # mean of u^8 over [0, 1] is 1/9
    assert abs(m["pyshoe_2d_m"] - expect) < 0.01 * expect
    rmse = position_errors(est, truth)["rmse_2d_m"]
    assert rmse > 1.5 * m["pyshoe_2d_m"]


def test_single_point_alignment_takes_the_heading_at_0p8_m():
    """An estimate whose direction is off by 2 deg only before 0.8 m gets turned by that sample alone."""
    n = 1001
    truth = np.column_stack([np.linspace(0.0, 4.0, n), np.zeros(n), np.zeros(n)])
    est = truth.copy()
    k = int(np.flatnonzero(truth[:, 0] >= 0.8)[0])
    est[k, 1] = 0.8 * math.tan(math.radians(2.0))  # one noisy sample at the alignment point
    m = pyshoe_metric(est, truth)
    # every later sample is turned by -2 deg: mean lateral error ~ mean(x) * 2 deg over the track
    expect = np.mean(truth[:, 0]) * math.radians(2.0) / math.sqrt(2.0)
    assert abs(m["pyshoe_2d_m"] - expect) < 0.05 * expect


def test_peer_follows_exact_simulated_walk_with_true_stance():
    """Exact data (no noise), true stance, gravity as the peer assumes: horizontal stance positions within
    5 cm on a straight 5.6 m walk; the vertical climbs (first-order mechanisation: one reason PyShoe-style
    tracks have the larger vertical error on the VICON trials); the SHOE statistic is ~0 in stance."""
    w = simulate_foot(footprints([(5.6, 0.0)]), rate_hz=200.0, gravity_m_s2=9.8029)
    # the simulator's body axes are z-up (specific force +g at rest); the peer works z-down as PyShoe's
    # files: flip y and z (a proper rotation by pi about x)
    flip = np.array([1.0, -1.0, -1.0])
    acc, gyro = w.acc_b * flip, w.gyro_b * flip
    pos = pyshoe_peer(acc, gyro, w.stance)
    T = peer_shoe_statistic(acc, gyro)
    assert np.median(T[w.stance]) < 1.0
    assert np.median(T[~w.stance]) > 1e4
    # the peer's frame: heading 0 at the start, and its ENU is a mirror of the simulator's (axis swap)
    truth = w.position_n - w.position_n[0]
    st = w.stance
    d_est = np.hypot(pos[st, 0], pos[st, 1])
    d_true = np.hypot(truth[st, 0], truth[st, 1])
    assert np.max(np.abs(d_est - d_true)) < 0.05
    # the first-order step (current sample, no trapezoid) climbs about 1.5 cm per stride on exact data
    dz = pos[st, 2] - truth[st, 2]
    assert 0.02 < np.max(np.abs(dz)) < 0.10


def test_a_failed_recording_counts_in_the_median():
    """A recording without a track (NaN error) is an infinite error in the benchmark's medians, never dropped."""
    from benchmarks.foot import median, n_failed

    assert median([0.1, 0.2, float("nan")]) == 0.2  # not 0.15, the median of the two that worked
    assert median([0.1, float("nan"), None, 0.3]) == math.inf
    assert n_failed([0.1, float("nan"), None, math.inf]) == 3
    e = position_errors(np.full((10, 3), np.nan), np.zeros((10, 3)))
    assert math.isnan(e["rmse_3d_m"]) and median([e["rmse_3d_m"], 0.1, 0.2]) == 0.2


def test_headlines_of_the_split_asked_for():
    """``python -m benchmarks.foot --split tuning`` prints the tuning split's headlines, not the report's."""
    from benchmarks.foot import headlines

    def case(v):
        return {"rmse_3d_median_m": v, "rmse_3d_median_walking_m": v, "rmse_3d_max_m": v, "n_failed": 0,
                "n_above_0p5_m": 0, "pyshoe_2d_median_m": v / 2, "stance_f1_median_walking": 0.9,
                "stance_f1_median_all": 0.9, "us_per_sample_median": 1.0}

    def split(v):
        return {"n_trials": 14, "pyshoe_best_per_trial_median_m": 0.04,
                "cases": {c: case(v) for c in ("shoe", "shoe_filter", "shoe_fixed", "song", "reference",
                                               "peer_shoe_fixed")}}

    out = {"pyshoe": {"tuning": split(0.06), "report": split(0.1)}}
    t, r = headlines(out, "tuning"), headlines(out)
    assert t["split"] == "tuning" and r["split"] == "report"
    assert t["pyshoe_metric_median_m"] == 0.03 and t["target_pyshoe_metric_median_not_worse_than_oracle"]
    assert r["pyshoe_metric_median_m"] == 0.05 and not r["target_pyshoe_metric_median_not_worse_than_oracle"]
    assert "pyshoe_metric_median_m" not in headlines({"pyshoe": {"report": split(0.1)}}, "tuning")
