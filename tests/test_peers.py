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


def yaw_rate_of_turning_phone():
    return 0.3  # the default of turning_phone (rad/s)


@pytest.mark.parametrize("name", peers.ALL_PEERS)
def test_every_peer_tracks_the_heading_of_a_tilted_turning_phone(name):
    if name not in peers.available_peers((name,)):
        pytest.skip(f"{name} not installed")
    rec, tn, heading = turning_phone()
    steps = tn[::50][10:-2]
    dip = math.atan2(40.0, 20.0)  # the simulated site's field (0, 20, -40) uT
    out, errors = peers.run_peers(rec, steps, names=(name,), magnetic_dip_rad=dip, delay_s=0.0, cutoff_hz=5.0)
    assert not errors
    # a step's heading is the mean over its interval (0.5 s here): the heading 0.25 s before the step
    truth = heading[::50][10:-2] - yaw_rate_of_turning_phone() * 0.25
    err = np.degrees((out[name] - truth + np.pi) % (2 * np.pi) - np.pi)
    assert np.max(np.abs(err[5:])) < 2.0  # what is left is the smoother's lag at 17 deg/s


def test_step_headings_are_the_mean_over_the_delay_compensated_interval():
    t = np.arange(0, 10_000_000_000, 10_000_000, dtype=np.int64)
    yaw = np.where(t < 5_000_000_000, 0.0, math.pi / 2)  # device y East, then North
    q = np.array([quat.from_axis_angle((0, 0, 1), y - math.pi / 2) for y in yaw])
    h = peers.step_headings(peers.Attitude(t, q), [4_000_000_000, 5_100_000_000, 9_000_000_000], cutoff_hz=2.0,
                            step_duration_s=[0.5, 0.2, 0.5])
    # before the turn; 0.1 s after it (mean over [4.9, 5.1] s after the delay: still turning); well after it
    np.testing.assert_allclose(h[[0, 2]], [0.0, math.pi / 2], atol=1e-3)
    assert 0.05 < h[1] < math.pi / 2 - 0.05


def test_dip_angle():
    acc = np.array([[0.0, 0.0, 9.81]])
    mag = np.array([[0.0, 20.0, -20.0 * math.tan(math.radians(60))]])
    assert math.degrees(peers.dip_angle_rad(acc, mag)) == pytest.approx(60.0)


