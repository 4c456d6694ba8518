"""Sensors that misbehave within their range (issue #12, class 1): saturated, dead, a magnetometer never used.

Each is flagged in ``Pipeline.labels()`` (the summary, the app's health panel)
with counters in the summary; a clean simulated walk gets none of these labels.
Impossible values (finite, beyond any phone sensor's range) are skipped and
counted like NaN; no stage of ``core.pdr`` raises on them.
"""

import math

import numpy as np
import pytest

from core.pdr.attitude import AttitudeEKF
from core.pdr.pipeline import Pipeline, SensorHealth
from core.recording import Recording, make_stream
from desktop.simulator import simulate_walk

HEALTH_WORDS = ("saturated", "dead", "rejected 100 %", "impossible")


@pytest.fixture(scope="module")
def walk():
    return simulate_walk([(0, 0), (0, 40), (30, 40)], rate_hz=50.0, seed=11)


@pytest.fixture(scope="module")
def clean(walk):
    return Pipeline().run(walk.recording).summary()


def _edit(rec: Recording, stream: str, fn) -> Recording:
    streams = dict(rec.streams)
    s = streams[stream]
    v = np.array(s.values, dtype=float)
    t_s = (s.t_ns - s.t_ns[0]) * 1e-9
    fn(t_s, v)
    streams[stream] = make_stream(stream, s.t_ns, v)
    return Recording(streams, source=rec.source, metadata=dict(rec.metadata))


def _labels_with(summary, word):
    return [lab for lab in summary["labels"] if word in lab]


def test_a_clean_walk_has_no_health_label(clean):
    assert not [lab for lab in clean["labels"] if any(w in lab for w in HEALTH_WORDS)]
    for d in clean["sensor_health"].values():
        assert d["saturated_runs"] == 0 and d["dead_runs"] == 0
    assert clean["mag_all_rejected"] is False
    assert clean["impossible_skipped"] == {}


def test_an_accelerometer_clipped_at_its_range_is_flagged(walk, clean):
    # a +-1.6 g range: the vertical axis clips at every step's peak (the walk's peaks reach about 13.6 m/s^2
    # on z: raise the bounce, then clip at 15.7 m/s^2)
    w = simulate_walk([(0, 0), (0, 40), (30, 40)], rate_hz=50.0, seed=11, bounce_scale=3.0)
    peak = np.abs(w.recording.streams["acc"].values).max()
    assert peak > 17.0
    rec = _edit(w.recording, "acc", lambda t, v: np.clip(v, -15.7, 15.7, out=v))
    s = Pipeline().run(rec).summary()
    h = s["sensor_health"]["acc"]
    assert h["saturated_runs"] >= 10 and h["saturation_level"] == pytest.approx(15.7)
    assert _labels_with(s, "accelerometer saturated")
    # the unclipped walk with the same bounce is not flagged
    s0 = Pipeline().run(w.recording).summary()
    assert not _labels_with(s0, "saturated")


def test_a_gyroscope_at_its_limit_for_seconds_is_flagged(walk, clean):
    def stuck(t, v):
        sel = (t > 20.0) & (t < 23.0)
        v[sel, 2] = 4.363  # +-250 deg/s
    s = Pipeline().run(_edit(walk.recording, "gyro", stuck)).summary()
    h = s["sensor_health"]["gyro"]
    assert h["saturated_runs"] == 1 and 2.9 < h["saturated_s"] < 3.05
    assert _labels_with(s, "gyroscope saturated")
    assert not _labels_with(s, "dead")  # one axis on the rail, the others move


@pytest.mark.parametrize("stream, word", [("gyro", "gyroscope dead: all zeros"), ("acc", "accelerometer dead"),
                                          ("mag", "magnetometer dead: frozen")])
