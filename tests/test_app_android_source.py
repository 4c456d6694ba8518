"""AndroidSource against a fake ``jnius``: sensor events at uneven intervals from a background thread.

The fake reproduces what the source relies on: ``PythonJavaClass`` /
``java_method``, ``autoclass`` for the activity, ``SensorManager`` (with the
5-argument ``registerListener``), ``HandlerThread``/``Handler``,
``LocationManager`` and ``SystemClock``.  A "hardware" thread calls the
registered listeners' ``onSensorChanged`` with ``SensorEvent``-like objects,
like Android's sensor thread does.
"""

import json
import math
import sys
import threading
import types

import numpy as np
import pytest

import _pyjnius_fake as pj
from app.session import Session
from app.sources import (PLYER_FALLBACK_WARNING, AndroidSource, PlyerFallbackSource, SensorStartError,
                         make_live_source)
from core.pdr.pipeline import Pipeline
from core.recording import read_recording

TYPES = {1: "acc", 2: "mag", 4: "gyro"}


class FakeSensor:
    def __init__(self, type_):
        self.type = type_

    def getType(self):
        return self.type

    def getName(self):
        return f"fake {TYPES.get(self.type, self.type)}"

    def getVendor(self):
        return "tests"

    def getMinDelay(self):
        return 2500


class FakeEvent:
    def __init__(self, sensor, timestamp, values):
        self.sensor = sensor
        self.timestamp = timestamp
        self.values = values  # pyjnius gives a Python list for float[]


class FakeSensorManager:
    __javaclass__ = "android/hardware/SensorManager"

    def __init__(self, missing=()):
        self.sensors = {t: FakeSensor(t) for t in (1, 2, 4) if t not in missing}
        self.registered = {}  # listener -> (sensor, period_us, latency_us, handler)
        self.register_calls = []
        self.lock = threading.Lock()

    def getDefaultSensor(self, type_):
        return self.sensors.get(type_)

    def registerListener(self, listener, sensor, period_us, latency_us, handler):
        with self.lock:
            self.registered[listener] = (sensor, period_us, latency_us, handler)
            self.register_calls.append((sensor.getType(), period_us, latency_us))
        return True

    def unregisterListener(self, listener, sensor=None):
        """``(listener)``: every sensor of the listener; ``(listener, sensor)``: that one (the Java overloads)."""
        with self.lock:
            if sensor is None or self.registered.get(listener, (None,))[0] is sensor:
                self.registered.pop(listener, None)

    def deliver(self, type_, t_ns, values):
        """What Android's sensor thread does: call every listener registered for that sensor."""
        with self.lock:
            targets = [(lst, s) for lst, (s, *_rest) in self.registered.items() if s.getType() == type_]
        for lst, s in targets:
            lst.onSensorChanged(FakeEvent(s, t_ns, list(values)))
        return len(targets)


class FakeLocation:
    """``android.location.Location``: a getter returns 0.0 when its ``has...()`` is false, as on Android."""

    def __init__(self, t_ns, lat, lon, acc=None, speed=None, bearing=None):
        self.t_ns, self.lat, self.lon, self.acc = t_ns, lat, lon, acc
        self.speed, self.bearing = speed, bearing

    def getElapsedRealtimeNanos(self):
        return self.t_ns

    def getLatitude(self):
        return self.lat

    def getLongitude(self):
        return self.lon

    def hasAltitude(self):
        return False

    def getAltitude(self):
        return 0.0

    def hasAccuracy(self):
        return self.acc is not None

    def getAccuracy(self):
        return 0.0 if self.acc is None else self.acc

    def hasSpeed(self):
        return self.speed is not None

    def getSpeed(self):
        return 0.0 if self.speed is None else self.speed

    def hasBearing(self):
        return self.bearing is not None

    def getBearing(self):
        return 0.0 if self.bearing is None else self.bearing


class FakeJavaList:
    def __init__(self, items):
        self.items = items

    def size(self):
        return len(self.items)

    def get(self, i):
        return self.items[i]


class FakeLocationManager:
    __javaclass__ = "android/location/LocationManager"
    GPS_PROVIDER = "gps"
    FUSED_PROVIDER = "fused"
    NETWORK_PROVIDER = "network"

    def __init__(self, allowed=True, providers=("gps", "fused", "network")):
        self.allowed = allowed
        self.providers = providers
        self.listeners = []

    def hasProvider(self, name):
        return name in self.providers

    def requestLocationUpdates(self, provider, min_ms, min_m, listener, looper):
        if not self.allowed:
            raise RuntimeError("java.lang.SecurityException: missing ACCESS_FINE_LOCATION")
        self.listeners.append((provider, min_ms, listener, looper))

    def removeUpdates(self, listener):
        self.listeners = [x for x in self.listeners if x[2] is not listener]

    nmea = None

    def addNmeaListener(self, listener, handler):
        self.nmea = listener

    def removeNmeaListener(self, listener):
        if self.nmea is listener:
            self.nmea = None


class FakeInsets:
    """``android.graphics.Insets``: public int fields."""

    def __init__(self, left, top, right, bottom):
        self.left, self.top, self.right, self.bottom = left, top, right, bottom


class FakeWindowInsets:
    def __init__(self, bars, cutout):
        self.bars, self.cutout = bars, cutout
        self.asked = []

    def getInsets(self, type_mask):
        self.asked.append(type_mask)
        parts = [v for bit, v in ((1, self.bars), (2, self.cutout)) if type_mask & bit]
        return FakeInsets(*(max(p[k] for p in parts) for k in range(4)))


class FakeBackDispatcher:
    """``OnBackInvokedDispatcher``: what the system calls on back (the top callback), or None: the default."""

    def __init__(self):
        self.callbacks = []

    def registerOnBackInvokedCallback(self, priority, callback):
        self.callbacks.append((priority, callback))

    def unregisterOnBackInvokedCallback(self, callback):
        self.callbacks = [(p, c) for p, c in self.callbacks if c is not callback]

    def back(self):
        if not self.callbacks:
            return False
        self.callbacks[-1][1].onBackInvoked()
        return True


class FakeWakeLock:
    def __init__(self, flags, tag):
        self.flags, self.tag, self.held, self.counted = flags, tag, False, True

    def setReferenceCounted(self, v):
        self.counted = v

    def acquire(self):
        self.held = True

    def release(self):
        self.held = False

    def isHeld(self):
        return self.held


class FakePowerManager:
    __javaclass__ = "android/os/PowerManager"
    PARTIAL_WAKE_LOCK = 1

    def __init__(self):
        self.locks = []

    def newWakeLock(self, flags, tag):
        self.locks.append(FakeWakeLock(flags, tag))
        return self.locks[-1]


