"""The app's plain-Python parts (no Kivy): replay source, session, health, settings, viewport, export, GPS layer."""

import dataclasses
import functools
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from app.health import HealthMonitor, StreamHealth
from app.overlay import (ELLIPSE_SIGMA, circles_mesh, covariance_ellipse, ellipse_points, gps_status_text, runs,
                         squares_mesh)
from app.session import Session, export_session, load_any_recording
from tests._session_helpers import replay_session
from app.settings import PROFILE_FILE, SETTINGS_FILE, STRIDE_MODEL_CHOICES, Settings
from app.sources import ReplaySource, sampling_period_us
from app.storage import new_recording_path, output_dir
from app.viewport import Viewport, format_length, nice_length
from core.geodesy import geodetic_to_enu
from core.gnss.fusion import GpsFusion
from core.pdr.calibration import CalibrationError, UserProfile
from core.pdr.pipeline import Pipeline
from core.recording import Recording, make_stream, write_recording
from desktop.simulator import DEFAULT_ORIGIN_LAT_LON, outdoor_walk, simulate_walk
from core.pdr.stride_models import load_stride_model, with_scale

WAYPOINTS = ((0.0, 0.0), (20.0, 0.0), (20.0, 12.0))


@pytest.fixture(scope="module")
def walk():
    return simulate_walk(WAYPOINTS, seed=11, rate_hz=50.0, still_start_s=1.5, still_end_s=1.5)


#: a GPS gap cut into the outdoor walk (s after the first event): the fused track dead-reckons through it
GPS_GAP_S = (50.0, 75.0)


def gps_walk(seed: int = 1, minutes: float = 2.0, gap_s=GPS_GAP_S):
    """A simulated outdoor walk with GPS (:func:`desktop.simulator.outdoor_walk`) with the fixes of ``gap_s``
    removed.  Seed 1: its first fix is good, a multipath episode near the end makes the fusion reject
    fixes, and the gap gives a dead-reckoning stretch in the middle.  At 50 Hz (the simulator's 100 is not the
    subject: the pipeline and the app replay it in several tests)."""
    w = outdoor_walk(seed, minutes=minutes, rate_hz=50.0)
    rec = w.recording
    g = rec.streams["gps"]
    t_s = (g.t_ns - rec.t0_ns) * 1e-9
    keep = ~((t_s >= gap_s[0]) & (t_s < gap_s[1]))
    rec.streams["gps"] = dataclasses.replace(g, t_ns=g.t_ns[keep], values=g.values[keep])
    return w


class FakeClock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


# -- replay source ------------------------------------------------------------------------


def _all(src, clock=None, dt=0.05):
    out = []
    for _ in range(100000):
        if src.finished:
            break
        if clock is not None:
            clock.t += dt
        out.extend(src.drain())
    return out


def test_replay_delivers_every_event_once_in_order_with_exact_timestamps(walk):
    rec = walk.recording
    src = ReplaySource(rec, speed=math.inf, max_chunk=777)
    src.start()
    got = _all(src)
    assert got == list(rec.events(["acc", "gyro", "mag"]))
    assert src.finished and src.progress == 1.0
    assert [e[1] for e in got if e[0] == "acc"] == rec.streams["acc"].t_ns.tolist()


@pytest.mark.parametrize("speed", [1.0, 10.0])
def test_replay_follows_the_wall_clock(walk, speed):
    rec = walk.recording
    clock = FakeClock()
    src = ReplaySource(rec, speed=speed, clock=clock, max_chunk=10**9)
    src.start()
    clock.t += 2.0
    first = src.drain()
    # exactly the events within 2 s x speed of sensor time after the first event
    limit = src.t0_ns + int(2.0 * speed * 1e9)
    expected = [e for e in rec.events(["acc", "gyro", "mag"]) if e[1] <= limit]
    assert first == expected
    assert abs(src.position_s() - 2.0 * speed) < 1e-9


def test_replay_pause_resume_and_seek(walk):
    rec = walk.recording
    clock = FakeClock()
    src = ReplaySource(rec, speed=1.0, clock=clock, max_chunk=10**9)
    src.start()
    clock.t += 1.0
    a = src.drain()
    src.pause()
    clock.t += 50.0  # paused: time passes, nothing is delivered
    assert src.drain() == []
    src.resume()
    clock.t += 1.0
    b = src.drain()
    assert a and b and b[0][1] > a[-1][1]
    assert abs((b[-1][1] - src.t0_ns) * 1e-9 - 2.0) < 0.02  # 2 s of sensor time in total, not 52
    src.seek_start()
    clock.t += 0.5
    c = src.drain()
    assert c[0] == a[0] and abs(src.position_s() - 0.5) < 1e-9
    src.set_speed(math.inf)
    rest = _all(src)
    assert c + rest == list(rec.events(["acc", "gyro", "mag"]))


