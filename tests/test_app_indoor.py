"""The floor plan in the app (issue #16, item 4): plan choice in the settings, the particle filter beside the
session's tracker (start by "I am here" or a recording's landmark, tap fixes, health line, exports), the
service's ops, and the walls and the map-matched position in the track view (canvas instructions, headless)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from app import kivy_env

kivy_env.prepare(headless=True)  # before anything imports kivy

from app.indoor import FIX_SD_M, MapMatcher, load_plan  # noqa: E402
from app.session import Session  # noqa: E402
from app.settings import Settings  # noqa: E402
from app.sources import ReplaySource  # noqa: E402
from core.indoor import FloorPlan, write_geojson  # noqa: E402
from core.recording import make_stream  # noqa: E402
from desktop.simulator import simulate_walk  # noqa: E402

#: an L-shaped corridor, 2 m wide: 30 m East, then 20 m North (as tests/test_cli_map.py)
CORRIDOR = [[-1.0, -1.0], [31.0, -1.0], [31.0, 21.0], [29.0, 21.0], [29.0, 1.0], [-1.0, 1.0]]
END = (30.0, 20.0)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    d = tmp_path_factory.mktemp("plan")
    plan = FloorPlan(areas=[(np.array(CORRIDOR), [])], wall_lines=[[10.0, -1.0, 10.0, -0.2]], name="corridor")
    write_geojson(plan, d / "corridor.geojson")
    # a 12 degree heading error: the raw track leaves the corridor, the map keeps it in
    w = simulate_walk(((0.0, 0.0), (30.0, 0.0), END), seed=12, rate_hz=50.0, still_start_s=1.5, still_end_s=1.5,
                      phone_yaw_offset_deg=12.0)
    return plan, str(d / "corridor.geojson"), w


def _session(rec, plan, *, here_at_start=True, **kw):
    ses = Session(ReplaySource(rec, speed=math.inf, max_chunk=200), plan=plan, plan_name="corridor",
                  pipeline_factory=Settings(use_gps=False).pipeline_factory(), **kw)
    ses.start()
    ses.tick(budget_s=0.0, chunk=100)  # under a second of standing still
    if here_at_start:
        assert not ses.steps
        ses.here(0.0, 0.0)
    return ses


def _finish(ses):
    for _ in range(100000):
        ses.tick(budget_s=0.01)
        if ses.finished:
            return ses
    raise AssertionError("replay did not finish")


@pytest.fixture(scope="module")
def matched(corridor):
    plan, _, w = corridor
    return _finish(_session(w.recording, plan))


def test_session_with_a_plan_keeps_every_map_matched_position_walkable(corridor, matched, tmp_path):
    plan, _, w = corridor
    ses = matched
    m = ses.map_overlay()
    xy = np.c_[m.east, m.north]
    assert m.placed and len(xy) == len(ses.steps) + 1 > 50  # the placement, then one point per step
    assert plan.is_walkable(xy).all()
    err_map = math.dist(xy[-1], END)
    raw = np.c_[ses.track_east, ses.track_north] + m.raw_offset
    assert err_map < 2.5 and math.dist(raw[-1], END) > err_map + 2.0
    assert not plan.is_walkable(raw).all()  # without the map the walk goes through a wall
    text = ses.health_text()
    assert "map corridor:" in text and "recoveries" in text and "ESS" in text and "ms/step" in text
    # exports: the map-matched position per step beside the raw one
    out = ses.export(str(tmp_path), "walk")
    assert not out["errors"] and {"geojson", "csv", "map_csv"} <= set(out)
    pts = [f["properties"] for f in json.loads(open(out["geojson"]).read())["features"]
           if f["geometry"]["type"] == "Point"]
    assert len(pts) == len(ses.steps) and {"east_m", "mm_east_m", "mm_north_m", "mm_spread_m"} <= set(pts[-1])
    got = [(p["mm_east_m"], p["mm_north_m"]) for p in pts if p["mm_east_m"] is not None]
    np.testing.assert_allclose(got, xy[1:], atol=2e-3)
    rows = list(csv.DictReader(open(out["map_csv"])))
    assert len(rows) == len(ses.steps) and float(rows[-1]["raw_east_m"]) == pytest.approx(ses.track_east[-1],
                                                                                          abs=1e-3)
    assert float(rows[-1]["mm_north_m"]) == pytest.approx(xy[-1, 1], abs=1e-3)


def test_a_tap_fix_moves_the_estimate_and_a_landmark_starts_a_replay(corridor, matched):
    plan, _, w = corridor
    mm = matched.map
    before = (mm.est.east_m, mm.est.north_m)
    n = len(mm.east)
    target = (30.0, 16.5)  # 3 m back down the second leg
    matched.here(*target)
    after = (mm.est.east_m, mm.est.north_m)
    assert mm.pf.diagnostics.fixes == 1 and len(mm.east) == n + 1
    assert math.dist(after, target) < math.dist(before, target) - 0.3  # Bayes: towards the tap, not onto it
    # a tap far from every particle (more than 5 sd): the cloud is drawn anew around it
    matched.here(0.0, 0.0)
    assert mm.pf.diagnostics.fix_resets == 1 and math.dist((mm.est.east_m, mm.est.north_m), (0, 0)) < 1.5
    assert mm.est.spread_m < 2 * FIX_SD_M and plan.is_walkable(np.c_[mm.east, mm.north]).all()
    # a recording's landmark (plan metres) starts the filter when the steps pass its time, without a tap (the
    # whole replay: the app's test below)
    ses = _session(w.recording, plan, here_at_start=False)
    t0 = int(w.recording.t0_ns + 1.0e9)
    ses.start_map_at(t0, 0.0, 0.0)
    assert not ses.map.placed and "first landmark" in ses.map.text()
    while len(ses.steps) < 3:
        ses.tick(budget_s=0.01)
    assert ses.map.placed and ses.map.east[0] == pytest.approx(0.0, abs=1.0)
    assert len(ses.map.east) == 1 + sum(s.t_ns > t0 for s in ses.steps) == 1 + ses.map.pf.diagnostics.steps
    # no plan: no map, and "here" says why
    ses.set_plan(None)
    assert ses.map_overlay() is None and "map" not in ses.health_text()
    with pytest.raises(ValueError, match="no floor plan"):
        ses.here(0.0, 0.0)


def test_plan_setting_round_trips_and_bad_plans_are_messages(corridor, tmp_path):
    _, path, _ = corridor
    p = tmp_path / "settings.json"
    Settings(floor_plan=path).save(str(p))
    s = Settings.load(str(p))
    assert s.floor_plan == path and not s.problems
    plan, name, problem = s.load_floor_plan()
    assert name == "corridor" and not problem and len(plan.walls) == len(CORRIDOR) + 1
    Settings().save(str(p))
    assert "floor_plan" not in json.loads(p.read_text()) and Settings.load(str(p)).load_floor_plan() == (None, "", "")
    p.write_text(json.dumps({"floor_plan": 3}))
    s = Settings.load(str(p))
    assert s.floor_plan == "" and "floor_plan" in s.problems[0]
    s.floor_plan = str(tmp_path / "gone.geojson")
    assert s.load_floor_plan()[2].startswith("floor plan not used") and "no such file" in s.load_floor_plan()[2]
    ipin = tmp_path / "floormaps"
    ipin.mkdir()
    (ipin / "x.cal").write_text("%\n")
    with pytest.raises(ValueError, match="Pillow"):
        load_plan(str(ipin))
    (tmp_path / "bad.geojson").write_text("{]")
    with pytest.raises(ValueError, match="not a floor plan"):
        load_plan(str(tmp_path / "bad.geojson"))


def test_the_service_runs_the_filter_and_the_ui_polls_it(corridor, tmp_path):
    """The live path without sockets: the service reads the plan from the settings, ``here`` places, a poll
    brings the map-matched points and the status the estimate (what ServiceSession.map_overlay builds)."""
    from app.service import TrackingService

    _, path, w = corridor
    data = tmp_path / "data"
    data.mkdir()
    Settings(floor_plan=path, use_gps=False).save(str(data / "settings.json"))
    svc = TrackingService({"data_dir": str(data), "record_path": None},
                          source_factory=lambda rate: ReplaySource(w.recording, speed=math.inf, max_chunk=200))
    svc.start()
    assert svc.session.map is not None and svc.handle({"op": "poll"})["status"]["map"]["placed"] is False
    svc.step(0.0)
    assert svc.handle({"op": "here", "east": 0.0, "north": 0.0})["ok"]
    while len(svc.session.steps) < 20:  # 20 steps are enough for the protocol
        svc.step(0.01)
    r = svc.handle({"op": "poll", "track_id": 0, "since": {"map": 3}})
    st = r["status"]["map"]
    assert st["placed"] and "map corridor" in st["text"] and "map corridor" in r["status"]["health"]
    assert r["map"][0] == svc.session.map.east[3:] and st["position"] == pytest.approx(r["map"][0][-1:] +
                                                                                       r["map"][1][-1:])
    json.dumps(r)  # what goes over the socket
    Settings(use_gps=False).save(str(data / "settings.json"))  # the user chose no plan
    r = svc.handle({"op": "plan"})
    assert r["track_id"] == 1 and r["status"]["map"] is None
    svc.stop()


def test_track_view_draws_the_walls_once_and_the_map_matched_position(corridor, matched):
    """Instructions, not pixels: one wall Mesh holding every wall segment in metres under the plan's
    transform, untouched by a pan or a zoom; the map-matched track over the shifted raw one, the marker on
    the estimate with its 2-sigma ellipse; a tap in Here mode gives plan metres."""
    from kivy.base import EventLoop
    from kivy.core.window import Window
    from kivy.tests.common import UnitTestTouch

    from app import track_view as T

    plan, _, _ = corridor
    ses = matched
    EventLoop.ensure_window()
    tv = T.TrackView(size=(400, 600), pos=(0, 0), size_hint=(None, None))
    Window.add_widget(tv)
    try:
        tv.set_plan(plan)
        tv.set_track(ses.track_east, ses.track_north)
        tv.set_map(ses.map_overlay())
        tv.fit()
        tv._redraw()
        meshes = tv.wall_meshes
        assert len(meshes) == 1 and meshes[0].mode == "lines"
        v = np.array(meshes[0].vertices).reshape(-1, 2, 4)[:, :, :2].reshape(-1, 4)
        np.testing.assert_array_equal(v, plan.walls)  # in metres
        vertices = meshes[0].vertices
        n_instructions = len(tv.canvas.children)
        translate, scale = tv._plan_world[0]
        assert tuple(translate.xy) == pytest.approx(tv.vp.to_screen(0.0, 0.0)) and scale.x == tv.vp.scale
        assert tv._wall_color.rgba == pytest.approx(list(T.WALL_COLOR))
        # the map-matched track, the raw one faint and shifted by the offset, the marker and the ellipse
        m = ses.map_overlay()
        assert tv.shows_map and tv.current_position == pytest.approx(m.position)
        np.testing.assert_allclose(np.array(tv._map_line.points_m()).reshape(-1, 2), np.c_[m.east, m.north])
        raw_t, _ = tv._world[0]
        assert tuple(raw_t.xy) == pytest.approx(tv.vp.to_screen(*m.raw_offset))
        assert tv._line_color.a == pytest.approx(T.RAW_UNDER_FUSED_ALPHA)
        px, py = tv.vp.to_screen(*m.position)
        p = (np.array(tv._ellipse.points).reshape(-1, 2) - (px, py)) / tv.vp.scale
        q = np.einsum("ij,jk,ik->i", p, np.linalg.inv(np.array(m.cov)), p)
        np.testing.assert_allclose(q, T.ELLIPSE_SIGMA ** 2, rtol=1e-3)
        assert "map · ±" in tv._legend.text
        # a pan, a zoom, steps: the walls are not rebuilt
        tv.vp.pan(40.0, -25.0)
        tv.vp.zoom_at(1.5, 200, 300)
        tv._view_changed()
        tv.set_map(ses.map_overlay())
        tv._redraw()
        assert tv.wall_meshes[0].vertices is vertices or tv.wall_meshes[0].vertices == vertices
        assert len(tv.canvas.children) == n_instructions
        assert tuple(translate.xy) == pytest.approx(tv.vp.to_screen(0.0, 0.0)) and scale.x == tv.vp.scale
        # Here: a tap in place mode fires on_here in plan metres, once; a drag is no tap
        got = []
        tv.bind(on_here=lambda w, e, n: got.append((e, n)))
        world = tv.vp.to_world(150, 250)
        tv.place_mode = True
        t = UnitTestTouch(150, 250)
        t.touch_down()
        t.touch_up()
        assert got == [pytest.approx(world)] and not tv.place_mode
        tv.place_mode = True
        t = UnitTestTouch(100, 100)
        t.touch_down()
        t.touch_move(180, 100)
        t.touch_up()
        assert len(got) == 1 and tv.place_mode
        # no plan: no walls, no map
        tv.set_plan(None)
        tv._redraw()
        assert not tv.wall_meshes and not tv.shows_map and tv._map_line.points_m() == []
    finally:
        Window.remove_widget(tv)


def test_matcher_rows_follow_the_session_steps():
    """Steps before the placement (their peak not later than the tap) get no map row and move nothing."""

    class S:
        def __init__(self, t, e):
            self.t_ns, self.length_m, self.heading_rad, self.east_m, self.north_m = t, 0.7, 0.0, e, 0.0

    plan = FloorPlan(areas=[(np.array(CORRIDOR), [])])
    mm = MapMatcher(plan, steps_before=2)
    mm.add_step(S(10, 0.7))
    mm.here(20, 5.0, 0.0)
    mm.add_step(S(15, 1.4))  # walked before the tap, completed after it
    mm.add_step(S(30, 2.1))
    assert len(mm.step_east) == 5 and np.isnan(mm.step_east[:4]).all() and math.isfinite(mm.step_east[4])
    assert mm.raw_offset == pytest.approx((5.0 - 1.4, 0.0))
    props = mm.export_properties([15, 30, 99], [0, 1, 10, 15, 30])
    assert props["mm_east_m"][0] is None and props["mm_east_m"][1] is not None and props["mm_east_m"][2] is None
    assert "mm_lat_deg" not in props


APP = r"""
import json, sys
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.config import Config
Config.set("graphics", "width", "400"); Config.set("graphics", "height", "700")
from kivy.clock import Clock
from kivy.tests.common import UnitTestTouch
from app.main_app import PDRApp