class FakeNotificationManager:
    __javaclass__ = "android/app/NotificationManager"
    IMPORTANCE_LOW = 2

    def __init__(self):
        self.channels, self.posted = [], []

    def createNotificationChannel(self, ch):
        self.channels.append(ch)

    def notify(self, id_, notification):
        self.posted.append((id_, notification))

    def cancel(self, id_):
        self.posted.append((id_, None))


def make_fake_jnius(sm, lm=None, *, sdk=34, bars=(0, 63, 0, 126), cutout=(0, 80, 0, 0), granted=None):
    """The fake ``jnius``; ``sdk`` is ``Build.VERSION.SDK_INT``, ``bars``/``cutout`` the insets (left, top,
    right, bottom, px) the activity's window reports, ``granted`` the permissions granted (default: all).

    Every Java call goes through :class:`tests._pyjnius_fake.Bridge`: the overload is chosen as pyjnius 1.7
    chooses it, logged in ``jn.calls`` as ``(class, method, signature)``, and an argument of the wrong Java
    type aborts as CheckJNI aborts a debuggable build (:class:`~tests._pyjnius_fake.CheckJNIAbort`)."""
    jn = types.ModuleType("jnius")
    bridge = pj.Bridge()
    jn.calls = bridge.calls
    jn.granted = granted
    jn.threads = []
    jn.power = FakePowerManager()
    jn.notifications = FakeNotificationManager()
    jn.back = FakeBackDispatcher()
    jn.window_insets = FakeWindowInsets(bars, cutout)
    jn.services_started = []
    jn.activity_requests = []
    jn.resolver = None
    jn.wrap = bridge.wrap  # a Java object handed to a Python callback, as pyjnius hands it

    class Context:
        SENSOR_SERVICE = "sensor"
        LOCATION_SERVICE = "location"
        POWER_SERVICE = "power"
        NOTIFICATION_SERVICE = "notification"

    class Intent:
        pass

    class AppInfo:
        icon = 17

    class PackageManager:
        def getLaunchIntentForPackage(self, name):
            return Intent()

    class View:
        def getRootWindowInsets(self):
            return jn.window_insets

    class Window:
        def getDecorView(self):
            return View()

    class Activity:
        """PythonActivity.mActivity, and PythonService.mService (a Context too)."""

        def getSystemService(self, name):
            return {"sensor": sm, "location": lm, "power": jn.power, "notification": jn.notifications}[name]

        def checkSelfPermission(self, name):
            return 0 if jn.granted is None or name in jn.granted else -1

        def getPackageName(self):
            return "org.pdrproject.pdrtracker"

        def getPackageManager(self):
            return PackageManager()

        def getApplicationInfo(self):
            return AppInfo()

        def getWindow(self):
            return Window()

        def getOnBackInvokedDispatcher(self):
            return jn.back

        def setAutoRestartService(self, v):
            self.auto_restart = v

        def startActivityForResult(self, intent, code):  # the system picker (tests/test_app_files.py)
            jn.activity_requests.append((intent, code))

        def getContentResolver(self):
            return jn.resolver

    class PythonActivity:
        mActivity = Activity()

    class PythonService:
        mService = PythonActivity.mActivity

    class ServiceTracker:
        @staticmethod
        def start(ctx, icon, title, text, argument):
            jn.services_started.append((icon, title, text, argument))

        @staticmethod
        def stop(ctx):
            jn.services_started.append("stop")

    class WindowInsetsType:
        @staticmethod
        def systemBars():
            return 1

        @staticmethod
        def displayCutout():
            return 2

    class NotificationChannel:
        def __init__(self, id_, name, importance):
            self.id, self.name, self.importance = id_, name, importance

        def setShowBadge(self, v):
            self.badge = v

    class PendingIntent:
        FLAG_IMMUTABLE = 1 << 26
        FLAG_UPDATE_CURRENT = 1 << 27

        @staticmethod
        def getActivity(ctx, code, intent, flags):
            return ("pending", intent, flags)

    class NotificationBuilder:
        def __init__(self, ctx, channel=None):
            self.fields = {"channel": channel}

        def __getattr__(self, name):  # setContentTitle, setContentText, ...
            if not name.startswith("set"):
                raise AttributeError(name)
            return lambda value: self.fields.__setitem__(name[3:], value)

        def build(self):
            return dict(self.fields)

    class Looper:
        pass

    class HandlerThread:
        def __init__(self, name):
            self.name = name
            self.started = self.quit = False
            jn.threads.append(self)

        def start(self):
            self.started = True

        def getLooper(self):
            return Looper()

        def quitSafely(self):
            self.quit = True

    class Handler:
        def __init__(self, looper):
            self.looper = looper

    class SystemClock:
        @staticmethod
        def elapsedRealtimeNanos():
            return 10**12

    class Build:
        MANUFACTURER = "Fake"
        MODEL = "Phone 1"

    class VERSION:
        SDK_INT = sdk

    classes = {"android.content.Context": Context, "org.kivy.android.PythonActivity": PythonActivity,
               "org.kivy.android.PythonService": PythonService,
               "org.pdrproject.pdrtracker.ServiceTracker": ServiceTracker,
               "android.view.WindowInsets$Type": WindowInsetsType, "android.app.NotificationChannel": NotificationChannel,
               "android.app.NotificationManager": FakeNotificationManager, "android.app.PendingIntent": PendingIntent,
               "android.app.Notification$Builder": NotificationBuilder, "android.os.PowerManager": FakePowerManager,
               "android.os.HandlerThread": HandlerThread, "android.os.Handler": Handler,
               "android.os.SystemClock": SystemClock, "android.os.Build": Build,
               "android.os.Build$VERSION": VERSION, "android.location.LocationManager": FakeLocationManager}
    jn.PythonJavaClass = pj.PythonJavaClass
    jn.java_method = pj.java_method
    jn.JavaException = pj.JavaException
    jn.cast = pj.cast
    jn.classes = classes
    def autoclass(name):
        if name not in classes:  # as pyjnius says it (e.g. the Java listener of an APK built without add_src)
            raise pj.JavaException(f"Class not found {name.replace('.', '/')!r}")
        return pj.JavaClassProxy(bridge, name, classes[name])

    jn.autoclass = autoclass
    return jn


