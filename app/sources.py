"""Sensor sources: one interface that yields time-stamped events for the pipeline.

Every source delivers *events* ``(stream, t_ns, values)`` exactly as
:meth:`core.recording.Recording.events` does: ``stream`` is one of the names
in :mod:`core.conventions` (``"acc"``, ``"gyro"``, ``"mag"``, ``"gps"``,
``"rotvec"``), ``t_ns`` the integer nanosecond timestamp on the sensor clock,
``values`` a tuple of floats in the units of :mod:`core`.

The UI thread calls :meth:`SensorSource.drain` from the Kivy clock (about 30
times a second) and hands the events to :class:`app.session.Session`.

Sources
-------
:class:`ReplaySource`
    Any :class:`core.recording.Recording`, played at 1x, 10x or as fast as
    possible, with pause and seek-to-start.  Desktop replay and tests.
:class:`AndroidSource`
    The phone's accelerometer, gyroscope and magnetometer through our own
    pyjnius ``SensorEventListener`` (one per sensor) registered at a
    sampling period of ``1e6 / rate_hz`` microseconds on a background
    ``HandlerThread``; every event keeps its ``SensorEvent.timestamp`` and is
    pushed into a bounded :class:`EventQueue`.  GPS through our own
    ``LocationListener`` stamped with ``Location.getElapsedRealtimeNanos()``
    (the sensor clock), from the provider the location grant allows:
    ``GPS_PROVIDER`` with precise location, ``FUSED_PROVIDER`` (API 31+) or
    ``NETWORK_PROVIDER`` with approximate location only (Android 12+ lets
    the user grant only that, and then ``GPS_PROVIDER`` throws).  A fix's
    values are the six ``gps`` columns with speed and course
    (:func:`location_values`).  There is no plyer GPS fallback: plyer 2.1.0
    (PyPI) lacks ``onLocationChanged(List)`` and loses batched fixes on
    Android 12+, and stamps fixes on arrival.  ``jnius`` is imported
    lazily, only when the source starts (or injected, for tests).
:class:`PlyerFallbackSource`
    plyer's sensor facades (about 5 Hz, no timestamps: events are stamped
    when polled).  Used only when the listener cannot start, with a visible
    warning.

Rates above 200 Hz are never requested: on Android 12+ that needs the
``HIGH_SAMPLING_RATE_SENSORS`` permission and throws a SecurityException in
debuggable builds without it.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter, deque
from typing import Callable, Iterable

import numpy as np

from core.conventions import ACC, GNSS_STATUS, GPS, GYRO, MAG, PRESSURE, ROTVEC
from core.gnss.nmea import NmeaSatelliteStatus

#: ``(stream, t_ns, values)``
Event = tuple

#: The streams the pipeline consumes (anything else in a recording is not replayed).
PIPELINE_STREAMS = (ACC, GYRO, MAG, GPS, ROTVEC, PRESSURE)

#: Replay speeds offered by the UI: label -> factor (``inf`` = as fast as possible).
REPLAY_SPEEDS = {"1x": 1.0, "10x": 10.0, "max": math.inf}

#: Highest rate requested from Android without the HIGH_SAMPLING_RATE_SENSORS permission.
MAX_RATE_HZ = 200.0

#: ``android.hardware.Sensor.TYPE_*`` constants (fixed by the Android API).
ANDROID_SENSOR_TYPES = {ACC: 1, MAG: 2, GYRO: 4, PRESSURE: 6, ROTVEC: 11}

#: sensors many phones lack: listened to when present, no warning when absent
OPTIONAL_STREAMS = (PRESSURE,)

#: the Java listener added to the APK (``android.add_src``: app/java/org/pdrproject/sensors/EventBuffer.java)
BUFFER_CLASS = "org.pdrproject.sensors.EventBuffer"
#: values the Java buffer keeps per event, per stream (rotvec: x, y, z and w when the phone gives it)
BUFFER_WIDTH = {ACC: 3, GYRO: 3, MAG: 3, PRESSURE: 1, ROTVEC: 4}
#: events one Java buffer holds: 5 s at the 200 Hz cap, polled every POLL_INTERVAL_S
BUFFER_CAPACITY = 1024
#: how often the Java buffers are taken (s): five times a second
POLL_INTERVAL_S = 0.2

#: ``android.hardware.SensorManager.SENSOR_STATUS_*`` names for the health panel.
ACCURACY_NAMES = {-1: "no contact", 0: "unreliable", 1: "low", 2: "medium", 3: "high"}


class SensorStartError(RuntimeError):
    """A source could not start (no jnius, no accelerometer, registration refused...)."""


def sampling_period_us(rate_hz: float) -> int:
    """Sampling period hint in microseconds for ``rate_hz``, never faster than :data:`MAX_RATE_HZ`."""
    if not rate_hz > 0:
        raise ValueError(f"sampling rate must be positive, got {rate_hz}")
    return int(round(1e6 / min(float(rate_hz), MAX_RATE_HZ)))


class EventQueue:
    """Bounded FIFO between sensor callbacks (any thread) and the UI thread.

    When full, the *oldest* event is discarded and counted in
    :attr:`dropped` (per stream), so a stalled UI loses old data, never the
    newest, and the loss is visible in the health panel.
    """

    def __init__(self, maxlen: int = 30000):
        if maxlen < 1:
            raise ValueError("queue length must be at least 1")
        self.maxlen = int(maxlen)
        self._q: deque = deque()
        self._lock = threading.Lock()
        self.dropped: Counter = Counter()
        self.pushed = 0

    def push(self, event: Event) -> None:
        with self._lock:
            if len(self._q) >= self.maxlen:
                old = self._q.popleft()
                self.dropped[old[0]] += 1
            self._q.append(event)
            self.pushed += 1

    def push_many(self, events: list) -> None:
        """:meth:`push` of each event, under one lock (a poll of the Java buffers)."""
        with self._lock:
            self._q.extend(events)
            self.pushed += len(events)
            for _ in range(len(self._q) - self.maxlen):
                self.dropped[self._q.popleft()[0]] += 1

    def drain(self, max_n: int | None = None) -> list:
        """Remove and return up to ``max_n`` events (all if ``None``), oldest first."""
        with self._lock:
            if max_n is None or max_n >= len(self._q):
                out = list(self._q)
                self._q.clear()
            else:
                out = [self._q.popleft() for _ in range(max_n)]
        return out

    def clear(self) -> None:
        with self._lock:
            self._q.clear()

    def __len__(self) -> int:
        return len(self._q)


class SensorSource:
    """Interface of every source.

    ``start()`` / ``stop()`` may be called repeatedly (the app stops sensors
    in ``on_pause`` and restarts them in ``on_resume``); ``drain()`` returns
    the events that arrived since the last call, oldest first.
    """

    #: short name shown in the UI
    kind = "source"
    #: True for sources fed by real sensors (recorded; never "finished")
    live = False

    def __init__(self):
        #: a problem the user must see ('' when all is well)
        self.warning = ""
        #: device description for the recording header
        self.device: dict = {}
        self.running = False
        #: Unix time minus sensor-clock time (ns), when known (GPX times)
        self.unix_offset_ns: int | None = None

    def start(self) -> None:
        self.running = True

    def stop(self) -> None:
        self.running = False

    def drain(self, max_events: int | None = None) -> list:  # pragma: no cover - interface
        raise NotImplementedError

    @property
    def finished(self) -> bool:
        """True when a finite source has delivered all its events."""
        return False

    def queue_drops(self) -> dict:
        """Events discarded by the source itself (queue overflow), per stream."""
        return {}

    def accuracy(self) -> dict:
        """Last reported accuracy per stream (Android ``SENSOR_STATUS_*``), where known."""
        return {}

    def describe(self) -> str:
        return self.kind


# ---------------------------------------------------------------------------
# desktop replay


def replay_source_for(recording, pipeline_factory: Callable, **kwargs) -> "ReplaySource":
    """A :class:`ReplaySource` of the streams the tracker reads: :data:`PIPELINE_STREAMS` for the hand-held
    pipeline, the tracker's ``input_streams(recording)`` when it has them (the foot INS: the foot IMU's and
    the waist IMU's streams, e.g. ``acc@left_foot``).  ``kwargs`` go to :class:`ReplaySource`."""
    wanted = getattr(pipeline_factory(), "input_streams", None)
    return ReplaySource(recording, streams=wanted(recording) if wanted is not None else None, **kwargs)


