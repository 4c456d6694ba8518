"""One tracking session, without Kivy: source -> reorder -> Pipeline, recorder, health, track.

The Kivy app calls :meth:`Session.tick` from its clock (about 30 times a
second) and only draws what the session holds.  Everything here is plain
Python so that it is tested without a window.

Event flow per tick::

    source.drain()  --(raw, as delivered)-->  BackgroundRecorder.add  (one batch per tick to its writer
          |                                                           thread; fsync'ed every flush_interval_s)
          |
          v
    reorder buffer (events held reorder_window_ns, released in time order,
                    ties in core.recording.STREAM_ORDER)
          |
          v
    HealthMonitor.accept  (drops events that still go backwards in their stream)
          |
          v
    Pipeline.update  ->  new steps -> track
                         GPS fusion (when the pipeline has one): fused track, fixes, uncertainty

At the end of a finite source the buffer is flushed and ``Pipeline.finish``
completes the last steps, so a replay gives exactly the batch result of
:meth:`core.pdr.pipeline.Pipeline.run`.

GPS fusion
    A pipeline built with ``gnss=GpsFusion()`` (:meth:`app.settings.Settings.pipeline_factory`
    with "Use GPS" on) gives a fused track, one :class:`core.gnss.fusion.FusedStep` per step.
    The session keeps what the track view draws as plain lists, appended as steps and fixes
    come: :meth:`Session.gps_overlay` hands them out as a :class:`GpsOverlay`.

View lines, bounded (issue #30)
    A line the view draws (the dead-reckoned track, the fused one) that passes
    :data:`app.overlay.VIEW_MAX_POINTS` is thinned (:func:`app.overlay.thin_line`: the old part
    decimated, the last points whole) into new lists, and the fixes keep the last
    :data:`app.overlay.VIEW_MAX_FIXES` (what the view draws); new lists are a new track to the view
    (it redraws them whole) and :attr:`Session.view_generation` counts them (the service's UI then
    fetches them anew).  The exports read the whole tracks back from disk (``steps``, the fusion's).
    Fixes the fusion screened out (bad accuracy) carry no local position in their record;
    once the walk is anchored they are placed from their latitude/longitude, so the view can
    show them as rejected.

Floor plan (issue #16)
    A session given a :class:`core.indoor.FloorPlan` (``plan=``, or :meth:`Session.set_plan`) runs a
    :class:`app.indoor.MapMatcher` (a :class:`core.indoor.ParticleFilter`) beside the tracker: it
    starts at the user's "I am here" (:meth:`Session.here`, plan metres) or at a recording's landmark
    (:meth:`Session.start_map_at`), every completed step goes to ``pf.update(step)``, and a later
    "I am here" is a fix.  :meth:`Session.map_overlay` hands the view the map-matched track, the estimate
    and its covariance; the health panel gets the filter's diagnostics; exports carry the map-matched
    position per step beside the raw one.
"""

from __future__ import annotations

import heapq
import math
import os
import shutil
import time
from dataclasses import dataclass
from typing import Callable

from core.conventions import CARRY_WORDS, GPS, PRESSURE, bearing_deg
from core.export import StepFile
from core.floors import FloorEstimator, floors_at
from core.gnss.base import ANCHOR_MAX_HACC_M, FusedTrack
from core.geodesy import geodetic_to_enu
from core.recording import STREAM_ORDER, STREAM_SPECS

from app.health import HealthMonitor
from app.indoor import MapMatcher
from app.overlay import VIEW_MAX_FIXES, VIEW_MAX_POINTS, VIEW_RECENT_POINTS, thin_line
from app.recorder import BackgroundRecorder

_RANK = {n: i for i, n in enumerate(STREAM_ORDER)}
#: how a live recording's pressure stream is written (hPa, as Android reports it)
_PRESSURE_SPEC = {"columns": ["p_hpa"], "unit": "hPa", "note": "barometric pressure (hPa = mbar, as Android reports it)"}


