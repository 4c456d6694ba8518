"""The tracking service: sensors, pipeline and recorder off the UI thread, with a small IPC for the UI.

Why a service
    Android delivers no sensor events to an app in the background (Android 9+), and a
    screen-off phone stops delivering non-wake-up sensors unless something holds a partial
    wake lock.  A walk with the phone in a pocket therefore runs in a *foreground service*:
    p4a starts ``app/service_main.py`` in its own process (``services = Tracker:...`` in
    ``buildozer.spec``), with a persistent notification.  That process owns the
    :class:`app.session.Session` (source -> reorder -> pipeline, recorder, floors); the UI
    only draws what it is told.  The per-event work is thus off the Kivy thread too (issue
    #14, item 4), and the listener queue is drained in batches by :meth:`TrackingService.step`.

The type: ``foregroundServiceType=location``
    Android 14+ requires a type, its permission (``FOREGROUND_SERVICE_LOCATION``) and a run-time
    prerequisite: a location permission granted.  The app asks for location anyway (GPS fusion),
    and only a location-type service may receive location updates while the screen is off
    without ``ACCESS_BACKGROUND_LOCATION``.  ``health`` would need ``ACTIVITY_RECOGNITION`` (one
    more dialog) or ``HIGH_SAMPLING_RATE_SENSORS`` (Play policy review) and would still lose GPS
    in the background.  Without a location grant the UI does not start the service (startForeground
    would throw a SecurityException) and tracks in its own process, screen on only, and says so.

IPC: a Unix-domain stream socket, one JSON object a line
    p4a's examples use OSC (``oscpy``): UDP datagrams, one message each way, no reply, a size
    limit per datagram, and the ``INTERNET`` permission for the localhost port.  The UI here needs
    request/reply (a poll returns what is new since what the UI holds) and, after a reopen,
    the whole track (7 000 steps an hour, plus the fused track and the fixes) in one answer.  A
    Unix socket in the app's private files directory gives that with the standard library, no
    permission and no port another app could reach; reading the recording file instead would
    make the UI re-run the pipeline over an hour of events.  The protocol:

    request ``{"op": "poll", "track_id": k, "since": {"track": n, "fused": m, "fused_source": j,
    "fix": f}}`` -> ``{"ok": true, "track_id": k', "status": {...}, "track": [east, north], ...}``
    with the lists' new items (all of them when ``k != k'``: a new track, or a new UI; or when the request's
    ``"view"`` is not the session's :attr:`app.session.Session.view_generation`, returned as ``"view"``: the
    session thinned its lists, issue #30).  Every
    other op (``pause``, ``resume``, ``record``, ``new_track``, ``calibration``, ``calibrate``,
    ``export``, ``here``, ``plan``, ``stop``) replies with the fresh ``status`` too.

The floor plan
    The service reads the chosen plan from the settings at its start, on ``new_track`` and on ``plan``
    (the user chose another: a new track id, so the UI fetches the map lists anew) and runs the particle
    filter in its session (:class:`app.indoor.MapMatcher`), so the map matching goes on with the screen
    off; ``here`` is the user's "I am here" (plan metres).  A poll brings the map-matched track's new points
    (``"map"``) and the status the estimate, its covariance and the health line (``status["map"]``).

Desktop
    :class:`InProcessService` runs the same :class:`TrackingService` and socket server in
    threads of the app's own process, so the UI talks to it exactly as on the phone and the tests
    exercise the real path (:class:`ServiceSession` is the UI's side).
"""

from __future__ import annotations

import json
import math
import os
import socket
import socketserver
import tempfile
import threading
import time
from typing import Callable

from app.session import GpsOverlay, Session

#: the p4a service's name (``services = Tracker:...``): its Java class is ``<package>.ServiceTracker``
SERVICE_NAME = "Tracker"
#: p4a numbers services from 1 in the order of the spec; the foreground notification has this id
NOTIFICATION_ID = 1
NOTIFICATION_CHANNEL = "pdr-tracking"
#: the notification is updated at most this often (s)
NOTIFY_INTERVAL_S = 2.0
SOCKET_NAME = "tracker.sock"
#: what the service was started with, ``active`` while it tracks (app.android_platform.take_interrupted_walk)
CONFIG_FILE = "service.json"


