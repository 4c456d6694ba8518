"""Bad input in the app (issue #12, class 7): the app's replay agrees with ``pdr replay`` (the same files
rejected with the same message, the same steps and degraded-mode labels for the ones accepted), an
unreadable file with ``--headless --exit-at-end`` exits non-zero with the error in the report, and a
settings folder that cannot be created does not stop the app."""

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.session import Session, load_any_recording
from app.sources import ReplaySource
from core.pdr.pipeline import Pipeline
from core.recording import write_recording
from desktop import cli
from desktop.simulator import simulate_walk

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def walk():
    return simulate_walk(((0.0, 0.0), (20.0, 0.0), (20.0, 10.0)), seed=4, rate_hz=50.0).recording


def with_values(rec, name, fn):
    s = rec.streams[name]
    v = np.array(s.values, dtype=float)
    fn(v)
    streams = dict(rec.streams)
    streams[name] = dataclasses.replace(s, values=v)
    return dataclasses.replace(rec, streams=streams)


def bad_files(walk, d):
    def nan_acc(v):
        v[400, 0] = np.nan
        v[700, 2] = np.inf

    def nan_gyro(v):
        v[300:310, 2] = np.nan

    def deg_s(v):
        v *= 180.0 / math.pi * 40  # a gyro far beyond any phone's range in rad/s

    files = {}
    for key, name, fn in (("nan_acc", "acc", nan_acc), ("nan_gyro", "gyro", nan_gyro), ("gyro_deg_s", "gyro", deg_s)):
        files[key] = d / f"{key}.csv"
        write_recording(str(files[key]), with_values(walk, name, fn))
    files["header_only"] = d / "header_only.csv"
    files["header_only"].write_text("# pdr-recording 1\n# " + json.dumps(
        {"format": "pdr-recording", "version": 1, "streams": {"acc": {"columns": ["x", "y", "z"]}}}) + "\n")
    files["garbage"] = d / "garbage.txt"
    files["garbage"].write_bytes(b"\x00\x01hello\xff\n" * 10)
    return files


def app_replay(path):
    """The app's replay path (PDRApp.open_recording without the window): read, then stream."""
    rec = load_any_recording(str(path))
    ses = Session(ReplaySource(rec, speed=math.inf), pipeline_factory=Pipeline)
    ses.start()
    while not ses.finished:
        ses.tick(budget_s=60.0)
    return ses


def test_app_replay_and_pdr_replay_agree_on_bad_files(walk, tmp_path, capsys):
    outcomes = {}
    for key, path in bad_files(walk, tmp_path).items():
        capsys.readouterr()
        code = cli.main(["replay", str(path), "--json"])
        out, err = capsys.readouterr()
        try:
            ses = app_replay(path)
        except Exception as e:  # noqa: BLE001 - what PDRApp.open_recording catches and shows
            assert code == 2, (key, e)
            assert f"pdr: error: {e}" in err  # the same message, naming the file
            assert str(path) in str(e)
            outcomes[key] = "rejected"
            continue
        assert code == 0, (key, err)
        batch = json.loads(out)
        s = ses.summary()
        assert ses.errors == 0
        assert s["steps"] == batch["n_steps"] > 0
        # streaming == batch with the same pipeline (the CLI's own height/stride defaults differ from Pipeline()'s)
        same = Pipeline().run(load_any_recording(str(path)))
        np.testing.assert_allclose(ses.track_east[1:], same.track.east_m, atol=1e-9)
        np.testing.assert_allclose(ses.track_north[1:], same.track.north_m, atol=1e-9)
        assert list(s["labels"]) == list(batch["labels"])  # the degraded modes the app shows
        outcomes[key] = "accepted"
    assert outcomes["nan_acc"] == "accepted" and outcomes["nan_gyro"] == "accepted"
    assert outcomes["header_only"] == outcomes["garbage"] == outcomes["gyro_deg_s"] == "rejected"