rec, data, out, result = sys.argv[1:5]
app = PDRApp(recording=rec, speed="max", data_dir=data, out_dir=out)
res = {}

def at_end(dt):
    ses = app.session
    if ses is None or not ses.finished:
        return True
    tv = app.track_view
    m = ses.map_overlay()
    res.update(has_plan=app.has_plan, plan_text=app.plan_text, walls=len(tv.wall_meshes),
               placed=m.placed, east=list(m.east), north=list(m.north), fixes=ses.map.pf.diagnostics.fixes,
               health="map corridor" in ses.health_text())
    app.root.ids.screens.current = "track"
    tv.follow = False
    tv.fit()
    tv._redraw()
    x, y = tv.vp.to_screen(30.0, 18.0)
    x, y = tv.to_window(x, y)
    tv.place_mode = True  # the Here button
    t = UnitTestTouch(x, y)
    t.touch_down()
    t.touch_up()
    res.update(fixes_after=ses.map.pf.diagnostics.fixes, message=app.message)
    res["export"] = sorted(k for k in app.export() if k != "errors")
    res["chose_none"] = app.choose_plan("")
    res.update(walls_after=len(tv.wall_meshes), map_after=ses.map_overlay() is None,
               saved=json.load(open(data + "/settings.json")).get("floor_plan"))
    json.dump(res, open(result, "w"))
    app.stop()
    return False