class ServiceUnavailable(OSError):
    """No tracking service answers on the socket."""


def socket_path(data_dir: str) -> str:
    """The socket in ``data_dir`` (the app's private files on the phone); a short path in the temporary
    directory when that one is too long for ``sun_path`` (108 bytes on Linux)."""
    path = os.path.join(os.path.abspath(data_dir), SOCKET_NAME)
    if len(path.encode()) < 100:
        return path
    import hashlib  # noqa: PLC0415

    tag = hashlib.sha1(path.encode()).hexdigest()[:16]
    return os.path.join(tempfile.gettempdir(), f"pdr-{tag}.sock")


def _finite(x):
    return x if isinstance(x, (int, float)) and math.isfinite(x) else None


# ---------------------------------------------------------------------------------------------
# the service side


class TrackingService:
    """One live (or, in tests, replayed) session, driven by :meth:`step` and queried by :meth:`handle`.

    Parameters
    ----------
    config : dict
        ``data_dir`` (settings and profile), ``record_path`` (None: not recording), ``metadata``
        (the recording's), ``out_dir``.
    source_factory : callable
        ``rate_hz -> started SensorSource`` (on the phone :func:`app.sources.make_live_source` with the
        service's context).
    hooks : object, optional
        The phone's side (:class:`app.android_ui.ServiceHooks`): ``acquire()``/``release()`` the
        partial wake lock, ``notify(title, text)``.  None on the desktop.
    clock : callable
        Seconds, for the notification's pace and the session's tick budget (tests inject one).
    on_stopping : callable, optional
        Called first when the walk stops, before the sensors and the recording (the phone clears
        ``service.json``'s ``active`` there).
    """

    def __init__(self, config: dict, *, source_factory: Callable, hooks=None,
                 clock: Callable[[], float] = time.monotonic, on_stopping: Callable | None = None):
        self.config = dict(config)
        self.on_stopping = on_stopping
        self.source_factory = source_factory
        self.hooks = hooks
        self.clock = clock
        self.lock = threading.RLock()
        self.session: Session | None = None
        self.track_id = 0
        self.stopped = False
        self.rate_hz = None
        self.message = ""
        self._last_notify = -math.inf
        self._notified = None

    # -- settings (the UI's files: read fresh each time, never saved stale) ---------------------

    @property
    def settings_path(self) -> str:
        from app.settings import SETTINGS_FILE  # noqa: PLC0415

        return os.path.join(self.config["data_dir"], SETTINGS_FILE)

    def _settings(self):
        from app.settings import Settings  # noqa: PLC0415

        return Settings.load(self.settings_path)

    # -- lifecycle ----------------------------------------------------------------------------------

    def start(self) -> None:
        settings = self._settings()
        self.rate_hz = settings.live_rate_hz()
        source = self.source_factory(self.rate_hz)
        factory = self.config.get("pipeline_factory") or settings.pipeline_factory()
        plan, name, problem = settings.load_floor_plan()
        if problem:
            self.message = problem
        self.session = Session(source, pipeline_factory=factory, record_path=self.config.get("record_path"),
                               metadata=self.config.get("metadata"), clock=self.clock, plan=plan, plan_name=name)
        self.session.start()
        if self.hooks is not None:
            self.hooks.acquire()
        self._notify(force=True)

    def step(self, budget_s: float = 0.01) -> int:
        """Drain the source and run the pipeline (bounded time); returns the steps completed."""
        with self.lock:
            if self.stopped or self.session is None:
                return 0
            new = self.session.tick(budget_s)
            self._notify()
            return len(new)

    def stop(self) -> int:
        """Finish the track, close the recording, keep what GPS taught, release the wake lock."""
        with self.lock:
            if self.stopped:
                return 0
            if self.on_stopping is not None:  # first: the phone clears service.json's `active`
                try:
                    self.on_stopping()
                except Exception as e:  # noqa: BLE001 - never lose the stop over it
                    self.message = f"stop not saved: {e}"
            ses = self.session
            n = 0
            if ses is not None:
                ses.close()
                n = ses.stop_recording()
                if ses.source.live:
                    try:
                        s = self._settings()
                        if s.learn_from_gps(ses.pipeline):
                            s.save(self.settings_path)
                    except Exception as e:  # noqa: BLE001 - never lose the stop over the profile
                        self.message = f"profile not saved: {e}"
            self.stopped = True
            if self.hooks is not None:
                self.hooks.release()
            return n

    def _notify(self, force: bool = False) -> None:
        if self.hooks is None or self.session is None:
            return
        now = self.clock()
        if not force and now - self._last_notify < NOTIFY_INTERVAL_S:
            return
        self._last_notify = now
        text = notification_text(self.session)
        if text != self._notified:
            self._notified = text
            try:
                self.hooks.notify("PDR Tracker", text)
            except Exception as e:  # noqa: BLE001 - a notification is never worth the walk
                self.message = f"notification failed: {e}"

    # -- the IPC's requests ------------------------------------------------------------------------

    def handle(self, req: dict) -> dict:
        op = req.get("op")
        with self.lock:
            ses = self.session
            if ses is None:
                return {"ok": False, "error": "not started"}
            fn = getattr(self, f"_op_{op}", None)
            if fn is None:
                return {"ok": False, "error": f"unknown op {op!r}"}
            try:
                out = fn(ses, req) or {}
            except Exception as e:  # noqa: BLE001 - a bad request must not stop the walk
                out = {"ok": False, "error": f"{type(e).__name__}: {e}"}
            out.setdefault("ok", True)
            out["track_id"] = self.track_id
            out["view"] = ses.view_generation
            out["status"] = self.status()
            return out

    def status(self) -> dict:
        ses = self.session
        summ = dict(ses.summary())
        summ["labels"] = list(summ["labels"])
        g = ses.gps_overlay()
        m = ses.map_overlay()
        src = ses.source
        return {"summary": summ, "running": ses.running, "finished": ses.finished, "stopped": self.stopped,
                "recording": ses.writer is not None, "record_path": ses.record_path,
                "record_error": ses.record_error, "events_in": ses.events_in, "errors": ses.errors,
                "last_error": ses.last_error, "warning": src.warning, "source_text": src.describe(),
                "live": bool(src.live), "progress": float(getattr(src, "progress", 0.0)),
                "unix_offset_ns": src.unix_offset_ns, "rate_hz": self.rate_hz,
                "calibrating": ses.calibrating, "calibration_range_ns": ses.calibration_range_ns,
                "calibration_distance_m": ses.calibration_distance_m(), "health": ses.health_text(),
                "message": self.message,
                "gps": None if g is None else {"n_fixes": g.n_fixes, "n_used": g.n_used, "cov_en_m2": g.cov_en_m2,
                                               "anchored": g.anchored, "fusion": g.fusion,
                                               "last_verdict": g.last_verdict},
                "map": None if m is None else {"position": m.position, "cov": m.cov, "raw_offset": m.raw_offset,
                                               "placed": m.placed, "text": m.text, "bias_rad": m.bias_rad}}

    def _op_poll(self, ses, req):
        since = req.get("since") or {}
        # another track, or the session thinned its lists since the UI's ("view": Session.view_generation)
        if req.get("track_id") != self.track_id or req.get("view", ses.view_generation) != ses.view_generation:
            since = {}
        a, f, j, x, m = (int(since.get(k, 0)) for k in ("track", "fused", "fused_source", "fix", "map"))
        mm = ses.map
        return {"map": [mm.east[m:], mm.north[m:]] if mm is not None else [[], []],"track": [ses.track_east[a:], ses.track_north[a:]],
                "fused": [ses.fused_east[f:], ses.fused_north[f:], ses.fused_source[j:]],
                "fixes": [ses.fix_east[x:], ses.fix_north[x:], ses.fix_hacc[x:], ses.fix_accepted[x:]]}

    def _op_ping(self, ses, req):
        return {}

    def _op_pause(self, ses, req):
        ses.pause()

    def _op_resume(self, ses, req):
        ses.resume()

    def _op_record(self, ses, req):
        if req.get("on"):
            ses.start_recording(req["path"], req.get("metadata"))
            return {}
        return {"events": ses.stop_recording()}

    def _op_new_track(self, ses, req):
        """A new track with the settings as saved now: a new pipeline, and the sensors at the new rate."""
        settings = self._settings()
        rate = settings.live_rate_hz()
        if ses.source.live and rate != self.rate_hz:
            ses.replace_source(self.source_factory(rate))
            self.rate_hz = rate
        ses.pipeline_factory = self.config.get("pipeline_factory") or settings.pipeline_factory()
        plan, ses.plan_name, self.message = settings.load_floor_plan()
        ses.plan = plan
        ses.reset_track()
        self.track_id += 1
        return {"rate_hz": rate}

    def _op_calibration(self, ses, req):
        if req.get("action") == "start":
            ses.start_calibration()
            return {}
        return {"distance_m": ses.stop_calibration()}

    def _op_calibrate(self, ses, req):
        from core.pdr.calibration import CalibrationError  # noqa: PLC0415

        settings = self._settings()
        try:
            res = settings.calibrate(ses.calibration_steps(), str(req.get("known", "")).strip())
        except CalibrationError as e:
            return {"ok": False, "error": str(e)}
        settings.save(self.settings_path)
        return {"scale": res.scale, "n_steps": res.n_steps, "model_distance_m": res.model_distance_m,
                "warnings": list(res.warnings)}

    def _op_here(self, ses, req):
        ses.here(float(req["east"]), float(req["north"]))

    def _op_plan(self, ses, req):
        """The floor plan as saved now (the user chose another, or none): placed anew."""
        plan, name, problem = self._settings().load_floor_plan()
        ses.set_plan(plan, name)
        self.message = problem
        self.track_id += 1  # the UI fetches the lists anew (the map's are new)
        return {"problem": problem}

    def _op_export(self, ses, req):
        return {"export": ses.export(req["out_dir"], req["basename"], raw_path=req.get("raw_path"))}

    def _op_stop(self, ses, req):
        return {"events": self.stop()}


