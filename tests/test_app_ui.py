"""The Kivy app, headless (SDL offscreen driver on Mesa; no display, no Xvfb).

Only one ``App.run()`` works per process, so the full app runs in
subprocesses: one through the documented command line (replay to the end,
screenshot, pixel checks along the expected path), one driving the app's
lifecycle (pause/resume, export).  The track widget's touch handling is
tested in this process on a bare window, and so is its GPS layer (canvas instructions
against the session's fused track, fixes and covariance).
"""

import dataclasses
import json
import math
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from app import kivy_env

kivy_env.prepare(headless=True)  # before anything imports kivy

from core.pdr.pipeline import Pipeline  # noqa: E402
from core.recording import write_recording  # noqa: E402
from desktop.simulator import simulate_walk  # noqa: E402
from core.pdr.calibration import UserProfile  # noqa: E402
from core.pdr.stride_models import load_stride_model, with_scale  # noqa: E402
from app.settings import Settings  # noqa: E402
from test_app_logic import gps_walk_run  # noqa: E402 - tests/ is on sys.path, as for the LIVE script

ROOT = Path(__file__).resolve().parents[1]
WAYPOINTS = ((0.0, 0.0), (30.0, 0.0), (30.0, 20.0), (10.0, 20.0))
SEED = 7
SIZE = (480, 800)
TRACK_RGB = np.array([0.15, 0.75, 1.0]) * 255
START_RGB = np.array([0.2, 0.85, 0.3]) * 255
POSITION_RGB = np.array([1.0, 0.55, 0.1]) * 255
FUSED_RGB = np.array([1.0, 0.84, 0.2]) * 255
FUSED_DR_RGB = np.array([0.78, 0.45, 1.0]) * 255
FIX_RGB = np.array([0.88, 0.90, 0.95]) * 255
REJECTED_RGB = np.array([1.0, 0.25, 0.3]) * 255