Clock.schedule_interval(at_end, 0.05)
app.run()
"""


def test_the_app_replays_on_the_plan_from_the_landmark_and_a_tap_in_here_mode_is_a_fix(corridor, tmp_path):
    """The real app (a subprocess: one App.run per process): the plan named in settings.json is drawn and used,
    the replay starts at the recording's landmark, a tap in Here mode is a fix, the export has the map's CSV,
    choosing no plan removes the walls and is saved."""
    import subprocess
    import sys
    from pathlib import Path

    from core.recording import write_recording

    plan, path, w = corridor
    rec = w.recording
    streams = dict(rec.streams)
    streams["posi"] = make_stream("posi", np.array([rec.t0_ns + 1_000_000_000, rec.t0_ns + 2_000_000_000]),
                                  np.array([[0.0, 0.0], [0.4, 0.0]]), columns=["east_m", "north_m"])
    rec_path = tmp_path / "walk.csv"
    write_recording(str(rec_path), type(rec)(streams, device=rec.device, metadata=rec.metadata))
    data = tmp_path / "data"
    data.mkdir()
    (data / "settings.json").write_text(json.dumps({"floor_plan": path, "use_gps": False}))
    root = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, "-c", APP, str(rec_path), str(data), str(tmp_path / "out"),
                        str(tmp_path / "res.json")], cwd=root, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((tmp_path / "res.json").read_text())
    assert res["has_plan"] and res["plan_text"] == "corridor" and res["walls"] == 1 and res["health"]
    assert res["placed"] and res["fixes"] == 0 and len(res["east"]) > 50
    assert plan.is_walkable(np.c_[res["east"], res["north"]]).all()
    assert math.dist((res["east"][-1], res["north"][-1]), END) < 2.5
    assert res["fixes_after"] == 1 and res["message"].startswith("you are at 30.0, 18.0 m")
    assert "map_csv" in res["export"]
    assert res["chose_none"] and res["walls_after"] == 0 and res["map_after"] and res["saved"] is None