class ReplaySource(SensorSource):
    """Play a :class:`~core.recording.Recording` in sensor-time order.

    Parameters
    ----------
    recording : core.recording.Recording
    speed : float
        Replay speed factor; ``math.inf`` delivers as fast as the caller drains.
    clock : callable
        Wall clock in seconds (injectable for tests).
    streams : iterable of str, optional
        Streams to replay (default: those of :data:`PIPELINE_STREAMS` present).
    max_chunk : int
        Most events returned by one :meth:`drain` when no limit is given.
    """

    kind = "replay"

    def __init__(self, recording, *, speed: float = 1.0, clock: Callable[[], float] = time.monotonic,
                 streams: Iterable[str] | None = None, max_chunk: int = 2000):
        super().__init__()
        names = [n for n in (streams or PIPELINE_STREAMS) if recording.has(n)]
        if not [n for n in names if n not in OPTIONAL_STREAMS]:  # a barometer alone tracks nothing
            raise ValueError(f"{recording.source or 'recording'}: nothing to replay "
                             f"(no {', '.join(PIPELINE_STREAMS)} stream)")
        self.recording = recording
        self._order = recording.stream_order(names)
        self._t, self._si, self._rows = recording.merged(self._order)
        self._vals = [recording.streams[n].values.tolist() for n in self._order]
        self._t_list = self._t.tolist()
        self._si_list = self._si.tolist()
        self._rows_list = self._rows.tolist()
        self.t0_ns = int(self._t[0])
        self.t1_ns = int(self._t[-1])
        self._clock = clock
        self.max_chunk = int(max_chunk)
        self._pos = 0
        self._elapsed_s = 0.0  # replay position (sensor seconds after t0) at the anchor
        self._anchor: float | None = None
        self.speed = float(speed)
        self.device = dict(recording.device)
        self.unix_offset_ns = recording.metadata.get("unix_offset_ns")

    # -- position and control -------------------------------------------------

    @property
    def n_events(self) -> int:
        return len(self._t_list)

    @property
    def delivered(self) -> int:
        return self._pos

    @property
    def duration_s(self) -> float:
        return (self.t1_ns - self.t0_ns) * 1e-9

    def position_s(self) -> float:
        """Replay position in sensor seconds after the first event."""
        if self._anchor is not None and math.isfinite(self.speed):
            return self._elapsed_s + (self._clock() - self._anchor) * self.speed
        return self._elapsed_s

    @property
    def progress(self) -> float:
        """Fraction of events delivered."""
        return self._pos / self.n_events

    @property
    def finished(self) -> bool:
        return self._pos >= self.n_events

    def start(self) -> None:
        if not self.running:
            self.running = True
            self._anchor = self._clock()

    def stop(self) -> None:
        """Pause: the position is kept; :meth:`start` continues from it."""
        if self.running:
            self._elapsed_s = self.position_s()
            self._anchor = None
            self.running = False

    pause = stop
    resume = start

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"replay speed must be positive, got {speed}")
        if self.running:
            self._elapsed_s = self.position_s()
            self._anchor = self._clock()
        if math.isinf(self.speed) and not math.isinf(speed):
            self._elapsed_s = self._delivered_time_s()
        self.speed = float(speed)

    def seek_start(self) -> None:
        """Back to the first event (the session starts a new track)."""
        self._pos = 0
        self._elapsed_s = 0.0
        if self.running:
            self._anchor = self._clock()

    def _delivered_time_s(self) -> float:
        return (self._t_list[self._pos - 1] - self.t0_ns) * 1e-9 if self._pos else 0.0

    # -- events -------------------------------------------------------------------

    def drain(self, max_events: int | None = None) -> list:
        if not self.running or self.finished:
            return []
        n = self.max_chunk if max_events is None else int(max_events)
        if math.isinf(self.speed):
            end = min(self._pos + n, self.n_events)
        else:
            target = self.t0_ns + int(self.position_s() * 1e9)
            end = int(np.searchsorted(self._t, target, side="right"))
            end = min(max(end, self._pos), self._pos + n)
        t, si, rows, order, vals = self._t_list, self._si_list, self._rows_list, self._order, self._vals
        out = [(order[si[i]], t[i], tuple(vals[si[i]][rows[i]])) for i in range(self._pos, end)]
        self._pos = end
        if math.isinf(self.speed):
            self._elapsed_s = self._delivered_time_s()
        return out

    def describe(self) -> str:
        sp = "max" if math.isinf(self.speed) else f"{self.speed:g}x"
        return f"replay {self.recording.source or ''} at {sp}".strip()