def hardware_stream(seed=0, seconds=4.0):
    """Per-sensor events at uneven intervals: 100 Hz acc/gyro, 50 Hz mag, jitter, bursts and gaps.

    Returns a list of (type, t_ns, values) in delivery order (sensors interleaved, each in its own order).
    """
    rng = np.random.default_rng(seed)
    out = []
    t_start = 987_654_321_000
    for type_, rate in ((1, 100.0), (4, 100.0), (2, 50.0)):
        n = int(seconds * rate)
        dt = (1e9 / rate) * rng.uniform(0.6, 1.4, n)  # uneven intervals
        dt[rng.choice(n, 3, replace=False)] *= 4.0  # a few gaps (events the OS never delivered)
        t = t_start + np.cumsum(dt).astype(np.int64) + int(rng.integers(0, 10**7))
        for ti in t.tolist():
            if type_ == 1:
                v = [0.1 * rng.normal(), 0.1 * rng.normal(), 9.81 + 2.0 * math.sin(ti * 1e-9 * 2 * math.pi * 1.8)]
            elif type_ == 4:
                v = [0.01 * rng.normal(), 0.01 * rng.normal(), 0.01 * rng.normal()]
            else:
                v = [0.0, 20.0 + rng.normal(), -44.0]
            out.append((type_, ti, v))
    # delivery: sensors interleave by time, with per-sensor batches arriving up to 30 ms late
    late = {1: 0, 4: 12_000_000, 2: 30_000_000}
    out.sort(key=lambda e: e[1] + late[e[0]])
    return out


def run_hardware(sm, events, chunk=50, pause_every=0.0):
    """Deliver ``events`` from a background thread (like Android's sensor thread)."""
    delivered = []

    def run():
        for i, (type_, t, v) in enumerate(events):
            if sm.deliver(type_, t, v):
                delivered.append((TYPES[type_], t, tuple(v)))
            if pause_every and i % chunk == 0:
                threading.Event().wait(pause_every)

    th = threading.Thread(target=run)
    th.start()
    return th, delivered


@pytest.fixture(autouse=True)
def no_real_jnius(monkeypatch):
    """The source must never import a real jnius here; a test that forgets to inject the fake fails."""
    monkeypatch.setitem(sys.modules, "jnius", None)