def read_png(path):
    """Minimal PNG reader (8-bit RGB/RGBA, not interlaced) -> (h, w, 3) uint8 array; no Pillow needed."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _c, _f, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    img = np.zeros((h, stride), dtype=np.int32)
    prev = np.zeros(stride, dtype=np.int32)
    for r in range(h):
        f = raw[r * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, r * (stride + 1) + 1).astype(np.int32)
        if f == 0:
            cur = line
        elif f == 2:
            cur = (line + prev) & 255
        else:  # sub / average / paeth need the running left neighbour
            cur = np.zeros(stride, dtype=np.int32)
            for i in range(stride):
                a = cur[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                if f == 1:
                    p = a
                elif f == 3:
                    p = (a + b) // 2
                else:
                    pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                    p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[i] = (line[i] + p) & 255
        img[r] = cur
        prev = cur
    return img.reshape(h, w, bpp)[:, :, :3].astype(np.uint8)


def _near_color(img, x, y, rgb, radius, tol=60.0):
    """Is there a pixel of colour ``rgb`` within ``radius`` px of Kivy point (x, y) (y up)?"""
    h, w, _ = img.shape
    row, col = int(round(h - y)), int(round(x))
    r0, r1 = max(row - radius, 0), min(row + radius + 1, h)
    c0, c1 = max(col - radius, 0), min(col + radius + 1, w)
    if r0 >= r1 or c0 >= c1:
        return False
    patch = img[r0:r1, c0:c1].astype(float)
    return bool((np.linalg.norm(patch - rgb, axis=2) < tol).any())


def _samples(xy, step_px=3.0):
    out = []
    for (x0, y0), (x1, y1) in zip(xy[:-1], xy[1:]):
        n = max(int(math.hypot(x1 - x0, y1 - y0) / step_px), 1)
        out += [(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n) for k in range(n)]
    return out


def _to_screen(view, east, north):
    cx, cy = view["center"]
    s = view["scale"]
    return [(view["x"] + view["width"] / 2 + (e - cx) * s, view["y"] + view["height"] / 2 + (n - cy) * s)
            for e, n in zip(east, north)]


def _run(args, timeout=60):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable] + args, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def walk_file(tmp_path_factory):
    w = simulate_walk(WAYPOINTS, seed=SEED, rate_hz=50.0, still_start_s=1.5, still_end_s=1.5)
    path = tmp_path_factory.mktemp("walk") / "sim-walk.csv"
    write_recording(str(path), w.recording)
    return w, path


def test_app_replays_to_the_end_and_the_screenshot_shows_the_track(walk_file, tmp_path):
    """... with the settings file of an older app version (Weinberg C = 0.47, the simulated walker's): the
    app migrates it to a profile and its pipeline uses the profile's stride model and height."""
    w, path = walk_file
    shot, report = tmp_path / "shot.png", tmp_path / "report.json"
    data = tmp_path / "data"
    data.mkdir()
    (data / "settings.json").write_text(json.dumps({"height_m": 1.8, "stride_c": 0.47, "rate_hz": 100.0}))
    r = _run(["-m", "app", str(path), "--speed", "max", "--headless", "--exit-at-end", "--size",
              f"{SIZE[0]}x{SIZE[1]}", "--screenshot", str(shot), "--report", str(report),
              "--data-dir", str(data), "--out", str(tmp_path / "out")])
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads(report.read_text())
    scale = 0.47 / load_stride_model("default").coefficient.c
    batch = Pipeline(height_m=1.8, stride_model=with_scale(load_stride_model("default"), scale)).run(w.recording)
    # the migrated profile was saved on exit; the old keys are gone from the settings
    assert UserProfile.load(data / "profile.json") == UserProfile(height_m=1.8, c_scale=scale)
    assert "stride_c" not in json.loads((data / "settings.json").read_text())
    assert rep["finished"] and rep["errors"] == 0 and rep["mode"] == "replay"
    assert rep["events"] == sum(len(s) for s in w.recording.streams.values())
    assert rep["summary"]["steps"] == len(batch.steps) == int(rep["status"]["steps"])
    assert rep["status"]["distance"] == f"{sum(s.length_m for s in batch.steps):.1f} m"
    np.testing.assert_allclose(rep["track_east"][1:], batch.track.east_m, atol=1e-9)

    img = read_png(shot)
    assert img.shape[:2] == (SIZE[1], SIZE[0])
    view = rep["view"]
    assert not view["follow"]  # fitted at the end
    # 1. the drawn track: every few pixels along the batch track there is track colour
    east = [0.0] + batch.track.east_m.tolist()
    north = [0.0] + batch.track.north_m.tolist()
    xy = _to_screen(view, east, north)
    start, end = xy[0], xy[-1]
    pts = [p for p in _samples(xy) if math.dist(p, start) > 12 and math.dist(p, end) > 26]
    hits = [_near_color(img, x, y, TRACK_RGB, radius=2) for x, y in pts]
    assert len(pts) > 100 and np.mean(hits) > 0.97, np.mean(hits)
    # 2. ... which is the walked path: the true path is within 2 m of drawn track almost everywhere
    truth = w.truth
    t_grid = np.linspace(truth.walk_start_t_ns, truth.walk_end_t_ns, 400).astype(np.int64)
    p = truth.position_at(t_grid)
    txy = _to_screen(view, p[:, 0], p[:, 1])
    tol = max(4, int(round(2.0 * view["scale"])))
    near = [_near_color(img, x, y, TRACK_RGB, radius=tol) for x, y in txy
            if math.dist((x, y), start) > 12 and math.dist((x, y), end) > 26]
    assert np.mean(near) > 0.9, np.mean(near)
    # 3. markers: green start, orange current position
    assert _near_color(img, *start, START_RGB, radius=4)
    assert _near_color(img, *end, POSITION_RGB, radius=4)
    # 4. away from the track there is no track colour (the check above can fail)
    rng = np.random.default_rng(0)
    seg = np.array(xy)
    far = []
    while len(far) < 300:
        x = rng.uniform(view["x"] + 5, view["x"] + view["width"] - 5)
        y = rng.uniform(view["y"] + 40, view["y"] + view["height"] - 45)
        if np.min(np.hypot(seg[:, 0] - x, seg[:, 1] - y)) > 30 and min(
                _dist_to_segments((x, y), xy)) > 20:
            far.append((x, y))
    assert not any(_near_color(img, x, y, TRACK_RGB, radius=1) for x, y in far)


def _dist_to_segments(p, xy):
    px, py = p
    for (x0, y0), (x1, y1) in zip(xy[:-1], xy[1:]):
        dx, dy = x1 - x0, y1 - y0
        L = dx * dx + dy * dy
        t = 0.0 if L == 0 else max(0.0, min(1.0, ((px - x0) * dx + (py - y0) * dy) / L))
        yield math.hypot(px - x0 - t * dx, py - y0 - t * dy)


LIFECYCLE = r"""
import json, sys
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.config import Config
Config.set("graphics", "width", "360"); Config.set("graphics", "height", "640")
from kivy.clock import Clock
from app.main_app import PDRApp

path, out, data, report, known = sys.argv[1:6]
app = PDRApp(recording=path, speed="10x", out_dir=out, data_dir=data)
log = {}

def maybe_pause(dt):
    ses = app.session
    if ses is None or ses.source.delivered == 0:
        return True  # not replaying yet
    log.setdefault("ticks_replaying", 0)
    log["ticks_replaying"] += 1
    if log["ticks_replaying"] < 5:
        return True
    app.save_calibration("50")
    log["calib_message_no_walk"] = app.calib_message
    app.toggle_calibration()  # calibration walk starts here
    log["calibration_range_at_start"] = ses.calibration_range_ns
    pause()
    return False

def pause():
    ses = app.session
    log["before_pause_events"] = ses.events_in
    log["pause_returned"] = app.on_pause()
    log["running_after_pause"] = ses.running
    log["delivered_at_pause"] = ses.source.delivered
    Clock.schedule_once(resume, 0.6)

def resume(dt):
    ses = app.session
    log["delivered_while_paused"] = ses.source.delivered - log["delivered_at_pause"]
    app.on_resume()
    log["running_after_resume"] = ses.running
    app.set_speed("max")
    Clock.schedule_interval(wait_end, 0.05)

def wait_end(dt):
    if not app.session.finished:
        return True
    app.toggle_calibration()  # ... and ends with the replay
    log["calibration_range"] = app.session.calibration_range_ns
    log["calib_text"] = app.calib_text
    log["calib_errors"] = []
    for bad in ("3", "abc"):
        app.save_calibration(bad)
        log["calib_errors"].append(app.calib_message)
    app.save_calibration(known)
    log["calib_message"] = app.calib_message
    log["c_text"] = app.c_text
    log["export"] = app.export()
    app.root.ids.screens.current = "health"
    app._update_ui(force=True)
    log["health"] = app.health_text
    log["report"] = app.report()
    app.new_track()  # the calibrated profile applies to the new track
    log["new_track_scale"] = app.session.pipeline.stride_model.coefficient.scale
    popup = app.show_file_chooser()
    chooser = app.chooser
    log["chooser"] = [chooser.path, list(chooser.filters), app.chooser_path_label.text, app.out_dir()]
    chooser.selection = [path]
    popup.content.children[0].children[-1].dispatch("on_release")  # the "Replay" button
    log["reopened"] = [app.mode, app.session.source.delivered, app.raw_path == path]
    with open(report, "w") as f:
        json.dump(log, f, default=float)
    app.stop()
    return False

Clock.schedule_interval(maybe_pause, 0.05)
app.run()
"""


def test_app_lifecycle_pause_resume_and_export(walk_file, tmp_path):
    w, path = walk_file
    report = tmp_path / "lifecycle.json"
    known = 55.0
    r = _run(["-c", LIFECYCLE, str(path), str(tmp_path / "out"), str(tmp_path / "data"), str(report), str(known)])
    assert r.returncode == 0, r.stderr[-3000:]
    log = json.loads(report.read_text())
    assert log["pause_returned"] is True and log["running_after_pause"] is False
    assert 0 < log["delivered_at_pause"] < 0.5 * sum(len(s) for s in w.recording.streams.values())
    assert log["delivered_while_paused"] == 0
    assert log["running_after_resume"] is True
    rep = log["report"]
    assert rep["finished"] and rep["paused"] == 1 and rep["resumed"] == 1
    # pausing lost nothing: same track as the batch run (of the app's pipeline: the settings' stride model)
    batch_steps = Pipeline(**Settings().pipeline_kwargs()).run(w.recording).steps
    assert rep["summary"]["steps"] == len(batch_steps)
    exp = log["export"]
    assert not exp["errors"] and {"geojson", "gpx", "csv", "raw"} <= set(exp)
    assert Path(exp["raw"]).read_bytes() == path.read_bytes()
    assert "acc" in log["health"] and "magnetometer trusted: yes" in log["health"]
    saved = json.loads((tmp_path / "data" / "settings.json").read_text())
    assert saved["replay_speed"] == "max"
    # calibration walk from the pause to the end of the replay, then saved with the known distance
    assert "do a calibration walk first" in log["calib_message_no_walk"]
    t0, t1 = log["calibration_range"]
    assert t0 == log["calibration_range_at_start"][0] and t1 == w.recording.t1_ns
    walked = sum(s.length_m for s in batch_steps if t0 <= s.t_ns)
    assert log["calib_text"] == f"measured {walked:.1f} m"
    assert "too short" in log["calib_errors"][0] and "must be a number of metres" in log["calib_errors"][1]
    profile = UserProfile.load(tmp_path / "data" / "profile.json")
    assert profile.c_scale == pytest.approx(known / walked), log["calib_message"]
    assert profile.calibrations[-1]["known_distance_m"] == known
    assert log["calib_message"].startswith(f"saved: step length x {known / walked:.3f}")
    assert log["c_text"] == f"step length x {known / walked:.3f} (1 walk)"
    assert log["new_track_scale"] == pytest.approx(known / walked)
    # the file chooser opens in the recordings folder, says where it is, lists what core.importers reads;
    # "Replay" starts the chosen file
    assert log["chooser"][0] == log["chooser"][3] == log["chooser"][2] == str(tmp_path / "out")
    assert {"*.csv", "*.txt", "*.gz", "*.zip"} <= set(log["chooser"][1])
    assert log["reopened"] == ["replay", 0, True]


def test_track_view_pan_zoom_follow():
    from kivy.base import EventLoop
    from kivy.core.window import Window
    from kivy.tests.common import UnitTestTouch

    from app.track_view import TrackView

    EventLoop.ensure_window()
    tv = TrackView(size=(400, 400), pos=(0, 0), size_hint=(None, None))
    Window.add_widget(tv)
    try:
        tv.set_track([0, 10, 10], [0, 0, 5])
        tv._redraw()
        assert tv.follow and tv.vp.center == (10, 5)  # follow keeps the current position centred
        scale = tv.vp.scale
        # scroll wheel zooms (about the centre while following)
        t = UnitTestTouch(200, 200)
        t.profile.append("button")
        t.button = "scrolldown"
        t.touch_down()
        assert tv.vp.scale == pytest.approx(scale * 1.25) and tv.follow
        # a drag pans and turns follow off
        world = tv.vp.to_world(100, 100)
        t = UnitTestTouch(100, 100)
        t.touch_down()
        t.touch_move(150, 80)
        t.touch_up()
        assert not tv.follow and tv.vp.to_world(150, 80) == pytest.approx(world)
        # pinch: two fingers moving apart zoom in about their midpoint
        s0 = tv.vp.scale
        a, b = UnitTestTouch(150, 200), UnitTestTouch(250, 200)
        a.touch_down()
        b.touch_down()
        b.touch_move(350, 200)
        assert tv.vp.scale == pytest.approx(s0 * 2.0)
        a.touch_up()
        b.touch_up()
        # fit shows the whole track; the line has one point per track point
        tv.fit()
        tv._redraw()
        pts = np.array(tv.to_screen_points(tv._line.points_m())).reshape(-1, 2)
        assert len(pts) == 3 and (pts >= 0).all() and (pts <= 400).all()
        m, px = tv.vp.scale_bar(120)
        assert tv._bar_label.text in (f"{m:g} m", f"{m * 100:g} cm")
    finally:
        Window.remove_widget(tv)


LIVE = r"""
import json, sys, threading, time
sys.path.insert(0, sys.argv[4])  # tests/: the fake jnius lives in test_app_android_source
from test_app_android_source import FakeSensorManager, hardware_stream, make_fake_jnius
sm = FakeSensorManager()
# Android 16: edge-to-edge (a 63 px status bar under an 80 px cutout, a 126 px navigation bar), predictive back
jn = make_fake_jnius(sm, sdk=36, bars=(0, 63, 0, 126), cutout=(0, 80, 0, 0))
sys.modules["jnius"] = jn  # what "import jnius" finds on the "phone"
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.config import Config
Config.set("graphics", "width", "360"); Config.set("graphics", "height", "640")
from kivy.clock import Clock
from kivy.core.window import Window
from app.main_app import PDRApp

out, data, report = sys.argv[1:4]
app = PDRApp(out_dir=out, data_dir=data, jnius=jn)
events = hardware_stream(seed=9, seconds=8.0)
half = len(events) // 2
log = {"delivered": []}

def deliver(chunk):
    for i, (type_, t, v) in enumerate(chunk):
        if sm.deliver(type_, t, v):
            log["delivered"].append([t, type_])
        if i % 30 == 0:
            time.sleep(0.004)

def rects(widget):
    # every widget's rectangle in window coordinates (the track view's own labels too)
    for w in widget.walk(restrict=True):
        if w is widget or w.width <= 0 or w.height <= 0 or w.opacity == 0:
            continue
        x0, y0 = w.to_window(w.x, w.y)
        yield type(w).__name__, x0, y0, x0 + w.width, y0 + w.height

def check_layout(dt):
    if app.frames < 3:
        Window.canvas.ask_update()
        return True  # laid out and drawn first
    W, H = Window.size
    left, top, right, bottom = app.insets
    bars = [(0, H - top, W, H), (0, 0, W, bottom)]
    log["insets"] = list(app.insets)
    log["under_bars"] = [r for r in rects(app.root) for bx0, by0, bx1, by1 in bars
                         if r[1] < bx1 and r[3] > bx0 and r[2] < by1 and r[4] > by0]
    log["n_widgets"] = len(list(rects(app.root)))
    # back: Settings -> Track through the OnBackInvokedCallback, never on_pause
    app.root.ids.screens.current = "settings"
    log["back_registered_on_settings"] = app.report()["back_registered"]
    log["system_back_handled"] = jn.back.back()
    Clock.schedule_once(after_back, 0)
    return False

def after_back(dt):
    log["screen_after_back"] = app.root.ids.screens.current
    log["back_registered_on_track"] = len(jn.back.callbacks)
    log["paused_by_back"] = app.paused_count
    Clock.schedule_once(start, 0)

def start(dt):
    app.go_live()
    log["started"] = app.mode == "live"
    log["mode"] = app.mode
    log["service"] = app.report()["service"]
    log["record_path"] = app.session.record_path
    th = threading.Thread(target=deliver, args=(events[:half],))
    th.start()
    Clock.schedule_interval(lambda dt: pause(th), 0.05)

def pause(th):
    if th.is_alive():
        return True
    Clock.schedule_once(do_pause, 0.2)  # let the service drain the queue first
    return False

def do_pause(dt):
    app.on_pause()  # the app leaves the screen: the service keeps tracking
    log["registered_while_paused"] = len(sm.registered)
    deliver(events[half:half + 50])  # recorded: the service listens in the background
    app.on_resume()
    log["registered_after_resume"] = len(sm.registered)
    th = threading.Thread(target=deliver, args=(events[half + 50:],))
    th.start()
    Clock.schedule_interval(lambda dt: finish(th), 0.05)

def finish(th):
    if th.is_alive():
        return True
    Clock.schedule_once(close_ui, 0.3)
    return False

def close_ui(dt):
    # the UI goes away (the activity is destroyed) and comes back: the new UI attaches to the service
    old = app.session
    log["track_before_close"] = len(old.track_east)
    old.detach()
    app.session = None
    log["attached"] = app.attach_service()
    app.session.host = old.host  # the desktop's in-process service, stopped with the app
    svc = old.host.service.session
    log["reopened_track_is_the_services"] = (app.session.track_east == svc.track_east
                                             and app.session.track_north == svc.track_north)
    log["reopened_view_points"] = len(app.track_view.east)
    log["service_steps"] = len(svc.steps)
    Clock.schedule_once(do_finish, 0.2)

def do_finish(dt):
    app.toggle_recording()  # stop recording: the file is closed
    log["recording_label_after_stop"] = app.recording_label
    log["events_in"] = app.session.events_in
    log["health"] = app.session.health_text()
    log["warning"] = app.warning
    host = app.session.host
    app.stop_live()  # the Stop button: the service ends
    log["after_stop"] = [app.mode, host.alive, host.service.stopped, app.message]
    with open(report, "w") as f:
        json.dump(log, f)
    app.stop()
    return False

Clock.schedule_interval(check_layout, 0.05)
app.run()
"""


def test_live_mode_records_every_event_through_the_service(tmp_path):
    """Live tracking through the (in-process) service with the fake jnius of an Android 16 phone: no widget
    under the status or navigation bar, back from Settings to the track through the OnBackInvokedCallback
    (no on_pause), the app leaving the screen does not stop the sensors, the UI closed and reopened gets the
    whole track, and the recording has every delivered event."""
    from core.recording import read_recording

    report = tmp_path / "live.json"
    r = _run(["-c", LIVE, str(tmp_path / "out"), str(tmp_path / "data"), str(report), str(ROOT / "tests")])
    assert r.returncode == 0, r.stderr[-3000:]
    log = json.loads(report.read_text())
    assert log["insets"] == [0, 80, 0, 126]  # the cutout is deeper than the status bar
    assert log["n_widgets"] > 20 and log["under_bars"] == []
    assert log["back_registered_on_settings"] and log["system_back_handled"]
    assert log["screen_after_back"] == "track" and log["back_registered_on_track"] == 0
    assert log["paused_by_back"] == 0
    assert log["started"] and log["mode"] == "live" and log["service"] and log["warning"] == ""
    assert log["registered_while_paused"] == 3 and log["registered_after_resume"] == 3
    assert log["attached"] and log["reopened_track_is_the_services"]
    assert log["reopened_view_points"] == log["service_steps"] + 1
    assert log["recording_label_after_stop"] == ""
    delivered = log["delivered"]
    assert log["events_in"] == len(delivered) > 1500
    rec = read_recording(log["record_path"], warn=False)
    assert rec.device["model"] == "Phone 1" and rec.device["sampling_period_us"] == 10000
    assert rec.metadata["stride_model"] == "default" and rec.metadata["c_scale"] == 1.0
    assert "unix_offset_ns" in rec.metadata
    names = {1: "acc", 2: "mag", 4: "gyro"}
    for type_, name in names.items():
        want = sorted(t for t, ty in delivered if ty == type_)
        assert rec.streams[name].t_ns.tolist() == want  # every event, exact timestamps
    assert "acc" in log["health"] and "gyro" in log["health"]
    mode, alive, stopped, message = log["after_stop"]
    assert mode == "idle" and not alive and stopped and message.startswith("tracking stopped: ")


@pytest.fixture(scope="module")
def gps_file(tmp_path_factory):
    """The GPS walk of tests/test_app_logic.py (outdoor, 2 min, a 25 s GPS gap, multipath) as a file."""
    w = gps_walk_run()[0]
    path = tmp_path_factory.mktemp("gps") / "gps-walk.csv"
    write_recording(str(path), w.recording)
    return w, path


def test_track_view_draws_the_gps_layer():
    """Instructions, not pixels: the fix squares sit on the fixes, the accuracy circles have radius hacc (the
    last MAX_ACCURACY_CIRCLES only), the violet lines are the "dr" stretches, the ellipse is the 2-sigma one of
    the last step's covariance, in the colours of the legend.  More fixes add no top-level instructions, a
    pan moves the squares by their Translate without rebuilding them, a new fix rebuilds only its chunk."""
    from kivy.base import EventLoop
    from kivy.core.window import Window
    from kivy.metrics import dp

    from app import track_view as T
    from app.overlay import runs

    ses = gps_walk_run()[2]  # the GPS walk replayed by a session with Chen's filter (shared with test_app_logic)
    g = ses.gps_overlay()
    EventLoop.ensure_window()
    tv = T.TrackView(size=(480, 640), pos=(0, 0), size_hint=(None, None))
    Window.add_widget(tv)
    try:
        tv.set_track(ses.track_east, ses.track_north)
        tv.set_gps(g)
        tv.fit()
        tv._redraw()
        vp = tv.vp
        n_instructions = len(tv.canvas.children)
        # the raw PDR track thin and faint under the fused one, which has every step
        assert tv.shows_fused and tv.current_position == (g.fused_east[-1], g.fused_north[-1])
        assert tv._line.width * vp.scale == pytest.approx(dp(1))  # the widths are in metres
        assert tv._line_color.a == pytest.approx(T.RAW_UNDER_FUSED_ALPHA)
        np.testing.assert_allclose(tv.to_screen_points(tv._fused.points_m()), vp.points(g.fused_east, g.fused_north),
                                   atol=0.01)
        assert tv._fused_color.rgba == pytest.approx(list(T.FUSED_COLOR))
        # fixes: one square per fix, centred on it, in its colour; circles of the last 60, radius hacc
        ok = np.array(g.fix_accepted)
        fe, fn, hacc = (np.array(v) for v in (g.fix_east, g.fix_north, g.fix_hacc))
        last = np.arange(len(ok)) >= len(ok) - T.MAX_ACCURACY_CIRCLES
        assert 1 <= (~ok).sum() and ok.sum() == g.n_used and len(ok) > T.MAX_ACCURACY_CIRCLES
        for key, mask, rgba in (("accepted", ok, T.FIX_COLOR), ("rejected", ~ok, T.REJECTED_COLOR)):
            x, y = vp.to_screen_arrays(fe[mask], fn[mask])
            sq = squares(tv, key)
            assert len(sq) == mask.sum() and sum(len(m.indices) for m in tv._dots[key]) == 6 * mask.sum()
            np.testing.assert_allclose(sq.mean(axis=1), np.c_[x, y], atol=0.01)
            assert tv._dot_colors[key].rgba == pytest.approx(list(rgba))
            m = mask & last
            ring = np.array(tv._circles[key].vertices).reshape(m.sum(), -1, 4)[:, :, :2]
            centre = ring.mean(axis=1)
            x, y = vp.to_screen_arrays(fe[m], fn[m])
            np.testing.assert_allclose(centre, np.c_[x, y], atol=0.01)
            radius = np.hypot(*(ring - centre[:, None, :]).transpose(2, 0, 1))
            np.testing.assert_allclose(radius, np.repeat((hacc[m] * vp.scale)[:, None], ring.shape[1], 1), rtol=1e-4)
            assert tv._circle_colors[key].rgba == pytest.approx([*rgba[:3], T.CIRCLE_ALPHA])
        # the dead-reckoning stretches of the fused track, each its own violet line
        stretches = runs(np.array(g.fused_source) == "dr")
        drawn = [ln for ln in tv._fused_dr_lines if ln.points_m()]
        assert len(drawn) == len(stretches) >= 2  # before the first fix, the gap (and the multipath)
        for line, (i0, i1) in zip(drawn, stretches):
            np.testing.assert_allclose(tv.to_screen_points(line.points_m()),
                                       vp.points(g.fused_east[i0:i1 + 1], g.fused_north[i0:i1 + 1]), atol=0.01)
        assert tv._fused_dr_color.rgba == pytest.approx(list(T.FUSED_DR_COLOR))
        # the ellipse: its outline, back in metres about the position, is p^T C^-1 p = 2^2
        px, py = vp.to_screen(g.fused_east[-1], g.fused_north[-1])
        p = (np.array(tv._ellipse.points).reshape(-1, 2) - (px, py)) / vp.scale
        ve, c, vn = g.cov_en_m2
        q = np.einsum("ij,jk,ik->i", p, np.linalg.inv([[ve, c], [c, vn]]), p)
        np.testing.assert_allclose(q, T.ELLIPSE_SIGMA ** 2, rtol=1e-3)
        sigma = ses.gnss.status()["sigma_m"]  # the fusion's own: sqrt of the largest eigenvalue
        assert np.max(np.hypot(p[:, 0], p[:, 1])) == pytest.approx(2.0 * sigma, rel=1e-3)
        assert len(tv._ellipse_fill.indices) == len(p) + 2 and tv._ellipse_color.rgba == pytest.approx(
            list(T.POSITION_COLOR))
        assert f"GPS: {g.n_fixes} fixes, {g.n_used} used · ±{2.0 * sigma:.1f} m (2σ)" in tv._legend.text
        assert "2σ ellipse" in tv._legend.text
        # twelve times the fixes (three chunks): the same top-level instructions, still 60 circles
        def more(k, extra=0):
            return dataclasses.replace(g, fix_east=g.fix_east * k + [0.0] * extra,
                                       fix_north=g.fix_north * k + [0.0] * extra,
                                       fix_hacc=g.fix_hacc * k + [3.0] * extra,
                                       fix_accepted=g.fix_accepted * k + [True] * extra)
        tv.set_gps(more(12))
        tv._redraw()
        assert len(tv.canvas.children) == n_instructions
        assert len(ok) * 12 > 2 * T.FIX_CHUNK and len(tv._dots["accepted"]) == 3
        n_circles = sum(len(tv._circles[k].vertices) for k in tv._circles) // (4 * 32)
        assert n_circles == T.MAX_ACCURACY_CIRCLES
        assert sum(len(squares(tv, k)) for k in tv._dots) == 12 * len(ok)
        before = [m.vertices for m in tv._dots["accepted"]]
        tv.set_gps(more(12, extra=1))  # one fix more: only the last chunk is rebuilt
        tv._redraw()
        after = [m.vertices for m in tv._dots["accepted"]]
        assert after[:2] == before[:2] and len(after[2]) == len(before[2]) + 16
        shift = tuple(tv._fix_shift.xy)
        tv.vp.pan(37.0, -21.0)  # a pan: no square is rebuilt, the Translate moves them
        tv._view_changed()
        tv._redraw()
        assert [m.vertices for m in tv._dots["accepted"]] == after
        assert tuple(tv._fix_shift.xy) == pytest.approx((shift[0] + 37.0, shift[1] - 21.0))
        x, y = tv.vp.to_screen_arrays(fe[ok], fn[ok])
        np.testing.assert_allclose(squares(tv, "accepted")[:ok.sum()].mean(axis=1), np.c_[x, y], atol=0.01)
        # GPS off: the PDR track as before, nothing of the GPS layer
        tv.set_gps(None)
        tv._redraw()
        assert tv._legend.text == "GPS off" and tv._fused.points_m() == [] and tv._ellipse.points == []
        assert all(not len(squares(tv, k)) and not tv._circles[k].vertices for k in tv._dots)
        assert not any(ln.points_m() for ln in tv._fused_dr_lines)
        assert tv._line.width * tv.vp.scale == pytest.approx(tv.line_width) and tv._line_color.a == 1.0
    finally:
        Window.remove_widget(tv)


def squares(tv, key):
    """The fix squares of colour ``key`` as drawn: (n, 4 corners, xy) in screen pixels, the Translate applied."""
    v = np.array([x for m in tv._dots[key] for x in m.vertices]).reshape(-1, 4, 4)[:, :, :2]
    return v + np.array(tv._fix_shift.xy)


def test_app_replay_with_gps_shows_fused_track_and_fixes(gps_file, tmp_path):
    """The app (Use GPS on, Chen's filter: the pixel checks below were written for its track) replays the GPS
    walk: its fused track is the batch fusion's, and the screenshot shows it gold where fused and violet
    through the gap, and the fixes off the track as light squares (rejected ones red)."""
    w, path = gps_file
    shot, report = tmp_path / "shot.png", tmp_path / "report.json"
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "settings.json").write_text(json.dumps({"gps_fusion": "chen"}))
    r = _run(["-m", "app", str(path), "--speed", "max", "--headless", "--exit-at-end", "--size",
              f"{SIZE[0]}x{SIZE[1]}", "--screenshot", str(shot), "--report", str(report),
              "--data-dir", str(tmp_path / "data"), "--out", str(tmp_path / "out")])
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads(report.read_text())
    g = rep["gps"]
    batch = gps_walk_run()[1].fusion  # Pipeline(**Settings().pipeline_kwargs(), gnss=GpsFusion()).run(w.recording)
    assert rep["finished"] and rep["errors"] == 0 and g["anchored"] and g["shows_fused"]
    np.testing.assert_allclose(g["fused_east"][1:], [s.east_m for s in batch.steps], rtol=0, atol=1e-9)
    assert g["fused_source"] == [s.source for s in batch.steps]
    assert g["legend"].startswith(f"GPS: {batch.counters['fixes']} fixes, {batch.counters['fixes_accepted']} used")

    img = read_png(shot)
    view = rep["view"]
    xy = _to_screen(view, g["fused_east"], g["fused_north"])
    src = g["fused_source"]
    end = xy[-1]

    def along(kind):
        """Samples of the fused track's segments of ``kind``, 6 px clear of the other kind and of the end."""
        segs = [(xy[k], xy[k + 1]) for k in range(len(src)) if src[k] == kind]
        foreign = np.array([p for k in range(len(src)) if src[k] != kind for p in _samples([xy[k], xy[k + 1]])])
        pts = [p for a, b in segs for p in _samples([a, b]) if math.dist(p, end) > 30]
        return [p for p in pts if not len(foreign) or np.min(np.hypot(*(foreign - p).T)) > 6]

    for kind, rgb in (("fused", FUSED_RGB), ("dr", FUSED_DR_RGB)):
        pts = along(kind)
        hits = [_near_color(img, x, y, rgb, radius=2) for x, y in pts]
        assert len(pts) > 30 and np.mean(hits) > 0.95, (kind, len(pts), np.mean(hits))
    # fixes at least 8 px off the fused track (elsewhere the track is drawn over them): 13 accepted, 5 rejected
    # at this writing; at least one of each, so that retuning the fusion does not break the test
    track = np.array(_samples(xy, step_px=1.0))
    for accepted, rgb in ((True, FIX_RGB), (False, REJECTED_RGB)):
        fxy = _to_screen(view, *zip(*[(e, n) for e, n, a in zip(g["fix_east"], g["fix_north"], g["fix_accepted"])
                                      if a == accepted]))
        off = [p for p in fxy if np.min(np.hypot(*(track - p).T)) > 8 and math.dist(p, end) > 30]
        hits = [_near_color(img, x, y, rgb, radius=1, tol=40) for x, y in off]
        assert len(off) >= 1 and np.mean(hits) > 0.9, (accepted, len(off), np.mean(hits))
    # and the colours are not everywhere: none of the fused or fix colours far from the track and fixes
    rng = np.random.default_rng(1)
    allfix = np.array(_to_screen(view, g["fix_east"], g["fix_north"]))
    far = []
    while len(far) < 200:
        x = rng.uniform(view["x"] + 5, view["x"] + view["width"] - 5)
        y = rng.uniform(view["y"] + 40, view["y"] + view["height"] - 140)  # below the legend
        if np.min(np.hypot(*(track - (x, y)).T)) > 25 and np.min(np.hypot(*(allfix - (x, y)).T)) > 40:
            far.append((x, y))
    for rgb in (FUSED_RGB, FUSED_DR_RGB, REJECTED_RGB):
        assert not any(_near_color(img, x, y, rgb, radius=1) for x, y in far)


