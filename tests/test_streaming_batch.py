"""Streaming and batch agree where they can break (issue #8).

``Pipeline.run`` is a loop over ``Pipeline.update``, so comparing that loop
with itself proves nothing.  These tests compare paths that really differ:

* the app's path -- a source drained in uneven batches on a clock tick,
  ``app.session.Session`` reordering, recording and calling ``status()``
  between ticks, ``finish()`` at the end of the source -- against
  ``Pipeline().run`` on the same recording, and the file the session wrote,
  replayed through ``Pipeline.run``;
* ``Pipeline.update`` fed in chunks of arbitrary (hypothesis-chosen) sizes,
  probed between chunks, on a recording that ends mid-walk (so ``finish()``
  has work to do), and ``run()`` on a pipeline that already streamed;
* each stage with a batch method (step detector, rotation smoother, dead
  reckoner) driven in random chunks against its ``run()``, and against an
  independent computation (a sine with known peaks, scipy's ``lfilter``,
  numpy's ``cumsum``).

Tolerances: step and event times are ints and compared exactly; lengths,
headings and positions within 1e-9 (m, rad); counts and flags exactly.
All randomness is seeded; hypothesis is derandomized with a bounded number of examples.
"""

from __future__ import annotations

import math
from collections import deque
from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from app.session import Session
from app.settings import Settings
from app.sources import ReplaySource, SensorSource
from core import quaternion as quat
from core.conventions import wrap_angle
from core.pdr.deadreckoning import DeadReckoner
from core.pdr.heading import RotationSmoother
from core.pdr.pipeline import Pipeline
from core.pdr.steps import StepDetector
from core.recording import Recording, make_stream, read_recording
from desktop.simulator import simulate_walk

TOL = 1e-9  # m and rad
# no shrinking phase: each example replays a walk, and a failure should be reported in seconds, not minutes
HYPOTHESIS = settings(max_examples=10, derandomize=True, deadline=None, database=None, report_multiple_bugs=False,
                      phases=(Phase.explicit, Phase.generate), suppress_health_check=[HealthCheck.too_slow])


# -- shared walks ------------------------------------------------------------------------------


@cache
def _sim():
    return simulate_walk([(0.0, 0.0), (12.0, 0.0), (12.0, 8.0), (4.0, 8.0)], seed=3)


@cache
def _walk():
    """A walk with two corners, plus a 1 Hz GPS stream the app feeds to the pipeline and run() does not."""
    rec = _sim().recording
    t_gps = np.arange(rec.t0_ns + 500_000_000, rec.t1_ns, 1_000_000_000, dtype=np.int64)
    k = np.arange(len(t_gps))
    gps = np.column_stack([48.0 + 1e-6 * k, 11.0 + 1e-6 * k, np.full(len(k), 500.0), np.full(len(k), 5.0)])
    streams = dict(rec.streams)
    streams["gps"] = make_stream("gps", t_gps, gps)
    return Recording(streams, device=dict(rec.device), metadata=dict(rec.metadata))


@cache
def _cut_walk():
    """A walk cut off mid-stride: steps are still waiting for their heading when the data ends."""
    rec = simulate_walk([(0.0, 0.0), (10.0, 0.0), (10.0, 6.0)], seed=5, rate_hz=50.0).recording
    # 0.25 s after a step's peak: detected (one grid sample plus the low-pass delay after it), but its
    # heading is read only heading_delay_s (0.45 s) after it -- so finish() has to complete it
    t_cut = int(Pipeline().run(rec).steps[15].t_ns) + 250_000_000
    return rec.slice_time(rec.t0_ns, t_cut)


def _app_pipeline_kwargs():
    """What the app passes to Pipeline (PDRApp._pipeline_factory with the default settings)."""
    return Settings().pipeline_kwargs()


@cache
def _batch(which: str):
    rec = {"walk": _walk, "cut": _cut_walk}[which]()
    kw = _app_pipeline_kwargs() if which == "walk" else {}
    return Pipeline(**kw).run(rec)


