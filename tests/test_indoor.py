"""core.indoor (issue #16): geometry, floor-plan formats, walls from images, the particle filter against truth."""

from __future__ import annotations

import gzip
import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.indoor import (
    FloorPlan, Georeference, ParticleConfig, ParticleFilter, StepArrays, map_match, plan_from_geojson, plan_to_geojson,
    read_geojson, read_ipin_cal, read_ipin_floor, read_ms_floor, write_geojson,
)
from core.indoor.geometry import WallGrid, points_in_polygon, segments_intersect
from core.indoor.raster import mask_boundary_segments, otsu_threshold, walls_from_image
from desktop.floor_images import read_floor_image

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MS_F3 = DATA / "ms_indoor_location_2020" / "site2" / "F3"
IPIN_MAPS = DATA / "ipin2023_track3" / "floormaps"

# ---------------------------------------------------------------------------
# geometry against a brute-force exact check


def _brute_intersect(a, b, c, d) -> bool:
    """Exact (rational) intersection of closed segments ab and cd by their parametric form."""
    a, b, c, d = ([Fraction(v) for v in p] for p in (a, b, c, d))
    r = (b[0] - a[0], b[1] - a[1])
    s = (d[0] - c[0], d[1] - c[1])
    qp = (c[0] - a[0], c[1] - a[1])
    den = r[0] * s[1] - r[1] * s[0]
    if den != 0:
        t = (qp[0] * s[1] - qp[1] * s[0]) / den
        u = (qp[0] * r[1] - qp[1] * r[0]) / den
        return 0 <= t <= 1 and 0 <= u <= 1
    if qp[0] * r[1] - qp[1] * r[0] != 0 or qp[0] * s[1] - qp[1] * s[0] != 0:
        return False  # parallel, on different lines
    # collinear (or degenerate): overlap of the 1-D projections on the dominant axis, or equal points
    pts_ab, pts_cd = (a, b), (c, d)
    for k in (0, 1):
        lo1, hi1 = sorted(p[k] for p in pts_ab)
        lo2, hi2 = sorted(p[k] for p in pts_cd)
        if hi1 < lo2 or hi2 < lo1:
            return False
    return True


coord = st.integers(-4, 4)
point = st.tuples(coord, coord)


@settings(max_examples=150, deadline=None)
@given(point, point, point, point)
def test_segment_intersection_matches_brute_force(a, b, c, d):
    got = bool(segments_intersect(np.array(a), np.array(b), np.array(c), np.array(d)))
    assert got == _brute_intersect(a, b, c, d)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(point, point), min_size=1, max_size=12), st.lists(st.tuples(point, point), min_size=1,
                                                                            max_size=12),
       st.sampled_from([0.7, 1.5, 3.0]))
def test_wall_grid_matches_testing_every_wall(walls, moves, cell_m):
    w = np.array([[*p, *q] for p, q in walls], dtype=float) * 0.5
    m = np.array([[*p, *q] for p, q in moves], dtype=float) * 0.5
    grid = WallGrid(w, cell_m=cell_m)
    got = grid.crosses(m[:, :2], m[:, 2:])
    want = [any(_brute_intersect(mv[:2], mv[2:], wl[:2], wl[2:]) for wl in w) for mv in m]
    assert got.tolist() == want


def test_point_in_polygon_even_odd():
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=float)
    pts = np.array([[2, 2], [5, 2], [-1, -1], [3.9, 0.1]])
    assert points_in_polygon(pts, square).tolist() == [True, False, False, True]


# ---------------------------------------------------------------------------
# plans and formats


def corridor_l(width: float = 2.0) -> FloorPlan:
    """An L-shaped corridor: 40 m East along y = 0, then 30 m North along x = 40 (``width`` wide)."""
    h = width / 2.0
    ring = [(-h, -h), (40 + h, -h), (40 + h, 30 + h), (40 - h, 30 + h), (40 - h, h), (-h, h)]
    return FloorPlan(areas=[(np.array(ring), [])], georef=Georeference(47.37, 8.54, 0.0), name="L", floor="0")


def test_shared_edge_of_two_walkable_polygons_is_an_opening():
    a = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    b = np.array([[2, 0], [4, 0], [4, 2], [2, 2]], dtype=float)  # shares x = 2 with a
    plan = FloorPlan(areas=[(a, []), (b, [])])
    assert len(plan.walls) == 6
    assert not plan.grid(1.0).crosses([[1.0, 1.0]], [[3.0, 1.0]])[0]
    assert plan.grid(1.0).crosses([[1.0, 1.0]], [[1.0, 3.0]])[0]