# ---------------------------------------------------------------------------
# Android: own pyjnius listeners


_CLASS_CACHE: dict = {}


def _java_classes(jnius):
    """The PythonJavaClass listener classes, built once per ``jnius`` module.

    They must subclass ``jnius.PythonJavaClass``, so they can only be defined
    after ``jnius`` is imported (on the phone, or a fake one in tests).
    """
    key = id(jnius)
    if key in _CLASS_CACHE:
        return _CLASS_CACHE[key]
    PythonJavaClass, java_method = jnius.PythonJavaClass, jnius.java_method

    class SensorListener(PythonJavaClass):
        """One listener per sensor, so the callback needs no ``event.sensor.getType()`` JNI calls."""

        __javainterfaces__ = ["android/hardware/SensorEventListener"]
        __javacontext__ = "app"

        def __init__(self, stream, on_event, on_accuracy):
            super().__init__()
            self.stream = stream
            self._on_event = on_event
            self._on_accuracy = on_accuracy
            self.errors = 0

        @java_method("(Landroid/hardware/SensorEvent;)V")
        def onSensorChanged(self, event):
            # runs on the sensor HandlerThread: copy out, never raise into Java
            try:
                self._on_event(self.stream, event.timestamp, event.values)
            except Exception:  # noqa: BLE001 - an exception here would crash the app in Java
                self.errors += 1

        @java_method("(Landroid/hardware/Sensor;I)V")
        def onAccuracyChanged(self, sensor, accuracy):
            try:
                self._on_accuracy(self.stream, int(accuracy))
            except Exception:  # noqa: BLE001
                pass

    class LocationListener(PythonJavaClass):
        """GNSS fixes with ``Location.getElapsedRealtimeNanos()`` (the sensor clock)."""

        __javainterfaces__ = ["android/location/LocationListener"]
        __javacontext__ = "app"

        def __init__(self, on_location):
            super().__init__()
            self._on_location = on_location

        @java_method("(Landroid/location/Location;)V")
        def onLocationChanged(self, location):
            try:
                self._on_location(location)
            except Exception:  # noqa: BLE001
                pass

        # Android 12+ may deliver a batch (default method of the interface)
        @java_method("(Ljava/util/List;)V", name="onLocationChanged")
        def onLocationChangedList(self, locations):
            try:
                for i in range(locations.size()):
                    self._on_location(locations.get(i))
            except Exception:  # noqa: BLE001
                pass

        # abstract before API 29: must exist or Java calls raise NotImplementedError
        @java_method("(Ljava/lang/String;)V")
        def onProviderEnabled(self, provider):
            pass

        @java_method("(Ljava/lang/String;)V")
        def onProviderDisabled(self, provider):
            pass

        @java_method("(Ljava/lang/String;ILandroid/os/Bundle;)V")
        def onStatusChanged(self, provider, status, extras):
            pass

    class NmeaListener(PythonJavaClass):
        """NMEA sentences of the GNSS chip (API 24+): the satellites in each fix and their C/N0 (Kubrak's rule).

        ``GnssStatus.Callback`` would give the same, but it is an abstract class, which pyjnius cannot
        implement; ``OnNmeaMessageListener`` is an interface.
        """

        __javainterfaces__ = ["android/location/OnNmeaMessageListener"]
        __javacontext__ = "app"

        def __init__(self, on_nmea):
            super().__init__()
            self._on_nmea = on_nmea

        @java_method("(Ljava/lang/String;J)V")
        def onNmeaMessage(self, message, timestamp):
            try:
                self._on_nmea(message)
            except Exception:  # noqa: BLE001
                pass

    _CLASS_CACHE[key] = (SensorListener, LocationListener, NmeaListener)
    return _CLASS_CACHE[key]