def _assert_same_steps(got, ref, what: str):
    """Same steps: count, index, time (exact ints), flags exactly; lengths, headings, positions within TOL."""
    assert len(got) == len(ref), f"{what}: {len(got)} steps, batch run() has {len(ref)}"
    assert [s.index for s in got] == [s.index for s in ref], f"{what}: step indices differ"
    assert [int(s.t_ns) for s in got] == [int(s.t_ns) for s in ref], f"{what}: step times differ from run()"
    np.testing.assert_allclose([s.length_m for s in got], [s.length_m for s in ref], rtol=0, atol=TOL,
                               err_msg=f"{what}: step lengths differ from run()")
    dh = [wrap_angle(a.heading_rad - b.heading_rad) for a, b in zip(got, ref)]
    np.testing.assert_allclose(dh, 0.0, rtol=0, atol=TOL, err_msg=f"{what}: step headings differ from run()")
    np.testing.assert_allclose([(s.east_m, s.north_m) for s in got], [(s.east_m, s.north_m) for s in ref],
                               rtol=0, atol=TOL, err_msg=f"{what}: positions differ from run()")
    assert [bool(s.mag_trusted) for s in got] == [bool(s.mag_trusted) for s in ref], \
        f"{what}: mag_trusted flags differ from run()"


def test_the_reference_walks_exercise_what_they_are_meant_to():
    """Guards the other tests: enough steps, and the cut walk leaves steps for finish()."""
    assert len(_batch("walk").steps) >= 30
    assert _walk().has("gps")
    p = Pipeline()
    streamed = []
    for name, t, v in _cut_walk().events(["gyro", "acc", "mag"]):
        streamed.extend(p.update(name, t, v))
    pending = p.finish()
    assert len(streamed) >= 8 and len(pending) >= 1, \
        f"the cut walk must end with steps pending (streamed {len(streamed)}, pending {len(pending)})"


# -- 1. the app's batched drain against a whole-file run ------------------------------------------


class TickClock:
    """Wall clock for the session and the replay: advances by ``per_call_s`` each time it is read
    (so Session.tick's time budget runs out mid-drain) and by ``tick`` between ticks."""

    def __init__(self, t=1000.0, per_call_s=0.0):
        self.t = t
        self.per_call_s = per_call_s

    def __call__(self):
        self.t += self.per_call_s
        return self.t


class BurstySource(SensorSource):
    """A live-like source: events arrive in per-sensor order with up to ``max_delay_ns`` of delivery
    delay (so streams interleave out of time order, as separate sensor callbacks do), and the queue is
    filled in uneven bursts (``release``) between ticks -- sometimes nothing, sometimes a stall's worth."""

    kind = "bursty"

    def __init__(self, recording, *, seed: int, max_delay_ns: int = 20_000_000):
        super().__init__()
        rng = np.random.default_rng(seed)
        events = list(recording.events())
        last_arrival: dict = {}
        arrivals = []
        for i, (name, t, _) in enumerate(events):
            a = max(last_arrival.get(name, -math.inf), t + int(rng.integers(0, max_delay_ns)))
            last_arrival[name] = a
            arrivals.append((a, i))
        self.pending = deque(events[i] for _, i in sorted(arrivals))
        self.queue: deque = deque()
        self.device = {"platform": "test"}

    def release(self, n: int) -> None:
        for _ in range(min(n, len(self.pending))):
            self.queue.append(self.pending.popleft())

    def drain(self, max_events=None) -> list:
        n = len(self.queue) if max_events is None else min(max_events, len(self.queue))
        return [self.queue.popleft() for _ in range(n)]

    @property
    def finished(self) -> bool:
        return not self.pending and not self.queue


def _drive_like_the_app(ses: Session, before_tick, max_ticks: int = 20000) -> list:
    """PDRApp._tick: ses.tick(), then the UI reads summary() / health_text() (status() of the pipeline)."""
    new_total = []
    ses.start()
    for _ in range(max_ticks):
        before_tick()
        new = ses.tick()
        new_total.extend(new)
        summ = ses.summary()
        assert summ["steps"] == len(ses.steps)
        ses.health_text()
        if ses.finished:
            break
    assert ses.finished, "the session never finished its source"
    ses.close()
    return new_total