def load_any_recording(path: str):
    """Read any recording ``core`` can read: ``core.importers.load_recording`` when it exists, else the
    project format, else the GetSensorData importer if the file looks like one."""
    try:
        from core.importers import load_recording  # noqa: PLC0415 - the importers' dispatcher
    except ImportError:
        load_recording = None
    if load_recording is not None:
        return load_recording(path)
    from core.recording import RecordingError, read_recording  # noqa: PLC0415

    try:
        return read_recording(path)
    except RecordingError:
        try:
            from core.importers import getsensordata  # noqa: PLC0415
            from core.importers._common import head_bytes, maybe_gunzip  # noqa: PLC0415

            head = maybe_gunzip(head_bytes(path), path).decode("utf-8", "replace")
            if getsensordata.looks_like(head):
                return getsensordata.read_getsensordata(path)
        except ImportError:
            pass
        raise


def reading_notes(rec) -> str:
    """What the app's warning line says about a recording it opens ("" for a clean one): the repairs made while
    reading (the first of them), then what the edge's validation only reported -- gaps, spikes
    (:mod:`core.validation`, ``rec.problems``) -- as ``pdr replay`` prints them (issue #30)."""
    parts = []
    if rec.repairs:
        parts.append(f"{len(rec.repairs)} repair(s) while reading: " + rec.repairs[0])
    reported = [f for f in getattr(rec, "problems", ()) if f.action == "reported"]
    if reported:
        more = f" (and {len(reported) - 1} more)" if len(reported) > 1 else ""
        parts.append(reported[0].text + more)
    return "; ".join(parts)


#: where each value of a ``gps`` event is (the columns of the stream spec; events carry no names)
_GPS_COLUMN = {c: i for i, c in enumerate(STREAM_SPECS[GPS]["columns"])}


def _gps_value(vals, column: str) -> float:
    """The value of ``column`` in a ``gps`` event's values, nan if the event is shorter (an older source)."""
    i = _GPS_COLUMN[column]
    return float(vals[i]) if len(vals) > i else math.nan


def _good_fix(vals, max_hacc_m: float = ANCHOR_MAX_HACC_M) -> bool:
    """A GNSS fix usable as the track's origin (finite, accuracy unknown or within ``max_hacc_m``: the
    fusion's anchor rule, as ``pdr replay``'s :func:`core.gnss.base.first_good_fix`)."""
    lat, lon = _gps_value(vals, "lat_deg"), _gps_value(vals, "lon_deg")
    hacc = _gps_value(vals, "hacc_m")
    return math.isfinite(lat) and math.isfinite(lon) and not (hacc > max_hacc_m)


@dataclass(frozen=True)
class GpsOverlay:
    """What the track view draws of the GPS fusion (plain data; lists are the session's own, append-only).

    Point ``k + 1`` of the fused track is the position after step ``k`` (point 0 is the start,
    like the dead-reckoned track); ``fused_source[k]`` is step ``k``'s ``"fused"`` or ``"dr"``.
    """

    fused_east: list  #: local ENU (m), the start (0, 0) first
    fused_north: list
    fused_source: list  #: one per step
    fix_east: list  #: fixes with a position, local ENU (m)
    fix_north: list
    fix_hacc: list  #: reported 68 % accuracy radius (m), nan if none
    fix_accepted: list  #: bool
    n_fixes: int  #: every fix the fusion saw (also those without a position)
    n_used: int  #: accepted fixes
    cov_en_m2: tuple | None  #: (var_e, cov_en, var_n) of the last fused step (m^2), None before a step
    anchored: bool  #: a good fix placed the walk on the map (the fused track is GPS-aided from then on)
    fusion: str = ""  #: the filter ("chen", "kubrak")
    last_verdict: str = ""  #: the last fix's verdict: "used", or why it was not


