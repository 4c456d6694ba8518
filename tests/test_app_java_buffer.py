"""The Java listener (issue #28, 5): ``EventBuffer`` in the APK buffers events, Python polls a few times a second.

``app/java/org/pdrproject/sensors/EventBuffer.java`` is compiled here with ``javac`` against three stub
classes of ``android.hardware`` and driven by a small harness; :class:`FakeEventBuffer` is its Python twin for
the fake jnius, held to the same answers on the same script.  Then :class:`app.sources.AndroidSource` on the
fake: polled at most every 0.2 s (a fake clock), every event kept with its timestamp, the sensors merged in
time order, drops counted, the last events taken when the sensors stop, and every Java call's signature.
"""

import math
import shutil
import subprocess

import numpy as np
import pytest

from app.sources import BUFFER_CAPACITY, AndroidSource
from app.session import Session
from core.pdr.pipeline import Pipeline
from test_app_android_source import (EXPECTED_SIGNATURES, FakeSensorManager, called_signatures, hardware_stream,
                                     make_fake_jnius)
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
JAVA = ROOT / "app" / "java" / "org" / "pdrproject" / "sensors" / "EventBuffer.java"


class FakeEventBuffer:
    """What EventBuffer.java does, in Python (held to it by test_the_python_twin_answers_as_the_java_class)."""

    def __init__(self, capacity, width):
        self.capacity, self.width = capacity, width
        self.t, self.v, self._dropped, self._accuracy = [], [], 0, -2
        self._taken = ([], [])

    def onSensorChanged(self, event):
        vals = [float(x) for x in event.values[:self.width]] + [math.nan] * max(0, self.width - len(event.values))
        if len(self.t) == self.capacity:
            self.t.pop(0)
            del self.v[:self.width]
            self._dropped += 1
        self.t.append(int(event.timestamp))
        self.v += vals

    def onAccuracyChanged(self, sensor, accuracy):
        self._accuracy = accuracy

    def take(self):
        self._taken, self.t, self.v = (self.t, self.v), [], []
        return len(self._taken[0])

    def takenTimes(self):
        return list(self._taken[0])

    def takenValues(self):
        return list(self._taken[1])

    def dropped(self):
        return self._dropped

    def accuracy(self):
        return self._accuracy


class Event:
    def __init__(self, t, values):
        self.timestamp, self.values = t, values


#: a script for both: events with 2, 3 and 4 values, takes, an overflow of a capacity-4 buffer
SCRIPT = [("e", 10, [1.5, -2.25, 3.0]), ("e", 20, [0.5, 0.25]), ("take",), ("take",),
          ("e", 30, [1.0, 2.0, 3.0, 4.0])] + [("e", 40 + k, [float(k), 0.0, -1.0]) for k in range(6)] + [("take",)]


def run_python(script, capacity=4, width=3):
    buf, out = FakeEventBuffer(capacity, width), []
    for op in script:
        if op[0] == "e":
            buf.onSensorChanged(Event(op[1], op[2]))
        else:
            n = buf.take()
            out.append((n, buf.takenTimes(), buf.takenValues(), buf.dropped()))
    return out


HARNESS = """
import android.hardware.SensorEvent;
import org.pdrproject.sensors.EventBuffer;

public class Harness {
    public static void main(String[] args) {
        EventBuffer b = new EventBuffer(Integer.parseInt(args[0]), Integer.parseInt(args[1]));
        for (int a = 2; a < args.length; a++) {
            if (args[a].equals("take")) {
                int n = b.take();
                StringBuilder s = new StringBuilder(n + "|");
                for (long t : b.takenTimes()) s.append(t).append(",");
                s.append("|");
                for (float v : b.takenValues()) s.append(v).append(",");
                System.out.println(s.append("|").append(b.dropped()));
            } else {
                String[] p = args[a].split(":");
                String[] vs = p[2].split(",");
                float[] v = new float[vs.length];
                for (int i = 0; i < vs.length; i++) v[i] = Float.parseFloat(vs[i]);
                b.onSensorChanged(new SensorEvent(Long.parseLong(p[1]), v));
            }
        }
    }
}
"""
STUBS = {"Sensor": "package android.hardware; public class Sensor {}",
         "SensorEventListener": "package android.hardware; public interface SensorEventListener {"
                                " void onSensorChanged(SensorEvent e); void onAccuracyChanged(Sensor s, int a); }",
         "SensorEvent": "package android.hardware; public class SensorEvent { public final float[] values;"
                        " public long timestamp; public SensorEvent(long t, float[] v) { timestamp = t; values = v; } }"}


