"""Barometric floors (core.floors) against the simulator's barometer (desktop.simulator.simulate_pressure: an
isothermal hypsometric model with weather, noise and transients, not the estimator's standard-atmosphere
polynomial), published standard-atmosphere numbers and the real single-floor IPIN routes."""

import math
from pathlib import Path

import numpy as np
import pytest

from core.floors import FloorChange, FloorEstimator, altitude_m, floors_at
from core.recording import make_stream
from desktop.simulator import BarometerModel, floor_profile, simulate_pressure

RATE_HZ = 10.0


def _run(segments, model=None, seed=0, **settings):
    total = sum(seg[0] for seg in segments)
    t = np.arange(0.0, total, 1.0 / RATE_HZ)
    t_ns = (t * 1e9).astype(np.int64) + 5_000_000_000
    return FloorEstimator(**settings).run(simulate_pressure(t_ns, floor_profile(t, segments), model, seed=seed))


def test_altitude_matches_the_standard_atmosphere_table():
    # ICAO standard atmosphere: 1001.29 hPa at 100 m, 954.61 hPa at 500 m, 898.76 hPa at 1000 m
    for p, h in ((1001.29, 100.0), (954.61, 500.0), (898.76, 1000.0)):
        assert abs(float(altitude_m(p, 1013.25)) - h) < 0.5


@pytest.mark.parametrize("seed", range(6))
def test_stairs_and_lift_floors_with_weather_drift(seed):
    storey = 3.5
    segments = [(60, 0.0), (14, storey, "linear"), (40, 0.0), (7.5, 2 * storey), (50, 0.0),
                (15, -storey, "linear"), (45, 0.0), (5.5, -storey), (40, 0.0)]
    model = BarometerModel(drift_hpa_per_h=4.0 if seed % 2 else -4.0, noise_hpa=0.03, quantum_hpa=0.01)
    res = _run(segments, model, seed=seed)
    got = [(c.floors, c.kind) for c in res.changes if c.floors]
    assert got == [(1, "stairs"), (2, "lift"), (-1, "stairs"), (-1, "lift")]
    assert res.summary()["final_floor"] == 1 and res.summary()["floors_visited"] == [0, 1, 2, 3]
    lift = [c for c in res.changes if c.kind == "lift"][0]
    assert abs(lift.delta_m - 2 * storey) < 0.7  # the altitude step, isothermal model vs the polynomial


def test_two_half_flights_with_a_pause_on_the_landing_make_one_floor():
    res = _run([(40, 0.0), (8, 1.75, "linear"), (12, 0.0), (8, 1.75, "linear"), (40, 0.0)],
               BarometerModel(drift_hpa_per_h=0.0, noise_hpa=0.02), seed=1)
    assert [c.floors for c in res.changes if c.floors] == [1]


def test_a_slow_slope_is_not_a_floor():
    res = _run([(30, 0.0), (200, 8.0, "linear"), (30, 0.0)], BarometerModel(noise_hpa=0.02), seed=2)
    assert res.summary()["floor_changes"] == 0 and res.summary()["slopes"] >= 1


def test_good_gps_during_a_change_means_outdoors():
    total = 120.0
    t = np.arange(0.0, total, 1.0 / RATE_HZ)
    t_ns = (t * 1e9).astype(np.int64)
    p = simulate_pressure(t_ns, floor_profile(t, [(40, 0.0), (14, 3.5, "linear"), (66, 0.0)]), seed=3)
    fixes_t = np.arange(0, int(total), 1) * 1_000_000_000
    gps = make_stream("gps", fixes_t, np.column_stack([np.full(len(fixes_t), 47.0), np.full(len(fixes_t), 8.0),
                                                       np.zeros(len(fixes_t)), np.full(len(fixes_t), 4.0)]))
    assert FloorEstimator().run(p).summary()["floor_changes"] == 1
    out = FloorEstimator().run(p, gps=gps)
    assert out.summary()["floor_changes"] == 0 and out.summary()["slopes"] == 1


def test_a_flat_hour_of_weather_and_door_transients_has_no_floor_change():
    model = BarometerModel(drift_hpa_per_h=4.0, swing_hpa=0.5, noise_hpa=0.04, transient_hpa=0.3, transient_s=3.0,
                           transients_per_h=40.0, quantum_hpa=0.01)
    for seed in range(3):
        res = _run([(3600, 0.0)], model, seed=seed)
        assert res.summary()["floor_changes"] == 0


def test_bad_readings_are_skipped_and_never_enter_the_state():
    est = FloorEstimator()
    t = 0
    for k in range(400):
        t += 100_000_000
        p = 1000.0 + 0.001 * k
        if k % 37 == 5:
            p = (math.nan, math.inf, -5.0, 5000.0)[k % 4]
        est.update(t, p)
        assert math.isfinite(est.altitude_m) and math.isfinite(est.level_m)
    est.update(t - 1, 1000.0)  # backwards in time
    assert est.counters["skipped"] == sum(1 for k in range(400) if k % 37 == 5) + 1