def test_importing_the_sources_does_not_import_jnius():
    import subprocess

    # ... nor Kivy: the tracking service's process (app/service_main.py) has no window
    code = ("import sys, app.sources, app.session, app.service, app.android_platform, app.service_main; "
            "print('jnius' in sys.modules, 'kivy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_listener_keeps_every_event_and_timestamp_at_uneven_intervals():
    sm = FakeSensorManager()
    src = AndroidSource(rate_hz=100, gps=False, jnius=make_fake_jnius(sm))
    src.start()
    # registered: one listener per sensor, 100 Hz hint, no batching, on our HandlerThread's handler
    assert sorted(sm.register_calls) == [(1, 10000, 0), (2, 10000, 0), (4, 10000, 0)]
    assert all(h.looper is not None for (_s, _p, _l, h) in sm.registered.values())
    events = hardware_stream(seed=3)
    th, delivered = run_hardware(sm, events)
    got = []
    while th.is_alive():  # the UI thread drains while the sensor thread delivers
        got.extend(src.drain())
    th.join()
    got.extend(src.drain())
    assert len(got) == len(events) == len(delivered)
    assert got == delivered  # same order, exact int timestamps, values copied
    assert all(isinstance(t, int) for _, t, _ in got)
    for name in ("acc", "gyro", "mag"):
        ts = [t for n, t, _ in got if n == name]
        assert ts == sorted(ts) and len(ts) > 150
    assert src.device["model"] == "Phone 1" and src.device["sampling_period_us"] == 10000
    assert src.unix_offset_ns is not None and src.warning == ""


def test_session_on_the_android_source_measures_rates_and_gaps():
    sm = FakeSensorManager()
    src = AndroidSource(rate_hz=100, gps=False, jnius=make_fake_jnius(sm))
    ses = Session(src, pipeline_factory=Pipeline, reorder_window_ns=50_000_000)
    ses.start()
    events = hardware_stream(seed=4, seconds=6.0)
    th, _ = run_hardware(sm, events, chunk=40, pause_every=0.002)
    while th.is_alive():
        ses.tick()
    th.join()
    ses.tick()
    ses._finish()
    rows = {s.stream: s for s in ses.health.snapshot()}
    assert rows["acc"].events == 600 and rows["gyro"].events == 600 and rows["mag"].events == 300
    assert all(r.out_of_order == 0 for r in rows.values())  # 30 ms late batches were put back in order
    assert 85 < rows["acc"].rate_hz < 115 and 42 < rows["mag"].rate_hz < 58
    assert all(r.gaps >= 3 and r.missed >= 3 for r in rows.values())
    assert all(r.jitter_ms > 1.0 for r in rows.values())  # uneven intervals are visible


def test_pause_unregisters_and_resume_registers_again():
    sm = FakeSensorManager()
    jn = make_fake_jnius(sm)
    src = AndroidSource(rate_hz=50, gps=False, jnius=jn)
    ses = Session(src, pipeline_factory=Pipeline)
    ses.start()
    assert len(sm.registered) == 3
    events = hardware_stream(seed=5, seconds=1.0)
    half = len(events) // 2
    for type_, t, v in events[:half]:
        sm.deliver(type_, t, v)
    ses.tick()
    n_before = ses.events_in
    ses.pause()  # on_pause
    assert sm.registered == {} and not src.running and jn.threads[0].quit
    for type_, t, v in events[half:]:
        assert sm.deliver(type_, t, v) == 0  # nobody listens while paused
    ses.tick()
    assert ses.events_in == n_before == half
    ses.resume()  # on_resume
    assert len(sm.registered) == 3 and src.running and len(jn.threads) == 2
    assert [c[1] for c in sm.register_calls] == [20000] * 6
    for type_, t, v in events[half:]:
        sm.deliver(type_, t + 10**9, v)
    ses.tick()
    assert ses.events_in == len(events)


def test_queue_is_bounded_and_counts_what_it_dropped():
    sm = FakeSensorManager()
    src = AndroidSource(gps=False, jnius=make_fake_jnius(sm), queue_max=100)
    src.start()
    events = [e for e in hardware_stream(seed=6, seconds=2.0) if e[0] == 1]  # 200 acc events
    for type_, t, v in events:
        sm.deliver(type_, t, v)
    got = src.drain()
    assert len(got) == 100 and [e[1] for e in got] == [e[1] for e in events[100:]]  # newest kept
    assert src.queue_drops() == {"acc": 100}


def test_exceptions_in_the_callback_never_reach_java():
    sm = FakeSensorManager()
    src = AndroidSource(gps=False, jnius=make_fake_jnius(sm))
    src.start()
    sm.deliver(1, 5, [1.0])  # too few values: would raise IndexError inside onSensorChanged
    sm.deliver(1, 6, [1.0, 2.0, 3.0])
    assert src.listener_errors == 1 and src.drain() == [("acc", 6, (1.0, 2.0, 3.0))]


def test_missing_gyroscope_is_a_warning_missing_accelerometer_falls_back_to_plyer():
    sm = FakeSensorManager(missing=(4,))
    src = AndroidSource(gps=False, jnius=make_fake_jnius(sm))
    src.start()
    assert "gyro" in src.warning and src.running

    class Facade:
        def __init__(self, value):
            self.value = value
            self.enabled = False

        def enable(self):
            self.enabled = True

        def disable(self):
            self.enabled = False

    plyer = types.SimpleNamespace(accelerometer=Facade(None), gyroscope=Facade(None), compass=Facade(None))
    plyer.accelerometer.acceleration = (0.1, 0.2, 9.8)
    plyer.gyroscope.rotation = (None, None, None)  # no event yet
    plyer.compass.field = (1.0, 20.0, -40.0)
    live = make_live_source(jnius=make_fake_jnius(FakeSensorManager(missing=(1,))), plyer=plyer, gps=False)
    assert isinstance(live, PlyerFallbackSource) and live.running
    assert live.warning.startswith(PLYER_FALLBACK_WARNING) and "accelerometer" in live.warning
    first = live.drain()
    assert sorted(e[0] for e in first) == ["acc", "mag"]
    assert live.drain() == []  # unchanged values are not new events
    plyer.accelerometer.acceleration = (0.2, 0.2, 9.8)
    assert [e[0] for e in live.drain()] == ["acc"]
    live.stop()
    assert not plyer.accelerometer.enabled


def test_without_jnius_the_source_refuses_to_start():
    with pytest.raises(SensorStartError, match="pyjnius not available"):
        AndroidSource(gps=False).start()


def test_gps_fixes_keep_the_elapsed_realtime_timestamp():
    sm, lm = FakeSensorManager(), FakeLocationManager()
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    src.start()
    assert src.gps_status.startswith("on") and lm.listeners[0][:2] == ("gps", 1000)
    listener = lm.listeners[0][2]
    listener.onLocationChanged(FakeLocation(1_000_000_123, 47.5, 8.5, 4.0))
    listener.onLocationChangedList(FakeJavaList([FakeLocation(2_000_000_456, 47.6, 8.6)]))
    got = src.drain()
    assert got[0][:2] == ("gps", 1_000_000_123) and got[0][2][:2] == (47.5, 8.5) and got[0][2][3] == 4.0
    assert math.isnan(got[0][2][2])  # no altitude
    assert got[1][:2] == ("gps", 2_000_000_456) and math.isnan(got[1][2][3])
    src.stop()
    assert lm.listeners == [] and lm.nmea is None


def test_nmea_sentences_become_gnss_status_events():
    """Kubrak's C/N0 rule on the phone: GSV/GSA/GGA sentences -> (satellites used, 4th-strongest C/N0)."""
    from tests.test_nmea import _epoch

    sm, lm = FakeSensorManager(), FakeLocationManager()
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    src.start()
    assert "C/N0 from NMEA" in src.gps_status and lm.nmea is not None
    for sentence in _epoch([(1, 40), (3, 38), (5, 30), (7, 22), (9, 18)], [1, 3, 5, 7, 9]) + ["$garbage*00"]:
        lm.nmea.onNmeaMessage(sentence, 1_700_000_000_000)
    got = [e for e in src.drain() if e[0] == "gnss_status"]
    assert got == [("gnss_status", 10**12, (5.0, 22.0))]  # stamped on the sensor clock at arrival
    src.stop()


def test_gps_without_permission_leaves_the_sensors_running():
    sm, lm = FakeSensorManager(), FakeLocationManager(allowed=False)
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    src.start()
    assert src.running and src.gps_status.startswith("off") and "SecurityException" in src.gps_status


GPS_COLUMNS = ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg")


def test_gps_fixes_carry_speed_and_course_where_the_fix_has_them():
    sm, lm = FakeSensorManager(), FakeLocationManager()
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    src.start()
    listener = lm.listeners[0][2]
    listener.onLocationChanged(FakeLocation(1_000_000_000, 47.5, 8.5, 4.0, speed=1.35, bearing=87.5))
    listener.onLocationChanged(FakeLocation(2_000_000_000, 47.5, 8.5, 4.0, speed=0.0))  # standing: no bearing
    listener.onLocationChanged(FakeLocation(3_000_000_000, 47.5, 8.5))  # neither
    (_, _, v1), (_, _, v2), (_, _, v3) = src.drain()
    assert len(v1) == len(v2) == len(v3) == len(GPS_COLUMNS)
    assert v1[4] == pytest.approx(1.35, abs=1e-12) and v1[5] == pytest.approx(87.5, abs=1e-12)
    assert v2[4] == pytest.approx(0.0, abs=1e-12) and math.isnan(v2[5])
    assert math.isnan(v3[3]) and math.isnan(v3[4]) and math.isnan(v3[5])


def test_live_recording_of_android_gps_has_the_six_columns(tmp_path):
    sm, lm = FakeSensorManager(), FakeLocationManager()
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    path = tmp_path / "live.csv"
    ses = Session(src, pipeline_factory=Pipeline, record_path=str(path))
    ses.start()
    listener = lm.listeners[0][2]
    fixes = [FakeLocation(987_654_321_000 + k * 10**9, 47.5 + 1e-5 * k, 8.5, 3.0 + k, speed=1.2 + 0.1 * k,
                          bearing=None if k == 0 else 10.0 * k) for k in range(3)]
    for fix in fixes:
        listener.onLocationChanged(fix)
    for type_, t, v in hardware_stream(seed=7, seconds=3.0):
        sm.deliver(type_, t, v)
    ses.tick()
    ses.close()
    gps = read_recording(str(path), warn=False).streams["gps"]
    assert gps.columns == GPS_COLUMNS
    assert list(gps.t_ns) == [f.t_ns for f in fixes]
    want = [[f.lat, f.lon, np.nan, f.acc, f.speed, np.nan if f.bearing is None else f.bearing] for f in fixes]
    np.testing.assert_allclose(gps.values, want, rtol=0, atol=1e-12)  # nan where nan
    assert ses.gps_origin == pytest.approx((47.5, 8.5), abs=1e-12)


def test_session_records_a_four_value_gps_event_with_nan_speed_and_course(tmp_path):
    """A source that still sends (lat, lon, alt, hacc) must not make the recording unreadable."""
    sm = FakeSensorManager()
    src = AndroidSource(gps=False, jnius=make_fake_jnius(sm))
    path = tmp_path / "old.csv"
    ses = Session(src, pipeline_factory=Pipeline, record_path=str(path))
    ses.start()
    ses.ingest([("gps", 5_000_000_000, (47.5, 8.5, 400.0, 35.0)), ("acc", 5_000_000_001, (0.0, 0.0, 9.81)),
                ("gps", 6_000_000_000, (47.6, 8.6, 400.0, 5.0))])
    ses.close()
    gps = read_recording(str(path), warn=False).streams["gps"]
    np.testing.assert_allclose(gps.values, [[47.5, 8.5, 400.0, 35.0, np.nan, np.nan],
                                            [47.6, 8.6, 400.0, 5.0, np.nan, np.nan]], rtol=0, atol=1e-12)
    assert ses.gps_origin == pytest.approx((47.6, 8.6), abs=1e-12)  # the first fix's 35 m is too coarse


def test_no_plyer_gps_fallback(monkeypatch):
    """plyer 2.1.0 loses Android 12+'s batched fixes and has no timestamps: a refused listener leaves GPS off
    (and says why), plyer's GPS is never started even where plyer is installed."""
    sm, lm = FakeSensorManager(), FakeLocationManager(allowed=False)
    started = []
    fake_gps = types.SimpleNamespace(configure=lambda **kw: started.append("configure"),
                                     start=lambda **kw: started.append("start"), stop=lambda: None)
    monkeypatch.setitem(sys.modules, "plyer", types.SimpleNamespace(gps=fake_gps))
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm))
    src.start()
    assert src.running and src.gps_status.startswith("off") and started == []


