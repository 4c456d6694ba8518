"""The lines the app keeps for its track view stay bounded on a long walk (issue #30).

Before: the session appended every step's point to the dead-reckoned and the fused line and every fix to
the fix lists, for the whole walk (about 0.4 MB an hour with GPS).  Now a line past
``VIEW_MAX_POINTS`` is thinned (the old part decimated, the recent points whole) into new lists, the fixes
keep the last ``VIEW_MAX_FIXES``; the exports still read every step back from disk.  The bounds are made
small here so that a 2-minute walk crosses them many times.
"""

from __future__ import annotations

import math

import numpy as np

import app.session as S
from app.overlay import thin_line
from app.settings import Settings
from app.sources import ReplaySource
from desktop.simulator import outdoor_walk


def test_thin_line_keeps_the_recent_points_the_ends_and_the_segment_tags():
    rng = np.random.default_rng(5)
    h = np.cumsum(rng.normal(0, 0.2, 5000))
    e, n = np.cumsum(0.7 * np.cos(h)).tolist(), np.cumsum(0.7 * np.sin(h)).tolist()
    e, n = [0.0] + e, [0.0] + n
    tags = ["dr" if (k // 300) % 2 else "fused" for k in range(5000)]
    E, N, T, tol = thin_line(e, n, tags, max_points=1000, recent=200)
    assert len(E) == len(N) <= 500 and len(T) == len(E) - 1 and tol >= 1.0
    assert E[-200:] == e[-200:] and N[-200:] == n[-200:] and T[-199:] == tags[-199:]  # the recent part whole
    assert (E[0], N[0]) == (0.0, 0.0)
    # every kept point is one of the line's, in order, and no dropped point is farther than tol from the line
    idx = [e.index(x) for x in E]
    assert idx == sorted(idx)
    for a, b in zip(idx, idx[1:]):
        assert T[idx.index(b) - 1] == tags[b - 1]  # a segment keeps its last step's tag
        for k in range(a + 1, b):
            assert math.hypot(e[k] - e[a], n[k] - n[a]) < tol


def test_a_long_session_keeps_bounded_view_lists_and_exports_every_step(monkeypatch, tmp_path):
    monkeypatch.setattr(S, "VIEW_MAX_POINTS", 60)
    monkeypatch.setattr(S, "VIEW_RECENT_POINTS", 10)
    monkeypatch.setattr(S, "VIEW_MAX_FIXES", 20)
    w = outdoor_walk(1, minutes=2.0, rate_hz=50.0)  # 50 Hz: the rate is not the subject
    ses = S.Session(ReplaySource(w.recording, speed=math.inf, max_chunk=500),
                    pipeline_factory=Settings().pipeline_factory())
    ses.start()
    longest = {"track": 0, "fused": 0, "fixes": 0}
    for _ in range(100000):
        ses.tick(budget_s=0.01)
        longest["track"] = max(longest["track"], len(ses.track_east))
        longest["fused"] = max(longest["fused"], len(ses.fused_east))
        longest["fixes"] = max(longest["fixes"], len(ses.fix_east))
        assert len(ses.fused_source) == len(ses.fused_east) - 1
        if ses.finished:
            break
    n = len(ses.steps)
    assert ses.finished and n > 150 and ses.gps_anchored and ses.view_generation >= 4
    assert longest["track"] <= 60 + 1 and longest["fused"] <= 60 + 1 and longest["fixes"] <= 24 + 1
    # the last points are the walk's own, the fixes the fusion's last
    last = list(ses.steps.last)[-5:]
    assert ses.track_east[-5:] == [s.east_m for s in last] and ses.track_north[-5:] == [s.north_m for s in last]
    fused = ses.gnss.steps[n - 5:]
    assert ses.fused_east[-5:] == [f.east_m for f in fused] and ses.fused_source[-5:] == [f.source for f in fused]
    assert ses.fix_accepted[-1] == ses.gnss.fixes[-1].accepted and ses.gps_overlay().n_fixes == len(ses.gnss.fixes)
    # the exports read every step back: the track CSV and the fused GeoJSON have one row / point per step
    out = ses.export(str(tmp_path), "walk")
    assert not out["errors"]
    with open(out["csv"], encoding="utf-8") as f:
        assert sum(1 for _ in f) == n + 1
    import json

    with open(out["geojson"], encoding="utf-8") as f:
        gj = json.load(f)
    assert gj["features"][0]["properties"]["n_steps"] == n and "sigma_m" in gj["features"][1]["properties"]
    ses.close()


def test_the_service_ui_follows_the_thinned_lists(monkeypatch, tmp_path):
    """The UI process polls what is new since its lists; when the session thins its lists the UI gets them
    whole again (``view``), so its lists stay the session's."""
    import json

    from app.service import ServiceSession, TrackingService

    monkeypatch.setattr(S, "VIEW_MAX_POINTS", 60)
    monkeypatch.setattr(S, "VIEW_RECENT_POINTS", 10)
    monkeypatch.setattr(S, "VIEW_MAX_FIXES", 20)
    w = outdoor_walk(2, minutes=1.5, rate_hz=50.0)
    data = tmp_path / "data"
    data.mkdir()
    Settings(use_gps=True).save(str(data / "settings.json"))
    svc = TrackingService({"data_dir": str(data), "record_path": None},
                          source_factory=lambda rate: ReplaySource(w.recording, speed=math.inf, max_chunk=300))
    svc.start()

    class Direct:  # the socket's JSON both ways, without the socket
        def request(self, op, **kw):
            return json.loads(json.dumps(svc.handle(json.loads(json.dumps({"op": op, **kw})))))

    ui = ServiceSession(Direct(), poll_interval_s=0.0)
    ses, seen = svc.session, set()
    for _ in range(10000):
        svc.step(0.01)
        ui.poll()
        seen.add(ses.view_generation)
        assert ui.track_east == ses.track_east and ui.fused_east == ses.fused_east
        assert ui.fused_source == ses.fused_source and ui.fix_east == ses.fix_east
        if ses.finished:
            break
    assert ses.finished and len(seen) >= 3 and len(ui.track_east) <= 61