def _run(args, timeout=90):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "app"] + args, cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_headless_exit_at_end_with_an_unreadable_file_exits_2_with_the_error(tmp_path):
    bad = tmp_path / "cut.csv"
    bad.write_text("# pdr-recording 1\n# {\"streams\": \n")
    report = tmp_path / "report.json"
    r = _run([str(bad), "--headless", "--exit-at-end", "--size", "320x480", "--report", str(report),
              "--data-dir", str(tmp_path / "data"), "--out", str(tmp_path / "out")])
    assert r.returncode == 2, r.stderr[-2000:]
    rep = json.loads(report.read_text())
    assert rep["exit_code"] == 2 and "cut.csv" in rep["error"] and "header" in rep["error"]
    assert rep["error"] in r.stderr and "session" not in rep or rep.get("events") is None


def test_a_settings_folder_that_cannot_be_created_does_not_stop_the_app(walk, tmp_path):
    path = tmp_path / "walk.csv"
    write_recording(str(path), walk)
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the settings folder's parent should be")
    report = tmp_path / "report.json"
    r = _run([str(path), "--speed", "max", "--headless", "--exit-at-end", "--size", "320x480", "--report",
              str(report), "--data-dir", str(blocker / "settings"), "--out", str(tmp_path / "out")])
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads(report.read_text())
    assert rep["finished"] and rep["summary"]["steps"] == len(Pipeline().run(walk).steps)
    assert rep["settings_problem"].startswith(f"settings folder {blocker / 'settings'} cannot be created")
    assert rep["settings_problem"].endswith("settings are kept for this run only")


FULL_DISK = r"""
import errno, json, sys, threading, time
sys.path.insert(0, sys.argv[4])  # tests/: the fake jnius lives in test_app_android_source
from test_app_android_source import FakeSensorManager, hardware_stream, make_fake_jnius
sm = FakeSensorManager()
sys.modules["jnius"] = make_fake_jnius(sm)
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.clock import Clock
import app.recorder
from app.main_app import PDRApp

real_write, writes = app.recorder.AppendFile.write, []

def write(self, data):  # the storage fills up after the first write, once 8 kB are on it (a byte count, not a
    # number of writes: how many events the writer thread batches per write depends on the machine's load)
    if writes and sum(writes) + len(data) > 8000:
        raise OSError(errno.ENOSPC, "No space left on device")
    writes.append(len(data))
    real_write(self, data)

app.recorder.AppendFile.write = write
out, data, report = sys.argv[1:4]
a = PDRApp(out_dir=out, data_dir=data)
log = {}

def deliver():
    for i, (type_, t, v) in enumerate(hardware_stream(seed=9, seconds=4.0)):
        sm.deliver(type_, t, v)
        if i % 30 == 0:
            time.sleep(0.03)  # about a second of delivery: several ticks, several writes

def start(dt):
    log["started"] = a.start_live()
    log["record_path"] = a.session.record_path
    th = threading.Thread(target=deliver)
    th.start()
    Clock.schedule_interval(lambda dt: finish(th), 0.05)

def finish(th):
    if th.is_alive():
        return True
    Clock.schedule_once(done, 0.3)
    return False

def done(dt):
    ses = a.session
    log.update(warning=a.warning, label=a.recording_label, record_error=ses.record_error, writer=not ses.recording,
               events_in=ses.events_in, writes=len(writes), running=ses.running)
    with open(report, "w") as f:
        json.dump(log, f)
    a.stop()

Clock.schedule_once(start, 0.3)
a.run()
"""


def test_a_full_disk_while_recording_live_is_shown_and_the_app_goes_on(tmp_path):
    from core.recording import read_recording

    report = tmp_path / "full.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", FULL_DISK, str(tmp_path / "out"), str(tmp_path / "data"), str(report),
                        str(ROOT / "tests")], cwd=ROOT, env=env, capture_output=True, text=True, timeout=90)
    assert r.returncode == 0, r.stderr[-3000:]
    log = json.loads(report.read_text())
    assert log["started"] and log["writes"] >= 1 and log["writer"] and log["running"]
    assert log["record_error"].startswith("recording stopped: cannot write")
    assert "No space left on device" in log["record_error"] and log["warning"].startswith(log["record_error"])
    assert log["label"] == ""  # no longer shown as recording
    kept = int(log["record_error"].split("(")[-1].split()[0])
    rec = read_recording(log["record_path"], warn=False)  # what was written before the error is there
    assert sum(len(s) for s in rec.streams.values()) == kept > 0 and log["events_in"] > kept