@pytest.mark.parametrize("granted, sdk, providers, want", [
    (None, 34, ("gps", "fused", "network"), "gps"),  # precise location: the GNSS chip (and its NMEA)
    ({"android.permission.ACCESS_COARSE_LOCATION"}, 34, ("gps", "fused", "network"), "fused"),  # approximate
    ({"android.permission.ACCESS_COARSE_LOCATION"}, 34, ("gps", "network"), "network"),  # no fused provider
    ({"android.permission.ACCESS_COARSE_LOCATION"}, 30, ("gps", "fused", "network"), "network"),  # before API 31
    (set(), 34, ("gps", "fused", "network"), None),  # no location permission: nothing asked for
])
def test_the_location_provider_follows_the_grant(granted, sdk, providers, want):
    sm, lm = FakeSensorManager(), FakeLocationManager(providers=providers)
    src = AndroidSource(gps=True, jnius=make_fake_jnius(sm, lm, sdk=sdk, granted=granted))
    src.start()
    assert src.running  # the sensors run whatever the grant
    if want is None:
        assert lm.listeners == [] and src.gps_status == "off (no location permission)"
        return
    assert [x[0] for x in lm.listeners] == [want] and src.location_provider == want
    assert ("approximate" in src.gps_status) == (want != "gps") and (lm.nmea is not None) == (want == "gps")
    lm.listeners[0][2].onLocationChanged(FakeLocation(5_000_000_000, 47.5, 8.5, 900.0))
    assert src.drain()[0][:2] == ("gps", 5_000_000_000)
    src.stop()
    assert lm.listeners == [] and src.location_provider is None


def test_the_service_holds_a_partial_wake_lock_and_shows_steps_and_distance():
    """The service's phone side (app.android_platform.ServiceHooks) against the fake jnius: a partial wake
    lock from start to stop, the notification on its own low-importance channel with the same id as p4a's
    foreground notification, updated with steps and distance, a tap opening the app."""
    from app.android_platform import PARTIAL_WAKE_LOCK, ServiceHooks
    from app.service import NOTIFICATION_CHANNEL, NOTIFICATION_ID, TrackingService

    sm = FakeSensorManager()
    jn = make_fake_jnius(sm, sdk=34)
    service = jn.autoclass("org.kivy.android.PythonService").mService
    hooks = ServiceHooks(jn, service)
    clock = iter(range(0, 10**6, 1)).__next__  # one second a call
    svc = TrackingService({"data_dir": "/nonexistent-dir-for-settings"},
                          source_factory=lambda rate: AndroidSource(rate_hz=rate, gps=False, jnius=jn, context=service),
                          hooks=hooks, clock=clock)
    svc.start()
    (lock,) = jn.power.locks
    assert lock.flags == PARTIAL_WAKE_LOCK and lock.held and not lock.counted
    assert len(sm.registered) == 3  # the sensors registered through the service's context
    (channel,) = jn.notifications.channels
    assert channel.id == NOTIFICATION_CHANNEL and channel.importance == FakeNotificationManager.IMPORTANCE_LOW
    nid, first = jn.notifications.posted[0]
    assert nid == NOTIFICATION_ID and first["ContentText"] == "0 steps · 0 m"
    assert first["Ongoing"] is True and first["OnlyAlertOnce"] is True and first["channel"] == NOTIFICATION_CHANNEL
    assert first["ContentIntent"][0] == "pending" and first["SmallIcon"] == 17
    # 6 s: a walk's first steps wait while the carry detector settles its mode (its first 4-s window; issue #25)
    for type_, t, v in hardware_stream(seed=8, seconds=6.0):
        sm.deliver(type_, t, v)
    for _ in range(5):
        svc.step()
    summ = svc.session.summary()
    assert summ["steps"] > 0
    assert jn.notifications.posted[-1][1]["ContentText"] == f"{summ['steps']} steps · {summ['distance_m']:.0f} m"
    n_posted = len(jn.notifications.posted)
    svc.step()
    assert len(jn.notifications.posted) == n_posted  # unchanged text: not posted again
    svc.stop()
    assert not lock.held and sm.registered == {}
    assert jn.notifications.posted[-1] == (NOTIFICATION_ID, None)  # the notification goes with the walk


def test_a_service_restarted_with_a_null_intent_does_not_track(tmp_path, monkeypatch):
    """After a kill, a sticky restart comes without an argument (p4a: a null intent): even with
    ``service.json`` still saying ``active``, no walk starts -- no sensors, no recording, no run loop."""
    import app.service
    from app.android_platform import save_service_config, service_config, service_main

    cfg = {"data_dir": str(tmp_path), "record_path": str(tmp_path / "pdr-1.csv"), "socket": "s"}
    assert service_config({"PYTHON_SERVICE_ARGUMENT": json.dumps(cfg)}) == cfg
    save_service_config(cfg, True, str(tmp_path))  # the process died while tracking
    assert service_config({}) is None and service_config({"PYTHON_SERVICE_ARGUMENT": ""}) is None
    runs = []
    monkeypatch.setattr(app.service, "run_service", lambda *a, **k: runs.append(a))
    sm = FakeSensorManager()
    jn = make_fake_jnius(sm)
    service_main(jnius=jn, environ={"ANDROID_PRIVATE": str(tmp_path), "PYTHON_SERVICE_ARGUMENT": ""})
    assert runs == [] and sm.register_calls == [] and not (tmp_path / "pdr-1.csv").exists()
    assert json.loads((tmp_path / "service.json").read_text())["active"] is True  # left for the UI to tell