def notification_text(session) -> str:
    """The notification's line: steps, distance, and whether it records or is paused."""
    s = session.summary()
    text = f"{s['steps']} steps · {s['distance_m']:.0f} m"
    if not session.running:
        text += " · paused"
    elif session.writer is not None:
        text += " · recording"
    if session.record_error:
        text += " · recording stopped"
    return text


class _Handler(socketserver.StreamRequestHandler):
    def handle(self):
        for line in self.rfile:
            try:
                req = json.loads(line)
                resp = self.server.service.handle(req if isinstance(req, dict) else {})
            except ValueError as e:
                req, resp = {}, {"ok": False, "error": f"bad request: {e}"}
            try:
                self.wfile.write((json.dumps(resp) + "\n").encode("utf-8"))
                self.wfile.flush()
            except OSError:
                return
            if req.get("op") == "stop":
                self.server.on_stop()


class _Server(socketserver.ThreadingMixIn, socketserver.UnixStreamServer):
    daemon_threads = True
    allow_reuse_address = True


class ServiceServer:
    """The socket the UI talks to (one thread per connection; requests go through the service's lock)."""

    def __init__(self, service: TrackingService, path: str):
        self.path = path
        if os.path.exists(path):
            if service_answers(path):
                raise OSError(f"a tracking service already answers on {path}")
            os.unlink(path)  # left by a killed service
        self._srv = _Server(path, _Handler)
        self._srv.service = service
        self._srv.on_stop = self._on_stop
        self.stopped = threading.Event()
        self._thread = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._srv.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="pdr-service-ipc", daemon=True)
        self._thread.start()

    def _on_stop(self):
        self.stopped.set()

    def close(self) -> None:
        self._srv.shutdown()
        self._srv.server_close()
        try:
            os.unlink(self.path)
        except OSError:
            pass


