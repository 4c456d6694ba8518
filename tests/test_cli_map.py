"""``pdr replay --map``: the floor-plan particle filter from the command line (core.indoor)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from core.indoor import FloorPlan, read_geojson, write_geojson
from core.recording import Recording, make_stream, write_recording
from desktop.cli import main
from desktop.simulator import simulate_walk

#: an L-shaped corridor, 2 m wide: 30 m East, then 20 m North
CORRIDOR = [[-1.0, -1.0], [31.0, -1.0], [31.0, 21.0], [29.0, 21.0], [29.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]]


@pytest.fixture(scope="module")
def walk_and_plan(tmp_path_factory):
    d = tmp_path_factory.mktemp("map")
    plan = FloorPlan(areas=[(np.array(CORRIDOR), [])], name="corridor")
    write_geojson(plan, d / "plan.geojson")
    w = simulate_walk(((0.0, 0.0), (30.0, 0.0), (30.0, 20.0)), seed=12, rate_hz=50.0, still_start_s=1.5,
                      still_end_s=1.5, phone_yaw_offset_deg=12.0)
    rec = w.recording
    path = d / "walk.csv"
    write_recording(str(path), Recording(dict(rec.streams), device=rec.device, metadata=rec.metadata))
    return str(path), str(d / "plan.geojson"), w


def test_the_map_keeps_the_track_in_the_corridor(walk_and_plan, tmp_path, capsys):
    path, plan_path, w = walk_and_plan
    out = tmp_path / "track.geojson"
    assert main(["replay", path, "--map", plan_path, "--start", "0,0,0.5", "--json", "--geojson", str(out),
                 "--no-profile"]) == 0
    s = json.loads(capsys.readouterr().out)
    m = s["map"]
    assert m["outside_walkable"] == 0 and m["steps"] > 50
    end = w.truth.end_en_m if hasattr(w.truth, "end_en_m") else (30.0, 20.0)
    gj = json.loads(out.read_text())
    pts = [f for f in gj["features"] if f["geometry"]["type"] == "Point"]
    last = pts[-1]["properties"]
    assert math.hypot(last["east_m"] - end[0], last["north_m"] - end[1]) < 3.0  # the map-matched end
    assert {"raw_east_m", "raw_north_m", "spread_m"} <= set(last)
    raw_end = (last["raw_east_m"], last["raw_north_m"])
    assert math.hypot(raw_end[0] - end[0], raw_end[1] - end[1]) > math.hypot(last["east_m"] - end[0],
                                                                             last["north_m"] - end[1])
    plan = read_geojson(plan_path)
    assert plan.is_walkable(np.array([[p["properties"]["east_m"], p["properties"]["north_m"]] for p in pts])).all()


def test_map_without_a_start_is_refused_before_the_run(walk_and_plan, capsys):
    path, plan_path, _ = walk_and_plan
    assert main(["replay", path, "--map", plan_path]) == 2
    assert "needs a start" in capsys.readouterr().err


def test_map_matched_exports_take_the_plans_geo_reference(walk_and_plan, tmp_path, capsys):
    """Issue #29: the exports of a map-matched track are placed by the plan's own geo-reference (here turned
    by 30 deg and scaled), not at 0, 0: every exported point maps back into the plan's walkable area, and
    the line starts at the --start point."""
    from core.indoor import Georeference

    path, _, _ = walk_and_plan
    georef = Georeference(47.3769, 8.5417, math.radians(30.0), 1.02, 0.98)
    plan = FloorPlan(areas=[(np.array(CORRIDOR), [])], name="corridor", georef=georef)
    plan_path = tmp_path / "geo_plan.geojson"
    write_geojson(plan, plan_path, units="m")
    out, csv_out = tmp_path / "track.geojson", tmp_path / "track.csv"
    assert main(["replay", path, "--map", str(plan_path), "--start", "0,0,0.5", "--geojson", str(out),
                 "--csv", str(csv_out), "--no-profile"]) == 0
    assert "not placed" not in capsys.readouterr().err
    gj = json.loads(out.read_text())
    line = gj["features"][0]
    assert line["properties"]["origin_known"] and line["properties"]["origin_lat_lon"] == pytest.approx([47.3769, 8.5417])
    lonlat = np.array(line["geometry"]["coordinates"])
    xy = georef.from_geodetic(lonlat[:, 1], lonlat[:, 0])
    assert np.hypot(*xy[0]) < 1.0  # the start point, not 0, 0
    assert plan.is_walkable(xy[1:]).all()
    rows = np.genfromtxt(csv_out, delimiter=",", names=True)
    xy_csv = georef.from_geodetic(rows["lat_deg"], rows["lon_deg"])
    np.testing.assert_allclose(xy_csv, xy[1:], atol=0.01)


def test_a_geo_referenced_plan_gives_the_declination(walk_and_plan, tmp_path, capsys):
    """The plan says where the building is: the World Magnetic Model's declination there, as a GPS fix would."""
    from core.geodesy import declination_rad, unix_ns_to_datetime
    from core.indoor import Georeference
    from core.recording import read_recording

    path, _, _ = walk_and_plan
    rec = read_recording(path)
    rec.metadata = {**rec.metadata, "unix_offset_ns": 1_751_328_000_000_000_000 - rec.t0_ns}  # 2025-07-01
    dated = tmp_path / "dated.csv"
    write_recording(str(dated), rec)
    plan = FloorPlan(areas=[(np.array(CORRIDOR), [])], name="corridor", georef=Georeference(30.3011, 120.1301))
    write_geojson(plan, tmp_path / "p.geojson", units="m")
    assert main(["replay", str(dated), "--map", str(tmp_path / "p.geojson"), "--start", "0,0", "--json",
                 "--no-profile"]) == 0
    d = json.loads(capsys.readouterr().out)["declination"]
    want = math.degrees(declination_rad(30.3011, 120.1301, 0.0, unix_ns_to_datetime(1_751_328_000_000_000_000)))
    assert d["source"].endswith("the floor plan's geo-reference") and abs(d["declination_deg"] - want) < 1e-6
    assert abs(want) > 1.0