class Session:
    """A live or replayed walk.

    Parameters
    ----------
    source : app.sources.SensorSource
    pipeline_factory : callable
        ``() -> core.pdr.pipeline.Pipeline`` or a :class:`core.foot.tracker.FootTracker` (the same
        streaming interface; its steps are strides), called again on :meth:`reset_track`.
    record_path : str, optional
        Write every event (as delivered, before reordering) to this file.
    flush_interval_s : float
        The recording is written and fsync'ed at least this often while events come (by the
        recorder's writer thread, :mod:`app.recorder`).  A write error stops the recording
        (what was written stays) and is kept in :attr:`record_error`.
    reorder_window_ns : int
        How long events wait so that late events of other sensors can be put in order.
    clock : callable
        Wall clock in seconds (tests inject one).
    """

    def __init__(self, source, *, pipeline_factory: Callable, record_path: str | None = None,
                 record_streams: dict | None = None, device: dict | None = None, metadata: dict | None = None,
                 flush_interval_s: float = 0.5, reorder_window_ns: int = 50_000_000,
                 clock: Callable[[], float] = time.monotonic, recorder_factory: Callable = BackgroundRecorder,
                 plan=None, plan_name: str = ""):
        self.source = source
        self.plan, self.plan_name = plan, plan_name
        self.pipeline_factory = pipeline_factory
        self.flush_interval_s = float(flush_interval_s)
        self.reorder_window_ns = int(reorder_window_ns)
        self._clock = clock
        self.writer: BackgroundRecorder | None = None
        self._recorder_factory = recorder_factory
        self.record_error = ""  #: why the recording stopped by itself ("" while it has not)
        self._record_width: dict = {}
        self.record_path = record_path
        self._record_streams = record_streams
        self._record_meta = (device, metadata)
        self._last_flush = clock()
        self.errors = 0
        self.last_error = ""
        self.events_in = 0
        self.reset_track()

    # -- track state ------------------------------------------------------------

    def reset_track(self) -> None:
        """Start a new track (new pipeline, empty track and health); the recording goes on."""
        self.pipeline = self.pipeline_factory()
        self._describe_sensors()
        g = self.gnss
        if g is not None and not g.keep_history and g.history_dir is None:
            g.history_dir = self._steps_dir()  # its fused steps and fix records beside the recording too
        old = getattr(self, "steps", None)
        if old is not None:
            old.close()
        #: the track's steps, written to a temporary file beside the recording as they come and read back for
        #: the exports (issue #30: a list of them grew 4.6 MB an hour); ``len``, iteration, ``distance_m``
        self.steps = StepFile(directory=self._steps_dir())
        self.track_east = [0.0]
        self.track_north = [0.0]
        self.health = HealthMonitor()
        self._heap: list = []
        self._seq = 0
        self._max_t: int | None = None
        self.first_t_ns: int | None = None
        self.last_t_ns: int | None = None
        self.gps_origin: tuple | None = None
        self.finished = False
        self._cal_range: tuple | None = None
        self._cal_steps: list = []  # the calibration walk's steps, whole (their features fit the stride model)
        # the GPS fusion's output, as the view draws it (see GpsOverlay)
        self.fused_east = [0.0]
        self.fused_north = [0.0]
        self.fused_source: list = []
        self.fix_east: list = []
        self.fix_north: list = []
        self.fix_hacc: list = []
        self.fix_accepted: list = []
        self._fixes_seen = 0
        self._fixes_used = 0
        self._fused_seen = 0
        #: times the view's lists were replaced by thinned ones (see "View lines, bounded")
        self.view_generation = 0
        # the barometer's floors (core.floors), beside the tracker: pressure events never reach the pipeline
        self.floors = FloorEstimator()
        # the floor plan's particle filter (app.indoor), placed again on every new track
        self.map = MapMatcher(self.plan, name=self.plan_name) if self.plan is not None else None

    def _describe_sensors(self) -> None:
        """The source's device description to a tracker that reads it (the foot INS: the gyroscope's full
        scale, :meth:`core.foot.tracker.FootTracker.use_device`); a live source has it once started."""
        use = getattr(self.pipeline, "use_device", None)
        if use is not None and self.source.device:
            use(self.source.device)

    def _steps_dir(self) -> str | None:
        """Where the step file goes: the recording's folder (it is writable), else the system's temporary one."""
        d = os.path.dirname(os.path.abspath(self.record_path)) if self.record_path else None
        return d if d and os.path.isdir(d) else None

    # -- lifecycle ----------------------------------------------------------------

    def start(self) -> None:
        """Start the source, then (if asked) open the recording with the source's device description."""
        self.source.start()
        self._describe_sensors()
        if self.record_path and self.writer is None:
            device, metadata = self._record_meta
            streams = self._record_streams or {**{n: STREAM_SPECS[n] for n in ("acc", "gyro", "mag", "gps", "gnss_status")},
                                               PRESSURE: _PRESSURE_SPEC}
            dev = dict(self.source.device)
            dev.update(device or {})
            meta = dict(metadata or {})
            if self.source.unix_offset_ns is not None:
                meta.setdefault("unix_offset_ns", int(self.source.unix_offset_ns))
            self.writer = self._recorder_factory(self.record_path, streams, dev, meta,
                                                 flush_interval_s=self.flush_interval_s)
            self.record_error = ""
            self._record_width = {n: len(spec["columns"]) for n, spec in streams.items()}
            self._last_flush = self._clock()

    def pause(self) -> None:
        """Stop the source (sensors off on Android, replay paused) and flush the recording.

        The health panel is told (:meth:`app.health.HealthMonitor.pause`): the time until the sensors
        deliver again is a pause, not dropped events."""
        was_running = self.running
        self.source.stop()
        if was_running:
            self.health.pause(self._max_t)
        self.flush()

    def resume(self) -> None:
        self.source.start()

    def replace_source(self, source) -> None:
        """Go on with another (started or not) source, e.g. the sensors at a new sampling rate; the time
        between the two is a pause for the health panel, the recording goes on."""
        if self.source.running:
            self.source.stop()
            self.health.pause(self._max_t)
        self.source = source
        source.start()
        self._describe_sensors()

    @property
    def recording(self) -> bool:
        """A recording is being written."""
        return self.writer is not None

    @property
    def running(self) -> bool:
        return bool(self.source.running)

    def close(self) -> None:
        """Stop the source, finish the track and close the recording."""
        self.source.stop()
        self._finish()
        self.stop_recording()

    def start_recording(self, path: str, metadata: dict | None = None) -> None:
        """Record from now on to ``path`` (a live session whose recording was stopped)."""
        self.record_path = path
        self._record_meta = (None, metadata)
        self.start()

    def export(self, out_dir: str, basename: str, raw_path: str | None = None) -> dict:
        """:func:`export_session` of this session."""
        return export_session(self, out_dir, basename, raw_path=raw_path)

    def stop_recording(self) -> int:
        """Close the recording (what is queued is written and fsync'ed); returns the events in the file."""
        w, self.writer = self.writer, None
        if w is None:
            return 0
        w.close()
        if w.error and not self.record_error:
            self.record_error = f"recording stopped: {w.error} ({w.events_written} events kept)"
        return w.events_written

    def flush(self, wait_s: float = 2.0) -> None:
        """Write and fsync the recording now (waits up to ``wait_s`` for the writer thread; never raises)."""
        if self.writer is not None:
            self.writer.flush(wait_s)
            self._check_recorder()
        self._last_flush = self._clock()

    def _check_recorder(self) -> None:
        """A write error stops the recording: kept in :attr:`record_error`, the file keeps what was written."""
        w = self.writer
        if w is not None and w.error:
            self.record_error = f"recording stopped: {w.error} ({w.events_written} events kept)"
            self.writer = None
            w.close(wait_s=1.0)

    # -- processing ---------------------------------------------------------------

    def tick(self, budget_s: float = 0.025, chunk: int = 1000) -> list:
        """Drain the source for at most ``budget_s`` of wall time; returns the steps completed."""
        new: list = []
        deadline = self._clock() + budget_s
        while True:
            events = self.source.drain(chunk)
            if events:
                self.ingest(events, new)
            if not events or len(events) < chunk or self._clock() >= deadline:
                break
        if self.source.finished and not self.finished:
            new.extend(self._finish())
        if self.writer is not None:
            self.writer.push()  # one batch per tick; the writer thread writes and fsyncs it
            self._check_recorder()
        return new

    def ingest(self, events, new: list | None = None) -> list:
        """Record, reorder and process ``events``; returns (or extends ``new`` with) completed steps."""
        new = [] if new is None else new
        writer = self.writer
        heap = self._heap
        width = self._record_width
        for ev in events:
            name, t = ev[0], ev[1]
            if writer is not None:
                vals = ev[2]
                if len(vals) < width.get(name, 0):  # e.g. GPS without speed/course: nan, so the file reads back
                    vals = tuple(vals) + (math.nan,) * (width[name] - len(vals))
                writer.add(name, t, vals)
            heapq.heappush(heap, (t, _RANK.get(name, len(_RANK)), self._seq, ev))
            self._seq += 1
            if self._max_t is None or t > self._max_t:
                self._max_t = t
        self.events_in += len(events)
        if self._max_t is not None:
            limit = self._max_t - self.reorder_window_ns
            while heap and heap[0][0] <= limit:
                self._process(heapq.heappop(heap)[3], new)
        return new

    def _process(self, ev, new: list) -> None:
        name, t, vals = ev
        if not self.health.accept(name, t):
            return  # went backwards in its stream beyond the reorder window: dropped, counted
        if self.first_t_ns is None:
            self.first_t_ns = t
            if self.gnss is not None:
                self.gnss.set_time_zero(t)  # outage times count from here, as in a batch run
        self.last_t_ns = t
        if name == PRESSURE:
            self.floors.update(t, vals[0])
            return
        if name == GPS:
            self.floors.note_fix(t, _gps_value(vals, "hacc_m"))
            if self.gps_origin is None and _good_fix(vals):
                self.gps_origin = (_gps_value(vals, "lat_deg"), _gps_value(vals, "lon_deg"))
        try:
            steps = self.pipeline.update(name, t, vals)
        except Exception as e:  # noqa: BLE001 - one bad event must not stop a live session
            self.errors += 1
            self.last_error = f"{type(e).__name__}: {e}"
            return
        if steps:
            self._add_steps(steps, new)
        if name == GPS:
            self._sync_fixes()

    def _add_steps(self, steps, new: list) -> None:
        cal = self._cal_range
        for s in steps:
            self.steps.append(s)
            if cal is not None and s.t_ns >= cal[0] and (cal[1] is None or s.t_ns <= cal[1]):
                self._cal_steps.append(s)  # kept whole while walked in the calibration (minutes)
            self.track_east.append(float(s.east_m))
            self.track_north.append(float(s.north_m))
            if self.map is not None:
                self.map.add_step(s)
            new.append(s)
        g = self.gnss
        if g is not None and len(g.steps) > self._fused_seen:
            for f in g.steps[self._fused_seen:]:  # the fusion's last steps (read back only if many came at once)
                self.fused_east.append(float(f.east_m))
                self.fused_north.append(float(f.north_m))
                self.fused_source.append(f.source)
            self._fused_seen = len(g.steps)
        self._sync_fixes()  # fixes wait in the fusion for the step after them
        self._bound_view()

    def _bound_view(self) -> None:
        """Thin the view's lines that grew past their bound into new lists (see "View lines, bounded")."""
        if len(self.track_east) > VIEW_MAX_POINTS:
            self.track_east, self.track_north, _, _ = thin_line(self.track_east, self.track_north,
                                                                max_points=VIEW_MAX_POINTS, recent=VIEW_RECENT_POINTS)
            self.view_generation += 1
        if len(self.fused_east) > VIEW_MAX_POINTS:
            self.fused_east, self.fused_north, self.fused_source, _ = thin_line(
                self.fused_east, self.fused_north, self.fused_source, max_points=VIEW_MAX_POINTS,
                recent=VIEW_RECENT_POINTS)
            self.view_generation += 1
        if len(self.fix_east) > VIEW_MAX_FIXES + VIEW_MAX_FIXES // 5:
            k = len(self.fix_east) - VIEW_MAX_FIXES
            self.fix_east, self.fix_north = self.fix_east[k:], self.fix_north[k:]
            self.fix_hacc, self.fix_accepted = self.fix_hacc[k:], self.fix_accepted[k:]
            self.view_generation += 1

    def _sync_fixes(self) -> None:
        """Append the fusion's new fix records to the view's lists (from the anchoring on: before it, no
        fix has a place in the local frame)."""
        g = self.gnss
        origin = g.origin_lat_lon if g is not None else None
        if origin is None:
            return
        fixes = g.fixes
        for f in fixes[self._fixes_seen:]:
            e, n = f.east_m, f.north_m
            if not (math.isfinite(e) and math.isfinite(n)) and math.isfinite(f.lat_deg) and math.isfinite(f.lon_deg):
                e, n = geodetic_to_enu(f.lat_deg, f.lon_deg, origin)  # screened out: placed for the view only
            if math.isfinite(e) and math.isfinite(n):
                self.fix_east.append(float(e))
                self.fix_north.append(float(n))
                self.fix_hacc.append(float(f.hacc_m))
                self.fix_accepted.append(bool(f.accepted))
            self._fixes_used += bool(f.accepted)
        self._fixes_seen = len(fixes)
        self._bound_view()

    def _finish(self) -> list:
        if self.finished:
            return []
        new: list = []
        while self._heap:
            self._process(heapq.heappop(self._heap)[3], new)
        try:
            steps = self.pipeline.finish()
        except Exception as e:  # noqa: BLE001
            self.errors += 1
            self.last_error = f"{type(e).__name__}: {e}"
            steps = []
        self._add_steps(steps, new)
        self._sync_fixes()  # finish() flushed the fixes still waiting
        self.finished = True
        return new

    # -- what the UI shows ------------------------------------------------------------

    def status(self):
        return self.pipeline.status()

    # -- the floor plan ------------------------------------------------------------------------

    def set_plan(self, plan, name: str = "") -> None:
        """Use ``plan`` (a :class:`core.indoor.FloorPlan`, None: no plan) from now on; it is placed anew."""
        self.plan, self.plan_name = plan, name
        self.map = MapMatcher(plan, name=name, steps_before=len(self.steps)) if plan is not None else None
        if self.map is not None:
            self.map._raw_last = (self.track_east[-1], self.track_north[-1])

    def here(self, east_m: float, north_m: float) -> None:
        """The user is at plan ``(east_m, north_m)`` now (the newest sensor time): the first time the map
        matching starts there, later it is a fix (:meth:`app.indoor.MapMatcher.here`)."""
        if self.map is None:
            raise ValueError("no floor plan: choose one in Settings")
        t = self._max_t if self._max_t is not None else (self.last_t_ns or 0)
        self.map.here(t, east_m, north_m)

    def start_map_at(self, t_ns: int, east_m: float, north_m: float, sd_m: float = 1.0) -> None:
        """Start the map matching at a landmark (plan metres) at sensor time ``t_ns`` (a replay's first)."""
        if self.map is not None:
            self.map.start_at(t_ns, east_m, north_m, sd_m)

    def map_overlay(self):
        """The map matching for the view (:class:`app.indoor.MapOverlay`), None without a plan."""
        return self.map.overlay() if self.map is not None else None

    # -- GPS fusion ---------------------------------------------------------------------------

    @property
    def gnss(self):
        """The pipeline's GPS fusion (:class:`core.gnss.base.FixFusion`), None when GPS is off."""
        return getattr(self.pipeline, "gnss", None)

    @property
    def gps_anchored(self) -> bool:
        """A good fix has placed the walk on the map (the fusion's origin is known)."""
        g = self.gnss
        return g is not None and g.origin_lat_lon is not None

    def position_covariance(self) -> tuple | None:
        """The 2x2 position covariance of the last fused step, ``((var_e, cov), (cov, var_n))`` (m^2), or None."""
        fused = getattr(self.pipeline, "fused", None)
        if not fused:
            return None
        ve, c, vn = fused[-1].cov_en_m2
        return ((ve, c), (c, vn))

    def gps_overlay(self) -> GpsOverlay | None:
        """The fused track, the fixes and the current uncertainty for the view; None when GPS is off."""
        g = self.gnss
        if g is None:
            return None
        fused = self.pipeline.fused
        return GpsOverlay(self.fused_east, self.fused_north, self.fused_source, self.fix_east, self.fix_north,
                          self.fix_hacc, self.fix_accepted, len(g.fixes), self._fixes_used,
                          fused[-1].cov_en_m2 if fused else None, g.origin_lat_lon is not None, g.name,
                          ("used" if g.fixes[-1].accepted else g.fixes[-1].reason) if g.fixes else "")

    @property
    def elapsed_s(self) -> float:
        if self.first_t_ns is None or self.last_t_ns is None:
            return 0.0
        return (self.last_t_ns - self.first_t_ns) * 1e-9

    def summary(self) -> dict:
        """Numbers for the status strip."""
        st = self.status()
        heading = st.heading_rad
        return {
            "steps": len(self.steps),
            #: steps found at a walk's start but held until the carry mode settles (counted up to 8 s later)
            "steps_held": int(getattr(st, "n_held", 0)),
            "distance_m": float(self.steps.distance_m),
            "heading_deg": bearing_deg(heading) if heading == heading else math.nan,
            "elapsed_s": self.elapsed_s,
            "east_m": self.track_east[-1],
            "north_m": self.track_north[-1],
            "heading_rad": heading,
            "mag_trusted": bool(st.mag_trusted),
            "labels": tuple(st.labels),
            "floor": self.floors.floor if self.floors.counters["readings"] else None,
            "floor_changes": sum(1 for c in self.floors.changes if c.floors),
            **self._carry(st),
        }

    def _carry(self, st) -> dict:
        """How the phone is carried (issue #17), for the strip: ``carry`` (a core.conventions.CARRY_MODES
        name, None when the pipeline has no carry-mode detector: foot mode, or turned off), its confidence
        and the number of changes."""
        det = getattr(self.pipeline, "carry", None)
        if det is None:
            return {"carry": None, "carry_confidence": math.nan, "carry_changes": 0}
        return {"carry": st.carry_mode, "carry_confidence": float(st.carry_confidence),
                "carry_changes": len(det.changes)}

    def carry_text(self) -> str:
        """The carry-mode detector's line for the health panel ("" without one)."""
        det = getattr(self.pipeline, "carry", None)
        if det is None or self.last_t_ns is None:
            return ""
        st = self.status()
        said = CARRY_WORDS.get(st.carry_mode, st.carry_mode)
        last = ""
        if det.changes:
            ch = det.changes[-1]
            t0 = self.first_t_ns if self.first_t_ns is not None else ch.t_ns
            dt = max(0, int((ch.t_ns - t0) * 1e-9))
            last = f", last at {dt // 60}:{dt % 60:02d} to {CARRY_WORDS.get(ch.to_mode, ch.to_mode)}"
        n = len(det.changes)
        return (f"carried: {said} ({100 * st.carry_confidence:.0f} % sure); "
                f"{n} change{'s' if n != 1 else ''}{last}")

    def floor_text(self) -> str:
        """The barometer's line for the health panel ("" without a barometer)."""
        f = self.floors
        if not f.counters["readings"]:
            return ""
        moves = [c for c in f.changes if c.floors]
        last = (f", last by {moves[-1].kind} ({moves[-1].floors:+d})" if moves else "")
        return (f"barometer: floor {f.floor:+d} ({len(moves)} change{'s' if len(moves) != 1 else ''}{last}), "
                f"altitude {f.altitude_m:+.1f} m")

    def step_floors(self) -> list[int]:
        """The floor of every step (a change counts from its midpoint: :func:`core.floors.floors_at`)."""
        return floors_at(self.floors.changes, [s.t_ns for s in self.steps]).tolist()

    def health_text(self) -> str:
        """The health panel: the sensor table, then what the tracker adds (the foot INS: stance, NIS, aid, sd)."""
        floor = [self.floor_text()] if self.floors.counters["readings"] else []
        carry = self.carry_text()
        if carry:
            floor.insert(0, carry)
        if self.map is not None:
            floor.append(self.map.text())
        extra = getattr(self.pipeline, "health_lines", None)
        if extra is not None:  # the foot INS: no adaptive magnetometer to trust or not
            self.health.mag_trusted = None
            return "\n".join([self.health.format(self.source.queue_drops(), self.source.accuracy(),
                                                  mag_line=False), *extra(), *floor])
        self.health.mag_trusted = bool(self.status().mag_trusted) if self.last_t_ns is not None else None
        return "\n".join([self.health.format(self.source.queue_drops(), self.source.accuracy()), *floor])

    def track(self):
        return self.steps.track()

    # -- calibration --------------------------------------------------------------------

    def start_calibration(self) -> None:
        """The calibration walk starts now (at the newest sensor time received)."""
        self._cal_range = (self._now_ns(), None)
        t0 = self._cal_range[0]
        self._cal_steps = [s for s in self.steps.last if s.t_ns >= t0]  # completed after the start, walked in it

    def stop_calibration(self) -> float:
        """The calibration walk ends now; returns the distance measured so far (steps still in the
        pipeline's delay are added as they complete)."""
        if self._cal_range is not None:
            self._cal_range = (self._cal_range[0], self._now_ns())
        return self.calibration_distance_m()

    def _now_ns(self):
        return self._max_t if self._max_t is not None else -math.inf

    @property
    def calibrating(self) -> bool:
        """A calibration walk is going on (started, not stopped)."""
        return self._cal_range is not None and self._cal_range[1] is None

    @property
    def calibration_range_ns(self) -> tuple | None:
        """(start, stop or None) of the calibration walk, sensor clock; None without one."""
        return self._cal_range

    def calibration_steps(self) -> list:
        """The steps of the calibration walk: their peaks lie between start and stop.

        Chosen by time, not by arrival: a step the pipeline completes after
        *stop* (heading delay, bout confirmation) still counts, one completed
        after *start* but walked before it does not.
        """
        if self._cal_range is None:
            return []
        t0, t1 = self._cal_range
        return [s for s in self._cal_steps if t0 <= s.t_ns and (t1 is None or s.t_ns <= t1)]

    def calibration_distance_m(self) -> float:
        """Distance the pipeline measured for the calibration walk (with the stride model in use)."""
        return float(sum(s.length_m for s in self.calibration_steps()))


