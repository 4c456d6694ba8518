"""The tracking service (issue #14, item 1 and 4): the session runs in the service, the UI polls a socket.

The service's session is driven step by step from the test (an injected clock that moves one second a
call, so each step drains one chunk of the replay), the UI's side is :class:`app.service.ServiceSession`
over the real Unix socket.  Nothing here sleeps.
"""

import itertools
import json
import math
import threading

import numpy as np
import pytest

from app.health import HealthMonitor
from app.service import (InProcessService, ServiceClient, ServiceServer, ServiceSession, ServiceUnavailable,
                         TrackingService, notification_text, socket_path)
from app.settings import Settings
from app.sources import ReplaySource
from core.recording import read_recording
from desktop.simulator import simulate_walk

WAYPOINTS = ((0.0, 0.0), (25.0, 0.0), (25.0, 15.0))


@pytest.fixture(scope="module")
def walk():
    return simulate_walk(WAYPOINTS, seed=11, rate_hz=50.0, still_start_s=1.0, still_end_s=1.0)


class LiveReplay(ReplaySource):
    """A replay the service takes for live sensors (a new sampling rate restarts it)."""

    live = True


def _ticking_clock():
    return itertools.count(0.0, 1.0).__next__  # every call one second later: one chunk per step


def _service(tmp_path, recording, *, record=True, rates=None, chunk=700):
    def source_factory(rate_hz):
        if rates is not None:
            rates.append(rate_hz)
            return LiveReplay(recording, speed=math.inf, max_chunk=chunk)
        return ReplaySource(recording, speed=math.inf, max_chunk=chunk)

    config = {"data_dir": str(tmp_path / "data"), "socket": socket_path(str(tmp_path / "data")),
              "record_path": str(tmp_path / "walk.csv") if record else None, "metadata": {"app": "test"}}
    (tmp_path / "data").mkdir(exist_ok=True)
    svc = TrackingService(config, source_factory=source_factory, clock=_ticking_clock())
    svc.start()
    server = ServiceServer(svc, config["socket"])
    server.start()
    return svc, server, config


def _ui(config):
    return ServiceSession(ServiceClient(config["socket"], timeout_s=10.0), poll_interval_s=0.0)


def test_a_replayed_walk_is_recorded_by_the_service_while_the_ui_closes_and_reopens(walk, tmp_path):
    rec = walk.recording
    svc, server, config = _service(tmp_path, rec, chunk=500)
    try:
        ui = _ui(config)
        ui.poll()
        assert ui.track_east == [0.0] and ui.running and ui.recording
        for _ in range(6):
            svc.step()
        ui.poll()
        svc.step()
        ui.poll()  # incremental: what is new since the last poll
        n_first = len(ui.track_east)
        assert 1 < n_first < 60 and ui.track_east == svc.session.track_east[:n_first]
        ui.detach()  # the UI is closed; the service goes on
        while not svc.session.finished:
            svc.step()
        reopened = _ui(config)  # a new UI: it knows nothing, the first poll brings the whole track
        assert reopened.poll() == list(range(len(svc.session.track_east)))
        batch = Settings().pipeline_factory()().run(rec)
        np.testing.assert_allclose(reopened.track_east[1:], batch.track.east_m, rtol=0, atol=1e-9)
        np.testing.assert_allclose(reopened.track_north[1:], batch.track.north_m, rtol=0, atol=1e-9)
        s = reopened.summary()
        assert s["steps"] == len(batch.steps) and reopened.finished and reopened.events_in == rec_events(rec)
        assert reopened.gps_overlay() is not None and reopened.gps_overlay().n_fixes == 0  # GPS on, no fixes
        reopened.close()  # stop: the recording is closed
    finally:
        server.close()
    assert svc.stopped
    got = read_recording(config["record_path"], warn=False)
    for name in ("acc", "gyro", "mag"):
        assert got.streams[name].t_ns.tolist() == rec.streams[name].t_ns.tolist()
        np.testing.assert_array_equal(got.streams[name].values, rec.streams[name].values)
    assert got.metadata["app"] == "test"


def rec_events(rec):
    return sum(len(s) for n, s in rec.streams.items() if n in ("acc", "gyro", "mag", "gps", "pressure"))