def test_replay_rejects_a_recording_without_pipeline_streams():
    rec = Recording({"pressure": make_stream("pressure", [1, 2], [[1.0], [2.0]], columns=["hpa"], unit="hPa")})
    with pytest.raises(ValueError, match="nothing to replay"):
        ReplaySource(rec)


# -- session ---------------------------------------------------------------------------------


def test_session_replay_gives_exactly_the_batch_track(walk):
    rec = walk.recording
    batch = Pipeline().run(rec)
    ses = replay_session(rec, Pipeline)
    assert len(ses.steps) == len(batch.steps) >= 40
    np.testing.assert_allclose(ses.track_east[1:], batch.track.east_m, atol=1e-9)
    np.testing.assert_allclose(ses.track_north[1:], batch.track.north_m, atol=1e-9)
    # and the track is the walk: final position within 2.5 m of the last waypoint (a sanity check; the
    # pipeline's accuracy is tested in tests/test_pipeline.py -- since the heading-only magnetometer update
    # the initial heading offset of this walk, about 5 degrees, decays more slowly: 2.26 m here, was 1.51 m)
    assert math.hypot(ses.track_east[-1] - 20.0, ses.track_north[-1] - 12.0) < 2.5
    s = ses.summary()
    assert s["steps"] == len(batch.steps) and abs(s["elapsed_s"] - rec.duration_s) < 0.05


def test_session_reorders_late_events_and_drops_hopeless_ones(walk):
    rec = walk.recording.slice_time(walk.recording.t0_ns, walk.recording.t0_ns + 20 * 10**9)
    events = list(rec.events(["acc", "gyro", "mag"]))
    rng = np.random.default_rng(5)
    # deliver in batches where each sensor's events arrive as a block (like per-sensor callbacks)
    shuffled = []
    for i in range(0, len(events), 12):
        block = events[i:i + 12]
        shuffled += sorted(block, key=lambda e: (e[0], rng.random()))
    ref = Session(ReplaySource(rec, speed=math.inf), pipeline_factory=Pipeline)
    ref.ingest(events)
    ref._finish()
    ses = Session(ReplaySource(rec, speed=math.inf), pipeline_factory=Pipeline)
    ses.ingest(shuffled)
    late = ("acc", events[100][1], events[100][2])  # 18 s too late: beyond any reorder window
    ses.ingest([late])
    ses._finish()
    assert ses.health.streams["acc"].out_of_order == 1
    assert [round(e, 9) for e in ses.track_east] == [round(e, 9) for e in ref.track_east]
    assert len(ses.steps) == len(ref.steps) > 10


def test_session_calibration_walk_is_chosen_by_step_time(walk):
    ses = Session(ReplaySource(walk.recording, speed=math.inf), pipeline_factory=Pipeline)
    ses.start()
    events = ses.source.drain(10**9)
    half, three_q = len(events) // 2, 3 * len(events) // 4
    ses.ingest(events[:half])
    ses.start_calibration()
    t0 = events[half - 1][1]
    assert ses.calibrating and ses.calibration_range_ns == (t0, None)
    ses.ingest(events[half:three_q])
    walked = ses.stop_calibration()
    t1 = events[three_q - 1][1]
    assert not ses.calibrating and ses.calibration_range_ns == (t0, t1)
    ses.ingest(events[three_q:])
    ses._finish()
    # steps completed after "stop" but walked before it count; none walked before "start"
    want = [s for s in ses.steps if t0 <= s.t_ns <= t1]
    got = ses.calibration_steps()  # whole steps (their features fit the stride model); the session's list is on disk
    assert [s.t_ns for s in got] == [s.t_ns for s in want] and len(want) > 5
    assert all(s.features.t_ns == s.t_ns for s in got)
    assert ses.calibration_distance_m() == pytest.approx(sum(s.length_m for s in want))
    assert ses.calibration_distance_m() > walked  # the pipeline's delay: steps come after "stop"
    ses.reset_track()
    assert ses.calibration_range_ns is None and ses.calibration_steps() == []