def test_geojson_round_trip_metres_and_degrees(tmp_path):
    plan = corridor_l()
    hole = np.array([[10, -0.5], [11, -0.5], [11, 0.5], [10, 0.5]], dtype=float)
    plan = FloorPlan(areas=[(plan.areas[0][0], [hole])], obstacles=[hole + [5, 0]],
                     wall_lines=[[20, -1, 20, -0.5]], georef=plan.georef, name="L", floor="0")
    for units, tol in (("m", 1e-12), ("deg", 1e-4)):
        path = tmp_path / f"plan_{units}.geojson.gz"
        write_geojson(plan, path, units=units)
        back = read_geojson(path)
        assert back.floor == "0" and back.name == "L"
        assert np.allclose(back.areas[0][0], plan.areas[0][0], atol=tol)
        assert np.allclose(back.areas[0][1][0], hole, atol=tol)
        assert np.allclose(back.obstacles[0], hole + [5, 0], atol=tol)
        assert np.allclose(back.wall_lines, plan.wall_lines, atol=tol)
        assert back.georef is not None
    # a GIS drawing without our header: degrees, polygons walkable, lines walls
    doc = plan_to_geojson(plan, units="deg")
    del doc["pdr_floorplan"]
    for f in doc["features"]:
        f["properties"] = {}
    back = plan_from_geojson(doc)
    assert len(back.areas) == 2 and not back.obstacles and len(back.wall_lines) == 1
    with pytest.raises(ValueError):
        plan_from_geojson({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {"kind": "door"}, "geometry": {"type": "Point", "coordinates": [0, 0]}}]})


def test_georeference_round_trip_through_core_geodesy():
    g = Georeference(49.46, 11.11, math.radians(-20.7), 1.001, 0.996)
    xy = np.array([[0.0, 0.0], [50.0, -20.0], [-130.0, 62.0]])
    lat, lon = g.to_geodetic(xy)
    assert np.allclose(g.from_geodetic(lat, lon), xy, atol=1e-6)


@pytest.mark.skipif(not MS_F3.exists(), reason="Microsoft indoor data absent")
def test_ms_floor_in_the_waypoints_metres():
    from benchmarks.datasets.ms_indoor import _waypoints_only

    plan = read_ms_floor(MS_F3)
    info = json.loads((MS_F3 / "floor_info.json").read_text())["map_info"]
    x0, y0, x1, y1 = plan.bounds()
    assert abs(x0) < 0.01 and abs(y0) < 0.01  # the tangent plane bends by a millimetre
    assert x1 == pytest.approx(info["width"], abs=0.01) and y1 == pytest.approx(info["height"], abs=0.01)
    assert len(plan.obstacles) == 275 and len(plan.walls) > 2000
    files = sorted((MS_F3 / "path_data_files").glob("*.txt*"))[:4]
    pts = np.vstack([np.column_stack([lm.east_m, lm.north_m]) for lm in map(_waypoints_only, files)])
    assert plan.is_walkable(pts).all()  # every surveyor waypoint in a corridor


# ---------------------------------------------------------------------------
# walls from images


def room_image(px_per_m: int = 20):
    """A 10 m x 6 m room (3-px black walls, grey noise-free floor) with an interior wall at x = 5 m and a 1 m door."""
    h, w = 6 * px_per_m, 10 * px_per_m
    img = np.full((h, w), 235.0)
    img[:3, :] = img[-3:, :] = 10.0
    img[:, :3] = img[:, -3:] = 10.0
    x = 5 * px_per_m
    img[:, x - 1:x + 2] = 10.0
    img[2 * px_per_m:3 * px_per_m, x - 1:x + 2] = 235.0  # the door: rows 2-3 m from the top
    return img


def test_otsu_and_boundary_vectorisation():
    img = room_image()
    thr = otsu_threshold(img)
    assert 10 < thr <= 235
    square = np.zeros((4, 5), dtype=bool)
    square[1:3, 1:4] = True
    segs = mask_boundary_segments(square)
    assert len(segs) == 4  # merged into the rectangle's 4 sides
    assert sorted(map(tuple, segs.tolist())) == sorted([(1, 1, 4, 1), (1, 3, 4, 3), (1, 1, 1, 3), (4, 1, 4, 3)])


