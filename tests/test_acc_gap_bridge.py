"""A gap in the accelerometer alone (issue #30): bridged from the gyroscope's gait rhythm, or refused.

Simulator truth: a walk with the accelerometer removed over a window (gyroscope and magnetometer running).
Before the bridge the distance walked in the gap was missing (no steps counted across it).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.pdr.gapbridge import AccGapBridge, GapVerdict
from core.pdr.pipeline import Pipeline
from core.recording import Recording, make_stream


@pytest.fixture(scope="module")
def walk():
    from desktop.simulator import simulate_walk

    return simulate_walk([(0, 0), (40, 0), (40, 30)], seed=5, rate_hz=50.0, still_start_s=2.0, still_end_s=25.0)


def _without_acc(rec: Recording, t0_s: float, t1_s: float) -> Recording:
    a = rec.streams["acc"]
    t = (a.t_ns - a.t_ns[0]) * 1e-9
    keep = (t < t0_s) | (t > t1_s)
    out = Recording(dict(rec.streams), dict(rec.device), dict(rec.metadata))
    out.streams["acc"] = make_stream("acc", a.t_ns[keep], a.values[keep])
    return out


def _end_error(res, truth) -> float:
    s = res.steps[-1]
    return math.hypot(s.east_m - truth.step_east_m[-1], s.north_m - truth.step_north_m[-1])


@pytest.fixture(scope="module")
def runs(walk):
    gap = _without_acc(walk.recording, 15.0, 35.0)  # 20 s, across the corner at about 24 s
    return {"clean": Pipeline().run(walk.recording), "bridged": Pipeline().run(gap),
            "off": Pipeline(acc_gap_bridge=False).run(gap), "gap": gap}


def test_a_walking_gap_is_bridged_close_to_the_walk_without_a_gap(walk, runs):
    clean, bridged, off = runs["clean"], runs["bridged"], runs["off"]
    d_clean = sum(s.length_m for s in clean.steps)
    d_bridged = sum(s.length_m for s in bridged.steps)
    d_off = sum(s.length_m for s in off.steps)
    est = [s for s in bridged.steps if s.estimated]
    d_est = sum(s.length_m for s in est)
    # without the bridge about 20 s of walking (about 24 m) are missing
    assert d_off < d_clean - 20.0
    # with it the distance is the clean run's within 3 % and the end point within 1.5 m + 8 % of the bridged
    # distance of the clean run's (the heading in the gap comes from the attitude filter without accelerometer)
    assert d_bridged == pytest.approx(d_clean, rel=0.03)
    assert len(est) > 25 and d_est > 18.0
    e_clean, e_bridged, e_off = _end_error(clean, walk.truth), _end_error(bridged, walk.truth), _end_error(off, walk.truth)
    assert e_bridged < e_clean + 1.5 + 0.08 * d_est
    assert e_bridged < 0.3 * e_off
    # the estimated steps lie inside the gap, in time order, and the summary and labels say what was done
    t0 = walk.recording.streams["acc"].t_ns[0]
    assert all(15e9 <= s.t_ns - t0 <= 35e9 for s in est)
    assert all(a.t_ns < b.t_ns for a, b in zip(bridged.steps, bridged.steps[1:]))
    s = bridged.summary()
    assert s["n_steps_estimated"] == len(est)
    (g,) = s["acc_gaps"]
    assert g["verdict"] == "BRIDGED" and g["n_steps"] == len(est) and g["distance_m"] == pytest.approx(d_est, abs=1e-3)
    assert any("steps" in lb and "estimated, not measured" in lb for lb in bridged.labels)
    assert bridged.track.estimated is not None and int(bridged.track.estimated.sum()) == len(est)
    assert clean.track.estimated is None and clean.summary()["acc_gaps"] == []


def test_streaming_and_batch_bridge_the_same(runs):
    p = Pipeline()
    steps = []
    for name, t, v in runs["gap"].events(["gyro", "acc", "mag"]):
        steps.extend(p.update(name, t, v))
    steps.extend(p.finish())
    batch = runs["bridged"].steps
    assert len(steps) == len(batch)
    assert [(s.t_ns, s.estimated) for s in steps] == [(s.t_ns, s.estimated) for s in batch]
    assert steps[-1].east_m == pytest.approx(batch[-1].east_m, abs=1e-9)


def test_a_standing_still_gap_adds_no_distance(walk, runs):
    """The walker stands still from the end of the walk on: the gyroscope shows no gait, nothing is invented."""
    rec = walk.recording
    t_end = (walk.truth.walk_end_t_ns - rec.streams["acc"].t_ns[0]) * 1e-9
    gap = _without_acc(rec, t_end + 3.0, t_end + 22.0)
    clean, res = runs["clean"], Pipeline().run(gap)
    assert not any(s.estimated for s in res.steps)
    assert len(res.steps) == len(clean.steps)
    assert sum(s.length_m for s in res.steps) == pytest.approx(sum(s.length_m for s in clean.steps), abs=1e-6)
    (g,) = res.summary()["acc_gaps"]
    assert g["verdict"] == "STILL" and g["n_steps"] == 0 and g["distance_m"] == 0.0
    assert any("no walking" in lb and "no distance added" in lb for lb in res.labels)


def _gyro_walk(bridge: AccGapBridge, t0_ns: int, seconds: float, period_s: float, amp: float) -> int:
    rng = np.random.default_rng(0)
    t = t0_ns
    last_acc = t0_ns
    for k in range(int(seconds * 100)):
        t = t0_ns + 10_000_000 * (k + 1)
        ph = 2 * math.pi * (t - t0_ns) * 1e-9 / (2 * period_s)  # the stride: two steps
        w = amp * np.array([math.sin(ph), 0.5 * math.sin(2 * ph + 0.3), math.cos(ph)]) + rng.normal(0, 0.003, 3)
        bridge.gyro(t, *w, last_acc, t - 10_000_000)
        if bridge.wants_heading(t):
            bridge.heading(t, 1.0, 0.0)
    return t + 10_000_000


def test_the_bridge_reads_the_cadence_and_refuses_without_a_stride_before_the_gap():
    b = AccGapBridge()
    for k in range(10):  # steps before the gap: 0.7 m every 0.5 s
        b.note_step(k * 500_000_000, 0.7, 0.5)
    end = _gyro_walk(b, 5_000_000_000, 30.0, 0.52, 0.4)
    gap, steps, length = b.close(end, attitude_started=True)
    assert gap.verdict is GapVerdict.BRIDGED and length == pytest.approx(0.7)
    assert gap.step_period_s == pytest.approx(0.52, rel=0.02)  # read off the gyroscope, not the 0.5 s before
    assert len(steps) == pytest.approx(30.0 / 0.52, abs=2)
    # no steps before the gap: the walk is seen but its stride is unknown -> refused, nothing added
    b = AccGapBridge()
    end = _gyro_walk(b, 5_000_000_000, 30.0, 0.52, 0.4)
    gap, steps, _ = b.close(end, attitude_started=True)
    assert steps == [] and gap.verdict in (GapVerdict.NO_STRIDE, GapVerdict.STILL)
    # a still phone (drift only): no walking
    b = AccGapBridge()
    for k in range(10):
        b.note_step(k * 500_000_000, 0.7, 0.5)
    end = _gyro_walk(b, 5_000_000_000, 30.0, 0.52, 0.01)
    gap, steps, _ = b.close(end, attitude_started=True)
    assert steps == [] and gap.verdict is GapVerdict.STILL


def test_the_fast_path_refuses_a_recording_with_an_accelerometer_gap(runs):
    from desktop.fast import run_fast

    with pytest.raises(NotImplementedError, match="does not bridge"):
        run_fast(runs["gap"])


def test_a_pause_of_the_whole_phone_is_no_accelerometer_gap(walk, runs):
    """acc and gyro stop together (real data: liatoutou_walk2's 229-s pause): nothing to bridge, nothing said,
    and the fast path does not refuse it."""
    from core.pdr.gapbridge import acc_gaps_with_gyro

    rec = walk.recording
    cut = {}
    for name in ("acc", "gyro"):
        s = rec.streams[name]
        t = (s.t_ns - rec.streams["acc"].t_ns[0]) * 1e-9
        keep = (t < 15.0) | (t > 35.0)
        cut[name] = make_stream(name, s.t_ns[keep], s.values[keep])
    both = Recording({**rec.streams, **cut}, dict(rec.device), dict(rec.metadata))
    res = Pipeline().run(both)
    assert res.summary()["acc_gaps"] == [] and not any(s.estimated for s in res.steps)
    assert acc_gaps_with_gyro(both.streams["acc"].t_ns, both.streams["gyro"].t_ns, 2.0) == 0
    gap = runs["gap"]
    assert acc_gaps_with_gyro(gap.streams["acc"].t_ns, gap.streams["gyro"].t_ns, 2.0) == 1