@pytest.mark.parametrize("mode", ["bursty", "replay_10x", "replay_max"])
def test_app_session_in_uneven_batches_equals_the_whole_file_run(tmp_path, mode):
    rec = _walk()
    batch = _batch("walk")
    kw = _app_pipeline_kwargs()
    rng = np.random.default_rng({"bursty": 1, "replay_10x": 2, "replay_max": 3}[mode])
    path = tmp_path / "live.pdr.csv"
    if mode == "bursty":
        clock = TickClock()
        src = BurstySource(rec, seed=7)

        def before_tick():
            clock.t += 1 / 30
            # mostly a tick's worth (about 8 events), sometimes none, sometimes a stall of up to 2500
            r = rng.random()
            src.release(0 if r < 0.15 else int(rng.integers(1, 2500)) if r > 0.9 else int(rng.integers(1, 20)))
    else:
        # the replay's own clock and the session's deadline both read this clock; at "max" the per-call
        # advance makes Session.tick stop mid-drain on its time budget, leaving uneven chunks
        clock = TickClock(per_call_s=0.004 if mode == "replay_max" else 0.0)
        src = ReplaySource(rec, speed=10.0 if mode == "replay_10x" else math.inf, clock=clock,
                           max_chunk=int(rng.integers(300, 1500)))

        def before_tick():
            clock.t += (1 / 30) * rng.uniform(0.3, 2.5)  # the Kivy clock is not regular either

    ses = Session(src, pipeline_factory=lambda: Pipeline(**kw), record_path=str(path), clock=clock)
    new = _drive_like_the_app(ses, before_tick)

    assert ses.errors == 0, ses.last_error
    assert ses.health.streams["acc"].out_of_order == 0, "the reorder window should absorb the delivery delay"
    _assert_same_steps(ses.steps, batch.steps, f"app session ({mode})")
    _assert_same_steps(new, batch.steps, f"steps returned by Session.tick ({mode})")
    np.testing.assert_allclose(ses.track_east[1:], batch.track.east_m, rtol=0, atol=TOL)
    np.testing.assert_allclose(ses.track_north[1:], batch.track.north_m, rtol=0, atol=TOL)
    st_ = ses.status()
    assert st_.n_steps == len(batch.steps)
    assert st_.distance_m == pytest.approx(float(np.sum(batch.track.length_m)), abs=TOL)

    # the file the app wrote: every event, exactly, and the same track when replayed as a file
    written = read_recording(str(path))
    for name, s in rec.streams.items():
        w = written.streams[name]
        assert w.t_ns.tolist() == s.t_ns.tolist(), f"recorded {name} times differ"
        np.testing.assert_allclose(w.values, s.values, rtol=0, atol=1e-12, err_msg=f"recorded {name} values")
    _assert_same_steps(Pipeline(**kw).run(written).steps, batch.steps, f"recorded file of the {mode} session")


# -- 2. Pipeline.update in chunks of arbitrary sizes ------------------------------------------------


def _stream_in_chunks(p: Pipeline, events: list, sizes: list[int], probe: bool) -> list:
    steps = []
    i = k = 0
    while i < len(events):
        n = sizes[k % len(sizes)]
        k += 1
        for name, t, v in events[i:i + n]:
            steps.extend(p.update(name, t, v))
        i += n
        if probe:
            s = p.status()
            assert s.n_steps == len(steps), "status() counts other steps than update() returned"
            assert s.distance_m == pytest.approx(sum(x.length_m for x in steps), abs=TOL)
            if steps:
                assert (s.east_m, s.north_m) == pytest.approx((steps[-1].east_m, steps[-1].north_m), abs=TOL)
            assert s.t_ns == events[min(i, len(events)) - 1][1], "status() is not at the last event fed"
    steps.extend(p.finish())
    return steps


@HYPOTHESIS
@given(sizes=st.lists(st.integers(min_value=1, max_value=900), min_size=1, max_size=8), probe=st.booleans())
def test_pipeline_update_in_arbitrary_chunks_equals_run_on_a_walk_cut_mid_stride(sizes, probe):
    rec = _cut_walk()
    events = list(rec.events(["gyro", "acc", "mag"]))
    p = Pipeline()
    got = _stream_in_chunks(p, events, sizes, probe)
    _assert_same_steps(got, _batch("cut").steps, f"update() in chunks {sizes}, status() probed: {probe}")
    assert p.finish() == [], "a second finish() must not complete steps again"


@HYPOTHESIS
@given(cut=st.floats(min_value=0.05, max_value=0.95))
def test_run_on_a_pipeline_that_already_streamed_equals_a_fresh_run(cut):
    """run() must reset everything streaming touched (a pipeline used live, then asked for the file's
    track)."""
    _streamed_then_run(cut)


def _streamed_then_run(cut: float) -> Pipeline:
    """A pipeline that streamed ``cut`` of :func:`_cut_walk`'s events, then ran the whole walk (checked)."""
    rec = _cut_walk()
    events = list(rec.events(["gyro", "acc", "mag"]))
    p = Pipeline()
    for name, t, v in events[: int(cut * len(events))]:
        p.update(name, t, v)
    res = p.run(rec)
    _assert_same_steps(res.steps, _batch("cut").steps, f"run() after streaming {cut:.0%} of the events")
    assert len(res.track) == len(res.steps)
    assert res.track.t_ns.tolist() == [s.t_ns for s in res.steps]
    return p


