"""A recording that ends mid-walk (issue #25 section 2, steps lost at the end of a walk).

The step detector finds a peak of the filtered norm one grid sample after it, and the low-pass puts that peak about
0.16 s after the heel strike on the simulator (the norm's own peak ~0.09 s after it, the 3-Hz filter's 0.075 s): a
recording stopped within that time of the last heel strike has no peak for it.  ``Pipeline(flush_at_end=True)``
(off by default: see ``docs/`` and ``core.pdr.steps``) takes a filtered norm still rising at the last sample as the
maximum of the data, through every other test, and gives out the step the weak-step rescue found but holds for the
next sample.  A walk that ends standing has a flat end: nothing is added.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.pdr.pipeline import Pipeline
from core.pdr.steps import TRUNK_GATES, StepDetector
from core.recording import Recording, Stream
from desktop.simulator import simulate_walk

PATH = [(0.0, 0.0), (8.0, 0.0)]
_CACHE: dict = {}


def _walk(placement: str, seed: int):
    key = (placement, seed)
    if key not in _CACHE:
        _CACHE[key] = simulate_walk(PATH, placement=placement, seed=seed, rate_hz=50.0, still_start_s=1.5,
                                    still_end_s=2.0)
    return _CACHE[key]


def _cut(rec: Recording, t_cut_ns: int) -> Recording:
    streams = {n: Stream(n, s.t_ns[s.t_ns <= t_cut_ns], s.values[s.t_ns <= t_cut_ns], s.columns, s.unit, s.note)
               for n, s in rec.streams.items()}
    return Recording(streams, dict(rec.device), dict(rec.metadata))


def _streamed(rec: Recording, **kw) -> list:
    p = Pipeline(**kw)
    p.reset()
    out = []
    for name, t, v in rec.events():
        out.extend(p.update(name, t, v))
    return out + p.finish()


@pytest.mark.parametrize("placement", ("handheld", "bag"))
def test_recording_stopped_mid_step_counts_its_last_heel_strike(placement):
    """Cut 0.3 step periods (0.16 s) after the fourth-last heel strike: without the flush that heel strike is missed
    (checked: every heel strike before it is counted, it is not); with it, it is counted within 0.15 s of its heel
    strike, in time order, and batch (``run``) and streaming (``update`` + ``finish``) give the same steps."""
    w = _walk(placement, 0)
    truth = np.asarray(w.truth.step_t_ns)
    period = truth[-4] - truth[-5]
    t_cut = int(truth[-4] + 0.3 * period)
    rec = _cut(w.recording, t_cut)
    n_true = int(np.sum(truth <= t_cut))
    off = Pipeline(flush_at_end=False).run(rec)
    assert len(off.steps) == n_true - 1, (len(off.steps), n_true)  # the bite
    p = Pipeline(flush_at_end=True)
    on = p.run(rec)
    assert len(on.steps) == n_true, (len(on.steps), n_true)
    assert on.counters["steps_flushed_at_end"] == 1
    assert abs(on.steps[-1].t_ns - truth[-4]) < 0.15e9
    assert np.all(np.diff([s.t_ns for s in on.steps]) > 0)
    assert [s.t_ns for s in _streamed(rec, flush_at_end=True)] == [s.t_ns for s in on.steps]


def test_walk_ending_standing_gets_nothing_from_the_flush():
    """A walk that stops and stands 2 s: the same steps with the flush as without (a flat end is no peak), all of
    them; streaming gives the last step out within one step period of its heel strike, before the end of data."""
    w = _walk("handheld", 1)
    truth = np.asarray(w.truth.step_t_ns)
    off = Pipeline(flush_at_end=False).run(w.recording)
    on = Pipeline(flush_at_end=True).run(w.recording)
    assert [s.t_ns for s in on.steps] == [s.t_ns for s in off.steps]
    assert len(on.steps) == len(truth)
    assert on.counters["steps_flushed_at_end"] == 0
    live = Pipeline(flush_at_end=True)
    live.reset()
    out_at = None
    for name, t, v in w.recording.events():
        if live.update(name, t, v) and live.n_steps == len(truth):
            out_at = t
    assert out_at is not None and out_at - truth[-1] < 1.2 * (truth[-1] - truth[-2]), out_at
    assert live.finish() == []


def _weak_step_norm(rate_hz: float = 50.0):
    """A norm stepping at 2 Hz (1.5 m/s^2) with its eighth step weak (0.35 m/s^2): the weak-step rescue's case."""
    t = np.arange(int(6.0 * rate_hz)) / rate_hz
    amp = np.where(np.floor(t * 2.0 + 0.25).astype(int) == 7, 0.35, 1.5)
    return (t * 1e9).astype(np.int64) + 10**9, 9.81 + amp * np.sin(2 * math.pi * 2.0 * t)


