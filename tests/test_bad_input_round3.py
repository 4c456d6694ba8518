"""Bad input, round 3 (issue #30): each class tried as a user would, ``pdr replay FILE`` on a recording
written with :func:`core.recording.write_recording` (small simulated walks), and what happens now.

Every test failed on the code before the issue (the outcome before is in each docstring;
benchmarks/BAD_INPUT_RESULTS.md, round 3, lists them).
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from core.recording import Recording, RecordingError, make_stream, read_recording, write_recording
from core.validation import StreamProblem
from desktop.cli import main


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))  # never the user's own profile


@pytest.fixture(scope="module")
def walk():
    """A 30-s simulated walk with GPS at 1 Hz (truth known), acc and gyro at 100 Hz, mag at 50 Hz."""
    from desktop.simulator import GpsModel, simulate_walk

    return simulate_walk([(0, 0), (20, 0), (20, 6)], seed=3, gps=GpsModel(), still_start_s=1.0,
                         still_end_s=1.0).recording


def _copy(rec: Recording, **streams) -> Recording:
    out = Recording(dict(rec.streams), dict(rec.device), dict(rec.metadata))
    for name, s in streams.items():
        if s is None:
            del out.streams[name]
        else:
            out.streams[name] = s
    return out


def _replay(tmp_path, rec: Recording, *args, name="walk.csv"):
    """``pdr replay FILE --json ARGS``: (exit code, JSON summary or None, stderr)."""
    p = tmp_path / name
    write_recording(str(p), rec)
    return _main(["replay", str(p), "--json", "--no-progress", *args])


def _main(argv):
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse
            code = e.code
    text = out.getvalue()
    return code, (json.loads(text) if code == 0 and text.strip() else None), err.getvalue()


# ---------------------------------------------------------------------------
# tracebacks


def test_a_floor_plan_whose_features_are_not_a_list_is_one_line_naming_the_file_and_the_feature(tmp_path, walk):
    """Before: ``AttributeError: 'dict' object has no attribute 'get'`` in core/indoor/floorplan.py."""
    plan = tmp_path / "plan.geojson"
    plan.write_text(json.dumps({"type": "FeatureCollection", "features": {"kind": "walkable"}}))
    code, _, err = _replay(tmp_path, walk, "--map", str(plan), "--start", "0,0")
    assert code == 2 and "Traceback" not in err
    line = [ln for ln in err.splitlines() if ln.startswith("pdr: error:")]
    assert len(line) == 1 and str(plan) in line[0] and "'features' must be a list" in line[0]
    plan.write_text(json.dumps({"type": "FeatureCollection", "pdr_floorplan": {"units": "m"}, "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [9, 0], [9, "x"]]]}}]}))
    code, _, err = _replay(tmp_path, walk, "--map", str(plan), "--start", "0,0")
    assert code == 2 and str(plan) in err and "feature 0" in err and "not two numbers" in err


def test_a_gps_outage_start_too_large_for_an_integer_is_a_clear_cli_error(tmp_path, walk):
    """Before: ``OverflowError: cannot convert float infinity to integer`` in desktop/cli.py."""
    code, _, err = _replay(tmp_path, walk, "--gps-outage", "1e300:10")
    assert code == 2 and "Traceback" not in err and "--gps-outage" in err and "at most" in err


# ---------------------------------------------------------------------------
# GPS streams


def test_an_impossible_gps_speed_or_course_is_set_unknown_and_said(tmp_path, walk):
    """Before: read without a word (a speed of 2000 m/s and a course of 720 deg went to the fusion as they were)."""
    g = walk.streams["gps"]
    v = g.values.copy()
    v[:, 4], v[:, 5] = 2000.0, 720.0
    v[::2, 4], v[::2, 5] = g.values[::2, 4], g.values[::2, 5]  # half of them possible: those are kept as they are
    v[1, 4] = -1.0  # a negative speed too
    code, s, err = _replay(tmp_path, _copy(walk, gps=make_stream("gps", g.t_ns, v)))
    n_bad = len(g) // 2
    assert code == 0 and s["stream_problems"] == {"IMPOSSIBLE_MOTION": n_bad} and s["gps"]["fixes"] == len(g)
    assert "impossible speed or course" in err and "set unknown, their positions kept" in err
    rec = _read(tmp_path, _copy(walk, gps=make_stream("gps", g.t_ns, v)))
    got = rec.streams["gps"].values
    assert np.isnan(got[1::2, 4]).all() and np.isnan(got[1::2, 5]).all()
    np.testing.assert_array_equal(got[::2, 4:6], g.values[::2, 4:6])
    np.testing.assert_array_equal(got[:, :4], g.values[:, :4])


def test_impossible_fixes_give_no_origin_and_no_evaluation_against_them(tmp_path, walk):
    """Before: the first impossible fix became the GeoJSON origin (``origin_known: true``)."""
    g = walk.streams["gps"]
    v = g.values.copy()
    v[:, 0], v[:, 1] = 123.0, 400.0
    gj = tmp_path / "t.geojson"
    code, s, err = _replay(tmp_path, _copy(walk, gps=make_stream("gps", g.t_ns, v)), "--geojson", str(gj))
    assert code == 0
    assert json.loads(gj.read_text())["features"][0]["properties"]["origin_known"] is False
    assert s["stream_problems"] == {"IMPOSSIBLE_FIX": len(g)} and "gps" not in s.get("rates_hz", {})
    assert "gps_fixes" not in json.dumps(s.get("truth", {}))  # no evaluation against impossible fixes
    assert "all %d fixes are impossible" % len(g) in err
    v[::2, 0] = g.values[::2, 0]  # half of them possible: those are kept
    v[::2, 1] = g.values[::2, 1]
    rec = _read(tmp_path, _copy(walk, gps=make_stream("gps", g.t_ns, v)))
    assert len(rec.streams["gps"]) == (len(g) + 1) // 2 and rec.problems[0].count == len(g) // 2


def _read(tmp_path, rec, name="r.csv"):
    p = tmp_path / name
    write_recording(str(p), rec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_recording(str(p))


@pytest.mark.parametrize("factor, unit", [(10**6, "milliseconds"), (10**3, "microseconds")])
def test_a_gps_stream_in_ms_or_us_is_repaired_with_a_warning(tmp_path, walk, factor, unit):
    """Before: read as nanoseconds, the summary said 1050 s and a GPS rate of 1 MHz, 34 of 49 fixes gated.

    Repaired, the stream is fused as the same stream in nanoseconds is: the same fixes accepted, none gated.
    (Until issue #26 that was nearly all of them; the GPS judge now holds a stream's first 15-20 s back until
    it has judged it, on this 21-fix walk all but the anchor and the last few, so the count is compared with
    the nanosecond stream's rather than with the number of fixes.)"""
    g = walk.streams["gps"]
    _, s0, _ = _replay(tmp_path, walk, name="ns.csv")
    code, s, err = _replay(tmp_path, _copy(walk, gps=make_stream("gps", g.t_ns // factor, g.values)))
    assert code == 0 and s["duration_s"] == pytest.approx(walk.duration_s, abs=0.1)
    assert s["rates_hz"]["gps"] == pytest.approx(1.0, rel=0.05)
    assert s["stream_problems"] == {"OTHER_TIME_UNIT": len(g)} and f"are {unit}, not nanoseconds" in err
    assert s["gps"]["fixes_accepted"] == s0["gps"]["fixes_accepted"] >= 3 and s["gps"]["fixes_gated"] == 0
    assert s["gps"]["fixes_accepted"] + s["gps"]["fixes_judged_out"] >= len(g) - 2


def test_a_gps_stream_on_the_unix_clock_is_moved_with_the_offset_or_dropped_in_one_line(tmp_path, walk):
    """Before: a duration of 54 years in the summary and 34 of 49 fixes rejected by the gate, silently."""
    g = walk.streams["gps"]
    off = 1_700_000_000 * 10**9
    unix = _copy(walk, gps=make_stream("gps", g.t_ns + off, g.values))
    code, s, err = _replay(tmp_path, unix)
    assert code == 0 and s["duration_s"] == pytest.approx(walk.duration_s, abs=0.1)
    assert s["stream_problems"] == {"OTHER_CLOCK": len(g)} and "the stream is dropped" in err and "gps" not in s
    unix.metadata["unix_offset_ns"] = off
    rec = _read(tmp_path, unix)
    np.testing.assert_array_equal(rec.streams["gps"].t_ns, g.t_ns)
    assert rec.problems[0].problem is StreamProblem.OTHER_CLOCK and rec.problems[0].action == "repaired"


def test_a_fix_every_millisecond_is_decimated_with_a_message(tmp_path, walk):
    """Before: 48 000 fixes fused one by one (12 s for a 52-s walk against 0.8 s), no word."""
    g = walk.streams["gps"]
    t = np.arange(g.t_ns[0], g.t_ns[-1], 10**6)
    idx = np.searchsorted(g.t_ns, t).clip(0, len(g) - 1)
    code, s, err = _replay(tmp_path, _copy(walk, gps=make_stream("gps", t, g.values[idx])))
    assert code == 0 and s["rates_hz"]["gps"] <= 10.0 + 1e-9 and "decimated to 10 Hz" in err
    assert s["stream_problems"]["RATE_TOO_HIGH"] == len(t) - s["gps"]["fixes"]


# ---------------------------------------------------------------------------
# maps


def _plan(tmp_path, rings, name="p.geojson"):
    p = tmp_path / name
    p.write_text(json.dumps({"type": "FeatureCollection", "pdr_floorplan": {"units": "m"}, "features": [
        {"type": "Feature", "properties": {"kind": "walkable"},
         "geometry": {"type": "Polygon", "coordinates": [r]}} for r in rings]}))
    return p


def test_a_self_intersecting_polygon_is_refused_naming_the_file_and_the_feature(tmp_path, walk):
    """Before: accepted; the even-odd rule made half the bow tie outside and bent the track (17 m against 5 m)."""
    ok = [[-5, -5], [40, -5], [40, 20], [-5, 20]]
    bow = [[-5, -5], [40, 20], [40, -5], [-5, 20]]
    p = _plan(tmp_path, [ok, bow])
    code, _, err = _replay(tmp_path, walk, "--map", str(p), "--start", "0,0")
    assert code == 2 and str(p) in err and "feature 1" in err and "crosses itself" in err


def test_plan_size_and_vertex_limits_are_clear_and_a_big_ring_is_indexed(tmp_path):
    """Before: a 94 MB plan ran 5 minutes in silence (1.2 GB); a ring of a million vertices took 4 GB."""
    from core.indoor.floorplan import PlanFileError, RingIndex, read_geojson
    from core.indoor.geometry import points_in_polygon

    th = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    ring = np.column_stack([30 * np.cos(th), 20 * np.sin(th)])
    p = _plan(tmp_path, [ring.tolist()])
    with pytest.raises(PlanFileError, match=r"p\.geojson: feature 0: ring 0 of polygon 0 has 2000 vertices, over "
                                            "the limit of 1000"):
        read_geojson(p, max_ring_vertices=1000)
    with pytest.raises(PlanFileError, match="more than 1500 vertices"):
        read_geojson(p, max_vertices=1500)
    with pytest.raises(PlanFileError, match="over 0 MiB of text"):
        read_geojson(p, max_bytes=1000)
    plan = read_geojson(p)
    pts = np.random.default_rng(0).uniform(-35, 35, (3000, 2))
    np.testing.assert_array_equal(plan.is_walkable(pts), points_in_polygon(pts, ring))
    idx = RingIndex(ring)
    assert idx.bands > 100 and len(idx._edges) < 3 * len(ring)  # a point meets a band's edges, not 2000


def test_malformed_map_files_name_the_file(tmp_path):
    from core.indoor.floorplan import PlanFileError, read_geojson, read_ms_floor

    p = tmp_path / "bad.geojson"
    p.write_text("{not json")
    with pytest.raises(PlanFileError, match=r"bad\.geojson: not JSON"):
        read_geojson(p)
    d = tmp_path / "F1"
    d.mkdir()
    (d / "geojson_map.json").write_text(json.dumps({"type": "FeatureCollection", "features": [{"geometry": 3}]}))
    (d / "floor_info.json").write_text(json.dumps({"map_info": {"width": 10}}))
    with pytest.raises(PlanFileError, match=r"floor_info\.json: needs 'map_info'"):
        read_ms_floor(d)
    (d / "floor_info.json").write_text(json.dumps({"map_info": {"width": 10, "height": 5}}))
    with pytest.raises(PlanFileError, match=r"geojson_map\.json: feature 0: 'geometry'"):
        read_ms_floor(d)


# ---------------------------------------------------------------------------
# units and rates


def test_a_gyroscope_declared_in_deg_s_with_data_in_rad_s_is_refused_not_converted(tmp_path, walk):
    """Before: "converted" (x pi/180): every turn 57 times too small, the heading left to the magnetometer alone,
    without a word (BAD_INPUT_RESULTS round 3 listed it open: a still phone looks the same in both units)."""
    g = walk.streams["gyro"]
    code, _, err = _replay(tmp_path, _copy(walk, gyro=make_stream("gyro", g.t_ns, g.values, unit="deg/s")))
    assert code == 2 and "declared in deg/s" in err and "look like rad/s already" in err
    assert "accelerometer shows movement" in err
    # the same walk really in deg/s is read and converted
    code, s, _ = _replay(tmp_path, _copy(walk, gyro=make_stream("gyro", g.t_ns, np.degrees(g.values), unit="deg/s")))
    assert code == 0 and s["n_steps"] > 30
    # a still phone cannot tell: rad/s values declared deg/s are read (the accelerometer shows no movement)
    n = 500
    t = walk.streams["acc"].t_ns[:n]
    still = Recording({"acc": make_stream("acc", t, np.tile([0.1, 0.2, 9.8], (n, 1))),
                       "gyro": make_stream("gyro", t, np.full((n, 3), 0.001), unit="deg/s")}, dict(walk.device), {})
    assert len(_read(tmp_path, still, "still.csv").streams["gyro"]) == n


def test_an_accelerometer_declared_in_g_with_data_in_m_s2_is_refused_not_converted(tmp_path, walk):
    """Before: "converted" from g (x 9.81): the distance +68 %."""
    a = walk.streams["acc"]
    code, _, err = _replay(tmp_path, _copy(walk, acc=make_stream("acc", a.t_ns, a.values, unit="g")))
    assert code == 2 and "declared in g" in err and "look like m/s^2 already" in err


def test_a_magnetometer_declared_in_nt_with_data_in_ut_names_the_unit_it_fits(tmp_path, walk):
    """Before: refused as "it looks like mT", the wrong way round."""
    m = walk.streams["mag"]
    code, _, err = _replay(tmp_path, _copy(walk, mag=make_stream("mag", m.t_ns, m.values, unit="nT")))
    assert code == 2 and "declared in nT" in err and 'declare "unit": "uT"' in err


def test_a_saturated_gyroscope_is_not_taken_for_deg_s(tmp_path, walk):
    """Before: refused: "it looks like deg/s" (35 rad/s on each axis is a |w| of 60.6)."""
    g = walk.streams["gyro"]
    v = g.values.copy()
    v[1000:1200] = 35.0  # two seconds stuck at the range on every axis
    rec = _read(tmp_path, _copy(walk, gyro=make_stream("gyro", g.t_ns, v)))
    assert len(rec.streams["gyro"]) == len(g)
    with pytest.raises(RecordingError, match="looks like deg/s"):  # a scale is still caught
        _read(tmp_path, _copy(walk, gyro=make_stream("gyro", g.t_ns, np.degrees(g.values) * 20)))


def test_a_foot_recording_at_10_hz_is_refused_stating_the_rate_the_stance_detector_needs(tmp_path, walk):
    """Before: the ZUPT filter ran at 10 Hz without a word (52 m of 60, the end 2.3 m off instead of 4 cm)."""
    slow = Recording({n: make_stream(n, s.t_ns[::10], s.values[::10]) for n, s in walk.streams.items()
                      if n in ("acc", "gyro", "mag")}, dict(walk.device), {})
    code, _, err = _replay(tmp_path, slow, "--mode", "foot")
    assert code == 2 and "runs at 10.0 Hz" in err and "needs at least 50 Hz" in err and "stance detector" in err


# ---------------------------------------------------------------------------
# gaps and spikes


def test_a_10_hour_gap_does_not_average_the_rate_away_nor_disable_step_detection(tmp_path, walk):
    """Before: acc "0.4 Hz", steps "not measured"."""
    shifted = {}
    cut = walk.t0_ns + 15 * 10**9
    for n, s in walk.streams.items():
        t = s.t_ns.copy()
        t[t > cut] += 36_000 * 10**9
        shifted[n] = make_stream(n, t, s.values)
    rec = Recording(shifted, dict(walk.device), {})
    code, s, err = _replay(tmp_path, rec)
    assert code == 0 and s["rates_hz"]["acc"] == pytest.approx(100.0, rel=0.02)
    assert s.get("steps_measured", True) and s["n_steps"] > 30
    assert s["stream_problems"]["GAP"] >= 3  # acc, gyro, mag each report theirs
    assert any(f["stream"] == "acc" and "36000" in f["text"] for f in s["stream_findings"])


def test_a_gap_in_the_accelerometer_alone_is_reported_in_the_summary_and_the_json(tmp_path, walk):
    """Before: silent (a 10-minute gap in acc alone: the track 52 m off, nothing said)."""
    a = walk.streams["acc"]
    keep = (a.t_ns < a.t_ns[0] + 10 * 10**9) | (a.t_ns > a.t_ns[0] + 18 * 10**9)
    rec = _copy(walk, acc=make_stream("acc", a.t_ns[keep], a.values[keep]))
    code, s, _ = _replay(tmp_path, rec)
    assert code == 0 and s["stream_problems"] == {"GAP": 1}
    text = s["stream_findings"][0]["text"]
    assert "the longest 8.0 s" in text and "while gyro and mag ran" in text and "no steps are measured" in text
    # the pipeline bridged it from the gyroscope's gait rhythm: estimated steps, said in the summary (#30)
    assert s["n_steps_estimated"] > 8 and s["acc_gaps"][0]["verdict"] == "BRIDGED"
    assert any("estimated, not measured" in lb for lb in s["labels"])
    import contextlib
    import io
    out = io.StringIO()  # the summary lines (the same file, without --json)
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(["replay", str(tmp_path / "walk.csv"), "--no-progress"]) == 0
    lines = out.getvalue().splitlines()
    assert any(ln.startswith("stream ") and "no steps are measured" in ln for ln in lines)
    assert any("estimated, not measured" in ln for ln in lines)
    assert any(ln.startswith("steps ") and "estimated across accelerometer gaps" in ln for ln in lines)
    # the app's warning line says it too (before: only repairs were shown, a reported gap was not)
    from app.session import reading_notes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        note = reading_notes(read_recording(str(tmp_path / "walk.csv")))
    assert "stream 'acc': 1 gap(s)" in note and "the longest 8.0 s" in note


def test_a_10_s_magnetometer_spike_is_reported(tmp_path, walk):
    """Before: unreported (2000 uT for 10 s)."""
    m = walk.streams["mag"]
    v = m.values.copy()
    v[500:1000] = [2000.0, 0.0, 0.0]  # 10 s at 50 Hz
    code, s, _ = _replay(tmp_path, _copy(walk, mag=make_stream("mag", m.t_ns, v)))
    assert code == 0 and s["stream_problems"] == {"SPIKE": 500}
    assert "the longest 10.0 s" in s["stream_findings"][0]["text"] and "up to 2000 uT" in s["stream_findings"][0]["text"]


def test_one_line_with_a_negative_timestamp_is_skipped_and_counted_not_the_whole_file(tmp_path, walk):
    """Before: refused: "the clock jumps back by 1000.0 s" (an overflowing timestamp was already skipped)."""
    p = tmp_path / "neg.csv"
    write_recording(str(p), walk)
    lines = p.read_text().splitlines(keepends=True)
    lines[500] = "acc,-5,0.1,0.2,9.8\n"
    p.write_text("".join(lines))
    code, s, err = _main(["replay", str(p), "--json", "--no-progress"])
    assert code == 0 and "skipped 1 bad line(s)" in err and "timestamp -5 is negative" in err
    assert any("skipped 1 bad line(s)" in r for r in s["repairs"]) and s["n_steps"] > 30


# ---------------------------------------------------------------------------
# recorder


def test_the_writer_holds_the_header_until_its_first_events(tmp_path):
    """Before: a kill before the first flush left a header-only file that the reader refuses."""
    from core.recording import RecordingWriter

    p = tmp_path / "live.csv"
    w = RecordingWriter(str(p), device={"model": "phone"})
    w.add("acc", 10**9, (0.0, 0.0, 9.8))
    assert not p.exists()  # killed here: no file, not a file nobody can open
    w.flush()
    rec = read_recording(str(p))
    assert len(rec.streams["acc"]) == 1 and rec.device == {"model": "phone"}
    w.add("acc", 2 * 10**9, (0.0, 0.0, 9.8))
    w.close()
    assert len(read_recording(str(p)).streams["acc"]) == 2 and not (tmp_path / "live.csv.part").exists()


# ---------------------------------------------------------------------------
# the validation as a property: any recording gives repaired streams on one clock, never an exception


def test_validation_never_raises_and_leaves_other_streams_on_the_imu_clock():
    from hypothesis import given, settings, strategies as st

    from core.validation import CLOCK_MARGIN_S, validate_recording

    ints = st.integers(0, 2**63 - 1)

    @settings(max_examples=100, deadline=None, derandomize=True)
    @given(t_acc=st.lists(ints, min_size=2, max_size=30, unique=True), t_gps=st.lists(ints, max_size=30, unique=True),
           scale=st.sampled_from([1, 10**3, 10**6, 10**9]), off=st.one_of(st.none(), st.integers(-2**64, 2**64)),
           lat=st.floats(-1e3, 1e3), hacc=st.floats(-5, 50))
    def check(t_acc, t_gps, scale, off, lat, hacc):
        t_acc = np.sort(np.array(t_acc, dtype=np.int64))
        t_gps = np.sort(np.array(t_gps, dtype=np.int64)) // scale
        gps = np.tile([lat, 8.5, 400.0, hacc, 1.0, 0.0], (len(t_gps), 1))
        rec = Recording({"acc": make_stream("acc", t_acc, np.zeros((len(t_acc), 3))),
                         "gps": make_stream("gps", t_gps, gps)}, metadata={} if off is None else
                        {"unix_offset_ns": off})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            validate_recording(rec)
        g = rec.streams["gps"]
        if len(g):
            margin = max(CLOCK_MARGIN_S * 1e9, float(t_acc[-1] - t_acc[0]))
            assert t_acc[0] - margin <= float(g.t_ns[0]) and float(g.t_ns[-1]) <= t_acc[-1] + margin
            assert np.all(np.abs(g.values[:, 0]) <= 90) and np.all(g.values[:, 3] >= 0)
        assert all(f.problem in StreamProblem for f in rec.problems)

    check()