# -- health ---------------------------------------------------------------------------------


def test_health_rate_jitter_and_missed_events():
    rng = np.random.default_rng(1)
    period = 10_000_000
    t = 10**12 + np.cumsum(period + rng.normal(0, 300_000, 2000).astype(np.int64))
    drop = {300, 301, 302, 1200}  # 3 + 1 events never delivered
    h = StreamHealth("acc", window_s=30.0, max_window=5000)
    for i, ti in enumerate(t.tolist()):
        if i not in drop:
            assert h.accept(ti)
    assert not h.accept(int(t[10]))  # backwards
    s = h.stats()
    assert s.missed == 4 and s.gaps == 2 and s.out_of_order == 1
    assert abs(s.rate_hz - 100.0 * (2000 - 4) / 2000) < 1.0
    assert 0.2 < s.jitter_ms < 1.5  # 0.3 ms interval noise, plus the gaps
    assert abs(s.median_dt_ms - 10.0) < 0.1


def test_health_panel_text_shows_queue_drops_and_mag_trust():
    m = HealthMonitor()
    for i in range(50):
        m.accept("mag", 10**9 + i * 20_000_000)
    m.mag_trusted = False
    txt = m.format(queue_drops={"mag": 7}, accuracy={"mag": 1})
    row = [line for line in txt.splitlines() if line.startswith("mag")][0]
    assert "50.0" in row and " 7 " in row and "low" in row
    assert "magnetometer trusted: NO" in txt


# -- settings and calibration ------------------------------------------------------------------


def test_settings_and_profile_round_trip_and_atomic_save(tmp_path):
    p = tmp_path / "d" / SETTINGS_FILE
    s = Settings(rate_hz=200.0, record_live=False, replay_speed="max", use_gps=False)
    s.height_m = 1.82
    s.set_stride_model("chen_linear")
    s.save(str(p))
    assert sorted(os.listdir(p.parent)) == [PROFILE_FILE, SETTINGS_FILE]  # no temporary file left behind
    assert "height_m" not in json.loads(p.read_text())  # the height lives in the profile only
    assert UserProfile.load(p.parent / PROFILE_FILE) == s.profile
    t = Settings.load(str(p))
    assert t == s and not t.problems and t.height_m == 1.82 and t.stride_model_name == "chen_linear"
    assert t.use_gps is False


def test_settings_survive_damaged_or_silly_files(tmp_path):
    p = tmp_path / SETTINGS_FILE
    p.write_text("{not json")
    s = Settings.load(str(p))
    assert s == Settings() and "could not read" in s.problems[0]
    p.write_text(json.dumps({"rate_hz": 1000, "replay_speed": "1x", "unknown": 1, "use_gps": "yes"}))
    (tmp_path / PROFILE_FILE).write_text(json.dumps({"format": "pdr-user-profile", "format_version": 1,
                                                     "height_m": 17.5, "c_scale": 1.1}))
    s = Settings.load(str(p))
    assert s.rate_hz == 100.0 and s.replay_speed == "1x" and s.profile == UserProfile() and s.use_gps is True
    assert len(s.problems) == 3 and "use_gps='yes' is not true/false" in s.problems[1]
    assert "plausible body height" in s.problems[2]
    (tmp_path / PROFILE_FILE).write_text(json.dumps(UserProfile(model="no_such_model", c_scale=1.2).to_dict()))
    s = Settings.load(str(p))
    assert s.stride_model_name == "default" and s.profile.c_scale == 1.0 and "no such model" in s.problems[-1]