def test_headline_targets_and_guard_compare():
    results = [
        {"dataset": "oxford_step_counter", "name": "a", "split": "report", "placement": "hand", "step_err_pct": 1.0,
         "step_f1": 0.99},
        {"dataset": "oxford_step_counter", "name": "b", "split": "report", "placement": "bag", "step_err_pct": -5.0,
         "step_f1": 0.9},
        {"dataset": "brajdic_harle_handheld", "name": "c", "split": "report", "placement": "hand",
         "step_err_pct": -3.0},
        {"dataset": "ipin2023_track3", "name": "d", "split": "report", "placement": "hand", "lm_distance_err_pct": 2.0,
         "sources": {"ours": {"lm_mean_m": 1.5, "lm_fit_mean_m": 1.0, "loop_pct": 1.5, "seg_heading_deg": 5.0},
                     "rotvec": {"lm_mean_m": 4.0, "lm_fit_mean_m": 1.0, "loop_pct": 3.0, "seg_heading_deg": 5.0}}},
        # a tuning-split recording must not move the report numbers
        {"dataset": "ipin2023_track3", "name": "e", "split": "tuning", "placement": "hand", "lm_distance_err_pct": 9.0,
         "sources": {"ours": {"lm_mean_m": 9.0, "lm_fit_mean_m": 9.0, "loop_pct": 9.0, "seg_heading_deg": 9.0}}},
        {"dataset": "ms_indoor_location_2020", "name": "f", "split": "report", "placement": "hand_flat",
         "lm_distance_err_pct": 1.0,
         "sources": {"ours": {"lm_mean_m": 2.0, "lm_fit_mean_m": 1.0, "loop_pct": math.nan, "seg_heading_deg": 5.0},
                     "rotvec": {"lm_mean_m": 2.5, "lm_fit_mean_m": 1.0, "loop_pct": math.nan, "seg_heading_deg": 5.0},
                     "ekf": {"lm_mean_m": 2.2, "lm_fit_mean_m": 1.0, "loop_pct": math.nan, "seg_heading_deg": 5.0}}},
        {"dataset": "sensorlogger_gps_walk_ethz", "name": "g", "split": "report", "placement": "hand_flat",
         "ref_sources": {"ours": {"median_m": 12.0, "fit_median_m": 5.0}}},
    ]
    h = run.headline(results)
    assert h["handheld_report_step_mae_pct"] == pytest.approx(2.0)
    assert h["oxford_report_all_step_mae_pct"] == pytest.approx(3.0)
    assert h["ipin2023_report_landmark_median_m"] == pytest.approx(1.5)
    assert h["ipin2023_tuning_landmark_median_m"] == pytest.approx(9.0)
    assert h["ipin2023_report_rotvec_landmark_median_m"] == pytest.approx(4.0)
    assert "ipin2023_tuning_rotvec_landmark_median_m" not in h  # the peer did not run on every tuning recording
    assert h["eth_walk_report_gps_median_m"] == 12.0 and h["eth_walk_report_gps_fit_median_m"] == 5.0
    assert not any("handheld_tuning" in k or "eth_walk_tuning" in k for k in h)
    targets = {(t["metric"], t["ref"]): t for t in run.evaluate_targets(h)}
    assert all(t["met"] for t in targets.values()), targets
    ms = targets[("ms_indoor_report_landmark_median_m", "ms_indoor_report_ekf_landmark_median_m")]
    assert ms["limit"] == 2.2  # better than every peer: the best peer is the limit
    h2 = dict(h, ms_indoor_report_landmark_median_m=2.3, ipin2023_report_loop_closure_median_pct=3.01)
    missed = {t["metric"] for t in run.evaluate_targets(h2) if t["met"] is False}
    assert missed == {"ms_indoor_report_landmark_median_m", "ipin2023_report_loop_closure_median_pct"}
    assert all(t["met"] is None for t in run.evaluate_targets({}))
    rows, ok = guard.compare(h, {"handheld_report_step_mae_pct": {"max": 1.5},
                                 "oxford_report_step_f1_median": {"min": 0.9},
                                 "ms_indoor_tuning_landmark_fit_median_m": {"max": 3.0}})
    assert not ok
    assert [r[3].split()[0] for r in rows] == ["WORSE", "ok", "absent"]
    th = guard.thresholds_from(h)
    assert th["handheld_report_step_mae_pct"] == {"max": 2.5, "baseline": 2.0}
    assert th["ipin2023_tuning_landmark_median_m"] == {"max": 9.9, "baseline": 9.0}
    assert "ipin2023_report_rotvec_landmark_median_m" not in th  # peers are not guarded


def test_a_failed_recording_counts_in_every_headline_never_dropped():
    ok_ipin = {"dataset": "ipin2023_track3", "split": "report", "placement": "hand", "lm_distance_err_pct": 2.0,
               "sources": {"ours": {"lm_mean_m": 1.5, "lm_fit_mean_m": 1.0, "loop_pct": 1.5, "seg_heading_deg": 5.0,
                                    "lm_errors_m": [1.0, 2.0]},
                           "rotvec": {"lm_mean_m": 4.0, "lm_fit_mean_m": 1.0, "loop_pct": 3.0,
                                      "seg_heading_deg": 5.0}}}
    failed = {"split": "report", "placement": "hand", "error": "ValueError: broken"}
    results = [dict(ok_ipin, name="a"), dict(ok_ipin, name="b"), dict(failed, dataset="ipin2023_track3", name="c"),
               {"dataset": "oxford_step_counter", "name": "d", "split": "report", "placement": "hand",
                "step_err_pct": 2.0, "step_f1": 0.9},
               dict(failed, dataset="oxford_step_counter", name="e"),
               {"dataset": "sensorlogger_gps_walk_ethz", "name": "g", "split": "report", "placement": "hand_flat",
                "ref_sources": {"ours": {"median_m": 12.0, "fit_median_m": 5.0}}},
               dict(failed, dataset="sensorlogger_gps_walk_ethz", name="h"),
               dict(failed, dataset="sensorlogger_gps_walk_ethz", name="i")]
    h = run.headline(results)
    assert h["ipin2023_report_landmark_median_m"] == 1.5  # median of (1.5, 1.5, inf): counted, not dropped
    assert h["ipin2023_report_landmark_pooled_median_m"] == 2.0  # (1, 2, 1, 2, inf)
    assert h["ipin2023_report_rotvec_landmark_median_m"] == 4.0  # the failed run left the peers without steps
    assert h["ipin2023_report_loop_closure_median_pct"] == 1.5
    assert h["oxford_report_all_step_mae_pct"] == pytest.approx(51.0)  # (|2| + |-100|) / 2: no steps
    assert h["oxford_report_step_f1_median"] == pytest.approx(0.45)  # (0.9, 0)
    assert h["eth_walk_report_gps_median_m"] == math.inf  # (12, inf, inf)
    results.append(dict(failed, dataset="ipin2023_track3", name="j"))
    assert run.headline(results)["ipin2023_report_landmark_median_m"] == math.inf  # (1.5, 1.5, inf, inf)