def location_values(location) -> tuple:
    """The ``gps`` values of an ``android.location.Location`` (nan where the fix has no such value).

    ``(lat_deg, lon_deg, alt_m, hacc_m, speed_m_s, course_deg)``, the columns
    of :data:`core.recording.STREAM_SPECS`: ``getSpeed()`` when ``hasSpeed()``,
    ``getBearing()`` (degrees clockwise from true north, the direction of
    travel, not the phone's) when ``hasBearing()``.
    """
    alt = float(location.getAltitude()) if location.hasAltitude() else math.nan
    acc = float(location.getAccuracy()) if location.hasAccuracy() else math.nan
    speed = float(location.getSpeed()) if location.hasSpeed() else math.nan
    course = float(location.getBearing()) if location.hasBearing() else math.nan
    return (float(location.getLatitude()), float(location.getLongitude()), alt, acc, speed, course)


def rotvec_quaternion(values) -> tuple:
    """Android ``TYPE_ROTATION_VECTOR`` values to an ENU<-device quaternion ``(w, x, y, z)``."""
    x, y, z = float(values[0]), float(values[1]), float(values[2])
    w = float(values[3]) if len(values) > 3 else math.sqrt(max(0.0, 1.0 - x * x - y * y - z * z))
    return (w, x, y, z)