def test_old_settings_with_stride_c_migrate_to_the_profile(tmp_path):
    p = tmp_path / SETTINGS_FILE
    c_default = load_stride_model("default").coefficient.c
    old = {"height_m": 1.8, "stride_c": 0.52, "rate_hz": 50.0, "record_live": True, "replay_speed": "10x",
           "calibrations": [{"time": "2025-01-01T10:00:00", "known_m": 50.0, "pdr_m": 44.0, "c_old": 0.455,
                             "c_new": 0.52}]}
    p.write_text(json.dumps(old))
    s = Settings.load(str(p))
    assert not s.problems and "converted" in s.notes[0]
    assert s.height_m == 1.8 and s.rate_hz == 50.0 and s.profile.c_scale == pytest.approx(0.52 / c_default)
    feats = Pipeline().run(simulate_walk(((0.0, 0.0), (10.0, 0.0)), seed=2).recording).steps[3].features
    assert s.stride_model().length_m(feats) == pytest.approx(0.52 * (feats.acc_max_m_s2 - feats.acc_min_m_s2) ** 0.25)
    s.save(str(p))
    assert set(json.loads(p.read_text())) == {"rate_hz", "record_live", "replay_speed", "use_gps", "gps_fusion",
                                              "tracking_mode"}  # old keys gone
    t = Settings.load(str(p))
    assert t == s and not t.notes
    # an old file that was never calibrated (the old default C), or with a C no walker has
    for c, scale, note in ((0.455, 1.0, None), (5.0, 1.0, "ignored")):
        q = tmp_path / str(c) / SETTINGS_FILE
        q.parent.mkdir()
        q.write_text(json.dumps({"stride_c": c, "height_m": None}))
        s = Settings.load(str(q))
        assert s.profile == UserProfile(c_scale=scale) and not s.problems
        assert (note in s.notes[0]) if note else not s.notes


def test_calibration_walk_corrects_the_distance_of_the_next_walk():
    """A walker with long steps (0.75 m, a bouncy gait) calibrates on a 40 m walk, through a session as the
    app does it; afterwards a second, different walk measures within 2 % (at 50 Hz, the rate not the subject: before
    -20.4 %, factor 1.252, after -0.37 %; at 100 Hz -20.4 %, 1.252, -0.34 %)."""
    cal = simulate_walk(((0.0, 0.0), (40.0, 0.0)), seed=4, weinberg_c=0.55, step_length_m=0.75, rate_hz=50.0)
    walk2 = simulate_walk(((0.0, 0.0), (25.0, 0.0), (25.0, 15.0)), seed=8, weinberg_c=0.55, step_length_m=0.75,
                          rate_hz=50.0)
    known, known2 = float(cal.truth.path_length_m), float(walk2.truth.path_length_m)
    s = Settings()
    s.height_m = 1.75
    before = Pipeline(**s.pipeline_kwargs()).run(walk2.recording).summary()["distance_m"]
    assert abs(before - known2) / known2 > 0.1
    ses = Session(ReplaySource(cal.recording, speed=math.inf), pipeline_factory=lambda: Pipeline(**s.pipeline_kwargs()))
    ses.start()
    ses.start_calibration()
    while not ses.finished:
        ses.tick()
    ses.stop_calibration()
    res = s.calibrate(ses.calibration_steps(), known)
    # the simulator's gait is not Weinberg's: the factor is what makes the model's distance the known one
    uncalibrated = Pipeline(**Settings().pipeline_kwargs()).run(cal.recording).summary()["distance_m"]
    assert s.profile is res.profile and s.profile.c_scale == res.scale == pytest.approx(known / uncalibrated, rel=0.01)
    assert res.scale > 1.1  # this walker's steps are longer than the default model says
    assert s.profile.height_m == 1.75 and len(s.profile.calibrations) == 1
    after = Pipeline(**s.pipeline_kwargs()).run(walk2.recording).summary()["distance_m"]
    assert abs(after - known2) / known2 < 0.02
    # the factor belongs to its model: another model starts uncalibrated, switching back restores it
    s.set_stride_model("weinberg_bp")
    assert s.profile.c_scale == 1.0 and s.calibration_walks() == []
    s.set_stride_model("default")
    assert s.profile.c_scale == res.scale and len(s.calibration_walks()) == 1


def test_calibration_refusals_are_messages_for_the_user(walk):
    steps = Pipeline().run(walk.recording).steps
    s = Settings()
    for steps_, known, msg in ((steps, "abc", "must be a number of metres"), (steps, "3", "too short"),
                               (steps, "", "must be a number"), (steps, "-30", "positive"),
                               (steps[:5], "20", "only 5 steps"), (steps, "300", "check the distance"),
                               (steps, "12", "factor")):
        with pytest.raises(CalibrationError, match=msg):
            s.calibrate(steps_, known)
    assert s.profile == UserProfile()  # unchanged


def test_stride_model_choices_are_shipped_models():
    for name in STRIDE_MODEL_CHOICES:
        load_stride_model(name)
    s = Settings()
    s.profile = UserProfile(height_m=1.7, c_scale=1.1)
    kw = s.pipeline_kwargs()
    ref = with_scale(load_stride_model("default"), 1.1)
    f = Pipeline().run(simulate_walk(((0.0, 0.0), (10.0, 0.0)), seed=2).recording).steps[3].features
    assert kw["height_m"] == 1.7 and kw["stride_model"].length_m(f) == ref.length_m(f)


