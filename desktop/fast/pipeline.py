"""``run_fast``: the hand-held pipeline over whole arrays, stage by stage.

The order of :class:`core.pdr.pipeline.Pipeline`'s per-event loop, taken
apart where the data allow it:

1. the events of the three streams, checked (non-finite, impossible) and
   merged in the pipeline's order, as arrays (vectorised); the sensor-health
   counters (vectorised where no reading sits on a rail or repeats, else
   core's :class:`core.pdr.pipeline.SensorHealth`);
2. the magnetometer calibration over its stream (it never sees the attitude:
   :func:`desktop.fast.attitude.calibrate_magnetometer`; compiled per reading,
   its fits core's Python);
3. the accelerometer norm (eq. 2) and its uniform grid (compiled);
4. the attitude filter over all events, the attitude taken at each grid sample
   (compiled after the reference's own start: :mod:`desktop.fast.attitude`);
5. the rotation smoother over the grid's attitudes (section 4.3, compiled);
6. the carry-mode detector (issue #17, :mod:`desktop.fast.carry`): its
   features over all hops at once (vectorised), each hop's decision core's;
   its mode and step period at every grid sample;
7. one step detector (eqs. 2-3) per distinct carry-mode gates of
   ``step_gates`` (usually two: the hand-held and the swinging hand's), each
   over the whole grid with the carry detector's step period, and the speed
   window at their peaks (compiled);
8. the gates and the steps (per step, :mod:`desktop.fast.gates`): the active
   mode's peaks are candidates; at a change to a mode with another detector
   that detector's held peaks replace the unconfirmed candidates.

The result is :meth:`core.pdr.pipeline.Pipeline.run`'s: the same steps, the
positions and headings within 1e-9 (``tests/test_fast_path.py``), the same
attitude log, counters and labels.  Desktop only: nothing in ``core/`` or
``app/`` imports it, and the phone's per-event path stays the reference.
"""

from __future__ import annotations

import time

import numpy as np

from core.conventions import ACC, CARRY_MODES, GYRO
from core.pdr.pipeline import (IMPOSSIBLE, MAG, SATURATION_FLOOR, AttitudeLog, Pipeline, PipelineResult, SensorHealth,
                               Track)
from core.recording import Recording
from desktop.fast import attitude as fatt
from desktop.fast.carry import run_carry
from desktop.fast.gates import StepRelease, rotation_sums
from desktop.fast.grid import acc_norm, grid_of
from desktop.fast.heading import smooth_headings
from desktop.fast.steps import detect_steps, speed_at

_KIND = {GYRO: fatt.GYRO_K, ACC: fatt.ACC_K}


def health_of(floor: float, t_ns: np.ndarray, v: np.ndarray) -> SensorHealth:
    """A stream's :class:`SensorHealth` after all its (valid) readings.

    Only a reading at or beyond ``floor`` or one equal to the one before it
    can change the detector's counters; without either (the usual case) only
    its count and last reading move, set here at once.
    """
    h = SensorHealth(floor)
    n = len(t_ns)
    if n == 0:
        return h
    on_rail = bool(np.any(np.abs(v) >= floor))
    repeats = n > 1 and bool(np.any(np.all(v[1:] == v[:-1], axis=1)))
    if on_rail or repeats:
        for ti, (x, y, z) in zip(t_ns.tolist(), v.tolist()):
            h.update(ti, x, y, z)
        return h
    h.n = n
    h._prev, h._prev_t = tuple(float(x) for x in v[-1]), int(t_ns[-1])
    return h


class _Events:
    """The valid events of the pipeline's streams, merged in its order (time, stream order, row)."""

    def __init__(self, recording: Recording, pipe: Pipeline):
        use = [n for n in (GYRO, ACC, pipe.mag_stream) if recording.has(n)]
        order = recording.stream_order(use)
        ts, ks, vs = [], [], []
        for k, name in enumerate(order):
            s = recording.streams[name]
            t = np.asarray(s.t_ns, dtype=np.int64)
            v = np.asarray(s.values, dtype=np.float64).reshape(len(t), -1)[:, 0:3]
            pipe.seen[name] = len(t)
            finite = np.all(np.isfinite(v), axis=1)
            lim = IMPOSSIBLE[name if name in IMPOSSIBLE else MAG]
            possible = np.all((v >= -lim) & (v <= lim), axis=1)
            if np.count_nonzero(~finite):
                pipe.n_nonfinite[name] = int(np.count_nonzero(~finite))
            if np.count_nonzero(finite & ~possible):
                pipe.n_impossible[name] = int(np.count_nonzero(finite & ~possible))
            ok = finite & possible
            ts.append(t)
            ks.append(np.full(len(t), k, dtype=np.int64))
            vs.append(np.where(ok[:, None], v, np.nan))
            floor = SATURATION_FLOOR[name if name in (GYRO, ACC) else MAG]
            pipe.health[name] = health_of(floor, t[ok], v[ok])
        t = np.concatenate(ts) if ts else np.zeros(0, np.int64)
        k = np.concatenate(ks) if ks else np.zeros(0, np.int64)
        v = np.concatenate(vs) if vs else np.zeros((0, 3))
        idx = np.lexsort((k, t))
        t, k, v = t[idx], k[idx], v[idx]
        keep = np.all(np.isfinite(v), axis=1)
        code = np.array([_KIND.get(name, fatt.MAG_K) for name in order], dtype=np.int8)
        self.t = np.ascontiguousarray(t[keep])
        self.kind = np.ascontiguousarray(code[k[keep]]) if len(order) else np.zeros(0, np.int8)
        self.v = np.ascontiguousarray(v[keep])
        self.pos = {c: np.flatnonzero(self.kind == c) for c in (fatt.GYRO_K, fatt.ACC_K, fatt.MAG_K)}