def run_service(config: dict, source_factory: Callable, *, hooks=None, stop: threading.Event | None = None,
                interval_s: float = 0.02, started: Callable | None = None,
                clock: Callable[[], float] = time.monotonic, on_stopping: Callable | None = None) -> TrackingService:
    """The service's main loop: start, serve the socket, step until stopped (by the UI's ``stop`` or by
    ``stop``), then close.  Runs in the p4a service process's main thread, or in a thread on the desktop.
    ``started(service)`` is called once the socket answers."""
    svc = TrackingService(config, source_factory=source_factory, hooks=hooks, clock=clock, on_stopping=on_stopping)
    svc.start()
    server = ServiceServer(svc, config["socket"])
    server.start()
    if started is not None:
        started(svc)
    stop = stop or threading.Event()
    try:
        while not svc.stopped and not stop.is_set():
            svc.step()
            if server.stopped.wait(interval_s):
                break
    finally:
        svc.stop()
        server.close()
    return svc


class InProcessService:
    """The desktop's service: :func:`run_service` in a thread of this process (same socket, same protocol)."""

    def __init__(self, config: dict, source_factory: Callable, *, interval_s: float = 0.02,
                 clock: Callable[[], float] = time.monotonic):
        self.config = config
        self._stop = threading.Event()
        self._ready = threading.Event()
        self.service: TrackingService | None = None
        self.error: BaseException | None = None

        def started(svc):
            self.service = svc
            self._ready.set()

        def run():
            try:
                run_service(config, source_factory, stop=self._stop, started=started, interval_s=interval_s,
                            clock=clock)
            except BaseException as e:  # noqa: BLE001 - reported to the UI by start()
                self.error = e
                self._ready.set()

        self._thread = threading.Thread(target=run, name="pdr-service", daemon=True)

    def start(self, timeout_s: float = 10.0) -> None:
        """Start and wait until the socket answers; raises what the service raised at its start."""
        self._thread.start()
        self._ready.wait(timeout_s)
        if self.error is not None:
            raise self.error

    def stop(self, timeout_s: float = 10.0) -> None:
        self._stop.set()
        self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()