def test_ekf_peer_gets_the_site_dip_not_the_recordings():
    if "ekf" not in peers.available_peers(("ekf",)):
        pytest.skip("ahrs not installed")
    from unittest import mock

    rec, tn, _ = turning_phone(duration_s=3.0)
    seen = []
    import ahrs.filters

    real = ahrs.filters.EKF

    def spy(*a, **kw):
        seen.append(kw.get("magnetic_ref"))
        return real(*a, **kw)

    with mock.patch.object(ahrs.filters, "EKF", spy):
        peers.attitude_ekf(rec, magnetic_dip_rad=math.radians(50.0))
        peers.attitude_ekf(rec)
    # the simulated field dips 63.4 deg: the peer must get the site's 50 deg, or its own default (None)
    assert seen == [pytest.approx(50.0), None]


def test_make_pipeline_passes_overrides_and_sets_the_declination():
    from core.pdr.pipeline import Pipeline

    from benchmarks.datasets.base import Trial

    trial = Trial(dataset="d", name="n", load=lambda: None, subject={"height_m": 1.8}, declination_rad=0.07)
    pipe = run.make_pipeline(trial)
    assert isinstance(pipe, Pipeline) and pipe.height_m == 1.8
    assert pipe.attitude.declination_rad == pytest.approx(0.07)
    custom = type(pipe.attitude)()
    pipe = run.make_pipeline(trial, attitude=custom, height_m=None, min_bout_steps=1)
    assert pipe.attitude is custom and custom.declination_rad == pytest.approx(0.07)
    assert pipe.height_m is None and pipe.min_bout_steps == 1

    class NoDeclination:
        pass

    p = type("P", (), {"attitude": NoDeclination()})()
    with pytest.raises(TypeError, match="declination_rad"):
        run.set_declination(p, 0.1)


def test_tuning_harness_refuses_the_report_split(tmp_path):
    from benchmarks import tune

    with pytest.raises(tune.ReportSplitError):
        tune.evaluate(split="report", data_root=tmp_path)
    with pytest.raises(ValueError):
        tune.evaluate(split="everything", data_root=tmp_path)
    # allowed explicitly, it gets as far as looking for the data
    with pytest.raises(FileNotFoundError):
        tune.evaluate(split="report", allow_report=True, data_root=tmp_path / "missing")
    assert tune.main(["--split", "report", "--data", str(tmp_path)]) == 2
    assert tune.parse_set(["min_bout_steps=2", "grid_rate_hz=50.0"]) == {"min_bout_steps": 2, "grid_rate_hz": 50.0}