def test_flush_gives_out_the_step_held_behind_a_rescued_one():
    """The weak-step rescue gives the weak step out first and the step that revealed it one grid sample later: data
    that end at that sample lost the second (checked: the stash is full then); ``flush`` gives it out, once."""
    t_ns, norm = _weak_step_norm()

    def fed(n):
        d = StepDetector()
        d.set_gates(TRUNK_GATES)
        d.step_period_s = 0.5
        return d, [ev for k in range(n) if (ev := d.update_grid(int(t_ns[k]), float(norm[k]))) is not None]

    full, all_steps = fed(len(t_ns))
    assert full.n_rescued == 1
    k = next(k for k in range(1, len(t_ns)) if fed(k)[0].n_rescued == 1)  # the sample that rescued
    d, steps = fed(k)
    assert d._stash is not None
    flushed = d.flush()
    assert len(flushed) == 1 and flushed[0].t_ns > steps[-1].t_ns
    assert [e.t_ns for e in steps + flushed] == [e.t_ns for e in all_steps[:len(steps) + 1]]
    assert d.flush() == []


@pytest.mark.parametrize("placement", ("handheld", "pocket", "ear"))
def test_fast_path_mirrors_the_flush(placement):
    """The fast path gives the flushed step as the reference does (times the same, positions within 1e-9, one step
    flushed) on walks cut 0.3 step periods after a heel strike, and without the flush the same steps as the
    reference too.  Before: the fast path had no flush (it refused the setting)."""
    from desktop.fast import run_fast

    w = _walk(placement, 0)
    truth = np.asarray(w.truth.step_t_ns)
    rec = _cut(w.recording, int(truth[-4] + 0.3 * (truth[-4] - truth[-5])))
    for flush in (True, False):
        ref = Pipeline(flush_at_end=flush).run(rec)
        fast = run_fast(rec, pipeline=Pipeline(flush_at_end=flush))
        assert [s.t_ns for s in fast.steps] == [s.t_ns for s in ref.steps]
        assert np.allclose([s.east_m for s in fast.steps], [s.east_m for s in ref.steps], rtol=0, atol=1e-9)
        assert np.allclose([s.north_m for s in fast.steps], [s.north_m for s in ref.steps], rtol=0, atol=1e-9)
        assert fast.counters.get("steps_flushed_at_end") == ref.counters.get("steps_flushed_at_end") \
            == (1 if flush else None)


def test_fast_kernel_flushes_the_stash_as_the_reference():
    """The fast step kernel (``desktop.fast.steps.detect_steps(flush=True)``) on data that end at the sample that
    rescued a weak step gives the step waiting behind it, as :meth:`StepDetector.flush` does."""
    from desktop.fast.steps import detect_steps

    t_ns, norm = _weak_step_norm()
    d = StepDetector()
    d.set_gates(TRUNK_GATES)
    d.step_period_s = 0.5
    out = []
    for k in range(len(t_ns)):
        ev = d.update_grid(int(t_ns[k]), float(norm[k]))
        if ev is not None:
            out.append(ev)
        if d.n_rescued:
            break
    out += d.flush()
    n = k + 1
    tick, t, f = detect_steps(StepDetector(), t_ns[:n], norm[:n], np.zeros(n, dtype=bool), TRUNK_GATES,
                              np.full(n, 0.5), flush=True)
    assert t.tolist() == [e.t_ns for e in out]
    assert tick[-1] == n and np.allclose(f[-1], [out[-1].acc_max_m_s2, out[-1].acc_min_m_s2, out[-1].acc_var_m2_s4,
                                                 out[-1].duration_s, out[-1].gravity_m_s2], rtol=0, atol=1e-12)