# ---------------------------------------------------------------------------------------------
# the UI side


def service_answers(path: str, timeout_s: float = 1.0) -> bool:
    """Does a tracking service answer on ``path``?"""
    try:
        ServiceClient(path, timeout_s=timeout_s).request("ping")
        return True
    except (OSError, ValueError):
        return False


class ServiceClient:
    """One connection to the service's socket (reconnects on the next request after an error)."""

    def __init__(self, path: str, timeout_s: float = 5.0):
        self.path = path
        self.timeout_s = timeout_s
        self._sock = None
        self._file = None

    def request(self, op: str, **kw) -> dict:
        try:
            if self._sock is None:
                s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                s.settimeout(self.timeout_s)
                s.connect(self.path)
                self._sock, self._file = s, s.makefile("rb")
            self._sock.sendall((json.dumps({"op": op, **kw}) + "\n").encode("utf-8"))
            line = self._file.readline()
            if not line:
                raise ServiceUnavailable("the tracking service closed the connection")
            return json.loads(line)
        except OSError as e:
            self.close()
            raise ServiceUnavailable(f"tracking service: {e}") from e

    def close(self) -> None:
        for x in (self._file, self._sock):
            try:
                if x is not None:
                    x.close()
            except OSError:
                pass
        self._sock = self._file = None


class RemoteSource:
    """What the UI reads of ``session.source`` when the source lives in the service."""

    kind = "service"

    def __init__(self):
        self.warning = ""
        self.text = "tracking service"
        self.live = True
        self.progress = 0.0
        self.unix_offset_ns = None
        self.running = True

    def describe(self) -> str:
        return self.text

    def stop(self) -> None:  # the UI's error path; the service keeps its own source
        pass