def test_report_labels_splits_and_compares_with_the_baseline(tmp_path, monkeypatch):
    from benchmarks import report

    base = {"dataset": "oxford_step_counter", "placement": "hand", "steps_true": 100, "info": {},
            "labels": [], "duration_s": 60.0, "events": 1000, "pipeline_s": 0.1}
    results = [dict(base, name="a", split="report", steps_ours=101, step_err_pct=1.0),
               {"dataset": "sensorlogger_gps_walk_ethz", "name": "walk", "split": "report", "placement": "hand_flat",
                "info": {"phone": "X", "gps_fixes_dropped": 3}, "labels": [], "n_fixes": 100, "ref_time_s": 600.0,
                "ref_source": "GPS", "ref_hacc_median_m": 4.7, "ref_path_m": 600.0, "steps_between_fixes": 700,
                "ref_distance_ours_m": 500.0, "declination_deg": 3.26,
                "ref_sources": {"ours": {"median_m": 12.0, "fit_median_m": 5.0, "p90_m": 20.0, "final_m": 30.0,
                                         "fit_rotation_deg": 10.0}}}]
    baseline = tmp_path / "baseline.json"
    baseline.write_text('{"code": "abc1234", "headline": {"oxford_report_all_step_mae_pct": 2.0, '
                        '"eth_walk_report_gps_median_m": 70.0, "ipin2023_tuning_landmark_median_m": 2.5}}')
    monkeypatch.setattr(report, "BASELINE", baseline)
    run_info = {"results": results, "jobs": 2, "wall_s": 1.0, "quick": False, "peers": [], "split": None,
                "datasets": {"oxford_step_counter": {"n_run": 1, "n_trials": 1, "splits": {"tuning": 0, "report": 1}},
                             "sensorlogger_gps_walk_ethz": {"n_run": 1, "n_trials": 1,
                                                            "splits": {"tuning": 0, "report": 1}}}}
    text = report.build(run_info, {}, tmp_path / "RESULTS.md")
    assert "## Targets (report split)" in text and "### oxford_step_counter: report split (1 recordings)" in text
    assert "| `oxford_*_all_step_mae_pct` |  |  |  | 2.000 | 1.000 | -1.000 |" in text
    assert "| `eth_walk_*_gps_median_m` |  |  |  | 70.000 | 12.000 | -58.000 |" in text
    assert "| `ipin2023_*_landmark_median_m` | 2.500 |  |  |  |  |  |" in text
    assert "median distance from its own GPS track" in text and "| ours | 12.0 | 5.0 |" in text
    assert "tuning split" in text  # the headline table has a column per split


def test_peer_cache_gives_the_peers_stored_attitude_and_misses_on_any_change(tmp_path, monkeypatch):
    """The peer cache (issue #13): a second run reads the stored attitude instead of running the peer (the
    peer's function is made to fail to prove it), with the same headings; a change of the recording's
    readings or of the site's dip is a different key, so the peer runs again."""
    rec, tn, _ = turning_phone(duration_s=12.0)
    steps = tn[::50][4:-2]
    dip = math.atan2(40.0, 20.0)
    cached: list = []
    first, err = peers.run_peers(rec, steps, names=("rotvec",), magnetic_dip_rad=dip, cache_dir=tmp_path,
                                 cached=cached, delay_s=0.0, cutoff_hz=5.0)
    assert not err and cached == [] and len(list(tmp_path.glob("rotvec-*.att"))) == 1

    def must_not_run(*a, **k):
        raise AssertionError("the peer ran although its attitude was stored")

    monkeypatch.setitem(peers.ATTITUDE, "rotvec", must_not_run)
    again, err = peers.run_peers(rec, steps, names=("rotvec",), magnetic_dip_rad=dip, cache_dir=tmp_path,
                                 cached=cached, delay_s=0.0, cutoff_hz=5.0)
    assert not err and cached == ["rotvec"]
    np.testing.assert_allclose(again["rotvec"], first["rotvec"], rtol=0, atol=1e-15)
    # another dip, or one reading changed: not the stored result (the peer is asked to run and fails here)
    _, err = peers.run_peers(rec, steps, names=("rotvec",), magnetic_dip_rad=dip + 1e-6, cache_dir=tmp_path)
    assert "AssertionError" in err["rotvec"]
    rv = rec.streams["rotvec"]
    values = rv.values.copy()
    values[100, 1] += 1e-9
    changed = Recording({**rec.streams, "rotvec": make_stream("rotvec", rv.t_ns, values)})
    assert peers.cache_key("rotvec", changed, dip) != peers.cache_key("rotvec", rec, dip)
    # a damaged stored file is run again (and replaced), never an error
    monkeypatch.undo()
    for f in tmp_path.glob("rotvec-*.att"):
        f.write_bytes(f.read_bytes()[:-5])  # cut short
    cached.clear()
    fixed, err = peers.run_peers(rec, steps, names=("rotvec",), magnetic_dip_rad=dip, cache_dir=tmp_path,
                                 cached=cached, delay_s=0.0, cutoff_hz=5.0)
    assert not err and cached == []
    np.testing.assert_allclose(fixed["rotvec"], first["rotvec"], rtol=0, atol=1e-15)
