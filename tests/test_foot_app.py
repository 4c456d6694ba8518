"""Foot mode as a user meets it: the tracking-mode choice, the streaming tracker, and the app's session
(track, status strip, health panel, export) on a simulated foot walk whose truth the simulator knows."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from app.session import Session, export_session
from app.settings import FOOT_MIN_RATE_HZ, Settings
from app.sources import replay_source_for
from core.foot.navigator import FootNavigator
from core.foot.tracker import FootStep, FootTracker, choose_mode, foot_settings_for
from core.pdr.pipeline import Pipeline
from core.recording import Recording
from desktop.foot_simulator import footprints, simulate_foot
from desktop.simulator import simulate_walk

LEGS = [(8.4, 0.0), (5.6, math.pi / 2), (4.2, math.pi / 2)]


@pytest.fixture(scope="module")
def foot_walk():
    return simulate_foot(footprints(LEGS), rate_hz=100.0, acc_noise_m_s2=0.05, gyro_noise_rad_s=0.005,
                         waist=True, seed=3)


@pytest.fixture(scope="module")
def hand_walk():
    return simulate_walk(((0.0, 0.0), (12.0, 0.0)), seed=4, still_start_s=1.0, still_end_s=1.0)


def _undeclared(rec: Recording) -> Recording:
    """The same recording without the placement it declares (so the signals decide)."""
    return Recording(rec.streams, device={k: v for k, v in rec.device.items() if k != "placement"},
                     metadata=dict(rec.metadata))


def test_mode_comes_from_the_declared_placement_then_from_the_signals(foot_walk, hand_walk):
    assert choose_mode(foot_walk.recording)[0] == "foot"
    assert "foot" in choose_mode(foot_walk.recording)[1]
    mode, why = choose_mode(_undeclared(foot_walk.recording))
    assert (mode, why.split(":")[0]) == ("foot", "detected")
    assert choose_mode(_undeclared(hand_walk.recording))[0] == "handheld"
    assert choose_mode(foot_walk.recording, "handheld") == ("handheld", "chosen by the user")
    with pytest.raises(ValueError):
        choose_mode(foot_walk.recording, "pocket")


def test_foot_settings_use_the_tckf_only_with_a_waist_magnetometer(foot_walk):
    fs, waist = foot_settings_for(foot_walk.recording)
    assert (fs.aid, waist) == ("tckf", "waist")
    fs, waist = foot_settings_for(None)  # a phone alone on the shoe
    assert (fs.aid, waist) == ("zupt", None)


def test_replays_are_smoothed_and_live_tracking_is_not(foot_walk):
    """The RTS smoother is for replays (a recording): live settings and the app's tracker never smooth."""
    assert foot_settings_for(foot_walk.recording)[0].rts_smoother
    assert not foot_settings_for(None)[0].rts_smoother
    fs, waist = foot_settings_for(foot_walk.recording)
    tracker = FootTracker(fs, waist_device=waist)
    assert not tracker.settings.rts_smoother and tracker.nav.ins.history is None


def test_tracker_streams_the_batch_strides_and_keeps_no_samples(foot_walk):
    rec = foot_walk.recording
    fs, waist = foot_settings_for(rec)
    batch = FootNavigator(replace(fs, rts_smoother=False), waist_device=waist).run(rec)  # the app: no smoother
    want = [s for s in batch.strides if math.isfinite(s.length_m)]
    tr = FootTracker(fs, waist_device=waist)
    got = []
    for name, t, v in rec.events():
        got += tr.update(name, t, v)
    got += tr.finish()
    assert len(got) == len(want) == len(tr.steps)
    assert all(isinstance(s, FootStep) for s in got)
    for g, w in zip(got, want):
        assert g.t_ns == w.t_end_ns
        assert abs(g.east_m - w.position_n[0]) < 1e-9 and abs(g.north_m - w.position_n[1]) < 1e-9
        assert abs(g.length_m - w.length_m) < 1e-9
    assert len(tr.nav.out_t) == 0  # per-sample outputs were not kept
    d = tr.diagnostics()
    assert d["samples"] == len(batch.t_ns)
    assert abs(d["stance_fraction"] - float(np.mean(batch.stance))) < 1e-12
    assert abs(d["zupt_nis_mean"] - float(np.mean(batch.zupt_nis))) < 1e-9
    # the track against the simulator's truth: every stride within 0.3 m of its footprint
    truth = foot_walk.footprints_n[1:len(got) + 1]
    err = np.hypot([s.east_m - e for s, e in zip(got, truth[:, 0])], [s.north_m - n for s, n in zip(got, truth[:, 1])])
    assert np.max(err) < 0.3
    st = tr.status()
    assert st.n_steps == len(got) and abs(st.distance_m - sum(s.length_m for s in got)) < 1e-9
    assert math.isfinite(st.heading_rad)


