"""Track export: geodesy round trip, GeoJSON/GPX/CSV files that other tools read back."""

import csv
import json
import math

import numpy as np
import pytest

from core.conventions import bearing_deg, heading_from_bearing_deg
from core.export import (enu_to_geodetic, geodetic_to_enu, track_geojson, write_track_csv, write_track_geojson,
                         write_track_gpx)
from core.pdr.pipeline import Track


def _track():
    h = np.array([0.0, 0.0, math.pi / 2, math.pi / 2, math.pi])
    d = np.full(5, 0.7)
    e = np.cumsum(d * np.cos(h))
    n = np.cumsum(d * np.sin(h))
    return Track(10**12 + np.arange(5, dtype=np.int64) * 550_000_000, d, h, e, n)


def test_local_tangent_plane_round_trip_and_scale():
    origin = (47.3769, 8.5417)
    lat, lon = enu_to_geodetic(1000.0, -500.0, origin)
    e, n = geodetic_to_enu(lat, lon, origin)
    assert e == pytest.approx(1000.0, abs=1e-6) and n == pytest.approx(-500.0, abs=1e-6)
    # one degree of latitude at 47 deg is about 111.2 km (published ellipsoid value 111,178 m at 47 deg)
    _, n1 = geodetic_to_enu(origin[0] + 1.0, origin[1], origin)
    assert n1 == pytest.approx(111_178, rel=2e-3)


def test_bearing_conversions():
    assert bearing_deg(math.pi / 2) == pytest.approx(0.0)  # North
    assert bearing_deg(0.0) == pytest.approx(90.0)  # East
    assert bearing_deg(-math.pi / 2) == pytest.approx(180.0)
    for b in (0.0, 45.0, 181.0, 359.0):
        assert bearing_deg(heading_from_bearing_deg(b)) == pytest.approx(b)


def test_geojson_is_lon_lat_and_places_the_track(tmp_path):
    origin = (51.5, -0.12)
    gj = track_geojson(_track(), origin)
    line = gj["features"][0]
    assert line["geometry"]["type"] == "LineString" and line["properties"]["origin_known"] is True
    lon0, lat0 = line["geometry"]["coordinates"][0]
    assert (lat0, lon0) == pytest.approx(origin)
    lon, lat = line["geometry"]["coordinates"][-1]
    e, n = geodetic_to_enu(lat, lon, origin)
    tr = _track()
    assert e == pytest.approx(tr.east_m[-1], abs=1e-3) and n == pytest.approx(tr.north_m[-1], abs=1e-3)
    assert gj["features"][1]["properties"]["bearing_deg"] == pytest.approx(90.0)
    p = tmp_path / "t.geojson"
    write_track_geojson(str(p), tr)
    back = json.loads(p.read_text())
    assert back["features"][0]["properties"]["origin_known"] is False


def test_gpx_round_trip_with_gpxpy(tmp_path):
    gpxpy = pytest.importorskip("gpxpy")
    p = tmp_path / "t.gpx"
    write_track_gpx(str(p), _track(), (10.0, 20.0), unix_offset_ns=1_700_000_000 * 10**9 - 10**12)
    g = gpxpy.parse(p.read_text())
    pts = g.tracks[0].segments[0].points
    assert len(pts) == 6
    assert pts[1].time.timestamp() == pytest.approx(1_700_000_000.0, abs=1e-3)
    assert (pts[-1].time - pts[1].time).total_seconds() == pytest.approx(4 * 0.55, abs=1e-3)
    e, n = geodetic_to_enu(pts[-1].latitude, pts[-1].longitude, (10.0, 20.0))
    assert e == pytest.approx(_track().east_m[-1], abs=0.01)
    ext = {el.tag.split("}")[1]: el.text for el in pts[2].extensions}
    assert float(ext["step_length_m"]) == pytest.approx(0.7) and float(ext["bearing_deg"]) == pytest.approx(90.0)


def test_csv_has_one_row_per_step_and_cumulative_distance(tmp_path):
    p = tmp_path / "t.csv"
    write_track_csv(str(p), _track())
    rows = list(csv.DictReader(p.open()))
    assert len(rows) == 5
    assert float(rows[-1]["distance_m"]) == pytest.approx(3.5)
    assert float(rows[2]["bearing_deg"]) == pytest.approx(0.0)


def test_gpx_times_increase_from_the_start_point(tmp_path):
    """Issue #29: the start point had the first step's time (the first two points of every GPX shared a
    timestamp); it is the first step's start, one step period (the first two steps' interval) before it."""
    gpxpy = pytest.importorskip("gpxpy")
    p = tmp_path / "t.gpx"
    write_track_gpx(str(p), _track(), (10.0, 20.0), unix_offset_ns=1_700_000_000 * 10**9 - 10**12)
    t = [q.time.timestamp() for q in gpxpy.parse(p.read_text()).tracks[0].segments[0].points]
    assert all(b > a for a, b in zip(t, t[1:])), t
    assert t[1] - t[0] == pytest.approx(t[2] - t[1], abs=1e-3)