def test_sampling_period_is_capped_at_200_hz():
    assert sampling_period_us(100) == 10000
    assert sampling_period_us(500) == 5000
    with pytest.raises(ValueError):
        sampling_period_us(0)


# -- viewport -----------------------------------------------------------------------------------


def test_viewport_inverse_zoom_and_fit():
    vp = Viewport(400, 300, x0=10, y0=20, scale=10.0, center=(5.0, -3.0))
    e, n = vp.to_world(*vp.to_screen(12.5, 7.25))
    assert (e, n) == pytest.approx((12.5, 7.25))
    world = vp.to_world(300, 100)
    vp.zoom_at(2.5, 300, 100)
    assert vp.scale == 25.0 and vp.to_world(300, 100) == pytest.approx(world)
    vp.pan(40, -20)
    assert vp.to_world(340, 80) == pytest.approx(world)
    east, north = [0, 50, 50, -10], [0, 0, 30, 30]
    vp.fit(east, north, margin_px=20)
    pts = np.array(vp.points(east, north)).reshape(-1, 2)
    assert pts[:, 0].min() >= 10 + 20 - 1e-9 and pts[:, 0].max() <= 410 - 20 + 1e-9
    assert pts[:, 1].min() >= 20 + 20 - 1e-9 and pts[:, 1].max() <= 320 - 20 + 1e-9
    m, px = vp.scale_bar(120)
    assert m in (1, 2, 5, 10, 20, 50) and px <= 120


def test_nice_length():
    assert [nice_length(x) for x in (0.7, 1, 3.3, 9.99, 12, 480)] == [0.5, 1, 2, 5, 10, 200]
    assert format_length(0.5) == "50 cm" and format_length(2000) == "2 km"


# -- export and storage -------------------------------------------------------------------------


def test_export_writes_track_files_and_copies_the_raw_recording(tmp_path, walk):
    raw = tmp_path / "walk.csv"
    write_recording(str(raw), walk.recording)
    rec = load_any_recording(str(raw))
    ses = Session(ReplaySource(rec, speed=math.inf), pipeline_factory=Pipeline)
    ses.start()
    while not ses.finished:
        ses.tick()
    out = export_session(ses, str(tmp_path / "out"), "walk", raw_path=str(raw))
    assert not out["errors"], out["errors"]
    gj = json.load(open(out["geojson"]))
    assert len(gj["features"][0]["geometry"]["coordinates"]) == len(ses.steps) + 1
    gpx = open(out["gpx"]).read()
    assert gpx.count("<trkpt") == len(ses.steps) + 1 and "<time>" in gpx
    assert open(out["raw"], "rb").read() == raw.read_bytes()


def test_storage_paths(tmp_path):
    d = output_dir(str(tmp_path / "data"), str(tmp_path / "out"))
    assert d == str(tmp_path / "out") and os.path.isdir(d)
    a = new_recording_path(d, when=0)
    open(a, "w").close()
    b = new_recording_path(d, when=0)
    assert a != b and b.endswith("-1.csv")


# -- GPS fusion in the session ---------------------------------------------------------------


@functools.cache
def gps_walk_run():
    """The GPS walk (:func:`gps_walk`), its batch run with the fusion and the app's settings, and a session's replay
    of it with Chen's filter (it trains the profile), computed once per process: tests/test_app_ui.py draws and
    replays the same (the two files are one xdist work unit, tests/conftest.py).  Shared: read them, never change
    them."""
    w = gps_walk()
    batch = Pipeline(**Settings().pipeline_kwargs(), gnss=GpsFusion()).run(w.recording)
    ses = replay_session(w.recording, Settings(gps_fusion="chen").pipeline_factory())
    return w, batch, ses


@pytest.fixture(scope="module")
def gps_run():
    """The GPS walk, its batch run with the fusion, and the session's replay of it (:func:`gps_walk_run`)."""
    return gps_walk_run()


def test_use_gps_setting_builds_a_fresh_fusion_per_pipeline():
    s = Settings()
    assert s.use_gps is True  # on by default
    make = s.pipeline_factory()
    a, b = make(), make()
    from core.gnss import AUTO_FUSION

    assert a.gnss.name == b.gnss.name == AUTO_FUSION and a.gnss is not b.gnss
    s.use_gps = False
    assert make().gnss is not None  # a factory keeps the settings it was made with ...
    assert s.pipeline_factory()().gnss is None  # ... a new one takes the change
    ses = Session(ReplaySource(simulate_walk(WAYPOINTS, seed=11).recording, speed=math.inf),
                  pipeline_factory=s.pipeline_factory())
    assert ses.gnss is None and ses.gps_overlay() is None and ses.position_covariance() is None