def test_a_dead_sensor_is_flagged(walk, stream, word):
    def dead(t, v):
        sel = (t > 15.0) & (t < 25.0)
        v[sel] = 0.0 if stream == "gyro" else v[np.argmax(sel)]
    s = Pipeline().run(_edit(walk.recording, stream, dead)).summary()
    h = s["sensor_health"][stream]
    assert h["dead_runs"] == 1 and 9.5 < h["dead_s"] < 10.1
    assert h["dead_zero"] is (stream == "gyro")
    assert _labels_with(s, word)


def test_a_magnetometer_rejected_all_the_time_is_a_degraded_mode(walk, clean):
    # a field five times the Earth's (a magnet in the case): every reading out of the geomagnetic range
    s = Pipeline().run(_edit(walk.recording, "mag", lambda t, v: v.__imul__(5.0))).summary()
    assert s["mag_all_rejected"] is True and s["mag_used"] == 0
    lab = _labels_with(s, "magnetometer rejected 100 %")
    assert lab and "invalid range" in lab[0]
    assert not _labels_with(clean, "rejected")


def test_the_status_carries_the_labels_for_the_app(walk):
    p = Pipeline()
    rec = _edit(walk.recording, "gyro", lambda t, v: v.__setitem__((t > 5.0) & (t < 9.0), 0.0))
    for name, t, v in rec.events(["gyro", "acc", "mag"]):
        p.update(name, t, v)
    assert any("gyroscope dead" in lab for lab in p.status().labels)


def test_impossible_values_are_skipped_and_counted(walk, clean):
    """gyro 1e300 and -5e3 rad/s, acc 1e300, mag -1e300, each at its own moment of one run (one run instead of
    four, for CI's time): each skipped and counted per sensor, no step lost, the end moves by under 10 cm."""
    def at(frac, bad):
        def one(t, v):
            v[int(frac * len(v)), 1] = bad
        return one
    rec = walk.recording
    for stream, frac, bad in (("gyro", 0.3, 1e300), ("gyro", 0.6, -5e3), ("acc", 0.5, 1e300), ("mag", 0.4, -1e300)):
        rec = _edit(rec, stream, at(frac, bad))
    s = Pipeline().run(rec).summary()
    assert s["impossible_skipped"] == {"gyro": 2, "acc": 1, "mag": 1}
    assert _labels_with(s, "impossible")
    assert s["n_steps"] == clean["n_steps"]
    moved = math.hypot(s["final_east_m"] - clean["final_east_m"], s["final_north_m"] - clean["final_north_m"])
    assert moved < 0.1


def test_the_attitude_filter_alone_never_raises_on_bad_numbers(walk):
    """NaN, +-inf and +-1e300 in turn, every 97th event of the walk (one pass over the walk for all five kinds
    instead of one per kind, for CI's time): each kind reaches every sensor, none raises, none is used."""
    bads = (math.nan, math.inf, -math.inf, 1e300, -1e300)
    f = AttitudeEKF()
    call = {"gyro": f.predict, "acc": f.update_acc, "mag": f.update_mag}
    seen = set()
    for k, (name, t, v) in enumerate(walk.recording.events(["gyro", "acc", "mag"])):
        v = [float(x) for x in v]
        if k % 97 == 0:
            kind = (k // 97) % len(bads)
            v[1] = bads[kind]
            seen.add((name, kind))
        call[name](t, *v)
    assert len(seen) == 3 * len(bads)  # every kind on every sensor
    assert f.n_skipped_nonfinite > 0
    assert np.all(np.isfinite(f.P)) and np.all(np.isfinite(f.q))
    assert abs(math.sqrt(sum(c * c for c in f.q)) - 1.0) < 1e-9


def test_the_health_detector_keeps_constant_memory():
    h = SensorHealth(15.5)
    before = sorted(vars(h))
    rng = np.random.default_rng(0)
    for k, v in enumerate(rng.normal(0.0, 3.0, (5000, 3)).tolist()):
        h.update(k * 20_000_000, *v)
    assert sorted(vars(h)) == before
    assert h.saturated_runs == 0 and h.dead_runs == 0