class StopWatchingSensorManager(FakeSensorManager):
    """Reads ``service.json`` when the sensors are unregistered (the moment a crash while stopping bites)."""

    def __init__(self, config_path):
        super().__init__()
        self.config_path = config_path
        self.active_at_unregister = []

    def unregisterListener(self, listener, sensor=None):
        self.active_at_unregister.append(json.loads(self.config_path.read_text())["active"])
        super().unregisterListener(listener, sensor)


def test_the_service_clears_active_before_the_sensors_stop(tmp_path):
    """The phone's service entry point, end to end on the fake jnius: ``active`` while it tracks, cleared as
    the user's stop begins (before the sensors are unregistered and the recording closed); the UI started
    next finds nothing interrupted."""
    from app.android_platform import service_main, take_interrupted_walk
    from app.service import ServiceClient, service_answers, socket_path

    data = tmp_path / "data"
    data.mkdir()
    cfg = {"data_dir": str(data), "socket": socket_path(str(data)), "record_path": str(tmp_path / "pdr-2.csv"),
           "metadata": {"app": "test"}}
    sm = StopWatchingSensorManager(tmp_path / "service.json")
    jn = make_fake_jnius(sm, FakeLocationManager())
    th = threading.Thread(target=service_main, kwargs={"jnius": jn, "environ": {
        "ANDROID_PRIVATE": str(tmp_path), "PYTHON_SERVICE_ARGUMENT": json.dumps(cfg)}})
    th.start()
    try:
        for _ in range(2000):  # until the socket answers (no sleep: service_answers has its own timeout)
            if service_answers(cfg["socket"], timeout_s=0.05):
                break
        assert json.loads((tmp_path / "service.json").read_text())["active"] is True
        assert len(sm.registered) == 3
        ServiceClient(cfg["socket"]).request("stop")
    finally:
        th.join(10)
    assert not th.is_alive() and sm.registered == {}
    assert sm.active_at_unregister == [False, False, False]
    assert take_interrupted_walk(str(tmp_path)) == ""


def test_the_next_ui_tells_of_a_walk_killed_while_tracking_once(tmp_path):
    from app.android_platform import save_service_config, take_interrupted_walk

    rec = tmp_path / "pdr-3.csv"
    rec.write_text("# a walk cut short\n")
    save_service_config({"record_path": str(rec), "socket": "s"}, True, str(tmp_path))
    told = take_interrupted_walk(str(tmp_path))
    assert "ended without Stop" in told and "pdr-3.csv" in told
    assert take_interrupted_walk(str(tmp_path)) == ""  # told once
    assert take_interrupted_walk(None) == "" and take_interrupted_walk(str(tmp_path / "none")) == ""


def test_starting_the_service_passes_the_configuration_to_the_p4a_service_class():
    from app.android_platform import location_grant, start_service

    jn = make_fake_jnius(FakeSensorManager())
    start_service(jn, {"socket": "/x/tracker.sock"})
    (icon, title, _text, arg), = jn.services_started
    assert icon == "" and title == "PDR Tracker" and json.loads(arg) == {"socket": "/x/tracker.sock"}
    act = jn.autoclass("org.kivy.android.PythonActivity").mActivity
    assert location_grant(act) == "fine"
    coarse = make_fake_jnius(FakeSensorManager(), granted={"android.permission.ACCESS_COARSE_LOCATION"})
    assert location_grant(coarse.autoclass("org.kivy.android.PythonActivity").mActivity) == "coarse"
    none = make_fake_jnius(FakeSensorManager(), granted=set())
    assert location_grant(none.autoclass("org.kivy.android.PythonActivity").mActivity) is None


def test_insets_and_back_below_android_15_and_13():
    from app.android_platform import BackHandler, system_bar_insets

    assert system_bar_insets(make_fake_jnius(FakeSensorManager(), sdk=34)) == (0, 0, 0, 0)  # not edge-to-edge
    jn = make_fake_jnius(FakeSensorManager(), sdk=35, bars=(10, 60, 20, 120), cutout=(0, 0, 0, 0))
    assert system_bar_insets(jn) == (10, 60, 20, 120)
    old = make_fake_jnius(FakeSensorManager(), sdk=32)
    handler = BackHandler(old, lambda: None)
    handler.want(True)  # Android 12: back still comes as key 27
    assert not handler.registered and old.back.callbacks == []
    new = make_fake_jnius(FakeSensorManager(), sdk=33)
    went = []
    handler = BackHandler(new, lambda: went.append(1))
    handler.want(True)
    handler.want(True)
    assert len(new.back.callbacks) == 1 and new.back.back() and went == [1]
    handler.want(False)
    assert new.back.callbacks == [] and not new.back.back()


# -- the Java signature of every call: pyjnius 1.7's overload choice (tests/_pyjnius_fake.py) ----------------