def run_fast(recording: Recording, *, timings: dict | None = None, pipeline: Pipeline | None = None,
             **params) -> PipelineResult:
    """``Pipeline(**params).run(recording)``, computed over whole arrays (see the module docstring).

    Takes the same parameters as :class:`core.pdr.pipeline.Pipeline`, or instead (not both) ``pipeline``: a
    ready-made one to fill, as ``pipeline.run(recording)`` would (it is reset first, as ``run`` resets it: its
    settings stay, e.g. a magnetic declination or site field given to its attitude filter).  A GPS fusion
    (``gnss``) and attitude filters the kernel does not implement
    (:func:`desktop.fast.attitude.check_supported`) raise ``NotImplementedError``.
    ``timings``, if given, receives the CPU seconds of each stage (the benchmark's breakdown).
    """
    clock = _Clock(timings)
    if pipeline is not None and params:
        raise TypeError("run_fast takes either a pipeline or the parameters of one, not both")
    if params.get("gnss") is not None or getattr(pipeline, "gnss", None) is not None:
        raise NotImplementedError("the fast path has no GPS fusion")
    recording.stream(ACC, "step detection needs the accelerometer")
    if pipeline is None:
        p = Pipeline(**params)
    else:
        p = pipeline
        p.reset()
    ekf = p.attitude
    fatt.check_supported(ekf)
    ev = _Events(recording, p)
    clock("events")
    # 2. the magnetometer calibration over its stream
    calibrator = ekf.mag_calibrator
    mag_pos = ev.pos[fatt.MAG_K]
    v = ev.v.copy()
    cal_ok = np.ones(len(ev.t), dtype=np.bool_)
    if ekf.use_magnetometer and len(mag_pos):
        v[mag_pos], cal_ok[mag_pos] = fatt.calibrate_magnetometer(calibrator, ev.t[mag_pos], ev.v[mag_pos])
    clock("magnetometer calibration (compiled per reading; core's fits, Python)")
    # 3. the grid
    acc_pos = ev.pos[fatt.ACC_K]
    gt, gx, src, restart = grid_of(ev.t[acc_pos], acc_norm(ev.v[acc_pos]), p.grid_rate_hz)
    tick_event = np.ascontiguousarray(acc_pos[src])
    clock("grid")
    n_ticks = len(gt)
    # 4. the attitude
    out_q = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (n_ticks, 1))
    out_acc_s2, out_mag_s2 = np.full(n_ticks, np.nan), np.full(n_ticks, np.nan)
    out_rej = np.zeros(n_ticks, dtype=np.bool_)
    ekf.mag_calibrator = None
    try:
        i0, j0, j_init = fatt.start_with_reference(ekf, ev.kind, ev.t, v, cal_ok, tick_event, out_q, out_acc_s2,
                                                   out_mag_s2, out_rej)
        if i0 < len(ev.t):
            st = fatt.KernelState(ekf, len(ev.pos[fatt.GYRO_K]), len(acc_pos), len(mag_pos))
            st.run(ev.kind, ev.t, v, cal_ok, i0, tick_event, j0, out_q, out_acc_s2, out_mag_s2, out_rej)
            st.write_back(ekf)
    finally:
        ekf.mag_calibrator = calibrator
    clock("attitude")
    # 5. the smoother
    east, north, heading = (np.full(n_ticks, np.nan) for _ in range(3))
    e, nn, h, upright, counters = smooth_headings(p.smoother, out_q[j_init:])
    east[j_init:], north[j_init:], heading[j_init:] = e, nn, h
    p.smoother.upright = bool(counters[0])
    p.smoother.n_axis_switches, p.smoother.n_upright = int(counters[1]), int(counters[2])
    if p.smoother.upright:
        p.smoother.forward_b = (0.0, 0.0, -1.0)
    clock("smoother")
    # 6. the carry-mode detector (issue #17): its mode and step period at every grid sample
    gyro_pos = ev.pos[fatt.GYRO_K]
    acc_at = ev.v[tick_event]
    track = det_at = None
    if p.carry is not None:
        g = np.searchsorted(gyro_pos, tick_event, side="left") - 1
        has_gyro = g >= 0
        gyro_at = np.where(has_gyro[:, None], ev.v[gyro_pos[np.maximum(g, 0)]] if len(gyro_pos) else 0.0, 0.0)
        track = run_carry(p.carry, gt, acc_at, gyro_at, has_gyro, restart)
        index = {d: i for i, d in enumerate(p._mode_detectors)}
        det_of_mode = np.array([index[p._det_of[m]] for m in CARRY_MODES], dtype=np.int64)
        det_at = det_of_mode[track.mode]
        p._carry_mode = CARRY_MODES[int(track.mode[-1])] if n_ticks else p._carry_mode
        p._active_det = p._mode_detectors[int(det_at[-1])] if n_ticks else p._active_det
    clock("carry-mode detector")
    # 7. every step detector (one per distinct gates), the speed window at their peaks
    found = []
    for det in p._mode_detectors:
        det.n_grid = n_ticks
        ev_tick, ev_t, ev_f = detect_steps(det, gt, gx, restart, det.gates,
                                           None if track is None else track.step_period_s)
        found.append((ev_tick, ev_t, ev_f))
    all_ticks = np.unique(np.concatenate([f[0] for f in found]))
    speed = speed_at(p.speed_window, gt, gx, restart, all_ticks)
    clock("steps, speed window")
    # 8. gates and steps
    rot_sum = np.empty(len(gyro_pos))
    rot_n = np.empty(len(gyro_pos), dtype=np.int64)
    rotation_sums(ev.t[gyro_pos], np.ascontiguousarray(ev.v[gyro_pos]), p._rot_window_ns, rot_sum, rot_n)
    peaks = []
    for ev_tick, ev_t, ev_f in found:
        g = np.searchsorted(gyro_pos, tick_event[ev_tick], side="left") - 1
        gi = np.maximum(g, 0)
        rms = np.where(g >= 0, np.sqrt(np.maximum(rot_sum[gi], 0.0) / np.maximum(rot_n[gi], 1)), 0.0) \
            if len(gyro_pos) else np.zeros(len(ev_tick))
        peaks.append((ev_tick, ev_t, ev_f, rms, speed[np.searchsorted(all_ticks, ev_tick)]))
    if len(gt):
        release = StepRelease(p, gt, gt[j_init:], east[j_init:], north[j_init:], out_rej)
        if getattr(p, "walkdir", None) is not None:
            axes = [(0.0, 0.0, -1.0) if u else (0.0, 1.0, 0.0) for u in upright.tolist()] if p.smoother.auto_axis \
                else [p.smoother.forward_b] * len(upright)
            release.walking_direction(j_init, out_q, acc_at, axes)
        release.run(peaks, track, det_at)
        clock.move("walking direction (core's stage, Python)", release.walkdir_s)
    else:
        p.finish()
    if len(ev.t):
        p.t_ns = int(ev.t[-1])
    clock("gates and steps")
    return _result(p, recording, AttitudeLog(gt, out_q, heading, out_acc_s2, out_mag_s2, out_rej))


