"""The UI survives a tracking service that is missing or slow, and any exception in a callback (issue #28, 3).

The app runs in a subprocess (one ``App.run()`` per process).  Its session is a
:class:`app.service.ServiceSession` over a fake client with a fake clock: "missing" refuses as a socket
with no server does, "slow" answers after 5 s, which the client (2 s timeout, as on the phone) gives up
on -- the fake clock moves by the timeout, nothing waits.  Every callback the layout binds is called in
both cases, then with a session whose requests raise ``RuntimeError``; then a clock callback raises
into Kivy's event loop.  The app must show a message each time, log the exceptions, and go on rendering.
"""

import json
import os
import re
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from app.service import ServiceClient, ServiceUnavailable

ROOT = Path(__file__).resolve().parents[1]

#: every callback layout.kv binds, with arguments as the layout passes them (checked against the file)
CALLS = {"show_plan_chooser": [], "save_settings": ["170", "100", True, "default", True, "auto", "auto"],
         "toggle_calibration": [], "save_calibration": ["50"], "show_file_chooser": [], "seek_start": [],
         "toggle_play": [], "set_speed": ["max"], "toggle_recording": [], "export": [], "new_track": [],
         "stop_live": [], "go_live": []}
#: the callbacks that talk to the service when live
SERVICE_CALLS = ("toggle_calibration", "save_calibration", "toggle_play", "toggle_recording", "export", "new_track")

SCRIPT = r"""
import json, logging, sys
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.clock import Clock
from kivy.core.window import Window
from kivy.logger import Logger
from app.main_app import PDRApp
from app.service import ServiceSession, ServiceUnavailable

out, data, report = sys.argv[1:4]
calls = json.loads(sys.argv[4])
service_calls = json.loads(sys.argv[5])
records = []

class Collect(logging.Handler):
    def emit(self, record):
        records.append([record.levelname, record.getMessage(), record.exc_info is not None])

Logger.addHandler(Collect())
app = PDRApp(out_dir=out, data_dir=data)
log = {"raised": [], "messages": {}, "clock": {}, "requests": {}}
retries = []
app.start_live = lambda: log.__setitem__("start_live", log.get("start_live", 0) + 1)  # no real sensors here
app.schedule_retry = lambda fn, delay: retries.append((fn, delay))

class FakeClock:
    t = 0.0
    def __call__(self):
        return self.t

STATUS = {"summary": {"steps": 3, "distance_m": 2.0, "heading_deg": 10.0, "elapsed_s": 4.0, "east_m": 1.0,
                      "north_m": 1.0, "heading_rad": 0.2, "mag_trusted": True, "labels": [], "floor": None,
                      "floor_changes": 0},
          "running": True, "finished": False, "stopped": False, "recording": True, "record_path": "/x/pdr.csv",
          "record_error": "", "events_in": 10, "errors": 0, "last_error": "", "warning": "", "source_text": "svc",
          "live": True, "progress": 0.0, "unix_offset_ns": None, "rate_hz": 100.0, "calibrating": False,
          "calibration_range_ns": [1, 2], "calibration_distance_m": 0.0, "health": "", "message": "",
          "gps": None, "map": None}

class FakeClient:
    # what ServiceClient does: a missing socket refuses at once; an answer later than the timeout is given up
    # on after the timeout (the fake clock moves by it); RuntimeError: a bug somewhere on the way
    timeout_s = 2.0
    def __init__(self, clock):
        self.clock, self.mode, self.requests = clock, "missing", []
    def request(self, op, **kw):
        self.requests.append(op)
        if self.mode == "missing":
            raise ServiceUnavailable("tracking service: [Errno 2] No such file or directory")
        if self.mode == "slow":  # answers after 5 s
            self.clock.t += min(5.0, self.timeout_s)
            raise ServiceUnavailable("tracking service: timed out")
        if self.mode == "broken":
            raise RuntimeError("boom")
        return {"ok": True, "track_id": 0, "status": STATUS, "track": [[], []], "fused": [[], [], []],
                "fixes": [[], [], [], []], "map": [[], []], "export": {"errors": []}, "events": 5,
                "distance_m": 1.0, "scale": 1.0, "n_steps": 3, "model_distance_m": 2.0, "warnings": []}
    def close(self):
        pass

clock = FakeClock()
client = FakeClient(clock)

def live_session():
    ses = ServiceSession(client, poll_interval_s=0.0, clock=clock)
    ses.status_dict = dict(STATUS)
    app.session = None  # the previous one is not closed (its client may be the broken one)
    app._replace_session(ses, "live", None)

def call_all(mode):
    client.mode = mode
    live_session()
    for name, args in calls.items():
        if name in ("stop_live", "go_live"):
            continue
        app.message = ""
        n0, t0 = len(client.requests), clock.t
        try:
            ret = getattr(app, name)(*args)
            if hasattr(ret, "dismiss"):
                ret.dismiss()
        except BaseException as e:
            log["raised"].append([mode, name, repr(e)])
        log["messages"].setdefault(mode, {})[name] = app.message
        log["requests"].setdefault(mode, {})[name] = len(client.requests) - n0
        log["clock"].setdefault(mode, {})[name] = clock.t - t0
    for name in ("stop_live", "go_live"):  # last: they end the session
        try:
            getattr(app, name)(*calls[name])
        except BaseException as e:
            log["raised"].append([mode, name, repr(e)])
        log["messages"].setdefault(mode, {})[name] = app.message

def start(dt):
    call_all("missing")
    call_all("slow")
    # a retry: play/pause pressed while the service was missing is sent again once it answers
    client.mode = "missing"
    live_session()
    retries.clear()
    app.toggle_play()
    log["retry_message"] = app.message
    log["retries"] = [d for _, d in retries]
    client.mode = "ok"
    n0 = len(client.requests)
    retries[0][0](0)
    log["after_retry"] = client.requests[n0:]
    log["playing_after_retry"] = app.playing
    call_all("broken")
    app.session = None  # nothing else writes the warning line now
    log["frames_before_raise"] = app.frames
    Clock.schedule_once(raise_in_clock, 0)

def raise_in_clock(dt):
    raise RuntimeError("clock boom")

def finish(dt):
    if app.frames < log["frames_before_raise"] + 10:
        Window.canvas.ask_update()  # an idle window does not flip
        return True
    log["frames_after"] = app.frames
    log["warning"] = app.warning
    log["records"] = records
    log["handler_count"] = app.exception_handler.count
    with open(report, "w") as f:
        json.dump(log, f)
    app.stop()
    return False

def after_start(dt):
    try:
        start(dt)
    except BaseException:  # the harness's own error: in the report, not hidden by the app's handler
        import traceback
        log["harness_error"] = traceback.format_exc()
        with open(report, "w") as f:
            json.dump(log, f)
        app.stop()
        return
    Clock.schedule_interval(finish, 0)

Clock.schedule_once(after_start, 0)
app.run()
"""