SEL, SENSOR = "Landroid/hardware/SensorEventListener;", "Landroid/hardware/Sensor;"
#: (class, method) -> the signature the app means; every Java call the app makes is here
EXPECTED_SIGNATURES = {
    ("android/content/Context", "getSystemService"): "(Ljava/lang/String;)Ljava/lang/Object;",
    ("android/content/Context", "checkSelfPermission"): "(Ljava/lang/String;)I",
    ("android/content/Context", "getPackageName"): "()Ljava/lang/String;",
    ("android/content/Context", "getPackageManager"): "()Landroid/content/pm/PackageManager;",
    ("android/content/Context", "getApplicationInfo"): "()Landroid/content/pm/ApplicationInfo;",
    ("android/app/Activity", "getWindow"): "()Landroid/view/Window;",
    ("android/app/Activity", "getOnBackInvokedDispatcher"): "()Landroid/window/OnBackInvokedDispatcher;",
    ("org/kivy/android/PythonService", "setAutoRestartService"): "(Z)V",
    ("android/hardware/SensorManager", "getDefaultSensor"): "(I)Landroid/hardware/Sensor;",
    ("android/hardware/SensorManager", "registerListener"): f"({SEL}{SENSOR}IILandroid/os/Handler;)Z",
    ("android/hardware/SensorManager", "unregisterListener"): f"({SEL}{SENSOR})V",
    ("android/hardware/Sensor", "getName"): "()Ljava/lang/String;",
    ("android/hardware/Sensor", "getVendor"): "()Ljava/lang/String;",
    ("android/hardware/Sensor", "getMinDelay"): "()I",
    ("android/hardware/Sensor", "getResolution"): "()F",
    ("android/hardware/Sensor", "getMaximumRange"): "()F",
    ("android/os/HandlerThread", "<init>"): "(Ljava/lang/String;)V",
    ("android/os/HandlerThread", "start"): "()V",
    ("android/os/HandlerThread", "getLooper"): "()Landroid/os/Looper;",
    ("android/os/HandlerThread", "quitSafely"): "()Z",
    ("android/os/Handler", "<init>"): "(Landroid/os/Looper;)V",
    ("android/os/SystemClock", "elapsedRealtimeNanos"): "()J",
    ("android/location/LocationManager", "requestLocationUpdates"):
        "(Ljava/lang/String;JFLandroid/location/LocationListener;Landroid/os/Looper;)V",
    ("android/location/LocationManager", "removeUpdates"): "(Landroid/location/LocationListener;)V",
    ("android/location/LocationManager", "hasProvider"): "(Ljava/lang/String;)Z",
    ("android/location/LocationManager", "addNmeaListener"):
        "(Landroid/location/OnNmeaMessageListener;Landroid/os/Handler;)Z",
    ("android/location/LocationManager", "removeNmeaListener"): "(Landroid/location/OnNmeaMessageListener;)V",
    ("android/os/PowerManager", "newWakeLock"): "(ILjava/lang/String;)Landroid/os/PowerManager$WakeLock;",
    ("android/os/PowerManager$WakeLock", "setReferenceCounted"): "(Z)V",
    ("android/os/PowerManager$WakeLock", "acquire"): "()V",
    ("android/os/PowerManager$WakeLock", "release"): "()V",
    ("android/os/PowerManager$WakeLock", "isHeld"): "()Z",
    ("android/app/NotificationManager", "createNotificationChannel"): "(Landroid/app/NotificationChannel;)V",
    ("android/app/NotificationManager", "notify"): "(ILandroid/app/Notification;)V",
    ("android/app/NotificationManager", "cancel"): "(I)V",
    ("android/app/NotificationChannel", "<init>"): "(Ljava/lang/String;Ljava/lang/CharSequence;I)V",
    ("android/app/NotificationChannel", "setShowBadge"): "(Z)V",
    ("android/app/PendingIntent", "getActivity"):
        "(Landroid/content/Context;ILandroid/content/Intent;I)Landroid/app/PendingIntent;",
    ("android/app/Notification$Builder", "<init>"): "(Landroid/content/Context;Ljava/lang/String;)V",
    ("android/app/Notification$Builder", "setContentTitle"): "(Ljava/lang/CharSequence;)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "setContentText"): "(Ljava/lang/CharSequence;)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "setSmallIcon"): "(I)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "setOngoing"): "(Z)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "setOnlyAlertOnce"): "(Z)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "setContentIntent"):
        "(Landroid/app/PendingIntent;)Landroid/app/Notification$Builder;",
    ("android/app/Notification$Builder", "build"): "()Landroid/app/Notification;",
    ("android/content/pm/PackageManager", "getLaunchIntentForPackage"): "(Ljava/lang/String;)Landroid/content/Intent;",
    ("org/pdrproject/pdrtracker/ServiceTracker", "start"):
        "(Landroid/content/Context;Ljava/lang/String;Ljava/lang/String;Ljava/lang/String;Ljava/lang/String;)V",
    ("org/pdrproject/pdrtracker/ServiceTracker", "stop"): "(Landroid/content/Context;)V",
    ("android/view/Window", "getDecorView"): "()Landroid/view/View;",
    ("android/view/View", "getRootWindowInsets"): "()Landroid/view/WindowInsets;",
    ("android/view/WindowInsets", "getInsets"): "(I)Landroid/graphics/Insets;",
    ("android/view/WindowInsets$Type", "systemBars"): "()I",
    ("android/view/WindowInsets$Type", "displayCutout"): "()I",
    ("android/window/OnBackInvokedDispatcher", "registerOnBackInvokedCallback"):
        "(ILandroid/window/OnBackInvokedCallback;)V",
    ("android/window/OnBackInvokedDispatcher", "unregisterOnBackInvokedCallback"):
        "(Landroid/window/OnBackInvokedCallback;)V",
}


def _declaring(cls, name, sig):
    """The class of the SDK table that declares ``name`` with ``sig`` (a call on a PythonActivity is Context's)."""
    for c in [cls] + sorted(pj.supertypes(cls) - {cls}):
        if sig in [s.replace("static ", "") for s in pj.SDK.get(c, ((), {}, {}))[1].get(name, [])]:
            return c
    return cls


def called_signatures(jn) -> dict:
    """``(declaring class, method) -> {signatures}`` of the Java calls the fake ``jn`` saw."""
    called = {}
    for cls, name, sig in jn.calls:
        called.setdefault((_declaring(cls, name, sig), name), set()).add(sig)
    return called


def run_every_java_path(jn, sm, lm):
    """Everything of app.sources and app.android_platform that talks to Java, once."""
    from app.android_platform import BackHandler, ServiceHooks, start_service, stop_service, system_bar_insets

    src = AndroidSource(gps=True, jnius=jn)
    src.start()
    for type_, t, v in hardware_stream(seed=9, seconds=0.2):
        sm.deliver(type_, t, v)
    src.drain()
    src.stop()
    coarse = AndroidSource(gps=True, jnius=jn)  # approximate location only: the fused provider
    jn.granted = {"android.permission.ACCESS_COARSE_LOCATION"}
    coarse.start()
    coarse.stop()
    service = jn.autoclass("org.kivy.android.PythonService").mService
    service.setAutoRestartService(False)
    hooks = ServiceHooks(jn, service)
    hooks.acquire()
    hooks.notify("PDR Tracker", "3 steps · 2 m")
    hooks.release()
    start_service(jn, {"socket": "/x"})
    stop_service(jn)
    system_bar_insets(jn)
    back = BackHandler(jn, lambda: None)
    back.want(True)
    back.want(False)


def test_every_java_call_resolves_to_the_intended_overload_as_pyjnius_1_7_chooses():
    """pyjnius 1.7 picks among overloads by score, ties to the highest signature string (the fake resolves
    the same way): every call the app makes lands on the signature it means, none on a deprecated one.
    ``unregisterListener(listener)`` alone would land on the deprecated ``(SensorListener)`` and abort."""
    sm, lm = FakeSensorManager(), FakeLocationManager()
    jn = make_fake_jnius(sm, lm, sdk=35)
    run_every_java_path(jn, sm, lm)
    called = called_signatures(jn)
    assert set(called) == set(EXPECTED_SIGNATURES)  # every call is asserted, and every asserted one happened
    for key, sigs in called.items():
        assert sigs == {EXPECTED_SIGNATURES[key]}, key
    assert not {(c, n, s) for c, n, s in jn.calls} & pj.DEPRECATED
    assert sm.registered == {} and sm.register_calls  # the listeners really went