def test_session_replay_gives_the_batch_fused_track(gps_run):
    """Same events in the same order through the same streaming kernel: the fused track, its sources, the
    fixes and the covariance agree with ``Pipeline(gnss=GpsFusion()).run`` to rounding (1e-9 m, 1e-9 m^2)."""
    w, batch, ses = gps_run
    fusion = batch.fusion
    g = ses.gps_overlay()
    assert g.anchored and ses.gps_anchored and len(ses.steps) == len(fusion.steps) > 150
    np.testing.assert_allclose(g.fused_east, [0.0] + [s.east_m for s in fusion.steps], rtol=0, atol=1e-9)
    np.testing.assert_allclose(g.fused_north, [0.0] + [s.north_m for s in fusion.steps], rtol=0, atol=1e-9)
    assert g.fused_source == [s.source for s in fusion.steps]
    assert g.n_fixes == fusion.counters["fixes"] == len(w.recording.streams["gps"])
    assert g.n_used == fusion.counters["fixes_accepted"]
    np.testing.assert_allclose(g.cov_en_m2, fusion.steps[-1].cov_en_m2, rtol=1e-9, atol=1e-12)
    (ve, c), (c2, vn) = ses.position_covariance()
    assert c == c2 and (ve, c, vn) == g.cov_en_m2
    assert ses.gnss.origin_lat_lon == pytest.approx(fusion.origin_lat_lon, abs=1e-12)
    # every fix is drawable here (all have a position); accepted ones sit where the fusion put them
    ok = np.array(g.fix_accepted)
    assert len(ok) == g.n_fixes and ok.sum() == g.n_used and (~ok).sum() >= 1  # the multipath episode (11 now)
    acc = [f for f in fusion.fixes if f.accepted]
    np.testing.assert_allclose(np.array(g.fix_east)[ok], [f.east_m for f in acc], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(g.fix_hacc)[ok], [f.hacc_m for f in acc], rtol=0, atol=1e-12)


def test_fused_track_dead_reckons_through_the_gps_gap(gps_run):
    """Dead-reckoning stretches: the step(s) before the first fix and while the GPS judge (issue #26) settles on
    the stream (8 fixes, then 10 s of passing: usable at about 20 s, deliberately), the gap (from the fusion's
    5 s timeout after the last fix on; the judge keeps a stream it found usable through a short gap, so the
    first fixes after it are fused at once), and whatever the fusion makes of the multipath episode of 103-118 s (with the
    fusion of this writing: gated fixes, then a relock, one stretch at 107-111 s); between the gap and the
    multipath all is "fused".  Up to the multipath the fused track is the walk (within 10 m of the truth;
    4.7 m at this writing).  What the app shows is checked against the fusion itself above; the looser
    numbers here are about the walk, so that retuning the fusion does not break the app's tests."""
    w, _, ses = gps_run
    t0 = w.recording.t0_ns
    t_s = np.array([(s.t_ns - t0) * 1e-9 for s in ses.steps])
    src = np.array(ses.fused_source)
    in_gap = (t_s > GPS_GAP_S[0] + 6.0) & (t_s < GPS_GAP_S[1])
    assert in_gap.sum() > 30 and (src[in_gap] == "dr").all()
    assert (src[(t_s > GPS_GAP_S[1] + 2.0) & (t_s < 103.0)] == "fused").all()
    stretches = runs(src == "dr")
    early = [(a, b) for a, b in stretches if t_s[b - 1] < GPS_GAP_S[0]]
    # before the first fix, and while the judge settles on the stream
    assert stretches[0][0] == 0 and early and all(t_s[b - 1] < 25.0 for a, b in early)
    gap = [(a, b) for a, b in stretches if t_s[a] < GPS_GAP_S[0] + 6.0 < GPS_GAP_S[1] - 1.0 < t_s[b - 1]]
    assert len(gap) == 1 and t_s[gap[0][1] - 1] < GPS_GAP_S[1] + 2.0
    assert all(t_s[a] > 100.0 for a, b in stretches[len(early) + 1:])  # any others: the multipath
    # the truth is in the simulator's frame; the fusion's frame is placed by its origin
    shift = np.array(geodetic_to_enu(*ses.gnss.origin_lat_lon, DEFAULT_ORIGIN_LAT_LON))
    truth = w.truth.position_at(np.array([s.t_ns for s in ses.steps]))[:, :2] - shift
    err = np.hypot(np.array(ses.fused_east[1:]) - truth[:, 0], np.array(ses.fused_north[1:]) - truth[:, 1])
    assert np.max(err[t_s < 103.0]) < 10.0, np.max(err[t_s < 103.0])


