"""The fast path's walking-direction stage over the whole grid against core's, fed sample by sample.

:func:`desktop.fast.walkdir.walking_direction_over_grid` is held to :class:`core.pdr.walkdir.WalkingDirection`
fed grid sample by grid sample with the very inputs ``Pipeline`` feeds it (recorded from ``Pipeline.run``):
after every grid sample the current axis and its accumulators (what ``step_heading``, ``applies``,
``offset_rad`` and ``estimate`` read) within ``TOL``, and at the end the whole state -- the delay buffer, the
open stride, every axis, the counters, the per-stride records, ``last_estimate`` and ``diagnostics()``.  The
inputs: pocket walks of the simulator (the offset applies), the IPIN cut (compass waving, then a hand-held
walk) and a synthetic stream with non-finite samples, axis switches, a quick turn and a pause (the gap's
reset) under five settings.  And ``run_fast`` with the stage wired into ``StepRelease`` as proposed
(:func:`wired_walkdir_to`) against ``Pipeline.run``.  Seeded; the kernels run as plain Python in CI (no numba).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from core.pdr.pipeline import Pipeline
from core.pdr.walkdir import WalkingDirection
from desktop.fast.walkdir import WalkdirTrace, walking_direction_over_grid
from desktop.simulator import simulate_walk
from test_fast_path import REAL, _real  # tests/ is on sys.path: the IPIN cut, skipped where absent

TOL = 1e-9  # on every float (rad, m/s^2 and the accumulators); in practice they are bit for bit equal
#: the accumulators an estimate reads (with ``symmetric_axis_below_ratio`` also the symmetric axes and the flag; 0.0
#: in the kernel's rows and in core's state without it)
FIELDS = ("c2", "s2", "w", "w2", "gx", "gy", "c2s", "s2s", "sym")


def _phase_wd(**kw) -> WalkingDirection:
    """The stage with the rules the compiled kernel implements (``sign_method="phase"``, no symmetric axis; the
    default ``"auto"`` and ``symmetric_axis_below_ratio`` > 0 are fed through ``update``,
    :func:`test_skew_sign_runs_core_update_and_equals_pipeline_run`)."""
    return WalkingDirection(**{"grid_rate_hz": 50.0, "delay_s": Pipeline().heading_delay_s, "sign_method": "phase",
                               "symmetric_axis_below_ratio": 0.0, **kw})


def _record(rec, **params):
    """``Pipeline(**params).run(rec)`` with its walking-direction stage's inputs and the estimate after each
    update recorded: ``(pipeline, inputs, after, result)``; the stage is :func:`_phase_wd` unless given."""
    params.setdefault("walkdir", _phase_wd())
    inputs, after = [], []
    orig = WalkingDirection.update

    def update(self, t_ns, q, ax, ay, az, fe, fn, step=False, axis=None, mat_nb=None):
        orig(self, t_ns, q, ax, ay, az, fe, fn, step, axis, mat_nb)
        inputs.append((t_ns, tuple(q), ax, ay, az, fe, fn, step, axis))
        after.append(_estimate_state(self))

    mp = pytest.MonkeyPatch()
    mp.setattr(WalkingDirection, "update", update)
    try:
        pipe = Pipeline(**params)
        res = pipe.run(rec)
    finally:
        mp.undo()
    return pipe, inputs, after, res


def _estimate_state(wd):
    """What the estimate is made of: the current axis and its accumulators (None without an accepted stride)."""
    st = wd._states.get(wd._axis_key)
    return wd._axis_key, (tuple(getattr(st, f) for f in FIELDS) + (st.n,) if st is not None and st.n else None)


def _arrays(inputs):
    t = np.array([x[0] for x in inputs], dtype=np.int64)
    q = np.array([x[1] for x in inputs], dtype=np.float64).reshape(-1, 4)
    acc = np.array([x[2:5] for x in inputs], dtype=np.float64).reshape(-1, 3)
    fe = np.array([x[5] for x in inputs], dtype=np.float64)
    fn = np.array([x[6] for x in inputs], dtype=np.float64)
    steps = {j for j, x in enumerate(inputs) if x[7]}
    axes = [x[8] for x in inputs]
    return t, q, acc, fe, fn, steps, axes


def _close(a, b) -> bool:
    """Floats within TOL (nan equal to nan); containers element by element; anything else equal."""
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return abs(a - b) <= TOL * max(1.0, abs(a))
    return type(a) is type(b) and a == b


def _state(wd) -> dict:
    """Everything of a WalkingDirection that updates change, as plain data."""
    return {"mean_u": wd._mean_u, "vz": wd._vz, "buf": list(wd._buf), "sums": wd._sums,
            "stride": (wd._stride_steps, wd._stride_t0, wd._stride_fwd0, wd._stride_skipped),
            "axis_key": wd._axis_key,
            "states": {k: tuple(getattr(v, f) for f in FIELDS) + (v.n,) for k, v in wd._states.items()},
            "last_accepted_ns": wd._last_accepted_ns, "n_gap_resets": wd.n_gap_resets,
            "last_estimate": wd.last_estimate, "strides": list(wd.strides), "maxlen": wd.strides.maxlen,
            "n_strides": wd.n_strides, "n_accepted": wd.n_accepted, "rejected": wd.rejected,
            "n_sign_disagreements": wd.n_sign_disagreements, "n_nonfinite": wd.n_nonfinite,
            "diagnostics": wd.diagnostics()}


def _check(ref: WalkingDirection, inputs, after, fresh: WalkingDirection, compiled: bool = True) -> WalkdirTrace:
    """The trace over ``inputs`` against the recorded estimate after each sample and the final state of ``ref``
    (``compiled``: the kernel, even where it runs as plain Python; else ``update`` fed sample by sample)."""
    t, q, acc, fe, fn, steps, axes = _arrays(inputs)
    trace = walking_direction_over_grid(fresh, t, q, acc, fe, fn, steps, axes, compiled=compiled)
    for j, (want_key, want) in enumerate(after):
        key, st = trace.offset_state(j)
        got = None if st is None else tuple(getattr(st, f) for f in FIELDS) + (st.n,)
        assert key == want_key and ((want is None and got is None) or (want is not None and _close(want, got))), j
    # what step_heading gives after a sample, with and without a carry mode: through WalkdirTrace.at, and from
    # an object holding the recorded estimate
    probe = WalkingDirection(**_settings(ref))
    for j in range(0, len(after), max(1, len(after) // 50)):
        trace.at(probe, j)
        want_key, want = after[j]
        shadow = WalkingDirection(**_settings(ref))
        shadow._axis_key = want_key
        if want is not None:
            st = shadow._states[want_key] = type(probe._states[want_key])()
            for f, v in zip(FIELDS + ("n",), want):
                setattr(st, f, v)
        for setting, mode in (("auto", None), ("auto", "pocket"), ("auto", "handheld"), ("acceleration", None)):
            assert _close(probe.step_heading(0.3, setting, mode), shadow.step_heading(0.3, setting, mode))
        assert _close(probe.estimate(), shadow.estimate())
    trace.finish(fresh)
    fresh.n_steps_offset = ref.n_steps_offset  # counted by step_heading, not by the updates
    assert _close(_state(ref), _state(fresh))
    return trace


def _settings(wd: WalkingDirection) -> dict:
    names = ("grid_rate_hz", "delay_s", "vz_leak_time_s", "mean_time_s", "min_stride_s", "max_stride_s",
             "min_horizontal_std_m_s2", "min_anisotropy", "max_stride_turn_rad", "min_forward_norm",
             "memory_strides", "confident_strides", "confident_sigma_rad", "confident_sign", "auto_min_strides",
             "auto_far_min_strides", "auto_min_offset_rad", "max_strides_kept", "axis_method", "pca_min_anisotropy",
             "min_coherence", "reset_after_gap_s", "sign_method", "phase_axis_below_ratio",
             "quadrature_phase", "symmetric_axis_below_ratio")
    return {k: getattr(wd, k) for k in names}


def test_simulated_pocket_walk_equals_core():
    walk = simulate_walk([(0.0, 0.0), (16.0, 0.0), (16.0, 10.0), (0.0, 10.0), (0.0, 0.0)], seed=5,
                         placement="pocket")
    pipe, inputs, after, _ = _record(walk.recording)
    ref = pipe.walkdir
    _check(ref, inputs, after, WalkingDirection(**_settings(ref)))
    assert ref.n_accepted >= 5 and ref.n_steps_offset > 0  # the offset was applied to steps


def test_ipin_cut_equals_core():
    # to 90 s (test_fast_path's cut ends at 80 s): the branches the walking direction takes in its last 10 s
    pipe, inputs, after, _ = _record(_real(REAL[0][0], 0.0, 90.0))
    ref = pipe.walkdir
    _check(ref, inputs, after, WalkingDirection(**_settings(ref)))
    assert ref.n_strides > 10


SETTINGS = (dict(max_strides_kept=8), dict(axis_method="pca", max_strides_kept=0),
            dict(axis_method="coherent", min_coherence=0.79), dict(axis_method="phase", min_anisotropy=1.05),
            dict(pca_min_anisotropy=3.0, memory_strides=4.0, reset_after_gap_s=5.0, delay_s=0.0),
            dict(phase_axis_below_ratio=10.0), dict(phase_axis_below_ratio=5.0),  # all strides switched; 3 of 32
            dict(quadrature_phase=True, axis_method="phase"), dict(symmetric_axis_below_ratio=0.8))


@cache
def _synthetic(i: int) -> WalkingDirection:
    """The synthetic stream with ``SETTINGS[i]``, checked: the reference (once per test session)."""
    settings = {"sign_method": "phase", "symmetric_axis_below_ratio": 0.0, **SETTINGS[i]}
    # 60 s at 50 Hz of a walk-like acceleration (steps every 0.54 s) whose forward axis is 70 deg off the device
    # heading, with a device turning slowly and once quickly; non-finite samples, axis switches, strides with a
    # vertical axis, a pause of 15 s (steps standing still for 4 s of it, then the gap's reset); each axis
    # method, an incoherence limit, no records kept, no delay
    rng = np.random.default_rng(21)
    n = 50 * 60
    t = 5_000_000_000 + 20_000_000 * np.arange(n, dtype=np.int64)
    s = t * 1e-9
    head = 0.02 * s + np.clip(s - 53.0, 0.0, 1.0) * 1.5  # 1.5 rad within a second at 53 s: turning strides
    yaw = np.column_stack([np.cos(0.5 * head), np.zeros(n), np.zeros(n), np.sin(0.5 * head)])
    phase = 2.0 * math.pi * s / 0.55
    walking = (s < 25.0) | (s > 40.0)  # j < 1000 and j > 1750
    fwd_dev = head + math.radians(70.0)
    a_f = np.where(walking, -1.2 * np.sin(phase), 0.0)
    a_up = np.where(walking, 2.0 * np.cos(phase), 0.0)
    a_side = np.where(walking, 0.5 * np.sin(0.5 * phase + 0.3), 0.0)
    ae = a_f * np.cos(fwd_dev) - a_side * np.sin(fwd_dev)
    an = a_f * np.sin(fwd_dev) + a_side * np.cos(fwd_dev)
    acc_n = np.column_stack([ae, an, 9.81 + a_up]) + rng.normal(scale=0.05, size=(n, 3))
    # device frame: rotate back by the yaw (q rotates body into ENU)
    c, sn = np.cos(head), np.sin(head)
    acc = np.column_stack([c * acc_n[:, 0] + sn * acc_n[:, 1], -sn * acc_n[:, 0] + c * acc_n[:, 1], acc_n[:, 2]])
    fe, fn = np.cos(head), np.sin(head)
    fe = fe.copy()
    fe[2200:2300] *= 0.05  # the forward axis nearly vertical for a while
    fn = fn.copy()
    fn[2200:2300] *= 0.05
    acc[rng.integers(0, n, size=15)] = np.nan
    fe[rng.integers(0, n, size=5)] = np.inf
    steps = {j for j in range(n) if (walking[j] or 1300 <= j < 1500) and (j % 27 == 0)}
    axes = [(0.0, 1.0, 0.0) if (j // 700) % 3 else (0.0, 0.0, -1.0) for j in range(n)]
    ref = WalkingDirection(**settings)
    after = []
    inputs = []
    for j in range(n):
        args = (int(t[j]), tuple(yaw[j].tolist()), float(acc[j, 0]), float(acc[j, 1]), float(acc[j, 2]),
                float(fe[j]), float(fn[j]), j in steps, axes[j])
        ref.update(*args)
        inputs.append(args)
        after.append(_estimate_state(ref))
    _check(ref, inputs, after, WalkingDirection(**settings))
    if i == 0:  # without numba the trace comes from update itself: the same
        _check(ref, inputs, after, WalkingDirection(**settings), compiled=False)
    return ref


@pytest.mark.parametrize("i", range(len(SETTINGS)),
                         ids=[",".join(f"{k}={v}" for k, v in d.items()) for d in SETTINGS])
def test_synthetic_stream_nonfinite_axis_switches_and_a_pause(i):
    ref = _synthetic(i)
    assert ref.n_gap_resets >= 1 and ref.n_accepted >= 5 and ref.n_nonfinite >= 15
    assert ref.last_estimate is not None and sum(ref.rejected.values()) > 0


def test_synthetic_streams_reach_every_outcome():
    # the settings above between them: both axes kept, most of the rejection reasons
    refs = [_synthetic(i) for i in range(len(SETTINGS))]
    assert any(len(r.diagnostics()["axes"]) == 2 for r in refs)
    seen = {k for r in refs for k, v in r.rejected.items() if v}
    assert {"duration", "vertical_axis", "still", "turning", "incoherent"} <= seen, seen


@cache
def _short_pocket_walk():
    rec = simulate_walk([(0.0, 0.0), (20.0, 0.0), (20.0, 6.0)], seed=8, placement="pocket").recording
    return rec, _record(rec)


def wired_walkdir_to(self, k: int, step_ticks: set) -> None:
    """``desktop.fast.gates.StepRelease._walkdir_to`` as the stage is wired in (the report of the change that
    added desktop/fast/walkdir.py): the whole grid in one pass at the first call, then the estimate after
    grid sample ``k`` put into the pipeline's WalkingDirection (the final state at the last sample)."""
    if self._walkdir is None:
        return
    if getattr(self, "_wd_trace", None) is None:
        j_init, q, acc, axes = self._walkdir
        self._wd_trace = walking_direction_over_grid(self.p.walkdir, self.grid_t, q, acc, self.fwd_e, self.fwd_n,
                                                     step_ticks, axes, j_init)
    self._wd_trace.at(self.p.walkdir, k)