def test_a_second_run_on_a_pipeline_that_streamed_and_ran_equals_the_first():
    """A second run() on the same object gives the same steps (once, not in each of the ten cuts above: what a
    run() leaves does not depend on what was streamed before it, that is what the test above checks)."""
    p = _streamed_then_run(0.5)
    again = p.run(_cut_walk())
    _assert_same_steps(again.steps, _batch("cut").steps, "a second run() on the same pipeline")


# -- 3. the stages with a batch method ------------------------------------------------------------


def _chunks(n_items: int, sizes: list[int]):
    i = k = 0
    while i < n_items:
        n = sizes[k % len(sizes)]
        yield i, min(i + n, n_items)
        i += n
        k += 1


def _assert_same_step_events(got, ref, what):
    assert len(got) == len(ref) > 0, f"{what}: {len(got)} events, run() {len(ref)}"
    assert [e.t_ns for e in got] == [e.t_ns for e in ref], f"{what}: peak times differ"
    for field in ("acc_max_m_s2", "acc_min_m_s2", "acc_var_m2_s4", "gravity_m_s2"):
        np.testing.assert_allclose([getattr(e, field) for e in got], [getattr(e, field) for e in ref],
                                   rtol=0, atol=TOL, err_msg=f"{what}: {field}")
    dur_g = np.array([e.duration_s for e in got])
    dur_r = np.array([e.duration_s for e in ref])
    assert np.isnan(dur_g).tolist() == np.isnan(dur_r).tolist(), f"{what}: bout starts differ"
    np.testing.assert_allclose(dur_g[~np.isnan(dur_g)], dur_r[~np.isnan(dur_r)], rtol=0, atol=TOL)


@cache
def _acc():
    acc = _walk().streams["acc"]
    return acc.t_ns.tolist(), acc.values.tolist(), StepDetector().run(acc.t_ns, acc.values)


@HYPOTHESIS
@given(sizes=st.lists(st.integers(min_value=1, max_value=1500), min_size=1, max_size=6))
def test_step_detector_in_chunks_equals_run(sizes):
    t, v, ref = _acc()
    det = StepDetector()
    got = []
    for a, b in _chunks(len(t), sizes):
        for ti, (x, y, z) in zip(t[a:b], v[a:b]):
            got.extend(det.update(ti, x, y, z))
    _assert_same_step_events(got, ref, f"StepDetector.update in chunks {sizes}")
    # run() on the detector that has just streamed everything starts again from scratch
    _assert_same_step_events(det.run(np.array(t, dtype=np.int64), np.array(v)), ref, "StepDetector.run again")


def test_step_detector_finds_the_peaks_of_a_known_sine():
    """Independent check: a 1.8 Hz, 2 m/s^2 bounce on gravity, sampled at a jittered 100 Hz, has one step
    per cycle, time-stamped at the sine's crest.

    Expected lag of a step behind its crest: the grid's box mean over (t - 20 ms, t] delays by 10 ms
    (not compensated), the low-pass's phase delay at 1.8 Hz (81.1 ms, scipy.signal.freqz) exceeds the
    low-frequency group delay the detector subtracts (75.0 ms) by 6.0 ms; a peak is picked on the
    20 ms grid, +-10 ms.  So 16 +- 10 ms (plus 0.5 ms for the jittered samples)."""
    rng = np.random.default_rng(8)
    f_hz, amp, g = 1.8, 2.0, 9.81
    t_ns = np.cumsum(rng.uniform(0.008, 0.012, 2000) * 1e9).astype(np.int64) + 10**12
    ts = (t_ns - t_ns[0]) * 1e-9
    norm = g + amp * np.sin(2 * np.pi * f_hz * ts)
    u = rng.normal(size=(len(ts), 3))
    acc = norm[:, None] * u / np.linalg.norm(u, axis=1, keepdims=True)  # direction irrelevant: eq. 2 is a norm
    det = StepDetector()
    got = []
    for a, b in _chunks(len(t_ns), [37, 1, 250, 3]):
        for ti, row in zip(t_ns[a:b].tolist(), acc[a:b].tolist()):
            got.extend(det.update(ti, *row))
    crests = t_ns[0] + ((np.arange(50) + 0.25) / f_hz * 1e9).astype(np.int64)
    crests = crests[crests < t_ns[-1] - 200_000_000]
    peaks = np.array([e.t_ns for e in got])
    # the low-pass needs about one cycle to settle on the first sample; every later crest is a step
    later = crests[crests > t_ns[0] + 600_000_000]
    nearest = np.abs(peaks[:, None] - later[None, :]).argmin(axis=0)
    lag_ms = (peaks[nearest] - later) * 1e-6
    assert np.all(np.abs(lag_ms - 16.0) <= 10.5), f"steps lag their crests by {lag_ms.min():.1f}..{lag_ms.max():.1f} ms"
    assert len(set(nearest.tolist())) == len(later), "two crests share one step"
    assert len(got) <= len(crests), f"{len(got)} steps for {len(crests)} crests"
    dur = np.array([e.duration_s for e in got[1:]])
    np.testing.assert_allclose(dur, 1 / f_hz, rtol=0, atol=0.025)
    gain = 1.0 / math.sqrt(1.0 + (f_hz / det.cutoff_hz) ** 4)  # |H| of a Butterworth low-pass, order 2
    np.testing.assert_allclose([e.acc_max_m_s2 for e in got[2:]], g + amp * gain, rtol=0, atol=0.05)