def test_walls_from_image_keep_the_door_open():
    img = room_image()
    walls = walls_from_image(img, 0.05, cell_m=0.1)  # y up, origin at the top-left corner: the room is y in [-6, 0]
    grid = WallGrid(walls, cell_m=2.0)
    left, right = [2.5, -3.0], [7.5, -3.0]
    through_door, through_wall = [[4.3, -2.5], [5.7, -2.5]], [[4.3, -4.5], [5.7, -4.5]]
    assert not grid.crosses([through_door[0]], [through_door[1]])[0]
    assert grid.crosses([through_wall[0]], [through_wall[1]])[0]
    assert grid.crosses([left], [[-1.0, -3.0]])[0]  # the outer wall
    assert not grid.crosses([left], [[3.5, -2.0]])[0]


def test_ipin_cal_format(tmp_path):
    from PIL import Image

    cal = tmp_path / "plan.cal"
    cal.write_text("% comment\n%\nroom.png other.png\n0 -1\n100 100\n49.46 49.46\n11.11 11.11\n-20.7 -20.7\n"
                   "0.05 0.05\n")
    cals = read_ipin_cal(cal)
    assert sorted(cals) == [-1, 0] and cals[0].image == "room.png" and cals[0].m_per_px == 0.05
    Image.fromarray(room_image().astype(np.uint8)).save(tmp_path / "room.png")
    plan = read_ipin_floor(tmp_path, 0, read_image=read_floor_image)
    assert plan.georef.rotation_rad == pytest.approx(math.radians(20.7))
    x0, y0, x1, y1 = plan.bounds()
    assert (x0, y0, x1, y1) == pytest.approx((-5.0, -3.0, 5.0, 3.0))  # centred on the image
    bad = tmp_path / "bad.cal"
    bad.write_text("a.png\n0\n")
    with pytest.raises(ValueError):
        read_ipin_cal(bad)


@pytest.mark.skipif(not IPIN_MAPS.exists(), reason="IPIN 2023 floor maps absent")
def test_ipin_cal_of_the_competition():
    cals = read_ipin_cal(IPIN_MAPS / "calib_mapa_Nuremberg.cal")
    assert sorted(cals) == [-2, -1, 0]
    assert cals[-1].image == "Map_Floor_-01.png" and cals[-1].rotation_deg == pytest.approx(-20.736)


# ---------------------------------------------------------------------------
# the particle filter against simulator truth


@pytest.fixture(scope="module")
def l_walk():
    from desktop.simulator import simulate_walk

    return simulate_walk([(0.0, 0.0), (40.0, 0.0), (40.0, 30.0)], rate_hz=25.0, seed=5).truth


def _measured(truth, bias_deg: float, seed: int = 0, scale: float = 1.0):
    rng = np.random.default_rng(seed)
    n = truth.n_steps
    return StepArrays(truth.step_t_ns, truth.step_length_m * scale * (1 + rng.normal(0, 0.03, n)),
                  truth.step_heading_rad + math.radians(bias_deg) + rng.normal(0, math.radians(3), n))


def _start(truth):
    return (int(truth.step_t_ns[0]) - 1, truth.start_east_m, truth.start_north_m, 0.3)


def test_heading_bias_recovered_in_an_l_corridor(l_walk):
    plan = corridor_l()
    steps = _measured(l_walk, 12.0)
    r = map_match(steps, plan, start=_start(l_walk), seed=1)
    free = map_match(steps, None, start=_start(l_walk), seed=1)
    err = np.hypot(r.east_m - l_walk.step_east_m, r.north_m - l_walk.step_north_m)
    err_free = np.hypot(free.east_m - l_walk.step_east_m, free.north_m - l_walk.step_north_m)
    assert math.degrees(r.final_bias_rad) == pytest.approx(12.0, abs=3.0)
    assert err[-1] < 1.5 and err_free[-1] > 5.0
    assert plan.is_walkable(np.column_stack([r.east_m, r.north_m])).all()
    assert r.diagnostics["deaths"] > 0 and r.diagnostics["recoveries"] == 0


def test_living_particles_never_cross_a_wall(l_walk):
    plan = corridor_l(width=1.6)
    steps = _measured(l_walk, -8.0, seed=2, scale=1.1)
    pf = ParticleFilter(plan, ParticleConfig(n_particles=300), seed=3)
    pf.start(*_start(l_walk))
    grid = plan.grid(pf.config.cell_m)
    for i in range(len(steps.t_ns)):
        before = pf.xy.copy()
        pf.update(StepArrays(int(steps.t_ns[i]), float(steps.length_m[i]), float(steps.heading_rad[i])))
        alive = pf.w > 0
        assert plan.is_walkable(pf.xy[alive]).all()
        assert np.all(np.isfinite(pf.xy)) and np.all(np.isfinite(pf.w))
        if pf.diagnostics.resamples == 0:  # no reordering yet: each particle's own move
            assert not grid.crosses(before[alive], pf.xy[alive]).any()