class _Clock:
    """CPU seconds since the last call, added to ``timings[name]`` (nothing without a dict)."""

    def __init__(self, timings: dict | None):
        self.timings = timings
        self.t = time.process_time()

    def __call__(self, name: str) -> None:
        if self.timings is not None:
            now = time.process_time()
            self.timings[name] = self.timings.get(name, 0.0) + now - self.t
            self.t = now

    def move(self, name: str, seconds: float) -> None:
        """Book ``seconds`` of the running interval under ``name`` (a stage interleaved with another)."""
        if self.timings is not None:
            self.timings[name] = self.timings.get(name, 0.0) + seconds
            self.t += seconds


def _result(p: Pipeline, recording: Recording, att: AttitudeLog) -> PipelineResult:
    """The :class:`PipelineResult` of the filled pipeline ``p``, with the counters ``Pipeline.run`` gives."""
    a = p.attitude
    counters = dict(mag_used=a.n_mag_used, mag_rejected=a.n_mag_rejected, acc_rejected=a.n_acc_rejected,
                    peaks_rejected_rotation=p.n_rejected_rotation, peaks_rejected_bout=p.n_rejected_bout)
    counters.update(peaks_replayed_mode_change=p.n_replayed, peaks_replaced_mode_change=p.n_replaced_mode)
    counters["nonfinite_skipped"] = dict(p.n_nonfinite)
    counters.update(p.health_counters())
    counters["attitude"] = a.counters()
    if p.carry is not None:
        counters["carry"] = p.carry.counters()
    return PipelineResult(list(p.steps), Track.from_steps(p.steps), att, p.labels(), recording, counters, None)