class AndroidSource(SensorSource):
    """Live sensors on Android through pyjnius listeners (see the module docstring).

    Parameters
    ----------
    rate_hz : float
        Requested sampling rate; a hint to Android, capped at :data:`MAX_RATE_HZ`.
    streams : tuple of str
        Sensor streams to register (``"acc"``, ``"gyro"``, ``"mag"``, optionally ``"rotvec"``).
    gps : bool
        Also start GNSS (needs the location permission granted at run time;
        :meth:`start_gps` can be called again once it is).
    jnius : module, optional
        The ``jnius`` module; imported lazily when ``None`` (tests inject a fake).
    queue_max : int
        Capacity of the event queue (about 100 s at 3 x 100 Hz by default).
    context : android.content.Context, optional
        Where the system services come from: the foreground service (``PythonService.mService``) in the
        tracking service's process, which has no activity; default the app's ``PythonActivity``.
    """

    kind = "android"
    live = True

    def __init__(self, *, rate_hz: float = 100.0, streams=(ACC, GYRO, MAG, PRESSURE), gps: bool = True,
                 jnius=None, queue_max: int = 30000, context=None, java_buffer: bool = True,
                 poll_interval_s: float = POLL_INTERVAL_S, clock: Callable[[], float] = time.monotonic):
        super().__init__()
        self.java_buffer = java_buffer
        self.poll_interval_s = float(poll_interval_s)
        self._clock = clock
        self._buffers: list = []  # (stream, EventBuffer) while the Java listener is used
        self._buffer_drops: dict = {}
        self._last_poll = -math.inf
        #: "java buffer" (EventBuffer in the APK) or "python listener" (a PythonJavaClass per sensor)
        self.listener_kind = ""
        self._context = context
        self.rate_hz = float(rate_hz)
        self.period_us = sampling_period_us(rate_hz)
        self.streams = tuple(streams)
        self.want_gps = gps
        self.queue = EventQueue(queue_max)
        self._jnius = jnius
        self._accuracy: dict = {}
        self.missing: list[str] = []
        self.sensor_info: dict = {}
        self.gps_status = "off"
        self._listeners: list = []
        self._location_listener = None
        self.location_provider = None  #: "gps", "fused" or "network" while fixes are asked for
        self._sm = None
        self._lm = None
        self._thread = None
        self.callback_errors = 0

    # -- jnius access (lazy) -----------------------------------------------------

    def _import_jnius(self):
        if self._jnius is None:
            try:
                import jnius  # noqa: PLC0415 - Android only, deliberately lazy
            except Exception as e:  # ImportError on the desktop; JVM errors on odd builds
                raise SensorStartError(f"pyjnius not available: {e}") from e
            self._jnius = jnius
        return self._jnius

    def _activity(self):
        if self._context is not None:
            return self._context
        return self._jnius.autoclass("org.kivy.android.PythonActivity").mActivity

    # -- callbacks (sensor thread) --------------------------------------------------

    def _on_event(self, stream, t_ns, values):
        if stream == ROTVEC:
            vals = rotvec_quaternion(values)
        elif stream == PRESSURE:
            vals = (float(values[0]),)
        else:
            vals = (float(values[0]), float(values[1]), float(values[2]))
        self.queue.push((stream, int(t_ns), vals))

    def _on_accuracy(self, stream, accuracy):
        self._accuracy[stream] = accuracy

    def _on_location(self, location):
        t_ns = int(location.getElapsedRealtimeNanos())
        self.queue.push((GPS, t_ns, location_values(location)))

    # -- lifecycle -------------------------------------------------------------------

    def start(self) -> None:
        if self.running:
            return
        jn = self._import_jnius()
        try:
            self._start_sensors(jn)
        except SensorStartError:
            self._unregister()
            raise
        except Exception as e:  # JavaException and friends
            self._unregister()
            raise SensorStartError(f"sensor listener failed to start: {e}") from e
        self.running = True
        if self.want_gps:
            self.start_gps()

    def _start_sensors(self, jn):
        autoclass = jn.autoclass
        Context = autoclass("android.content.Context")
        activity = self._activity()
        self._sm = activity.getSystemService(Context.SENSOR_SERVICE)
        HandlerThread = autoclass("android.os.HandlerThread")
        Handler = autoclass("android.os.Handler")
        self._thread = HandlerThread("pdr-sensors")
        self._thread.start()
        handler = Handler(self._thread.getLooper())
        SensorListener = _java_classes(jn)[0]
        Buffer = self._buffer_class(jn)
        self.listener_kind = "java buffer" if Buffer is not None else "python listener"
        self._buffers = []
        self.missing = []
        for name in self.streams:
            sensor = self._sm.getDefaultSensor(ANDROID_SENSOR_TYPES[name])
            if sensor is None:
                self.missing.append(name)
                continue
            if Buffer is not None:
                listener = Buffer(BUFFER_CAPACITY, BUFFER_WIDTH[name])
            else:
                listener = SensorListener(name, self._on_event, self._on_accuracy)
            # (listener, sensor, samplingPeriodUs, maxReportLatencyUs=0: no batching, handler)
            if not self._sm.registerListener(listener, sensor, self.period_us, 0, handler):
                self.missing.append(name)
                continue
            # keep a Python reference while Java holds the proxy, and the sensor for unregisterListener
            self._listeners.append((listener, sensor))
            if Buffer is not None:
                self._buffers.append((name, listener))
            self.sensor_info[name] = _sensor_info(sensor)
        if ACC in self.missing or not self._listeners:
            raise SensorStartError("no accelerometer could be registered")
        missing = [n for n in self.missing if n not in OPTIONAL_STREAMS]
        self.warning = ("missing sensor(s): " + ", ".join(missing)) if missing else ""
        self.device = {"platform": "android", "requested_rate_hz": min(self.rate_hz, MAX_RATE_HZ),
                       "sampling_period_us": self.period_us, "sensors": dict(self.sensor_info),
                       "listener": self.listener_kind}
        try:
            clock = autoclass("android.os.SystemClock")
            self.unix_offset_ns = int(time.time_ns() - int(clock.elapsedRealtimeNanos()))
        except Exception:  # noqa: BLE001 - only used for absolute times in exports
            self.unix_offset_ns = None
        try:
            Build = autoclass("android.os.Build")
            VERSION = autoclass("android.os.Build$VERSION")
            self.device.update(manufacturer=str(Build.MANUFACTURER), model=str(Build.MODEL),
                               android_sdk=int(VERSION.SDK_INT))
        except Exception:  # noqa: BLE001 - cosmetic
            pass

    def _buffer_class(self, jn):
        """The Java listener class when the APK has it (and it is wanted), else None: the Python listener."""
        if not self.java_buffer:
            return None
        try:
            return jn.autoclass(BUFFER_CLASS)
        except Exception:  # noqa: BLE001 - JavaException "Class not found": an APK built without add_src
            return None

    def poll_buffers(self) -> int:
        """Take every Java buffer's events into the queue, all sensors merged in timestamp order (as a
        listener per event would have pushed them); returns how many."""
        batch = []
        for name, buf in self._buffers:
            try:
                n = buf.take()
                if n:
                    batch += _buffer_events(name, buf.takenTimes(), buf.takenValues(), n)
                self._buffer_drops[name] = int(buf.dropped())
                acc = int(buf.accuracy())
                if acc >= -1:
                    self._accuracy[name] = acc
            except Exception:  # noqa: BLE001 - a poll lost, not the walk
                self.callback_errors += 1
        if batch:
            batch.sort(key=_event_time)
            self.queue.push_many(batch)
        self._last_poll = self._clock()
        return len(batch)

    def start_gps(self) -> bool:
        """Start GNSS updates with our own listener, from the provider the grant allows; True when running."""
        if self._location_listener is not None:
            return True
        from app.android_platform import location_grant, sdk_int  # noqa: PLC0415 - jnius-free module

        jn = self._jnius
        try:
            ctx = self._activity()
            grant = location_grant(ctx)
            if grant is None:
                self.gps_status = "off (no location permission)"
                return False
            autoclass = jn.autoclass
            Context = autoclass("android.content.Context")
            LocationManager = autoclass("android.location.LocationManager")
            LocationListener, NmeaListener = _java_classes(jn)[1:]
            self._lm = ctx.getSystemService(Context.LOCATION_SERVICE)
            provider = self._provider(LocationManager, grant, sdk_int(jn))
            listener = LocationListener(self._on_location)
            # (provider, minTimeMs, minDistanceM, listener, looper): fixes delivered on the sensor thread
            self._lm.requestLocationUpdates(provider, 1000, 0.0, listener, self._thread.getLooper())
        except Exception as e:  # noqa: BLE001 - SecurityException, a provider switched off, ...
            self.gps_status = f"off ({e})"
            return False
        self._location_listener = listener
        self.location_provider = str(provider)
        approx = "" if grant == "fine" else ", approximate location only"
        self.gps_status = f"on ({provider} provider{approx}; LocationListener, elapsed-realtime timestamps)"
        if grant == "fine":  # satellites only from the GNSS chip
            self._start_nmea(NmeaListener)
        return True

    def _provider(self, LocationManager, grant: str, sdk: int):
        """``GPS_PROVIDER`` with precise location; with approximate only, ``FUSED_PROVIDER`` (API 31+, when
        the phone has it), else ``NETWORK_PROVIDER`` (``GPS_PROVIDER`` would throw)."""
        if grant == "fine":
            return LocationManager.GPS_PROVIDER
        if sdk >= 31:
            try:
                if self._lm.hasProvider(LocationManager.FUSED_PROVIDER):
                    return LocationManager.FUSED_PROVIDER
            except Exception:  # noqa: BLE001
                pass
        return LocationManager.NETWORK_PROVIDER

    def _start_nmea(self, NmeaListener) -> None:
        """Satellite C/N0 from the NMEA stream, as ``gnss_status`` events stamped on arrival (best effort)."""
        jn = self._jnius
        try:
            SystemClock = jn.autoclass("android.os.SystemClock")
            Handler = jn.autoclass("android.os.Handler")
            parser = NmeaSatelliteStatus()

            def on_nmea(message):
                status = parser.update(str(message))
                if status is not None:
                    self.queue.push((GNSS_STATUS, int(SystemClock.elapsedRealtimeNanos()), status))

            listener = NmeaListener(on_nmea)
            self._lm.addNmeaListener(listener, Handler(self._thread.getLooper()))
            self._nmea_listener = listener
            self.gps_status += "; satellite C/N0 from NMEA"
        except Exception as e:  # noqa: BLE001 - an old phone or a chip without NMEA: the fixes still come
            self.gps_status += f"; no satellite C/N0 ({e})"

    def stop(self) -> None:
        self._unregister()
        self.running = False

    def _unregister(self):
        if self._sm is not None:
            for listener, sensor in self._listeners:
                # the (listener, sensor) overload: with the listener alone pyjnius 1.7 scores the deprecated
                # unregisterListener(SensorListener) as high as unregisterListener(SensorEventListener) and
                # the tie goes to the former (the higher signature string), which CheckJNI aborts on
                try:
                    self._sm.unregisterListener(listener, sensor)
                except Exception:  # noqa: BLE001
                    pass
        if self._buffers:
            self.poll_buffers()  # what came before the listeners went
            self._buffers = []
        self._listeners = []
        if self._lm is not None and self._location_listener is not None:
            try:
                self._lm.removeUpdates(self._location_listener)
            except Exception:  # noqa: BLE001
                pass
        self._location_listener = None
        if self._lm is not None and getattr(self, "_nmea_listener", None) is not None:
            try:
                self._lm.removeNmeaListener(self._nmea_listener)
            except Exception:  # noqa: BLE001
                pass
        self._nmea_listener = None
        self.location_provider = None
        if self._thread is not None:
            try:
                self._thread.quitSafely()
            except Exception:  # noqa: BLE001
                pass
            self._thread = None
        self.gps_status = "off"

    # -- consumer side -----------------------------------------------------------

    def drain(self, max_events: int | None = None) -> list:
        if self._buffers and self._clock() - self._last_poll >= self.poll_interval_s:
            self.poll_buffers()
        return self.queue.drain(max_events)

    def queue_drops(self) -> dict:
        drops = Counter(self.queue.dropped)
        drops.update(self._buffer_drops)
        return {k: v for k, v in drops.items() if v}

    def accuracy(self) -> dict:
        return dict(self._accuracy)

    @property
    def listener_errors(self) -> int:
        """Exceptions caught inside the sensor callbacks (each one lost an event)."""
        return sum(getattr(lst, "errors", 0) for lst, _sensor in self._listeners)

    def describe(self) -> str:
        kind = f", {self.listener_kind}" if self.listener_kind else ""
        return f"android sensors at {min(self.rate_hz, MAX_RATE_HZ):g} Hz (requested{kind})"