def test_wired_into_the_fast_path(monkeypatch):
    # run_fast with StepRelease._walkdir_to replaced as proposed: the steps and the stage's final state (labels
    # and counters read it) as Pipeline.run's
    from desktop.fast import gates, run_fast

    rec, (pipe, _, _, res) = _short_pocket_walk()
    monkeypatch.setattr(gates.StepRelease, "_walkdir_to", wired_walkdir_to)
    fast = Pipeline(walkdir=_phase_wd())
    got = run_fast(rec, pipeline=fast)
    assert fast.walkdir.n_steps_offset == pipe.walkdir.n_steps_offset > 0
    assert _close(_state(pipe.walkdir), _state(fast.walkdir))
    assert np.array_equal(got.track.t_ns, res.track.t_ns)
    for name in ("heading_rad", "east_m", "north_m", "length_m"):
        assert np.allclose(getattr(got.track, name), getattr(res.track, name), rtol=0.0, atol=TOL), name
    assert got.summary()["labels"] == res.summary()["labels"]


def test_from_a_later_grid_sample_and_as_step_release_reads_it():
    # j_init > 0 and the axes given as indices: the samples before j_init are not fed; at() before j_init and
    # at the end
    _, (pipe, inputs, after, _) = _short_pocket_walk()
    t, q, acc, fe, fn, steps, axes = _arrays(inputs)
    j0 = 7
    pad_t = np.concatenate([t[0] - 20_000_000 * np.arange(j0, 0, -1), t])
    pad_q = np.concatenate([np.full((j0, 4), np.nan), q])
    pad_acc = np.concatenate([np.full((j0, 3), np.nan), acc])
    keys = sorted(set(axes))
    ids = np.array([keys.index(a) for a in axes])
    wd = WalkingDirection(**_settings(pipe.walkdir))
    trace = walking_direction_over_grid(wd, pad_t, pad_q, pad_acc, fe, fn, {j + j0 for j in steps}, ids, j0,
                                        axis_keys=keys, compiled=True)
    trace.at(wd, j0 - 1)
    assert wd._axis_key is None and wd._states == {} and wd.offset_rad == 0.0
    for j, (want_key, want) in enumerate(after):
        key, st = trace.offset_state(j + j0)
        assert key == want_key and (st is None) == (want is None)
    trace.at(wd, len(pad_t) - 1)
    wd.n_steps_offset = pipe.walkdir.n_steps_offset
    assert _close(_state(pipe.walkdir), _state(wd))