def test_screened_out_fixes_are_placed_for_the_view():
    """A fix with a bad accuracy is screened out by the fusion (its record has no local position); once the
    walk is anchored the session places it from its latitude/longitude, as rejected."""
    w = gps_walk(gap_s=(0.0, 0.0))
    rec = w.recording
    g = rec.streams["gps"]
    v = g.values.copy()
    v[20, 3] = 80.0  # hacc 80 m > the fusion's 25 m
    rec.streams["gps"] = dataclasses.replace(g, values=v)
    rec = rec.slice_time(rec.t0_ns, rec.t0_ns + 40 * 10**9)
    ses = replay_session(rec, Settings().pipeline_factory())
    rejected = [f for f in ses.gnss.fixes if "accuracy" in f.reason]
    assert len(rejected) == 1 and math.isnan(rejected[0].east_m)
    k = [i for i, h in enumerate(ses.fix_hacc) if h == 80.0]
    assert len(k) == 1 and ses.fix_accepted[k[0]] is False
    e, n = geodetic_to_enu(v[20, 0], v[20, 1], ses.gnss.origin_lat_lon)
    assert (ses.fix_east[k[0]], ses.fix_north[k[0]]) == pytest.approx((e, n), abs=1e-9)


def test_gps_on_without_fixes_is_not_anchored(walk):
    ses = replay_session(walk.recording, Settings().pipeline_factory())
    g = ses.gps_overlay()
    assert not g.anchored and g.n_fixes == 0 and g.fix_east == []
    assert len(g.fused_source) == len(ses.steps) and set(g.fused_source) == {"dr"}
    assert "no fix yet" in gps_status_text(g.n_fixes, g.n_used, g.cov_en_m2, g.anchored)


def test_export_places_the_track_with_the_fusion_origin(gps_run, tmp_path):
    """With GPS fusion the export's origin is the fusion's (the walk's start), within 10 m of the true start."""
    _, batch, ses = gps_run
    out = export_session(ses, str(tmp_path), "walk")
    assert not out["errors"], out["errors"]
    props = json.loads(Path(out["geojson"]).read_text())["features"][0]["properties"]
    assert props["origin_known"] and props["origin_lat_lon"] == pytest.approx(batch.fusion.origin_lat_lon, abs=1e-12)
    assert np.hypot(*geodetic_to_enu(*props["origin_lat_lon"], DEFAULT_ORIGIN_LAT_LON)) < 10.0
    import gpxpy  # noqa: PLC0415 - the export's own dependency

    start = gpxpy.parse(Path(out["gpx"]).read_text()).tracks[0].segments[0].points[0]
    assert (start.latitude, start.longitude) == pytest.approx(batch.fusion.origin_lat_lon, abs=1e-9)
    # the fused track is what is written: its points carry the uncertainty and the source, and the last
    # point is the batch fusion's last step
    pts = [f for f in json.loads(Path(out["geojson"]).read_text())["features"] if f["geometry"]["type"] == "Point"]
    assert len(pts) == len(batch.fusion.steps) and {p["properties"]["source"] for p in pts} == {"fused", "dr"}
    last = batch.fusion.steps[-1]
    assert pts[-1]["geometry"]["coordinates"][::-1] == pytest.approx([last.lat_deg, last.lon_deg], abs=1e-7)


# -- GPS layer geometry (app.overlay) ---------------------------------------------------------