def write_map_csv(path: str, session: Session) -> None:
    """One row per step: the raw (dead-reckoned) position and the map-matched one (plan metres, empty before
    the placement) with its spread."""
    import csv  # noqa: PLC0415

    mm = session.map
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["t_ns", "raw_east_m", "raw_north_m", "mm_east_m", "mm_north_m", "mm_spread_m"])
        for k, s in enumerate(session.steps):
            mmv = [mm.step_east[k], mm.step_north[k], mm.step_spread[k]]
            w.writerow([int(s.t_ns), f"{float(s.east_m):.3f}", f"{float(s.north_m):.3f}",
                        *("" if not math.isfinite(v) else f"{v:.3f}" for v in mmv)])


def export_session(session: Session, out_dir: str, basename: str, raw_path: str | None = None) -> dict:
    """Write the track as GeoJSON, GPX and CSV (``core.export``) and copy the raw recording as is.

    With GPS fusion and an anchored walk the fused track is written (points carry ``sigma_m``
    and ``source``), else the dead-reckoned one.

    Returns ``{"geojson": path, "gpx": path, "csv": path, "raw": path}`` for the
    files written, and ``"errors"`` (a list) for what could not be written.
    """
    os.makedirs(out_dir, exist_ok=True)
    out: dict = {"errors": []}
    track = session.track()
    extra = None
    # with GPS fusion: the fused track (with its per-step uncertainty and source), placed by the fusion's
    # origin; without: the dead-reckoned track, the first good fix taken as the start
    gnss = session.gnss
    origin = gnss.origin_lat_lon if gnss is not None and gnss.origin_lat_lon is not None else session.gps_origin
    if gnss is not None and gnss.origin_lat_lon is not None and gnss.steps:
        fused = FusedTrack.from_steps(gnss.steps)  # read back from disk in one pass in the live app
        track, extra = fused, fused.point_properties()
    if session.floors.counters["readings"]:  # the barometer's floor of every step
        extra = {**(extra or {}), "floor": floors_at(session.floors.changes, track.t_ns).tolist()}
    if getattr(session.pipeline, "carry", None) is not None and len(session.steps) == len(track):
        extra = {**(extra or {}), "carry": [getattr(st, "carry_mode", "") for st in session.steps]}
    mm = getattr(session, "map", None)
    if mm is not None and mm.placed:  # the map-matched position (plan metres) beside the raw one, per step
        extra = {**(extra or {}), **mm.export_properties(track.t_ns, [s.t_ns for s in session.steps])}
    try:
        from core import export  # noqa: PLC0415 - the lead's module
    except ImportError as e:
        out["errors"].append(f"track export unavailable: {e}")
        export = None
    if export is not None:
        offset = session.source.unix_offset_ns
        jobs = (("geojson", ".geojson", lambda p: export.write_track_geojson(p, track, origin_lat_lon=origin,
                                                                              point_properties=extra)),
                ("gpx", ".gpx", lambda p: export.write_track_gpx(p, track, origin_lat_lon=origin,
                                                                 unix_offset_ns=offset, point_properties=extra)),
                ("csv", ".track.csv", lambda p: export.write_track_csv(
                    p, track, {"carry": extra["carry"]} if extra and "carry" in extra else None)))
        if mm is not None and mm.placed:
            jobs += (("map_csv", ".map.csv", lambda p: write_map_csv(p, session)),)
        for key, ext, fn in jobs:
            path = os.path.join(out_dir, basename + ext)
            try:
                fn(path)
                out[key] = path
            except Exception as e:  # noqa: BLE001 - report, keep the other formats
                out["errors"].append(f"{key}: {type(e).__name__}: {e}")
    if raw_path and os.path.exists(raw_path):
        session.flush()
        dest = os.path.join(out_dir, os.path.basename(raw_path))
        if os.path.abspath(dest) != os.path.abspath(raw_path):
            shutil.copyfile(raw_path, dest)
        out["raw"] = dest
    return out