def test_skew_sign_runs_core_update_and_equals_pipeline_run():
    # sign_method other than "phase" (issue #25): the compiled kernel does not implement it, so the trace is fed
    # through WalkingDirection.update (whatever ``compiled`` says) and carries the skew evidence (kx, ky, wp):
    # run_fast gives Pipeline.run's steps and the stage's final state
    from desktop.fast import run_fast

    rec, _ = _short_pocket_walk()

    def pipe():
        return Pipeline(walkdir=WalkingDirection(grid_rate_hz=50.0, delay_s=Pipeline().heading_delay_s,
                                                 sign_method="auto"))

    ref = pipe()
    res = ref.run(rec)
    fast = pipe()
    got = run_fast(rec, pipeline=fast)
    assert ref.walkdir.n_accepted > 5 and any("skew" in s for s in ref.walkdir.strides)
    assert fast.walkdir.n_steps_offset == ref.walkdir.n_steps_offset > 0
    assert _close(_state(ref.walkdir), _state(fast.walkdir))
    assert _close({k: (v.kx, v.ky, v.wp) for k, v in ref.walkdir._states.items()},
                  {k: (v.kx, v.ky, v.wp) for k, v in fast.walkdir._states.items()})
    for name in ("heading_rad", "east_m", "north_m", "length_m"):
        assert np.allclose(getattr(got.track, name), getattr(res.track, name), rtol=0.0, atol=TOL), name