class ServiceSession:
    """The UI's view of the service's session: the same attributes and methods the app uses of
    :class:`app.session.Session`, filled by polling the socket (at most every ``poll_interval_s``).

    ``host``: the :class:`InProcessService` on the desktop (None on the phone: the service is its own
    process).  Closing the UI calls :meth:`detach` (the service goes on); :meth:`close` stops it.
    """

    def __init__(self, client: ServiceClient, *, host: InProcessService | None = None,
                 poll_interval_s: float = 0.1, clock: Callable[[], float] = time.monotonic):
        self.client = client
        self.host = host
        self.poll_interval_s = poll_interval_s
        self._clock = clock
        self._last_poll = -math.inf
        self.source = RemoteSource()
        self.track_id = None
        self.view = 0  #: the session's thinning of its view lists that ours come from (Session.view_generation)
        self.status_dict: dict = {}
        self.polls = 0
        self.error = ""
        self._new_lists()

    def _new_lists(self):
        # new list objects for a new track (the track view tells a new track by the lists' identity)
        self.track_east, self.track_north = [], []
        self.fused_east, self.fused_north, self.fused_source = [], [], []
        self.fix_east, self.fix_north, self.fix_hacc, self.fix_accepted = [], [], [], []
        self.map_east, self.map_north = [], []

    # -- talking to the service -----------------------------------------------------------------

    def _request(self, op: str, **kw) -> dict:
        resp = self.client.request(op, **kw)
        if "status" in resp:
            self._take_status(resp)
        return resp

    def _take_status(self, resp: dict) -> None:
        st = resp["status"]
        self.status_dict = st
        src = self.source
        src.warning, src.text, src.live = st["warning"], st["source_text"], st["live"]
        src.progress, src.unix_offset_ns, src.running = st["progress"], st["unix_offset_ns"], st["running"]

    def poll(self) -> list:
        """Fetch what is new; returns the indices of the new track points (steps)."""
        since = {"track": len(self.track_east), "fused": len(self.fused_east),
                 "fused_source": len(self.fused_source), "fix": len(self.fix_east), "map": len(self.map_east)}
        resp = self._request("poll", track_id=self.track_id, view=self.view, since=since)
        self.polls += 1
        if resp["track_id"] != self.track_id or resp.get("view", 0) != self.view:
            self.track_id, self.view = resp["track_id"], resp.get("view", 0)
            self._new_lists()
        n0 = len(self.track_east)
        east, north = resp["track"]
        self.track_east.extend(east)
        self.track_north.extend(north)
        fe, fn, fs = resp["fused"]
        self.fused_east.extend(fe)
        self.fused_north.extend(fn)
        self.fused_source.extend(fs)
        for lst, new in zip((self.fix_east, self.fix_north, self.fix_hacc, self.fix_accepted), resp["fixes"]):
            lst.extend(new)
        me, mn = resp.get("map", ([], []))
        self.map_east.extend(me)
        self.map_north.extend(mn)
        return list(range(n0, len(self.track_east)))

    def tick(self, budget_s: float | None = None, chunk: int | None = None) -> list:
        """The UI clock's call: poll when due; the service unreachable is shown, never raised."""
        now = self._clock()
        if now - self._last_poll < self.poll_interval_s:
            return []
        self._last_poll = now
        try:
            new = self.poll()
            self.error = ""
            return new
        except (OSError, ValueError, KeyError) as e:
            self.error = str(e)
            self.source.warning = ("starting the tracking service..." if not self.polls else
                                   f"tracking service not answering: {e}")
            return []

    # -- what the UI reads --------------------------------------------------------------------------

    def _st(self, key, default=None):
        return self.status_dict.get(key, default)

    def summary(self) -> dict:
        s = dict(self._st("summary") or {"steps": 0, "distance_m": 0.0, "heading_deg": math.nan,
                                         "elapsed_s": 0.0, "east_m": 0.0, "north_m": 0.0,
                                         "heading_rad": math.nan, "mag_trusted": False, "labels": [],
                                         "floor": None, "floor_changes": 0})
        s["labels"] = tuple(s.get("labels", ()))
        for k in ("heading_deg", "heading_rad"):
            if s.get(k) is None:
                s[k] = math.nan
        return s

    def gps_overlay(self) -> GpsOverlay | None:
        g = self._st("gps")
        if g is None:
            return None
        cov = tuple(g["cov_en_m2"]) if g["cov_en_m2"] is not None else None
        return GpsOverlay(self.fused_east or [0.0], self.fused_north or [0.0], self.fused_source, self.fix_east,
                          self.fix_north, self.fix_hacc, self.fix_accepted, g["n_fixes"], g["n_used"], cov,
                          g["anchored"], g["fusion"], g["last_verdict"])

    def map_overlay(self):
        """The service's map matching (:class:`app.indoor.MapOverlay`), None without a plan."""
        m = self._st("map")
        if m is None:
            return None
        from app.indoor import MapOverlay  # noqa: PLC0415

        cov = tuple(tuple(r) for r in m["cov"]) if m["cov"] is not None else None
        return MapOverlay(self.map_east, self.map_north, tuple(m["position"]) if m["position"] else None, cov,
                          tuple(m["raw_offset"]), bool(m["placed"]), m["text"], float(m.get("bias_rad", 0.0)))

    def health_text(self) -> str:
        return self._st("health", "")

    running = property(lambda self: bool(self._st("running", False)))
    finished = property(lambda self: bool(self._st("finished", False)))
    recording = property(lambda self: bool(self._st("recording", False)))
    record_path = property(lambda self: self._st("record_path"))
    record_error = property(lambda self: self._st("record_error", ""))
    events_in = property(lambda self: int(self._st("events_in", 0)))
    errors = property(lambda self: int(self._st("errors", 0)))
    last_error = property(lambda self: self._st("last_error", ""))
    calibrating = property(lambda self: bool(self._st("calibrating", False)))
    calibration_range_ns = property(lambda self: tuple(self._st("calibration_range_ns") or ()) or None)
    elapsed_s = property(lambda self: float(self.summary()["elapsed_s"]))

    def calibration_distance_m(self) -> float:
        return float(self._st("calibration_distance_m", 0.0))

    # -- what the UI asks ------------------------------------------------------------------------------

    def pause(self) -> None:
        self._request("pause")

    def resume(self) -> None:
        resp = self._request("resume")
        if not resp.get("ok"):
            from app.sources import SensorStartError  # noqa: PLC0415

            raise SensorStartError(resp.get("error", "the service could not restart the sensors"))

    def start_recording(self, path: str, metadata: dict | None = None) -> None:
        self._request("record", on=True, path=path, metadata=metadata)

    def stop_recording(self) -> int:
        return int(self._request("record", on=False).get("events", 0))

    def new_track(self) -> None:
        """A new track with the saved settings (the service re-reads them: pipeline and sampling rate)."""
        self._request("new_track")
        self.poll()

    def start_calibration(self) -> None:
        self._request("calibration", action="start")

    def stop_calibration(self) -> float:
        self.poll()  # the steps up to now
        return float(self._request("calibration", action="stop").get("distance_m", 0.0))

    def calibrate(self, known: str) -> dict:
        return self._request("calibrate", known=known)

    def here(self, east_m: float, north_m: float) -> None:
        """The user's "I am here" (plan metres), run by the service's particle filter."""
        resp = self._request("here", east=float(east_m), north=float(north_m))
        if not resp.get("ok"):
            raise ValueError(resp.get("error", "not placed"))
        self.poll()

    def set_plan(self, plan=None, name: str = "") -> str:
        """The service reads the floor plan saved in the settings again (``plan``, ``name``: the UI's copy,
        not sent); returns why it could not use it ("" when it could)."""
        resp = self._request("plan")
        self.poll()
        return resp.get("problem", "") or resp.get("error", "")

    def export(self, out_dir: str, basename: str, raw_path: str | None = None) -> dict:
        resp = self._request("export", out_dir=out_dir, basename=basename, raw_path=raw_path)
        if not resp.get("ok"):
            return {"errors": [resp.get("error", "export failed")]}
        return resp["export"]

    def detach(self) -> None:
        """The UI goes away; the service goes on recording."""
        self.client.close()

    def close(self) -> None:
        """Stop the service: the track is finished and the recording closed (then the service ends)."""
        try:
            self._request("stop")
        except OSError:
            pass
        self.client.close()
        if self.host is not None:
            self.host.stop()