@cache
def _matrices():
    """Rotation matrices on the 50 Hz grid from the simulator's exact attitude (no EKF involved)."""
    rec = _walk()
    t = np.arange(rec.t0_ns, rec.t1_ns, 20_000_000, dtype=np.int64)
    q = _sim().truth.attitude_at(t)
    return [quat.to_matrix(tuple(r)) for r in q.tolist()]


@HYPOTHESIS
@given(sizes=st.lists(st.integers(min_value=1, max_value=600), min_size=1, max_size=6))
def test_rotation_smoother_in_chunks_equals_run(sizes):
    mats = _matrices()
    sm = RotationSmoother()
    ref = sm.run(mats)
    sm = RotationSmoother()
    got = []
    for a, b in _chunks(len(mats), sizes):
        got.extend(sm.update(m) for m in mats[a:b])
    np.testing.assert_allclose(wrap_angle(np.array(got) - np.array(ref)), 0.0, rtol=0, atol=TOL)
    np.testing.assert_allclose(wrap_angle(np.array(sm.run(mats)) - np.array(ref)), 0.0, rtol=0, atol=TOL)


def test_rotation_smoother_equals_scipy_lfilter_on_the_matrix_elements():
    """Independent check: scipy's Butterworth on the six first-row elements, started in steady state."""
    signal = pytest.importorskip("scipy.signal")
    mats = _matrices()
    sm = RotationSmoother()
    got = np.array(sm.run(mats))
    b, a = signal.butter(2, sm.cutoff_hz, fs=sm.grid_rate_hz)
    e = np.array([[m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2]] for m in mats])
    zi = signal.lfilter_zi(b, a)
    y = np.column_stack([signal.lfilter(b, a, e[:, j], zi=zi * e[0, j])[0] for j in range(6)])
    fx, fy, fz = sm.forward_b
    expect = np.arctan2(y[:, 3] * fx + y[:, 4] * fy + y[:, 5] * fz, y[:, 0] * fx + y[:, 1] * fy + y[:, 2] * fz)
    np.testing.assert_allclose(wrap_angle(got - expect), 0.0, rtol=0, atol=1e-9)
    # and it did smooth something: the raw heading of the swaying phone differs from the smoothed one
    raw = np.arctan2(e[:, 3] * fx + e[:, 4] * fy + e[:, 5] * fz, e[:, 0] * fx + e[:, 1] * fy + e[:, 2] * fz)
    assert np.max(np.abs(wrap_angle(raw - got))) > 0.02


@HYPOTHESIS
@given(sizes=st.lists(st.integers(min_value=1, max_value=80), min_size=1, max_size=6),
       seed=st.integers(min_value=0, max_value=2**16))
def test_dead_reckoner_in_chunks_equals_run_and_a_cumsum(sizes, seed):
    rng = np.random.default_rng(seed)
    d, h = rng.uniform(0.3, 0.9, 200), rng.uniform(-3 * math.pi, 3 * math.pi, 200)
    east = np.cumsum(d * np.cos(h))  # eq. 1, computed independently
    north = np.cumsum(d * np.sin(h))
    dr = DeadReckoner()
    ref = np.array(dr.run(d, h))
    dr = DeadReckoner()
    got = []
    for a, b in _chunks(len(d), sizes):
        got.extend(dr.update(float(x), float(y)) for x, y in zip(d[a:b], h[a:b]))
        assert dr.n_steps == b
        assert (dr.east_m, dr.north_m) == pytest.approx((east[b - 1], north[b - 1]), abs=TOL)
    np.testing.assert_allclose(np.array(got), ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(ref, np.column_stack([east, north]), rtol=0, atol=TOL)
    assert dr.distance_m == pytest.approx(float(d.sum()), abs=TOL)
