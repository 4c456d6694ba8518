"""`pdr replay` shows the error against the ground truth a recording carries, computed here independently."""

import json

import numpy as np
import pytest

from core.pdr.pipeline import Pipeline
from core.pdr.stride_models import load_stride_model
from core.recording import Stream, read_recording, write_recording
from core.metrics import truth_of
from desktop.cli import main, truth_lines
from desktop.simulator import simulate_walk


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))  # never the user's own profile


@pytest.fixture(scope="module")
def square(tmp_path_factory):
    """A simulated 20 m square at 50 Hz, its file, and the pipeline's own track of it (run here, not by the CLI)."""
    walk = simulate_walk([(0, 0), (20, 0), (20, 20), (0, 20), (0, 0)], rate_hz=50.0, seed=4)
    path = tmp_path_factory.mktemp("truth") / "square.csv"
    write_recording(str(path), walk.recording)
    track = Pipeline(stride_model=load_stride_model("default")).run(read_recording(str(path))).track
    return walk, path, track


def test_simulator_truth_errors_equal_an_independent_computation(square, capsys):
    walk, path, track = square
    assert main(["replay", str(path), "--json", "--no-progress"]) == 0
    sim = json.loads(capsys.readouterr().out)["truth"]["simulator"]
    n_true, path_m = walk.truth.n_steps, walk.truth.path_length_m
    assert sim["n_steps"] == n_true and sim["path_m"] == pytest.approx(path_m)
    assert sim["step_count_err_pct"] == pytest.approx(100.0 * (len(track) - n_true) / n_true)
    assert sim["distance_err_pct"] == pytest.approx(100.0 * (track.length_m.sum() - path_m) / path_m)
    # a closed loop: the end point's error is about the track's start-to-end gap (within a step's interpolation)
    gap = float(np.hypot(track.east_m[-1], track.north_m[-1]))
    assert abs(sim["end_error_m"] - gap) < 0.7
    assert sim["loop_closure_pct"] == pytest.approx(100.0 * sim["end_error_m"] / path_m, rel=1e-6)
    lines = "\n".join(truth_lines({"simulator": sim}))  # the summary's lines of the same numbers
    assert f"truth         {n_true} steps, {path_m:.1f} m (simulator)" in lines
    assert f"distance {sim['distance_err_pct']:+.1f} %" in lines and f"end point {sim['end_error_m']:.2f} m" in lines


def _with_landmarks(walk, track, every: int, columns=("east_m", "north_m")):
    """The walk with a ``posi`` stream of true positions at every ``every``-th detected step's time
    (at a step's time the track's position is that step's end point: no interpolation in the expectation)."""
    idx = np.arange(3, len(track), every)
    t = track.t_ns[idx]
    true = walk.truth.position_at(t)
    rec = walk.recording
    streams = dict(rec.streams)
    streams["posi"] = Stream("posi", t, true, columns, "m,m", "ground-truth landmarks (test)")
    return type(rec)(streams, dict(rec.device), dict(rec.metadata), list(rec.repairs), rec.source), idx, true


def test_landmark_errors_equal_an_independent_computation(square, tmp_path, capsys, monkeypatch):
    walk, _, track = square
    rec, idx, true = _with_landmarks(walk, track, every=12)
    path = tmp_path / "with_posi.csv"
    write_recording(str(path), rec)
    ours = np.column_stack([track.east_m[idx], track.north_m[idx]])
    err = np.hypot(*((ours - ours[0]) - (true - true[0])).T)[1:]  # placed at the first landmark, absolute heading
    drawn = {}
    monkeypatch.setattr("desktop.plot.plot_track", lambda p, tr, **kw: drawn.update(kw))
    assert main(["replay", str(path), "--json", "--no-progress", "--plot", str(tmp_path / "t.png")]) == 0
    out = capsys.readouterr().out
    lm = json.loads(out)["truth"]["landmarks"]
    assert lm["n"] == len(idx) and "posi" in lm["what"]
    assert lm["median_m"] == pytest.approx(float(np.median(err)), abs=1e-6)
    assert lm["max_m"] == pytest.approx(float(err.max()), abs=1e-6)
    assert lm["errors_m"] == pytest.approx(err.tolist(), abs=1e-6)
    seg_len = float(np.hypot(*np.diff(true, axis=0).T).sum())
    walked = float(track.length_m[idx[0] + 1: idx[-1] + 1].sum())
    assert lm["distance_err_pct"] == pytest.approx(100.0 * (walked - seg_len) / seg_len, abs=1e-6)
    # the plot gets the landmarks moved into the track's frame: the first one on the track at its time
    assert np.allclose(drawn["landmarks_en"][0], ours[0]) and len(drawn["landmarks_en"]) == len(idx)
    assert "landmarks: median" in drawn["subtitle"]