def test_floors_at_counts_a_change_from_its_midpoint():
    changes = [FloorChange(10, 30, 1, 3.5, 0.3, "stairs", 1), FloorChange(50, 60, 0, 1.0, 0.03, "slope", 1),
               FloorChange(100, 120, -2, -7.0, 1.0, "lift", -1)]
    assert floors_at(changes, [0, 19, 20, 21, 55, 109, 110, 200]).tolist() == [0, 0, 1, 1, 1, 1, -1, -1]
    assert floors_at([], [1, 2]).tolist() == [0, 0]


IPIN = Path(__file__).resolve().parents[2] / "shared" / "data" / "ipin2023_track3" / "logfiles"


@pytest.mark.skipif(not IPIN.is_dir(), reason="IPIN 2023 data not beside the checkout")
def test_real_single_floor_ipin_routes_have_no_floor_change():
    from core.importers import load_recording

    for name in ("IPIN2023_T3_TrainingTrial04_repetition01.txt.gz", "IPIN2023_T3_TrainingTrial23_repetition02.txt.gz"):
        rec = load_recording(IPIN / name, warn=False)
        res = FloorEstimator().run(rec.streams["pressure"])
        assert res.summary()["floor_changes"] == 0, (name, res.changes)
        assert res.counters["readings"] > 100


def test_the_app_session_shows_floors_and_exports_them_per_step(tmp_path):
    """A simulated hand-held walk with a barometer that goes up a floor by stairs half-way: the session's
    floor, the health panel's line and the GeoJSON's per-step floor (the steps before the stairs on 0)."""
    import json

    from app.session import export_session
    from core.pdr.pipeline import Pipeline
    from tests._session_helpers import replay_session
    from core.recording import Recording
    from desktop.simulator import simulate_walk

    w = simulate_walk(((0.0, 0.0), (40.0, 0.0), (40.0, 30.0)), seed=5, rate_hz=50.0, still_start_s=2.0, still_end_s=2.0)
    rec = w.recording
    t = np.arange(rec.t0_ns, rec.t0_ns + int(rec.duration_s * 1e9), 100_000_000)
    t_s = (t - t[0]) * 1e-9
    half = 0.5 * t_s[-1]
    climb = floor_profile(t_s, [(half - 7.0, 0.0), (14.0, 3.5, "linear"), (t_s[-1], 0.0)])
    streams = dict(rec.streams, pressure=simulate_pressure(t, climb, BarometerModel(drift_hpa_per_h=2.0), seed=5))
    rec2 = Recording(streams, device=rec.device, metadata=rec.metadata)
    ses = replay_session(rec2, Pipeline)
    assert ses.summary()["floor"] == 1 and ses.summary()["floor_changes"] == 1
    assert "barometer: floor +1" in ses.health_text() and "stairs" in ses.health_text()
    assert len(ses.steps) == len(Pipeline().run(rec).steps)  # pressure does not disturb the steps
    out = export_session(ses, str(tmp_path), "walk")
    feats = json.loads(open(out["geojson"]).read())["features"]
    floors = [f["properties"]["floor"] for f in feats if f["geometry"]["type"] == "Point" and "floor" in f["properties"]]
    step_t = np.array([s.t_ns for s in ses.steps])
    change = ses.floors.changes[0]
    assert len(floors) == len(step_t)
    assert floors == [0 if tt < change.t_mid_ns else 1 for tt in step_t] and floors[0] == 0 and floors[-1] == 1
    assert abs((change.t_mid_ns - t[0]) * 1e-9 - half) < 5.0  # the midpoint of the stairs, within 5 s


def test_pdr_replay_reports_floors_and_writes_them_per_step(tmp_path, capsys):
    import csv
    import json

    from core.recording import Recording, write_recording
    from desktop.cli import main
    from desktop.simulator import simulate_walk

    w = simulate_walk(((0.0, 0.0), (30.0, 0.0), (30.0, 20.0)), seed=6, rate_hz=50.0, still_start_s=2.0, still_end_s=2.0)
    rec = w.recording
    t = np.arange(rec.t0_ns, rec.t0_ns + int(rec.duration_s * 1e9), 100_000_000)
    t_s = (t - t[0]) * 1e-9
    down = floor_profile(t_s, [(0.4 * t_s[-1], 0.0), (6.0, -7.0), (t_s[-1], 0.0)])  # a lift, two floors down
    path = tmp_path / "walk.csv"
    write_recording(str(path), Recording(dict(rec.streams, pressure=simulate_pressure(t, down, seed=6)),
                                         device=rec.device, metadata=rec.metadata))
    out_csv = tmp_path / "track.csv"
    assert main(["replay", str(path), "--json", "--csv", str(out_csv), "--no-profile"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["floors"]["final_floor"] == -2 and s["floors"]["lifts"] == 1
    assert [c["floors"] for c in s["floors"]["changes"]] == [-2]
    rows = list(csv.DictReader(open(out_csv)))
    assert rows[0]["floor"] == "0" and rows[-1]["floor"] == "-2"
    with pytest.raises(SystemExit) as e:  # not a storey: refused before the run
        main(["replay", str(path), "--storey-height", "0.2"])
    assert e.value.code == 2