def _event_time(event) -> int:
    return event[1]


def _buffer_events(name: str, times, values, n: int) -> list:
    """A Java buffer's ``n`` events (``long[]`` times, ``float[]`` values of :data:`BUFFER_WIDTH` each, as
    pyjnius gives them: lists) as the pipeline's ``(stream, t_ns, values)``."""
    if name == ROTVEC:
        w = BUFFER_WIDTH[ROTVEC]
        return [(name, times[k], rotvec_quaternion([x for x in values[k * w:(k + 1) * w] if x == x]))
                for k in range(n)]
    if BUFFER_WIDTH[name] == 1:
        return [(name, t, (v,)) for t, v in zip(times, values)]
    it = iter(values)
    return [(name, t, (a, b, c)) for t, a, b, c in zip(times, it, it, it)]


def _sensor_info(sensor) -> dict:
    info = {}
    for key, getter in (("name", "getName"), ("vendor", "getVendor"), ("min_delay_us", "getMinDelay"),
                        ("resolution", "getResolution"), ("max_range", "getMaximumRange")):
        try:
            v = getattr(sensor, getter)()
            info[key] = v if isinstance(v, (int, float)) else str(v)
        except Exception:  # noqa: BLE001 - informational only
            pass
    return info


# ---------------------------------------------------------------------------
# plyer fallback