@pytest.mark.skipif(shutil.which("javac") is None, reason="no JDK: EventBuffer.java is not compiled here")
def test_the_python_twin_answers_as_the_java_class(tmp_path):
    src = tmp_path / "src"
    (src / "android" / "hardware").mkdir(parents=True)
    for name, text in STUBS.items():
        (src / "android" / "hardware" / f"{name}.java").write_text(text)
    (src / "Harness.java").write_text(HARNESS)
    classes = tmp_path / "classes"
    fast = ["-XX:TieredStopAtLevel=1", "-XX:+UseSerialGC", "-Xshare:auto"]  # a JVM that starts quickly
    subprocess.run(["javac", *("-J" + f for f in fast), "-d", str(classes), "-sourcepath", str(src), str(src / "Harness.java"), str(JAVA)],
                   check=True, capture_output=True, timeout=120)
    args = ["4", "3"] + ["take" if op[0] == "take" else f"e:{op[1]}:{','.join(map(str, op[2]))}" for op in SCRIPT]
    out = subprocess.run(["java", *fast, "-cp", str(classes), "Harness", *args], check=True, capture_output=True,
                         text=True, timeout=60).stdout.split()
    java = []
    for line in out:
        n, ts, vs, dropped = line.split("|")
        java.append((int(n), [int(x) for x in ts.split(",") if x], [float(x) for x in vs.split(",") if x], int(dropped)))
    py = run_python(SCRIPT)
    assert [j[0] for j in java] == [p[0] for p in py] == [2, 0, 4]
    for (jn, jt, jv, jd), (pn, pt, pv, pd) in zip(java, py):
        assert jt == pt and jd == pd
        np.testing.assert_array_equal(np.float32(jv), np.float32(pv))  # NaN where a value was missing
    assert py[2][1] == [42, 43, 44, 45] and py[2][3] == 3  # the oldest dropped and counted


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


def buffered_source(sm, **kw):
    jn = make_fake_jnius(sm)
    jn.classes["org.pdrproject.sensors.EventBuffer"] = FakeEventBuffer
    clock = Clock()
    return AndroidSource(rate_hz=100, gps=False, jnius=jn, clock=clock, **kw), jn, clock