def test_landmarks_in_degrees_and_no_truth(square, capsys):
    """An IPIN-style posi stream (lat_deg, lon_deg) is the same truth as one in metres; no truth, nothing."""
    from core.geodesy import enu_to_geodetic

    walk, _, track = square
    rec, idx, true = _with_landmarks(walk, track, every=15)
    metres = truth_of(rec).landmarks
    lat, lon = enu_to_geodetic(true[:, 0], true[:, 1], (49.46, 11.11))
    rec.streams["posi"] = Stream("posi", rec.streams["posi"].t_ns, np.column_stack([lat, lon]), ("lat_deg", "lon_deg"),
                                 "deg,deg", "")
    deg = truth_of(rec).landmarks
    assert deg.origin_lat_lon == pytest.approx((lat[0], lon[0]))
    assert np.allclose(deg.east_m - metres.east_m + metres.east_m[0], 0.0, atol=0.01)
    assert np.allclose(deg.north_m - metres.north_m + metres.north_m[0], 0.0, atol=0.01)
    assert deg.label == f"{len(idx)} landmarks (posi stream)"
    bare = type(rec)({k: v for k, v in rec.streams.items() if k != "posi"}, {}, {}, [], "bare")
    assert not truth_of(bare)


def test_calibrate_from_gps_stores_what_gps_taught_in_the_profile(tmp_path, capsys):
    """A straight 140 m walk with GPS: the trainer's stride scale and heading model go into the app's profile."""
    from core.pdr.calibration import UserProfile
    from desktop.simulator import GpsModel

    walk = simulate_walk([(0, 0), (0, 140)], rate_hz=50.0, gps=GpsModel(multipath_per_min=0.0), seed=5)
    path = tmp_path / "gps_walk.csv"
    write_recording(str(path), walk.recording)
    assert main(["calibrate", str(path), "--from-gps", "--json", "--no-progress"]) == 0
    doc = json.loads(capsys.readouterr().out)
    stored = UserProfile.load(tmp_path / "app" / "profile.json")
    assert doc["profile_path"] == str(tmp_path / "app" / "profile.json")
    assert stored.gps["stride_scale"] == doc["gps"]["stride_scale"] and stored.gps["stride_gps_m"] >= 100
    # the dead-reckoning distance of that run is the model's: the walker's true length over it is the scale
    # GPS should have taught (within a per cent or two)
    assert stored.gps["stride_scale"] == pytest.approx(walk.truth.path_length_m / doc["pdr_distance_m"], rel=0.02)


def test_ground_truth_counters_step_count_and_wheel_distance(capsys):
    """Cumulative ground-truth streams (Oxford's foot-switch step counts, a trundle wheel's metres): the track's
    steps and metres between the counter's first and last event against the counter's."""
    from core.metrics import truth_errors
    from core.pdr.pipeline import Track
    from core.recording import Recording

    s = 1_000_000_000
    n = 40
    track = Track(np.arange(1, n + 1, dtype=np.int64) * s, np.full(n, 0.7), np.zeros(n), np.cumsum(np.full(n, 0.7)),
                  np.zeros(n))
    t_counter = np.array([5, 20, 30], dtype=np.int64) * s + s // 2  # steps 6..30 are after the first event
    streams = {
        "step_counts": Stream("step_counts", t_counter, np.array([[3, 10, 0], [20, 24, 0], [27, 37, 0]], float),
                              ("app", "ground_truth", "android_hw"), "1", ""),
        "wheel": Stream("wheel", t_counter, np.array([[2.0], [12.0], [19.0]]), ("distance_m",), "m", ""),
    }
    truth = truth_of(Recording(streams))
    errs = truth_errors(track, truth)
    ours = 30 - 5  # steps at 6 s .. 30 s
    assert errs["steps"]["n_true"] == 27 and errs["steps"]["n"] == ours
    assert errs["steps"]["err_pct"] == pytest.approx(100.0 * (ours - 27) / 27)
    assert errs["distance"]["true_m"] == pytest.approx(17.0) and errs["distance"]["m"] == pytest.approx(0.7 * ours)
    assert errs["distance"]["err_pct"] == pytest.approx(100.0 * (0.7 * ours - 17.0) / 17.0)
    lines = truth_lines(errs)
    assert "truth         27 steps (step_counts stream, ground_truth)" in lines
    assert f"truth error   distance {errs['distance']['err_pct']:+.1f} % (17.5 m over the same time)" in lines
    # a counter that is not ground truth (the phone's own) is not truth
    phone = Stream("step_counts", t_counter, np.array([[1.0], [9.0], [20.0]]), ("phone",), "1", "")
    assert not truth_of(Recording({"step_counts": phone}))