def _replay(rec, factory) -> Session:
    ses = Session(replay_source_for(rec, factory, speed=math.inf, max_chunk=700), pipeline_factory=factory)
    ses.start()
    for _ in range(100000):
        ses.tick(budget_s=0.01)
        if ses.finished:
            break
    return ses


def test_app_session_replays_a_foot_recording_in_foot_mode(foot_walk, tmp_path):
    rec = foot_walk.recording
    s = Settings()
    assert s.choose_tracking_mode(rec)[0] == "foot"
    ses = _replay(rec, s.pipeline_factory(rec))
    assert isinstance(ses.pipeline, FootTracker)
    fs, waist = foot_settings_for(rec)
    batch = FootNavigator(replace(fs, rts_smoother=False), waist_device=waist).run(rec)  # the app: no smoother
    want = np.array([s.position_n[:2] for s in batch.strides if math.isfinite(s.length_m)])
    assert np.allclose(np.column_stack([ses.track_east[1:], ses.track_north[1:]]), want, atol=1e-9)
    summ = ses.summary()
    assert summ["steps"] == len(want)
    assert sorted(ses.health.streams) == ["acc", "acc@waist", "gyro", "mag", "mag@waist"]  # the waist's too
    health = ses.health_text()
    assert "foot INS" in health and "stance" in health and "magnetometer trusted" not in health
    out = export_session(ses, str(tmp_path), "foot")
    assert not out["errors"]
    with open(out["geojson"]) as f:
        gj = json.load(f)
    assert gj["type"] == "FeatureCollection"
    rows = open(out["csv"]).read().strip().splitlines()
    assert len(rows) == len(want) + 1


def test_settings_choose_the_mode_and_the_live_rate(tmp_path, foot_walk, hand_walk):
    s = Settings()
    assert s.choose_tracking_mode(None)[0] == "handheld"  # live, auto: hand-held
    assert isinstance(s.pipeline_factory(hand_walk.recording)(), Pipeline)
    s.tracking_mode = "foot"
    s.rate_hz = 100.0
    assert s.choose_tracking_mode(None) == ("foot", "chosen in Settings")
    assert s.live_rate_hz() == FOOT_MIN_RATE_HZ
    assert isinstance(s.pipeline_factory(None)(), FootTracker)
    s.tracking_mode = "handheld"
    assert isinstance(s.pipeline_factory(foot_walk.recording)(), Pipeline)  # the user's choice wins
    s.tracking_mode = "foot"
    path = str(tmp_path / "settings.json")
    s.save(path)
    assert Settings.load(path).tracking_mode == "foot"
    with open(path, "w") as f:
        json.dump({"tracking_mode": "skates"}, f)
    back = Settings.load(path)
    assert back.tracking_mode == "auto" and any("tracking_mode" in p for p in back.problems)


def test_the_app_replays_a_foot_recording_file_in_foot_mode(foot_walk, tmp_path):
    """The real app, headless, on a recording file with a foot IMU and a waist IMU: the track is the batch
    foot INS's strides, the strip counts strides, the health panel shows the INS and the waist streams."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from core.recording import write_recording

    root = Path(__file__).resolve().parents[1]
    path = tmp_path / "foot-walk.csv"
    write_recording(str(path), foot_walk.recording)
    report = tmp_path / "report.json"
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "app", str(path), "--speed", "max", "--headless", "--exit-at-end",
                        "--size", "360x640", "--report", str(report), "--data-dir", str(tmp_path / "data"),
                        "--out", str(tmp_path / "out")], cwd=root, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads(report.read_text())
    assert rep["tracking"]["mode"] == "foot" and rep["tracking"]["steps_name"] == "strides"
    assert "foot" in rep["tracking"]["reason"]
    fs, waist = foot_settings_for(foot_walk.recording)
    batch = FootNavigator(replace(fs, rts_smoother=False), waist_device=waist).run(foot_walk.recording)
    want = [s for s in batch.strides if math.isfinite(s.length_m)]
    assert rep["finished"] and rep["errors"] == 0
    assert int(rep["status"]["steps"]) == len(want)
    np.testing.assert_allclose(rep["track_east"][1:], [s.position_n[0] for s in want], atol=1e-9)
    assert "foot INS" in rep["health"] and "acc@waist" in rep["health"]
