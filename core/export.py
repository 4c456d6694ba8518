"""Track export: CSV (local metres), GeoJSON and GPX (WGS-84), converting at the edge.

Geodesy: the ENU track is placed on the WGS-84 ellipsoid with a local
tangent plane at ``origin = (lat0, lon0)`` by :mod:`core.geodesy` (the
project's one geodesy; :func:`enu_to_geodetic` and :func:`geodetic_to_enu`
are re-exported here for the exporters' callers).

Without a known origin the track is placed at latitude/longitude (0, 0) and
every file says so (``origin_known = false``): shape and size are right, the
place is not.

GPX needs absolute times: ``unix_offset_ns`` (Unix time minus sensor-clock
time, from the recording's metadata when the importer knew it) converts
``t_ns``; without it the times count from the Unix epoch and the file says so.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json

from core.conventions import bearing_deg
from core.geodesy import WGS84_A_M, WGS84_E2, enu_to_geodetic, geodetic_to_enu  # noqa: F401 (re-exported)


#: the start point's time before the first step when the track cannot tell the step period (one step, or a
#: pause of 2 s or more between the first two): about one step at walking cadence
_STEP_PERIOD_NS = 500_000_000


def _points(track):
    """Rows (t_ns, east, north, length, heading) with the start point first: where the walker stood before
    the first step (:func:`core.metrics.track_start`; (0, 0) for a dead-reckoned track, the first step's start
    on a map-matched one, which used to be drawn from (0, 0) too).

    The start point's time is the first step's start: one step period (the first two steps' interval)
    before the first step, whose time is the step's end (it used to be the first step's own time, so the
    first two GPX points shared a timestamp: issue #29)."""
    rows = []
    if len(track):
        t0 = int(track.t_ns[0])
        dt = int(track.t_ns[1]) - t0 if len(track) > 1 else 0
        from core.metrics import track_start

        e0, n0 = track_start(track)
        rows.append((t0 - (dt if 0 < dt < 2_000_000_000 else _STEP_PERIOD_NS), e0, n0, 0.0,
                     float(track.heading_rad[0])))
    for i in range(len(track)):
        rows.append((int(track.t_ns[i]), float(track.east_m[i]), float(track.north_m[i]),
                     float(track.length_m[i]), float(track.heading_rad[i])))
    return rows


def track_csv_rows(track, columns: dict | None = None) -> list[list]:
    """The track CSV as rows, header first: ``t_ns, t_s, step_length_m, heading_rad, bearing_deg, east_m,
    north_m, distance_m`` per step, then ``columns`` (``{name: per-step values}``, e.g. lat/lon, floor), then
    ``estimated`` (1: a step estimated across an accelerometer gap, not measured) when the track has such steps."""
    extra = dict(columns or {})
    est = getattr(track, "estimated", None)
    if est is not None and "estimated" not in extra:  # steps placed in an accelerometer gap (issue #30)
        extra["estimated"] = [int(bool(v)) for v in est]
    t0 = int(track.t_ns[0]) if len(track) else 0
    dist = 0.0
    rows = [["t_ns", "t_s", "step_length_m", "heading_rad", "bearing_deg", "east_m", "north_m", "distance_m",
             *extra]]
    for i in range(len(track)):
        dist += float(track.length_m[i])
        h = float(track.heading_rad[i])
        rows.append([int(track.t_ns[i]), f"{(int(track.t_ns[i]) - t0) * 1e-9:.3f}",
                     f"{float(track.length_m[i]):.4f}", f"{h:.5f}", f"{bearing_deg(h):.2f}",
                     f"{float(track.east_m[i]):.3f}", f"{float(track.north_m[i]):.3f}", f"{dist:.3f}",
                     *(vals[i] for vals in extra.values())])
    return rows


def write_track_csv(path: str, track, columns: dict | None = None) -> None:
    """One row per step (:func:`track_csv_rows`), with the optional extra ``columns``."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows(track_csv_rows(track, columns))


FIX_COLUMNS = ("t_ns", "lat_deg", "lon_deg", "hacc_m", "speed_m_s", "course_deg", "used", "verdict", "nis",
               "correction_m")


def _fix_row(f) -> dict:
    """One GPS fix's verdict (:class:`core.gnss.base.FixRecord`) as plain values."""
    def num(v, nd):
        return round(float(v), nd) if v == v else None
    return {"t_ns": int(f.t_ns), "lat_deg": num(f.lat_deg, 8), "lon_deg": num(f.lon_deg, 8), "hacc_m": num(f.hacc_m, 2),
            "speed_m_s": num(f.speed_m_s, 3), "course_deg": num(f.course_deg, 2), "used": bool(f.accepted),
            "verdict": "used" if f.accepted else f.reason, "nis": num(f.nis, 3), "correction_m": num(f.correction_m, 3)}


def write_fixes_csv(path: str, fixes) -> None:
    """Every GPS fix the fusion saw with its verdict: used, or why not (one row per fix, :data:`FIX_COLUMNS`)."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(FIX_COLUMNS)
        for fx in fixes:
            row = _fix_row(fx)
            w.writerow(["" if row[c] is None else row[c] for c in FIX_COLUMNS])


def track_geojson(track, origin_lat_lon: tuple[float, float] | None = None, properties: dict | None = None,
                  point_properties: dict | None = None, fixes=None) -> dict:
    """The track as a GeoJSON FeatureCollection (RFC 7946: lon, lat order): a LineString and one Point per step.

    ``point_properties``: optional ``{name: list}`` of per-step values (one per
    step, e.g. the fused track's ``sigma_m`` and ``source``) added to each Point.
    ``fixes``: the GPS fixes with their verdicts (:class:`core.gnss.base.FixRecord`),
    one Point each with ``"kind": "gps_fix"``, ``used`` and ``verdict``.
    """
    extra = dict(point_properties or {})
    est = getattr(track, "estimated", None)
    if est is not None and "estimated" not in extra:  # steps placed in an accelerometer gap (issue #30)
        extra["estimated"] = [bool(v) for v in est]
    known = origin_lat_lon is not None
    origin = origin_lat_lon if known else (0.0, 0.0)
    pts = _points(track)
    coords = []
    feats = []
    for k, (t, e, n, length, h) in enumerate(pts):
        lat, lon = enu_to_geodetic(e, n, origin)
        coords.append([round(lon, 8), round(lat, 8)])
        if k > 0:
            feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": coords[-1]},
                          "properties": {"step": k, "t_ns": t, "step_length_m": round(length, 4),
                                         "bearing_deg": round(bearing_deg(h), 2), "east_m": round(e, 3),
                                         "north_m": round(n, 3),
                                         **{name: vals[k - 1] for name, vals in extra.items()}}})
    props = {"name": "PDR track", "n_steps": len(track), "origin_known": known,
             "origin_lat_lon": list(origin), **(properties or {})}
    line = {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords}, "properties": props}
    for fx in fixes or ():
        row = _fix_row(fx)
        if row["lat_deg"] is None or row["lon_deg"] is None:
            continue
        feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [row["lon_deg"], row["lat_deg"]]},
                      "properties": {"kind": "gps_fix", **{k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}}})
    return {"type": "FeatureCollection", "features": [line] + feats}


def write_track_geojson(path: str, track, origin_lat_lon: tuple[float, float] | None = None,
                        properties: dict | None = None, point_properties: dict | None = None, fixes=None) -> None:
    with open(path, "w", encoding="utf-8") as f:
        json.dump(track_geojson(track, origin_lat_lon, properties, point_properties, fixes), f, indent=1)


def write_track_gpx(path: str, track, origin_lat_lon: tuple[float, float] | None = None,
                    unix_offset_ns: int | None = None, name: str = "PDR track",
                    point_properties: dict | None = None) -> None:
    """GPX 1.1 track (needs the ``gpxpy`` package) with per-point time, step length and bearing as extensions.

    ``point_properties``: optional ``{name: list}`` of per-step values written as
    further extensions of each point after the start point (e.g. ``sigma_m``, ``source``).
    """
    extra = point_properties or {}
    try:
        import gpxpy.gpx
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("GPX export needs gpxpy: pip install gpxpy") from e
    from xml.etree import ElementTree as ET

    ns = "https://pdr.invalid/gpx/1"
    known = origin_lat_lon is not None
    origin = origin_lat_lon if known else (0.0, 0.0)
    gpx = gpxpy.gpx.GPX()
    gpx.nsmap["pdr"] = ns
    gpx.creator = "pdr"
    notes = []
    if not known:
        notes.append("origin unknown: track placed at 0,0")
    if unix_offset_ns is None:
        notes.append("absolute time unknown: times count from the sensor clock's zero")
    gpx.description = "; ".join(notes) or None
    trk = gpxpy.gpx.GPXTrack(name=name)
    seg = gpxpy.gpx.GPXTrackSegment()
    trk.segments.append(seg)
    gpx.tracks.append(trk)
    off = unix_offset_ns or 0
    for k, (t, e, n, length, h) in enumerate(_points(track)):
        lat, lon = enu_to_geodetic(e, n, origin)
        when = _dt.datetime.fromtimestamp((t + off) * 1e-9, tz=_dt.timezone.utc)
        p = gpxpy.gpx.GPXTrackPoint(latitude=lat, longitude=lon, time=when)
        tags = [("step_length_m", f"{length:.4f}"), ("bearing_deg", f"{bearing_deg(h):.2f}")]
        if k > 0:
            tags += [(name, str(vals[k - 1])) for name, vals in extra.items()]
        for tag, val in tags:
            el = ET.Element(f"{{{ns}}}{tag}")
            el.text = val
            p.extensions.append(el)
        seg.points.append(p)
    with open(path, "w", encoding="utf-8") as f:
        f.write(gpx.to_xml(version="1.1"))


#: the columns of a step file (:class:`StepFile`)
STEP_FILE_COLUMNS = ("index", "t_ns", "length_m", "heading_rad", "east_m", "north_m", "mag_trusted", "estimated",
                     "carry_mode")


class StepRow:
    """A step read back from a :class:`StepFile`: the fields of :class:`core.pdr.pipeline.Step` the track, the
    exports and the app use."""

    __slots__ = STEP_FILE_COLUMNS

    def __init__(self, index: int, t_ns: int, length_m: float, heading_rad: float, east_m: float, north_m: float,
                 mag_trusted: bool = False, estimated: bool = False, carry_mode: str = ""):
        self.index, self.t_ns, self.length_m, self.heading_rad = index, t_ns, length_m, heading_rad
        self.east_m, self.north_m, self.mag_trusted = east_m, north_m, mag_trusted
        self.estimated, self.carry_mode = estimated, carry_mode


class RecordFile:
    """Records written to a file as they come and read back when all of them are needed (issue #30).

    What a live session must keep for its exports but must not hold in memory for a day: memory holds the
    count and the last ``keep_last`` records (as given, :attr:`last`); ``len``, iteration (the records read
    back one at a time, in order, appends in between allowed), ``[k]`` and ``[a:]`` (from :attr:`last` when
    the records are still there, else read back) give the rest.  ``kind``, a dataclass of plain values
    (numbers, strings, booleans, tuples of them), is written one JSON list a line (floats read back exactly,
    nan and inf too) and read back as ``kind``; :class:`StepFile` writes its own CSV instead.

    ``path`` None: an anonymous temporary file (in ``directory``, which may be set until the first record:
    the file opens then), gone when closed.  A file that cannot be written (disk full) is given up: the
    records from then on are kept in memory and :attr:`error` says why.
    """

    #: what the file is called in an error message
    what = "record file"

    def __init__(self, kind=None, path: str | None = None, *, directory: str | None = None, keep_last: int = 64):
        from collections import deque
        from dataclasses import fields

        self.kind = kind
        self._names = tuple(f.name for f in fields(kind)) if kind is not None else ()
        self.path = path
        self.directory = directory
        self.error = ""
        self._f = None
        self._opened = False
        self._writable = True
        self._memory: list = []  # only after the file failed
        self._n_file = 0
        self.n = 0
        #: the last records (as given)
        self.last = deque(maxlen=keep_last)

    # -- the format (a subclass may write its own) ----------------------------------------------
    def _header(self) -> str:
        return json.dumps(list(self._names))

    def _row(self, item):
        """What is written (and kept, after the file failed) of ``item``."""
        return item

    def _line(self, row) -> str:
        return json.dumps([getattr(row, k) for k in self._names])

    def _parse(self, line: str):
        return self.kind(*(tuple(v) if isinstance(v, list) else v for v in json.loads(line)))

    # -- writing --------------------------------------------------------------------------------
    def _open(self) -> None:
        import tempfile

        self._opened = True
        try:
            self._f = (open(self.path, "w+", encoding="utf-8", newline="") if self.path is not None
                       else tempfile.TemporaryFile("w+", encoding="utf-8", newline="", dir=self.directory))
            self._f.write(self._header() + "\n")
        except OSError as e:
            self._f, self.error, self._writable = None, f"{self.what}: {e}", False

    def append(self, item) -> None:
        self.n += 1
        self.last.append(item)
        row = self._row(item)
        if not self._opened:
            self._open()
        if self._writable:
            try:
                self._f.seek(0, 2)
                self._f.write(self._line(row) + "\n")
                self._n_file += 1
                return
            except OSError as e:
                self.error = f"{self.what}: {e}; the records from record {self.n} on are kept in memory"
                self._writable = False
        self._memory.append(row)

    # -- reading --------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.n

    def __bool__(self) -> bool:
        return self.n > 0

    def __iter__(self):
        yield from self._read_file()
        yield from list(self._memory)

    def __getitem__(self, k):
        """``[k]`` (negative from the end) or ``[a:b]``: from :attr:`last` when the records are still there."""
        import itertools

        if isinstance(k, slice):
            a, b, step = k.indices(self.n)
            if step != 1:
                raise ValueError("a record file reads back every record in order: no slice step")
        else:
            a = k + self.n if k < 0 else k
            if not 0 <= a < self.n:
                raise IndexError(f"record {k} of {self.n}")
            b = a + 1
        first = self.n - len(self.last)
        if a >= first:
            out = list(itertools.islice(self.last, a - first, max(b - first, 0)))
        else:
            out = list(itertools.islice(iter(self), a, b))
        return out if isinstance(k, slice) else out[0]

    def _read_file(self, block: int = 4096):
        """The file's rows, ``block`` lines at a time; appends in between (at the end) do not disturb it."""
        f = self._f
        if f is None or not self._n_file:
            return
        left = self._n_file
        try:
            f.flush()
        except OSError:
            pass
        f.seek(0)
        f.readline()  # the header
        off = f.tell()
        parse = self._parse
        while left > 0:
            f.seek(off)
            lines = [f.readline() for _ in range(min(block, left))]
            off = f.tell()
            f.seek(0, 2)  # appends go on at the end
            left -= len(lines)
            for line in lines:
                yield parse(line.rstrip("\n"))

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None


class StepFile(RecordFile):
    """A session's steps, written to a file as they come and read back when the whole track is needed (issue #30).

    A day-long walk is about 150 000 steps: kept as :class:`core.pdr.pipeline.Step` objects they held about
    700 bytes each.  Here each step is one CSV line (:data:`STEP_FILE_COLUMNS`, floats in ``repr``: they read
    back exactly); memory holds the count, the distance and the last ``keep_last`` steps.  ``len``,
    iteration (:class:`StepRow` read back one at a time, in order), :meth:`track` (a
    :class:`core.pdr.pipeline.Track` read back in one pass) give everything; the file is a :class:`RecordFile`'s.
    """

    what = "step file"

    def __init__(self, path: str | None = None, *, directory: str | None = None, keep_last: int = 64):
        super().__init__(None, path, directory=directory, keep_last=keep_last)
        self.distance_m = 0.0

    def append(self, step) -> None:
        self.distance_m += float(step.length_m)
        super().append(step)

    def _header(self) -> str:
        return ",".join(STEP_FILE_COLUMNS)

    def _row(self, step) -> StepRow:
        return StepRow(int(getattr(step, "index", self.n - 1)), int(step.t_ns), float(step.length_m),
                       float(step.heading_rad), float(step.east_m), float(step.north_m),
                       bool(getattr(step, "mag_trusted", False)), bool(getattr(step, "estimated", False)),
                       str(getattr(step, "carry_mode", "")))

    def _line(self, row: StepRow) -> str:
        return (f"{row.index},{row.t_ns},{row.length_m!r},{row.heading_rad!r},{row.east_m!r},"
                f"{row.north_m!r},{int(row.mag_trusted)},{int(row.estimated)},{row.carry_mode}")

    def _parse(self, line: str) -> StepRow:
        i, t, length, h, e, n, mag, est, mode = line.split(",")
        return StepRow(int(i), int(t), float(length), float(h), float(e), float(n), mag == "1", est == "1", mode)

    def track(self):
        """The whole track (:class:`core.pdr.pipeline.Track`), read back in one pass."""
        from array import array

        import numpy as np

        from core.pdr.pipeline import Track

        cols = [array("q"), array("d"), array("d"), array("d"), array("d"), array("b")]
        for r in self:
            cols[0].append(r.t_ns)
            cols[1].append(r.length_m)
            cols[2].append(r.heading_rad)
            cols[3].append(r.east_m)
            cols[4].append(r.north_m)
            cols[5].append(r.estimated)
        est = np.array(cols[5], dtype=bool)
        return Track(np.array(cols[0], dtype=np.int64), *(np.array(c, dtype=float) for c in cols[1:5]),
                     est if est.any() else None)