def test_layout_binds_exactly_the_callbacks_tested():
    kv = (ROOT / "app" / "layout.kv").read_text()
    assert set(re.findall(r"\bapp\.(\w+)\(", kv)) == set(CALLS)


@pytest.fixture(scope="module")
def robust_log(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("robust")
    report = tmp / "log.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp / "out"), str(tmp / "data"), str(report),
                        json.dumps(CALLS), json.dumps(SERVICE_CALLS)], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    log = json.loads(report.read_text())
    assert "harness_error" not in log, log["harness_error"]
    return log


@pytest.mark.parametrize("mode", ["missing", "slow"])
def test_every_callback_survives_a_missing_or_slow_service(robust_log, mode):
    log = robust_log
    assert log["raised"] == []  # nothing reached Kivy: the app stayed up
    for name in SERVICE_CALLS:
        msg = log["messages"][mode][name]
        assert "tracking service is not answering" in msg, (name, msg)
        assert log["requests"][mode][name] >= 1
        if mode == "slow":  # the client gave up after its timeout (fake clock), not after the 5 s answer
            assert "timed out" in msg and log["clock"][mode][name] == pytest.approx(2.0 * log["requests"][mode][name])
    assert "tracking stopped" in log["messages"][mode]["stop_live"]


def test_play_pause_is_tried_again_once_the_service_answers(robust_log):
    log = robust_log
    assert "trying again in 1.5 s" in log["retry_message"] and log["retries"] == [1.5]
    assert log["after_retry"] == ["pause"]  # the wanted state (running -> paused), sent again


def test_an_exception_in_any_callback_is_logged_and_the_app_keeps_running(robust_log):
    log = robust_log
    failed = [r for r in log["records"] if r[0] == "ERROR" and " failed" in r[1]]
    for name in SERVICE_CALLS:
        assert "failed: RuntimeError: boom (logged; the app goes on)" in log["messages"]["broken"][name], name
        assert any(f"PDR: {name} failed" in r[1] for r in failed) or name == "toggle_play"
    assert all(r[2] for r in failed)  # with the traceback
    # and an exception raised into Kivy's loop (a clock callback): logged, shown, the app renders on
    assert log["handler_count"] == 1 and "internal error" in log["warning"] and "clock boom" in log["warning"]
    assert any("uncaught RuntimeError: clock boom" in r[1] and r[2] for r in log["records"])
    assert log["frames_after"] >= log["frames_before_raise"] + 10


def test_the_client_gives_up_on_a_service_that_does_not_answer(tmp_path):
    """The real client: a socket that accepts and never answers is a ServiceUnavailable after the timeout."""
    path = str(tmp_path / "s.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen(1)
    conns = []
    th = threading.Thread(target=lambda: conns.append(srv.accept()))
    th.start()
    try:
        with pytest.raises(ServiceUnavailable, match="timed out"):
            ServiceClient(path, timeout_s=0.05).request("pause")
        with pytest.raises(ServiceUnavailable):
            ServiceClient(str(tmp_path / "none.sock")).request("pause")
    finally:
        th.join(5)
        for c, _ in conns:
            c.close()
        srv.close()