def test_the_fake_resolves_overloads_by_pyjnius_1_7_scores():
    """The facts the fake reproduces (jnius_utils.pxi calculate_score, JavaMultipleMethod.__call__)."""
    um = pj.SDK["android/hardware/SensorManager"][1]["unregisterListener"]
    listener = type("L", (pj.PythonJavaClass,), {"__javainterfaces__": ["android/hardware/SensorEventListener"]})()
    bridge = pj.Bridge()
    sensor = pj.JavaObject(bridge, "android/hardware/Sensor", object())
    # a Python listener scores +1 against any object parameter: a tie, broken by the signature string
    assert pj.choose(um, (listener,), "u") == "(Landroid/hardware/SensorListener;)V"
    assert pj.choose(um, (listener, sensor), "u") == f"({SEL}{SENSOR})V"
    # an autoclass object scores +5 for any other class: putExtra(name, uri) lands on putExtra(String, String)
    put = pj.SDK["android/content/Intent"][1]["putExtra"]
    uri = pj.JavaObject(bridge, "android/net/Uri", object())
    assert pj.choose(put, ("android.intent.extra.STREAM", uri), "p") == \
        "(Ljava/lang/String;Ljava/lang/String;)Landroid/content/Intent;"
    parcel = pj.cast("android.os.Parcelable", uri)
    assert pj.choose(put, ("x", parcel), "p") == "(Ljava/lang/String;Landroid/os/Parcelable;)Landroid/content/Intent;"
    # a Python str is no CharSequence among overloads; an int no Integer
    with pytest.raises(pj.JavaException):
        pj.choose(["(Ljava/lang/CharSequence;)V", "(I)V"], ("text",), "t")
    assert pj.choose(pj.SDK["android/content/ContentValues"][1]["put"], ("k", "v"), "put") == \
        "(Ljava/lang/String;Ljava/lang/String;)V"
    with pytest.raises(pj.JavaException):
        pj.choose(pj.SDK["android/content/ContentValues"][1]["put"], ("k", 1), "put")
    # a wrong Java type aborts a debuggable build (CheckJNI), past any `except Exception`
    sm = FakeSensorManager()
    jn = make_fake_jnius(sm)
    sm_java = jn.autoclass("org.kivy.android.PythonActivity").mActivity.getSystemService("sensor")
    with pytest.raises(pj.CheckJNIAbort):
        try:
            sm_java.unregisterListener(listener)
        except Exception:  # noqa: BLE001 - as app code would
            pass


class RangedSensor(FakeSensor):
    """A sensor with Android's ``getMaximumRange()`` (in the sensor's unit: rad/s for the gyroscope)."""

    def __init__(self, type_, max_range):
        super().__init__(type_)
        self.max_range = max_range

    def getMaximumRange(self):
        return self.max_range


def _live_foot_session(gyro_max_range, path, events=()):
    """A live foot-mode session on the fake sensors (the gyroscope declaring ``gyro_max_range``), recording to
    ``path``, fed ``events`` ((stream, t_ns, values)) through the sensor thread, then closed."""
    from app.settings import Settings

    sm = FakeSensorManager()
    sm.sensors[4] = RangedSensor(4, gyro_max_range)
    src = AndroidSource(rate_hz=200, gps=False, jnius=make_fake_jnius(sm))
    ses = Session(src, pipeline_factory=Settings(tracking_mode="foot").pipeline_factory(), record_path=str(path))
    ses.start()
    types_ = {"acc": 1, "gyro": 4}
    for k, (name, t, v) in enumerate(events):
        sm.deliver(types_[name], t, v)
        if k % 500 == 499:
            ses.tick(budget_s=10.0)
    ses.tick(budget_s=10.0)
    ses.close()
    return ses


def test_live_foot_mode_repairs_clipping_at_the_gyroscopes_maximum_range(tmp_path):
    """Android's getMaximumRange of the gyroscope reaches the foot INS of a live foot-mode session (clipped
    swings repaired), the recording keeps it, and a replay of that recording uses it.  Before: nan, none."""
    from core.foot.tracker import FootTracker, foot_settings_for
    from tests.test_foot_saturation import _clipped_walk

    w, rec, level = _clipped_walk(1)
    events = [e for e in rec.events() if e[0] in ("acc", "gyro")]
    path = tmp_path / "live.csv"
    ses = _live_foot_session(level / 0.995, path, events)
    tr = ses.pipeline
    assert isinstance(tr, FootTracker)
    assert tr.settings.gyro_range_rad_s == tr.nav.settings.gyro_range_rad_s == pytest.approx(level / 0.995, abs=1e-12)
    d = tr.diagnostics()
    assert d["gyro_clipped_runs_repaired"] >= 5 and d["gyro_range_refused"] == 0  # a run per stride
    assert any("clipped runs repaired" in line for line in tr.health_lines())
    back = read_recording(str(path), warn=False)
    assert back.device["sensors"]["gyro"]["max_range"] == pytest.approx(level / 0.995, abs=1e-12)
    assert foot_settings_for(back)[0].gyro_range_rad_s == pytest.approx(level / 0.995, abs=1e-12)
    ses.reset_track()  # a new track of the same sensors keeps it
    assert ses.pipeline.nav.settings.gyro_range_rad_s == pytest.approx(level / 0.995, abs=1e-12)


def test_the_gyroscopes_maximum_range_reaches_a_foot_session(tmp_path):
    ses = _live_foot_session(8.7, tmp_path / "a.csv", [("acc", 10**9, (0.0, 0.0, 9.81))])
    assert ses.pipeline.nav.settings.gyro_range_rad_s == pytest.approx(8.7, abs=1e-12)
    assert read_recording(str(tmp_path / "a.csv"), warn=False).device["sensors"]["gyro"]["max_range"] == 8.7


@pytest.mark.parametrize("bad", [math.nan, math.inf, 0.0, -8.7, 0.5])
def test_a_broken_maximum_range_is_ignored_and_said(tmp_path, bad):
    """nan / inf / 0 / negative / implausibly small from a broken sensor: nothing repaired, counted and said
    in the diagnostics and the health panel, no crash; the recording stays readable and its replay ignores it."""
    from core.foot.tracker import foot_settings_for, recording_gyro_range

    path = tmp_path / "bad.csv"
    ses = _live_foot_session(bad, path, [("acc", 10**9, (0.0, 0.0, 9.81)), ("gyro", 10**9 + 1, (0.0, 0.0, 0.0))])
    tr = ses.pipeline
    assert math.isnan(tr.settings.gyro_range_rad_s) and math.isnan(tr.nav.settings.gyro_range_rad_s)
    d = tr.diagnostics()
    assert d["gyro_range_refused"] == 1 and d["gyro_clipped_runs_repaired"] == 0
    assert any("not repaired" in line and "maximum range" in line for line in tr.health_lines())
    back = read_recording(str(path), warn=False)
    assert math.isnan(foot_settings_for(back)[0].gyro_range_rad_s)
    assert "maximum range" in recording_gyro_range(back)[1]