def test_streaming_equals_batch(l_walk):
    plan = corridor_l()
    steps = _measured(l_walk, 5.0)
    fixes = [(int(l_walk.step_t_ns[30]), float(l_walk.step_east_m[30]), float(l_walk.step_north_m[30]), 0.5)]
    batch = map_match(steps, plan, start=_start(l_walk), fixes=fixes, seed=4)
    pf = ParticleFilter(plan, seed=4)
    pf.start(*_start(l_walk))
    live = []
    for i in range(len(steps.t_ns)):
        if i == 31:
            pf.fix(*fixes[0])
        live.append(pf.update(StepArrays(int(steps.t_ns[i]), float(steps.length_m[i]), float(steps.heading_rad[i]))))
    assert np.array_equal(batch.east_m, [e.east_m for e in live])
    assert np.array_equal(batch.bias_rad, [e.bias_rad for e in live])
    assert batch.diagnostics == pf.diagnostics.as_dict()


def test_a_fix_pulls_the_estimate_and_shrinks_the_spread():
    pf = ParticleFilter(None, ParticleConfig(n_particles=1000), seed=0)
    e0 = pf.start(0, 0.0, 0.0, 3.0)
    e1 = pf.fix(1, 4.0, 0.0, 1.0)
    assert e1.east_m > 3.0 and abs(e1.north_m) < 0.5
    assert e1.spread_m < 0.6 * e0.spread_m
    far = pf.fix(2, 100.0, 0.0, 1.0)  # beyond any particle: the cloud is reset around it
    assert far.east_m == pytest.approx(100.0, abs=0.3) and pf.diagnostics.fix_resets == 1


def test_fixes_correct_a_drifting_walk(l_walk):
    steps = _measured(l_walk, 15.0, scale=1.1)
    k = np.arange(20, l_walk.n_steps, 20)
    fixes = [(int(l_walk.step_t_ns[i]), float(l_walk.step_east_m[i]), float(l_walk.step_north_m[i]), 0.5) for i in k]
    r = map_match(steps, None, start=_start(l_walk), fixes=fixes, seed=0, smooth=True)
    free = map_match(steps, None, start=_start(l_walk), seed=0)
    err = np.hypot(r.east_m - l_walk.step_east_m, r.north_m - l_walk.step_north_m)
    err_free = np.hypot(free.east_m - l_walk.step_east_m, free.north_m - l_walk.step_north_m)
    sm = np.hypot(r.smoothed_east_m - l_walk.step_east_m, r.smoothed_north_m - l_walk.step_north_m)
    assert np.median(err) < 0.4 * np.median(err_free)
    assert np.median(sm) <= np.median(err) + 0.2
    assert math.degrees(r.final_bias_rad) == pytest.approx(15.0, abs=5.0)


def test_all_particles_dead_recovers_without_nan():
    wall = FloorPlan(wall_lines=[[1.0, -5.0, 1.0, 5.0]])
    pf = ParticleFilter(wall, ParticleConfig(n_particles=200, bias_sd_rad=0.01, heading_sd_rad=0.01), seed=0)
    pf.start(0, 0.0, 0.0, 0.05)
    for t in range(1, 6):  # walking East into the wall, 1.5 m steps
        e = pf.update(StepArrays(t, 1.5, 0.0))
        assert np.all(np.isfinite(pf.xy)) and math.isfinite(e.east_m)
        assert (pf.xy[:, 0] < 1.0).all()  # nobody passed
    assert pf.diagnostics.recoveries >= 1 and pf.diagnostics.retries >= 1
    e = pf.update(StepArrays(7, float("nan"), 0.0))  # a step without a length: the walker stands
    assert math.isfinite(e.east_m)


def test_start_from_gps_through_the_georeference():
    plan = corridor_l()
    lat, lon = plan.georef.to_geodetic(np.array([[20.0, 0.0]]))
    pf = ParticleFilter(plan, seed=0)
    e = pf.start_gps(0, float(lat[0]), float(lon[0]), 1.0)
    assert e.east_m == pytest.approx(20.0, abs=0.2) and abs(e.north_m) < 0.2
    assert plan.is_walkable(pf.xy).all()  # drawn inside the corridor only
    with pytest.raises(ValueError):
        ParticleFilter(None).start_gps(0, 47.0, 8.0, 5.0)