PLYER_FALLBACK_WARNING = ("Sensor listener unavailable, using plyer at about 5 Hz without sensor timestamps: "
                          "step timing and heading are unreliable")


class PlyerFallbackSource(SensorSource):
    """plyer's accelerometer / gyroscope / compass facades, polled from the UI clock.

    plyer keeps only the latest value and no timestamp, so each *changed*
    value is stamped with ``clock()`` when it is polled (a repeated value is
    assumed to be the same event).  Always carries :data:`PLYER_FALLBACK_WARNING`.
    """

    kind = "plyer"
    live = True

    def __init__(self, *, plyer=None, clock: Callable[[], int] = time.monotonic_ns, reason: str = ""):
        super().__init__()
        self._plyer = plyer
        self._clock = clock
        self.reason = reason
        self.warning = PLYER_FALLBACK_WARNING + (f" ({reason})" if reason else "")
        self._facades: dict = {}
        self._last: dict = {}
        self.device = {"platform": "android", "source": "plyer (SENSOR_DELAY_NORMAL, poll-time stamps)"}

    def start(self) -> None:
        if self.running:
            return
        if self._plyer is None:
            import plyer  # noqa: PLC0415

            self._plyer = plyer
        wanted = {ACC: ("accelerometer", "acceleration"), GYRO: ("gyroscope", "rotation"),
                  MAG: ("compass", "field")}
        self._facades = {}
        for name, (facade, attr) in wanted.items():
            try:
                f = getattr(self._plyer, facade)
                f.enable()
                self._facades[name] = (f, attr)
            except Exception:  # noqa: BLE001 - NotImplementedError on desktop, missing sensor
                pass
        if ACC not in self._facades:
            raise SensorStartError("plyer accelerometer unavailable")
        self.running = True

    def stop(self) -> None:
        for f, _ in self._facades.values():
            try:
                f.disable()
            except Exception:  # noqa: BLE001
                pass
        self._facades = {}
        self.running = False

    def drain(self, max_events: int | None = None) -> list:
        if not self.running:
            return []
        t = int(self._clock())
        out = []
        for name, (f, attr) in self._facades.items():
            try:
                v = getattr(f, attr)
            except Exception:  # noqa: BLE001
                continue
            if v is None or len(v) < 3 or any(x is None for x in v[:3]):
                continue
            vals = (float(v[0]), float(v[1]), float(v[2]))
            if self._last.get(name) == vals:
                continue
            self._last[name] = vals
            out.append((name, t, vals))
        return out


def make_live_source(*, rate_hz: float = 100.0, gps: bool = True, jnius=None, plyer=None,
                     context=None) -> SensorSource:
    """Start the Android listener source, or plyer's facades with a visible warning.

    Returns a *started* source.  Raises :class:`SensorStartError` if neither works.
    ``context``: see :class:`AndroidSource` (the tracking service passes its own).
    """
    src = AndroidSource(rate_hz=rate_hz, gps=gps, jnius=jnius, context=context)
    try:
        src.start()
        return src
    except SensorStartError as e:
        fallback = PlyerFallbackSource(plyer=plyer, reason=str(e))
        fallback.start()
        return fallback
