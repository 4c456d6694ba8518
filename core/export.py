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
    north_m, distance_m`` per step, then ``columns`` (``{name: per-step values}``, e.g. lat/lon, floor)."""
    extra = columns or {}
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
    extra = point_properties or {}
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