def test_track_view_appends_to_the_last_chunk_and_follows_by_the_transform():
    """Issue #14 item 3, as counts rather than times: a new step rebuilds one Line chunk, following the walker
    changes only the world transform, a zoom rebuilds every chunk (the widths are in metres), new lists are a
    new track; the drawn points are the track's, and the dead-reckoning stretches grown step by step are
    those of the whole track."""
    from kivy.base import EventLoop
    from kivy.core.window import Window

    from app import track_view as T
    from app.overlay import runs

    EventLoop.ensure_window()
    tv = T.TrackView(size=(400, 600), pos=(0, 0), size_hint=(None, None))
    Window.add_widget(tv)
    try:
        rng = np.random.default_rng(5)
        heading = np.cumsum(rng.normal(0, 0.2, 1233))
        east = [0.0] + np.cumsum(0.7 * np.cos(heading)).tolist()
        north = [0.0] + np.cumsum(0.7 * np.sin(heading)).tolist()
        tv.set_track(east, north)
        tv._redraw()
        chunks = -(-(len(east) - 1) // T.LINE_CHUNK)
        assert len(tv._line.lines) == tv._line.rebuilt_chunks == chunks > 3
        np.testing.assert_array_equal(np.array(tv._line.points_m()).reshape(-1, 2), np.c_[east, north])
        for k in range(300):  # the walk goes on: each step rebuilds the last chunk only (or starts a new one)
            east.append(east[-1] + 0.7)
            north.append(north[-1])
            tv.set_track(east, north)
            tv._redraw()
            assert tv._line.rebuilt_chunks == 1, k
            translate, scale = tv._world[0]
            assert tv.vp.center == (east[-1], north[-1])  # followed by moving the transform
            assert tuple(translate.xy) == pytest.approx(tv.vp.to_screen(0.0, 0.0)) and scale.x == tv.vp.scale
        chunks = -(-(len(east) - 1) // T.LINE_CHUNK)
        assert len(tv._line.lines) == chunks
        np.testing.assert_array_equal(np.array(tv._line.points_m()).reshape(-1, 2), np.c_[east, north])
        tv._line_dirty = True
        tv._redraw()
        assert tv._line.rebuilt_chunks == 0  # the same track again: nothing rebuilt
        tv.vp.zoom_at(2.0, 200, 300)
        tv._view_changed()
        tv._redraw()
        assert tv._line.rebuilt_chunks == chunks and tv._line.width * tv.vp.scale == pytest.approx(tv.line_width)
        tv.set_track(list(east), list(north))  # other lists: a new track, drawn anew
        tv._redraw()
        assert tv._line.rebuilt_chunks == chunks
        tv.set_track([0.0, 1.0], [0.0, 0.0])
        tv._redraw()
        assert [bool(ln.points) for ln in tv._line.lines] == [True] + [False] * (chunks - 1)
    finally:
        Window.remove_widget(tv)
    source = list(rng.choice(["fused", "dr"], 400, p=[0.7, 0.3]))
    tv2 = T.TrackView.__new__(T.TrackView)  # the stretch bookkeeping alone
    tv2._fused_dr_runs, tv2._dr_scanned = [], 0
    n = 0
    while n < len(source):
        n = min(n + int(rng.integers(1, 9)), len(source))
        tv2._scan_dr(source, n)
    assert tv2._fused_dr_runs == runs([s == "dr" for s in source])


def test_a_zoomed_out_track_tessellates_fewer_points_and_all_again_zoomed_in():
    """Issue #28 item 5: a pinch rebuilds every chunk; with the points closer than a pixel to the last kept
    one dropped, a walk of an hour fitted into the view hands the tessellator a small fraction of its points,
    every chunk still starts and ends on the track, and zoomed in again every point is drawn."""
    from kivy.base import EventLoop
    from kivy.core.window import Window

    from app import track_view as T

    xs = [0.0, 0.3, 0.6, 2.0, 2.1, 5.0]
    assert T.decimate(xs, [0.0] * 6, 1.0) == ([0.0, 2.0, 5.0], [0.0] * 3)
    assert T.decimate(xs, [0.0] * 6, 0.0) == (xs, [0.0] * 6)
    EventLoop.ensure_window()
    tv = T.TrackView(size=(400, 600), pos=(0, 0), size_hint=(None, None))
    Window.add_widget(tv)
    try:
        rng = np.random.default_rng(8)
        heading = np.cumsum(rng.normal(0, 0.1, 7000))  # about an hour of steps
        east = [0.0] + np.cumsum(0.7 * np.cos(heading)).tolist()
        north = [0.0] + np.cumsum(0.7 * np.sin(heading)).tolist()
        tv.set_track(east, north)
        tv._redraw()
        full = tv._line.n_points
        assert full >= len(east)  # 14 px a step at the start: nothing dropped
        tv.fit()
        tv._redraw()
        scale = tv.vp.scale
        assert scale * 0.7 < 1.0  # fitted: a step is under a pixel
        fitted = tv._line.n_points
        assert fitted < 0.2 * full, (fitted, full)
        tol = T.DECIMATE_PX / scale
        pts = np.array(tv._line.points_m()).reshape(-1, 2)
        track = np.c_[east, north]
        for line in tv._line.lines:  # each chunk's ends are track points
            p = np.array(line.points).reshape(-1, 2)
            assert np.min(np.hypot(*(track - p[0]).T)) == 0.0 and np.min(np.hypot(*(track - p[-1]).T)) == 0.0
        # every track point (every 97th checked) is within a pixel of a drawn one
        d = np.array([np.min(np.hypot(*(pts - q).T)) for q in track[::97]])
        assert d.max() <= tol + 1e-9
        tv.vp.zoom_at(1.0 / (scale / 20.0), 200, 300)  # back to 20 px/m
        tv._view_changed()
        tv._redraw()
        assert tv._line.n_points == full
    finally:
        Window.remove_widget(tv)