def test_the_source_polls_the_java_buffers_five_times_a_second_and_keeps_every_event():
    sm = FakeSensorManager()
    src, jn, clock = buffered_source(sm)
    src.start()
    assert src.listener_kind == "java buffer" and src.device["listener"] == "java buffer"
    assert all(isinstance(lst, FakeEventBuffer) for lst in sm.registered)
    assert sorted(c[1:] for c in sm.register_calls) == [(10000, 0)] * 3
    events = hardware_stream(seed=5, seconds=3.0)
    got, polls = [], 0
    for i, (type_, t, v) in enumerate(events):
        sm.deliver(type_, t, v)
        if i % 20 == 0:
            clock.t += 0.05  # the service drains every 50 ms here: a poll every fourth drain
            before = len(jn.calls)
            got += src.drain()
            polls += any(name == "take" for _c, name, _s in jn.calls[before:])
    clock.t += 1.0
    got += src.drain()
    assert polls == len(events) // 80 + (1 if len(events) % 80 else 0)  # not more often than every 0.2 s
    want = [(["acc", "mag", None, "gyro"][type_ - 1], t, tuple(float(x) for x in v)) for type_, t, v in events]
    key = lambda e: (e[1], e[0])  # noqa: E731
    assert sorted(got, key=key) == sorted(want, key=key)  # every event, timestamp and values exact
    for name in ("acc", "gyro", "mag"):  # each sensor in its own order
        assert [e for e in got if e[0] == name] == [e for e in want if e[0] == name]
    # each poll's events in time order across the sensors (later polls may bring older ones: a sensor's
    # batch delivered late, as with a listener per event; the session's reorder buffer puts them back)
    assert sum(a[1] > b[1] for a, b in zip(got, got[1:])) <= polls  # at most one step back per batch boundary
    sm.deliver(1, events[-1][1] + 10**7, [0.0, 0.0, 9.8])
    src.stop()  # the last events are taken as the listeners go
    assert src.drain() == [("acc", events[-1][1] + 10**7, (0.0, 0.0, 9.8))] and sm.registered == {}
    signatures = called_signatures(jn)
    assert signatures[("android/hardware/SensorManager", "unregisterListener")] == \
        {EXPECTED_SIGNATURES[("android/hardware/SensorManager", "unregisterListener")]}
    assert signatures[("android/hardware/SensorManager", "registerListener")] == \
        {EXPECTED_SIGNATURES[("android/hardware/SensorManager", "registerListener")]}
    assert {k: v for k, v in signatures.items() if k[0] == "org/pdrproject/sensors/EventBuffer"} == {
        ("org/pdrproject/sensors/EventBuffer", "<init>"): {"(II)V"},
        ("org/pdrproject/sensors/EventBuffer", "take"): {"()I"},
        ("org/pdrproject/sensors/EventBuffer", "takenTimes"): {"()[J"},
        ("org/pdrproject/sensors/EventBuffer", "takenValues"): {"()[F"},
        ("org/pdrproject/sensors/EventBuffer", "dropped"): {"()J"},
        ("org/pdrproject/sensors/EventBuffer", "accuracy"): {"()I"}}


def test_a_full_buffer_counts_its_drops_and_an_apk_without_it_uses_the_python_listener():
    sm = FakeSensorManager()
    src, jn, clock = buffered_source(sm)
    src.start()
    acc = [e for e in hardware_stream(seed=6, seconds=12.0) if e[0] == 1]  # 1 200 events between two polls
    for type_, t, v in acc:
        sm.deliver(type_, t, v)
    for lst in sm.registered:
        lst.onAccuracyChanged(None, 3)
    clock.t += 1.0
    got = src.drain()
    assert len(got) == BUFFER_CAPACITY and [e[1] for e in got] == [e[1] for e in acc[-BUFFER_CAPACITY:]]
    assert src.queue_drops() == {"acc": len(acc) - BUFFER_CAPACITY} and src.accuracy()["acc"] == 3
    plain = AndroidSource(gps=False, jnius=make_fake_jnius(FakeSensorManager()))  # no EventBuffer class
    plain.start()
    assert plain.listener_kind == "python listener" and "python listener" in plain.describe()
    off = AndroidSource(gps=False, jnius=jn, java_buffer=False)  # the setting, with the class there
    off.start()
    assert off.listener_kind == "python listener"


def test_a_session_on_the_buffered_source_tracks_as_on_the_python_listener():
    tracks = []
    for buffered in (True, False):
        sm = FakeSensorManager()
        src, jn, clock = buffered_source(sm, java_buffer=buffered)
        ses = Session(src, pipeline_factory=Pipeline, reorder_window_ns=50_000_000)
        ses.start()
        for i, (type_, t, v) in enumerate(hardware_stream(seed=4, seconds=6.0)):
            sm.deliver(type_, t, v)
            if i % 30 == 0:
                clock.t += 0.1
                ses.tick()
        clock.t += 1.0
        ses.tick()
        ses._finish()
        tracks.append((ses.events_in, list(ses.track_east), list(ses.track_north)))
    assert tracks[0] == tracks[1]