def test_ops_through_the_socket_pause_record_new_track_and_bad_requests(walk, tmp_path):
    rates = []
    svc, server, config = _service(tmp_path, walk.recording, record=False, rates=rates)
    try:
        ui = _ui(config)
        ui.poll()
        assert not ui.recording and rates == [100.0]
        ui.pause()
        assert not ui.running
        ui.resume()
        ui.start_recording(str(tmp_path / "later.csv"), {"app": "test"})
        assert ui.recording and ui.record_path.endswith("later.csv")
        for _ in range(10):
            svc.step()
        assert ui.stop_recording() > 0 and not ui.recording
        ui.poll()
        old_track = ui.track_east
        assert len(old_track) > 1
        # "applies to the next track": the saved sampling rate restarts the sensors, the pipeline is new
        s = Settings.load(str(tmp_path / "data" / "settings.json"))
        s.rate_hz = 50.0
        s.save(str(tmp_path / "data" / "settings.json"))
        ui.new_track()
        assert rates == [100.0, 50.0] and ui.track_east == [0.0] and ui.track_east is not old_track
        assert svc.session.health.pauses == 0  # a new health monitor for the new track
        c = ServiceClient(config["socket"])
        assert c.request("fly")["ok"] is False and "unknown op" in c.request("fly")["error"]
        c._sock.sendall(b"not json\n")
        assert json.loads(c._file.readline())["error"].startswith("bad request")
        c.close()
        ui.close()
    finally:
        server.close()
    with pytest.raises(ServiceUnavailable):
        ServiceClient(config["socket"], timeout_s=1.0).request("ping")


def test_the_in_process_service_runs_its_own_loop(walk, tmp_path):
    """The desktop's service: the same loop and socket in a thread; the UI polls until the replay ends."""
    (tmp_path / "data").mkdir()
    config = {"data_dir": str(tmp_path / "data"), "socket": socket_path(str(tmp_path / "data")),
              "record_path": str(tmp_path / "w.csv")}
    host = InProcessService(config, lambda rate: ReplaySource(walk.recording, speed=math.inf, max_chunk=400),
                            interval_s=0.001)
    host.start()
    ui = ServiceSession(ServiceClient(config["socket"]), host=host, poll_interval_s=0.0)
    done = threading.Event()
    while not ui.finished:
        ui.tick()
        done.wait(0.005)
    ui.poll()
    assert ui.summary()["steps"] == len(ui.track_east) - 1 > 10
    ui.close()
    assert not host.alive and host.service.stopped
    assert len(read_recording(config["record_path"], warn=False).streams["acc"]) == len(walk.recording.streams["acc"])


def test_a_pause_is_not_a_drop_but_a_gap_while_running_is():
    h = HealthMonitor()
    t = 0
    for _ in range(300):  # 3 s at 100 Hz
        t += 10_000_000
        h.accept("acc", t)
    h.pause(t)  # e.g. a minute in the background without the service
    t += 60 * 10**9
    for _ in range(100):
        h.accept("acc", t)
        t += 10_000_000
    (row,) = h.snapshot()
    assert row.missed == 0 and row.gaps == 0
    assert "paused 1x, 60 s" in h.format()
    t += 500_000_000  # the phone stopped delivering for half a second while tracking: a real drop
    h.accept("acc", t)
    (row,) = h.snapshot()
    assert row.gaps == 1 and row.missed == 50  # 0.51 s / 10 ms - 1


def test_the_notification_line():
    class S:
        running, writer, record_error = True, object(), ""

        def summary(self):
            return {"steps": 1234, "distance_m": 987.6}

    s = S()
    assert notification_text(s) == "1234 steps · 988 m · recording"
    s.running = False
    assert notification_text(s) == "1234 steps · 988 m · paused"


def test_long_data_dirs_get_a_short_socket_path(tmp_path):
    p = socket_path("/" + "x" * 200)
    assert len(p.encode()) < 100 and p == socket_path("/" + "x" * 200)
    assert socket_path("/data/user/0/org.pdrproject.pdrtracker/files") == \
        "/data/user/0/org.pdrproject.pdrtracker/files/tracker.sock"