def test_declination_comes_from_the_magnetic_model_at_the_first_good_fix(tmp_path, capsys):
    """A recording with a date and GPS whose first fix is 40 m inaccurate: the declination is the World
    Magnetic Model's at the first fix of 12 m or better (not the first fix), and --declination overrides it."""
    import dataclasses
    import math

    import numpy as np

    from core.geodesy import declination_rad, unix_ns_to_datetime
    from core.recording import write_recording
    from desktop.cli import main
    from desktop.simulator import outdoor_walk

    w = outdoor_walk(2, minutes=0.5, rate_hz=50.0)  # the declination is set at the first good fix, seconds in
    rec = w.recording
    g = rec.streams["gps"]
    vals = g.values.copy()
    vals[0, 3] = 40.0  # the first fix: poor
    vals[0, 0] += 0.5  # ... and far off (half a degree north)
    rec.streams["gps"] = dataclasses.replace(g, values=vals)
    rec.metadata = {**rec.metadata, "unix_offset_ns": 1_751_328_000_000_000_000 - rec.t0_ns}  # walked 2025-07-01
    path = tmp_path / "walk.csv"
    write_recording(str(path), rec)
    assert main(["replay", str(path), "--json", "--gps", "off", "--no-profile"]) == 0
    s = json.loads(capsys.readouterr().out)
    good = int(np.flatnonzero(vals[:, 3] <= 12.0)[0])
    when = unix_ns_to_datetime(rec.metadata["unix_offset_ns"] + int(g.t_ns[good]))
    want = math.degrees(declination_rad(vals[good, 0], vals[good, 1], vals[good, 2], when))
    assert s["declination"]["source"].endswith("the first good GPS fix")
    assert abs(s["declination"]["declination_deg"] - want) < 1e-6 and abs(want) > 0.1
    assert abs(s["declination"]["lat_deg"] - vals[good, 0]) < 1e-9
    assert main(["replay", str(path), "--json", "--gps", "off", "--no-profile", "--declination", "-3.5"]) == 0
    assert json.loads(capsys.readouterr().out)["declination"] == {"declination_deg": -3.5, "source": "--declination"}


def test_undated_recording_gets_the_declination_of_its_place():
    """A recording without a date (a phyphox export without meta/time.csv) and a good fix in Lueneburg: the
    declination is the model's at that place for UNDATED_MODEL_DATE (about +4 deg), not 0; a dated one keeps its
    own date; --declination still overrides."""
    import math

    import numpy as np

    from core.geodesy import declination_rad, unix_ns_to_datetime
    from core.recording import Recording, Stream
    from desktop.cli import UNDATED_MODEL_UNIX_NS, build_gnss, build_pipeline, make_parser, place_site

    lat, lon = 53.2290, 10.4004
    t = np.arange(5, dtype=np.int64) * 1_000_000_000
    vals = np.tile([lat, lon, 20.0, 5.0, 1.3, 90.0], (5, 1))
    gps = Stream("gps", t, vals, ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg"))
    want = math.degrees(declination_rad(lat, lon, 20.0, unix_ns_to_datetime(UNDATED_MODEL_UNIX_NS)))
    assert 2.0 < want < 7.0
    for metadata, expect in (({}, want),
                             ({"unix_offset_ns": 1_420_070_400_000_000_000},  # 2015-01-01: its own date
                              math.degrees(declination_rad(lat, lon, 20.0, unix_ns_to_datetime(1_420_070_400_000_000_000))))):
        rec = Recording({"gps": gps}, metadata=metadata)
        args = make_parser().parse_args(["replay", "x.csv", "--no-profile"])
        pipe = build_pipeline(args, build_gnss(args, rec, None), None)
        summary, lines = place_site(args, rec, pipe)
        assert abs(summary["declination_deg"] - expect) < 1e-9, (metadata, summary)
        assert ("no date" in summary["source"]) == (not metadata)
        assert abs(math.degrees(pipe.attitude.declination_rad) - expect) < 1e-9
    assert abs(want - expect) > 0.5  # ten years of secular change in Germany: the date matters, a little
    args = make_parser().parse_args(["replay", "x.csv", "--no-profile", "--declination", "-3.5"])
    assert place_site(args, Recording({"gps": gps}), build_pipeline(args, None, None))[0]["declination_deg"] == -3.5
    # a simulated recording's field is synthetic (its own declination): no date stays no declination
    args = make_parser().parse_args(["replay", "x.csv", "--no-profile"])
    sim = Recording({"gps": gps}, metadata={"simulator": 1})
    assert place_site(args, sim, build_pipeline(args, None, None))[0] == {"declination_deg": 0.0, "source": "no date"}