def test_covariance_ellipse_axes_and_orientation():
    ang = math.radians(30.0)
    R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    C = R @ np.diag([9.0, 1.0]) @ R.T  # SD 3 m along 30 deg, 1 m across
    a, b, angle = covariance_ellipse((C[0, 0], C[0, 1], C[1, 1]), k_sigma=2.0)
    assert (a, b) == pytest.approx((6.0, 2.0), rel=1e-12) and angle == pytest.approx(ang, abs=1e-12)
    # every point of the drawn outline lies on p^T C^-1 p = k^2
    pts = np.array(ellipse_points(10.0, -5.0, a, b, angle, n=37)).reshape(-1, 2) - (10.0, -5.0)
    q = np.einsum("ij,jk,ik->i", pts, np.linalg.inv(C), pts)
    np.testing.assert_allclose(q, 4.0, rtol=1e-12)
    assert ELLIPSE_SIGMA == 2.0
    # degenerate and axis-aligned cases
    assert covariance_ellipse((0.0, 0.0, 0.0)) == (0.0, 0.0, pytest.approx(0.0, abs=np.pi / 2 + 1e-12))
    a, b, angle = covariance_ellipse((1.0, 0.0, 4.0), k_sigma=1.0)
    assert (a, b) == pytest.approx((2.0, 1.0)) and abs(angle) == pytest.approx(math.pi / 2)


def test_overlay_meshes_runs_and_status():
    v, i = circles_mesh([0.0, 100.0], [0.0, 50.0], [3.0, 7.5], n=16)
    xy = np.array(v).reshape(2, 16, 4)[:, :, :2]
    np.testing.assert_allclose(np.hypot(*(xy - np.array([[[0.0, 0.0]], [[100.0, 50.0]]])).transpose(2, 0, 1)),
                               [[3.0] * 16, [7.5] * 16], rtol=1e-12)
    assert len(i) == 2 * 2 * 16 and max(i) == 31 and i[:4] == [0, 1, 1, 2] and i[31] == 0
    v, i = squares_mesh([5.0], [6.0], 2.0)
    assert np.array(v).reshape(4, 4)[:, :2].tolist() == [[3, 4], [7, 4], [7, 8], [3, 8]] and i == [0, 1, 2, 2, 3, 0]
    assert squares_mesh([], [], 1.0) == ([], []) and circles_mesh([], [], []) == ([], [])
    assert runs([True, True, False, False, True]) == [(0, 2), (4, 5)] and runs([False]) == [] and runs([]) == []
    assert gps_status_text(118, 92, (0.25, 0.0, 0.09), True) == "GPS: 118 fixes, 92 used · ±1.0 m (2σ)"
    assert gps_status_text(1, 0, None, False) == "GPS: 1 fix, 0 used · waiting for a good fix"


def test_a_live_walk_with_gps_teaches_the_profile_and_the_next_track_starts_from_it(gps_run, tmp_path):
    _, _, ses = gps_run
    s = Settings(gps_fusion="chen")
    trainer = ses.pipeline.gnss.trainer
    learnt = s.learn_from_gps(ses.pipeline)
    assert learnt == (trainer.stride_gps_distance_m >= 100.0 or trainer.n_heading_samples >= 4)
    assert learnt, "the 2-minute GPS walk should teach at least the heading model"
    path = tmp_path / "settings.json"
    s.save(str(path))
    back = Settings.load(str(path))
    assert back.profile.gps == s.profile.gps
    fusion = back.pipeline_factory()().gnss
    got = fusion.heading_model.coefficients_rad()[0]
    assert math.degrees(got) == pytest.approx(math.degrees(trainer.heading_model.coefficients_rad()[0]), abs=1e-6)
    assert not Settings().learn_from_gps(Pipeline())  # no GPS fusion: nothing to learn


def test_gps_filter_setting_persists_and_builds_that_filter(tmp_path):
    """The app's GPS filter choice (auto/chen/kubrak, issue #10) is saved, validated and used by new tracks."""
    from core.gnss import AUTO_FUSION
    from core.gnss.kubrak import KubrakFusion

    path = str(tmp_path / "settings.json")
    s = Settings()
    s.gps_fusion = "kubrak"
    s.save(path)
    back = Settings.load(path)
    assert back.gps_fusion == "kubrak" and isinstance(back.pipeline_factory()().gnss, KubrakFusion)
    back.gps_fusion = "lsq"
    assert any("gps_fusion" in p for p in back.validate()) and back.gps_fusion == "auto"
    assert back.pipeline_factory()().gnss.name == AUTO_FUSION
    assert gps_status_text(5, 3, (0.25, 0.0, 0.09), True, verdict="C/N0 of the 4th satellite 20 dB-Hz < 25") == \
        "GPS: 5 fixes, 3 used · ±1.0 m (2σ) · last fix: C/N0 of the 4th satellite 20 dB-Hz < 25"
